"""The ADMM penalty ρ: its default scale, residual balancing, and per-step clocks (docs/maths.md §5–6).

Shared by ``objectives.admm.splitting`` (Algorithm 3) and ``objectives.admm.fast`` (Algorithm 8).

**Scale.** The exact variants measure the augmented-Lagrangian penalties in the A-norm, the thesis
variants (``A ≈ rI``, ``r = 1/n``) in the Frobenius norm. For ``A = rI`` the two are the same iteration
when ``ρ_Frobenius = r·ρ_A`` (``(ρ_A/2)‖Y‖²_A = (rρ_A/2)‖Y‖²_F``): ``penalty_scale`` is that ``r`` (1 for the
exact variants) and every default ρ₀ is multiplied by it (``default_rho``: ``max(μ, 1)·r``).

**Balancing** (Boyd et al. 2011 §3.4.1, thesis §2.4.2): ``RhoRule`` multiplies ρ by ``τ`` or ``1/τ`` when one
residual exceeds ``η`` times the other and rescales the scaled duals ``U ← U/factor`` so that the unscaled
multipliers ``y = ρU`` — the state of the method — are unchanged by the step. The rules were measured against
each other once (``docs/benchmarks/admm-rho.md``).

**Clocks.** ``StepClock`` sums the wall time of each step (``STEPS``) for ``ADMMResult.step_times``.
"""

from __future__ import annotations

import time

import numpy as np

from stiefel.errors import ParameterError

__all__ = ["VARIANTS", "RULES", "rule_name", "check_variant", "check_rule", "penalty_scale", "default_rho",
           "RhoRule", "StepClock", "STEPS"]

#: the ADMM variants: A-norm penalties (exact steps) or the thesis's Frobenius penalties with A ≈ I/n
VARIANTS = ("exact", "thesis")
#: the values of ``adapt_rho``: ``"increase"``, ``"both"`` (``True`` is ``"both"``), ``False`` (fixed ρ)
RULES = ("increase", "both", True, False)


def rule_name(adapt_rho) -> str:
    """``"increase"``, ``"both"`` or ``"fixed"`` for a valid ``adapt_rho``."""
    if adapt_rho is False:
        return "fixed"
    return "both" if adapt_rho is True else adapt_rho


def check_variant(variant, error: type[Exception] = ParameterError) -> str:
    """``variant`` one of ``VARIANTS``, else ``error`` naming the choices."""
    if not isinstance(variant, str) or variant not in VARIANTS:
        raise error(f"unknown ADMM variant {variant!r}; choose one of {VARIANTS}")
    return variant


def check_rule(adapt_rho, error: type[Exception] = ParameterError):
    """``adapt_rho`` one of ``"increase"``, ``"both"``, ``True``, ``False``, else ``error``."""
    if isinstance(adapt_rho, (bool, np.bool_)) or (isinstance(adapt_rho, str) and adapt_rho in RULES):
        return bool(adapt_rho) if isinstance(adapt_rho, np.bool_) else adapt_rho
    raise error(f"adapt_rho must be 'increase', 'both', True or False, got {adapt_rho!r}")


def penalty_scale(variant: str, n: int) -> float:
    """The factor from an A-norm penalty to this variant's: 1 (``"exact"``) or ``r = 1/n`` (``"thesis"``)."""
    return 1.0 if check_variant(variant) == "exact" else 1.0 / n


def default_rho(variant: str, mu: float, n: int) -> float:
    """ρ₀ when none is given: ``max(μ, 1)`` on the A-norm scale, times ``penalty_scale``."""
    return max(float(mu), 1.0) * penalty_scale(variant, n)


class RhoRule:
    """ρ adaptation (``options.adapt_rho``), checked every ``options.adapt_every`` iterations.

    Both rules raise ρ ← τρ when the primal residual dominates, ``r > η s``, or when it has not improved by
    1% over ``stall_checks`` checks while above its tolerance ``primal_tol`` (the stall guard): on this
    nonconvex problem a too-small ρ lets the copies E, S drift from Ψ while neither residual dominates
    (fandisk, camelhead and armadillo diverged at ρ = 3λ_k without it). ``r/s`` is compared on the A-norm
    scale (``penalty_scale``·r/s, given ``n``): for the same iterate the Frobenius variants' r/s is n times the
    A-norm one's, and on their own scale ``"increase"`` drove the thesis variant's ρ n times too stiff.

    ``"increase"``: ρ never decreases.

    ``"both"`` (Boyd §3.4.1 both ways) also lowers ρ ← ρ/τ when the dual residual dominates — both raw,
    ``s > η r``, and relative to the scales of Boyd's relative tolerances, ``s/‖ρ(U^E + U^S)‖ >
    η r/max(‖(Ψ, Ψ)‖, ‖(E, S)‖)`` (Wohlberg 2017). Lowering on the raw test alone is what diverged: while a
    too-small ρ lets the iterates wander, the raw dual residual exceeds η times the primal one, so every raise
    by the stall guard was undone at the next check and ρ stayed where the iteration never settles (bumpy,
    k = 10, μ = n/100, ρ₀ = μ, random start: objective 9.8e4 after 2000 iterations; 751 with the relative test).
    Raising on the relative test as well failed the other way (starfish, thesis variant: 945 vs 876), so the
    relative test only vetoes lowering. No floor is needed: from a start 2562 times too stiff, ``"both"``
    lowers ρ by 2⁸ and reaches 751.0 (exact) / 767.8 (thesis), ``"increase"`` 839 / 847.

    ``update(it, primal, dual, primal_scale, dual_scale, primal_tol)`` returns the factor to multiply ρ by;
    ``apply`` also divides the scaled duals by it (in place), so the unscaled multipliers ``ρU`` — the
    method's state — are unchanged by the step. ``raised``/``lowered`` count the changes.
    """

    def __init__(self, options, n: int | None = None, *, stall_checks: int = 10):
        self.mode = rule_name(options.adapt_rho)
        self.ratio = float(options.rho_ratio)
        self.tau = float(options.rho_tau)
        self.every = int(options.adapt_every)
        self.scale = 1.0 if n is None else penalty_scale(options.variant, n)
        self.stall_checks = stall_checks
        self.best = np.inf
        self.stalled = 0
        self.raised = 0
        self.lowered = 0

    def update(self, it: int, primal: float, dual: float, primal_scale: float = 1.0, dual_scale: float = 1.0,
               primal_tol: float = 0.0) -> float:
        if self.mode == "fixed" or it % self.every:
            return 1.0
        if primal < 0.99 * self.best or primal <= primal_tol:  # improving, or already within its tolerance
            self.best, self.stalled = min(primal, self.best), 0
        else:
            self.stalled += 1
        stalled = self.stalled >= self.stall_checks
        tiny = np.finfo(float).tiny
        r_rel, s_rel = primal / max(primal_scale, tiny), dual / max(dual_scale, tiny)
        r_a = self.scale * primal  # r/s on the A-norm scale: the thesis variant's r/s is n times the exact one's
        if r_a > self.ratio * dual or stalled:
            self.best, self.stalled = np.inf, 0
            self.raised += 1
            return self.tau
        if self.mode == "both" and dual > self.ratio * r_a and s_rel > self.ratio * r_rel:
            self.lowered += 1
            return 1.0 / self.tau
        return 1.0

    def apply(self, it: int, primal: float, dual: float, rho: float, *duals: np.ndarray,
              primal_scale: float = 1.0, dual_scale: float = 1.0, primal_tol: float = 0.0) -> float:
        """The new ρ; the scaled duals are divided by its factor in place (``ρU`` unchanged)."""
        factor = self.update(it, primal, dual, primal_scale, dual_scale, primal_tol)
        if factor != 1.0:
            for u in duals:
                u /= factor
        return rho * factor


#: the steps ``StepClock`` times (``step_times`` keys): Ψ-step (X-step in Algorithm 8), E-step, S-step, dual
#: update with the ρ update (its rescaling of the duals), residuals with the stopping test, and the
#: true objective recorded in the history (not part of the method; the thesis variant re-orthonormalises for it)
STEPS = ("psi", "E", "S", "dual", "residual", "objective")


class StepClock:
    """Cumulative wall time per step: ``mark()`` starts a step, ``lap(key)`` adds the time since the last
    mark or lap to ``totals[key]``. Time between a lap and the next mark (monitor, stop checks) is not counted."""

    def __init__(self):
        self.totals = dict.fromkeys(STEPS, 0.0)
        self.last = time.perf_counter()

    def mark(self) -> None:
        self.last = time.perf_counter()

    def lap(self, key: str) -> None:
        now = time.perf_counter()
        self.totals[key] += now - self.last
        self.last = now
