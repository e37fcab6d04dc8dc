"""Compressed manifold modes: manifold methods vs the ADMM baseline (docs/maths.md §4–5)."""

import numpy as np
import pytest
import scipy.sparse as sp

import mesh
from objectives.admm.splitting import ADMMOptions, admm
from objectives.cmm.modes import compressed_modes, first_eigenpairs
from objectives.cmm.solvers import ADMMCMM, BlockCMM, FastCMM, SequentialCMM, SolverOptionError

from mesh_fixtures import hand_laplacian, hand_mesh, knight_laplacian, knight_mesh

# A generated mesh (tests/mesh_fixtures.py): the starfish example at size 0 (642 vertices, closed, five
# arms of different lengths). It replaced both hand_868.obj ("hand") and decimated-knight.off (502
# vertices, "knight"); the two fixtures keep the names of the tests' original meshes.
#
# The hand's tests used μ = 0.01·n and ADMM/fast ρ = 100. The starfish's first eigenvalues are about
# 1.7× the hand's (λ_5 = 63.5 against 38.5), so the analogue is μ = 0.02·n (μ/λ_5 ≈ 0.2 on both; at
# 0.01·n the starfish's modes were hardly sparse: 3 % of entries below 1e-3·peak, against the hand's 13 %),
# and ρ = 200 (ρ = 100 left ADMM at objective 3058 after 3000 iterations, 17× the block solver's 184.26).
HAND_MU = 0.02
ADMM_RHO = 200.0


@pytest.fixture(scope="module")
def hand():
    return hand_laplacian()


@pytest.fixture(scope="module")
def hand_block(hand):
    """The default block solve on the hand (k = 6, μ = HAND_MU·n, uniform weighting), shared by the
    tests that compare with it: 200 iterations (4 starts screened, the chosen one's 98), objective 184.2571,
    15 % of entries below 1e-3·peak."""
    return compressed_modes(hand, 6, HAND_MU * hand.n, weighting="uniform")


@pytest.fixture(scope="module")
def knight():
    return knight_laplacian()


def principal_cosines(lap, X, Y):
    a = lap.A.diagonal()
    return np.linalg.svd(X.T @ (a[:, None] * Y), compute_uv=False)


def test_cross_method_agreement_on_hand(hand, hand_block):
    """Hand stand-in, k = 6, μ = 0.02·n, uniform weighting: the manifold solver is within 1% of ADMM (or lower)
    (measured: ADMM 184.25796 after its 3000 iterations, the block solver 184.25864 in 98; hand_868 at
    μ = 0.01·n: 157.3856 and 157.3841)."""
    n = hand.n
    mu = HAND_MU * n
    ref = compressed_modes(hand, 6, mu, solver=ADMMCMM(rho=ADMM_RHO, adapt_rho=False, max_iters=3000),
                           weighting="uniform")
    res = hand_block
    assert res.params["continuation"] == 4  # the default solver: BlockCMM()
    assert res.objective <= 1.01 * ref.objective, (res.objective, ref.objective)
    for r in (ref, res):
        assert r.orthogonality <= 1e-10
        assert np.all(np.diff(r.compressed_eigenvalues) >= 0)
        np.testing.assert_allclose(r.dirichlet + r.l1, r.objective, rtol=1e-12)
    # the modes are localised: a sizeable fraction is (numerically) zero (measured 15.0 %; hand_868 12.8 %)
    assert res.sparsity["1e-3"] > 0.05


@pytest.mark.parametrize("solver", [BlockCMM, pytest.param(SequentialCMM, marks=pytest.mark.slow)])
def test_mu_zero_gives_eigenfunctions(knight, solver):
    """μ = 0: the modes span the first k Laplacian eigenfunctions (subspace angle ≤ 1e-6)."""
    k = 5
    W, a = knight.W, knight.A.diagonal()
    _, evecs = first_eigenpairs(W, a, k)
    res = compressed_modes(knight, k, 0.0, solver=solver(gtol=1e-9, continuation=1), start="random")
    cos = principal_cosines(knight, evecs, res.modes)
    assert np.arccos(np.clip(cos.min(), -1, 1)) <= 1e-6
    assert res.orthogonality <= 1e-10


def test_admm_mu_zero_gives_eigenfunctions(knight):
    """ρ = 100: the knight's ρ = 50 scaled with the eigenvalues (λ_4 = 29.3 on the stand-in, 19.1 on the knight;
    ρ = 50 ran out of its 4000 iterations at a right angle; ρ = 100 converges in 67, angle 8.4e-6)."""
    k = 5
    _, evecs = first_eigenpairs(knight.W, knight.A.diagonal(), k)
    res = compressed_modes(knight, k, 0.0, solver=ADMMCMM(rho=100.0, adapt_rho=False, max_iters=4000), start="random")
    cos = principal_cosines(knight, evecs, res.modes)
    assert np.arccos(np.clip(cos.min(), -1, 1)) <= 1e-3


@pytest.mark.slow
def test_isometry_permuted_mesh_gives_permuted_modes(knight):
    """Prop. 3.5.4: on a vertex-permuted mesh, from the permuted start, the CMMs are the permuted CMMs."""
    m = knight_mesh()
    perm = np.random.default_rng(0).permutation(m.vertices.shape[0])
    lap_p = mesh.laplacian(mesh.permute(m, perm), weights="cotangent", area="lumped")
    k, mu = 4, 0.01 * knight.n
    X0 = np.random.default_rng(1).standard_normal((knight.n, k))
    # permute(m, perm): new vertex i is old vertex perm[i]
    solver = BlockCMM(gtol=1e-9, continuation=1, eps=1e-2, delta=1e-2)
    res = compressed_modes(knight, k, mu, solver=solver, start=X0)
    res_p = compressed_modes(lap_p, k, mu, solver=solver, start=X0[perm])
    assert abs(res.objective - res_p.objective) <= 1e-8 * res.objective
    np.testing.assert_allclose(res_p.modes, res.modes[perm], atol=1e-5)


def test_admm_variants_and_history(hand):
    W, a = hand.W, hand.A.diagonal()
    mu = HAND_MU * hand.n
    for variant in ("exact", "thesis"):
        r = admm(W, a, 4, mu, weighting="area", options=ADMMOptions(rho=ADMM_RHO, adapt_rho=False, max_iters=300,
                                                                     variant=variant))
        assert r.Psi.shape == (hand.n, 4)
        np.testing.assert_allclose(r.Psi.T @ (a[:, None] * r.Psi), np.eye(4), atol=1e-10)
        h = r.history
        assert len(h["objective"]) == r.iterations and np.all(np.isfinite(h["objective"]))
        assert np.all(np.diff(h["time"]) >= 0)
        assert h["objective"][-1] < h["objective"][0]


def test_bad_parameters(hand):
    """Problem-level checks in ``compressed_modes``; the solvers' own options in tests/test_cmm_solvers.py."""
    with pytest.raises(SolverOptionError, match="solver must be a CMM solver object"):
        compressed_modes(hand, 3, 1.0, solver="newton")
    with pytest.raises(ValueError, match="k must"):
        compressed_modes(hand, hand.n + 1, 1.0)
    with pytest.raises(ValueError, match="mu"):
        compressed_modes(hand, 3, -1.0)
    with pytest.raises(ValueError, match="diagonal"):
        compressed_modes((hand.W, hand.A + sp.eye(hand.n, k=1) * 1e-6), 3, 1.0)
    with pytest.raises(ValueError, match="unknown weighting"):
        compressed_modes(hand, 3, 1.0, weighting="cotangent")
    with pytest.raises(ValueError, match="unknown start"):
        compressed_modes(hand, 3, 1.0, start="zeros")
    with pytest.raises(ValueError, match="start must have shape"):
        compressed_modes(hand, 3, 1.0, start=np.zeros((hand.n, 2)))
    with pytest.raises(SolverOptionError, match="unknown preconditioner"):
        BlockCMM(preconditioner="ilu")
    with pytest.raises(TypeError, match="preconditioner"):  # the sequential solver has no such option
        SequentialCMM(preconditioner="active_set")
    with pytest.raises(SolverOptionError, match="unknown optimizer"):
        BlockCMM(optimizer="newton")
    with pytest.raises(TypeError, match="optimizer"):
        SequentialCMM(optimizer="lbfgs")
    with pytest.raises(SolverOptionError, match="continuation"):
        BlockCMM(continuation=0)
    with pytest.raises(SolverOptionError, match="stage_window"):
        BlockCMM(stage_window=0)


def test_block_continuation_stops_intermediate_stages_early(hand):
    """Block solve of one start: 4 smoothing stages, the first three stopped by stage_ftol over
    stage_window iterations; the last runs to gtol/ftol, so the objective is that of the
    single-stage solve (hand stand-in, k = 6, μ = 0.02n: 98 iterations against 121 single-stage
    and 116 with the intermediate stages run to the tight tolerance; hand_868 at μ = 0.01n: 95, 116, 122)."""
    mu = HAND_MU * hand.n
    one = compressed_modes(hand, 6, mu, solver=BlockCMM(continuation=1, starts=1), weighting="uniform")
    res = compressed_modes(hand, 6, mu, solver=BlockCMM(starts=1), weighting="uniform")
    full_stages = compressed_modes(hand, 6, mu, solver=BlockCMM(stage_ftol=1e-9, starts=1), weighting="uniform")
    assert res.params["continuation"] == 4 and one.params["continuation"] == 1
    assert res.params["stage_ftol"] == 3e-4 and res.params["stage_window"] == 5
    assert res.status == "converged" and res.orthogonality <= 1e-10
    assert abs(res.objective - one.objective) <= 1e-6 * one.objective
    assert abs(full_stages.objective - one.objective) <= 1e-6 * one.objective
    assert res.iterations < full_stages.iterations
    assert "screened_starts" not in res.params
    h = res.history  # one entry per iterate: a stage's start is the previous stage's end
    assert len(h["time"]) == len(h["objective"]) == res.iterations + 1
    assert np.all(np.diff(h["time"]) >= 0)


def test_block_screens_rotated_starts_and_goes_on_from_the_lowest(hand, hand_block):
    """The default screens the eigenbasis and 3 rotations of it through the intermediate stages and
    finishes the start whose true objective is lowest there: the same solve as that rotation given as
    an array start with ``starts=1``; the iterations are those of every screen plus the last stage's, the
    history the chosen start's."""
    res = hand_block
    screened = res.params["screened_starts"]
    assert res.params["starts"] == 4 and len(screened) == 4
    assert [c["status"] for c in screened] == ["converged"] * 4
    chosen = [j for j, c in enumerate(screened) if c["chosen"]]
    assert len(chosen) == 1 and screened[chosen[0]]["objective"] == min(c["objective"] for c in screened)
    others = sum(c["iterations"] for j, c in enumerate(screened) if j != chosen[0])
    assert len(res.history["objective"]) == res.iterations - others + 1
    assert res.history["objective"][screened[chosen[0]]["iterations"]] == screened[chosen[0]]["objective"]
    # the chosen start, solved alone
    from objectives.cmm.block_stages import rotated_starts  # noqa: PLC0415
    from objectives.cmm.modes import first_eigenpairs  # noqa: PLC0415
    _, U = first_eigenpairs(hand.W, hand.A.diagonal(), 6)
    X0 = rotated_starts(U, 4, 0)[chosen[0]]
    alone = compressed_modes(hand, 6, HAND_MU * hand.n, weighting="uniform", start=X0, solver=BlockCMM(starts=1))
    assert "screened_starts" not in alone.params  # an array start is used as given
    assert abs(alone.objective - res.objective) <= 1e-9 * res.objective
    assert alone.iterations == res.iterations - others
    # rotations keep the span and the A-orthonormality
    for X in rotated_starts(U, 4, 0):
        np.testing.assert_allclose(X.T @ (hand.A @ X), np.eye(6), atol=1e-12)
        np.testing.assert_allclose(U @ (U.T @ (hand.A @ X)), X, atol=1e-10)


def test_block_screen_interrupted_or_out_of_budget_ends_the_solve(hand):
    """A stop while the second start is screened ends the solve there (status ``interrupted``, no last stage), though
    the first start, screened in full, is the one returned — also when the stop answers True only once; a budget
    spent in the screen ends it as ``max_iters``."""
    mu = HAND_MU * hand.n
    pulse, stages_seen = [], []

    def progress(info):
        if stages_seen and info.stage < stages_seen[-1] and not stages_seen.count(-1):  # the next start began
            pulse.append(True)
            stages_seen.append(-1)
        stages_seen.append(info.stage)

    res = compressed_modes(hand, 6, mu, weighting="uniform", finish=None, progress=progress,
                           stop=lambda: bool(pulse and pulse.pop()))
    screened = res.params["screened_starts"]
    assert res.status == "interrupted" and len(screened) == 2 and screened[1]["status"] == "interrupted"
    assert res.iterations == sum(c["iterations"] for c in screened)  # nothing after the screen
    spent = compressed_modes(hand, 6, mu, solver=BlockCMM(max_iters=70), weighting="uniform", finish=None)
    assert spent.status == "max_iters" and spent.iterations == 70
    assert spent.params["screened_starts"][-1]["status"] == "max_iters"


def test_block_screen_with_one_stage_and_a_random_start(hand):
    """One smoothing stage: each start's screen is a first run of that stage with the intermediate stop; a random
    start is screened with its rotations too; k = 1 has nothing to rotate."""
    mu = HAND_MU * hand.n
    res = compressed_modes(hand, 6, mu, solver=BlockCMM(continuation=1, starts=2), weighting="uniform",
                           start="random", seed=3)
    assert res.status == "converged" and len(res.params["screened_starts"]) == 2
    assert res.iterations > sum(c["iterations"] for c in res.params["screened_starts"])  # and the last stage
    single = compressed_modes(hand, 1, mu, solver=BlockCMM(starts=3), weighting="uniform", finish=None)
    assert "screened_starts" not in single.params and single.status == "converged"


@pytest.fixture(scope="module")
def hand_local():
    m = hand_mesh()
    return m, mesh.local_functions(m, n_samples=200, seed=0)


def test_fast_lemmas_7_1_2_and_7_1_3(hand, hand_local):
    """Lifted restricted eigenfunctions are A-orthonormal and their Dirichlet energies are the
    restricted eigenvalues, to 1e-10; restricted eigenvalues bound the true ones from above."""
    from objectives.admm.fast import restricted_eigenbasis

    _, lf = hand_local
    k = 8
    evals, lifted, _ = restricted_eigenbasis(hand.W, hand.A, lf.U, k)
    np.testing.assert_allclose(lifted.T @ (hand.A @ lifted), np.eye(k), atol=1e-10)
    np.testing.assert_allclose(np.sum(lifted * (hand.W @ lifted), axis=0), evals, rtol=1e-10, atol=1e-10)
    true = mesh.eigenbasis(hand, k).evals
    assert np.all(evals >= true - 1e-9)


def test_fast_glmh_low_rank_term(hand, hand_local):
    """Algorithm 7 with Q = W + c·BBᵀ restricted without an n × n matrix equals the dense restriction."""
    from objectives.admm.fast import restricted_eigenbasis

    _, lf = hand_local
    B = hand.A @ mesh.eigenbasis(hand, 3).evecs
    ev_lr = restricted_eigenbasis(hand.W, hand.A, lf.U, 5, low_rank=(B, 7.0))[0]
    U = lf.U.toarray()  # test-only dense reference (n = 642)
    Q = hand.W.toarray() + 7.0 * B @ B.T
    import scipy.linalg as sla

    ref = sla.eigh(U.T @ Q @ U, U.T @ hand.A.toarray() @ U, subset_by_index=(0, 4))[0]
    np.testing.assert_allclose(ev_lr, ref, rtol=1e-9, atol=1e-9)


def test_restricted_admm_matches_a_dense_reference(hand, hand_local):
    """Algorithm 8 with sparse restricted matrices equals the dense textbook iteration
    (X = Ā^{-1/2} polar(Ā^{-1/2}B), dense E-step) iterate for iterate (hand stand-in, d = 200, 60 steps)."""
    import scipy.linalg as sla

    from objectives.admm.splitting import soft_threshold
    from objectives.admm.fast import restricted_admm, restricted_matrices

    _, lf = hand_local
    U, a, k, mu, rho, steps = lf.U, hand.A.diagonal(), 4, HAND_MU * hand.n, 80.0, 60
    Wb, Ab = restricted_matrices(hand.W, hand.A, U)
    X0 = np.random.default_rng(3).standard_normal((Wb.shape[0], k))
    got = restricted_admm(hand.W, a, U, k, mu, weighting="uniform", X0=X0,
                          options=ADMMOptions(rho=rho, adapt_rho=False, max_iters=steps, eps_abs=0.0, eps_rel=0.0))
    # dense reference: the same steps with d × d dense matrices
    ev, V = np.linalg.eigh(Ab)
    isq = (V / np.sqrt(ev)) @ V.T
    X = X0 @ np.linalg.inv(sla.sqrtm(X0.T @ Ab @ X0).real)
    E, S = X.copy(), U @ X
    UE, US = np.zeros_like(E), np.zeros_like(S)
    Ud = U.toarray()
    for _ in range(steps):
        P, _, Qt = np.linalg.svd(isq @ (Ab @ (E - UE) + Ud.T @ (a[:, None] * (S - US))), full_matrices=False)
        X = isq @ (P @ Qt)
        E = np.linalg.solve(2 * Wb + rho * Ab, rho * Ab @ (X + UE))
        S = soft_threshold(U @ X + US, mu / hand.n / (rho * a[:, None]))
        UE += X - E
        US += U @ X - S
    assert got.iterations == steps
    Xf = X @ np.linalg.inv(sla.sqrtm(X.T @ Ab @ X).real)
    np.testing.assert_allclose(got.Psi, U @ Xf, atol=1e-9 * np.abs(got.Psi).max())
    np.testing.assert_allclose(got.Psi.T @ (a[:, None] * got.Psi), np.eye(k), atol=1e-10)


def test_fast_method_is_a_reasonable_approximation(hand, hand_local, hand_block):
    """Measured: the fast method's objective is 1.0059× the full solve's (ρ = 200, 1500 iterations)."""
    _, lf = hand_local
    mu = HAND_MU * hand.n
    fast = compressed_modes(hand, 6, mu, solver=FastCMM(lf.U, rho=ADMM_RHO, adapt_rho=False, max_iters=1500),
                            weighting="uniform", finish=None)  # the method's own answer (the default finishes it)
    assert fast.orthogonality <= 1e-10
    full = hand_block
    assert full.objective <= fast.objective <= 1.25 * full.objective
    with pytest.raises(TypeError, match="local_functions"):
        FastCMM()


def test_fast_method_default_rho_is_twice_the_kth_restricted_eigenvalue(hand, hand_local):
    from objectives.admm.fast import restricted_eigenbasis

    _, lf = hand_local
    mu = HAND_MU * hand.n
    res = compressed_modes(hand, 6, mu, solver=FastCMM(lf.U, max_iters=50), weighting="uniform")
    lam = restricted_eigenbasis(hand.W, hand.A, lf.U, 6)[0]
    assert res.params["rho0"] == pytest.approx(2.0 * lam[-1], rel=1e-12)
    assert res.orthogonality <= 1e-10
    given = compressed_modes(hand, 6, mu, solver=FastCMM(lf.U, rho=7.0, max_iters=5), weighting="uniform")
    assert given.params["rho0"] == 7.0


@pytest.mark.slow
def test_select_mu_brackets_a_target_sparsity(knight):
    from objectives.cmm.modes import select_mu

    mu, res, trials = select_mu(knight, 3, 0.4, tol=0.08, max_evals=8, weighting="uniform",
                                solver=BlockCMM(continuation=1, eps=1e-2, delta=1e-2, gtol=1e-5))
    assert abs(res.sparsity["1e-3"] - 0.4) <= 0.08 or len(trials) == 8
    sparsities = [s for _, s, _ in sorted(trials)]
    assert sparsities[0] <= sparsities[-1]  # sparser with larger μ
    assert res.params["mu"] == mu


@pytest.mark.slow
def test_sequential_callback_reports_each_column(knight):
    seen = []
    res = compressed_modes(knight, 3, 0.01 * knight.n, solver=SequentialCMM(max_iters=200),
                           callback=lambda j, info: seen.append((j, np.asarray(info["x"]).copy())))
    assert [j for j, _ in seen] == [0, 1, 2]
    a = knight.A.diagonal()
    X = np.stack([x for _, x in seen], axis=1)
    np.testing.assert_allclose(X.T @ (a[:, None] * X), np.eye(3), atol=1e-10)
    assert res.orthogonality <= 1e-10


def test_active_set_preconditioner_matches_its_dense_definition(hand):
    """P_j = block-diagonal part of (W + σA + diag(c∘pinned_j))⁻¹: free rows solve K_FF, pinned rows 1/(K_ii + c_i)."""
    from objectives.cmm.active_set import ActiveSetPreconditioner

    W, a = hand.W, hand.A.diagonal()
    n, k, mu, width = hand.n, 4, HAND_MU * hand.n, 1e-3
    _, evecs = first_eigenpairs(W, a, k)
    X = evecs.copy()
    X[np.abs(X) < 0.3 * np.abs(X).max(axis=0)] *= 1e-6  # many entries in the flat zone
    pc = ActiveSetPreconditioner(W, a, 0.5, mu, np.full(n, 1.0 / n), width)
    mask = pc.pinned(X)
    assert 0.05 < mask.mean() < 0.95
    # pinned ⇒ in the flat zone and within the ℓ1 subgradient bound
    assert np.all(np.abs(X[mask]) < width)
    pc.refresh(X)
    Y = np.random.default_rng(0).standard_normal((n, k))
    out = pc(Y)
    K = (W + 0.5 * sp.diags(a)).toarray()
    for j in range(k):
        free = ~mask[:, j]
        ref = Y[:, j] / (np.diag(K) + mu / n / (2 * width))
        ref[free] = np.linalg.solve(K[np.ix_(free, free)], Y[free, j])
        np.testing.assert_allclose(out[:, j], ref, rtol=1e-9, atol=1e-12)
        assert Y[:, j] @ out[:, j] > 0  # SPD
    # a continuation stage: the same object with a new width acts as one built with that width
    wider = 3e-3
    pc.set_width(wider)
    pc.refresh(X)
    fresh = ActiveSetPreconditioner(W, a, 0.5, mu, np.full(n, 1.0 / n), wider)
    fresh.refresh(X)
    assert not np.allclose(fresh(Y), out)  # the width matters (the pinned rows' curvature)
    np.testing.assert_allclose(pc(Y), fresh(Y), rtol=1e-12, atol=1e-15)


@pytest.mark.slow
def test_active_set_block_solver_agrees_with_shifted(hand, hand_block):
    """Both preconditioners reach the same CMM objective (within 1e-3) on the hand stand-in, k = 6, μ = 0.02n
    (measured: 9e-9 apart, 106 iterations)."""
    mu = HAND_MU * hand.n
    ref = hand_block
    res = compressed_modes(hand, 6, mu, solver=BlockCMM(preconditioner="active_set", refresh=25), weighting="uniform")
    assert res.status == "converged"
    assert res.orthogonality <= 1e-10
    assert abs(res.objective - ref.objective) <= 1e-3 * ref.objective
    h = res.history  # the chosen start's iterates: every screened start's iterations but the chosen one's are not in it
    others = sum(c["iterations"] for c in res.params["screened_starts"] if not c["chosen"])
    assert len(h["time"]) == len(h["objective"]) == res.iterations - others + 1
    assert np.all(np.diff(h["time"]) >= 0)


@pytest.mark.parametrize("preconditioner", ["shifted", pytest.param("active_set", marks=pytest.mark.slow)])
def test_lbfgs_block_solver_agrees_with_cg(hand, hand_block, preconditioner):
    """optimizer="lbfgs" reaches CG's CMM objective (within 1e-3) on the hand stand-in, k = 6, μ = 0.02n
    (measured: 2e-8 and 7e-9 apart, 100 and 109 iterations)."""
    mu = HAND_MU * hand.n
    ref = hand_block
    res = compressed_modes(hand, 6, mu, solver=BlockCMM(optimizer="lbfgs", preconditioner=preconditioner, refresh=25),
                           weighting="uniform")
    assert res.status == "converged", res.status
    assert res.params["optimizer"] == "lbfgs"
    assert res.orthogonality <= 1e-10
    assert abs(res.objective - ref.objective) <= 1e-3 * ref.objective


def test_soft_threshold_is_the_l1_prox():
    """S-step: soft_threshold(v, t) = argmin_s t|s| + ½(s − v)² (checked on a fine grid)."""
    from objectives.admm.splitting import soft_threshold

    grid = np.linspace(-3.0, 3.0, 60001)
    for v, t in [(2.0, 0.5), (-1.2, 0.3), (0.2, 0.5), (0.0, 1.0), (-0.4, 0.4)]:
        best = grid[np.argmin(t * np.abs(grid) + 0.5 * (grid - v) ** 2)]
        assert abs(float(soft_threshold(np.asarray(v), t)) - best) <= 1e-4
    V = np.array([[1.0, -2.0], [0.1, 0.0]])
    np.testing.assert_array_equal(soft_threshold(V, np.array([[0.5], [0.2]])), [[0.5, -1.5], [0.0, 0.0]])


@pytest.mark.slow
def test_precomputed_eigenpairs_give_the_same_solve(knight):
    """``eigenpairs=`` replaces the eigensolve (same start and shift, so the same modes); bad pairs are
    refused before any work."""
    from stiefel.errors import NonFiniteError, ParameterError, ShapeError

    W, a = knight.W, knight.A.diagonal()
    pairs = first_eigenpairs(W, a, 4)  # what compressed_modes computes for k = 4
    solver = BlockCMM(max_iters=300)
    ref = compressed_modes(knight, 4, 0.05 * knight.n, solver=solver)
    got = compressed_modes(knight, 4, 0.05 * knight.n, solver=solver, eigenpairs=pairs)
    assert got.iterations == ref.iterations and np.array_equal(got.modes, ref.modes)
    more = first_eigenpairs(W, a, 6)  # more pairs than needed: the first max(k, 2) are used
    assert compressed_modes(knight, 4, 0.05 * knight.n, solver=solver, eigenpairs=more).objective == pytest.approx(
        ref.objective, rel=1e-6)
    with pytest.raises(ShapeError, match="at least max"):
        compressed_modes(knight, 4, 1.0, eigenpairs=(pairs[0][:3], pairs[1][:, :3]))
    with pytest.raises(ParameterError, match="pair"):
        compressed_modes(knight, 4, 1.0, eigenpairs=pairs[0])
    with pytest.raises(ParameterError, match="ascending"):
        compressed_modes(knight, 4, 1.0, eigenpairs=(pairs[0][::-1], pairs[1]))
    bad = pairs[1].copy()
    bad[0, 0] = np.nan
    with pytest.raises(NonFiniteError):
        compressed_modes(knight, 4, 1.0, eigenpairs=(pairs[0], bad))
