"""ADMM's penalty ρ (``objectives.admm.rho``): the thesis variants' scale, two-way residual balancing, the
scaled-dual invariant, per-step timings, Algorithm 8 in its printed form, and the option checks
(docs/maths.md §5–6; thesis §2.4.2, Algorithms 3 and 8, Table 7.2)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import mesh
from stiefel_cmm.cli.demo_mesh import demo_mesh
from objectives.admm.splitting import ADMMOptions, admm, admm_sequential, orthonormalize, soft_threshold
from objectives.admm.rho import STEPS, RhoRule, default_rho, penalty_scale
from objectives.cmm.modes import compressed_modes
from objectives.cmm.solvers import ADMMCMM, FastCMM, SequentialADMMCMM, SolverOptionError
from objectives.admm.fast import _a_orthonormal_maximiser, _thesis_x_step, restricted_admm
from stiefel.errors import ParameterError
from stiefel.linalg.sparse_factor import SymmetricFactor

K = 4


@pytest.fixture(scope="module")
def small():
    """The demo mesh at 2 subdivisions (n = 162): ``(W csr, a)``."""
    lap = mesh.laplacian(mesh.load(demo_mesh(subdivisions=2)))
    return sp.csr_matrix(lap.W), lap.A.diagonal().copy()


@pytest.fixture(scope="module")
def demo():
    """The demo mesh at 3 subdivisions (n = 642) and 64 local functions."""
    m = mesh.load(demo_mesh(subdivisions=3))
    lap = mesh.laplacian(m)
    return lap, mesh.local_functions(m, n_samples=lap.n // 10).U


# ---------------------------------------------------------------------------- ρ's scale


def test_default_rho_is_on_the_a_norm_scale_and_rho_overrides_it(small):
    W, a = small
    n = len(a)
    assert default_rho("exact", 30.0, n) == 30.0 and default_rho("exact", 0.2, n) == 1.0
    assert default_rho("thesis", 30.0, n) == pytest.approx(30.0 / n) and penalty_scale("thesis", n) == 1.0 / n
    for variant, expected in (("exact", 1.62), ("thesis", 1.62 / n)):
        res = admm(W, a, K, 1.62, options=ADMMOptions(variant=variant, max_iters=3))
        assert res.rho0 == pytest.approx(expected, rel=1e-15)
        assert admm(W, a, K, 1.62, options=ADMMOptions(variant=variant, rho=7.0, max_iters=3)).rho0 == 7.0


@pytest.mark.parametrize("rule", [False, "both"])
def test_thesis_variant_with_its_scaled_rho_repeats_the_exact_iterates_when_a_is_i_over_n(small, rule):
    """With A = I/n the thesis's Ψ-step is exact, and its Frobenius penalty at ρ/n is the A-norm penalty at ρ:
    the default ρ₀ (and a given one divided by n) give the same iterates in both variants, and so does
    residual balancing, which compares the residuals on the A-norm scale."""
    W, a = small
    n = len(a)
    a_uniform = np.full(n, 1.0 / n)
    mu = 0.01 * n
    X0 = np.random.default_rng(3).standard_normal((n, K))
    rho = None if rule is False else 1000.0  # "both": a start 10× too stiff, lowered 4 times
    runs = {v: admm(W, a_uniform, K, mu, Psi0=X0,
                    options=ADMMOptions(variant=v, adapt_rho=rule, rho=rho if rho is None or v == "exact" else rho / n,
                                        max_iters=120, adapt_every=5, eps_abs=0.0, eps_rel=0.0))
            for v in ("exact", "thesis")}
    exact, thesis = runs["exact"], runs["thesis"]
    assert thesis.rho0 == pytest.approx(exact.rho0 / n, rel=1e-15)
    np.testing.assert_allclose(thesis.history["rho"] * n, exact.history["rho"], rtol=1e-12)
    np.testing.assert_allclose(thesis.Psi, exact.Psi, atol=1e-9 * np.abs(exact.Psi).max())
    np.testing.assert_allclose(thesis.history["objective"], exact.history["objective"], rtol=1e-9)
    if rule == "both":
        assert exact.history["rho"][-1] == 62.5
    # the solver objects scale ρ₀ = 2λ_{k−1} of the eigenbasis start alike
    res = {v: compressed_modes((W, sp.diags_array(a_uniform)), K, mu, solver=ADMMCMM(variant=v, max_iters=20))
           for v in ("exact", "thesis")}
    assert res["thesis"].params["rho0"] == pytest.approx(res["exact"].params["rho0"] / n, rel=1e-12)


# ---------------------------------------------------------------------------- two-way balancing


def _rule(adapt_rho, n=None, **kw):
    return RhoRule(ADMMOptions(adapt_rho=adapt_rho, adapt_every=1, **kw), n)


def test_two_way_balancing_raises_and_lowers_rho():
    both, increase = _rule("both"), _rule("increase")
    assert both.update(1, 1.0, 1e-3) == 2.0 and increase.update(1, 1.0, 1e-3) == 2.0  # r > η s: raise
    assert both.update(2, 1e-3, 1.0) == 0.5  # s > η r, raw and relative: lower
    assert increase.update(2, 1e-3, 1.0) == 1.0  # "increase" never lowers
    assert both.update(3, 1.0, 0.5) == 1.0  # within a factor η: keep
    # lowering also needs the dual residual to dominate relative to Boyd's tolerance scales (‖Ψ‖ vs ‖ρU‖):
    # not when the multipliers are large (s/‖ρU‖ small) — raw, it would lower
    assert both.update(4, 1e-3, 1.0, primal_scale=1.0, dual_scale=1e4) == 1.0
    assert (both.raised, both.lowered) == (1, 1)
    assert _rule(False).update(1, 1.0, 1e-9) == 1.0
    assert RhoRule(ADMMOptions(adapt_rho="both", adapt_every=10)).update(5, 1.0, 1e-9) == 1.0  # not a check


def test_the_thesis_variants_residuals_are_compared_on_the_a_norm_scale():
    """For the same iterate the Frobenius variant's r/s is n times the A-norm variant's (A = I/n)."""
    exact, thesis = _rule("both", 100), _rule("both", 100, variant="thesis")
    assert exact.update(1, 1.0, 0.05) == 2.0  # r/s = 20 > η
    assert thesis.update(1, 1.0, 0.05) == 1.0  # r/(n s) = 0.2
    assert thesis.update(2, 1.0, 1e-4) == 2.0  # r/(n s) = 100
    assert thesis.update(3, 1.0, 1.0) == 1.0  # n s / r = 100, but s/‖ρU‖ = r/‖Ψ‖
    assert thesis.update(4, 1.0, 1.0, dual_scale=1e-2) == 0.5  # and s/‖ρU‖ = 100 r/‖Ψ‖


def test_stall_guard_raises_rho_unless_the_primal_residual_is_within_its_tolerance():
    rule = _rule("both")
    rho = 1.0
    for it in range(1, 12):  # the primal residual does not improve, neither residual dominates
        rho = rule.apply(it, 1.0, 1.0, rho)
    assert rho == 2.0 and rule.raised == 1
    calm = _rule("increase")
    assert all(calm.apply(it, 1e-9, 1e-9, 1.0, primal_tol=1e-8) == 1.0 for it in range(1, 40))


@pytest.mark.parametrize("variant", ["exact", "thesis"])
def test_two_way_balancing_moves_a_bad_rho0_back_in_both_variants(small, variant):
    W, a = small
    n = len(a)
    mu = 0.01 * n
    for factor, moved in ((1e3, "lowered"), (1e-3, "raised")):
        rho0 = factor * default_rho(variant, mu, n)
        res = admm(W, a, K, mu, seed=1, options=ADMMOptions(variant=variant, adapt_rho="both", rho=rho0,
                                                           max_iters=400))
        rho = res.history["rho"]
        assert (rho.min() < rho0 / 10) if moved == "lowered" else (rho.max() > 10 * rho0), (factor, rho[-1])
        orth = res.Psi.T @ (a[:, None] * res.Psi)
        assert np.max(np.abs(orth - np.eye(K))) <= 1e-10


def test_rescaling_keeps_the_unscaled_duals():
    rule = _rule("both")
    UE, US = np.full((3, 2), 0.3), np.full((4, 2), -1.5)
    before = 5.0 * UE, 5.0 * US
    rho = rule.apply(1, 1.0, 1e-4, 5.0, UE, US)  # raised
    assert rho == 10.0
    np.testing.assert_allclose(rho * UE, before[0], rtol=1e-15)
    np.testing.assert_allclose(rho * US, before[1], rtol=1e-15)


def _unscaled_reference(W, a, k, mu, X0, rho, schedule, iters):
    """Algorithm 3 (exact form, area weights) with unscaled multipliers y = ρU, dense, and a given ρ schedule."""
    Wd = W.toarray()
    sq = np.sqrt(a)[:, None]
    Psi = orthonormalize(X0, a)
    E, S = Psi.copy(), Psi.copy()
    yE, yS = np.zeros_like(Psi), np.zeros_like(Psi)
    for it in range(1, iters + 1):
        UE, US = yE / rho, yS / rho
        u, _, vt = np.linalg.svd(sq * 0.5 * (E - UE + S - US), full_matrices=False)
        Psi = (u @ vt) / sq
        E = np.linalg.solve(2.0 * Wd + rho * np.diag(a), rho * a[:, None] * (Psi + UE))
        S = soft_threshold(Psi + US, mu / rho)
        yE += rho * (Psi - E)
        yS += rho * (Psi - S)
        rho *= schedule.get(it, 1.0)
    return Psi


def test_a_rho_schedule_with_rescaled_duals_is_the_unscaled_iteration(small, monkeypatch):
    """The scaled-dual invariant over a run: changing ρ and dividing U by the factor is the same ADMM as
    keeping the multipliers y = ρU (textbook form), whatever the schedule."""
    W, a = small
    n = len(a)
    mu = 0.01 * n
    X0 = np.random.default_rng(5).standard_normal((n, K))
    schedule = {3: 2.0, 6: 0.5, 7: 0.25, 10: 8.0}
    monkeypatch.setattr(RhoRule, "update", lambda self, it, *args, **kw: schedule.get(it, 1.0))
    res = admm(W, a, K, mu, Psi0=X0, options=ADMMOptions(rho=40.0, max_iters=14, eps_abs=0.0, eps_rel=0.0))
    np.testing.assert_allclose(res.history["rho"], 40.0 * np.cumprod([1.0] + [schedule.get(i, 1.0)
                                                                             for i in range(1, 14)]))
    ref = _unscaled_reference(W, a, K, mu, X0, 40.0, schedule, 14)
    np.testing.assert_allclose(res.Psi, ref, atol=1e-10 * np.abs(ref).max())


# ---------------------------------------------------------------------------- per-step timings


def _check_steps(res):
    assert set(res.step_times) == set(STEPS)
    assert all(t > 0.0 for t in res.step_times.values()), res.step_times
    assert sum(res.step_times.values()) <= res.wall_time


def test_step_times_of_every_admm(small, demo):
    W, a = small
    mu = 0.01 * len(a)
    for variant in ("exact", "thesis"):
        _check_steps(admm(W, a, K, mu, options=ADMMOptions(variant=variant, max_iters=30)))
    _check_steps(admm_sequential(W, a, K, mu, options=ADMMOptions(max_iters=40)))
    lap, U = demo
    for variant in ("exact", "thesis"):
        _check_steps(restricted_admm(lap.W, lap.A.diagonal(), U, K, 0.01 * lap.n,
                                     options=ADMMOptions(variant=variant, max_iters=30)))
    for solver in (ADMMCMM(max_iters=20), SequentialADMMCMM(max_iters=20), FastCMM(U, variant="thesis", max_iters=20)):
        res = compressed_modes(lap, K, 0.01 * lap.n, solver=solver)
        steps = res.params["step_times"]
        assert set(steps) == set(STEPS) and all(t > 0.0 for t in steps.values())
        assert sum(steps.values()) <= res.wall_time


# ---------------------------------------------------------------------------- Algorithm 8 as printed


def test_printed_x_step_is_the_maximiser_for_the_frobenius_penalties(demo):
    """docs/maths.md note 4's X-step: with ``Z = E − U^E + S̃`` and ``ỸᵀỸ = ¼ZᵀUᵀUZ``, ``X = √n Z (ZᵀUᵀUZ)^{-1/2}``
    maximises ``tr(XᵀUᵀUZ)`` over ``(UX)ᵀ(UX) = nI``."""
    lap, U = demo
    n, d = U.shape
    U = sp.csr_array(U)
    G = sp.csr_array(U.T @ U)
    factor = SymmetricFactor(G)
    rng = np.random.default_rng(0)
    E, UE = rng.standard_normal((d, K)), 0.1 * rng.standard_normal((d, K))
    S, US = rng.standard_normal((n, K)), 0.1 * rng.standard_normal((n, K))
    X = _thesis_x_step(E, UE, S, US, U.T.tocsr(), factor, G, np.sqrt(n))
    UX = U @ X
    np.testing.assert_allclose(UX.T @ UX, n * np.eye(K), atol=1e-10 * n)
    Z = E - UE + factor.solve(U.T @ (S - US)).reshape(E.shape)
    best = np.sqrt(n) * _a_orthonormal_maximiser(G @ Z, factor)
    np.testing.assert_allclose(X, best, atol=1e-10 * np.abs(best).max())


def test_printed_algorithm_8_is_a_orthonormal_and_close_to_the_exact_form(demo):
    """Both forms end exactly Ā-orthonormal (1e-10); from the same restricted eigenbasis start the printed
    form's objective is within 5% of the exact form's (measured: +1.3% at 800 iterations, area weights)."""
    lap, U = demo
    mu = 0.01 * lap.n
    a = lap.A.diagonal()
    res = {v: compressed_modes(lap, K, mu, solver=FastCMM(U, variant=v, max_iters=800)) for v in ("exact", "thesis")}
    for r in res.values():
        assert r.orthogonality <= 1e-10
    assert abs(res["thesis"].objective / res["exact"].objective - 1.0) <= 0.05
    assert res["thesis"].params["rho0"] == pytest.approx(res["exact"].params["rho0"] / lap.n, rel=1e-12)
    raw = restricted_admm(lap.W, a, U, K, mu, seed=2, options=ADMMOptions(variant="thesis", max_iters=200))
    np.testing.assert_allclose(raw.Psi.T @ (a[:, None] * raw.Psi), np.eye(K), atol=1e-10)
    assert raw.rho0 == pytest.approx(max(mu, 1.0) / lap.n)


# ---------------------------------------------------------------------------- option checks


@pytest.mark.parametrize("options, match", [
    (dict(variant="frobenius"), "unknown ADMM variant 'frobenius'"),
    (dict(adapt_rho="sometimes"), "adapt_rho must be"),
    (dict(adapt_rho=2), "adapt_rho must be"),
    (dict(rho=0.0), "rho must be"),
    (dict(rho=-1.0), "rho must be"),
    (dict(rho=float("nan")), "rho must be"),
    (dict(rho_tau=1.0), "rho_tau must be a finite number > 1"),
    (dict(rho_ratio=1.0), "rho_ratio must be a finite number > 1"),
    (dict(adapt_every=0), "adapt_every must be an integer ≥ 1"),
])
def test_bad_admm_options_raise_named_errors(options, match):
    with pytest.raises(ParameterError, match=match):
        ADMMOptions(**options)


def test_bad_solver_options_and_variants_raise_named_errors(small, demo):
    W, a = small
    U = demo[1]
    with pytest.raises(ParameterError, match="exact"):
        admm_sequential(W, a, K, 1.0, options=ADMMOptions(variant="thesis"))
    for make, match in ((lambda: FastCMM(U, variant="printed"), "unknown ADMM variant"),
                        (lambda: ADMMCMM(adapt_rho="decrease"), "adapt_rho must be"),
                        (lambda: FastCMM(U, rho_ratio=0.5), "rho_ratio must be a finite number > 1")):
        with pytest.raises(SolverOptionError, match=match):
            make()

