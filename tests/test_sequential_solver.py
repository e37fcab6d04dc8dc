"""Sequential solver (thesis Algorithm 6): with μ = 0 it must reproduce scipy's eigsh."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from stiefel import SolverError, Status, as_operator, minimize_sequential, shifted_inverse

from stiefel_cases import grid_laplacian, metric_matrix

K = 10


def eig_reference(W, M, k):
    Mm = sp.diags(M) if np.ndim(M) == 1 else M
    vals, vecs = sla.eigsh(sp.csc_matrix(W), k=k, M=sp.csc_matrix(Mm), sigma=-1e-6, which="LM")
    return vals, vecs


def assert_eigenpairs(res, W, M, *, vtol=1e-7):
    vals, vecs = eig_reference(W, M, K)
    Mm = sp.diags(M) if np.ndim(M) == 1 else M
    got = np.asarray(res.values)
    assert res.converged, res.status_names
    # eigenvalues to 1e-8 relative (the zero eigenvalue to 1e-10 absolute)
    np.testing.assert_allclose(got, vals, rtol=1e-8, atol=1e-10)
    X = np.asarray(res.x)
    overlap = np.abs(np.sum(X * (Mm @ vecs), axis=0))  # |⟨x_j, φ_j⟩_M| = 1 up to sign
    np.testing.assert_allclose(overlap, 1.0, atol=vtol)
    np.testing.assert_allclose(X.T @ (Mm @ X), np.eye(K), atol=1e-10)


@pytest.fixture(scope="module")
def problem():
    W = grid_laplacian(12)  # n = 144, λ₀ = 0 with the constant eigenvector
    M = metric_matrix("diagonal", W.shape[0], seed=5)
    f = lambda x, Wop=as_operator(W, check=False, factor=False): jnp.dot(x, Wop.mv(x))  # noqa: E731
    return W, M, f


@pytest.mark.slow
def test_mu_zero_reproduces_eigsh_plain_cg(problem):
    W, M, f = problem
    res = minimize_sequential(f, M, K, gtol=1e-10, max_iters=5000 * K)  # a total, shared by the K columns
    assert_eigenpairs(res, W, M)


@pytest.mark.slow
def test_mu_zero_reproduces_eigsh_preconditioned(problem):
    W, M, f = problem
    res = minimize_sequential(f, M, K, gtol=1e-10, max_iters=1000 * K, preconditioner=shifted_inverse(W, M, 0.05))
    assert_eigenpairs(res, W, M)
    assert int(np.max(np.asarray(res.iterations))) < 300  # preconditioning is what makes it fast


@pytest.mark.slow
@pytest.mark.parametrize("direction", ["gd", "momentum"])
def test_mu_zero_other_directions(problem, direction):
    W, M, f = problem
    res = minimize_sequential(f, M, K, gtol=1e-10, max_iters=3000 * K, direction=direction,  # total over K columns
                              preconditioner=shifted_inverse(W, M, 0.05))
    assert_eigenpairs(res, W, M)


@pytest.mark.slow
def test_mu_zero_with_sparse_non_diagonal_metric():
    W = grid_laplacian(9)
    M = metric_matrix("sparse", W.shape[0], seed=2)
    Wop = as_operator(W, check=False, factor=False)
    res = minimize_sequential(lambda x: jnp.dot(x, Wop.mv(x)), M, K, gtol=1e-10, max_iters=1000 * K,
                              preconditioner=shifted_inverse(W, M, 0.05))
    assert_eigenpairs(res, W, M)


@pytest.mark.slow
def test_history_start_and_monotone_decrease(problem):
    W, M, f = problem
    X0 = np.random.default_rng(1).standard_normal((W.shape[0], K))
    seen = []
    res = minimize_sequential(f, M, K, X0=X0, gtol=1e-8, max_iters=2000 * K,
                              callback=lambda j, info: seen.append((j, info["status"])))
    assert [j for j, _ in seen] == list(range(K))
    for j in range(K):
        values = np.asarray(res.history.value[j])[: int(res.iterations[j]) + 1]
        assert np.all(np.diff(values) <= 1e-12 * np.abs(values[:-1]) + 1e-15)
        assert np.isnan(np.asarray(res.history.value[j])[int(res.iterations[j]) + 1:]).all()
    # column 0 started from X0[:, 0] normalised
    x0 = X0[:, 0] / np.sqrt(X0[:, 0] @ (M * X0[:, 0]))
    assert abs(float(res.history.value[0, 0]) - float(f(jnp.asarray(x0)))) < 1e-9
    assert res.wall_time > 0 and len(res.column_times) == K


def test_max_iters_status(problem):
    """max_iters is the total of the call, shared fairly: ⌈3/2⌉ = 2 iterations, then the 1 left."""
    W, M, f = problem
    res = minimize_sequential(f, M, 2, gtol=1e-14, max_iters=3)
    assert list(np.asarray(res.status)) == [Status.MAX_ITERS] * 2
    assert list(np.asarray(res.iterations)) == [2, 1]


def test_nan_region_is_never_entered(problem):
    """The objective is NaN past |x₀| > 0.2 and decreases towards it: the line search treats NaN
    trials as too long, so iterates and recorded values stay finite and inside the finite region."""
    W, M, _ = problem
    f = lambda x: jnp.where(jnp.abs(x[0]) > 0.2, jnp.nan, -x[0] ** 2 - 1e-3 * jnp.sum(x))  # noqa: E731
    X0 = np.ones((W.shape[0], 1)) * 0.01
    res = minimize_sequential(f, M, 1, X0=X0, max_iters=50)
    x = np.asarray(res.x)
    assert np.all(np.isfinite(x)) and np.isfinite(float(res.value))
    assert abs(x[0, 0]) <= 0.2 and abs(x[0, 0]) > 0.1  # it did move towards the boundary
    recorded = np.asarray(res.history.value[0])[: int(res.iterations[0]) + 1]
    assert np.all(np.isfinite(recorded))


def test_nan_at_start_is_non_finite_status(problem):
    W, M, _ = problem
    res = minimize_sequential(lambda x: jnp.nan * jnp.sum(x), M, 1, max_iters=5)
    assert int(res.status[0]) == Status.NON_FINITE and int(res.iterations[0]) == 0
    with pytest.raises(SolverError, match="non_finite"):
        minimize_sequential(lambda x: jnp.nan * jnp.sum(x), M, 1, max_iters=5, throw=True)
