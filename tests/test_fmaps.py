"""Functional maps (objectives.fmaps; thesis §5.1–5.3, docs/maths.md §8).

Pairs: the knight and a vertex-permuted copy (an exact discrete isometry, Def. 3.4.8)
and the knight and a noisy copy (same connectivity, not isometric). The "knight" is the generated
stand-in of tests/mesh_fixtures.py (the starfish example at size 0, 642 vertices), which replaced
decimated-knight.off (502 vertices).
Convention: ``C`` is ``(k_tgt, k_src)``, ``b ≈ C a`` (the thesis's ``Cᵀ``).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
import trimesh

import mesh
from objectives import fmaps
from objectives.evaluation import RankDeficientWarning
from mesh_fixtures import knight_mesh

K = 12


def _functions(m, lap, sources):
    """Corresponding descriptor functions: normal bumps of geodesic distance from ``sources`` + HKS."""
    lam, Phi = mesh.eigenbasis(lap, 30)
    bumps = mesh.normdist(mesh.geodists(m, sources), r=0.2)
    return np.hstack([bumps, mesh.hks(lam, Phi, times=10)])


@functools.lru_cache(maxsize=None)
def _isometric_pair():
    m = knight_mesh()
    rng = np.random.default_rng(7)
    perm = rng.permutation(m.n_vertices)
    inv = mesh.inverse_permutation(perm)
    mp = mesh.permute(m, perm)
    lap, lap_p = mesh.laplacian(m), mesh.laplacian(mp)
    lam, Phi = mesh.eigenbasis(lap, K)
    lam_p, Phi_p = mesh.eigenbasis(lap_p, K)
    signs = rng.choice([-1.0, 1.0], size=K)
    Phi_p = Phi_p * signs  # arbitrary sign flips: C must be diag(signs)
    sources = rng.choice(m.n_vertices, size=20, replace=False)
    F = _functions(m, lap, sources)
    Fp = _functions(mp, lap_p, inv[sources])  # computed on the copy, not copied
    return dict(m=m, mp=mp, perm=perm, lap=lap, lap_p=lap_p, lam=lam, Phi=Phi, lam_p=lam_p, Phi_p=Phi_p,
                signs=signs, F=F, Fp=Fp)


@functools.lru_cache(maxsize=None)
def _noisy_pair():
    m = knight_mesh()
    rng = np.random.default_rng(3)
    e = fmaps.mean_edge_length(m.vertices, m.faces)
    mn = mesh.load((m.vertices + 0.15 * e * rng.standard_normal(m.vertices.shape), m.faces))
    lap, lap_n = mesh.laplacian(m), mesh.laplacian(mn)
    lam, Phi = mesh.eigenbasis(lap, K)
    lam_n, Phi_n = mesh.eigenbasis(lap_n, K - 2)
    sources = rng.choice(m.n_vertices, size=25, replace=False)
    return dict(m=m, mn=mn, lap=lap, lap_n=lap_n, lam=lam, Phi=Phi, lam_n=lam_n, Phi_n=Phi_n,
                F=_functions(m, lap, sources), Fn=_functions(mn, lap_n, sources))


@pytest.fixture
def iso():
    return _isometric_pair()


@pytest.fixture
def noisy():
    return _noisy_pair()


def test_permuted_copy_gives_signed_identity_and_exact_p2p(iso):
    d = iso
    assert np.all(np.diff(d["lam"]) > 1e-6 * d["lam"][-1])  # simple eigenvalues
    for w in (0.0, 1e-3):
        C = fmaps.functional_map(d["Phi"], d["Phi_p"], d["F"], d["Fp"], d["lap"].A, d["lap_p"].A,
                                 evals_src=d["lam"], evals_tgt=d["lam_p"], commutativity=w)
        np.testing.assert_allclose(C, np.diag(d["signs"]), atol=1e-6)
        p = fmaps.p2p_from_fmap(C, d["Phi"], d["Phi_p"])
        np.testing.assert_array_equal(p, d["perm"])  # target vertex i is source vertex perm[i]
    q = fmaps.p2p_from_fmap(C, d["Phi"], d["Phi_p"], direction="src_to_tgt")
    np.testing.assert_array_equal(q, mesh.inverse_permutation(d["perm"]))
    assert fmaps.orthogonality_error(C) < 1e-6
    e = fmaps.mean_edge_length(d["m"].vertices, d["m"].faces)
    assert fmaps.err_gd(p, d["perm"], d["m"].vertices, e) == 0.0


def test_commutativity_rows_match_kronecker_reference(noisy):
    """The row-by-row ridge solve equals the k²-unknown Kronecker least squares of eq. 5.1.11 (dense, test only)."""
    d = noisy
    A_s, A_t = d["lap"].A, d["lap_n"].A
    w = 3e-4
    C = fmaps.functional_map(d["Phi"], d["Phi_n"], d["F"], d["Fn"], A_s, A_t,
                             evals_src=d["lam"], evals_tgt=d["lam_n"], commutativity=w)
    a = d["Phi"].T @ (A_s @ d["F"])
    b = d["Phi_n"].T @ (A_t @ d["Fn"])
    kt, ks = C.shape
    # vec(C a) = (aᵀ ⊗ I) vec C ; vec(Λt C − C Λs) = (I ⊗ Λt − Λs ⊗ I) vec C   (column-major vec)
    lhs = np.vstack([np.kron(a.T, np.eye(kt)),
                     np.sqrt(w) * (np.kron(np.eye(ks), np.diag(d["lam_n"])) - np.kron(np.diag(d["lam"]), np.eye(kt)))])
    rhs = np.concatenate([b.reshape(-1, order="F"), np.zeros(kt * ks)])
    ref = np.linalg.lstsq(lhs, rhs, rcond=None)[0].reshape((kt, ks), order="F")
    np.testing.assert_allclose(C, ref, rtol=1e-8, atol=1e-10)
    C0 = fmaps.functional_map(d["Phi"], d["Phi_n"], d["F"], d["Fn"], A_s, A_t)
    assert np.linalg.norm(C - C0) > 1e-6  # the commutativity term does something


def test_least_squares_map_minimises_err_s(noisy):
    """Thm. 5.3.1: C_ls = argmin ‖ΨB − ΨCA‖_F; ICP refinement (or any perturbation) cannot lower it."""
    d = noisy
    A_s, A_t = d["lap"].A, d["lap_n"].A
    C = fmaps.functional_map(d["Phi"], d["Phi_n"], d["F"], d["Fn"], A_s, A_t)
    assert C.shape == (K - 2, K)
    a = fmaps.function_coefficients(d["Phi"], d["F"], A_s)
    G = d["Phi_n"] @ fmaps.function_coefficients(d["Phi_n"], d["Fn"], A_t)  # ΨB, the theorem's target
    e_ls = fmaps.err_s(C, d["Phi_n"], a, G)
    C_icp, p = fmaps.icp_refine(C, d["Phi"], d["Phi_n"], iters=5)
    e_icp = fmaps.err_s(C_icp, d["Phi_n"], a, G)
    assert e_ls <= e_icp
    assert fmaps.orthogonality_error(C_icp.T) < 1e-10  # rows orthonormal (k_tgt < k_src)
    rng = np.random.default_rng(0)
    for _ in range(5):
        assert e_ls < fmaps.err_s(C + 1e-3 * rng.standard_normal(C.shape), d["Phi_n"], a, G)
    # ICP is a reasonable map on this near-isometric pair (ground truth: identity)
    e = fmaps.mean_edge_length(d["m"].vertices, d["m"].faces)
    assert fmaps.err_gd(p, np.arange(d["mn"].n_vertices), d["m"].vertices, e) < 3.0


def test_err_s_symmetric_for_isometry(iso):
    """Thm. 5.3.2: for an isometric pair Err_S(C) = Err_S(D), D the reverse map; D = Cᵀ (Def. 5.2.5)."""
    d = iso
    A_s, A_t = d["lap"].A, d["lap_p"].A
    C = fmaps.functional_map(d["Phi"], d["Phi_p"], d["F"], d["Fp"], A_s, A_t)
    D = fmaps.functional_map(d["Phi_p"], d["Phi"], d["Fp"], d["F"], A_t, A_s)
    a = fmaps.function_coefficients(d["Phi"], d["F"], A_s)
    b = fmaps.function_coefficients(d["Phi_p"], d["Fp"], A_t)
    e_c = fmaps.err_s(C, d["Phi_p"], a, d["Fp"])
    e_d = fmaps.err_s(D, d["Phi"], b, d["F"])
    assert e_c > 1e-3  # not a trivial zero: the functions are not in the span of the bases
    assert e_c == pytest.approx(e_d, rel=1e-8)
    assert fmaps.c_orthogonality_error(C, D) < 1e-8
    assert fmaps.err_t(C, d["Phi_p"], a, d["Fp"]) == pytest.approx(fmaps.err_t(D, d["Phi"], b, d["F"]), rel=1e-8)


def test_icp_recovers_isometry_from_perturbed_map(iso):
    d = iso
    rng = np.random.default_rng(1)
    C0 = np.diag(d["signs"]) + 0.05 * rng.standard_normal((K, K))
    C, p = fmaps.icp_refine(C0, d["Phi"], d["Phi_p"], iters=20)
    np.testing.assert_array_equal(p, d["perm"])
    np.testing.assert_allclose(C, np.diag(d["signs"]), atol=1e-8)


def test_err_t_and_err_s_relation_lemma_5_2_3(noisy):
    d = noisy
    A_s, A_t = d["lap"].A, d["lap_n"].A
    C = fmaps.functional_map(d["Phi"], d["Phi_n"], d["F"], d["Fn"], A_s, A_t)
    a = fmaps.function_coefficients(d["Phi"], d["F"], A_s)
    S, T = fmaps.err_s(C, d["Phi_n"], a, d["Fn"]), fmaps.err_t(C, d["Phi_n"], a, d["Fn"])
    e = np.linalg.norm(d["Fn"] - d["Phi_n"] @ C @ a, axis=1)
    p = e.size
    np.testing.assert_allclose(S ** 2, p ** 2 * T ** 2 - (e.sum() ** 2 - np.sum(e ** 2)), rtol=1e-10)
    assert T == pytest.approx(e.mean())


def test_err_gd_and_edge_length():
    V = np.array([[0.0, 0, 0], [3.0, 0, 0], [0, 4.0, 0], [3.0, 4.0, 0]])
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    tm = trimesh.Trimesh(V, faces, process=False)
    e = fmaps.mean_edge_length(V, faces)
    assert e == pytest.approx(tm.edges_unique_length.mean())
    assert e == pytest.approx((3 + 4 + 5 + 4 + 3) / 5)
    # mean (docs/maths.md note 9), not sum: distances 5 and 0 → 2.5 / e
    assert fmaps.err_gd(np.array([0, 2]), np.array([3, 2]), V, e) == pytest.approx(2.5 / e)
    with pytest.raises(fmaps.FmapShapeError):
        fmaps.err_gd(np.array([0, 1]), np.array([0]), V, e)


def test_bad_input(iso):
    d = iso
    A_s, A_t = d["lap"].A, d["lap_p"].A
    with pytest.raises(fmaps.TooFewFunctionsError, match="f ≥ k_src"):
        fmaps.functional_map(d["Phi"], d["Phi_p"], d["F"][:, :K - 1], d["Fp"][:, :K - 1], A_s, A_t)
    with pytest.raises(fmaps.FmapShapeError, match="correspond"):
        fmaps.functional_map(d["Phi"], d["Phi_p"], d["F"], d["Fp"][:, :-1], A_s, A_t)
    with pytest.raises(fmaps.FmapShapeError, match="same number of rows"):
        fmaps.functional_map(d["Phi"], d["Phi_p"][:-1], d["F"], d["Fp"], A_s, A_t)
    with pytest.raises(fmaps.FmapShapeError, match="A_tgt"):
        fmaps.functional_map(d["Phi"], d["Phi_p"], d["F"], d["Fp"], A_s, A_t[:-1, :-1])
    with pytest.raises(fmaps.FmapShapeError, match="eigenvalues"):
        fmaps.functional_map(d["Phi"], d["Phi_p"], d["F"], d["Fp"], A_s, A_t, evals_src=d["lam"][:-1],
                             evals_tgt=d["lam_p"], commutativity=1.0)
    with pytest.raises(ValueError, match="needs evals"):
        fmaps.functional_map(d["Phi"], d["Phi_p"], d["F"], d["Fp"], A_s, A_t, commutativity=1.0)
    with pytest.raises(fmaps.FmapShapeError, match="k_tgt, k_src"):
        fmaps.p2p_from_fmap(np.eye(K + 1, K), d["Phi"], d["Phi_p"])
    with pytest.raises(fmaps.FmapShapeError):
        fmaps.c_orthogonality_error(np.eye(K, K - 1), np.eye(K, K - 1))
    # repeated functions: f ≥ k but rank < k → warning, minimum-norm C (not silent)
    F_rep = np.tile(d["F"][:, :4], (1, 4))
    Fp_rep = np.tile(d["Fp"][:, :4], (1, 4))
    with pytest.warns(RankDeficientWarning, match="rank 4 < k_src"):
        fmaps.functional_map(d["Phi"], d["Phi_p"], F_rep, Fp_rep, A_s, A_t)


# ---- commutativity with full operators (any basis; thesis §5.3) -------------------------------------------------


def _kron_reference(a, b, S, T, w):
    """Dense least squares of eq. 5.1.11 for ``‖Ca − b‖² + w‖TC − CS‖²`` with ``np.kron`` (column-major vec)."""
    kt, ks = b.shape[0], a.shape[0]
    lhs = np.vstack([np.kron(a.T, np.eye(kt)), np.sqrt(w) * (np.kron(np.eye(ks), T) - np.kron(S.T, np.eye(kt)))])
    rhs = np.concatenate([b.reshape(-1, order="F"), np.zeros(kt * ks)])
    return np.linalg.lstsq(lhs, rhs, rcond=None)[0].reshape((kt, ks), order="F")


def _random_problem(seed, ks, kt, f=None, n=40):
    """Orthonormal bases (A = None: Euclidean) and functions on ``n`` points: ``a = B_srcᵀF_src``, ``b = B_tgtᵀF_tgt``."""
    rng = np.random.default_rng(seed)
    f = f or ks + 3
    Bs, Bt = np.linalg.qr(rng.standard_normal((n, ks)))[0], np.linalg.qr(rng.standard_normal((n, kt)))[0]
    Fs, Ft = rng.standard_normal((n, f)), rng.standard_normal((n, f))
    return rng, Bs, Bt, Fs, Ft, Bs.T @ Fs, Bt.T @ Ft


def _sym(rng, k):
    X = rng.standard_normal((k, k))
    return X + X.T


@pytest.mark.parametrize("seed, ks, kt, w", [(0, 5, 4, 0.3), (1, 6, 6, 1.0), (2, 4, 7, 0.05), (3, 8, 5, 10.0)])
def test_full_symmetric_operators_match_kronecker_lstsq(seed, ks, kt, w):
    rng, Bs, Bt, Fs, Ft, a, b = _random_problem(seed, ks, kt)
    S, T = _sym(rng, ks), _sym(rng, kt)
    ref = _kron_reference(a, b, S, T, w)
    for solver in ("auto", "eigh", "kronecker"):
        C = fmaps.functional_map(Bs, Bt, Fs, Ft, None, None, op_src=S, op_tgt=T, commutativity=w, op_solver=solver)
        np.testing.assert_allclose(C, ref, rtol=1e-9, atol=1e-10 * np.abs(ref).max(), err_msg=solver)
    # the reference is not a trivial map: both terms pull, and the operator term changes the answer
    C0 = fmaps.functional_map(Bs, Bt, Fs, Ft, None, None)
    assert np.linalg.norm(ref - C0) > 1e-3 * np.linalg.norm(C0)


@pytest.mark.parametrize("seed, ks, kt", [(4, 5, 4), (5, 6, 6)])
def test_non_symmetric_operators_use_kronecker_route(seed, ks, kt):
    rng, Bs, Bt, Fs, Ft, a, b = _random_problem(seed, ks, kt)
    S, T = rng.standard_normal((ks, ks)), rng.standard_normal((kt, kt))
    ref = _kron_reference(a, b, S, T, 0.7)
    for solver in ("auto", "kronecker"):
        C = fmaps.functional_map(Bs, Bt, Fs, Ft, None, None, op_src=S, op_tgt=T, commutativity=0.7, op_solver=solver)
        np.testing.assert_allclose(C, ref, rtol=1e-9, atol=1e-10 * np.abs(ref).max())
    # the symmetric parts give a different map: the route is not silently symmetrising
    Csym = fmaps.functional_map(Bs, Bt, Fs, Ft, None, None, op_src=(S + S.T) / 2, op_tgt=(T + T.T) / 2,
                                commutativity=0.7)
    assert np.linalg.norm(Csym - ref) > 1e-3 * np.linalg.norm(ref)


def test_diagonal_operators_and_rotated_bases_reproduce_evals_path(noisy):
    d = noisy
    args = (d["Phi"], d["Phi_n"], d["F"], d["Fn"], d["lap"].A, d["lap_n"].A)
    w = 3e-4
    C = fmaps.functional_map(*args, evals_src=d["lam"], evals_tgt=d["lam_n"], commutativity=w)
    Cop = fmaps.functional_map(*args, op_src=np.diag(d["lam"]), op_tgt=np.diag(d["lam_n"]), commutativity=w)
    np.testing.assert_array_equal(Cop, C)  # exactly the diagonal code path
    Ckr = fmaps.functional_map(*args, op_src=np.diag(d["lam"]), op_tgt=np.diag(d["lam_n"]), commutativity=w,
                               op_solver="kronecker")
    np.testing.assert_allclose(Ckr, C, rtol=0, atol=1e-12)  # normal equations: ~2e-14 here
    # rotate both eigenbases by random orthogonal R: the operators become Rᵀ Λ R (full), the map RₜᵀCRₛ
    rng = np.random.default_rng(11)
    Rs = np.linalg.qr(rng.standard_normal((K, K)))[0]
    Rt = np.linalg.qr(rng.standard_normal((K - 2, K - 2)))[0]
    Ss, Tt = Rs.T @ np.diag(d["lam"]) @ Rs, Rt.T @ np.diag(d["lam_n"]) @ Rt
    assert np.linalg.norm(Ss - np.diag(np.diag(Ss))) > 0.1 * np.linalg.norm(Ss)
    Crot = fmaps.functional_map(d["Phi"] @ Rs, d["Phi_n"] @ Rt, *args[2:], op_src=Ss, op_tgt=Tt, commutativity=w)
    np.testing.assert_allclose(Crot, Rt.T @ C @ Rs, atol=1e-10)


def test_basis_operator_of_eigenbasis_is_diag_evals(noisy):
    d = noisy
    S = fmaps.basis_operator(d["Phi"], d["lap"].W)
    T = fmaps.basis_operator(d["Phi_n"], d["lap_n"].W.toarray())  # dense W too
    np.testing.assert_array_equal(S, S.T)
    np.testing.assert_allclose(S, np.diag(d["lam"]), atol=1e-9 * d["lam"][-1])
    np.testing.assert_allclose(T, np.diag(d["lam_n"]), atol=1e-9 * d["lam_n"][-1])
    args = (d["Phi"], d["Phi_n"], d["F"], d["Fn"], d["lap"].A, d["lap_n"].A)
    C = fmaps.functional_map(*args, evals_src=d["lam"], evals_tgt=d["lam_n"], commutativity=3e-4)
    Cop = fmaps.functional_map(*args, op_src=S, op_tgt=T, commutativity=3e-4)  # full (rounding) → eigh route
    np.testing.assert_allclose(Cop, C, atol=1e-8)


@functools.lru_cache(maxsize=None)
def _lmh_bases():
    """[Φ_6, 6 LMHs localised at the first bump] on both meshes of the noisy pair, A-orthonormalised (§3.1.1)."""
    from objectives import bases
    d = _noisy_pair()
    out = []
    for lap, Phi, F in ((d["lap"], d["Phi"], d["F"]), (d["lap_n"], d["Phi_n"], d["Fn"])):
        u = F[:, 0] / F[:, 0].max()
        lm = bases.lmh(lap.W, lap.A, 6, Phi[:, :6], mu_perp=1e3, v=(1 - u) ** 2, mu_R=1e2)
        X = bases.concatenate(Phi[:, :6], lm.Psi, lap.A)[0]
        L = np.linalg.cholesky(X.T @ (lap.A @ X))
        out.append(np.linalg.solve(L, X.T).T)  # X L⁻ᵀ: A-orthonormal, same span
    return tuple(out)


def test_lmh_basis_full_commutativity_beats_diagonal_approximation(noisy):
    d = noisy
    Xs, Xt = _lmh_bases()
    np.testing.assert_allclose(Xs.T @ (d["lap"].A @ Xs), np.eye(12), atol=1e-10)
    S, T = fmaps.basis_operator(Xs, d["lap"].W), fmaps.basis_operator(Xt, d["lap_n"].W)
    assert np.linalg.norm(S - np.diag(np.diag(S))) > 0.05 * np.linalg.norm(S)  # genuinely non-diagonal
    args = (Xs, Xt, d["F"], d["Fn"], d["lap"].A, d["lap_n"].A)
    a = fmaps.function_coefficients(Xs, d["F"], d["lap"].A)
    b = fmaps.function_coefficients(Xt, d["Fn"], d["lap_n"].A)
    for w in (1e-3, 1e-2):
        C_full = fmaps.functional_map(*args, op_src=S, op_tgt=T, commutativity=w)
        C_diag = fmaps.functional_map(*args, evals_src=np.diag(S), evals_tgt=np.diag(T), commutativity=w)
        res_full, res_diag = (np.linalg.norm(T @ C - C @ S) for C in (C_full, C_diag))
        assert res_full < 0.7 * res_diag
        J = [np.linalg.norm(C @ a - b) ** 2 + w * np.linalg.norm(T @ C - C @ S) ** 2 for C in (C_full, C_diag)]
        assert J[0] < J[1]  # C_full minimises the true objective
        C_kr = fmaps.functional_map(*args, op_src=S, op_tgt=T, commutativity=w, op_solver="kronecker")
        np.testing.assert_allclose(C_full, C_kr, atol=1e-9)


def test_full_operator_bad_input(noisy, monkeypatch):
    d = noisy
    args = (d["Phi"], d["Phi_n"], d["F"], d["Fn"], d["lap"].A, d["lap_n"].A)
    S, T = np.diag(d["lam"]), np.diag(d["lam_n"])
    err = fmaps.FmapCommutativityError
    assert issubclass(err, ValueError)
    with pytest.raises(err, match="not both"):
        fmaps.functional_map(*args, evals_src=d["lam"], evals_tgt=d["lam_n"], op_src=S, op_tgt=T, commutativity=1.0)
    with pytest.raises(err, match="not both"):  # also when the weight is zero
        fmaps.functional_map(*args, evals_src=d["lam"], op_tgt=T)
    with pytest.raises(err, match="both op_src"):
        fmaps.functional_map(*args, op_src=S, commutativity=1.0)
    with pytest.raises(fmaps.FmapShapeError, match=r"op_tgt has shape \(10, 9\).*square"):
        fmaps.functional_map(*args, op_src=S, op_tgt=T[:, :-1], commutativity=1.0)
    with pytest.raises(fmaps.FmapShapeError, match=r"op_src has shape \(11, 11\); expected \(k_src, k_src\)"):
        fmaps.functional_map(*args, op_src=S[1:, 1:], op_tgt=T, commutativity=1.0)
    S_nan = S.copy()
    S_nan[2, 3] = np.nan
    with pytest.raises(err, match="source operator has 1 non-finite"):
        fmaps.functional_map(*args, op_src=S_nan, op_tgt=T)  # checked even at zero weight
    T_ns = T.copy()
    T_ns[0, 1] = 1.0
    with pytest.raises(err, match="op_tgt is not symmetric.*op_solver='kronecker'"):
        fmaps.functional_map(*args, op_src=S, op_tgt=T_ns, commutativity=1.0, op_solver="eigh")
    for bad_w in (-1e-3, np.nan, np.inf):
        with pytest.raises(err, match="finite and ≥ 0"):
            fmaps.functional_map(*args, op_src=S, op_tgt=T, commutativity=bad_w)
    with pytest.raises(ValueError, match="unknown op_solver"):
        fmaps.functional_map(*args, op_src=S, op_tgt=T, commutativity=1.0, op_solver="lu")
    monkeypatch.setattr(fmaps, "KRONECKER_MAX_UNKNOWNS", 100)
    with pytest.raises(err, match="120 > KRONECKER_MAX_UNKNOWNS = 100"):
        fmaps.functional_map(*args, op_src=S, op_tgt=T_ns, commutativity=1.0)
    # basis_operator
    n = d["m"].n_vertices
    with pytest.raises(fmaps.FmapShapeError, match=rf"W has shape \({n - 1}, {n - 1}\)"):
        fmaps.basis_operator(d["Phi"], d["lap"].W[:-1, :-1])
    with pytest.raises(fmaps.FmapShapeError, match="Psi must be"):
        fmaps.basis_operator(d["Phi"][:, 0], d["lap"].W)
    L = (d["lap"].W.T / d["lap"].A.diagonal()).T  # A⁻¹W, not symmetric
    with pytest.raises(err, match="not the Laplacian"):
        fmaps.basis_operator(d["Phi"], L)
    with pytest.raises(err, match="non-finite"):
        fmaps.basis_operator(np.full_like(d["Phi"], np.nan), d["lap"].W)
