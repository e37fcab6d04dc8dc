"""Discrete isometry (thesis Def. 3.4.8, Prop. 3.4.12) and vertex reordering."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st

import mesh
from mesh_fixtures import CLOSED_SURFACES, SURFACES, grid, sphere, surface


def _bandwidth(M) -> int:
    c = sp.coo_array(M)
    return int(np.max(np.abs(c.row - c.col)))


@pytest.mark.parametrize("name", SURFACES)
@pytest.mark.parametrize("weights, area", [("cotangent", "lumped"), ("cotangent", "fem"), ("graph", "degree"), ("cotangent", "mixed")])
def test_permuted_copy_is_isometric(name, weights, area):
    m = surface(name)
    perm = np.random.default_rng(3).permutation(m.n_vertices)
    n = mesh.permute(m, perm)
    np.testing.assert_array_equal(n.vertices, m.vertices[perm])
    lp = mesh.laplacian(m, weights=weights, area=area)
    ln = mesh.laplacian(n, weights=weights, area=area)
    assert mesh.is_isometric(lp, ln, perm)
    Pi = mesh.permutation_matrix(perm)
    assert abs(ln.W - Pi @ lp.W @ Pi.T).max() <= 1e-12 * abs(lp.W).max()
    # a different bijection is not an isometry
    assert not mesh.is_isometric(lp, ln, np.roll(perm, 1))


@pytest.mark.parametrize("name", [*CLOSED_SURFACES, "sphere"])
def test_eigenfunctions_permute(name):
    # the icosphere's symmetry makes its eigenvalues repeat exactly (multiplicities 1, 3, 5): k = 9 ends a cluster
    m, k = (sphere(3), 9) if name == "sphere" else (surface(name), 10)
    perm = np.random.default_rng(5).permutation(m.n_vertices)
    lp = mesh.laplacian(m)
    ln = mesh.laplacian(mesh.permute(m, perm))
    ep, Vp = mesh.eigenbasis(lp, k)
    en, Vn = mesh.eigenbasis(ln, k)
    np.testing.assert_allclose(en, ep, rtol=1e-9, atol=1e-9)
    # group (numerically) repeated eigenvalues
    cluster = np.concatenate([[0], np.cumsum(np.diff(ep) > 1e-6 * ep[-1])])
    assert (np.bincount(cluster).tolist() == [1, 3, 5]) == (name == "sphere")
    for c in np.unique(cluster):
        idx = np.flatnonzero(cluster == c)
        a, b = Vn[:, idx], Vp[perm][:, idx]  # φ_N = Π φ_P (Prop. 3.4.12)
        if idx.size == 1:  # simple eigenvalue: equal up to sign
            err = min(np.abs(a - b).max(), np.abs(a + b).max())
            assert err <= 1e-6 * np.abs(b).max()  # eigenvector accuracy ~ eps/gap
        else:  # repeated eigenvalue: the eigenspaces coincide (all principal angles 0)
            cosines = np.linalg.svd(b.T @ (ln.A @ a), compute_uv=False)
            np.testing.assert_allclose(cosines, 1.0, atol=1e-8)


def test_affine_stretch_is_isometric_only_for_graph_weights():
    # thesis Ex. 3.4.10: an affine map changes angles, so the identity is an isometry for
    # the graph Laplacian but not for the cotangent weights or mixed Voronoi areas
    V, F = grid(5, 4, jitter=0.2)
    p = mesh.load((V, F))
    q = replace(p, vertices=p.vertices * [3.0, 1.0, 1.0])
    ident = np.arange(p.n_vertices)
    assert mesh.is_isometric(mesh.laplacian(p, weights="graph", area="uniform"), mesh.laplacian(q, weights="graph", area="uniform"), ident)
    assert not mesh.is_isometric(mesh.laplacian(p), mesh.laplacian(q), ident)
    assert not mesh.is_isometric(mesh.laplacian(p, weights="graph", area="mixed"), mesh.laplacian(q, weights="graph", area="mixed"), ident)


def test_reorder_reduces_bandwidth_and_is_an_isometry():
    m = surface("torus")
    shuffled = mesh.permute(m, np.random.default_rng(0).permutation(m.n_vertices))
    r, perm = mesh.reorder(shuffled)
    l0, l1 = mesh.laplacian(shuffled), mesh.laplacian(r)
    assert mesh.is_isometric(l0, l1, perm)
    assert _bandwidth(l1.W) < _bandwidth(l0.W) / 4
    inv = mesh.inverse_permutation(perm)
    np.testing.assert_array_equal(r.vertices[inv], shuffled.vertices)


def test_permute_rejects_non_permutations():
    m = surface("hand")
    with pytest.raises(ValueError, match="permutation"):
        mesh.permute(m, np.zeros(m.n_vertices, dtype=int))


@settings(max_examples=10, deadline=None)
@given(
    nx=st.integers(3, 7),
    ny=st.integers(3, 7),
    seed=st.integers(0, 2**16),
    area=st.sampled_from(["lumped", "mixed", "voronoi", "fem", "degree"]),
)
def test_isometry_under_random_relabelling(nx, ny, seed, area):
    V, F = grid(nx, ny, jitter=0.4, seed=seed)
    p = mesh.load((V, F))
    perm = np.random.default_rng(seed).permutation(p.n_vertices)
    lp = mesh.laplacian(p, area=area)
    ln = mesh.laplacian(mesh.permute(p, perm), area=area)
    assert mesh.is_isometric(lp, ln, perm)
    dA, dW = mesh.isometry_defect(lp, ln, perm)
    assert dA <= 1e-12 * abs(lp.A).max() and dW <= 1e-12 * abs(lp.W).max()
