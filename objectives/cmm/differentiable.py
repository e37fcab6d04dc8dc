"""Differentiable compressed manifold modes: a CMM solve inside a larger JAX program.

``cmm_solve(W, area, X0, mu, ...)`` minimises the smoothed CMM energy (docs/maths.md §4)

    ``F(Ψ) = tr(ΨᵀWΨ) + μ Σ_ij w_i s_ε,δ(Ψ_ij)``  over  ``ΨᵀAΨ = I``

with ``stiefel.minimize`` and returns the modes as a JAX array whose derivatives with respect
to μ, ε/δ, the per-vertex ℓ1 weights ``w``, the values of W and the mass diagonal ``area`` come
from the implicit function theorem (``stiefel.RiemannianImplicitAdjoint``, docs/maths.md §9) — no
iteration is unrolled. Everything may be traced: call it inside ``jax.grad``/``jax.jvp``.

Derivatives are those of the *smoothed* problem at a point where its Riemannian gradient
vanishes: solve the last stage to a tight ``gtol`` (no stall stop), with a smoothing width the
derivative is meant for (as δ → 0 the Hessian's curvature μw/δ on near-zero entries grows and
the modes' support becomes non-differentiable). The continuation stages before the last only
provide the start (their outputs carry no derivative: ``stop_gradient``). A last stage that does
not converge raises when a derivative is taken (``throw=True``) or gives NaN derivatives.
"""

from __future__ import annotations

from typing import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
from jax.experimental import sparse as jsparse
from jaxtyping import Array, Float

import stiefel
from stiefel.manifolds.signs import canonical_signs
from stiefel.validation import check_count, check_nonnegative, check_positive

from ..energy.energies import CMMEnergy, l1_weights
from ..energy import smoothings as _smoothings

__all__ = ["cmm_solve", "BCOOOperator"]


class BCOOOperator(stiefel.LinearOperator):
    """A ``jax.experimental.sparse.BCOO`` matrix (e.g. from ``mesh.laplacian_jax``) as an operator
    with ``mv`` (products only; differentiable in its values). Stored as its arrays, so that it is
    an ordinary pytree (JAX treats a BCOO as one opaque leaf in some transformations)."""

    data: Float[Array, " nse"]
    indices: Array
    shape: tuple = eqx.field(static=True)

    def __init__(self, matrix: jsparse.BCOO):
        self.data, self.indices, self.shape = matrix.data, matrix.indices, tuple(matrix.shape)

    @property
    def n(self) -> int:
        return self.shape[0]

    def mv(self, x):
        return jsparse.BCOO((self.data, self.indices), shape=self.shape) @ x

    def diagonal(self):
        on = self.indices[:, 0] == self.indices[:, 1]
        return jnp.zeros(self.n, self.data.dtype).at[self.indices[:, 0]].add(jnp.where(on, self.data, 0.0))


def _operator(W):
    if isinstance(W, jsparse.BCOO):
        return BCOOOperator(W)
    if hasattr(W, "mv"):
        return W
    raise TypeError("W must be an operator with .mv (stiefel.SparseOperator, mesh.weight_operator_jax(V, F)) "
                    f"or a jax.experimental.sparse.BCOO matrix (mesh.laplacian_jax), got {type(W).__name__}")


def cmm_solve(
    W,
    area: Float[Array, " n"],
    X0: Float[Array, "n k"],
    mu,
    *,
    weights: Float[Array, " n"] | None = None,
    weighting: str = "area",
    smoothing: str = "f6",
    eps=0.5,
    delta=None,
    stages: Sequence[float] = (),
    preconditioner: Callable | None = None,
    method: str = "lbfgs",
    gtol: float = 1e-9,
    max_iters: int = 3000,
    throw: bool = True,
) -> tuple[Float[Array, "n k"], stiefel.Result]:
    """Smoothed CMMs as a differentiable function (module docstring).

    Args:
      W: ``(n, n)`` stiffness: an operator with ``.mv`` or a ``BCOO`` (``mesh.laplacian_jax``).
      area: ``(n,)`` lumped mass diagonal A (the constraint ``ΨᵀAΨ = I``); may be traced.
      X0: ``(n, k)`` start (e.g. ``objectives.cmm.modes.first_eigenpairs`` at the current values); it is
        projected onto the manifold and carries no derivative.
      mu: μ ≥ 0; weights: ``(n,)`` per-vertex ℓ1 weights (default: ``weighting``'s, ``A_ii`` or
        ``1/n``); smoothing, eps, delta: the Table 6.1 smoothing and its parameters (delta
        defaults to eps); all may be traced. The default width 0.5 suits area-normalised meshes
        (entries of Ψ of order √n): on hand_868 (k = 3, μ = 0.05n) the gradient norm reaches
        1e-8 in 39 L-BFGS iterations at ε = 0.5, but stalls near 1e-6 at ε = 0.05 (rounding at
        the Huber kinks), where derivatives are not to be trusted.
      stages: widths before the last stage (multiples of ``eps``/``delta``, e.g. ``(10.0, 3.0)``),
        solved warm-started, without derivatives.
      preconditioner: ``Y ↦ PY`` (e.g. ``stiefel.shifted_inverse(W₀, A₀, σ).solve`` built from the
        current concrete matrices: a preconditioner need not follow θ); also used by the adjoint.
      method, gtol: the block solver's (``stiefel.minimize``), per stage; max_iters: the total number of
        iterations of the call, shared by the stages in turn (each gets what the earlier ones left, a
        runtime budget: one compilation; a last stage left with none ends with status ``max_iters``, and
        with ``throw`` a derivative through it raises).
      throw: raise on a failed solve / on a derivative through a non-converged last stage.

    Returns:
      ``(Ψ, result)``: the modes ``(n, k)`` (unsorted; differentiable; each column's largest-magnitude
      entry positive, ``stiefel.manifolds.signs``) and the last stage's ``stiefel.Result``.
    """
    _smoothings.info(smoothing)  # validates the name
    max_iters = check_count("max_iters", max_iters)
    check_nonnegative("gtol", gtol)
    check_nonnegative("mu", mu)  # these three only when concrete (they may be traced)
    check_positive("eps", eps)
    if delta is not None:
        check_positive("delta", delta)
    for i, width in enumerate(stages):
        check_positive(f"stages[{i}]", width)
    op = _operator(W)
    area = jnp.asarray(area)
    k = X0.shape[1]
    w = l1_weights(area, weighting) if weights is None else jnp.asarray(weights, dtype=area.dtype)
    if w.shape != area.shape:
        raise ValueError(f"weights must have shape {area.shape}, got {w.shape}")
    eps = jnp.asarray(eps, dtype=area.dtype)
    delta = eps if delta is None else jnp.asarray(delta, dtype=area.dtype)
    S = stiefel.GeneralizedStiefel(area, k, retraction="cholesky")
    energy = CMMEnergy(W=op, weights=w, mu=jnp.asarray(mu, dtype=area.dtype), eps=eps, delta=delta,
                       smoothing=_smoothings.info(smoothing).name, weighting=weighting)
    X = jax.lax.stop_gradient(S.project_to_manifold(jnp.asarray(X0, dtype=area.dtype)))
    frozen = jax.lax.stop_gradient(energy)
    used = jnp.zeros((), jnp.int32)  # iterations of the earlier stages (a runtime value)
    for width in stages:
        F = eqx.tree_at(lambda e: (e.eps, e.delta), frozen, (frozen.eps * width, frozen.delta * width))
        res = stiefel.minimize(F, jax.lax.stop_gradient(S), X, method=method, gtol=gtol, ftol=1e-6, ftol_window=5,
                               max_iters=max_iters, budget=max_iters - used, preconditioner=preconditioner,
                               check=False, throw=throw)
        X = jax.lax.stop_gradient(res.x)
        used = used + jax.lax.stop_gradient(res.iterations).astype(jnp.int32)
    res = stiefel.minimize(energy, S, X, method=method, gtol=gtol, max_iters=max_iters,
                           budget=max_iters - used if stages else None, preconditioner=preconditioner, check=False,
                           throw=throw)
    return canonical_signs(res.x), res  # the sign convention (stiefel.manifolds.signs); res.x keeps the solver's signs
