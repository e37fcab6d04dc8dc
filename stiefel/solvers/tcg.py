"""Truncated conjugate gradients for the trust-region subproblem (Steihaug–Toint; Absil, Baker,
Gallivan 2007, Alg. 2), preconditioned, on ``T_X S_M`` with the M-weighted metric ``⟨a, b⟩ = tr(aᵀMb)``.

Approximately solves

    ``min_η  m(η) = ⟨g, η⟩ + ½⟨η, Hess[η]⟩``   subject to   ``‖η‖_P ≤ Δ``,   ``‖η‖_P² = ⟨η, P⁻¹η⟩``,

for tangent ``η``, where ``P`` is the preconditioner (SPD on ``T_X`` in ``⟨·,·⟩``; the identity when
None). Stops at negative curvature or the boundary (both then land on the boundary, ``limited``), when
the residual has dropped to ``‖r0‖·min(‖r0‖^θ, κ)`` (θ = 1 gives the outer method local quadratic
convergence), after ``max_inner`` iterations, or when ``⟨Pr, r⟩ ≤ 0`` for ``r ≠ 0`` (the preconditioner
is not positive definite there). The norms ``⟨η, P⁻¹η⟩`` are kept by recurrences: P⁻¹ is never applied.
Tangent vectors may be arrays or tuples of arrays (a ``stiefel.Product``; ``stiefel.manifolds.tangent_algebra``).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float, Int

from ..manifolds import tangent_algebra as ta

__all__ = ["TCGStop", "TCGResult", "truncated_cg"]


class TCGStop:
    """Why the inner solve stopped (``TCGResult.stop``)."""

    RUNNING = 0
    NEGATIVE_CURVATURE = 1  #: ⟨δ, Hess δ⟩ ≤ 0: went to the boundary along δ
    EXCEEDED_RADIUS = 2  #: the next iterate would leave the trust region: stopped on its boundary
    CONVERGED = 3  #: residual ≤ ‖r0‖ min(‖r0‖^θ, κ)
    MAX_INNER = 4  #: ran out of inner iterations
    INDEFINITE_PRECONDITIONER = 5  #: ⟨Pr, r⟩ ≤ 0 for a residual r ≠ 0

    names = ("running", "negative_curvature", "exceeded_radius", "converged", "max_inner",
             "indefinite_preconditioner")


class TCGResult(NamedTuple):
    eta: Float[Array, "n k"]  # the step
    Heta: Float[Array, "n k"]  # Hess[η] (by the recurrence, no extra product)
    n_inner: Int[Array, ""]  # inner iterations = Hessian-vector products
    stop: Int[Array, ""]  # TCGStop code
    limited: jax.Array  # the step lies on the trust-region boundary


class _Loop(NamedTuple):
    j: jax.Array
    eta: jax.Array
    Heta: jax.Array
    r: jax.Array
    delta: jax.Array
    e_Pe: jax.Array  # ‖η‖_P²
    e_Pd: jax.Array  # ⟨η, P⁻¹δ⟩
    d_Pd: jax.Array  # ‖δ‖_P²
    z_r: jax.Array  # ⟨Pr, r⟩
    stop: jax.Array


def truncated_cg(hess: Callable, precondition: Callable | None, inner: Callable, proj: Callable,
                 grad: Float[Array, "n k"], radius, *, max_inner, kappa, theta, min_inner: int = 1) -> TCGResult:
    """Steihaug–Toint CG on the trust-region model (module docstring).

    Args:
      hess: tangent ``δ ↦ Hess F(X)[δ]`` (self-adjoint in ``inner``).
      precondition: tangent ``r ↦ Pr`` (SPD in ``inner``) or None.
      inner: ``(a, b) ↦ ⟨a, b⟩`` on ``T_X``; proj: ambient ``↦`` tangent (re-applied to residuals and
        directions against drift).
      grad: the Riemannian gradient ``g`` (tangent, ``(n, k)``, or a tuple of them).
      radius: ``Δ > 0``; max_inner: iteration bound (runtime); kappa, theta: the residual target.
    """
    P = precondition if precondition is not None else (lambda r: r)
    dt = ta.dtype_of(grad)
    zero = ta.zeros_like(grad)
    z0 = P(grad)
    z_r0 = inner(z0, grad)
    norm_r0 = jnp.sqrt(jnp.maximum(inner(grad, grad), 0.0))
    target = norm_r0 * jnp.minimum(norm_r0 ** theta, kappa)
    bad0 = (norm_r0 > 0) & ~(z_r0 > 0)
    stop0 = jnp.where(bad0, TCGStop.INDEFINITE_PRECONDITIONER,
                      jnp.where(norm_r0 == 0, TCGStop.CONVERGED, TCGStop.RUNNING))
    start = _Loop(jnp.zeros((), jnp.int32), zero, zero, grad, ta.tmap(jnp.negative, z0), jnp.zeros((), dt),
                  jnp.zeros((), dt),
                  z_r0, z_r0, jnp.asarray(stop0, jnp.int32))

    def body(c: _Loop) -> _Loop:
        Hd = hess(c.delta)
        d_Hd = inner(c.delta, Hd)
        alpha = c.z_r / d_Hd
        e_Pe_new = c.e_Pe + 2.0 * alpha * c.e_Pd + alpha ** 2 * c.d_Pd
        to_boundary = ~(d_Hd > 0) | (e_Pe_new >= radius ** 2)
        # τ ≥ 0 with ‖η + τδ‖_P = Δ
        disc = jnp.maximum(c.e_Pd ** 2 + c.d_Pd * (radius ** 2 - c.e_Pe), 0.0)
        tau = (-c.e_Pd + jnp.sqrt(disc)) / c.d_Pd
        t = jnp.where(to_boundary, tau, alpha)
        eta, Heta = ta.tmap(lambda e, d: e + t * d, c.eta, c.delta), ta.tmap(lambda e, d: e + t * d, c.Heta, Hd)
        j = c.j + 1
        r = proj(ta.tmap(lambda r, d: r + alpha * d, c.r, Hd))
        norm_r = jnp.sqrt(jnp.maximum(inner(r, r), 0.0))
        z = P(r)
        z_r = inner(z, r)
        beta = z_r / c.z_r
        delta = proj(ta.tmap(lambda z, d: -z + beta * d, z, c.delta))
        stop = jnp.where(
            to_boundary, jnp.where(d_Hd > 0, TCGStop.EXCEEDED_RADIUS, TCGStop.NEGATIVE_CURVATURE),
            jnp.where((j >= min_inner) & (norm_r <= target), TCGStop.CONVERGED,
                      jnp.where((norm_r > 0) & ~(z_r > 0), TCGStop.INDEFINITE_PRECONDITIONER,
                                jnp.where(j >= max_inner, TCGStop.MAX_INNER, TCGStop.RUNNING))))
        inside = ~to_boundary
        return _Loop(j, eta, Heta, ta.where(inside, r, c.r), ta.where(inside, delta, c.delta),
                     jnp.where(inside, e_Pe_new, c.e_Pe), jnp.where(inside, beta * (c.e_Pd + alpha * c.d_Pd), c.e_Pd),
                     jnp.where(inside, z_r + beta ** 2 * c.d_Pd, c.d_Pd), jnp.where(inside, z_r, c.z_r),
                     stop.astype(jnp.int32))

    out = jax.lax.while_loop(lambda c: c.stop == TCGStop.RUNNING, body, start)
    limited = (out.stop == TCGStop.NEGATIVE_CURVATURE) | (out.stop == TCGStop.EXCEEDED_RADIUS)
    return TCGResult(out.eta, out.Heta, out.j, out.stop, limited)
