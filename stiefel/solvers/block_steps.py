"""One iteration of the Riemannian block minimisers (``stiefel.solvers.minimisers``): the state and the step.

Everything here is pure and shared by the three methods (CG, L-BFGS, BB); the solver object
supplies the options. Directional derivatives are taken as ``tr(RᵀZ)`` with the tangent
residual ``R = G − MX sym(XᵀG)`` (``manifold.tangent_residual``) instead of ``tr(GᵀZ)``: equal
for tangent ``Z``, but R vanishes at critical points while G does not, so slopes keep their
relative accuracy. Points and tangent vectors are arrays or, on a ``stiefel.Product``, tuples of
arrays: the vector algebra goes through ``stiefel.manifolds.tangent_algebra`` (the same operations for one array).
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..manifolds import tangent_algebra as ta
from .linesearch import along_curve, strong_wolfe
from .preconditioning import at_point, preconditioned_gradient, preconditioned_residual
from ..result import History, Status

STALL_WINDOW_MAX = 64  # ring buffer of recent objective values for the ftol test

__all__ = ["State", "init_state", "step"]


class State(NamedTuple):
    X: jax.Array
    F: jax.Array
    G: jax.Array  # tangent residual R (module docstring)
    xi: jax.Array  # search gradient (preconditioned if P given)
    gnorm: jax.Array  # manifold-metric Riemannian gradient norm
    eta: jax.Array  # search direction (CG) / previous search gradient (BB)
    step: jax.Array  # last accepted step (initial step guess)
    F_prev: jax.Array
    C: jax.Array  # nonmonotone reference value (BB)
    Q: jax.Array
    it: jax.Array
    status: jax.Array  # stiefel.Status code, −1 while running
    history: History
    recent: jax.Array  # ring buffer of the last STALL_WINDOW_MAX objective values (ftol test)
    n_fevals: jax.Array
    n_restarts: jax.Array
    S_mem: jax.Array  # (m, n, k) L-BFGS steps (m = 0 for the other methods); a tuple of them on a Product
    Y_mem: jax.Array  # (m, n, k) L-BFGS gradient differences
    rho_mem: jax.Array  # (m,) 1/⟨s, y⟩
    n_mem: jax.Array  # pairs stored (≤ m); the newest sits at (n_pairs − 1) mod m
    n_pairs: jax.Array  # pairs stored since the last reset
    retrying: jax.Array  # the last search failed: this iteration retries along −ξ, and a second failure is final
    aux: object  # fn's auxiliary output at X


_trace = ta.inner
tmap = ta.tmap


def _value_and_grad(fn, args):
    """``X ↦ ((F, aux), ∂F/∂X)`` for an optimistix-style ``fn(X, args) -> (F, aux)``."""
    return jax.value_and_grad(lambda X: fn(X, args), has_aux=True)


def _gradients(solver, X, G):
    """(search gradient ξ, manifold-metric gradient norm, tangent residual R)."""
    S, P = solver.manifold, at_point(solver.preconditioner, X)
    rg = S.egrad_to_rgrad(X, G)
    gn = S.norm(X, rg)
    R = S.tangent_residual(X, G)
    if P is None or solver.method == "lbfgs":  # L-BFGS applies P inside its two-loop recursion
        xi = rg
    elif solver.precondition == "metric":
        xi = preconditioned_gradient(S.op, P, X, G)
    else:
        xi = preconditioned_residual(S, P, X, R)
    return xi, gn, R


def _converged_grad(solver, gn, F):
    return gn <= solver.atol + solver.rtol * jnp.abs(F)


def _out_of_budget(solver, status, it):
    """``MAX_ITERS`` for a running status once ``it`` iterations used up the solver's runtime budget."""
    if solver.budget is None:
        return status
    return jnp.where((status < 0) & (it >= solver.budget), Status.MAX_ITERS, status).astype(jnp.int32)


def _watch(solver, X):
    return jnp.nan if solver.monitor is None else solver.monitor(X)


def init_state(solver, fn, X0, args) -> State:
    S = solver.manifold
    (F0, aux0), G0 = _value_and_grad(fn, args)(X0)
    xi0, gn0, R0 = _gradients(solver, X0, G0)
    dtype = ta.dtype_of(X0)
    hist = History.empty(max(solver.history, 1), dtype).record(0, F0, gn0, 0.0, _watch(solver, X0))
    finite0 = jnp.isfinite(F0) & ta.all_finite(G0)
    status0 = jnp.where(~finite0, Status.NON_FINITE, jnp.where(_converged_grad(solver, gn0, F0), Status.CONVERGED, -1))
    status0 = _out_of_budget(solver, jnp.asarray(status0, jnp.int32), 0)
    m = solver.memory_size if solver.method != "lbfgs" else solver.memory
    zero_i = jnp.zeros((), jnp.int32)
    return State(
        X=X0, F=F0, G=R0, xi=xi0, gnorm=gn0, eta=tmap(jnp.negative, xi0),
        step=jnp.asarray(solver.init_step, dtype) / jnp.maximum(S.norm(X0, xi0), jnp.finfo(dtype).tiny),
        F_prev=F0, C=F0, Q=jnp.ones((), dtype), it=zero_i, status=status0, history=hist,
        recent=jnp.full((STALL_WINDOW_MAX,), F0, dtype), n_fevals=jnp.ones((), jnp.int32), n_restarts=zero_i,
        S_mem=ta.stacked_zeros(m, X0, dtype), Y_mem=ta.stacked_zeros(m, X0, dtype),
        rho_mem=jnp.zeros((m,), dtype), n_mem=zero_i, n_pairs=zero_i, retrying=jnp.zeros((), bool), aux=aux0,
    )


def _interpolated_step(c: State, slope, fallback):
    """Initial step by quadratic interpolation on the last decrease (N&W eq. 3.60), or ``fallback``."""
    guess = 2.02 * (c.F - c.F_prev) / slope
    return jnp.where(jnp.isfinite(guess) & (guess > 0), guess, fallback)


def _wolfe_search(solver, F, args, c: State, eta, slope, guess, scale):
    """Strong Wolfe search along ``R_X(τη)`` from ``min(guess, max_move/‖η‖)``."""
    S = solver.manifold
    tau0 = jnp.minimum(guess, solver.max_move / S.norm(c.X, eta))
    phi = solver.line(S, c.X, eta, args) if solver.line is not None else None
    phi = phi if phi is not None else along_curve(F, lambda t: S.retract(c.X, tmap(lambda e: t * e, eta)))
    ls = strong_wolfe(phi, c.F, slope, tau0, c1=solver.c1, c2=solver.c2, max_evals=solver.ls_max_evals,
                      value_scale=scale)
    return S.retract(c.X, tmap(lambda e: ls.step * e, eta)), ls.step, ls.accepted, ls.n_evals


def _precondition_tangent(solver, X, q):
    """The preconditioner as a map of tangent vectors (the L-BFGS initial inverse Hessian)."""
    S, P = solver.manifold, at_point(solver.preconditioner, X)
    Mq = S.mv(q)
    if solver.precondition == "metric":
        return preconditioned_gradient(S.op, P, X, Mq)
    return preconditioned_residual(S, P, X, Mq)


def _lbfgs_direction(solver, c: State):
    """Two-loop recursion: ``−proj_X(H ξ)`` with the stored pairs (newest first, then back)."""
    S = solver.manifold
    m = c.rho_mem.shape[0]
    inner = lambda U, V: S.inner(c.X, U, V)  # noqa: E731

    def first(t, state):
        q, alphas = state
        i = (c.n_pairs - 1 - t) % m
        a = jnp.where(t < c.n_mem, c.rho_mem[i] * inner(ta.take(c.S_mem, i), q), 0.0)
        return tmap(lambda q, y: q - a * y, q, ta.take(c.Y_mem, i)), alphas.at[t].set(a)

    q, alphas = jax.lax.fori_loop(0, m, first, (c.xi, jnp.zeros((m,), c.F.dtype)))
    if solver.preconditioner is None:
        newest = (c.n_pairs - 1) % m
        y = ta.take(c.Y_mem, newest)
        gamma = jnp.where(c.n_mem > 0, 1.0 / (c.rho_mem[newest] * inner(y, y)), 1.0)
        r = tmap(lambda q: gamma * q, q)
    else:
        r = _precondition_tangent(solver, c.X, q)

    def second(t, r):
        tt = m - 1 - t  # oldest stored first
        i = (c.n_pairs - 1 - tt) % m
        b = c.rho_mem[i] * inner(ta.take(c.Y_mem, i), r)
        coef = jnp.where(tt < c.n_mem, alphas[tt] - b, 0.0)
        return tmap(lambda r, s: r + coef * s, r, ta.take(c.S_mem, i))

    return tmap(jnp.negative, S.proj(c.X, jax.lax.fori_loop(0, m, second, r)))


def _direction(solver, c: State):
    """``(η, slope tr(Rᵀη), restart, initial step guess)`` for CG and L-BFGS."""
    if solver.method == "cg":
        slope = _trace(c.G, c.eta)
        restart = ~(slope < 0) | c.retrying
        eta = tmap(lambda x, e: jnp.where(restart, -x, e), c.xi, c.eta)
        slope = jnp.where(restart, -_trace(c.G, c.xi), slope)
        return eta, slope, restart, jnp.where(c.it > 0, _interpolated_step(c, slope, c.step), c.step)
    eta = _lbfgs_direction(solver, c)
    slope = _trace(c.G, eta)
    restart = ~(slope < 0) | c.retrying
    if solver.preconditioner is not None:  # the preconditioned gradient only when needed (a host solve)
        eta = jax.lax.cond(restart, lambda: -_precondition_tangent(solver, c.X, c.xi), lambda: eta)
    else:
        eta = tmap(lambda x, e: jnp.where(restart, -x, e), c.xi, eta)
    slope = jnp.where(restart, _trace(c.G, eta), slope)
    # unit step once the memory (or the preconditioner) sets the scale, unless the last decrease
    # predicts a shorter one (with P, unit steps overshot: 3.2 → 1.0 trials per iteration on fandisk)
    unit = jnp.minimum(1.0, _interpolated_step(c, slope, 1.0))
    return eta, slope, restart, jnp.where((c.n_mem > 0) | (solver.preconditioner is not None), unit, c.step)


def _bb_search(solver, F, c: State):
    """Nonmonotone Armijo backtracking along ``−ξ`` from the BB step: ``(X_new, τ, ok, n_evals)``."""
    S = solver.manifold
    eta = tmap(jnp.negative, c.xi)
    slope = -_trace(c.G, c.xi)
    tau0 = jnp.minimum(c.step, solver.max_move / S.norm(c.X, eta))
    armijo = lambda tau, f: jnp.isfinite(f) & (f <= c.C + solver.c1 * tau * slope)  # noqa: E731

    along = lambda t: S.retract(c.X, tmap(lambda e: t * e, eta))  # noqa: E731

    def body(s):
        tau, _, n = s
        return 0.5 * tau, F(along(0.5 * tau)), n + 1

    cond = lambda s: ~armijo(s[0], s[1]) & (s[2] < solver.ls_max_evals)  # noqa: E731
    tau, f_acc, n = jax.lax.while_loop(cond, body, (tau0, F(along(tau0)), jnp.ones((), jnp.int32)))
    ok = armijo(tau, f_acc) & (slope < 0)
    tau = jnp.where(ok, tau, 0.0)
    return along(tau), tau, ok, n


def step(solver, fn, args, c: State) -> State:
    """One iteration; on a failed or non-finite step the iterate is kept and ``status`` set."""
    S, method = solver.manifold, solver.method
    F = lambda X: fn(X, args)[0]  # noqa: E731
    if method == "bb":
        eta_used, restart = tmap(jnp.negative, c.xi), jnp.zeros((), bool)
        X_new, tau, ok, n_ls = _bb_search(solver, F, c)
    else:
        eta_used, slope, restart, guess = _direction(solver, c)
        X_new, tau, ok, n_ls = _wolfe_search(solver, F, args, c, eta_used, slope, guess, c.history.value[0])
    (F_new, aux_new), G_new = _value_and_grad(fn, args)(X_new)
    xi_new, gn_new, G_new = _gradients(solver, X_new, G_new)
    finite = jnp.isfinite(F_new) & ta.all_finite(G_new) & ta.all_finite(X_new)
    good = ok & finite
    it = c.it + 1
    conv = _converged_grad(solver, gn_new, F_new)
    conv = conv | ((solver.xtol > 0) & ok & (tau * S.norm(c.X, eta_used) <= solver.xtol))
    if solver.stall_test:  # relative decrease over the last ftol_window iterations ≤ ftol
        window = solver.ftol_window.astype(jnp.int32)
        past = c.recent[(it - window) % c.recent.shape[0]]
        conv = conv | ((it >= window) & ok & (past - F_new <= solver.ftol * jnp.abs(F_new)))
    # a failed search along a CG / L-BFGS direction is retried along −ξ (a reset) before giving up; a failed retry
    # ends the run (it used to retry the same search until max_iters: e.g. 767 idle iterations, then "max_iters")
    retry = ~ok & ~restart if method != "bb" else jnp.zeros((), bool)
    status = jnp.where(retry, -1, jnp.where(~ok, Status.LINE_SEARCH_FAILED, jnp.where(
        ~finite, Status.NON_FINITE, jnp.where(conv, Status.CONVERGED, -1)))).astype(jnp.int32)
    status = _out_of_budget(solver, status, it)
    eta_next, step_next, C_next, Q_next = c.eta, tau, F_new, c.Q
    if method == "cg":
        T_xi, T_eta = S.transport_pair(X_new, c.xi, eta_used)
        beta = jnp.maximum(_trace(G_new, tmap(jnp.subtract, xi_new, T_xi)) / _trace(c.G, c.xi), 0.0)
        beta = jnp.where(jnp.isfinite(beta), beta, 0.0)
        eta_next = tmap(lambda x, xn, te: jnp.where(retry, -x, -xn + beta * te), c.xi, xi_new, T_eta)
    elif method == "bb":
        Sd, Yd = tmap(jnp.subtract, X_new, c.X), tmap(jnp.subtract, xi_new, c.xi)
        MS = S.mv(Sd)
        sy, ss, yy = jnp.abs(_trace(MS, Yd)), _trace(MS, Sd), _trace(Yd, S.mv(Yd))
        bb = jnp.where(it % 2 == 1, ss / sy, sy / yy)
        cap = solver.max_move / jnp.maximum(S.norm(X_new, xi_new), jnp.finfo(ta.dtype_of(X_new)).tiny)
        step_next = jnp.where(jnp.isfinite(bb) & (bb > 0), jnp.minimum(bb, cap), tau)
        eta_next = xi_new
        Q_next = solver.bb_gamma * c.Q + 1.0
        C_next = (solver.bb_gamma * c.Q * c.C + F_new) / Q_next
    keep = lambda new, old: ta.where(good, new, old)  # noqa: E731
    S_mem, Y_mem, rho_mem, n_mem, n_pairs = c.S_mem, c.Y_mem, c.rho_mem, c.n_mem, c.n_pairs
    if method == "lbfgs":
        m = rho_mem.shape[0]
        n_mem = jnp.where(restart | retry, 0, n_mem)  # a reset empties the memory before the new pair
        n_pairs = jnp.where(restart | retry, 0, n_pairs)
        s_new, y_new = tmap(lambda e: tau * e, eta_used), tmap(jnp.subtract, xi_new, c.xi)
        sy = S.inner(X_new, s_new, y_new)
        store = good & (sy > jnp.finfo(ta.dtype_of(X_new)).eps * S.norm(X_new, s_new) * S.norm(X_new, y_new))
        slot = n_pairs % m  # written in place (a select over the whole (m, n, k) buffer would copy it)
        S_mem = ta.set_at(S_mem, slot, ta.where(store, s_new, ta.take(S_mem, slot)))
        Y_mem = ta.set_at(Y_mem, slot, ta.where(store, y_new, ta.take(Y_mem, slot)))
        rho_mem = rho_mem.at[slot].set(jnp.where(store, 1.0 / sy, rho_mem[slot]))
        n_mem = jnp.where(store, jnp.minimum(n_mem + 1, m), n_mem)
        n_pairs = jnp.where(store, n_pairs + 1, n_pairs)
    F_rec = keep(F_new, c.F)
    X_rec = keep(X_new, c.X)
    gn_rec = keep(gn_new, c.gnorm)
    return State(
        X=X_rec, F=F_rec, G=keep(G_new, c.G), xi=keep(xi_new, c.xi), gnorm=gn_rec,
        eta=ta.where(good | retry, eta_next, c.eta), step=keep(step_next, c.step), F_prev=c.F,
        C=keep(C_next, c.C), Q=keep(Q_next, c.Q), it=it, status=status,
        history=c.history.record(it, F_rec, gn_rec, tau, _watch(solver, X_rec)),
        recent=c.recent.at[it % c.recent.shape[0]].set(F_rec),
        n_fevals=c.n_fevals + n_ls + 1, n_restarts=c.n_restarts + (restart | retry).astype(jnp.int32),
        S_mem=S_mem, Y_mem=Y_mem, rho_mem=rho_mem, n_mem=n_mem, n_pairs=n_pairs, retrying=retry,
        aux=jax.tree_util.tree_map(keep, aux_new, c.aux),
    )
