"""The block minimisers as optimistix solvers: same iterates as stiefel.minimize, RESULTS codes, validation."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
import scipy.linalg as sla

import stiefel
from stiefel import GeneralizedStiefel, RiemannianBB, RiemannianCG, RiemannianImplicitAdjoint, RiemannianLBFGS, Status

from stiefel_cases import dense_of, grid_laplacian, metric_matrix

K = 3


@pytest.fixture(scope="module")
def brockett():
    """Generalised Brockett problem tr(XᵀWXD), sparse W (7×7 grid + I), diagonal M; optimum from eigh."""
    W = grid_laplacian(7) + 0.5 * np.eye(49)
    M = metric_matrix("diagonal", 49, seed=1)
    Wop = stiefel.as_operator(W, check=False, factor=False)
    d = jnp.arange(K, 0, -1.0)
    F = lambda X, args: jnp.sum((X * Wop.mv(X)) @ args)  # noqa: E731  tr(XᵀWX diag(args))
    vals = sla.eigh(dense_of(W), np.diag(M), eigvals_only=True)[:K]
    return W, M, F, d, float(vals @ np.arange(K, 0, -1.0))


@pytest.mark.slow
@pytest.mark.parametrize("cls,method", [(RiemannianCG, "cg"), (RiemannianLBFGS, "lbfgs"), (RiemannianBB, "bb")])
def test_optx_path_equals_minimize(brockett, cls, method):
    W, M, F, d, target = brockett
    S = GeneralizedStiefel(M, K, retraction="cholesky")
    X0 = S.random_point(jax.random.PRNGKey(2))
    P = stiefel.shifted_inverse(W, M, 0.5).solve
    kw = dict(c2=0.1) if method == "cg" else {}
    # gtol 1e-8: CG's projected gradient floors at 3.6e-9 on some CPUs (AVX-512), the value already exact
    sol = optx.minimise(F, cls(S, 0.0, 1e-8, preconditioner=P, **kw), X0, d, max_steps=400,
                        adjoint=RiemannianImplicitAdjoint())
    res = stiefel.minimize(F, S, X0, args=d, method=method, gtol=1e-8, max_iters=400, preconditioner=P)
    assert res.converged and sol.result == optx.RESULTS.successful
    assert int(sol.stats["num_steps"]) == int(res.iterations)
    assert float(jnp.max(jnp.abs(sol.value - res.x))) <= 1e-12  # the same iterates: one implementation
    assert abs(float(res.value) - target) <= 1e-10 * target
    assert float(S.dist_to_manifold(sol.value)) <= 1e-12


@pytest.mark.slow
def test_results_codes_and_throw(brockett):
    W, M, F, d, _ = brockett
    S = GeneralizedStiefel(M, K)
    X0 = S.random_point(jax.random.PRNGKey(0))
    sol = optx.minimise(F, RiemannianCG(S, 0.0, 1e-12), X0, d, max_steps=3, throw=False,
                        adjoint=RiemannianImplicitAdjoint())
    assert sol.result == optx.RESULTS.nonlinear_max_steps_reached
    with pytest.raises(Exception, match="maximum number of steps"):
        optx.minimise(F, RiemannianCG(S, 0.0, 1e-12), X0, d, max_steps=3, adjoint=RiemannianImplicitAdjoint())
    bad = lambda X, args: jnp.sum(X) + jnp.where(X[0, 0] > 10.0, 0.0, jnp.nan)  # noqa: E731
    sol = optx.minimise(bad, RiemannianLBFGS(S), X0, None, max_steps=5, throw=False)
    assert sol.result == optx.RESULTS.nonfinite
    assert int(sol.stats["status"]) == Status.NON_FINITE
    res = stiefel.minimize(lambda X: bad(X, None), S, X0, max_iters=5)
    assert res.status_name == "non_finite"
    assert stiefel.solvers.minimisers.to_optx_result(jnp.asarray(Status.LINE_SEARCH_FAILED)) == optx.RESULTS.nonlinear_divergence


@pytest.mark.slow
def test_runtime_values_do_not_recompile(brockett):
    """Tolerances are traced leaves: two solves differing only in them share one compilation."""
    W, M, F, d, _ = brockett
    S = GeneralizedStiefel(M, K)
    X0 = S.random_point(jax.random.PRNGKey(0))
    jax.clear_caches()  # r1 compiles here, whatever other modules in this process compiled
    r1 = stiefel.minimize(F, S, X0, args=d, gtol=1e-1, ftol=1e-12, c1=1e-4, max_iters=300)
    r2 = stiefel.minimize(F, S, X0, args=d, gtol=1e-7, ftol=1e-13, c1=1e-3, ftol_window=7, max_iters=300)
    assert r2.compile_time < 0.25 * r1.compile_time, (r1.compile_time, r2.compile_time)
    assert int(r1.iterations) != int(r2.iterations)


@pytest.mark.parametrize("kwargs,match", [
    (dict(c1=0.5, c2=0.1), "0 < c1 < c2 < 1"),
    (dict(atol=-1.0), "atol must be a finite number ≥ 0"),
    (dict(init_step=0.0), "init_step must be a finite number > 0"),
    (dict(ftol_window=100), "ftol_window"),
    (dict(ls_max_evals=0), "ls_max_evals"),
])
def test_solver_options_validated(kwargs, match):
    S = GeneralizedStiefel(np.ones(5), 2)
    with pytest.raises(stiefel.StiefelError, match=match):
        RiemannianCG(S, **kwargs)


def test_method_specific_validation():
    S = GeneralizedStiefel(np.ones(5), 2)
    with pytest.raises(stiefel.StiefelError, match="memory"):
        RiemannianLBFGS(S, memory=0)
    with pytest.raises(stiefel.StiefelError, match="bb_gamma"):
        RiemannianBB(S, bb_gamma=1.5)
    with pytest.raises(stiefel.StiefelError, match="GeneralizedStiefel"):
        RiemannianCG(np.ones(5))
    with pytest.raises(stiefel.StiefelError, match="max_iters"):
        stiefel.minimize(lambda X: jnp.sum(X), S, S.random_point(jax.random.PRNGKey(0)), max_iters=-5)
    with pytest.raises(stiefel.StiefelError, match="gtol"):
        stiefel.minimize(lambda X: jnp.sum(X), S, S.random_point(jax.random.PRNGKey(0)), gtol=-1.0)
