"""Block solvers for ``min F(X)`` over the whole matrix ``X ∈ S_M`` (pure, over ``lax.while_loop``).

Methods:

* ``"bb"`` — Riemannian gradient descent with alternating Barzilai–Borwein
  steps and the Zhang–Hager nonmonotone Armijo backtracking (Wen & Yin 2013).
  BB steps are capped (``max_move``): unbounded ones break orthogonality.
* ``"cg"`` — Riemannian nonlinear conjugate gradients (Polak–Ribière+, restart
  on non-descent) with the strong Armijo–Wolfe line search on the exact
  ``h(τ) = F(R_X(τη))``; vector transport by projection.
* ``"lbfgs"`` — Riemannian limited-memory BFGS (Nocedal & Wright Alg. 7.4, the
  two-loop recursion) with the same line search (``c2 = 0.9``; first trial the unit
  step, or less when the last decrease predicts less, N&W eq. 3.60).
  The ``memory`` pairs ``s = τη``, ``y = ξ⁺ − ξ`` are kept as ambient matrices and
  the direction is projected onto the current tangent space once (no transport of
  the memory, which saves 2m projections per iteration; in a prototype on the CMM
  benchmark the untransported memory needed 38 iterations to ADMM's best on fandisk
  against 34 transported, and 541 against 673 on camelhead). The initial inverse Hessian is
  the preconditioner (``q ↦ proj_X(P M q)``), or ``⟨s, y⟩/⟨y, y⟩·I`` without one.
  Pairs with ``⟨s, y⟩ ≤ 0`` are skipped; a non-descent direction resets the memory.

All accept a preconditioner (``stiefel.preconditioning``): the search
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

METHODS = ("cg", "bb", "lbfgs")


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
    S_mem: jax.Array  # (m, n, k) L-BFGS steps (m = 0 for the other methods)
    Y_mem: jax.Array  # (m, n, k) L-BFGS gradient differences
    rho_mem: jax.Array  # (m,) 1/⟨s, y⟩
    n_mem: jax.Array  # pairs stored (≤ m); the newest sits at (n_pairs − 1) mod m
    n_pairs: jax.Array  # pairs ever stored since the last reset


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
    memory: int = 8

    def __post_init__(self):
        if self.method == "lbfgs" and self.memory < 1:
            raise StiefelError(f"memory must be ≥ 1 for method='lbfgs', got {self.memory}")
        if self.ftol_window < 1:
            raise StiefelError(f"ftol_window must be ≥ 1, got {self.ftol_window}")


def _core(F, manifold: GeneralizedStiefel, P, X0, monitor, opts: BlockOptions, stall=None):
    """The solver loop. ``stall``: optional traced ``(ftol, ftol_window)`` overriding ``opts``'s values
    (``opts.ftol > 0`` still switches the test on), so solves that differ only in them share one
    compilation."""
    ftol, ftol_window = (opts.ftol, opts.ftol_window) if stall is None else stall
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
        if P is None or method == "lbfgs":  # L-BFGS applies P inside its two-loop recursion
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
    m_mem = opts.memory if method == "lbfgs" else 0
    carry0 = _Carry(
        X=X0, F=F0, G=G0, xi=xi0, gnorm=gn0, eta=-xi0, X_prev=X0,
        step=jnp.asarray(init_step, dtype) / jnp.maximum(manifold.norm(X0, xi0), jnp.finfo(dtype).tiny),
        F_prev=F0, C=F0, Q=jnp.ones((), dtype), it=jnp.zeros((), jnp.int32),
        status=jnp.asarray(status0, jnp.int32), history=hist,
        n_fevals=jnp.ones((), jnp.int32), n_restarts=jnp.zeros((), jnp.int32),
        S_mem=jnp.zeros((m_mem,) + X0.shape, dtype), Y_mem=jnp.zeros((m_mem,) + X0.shape, dtype),
        rho_mem=jnp.zeros((m_mem,), dtype), n_mem=jnp.zeros((), jnp.int32), n_pairs=jnp.zeros((), jnp.int32),
    )
    xi_norm_cap = jnp.asarray(max_move, dtype)

    def interpolated_step(c: _Carry, slope, fallback):
        """Initial step by quadratic interpolation on the last decrease (N&W eq. 3.60), or ``fallback``."""
        guess = 2.02 * (c.F - c.F_prev) / slope
        return jnp.where(jnp.isfinite(guess) & (guess > 0), guess, fallback)

    def wolfe_search(c: _Carry, eta, slope, guess):
        """Strong Wolfe search along ``R_X(τη)`` from ``min(guess, max_move/‖η‖)``:
        ``(X_new, step, accepted, n_evals)`` (CG and L-BFGS)."""
        tau0 = jnp.minimum(guess, xi_norm_cap / manifold.norm(c.X, eta))
        line = getattr(F, "line", None)  # an objective may evaluate F ∘ R_X(τη) faster itself
        phi = line(manifold, c.X, eta) if callable(line) else None
        phi = phi if phi is not None else along_curve(F, lambda t: manifold.retract(c.X, t * eta))
        ls = strong_wolfe(phi, c.F, slope, tau0, c1=c1, c2=c2, max_evals=ls_max_evals, value_scale=F0)
        return manifold.retract(c.X, ls.step * eta), ls.step, ls.accepted, ls.n_evals

    def precondition_tangent(X, q):
        """The preconditioner as a map of tangent vectors (the L-BFGS initial inverse Hessian)."""
        Mq = manifold.op.mv(q)
        if opts.precondition == "metric":
            return preconditioned_gradient(manifold.op, P, X, Mq)
        return preconditioned_residual(manifold, P, X, Mq)

    def lbfgs_direction(c: _Carry):
        """Two-loop recursion: ``−proj_X(H ξ)`` with the stored pairs (newest first, then back)."""
        m = c.S_mem.shape[0]
        inner = lambda U, V: manifold.inner(c.X, U, V)  # noqa: E731

        def first(t, state):
            q, alphas = state
            i = (c.n_pairs - 1 - t) % m
            valid = t < c.n_mem
            a = jnp.where(valid, c.rho_mem[i] * inner(c.S_mem[i], q), 0.0)
            return q - a * c.Y_mem[i], alphas.at[t].set(a)

        q, alphas = jax.lax.fori_loop(0, m, first, (c.xi, jnp.zeros((m,), c.F.dtype)))
        if P is None:
            newest = (c.n_pairs - 1) % m
            y = c.Y_mem[newest]
            gamma = jnp.where(c.n_mem > 0, 1.0 / (c.rho_mem[newest] * inner(y, y)), 1.0)
            r = gamma * q
        else:
            r = precondition_tangent(c.X, q)

        def second(t, r):
            tt = m - 1 - t  # oldest stored first
            i = (c.n_pairs - 1 - tt) % m
            valid = tt < c.n_mem
            b = c.rho_mem[i] * inner(c.Y_mem[i], r)
            return r + jnp.where(valid, alphas[tt] - b, 0.0) * c.S_mem[i]

        r = jax.lax.fori_loop(0, m, second, r)
        return -manifold.proj(c.X, r)

    def lbfgs_step(c: _Carry):
        eta = lbfgs_direction(c)
        slope = _trace(c.G, eta)
        restart = ~(slope < 0)
        if P is not None:  # the preconditioned gradient, computed only when needed (a host solve)
            eta = jax.lax.cond(restart, lambda: -precondition_tangent(c.X, c.xi), lambda: eta)
        else:
            eta = jnp.where(restart, -c.xi, eta)
        slope = jnp.where(restart, _trace(c.G, eta), slope)
        # unit step once the memory (or the preconditioner) sets the scale, unless the last decrease
        # predicts a shorter one (with P the Huber stiffness is missing from H₀: unit steps overshoot,
        # 3.2 → 1.0 trials per iteration on fandisk); before that, the initial guess
        unit = jnp.minimum(1.0, interpolated_step(c, slope, 1.0))
        guess = jnp.where((c.n_mem > 0) | (P is not None), unit, c.step)
        return (*wolfe_search(c, eta, slope, guess), eta, restart)

    def cg_step(c: _Carry):
        slope = _trace(c.G, c.eta)
        restart = ~(slope < 0)
        eta = jnp.where(restart, -c.xi, c.eta)
        slope = jnp.where(restart, -_trace(c.G, c.xi), slope)
        guess = jnp.where(c.it > 0, interpolated_step(c, slope, c.step), c.step)
        return (*wolfe_search(c, eta, slope, guess), eta, restart)

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
        step_fn = {"cg": cg_step, "bb": bb_step, "lbfgs": lbfgs_step}[method]
        X_new, tau, ok, n_ls, eta_used, restart = step_fn(c)
        F_new, G_new = value_and_grad(X_new)
        xi_new, gn_new, G_new = gradients(X_new, G_new)
        finite = jnp.isfinite(F_new) & jnp.all(jnp.isfinite(G_new)) & jnp.all(jnp.isfinite(X_new))
        good = ok & finite
        it = c.it + 1
        move = tau * manifold.norm(c.X, eta_used)
        conv = (gn_new <= gtol) | ((xtol > 0) & ok & (move <= xtol))
        if opts.ftol > 0:  # stalled: relative decrease over the last ftol_window iterations ≤ ftol
            past = c.history.value[jnp.maximum(it - ftol_window, 0)]
            conv = conv | ((it >= ftol_window) & ok & (past - F_new <= ftol * jnp.abs(F_new)))
        # a failed search along a CG / L-BFGS direction is retried along −ξ (a reset) before giving up
        retry = ~ok & ~restart if method in ("cg", "lbfgs") else jnp.zeros((), bool)
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
        elif method == "lbfgs":
            eta_next, step_next, C_next, Q_next = c.eta, tau, F_new, c.Q
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
        S_mem, Y_mem, rho_mem, n_mem, n_pairs = c.S_mem, c.Y_mem, c.rho_mem, c.n_mem, c.n_pairs
        if method == "lbfgs":
            m = S_mem.shape[0]
            # a reset (non-descent or a failed search) empties the memory before the new pair
            n_mem = jnp.where(restart | retry, 0, n_mem)
            n_pairs = jnp.where(restart | retry, 0, n_pairs)
            s_new, y_new = tau * eta_used, xi_new - c.xi
            sy = manifold.inner(X_new, s_new, y_new)
            store = good & (sy > jnp.finfo(dtype).eps * manifold.norm(X_new, s_new) * manifold.norm(X_new, y_new))
            slot = n_pairs % m
            # write the slot in place (a select over the whole (m, n, k) buffer would copy it)
            S_mem = S_mem.at[slot].set(jnp.where(store, s_new, S_mem[slot]))
            Y_mem = Y_mem.at[slot].set(jnp.where(store, y_new, Y_mem[slot]))
            rho_mem = rho_mem.at[slot].set(jnp.where(store, 1.0 / sy, rho_mem[slot]))
            n_mem = jnp.where(store, jnp.minimum(n_mem + 1, m), n_mem)
            n_pairs = jnp.where(store, n_pairs + 1, n_pairs)
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
            S_mem=S_mem, Y_mem=Y_mem, rho_mem=rho_mem, n_mem=n_mem, n_pairs=n_pairs,
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
    ftol_window: int = 20,
    max_iters: int = 1000,
    c1: float = 1e-4,
    c2: float | None = None,
    ls_max_evals: int = 30,
    init_step: float = 1.0,
    max_move: float = 1.0,
    bb_gamma: float = 0.85,
    memory: int = 8,
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
      method: ``"cg"`` (Riemannian CG + strong Wolfe), ``"lbfgs"`` (Riemannian L-BFGS +
        strong Wolfe) or ``"bb"`` (BB + nonmonotone Armijo).
      preconditioner: None, a callable ``Y ↦ PY`` (P SPD), or an SPD matrix/operator
        ``K`` whose inverse is applied (e.g. ``stiefel.shifted_inverse(W, M, σ)``).
      precondition: ``"residual"`` (``proj_X(P R)``, k columns of P per iteration) or
        ``"metric"`` (the exact gradient in the P⁻¹-metric, 2k columns); see
        ``stiefel.preconditioning``.
      gtol: stop when the Riemannian gradient norm (manifold metric) is ≤ gtol.
      xtol: stop when an accepted step moves X by ≤ xtol (M-norm); 0 disables.
      ftol: stop (as converged) when the objective decreased by ≤ ftol·|F| over the last
        ``ftol_window`` iterations; 0 disables. For non-smooth objectives under smoothing, where
        the gradient norm stalls above gtol.
      ftol_window: iterations over which ``ftol`` measures the decrease (≥ 1).
      max_iters: iteration limit.
      c1, c2: Armijo / curvature constants; ``c2`` defaults to 0.1 for ``"cg"`` (CG needs
        a tighter curvature condition than quasi-Newton methods: with 0.9 it stalled
        in tests), 0.9 for ``"lbfgs"``, and is unused by ``"bb"``; ls_max_evals:
        line-search evaluations.
      init_step: first step length in units of 1/‖grad‖; max_move: cap on τ‖η‖ per step.
      bb_gamma: Zhang–Hager averaging parameter (``"bb"``).
      memory: stored pairs (``"lbfgs"``), ≥ 1.
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
    if ftol_window < 1:
        raise StiefelError(f"ftol_window must be ≥ 1, got {ftol_window}")
    if precondition not in PRECONDITIONING_MODES:
        raise StiefelError(f"unknown precondition mode {precondition!r}; choose one of {PRECONDITIONING_MODES}")
    X0 = jnp.asarray(X0, dtype=manifold.dtype)
    if check:
        manifold.check_point(X0, atol=max(1e-8, 1e3 * float(jnp.finfo(manifold.dtype).eps)))
    P = as_preconditioner(preconditioner)
    c2 = (0.9 if method == "lbfgs" else 0.1) if c2 is None else c2
    # ftol and its window enter traced (only "on/off" is static): no recompilation when they change
    opts = BlockOptions(method=method, gtol=float(gtol), xtol=float(xtol), max_iters=int(max_iters), c1=float(c1),
                        c2=float(c2), ls_max_evals=int(ls_max_evals), init_step=float(init_step),
                        max_move=float(max_move), bb_gamma=float(bb_gamma), precondition=precondition,
                        ftol=1.0 if ftol > 0 else 0.0, memory=int(memory))
    stall = (jnp.asarray(ftol, dtype=X0.dtype), jnp.asarray(ftol_window, dtype=jnp.int32))
    out, t_compile, t_run = run_compiled(_core, F, manifold, P, X0, monitor, opts, stall)
    X, value, gnorm, it, status, history, stats = out
    result = Result(x=X, value=value, grad_norm=gnorm, iterations=it, status=status, history=history,
                    stats={k: np.asarray(v) for k, v in stats.items()}, wall_time=t_run, compile_time=t_compile)
    if throw:
        result.raise_for_status()
    return result

