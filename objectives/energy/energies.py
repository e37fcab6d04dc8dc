"""Objective building blocks: Dirichlet energy, weighted ℓ1 terms, the CMM energy.

docs/maths.md §4; thesis Def. 3.2.10 (compressed manifold modes) and Def. 3.2.15
(compressed eigenvalue). Everything is pure JAX: operators are anything with
``.mv(X)`` (``stiefel.linalg.operators.SparseOperator``, ``DiagonalOperator``, …); a
``scipy.sparse`` matrix is wrapped with ``SparseOperator.from_scipy`` (never
densified). Nothing here knows about meshes or solvers.

Shapes: ``X`` is ``(n, k)`` (a block of k functions on n vertices) or ``(n,)``
(one column). Every term is a sum over columns, so for the CMM energy ``F``
``F(X) == Σ_j F(X[:, j])`` (the column-separable part used by the sequential
solver, thesis §6.4).

ℓ1 weightings (docs/maths.md §4, both are in the literature):

* ``"area"``:    ``w_i = A_ii``  → ``μ Σ_ij A_ii s(X_ij)`` = ``μ‖AX‖₁`` (the thesis);
* ``"uniform"``: ``w_i = 1/n``   → ``(μ/n) Σ_ij s(X_ij)`` (Neumann et al. 2014).

They agree when every ``A_ii = 1/n`` (thesis Rem. 3.2.14).
"""

from __future__ import annotations

from typing import Callable, Literal

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
import numpy as np
import scipy.sparse as sp
from jaxtyping import Array, ArrayLike, Float, Int

from stiefel.runtime.compilation import host_array
from stiefel.linalg.operators import DenseOperator, DiagonalOperator, LinearOperator, SparseOperator, quadratic_form

from . import smoothings as _smoothings

__all__ = [
    "Weighting",
    "dirichlet",
    "l1_weights",
    "l1_term",
    "CMMEnergy",
    "cmm_energy",
    "compressed_eigenvalues",
    "order_by_compressed_eigenvalue",
]

Weighting = Literal["area", "uniform"]


def _as_matvec(W) -> LinearOperator:
    """Anything with ``.mv``, a ``scipy.sparse`` matrix, or a dense 2-D array → operator."""
    if hasattr(W, "mv"):
        return W
    if sp.issparse(W):
        return SparseOperator.from_scipy(W)
    arr = jnp.asarray(W)
    if arr.ndim == 2 and arr.shape[0] == arr.shape[1]:
        return DenseOperator(arr)  # products only: W may be singular
    raise TypeError(
        f"W must be an operator with .mv (e.g. stiefel.linalg.operators.SparseOperator), a scipy.sparse "
        f"matrix or a square 2-D array; got {type(W).__name__} with shape {getattr(W, 'shape', None)}"
    )


def _as_diag(area_diag) -> Float[Array, " n"]:
    """The diagonal of the mass matrix A from a 1-D array or a diagonal operator."""
    if isinstance(area_diag, DiagonalOperator):
        return area_diag.d
    if hasattr(area_diag, "diagonal") and not isinstance(area_diag, (np.ndarray, jnp.ndarray)):
        return jnp.asarray(area_diag.diagonal())
    d = jnp.asarray(area_diag)
    if d.ndim != 1:
        raise ValueError(
            f"area_diag must be the 1-D diagonal of the lumped mass matrix A, got shape {d.shape}; "
            "pass jnp.diagonal(A) or a DiagonalOperator"
        )
    return d


def _rows(w: Float[Array, " n"], X: Array) -> Array:
    """``w`` reshaped to broadcast over the rows of ``X`` (``(n,)`` or ``(n, k)``)."""
    return w.reshape(w.shape + (1,) * (X.ndim - 1))


def dirichlet(W) -> Callable[[Float[Array, "n *k"]], Float[Array, ""]]:
    """The Dirichlet energy ``X ↦ tr(XᵀWX)`` (docs/maths.md §4; ``xᵀWx`` for a column).

    Args:
      W: the ``(n, n)`` weight (stiffness) matrix, an operator with ``.mv``
        (or ``scipy.sparse`` / dense, wrapped).

    Returns:
      ``E(X)`` for ``X: (n,)`` or ``(n, k)``, a scalar; ``E(X) = Σ_j E(X[:, j])``.
      Costs one ``W.mv``; its gradient ``2WX`` costs one more (W symmetric).
    """
    op = _as_matvec(W)

    def energy(X: Float[Array, "n *k"]) -> Float[Array, ""]:
        return quadratic_form(op, X)

    return energy


def l1_weights(area_diag: Float[ArrayLike, " n"], weighting: Weighting = "area") -> Float[Array, " n"]:
    """Row weights ``w`` of the ℓ1 term: ``A_ii`` (``"area"``) or ``1/n`` (``"uniform"``), docs/maths.md §4."""
    d = _as_diag(area_diag)
    if weighting == "area":
        return d
    if weighting == "uniform":
        return jnp.full_like(d, 1.0 / d.shape[0])
    raise ValueError(f"weighting must be 'area' (w_i = A_ii, the thesis) or 'uniform' (w_i = 1/n), got {weighting!r}")


def l1_term(
    weights: Float[ArrayLike, " n"], smoothing: str | Callable = "f3", *, eps: float = 1e-3, delta: float = 1e-3
) -> Callable[[Float[Array, "n *k"]], Float[Array, ""]]:
    """The weighted (smoothed) ℓ1 term ``X ↦ Σ_ij w_i s(X_ij)``.

    Args:
      weights: ``(n,)`` row weights (see ``l1_weights``).
      smoothing: a Table 6.1 name or alias (``"f3"``, ``"abs"``, ``"huber"``, …)
        or an elementwise callable ``s``.
      eps, delta: ε, δ for a named smoothing.
    """
    w = jnp.asarray(weights)
    s = _smoothings.get(smoothing, eps, delta) if isinstance(smoothing, str) else smoothing

    def term(X: Float[Array, "n *k"]) -> Float[Array, ""]:
        return jnp.sum(_rows(w, X) * s(X))

    return term


class CMMEnergy(eqx.Module):
    """Smoothed compressed-manifold-mode energy (thesis Def. 3.2.10, §6.5):

        ``F(X) = tr(XᵀWX) + μ Σ_ij w_i s_ε,δ(X_ij)``

    with ``w`` the weighting's row weights (``A_ii`` or ``1/n``) and ``s`` a
    Table 6.1 smoothing. An immutable pytree: ``mu``, ``eps``, ``delta`` and
    ``weights`` are leaves (a continuation in δ re-uses the compiled solver;
    use ``with_params``), ``smoothing`` and ``weighting`` are static — unless the
    energy was built with ``runtime_smoothing=True``: then ``choice`` (an int32 leaf, the
    index in ``smoothings.NAMES``) selects the smoothing by ``lax.switch`` and
    ``with_params(smoothing=...)`` changes it without recompiling (all ten smoothings of
    a comparison share one compiled solver; ``smoothing`` is then ``"runtime"``).

    ``X`` may be ``(n, k)`` or a column ``(n,)``; ``F(X) == Σ_j F(X[:, j])``.
    """

    W: LinearOperator
    weights: Float[Array, " n"]
    mu: Float[Array, ""]
    eps: Float[Array, ""]
    delta: Float[Array, ""]
    smoothing: str = eqx.field(static=True, default="f3")
    weighting: str = eqx.field(static=True, default="area")
    choice: Int[Array, ""] | None = None

    @property
    def smoothing_name(self) -> str:
        """The canonical name of the smoothing in use (read from ``choice`` when it is a runtime value)."""
        if self.choice is None:
            return self.smoothing
        return _smoothings.NAMES[int(self.choice)]

    def _s(self, X):
        if self.choice is None:
            return _smoothings.info(self.smoothing).fn(X, self.eps, self.delta)
        branches = [_smoothings.info(name).fn for name in _smoothings.NAMES]
        return jax.lax.switch(self.choice, branches, X, self.eps, self.delta)

    def dirichlet(self, X: Float[Array, "n *k"]) -> Float[Array, ""]:
        """``tr(XᵀWX)`` (gradient ``2WX`` by ``stiefel.linalg.operators.quadratic_form``'s rule)."""
        return quadratic_form(self.W, X)

    def l1(self, X: Float[Array, "n *k"], smooth: bool = True) -> Float[Array, ""]:
        """``Σ_ij w_i s(X_ij)`` (without μ); ``smooth=False`` uses ``|·|``."""
        vals = self._s(X) if smooth else _smoothings.f0(X)
        return jnp.sum(_rows(self.weights, X) * vals)

    def __call__(self, X: Float[Array, "n *k"]) -> Float[Array, ""]:
        """The smoothed energy ``F(X)``, a scalar."""
        return self.dirichlet(X) + self.mu * self.l1(X)

    def parts(self, X: Float[Array, "n *k"], smooth: bool = True) -> tuple[Float[Array, ""], Float[Array, ""]]:
        """``(tr(XᵀWX), μ Σ w_i s(X_ij))``, summing to ``F(X)`` (``smooth=False``: to ``true_value``)."""
        return self.dirichlet(X), self.mu * self.l1(X, smooth)

    def true_value(self, X: Float[Array, "n *k"]) -> Float[Array, ""]:
        """The unsmoothed CMM objective ``tr(XᵀWX) + μ Σ w_i |X_ij|`` (f0), for reporting."""
        d, l = self.parts(X, smooth=False)
        return d + l

    def line(self, manifold, X: Float[Array, "n k"], eta: Float[Array, "n k"]):
        """``φ(τ) = (F(R_X(τη)), dF(R_X(τη))/dτ)`` for the block solver's line search, or None.

        For the Cholesky retraction ``R_X(τη) = Y L⁻ᵀ`` (``Y = X + τη``, ``LLᵀ = YᵀMY``) the
        Gram matrices are quadratics in τ, ``YᵀMY = G₀ + τ(C + Cᵀ) + τ²S`` and
        ``YᵀWY = Q₀ + τ(B + Bᵀ) + τ²T``, so after one product with M and W (here, once per
        line search) each trial costs ``k×k`` algebra for the Dirichlet part plus one
        ``n×k×k`` product and the smoothing for the ℓ1 part — instead of a retraction and
        a sparse product per trial. Same value as ``F(manifold.retract(X, τη))`` up to
        rounding. Other retractions: None (the solver differentiates ``F ∘ R`` itself).
        """
        if getattr(manifold, "retraction_name", None) != "cholesky" or X.ndim != 2:
            return None
        U = jnp.concatenate([X, eta], axis=1)
        k = X.shape[1]
        # all six k×k Gram blocks from one (2k × 4k) product (one GEMM instead of six skinny ones)
        Gr = U.T @ jnp.concatenate([manifold.op.mv(U), self.W.mv(U)], axis=1)
        G0, C, S = Gr[:k, :k], Gr[:k, k:2 * k], Gr[k:, k:2 * k]
        Q0, B, T = Gr[:k, 2 * k:3 * k], Gr[:k, 3 * k:], Gr[k:, 3 * k:]
        eye = jnp.eye(k, dtype=X.dtype)

        def h(t):
            G = G0 + t * (C + C.T) + (t * t) * S
            L = jnp.linalg.cholesky(0.5 * (G + G.T))
            Linv = jsl.solve_triangular(L, eye, lower=True)
            Q = Q0 + t * (B + B.T) + (t * t) * T
            R = (X + t * eta) @ Linv.T
            return jnp.sum(Linv * (Linv @ Q)) + self.mu * self.l1(R)

        return lambda t: jax.jvp(h, (t,), (jnp.ones_like(t),))

    def compressed_eigenvalues(self, Psi: Float[Array, "n *k"]) -> Float[Array, "*k"]:
        """Def. 3.2.15 per column with this energy's W, weights and μ."""
        return _compressed_eigenvalues(self.W, self.weights, Psi, self.mu)

    def with_params(self, *, mu=None, eps=None, delta=None, smoothing: str | None = None) -> "CMMEnergy":
        """A copy with new ``mu``/``eps``/``delta`` (same pytree structure, no recompilation) and, for an
        energy built with ``runtime_smoothing=True``, a new ``smoothing`` (a name or alias)."""
        out = self
        if smoothing is not None:
            name = _smoothings.info(smoothing).name
            if self.choice is None:
                if name != self.smoothing:
                    raise ValueError("this energy's smoothing is static (a compile-time constant); build it with "
                                     "cmm_energy(..., runtime_smoothing=True) to change it by with_params")
            else:
                out = eqx.tree_at(lambda e: e.choice, out, host_array(_smoothings.NAMES.index(name), np.int32))
        for name, value in (("mu", mu), ("eps", eps), ("delta", delta)):
            if value is not None:
                old = getattr(out, name)
                out = eqx.tree_at(lambda e, n=name: getattr(e, n), out, host_array(value, old.dtype))
        return out


def cmm_energy(
    W,
    area_diag: Float[ArrayLike, " n"],
    mu: float,
    *,
    smoothing: str = "f3",
    eps: float = 1e-3,
    delta: float = 1e-3,
    weighting: Weighting = "area",
    runtime_smoothing: bool = False,
) -> CMMEnergy:
    """Build the smoothed CMM energy ``tr(XᵀWX) + μ Σ_ij w_i s(X_ij)`` (docs/maths.md §4).

    Args:
      W: ``(n, n)`` weight matrix (operator with ``.mv``, ``scipy.sparse`` or dense).
      area_diag: ``(n,)`` diagonal of the lumped mass matrix A (or a ``DiagonalOperator``).
      mu: sparsity parameter μ ≥ 0.
      smoothing: Table 6.1 name or alias (default ``"f3"``).
      eps, delta: smoothing parameters (thesis default 1e-3).
      weighting: ``"area"`` (``w_i = A_ii``, the thesis) or ``"uniform"`` (``w_i = 1/n``).
      runtime_smoothing: the smoothing as a runtime index (``CMMEnergy.choice``, a ``lax.switch`` over the
        ten): one compiled solver serves every smoothing (``with_params(smoothing=...)``).
    """
    op = _as_matvec(W)
    w = l1_weights(area_diag, weighting)
    canonical = _smoothings.info(smoothing).name  # validates the name
    _smoothings.get(canonical, eps, delta)  # validates eps, delta
    dtype = w.dtype
    return CMMEnergy(
        W=op,
        weights=w,
        mu=host_array(mu, dtype),
        eps=host_array(eps, dtype),
        delta=host_array(delta, dtype),
        smoothing="runtime" if runtime_smoothing else canonical,
        weighting=weighting,
        choice=host_array(_smoothings.NAMES.index(canonical), np.int32) if runtime_smoothing else None,
    )


def _compressed_eigenvalues(op, w, Psi, mu):
    return jnp.sum(Psi * op.mv(Psi), axis=0) + 0.5 * mu * jnp.sum(_rows(w, Psi) * jnp.abs(Psi), axis=0)


def compressed_eigenvalues(
    W,
    area_diag: Float[ArrayLike, " n"],
    Psi: Float[Array, "n *k"],
    mu: float,
    weighting: Weighting = "area",
) -> Float[Array, "*k"]:
    """Compressed eigenvalues (thesis Def. 3.2.15), one per column of ``Psi``:

        ``λ_j = ψ_jᵀ W ψ_j + (μ/2) Σ_i w_i |Ψ_ij|``

    with ``w_i = A_ii`` (``"area"``: ``(μ/2)‖Aψ_j‖₁``) or ``1/n`` (``"uniform"``).
    ``Psi: (n, k)`` → ``(k,)``; ``(n,)`` → scalar.
    """
    return _compressed_eigenvalues(_as_matvec(W), l1_weights(area_diag, weighting), jnp.asarray(Psi), mu)


def order_by_compressed_eigenvalue(
    W,
    area_diag: Float[ArrayLike, " n"],
    Psi: Float[Array, "n k"],
    mu: float,
    weighting: Weighting = "area",
) -> Int[Array, " k"]:
    """Permutation ``p`` with ``λ[p]`` ascending (thesis Rem. 3.2.16): report ``Psi[:, p]``.

    Stable, so equal eigenvalues keep their order.
    """
    lam = compressed_eigenvalues(W, area_diag, Psi, mu, weighting)
    return jnp.argsort(lam, stable=True)
