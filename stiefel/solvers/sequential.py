"""Column-by-column optimisation (thesis §6.4, Algorithm 6; docs/maths.md §2).

For a column-separable objective ``F(X) = Σ_j f(x_j)``, column ``m+1`` minimises
``f`` over ``V_Φ ∩ E_M = {x : ΦᵀMx = 0, xᵀMx = 1}``, ``Φ = [x_1 … x_m]``.
Each column is one pure ``lax.while_loop`` (compiled once: ``Φ`` is kept at
its full width ``(n, k)`` with zero columns for those not yet found), stepping
along the periodic retraction ``x ← cos τ · x + sin τ · d`` (``dᵀMd = 1``)
with τ from the strong Armijo–Wolfe line search, ``τ ≤ π/2`` (Cor. 6.4.25).

Directions (``direction=``):

* ``"gd"`` — ``d = −grad/‖grad‖_M`` (Algorithm 6 as printed);
* ``"momentum"`` — the thesis's acceleration (after Siegel 2019): momentum
  ``β_i = (i−1)/(i+2)`` on the transported previous direction, restarted to
  the plain gradient whenever it is not a descent direction or the
  objective did not decrease;
* ``"cg"`` (default) — Polak–Ribière+ conjugate gradients, restart on non-descent.

With ``preconditioner=`` (e.g. ``shifted_inverse(W, M, σ)`` ≈ inverse Hessian)
the gradient is taken in the preconditioned metric (see
``stiefel.solvers.preconditioning``); the reported gradient norm is always ``‖grad‖_M``.
"""

from __future__ import annotations

import dataclasses
import time
from types import SimpleNamespace
from typing import Callable, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..runtime.compilation import is_traced, run_compiled
from .driver import _stopped
from ..errors import RankDeficientError, ShapeError, StiefelError
from .linesearch import along_curve, strong_wolfe
from ..manifolds.manifold import GeneralizedStiefel
from ..linalg.operators import LinearOperator, as_operator
from .preconditioning import PRECONDITIONING_MODES, as_preconditioner, constrained_preconditioned_gradient
from ..manifolds.product import Product
from ..result import History, SequentialResult, Status
from ..validation import (check_count, check_finite, check_full_rank, check_nonnegative, check_number, check_wolfe, is_integer)

__all__ = ["SequentialConstraint", "SequentialOptions", "minimize_sequential", "DIRECTIONS"]

DIRECTIONS = ("cg", "momentum", "gd")


class SequentialConstraint(eqx.Module):
    """``{x : ΦᵀMx = 0, xᵀMx = 1}`` (docs/maths.md §2) with ``ΦᵀMΦ = I`` on the active columns.

    ``Phi`` has shape ``(n, c)``; columns that are zero impose no constraint, so a
    fixed-width ``Phi`` can hold the columns found so far.
    """

    op: LinearOperator
    Phi: Float[Array, "n c"]

    def __init__(self, M, Phi):
        self.op = as_operator(M)
        self.Phi = jnp.asarray(Phi)

    def _complement(self, y):
        """``(I − ΦΦᵀM) y``."""
        return y - self.Phi @ (self.Phi.T @ self.op.mv(y))

    def project(self, y: Float[Array, " n"]) -> Float[Array, " n"]:
        """Projection onto the set: ``proj_E((I − ΦΦᵀM)y)``, ``proj_E(y) = y/√(yᵀMy)`` (Rem. 6.4.14)."""
        z = self._complement(y)
        return z / jnp.sqrt(jnp.dot(z, self.op.mv(z)))

    def proj(self, x, v):
        """Tangent projection ``(I − ΦΦᵀM − xxᵀM) v`` at ``x``."""
        Mv = self.op.mv(v)
        return v - self.Phi @ (self.Phi.T @ Mv) - x * jnp.dot(x, Mv)

    def inner(self, x, a, b):
        """``aᵀMb`` (both metrics coincide for one column)."""
        return jnp.dot(a, self.op.mv(b))

    def egrad_to_rgrad(self, x, g):
        """``P M⁻¹ g`` with ``P`` the tangent projector (docs/maths.md §2)."""
        return self.proj(x, self.op.solve(g))

    def retract(self, x, z):
        """Periodic retraction ``cos‖z‖_M x + sin‖z‖_M z/‖z‖_M`` (Def. 6.4.20)."""
        from ..manifolds.retractions import periodic

        return periodic(self.op, x[:, None], z[:, None])[:, 0]

    def random_point(self, key) -> Float[Array, " n"]:
        y = jax.random.normal(key, (self.Phi.shape[0],), dtype=self.Phi.dtype)
        return self.project(y)


@dataclasses.dataclass(frozen=True)
class SequentialOptions:
    """Static options of ``minimize_sequential`` (see its docstring)."""

    direction: str = "cg"
    gtol: float = 1e-6
    xtol: float = 0.0
    max_iters: int = 1000
    c1: float = 1e-4
    c2: float = 0.1
    ls_max_evals: int = 30
    max_step: float = float(np.pi / 2)
    precondition: str = "residual"

    def __post_init__(self):
        _check_options(self)


def _check_options(o) -> None:
    """The numeric options of ``minimize_sequential`` in range (``ParameterError``)."""
    check_count("max_iters", o.max_iters)
    check_count("ls_max_evals", o.ls_max_evals)
    check_nonnegative("gtol", o.gtol)
    check_nonnegative("xtol", o.xtol)
    check_wolfe(o.c1, o.c2)
    check_number("max_step", o.max_step, low=0, high=float(np.pi), low_open=True)


class _Carry(NamedTuple):
    x: jax.Array
    f: jax.Array
    r: jax.Array  # tangent residual: rᵀz = ∇f(x)ᵀz for tangent z, small near a critical point
    xi: jax.Array  # search gradient (preconditioned if P given)
    gnorm: jax.Array  # ‖grad‖_M
    d: jax.Array  # previous direction (unnormalised)
    f_prev: jax.Array
    step: jax.Array
    since_restart: jax.Array
    it: jax.Array
    status: jax.Array
    history: History
    n_fevals: jax.Array
    n_restarts: jax.Array


def _column_core(f, op: LinearOperator, P, Phi, active, x0, budget, opts: SequentialOptions):
    """Minimise ``f`` on ``{ΦᵀMx = 0, xᵀMx = 1}`` from ``x0`` (already on the set) in at most ``budget``
    (a runtime int32, ≤ ``opts.max_iters``) iterations."""
    S = SequentialConstraint.__new__(SequentialConstraint)
    object.__setattr__(S, "op", op)
    object.__setattr__(S, "Phi", Phi)
    value_and_grad = jax.value_and_grad(f)
    dtype = x0.dtype
    max_step = jnp.asarray(opts.max_step, dtype)
    if P is not None and opts.precondition == "metric":
        MPhi = op.mv(Phi)
        PMPhi = P(MPhi)
        act = jnp.concatenate([active, jnp.ones((1,), dtype)])

    def gradients(x, g):
        rg = S.egrad_to_rgrad(x, g)
        rg = S.proj(x, rg)  # a second projection removes the rounding left by the first
        gn = jnp.sqrt(jnp.maximum(S.inner(x, rg, rg), 0.0))
        r = op.mv(rg)
        if P is None:
            return rg, gn, r
        if opts.precondition == "residual":
            return S.proj(x, P(r[:, None])[:, 0]), gn, r
        Mx = op.mv(x)
        MC = jnp.concatenate([MPhi, Mx[:, None]], axis=1)
        PMC = jnp.concatenate([PMPhi, P(Mx[:, None])], axis=1)
        xi = constrained_preconditioned_gradient(P, MC, PMC, act, g)
        return S.proj(x, xi), gn, r

    f0, g0 = value_and_grad(x0)
    xi0, gn0, r0 = gradients(x0, g0)
    finite0 = jnp.isfinite(f0) & jnp.all(jnp.isfinite(g0))
    status0 = jnp.where(~finite0, Status.NON_FINITE, jnp.where(gn0 <= opts.gtol, Status.CONVERGED,
                                                                jnp.where(budget <= 0, Status.MAX_ITERS, -1)))
    carry0 = _Carry(
        x=x0, f=f0, r=r0, xi=xi0, gnorm=gn0, d=-xi0, f_prev=f0, step=max_step,
        since_restart=jnp.zeros((), jnp.int32), it=jnp.zeros((), jnp.int32),
        status=jnp.asarray(status0, jnp.int32),
        history=History.empty(opts.max_iters + 1, dtype).record(0, f0, gn0, 0.0),
        n_fevals=jnp.ones((), jnp.int32), n_restarts=jnp.zeros((), jnp.int32),
    )

    def body(c: _Carry) -> _Carry:
        d = c.d
        slope_raw = jnp.dot(c.r, d)
        restart = ~(slope_raw < 0) | (c.since_restart == 0)
        d = jnp.where(restart, -c.xi, d)
        d = S.proj(c.x, d)
        d_norm = jnp.sqrt(jnp.maximum(S.inner(c.x, d, d), 0.0))
        d_hat = d / jnp.where(d_norm > 0, d_norm, 1.0)
        slope = jnp.dot(c.r, d_hat)
        guess = jnp.where(c.it > 0, 2.02 * (c.f - c.f_prev) / slope, max_step)
        tau0 = jnp.where(jnp.isfinite(guess) & (guess > 0), jnp.minimum(guess, max_step), max_step)
        phi = along_curve(f, lambda t: jnp.cos(t) * c.x + jnp.sin(t) * d_hat)
        ls = strong_wolfe(phi, c.f, slope, tau0, c1=opts.c1, c2=opts.c2, max_step=max_step,
                          max_evals=opts.ls_max_evals, value_scale=f0)
        tau = ls.step
        x_new = S.project(jnp.cos(tau) * c.x + jnp.sin(tau) * d_hat)  # re-orthonormalise against Φ
        f_new, g_new = value_and_grad(x_new)
        xi_new, gn_new, r_new = gradients(x_new, g_new)
        ok = ls.accepted
        finite = jnp.isfinite(f_new) & jnp.all(jnp.isfinite(g_new)) & jnp.all(jnp.isfinite(x_new))
        good = ok & finite
        # a failed search along an accelerated direction is retried along −grad before giving up
        retry = ~ok & ~restart & (opts.direction != "gd")
        it = c.it + 1
        conv = (gn_new <= opts.gtol) | ((opts.xtol > 0) & ok & (tau <= opts.xtol))
        status = jnp.where(
            retry, jnp.where(it >= budget, Status.MAX_ITERS, -1),
            jnp.where(~ok, Status.LINE_SEARCH_FAILED,
                      jnp.where(~finite, Status.NON_FINITE,
                                jnp.where(conv, Status.CONVERGED,
                                          jnp.where(it >= budget, Status.MAX_ITERS, -1)))),
        ).astype(jnp.int32)
        # next direction (unnormalised), transported by projection onto the new tangent space
        d_moved = S.proj(x_new, d)
        if opts.direction == "cg":
            beta = jnp.dot(r_new, xi_new - S.proj(x_new, c.xi)) / jnp.dot(c.r, c.xi)
            beta = jnp.where(jnp.isfinite(beta), jnp.maximum(beta, 0.0), 0.0)
            d_next = -xi_new + beta * d_moved * (jnp.sqrt(jnp.dot(c.r, c.xi)) / jnp.maximum(d_norm, 1e-300)) ** 0
        elif opts.direction == "momentum":
            i = (c.since_restart + 1).astype(dtype)
            beta = (i - 1.0) / (i + 2.0)
            d_next = -xi_new + beta * d_moved
        else:
            d_next = -xi_new
        since = jnp.where(retry, 0, jnp.where(f_new <= c.f, (jnp.where(restart, 0, c.since_restart) + 1), 0))
        since = jnp.where(opts.direction == "gd", 0, since).astype(jnp.int32)
        keep = lambda new, old: jnp.where(good, new, old)  # noqa: E731
        f_rec = jnp.where(good, f_new, c.f)
        g_rec = jnp.where(good, gn_new, c.gnorm)
        return _Carry(
            x=keep(x_new, c.x), f=f_rec, r=keep(r_new, c.r), xi=keep(xi_new, c.xi), gnorm=g_rec,
            d=jnp.where(good, d_next, -c.xi), f_prev=jnp.where(good, c.f, c.f_prev),
            step=jnp.where(good, tau, c.step), since_restart=since, it=it, status=status,
            history=c.history.record(it, f_rec, g_rec, tau),
            n_fevals=c.n_fevals + ls.n_evals + 1,
            n_restarts=c.n_restarts + (restart | retry).astype(jnp.int32),
        )

    c = jax.lax.while_loop(lambda c: c.status < 0, body, carry0)
    return c.x, c.f, c.gnorm, c.it, c.status, c.history, c.n_fevals, c.n_restarts


def minimize_sequential(
    f: Callable,
    M,
    k: int,
    *,
    X0=None,
    key=None,
    seed: int = 0,
    retraction: str = "periodic",
    direction: str = "cg",
    preconditioner=None,
    precondition: str = "residual",
    gtol: float = 1e-6,
    xtol: float = 0.0,
    max_iters: int = 1000,
    c1: float = 1e-4,
    c2: float = 0.1,
    ls_max_evals: int = 30,
    max_step: float = float(np.pi / 2),
    dtype=None,
    throw: bool = False,
    callback: Callable | None = None,
    budget: int | None = None,
    stop=None,
) -> SequentialResult:
    """Find ``k`` M-orthonormal columns one at a time (thesis Algorithm 6).

    Column ``j`` minimises ``f`` over ``{x : x_iᵀMx = 0 (i < j), xᵀMx = 1}``.

    Args:
      f: column objective ``x (n,) -> scalar`` (JAX-differentiable). For an
        even ``f`` (``f(−x) = f(x)``, true of every CMM energy) steps beyond π/2
        are never needed (Cor. 6.4.25); for other ``f`` pass ``max_step=np.pi``.
      M: SPD metric matrix (1-D diagonal, dense, ``scipy.sparse``) or operator.
      k: number of columns, ``1 ≤ k ≤ n``.
      X0: optional start ``(n, k)``; column ``j`` starts from ``X0[:, j]`` projected
        onto the constraint set. Default: random Gaussian starts from ``key``/``seed``.
      retraction: only ``"periodic"`` (the M-geodesic of the ellipsoid) is offered:
        it is exact, π-periodic for even objectives and costs nothing extra.
      direction: ``"cg"`` (default), ``"momentum"`` (the thesis's restart
        acceleration) or ``"gd"`` (Algorithm 6 as printed).
      preconditioner: as in ``stiefel.minimize`` (e.g. ``shifted_inverse(W, M, σ)``).
      precondition: ``"residual"`` (P on one column per iteration) or ``"metric"`` (the
        exact gradient in the P⁻¹-metric with the constraints as multipliers).
      gtol: stop a column when ``‖grad‖_M ≤ gtol``; xtol: or when the step τ ≤ xtol (0: off).
      max_iters: iteration limit: the total number of iterations of the call, shared fairly by the
        columns: column j may use ⌈left / (k − j)⌉ of the ``left`` iterations columns 0 … j−1 did not
        use (what a column leaves rolls over; one that cannot converge does not starve the others; a
        column that gets none keeps its projected start, 0 iterations, status ``max_iters``). An integer
        in ``[1, 2³¹ − 1]``; also the compiled loop bound (each column's history has ``max_iters + 1``
        entries).
      c1, c2, ls_max_evals, max_step: line search parameters (``0 < c1 < c2 < 1``, ``0 < max_step ≤ π``).
      dtype: computation dtype (default float64 when x64 is enabled).
      throw: raise ``SolverError`` if a column ends with ``line_search_failed`` / ``non_finite``.
      callback: optional host function ``callback(j, column_result_dict)`` called after
        each column (progress reporting, saving partial results).
      budget: optional total ``0 ≤ budget ≤ max_iters`` used instead of ``max_iters`` without
        recompiling (warm-started stages sharing one total pass what is left).
      stop: optional ``threading.Event`` (or a callable returning True) checked before each column; once
        it is set — or after a ``KeyboardInterrupt`` during a column — the remaining columns keep their
        projected starts (status ``interrupted``, 0 iterations, value NaN) and the call returns.

    Every option is checked before any work (``ParameterError``; ``RankDeficientError`` for an ``X0``
    with dependent columns).

    Returns:
      ``SequentialResult`` (per-column status, iterations, history and timings).

    Not differentiable: called under ``jax.grad``/``jax.jvp``/``jit`` it raises ``StiefelError``
    (use ``stiefel.minimize``, whose solutions have implicit derivatives).
    """
    if direction not in DIRECTIONS:
        raise StiefelError(f"unknown direction {direction!r}; choose one of {DIRECTIONS}")
    if isinstance(M, (GeneralizedStiefel, Product)):
        raise StiefelError(f"minimize_sequential takes the matrix M (and k), not a manifold ({type(M).__name__}); "
                           "pass S.op for a GeneralizedStiefel S (a stiefel.Product is not supported)")
    if is_traced(f, M, X0, preconditioner):
        raise StiefelError(
            "minimize_sequential cannot run inside jax.grad/jax.jvp/jit (it is a host loop over columns and "
            "has no implicit derivative); differentiate a block solve instead: stiefel.minimize(F, S, X0, args=θ)"
        )
    if precondition not in PRECONDITIONING_MODES:
        raise StiefelError(f"unknown precondition mode {precondition!r}; choose one of {PRECONDITIONING_MODES}")
    if retraction != "periodic":
        raise StiefelError("minimize_sequential steps along the periodic retraction only (retraction='periodic')")
    _check_options(SimpleNamespace(max_iters=max_iters, ls_max_evals=ls_max_evals, gtol=gtol, xtol=xtol, c1=c1,
                                   c2=c2, max_step=max_step))
    max_iters = int(max_iters)
    budget = max_iters if budget is None else check_count("budget", budget, 0, max_iters,
                                                          high_label=f"max_iters = {max_iters}")
    op = as_operator(M, dtype=dtype)
    n = op.n
    if not is_integer(k) or not 1 <= int(k) <= n:
        raise ShapeError(f"k must be an integer with 1 ≤ k ≤ n = {n}, got k = {k!r}")
    k = int(k)
    dt = op.diagonal().dtype
    if X0 is not None:
        X0 = jnp.asarray(X0, dtype=dt)
        if X0.shape != (n, k):
            raise ShapeError(f"X0 must have shape (n, k) = {(n, k)}, got {X0.shape}")
        check_finite("X0", X0)
        check_full_rank("X0", X0.T @ op.mv(X0))
    if key is None:
        key = jax.random.PRNGKey(seed)
    P = as_preconditioner(preconditioner)
    opts = SequentialOptions(direction=direction, gtol=float(gtol), xtol=float(xtol), max_iters=max_iters,
                             c1=float(c1), c2=float(c2), ls_max_evals=int(ls_max_evals), max_step=float(max_step),
                             precondition=precondition)

    Phi = jnp.zeros((n, k), dtype=dt)
    active = jnp.zeros((k,), dtype=dt)
    keys = jax.random.split(key, k)
    out = {name: [] for name in ("values", "grad_norm", "iterations", "status", "n_fevals", "n_restarts")}
    hist = []
    times, compile_total, t_start = [], 0.0, time.perf_counter()
    left = budget  # iterations the remaining columns share (fairly, see max_iters)
    stopped = False
    for j in range(k):
        S = SequentialConstraint(op, Phi)
        y = X0[:, j] if X0 is not None else jax.random.normal(keys[j], (n,), dtype=dt)
        if X0 is not None:
            z = S._complement(y)
            if not float(jnp.dot(z, op.mv(z))) > 1e-16 * float(jnp.dot(y, op.mv(y))):
                raise RankDeficientError(
                    f"X0[:, {j}] lies in the span of the previous columns (found so far); "
                    "cannot start there: give linearly independent start columns"
                )
        x0 = S.project(y)
        share = -(-left // (k - j))  # ⌈left / columns to go⌉: a fair part of what is left
        stopped = stopped or _stopped(stop)
        if not stopped:
            try:
                res, t_compile, t_run = run_compiled(_column_core, f, op, P, Phi, active, x0,
                                                     jnp.asarray(share, jnp.int32), opts)
            except KeyboardInterrupt:
                stopped = True
        if stopped:  # this column and the later ones keep their projected starts
            zero = jnp.asarray(0, jnp.int32)
            res = (x0, jnp.asarray(np.nan, dt), jnp.asarray(np.nan, dt), zero,
                   jnp.asarray(Status.INTERRUPTED, jnp.int32), History.empty(opts.max_iters + 1, dt), zero, zero)
            t_compile, t_run = 0.0, 0.0
        x, fx, gn, it, st, h, nf, nr = res
        left -= int(it)
        compile_total += t_compile
        times.append(t_run)
        Phi = Phi.at[:, j].set(x)
        active = active.at[j].set(1.0)
        for name, v in zip(("values", "grad_norm", "iterations", "status", "n_fevals", "n_restarts"),
                           (fx, gn, it, st, nf, nr)):
            out[name].append(v)
        hist.append(h)
        if callback is not None and not stopped:
            callback(j, {"x": np.asarray(x), "value": float(fx), "grad_norm": float(gn),
                         "iterations": int(it), "status": Status.name(st), "time": t_run})
    history = History(*(jnp.stack([getattr(h, fld) for h in hist]) for fld in ("value", "grad_norm", "step", "monitor")))
    values = jnp.stack(out["values"])
    result = SequentialResult(
        x=Phi, value=jnp.sum(values), values=values, grad_norm=jnp.stack(out["grad_norm"]),
        iterations=jnp.stack(out["iterations"]), status=jnp.stack(out["status"]), history=history,
        stats={"n_fevals": np.asarray(jnp.stack(out["n_fevals"])),
               "n_restarts": np.asarray(jnp.stack(out["n_restarts"])),
               "dist_to_manifold": float(jnp.max(jnp.abs(Phi.T @ op.mv(Phi) - jnp.eye(k, dtype=dt))))},
        wall_time=time.perf_counter() - t_start - compile_total, compile_time=compile_total,
        column_times=tuple(times),
    )
    if throw:
        result.raise_for_status()
    return result
