"""Exact-support finish: compressed modes with exact zeros from a smoothed solution (docs/maths.md §9).

A smoothed ℓ1 (``f0 … f9``) leaves the entries that the true ℓ1 would zero at ``|Φ_ij| ≲ δ``. This
finish identifies the support ``S`` (entries above ``threshold`` of their column's peak) with the signs
``s`` there, and solves the *true* problem restricted to that support and sign pattern,

    min  tr(ΦᵀWΦ) + μ Σ_{(i,j)∈S} w_i s_ij Φ_ij   over   ΦᵀAΦ = I,  Φ_ij = 0 off S,    (9.16)

which is smooth: on ``S`` with fixed signs ``μ Σ w|Φ|`` is linear. Its feasible set is a submanifold of
the support's coordinates; with the A-metric its normal space at Φ is ``{S∘(ΦΛ) : Λ = Λᵀ}`` (A
diagonal), so the tangent projection is ``P(V) = V − S∘(ΦΛ)`` with ``L_S(Λ) = sym(ΦᵀAV)`` (eq. 9.15,
``objectives.energy.l1_optimality.MaskedGram``), and

    grad f = P(S∘A⁻¹∇f),   Hess f[ξ] = P(S∘(2A⁻¹Wξ − ξΛ)),  Λ = L_S⁻¹ sym(Φᵀ S∘∇f)   (9.17)

(``∇f = 2WΦ + μ w∘s``; Λ is the Lagrange multiplier). Newton steps by preconditioned truncated CG
(one sparse Cholesky factor of ``2(W + σA)``, its solves masked to the support), Armijo
backtracking on the true objective, and an orthant-wise retraction: entries that would cross zero are
set to zero and leave ``S``, then ``ΦᵀAΦ = I`` is restored by Newton's method along ``S∘(ΦΛ)`` (zeros stay
exactly zero). Zero entries that violate (9.9) (``|v_ij| > μ w_i``, ``v = 2WΦ − AΦΛ*``, Λ* the certifying
multiplier of (9.10)) join ``S`` with the sign ``−sign v_ij`` once their violation is comparable to the gradient
on ``S``; zeros of ``S`` whose projected step points out of their orthant leave ``S`` before the line search, and
zeros dropped after a failed line search are not freed again before a step is taken.
It stops when the gradient on ``S`` is at round-off or the objective stalls; the exact stationarity residual
(9.10) is the convergence measure ("converged" only when it is at most ``tol``, else "stalled"); it also stops as
"cycling" when its steps keep sending the zeros just freed back out (``CYCLE_LIMIT``). A start that does
not converge is followed by starts from other thresholds (``SupportFinish.retry_thresholds``); the best is returned.
The restricted problem itself is ``objectives.cmm.restricted``.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import scipy.sparse as sp
from jaxtyping import Float

from stiefel.validation import check_count, check_number

from ..admm.splitting import _true_objective as true_objective  # tr(ΦᵀWΦ) + μ Σ w_i |Φ_ij| (docs/maths.md §4)
from ..energy.l1_optimality import L1Stationarity, MaskedGram, l1_stationarity, support_stats
from .restricted import _Restricted, _truncated_cg

#: zero entries violating (9.9) join the support once their excess (A⁻¹-norm) is ≥ this × the gradient on the
#: support (measured on example:bumpy from the block modes, k = 10, μ = 2λ: 1 → 10 cut the entries added and dropped
#: from 2.2·10⁵ to 8.9·10⁴ and the finish from 17 s to 7 s, same minimum)
ADD_RATIO = 10.0
#: support entries below this fraction of their column's peak count as at zero for leaving the support
TINY = 1e-6
#: relative change of the objective within its round-off (``_at_floor``)
ROUNDOFF = 1e-12
#: a Newton run stops as "stalled" when the objective fell by ≤ 1e-10 (relative) over this many steps
STALL_WINDOW = 20
#: a Newton run stops as "cycling" when, this many steps in a row, the step sends at least half of the zeros it has
#: just freed straight out of the support again (the certificate's Λ* and the support's multiplier disagree on them).
#: Measured on hand_868 from the screened block modes (k = 10, μ = 2λ): ~47 entries freed and dropped every step at a
#: violation of 1e-2 until the start's budget — 60 and 100 steps from 1e-4 and 1e-3, then 1e-5 converged in 11
#: (8.8 s → 2.1 s with the rule); 3 stopped ManPG's n = 4096, r = 10, μ = 0.1 start that converges later, 5 does not
#: (the finish from the block modes of 77 problems: the same 73 converge, 189 s → 154 s)
CYCLE_LIMIT = 5
__all__ = ["SupportFinish", "FinishResult", "finish_support"]

FINISH_STATUSES = ("converged", "stalled", "cycling", "max_rounds", "max_iters", "line_search_failed",
                   "retraction_failed", "objective_increased", "non_finite")


@dataclasses.dataclass(frozen=True, kw_only=True)
class SupportFinish:
    """Options of the exact-support finish (``finish_support``; ``compressed_modes(finish=...)``).

    threshold: initial support = entries with ``|Φ_ij| > threshold · max_i |Φ_ij|`` (relative, in [0, 1)).
    retry_thresholds: when the finish from ``threshold`` does not converge it starts again from each of these in
      turn (same Ψ; each start has its own Newton budget) until one converges; the best outcome is returned — a
      converged one, else the lowest objective. Measured from the block modes on 50 problems (22 meshes at
      μ = 0.01n and 2λ, ManPG's 24 Schrödinger cases, RPN-CG's 4): 1e-3 alone converged on 44 (decimated-knight at
      2λ: the cut raised the objective by 2 % and the finish could not recover it), 1e-4 alone on 45 (every mesh),
      1e-4 then 1e-3 then 1e-5 on 46; the starts disagree only on ManPG's r = 10 cases. ``()``: one start.
    gtol: a support's Newton solve stops at ``‖grad‖_A ≤ gtol · scale`` (scale of eq. 9.10).
    tol: the certificate: "converged" only when the exact ℓ1 stationarity residual (9.10, relative) is ≤ tol.
    max_rounds: active-set rounds (drop sign flips / add violators); max_newton: Newton steps per start.
    max_cg: CG iterations per Newton step. kkt_margin: a zero entry is freed when
    ``|v_ij| > (1 + kkt_margin) μ w_i``.
    """

    threshold: float = 1e-4
    retry_thresholds: tuple[float, ...] = (1e-3, 1e-5)
    gtol: float = 1e-9
    tol: float = 1e-8
    max_rounds: int = 30
    max_newton: int = 300
    max_cg: int = 200
    kkt_margin: float = 1e-8

    def __post_init__(self) -> None:
        from .base import SolverOptionError

        check_number("threshold", self.threshold, low=0.0, high=1.0, high_open=True, error=SolverOptionError)
        if not isinstance(self.retry_thresholds, tuple):
            raise SolverOptionError(f"retry_thresholds must be a tuple of thresholds in [0, 1), got "
                                    f"{self.retry_thresholds!r}")
        for t in self.retry_thresholds:
            check_number("retry_thresholds entry", t, low=0.0, high=1.0, high_open=True, error=SolverOptionError)
        check_number("gtol", self.gtol, low=0.0, error=SolverOptionError)
        check_number("tol", self.tol, low=0.0, low_open=True, error=SolverOptionError)
        check_number("kkt_margin", self.kkt_margin, low=0.0, error=SolverOptionError)
        check_count("max_rounds", self.max_rounds, 1, error=SolverOptionError)
        check_count("max_newton", self.max_newton, 1, error=SolverOptionError)
        check_count("max_cg", self.max_cg, 1, error=SolverOptionError)


@dataclasses.dataclass
class FinishResult:
    """What ``finish_support`` returns.

    Psi: ``(n, k)`` A-orthonormal with exact zeros (the input when the finish was rejected);
    status: one of ``FINISH_STATUSES``; objective / objective_before: the true objective after and before;
    stationarity: eq. (9.10) of ``Psi``; rounds, newton_iterations, cg_iterations, w_products;
    added / removed: support entries freed / dropped over all rounds; wall_time (s);
    support: ``support_stats`` of ``Psi`` (exact-zero fraction, support sizes and areas per mode);
    attempts: per start tried (``SupportFinish.retry_thresholds``) its threshold, status, objective, residual,
    Newton iterations and seconds; the counts above are summed over them, ``trace`` is the returned start's;
    trace: ``(T, 5)`` per Newton iterate — true objective, ``‖grad‖_A`` on the support and the (9.9) violation
    of the zeros (``A⁻¹``-norm), both relative to the scale of eq. 9.10, support size, CG iterations of its step.
    """

    Psi: np.ndarray
    status: str
    objective: float
    objective_before: float
    stationarity: L1Stationarity
    rounds: int
    newton_iterations: int
    cg_iterations: int
    w_products: int
    added: int
    removed: int
    wall_time: float
    support: dict
    trace: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 5)))
    attempts: list = dataclasses.field(default_factory=list)


def _at_floor(prob: _Restricted, trial, W_trial, f_trial: float, f: float, gnorm: float) -> bool:
    """A full step whose decrease is below the round-off of f (Armijo cannot see it) is taken when it keeps the
    support and halves the gradient: near the minimiser Newton's quadratic convergence shows in the gradient
    long after f has stopped moving (measured: the hand stand-in, k = 6, stopped at residual 1.7e-8 without)."""
    if f_trial > f + ROUNDOFF * max(abs(f), 1.0) or np.any(trial[1] != prob.mask):
        return False
    grad = prob.point(trial[0], W_trial)[2]
    return bool(np.sqrt(prob.inner(grad, grad)) <= 0.5 * gnorm)


def _newton(prob: _Restricted, Phi, gtol_abs: float, scale: float, budget: int, max_cg: int, margin: float,
            trace: list):
    """Orthant-wise Riemannian Newton-CG on (9.16): Armijo backtracking on the true objective along
    ``orthant_retract`` (entries reaching zero leave the support). Returns (Φ, WΦ, steps, cg, dropped,
    status); appends ``(objective, ‖grad‖_A / scale, violation / scale, support size, CG iterations)`` per
    iterate to ``trace``."""
    WPhi = prob.matvec(Phi)
    f = prob.value(Phi, WPhi)
    steps = cg = dropped = added = 0
    recent = [f]  # objective values of the last STALL_WINDOW steps
    freed = np.zeros_like(prob.mask, dtype=bool)  # entries the violation rule freed (see the stuck rule)
    blocked = np.zeros_like(freed)  # zeros dropped after a failed search, not re-freed until a step is taken
    cycles = 0  # consecutive steps that sent most of the zeros just freed back out (CYCLE_LIMIT)
    while True:
        gram, lam, grad = prob.point(Phi, WPhi)
        gnorm = np.sqrt(prob.inner(grad, grad))
        if not np.isfinite(gnorm):
            return Phi, WPhi, steps, cg, dropped, added, "non_finite"
        # support entries at (or within TINY of) zero that descent would push out of their orthant leave the
        # support: a step would cut them at zero, and the cut breaks the step's first-order decrease
        peak = np.max(np.abs(Phi), axis=0, keepdims=True)
        # entries freed as violators of (9.9) are exempt while nonzero: a minimiser's entries can be that small
        # (measured: bumpy.off, k = 10, μ = 0.01n, two entries at 6.5e-7 of their peak), and dropping them
        # re-creates the violation that freed them — a cycle that stalled at residual 1.6e-6
        stuck = (prob.mask > 0) & (np.abs(Phi) <= TINY * peak) & (grad * prob.signs > 0) & ~(freed & (Phi != 0.0))
        if stuck.any():
            mask = prob.mask.copy()
            mask[stuck] = 0.0
            new = (Phi, WPhi, f)
            if np.any(Phi[stuck] != 0.0):  # a failed restoration keeps the entries (new = None)
                restored = prob.restore(mask * Phi, mask)
                W_restored = None if restored is None else prob.matvec(restored)
                new = None if restored is None else (restored, W_restored, prob.value(restored, W_restored))
            # zeroing entries below TINY of the peak moves the objective by next to nothing: a restoration that
            # moved it more jumped elsewhere (an ill-conditioned Gram map) and is refused, the entries stay
            if new is not None and new[2] <= f + 1e-9 * max(abs(f), 1.0):
                dropped += int(stuck.sum())
                Phi, WPhi, f = new
                prob.set_support(mask, prob.signs)
                gram, lam, grad = prob.point(Phi, WPhi)
                gnorm = np.sqrt(prob.inner(grad, grad))
        # zero entries violating (9.9) join the support when their violation is comparable to the gradient
        violate, viol_norm, v = prob.violations(Phi, WPhi, margin)
        violate &= ~blocked
        trace.append([f, gnorm / scale, viol_norm / scale, int(prob.mask.sum()), 0])
        just = np.zeros_like(freed)
        if violate.any() and viol_norm >= ADD_RATIO * gnorm:
            just = violate
            added += int(violate.sum())
            mask, signs = prob.mask.copy(), prob.signs.copy()
            mask[violate] = 1.0
            signs[violate] = -np.sign(v[violate])
            freed |= violate
            prob.set_support(mask, signs)
            gram, lam, grad = prob.point(Phi, WPhi)
            gnorm = np.sqrt(prob.inner(grad, grad))
        elif gnorm <= gtol_abs:
            return Phi, WPhi, steps, cg, dropped, added, "converged"
        if steps >= budget:
            return Phi, WPhi, steps, cg, dropped, added, "max_iters"
        eta, n_cg = _truncated_cg(prob, gram, Phi, lam, grad, min(0.5, np.sqrt(gnorm / scale)), max_cg)
        cg += n_cg
        trace[-1][4] = n_cg
        found, sent_back = None, 0
        for attempt in range(2):  # the Newton direction, then (if it fails) the preconditioned gradient
            if attempt == 1:
                eta = -prob.precondition(gram, Phi, grad)
            # support entries at zero whose (tangent) move leaves their orthant leave the support, until none do
            # (then the step moves every zero inward to first order and the Armijo slope is honest)
            for _ in range(10):
                eta = prob.project(gram, Phi, prob.mask * eta)
                bad = (prob.mask > 0) & (Phi == 0.0) & (eta * prob.signs < 0)
                if not bad.any():
                    break
                sent_back += int(np.sum(bad & just)) if attempt == 0 else 0
                dropped += int(bad.sum())
                mask = prob.mask.copy()
                mask[bad] = 0.0
                prob.set_support(mask, prob.signs)
                gram, lam, grad = prob.point(Phi, WPhi)
                gnorm = np.sqrt(prob.inner(grad, grad))
            slope = prob.inner(grad, eta)
            if not slope < 0.0:  # not a descent direction: steepest descent
                eta, slope = -grad, -gnorm**2
            t = 1.0
            for _ in range(50):
                trial = prob.orthant_retract(Phi + t * eta, gram)
                if trial is not None:
                    W_trial = prob.matvec(trial[0])
                    f_trial = prob.value(trial[0], W_trial)
                    if f_trial <= f + 1e-4 * t * slope or (t == 1.0 and _at_floor(prob, trial, W_trial, f_trial, f, gnorm)):
                        found = trial
                        break
                if -slope * t <= 1e-15 * max(abs(f), 1.0):  # below round-off of f: no measurable decrease left
                    break
                t *= 0.5
            if found is not None:
                break
        steps += 1
        if just.any():
            cycles = cycles + 1 if 2 * sent_back >= int(just.sum()) else 0
            if cycles >= CYCLE_LIMIT:
                return Phi, WPhi, steps, cg, dropped, added, "cycling"
        if found is None:  # no decrease along the direction: the round-off floor (or a failed restore)
            zeros = (prob.mask > 0) & (Phi == 0.0)
            floor = -slope <= 1e-12 * max(abs(f), 1.0) or gnorm <= 1e3 * gtol_abs
            if not floor and zeros.any():  # freed zeros blocked every step: drop them and go on
                dropped += int(zeros.sum())
                blocked |= zeros
                mask = prob.mask.copy()
                mask[zeros] = 0.0
                prob.set_support(mask, prob.signs)
                continue
            return Phi, WPhi, steps, cg, dropped, added, ("converged" if floor else "line_search_failed")
        Phi, mask = found
        blocked[:] = False
        recent = (recent + [f_trial])[-STALL_WINDOW:]
        if len(recent) == STALL_WINDOW and recent[0] - recent[-1] <= 1e-10 * max(abs(f_trial), 1.0):
            if np.any(mask != prob.mask):
                prob.set_support(mask, prob.signs)
            return Phi, W_trial, steps, cg, dropped, added, "stalled"
        if np.any(mask != prob.mask):
            dropped += int(np.sum(prob.mask - mask))
            prob.set_support(mask, prob.signs)
        WPhi, f = W_trial, f_trial


def _start(prob: _Restricted, Psi):
    """The first point on the support: Ψ cut to the support and restored, its entries taking the signs they have
    there — small entries that the restoration moved across zero keep their new sign rather than leaving the
    support (dropping them and restoring again failed on hand_868 from the block modes, k = 10, μ = 2λ: the cut
    removed what had kept two barely overlapping modes orthogonal). ``(Φ, mask, signs)``, or None when the
    restoration fails."""
    Z = prob.restore(prob.mask * Psi, prob.mask)
    if Z is None:
        return None
    mask = prob.mask * (Z != 0.0)
    return Z, mask, np.sign(Z) * mask


def finish_support(W, a: Float[np.ndarray, " n"], w: Float[np.ndarray, " n"], mu: float,
                   Psi: Float[np.ndarray, "n k"], options: SupportFinish = SupportFinish(),
                   sigma: float | None = None) -> FinishResult:
    """Exact-support finish of A-orthonormal modes Ψ (a smoothed or ADMM solution) on the true ℓ1 problem.

    W: ``(n, n)`` sparse PSD; a: ``(n,)`` diag A; w: ``(n,)`` ℓ1 weights (``l1_weights_np``); μ ≥ 0;
    Psi: ``(n, k)``; sigma: the preconditioner's shift (default: the largest diagonal of the start's
    multiplier, ≈ 2 × the largest compressed eigenvalue). Returns a ``FinishResult``: M-orthonormal to
    1e-12 (1e-14 typically) with exact zeros, or — when the finish would raise the true objective — the input with status
    ``objective_increased``. Never raises on a failed solve: the status says what happened.
    """
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # non-finite values end in a status
        return _finish(W, a, w, mu, Psi, options, sigma)


def _finish(W, a, w, mu: float, Psi, options: SupportFinish, sigma: float | None) -> FinishResult:
    t0 = time.perf_counter()
    W = sp.csr_matrix(W, dtype=np.float64)
    a = np.asarray(a, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64)
    Psi = np.asarray(Psi, dtype=np.float64)
    k = Psi.shape[1]
    before = true_objective(W, w, mu, Psi)
    WPsi = W @ Psi
    if sigma is None:
        lam0 = MaskedGram(Psi, a).solve(Psi.T @ (2.0 * WPsi + mu * w[:, None] * np.sign(Psi)))
        sigma = max(float(np.max(np.diag(lam0))) / 2.0, 1e-12)
    scale = float(np.sqrt(np.sum((2.0 * WPsi) ** 2 / a[:, None])) + mu * np.sqrt(k * np.sum(w**2 / a)))
    ones = np.ones_like(Psi)
    prob = _Restricted(W, a, w, mu, ones, np.sign(Psi), sigma)  # one factor for every start
    attempts, best, work = [], None, np.zeros(5, dtype=int)  # work: rounds, Newton, CG, added, removed
    for threshold in (options.threshold, *options.retry_thresholds):
        t1 = time.perf_counter()
        run = _attempt(prob, Psi, before, scale, options, threshold)
        work += run[-1]
        attempts.append(dict(threshold=threshold, status=run[1], objective=run[2], residual=run[3].relative,
                             newton_iterations=int(run[-1][1]), seconds=time.perf_counter() - t1))
        if best is None or _better(run, best):
            best = run
        if best[1] == "converged":
            break
    Phi, status, after, stationarity, trace, _ = best
    return FinishResult(Psi=Phi, status=status, objective=after, objective_before=before,
                        stationarity=stationarity, rounds=int(work[0]), newton_iterations=int(work[1]),
                        cg_iterations=int(work[2]), w_products=prob.products, added=int(work[3]),
                        removed=int(work[4]), wall_time=time.perf_counter() - t0, support=support_stats(Phi, a),
                        trace=np.asarray(trace, dtype=np.float64).reshape(-1, 5), attempts=attempts)


def _better(run, best) -> bool:
    """A converged outcome beats any other; among the rest (or among converged ones) the lower objective wins."""
    if (run[1] == "converged") != (best[1] == "converged"):
        return run[1] == "converged"
    return run[2] < best[2]


def _attempt(prob: _Restricted, Psi, before: float, scale: float, options: SupportFinish, threshold: float):
    """The finish from the support of Ψ's entries above ``threshold`` of their column's peak: ``(Φ, status,
    objective, stationarity, trace, work)``, Ψ itself (status ``objective_increased``) when it would raise the
    objective."""
    W, a, w, mu = prob.W, prob.a, prob.w, prob.mu
    peak = np.max(np.abs(Psi), axis=0, keepdims=True)
    mask = (np.abs(Psi) > threshold * peak).astype(np.float64)
    prob.set_support(mask, np.sign(Psi) * mask)
    gtol_abs = options.gtol * scale
    rounds = newton = cg = added = removed = 0
    status = "max_rounds"
    trace: list = []
    start = _start(prob, Psi)
    Phi = None if start is None else start[0]
    if start is None:
        status = "retraction_failed"
    else:
        removed += int(np.sum(mask - start[1]))
        prob.set_support(start[1], start[2])
    while Phi is not None and rounds < options.max_rounds:
        rounds += 1
        Phi, WPhi, steps, n_cg, dropped, n_added, st = _newton(
            prob, Phi, gtol_abs, scale, options.max_newton - newton, options.max_cg, options.kkt_margin, trace)
        newton, cg, removed, added = newton + steps, cg + n_cg, removed + dropped, added + n_added
        status = st
        if st != "line_search_failed" or steps <= 1:  # a failed line search is retried once from a new round
            break
    if Phi is None or not np.all(np.isfinite(Phi)):
        Phi, status = Psi, (status if status != "max_rounds" else "non_finite")
    after = true_objective(W, w, mu, Phi)
    if after > before + 1e-12 * abs(before):
        Phi, after, status = Psi, before, "objective_increased"
    stationarity = l1_stationarity(W, a, w, mu, Phi)
    if status in ("converged", "stalled", "cycling"):  # the steps stopped: (9.10) tells round-off from a stall
        status = "converged" if stationarity.relative <= options.tol else ("stalled" if status == "converged" else status)
    return Phi, status, after, stationarity, trace, np.array([rounds, newton, cg, added, removed])
