"""The JAX operators of a Laplacian agree with scipy (float64)."""

from __future__ import annotations

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import mesh  # noqa: E402
from stiefel.linalg.operators import DiagonalOperator, SparseOperator  # noqa: E402
from mesh_fixtures import SURFACES, surface  # noqa: E402


@pytest.mark.parametrize("name", SURFACES)
@pytest.mark.parametrize("area", ["lumped", "fem"])
def test_jax_W_and_A_match_scipy(name, area):
    lap = mesh.laplacian(surface(name), area=area)
    rng = np.random.default_rng(0)
    X = rng.standard_normal((lap.n, 10))
    x = X[:, 0]
    W_op, A_op = lap.W_op, lap.A_op
    assert isinstance(W_op, SparseOperator) and W_op.vals.dtype == jnp.float64
    assert isinstance(A_op, DiagonalOperator if area == "lumped" else SparseOperator)
    ref_W, ref_A = lap.W @ X, lap.A @ X
    scale = np.abs(ref_W).max()
    out = jax.jit(lambda op, y: op.mv(y))(W_op, jnp.asarray(X))
    assert np.abs(np.asarray(out) - ref_W).max() <= 1e-12 * scale
    assert np.abs(np.asarray(W_op @ jnp.asarray(x)) - lap.W @ x).max() <= 1e-12 * scale
    assert np.abs(np.asarray(A_op.mv(jnp.asarray(X))) - ref_A).max() <= 1e-12 * np.abs(ref_A).max()


def test_fem_area_solve_and_dtype():
    lap = mesh.laplacian(surface("hand"), area="fem")
    _, A_op = lap.operators(factor_area=True)
    b = np.random.default_rng(1).standard_normal((lap.n, 3))
    x = np.asarray(A_op.solve(jnp.asarray(b)))
    assert np.abs(lap.A @ x - b).max() <= 1e-10 * np.abs(b).max()
    W32, _ = lap.operators(dtype=jnp.float32)
    assert W32.vals.dtype == jnp.float32
