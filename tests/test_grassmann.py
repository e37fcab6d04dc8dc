"""stiefel.Grassmann (the quotient S_M/O(k)) and the sphere/stiefel helpers: geodesics against principal
angles from scipy, the domain of log, invariance, the slope checks, and solvers on the dominant invariant
subspace problem against eigh (trust regions converge quadratically: no vertical null space)."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
import scipy.linalg as sla

import stiefel
from stiefel import Grassmann

N, K = 30, 3


def _setup(seed=0):
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((N, N))
    M = rng.uniform(0.5, 2.0, N)
    G = Grassmann(M, K)
    X = G.random_point(jax.random.PRNGKey(seed))
    return (A + A.T) / 2, M, G, X


@pytest.mark.slow
def test_geodesics_and_principal_angles():
    A, M, G, X = _setup()
    xi = G.random_tangent(jax.random.PRNGKey(5), X)
    assert float(jnp.max(jnp.abs(X.T @ (M[:, None] * xi)))) <= 1e-14  # horizontal
    r = np.sqrt(M)[:, None]
    for length in (1e-6, 0.4, 1.3):
        Y = G.exp(X, length * xi)
        assert float(G.dist_to_manifold(Y)) <= 1e-13
        assert float(jnp.max(jnp.abs(G.log(X, Y) - length * xi))) <= 1e-11
        assert abs(float(G.dist(X, Y)) - length) <= 1e-11
        # principal angles of the isometric images (M^{1/2}X) from scipy
        ref = np.sort(sla.subspace_angles(r * np.asarray(X), r * np.asarray(Y)))
        assert np.max(np.abs(np.asarray(G.principal_angles(X, Y)) - ref)) <= 1e-10
    Q = jnp.asarray(sla.qr(np.random.default_rng(1).standard_normal((K, K)))[0])
    assert float(G.dist(X, X @ Q)) <= 1e-7 and float(jnp.max(jnp.abs(G.log(X, X @ Q)))) <= 1e-12  # same subspace
    _, vel = jax.jvp(lambda t: G.exp(X, t * xi), (0.0,), (1.0,))
    assert float(jnp.max(jnp.abs(vel - xi))) <= 1e-12


def test_log_outside_its_domain():
    _, M, G, X = _setup()
    # a subspace containing a direction M-orthogonal to span X: a principal angle of π/2
    xi = G.random_tangent(jax.random.PRNGKey(2), X)
    Y = G.project_to_manifold(X.at[:, 0].set(xi[:, 0]))
    with pytest.raises(stiefel.OutOfDomainError, match="π/2"):
        G.log(X, Y)
    assert bool(jnp.all(jnp.isnan(eqx.filter_jit(G.log)(X, Y))))
    assert abs(float(G.principal_angles(X, Y)[-1]) - np.pi / 2) <= 1e-7


@pytest.mark.slow
def test_checks_and_dimension():
    A, M, G, X = _setup(3)
    f = lambda Y: -jnp.trace(Y.T @ A @ Y)  # noqa: E731
    assert stiefel.check_gradient(f, G, X).passed
    assert stiefel.check_hessian(f, G, X).passed
    check = stiefel.check_retraction(G, X)
    assert check.passed and abs(check.details["order"] - 2.0) <= 0.15  # polar: second order
    assert G.dim == K * (N - K)


@pytest.mark.parametrize("solver", ["tr", "lbfgs", pytest.param("cg", marks=pytest.mark.slow)])
def test_dominant_invariant_subspace(solver):
    """max tr(XᵀAX) on Grassmann(M, k): the top k generalised eigenvalues (pymanopt's first example)."""
    A, M, G, X0 = _setup(4)
    fn = lambda X, a: -jnp.trace(X.T @ A @ X)  # noqa: E731
    cls = {"tr": stiefel.RiemannianTrustRegion, "lbfgs": stiefel.RiemannianLBFGS, "cg": stiefel.RiemannianCG}[solver]
    sol = optx.minimise(fn, cls(G, 0.0, 1e-10, history=3001), X0, None, max_steps=3000)
    top = sla.eigh(A, np.diag(M), eigvals_only=True)[-K:]
    assert abs(-float(sol.stats["value"]) - top.sum()) <= 1e-10 * abs(top.sum())
    assert float(G.dist_to_manifold(sol.value)) <= 1e-12
    if solver == "tr":
        g = np.asarray(sol.stats["history"].grad_norm)[: int(sol.stats["num_steps"]) + 1]
        a, b, c = np.log(g[-3:])
        assert (c - b) / (b - a) >= 1.6, g  # quadratic


def test_sphere_and_stiefel_helpers():
    S = stiefel.sphere(7)
    x = S.random_point(jax.random.PRNGKey(0))
    assert x.shape == (7, 1) and abs(float(jnp.sum(x * x)) - 1.0) <= 1e-14
    E = stiefel.sphere(4, np.array([1.0, 2.0, 3.0, 4.0]), retraction="periodic")
    assert E.retraction_name == "periodic" and E.k == 1
    with pytest.raises(stiefel.ShapeError):
        stiefel.sphere(5, np.ones(4))
    St = stiefel.stiefel(9, 3)
    assert St.dim == 9 * 3 - 6 and St.random_point(jax.random.PRNGKey(1)).shape == (9, 3)
