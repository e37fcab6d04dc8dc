"""Functional maps (objectives.fmaps; thesis §5.1–5.3, docs/maths.md §8).

Pairs: the knight and a vertex-permuted copy (an exact discrete isometry, Def. 3.4.8)
and the knight and a noisy copy (same connectivity, not isometric).
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
from mesh_fixtures import shared_mesh

K = 12


def _functions(m, lap, sources):
    """Corresponding descriptor functions: normal bumps of geodesic distance from ``sources`` + HKS."""
    lam, Phi = mesh.eigenbasis(lap, 30)
    bumps = mesh.normdist(mesh.geodists(m, sources), r=0.2)
    return np.hstack([bumps, mesh.hks(lam, Phi, times=10)])


@functools.lru_cache(maxsize=None)
def _isometric_pair():
    m = shared_mesh("decimated-knight.off")
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
    m = shared_mesh("decimated-knight.off")
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
