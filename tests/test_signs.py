"""The sign convention (``stiefel.manifolds.signs``): in every basis the toolkit returns, each column's
entry of largest magnitude is positive — CMMs of every solver, batches, differentiable solves,
eigenbases, GMH/LMH/Hamiltonian bases."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mesh
import stiefel
from objectives import bases
from objectives.cmm.batch import cmm_batch
from objectives.cmm.modes import compressed_modes, first_eigenpairs, unpack_laplacian
from objectives.cmm.solvers import ADMMCMM, BlockCMM, FastCMM, SequentialADMMCMM, SequentialCMM
from objectives.cmm.differentiable import cmm_solve


def _peaks_positive(X) -> bool:
    X = np.asarray(X)
    return bool(np.all(X[np.argmax(np.abs(X), axis=0), np.arange(X.shape[1])] > 0))


@pytest.fixture(scope="module")
def small():
    m = mesh.example("starfish", size=-1)  # n = 162
    return m, mesh.laplacian(m)


def test_canonical_signs_rule_numpy_and_jax():
    rng = np.random.default_rng(0)
    X = rng.standard_normal((30, 5))
    Y = stiefel.canonical_signs(X)
    assert _peaks_positive(Y)
    np.testing.assert_array_equal(np.abs(Y), np.abs(X))
    np.testing.assert_array_equal(stiefel.canonical_signs(-X), Y)          # sign-flip invariant
    np.testing.assert_array_equal(stiefel.canonical_signs(Y), Y)           # idempotent
    perm = rng.permutation(30)
    np.testing.assert_array_equal(stiefel.canonical_signs(X[perm]), Y[perm])  # permutation-equivariant
    Yj = jax.jit(stiefel.canonical_signs)(jnp.asarray(X))
    np.testing.assert_array_equal(np.asarray(Yj), Y)
    batched = jax.vmap(stiefel.canonical_signs)(jnp.stack([jnp.asarray(X), -jnp.asarray(X)]))
    np.testing.assert_array_equal(np.asarray(batched[1]), Y)
    # the signs are constants for differentiation: d/dX Σ canonical_signs(X) = s broadcast
    g = jax.grad(lambda Z: jnp.sum(stiefel.canonical_signs(Z)))(jnp.asarray(X))
    np.testing.assert_array_equal(np.asarray(g), np.broadcast_to(stiefel.column_signs(X), X.shape))
    # a zero column keeps its sign (+1), a column whose peak is negative flips
    Z = np.zeros((3, 2)); Z[1, 1] = -2.0
    np.testing.assert_array_equal(stiefel.column_signs(Z), [1.0, -1.0])


@pytest.mark.parametrize("make", [BlockCMM, SequentialCMM, ADMMCMM, SequentialADMMCMM, "fast"],
                         ids=["block", "sequential", "admm", "admm_sequential", "fast"])
@pytest.mark.slow
def test_every_cmm_solver_returns_canonical_signs(small, make):
    m, lap = small
    if make == "fast":
        solver = FastCMM(mesh.local_functions(m, n_samples=40).U, max_iters=200)
    else:
        solver = make(max_iters=200)
    # a start with every column's peak negative: the convention must still hold at the end
    W, a = unpack_laplacian(lap)
    _, phi = first_eigenpairs(W, a, 4)
    start = "random" if make == "fast" else -phi  # FastCMM builds its own start in span(U)
    res = compressed_modes(lap, 4, 0.05 * lap.n, solver=solver, start=start, weighting="uniform")
    assert _peaks_positive(res.modes)


def test_bases_and_eigenbases_have_canonical_signs(small):
    m, lap = small
    eb = mesh.eigenbasis(lap, 6)
    assert _peaks_positive(eb.evecs)
    W, a = unpack_laplacian(lap)
    assert _peaks_positive(first_eigenpairs(W, a, 6)[1])
    g = bases.glmh(lap.W, lap.A, 4, mu_V=10.0, V=np.asarray(m.vertices[:, 0]) ** 2)
    assert _peaks_positive(g.Psi)
    lm = bases.lmh(lap.W, lap.A, 3, eb.evecs[:, :3], 1e4, v=(np.asarray(m.vertices[:, 2]) > 0.5).astype(float),
                   mu_R=1e4)
    assert _peaks_positive(lm.Psi)


@pytest.mark.slow
def test_batch_and_differentiable_solves_have_canonical_signs(small):
    _, lap = small
    W, a = unpack_laplacian(lap)
    _, phi = first_eigenpairs(W, a, 3)
    out = cmm_batch(lap, 3, [0.02 * lap.n, 0.05 * lap.n], starts=-phi)
    for X in out.modes:
        assert _peaks_positive(X)
    Psi, _ = cmm_solve(lap.W_op, jnp.asarray(a), jnp.asarray(-phi), 0.05 * lap.n, max_iters=300, throw=False)
    assert _peaks_positive(Psi)
