"""Second-order finish of the smoothed CMM energy: a curvature-aware preconditioner and the trust-region
polish of ``BlockCMM`` (docs/maths.md §9, eqs. 9.13 and 9.19).

The Euclidean Hessian of ``F(X) = tr(XᵀWX) + μ Σ_ij w_i s(X_ij)`` acts column by column as

    ``∇²F[Z] = 2WZ + D ⊙ Z``,   ``D_ij = μ w_i s''(X_ij)``,

and near a minimiser most entries sit in the smoothing's kink (``|X_ij| ≲ δ``), where ``D_ij ∝ 1/δ`` dwarfs
W's scale: the shifted preconditioner ``K⁻¹ = (W + σA)⁻¹`` ignores D, and truncated CG then spends most of
its Hessian products on the pinned entries (hand_868's final stage: ~19 per outer iteration). The point
preconditioner here splits the entries at X into *pinned* (``D_ij > τ σ a_i``) and *free* ones and inverts
the two blocks apart, dropping the coupling through W between them:

    ``P_X Y = F ⊙ K⁻¹(F ⊙ Y) + (1 − F) ⊙ Y / (σ a + D/2)``,   ``F`` the 0/1 mask of the free entries

(both terms positive semi-definite, their sum positive definite; ``D/2`` matches ``K``'s scale, half the
Hessian's ``2W``). One sparse solve per application, as for ``K⁻¹``, and no factorisation per point: the
free block reuses the factor of ``K``. ``objectives.cmm.active_set`` splits the entries the same way for the
first-order solver, but factors the free rows of each column on the host and is refreshed between rounds
of iterations; trust regions need ``P_X`` at every outer iterate inside the compiled loop, hence this
cheaper, jittable form (it keeps K's coupling of free and pinned rows in the free block).

``polish`` runs ``stiefel.RiemannianTrustRegion`` with it from the block solver's last iterate to a relative
gradient norm (Riemannian, A-metric) ``≤ gtol·|F|``: quadratic convergence where first-order solvers crawl.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import optimistix as optx

import stiefel
from stiefel.runtime.compilation import run_compiled

__all__ = ["curvature_diagonal", "curvature_preconditioner", "polish", "POLISH_MAX_STEPS", "PIN_FACTOR"]

#: the compiled bound of the polish's trust-region iterations (its runtime budget is ``max_iters``)
POLISH_MAX_STEPS = 2000
#: entries whose smoothing curvature exceeds this multiple of ``σ a_i`` are treated as pinned
PIN_FACTOR = 1.0


def curvature_diagonal(energy, X: jax.Array) -> jax.Array:
    """``D = μ w_i max(s''(X_ij), 0)``, ``(n, k)``: the ℓ1 term's (diagonal) Hessian, clipped at 0 for the
    non-convex smoothings (the sum over entries is separable, so one JVP with ones gives the diagonal)."""
    total = lambda Y: jnp.sum(energy._s(Y))  # noqa: E731
    s2 = jax.jvp(jax.grad(total), (X,), (jnp.ones_like(X),))[1]
    return energy.mu * energy.weights[:, None] * jnp.maximum(s2, 0.0)


def curvature_preconditioner(energy, solve, a: jax.Array, sigma, *, pin_factor=PIN_FACTOR
                             ) -> stiefel.PointPreconditioner:
    """``P_X`` of the module docstring for the CMM energy ``energy`` (``objectives.energy.energies.CMMEnergy``).

    Args:
      solve: ``Y ↦ (W + σA)⁻¹Y`` (e.g. ``stiefel.shifted_inverse(W, A, σ).solve``); a: ``(n,)`` the lumped
        masses (positive); sigma: the shift σ > 0 of ``solve``; pin_factor: τ.
    """
    a = jnp.asarray(a)[:, None]

    def apply(X, Y):
        D = curvature_diagonal(energy, X)
        base = sigma * a
        free = (D <= pin_factor * base).astype(Y.dtype)
        return free * solve(free * Y) + (1.0 - free) * Y / (base + 0.5 * D)

    return stiefel.PointPreconditioner(apply)


def _tr_solve(fn, solver, X):
    return optx.minimise(fn, solver, X, None, max_steps=POLISH_MAX_STEPS, throw=False)


def polish(energy, manifold, X, solve, a, sigma, *, gtol: float, max_iters: int) -> tuple:
    """Trust regions (``stiefel.RiemannianTrustRegion``, exact Hessian, ``curvature_preconditioner``) from X
    to ``‖grad F‖ ≤ gtol·|F|``, at most ``max_iters`` outer iterations (a runtime budget: gtol and the
    budget never recompile).

    Returns ``(X_new, record, run seconds, compile seconds)``; record: ``iterations``, ``hvps`` (Hessian
    products), ``grad_norm`` (after; ``grad_norm_start`` before), ``value`` (the smoothed F after;
    ``value_start`` before), ``status`` (a ``stiefel.Status`` name: converged, max_iters,
    trust_region_collapsed, ...). X_new is the last accepted iterate (X itself when none was).
    """
    P = curvature_preconditioner(energy, solve, a, sigma)
    solver = stiefel.RiemannianTrustRegion(manifold, rtol=gtol, atol=0.0, preconditioner=P, budget=max_iters,
                                           history=1)
    fn = lambda Y, args: energy(Y)  # noqa: E731
    sol, t_compile, t_run = run_compiled(_tr_solve, fn, solver, X)
    st = sol.stats
    start = st["history"]  # entry 0: the start
    record = {"iterations": int(st["num_steps"]), "hvps": int(st["n_hvps"]), "grad_norm": float(st["grad_norm"]),
              "grad_norm_start": float(start.grad_norm[0]), "value": float(st["value"]),
              "value_start": float(start.value[0]), "status": stiefel.Status.names[int(st["status"])],
              "seconds": t_run}
    return sol.value, record, t_run, t_compile
