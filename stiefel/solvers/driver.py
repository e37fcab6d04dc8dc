"""A host loop over compiled chunks of iterations: progress reports and clean stops, no callback in the loop.

``stiefel.minimize`` runs its solver here (``run_chunked``) when it is not traced. Two programs are
compiled once per problem shape: ``init`` (the state at ``X0``) and ``advance`` (iterate until the
solver stops or the state's iteration count reaches a runtime bound). The host calls ``advance``
repeatedly, sizing each chunk so that it takes about ``interval`` seconds (the first chunk is one
iteration, then the measured time per iteration sets the next, growing at most 4× per chunk), and
between chunks it

* calls ``progress(Progress(...))`` — at most once per chunk, so at a bounded rate whatever the speed
  of an iteration;
* checks ``stop`` (a callable or a ``threading.Event``) and catches ``KeyboardInterrupt``: the solve
  ends with status ``interrupted`` and the last completed chunk's iterate.

Nothing inside the compiled loop calls Python (a ``jax.debug.callback`` or ``pure_callback`` would
keep JAX's persistent compilation cache from serving the program, ``stiefel.linalg.ffi_solve``), and the
iterates are those of one uninterrupted ``lax.while_loop``: the chunk boundaries change nothing.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Callable, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import block_steps as _steps
from ..linalg import ffi_solve
from ..runtime import program_cache
from ..runtime.compilation import compile_aot, host_array
from ..errors import SolverError
from ..result import History, Status

__all__ = ["Progress", "CallbackError", "HostMonitor", "run_chunked", "DEFAULT_INTERVAL"]

DEFAULT_INTERVAL = 0.25  # seconds per chunk: at most about four progress reports per second


class Progress(NamedTuple):
    """One progress report of a running solve (``progress=`` of ``stiefel.minimize``,
    ``compressed_modes``, ...).

    iteration: iterations done so far (over all stages of a multi-stage solve); max_iters: the cap.
    objective: the current objective (smoothed, for CMM energies); grad_norm: Riemannian gradient norm
      (ADMM: the primal residual).
    elapsed: seconds since the solve started (compilation excluded); remaining: an estimate of the
      seconds left (from the recent decrease rate of ``log grad_norm`` towards the tolerance, capped by
      the iterations left at the current speed), None when it cannot be estimated yet.
    stage, n_stages: the continuation stage (0-based) and their number (1 for a single-stage solve).
    method: the solver's name.
    """

    iteration: int
    max_iters: int
    objective: float
    grad_norm: float
    elapsed: float
    remaining: float | None
    stage: int = 0
    n_stages: int = 1
    method: str = ""

    def line(self) -> str:
        """A one-line summary: ``it 120/5000  f = 953.6  |g| = 1.2e-04  stage 4/4  3.1 s, ~1.2 s left``."""
        left = "" if self.remaining is None else f", ~{self.remaining:.1f} s left"
        stage = f"  stage {self.stage + 1}/{self.n_stages}" if self.n_stages > 1 else ""
        cap = f"/{self.max_iters}" if self.max_iters > 0 else ""
        f = f"  f = {self.objective:.7g}" if math.isfinite(self.objective) else ""  # NaN: not known (eigsh)
        g = f"  |g| = {self.grad_norm:.2e}" if math.isfinite(self.grad_norm) else ""
        return f"it {self.iteration}{cap}{f}{g}{stage}  {self.elapsed:.1f} s{left}"


class CallbackError(SolverError):
    """A ``progress`` callback raised: the solve stopped. ``result`` holds the iterate reached (status
    ``interrupted``); the callback's exception is the ``__cause__``."""

    def __init__(self, message: str, result=None):
        super().__init__(message)
        self.result = result


def _stopped(stop) -> bool:
    if stop is None:
        return False
    if isinstance(stop, threading.Event) or hasattr(stop, "is_set"):
        return bool(stop.is_set())
    return bool(stop())


class _NoAux(eqx.Module):
    """``fn(X, args)`` (a scalar) as ``(value, None)``, the form the solver's steps take (as optimistix wraps it)."""

    fn: Callable

    def __call__(self, X, args):
        return jnp.asarray(self.fn(X, args)), None


def _init(solver, fn, X0, args):
    return _steps.init_state(solver, fn, X0, args)


def _advance(solver, fn, args, state, stop_at):
    """Iterate from ``state`` while running and ``state.it < stop_at``; also ``dist_to_manifold(X)``."""
    state = jax.lax.while_loop(lambda s: (s.status < 0) & (s.it < stop_at),
                               lambda s: _steps.step(solver, fn, args, s), state)
    return state, solver.manifold.dist_to_manifold(state.X)


class _Estimate:
    """Remaining seconds from the last two reports' ``log grad_norm`` (towards ``gtol``), capped by the
    iterations left at the measured speed."""

    def __init__(self, gtol: float):
        self.gtol, self.last = gtol, None

    def __call__(self, it: int, max_iters: int, gnorm: float, elapsed: float) -> float | None:
        last, self.last = self.last, (it, gnorm, elapsed)
        if last is None or it <= last[0] or elapsed <= last[2]:
            return None
        per_it = (elapsed - last[2]) / (it - last[0])
        cap = per_it * (max_iters - it)
        if not (self.gtol > 0 and gnorm > 0 and last[1] > 0) or not math.isfinite(gnorm):
            return cap
        rate = (math.log(last[1]) - math.log(gnorm)) / (elapsed - last[2])
        if rate <= 0 or gnorm <= self.gtol:
            return cap
        return min(cap, (math.log(gnorm) - math.log(self.gtol)) / rate)


def _program(fn, args: tuple, out_template, optimize: bool = True):
    """``fn(*args)`` compiled: from ``stiefel.runtime.program_cache`` (no tracing) where it can serve it, else
    traced and compiled (``compile_aot``); ``optimize=False`` for a program run once (``ONE_SHOT_OPTIONS``)."""
    call = program_cache.load_or_export(fn, args, out_template, custom_calls=ffi_solve.CUSTOM_CALLS,
                                        optimize=optimize)
    return call if call is not None else compile_aot(fn, *args, optimize=optimize)


def run_program(fn, args: tuple, out_template, *, optimize: bool = True):
    """Run ``fn(*args)`` as ``_program`` compiles it (stored programs when JAX's persistent cache is on: a later
    process neither traces nor compiles it); ``(out, compile_seconds, run_seconds)`` like ``run_compiled``.
    ``out_template``: a pytree of ``fn``'s output structure (leaves ignored)."""
    t0 = time.perf_counter()
    call = _program(fn, args, out_template, optimize=optimize)
    t1 = time.perf_counter()
    out = jax.block_until_ready(call(*args))
    return out, t1 - t0, time.perf_counter() - t1


def run_chunked(solver, fn, X0, args, max_iters: int, *, progress: Callable | None = None,
                interval: float = DEFAULT_INTERVAL, stop=None, method: str = ""):
    """Run ``solver`` (a ``stiefel`` Riemannian minimiser) on ``fn(X, args)`` from ``X0`` for at most
    ``max_iters`` iterations, in chunks (module docstring).

    Returns ``(state, dist_to_manifold, compile_seconds, run_seconds)``; ``state.status`` is a
    ``Status`` code, ``MAX_ITERS`` when the cap ended the run and ``INTERRUPTED`` after ``stop``, a
    ``KeyboardInterrupt``, or a ``progress`` callback that raised (then ``CallbackError`` is raised by
    the caller, ``stiefel.minimize``; here the exception is returned as ``state, ..., error``).
    """
    fn = _NoAux(fn)
    t0 = time.perf_counter()
    template = _steps.State(*([0] * len(_steps.State._fields)))._replace(history=History(0, 0, 0, 0), aux=None)
    # the initial state is compiled like the loop (not ONE_SHOT_OPTIONS, though it runs once): the backend's
    # optimisations change its rounding, and minimize must take optx.minimise's iterates to the last digit
    init = _program(_init, (solver, fn, X0, args), template)
    state = init(solver, fn, X0, args)
    advance = _program(_advance, (solver, fn, args, state, host_array(0, np.int32)), (template, 0))
    t_compile = time.perf_counter() - t0
    estimate = _Estimate(float(np.asarray(solver.atol)))
    t_start = time.perf_counter()
    state = jax.block_until_ready(state)
    dist, chunk, error, interrupted = None, 1, None, False
    it = 0
    while True:
        try:
            if _stopped(stop):
                interrupted = True
                break
            t_chunk = time.perf_counter()
            new_state, new_dist = advance(solver, fn, args, state, host_array(min(it + chunk, max_iters), np.int32))
            new_state, new_dist = jax.block_until_ready((new_state, new_dist))
            state, dist = new_state, new_dist
        except KeyboardInterrupt:
            interrupted = True
            break
        done = int(state.it) - it
        it = int(state.it)
        spent = time.perf_counter() - t_chunk
        if done > 0:  # next chunk: about ``interval`` seconds, at most 4× the last one
            chunk = int(max(1, min(4 * chunk, interval * done / max(spent, 1e-9))))
        running = int(state.status) < 0 and it < max_iters
        if progress is not None:
            elapsed = time.perf_counter() - t_start
            info = Progress(iteration=it, max_iters=max_iters, objective=float(state.F), grad_norm=float(state.gnorm),
                            elapsed=elapsed, remaining=estimate(it, max_iters, float(state.gnorm), elapsed) if running
                            else 0.0, method=method)
            try:
                progress(info)
            except KeyboardInterrupt:
                interrupted = True
                break
            except Exception as exc:  # noqa: BLE001 — reported as CallbackError by the caller
                error, interrupted = exc, True
                break
        if not running:
            break
    if dist is None:  # stopped before the first chunk
        dist = solver.manifold.dist_to_manifold(state.X)
    if interrupted:
        state = state._replace(status=host_array(Status.INTERRUPTED, np.int32))
    elif int(state.status) < 0:
        state = state._replace(status=host_array(Status.MAX_ITERS, np.int32))
    return state, dist, t_compile, time.perf_counter() - t_start, error


class HostMonitor:
    """Progress reports and stop checks for solvers that iterate on the host (ADMM, column loops).

    ``tick(iteration, objective, residual)`` after each iteration: calls ``progress`` when ``interval``
    seconds passed since the last report (and ``final=True`` always), and returns True when the loop
    should stop (``stop`` set, or a ``KeyboardInterrupt`` raised by the callback). A callback that raises
    anything else becomes ``CallbackError`` (``result`` is given by the caller, ``error_result``).
    ``interrupted`` says whether the loop was stopped from outside.
    """

    def __init__(self, progress: Callable | None = None, stop=None, *, interval: float = DEFAULT_INTERVAL,
                 max_iters: int = 0, method: str = "", tol: float = 0.0):
        self.progress, self.stop, self.interval = progress, stop, interval
        self.max_iters, self.method = max_iters, method
        self.t0 = time.perf_counter()
        self.last = float("-inf")
        self.estimate = _Estimate(tol)
        self.interrupted = False

    def tick(self, iteration: int, objective: float, residual: float, *, final: bool = False,
             error_result=None) -> bool:
        if self.progress is not None:
            now = time.perf_counter()
            if final or now - self.last >= self.interval:
                self.last = now
                elapsed = now - self.t0
                left = 0.0 if final else self.estimate(iteration, self.max_iters, residual, elapsed)
                info = Progress(iteration=int(iteration), max_iters=int(self.max_iters), objective=float(objective),
                                grad_norm=float(residual), elapsed=elapsed, remaining=left, method=self.method)
                try:
                    self.progress(info)
                except KeyboardInterrupt:
                    self.interrupted = True
                    return True
                except Exception as exc:  # noqa: BLE001 — a named error for the caller
                    raise CallbackError(f"the progress callback raised {type(exc).__name__}: {exc}; the solve "
                                        f"stopped after {int(iteration)} iterations", error_result) from exc
        if not final and _stopped(self.stop):
            self.interrupted = True
            return True
        return False
