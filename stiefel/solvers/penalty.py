"""The quadratic-penalty baseline: unconstrained L-BFGS (``jaxopt``) on ``F(X) + ρ‖XᵀMX − I‖²_F``.

What one writes without a manifold toolkit: drop the constraint ``XᵀMX = I`` into the objective,

    minimise_{X ∈ R^{n×k}}  P_ρ(X) = F(X) + ρ ‖XᵀMX − I_k‖²_F,

then map the minimiser to ``S_M`` with ``manifold.project_to_manifold`` (``X (XᵀMX)^{-1/2}``).
The penalty minimiser violates the constraint by O(1/ρ) (for ``F = tr(XᵀWXD)`` its columns are
M-eigenvectors scaled to ``xᵢᵀMxᵢ = 1 − dᵢλᵢ/(2ρ)``), while the Hessian of ``P_ρ`` grows like ρ, so
L-BFGS slows as ρ grows; a short increasing sequence of ρ, each stage warm-started from the last
(continuation), keeps the early stages well conditioned. Used as the baseline in
``bench/bench_penalty.py``.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from ..runtime.compilation import run_compiled
from ..errors import ParameterError, ShapeError, StiefelError
from ..manifolds.manifold import GeneralizedStiefel
from ..validation import check_count, check_positive

__all__ = ["PenaltyResult", "penalty_minimize"]


class PenaltyResult(eqx.Module):
    """Outcome of ``penalty_minimize``.

    Attributes:
      x: ``(n, k)`` returned point (projected to ``S_M`` when ``project=True``).
      value: ``F(x)`` (without the penalty).
      constraint_violation_before_projection: ``max|XᵀMX − I|`` of the L-BFGS minimiser of ``P_ρ``.
      constraint_violation: ``max|xᵀMx − I|`` of the returned ``x``.
      iterations: L-BFGS iterations, all ρ stages together; stage_iterations: ``(stages,)``.
      grad_norm: ‖∇P_ρ‖_F at the end of the last stage (jaxopt's stopping quantity).
      rho: ``(stages,)`` the penalty weights used.
      stats: ``n_fevals``, ``n_gevals`` (value and gradient evaluations), ``n_linesearch_failed`` (stages).
      wall_time: seconds for the compiled solve; compile_time: seconds to trace and compile it.
      status: ``"converged"`` (the last stage's ‖∇P_ρ‖_F ≤ tol), ``"non_finite"`` (x or its value is not
      finite: ρ too small for F's curvature lets the columns collapse, or the line search blew up),
      ``"line_search_failed"`` (a stage's line search failed and the last stage did not converge) or
      ``"max_iters"``.
    """

    x: Float[Array, "n k"]
    value: Float[Array, ""]
    constraint_violation_before_projection: Float[Array, ""]
    constraint_violation: Float[Array, ""]
    iterations: Int[Array, ""]
    stage_iterations: Int[Array, " stages"]
    grad_norm: Float[Array, ""]
    rho: Float[Array, " stages"]
    stats: dict
    wall_time: float = 0.0
    compile_time: float = 0.0
    status: str = eqx.field(static=True, default="converged")


def _status(X, value, gnorm, failed, tol) -> str:
    """The outcome, from the host values of the solve (see ``PenaltyResult.status``)."""
    if not (np.all(np.isfinite(np.asarray(X))) and np.isfinite(float(value))):
        return "non_finite"
    if float(gnorm) <= tol:
        return "converged"
    return "line_search_failed" if int(failed) > 0 else "max_iters"


def _penalised(fn, op, with_args):
    def P(X, rho, args):
        C = X.T @ op.mv(X) - jnp.eye(X.shape[1], dtype=X.dtype)
        return (fn(X, args) if with_args else fn(X)) + rho * jnp.sum(C * C)
    return P


def _run(fn, manifold, X0, rhos, args, maxiter, tol, project, with_args):
    import jaxopt  # archived upstream; warns on import (DeprecationWarning), hence lazily

    # implicit_diff=False: the solve is not differentiated (run_compiled needs concrete inputs), and the
    # custom_root wrapper cost ~1 s of compile time (measured, n = 100)
    solver = jaxopt.LBFGS(_penalised(fn, manifold.op, with_args), maxiter=maxiter, tol=tol, implicit_diff=False)

    def stage(X, rho):
        X, state = solver.run(X, rho, args)
        return X, (state.iter_num, state.error, state.num_fun_eval, state.num_grad_eval, state.failed_linesearch)

    X, (its, errs, nf, ng, failed) = jax.lax.scan(stage, X0, rhos)
    before = manifold.dist_to_manifold(X)
    if project:
        X = manifold.project_to_manifold(X)
    value = fn(X, args) if with_args else fn(X)
    stats = {"n_fevals": jnp.sum(nf), "n_gevals": jnp.sum(ng), "n_linesearch_failed": jnp.sum(failed)}
    return X, value, before, manifold.dist_to_manifold(X), its, errs[-1], stats


def penalty_minimize(fn: Callable, manifold: GeneralizedStiefel, X0, *, args: Any = None,
                     rho: float | Sequence[float] = 10.0, maxiter: int = 1000,
                     tol: float = 1e-6, project: bool = True) -> PenaltyResult:
    """Minimise ``fn(X) + ρ‖XᵀMX − I‖²_F`` over ``X ∈ R^{n×k}`` with ``jaxopt.LBFGS``, then project.

    Args:
      fn: ``X (n, k) -> scalar`` (``fn(X, args)`` when ``args`` is given), JAX-differentiable.
      manifold: a ``GeneralizedStiefel`` (its ``M`` defines the constraint and the projection).
      X0: ``(n, k)`` start; need not be on the manifold.
      args: parameters passed to ``fn`` (arrays in it are traced: new values do not recompile).
      rho: penalty weight ρ > 0 (in units of F: it must dominate F's curvature, e.g. ρ > max dᵢλᵢ/2
        for ``tr(XᵀWXD)``, or columns collapse), or a non-decreasing sequence of weights solved in turn,
        each stage warm-started from the previous minimiser (continuation). Measured on the test
        problem (n = 60, k = 3, tol 1e-9): ρ = 10 → 100 → 1000 took 636 + 1045 + 2325 iterations, a cold
        ρ = 1000 solve 4759, a modest gain; for the projected point alone one small ρ converges fastest
        (636 iterations at ρ = 10), see ``docs/benchmarks/penalty.md``.
      maxiter: L-BFGS iteration limit per ρ stage (an integer in ``[1, 2³¹ − 1]``; jaxopt's loop bound is
        static, so each stage gets the same cap and the total is at most ``stages × maxiter``).
      tol: per-stage stop when ‖∇P_ρ(X)‖_F ≤ tol (> 0).
      project: map the minimiser to ``S_M`` by ``X (XᵀMX)^{-1/2}``.

    Call it outside ``jit``/``grad`` (it compiles and times the solve itself); the solve is not
    differentiable: for derivatives of solutions use ``stiefel.minimize(..., args=)``.

    Returns:
      ``PenaltyResult`` (``x, value, constraint_violation_before_projection, constraint_violation,
      iterations, stage_iterations, grad_norm, rho, stats, wall_time, compile_time, status``).
    """
    if not isinstance(manifold, GeneralizedStiefel):
        raise StiefelError("manifold must be a stiefel.GeneralizedStiefel")
    rhos = [rho] if np.ndim(rho) == 0 else list(rho)
    if not rhos:
        raise ParameterError("rho must be a finite number > 0 or a non-empty sequence of them, got an empty sequence")
    rhos = [check_positive("rho" if len(rhos) == 1 else f"rho[{i}]", r) for i, r in enumerate(rhos)]
    if any(b < a for a, b in zip(rhos, rhos[1:])):
        raise ParameterError(f"a rho sequence must be non-decreasing (continuation), got {rhos}")
    maxiter = check_count("maxiter", maxiter)
    tol = check_positive("tol", tol)
    shape = tuple(np.shape(X0))
    if shape != (manifold.n, manifold.k):
        raise ShapeError(f"X0 must have shape (n, k) = {(manifold.n, manifold.k)}, got {shape}")
    X0 = jnp.asarray(X0, dtype=manifold.dtype)
    rho_arr = jnp.asarray(rhos, dtype=manifold.dtype)
    out, t_compile, t_run = run_compiled(_run, fn, manifold, X0, rho_arr, args, int(maxiter), float(tol),
                                         bool(project), args is not None)
    X, value, before, after, its, gnorm, stats = out
    return PenaltyResult(x=X, value=value, constraint_violation_before_projection=before,
                         constraint_violation=after, iterations=jnp.sum(its), stage_iterations=its,
                         grad_norm=gnorm, rho=rho_arr, stats={k: np.asarray(v) for k, v in stats.items()},
                         wall_time=t_run, compile_time=t_compile,
                         status=_status(X, value, gnorm, stats["n_linesearch_failed"], tol))
