"""Poisson-disk sampling and the local-function matrix U (thesis §7.1, docs/maths.md §6)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.csgraph as csgraph

import mesh
from mesh.sampling import SLACK, SamplingError, bump, local_distance
from mesh_fixtures import SURFACES, grid, quiet_load, surface, two_spheres


def test_bump_polynomial():
    rho = 2.0
    np.testing.assert_allclose(bump([0.0, 1.0, 2.0, 3.0], rho), [1.0, 0.5, 0.0, 0.0])
    # C¹ at both ends of the support: zero slope at r = 0 and r = ρ
    h = 1e-6
    assert abs((bump(h, rho) - 1.0) / h) < 1e-5
    assert abs((bump(rho, rho) - bump(rho - h, rho)) / h) < 1e-5
    r = np.linspace(0, rho, 11)
    np.testing.assert_allclose(bump(r, rho), 2 * r**3 / rho**3 - 3 * r**2 / rho**2 + 1)
    # one radius per entry: the same polynomial in r/ρ_i
    np.testing.assert_allclose(bump([0.5, 1.5, 1.0], np.array([1.0, 3.0, 0.5])), [0.5, 0.5, 0.0])


@pytest.mark.parametrize("name", SURFACES)
def test_poisson_disk_is_separated_and_maximal(name):
    m = surface(name)
    samples, radius = mesh.poisson_disk_sample(m, n_samples=60, seed=1)
    assert 30 <= samples.size <= 120 and np.unique(samples).size == samples.size
    D = csgraph.dijkstra(mesh.edge_graph(m), directed=False, indices=samples)
    Dss = D[:, samples]
    assert np.all(Dss[~np.eye(samples.size, dtype=bool)] >= radius)  # separated
    assert np.all(D.min(axis=0) < radius)  # maximal: every vertex is covered


def test_poisson_disk_accepts_a_one_sided_graph():
    """A user graph holding each edge in one direction only gives the same sample as edge_graph."""
    import scipy.sparse as sp

    m = surface(SURFACES[0])
    G = mesh.edge_graph(m)
    upper = sp.csr_array(sp.triu(G))
    assert upper.nnz * 2 == G.nnz
    full = mesh.poisson_disk_sample(m, n_samples=40, seed=2)
    one_sided = mesh.poisson_disk_sample(m, n_samples=40, seed=2, graph=upper)
    np.testing.assert_array_equal(full[0], one_sided[0])


def _check_support_and_cover(m, lf, cover=(7, 15)):
    """Rows sum to 1; column i is bump(r, ρ_i)/rowsum exactly where r < ρ_i; every function covers lo–hi others."""
    U = lf.U
    d = lf.samples.size
    assert U.shape == (m.n_vertices, d) and lf.radii.shape == (d,)
    np.testing.assert_allclose(U.sum(axis=1), 1.0, atol=1e-14)
    assert U.data.min() > 0
    r = local_distance(m, lf.samples, distance=lf.distance)  # (n, d), the reference distance
    inside = r < lf.radii
    Ut = np.where(inside, bump(r, lf.radii), 0.0)
    np.testing.assert_allclose(U.toarray(), Ut / Ut.sum(axis=1, keepdims=True), rtol=1e-12, atol=1e-15)
    others = inside[lf.samples].sum(axis=0) - 1  # samples inside each support, minus itself
    np.testing.assert_array_equal(lf.coverage, others)
    lo, hi = cover
    assert lf.coverage.min() >= lo and lf.coverage.max() <= hi, (lf.coverage.min(), lf.coverage.max())
    assert lf.rho == np.median(lf.radii)


@pytest.mark.parametrize("distance", ["corrected", "dijkstra"])
@pytest.mark.parametrize("name", SURFACES)
def test_local_functions_partition_of_unity_full_rank_and_cover(name, distance):
    """Thesis §7.1: every local function's support holds between 7 and 15 other samples."""
    m = surface(name)
    lf = mesh.local_functions(m, n_samples=80, seed=0, distance=distance)
    assert lf.distance == distance
    _check_support_and_cover(m, lf)
    s = np.linalg.svd(lf.U.toarray(), compute_uv=False)
    assert s.min() > 1e-3 * s.max()  # full column rank (Rem. 7.1.1)


@pytest.mark.parametrize("n_samples", [40, 150, 300])
def test_cover_on_thin_parts_at_several_densities(n_samples):
    """A hand (fingers, thin parts): the former single median ρ left too few others at the worst sample."""
    m = surface("hand")
    for seed in (0, 1):
        lf = mesh.local_functions(m, n_samples=n_samples, seed=seed)
        _check_support_and_cover(m, lf)
        assert mesh.local_functions(m, samples=lf.samples, rho=lf.rho).coverage.min() < 7  # a test of the radii


@pytest.mark.parametrize("name", ["patch", "starfish"])
def test_cover_on_shipped_examples(name):
    """The shipped examples: ``patch`` has a boundary (the former ρ gave 4 others there), ``starfish`` thin arms."""
    m = mesh.example(name)
    lf = mesh.local_functions(m, n_samples=120, seed=0)
    _check_support_and_cover(m, lf)
    lf = mesh.local_functions(m, n_samples=120, seed=0, cover=(4, 6))
    _check_support_and_cover(m, lf, cover=(4, 6))


def test_components_are_covered_separately():
    """Two spheres: every vertex covered, no support crosses to the other component."""
    m = quiet_load(two_spheres(2))
    lf = mesh.local_functions(m, n_samples=60, seed=0)
    _check_support_and_cover(m, lf)
    half = m.n_vertices // 2
    comp = np.arange(m.n_vertices) >= half
    rows, cols = lf.U.nonzero()
    np.testing.assert_array_equal(comp[rows], comp[lf.samples[cols]])


def test_explicit_samples_and_rho():
    """``rho=``: the thesis's single global radius, reproducing the former (plain Dijkstra) result exactly."""
    m = surface("hand")
    samples, r = mesh.poisson_disk_sample(m, n_samples=40)
    lf = mesh.local_functions(m, samples=samples, rho=2.5 * r, distance="dijkstra")
    assert lf.rho == 2.5 * r and np.all(lf.radii == 2.5 * r)
    np.testing.assert_array_equal(lf.samples, samples)
    D = mesh.geodesic_distance(m, samples)  # (n, d) Dijkstra
    Ut = np.where(D < lf.rho, bump(D, lf.rho), 0.0)
    np.testing.assert_allclose(lf.U.toarray(), Ut / Ut.sum(axis=1, keepdims=True), rtol=1e-12, atol=1e-15)
    # the corrected distance with the same ρ: larger supports (r ≤ D), the same formula in r
    lc = mesh.local_functions(m, samples=samples, rho=2.5 * r)
    assert lc.distance == "corrected" and lc.U.nnz > lf.U.nnz
    _check_support_and_cover(m, lc, cover=(0, samples.size))
    with pytest.raises(SamplingError, match="outside every local function"):
        mesh.local_functions(m, samples=samples[:2], rho=0.5 * r)


def _flat_grid(n: int = 21) -> mesh.Mesh:
    return mesh.load(grid(n, n))


def test_corrected_distance_is_exact_on_a_flat_grid():
    """On a flat grid the geodesic distance is the Euclidean one: the corrected distance equals it within
    the search radius, while plain Dijkstra overestimates against the triangles' diagonals (up to √2)."""
    m = _flat_grid(21)  # spacing h = 0.05
    centre = 10 * 21 + 10
    true = np.linalg.norm(m.vertices - m.vertices[centre], axis=1)
    limit = 0.32
    r = local_distance(m, centre, limit=limit)
    near = true < limit * (1 - 1e-9)
    assert near.sum() > 100
    np.testing.assert_allclose(r[near], true[near], rtol=1e-12, atol=1e-15)
    assert np.all(np.isinf(r[true > limit * (1 + 1e-9)]))
    D = local_distance(m, centre, limit=limit, distance="dijkstra")
    np.testing.assert_array_equal(D, np.where(D <= limit, mesh.geodesic_distance(m, centre), np.inf))
    anti = np.isfinite(D) & np.isclose(m.vertices[:, 0] - 0.5, 0.5 - m.vertices[:, 1]) & (true > 0)
    assert anti.sum() >= 4
    np.testing.assert_allclose(D[anti] / true[anti], SLACK, rtol=1e-12)  # zig-zag along the anti-diagonal
    # and the local functions' supports are the Euclidean discs r < ρ_i
    lf = mesh.local_functions(m, n_samples=30, seed=0)
    E = np.linalg.norm(m.vertices[:, None, :] - m.vertices[lf.samples][None, :, :], axis=2)  # (n, d)
    clear = np.abs(E - lf.radii) > 1e-9 * lf.radii
    np.testing.assert_array_equal((lf.U.toarray() > 0)[clear], (E < lf.radii)[clear])


def _folded_strip(length=4.0, width=0.5, gap=0.1, nx=161, ny=11):
    """A flat strip folded into a U: two parallel arms ``gap`` apart, joined by a half-cylinder of radius
    ``gap/2``. Returns the mesh and each vertex's flat coordinates ``(s, y)`` (the strip is developable, so
    geodesic distance is the flat distance in ``(s, y)``)."""
    V, F = grid(nx, ny)
    s, y = V[:, 0] * length, V[:, 1] * width
    rad = gap / 2
    arm = (length - np.pi * rad) / 2
    theta = np.clip((s - arm) / rad, 0.0, np.pi)
    x = np.where(s < arm, s, np.where(theta < np.pi, arm + rad * np.sin(theta), arm - (s - arm - np.pi * rad)))
    z = np.where(s < arm, 0.0, rad - rad * np.cos(theta))
    return mesh.load((np.stack([x, y, z], axis=1), F)), np.stack([s, y], axis=1)


@pytest.mark.parametrize("distance", ["corrected", "dijkstra"])
def test_folded_strip_keeps_the_two_arms_apart(distance):
    """Points close in space (across the fold's gap) but far along the surface share no support."""
    m, flat = _folded_strip()
    lf = mesh.local_functions(m, n_samples=60, seed=0, distance=distance)
    _check_support_and_cover(m, lf)
    P = m.vertices
    S = lf.samples
    E = np.linalg.norm(P[:, None, :] - P[S][None, :, :], axis=2)  # (n, d) straight-line
    geo = np.linalg.norm(flat[:, None, :] - flat[S][None, :, :], axis=2)  # (n, d) along the surface
    close_far = (E < lf.radii) & (geo > 3 * lf.radii)  # across the gap
    assert close_far.sum() > 1000  # a Euclidean-only distance would put these in the supports
    supp = lf.U.toarray() > 0
    assert not supp[close_far].any()
    assert np.all(geo[supp] < SLACK * lf.radii[np.nonzero(supp)[1]])  # supports are geodesically local


def test_local_functions_rejects_bad_input():
    m = surface("hand")
    samples, r = mesh.poisson_disk_sample(m, n_samples=40)
    bad_cover = [(7,), (7, 15, 20), (0, 5), (8, 7), (7.0, 15), (True, 15), "ab", 7, None, (-1, 3)]
    for cover in bad_cover:
        with pytest.raises(SamplingError, match="cover must be a pair"):
            mesh.local_functions(m, samples=samples, cover=cover)
    with pytest.raises(SamplingError, match=r"at least 7 other samples.*d − 1 = 4"):
        mesh.local_functions(m, samples=samples[:5])
    lf = mesh.local_functions(m, samples=samples[:9], cover=(7, 15))  # hi above d − 1: capped
    assert lf.coverage.max() <= 8 and lf.coverage.min() >= 7
    for distance in ["geodesic", "Dijkstra", None, 1]:
        with pytest.raises(SamplingError, match="distance must be one of"):
            mesh.local_functions(m, samples=samples, distance=distance)
        with pytest.raises(SamplingError, match="distance must be one of"):
            local_distance(m, 0, distance=distance)
    for rho in [0.0, -1.0, np.nan, np.inf, "1", True]:
        with pytest.raises(SamplingError, match="rho must be a finite number > 0"):
            mesh.local_functions(m, samples=samples, rho=rho)
    for bad in [np.array([0, m.n_vertices]), np.array([-1, 3]), np.array([3, 3, 4]), np.array([]),
                np.array([1.0, 2.0]), np.array([[1, 2]])]:
        with pytest.raises(SamplingError, match="samples"):
            mesh.local_functions(m, samples=bad)
    with pytest.raises(SamplingError, match="give n_samples or samples"):
        mesh.local_functions(m)
    with pytest.raises(SamplingError, match="n_samples must be an integer"):
        mesh.local_functions(m, n_samples=0)
    with pytest.raises(SamplingError, match="radius must be a finite number > 0"):
        mesh.poisson_disk_sample(m, radius=-1.0)
    assert issubclass(SamplingError, mesh.MeshError) and issubclass(SamplingError, ValueError)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["bumpy_large", "torus_large"])
def test_local_functions_full_rank_large(name):
    m = surface(name)
    lf = mesh.local_functions(m, n_samples=300, seed=0)
    np.testing.assert_allclose(lf.U.sum(axis=1), 1.0, atol=1e-14)
    s = np.linalg.svd(lf.U.toarray(), compute_uv=False)
    assert s.min() > 1e-3 * s.max()
    assert lf.coverage.min() >= 7 and lf.coverage.max() <= 15
