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
import numpy as np
import scipy.sparse as sp
from jax.experimental import sparse as jsparse
from jaxtyping import Array, Float

import stiefel
from stiefel.manifolds.signs import canonical_signs
from stiefel.errors import NotSPDError, ShapeError
from stiefel.validation import (check_count, check_finite, checked_entries, checked_finite, checked_number,
                                known_value)

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


def _operator_size(op) -> int | None:
    try:
        return int(op.shape[0]) if hasattr(op, "shape") else int(op.n)
    except (AttributeError, NotImplementedError, TypeError, ValueError):  # no size known: mv's products will tell
        return None


def _checked_operator(op):
    """``op`` with its floating-point arrays checked finite (``NonFiniteError`` naming ``W``, for a ``BCOO``
    the first bad entry's (row, column); traced: when the program runs)."""
    if isinstance(op, BCOOOperator):
        data, idx = known_value(op.data), known_value(op.indices)
        if data is not None and idx is not None:
            check_finite("W", sp.coo_array((data, (idx[:, 0], idx[:, 1])), shape=op.shape))
            return op
        return eqx.tree_at(lambda o: o.data, op, checked_finite("W", op.data))
    leaves, treedef = jax.tree_util.tree_flatten_with_path(op)
    leaves = [checked_finite(f"W (its {jax.tree_util.keystr(path).lstrip('.')})", leaf)
              if eqx.is_inexact_array(leaf) else leaf for path, leaf in leaves]
    return jax.tree_util.tree_unflatten(treedef, leaves)


def _checked_inputs(op, area, X0, weights, weighting):
    """``(op, area, X0, w)`` checked where they enter ``cmm_solve``, shapes first: ``area (n,)``, ``W (n, n)``,
    ``X0 (n, k)``, ``weights (n,)`` (``ShapeError`` naming the argument, its shape and the expected one); then values:
    ``W``, ``area``, ``weights``, ``X0`` finite (``NonFiniteError``; W first, as its first bad row is near a bad
    vertex while a normalised area is NaN everywhere), ``area > 0``, ``w ≥ 0``. Returned checked: use them."""
    area = jnp.asarray(area)
    if area.ndim != 1 or not (jnp.issubdtype(area.dtype, jnp.floating) or jnp.issubdtype(area.dtype, jnp.integer)):
        raise ShapeError(f"area must be a real vector (n,), the lumped mass diagonal, got shape {area.shape} "
                         f"and dtype {area.dtype}")
    if jnp.issubdtype(area.dtype, jnp.integer):
        area = area.astype(jnp.result_type(float))
    n = area.shape[0]
    size = _operator_size(op)
    if size is not None and size != n:
        raise ShapeError(f"W must be (n, n) = ({n}, {n}) with n = {n} the size of area, got ({size}, {size})")
    shape = tuple(np.shape(X0))
    if len(shape) != 2 or shape[0] != n or not 1 <= shape[1] <= n:
        raise ShapeError(f"X0 must have shape (n, k) = ({n}, k) with 1 ≤ k ≤ {n} (n = {n}: the size of area), "
                         f"got {shape}")
    w = None if weights is None else jnp.asarray(weights, dtype=area.dtype)
    if w is not None and w.shape != area.shape:
        raise ShapeError(f"weights must have shape (n,) = {area.shape} (one per vertex, as area), got {w.shape}")
    op = _checked_operator(op)
    area = checked_entries("area", checked_finite("area", area), low=0, low_open=True,
                           what=" (the lumped mass diagonal A of ΨᵀAΨ = I)", error=NotSPDError)
    if w is None:
        w = l1_weights(area, weighting)
    else:
        w = checked_entries("weights", checked_finite("weights", w), low=0, what=" (per-vertex ℓ1 weights)")
    X0 = checked_finite("X0", jnp.asarray(X0, dtype=area.dtype))
    return op, area, X0, w


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

    Raises (where the input enters, naming it): ``ShapeError`` (``X0`` not ``(n, k)``, ``weights`` not ``(n,)``,
    ``W`` not ``(n, n)``, with ``n`` the size of ``area``); ``NonFiniteError`` (a NaN/inf in ``area``, ``W``,
    ``weights`` or ``X0``, e.g. from a NaN vertex upstream, with the first bad entry's index);
    ``NotSPDError`` (``area ≤ 0``); ``ParameterError`` (``mu``, ``eps``, ``delta``, ``stages``, ``gtol``,
    ``weights`` out of range). Values known on the host — concrete, or the primal under ``jax.grad`` — are
    checked before anything is compiled; traced ones (under ``jit``/``vmap``) when the program runs, as an
    ``EquinoxRuntimeError`` with the same naming (``stiefel.validation.checked_number`` and friends).
    """
    _smoothings.info(smoothing)  # validates the name
    max_iters = check_count("max_iters", max_iters)
    # every input is checked where it enters: now when its value is known (concrete, or the primal under
    # jax.grad), when the program runs when it is traced (eqx.error_if; stiefel.validation.checked_*)
    gtol = checked_number("gtol", gtol, low=0)
    mu = checked_number("mu", mu, low=0)
    eps = checked_number("eps", eps, low=0, low_open=True)
    if delta is not None:
        delta = checked_number("delta", delta, low=0, low_open=True)
    stages = [checked_number(f"stages[{i}]", width, low=0, low_open=True) for i, width in enumerate(stages)]
    op = _operator(W)
    op, area, X0, w = _checked_inputs(op, area, X0, weights, weighting)
    k = X0.shape[1]
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
