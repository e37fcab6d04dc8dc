"""Negative curvature on ``S_M = {XᵀMX = I}``: detect a saddle and step off it (docs/maths.md §9).

First-order solvers stop wherever the gradient (or the objective's decrease) is small, including
at saddle points and on the plateaus around them. A saddle is told from a minimum by the smallest
eigenvalue of the Riemannian Hessian ``Hess F(X)`` (``stiefel.derivatives.hessian``), self-adjoint in the metric
``⟨ξ, η⟩ = tr(ξᵀMη)`` on the tangent space:

    ``θ = min_{ξ ∈ T_X, ξ ≠ 0} ⟨ξ, Hess F(X)[ξ]⟩ / ⟨ξ, ξ⟩``.

``negative_curvature`` estimates θ and its direction by a single-vector LOBPCG (Knyazev 2001): the
Rayleigh–Ritz problem on ``span{x, w, p}`` each step, ``w = P_X(P·M r)`` the residual
``r = Hess[x] − θx`` preconditioned by an SPD ``P ≈ (∇²F)⁻¹`` (e.g. the solvers' ``(W + σM)⁻¹``), ``p``
the previous update. One Hessian-vector product per step. A direction with θ < 0 is all an escape
needs, so a few tens of steps suffice even where the estimate is far from converged.

``escape_step`` moves along that direction ``d`` (unit in the metric, signed so ``⟨grad, d⟩ ≤ 0``) by
the largest ``t = t₀ 2⁻ʲ`` whose decrease is at least half the second-order model's,

    ``F(R_X(t d)) ≤ F(X) + ½ (t ⟨grad, d⟩ + ½ θ t²)``        (Conn, Gould & Toint's curvilinear test).

Both are pure and jittable. ``row_mask`` keeps rows at zero (e.g. the zero padding of a bucketed
problem, where the Hessian is ``−ξ sym(XᵀG)`` and would report curvature of rows that do not exist).
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ..derivatives.hessian import _euclidean
from ..manifolds.manifold import GeneralizedStiefel
from .preconditioning import as_preconditioner

__all__ = ["Curvature", "negative_curvature", "escape_step", "EscapeStep"]

#: alternating projections (mask, then tangent) per application: the masked search space meets T_X at a
#: wide angle when X is small off the mask, so a few suffice; the last is the tangent projection
PROJECTIONS = 3


class Curvature(NamedTuple):
    """Result of ``negative_curvature``.

    value: the Rayleigh quotient θ of ``direction`` (an upper bound of the smallest eigenvalue of the
      Riemannian Hessian on the tangent space); direction: ``(n, k)`` tangent, unit in the metric;
    residual: ``‖Hess[d] − θd‖ / max(|θ|, tiny)`` (metric norm); iterations: LOBPCG steps (= Hessian
    products beyond the first).
    """

    value: Float[Array, ""]
    direction: Float[Array, "n k"]
    residual: Float[Array, ""]
    iterations: Int[Array, ""]


class EscapeStep(NamedTuple):
    """Result of ``escape_step``: ``X`` (the new point, or the old one when no step was accepted),
    ``value`` (F there), ``start_value`` (F at the old point), ``step`` (t, 0 when none), ``accepted``,
    ``trials`` (objective evaluations)."""

    X: Float[Array, "n k"]
    value: Float[Array, ""]
    start_value: Float[Array, ""]
    step: Float[Array, ""]
    accepted: jax.Array
    trials: Int[Array, ""]


def _rayleigh_ritz(U, HU, inner):
    """The smallest Ritz pair of ``span(U)`` (3 vectors, possibly dependent): ``(θ, coefficients)``.

    The Gram matrix is whitened by its eigendecomposition; directions with eigenvalue below 1e-10 of the
    largest are dropped (their reduced diagonal is set to +∞ so they are never chosen)."""
    m = len(U)
    B = jnp.array([[inner(U[i], U[j]) for j in range(m)] for i in range(m)])
    A = jnp.array([[inner(U[i], HU[j]) for j in range(m)] for i in range(m)])
    A = 0.5 * (A + A.T)
    d, V = jnp.linalg.eigh(0.5 * (B + B.T))
    keep = d > 1e-10 * jnp.max(d)
    C = V / jnp.sqrt(jnp.where(keep, d, 1.0))
    R = C.T @ A @ C
    big = jnp.max(jnp.abs(R)) * 10.0 + 1.0
    R = jnp.where(keep[:, None] & keep[None, :], R, 0.0) + jnp.diag(jnp.where(keep, 0.0, big))
    theta, Z = jnp.linalg.eigh(R)
    return theta[0], C @ Z[:, 0]


def negative_curvature(fn: Callable, manifold: GeneralizedStiefel, X: Float[Array, "n k"], *, args: Any = None,
                       preconditioner=None, mask: Float[Array, "n k"] | None = None, max_iters: int = 40,
                       rtol: float = 1e-2, key: jax.Array | None = None) -> Curvature:
    """The smallest curvature of ``fn`` at ``X`` and its direction (module docstring), by LOBPCG.

    Args:
      fn: ``F(X)`` or ``F(X, args)`` → scalar (twice differentiable); X: ``(n, k)`` on the manifold.
      preconditioner: None, a callable ``Y ↦ P Y`` (SPD) or a matrix K whose inverse is applied
        (``stiefel.as_preconditioner``); it preconditions ``M r``.
      row_mask: optional ``(n,)`` 0/1: directions are confined to the rows marked 1.
      max_iters: LOBPCG steps (one Hessian product each; a static bound); rtol: stop once the residual is
        below ``rtol·|θ|``.
      key: PRNG key of the random start (default ``PRNGKey(0)``).

    Returns:
      ``Curvature(value, direction, residual, iterations)``; θ < 0 proves a saddle (or a maximum).
    """
    apply_P = as_preconditioner(preconditioner)
    G, hvp = jax.linearize(jax.grad(_euclidean(fn, args)), X)
    if mask is not None:
        mask = jnp.asarray(mask, X.dtype)
        mask = mask[:, None] if mask.ndim == 1 else mask

    def tangent(Z):  # alternating projections onto {masked} ∩ T_X, ending exactly tangent
        if mask is None:
            return manifold.proj(X, Z)
        for _ in range(PROJECTIONS):
            Z = manifold.proj(X, Z * mask)
        return Z

    def full_hess(Z):
        return manifold.ehess_to_rhess(X, G, hvp(Z), Z)

    def hess(Z):  # re-projected: keeps the iterates' round-off drift out of the normal space
        return tangent(full_hess(Z))

    def inner(Z1, Z2):
        return manifold.inner(X, Z1, Z2)

    def unit(Z, HZ):
        s = 1.0 / jnp.sqrt(jnp.maximum(inner(Z, Z), jnp.finfo(X.dtype).tiny))
        return Z * s, HZ * s

    key = jax.random.PRNGKey(0) if key is None else key
    x0 = tangent(jax.random.normal(key, X.shape, X.dtype))
    x, Hx = unit(x0, hess(x0))
    theta0 = inner(x, Hx)
    tiny = jnp.finfo(X.dtype).eps

    def residual(x, Hx, theta):
        r = Hx - theta * x
        return r, jnp.sqrt(jnp.maximum(inner(r, r), 0.0)) / jnp.maximum(jnp.abs(theta), tiny)

    def cond(c):
        it, x, Hx, p, Hp, theta, res = c
        return (it < max_iters) & (res > rtol)

    def body(c):
        it, x, Hx, p, Hp, theta, _ = c
        r, _ = residual(x, Hx, theta)
        w = r if apply_P is None else tangent(apply_P(manifold.op.mv(r)))
        w, Hw = unit(w, hess(w))
        theta_n, y = _rayleigh_ritz((x, w, p), (Hx, Hw, Hp), inner)
        p_new, Hp_new = y[1] * w + y[2] * p, y[1] * Hw + y[2] * Hp
        x_new, Hx_new = unit(y[0] * x + p_new, y[0] * Hx + Hp_new)
        p_new, Hp_new = unit(p_new, Hp_new)
        theta_n = inner(x_new, Hx_new)
        _, res = residual(x_new, Hx_new, theta_n)
        return it + 1, x_new, Hx_new, p_new, Hp_new, theta_n, res

    zero = jnp.zeros_like(X)
    _, res0 = residual(x, Hx, theta0)
    it, x, _, _, _, _, _ = jax.lax.while_loop(cond, body, (jnp.asarray(0), x, Hx, zero, zero, theta0, res0))
    d, Hd = unit(x, full_hess(x))  # the true Rayleigh quotient and residual of the (tangent) direction
    theta = inner(d, Hd)
    _, res = residual(d, Hd, theta)
    # a strongly typed count: a stored program's outputs lose JAX's weak types, and a weak one here would make the
    # escape step's program key differ between a process that compiled this and one that loaded it
    return Curvature(value=theta, direction=d, residual=res, iterations=jnp.asarray(it, it.dtype))


def escape_step(fn: Callable, manifold: GeneralizedStiefel, X: Float[Array, "n k"], curvature: Curvature, *,
                args: Any = None, initial_step: float = 1.0, max_halvings: int = 30) -> EscapeStep:
    """A step off a saddle along ``curvature.direction`` (module docstring): the largest
    ``t = initial_step·2⁻ʲ`` (``j ≤ max_halvings``) with at least half the decrease of the model
    ``t⟨grad, d⟩ + ½θt²``; none (``accepted`` False, ``X`` unchanged) when θ ≥ 0 or no t qualifies.
    ``initial_step`` is measured in the metric (a unit tangent of an A-orthonormal basis moves about one column)."""
    f = _euclidean(fn, args)
    f0, G = jax.value_and_grad(f)(X)
    d = curvature.direction
    slope = jnp.sum(G * d)  # ⟨grad, d⟩ = tr(Gᵀd) for tangent d
    d = jnp.where(slope > 0, -d, d)
    slope = -jnp.abs(slope)
    theta = curvature.value

    def trial(t):
        Xt = manifold.retract(X, t * d)
        return Xt, f(Xt)

    def cond(c):
        j, t, _, ft, ok = c
        return (~ok) & (j <= max_halvings) & (theta < 0)

    def body(c):
        j, t, _, _, _ = c
        Xt, ft = trial(t)
        ok = jnp.isfinite(ft) & (ft <= f0 + 0.5 * (t * slope + 0.5 * theta * t * t))
        return j + 1, jnp.where(ok, t, 0.5 * t), Xt, ft, ok

    init = (jnp.asarray(0), jnp.asarray(initial_step, X.dtype), X, f0, jnp.asarray(False))
    j, t, Xt, ft, ok = jax.lax.while_loop(cond, body, init)
    return EscapeStep(X=jnp.where(ok, Xt, X), value=jnp.where(ok, ft, f0), start_value=f0,
                      step=jnp.where(ok, t, 0.0), accepted=ok, trials=j)
