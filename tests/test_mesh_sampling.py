"""Poisson-disk sampling and the local-function matrix U (thesis §7.1, docs/maths.md §6)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse.csgraph as csgraph

import mesh
from mesh.sampling import bump
from mesh_fixtures import SMALL, shared_mesh


def test_bump_polynomial():
    rho = 2.0
    np.testing.assert_allclose(bump([0.0, 1.0, 2.0, 3.0], rho), [1.0, 0.5, 0.0, 0.0])
    # C¹ at both ends of the support: zero slope at r = 0 and r = ρ
    h = 1e-6
    assert abs((bump(h, rho) - 1.0) / h) < 1e-5
    assert abs((bump(rho, rho) - bump(rho - h, rho)) / h) < 1e-5
    r = np.linspace(0, rho, 11)
    np.testing.assert_allclose(bump(r, rho), 2 * r**3 / rho**3 - 3 * r**2 / rho**2 + 1)


@pytest.mark.parametrize("name", SMALL)
def test_poisson_disk_is_separated_and_maximal(name):
    m = shared_mesh(name)
    samples, radius = mesh.poisson_disk_sample(m, n_samples=60, seed=1)
    assert 30 <= samples.size <= 120 and np.unique(samples).size == samples.size
    D = csgraph.dijkstra(mesh.edge_graph(m), directed=False, indices=samples)
    Dss = D[:, samples]
    assert np.all(Dss[~np.eye(samples.size, dtype=bool)] >= radius)  # separated
    assert np.all(D.min(axis=0) < radius)  # maximal: every vertex is covered


def test_poisson_disk_accepts_a_one_sided_graph():
    """A user graph holding each edge in one direction only gives the same sample as edge_graph."""
    import scipy.sparse as sp

    m = shared_mesh(SMALL[0])
    G = mesh.edge_graph(m)
    upper = sp.csr_array(sp.triu(G))
    assert upper.nnz * 2 == G.nnz
    full = mesh.poisson_disk_sample(m, n_samples=40, seed=2)
    one_sided = mesh.poisson_disk_sample(m, n_samples=40, seed=2, graph=upper)
    np.testing.assert_array_equal(full[0], one_sided[0])


@pytest.mark.parametrize("name", SMALL)
def test_local_functions_partition_of_unity_full_rank(name):
    m = shared_mesh(name)
    lf = mesh.local_functions(m, n_samples=80, seed=0)
    U = lf.U
    d = lf.samples.size
    assert U.shape == (m.n_vertices, d)
    np.testing.assert_allclose(U.sum(axis=1), 1.0, atol=1e-14)
    assert U.data.min() > 0
    s = np.linalg.svd(U.toarray(), compute_uv=False)
    assert s.min() > 1e-3 * s.max()  # full column rank (Rem. 7.1.1)
    assert 7 <= np.median(lf.coverage) <= 15
    # support: column i vanishes beyond ρ of sample i; U[s_i, i] is the largest entry of its row... at least positive
    D = csgraph.dijkstra(mesh.edge_graph(m), directed=False, indices=lf.samples)  # (d, n)
    Ud = U.toarray().T
    assert np.all(Ud[D >= lf.rho] == 0) and np.all(Ud[D < lf.rho] > 0)


def test_explicit_samples_and_rho():
    m = shared_mesh("decimated-knight.off")
    samples, r = mesh.poisson_disk_sample(m, n_samples=40)
    lf = mesh.local_functions(m, samples=samples, rho=2.5 * r)
    assert lf.rho == 2.5 * r
    np.testing.assert_array_equal(lf.samples, samples)
    D = csgraph.dijkstra(mesh.edge_graph(m), directed=False, indices=samples)
    Ut = np.where(D < lf.rho, bump(D, lf.rho), 0.0).T
    np.testing.assert_allclose(lf.U.toarray(), Ut / Ut.sum(axis=1, keepdims=True), rtol=1e-12, atol=1e-15)
    with pytest.raises(ValueError, match="outside every local function"):
        mesh.local_functions(m, samples=samples[:2], rho=0.5 * r)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["bunny.off", "fandisk.off"])
def test_local_functions_full_rank_large(name):
    m = shared_mesh(name)
    lf = mesh.local_functions(m, n_samples=300, seed=0)
    np.testing.assert_allclose(lf.U.sum(axis=1), 1.0, atol=1e-14)
    s = np.linalg.svd(lf.U.toarray(), compute_uv=False)
    assert s.min() > 1e-3 * s.max()
    assert 7 <= np.median(lf.coverage) <= 15
