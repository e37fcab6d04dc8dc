"""``stiefel.minimize``'s defaults converge, and a line search that fails at the round-off floor is convergence.

The problem a new user tried: the Brockett cost ``tr(XᵀAXN)``, A the 20×20 Dirichlet grid Laplacian (n = 400),
M a random diagonal in [0.5, 2], N = diag(4, 3, 2, 1) (``python -m bench default-method`` measures the panel
behind the default). One compiled L-BFGS program serves the default solve and the floor runs (gtol is a
runtime value); the optimistix path and a failure above the floor are checked in the slow run (one more
compilation each)."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
import scipy.linalg as sla
import scipy.sparse as sp

import stiefel
from stiefel.solvers.linesearch import round_off_floor

K = 4


@pytest.fixture(scope="module")
def brockett():
    m = 20
    path = sp.diags_array([-np.ones(m - 1), 2.0 * np.ones(m), -np.ones(m - 1)], offsets=[-1, 0, 1])
    A = (sp.kron(path, sp.identity(m)) + sp.kron(sp.identity(m), path)).toarray()
    M = np.random.default_rng(0).uniform(0.5, 2.0, m * m)
    lam, V = sla.eigh(A, np.diag(M), subset_by_index=[0, K - 1])
    Aj, N = jnp.asarray(A), jnp.diag(jnp.arange(K, 0, -1.0))
    F = lambda X: jnp.trace(X.T @ Aj @ X @ N)  # noqa: E731 — as a user writes it
    S = stiefel.GeneralizedStiefel(M, K)
    res = stiefel.minimize(F, S, S.random_point(jax.random.PRNGKey(0)))  # every default
    return dict(A=A, M=M, lam=lam, V=V, F=F, S=S, res=res, optimum=float(np.arange(K, 0, -1.0) @ lam))


def test_the_default_converges_and_matches_eigh(brockett):
    """Every default: status converged, the objective and the Ritz values within 1e-8 of eigh's (the former
    default, CG with 1000 iterations, ended max_iters at ‖grad‖ ~1e-5)."""
    res, A = brockett["res"], brockett["A"]
    assert res.status_name == "converged" and float(res.grad_norm) <= 1e-6 and not res.at_floor
    assert abs(float(res.value) - brockett["optimum"]) <= 1e-8 * brockett["optimum"]
    X = np.asarray(res.x)
    ritz = np.diag(X.T @ A @ X)  # column j holds the eigenvector of λ_j (weight K − j)
    assert np.max(np.abs(ritz - brockett["lam"]) / brockett["lam"]) <= 1e-8
    assert float(brockett["S"].dist_to_manifold(res.x)) <= 1e-12


def test_a_search_that_fails_at_the_round_off_floor_is_convergence(brockett):
    """gtol = 0 is below what rounding allows: the run ends when the line search can no longer find a step, with
    ‖grad‖ under ``stats["round_off_floor"]`` — reported as converged at the floor, not line_search_failed
    (before: line_search_failed at ‖grad‖ 5e-15, the minimiser correct to 1e-15)."""
    S, F = brockett["S"], brockett["F"]
    X0 = brockett["res"].x
    res = stiefel.minimize(F, S, X0, gtol=0.0)
    floor = float(res.stats["round_off_floor"])
    assert res.status_name == "converged" and res.at_floor and bool(res.stats["at_floor"])
    assert float(res.grad_norm) <= floor
    n_entries = X0.size
    expected = 10.0 * np.sqrt(n_entries) * np.finfo(float).eps * (abs(float(res.value)) + abs(float(F(X0))))
    assert floor == pytest.approx(expected, rel=1e-12)  # 10·√N·ε·(|F(X)| + |F(X0)|)
    assert floor <= 1e-12  # and far below any gradient norm a failing search leaves (CG: 1e-9 … 1e-6)
    assert abs(float(res.value) - brockett["optimum"]) <= 1e-13 * brockett["optimum"]
    assert "at the round-off floor" in repr(res)
    res.raise_for_status()  # converged: no error


@pytest.mark.slow
def test_optimistix_reports_the_floor_as_success(brockett):
    """The same through ``optx.minimise`` (throw=True, optimistix's default): successful, not 'Nonlinear solve
    diverged'; the status and the floor are in ``sol.stats``."""
    S, F = brockett["S"], brockett["F"]
    sol = optx.minimise(lambda X, a: F(X), stiefel.RiemannianLBFGS(S, rtol=0.0, atol=0.0), brockett["res"].x,
                        max_steps=5000)
    assert sol.result == optx.RESULTS.successful
    assert int(sol.stats["status"]) == stiefel.Status.CONVERGED and bool(sol.stats["at_floor"])
    assert float(sol.stats["grad_norm"]) <= float(sol.stats["round_off_floor"])


@pytest.mark.slow
def test_a_search_that_fails_above_the_floor_stays_a_failure():
    """CG's search fails at ‖grad‖ ~1e-9 on a small diagonal problem, where L-BFGS goes on to 1e-14: that is the
    method's failure, far above the floor (2e-12), and it stays line_search_failed."""
    n, k = 30, 3
    A = np.diag(np.arange(1.0, n + 1))
    N = jnp.diag(jnp.arange(k, 0, -1.0))
    S = stiefel.GeneralizedStiefel(None, k, n=n)
    X0 = stiefel.GeneralizedStiefel(np.ones(n), k).random_point(jax.random.PRNGKey(1))
    res = stiefel.minimize(lambda X: jnp.trace(X.T @ A @ X @ N), S, X0, method="cg", gtol=0.0, max_iters=3000)
    assert res.status_name == "line_search_failed" and not res.at_floor
    assert float(res.grad_norm) > 100 * float(res.stats["round_off_floor"])


def test_the_floor_scales_with_the_objective_the_size_and_the_precision():
    f64 = float(round_off_floor(jnp.asarray(2.0), jnp.asarray(-3.0), 400))
    assert f64 == pytest.approx(10 * 20 * np.finfo(np.float64).eps * 5.0, rel=1e-12)
    f32 = float(round_off_floor(jnp.asarray(2.0, jnp.float32), jnp.asarray(-3.0, jnp.float32), 400))
    assert f32 == pytest.approx(10 * 20 * np.finfo(np.float32).eps * 5.0, rel=1e-6)
