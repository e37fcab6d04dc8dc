"""The manifold CMM solvers (thesis §6.5, Algorithm 6; docs/maths.md §4): ``BlockCMM`` and ``SequentialCMM``.

Both minimise the smoothed energy ``tr(XᵀWX) + μ Σ_ij w_i s_{ε,δ}(X_ij)`` on ``XᵀAX = I``
(``objectives.energy.energies.cmm_energy``), with ε and δ driven to their targets in ``continuation``
warm-started stages; the returned modes are re-orthonormalised exactly in A.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

import stiefel
from stiefel.runtime.compilation import host_array
from stiefel.runtime.buckets import DEFAULT_GROWTH, check_growth
from stiefel.solvers.driver import Progress
from stiefel.solvers.minimisers import STALL_WINDOW_MAX
from stiefel.linalg.operators import SparseOperator

from . import newton as cmm_newton
from . import block_stages as stages
from ..energy import smoothings
from .active_set import ActiveSetPreconditioner
from ..admm.splitting import l1_weights_np, orthonormalize
from ..energy.energies import cmm_energy
from .padding import PaddedProblem
from .base import (CMMSolver, SolverOptionError, SolverRun, Start, _check_int, _check_number, _is_number, _no_callback, _require)

__all__ = ["BlockCMM", "SequentialCMM", "PRECONDITIONERS", "OPTIMIZERS"]

PRECONDITIONERS = ("shifted", "active_set")
OPTIMIZERS = ("cg", "lbfgs")


def _continuation(eps: float, steps: int, start: float) -> list[float]:
    """Smoothing widths of the stages: geometric from ``start`` to ``eps`` (just ``eps`` if ≤ 1 step)."""
    if steps <= 1 or start <= eps:
        return [eps]
    return list(np.geomspace(start, eps, steps))


def _column_progress(callback, progress, k: int, max_iters: int):
    """A ``minimize_sequential`` column callback that also reports ``stiefel.Progress`` (columns done so far)."""
    if progress is None:
        return callback
    t0, done = time.perf_counter(), [0, 0]

    def report(j, info):
        if callback is not None:
            callback(j, info)
        done[0] += int(info["iterations"])
        done[1] += 1
        elapsed = time.perf_counter() - t0
        left = elapsed / done[1] * (k - j - 1) if j + 1 < k else 0.0  # per column so far
        progress(Progress(iteration=done[0], max_iters=max_iters, objective=float(info["value"]),
                          grad_norm=float(info["grad_norm"]), elapsed=elapsed, remaining=left,
                          stage=j, n_stages=k, method="sequential"))

    return report


def _shifted_inverse(W, a, sigma: float, dtype, padded: PaddedProblem | None = None):
    """``(P, seconds)`` with ``P = (W + σA)⁻¹`` factored in ``dtype`` (of the padded problem, with its
    bucketed shapes, when ``padded`` is given); the seconds count as part of the run, as ADMM's E-step
    factorisations do."""
    t0 = time.perf_counter()
    if padded is None:
        P = stiefel.as_operator(W + sp.diags_array(sigma * a), dtype=dtype)
    else:  # checked as the unpadded one is (symmetry, positive diagonal)
        P = stiefel.as_operator(padded.W + sp.diags_array(sigma * padded.a), dtype=dtype, width=padded.width,
                                factor_size=padded.factor_size)
    return P, time.perf_counter() - t0


@dataclasses.dataclass(frozen=True, kw_only=True)
class _SmoothedSolver(CMMSolver):
    """Options shared by the manifold solvers: the ℓ1 smoothing (``objectives.energy.smoothings``), whose ε and
    δ both follow a geometric continuation of ``continuation`` stages from ``continuation_start``; the
    per-stage ``gtol``; ``max_iters``, the total number of iterations of the solve, shared by the stages
    in turn (each gets what the earlier ones left; once it is spent the remaining stages are skipped and
    the status is ``max_iters``), an integer in ``[1, 2³¹ − 1]``; σ of ``(W + σA)⁻¹`` (None: λ_{k−1}, the
    largest of the first k eigenvalues, λ₁ for k ≤ 2 — the scale of the modes sought, ``docs/benchmarks/cmm.md``);
    ``runtime_smoothing``: the smoothing as a runtime value of the compiled solver (``lax.switch`` over the
    ten, ``objectives.energy.energies.CMMEnergy``), so solvers differing only in ``smoothing`` share one
    compilation — for comparisons; measured on fandisk (k = 8–10): 2.0–2.5× the compile time of one
    smoothing and 7–12 % more time per iteration, so it is off by default."""

    smoothing: str = "f6"
    eps: float = 1e-3
    delta: float = 1e-3
    gtol: float = 1e-6
    max_iters: int = 5000
    continuation: int = 1
    continuation_start: float = 1e-1
    preconditioner_shift: float | None = None
    runtime_smoothing: bool = False

    def __post_init__(self) -> None:
        _require(isinstance(self.runtime_smoothing, bool), f"runtime_smoothing must be True or False, got "
                 f"{self.runtime_smoothing!r}")
        _require(_is_number(self.eps) and _is_number(self.delta),
                 f"eps and delta must be positive numbers, got {self.eps!r}, {self.delta!r}")
        try:
            smoothings.get(self.smoothing, self.eps, self.delta)  # the name, ε > 0 and δ > 0
        except (ValueError, TypeError) as e:
            raise SolverOptionError(f"{type(self).__name__}: {e}") from None
        _check_number("gtol", self.gtol, 0)
        _check_int("max_iters", self.max_iters, 1)
        _check_int("continuation (the number of smoothing stages)", self.continuation, 1)
        _check_number("continuation_start", self.continuation_start, 0, strict=True)
        shift = self.preconditioner_shift
        _require(shift is None or (_is_number(shift) and math.isfinite(shift) and shift > 0),
                 f"preconditioner_shift must be None (λ_{{k−1}}) or a positive finite number, got {shift!r}")

    def needs_eigenpairs(self, start: str) -> bool:
        return start == "eigen" or self.preconditioner_shift is None

    def _setup(self, W, a, mu: float, start: Start, weighting: str, dtype, padded: PaddedProblem | None = None):
        """``(σ, computation dtype, energy, stage widths, (ε/min, δ/min))``; the energy of the padded
        problem (ℓ1 weights 0 on the padded rows) when ``padded`` is given."""
        sigma = self.preconditioner_shift
        if sigma is None:
            _require(start.evals is not None, f"{type(self).__name__} needs the first max(k, 2) eigenvalues in "
                     "start.evals for its default shift, or preconditioner_shift=σ")
            sigma = float(max(start.evals[-1], 1e-12))
        # every array of the problem in the computation dtype (float32 runs stay float32)
        dt = np.dtype(dtype or (jnp.float64 if jax.config.jax_enable_x64 else jnp.float32))
        Wop = SparseOperator.from_scipy(W, dtype=dt) if padded is None else SparseOperator.from_scipy(
            padded.W, dtype=dt, width=padded.width)
        energy = cmm_energy(Wop, host_array(a if padded is None else padded.a, dt), mu,
                            smoothing=self.smoothing, eps=self.eps, delta=self.delta, weighting=weighting,
                            runtime_smoothing=self.runtime_smoothing)
        if padded is not None:  # the real rows' weights (uniform: 1/n of the real n), 0 on the padding
            weights = padded.pad(l1_weights_np(a, weighting))
            energy = eqx.tree_at(lambda e: e.weights, energy, host_array(weights, dt))
        low = min(self.eps, self.delta)
        schedule = _continuation(low, self.continuation, self.continuation_start)
        return sigma, dt, energy, schedule, (self.eps / low, self.delta / low)


@dataclasses.dataclass(frozen=True, kw_only=True)
class BlockCMM(_SmoothedSolver):
    """The block manifold solver (``stiefel.minimize`` on ``ΨᵀAΨ = I``, Cholesky retraction).

    continuation: smoothing stages (default 4: δ = 0.1 → target); intermediate stages end once the
      smoothed objective decreased by less than ``stage_ftol`` (relative) over ``stage_window``
      iterations, so they only settle the modes' arrangement (``docs/benchmarks/cmm.md``: iterations to
      ADMM's best 337 → 67 on camelhead, k = 10); the last runs to ``gtol`` or ``ftol`` (relative
      decrease over 20 iterations — the gradient can stall above gtol in the rounding regime).
    starts: the number of starts screened (1–64; ``objectives.cmm.block_stages``): the given start and
      ``starts − 1`` rotations ``X0·Q`` of it (random orthogonal ``Q``, seeded by ``seed``: the same span) each go
      through the intermediate stages; the one with the lowest true objective there goes on to the last stage
      (``params["screened_starts"]``: each start's iterations, objective and status). Only for the ``"eigen"`` and
      ``"random"`` starts — an array start is used as given — and k > 1. Why: from the eigenbasis the
      solve keeps the symmetric arrangements of the eigenfunctions and ends in a worse minimum on several
      meshes (k = 10, uniform weights: bumpy.off at μ = 2λ 1.1 % above ADMM's; ``docs/benchmarks/starts.md``); the
      intermediate stages settle the arrangement, and cost ~60 iterations of the 300–2400 of a solve.
    optimizer: ``"cg"`` (Riemannian CG) or ``"lbfgs"`` (each active-set round restarts its memory).
    preconditioner: ``"shifted"`` (``(W + σA)⁻¹``, one factorisation) or ``"active_set"``
      (``W + σA`` plus the ℓ1 curvature of the entries pinned at zero, rebuilt every ``refresh`` iterations).
    bucket_growth: the problem is padded to size buckets (``stiefel.runtime.buckets``, ``objectives.cmm.padding``:
      rows, neighbour-table width and factor entries on a grid growing by this factor) so that meshes
      of similar size share one compiled solver, also across processes through JAX's persistent
      cache; the padded rows stay exactly zero. None: exact shapes. Only with the shifted preconditioner.
    saddle_checks: at most this many saddle checks in the last stage (0: none; ``objectives.cmm.saddle``):
      while the stage has not passed one it stops at the looser relative decrease ``saddle_ftol``, measures
      the Hessian's most negative curvature θ (20 LOBPCG products) and, when θ < −``saddle_tol``·σ (σ the
      preconditioner's shift, λ_{k−1} by default), steps off along it and resumes; a passed check moves
      the stage on to ``ftol``, where one more check is made (the last of the budget is kept for that
      point). The result records each (θ, step, decrease, iteration) in ``params["saddles"]``. Measured on
      example:bumpy (k = 10, μ = 2λ₉): the stall test had stopped on a saddle's plateau at 1802.50
      (θ = −89); with the checks the solve ends within 0.011 % of ADMM's objective
      (``docs/benchmarks/saddle.md``). ``saddle_ftol`` 1e-5 → 1e-4 (the first check sooner) brought it within
      0.1 % of ADMM's objective at iteration 544 instead of 706 (2457 → 1990 in all), the same iteration as
      before on five other meshes, the same final objectives (torus: lower, 1881.13 for 1881.23, in 1915
      iterations instead of 646).
    polish: None, or ``"tr"``: after a converged last stage, trust regions with the curvature-aware point
      preconditioner (``objectives.cmm.newton``) take the smoothed problem to a Riemannian gradient norm
      ``≤ polish_gtol·|F|`` in at most ``polish_iters`` outer iterations (the first-order stop is a stall
      test, its gradient norm typically 10⁻³–1 relative); recorded in ``params["polish_run"]`` (iterations,
      Hessian products, gradient norms and smoothed values before and after, status: the solve's status
      stays the block solver's, the polish's own is in the record). Only with the shifted preconditioner.
    """

    name: ClassVar[str] = "block"
    continuation: int = 4
    starts: int = 4
    ftol: float = 1e-7
    stage_ftol: float = 3e-4
    stage_window: int = 5
    optimizer: str = "cg"
    preconditioner: str = "shifted"
    refresh: int = 50
    bucket_growth: float | None = DEFAULT_GROWTH
    saddle_checks: int = 4
    saddle_ftol: float = 1e-4
    saddle_tol: float = 1e-3
    polish: str | None = None
    polish_gtol: float = 1e-8
    polish_iters: int = 500

    def __post_init__(self) -> None:
        super().__post_init__()
        _require(self.polish in (None, "tr"), f"unknown polish {self.polish!r}; choose None or 'tr'")
        _check_number("polish_gtol", self.polish_gtol, 0)
        _check_int("polish_iters", self.polish_iters, 1)
        _require(self.polish is None or self.preconditioner == "shifted",
                 "polish='tr' needs preconditioner='shifted' (it reuses the factor of W + σA)")
        _check_int("saddle_checks", self.saddle_checks, 0)
        _check_int("starts", self.starts, 1, 64)
        _check_number("saddle_ftol", self.saddle_ftol, 0)
        _check_number("saddle_tol", self.saddle_tol, 0)
        try:
            check_growth(self.bucket_growth)
        except ValueError as e:
            raise SolverOptionError(f"BlockCMM: {e}") from None
        _check_number("ftol", self.ftol, 0)
        # the early stop of the intermediate continuation stages
        _check_int("stage_window", self.stage_window, 1, STALL_WINDOW_MAX)
        _check_number("stage_ftol", self.stage_ftol, 0)
        _require(self.optimizer in OPTIMIZERS, f"unknown optimizer {self.optimizer!r}; choose one of {OPTIMIZERS}")
        _require(self.preconditioner in PRECONDITIONERS,
                 f"unknown preconditioner {self.preconditioner!r}; choose one of {PRECONDITIONERS}")
        _check_int("refresh", self.refresh, 1)

    supports_progress: ClassVar[bool] = True

    def solve(self, W, a, k, mu, start, *, weighting="area", seed=0, dtype=None, callback=None, progress=None,
              stop=None) -> SolverRun:
        """Continuation over the smoothing stages, warm-started; history ``time``, ``smoothed_objective``
        and ``objective`` (true), one entry per iterate. ``progress(stiefel.Progress)`` between compiled
        chunks (iterations over all stages, the stage), ``stop`` checked between them: an interrupted stage
        ends the solve (status ``interrupted``, the current iterate)."""
        _no_callback(self, callback)
        # the active-set preconditioner is a host callback (never cached): exact shapes for it
        growth = self.bucket_growth if self.preconditioner == "shifted" else None
        padded = PaddedProblem.build(W, a, growth)
        sigma, dt, energy, schedule, (ratio_e, ratio_d) = self._setup(W, a, mu, start, weighting, dtype, padded)
        if self.preconditioner == "shifted":
            P, t_factor = _shifted_inverse(W, a, sigma, dt, padded)
        else:
            P, t_factor = ActiveSetPreconditioner(W, a, sigma, mu, l1_weights_np(a, weighting), schedule[0]), 0.0
        manifold = stiefel.GeneralizedStiefel(padded.a, k, retraction="cholesky", dtype=dtype)
        # A-orthonormalised on the host (no compilation), then padded with zero rows
        X0 = orthonormalize(np.asarray(start.X0, dtype=np.float64), a)
        candidates = stages.rotated_starts(X0, 1 if start.kind == "array" else self.starts, seed)
        energy_at = lambda s: energy.with_params(eps=s * ratio_e, delta=s * ratio_d)  # noqa: E731
        n_stages = len(schedule)
        # the screen: the intermediate stages (a first run of the only stage when there is one and several starts)
        widths = list(enumerate(schedule[:-1])) or ([(0, schedule[0])] if len(candidates) > 1 else [])
        clock, screened = stages.Clock(wall=t_factor), []
        for X in candidates:
            trace, before = stages.Trace(), clock.iters
            X, st = stages.intermediate_stages(self, widths, energy_at, manifold, host_array(padded.pad(X), dt), P,
                                               clock, trace, n_stages=n_stages, progress=progress, stop_signal=stop)
            value = trace.true_values[-1] if trace.true_values else float("nan")
            screened.append(dict(X=X, status=st, trace=trace, iterations=clock.iters - before, objective=float(value)))
            if st in ("interrupted", "max_iters"):  # the solve ends: the best start screened so far is returned
                break
        chosen = min(range(len(screened)), key=lambda j: _screen_rank(screened[j]))
        pick = screened[chosen]
        X, status, trace, checks = pick["X"], pick["status"], pick["trace"], []
        if screened[-1]["status"] in ("interrupted", "max_iters"):  # whichever start is returned, the solve ends
            status = screened[-1]["status"]
        elif status == "converged" and clock.iters >= self.max_iters:
            status = "max_iters"
        if status == "converged":
            s = schedule[-1]
            X, status, checks = stages.last_stage(self, energy_at(s), s, max(s * ratio_e, s * ratio_d), sigma, manifold,
                                                  X, P, clock, trace, stage=n_stages - 1, progress=progress,
                                                  stop_signal=stop)
        polished = None
        if self.polish == "tr" and status == "converged":
            X, polished, t_run, t_compile = cmm_newton.polish(
                energy_at(schedule[-1]), manifold, X, P.solve, host_array(padded.a, dt), sigma, gtol=self.polish_gtol,
                max_iters=self.polish_iters)
            clock.wall += t_run
            clock.compile += t_compile
            trace.times.append(clock.wall)
            trace.values.append(polished["value"])
            trace.true_values.append(float(energy_at(schedule[-1]).true_value(X)))
        history = {"time": np.asarray(trace.times), "smoothed_objective": np.asarray(trace.values),
                   "objective": np.asarray(trace.true_values)}
        Psi = orthonormalize(padded.unpad(np.asarray(X, dtype=np.float64)), a)  # exact A-orthonormality
        info = {"padded_size": padded.size}
        if len(candidates) > 1:
            info["screened_starts"] = [dict(start=j, status=c["status"], iterations=c["iterations"],
                                            objective=c["objective"], chosen=j == chosen) for j, c in enumerate(screened)]
        if polished is not None:
            info["polish_run"] = polished
        if checks:
            info["saddles"] = checks
        return SolverRun(Psi, clock.iters, status, clock.wall, clock.compile, history, info)


def _screen_rank(c: dict) -> tuple:
    """A screened start's rank: screens that finished first (``converged``), then the lowest true objective
    (NaN last)."""
    value = c["objective"]
    return (c["status"] != "converged", value if np.isfinite(value) else np.inf)


@dataclasses.dataclass(frozen=True, kw_only=True)
class SequentialCMM(_SmoothedSolver):
    """Thesis Algorithm 6 (``stiefel.minimize_sequential``): CG column by column, preconditioned by
    ``(W + σA)⁻¹``; ``continuation`` stages (default 1: none) each restart at column 0. ``max_iters`` is
    the total over all stages and columns: a stage gets what the earlier stages left, and its columns
    share that fairly (``stiefel.minimize_sequential``)."""

    name: ClassVar[str] = "sequential"
    supports_callback: ClassVar[bool] = True
    supports_progress: ClassVar[bool] = True

    def solve(self, W, a, k, mu, start, *, weighting="area", seed=0, dtype=None, callback=None, progress=None,
              stop=None) -> SolverRun:
        """``callback(j, info)`` after each finished column (``stiefel.minimize_sequential``'s), so a long run
        can save its columns; history ``time`` and ``smoothed_objective``, one entry per stage.
        ``progress(stiefel.Progress)`` after each column (a column is one compiled solve: no reports
        inside it); ``stop`` is checked before each column and Ctrl-C ends the column running: the
        columns not solved keep their projected starts (status ``interrupted``)."""
        callback = _column_progress(callback, progress, k, self.max_iters)
        sigma, dt, energy, schedule, (ratio_e, ratio_d) = self._setup(W, a, mu, start, weighting, dtype)
        P, t_factor = _shifted_inverse(W, a, sigma, dt)
        X = jnp.asarray(start.X0, dtype=dt)
        iters, wall, compile_t, status = 0, t_factor, 0.0, "converged"
        times, values = [], []
        for s in schedule:
            if iters >= self.max_iters:  # the total is spent: the remaining stages are skipped
                status = "max_iters"
                break
            F = energy.with_params(eps=s * ratio_e, delta=s * ratio_d)
            res = stiefel.minimize_sequential(F, a, k, X0=np.asarray(X), preconditioner=P, gtol=self.gtol,
                                              max_iters=self.max_iters, budget=self.max_iters - iters, dtype=dtype,
                                              callback=callback, stop=stop)
            X = res.x
            iters += int(np.sum(np.asarray(res.iterations)))
            names = set(res.status_names)
            st = "converged" if names == {"converged"} else sorted(names - {"converged"})[0]
            times.append(wall + res.wall_time)
            values.append(float(res.value))
            wall += res.wall_time
            compile_t += res.compile_time
            if st != "converged":
                status = st
            if st == "interrupted":
                break
        history = {"time": np.asarray(times), "smoothed_objective": np.asarray(values)}
        Psi = orthonormalize(np.asarray(X, dtype=np.float64), a)
        return SolverRun(Psi, iters, status, wall, compile_t, history, {})
