"""Generalised eigenpairs Wφ = λAφ (thesis §2.5.2)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

import mesh
from mesh_fixtures import quiet_load, sphere, surface, two_spheres

CASES = [
    ("torus", "lumped"),
    ("hand", "mixed"),
    ("bumpy", "fem"),
    ("torus_holes", "lumped"),
    ("torus_holes", "fem"),
]


def _check_pairs(lap, evals, evecs, ortho_tol=1e-10):
    k = evals.size
    assert np.all(np.diff(evals) >= -1e-10 * max(1.0, abs(evals[-1])))
    G = evecs.T @ (lap.A @ evecs)
    assert np.abs(G - np.eye(k)).max() <= ortho_tol
    R = lap.W @ evecs - (lap.A @ evecs) * evals
    scale = max(1.0, evals[-1]) * np.abs(lap.A @ evecs).max()
    assert np.abs(R).max() <= 1e-9 * scale


@pytest.mark.parametrize("name, area", CASES)
def test_eigenpairs_are_A_orthonormal_and_solve_the_problem(name, area):
    m = surface(name)
    lap = mesh.laplacian(m, area=area)
    evals, evecs = mesh.eigenbasis(lap, 12)
    _check_pairs(lap, evals, evecs)
    # first eigenvalue 0 with a constant eigenvector (closed or with a Neumann boundary)
    assert abs(evals[0]) <= 1e-9 * evals[1]
    np.testing.assert_allclose(evecs[:, 0], 1.0 / np.sqrt(lap.A.sum()), rtol=1e-8)
    assert evals[1] > 1.0  # connected: a simple zero eigenvalue


def test_matches_dense_generalised_eigh():
    lap = mesh.laplacian(surface("hand"), area="fem")
    evals, _ = mesh.eigenbasis(lap, 20)
    ref = sla.eigh(lap.W.toarray(), lap.A.toarray(), eigvals_only=True, subset_by_index=[0, 19])
    np.testing.assert_allclose(evals[1:], ref[1:], rtol=1e-9)
    assert abs(evals[0] - ref[0]) < 1e-8


def test_eigenvalues_scale_inversely_with_area():
    lap = mesh.laplacian(surface("bumpy"))
    mu = 7.5
    scaled = replace(lap, A=sp.csr_array(lap.A * mu))
    e1, _ = mesh.eigenbasis(lap, 8)
    e2, _ = mesh.eigenbasis(scaled, 8)
    np.testing.assert_allclose(e2[1:], e1[1:] / mu, rtol=1e-10)
    raw = mesh.laplacian(surface("bumpy"), normalize_area=False)
    e3, _ = mesh.eigenbasis(raw, 8)
    np.testing.assert_allclose(e3[1:], e1[1:] * lap.area_scale, rtol=1e-10)


def test_sphere_spectrum_multiplicities():
    # unit sphere: λ = l(l+1) with multiplicity 2l+1 (before area normalisation)
    lap = mesh.laplacian(sphere(3), area="mixed", normalize_area=False)
    evals, evecs = mesh.eigenbasis(lap, 9)
    np.testing.assert_allclose(evals[1:4], 2.0, rtol=0.01)
    np.testing.assert_allclose(evals[4:9], 6.0, rtol=0.02)
    _check_pairs(lap, evals, evecs)


def test_two_components_have_two_zero_eigenvalues():
    m = quiet_load(two_spheres(2))
    lap = mesh.laplacian(m)
    evals, evecs = mesh.eigenbasis(lap, 6)
    _check_pairs(lap, evals, evecs)
    assert np.all(np.abs(evals[:2]) <= 1e-9 * evals[2]) and evals[2] > 1.0
    # the kernel is spanned by the component indicators
    for j in range(2):
        for c in range(2):
            vals = evecs[m.component == c, j]
            assert np.ptp(vals) <= 1e-8 * np.abs(evecs[:, j]).max()


def test_bad_k():
    lap = mesh.laplacian(sphere(1))
    with pytest.raises(ValueError, match="k must be an integer"):
        mesh.eigenbasis(lap, 0)
    with pytest.raises(ValueError, match="k must be an integer"):
        mesh.eigenbasis(lap, lap.n)


def test_graph_laplacian_with_uniform_area():
    lap = mesh.laplacian(surface("hand"), weights="graph", area="uniform")
    evals, evecs = mesh.eigenbasis(lap, 6)
    _check_pairs(lap, evals, evecs)
    # A = I/n: eigenvalues are n × those of Deg − Adj
    ref = np.linalg.eigvalsh(lap.W.toarray())[:6] * lap.n
    np.testing.assert_allclose(evals[1:], ref[1:], rtol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["quadruped_large", "patch_large"])
def test_eigenpairs_large(name):
    lap = mesh.laplacian(surface(name), area="fem")
    evals, evecs = mesh.eigenbasis(lap, 50)
    _check_pairs(lap, evals, evecs)
    assert abs(evals[0]) <= 1e-9 * evals[1]


def test_eigenbasis_reports_progress_without_changing_the_result():
    """``progress=`` counts ARPACK's shift-invert solves (a report at once, the last one at the end) and
    changes nothing."""
    lap = mesh.laplacian(sphere())
    reports = []
    eb = mesh.eigenbasis(lap, 8, progress=reports.append)
    ref = mesh.eigenbasis(lap, 8)
    assert np.array_equal(eb.evals, ref.evals) and np.array_equal(eb.evecs, ref.evecs)
    assert len(reports) >= 2 and reports[0].iteration == 1 and reports[-1].remaining == 0.0
    assert reports[-1].iteration >= 8 and all(r.method == "eigsh" for r in reports)
    assert "f =" not in reports[-1].line() and reports[-1].line().startswith(f"it {reports[-1].iteration} ")
