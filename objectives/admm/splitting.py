"""ADMM for compressed manifold modes — the baseline (thesis Algorithm 3, §3.2.2; docs/maths.md §5).

Minimise ``tr(ΨᵀWΨ) + μ Σ_ij w_i |Ψ_ij|`` subject to ``ΨᵀAΨ = I`` by splitting
``Ψ`` (orthonormality), ``E`` (Dirichlet) and ``S`` (ℓ1) with scaled duals
``U^E``, ``U^S``. Two variants:

* ``"exact"`` (default): penalties in the A-norm ``‖Y‖²_A = tr(YᵀAY)`` (as in
  Neumann et al.'s reference code); every step is closed-form for diagonal A:
  ``Ψ = A^{-1/2} polar(A^{1/2} Y)``, ``Y = ½(E − U^E + S − U^S)``;
  ``(2W + ρA) E = ρA(Ψ + U^E)``; ``S = shrink(Ψ + U^S, μ w_i/(ρ a_i))``.
* ``"thesis"``: Frobenius penalties and the Ψ-step for ``A ≈ I/n`` (eq. 3.2.24),
  ``(2W + ρI)E = ρ(Ψ + U^E)``, with the final Ψ re-orthonormalised exactly in A.

The E-step matrix is factored once per value of ρ (sparse LU in symmetric mode;
factorisations are cached while ρ adapts). Stopping and ρ adaptation follow
Boyd et al. §3.3–3.4 (thesis §2.4.2): primal residual ``r = ‖[Ψ−E; Ψ−S]‖``, dual
residual ``s = ρ‖(E−E⁻) + (S−S⁻)‖`` (Boyd's ``ρAᵀB(z−z⁻)`` for the constraint
``[I; I]Ψ = [E; S]``; both in the penalty norm); ρ starts at ``options.rho`` or
``objectives.admm.rho.default_rho`` (``max(μ, 1)``, divided by n in the thesis variant:
same scale as the exact one) and adapts by ``objectives.admm.rho.RhoRule`` (duals rescaled).
The result's ``step_times`` are the cumulative seconds of each step (thesis Table 7.2).

This runs on the host (numpy/scipy): each iteration is one sparse solve with k
right-hand sides plus O(nk) work; the history records the true (non-smooth)
objective of the feasible iterate Ψ and the wall time of every iteration.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import scipy.sparse as sp

from stiefel.errors import ParameterError
from stiefel.linalg.sparse_factor import SymmetricFactor
from stiefel.solvers.driver import HostMonitor
from stiefel.validation import check_count, check_nonnegative, check_number, check_positive

from .rho import RhoRule, StepClock, check_rule, check_variant, default_rho

__all__ = ["ADMMOptions", "ADMMResult", "admm", "admm_sequential", "l1_weights_np", "RhoRule", "soft_threshold"]


@dataclasses.dataclass(frozen=True)
class ADMMOptions:
    """Options of ``admm`` / ``admm_sequential`` / ``objectives.admm.fast.restricted_admm``.

    rho: initial penalty (None: ``objectives.admm.rho.default_rho`` — ``max(μ, 1)`` on the A-norm scale, divided
    by n for the thesis variants, whose Frobenius penalty is n times the A-norm one when A = I/n); adapt_rho:
    Boyd's residual balancing (factor ``rho_tau`` > 1 when one residual exceeds ``rho_ratio`` > 1 times the
    other, checked every ``adapt_every`` iterations; ``objectives.admm.rho.RhoRule``): ``"increase"``
    (default) only ever raises ρ, ``True``/``"both"`` also lowers it when the dual residual dominates both
    raw and relative to Boyd's tolerance scales (recovers from a too-stiff ρ₀; on meshes where ρ₀ is
    right it reaches the same objectives but converges less often: ``docs/benchmarks/admm-rho.md``),
    ``False`` keeps ρ fixed; eps_abs, eps_rel: stopping
    tolerances; max_iters: the total number of iterations of a call (``admm_sequential``: shared fairly by the
    modes), an integer in ``[1, 2³¹ − 1]``; variant: ``"exact"`` or ``"thesis"``; time_limit (s). Checked on
    construction (``stiefel.ParameterError``).
    """

    rho: float | None = None
    adapt_rho: bool | str = "increase"
    rho_ratio: float = 10.0
    rho_tau: float = 2.0
    adapt_every: int = 10
    eps_abs: float = 1e-7
    eps_rel: float = 1e-5
    max_iters: int = 20000
    variant: str = "exact"
    time_limit: float = float("inf")

    def __post_init__(self) -> None:
        if self.rho is not None:
            check_positive("rho", self.rho)
        check_rule(self.adapt_rho)
        check_number("rho_ratio", self.rho_ratio, low=1, low_open=True)
        check_number("rho_tau", self.rho_tau, low=1, low_open=True)
        check_count("adapt_every", self.adapt_every)
        check_nonnegative("eps_abs", self.eps_abs)
        check_nonnegative("eps_rel", self.eps_rel)
        check_count("max_iters", self.max_iters)
        check_variant(self.variant)
        check_positive("time_limit", self.time_limit, finite=False)

    def initial_rho(self, mu: float, n: int) -> float:
        """ρ₀: ``rho`` when given, else ``default_rho(variant, μ, n)``."""
        return float(self.rho) if self.rho is not None else default_rho(self.variant, mu, n)


@dataclasses.dataclass
class ADMMResult:
    """Outcome of ADMM: modes ``Psi (n, k)`` (A-orthonormal), true objective, and per-iteration history.

    history: dict of arrays ``objective``, ``primal``, ``dual``, ``rho``, ``time`` (seconds since start).
    status: ``"converged"``, ``"max_iters"``, ``"time_limit"``, ``"target"`` or ``"interrupted"``.
    rho0: the initial penalty; step_times: cumulative seconds per step (``objectives.admm.rho.STEPS``: ``psi``
    (Ψ-/X-step), ``E``, ``S``, ``dual`` (dual and ρ updates), ``residual``, ``objective`` (the history's true
    objective)), their sum ≤ ``wall_time`` (thesis Table 7.2 reports them per iteration).
    """

    Psi: np.ndarray
    objective: float
    iterations: int
    status: str
    history: dict
    wall_time: float
    factor_time: float
    n_factorizations: int
    rho0: float = float("nan")
    step_times: dict = dataclasses.field(default_factory=dict)


def l1_weights_np(area_diag: np.ndarray, weighting: str) -> np.ndarray:
    """ℓ1 weights: ``A_ii`` (``"area"``) or ``1/n`` (``"uniform"``) (docs/maths.md §4)."""
    if weighting == "area":
        return np.asarray(area_diag, dtype=np.float64)
    if weighting == "uniform":
        return np.full(len(area_diag), 1.0 / len(area_diag))
    raise ValueError(f"unknown weighting {weighting!r}; choose 'area' or 'uniform'")


def _true_objective(W, w, mu, Psi) -> float:
    return float(np.sum(Psi * (W @ Psi)) + mu * np.sum(w[:, None] * np.abs(Psi)))


def orthonormalize(Psi, M):
    """``Ψ (ΨᵀMΨ)^{-1/2}`` (exact, symmetric M-orthonormalisation); ``M`` a diagonal (1-D) or a matrix."""
    MPsi = M[:, None] * Psi if np.ndim(M) == 1 else M @ Psi
    G = Psi.T @ MPsi
    vals, vecs = np.linalg.eigh(0.5 * (G + G.T))
    return Psi @ (vecs / np.sqrt(vals)) @ vecs.T



class _EStep:
    """Cached factorisations of ``2W + ρD`` (D = A or I) per value of ρ."""

    def __init__(self, W, d):
        self.W2 = sp.csc_matrix(2.0 * W)
        self.D = sp.diags(d, format="csc")
        self.cache: dict = {}
        self.factor_time = 0.0
        self.count = 0

    def solve(self, rho, rhs):
        lu = self.cache.get(rho)
        if lu is None:
            t0 = time.perf_counter()
            lu = SymmetricFactor(self.W2 + rho * self.D, check=False)
            self.factor_time += time.perf_counter() - t0
            self.count += 1
            if len(self.cache) > 8:
                self.cache.clear()
            self.cache[rho] = lu
        return lu.solve(rhs)


def soft_threshold(V: np.ndarray, t) -> np.ndarray:
    """The prox of ``t·|·|`` elementwise (the S-step): ``sgn(V)·max(|V| − t, 0)``; ``t`` broadcasts."""
    return np.sign(V) * np.maximum(np.abs(V) - t, 0.0)


class _History:
    """ADMM traces (objective, residuals, ρ, seconds since ``t0``), as numpy arrays at the end."""

    KEYS = ("objective", "primal", "dual", "rho", "time")

    def __init__(self, t0: float):
        self.t0 = t0
        self.data: dict = {key: [] for key in self.KEYS}

    def record(self, **values) -> float:
        """Append the given traces and the elapsed time; returns the elapsed time."""
        for key, value in values.items():
            self.data[key].append(value)
        elapsed = time.perf_counter() - self.t0
        self.data["time"].append(elapsed)
        return elapsed

    def arrays(self) -> dict:
        return {key: np.asarray(v) for key, v in self.data.items()}


def _polar(B):
    U, _, Vt = np.linalg.svd(B, full_matrices=False)
    return U @ Vt


def admm(W, area_diag, k: int, mu: float, *, weighting: str = "area", Psi0=None, seed: int = 0,
         options: ADMMOptions = ADMMOptions(), target: float | None = None,
         monitor: HostMonitor | None = None) -> ADMMResult:
    """ADMM for CMMs (Algorithm 3).

    Args:
      W: ``(n, n)`` sparse PSD weight (stiffness) matrix.
      area_diag: ``(n,)`` diagonal of the lumped area matrix A.
      k: number of modes; mu: sparsity weight μ.
      weighting: ``"area"`` (``μ Σ A_ii|Ψ_ij|``) or ``"uniform"`` (``(μ/n) Σ|Ψ_ij|``).
      Psi0: start ``(n, k)`` (A-orthonormalised here); default: random (``seed``).
      options: ``ADMMOptions``.
      target: optional objective value; the run stops once the true objective is ≤ target.
      monitor: optional ``stiefel.solvers.driver.HostMonitor`` (progress with the primal residual, stop checks); a
        stop or Ctrl-C (``KeyboardInterrupt``) ends the run with status ``"interrupted"`` and the current Ψ.
    """
    W = sp.csr_matrix(W, dtype=np.float64)
    a = np.asarray(area_diag, dtype=np.float64)
    n = a.shape[0]
    check_count("k", k, 1, n, high_label=f"n = {n}")
    check_nonnegative("mu", mu)
    w = l1_weights_np(a, weighting)
    exact = check_variant(options.variant) == "exact"
    d = a if exact else np.ones(n)  # the penalty metric
    r_scale = 1.0 / n  # the thesis's A ≈ rI
    if Psi0 is None:
        Psi0 = np.random.default_rng(seed).standard_normal((n, k))
    Psi = orthonormalize(np.asarray(Psi0, dtype=np.float64), a)
    E, S = Psi.copy(), Psi.copy()
    UE, US = np.zeros_like(Psi), np.zeros_like(Psi)
    rho = rho0 = options.initial_rho(mu, n)
    estep = _EStep(W, d)
    thresh_w = w / d  # shrink S at μ w_i / (ρ d_i)
    sqrt_d = np.sqrt(d)[:, None]
    dcol = d[:, None]
    status = "max_iters"
    rule = RhoRule(options, n)
    clock = StepClock()
    t0 = time.perf_counter()
    hist = _History(t0)
    it = 0
    try:
        for it in range(1, options.max_iters + 1):
            clock.mark()
            Y = 0.5 * (E - UE + S - US)
            if exact:
                Psi = _polar(sqrt_d * Y) / sqrt_d
            else:
                Psi = _polar(Y) / np.sqrt(r_scale)
            clock.lap("psi")
            E_old, S_old = E, S
            E = estep.solve(rho, rho * (dcol * (Psi + UE)))
            clock.lap("E")
            S = soft_threshold(Psi + US, mu * thresh_w[:, None] / rho)
            clock.lap("S")
            UE += Psi - E
            US += Psi - S
            clock.lap("dual")
            # residuals in the penalty norm, and the scales of Boyd's relative tolerances
            primal = np.sqrt(np.sum(dcol * ((Psi - E) ** 2 + (Psi - S) ** 2)))
            dual = rho * np.sqrt(np.sum(dcol * (E - E_old + S - S_old) ** 2))
            primal_scale = max(np.sqrt(np.sum(dcol * Psi**2)) * np.sqrt(2), np.sqrt(np.sum(dcol * (E**2 + S**2))))
            dual_scale = rho * np.sqrt(np.sum(dcol * (UE + US) ** 2))
            eps_pri = np.sqrt(2 * n * k) * options.eps_abs + options.eps_rel * primal_scale
            eps_dual = np.sqrt(n * k) * options.eps_abs + options.eps_rel * dual_scale
            clock.lap("residual")
            Psi_feasible = Psi if exact else orthonormalize(Psi, a)
            obj = _true_objective(W, w, mu, Psi_feasible)
            elapsed = hist.record(objective=obj, primal=primal, dual=dual, rho=rho)
            clock.lap("objective")
            if primal <= eps_pri and dual <= eps_dual:
                status = "converged"
                break
            if target is not None and obj <= target:
                status = "target"
                break
            if elapsed > options.time_limit:
                status = "time_limit"
                break
            if monitor is not None and monitor.tick(it, obj, primal, error_result=Psi):
                status = "interrupted"
                break
            clock.mark()
            rho = rule.apply(it, primal, dual, rho, UE, US, primal_scale=primal_scale, dual_scale=dual_scale,
                                  primal_tol=eps_pri)
            clock.lap("dual")
    except KeyboardInterrupt:  # Ctrl-C: the current iterate, status interrupted
        status = "interrupted"
    wall = time.perf_counter() - t0
    Psi_out = orthonormalize(Psi, a)
    return ADMMResult(
        Psi=Psi_out, objective=_true_objective(W, w, mu, Psi_out), iterations=it, status=status,
        history=hist.arrays(), wall_time=wall,
        factor_time=estep.factor_time, n_factorizations=estep.count, rho0=rho0, step_times=clock.totals,
    )


def admm_sequential(W, area_diag, k: int, mu: float, *, weighting: str = "area", Psi0=None, seed: int = 0,
                    options: ADMMOptions = ADMMOptions(), monitor: HostMonitor | None = None) -> ADMMResult:
    """Sequential ADMM (§3.2.2, end): one mode at a time with ``ψᵀAΨ_prev = 0``.

    The Ψ-step for one column is the A-closest unit vector A-orthogonal to the previous
    modes: ``ψ = normalise_A((I − ΦΦᵀA) y)``. ``options.max_iters`` is the total over all modes, shared
    fairly: mode j may use ⌈left / (k − j)⌉ of the iterations modes 0 … j−1 left (what a mode leaves
    rolls over); a mode stopped by its share ends with status ``"max_iters"``, and one that gets no
    iteration is its projected start. ``monitor``: as in ``admm``; after a stop or Ctrl-C the modes not
    reached are their projected starts (status ``"interrupted"``).
    """
    W = sp.csr_matrix(W, dtype=np.float64)
    a = np.asarray(area_diag, dtype=np.float64)
    n = a.shape[0]
    check_count("k", k, 1, n, high_label=f"n = {n}")
    check_nonnegative("mu", mu)
    w = l1_weights_np(a, weighting)
    if check_variant(options.variant) != "exact":
        raise ParameterError("sequential ADMM is implemented in the exact (A-weighted) form only")
    rng = np.random.default_rng(seed)
    Phi = np.zeros((n, 0))
    estep = _EStep(W, a)
    rho0 = options.initial_rho(mu, n)
    clock = StepClock()
    t0 = time.perf_counter()
    hist = _History(t0)
    total_it = 0
    status = "converged"
    try:
        for j in range(k):
            y0 = np.asarray(Psi0[:, j]) if Psi0 is not None else rng.standard_normal(n)

            def project(y):
                z = y - Phi @ (Phi.T @ (a * y))
                return z / np.sqrt(np.sum(a * z * z))

            psi = project(y0)
            e, s = psi.copy(), psi.copy()
            ue, us = np.zeros(n), np.zeros(n)
            rho = rho0
            col_status = "max_iters"
            rule = RhoRule(options, n)
            it = 0
            share = -(-(options.max_iters - total_it) // (k - j))  # ⌈left / modes to go⌉
            for it in range(1, share + 1):
                clock.mark()
                psi = project(0.5 * (e - ue + s - us))
                clock.lap("psi")
                e_old, s_old = e, s
                e = estep.solve(rho, rho * a * (psi + ue))
                clock.lap("E")
                s = soft_threshold(psi + us, mu * w / (a * rho))
                clock.lap("S")
                ue += psi - e
                us += psi - s
                clock.lap("dual")
                primal = np.sqrt(np.sum(a * ((psi - e) ** 2 + (psi - s) ** 2)))
                dual = rho * np.sqrt(np.sum(a * (e - e_old + s - s_old) ** 2))
                primal_scale = max(np.sqrt(2.0), np.sqrt(np.sum(a * (e**2 + s**2))))
                dual_scale = rho * np.sqrt(np.sum(a * (ue + us) ** 2))
                eps_pri = np.sqrt(2 * n) * options.eps_abs + options.eps_rel * np.sqrt(2.0)
                eps_dual = np.sqrt(n) * options.eps_abs + options.eps_rel * dual_scale
                clock.lap("residual")
                if primal <= eps_pri and dual <= eps_dual:
                    col_status = "converged"
                    break
                if monitor is not None and monitor.tick(total_it + it, float("nan"), primal, error_result=Phi):
                    col_status = "interrupted"
                    break
                clock.mark()
                rho = rule.apply(it, primal, dual, rho, ue, us, primal_scale=primal_scale, dual_scale=dual_scale,
                                 primal_tol=eps_pri)
                clock.lap("dual")
            total_it += it
            if col_status != "converged":
                status = col_status
            Phi = np.concatenate([Phi, psi[:, None]], axis=1)
            clock.mark()
            hist.record(objective=_true_objective(W, w, mu, Phi))
            clock.lap("objective")
            if col_status == "interrupted":
                break
    except KeyboardInterrupt:  # Ctrl-C: the current iterate, status interrupted
        status = "interrupted"
    for j in range(Phi.shape[1], k):  # interrupted: the modes not reached are their projected starts
        y = np.asarray(Psi0[:, j]) if Psi0 is not None else rng.standard_normal(n)
        z = y - Phi @ (Phi.T @ (a * y))
        Phi = np.concatenate([Phi, (z / np.sqrt(np.sum(a * z * z)))[:, None]], axis=1)
    Psi_out = orthonormalize(Phi, a)
    return ADMMResult(
        Psi=Psi_out, objective=_true_objective(W, w, mu, Psi_out), iterations=total_it, status=status,
        history=hist.arrays(), wall_time=time.perf_counter() - t0,
        factor_time=estep.factor_time, n_factorizations=estep.count, rho0=rho0, step_times=clock.totals,
    )
