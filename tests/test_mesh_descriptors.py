"""Descriptor functions and landmarks (thesis §4.1)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

import mesh
from mesh_fixtures import SURFACES, grid, sphere, surface


@pytest.mark.parametrize("name", SURFACES)
def test_dijkstra_distance_is_a_shortest_path_tree(name):
    m = surface(name)
    src = [0, m.n_vertices // 2]
    D = mesh.geodesic_distance(m, src)
    e = m.edges
    length = np.linalg.norm(m.vertices[e[:, 0]] - m.vertices[e[:, 1]], axis=1)
    for j, s in enumerate(src):
        d = D[:, j]
        assert d[s] == 0 and np.all(d[np.arange(m.n_vertices) != s] > 0)
        # triangle inequality along every edge, both directions
        slack = 1e-12 * d.max()
        assert np.all(d[e[:, 1]] <= d[e[:, 0]] + length + slack)
        assert np.all(d[e[:, 0]] <= d[e[:, 1]] + length + slack)
        # equality along the tree: every vertex but the source has a tight predecessor edge
        tight = np.zeros(m.n_vertices, dtype=bool)
        t1 = np.abs(d[e[:, 1]] - (d[e[:, 0]] + length)) <= slack
        t0 = np.abs(d[e[:, 0]] - (d[e[:, 1]] + length)) <= slack
        tight[e[t1, 1]] = True
        tight[e[t0, 0]] = True
        assert tight.sum() == m.n_vertices - 1 and not tight[s]


@pytest.mark.parametrize("method, tol", [("heat", 0.03), ("fast_marching", 0.03), ("dijkstra", 0.12)])
def test_geodesics_on_the_sphere(method, tol):
    m = sphere(4)  # unit sphere: geodesic distance = angle
    d = mesh.geodesic_distance(m, 0, method=method)
    exact = np.arccos(np.clip(m.vertices @ m.vertices[0], -1, 1))
    assert abs(d[0]) <= 1e-3
    assert np.abs(d - exact).max() <= tol * np.pi
    if method == "dijkstra":  # an edge path is never shorter than the straight chord
        assert np.all(d >= np.linalg.norm(m.vertices - m.vertices[0], axis=1) - 1e-12)


def test_dijkstra_limit():
    m = surface("bumpy")
    full = mesh.geodesic_distance(m, 3)
    r = np.median(full)
    cut = mesh.geodesic_distance(m, 3, limit=r)
    inside = full <= r
    np.testing.assert_array_equal(cut[inside], full[inside])
    assert np.all(np.isinf(cut[~inside]))


def test_geodists_deltas_normdist():
    m = mesh.scaled_to_unit_area(surface("bumpy"))
    assert abs(m.total_area - 1) < 1e-12
    lm = mesh.landmarks(m)
    G = mesh.geodists(m, lm)
    assert G.shape == (m.n_vertices, lm.size)
    np.testing.assert_allclose(G.max(axis=0), 1.0)
    np.testing.assert_array_equal(G[lm, np.arange(lm.size)], 0.0)
    D = mesh.geodesic_distance(m, lm)
    dl = mesh.deltas(D, r=0.05)
    np.testing.assert_allclose(dl[lm, np.arange(lm.size)], 1 / (0.05 * np.sqrt(np.pi)))
    assert np.all(dl[D > 0.05] == 0) and np.all(dl[D <= 0.05] > 0)
    nd = mesh.normdist(D, r=0.1)
    np.testing.assert_allclose(nd[lm, np.arange(lm.size)], 1.0)
    assert np.all(nd[D > 0.1] == 0)
    sigma = D.max(axis=0) / 3
    j = 0
    inside = D[:, j] <= 0.1
    np.testing.assert_allclose(nd[inside, j], np.exp(-((D[inside, j] / (2 * sigma[j])) ** 2)))


def test_hks_with_a_full_eigenbasis():
    # with all n eigenpairs ΦΦᵀ = A⁻¹, so HKS(v, 0) = 1/A_vv; HKS decreases in t
    m = sphere(1)
    lap = mesh.laplacian(m, area="mixed")
    evals, evecs = sla.eigh(lap.W.toarray(), lap.A.toarray())
    t = np.array([0.0, 1e-3, 1e-2, 1.0])
    H = mesh.hks(evals, evecs, t)
    np.testing.assert_allclose(H[:, 0], 1.0 / lap.A.diagonal(), rtol=1e-10)
    assert np.all(H > 0) and np.all(np.diff(H, axis=1) < 0)
    np.testing.assert_allclose(H[:, -1], 1.0, rtol=1e-2)  # → 1/total area as t → ∞ (total area 1)


def test_hks_wks_from_a_mesh_basis():
    lap = mesh.laplacian(surface("bumpy"), area="fem")
    evals, evecs = mesh.eigenbasis(lap, 60)
    times = mesh.hks_times(evals, 30)
    np.testing.assert_allclose(times[[0, -1]], 4 * np.log(10) / evals[[-1, 9]], rtol=1e-12)
    H = mesh.hks(evals, evecs, 30)
    assert H.shape == (lap.n, 30) and np.all(H > 0)
    W = mesh.wks(evals, evecs, 100)
    assert W.shape == (lap.n, 100) and np.all(W > 0)
    e, sigma = mesh.wks_energies(evals, 100)
    lo, hi = np.log(evals[1]), np.log(evals[-1])
    s = 7 * (hi - lo) / 100
    np.testing.assert_allclose(e[[0, -1]], [lo + 2 * s, hi - 2 * s], rtol=1e-12)
    np.testing.assert_allclose(sigma, 7 * (hi - lo) / 128)
    # WKS is a weighted mean of φ_k² (k ≥ 2): bounded by their extremes at every vertex
    phi2 = evecs[:, 1:] ** 2
    assert np.all(W <= phi2.max(axis=1, keepdims=True) * (1 + 1e-12))
    with pytest.raises(ValueError, match="n_energies"):
        mesh.wks(evals, evecs, 20)


def test_landmarks_on_a_flat_grid():
    V, F = grid(5, 5)
    m = mesh.load((V, F))
    assert mesh.central_points(m).tolist() == [12]  # the grid centre (0.5, 0.5)
    ext = mesh.extremal_points(m)
    x, y = m.vertices[ext, 0], m.vertices[ext, 1]
    assert set(np.round(x, 6)) | set(np.round(y, 6)) >= {0.0, 1.0}
    V2 = m.vertices
    for i in ext:
        assert any(V2[i, c] in (V2[:, c].max(), V2[:, c].min()) for c in range(3))
    np.testing.assert_array_equal(mesh.constant(m), np.ones((25, 1)))
    np.testing.assert_array_equal(mesh.vertex_positions(m), m.vertices)


def test_central_point_fallback_and_extremal_on_sphere():
    m = sphere(2)
    ext = mesh.extremal_points(m)
    assert ext.size == 6
    np.testing.assert_allclose(np.abs(m.vertices[ext]).max(axis=1), 1.0)
    c = mesh.central_points(m)
    assert c.size >= 1
    r = 0.5 * (m.vertices.max(0) + m.vertices.min(0))
    d = np.linalg.norm(m.vertices - r, axis=1)
    assert np.isclose(d[c[0]], d.min())
