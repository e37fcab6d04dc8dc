"""Block solvers for ``min F(X)`` over the whole matrix ``X ∈ S_M`` (pure, over ``lax.while_loop``).

Methods:

* ``"bb"`` — Riemannian gradient descent with alternating Barzilai–Borwein
  steps and the Zhang–Hager nonmonotone Armijo backtracking (Wen & Yin 2013).
  BB steps are capped (``max_move``): unbounded ones break orthogonality.
* ``"cg"`` — Riemannian nonlinear conjugate gradients (Polak–Ribière+, restart
  on non-descent) with the strong Armijo–Wolfe line search on the exact
  ``h(τ) = F(R_X(τη))``; vector transport by projection.

Both accept a preconditioner (``stiefel.preconditioning``): the search
direction is then the gradient in the metric ``tr(Z1ᵀP⁻¹Z2)``, still a
guaranteed descent direction. The reported gradient norm is always the
manifold metric's, so runs are comparable.
"""

from __future__ import annotations

import dataclasses
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._compile import run_compiled
from .errors import StiefelError
from .linesearch import LineSearchStatus, along_curve, strong_wolfe
from .manifold import GeneralizedStiefel, sym
from .preconditioning import PRECONDITIONING_MODES, as_preconditioner, preconditioned_gradient, preconditioned_residual
from .result import History, Result, Status

__all__ = ["minimize", "solve", "BlockOptions", "METHODS"]

METHODS = ("cg", "bb")


class _Carry(NamedTuple):
    X: jax.Array
    F: jax.Array
    G: jax.Array  # tangent residual R = ∂F/∂X − MX sym(Xᵀ∂F/∂X): tr(RᵀZ) = tr(GᵀZ) for tangent Z
    xi: jax.Array  # search gradient (preconditioned if P given)
    gnorm: jax.Array  # manifold-metric Riemannian gradient norm
    eta: jax.Array  # search direction (CG) / previous search gradient (BB)
    X_prev: jax.Array
    step: jax.Array  # last accepted step (initial step guess for BB)
    F_prev: jax.Array
    C: jax.Array  # nonmonotone reference value (BB)
    Q: jax.Array
    it: jax.Array
    status: jax.Array
    history: History
    n_fevals: jax.Array
    n_restarts: jax.Array


def _trace(A, B):
    return jnp.sum(A * B)


@dataclasses.dataclass(frozen=True)
class BlockOptions:
    """Static options of the block solver (see ``minimize``)."""

    method: str = "cg"
    gtol: float = 1e-6
    xtol: float = 0.0
    max_iters: int = 1000
    c1: float = 1e-4
    c2: float = 0.9
    ls_max_evals: int = 30
    init_step: float = 1.0
    max_move: float = 1.0
    bb_gamma: float = 0.85
    precondition: str = "residual"
    ftol: float = 0.0
    ftol_window: int = 20


def _core(F, manifold: GeneralizedStiefel, P, X0, monitor, opts: BlockOptions):
    method, gtol, xtol, max_iters = opts.method, opts.gtol, opts.xtol, opts.max_iters
    c1, c2, ls_max_evals, init_step = opts.c1, opts.c2, opts.ls_max_evals, opts.init_step
    max_move, bb_gamma = opts.max_move, opts.bb_gamma
    value_and_grad = jax.value_and_grad(F)

    def gradients(X, G):
        """(search gradient ξ, manifold-metric gradient norm, tangent residual R).

        Directional derivatives are taken as ``tr(RᵀZ)``, not ``tr(GᵀZ)``: equal for
        tangent Z, but R is small near a critical point while G is not, so the
        slope keeps its relative accuracy down to gradient norms ~1e-8·scale.
        """
        rg = manifold.egrad_to_rgrad(X, G)
        gn = manifold.norm(X, rg)
        R = G - manifold.op.mv(X) @ sym(X.T @ G)
        if P is None:
            xi = rg
        elif opts.precondition == "metric":
            xi = preconditioned_gradient(manifold.op, P, X, G)
        else:
            xi = preconditioned_residual(manifold, P, X, R)
        return xi, gn, R

    F0, G0 = value_and_grad(X0)
    xi0, gn0, G0 = gradients(X0, G0)
    dtype = X0.dtype
    watch = (lambda X: jnp.nan) if monitor is None else monitor  # noqa: E731
    hist = History.empty(max_iters + 1, dtype).record(0, F0, gn0, 0.0, watch(X0))
    finite0 = jnp.isfinite(F0) & jnp.all(jnp.isfinite(G0))
    status0 = jnp.where(~finite0, Status.NON_FINITE, jnp.where(gn0 <= gtol, Status.CONVERGED, -1))
    zero = jnp.zeros((), dtype)
    carry0 = _Carry(
        X=X0, F=F0, G=G0, xi=xi0, gnorm=gn0, eta=-xi0, X_prev=X0,
        step=jnp.asarray(init_step, dtype) / jnp.maximum(manifold.norm(X0, xi0), jnp.finfo(dtype).tiny),
        F_prev=F0, C=F0, Q=jnp.ones((), dtype), it=jnp.zeros((), jnp.int32),
        status=jnp.asarray(status0, jnp.int32), history=hist,
        n_fevals=jnp.ones((), jnp.int32), n_restarts=jnp.zeros((), jnp.int32),
    )
    xi_norm_cap = jnp.asarray(max_move, dtype)

    def cg_step(c: _Carry):
        slope = _trace(c.G, c.eta)
        restart = ~(slope < 0)
        eta = jnp.where(restart, -c.xi, c.eta)
        slope = jnp.where(restart, -_trace(c.G, c.xi), slope)
        eta_norm = manifold.norm(c.X, eta)
        # initial step: quadratic interpolation on the last decrease (N&W eq. 3.60), capped
        guess = jnp.where(c.it > 0, 2.02 * (c.F - c.F_prev) / slope, c.step)
        guess = jnp.where(jnp.isfinite(guess) & (guess > 0), guess, c.step)
        tau0 = jnp.minimum(guess, xi_norm_cap / eta_norm)
        line = getattr(F, "line", None)  # an objective may evaluate F ∘ R_X(τη) faster itself
        phi = line(manifold, c.X, eta) if callable(line) else None
        phi = phi if phi is not None else along_curve(F, lambda t: manifold.retract(c.X, t * eta))
        ls = strong_wolfe(phi, c.F, slope, tau0, c1=c1, c2=c2, max_evals=ls_max_evals, value_scale=F0)
        X_new = manifold.retract(c.X, ls.step * eta)
        return X_new, ls.step, ls.accepted, ls.n_evals, eta, restart

    def bb_step(c: _Carry):
        eta = -c.xi
        slope = -_trace(c.G, c.xi)
        eta_norm = manifold.norm(c.X, eta)
        tau0 = jnp.minimum(c.step, xi_norm_cap / eta_norm)

        def bt_cond(s):
            tau, f, n = s
            return ~(jnp.isfinite(f) & (f <= c.C + c1 * tau * slope)) & (n < ls_max_evals)

        def bt_body(s):
            tau, _, n = s
            tau = 0.5 * tau
            return tau, F(manifold.retract(c.X, tau * eta)), n + 1

        f_first = F(manifold.retract(c.X, tau0 * eta))
        tau, f_acc, n = jax.lax.while_loop(bt_cond, bt_body, (tau0, f_first, jnp.ones((), jnp.int32)))
        ok = jnp.isfinite(f_acc) & (f_acc <= c.C + c1 * tau * slope) & (slope < 0)
        tau = jnp.where(ok, tau, 0.0)
        X_new = manifold.retract(c.X, tau * eta)
        return X_new, tau, ok, n, c.xi, jnp.zeros((), bool)

    def body(c: _Carry) -> _Carry:
        X_new, tau, ok, n_ls, eta_used, restart = cg_step(c) if method == "cg" else bb_step(c)
        F_new, G_new = value_and_grad(X_new)
        xi_new, gn_new, G_new = gradients(X_new, G_new)
        finite = jnp.isfinite(F_new) & jnp.all(jnp.isfinite(G_new)) & jnp.all(jnp.isfinite(X_new))
        good = ok & finite
        it = c.it + 1
        move = tau * manifold.norm(c.X, eta_used)
        conv = (gn_new <= gtol) | ((xtol > 0) & ok & (move <= xtol))
        if opts.ftol > 0:  # stalled: relative decrease over the last ftol_window iterations ≤ ftol
            past = c.history.value[jnp.maximum(it - opts.ftol_window, 0)]
            conv = conv | ((it >= opts.ftol_window) & ok & (past - F_new <= opts.ftol * jnp.abs(F_new)))
        # a failed search along a CG direction is retried along −ξ before giving up
        retry = ~ok & ~restart if method == "cg" else jnp.zeros((), bool)
        status = jnp.where(
            retry, -1,
            jnp.where(~ok, Status.LINE_SEARCH_FAILED,
            jnp.where(~finite, Status.NON_FINITE,
                      jnp.where(conv, Status.CONVERGED, jnp.where(it >= max_iters, Status.MAX_ITERS, -1)))),
        ).astype(jnp.int32)
        status = jnp.where(retry & (it >= max_iters), Status.MAX_ITERS, status).astype(jnp.int32)
        if method == "cg":
            T_xi, T_eta = manifold.transport_pair(X_new, c.xi, eta_used)
            beta = jnp.maximum(_trace(G_new, xi_new - T_xi) / _trace(c.G, c.xi), 0.0)
            beta = jnp.where(jnp.isfinite(beta), beta, 0.0)
            eta_next = jnp.where(retry, -c.xi, -xi_new + beta * T_eta)
            step_next = tau
            C_next, Q_next = F_new, c.Q
        else:
            S = X_new - c.X
            Y = xi_new - c.xi
            MS = manifold.op.mv(S)
            sy = jnp.abs(_trace(MS, Y))
            ss = _trace(MS, S)
            yy = _trace(Y, manifold.op.mv(Y))
            bb = jnp.where(it % 2 == 1, ss / sy, sy / yy)
            cap = xi_norm_cap / jnp.maximum(manifold.norm(X_new, xi_new), jnp.finfo(X_new.dtype).tiny)
            step_next = jnp.where(jnp.isfinite(bb) & (bb > 0), jnp.minimum(bb, cap), tau)
            eta_next = xi_new
            Q_next = bb_gamma * c.Q + 1.0
            C_next = (bb_gamma * c.Q * c.C + F_new) / Q_next
        keep = lambda new, old: jnp.where(good, new, old)  # noqa: E731
        eta_keep = jnp.where(good | retry, eta_next, c.eta)
        F_rec = jnp.where(good, F_new, c.F)
        return _Carry(
            X=keep(X_new, c.X), F=F_rec, G=keep(G_new, c.G), xi=keep(xi_new, c.xi),
            gnorm=jnp.where(good, gn_new, c.gnorm), eta=eta_keep, X_prev=c.X,
            step=jnp.where(good, step_next, c.step), F_prev=c.F, C=jnp.where(good, C_next, c.C),
            Q=jnp.where(good, Q_next, c.Q), it=it, status=status,
            history=c.history.record(it, F_rec, jnp.where(good, gn_new, c.gnorm), tau,
                                     watch(jnp.where(good, X_new, c.X))),
            n_fevals=c.n_fevals + n_ls + 1, n_restarts=c.n_restarts + (restart | retry).astype(jnp.int32),
        )

    c = jax.lax.while_loop(lambda c: c.status < 0, body, carry0)
    stats = {"n_fevals": c.n_fevals, "n_grads": c.it + 1, "n_restarts": c.n_restarts,
             "dist_to_manifold": manifold.dist_to_manifold(c.X)}
    return c.X, c.F, c.gnorm, c.it, c.status, c.history, stats


def solve(F: Callable, manifold: GeneralizedStiefel, X0, options: BlockOptions = BlockOptions(), *,
          preconditioner: Callable | None = None, monitor: Callable | None = None) -> Result:
    """The block solver as a pure function: jittable and vmappable (e.g. over starts or over
    parameters of ``F``), no validation, no timing (``wall_time = compile_time = 0``).

    ``preconditioner`` must already be a callable ``Y ↦ PY`` (see ``as_preconditioner``).
    ``minimize`` is the checked, timed front end of the same computation.
    """
    X, value, gnorm, it, status, history, stats = _core(F, manifold, preconditioner, X0, monitor, options)
    return Result(x=X, value=value, grad_norm=gnorm, iterations=it, status=status, history=history, stats=stats)


def minimize(
    F: Callable,
    manifold: GeneralizedStiefel,
    X0,
    *,
    method: str = "cg",
    preconditioner=None,
    precondition: str = "residual",
    gtol: float = 1e-6,
    xtol: float = 0.0,
    ftol: float = 0.0,
    max_iters: int = 1000,
    c1: float = 1e-4,
    c2: float | None = None,
    ls_max_evals: int = 30,
    init_step: float = 1.0,
    max_move: float = 1.0,
    bb_gamma: float = 0.85,
    check: bool = True,
    throw: bool = False,
    monitor: Callable | None = None,
) -> Result:
    """Minimise ``F(X)`` over ``X ∈ S_M`` from ``X0`` (the whole block at once).

    Args:
      F: ``X (n, k) -> scalar``, a JAX-differentiable function (gradient by ``jax.grad``).
        An objective may also define ``F.line(manifold, X, η)`` returning
        ``τ ↦ (F(R_X(τη)), d/dτ)`` (or None) to evaluate line-search trials faster than
        through the retraction (``objectives.CMMEnergy`` does, for the Cholesky retraction).
      manifold: a ``GeneralizedStiefel`` (its metric and retraction are used).
      X0: start, shape ``(n, k)``, on the manifold (``manifold.project_to_manifold``).
      method: ``"cg"`` (Riemannian CG + strong Wolfe) or ``"bb"`` (BB + nonmonotone Armijo).
      preconditioner: None, a callable ``Y ↦ PY`` (P SPD), or an SPD matrix/operator
        ``K`` whose inverse is applied (e.g. ``stiefel.shifted_inverse(W, M, σ)``).
      precondition: ``"residual"`` (``proj_X(P R)``, k columns of P per iteration) or
        ``"metric"`` (the exact gradient in the P⁻¹-metric, 2k columns); see
        ``stiefel.preconditioning``.
      gtol: stop when the Riemannian gradient norm (manifold metric) is ≤ gtol.
      xtol: stop when an accepted step moves X by ≤ xtol (M-norm); 0 disables.
      ftol: stop (as converged) when the objective decreased by ≤ ftol·|F| over the last
        20 iterations; 0 disables. For non-smooth objectives under smoothing, where the
        gradient norm stalls above gtol.
      max_iters: iteration limit.
      c1, c2: Armijo / curvature constants; ``c2`` defaults to 0.1 for ``"cg"`` (CG needs
        a tighter curvature condition than quasi-Newton methods: with 0.9 it stalled
        in tests) and is unused by ``"bb"``; ls_max_evals: line-search evaluations.
      init_step: first step length in units of 1/‖grad‖; max_move: cap on τ‖η‖ per step.
      bb_gamma: Zhang–Hager averaging parameter (``"bb"``).
      check: validate ``X0`` (shape, finiteness, on the manifold to 1e-8, or to 1000 ulps in a
        lower precision: 1.2e-4 in float32).
      throw: raise ``SolverError`` on ``line_search_failed`` / ``non_finite``.
      monitor: optional JAX function ``X ↦ scalar`` recorded at every iterate in
        ``history.monitor`` (e.g. the true non-smooth objective, for time-to-target curves).

    Returns:
      ``Result`` with ``x, value, grad_norm, iterations, status, history, stats,
      wall_time, compile_time``.
    """
    if method not in METHODS:
        raise StiefelError(f"unknown method {method!r}; choose one of {METHODS}")
    if not isinstance(manifold, GeneralizedStiefel):
        raise StiefelError("manifold must be a stiefel.GeneralizedStiefel")
    if max_iters < 1:
        raise StiefelError(f"max_iters must be ≥ 1, got {max_iters}")
    if precondition not in PRECONDITIONING_MODES:
        raise StiefelError(f"unknown precondition mode {precondition!r}; choose one of {PRECONDITIONING_MODES}")
    X0 = jnp.asarray(X0, dtype=manifold.dtype)
    if check:
        manifold.check_point(X0, atol=max(1e-8, 1e3 * float(jnp.finfo(manifold.dtype).eps)))
    P = as_preconditioner(preconditioner)
    c2 = 0.1 if c2 is None else c2
    opts = BlockOptions(method=method, gtol=float(gtol), xtol=float(xtol), max_iters=int(max_iters), c1=float(c1),
                        c2=float(c2), ls_max_evals=int(ls_max_evals), init_step=float(init_step),
                        max_move=float(max_move), bb_gamma=float(bb_gamma), precondition=precondition,
                        ftol=float(ftol))
    out, t_compile, t_run = run_compiled(_core, F, manifold, P, X0, monitor, opts)
    X, value, gnorm, it, status, history, stats = out
    result = Result(x=X, value=value, grad_norm=gnorm, iterations=it, status=status, history=history,
                    stats={k: np.asarray(v) for k, v in stats.items()}, wall_time=t_run, compile_time=t_compile)
    if throw:
        result.raise_for_status()
    return result

