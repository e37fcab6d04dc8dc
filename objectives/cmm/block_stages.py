"""The stages of the block CMM solver (``objectives.cmm.manifold_solvers.BlockCMM``; docs/maths.md §4).

A solve is a continuation over smoothing widths. The intermediate stages stop once the smoothed
objective stalls (``stage_ftol``): they only settle the modes' arrangement, which is where the basin of
the final minimum is chosen. Several starts (the eigenbasis and rotations ``U·Q`` of it) go through
those stages; the one with the lowest true objective goes on to the last stage, which runs to ``ftol``
with saddle checks (``objectives.cmm.saddle``).

* ``block_rounds`` — one run of Riemannian CG/L-BFGS (in rounds when the preconditioner is rebuilt);
* ``Clock`` / ``Trace`` — the solve's iterations and seconds, and one start's history;
* ``intermediate_stages`` / ``last_stage`` — the two phases; ``rotated_starts`` — the starts screened.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

import stiefel

from . import saddle as cmm_saddle
from .active_set import ActiveSetPreconditioner

__all__ = ["block_rounds", "Clock", "Trace", "intermediate_stages", "last_stage", "rotated_starts"]


def block_rounds(F, manifold, X, P, *, gtol: float, ftol: float, max_iters: int, budget: int,
                 refresh: int | None = None, optimizer: str = "cg", ftol_window: int = 20, progress=None, stop=None):
    """Riemannian CG/L-BFGS (``optimizer``) on the block for at most ``budget ≤ max_iters`` iterations, in one
    run (fixed ``P``) or in rounds of ``refresh`` iterations with an ``ActiveSetPreconditioner`` rebuilt
    before each round. ``max_iters`` is the compiled bound (the same for every call: one compilation).

    ``progress(stiefel.Progress)`` and ``stop`` go to ``stiefel.minimize`` (``iteration`` counts this call's
    iterations; the caller adds its offset).

    Returns ``(X, iterations, status, run seconds (incl. refreshes), compile seconds,
    history {"time", "value", "monitor"})``; a round that ends converged or interrupted ends the run.
    """
    if not isinstance(P, ActiveSetPreconditioner):
        res = stiefel.minimize(F, manifold, X, method=optimizer, preconditioner=P, gtol=gtol, ftol=ftol,
                               ftol_window=ftol_window, max_iters=max_iters, budget=budget, monitor=F.true_value,
                               progress=progress, stop=stop, check=False)  # X: A-orthonormalised by the caller
        h = res.trimmed_history()
        h["time"] = np.linspace(0.0, res.wall_time, len(h["value"]))
        return res.x, int(res.iterations), res.status_name, res.wall_time, res.compile_time, h
    done, wall, compile_t, status = 0, 0.0, 0.0, "max_iters"
    parts: dict = {"time": [], "value": [], "monitor": []}
    bound = min(refresh, max_iters)
    while done < budget:
        t0 = time.perf_counter()
        P.refresh(X)
        wall += time.perf_counter() - t0
        shifted = None if progress is None else (lambda info, d=done: progress(info._replace(iteration=d + info.iteration)))
        res = stiefel.minimize(F, manifold, X, method=optimizer, preconditioner=P.apply, gtol=gtol, ftol=ftol,
                               ftol_window=ftol_window, max_iters=bound, budget=min(bound, budget - done),
                               monitor=F.true_value, check=False, progress=shifted, stop=stop)
        h = res.trimmed_history()
        first = 0 if done == 0 else 1  # a later round's entry 0 repeats the previous round's last
        parts["time"].append(wall + np.linspace(0.0, res.wall_time, len(h["value"]))[first:])
        parts["value"].append(h["value"][first:])
        parts["monitor"].append(h["monitor"][first:])
        wall += res.wall_time
        compile_t += res.compile_time
        done += int(res.iterations)
        X = res.x
        if res.status_name != "max_iters":
            status = res.status_name
            break
    return X, done, status, wall, compile_t, {key: np.concatenate(v) for key, v in parts.items()}


def _staged(progress, offset: int, elapsed: float, stage: int, n_stages: int, final: bool = True):
    """``progress`` with a stage's reports shifted to the whole solve: iterations and seconds of the earlier
    runs added, the stage and the number of stages set; ``final``: this run may end the solve (the last
    stage's run to ``ftol``, not its stop for a saddle check or a screened start)."""

    def report(info):
        if (stage < n_stages - 1 or not final) and info.remaining == 0.0:  # an intermediate end is not the end
            info = info._replace(remaining=None)
        progress(info._replace(iteration=offset + info.iteration, elapsed=elapsed + info.elapsed, stage=stage,
                               n_stages=n_stages, method="block"))

    return report


@dataclasses.dataclass
class Clock:
    """What the whole solve has spent: iterations (the budget ``max_iters`` is shared by every start and
    stage), run and compile seconds."""

    iters: int = 0
    wall: float = 0.0
    compile: float = 0.0


@dataclasses.dataclass
class Trace:
    """One start's history: per iterate the solve's elapsed seconds, the smoothed and the true objective."""

    times: list = dataclasses.field(default_factory=list)
    values: list = dataclasses.field(default_factory=list)
    true_values: list = dataclasses.field(default_factory=list)

    def extend(self, h: dict, elapsed: float) -> None:
        first = 0 if not self.times else 1  # a later run's entry 0 is the previous run's last iterate
        self.true_values.extend(list(h["monitor"][first:]))
        self.times.extend(list(elapsed + h["time"][first:]))
        self.values.extend(list(h["value"][first:]))


def _run(solver, F, manifold, X, P, clock: Clock, trace: Trace, report, stop_signal, **stop):
    """One ``block_rounds`` call with the solve's budget, booked on ``clock`` and ``trace``."""
    elapsed = clock.wall
    X, it, st, t_run, t_compile, h = block_rounds(
        F, manifold, X, P, gtol=solver.gtol, max_iters=solver.max_iters, budget=solver.max_iters - clock.iters,
        refresh=solver.refresh, optimizer=solver.optimizer, progress=report, stop=stop_signal, **stop)
    clock.iters += it
    clock.wall += t_run
    clock.compile += t_compile
    trace.extend(h, elapsed)
    return X, st


def rotated_starts(X0: np.ndarray, count: int, seed: int) -> list[np.ndarray]:
    """``[X0, X0·Q₁, …]``: ``X0`` and ``count − 1`` rotations of it by random orthogonal ``Q (k, k)``
    (QR of Gaussian matrices, ``numpy.random.default_rng(seed)``) — the same span, and the same A-orthonormality."""
    k = X0.shape[1]
    rng = np.random.default_rng(seed)
    out = [X0]
    for _ in range(count - 1 if k > 1 else 0):  # k = 1: a rotation is a sign, the same objective
        Q, R = np.linalg.qr(rng.standard_normal((k, k)))
        out.append(X0 @ (Q * np.sign(np.diag(R))))
    return out


def intermediate_stages(solver, widths, energy_at, manifold, X, P, clock: Clock, trace: Trace, *, n_stages: int,
                        progress=None, stop_signal=None):
    """The stages before the last (or, for a one-stage solve, a first run of the only stage), each stopped
    once the smoothed objective decreased by less than ``stage_ftol`` over ``stage_window`` iterations.

    ``widths``: ``[(stage index, ε-scale)]``; ``energy_at(s)``: the energy at that stage; ``P``: the
    preconditioner (or the ``ActiveSetPreconditioner``, its width set per stage). Returns ``(X, status)``:
    ``"converged"``, or the status that ends the solve (``max_iters``, ``interrupted``, ``non_finite``) —
    a line search that failed at a stage's round-off floor hands its iterate on.
    """
    stop = dict(ftol=max(solver.ftol, solver.stage_ftol), ftol_window=solver.stage_window)
    for stage, s in widths:
        if clock.iters >= solver.max_iters:
            return X, "max_iters"
        F = energy_at(s)
        if isinstance(P, ActiveSetPreconditioner):
            P.set_width(s)
        report = None if progress is None else _staged(progress, clock.iters, clock.wall, stage, n_stages, False)
        X, st = _run(solver, F, manifold, X, P, clock, trace, report, stop_signal, **stop)
        if st not in ("converged", "line_search_failed"):  # max_iters: the run was given all the budget left
            return X, st
    return X, "converged"


def last_stage(solver, F, s: float, width: float, sigma: float, manifold, X, P, clock: Clock, trace: Trace, *,
               stage: int, progress=None, stop_signal=None):
    """The last stage (scale ``s``, smoothing width ``width = max(ε, δ)``): to ``ftol`` (relative decrease over
    20 iterations) or ``gtol``, with at most ``saddle_checks`` saddle checks (``objectives.cmm.saddle``, threshold
    ``saddle_tol·σ``; the last of the budget is kept for the point where the tight test stops). Returns
    ``(X, status, checks)`` with the checks' records."""
    checks: list = []
    tight = solver.saddle_checks == 0
    shifted = None if isinstance(P, ActiveSetPreconditioner) else P  # the saddle checks' preconditioner
    if shifted is None:
        P.set_width(s)
    while True:
        stop = dict(ftol=solver.ftol if tight else max(solver.ftol, solver.saddle_ftol))
        report = None if progress is None else _staged(progress, clock.iters, clock.wall, stage, stage + 1, tight)
        X, st = _run(solver, F, manifold, X, P, clock, trace, report, stop_signal, **stop)
        if st != "converged":
            return X, st, checks
        if len(checks) < solver.saddle_checks - (0 if tight else 1):
            X_new, record, t_run, t_compile = cmm_saddle.check(F, manifold, X, shifted, width=width,
                                                               threshold=solver.saddle_tol * sigma)
            clock.wall += t_run
            clock.compile += t_compile
            checks.append(dict(record, iteration=clock.iters))
            if X_new is not None:  # stepped off a saddle: resume (the stall test loose again)
                X, tight = X_new, False
                if clock.iters >= solver.max_iters:
                    return X, "max_iters", checks
                continue
        if tight:
            return X, st, checks
        tight = True  # no saddle where the loose test stopped: on to the final tolerance

