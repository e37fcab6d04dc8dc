"""GLMHs, LMHs, Hamiltonian eigenfunctions (objectives.bases) and basis evaluation (objectives.evaluation).

Thesis §3.1, §3.3 (Thm. 3.3.7), §4.2, §4.6; docs/maths.md §4, §8. Dense n × n matrices appear
here only as references on the 642-vertex knight stand-in (tests/mesh_fixtures.py: the starfish
example at size 0; it replaced decimated-knight.off, 502 vertices).
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
import scipy.linalg as sla
import scipy.sparse as sp

import mesh
from objectives import bases
from objectives import evaluation as ev
from mesh_fixtures import hand_mesh, knight_laplacian, knight_mesh


@functools.lru_cache(maxsize=None)
def _knight():
    m = knight_mesh()
    lap = knight_laplacian()
    lam, Phi = mesh.eigenbasis(lap, 20)
    return m, lap, lam, Phi


@pytest.fixture
def knight():
    return _knight()


def _dense_reference(lap, k, mu_V=0.0, V=None, mu_perp=0.0, Phi=None, M=None):
    Wd, Ad = lap.W.toarray(), lap.A.toarray()
    Q = Wd.copy()
    if mu_V:
        Q += mu_V * Ad @ np.diag(V)
    if mu_perp:
        Q += mu_perp * (Ad @ Phi) @ (Ad @ Phi).T
    Md = Ad if M is None else M.toarray()
    return sla.eigh(0.5 * (Q + Q.T), Md, subset_by_index=(0, k - 1))


# ---------------------------------------------------------------- GLMH


def test_glmh_without_penalties_is_the_eigenbasis(knight):
    m, lap, lam, Phi = knight
    evals, Psi = bases.glmh(lap.W, lap.A, 12, seed=3)
    np.testing.assert_allclose(evals[1:], lam[1:12], rtol=1e-8)
    assert abs(evals[0]) < 1e-8 * lam[1]
    assert ev.principal_angles(Psi, Phi[:, :12], lap.A).max() <= 1e-6
    np.testing.assert_allclose(Psi.T @ (lap.A @ Psi), np.eye(12), atol=1e-10)


@pytest.mark.parametrize("mu_V, mu_perp", [(50.0, 1e3), (1e6, 1e6)])  # the thesis uses μ_R = μ_⊥ = 1e6
def test_glmh_low_rank_path_matches_dense_reference(knight, mu_V, mu_perp):
    m, lap, lam, Phi = knight
    X = mesh.vertex_positions(m)
    _, v, _ = bases.region_from_reconstruction(lap.A, Phi[:, :10], X, quantile=0.8)
    k = 6
    res = bases.glmh(lap.W, lap.A, k, mu_V=mu_V, V=v, mu_perp=mu_perp, Phi=Phi[:, :10])
    w, U = _dense_reference(lap, k, mu_V, v, mu_perp, Phi[:, :10])
    np.testing.assert_allclose(res.evals, w, rtol=1e-8)
    assert ev.principal_angles(res.Psi, U, lap.A).max() <= 1e-6
    assert np.all(np.diff(res.evals) >= 0)
    np.testing.assert_allclose(res.Psi.T @ (lap.A @ res.Psi), np.eye(k), atol=1e-10)
    # the energies are the eigenvalues (Thm. 3.3.7): λ_i = ψ_iᵀ Q ψ_i, Q applied without forming it
    B = lap.A @ Phi[:, :10]
    QPsi = lap.W @ res.Psi + mu_V * (lap.A @ (v[:, None] * res.Psi)) + mu_perp * B @ (B.T @ res.Psi)
    np.testing.assert_allclose(np.sum(res.Psi * QPsi, axis=0), res.evals, rtol=1e-9)


def test_glmh_nondiagonal_mass_and_separate_M(knight):
    """FEM (non-diagonal) A: the potential term is sym(A diag(V)); M may differ from A."""
    m, lap, lam, Phi = knight
    fem = mesh.laplacian(m, area="fem")
    V = np.linspace(0.0, 1.0, m.n_vertices)
    res = bases.glmh(fem.W, fem.A, 5, mu_V=20.0, V=V, M=lap.A)
    Wd, Ad = fem.W.toarray(), fem.A.toarray()
    Q = Wd + 20.0 * Ad @ np.diag(V)
    w, U = sla.eigh(0.5 * (Q + Q.T), lap.A.toarray(), subset_by_index=(0, 4))
    np.testing.assert_allclose(res.evals, w, rtol=1e-8, atol=1e-10)
    assert ev.principal_angles(res.Psi, U, lap.A).max() <= 1e-6


def test_hamiltonian_constant_potential_shifts_the_spectrum(knight):
    """V = c·1: (W + μcA)ψ = (λ + μc)Aψ — same eigenfunctions, eigenvalues shifted by μc (eq. 3.1.7)."""
    m, lap, lam, Phi = knight
    res = bases.hamiltonian(lap.W, lap.A, 8, np.full(m.n_vertices, 0.5), mu_V=30.0)
    np.testing.assert_allclose(res.evals, lam[:8] + 15.0, rtol=1e-9)
    assert ev.principal_angles(res.Psi[:, 1:], Phi[:, 1:8], lap.A).max() <= 1e-6


def test_hamiltonian_negative_potential_default_shift(knight):
    """A potential with negative values (spectrum below 0): the default shift stays below it."""
    m, lap, lam, Phi = knight
    V = -np.ones(m.n_vertices)
    res = bases.hamiltonian(lap.W, lap.A, 4, V, mu_V=5.0)
    np.testing.assert_allclose(res.evals[1:], lam[1:4] - 5.0, rtol=1e-8)
    assert abs(res.evals[0] + 5.0) < 1e-8


def test_potential_from_reconstruction(knight):
    m, lap, lam, Phi = knight
    X = mesh.vertex_positions(m)
    V = bases.potential_from_reconstruction(lap.A, Phi[:, :10], X)
    _, _, e = bases.region_from_reconstruction(lap.A, Phi[:, :10], X)
    assert V.min() == pytest.approx(0.0) and V.max() <= 1.0
    assert np.argmin(V) == np.argmax(e)
    # exactly reconstructed functions: no preferred area
    assert np.all(bases.potential_from_reconstruction(lap.A, Phi[:, :10], Phi[:, :3]) == pytest.approx(1.0))


def test_lmh_orthogonality_and_localisation(knight):
    m, lap, lam, Phi = knight
    X = mesh.vertex_positions(m)
    Phi_k = Phi[:, :10]
    u, v, e = bases.region_from_reconstruction(lap.A, Phi_k, X, quantile=0.85)
    assert u.sum() == int(np.ceil(0.15 * m.n_vertices)) or abs(u.sum() - 0.15 * m.n_vertices) <= 2
    assert np.all(e[u] > e[~u].max())
    a = lap.A.diagonal()
    weak = bases.lmh(lap.W, lap.A, 5, Phi_k, 1e1, v=v, mu_R=0.0)
    strong = bases.lmh(lap.W, lap.A, 5, Phi_k, 1e5, v=v, mu_R=1e3)
    X1, err_weak = bases.concatenate(Phi_k, weak.Psi, lap.A)
    X2, err_strong = bases.concatenate(Phi_k, strong.Psi, lap.A)
    assert X2.shape == (m.n_vertices, 15)
    np.testing.assert_array_equal(X2[:, 10:], strong.Psi)
    assert err_strong == pytest.approx(np.linalg.norm(Phi_k.T @ (lap.A @ strong.Psi)))
    assert err_strong < 1e-2 * err_weak  # the μ_⊥ penalty enforces ΦᵀAΨ ≈ 0 (eq. 3.1.4)
    mass_in_R = lambda P: np.sum(a[u, None] * P[u] ** 2, axis=0)  # noqa: E731
    assert mass_in_R(strong.Psi).min() > 0.8  # μ_R concentrates the LMHs on R
    assert mass_in_R(strong.Psi).mean() > mass_in_R(weak.Psi).mean()


def test_glmh_bad_input(knight):
    m, lap, lam, Phi = knight
    with pytest.raises(ValueError, match="potential V"):
        bases.glmh(lap.W, lap.A, 3, mu_V=1.0)
    with pytest.raises(ValueError, match="Phi"):
        bases.glmh(lap.W, lap.A, 3, mu_perp=1.0, Phi=Phi[:-1])
    with pytest.raises(ValueError, match="k must be an integer"):
        bases.glmh(lap.W, lap.A, m.n_vertices)
    with pytest.raises(ValueError, match="match W"):
        bases.glmh(lap.W, sp.eye(5), 3)


# ---------------------------------------------------------------- reconstruction (§4.2)


def test_least_squares_beats_matrix_manipulation(knight):
    m, lap, lam, Phi = knight
    X = mesh.vertex_positions(m)
    F = np.hstack([X, mesh.hks(lam, Phi, times=np.array([1e-3, 1e-2])), np.sin(5 * X)])
    Phi_k = Phi[:, :10]
    _, v, _ = bases.region_from_reconstruction(lap.A, Phi_k, X)
    Psi = bases.lmh(lap.W, lap.A, 5, Phi_k, 1e2, v=v, mu_R=1e2).Psi
    H = bases.hamiltonian(lap.W, lap.A, 10, bases.potential_from_reconstruction(lap.A, Phi_k, X), 1e2).Psi
    for name, B in [("Phi_k", Phi_k), ("Phi", Phi), ("LMH", Psi), ("Ham", H),
                    ("concat", bases.concatenate(Phi_k, Psi, lap.A)[0])]:
        R_ls, c_ls = ev.reconstruct(F, B)
        R_mm, c_mm = ev.reconstruct(F, B, lap.A, method="manipulation")
        # least squares minimises the Frobenius (root-mean-square) error: a theorem, every basis
        assert np.linalg.norm(F - R_ls) <= np.linalg.norm(F - R_mm) * (1 + 1e-12)
        # the mean per-vertex error of Def. 4.2.2 is smaller too for the A-orthonormal bases with vertex
        # positions (the thesis's observation, §4.3) -- not a theorem: it failed for the 5 LMHs alone on
        # decimated-knight.off (on the stand-in it holds for them too: 0.381 against 0.395)
        if name != "LMH":
            G, RG_ls, RG_mm = F[:, :3], R_ls[:, :3], R_mm[:, :3]
            assert ev.reconstruction_error(G, RG_ls) <= ev.reconstruction_error(G, RG_mm) * (1 + 1e-12), name
        np.testing.assert_allclose(c_ls, np.linalg.solve(B.T @ B, B.T @ F), rtol=1e-6, atol=1e-8)
    # and they differ for a non-uniform A (otherwise the comparison above is vacuous)
    assert np.linalg.norm(F - ev.reconstruct(F, Phi_k)[0]) < 0.999 * np.linalg.norm(
        F - ev.reconstruct(F, Phi_k, lap.A, method="manipulation")[0])


def test_graph_laplacian_methods_coincide(knight):
    """A = I (graph Laplacian, uniform unnormalised area): BᵀB = I, both methods agree (§4.2.3)."""
    m = knight[0]
    g = mesh.laplacian(m, weights="graph", area="uniform", normalize_area=False)
    assert abs(g.A - sp.eye(m.n_vertices)).max() == 0
    _, B = mesh.eigenbasis(g, 15)
    F = mesh.vertex_positions(m)
    R_ls, _ = ev.reconstruct(F, B)
    R_mm, _ = ev.reconstruct(F, B, g.A, method="manipulation")
    np.testing.assert_allclose(R_ls, R_mm, atol=1e-10)
    assert ev.reconstruction_error(F, R_ls) == pytest.approx(ev.reconstruction_error(F, R_mm), rel=1e-10)


def test_reconstruction_error_definition():
    F = np.array([[3.0, 4.0], [0.0, 0.0], [1.0, 1.0]])
    R = np.zeros_like(F)
    assert ev.reconstruction_error(F, R) == pytest.approx((5.0 + 0.0 + np.sqrt(2.0)) / 3)
    np.testing.assert_allclose(ev.per_vertex_error(F, R), [5.0, 0.0, np.sqrt(2.0)])
    with pytest.raises(ValueError, match="differ in shape"):
        ev.reconstruction_error(F, R[:2])


def test_rank_deficient_basis_warns_and_projects(knight):
    m, lap, lam, Phi = knight
    B = np.hstack([Phi[:, :6], Phi[:, :2]])  # repeated functions: rank 6 < 8
    F = mesh.vertex_positions(m)
    with pytest.warns(ev.RankDeficientWarning, match="rank 6 < 8"):
        R, _ = ev.reconstruct(F, B)
    R6, _ = ev.reconstruct(F, Phi[:, :6])
    np.testing.assert_allclose(R, R6, atol=1e-10)  # still the orthogonal projection, not garbage
    with pytest.raises(ValueError, match="same number of rows"):
        ev.reconstruct(F[:-1], B)


def test_basis_in_basis_reconstruction(knight):
    m, lap, lam, Phi = knight
    assert ev.basis_reconstruction_error(Phi[:, :5], Phi[:, :10]) < 1e-12  # nested: exact
    assert ev.basis_reconstruction_error(Phi[:, 10:15], Phi[:, :10], lap.A, method="manipulation") == \
        pytest.approx(ev.reconstruction_error(Phi[:, 10:15], 0 * Phi[:, 10:15]), rel=1e-8)  # A-orthogonal: nothing


# ---------------------------------------------------------------- principal angles (§4.6)


def _random_orthogonal(k, rng):
    Q, R = np.linalg.qr(rng.standard_normal((k, k)))
    return Q * np.sign(np.diag(R))


def test_grassmann_distance_is_basis_invariant(knight):
    m, lap, lam, Phi = knight
    rng = np.random.default_rng(0)
    X = mesh.vertex_positions(m)
    H = bases.hamiltonian(lap.W, lap.A, 8, bases.potential_from_reconstruction(lap.A, Phi[:, :10], X), 1e3).Psi
    B1 = Phi[:, :8]
    d = ev.grassmann_distance(B1, H, lap.A)
    assert d > 0.1
    for _ in range(3):
        d2 = ev.grassmann_distance(B1 @ _random_orthogonal(8, rng), H @ _random_orthogonal(8, rng), lap.A)
        assert d2 == pytest.approx(d, rel=1e-10)
    assert ev.grassmann_distance(H, B1, lap.A) == pytest.approx(d, rel=1e-12)


def test_known_angle_and_nested_spans(knight):
    m, lap, lam, Phi = knight
    rng = np.random.default_rng(1)
    t = 0.3
    B1 = Phi[:, :3]
    B2 = np.column_stack([Phi[:, 0], Phi[:, 1], np.cos(t) * Phi[:, 2] + np.sin(t) * Phi[:, 7]])
    np.testing.assert_allclose(ev.principal_angles(B1, B2 @ _random_orthogonal(3, rng), lap.A), [0, 0, t], atol=1e-12)
    assert ev.grassmann_distance(B1, B2, lap.A) == pytest.approx(t, rel=1e-12)
    # nested: span(small) ⊂ span(big) → every angle 0, accurately (not ~1e-8 from arccos)
    small = Phi[:, :10] @ _random_orthogonal(10, rng)[:, :4]
    angles = ev.principal_angles(small, Phi[:, :15] @ _random_orthogonal(15, rng), lap.A)
    assert angles.shape == (4,) and angles.max() <= 1e-12
    # orthogonal spans: all angles π/2
    np.testing.assert_allclose(ev.principal_angles(Phi[:, :3], Phi[:, 3:8], lap.A), np.pi / 2, atol=1e-12)


def test_principal_angles_nonorthonormal(knight):
    m, lap, lam, Phi = knight
    B1 = Phi[:, :4] * 2.0
    with pytest.raises(ev.NotOrthonormalError, match="not A-orthonormal"):
        ev.principal_angles(B1, Phi[:, 2:6], lap.A)
    with pytest.raises(ev.NotOrthonormalError):
        ev.principal_angles(Phi[:, :4], Phi[:, :4], None)  # Euclidean inner product: not orthonormal
    mixed = Phi[:, :4] @ np.triu(np.ones((4, 4)))  # same span, not orthonormal
    np.testing.assert_allclose(ev.principal_angles(mixed, Phi[:, 2:6], lap.A, orthonormalize=True),
                               ev.principal_angles(Phi[:, :4], Phi[:, 2:6], lap.A), atol=1e-10)
    # non-diagonal A (FEM mass) takes the eigen-based sine path
    fem = mesh.laplacian(m, area="fem")
    P = ev.a_orthonormalize(Phi[:, :5], fem.A)
    np.testing.assert_allclose(P.T @ (fem.A @ P), np.eye(5), atol=1e-12)
    assert ev.principal_angles(P[:, :3], P, fem.A).max() < 1e-7


def test_woodbury_inverse_matches_dense(knight):
    """(S + c BBᵀ)⁻¹ applied by Woodbury equals the dense inverse (S = W − σA, B = AΦ)."""
    m, lap, lam, Phi = knight
    S = sp.csc_matrix(lap.W + 1e-3 * lap.A)
    B = np.asarray(lap.A @ Phi[:, :7])
    op = bases._woodbury_inverse(S, B, 1e4)
    x = np.random.default_rng(0).standard_normal((m.n_vertices, 2))
    ref = np.linalg.solve(S.toarray() + 1e4 * B @ B.T, x)
    np.testing.assert_allclose(op.matmat(x), ref, rtol=1e-7, atol=1e-9 * np.abs(ref).max())


def test_lmh_permutes_with_the_mesh():
    """Prop. 3.5.1: on a vertex-permuted copy (Def. 3.4.8) LMHs permute with the vertices."""
    m = hand_mesh()  # the hand stand-in (it replaced hand_868.obj)
    perm = np.random.default_rng(5).permutation(m.n_vertices)
    mp = mesh.permute(m, perm)
    out = []
    for mm in (m, mp):
        lap = mesh.laplacian(mm)
        _, Phi = mesh.eigenbasis(lap, 10)
        _, v, _ = bases.region_from_reconstruction(lap.A, Phi, mesh.vertex_positions(mm), quantile=0.8)
        out.append(bases.lmh(lap.W, lap.A, 4, Phi, 1e3, v=v, mu_R=1e2))
    np.testing.assert_allclose(out[1].evals, out[0].evals, rtol=1e-9)
    np.testing.assert_allclose(out[1].Psi, out[0].Psi[perm], atol=1e-7)


@settings(max_examples=25)
@given(n=st.integers(8, 30), k=st.integers(1, 5), l=st.integers(1, 5), seed=st.integers(0, 10_000))
def test_principal_angles_match_scipy(n, k, l, seed):
    """A-weighted angles equal scipy's Euclidean subspace angles of √a·B (Lemma 4.6.3)."""
    rng = np.random.default_rng(seed)
    a = rng.uniform(0.1, 2.0, n)
    B1 = ev.a_orthonormalize(rng.standard_normal((n, k)), a)
    B2 = ev.a_orthonormalize(rng.standard_normal((n, l)), a)
    ours = ev.principal_angles(B1, B2, sp.diags(a))
    ref = np.sort(sla.subspace_angles(np.sqrt(a)[:, None] * B1, np.sqrt(a)[:, None] * B2))
    np.testing.assert_allclose(ours, ref, atol=1e-10)
    assert ev.grassmann_distance(B1, B2, a) == pytest.approx(np.sqrt(np.sum(ref ** 2)), abs=1e-10)
