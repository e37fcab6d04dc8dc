"""The ADMM CMM solvers (thesis Algorithms 3 and 8; docs/maths.md §5–6): ``ADMMCMM`` (exact or thesis form),
``SequentialADMMCMM`` and ``FastCMM`` (restricted to local functions; exact or printed form). Host numpy/scipy,
float64. Each run reports ``info`` → ``CMMResult.params``: ``rho0`` (the initial penalty) and ``step_times``
(cumulative seconds of the Ψ/X-, E-, S-steps, dual/ρ updates, residuals and the recorded objective;
``objectives.admm.rho.STEPS``)."""

from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar

import scipy.sparse as sp

from stiefel.solvers.driver import HostMonitor

from ..admm.splitting import ADMMOptions, ADMMResult, admm, admm_sequential
from ..admm.rho import RULES, VARIANTS, check_rule, check_variant, penalty_scale
from .base import (CMMSolver, SolverOptionError, SolverRun, _check_int, _check_number, _is_number, _no_callback, _require)
from ..admm.fast import restricted_admm, restricted_eigenbasis

__all__ = ["ADMMCMM", "SequentialADMMCMM", "FastCMM", "VARIANTS", "RULES"]


def _solver_run(res: ADMMResult, opts: ADMMOptions, mu: float) -> SolverRun:
    """The ``SolverRun`` of an ADMM result: history ``time``/``objective``; ``info["rho0"]`` (the ρ it began
    with) and ``info["step_times"]`` (seconds per step, ``ADMMResult.step_times``)."""
    history = {"time": res.history["time"], "objective": res.history["objective"]}
    info = {"rho0": float(res.rho0), "step_times": {key: float(t) for key, t in res.step_times.items()}}
    return SolverRun(res.Psi, res.iterations, res.status, res.wall_time, 0.0, history, info)


def _finish(res: ADMMResult, opts: ADMMOptions, mu: float, monitor: HostMonitor | None) -> SolverRun:
    """The last progress report (whatever the time since the previous one), then the ``SolverRun``."""
    if monitor is not None:
        primal = res.history.get("primal", [])
        monitor.tick(res.iterations, res.objective, float(primal[-1]) if len(primal) else float("nan"), final=True)
    return _solver_run(res, opts, mu)


@dataclasses.dataclass(frozen=True, kw_only=True)
class _ADMMSolver(CMMSolver):
    """``ADMMOptions`` (``objectives.admm.splitting``) without the variant: ``rho`` (None: 2λ_{k−1} from the
    eigenbasis start's eigenvalues — the modes' spectrum; too small a ρ diverges —, else ``max(μ, 1)``; both
    divided by n for a thesis variant, whose Frobenius penalty is n times the A-norm one when A = I/n),
    residual balancing ``adapt_rho`` (``"increase"``, ``True``/``"both"``, ``False``; ``objectives.admm.rho.
    RhoRule``) by ``rho_tau`` > 1 when one residual exceeds ``rho_ratio`` > 1 times the other, every
    ``adapt_every`` iterations;
    stopping ``eps_abs``, ``eps_rel``, ``time_limit`` (s) and ``max_iters``, the total number of ADMM
    iterations of the solve (an integer in ``[1, 2³¹ − 1]``; ``SequentialADMMCMM``'s modes share it
    fairly). Host numpy/scipy, float64. ``solve(..., progress=, stop=)``: reports (primal residual as
    ``grad_norm``) a few times per second and stops cleanly (status ``"interrupted"``,
    ``stiefel.solvers.driver.HostMonitor``)."""

    supports_progress: ClassVar[bool] = True

    rho: float | None = None
    adapt_rho: bool | str = ADMMOptions.adapt_rho
    rho_ratio: float = ADMMOptions.rho_ratio
    rho_tau: float = ADMMOptions.rho_tau
    adapt_every: int = ADMMOptions.adapt_every
    eps_abs: float = ADMMOptions.eps_abs
    eps_rel: float = ADMMOptions.eps_rel
    max_iters: int = ADMMOptions.max_iters
    time_limit: float = ADMMOptions.time_limit

    def __post_init__(self) -> None:
        _require(self.rho is None or (_is_number(self.rho) and math.isfinite(self.rho) and self.rho > 0),
                 f"rho must be None (automatic) or a positive finite number, got {self.rho!r}")
        check_rule(self.adapt_rho, SolverOptionError)
        _check_number("rho_ratio", self.rho_ratio, 1, strict=True)
        _check_number("rho_tau", self.rho_tau, 1, strict=True)
        _check_int("adapt_every", self.adapt_every, 1)
        _check_number("eps_abs", self.eps_abs, 0)
        _check_number("eps_rel", self.eps_rel, 0)
        _check_int("max_iters", self.max_iters, 1)
        _check_number("time_limit (seconds; inf: none)", self.time_limit, 0, strict=True, finite=False)

    def admm_options(self, rho: float | None = None) -> ADMMOptions:
        """These options as ``ADMMOptions`` (``rho`` overrides ``self.rho`` when given)."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(ADMMOptions) if hasattr(self, f.name)}
        return ADMMOptions(**{**fields, "rho": rho if rho is not None else self.rho})

    def _rho(self, evals, k: int, n: int) -> float | None:
        """``rho``, else 2λ_{k−1} (A-norm scale) times the variant's ``penalty_scale`` when eigenvalues are known."""
        if self.rho is None and evals is not None:
            scale = penalty_scale(getattr(self, "variant", "exact"), n)
            return 2.0 * float(evals[k - 1] if k > 1 else evals[1]) * scale
        return self.rho

    def _monitor(self, progress, stop, opts: ADMMOptions) -> HostMonitor | None:
        if progress is None and stop is None:
            return None
        return HostMonitor(progress, stop, max_iters=opts.max_iters, method=self.name, tol=opts.eps_abs)

    def _run(self, run, W, a, k, mu, start, weighting, seed, callback, progress, stop) -> SolverRun:
        _no_callback(self, callback)
        opts = self.admm_options(self._rho(start.evals, k, a.shape[0]))
        monitor = self._monitor(progress, stop, opts)
        res = run(W, a, k, mu, weighting=weighting, Psi0=start.X0, seed=seed, options=opts, monitor=monitor)
        return _finish(res, opts, mu, monitor)


@dataclasses.dataclass(frozen=True, kw_only=True)
class ADMMCMM(_ADMMSolver):
    """ADMM, thesis Algorithm 3 (``objectives.admm.splitting.admm``); ``variant``: ``"exact"`` (A-norm penalties,
    closed-form steps) or ``"thesis"`` (Frobenius penalties, the Ψ-step for A ≈ I/n, eq. 3.2.24)."""

    name: ClassVar[str] = "admm"
    variant: str = "exact"

    def __post_init__(self) -> None:
        super().__post_init__()
        check_variant(self.variant, SolverOptionError)

    def solve(self, W, a, k, mu, start, *, weighting="area", seed=0, dtype=None, callback=None, progress=None,
              stop=None) -> SolverRun:
        """History: true objective and seconds per iteration; ``info["rho0"]``."""
        return self._run(admm, W, a, k, mu, start, weighting, seed, callback, progress, stop)


@dataclasses.dataclass(frozen=True, kw_only=True)
class SequentialADMMCMM(_ADMMSolver):
    """ADMM one mode at a time with ``ψᵀAΨ_prev = 0`` (``objectives.admm.splitting.admm_sequential``, exact form);
    ``max_iters`` is the total over all modes: mode j may use ⌈left / (k − j)⌉ of what modes 0 … j−1
    left (unused iterations roll over; status ``max_iters`` when a share runs out)."""

    name: ClassVar[str] = "admm_sequential"

    def solve(self, W, a, k, mu, start, *, weighting="area", seed=0, dtype=None, callback=None, progress=None,
              stop=None) -> SolverRun:
        """History: the true objective of the modes found so far, one entry per column."""
        return self._run(admm_sequential, W, a, k, mu, start, weighting, seed, callback, progress, stop)


@dataclasses.dataclass(frozen=True, eq=False)
class FastCMM(_ADMMSolver):
    """Algorithm 8 (``objectives.admm.fast.restricted_admm``) on ``span(U)``, ``local_functions``: ``(n, d)``
    (sparse), e.g. ``mesh.local_functions(m, n_samples=d).U``; ``variant``: ``"exact"`` (A-norm penalties)
    or ``"thesis"`` (the printed algorithm: Frobenius penalties, A ≈ I/n; final X Ā-orthonormal either way).
    Start ``"eigen"``: the restricted eigenbasis (Algorithm 7) with ρ = 2λ̄_{k−1} (its k-th eigenvalue; /n
    for the thesis variant) unless ``rho`` is given; ``"random"``: random coefficients (seed), ρ = ``rho``
    or ``max(μ, 1)`` (/n). Equal when ``U`` is the same object and the other options are equal."""

    name: ClassVar[str] = "fast"
    restricted: ClassVar[bool] = True
    local_functions: Any
    variant: str = "exact"

    def __post_init__(self) -> None:
        super().__post_init__()
        check_variant(self.variant, SolverOptionError)
        shape = getattr(self.local_functions, "shape", None)
        _require(shape is not None and len(shape) == 2 and shape[1] >= 1,
                 "local_functions must be an (n, d) matrix with d ≥ 1 (e.g. mesh.local_functions(m, n_samples=d).U), "
                 f"got {type(self.local_functions).__name__} of shape {shape}")

    def _key(self) -> tuple:
        return (id(self.local_functions),) + tuple(getattr(self, f.name) for f in dataclasses.fields(self)
                                                   if f.name != "local_functions")

    def __eq__(self, other) -> bool:
        return type(other) is type(self) and other.local_functions is self.local_functions \
            and other._key() == self._key()

    def __hash__(self) -> int:
        return hash(self._key())

    def __repr__(self) -> str:
        U = self.local_functions
        opts = ", ".join(f"{key}={v!r}" for key, v in self.as_dict().items() if key != "local_functions")
        return f"FastCMM(local_functions=<{U.shape[0]}×{U.shape[1]} {type(U).__name__}>, {opts})"

    def as_dict(self) -> dict:
        out = super().as_dict()
        out["local_functions"] = tuple(self.local_functions.shape)  # the shape, not the matrix
        return out

    def solve(self, W, a, k, mu, start, *, weighting="area", seed=0, dtype=None, callback=None, progress=None,
              stop=None) -> SolverRun:
        """History: true objective and seconds per iteration; ``info["rho0"]``."""
        _no_callback(self, callback)
        n = a.shape[0]
        _require(self.local_functions.shape[0] == n, f"local_functions has {self.local_functions.shape[0]} rows, "
                 f"the Laplacian {n}: build U on the same mesh")
        Xr, rho = None, self.rho
        if start.kind == "eigen":
            evals_r, _, Xr = restricted_eigenbasis(W, sp.diags_array(a), self.local_functions, max(k, 2))
            Xr = Xr[:, :k]
            if rho is None:  # as for the full ADMM: ρ of the order of the modes' spectrum
                rho = 2.0 * float(evals_r[k - 1] if k > 1 else evals_r[1]) * penalty_scale(self.variant, n)
        opts = self.admm_options(rho)
        monitor = self._monitor(progress, stop, opts)
        res = restricted_admm(W, a, self.local_functions, k, mu, weighting=weighting, X0=Xr, seed=seed, options=opts,
                              monitor=monitor)
        return _finish(res, opts, mu, monitor)
