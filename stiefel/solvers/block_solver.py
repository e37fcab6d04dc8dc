"""The block solver front end: ``minimize`` (checked, timed) and ``solve`` (pure) over the
whole matrix ``X ∈ S_M``.

Both run the optimistix minimisers of ``stiefel.solvers.minimisers`` (``RiemannianCG``,
``RiemannianLBFGS``, ``RiemannianBB``; the methods are described there) through
``optx.minimise`` with ``stiefel.RiemannianImplicitAdjoint``: one implementation, and every
solve is differentiable with respect to ``args``, arrays closed over by ``F`` and ``M``
(docs/maths.md §9). All accept a preconditioner (``stiefel.solvers.preconditioning``): the search
direction is then the gradient in the metric ``tr(Z1ᵀP⁻¹Z2)``, still a guaranteed descent
direction. The reported gradient norm is always the manifold metric's, so runs are comparable.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ..runtime.compilation import is_traced
from .driver import DEFAULT_INTERVAL, CallbackError, run_chunked
from ..errors import ParameterError, StiefelError
from ..derivatives.implicit import RiemannianImplicitAdjoint
from ..manifolds.manifold import GeneralizedStiefel
from .objective_form import takes_args
from .minimisers import STALL_WINDOW_MAX, RiemannianBB, RiemannianCG, RiemannianLBFGS, settled_status
from .preconditioning import PRECONDITIONING_MODES, as_preconditioner
from ..result import Result, Status
from ..validation import check_count, check_nonnegative, check_positive, check_unit_interval, check_wolfe

__all__ = ["minimize", "solve", "solver_for", "BlockOptions", "METHODS", "DEFAULT_METHOD", "DEFAULT_MAX_ITERS"]

METHODS = ("cg", "bb", "lbfgs")
#: the defaults of ``minimize`` and ``BlockOptions``, chosen on the panel of ``python -m bench default-method``
#: (docs/benchmarks/default-method.md): unpreconditioned L-BFGS converged on 38 of 38 runs there, to the optimum
#: within 1e-8, in up to 4701 iterations (n = 10⁴); CG (34 of 40) and BB (38 of 40) failed searches or hit the cap
DEFAULT_METHOD = "lbfgs"
DEFAULT_MAX_ITERS = 10000


@dataclasses.dataclass(frozen=True)
class BlockOptions:
    """Options of the pure block solver ``solve`` (see ``minimize``; the same defaults: L-BFGS, at most 10000
    iterations); mapped onto a ``stiefel.RiemannianCG`` / ``RiemannianLBFGS`` / ``RiemannianBB`` by ``solver_for``.
    ``c2`` = 0.9 suits the default L-BFGS; pass ``c2=0.1`` with ``method="cg"`` (as ``minimize`` does)."""

    method: str = DEFAULT_METHOD
    gtol: float = 1e-6
    xtol: float = 0.0
    max_iters: int = DEFAULT_MAX_ITERS
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
        if self.method not in METHODS:
            raise StiefelError(f"unknown method {self.method!r}; choose one of {METHODS}")
        if self.precondition not in PRECONDITIONING_MODES:
            raise StiefelError(f"unknown precondition mode {self.precondition!r}; "
                               f"choose one of {PRECONDITIONING_MODES}")
        _check_options(self)


def _check_options(o) -> None:
    """Every numeric option of ``BlockOptions`` (or of ``minimize``'s keywords) in range (``ParameterError``)."""
    check_count("max_iters", o.max_iters)
    check_count("ls_max_evals", o.ls_max_evals)
    check_count("ftol_window", o.ftol_window, 1, STALL_WINDOW_MAX)
    check_count("memory (L-BFGS pairs)", o.memory)
    for name in ("gtol", "xtol", "ftol"):
        check_nonnegative(name, getattr(o, name))
    check_wolfe(o.c1, o.c2)
    check_positive("init_step", o.init_step)
    check_positive("max_move", o.max_move, finite=False)
    check_unit_interval("bb_gamma", o.bb_gamma, closed=True)


class _NoArgs(eqx.Module):
    """``F(X)`` as optimistix's ``fn(X, args)`` (a pytree: F's arrays stay traced leaves)."""

    F: Callable

    def __call__(self, X, args):
        return self.F(X)


class _Line(eqx.Module):
    """An objective's fast line evaluator ``F.line(manifold, X, η[, args])`` in the solvers' form."""

    F: Callable
    with_args: bool = eqx.field(static=True)

    def __call__(self, manifold, X, eta, args):
        return self.F.line(manifold, X, eta, args) if self.with_args else self.F.line(manifold, X, eta)


def solver_for(manifold: GeneralizedStiefel, options: BlockOptions, *, F=None, preconditioner=None,
               monitor=None, stall=None, with_args: bool = False, history: bool = True, budget=None):
    """The optimistix minimiser that ``options`` describe (``stall``: traced ``(ftol, ftol_window)``;
    ``budget``: the runtime iteration limit, ≤ ``options.max_iters``)."""
    o = options
    ftol, window = (o.ftol, o.ftol_window) if stall is None else stall
    line = _Line(F, with_args) if F is not None and callable(getattr(F, "line", None)) else None
    common = dict(rtol=0.0, atol=o.gtol, preconditioner=preconditioner, precondition=o.precondition, c1=o.c1,
                  c2=o.c2, ls_max_evals=int(o.ls_max_evals), init_step=o.init_step, max_move=o.max_move,
                  ftol=ftol, ftol_window=window, stall_test=o.ftol > 0, xtol=o.xtol, monitor=monitor,
                  history=int(o.max_iters) + 1 if history else 0, line=line, budget=budget)
    if o.method == "lbfgs":
        return RiemannianLBFGS(manifold, memory=int(o.memory), **common)
    if o.method == "bb":
        return RiemannianBB(manifold, bb_gamma=o.bb_gamma, **common)
    return RiemannianCG(manifold, **common)


def _run(fn, solver, X0, args, max_steps: int, adjoint):
    """``optx.minimise`` with the solver, mapped to ``Result``'s fields (jittable, vmappable)."""
    sol = optx.minimise(fn, solver, X0, args, max_steps=max_steps, adjoint=adjoint, throw=False)
    st = sol.stats
    status = jnp.where(st["status"] >= 0, st["status"], Status.MAX_ITERS).astype(jnp.int32)
    stats = {key: st[key] for key in ("n_fevals", "n_grads", "n_restarts", "dist_to_manifold", "round_off_floor",
                                      "at_floor")}
    return sol.value, st["value"], st["grad_norm"], st["num_steps"], status, st["history"], stats


def solve(F: Callable, manifold: GeneralizedStiefel, X0, options: BlockOptions = BlockOptions(), *,
          preconditioner: Callable | None = None, monitor: Callable | None = None,
          adjoint: optx.AbstractAdjoint | None = None) -> Result:
    """The block solver as a pure function: jittable, vmappable (e.g. over starts or over
    parameters of ``F``) and differentiable (``RiemannianImplicitAdjoint``); no validation, no
    timing (``wall_time = compile_time = 0``). The same code as ``minimize``.

    ``preconditioner`` must already be a callable ``Y ↦ PY`` (see ``as_preconditioner``).
    """
    if not isinstance(manifold, GeneralizedStiefel):
        raise StiefelError("manifold must be a stiefel.GeneralizedStiefel (for a stiefel.Product, call "
                           "optx.minimise with stiefel.RiemannianCG and friends)")
    with_args = takes_args(F, None)  # F(X), or an optimistix-style F(X, args) called with args = None
    solver = solver_for(manifold, options, F=F, preconditioner=preconditioner, monitor=monitor, with_args=with_args)
    fn = F if with_args else _NoArgs(F)
    out = _run(fn, solver, X0, None, options.max_iters, adjoint or RiemannianImplicitAdjoint())
    X, value, gnorm, it, status, history, stats = out
    return Result(x=X, value=value, grad_norm=gnorm, iterations=it, status=status, history=history, stats=stats)


def minimize(
    F: Callable,
    manifold: GeneralizedStiefel,
    X0,
    *,
    method: str = DEFAULT_METHOD,
    preconditioner=None,
    precondition: str = "residual",
    gtol: float = 1e-6,
    xtol: float = 0.0,
    ftol: float = 0.0,
    ftol_window: int = 20,
    max_iters: int = DEFAULT_MAX_ITERS,
    c1: float = 1e-4,
    c2: float | None = None,
    ls_max_evals: int = 30,
    init_step: float = 1.0,
    max_move: float = 1.0,
    bb_gamma: float = 0.85,
    memory: int = 8,
    check: bool = True,
    throw: bool | None = None,
    monitor: Callable | None = None,
    args: Any = None,
    adjoint: optx.AbstractAdjoint | None = None,
    budget: int | None = None,
    progress: Callable | None = None,
    progress_interval: float = DEFAULT_INTERVAL,
    stop: Any = None,
) -> Result:
    """Minimise ``F(X)`` over ``X ∈ S_M`` from ``X0`` (the whole block at once).

    Args:
      F: ``X (n, k) -> scalar``, a JAX-differentiable function (gradient by ``jax.grad``), or
        ``F(X, args)`` as for ``optx.minimise`` (called with ``args``, None when not given; ``stiefel.solvers.
        objective_form``: a signature that fits neither is an ``ObjectiveSignatureError`` at the call). An objective may also define
        ``F.line(manifold, X, η)`` (``F.line(manifold, X, η, args)`` with ``args``) returning
        ``τ ↦ (F(R_X(τη)), d/dτ)`` (or None) to evaluate line-search trials faster than
        through the retraction (``objectives.CMMEnergy`` does, for the Cholesky retraction).
      manifold: a ``GeneralizedStiefel`` (its metric and retraction are used).
      X0: start, shape ``(n, k)``, on the manifold (``manifold.project_to_manifold``).
      method: ``"lbfgs"`` (Riemannian L-BFGS + strong Wolfe; the default: it converged on every problem and
        start of the panel of ``python -m bench default-method``, docs/benchmarks/default-method.md, where CG
        and BB did not), ``"cg"`` (Riemannian CG + strong Wolfe) or ``"bb"`` (BB + nonmonotone Armijo).
      preconditioner: None, a callable ``Y ↦ PY`` (P SPD), or an SPD matrix/operator
        ``K`` whose inverse is applied (e.g. ``stiefel.shifted_inverse(W, M, σ)``).
      precondition: ``"residual"`` (``proj_X(P R)``, k columns of P per iteration) or
        ``"metric"`` (the exact gradient in the P⁻¹-metric, 2k columns); see
        ``stiefel.solvers.preconditioning``.
      gtol: stop when the Riemannian gradient norm (manifold metric) is ≤ gtol. A line search that fails with
        the gradient norm at or below the round-off floor (``stats["round_off_floor"]``,
        ``stiefel.solvers.linesearch.round_off_floor``: 10·√(nk)·ε·(|F(X)| + |F(X0)|)) ends the run as
        ``converged`` with ``stats["at_floor"]`` set: a gtol below what rounding allows is reached as far as it
        can be; a search that fails above the floor ends ``line_search_failed``.
      xtol: stop when an accepted step moves X by ≤ xtol (M-norm); 0 disables.
      ftol: stop (as converged) when the objective decreased by ≤ ftol·|F| over the last
        ``ftol_window`` iterations; 0 disables. For non-smooth objectives under smoothing, where
        the gradient norm stalls above gtol.
      ftol_window: iterations over which ``ftol`` measures the decrease (1 … 64).
      max_iters: iteration limit (default 10000): the total number of iterations of this call, an integer in
        ``[1, 2³¹ − 1]``; it is also the compiled loop bound (``history`` has ``max_iters + 1`` entries).
      c1, c2: Armijo / curvature constants; ``c2`` defaults to 0.1 for ``"cg"`` (CG needs
        a tighter curvature condition than quasi-Newton methods: with 0.9 it stalled
        in tests), 0.9 for ``"lbfgs"``, and is unused by ``"bb"``; ls_max_evals:
        line-search evaluations.
      init_step: first step length in units of 1/‖grad‖; max_move: cap on τ‖η‖ per step.
      bb_gamma: Zhang–Hager averaging parameter (``"bb"``).
      memory: stored pairs (``"lbfgs"``), ≥ 1.
      check: validate ``X0`` (shape, finiteness, on the manifold to 1e-8, or to 1000 ulps in a
        lower precision: 1.2e-4 in float32).
      throw: None (default): the result carries its status and a derivative through a solve that did not
        converge raises (``RiemannianImplicitAdjoint(throw=True)``: never a silent NaN); True: also raise
        ``SolverError`` on ``line_search_failed`` / ``non_finite``; False: NaN derivatives through a
        non-converged solve, nothing raised.
      monitor: optional JAX function ``X ↦ scalar`` recorded at every iterate in
        ``history.monitor`` (e.g. the true non-smooth objective, for time-to-target curves).
      args: parameters θ passed to ``F(X, args)`` (Python floats in it are traced values, as for ``jax.jit``: a new
        value reuses the compiled solve; use them in JAX operations, not in Python ``if``). The solution is differentiable in them (and in
        arrays closed over by F, and in M) under ``jax.jvp``/``jax.grad``/``jax.jacfwd`` by implicit
        differentiation (docs/maths.md §9); call ``minimize`` inside the differentiated function. Under
        such tracing the solve is not timed separately (``wall_time = compile_time = 0``) and
        ``throw`` checks run inside the computation.
      adjoint: the ``optx`` adjoint (default ``RiemannianImplicitAdjoint(throw=throw is not False)``; pass
        ``RiemannianImplicitAdjoint(invariant=True)`` to assert ``F(XQ) = F(X)``; by default it is detected).
        A derivative through a solve that did not converge raises, or is NaN with ``throw=False``.
      budget: optional runtime limit ``0 ≤ budget ≤ max_iters`` (may be traced): warm-started stages
        sharing one total of iterations pass ``max_iters=total, budget=left`` and compile once; the
        status is ``max_iters`` when the budget ends the run.
      progress: optional ``progress(stiefel.Progress)``, called between compiled chunks of about
        ``progress_interval`` seconds (``stiefel.solvers.driver``: iteration, objective, gradient norm, elapsed
        and estimated remaining time). If it raises, the solve stops and ``stiefel.CallbackError`` is
        raised with the iterate reached in its ``result``.
      stop: optional ``threading.Event`` (or a callable returning True) checked between chunks; when set,
        the solve returns the current iterate with status ``interrupted`` — as it does on Ctrl-C
        (``KeyboardInterrupt``) during the solve. Neither adds anything to the compiled loop.

    Every option is checked before any work (``ParameterError``, naming the option, its value and
    its range; ``RankDeficientError`` for a start with dependent columns).

    Returns:
      ``Result`` with ``x, value, grad_norm, iterations, status, history, stats,
      wall_time, compile_time``.
    """
    if method not in METHODS:
        raise StiefelError(f"unknown method {method!r}; choose one of {METHODS}")
    if not isinstance(manifold, GeneralizedStiefel):
        raise StiefelError("manifold must be a stiefel.GeneralizedStiefel (for a stiefel.Product, call "
                           "optx.minimise with stiefel.RiemannianCG and friends)")
    c2 = (0.9 if method == "lbfgs" else 0.1) if c2 is None else c2
    _check_options(SimpleNamespace(max_iters=max_iters, ls_max_evals=ls_max_evals, ftol_window=ftol_window,
                                   memory=memory, gtol=gtol, xtol=xtol, ftol=ftol, c1=c1, c2=c2, init_step=init_step,
                                   max_move=max_move, bb_gamma=bb_gamma))
    check_positive("progress_interval", progress_interval)
    if budget is None:  # always a runtime limit: calls with and without one share a compilation
        budget = int(max_iters)
    check_count("budget", budget, 0, int(max_iters), high_label=f"max_iters = {max_iters}")
    if precondition not in PRECONDITIONING_MODES:
        raise StiefelError(f"unknown precondition mode {precondition!r}; choose one of {PRECONDITIONING_MODES}")
    X0 = jnp.asarray(X0, dtype=manifold.dtype)
    # Python floats in args are values, as jax.jit's arguments are: traced, so a new θ reuses the compiled solve
    # (static leaves of args would compile once per value: the README's finite difference compiled twice more)
    args = jax.tree_util.tree_map(lambda x: jnp.asarray(x) if isinstance(x, float) else x, args)
    traced = is_traced(F, manifold, X0, args, preconditioner, monitor)
    if check and not is_traced(X0):
        manifold.check_point(X0, atol=max(1e-8, 1e3 * float(jnp.finfo(manifold.dtype).eps)))
    P = as_preconditioner(preconditioner)
    opts = BlockOptions(method=method, gtol=float(gtol), xtol=float(xtol), max_iters=int(max_iters), c1=float(c1),
                        c2=float(c2), ls_max_evals=int(ls_max_evals), init_step=float(init_step),
                        max_move=float(max_move), bb_gamma=float(bb_gamma), precondition=precondition,
                        ftol=float(ftol), ftol_window=int(ftol_window), memory=int(memory))
    # tolerances, line-search constants and the stall window are traced leaves: no recompilation when they change
    with_args = takes_args(F, args)
    solver = solver_for(manifold, opts, F=F, preconditioner=P, monitor=monitor, with_args=with_args, budget=budget)
    fn = F if with_args else _NoArgs(F)
    if throw not in (None, True, False):
        raise ParameterError(f"throw must be None, True or False, got {throw!r}")
    adjoint = adjoint if adjoint is not None else RiemannianImplicitAdjoint(throw=throw is not False)
    if traced:  # inside jax.grad / jax.jvp / jit: no ahead-of-time timing, no host-side checks
        X, value, gnorm, it, status, history, stats = _run(fn, solver, X0, args, opts.max_iters, adjoint)
        if throw:
            bad = (status == Status.LINE_SEARCH_FAILED) | (status == Status.NON_FINITE)
            X = eqx.error_if(X, bad, "stiefel.minimize: the solver stopped with status line_search_failed or non_finite")
        return Result(x=X, value=value, grad_norm=gnorm, iterations=it, status=status, history=history, stats=stats)
    state, dist, t_compile, t_run, error = run_chunked(solver, fn, X0, args, opts.max_iters, progress=progress,
                                                       interval=float(progress_interval), stop=stop, method=method)
    status, floor, at_floor = settled_status(state)  # a search that failed at the round-off floor converged
    state = state._replace(status=status)
    stats = {"n_fevals": state.n_fevals, "n_grads": np.asarray(state.it) + 1, "n_restarts": state.n_restarts,
             "dist_to_manifold": dist, "round_off_floor": floor, "at_floor": at_floor}
    result = Result(x=state.X, value=state.F, grad_norm=state.gnorm, iterations=state.it, status=state.status,
                    history=state.history, stats={k: np.asarray(v) for k, v in stats.items()}, wall_time=t_run,
                    compile_time=t_compile)
    if error is not None:
        raise CallbackError(f"the progress callback raised {type(error).__name__}: {error}; the solve stopped "
                            f"after {int(state.it)} iterations (the iterate is in this error's result)",
                            result) from error
    if throw:
        result.raise_for_status()
    return result
