"""Weight and area matrices (thesis Ex. 2.5.17, 2.5.22, 2.5.24) against libigl and by hand."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp

import mesh
from mesh_fixtures import LARGE_SURFACES, SURFACES, grid, sphere, surface

igl = pytest.importorskip("igl")


def _maxabs(M) -> float:
    M = sp.csr_array(M)
    return float(np.max(np.abs(M.data))) if M.nnz else 0.0


def _check_against_igl(m: mesh.Mesh) -> None:
    V, F = m.vertices, m.faces
    W = mesh.laplacian(m, normalize_area=False).W
    L_igl = igl.cotmatrix(V, F)  # igl: negative semi-definite L = −W
    assert _maxabs(W + L_igl) <= 1e-12 * _maxabs(W)
    for area, kind in [
        ("barycentric", igl.MASSMATRIX_TYPE_BARYCENTRIC),
        ("lumped", igl.MASSMATRIX_TYPE_BARYCENTRIC),
        ("mixed", igl.MASSMATRIX_TYPE_VORONOI),  # igl's "Voronoi" is Meyer's mixed Voronoi
        ("fem", igl.MASSMATRIX_TYPE_FULL),
    ]:
        A = mesh.area_matrix(m, area)
        A_igl = igl.massmatrix(V, F, kind)
        assert _maxabs(A - A_igl) <= 1e-12 * _maxabs(A), area


@pytest.mark.parametrize("name", SURFACES)
def test_cotangent_and_mass_match_libigl(name):
    _check_against_igl(surface(name))


@pytest.mark.slow
@pytest.mark.parametrize("name", LARGE_SURFACES)
def test_cotangent_and_mass_match_libigl_large(name):
    _check_against_igl(surface(name))


@pytest.mark.parametrize("name", SURFACES)
@pytest.mark.parametrize("weights", ["cotangent", "graph", "robust"])
def test_weight_matrix_symmetric_rows_sum_to_zero(name, weights):
    lap = mesh.laplacian(surface(name), weights=weights)
    W = lap.W
    s = _maxabs(W)
    assert _maxabs(W - W.T) <= 1e-14 * s
    assert np.max(np.abs(W.sum(axis=1))) <= 1e-12 * s
    assert np.all(W.diagonal() > 0)


@pytest.mark.parametrize("area", mesh.AREAS)
def test_normalised_total_area_is_one(area):
    m = surface("torus_holes")
    lap = mesh.laplacian(m, area=area)
    assert abs(lap.A.sum() - 1.0) <= 1e-13
    assert lap.is_diagonal_area == (area != "fem")
    raw = mesh.area_matrix(m, area).sum()
    np.testing.assert_allclose(lap.area_scale, 1.0 / raw, rtol=1e-14)


@pytest.mark.parametrize("name", SURFACES)
def test_surface_areas_sum_to_total_area(name):
    m = surface(name)
    total = m.total_area
    for area in ("barycentric", "voronoi", "mixed", "fem", "lumped"):
        np.testing.assert_allclose(mesh.area_matrix(m, area).sum(), total, rtol=1e-12, err_msg=area)
    fem = mesh.area_matrix(m, "fem")
    # lumped FEM mass (Def. 2.5.18) equals the barycentric areas (Ex. 2.5.17(ii))
    np.testing.assert_allclose(np.asarray(fem.sum(axis=1)).ravel(), mesh.area_matrix(m, "barycentric").diagonal(), rtol=1e-12)
    # FEM diagonal is half the barycentric area: 1/6 vs 1/3 of the incident areas
    np.testing.assert_allclose(fem.diagonal(), 0.5 * mesh.area_matrix(m, "barycentric").diagonal(), rtol=1e-12)


def test_single_triangles_by_hand():
    # equilateral triangle of side 1: every angle 60°, boundary edges carry one cotangent
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0]])
    m = mesh.load((V, [[0, 1, 2]]))
    W = mesh.laplacian(m).W.toarray()
    c = 1 / np.sqrt(3) / 2
    np.testing.assert_allclose(W, [[2 * c, -c, -c], [-c, 2 * c, -c], [-c, -c, 2 * c]], atol=1e-15)
    area = np.sqrt(3) / 4
    np.testing.assert_allclose(mesh.area_matrix(m, "voronoi").diagonal(), area / 3, rtol=1e-14)
    fem = mesh.area_matrix(m, "fem").toarray()
    np.testing.assert_allclose(fem, area / 12 * (np.ones((3, 3)) + np.eye(3)), rtol=1e-14)
    # obtuse triangle: mixed areas are 1/2 (obtuse corner), 1/4, 1/4 of the face area
    V2 = np.array([[0.0, 0, 0], [2, 0, 0], [1, 0.2, 0]])
    m2 = mesh.load((V2, [[0, 1, 2]]))
    np.testing.assert_allclose(mesh.area_matrix(m2, "mixed").diagonal(), [0.05, 0.05, 0.1], rtol=1e-13)
    vor = mesh.area_matrix(m2, "voronoi").diagonal()
    # circumcentre outside, beyond edge (0, 1): the acute corners get negative cell parts
    np.testing.assert_allclose(vor, [-0.55, -0.55, 1.3], rtol=1e-12)
    assert abs(vor.sum() - 0.2) < 1e-14


def test_graph_and_degree():
    m = surface("hand")
    W = mesh.laplacian(m, weights="graph").W
    deg = W.diagonal()
    assert np.all(deg == np.round(deg)) and deg.sum() == 2 * len(m.edges)
    off = W - sp.diags_array(deg)
    assert set(np.unique(off.data)) == {-1.0}
    uni = mesh.laplacian(m, weights="uniform", area="degree", normalize_area=False)
    np.testing.assert_array_equal(uni.A.diagonal(), deg)
    np.testing.assert_array_equal(uni.W.toarray(), W.toarray())
    g = mesh.laplacian(m, weights="graph", area="uniform")
    np.testing.assert_allclose(g.A.diagonal(), 1.0 / m.n_vertices)


def test_cotangent_weights_scale_invariant_areas_scale_quadratically():
    m = surface("bumpy")
    m3 = replace(m, vertices=3.0 * m.vertices)
    a, b = mesh.laplacian(m, normalize_area=False), mesh.laplacian(m3, normalize_area=False)
    assert _maxabs(a.W - b.W) <= 1e-12 * _maxabs(a.W)
    assert _maxabs(9.0 * a.A - b.A) <= 1e-12 * _maxabs(b.A)
    an, bn = mesh.laplacian(m), mesh.laplacian(m3)
    assert _maxabs(an.A - bn.A) <= 1e-12 * _maxabs(an.A)


def test_negative_weights_counted_and_robust_laplacian_is_psd():
    # a rhombus folded flat so that both angles opposite the shared edge are obtuse
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0.5, 0.1, 0], [0.5, -0.1, 0]])
    m = mesh.load((V, [[0, 1, 2], [1, 0, 3]]))
    lap = mesh.laplacian(m)
    assert lap.n_negative_weights == 1
    assert lap.W[0, 1] > 0  # W_ij > 0 ⇔ cot α + cot β < 0
    # Prop. 2.5.21's Geršgorin argument no longer applies, but W stays PSD: it is the P1
    # stiffness matrix Σ_t area_t |∇f|² (a sum of per-triangle PSD forms); what fails is the
    # sign pattern (maximum principle), which the robust Laplacian restores
    assert np.linalg.eigvalsh(lap.W.toarray()).min() > -1e-12
    rob = mesh.robust_laplacian(m)
    assert rob.n_negative_weights == 0
    assert np.linalg.eigvalsh(rob.W.toarray()).min() > -1e-12
    assert abs(rob.A.sum() - 1) < 1e-13


def test_counts_match_off_diagonal_signs_on_an_irregular_mesh():
    lap = mesh.laplacian(surface("torus"))
    off = sp.triu(lap.W, 1)
    assert lap.n_negative_weights == int(np.sum(off.data > 1e-12 * _maxabs(lap.W))) > 0
    assert mesh.robust_laplacian(surface("torus")).n_negative_weights == 0


def test_cotangent_laplacian_converges_on_the_sphere():
    # L = A⁻¹W applied to a coordinate function: Δ z = 2 z on the unit sphere
    m = sphere(4)
    lap = mesh.laplacian(m, area="mixed", normalize_area=False)
    z = m.vertices[:, 2]
    Lz = (lap.W @ z) / lap.A.diagonal()
    assert np.max(np.abs(Lz - 2 * z)) < 0.02


def test_bad_options():
    m = sphere(1)
    with pytest.raises(ValueError, match="unknown weights"):
        mesh.laplacian(m, weights="cot")
    with pytest.raises(ValueError, match="unknown area"):
        mesh.laplacian(m, area="voronoii")


def test_dirichlet_energy_of_linear_function_on_flat_grid():
    # ∫|∇f|² for f = x is the domain area; the cotangent Dirichlet energy (eq. 2.5.10) is exact for linear f
    V, F = grid(6, 5, jitter=0.3)
    m = mesh.load((V, F))
    lap = mesh.laplacian(m)
    np.testing.assert_allclose(lap.dirichlet_energy(V[:, 0]), m.total_area, rtol=1e-12)
    np.testing.assert_allclose(lap.dirichlet_energy(V[:, :2] @ [3.0, -2.0]), 13 * m.total_area, rtol=1e-12)
