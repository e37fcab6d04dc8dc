"""``laplacian_jax`` (docs/maths.md §7, Ex. 2.5.17, 2.5.22) against the scipy assembly, finite differences and jit."""

from __future__ import annotations

import functools
from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mesh
from stiefel_cmm.cli.demo_mesh import demo_mesh
from mesh.laplacian_jax import AREAS_JAX
from mesh_fixtures import SURFACES, grid, surface


@functools.lru_cache(maxsize=None)
def _demo(subdivisions: int = 4) -> mesh.Mesh:
    return mesh.load(demo_mesh(subdivisions))


def _mesh(name: str) -> mesh.Mesh:
    return _demo() if name == "demo" else surface(name)


def _rel(x, ref) -> float:
    """``max|x − ref| / max|ref|``."""
    ref = np.asarray(ref)
    return float(np.max(np.abs(np.asarray(x) - ref)) / np.max(np.abs(ref)))


@pytest.mark.parametrize("name", [*SURFACES, "demo"])
def test_matches_scipy_assembly(name):
    m = _mesh(name)
    F = m.faces

    @jax.jit  # one compilation per mesh for every area type
    def assemble(V):
        pairs = [mesh.laplacian_jax(V, F, area) for area in AREAS_JAX]
        return pairs, [mesh.mass_diagonal_jax(V, F, area, normalize_area=False) for area in AREAS_JAX]

    pairs, raw = assemble(jnp.asarray(m.vertices))
    for area, (W, A), d in zip(AREAS_JAX, pairs, raw):
        lap = mesh.laplacian(m, weights="cotangent", area=area)
        # the same CSR pattern (every edge both ways, every diagonal), entry by entry
        rows, cols = np.asarray(W.indices).T
        np.testing.assert_array_equal(cols, lap.W.indices)
        np.testing.assert_array_equal(np.bincount(rows, minlength=m.n_vertices), np.diff(lap.W.indptr))
        assert _rel(W.data, lap.W.data) <= 1e-12, area
        np.testing.assert_array_equal(np.asarray(A.indices), np.stack([np.arange(m.n_vertices)] * 2, axis=1))
        assert _rel(A.data, lap.A.diagonal()) <= 1e-12, area
        assert abs(float(jnp.sum(A.data)) - 1.0) <= 1e-13  # Rem. 2.5.31: A only
        assert _rel(d, mesh.area_matrix(m, area).diagonal()) <= 1e-12, area  # normalize_area=False


def test_weight_operator_matches_bcoo():
    m = surface("torus_holes")
    F = m.faces
    rng = np.random.default_rng(0)
    V, dV = jnp.asarray(m.vertices), jnp.asarray(rng.standard_normal((m.n_vertices, 3)))
    X = jnp.asarray(rng.standard_normal((m.n_vertices, 3)))

    @jax.jit
    def both(V, dV):  # W X through the ELL operator and the BCOO, and the jvp of ⟨X, W X⟩ through each
        op, (W, _) = mesh.weight_operator_jax(V, F), mesh.laplacian_jax(V, F)
        _, t_op = jax.jvp(lambda V: jnp.vdot(X, mesh.weight_operator_jax(V, F).mv(X)), (V,), (dV,))
        _, t_bcoo = jax.jvp(lambda V: jnp.vdot(X, mesh.laplacian_jax(V, F)[0] @ X), (V,), (dV,))
        return op.mv(X), W @ X, op.diagonal(), t_op, t_bcoo

    WX_op, WX, diag, t_op, t_bcoo = both(V, dV)
    assert _rel(WX_op, WX) <= 1e-13
    assert _rel(diag, mesh.laplacian(m).W.diagonal()) <= 1e-12
    assert abs(float(t_op - t_bcoo)) <= 1e-12 * abs(float(t_bcoo))


def _probe(V, F, u, c):
    """``uᵀWu`` and ``cᵀAc`` (through the BCOOs) and ``Σ c_i A_ii`` (mass_diagonal_jax) for every area kind."""
    W, A = mesh.laplacian_jax(V, F, "voronoi")  # normalised
    out = [u @ (W @ u), c @ (A @ c), c @ mesh.mass_diagonal_jax(V, F, "mixed")]
    out += [c @ mesh.mass_diagonal_jax(V, F, area, normalize_area=False) for area in ("lumped", "voronoi", "mixed")]
    return jnp.stack(out)


@pytest.mark.slow
def test_derivatives_match_finite_differences():
    # torus with holes: boundary edges carry one cotangent, obtuse faces exercise "mixed"
    m = surface("torus_holes")
    V, F = jnp.asarray(m.vertices), m.faces
    rng = np.random.default_rng(0)
    u, c = (jnp.asarray(rng.standard_normal(m.n_vertices)) for _ in range(2))
    dV = jnp.asarray(rng.standard_normal(V.shape))
    dV = dV * (jnp.linalg.norm(V) / jnp.linalg.norm(dV))  # so that h is a relative step
    h = 1e-6
    w = jnp.asarray(rng.standard_normal(6))

    @jax.jit
    def derivatives(V, dV, u, c, w):  # one compilation: jvp, central differences, gradient
        probe = lambda V: _probe(V, F, u, c)  # noqa: E731
        _, tangent = jax.jvp(probe, (V,), (dV,))
        fd = (probe(V + h * dV) - probe(V - h * dV)) / (2 * h)
        return tangent, fd, jax.grad(lambda V: w @ probe(V))(V)

    tangent, fd, grad = derivatives(V, dV, u, c, w)
    fd_err = np.abs(np.asarray(fd - tangent)) / np.abs(np.asarray(tangent))
    assert np.max(fd_err) <= 1e-6, f"central differences vs jvp, relative errors {fd_err}"
    # reverse mode: ⟨∇(w·probe), dV⟩ = w·jvp, and no NaN in the gradient
    assert bool(jnp.all(jnp.isfinite(grad)))
    assert abs(float(jnp.vdot(grad, dV) - w @ tangent)) <= 1e-12 * float(jnp.abs(w) @ jnp.abs(tangent))


def test_jit_traces_once_for_moved_vertices():
    m = surface("torus")
    F = m.faces
    traces = []

    @jax.jit
    def assemble(V):
        traces.append(None)  # runs only while tracing
        return mesh.laplacian_jax(V, F, "mixed")

    V0 = jnp.asarray(m.vertices)
    V1 = V0 + 0.5 * jnp.asarray(np.random.default_rng(0).standard_normal(V0.shape))
    for V in (V0, V1):
        W, A = assemble(V)
        lap = mesh.laplacian(replace(m, vertices=np.asarray(V)), area="mixed")
        assert _rel(W.data, lap.W.data) <= 1e-12
        assert _rel(A.data, lap.A.diagonal()) <= 1e-12
    assert len(traces) == 1


def test_values_follow_the_dtype_of_v():
    V, F = grid(4, 4, jitter=0.2)
    W, A = mesh.laplacian_jax(jnp.asarray(V, dtype=jnp.float32), F)
    assert W.dtype == A.dtype == jnp.float32
    lap = mesh.laplacian(mesh.load((V, F)))
    assert _rel(W.data, lap.W.data) <= 1e-5


def test_bad_input_is_named_before_tracing():
    V, F = grid(3, 3)
    n = V.shape[0]
    with pytest.raises(mesh.MeshError, match=r"V must have shape \(n, 3\)"):
        mesh.laplacian_jax(V[:, :2], F)
    with pytest.raises(mesh.MeshError, match=r"V must have shape \(n, 3\)"):
        mesh.laplacian_jax(V.ravel(), F)
    with pytest.raises(mesh.MeshError, match="floating"):
        mesh.laplacian_jax(V.astype(int), F)
    with pytest.raises(mesh.NonTriangleFacesError, match=r"\(m, 3\)"):
        mesh.laplacian_jax(V, np.concatenate([F, F[:, :1]], axis=1))
    with pytest.raises(mesh.MeshError, match="integer"):
        mesh.laplacian_jax(V, F.astype(float))
    with pytest.raises(mesh.EmptyMeshError):
        mesh.laplacian_jax(V, np.zeros((0, 3), dtype=int))
    for bad in (n, -1):
        F_bad = F.copy()
        F_bad[3, 1] = bad
        with pytest.raises(mesh.IndexOutOfRangeError, match="e.g. face 3"):
            mesh.laplacian_jax(V, F_bad)
        with pytest.raises(mesh.IndexOutOfRangeError):  # raised while tracing: needs no values of V
            jax.jit(lambda V: mesh.laplacian_jax(V, F_bad))(V)
    F_rep = F.copy()
    F_rep[2] = [0, 0, 1]
    with pytest.raises(mesh.DegenerateMeshError, match="repeat a vertex"):
        mesh.mass_diagonal_jax(V, F_rep)
    for area in ("voronoii", "fem", "uniform"):
        with pytest.raises(mesh.MeshError, match="unknown area"):
            mesh.laplacian_jax(V, F, area)
    with pytest.raises(mesh.IndexOutOfRangeError):
        mesh.weight_operator_jax(V[:4], F)
    with pytest.raises(TypeError, match="F must be concrete"):
        jax.jit(mesh.laplacian_jax)(V, F)
