"""stiefel.Product: factor-wise geometry against dense references, the slope checks on a coupled
objective, every solver on a separable problem with known minimum (generalised eigenvalues), and the
named errors for bad input."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
import scipy.linalg as sla

import stiefel
from stiefel import (GeneralizedStiefel, Grassmann, OffManifoldError, ParameterError, Product, ShapeError,
                     StiefelError)

N1, K1, N2, K2, N3 = 12, 3, 10, 2, 8
D = np.arange(K1, 0, -1.0)  # Brockett weights: distinct, so the minimiser is isolated


def _spd(rng, n):
    B = rng.standard_normal((n, n))
    return B @ B.T / n + np.eye(n)


def _sym(rng, n):
    A = rng.standard_normal((n, n))
    return A + A.T


@pytest.fixture(scope="module")
def problem():
    """S1 = generalised Stiefel (dense random SPD M1), S2 = Grassmann (diagonal M2), S3 = the unit sphere."""
    rng = np.random.default_rng(3)
    M1, M2 = _spd(rng, N1), np.linspace(1.0, 3.0, N2)
    A, B, C = _sym(rng, N1), _sym(rng, N2), _sym(rng, N3)
    P = Product(GeneralizedStiefel(M1, K1), Grassmann(M2, K2), stiefel.sphere(N3))
    target = (sla.eigh(A, M1, eigvals_only=True)[:K1] @ D + sla.eigh(B, np.diag(M2), eigvals_only=True)[:K2].sum()
              + np.linalg.eigvalsh(C)[0])
    Aj, Bj, Cj, d = map(jnp.asarray, (A, B, C, D))

    def separable(X, args=None):
        X1, X2, x3 = X
        return jnp.sum((X1 * (Aj @ X1)) @ d) + jnp.sum(X2 * (Bj @ X2)) + jnp.sum(x3 * (Cj @ x3))

    u, v, w = rng.standard_normal(N1), rng.standard_normal(K1), rng.standard_normal(N3)

    def coupled(X, args=None):  # couples S1 and S3: (uᵀX1v)(wᵀx3) and its square
        c = (u @ X[0] @ v) * (w @ X[2][:, 0])
        return separable(X) + c + 0.5 * c ** 2

    return dict(P=P, M=(M1, np.diag(M2), np.eye(N3)), target=float(target), separable=separable, coupled=coupled,
                X=P.random_point(jax.random.PRNGKey(0)))


def _gram_error(X, M):
    return float(np.max(np.abs(np.asarray(X).T @ M @ np.asarray(X) - np.eye(X.shape[1]))))


def _random_ambient(P, key):
    keys = jax.random.split(key, len(P.factors))
    return tuple(jax.random.normal(k, (S.n, S.k)) for S, k in zip(P.factors, keys))


# --- construction ------------------------------------------------------------------------------------
def test_construction_and_sizes(problem):
    P = problem["P"]
    assert Product(list(P.factors)).factors == P.factors
    assert P.dim == (N1 * K1 - K1 * (K1 + 1) // 2) + K2 * (N2 - K2) + (N3 - 1)
    assert P.typical_dist == pytest.approx(np.sqrt(K1 + K2 + 1))
    assert P.dtype == jnp.float64
    with pytest.raises(ParameterError, match="nested Products"):
        Product(P, stiefel.sphere(3))
    with pytest.raises(ParameterError, match="factor 1 must be a stiefel.GeneralizedStiefel"):
        Product(stiefel.sphere(3), np.eye(3))
    with pytest.raises(ParameterError, match="at least one factor"):
        Product()


# --- geometry -----------------------------------------------------------------------------------------
def test_proj_is_idempotent_and_tangent_per_factor(problem):
    P, X = problem["P"], problem["X"]
    Z = P.proj(X, _random_ambient(P, jax.random.PRNGKey(1)))
    Z2 = P.proj(X, Z)
    for z, z2 in zip(Z, Z2):
        np.testing.assert_allclose(z2, z, atol=1e-12)
    (X1, X2, x3), (M1, M2, _) = X, problem["M"]
    B1 = np.asarray(X1).T @ M1 @ np.asarray(Z[0])
    assert np.max(np.abs(B1 + B1.T)) <= 1e-12  # Stiefel: XᵀMZ skew
    assert np.max(np.abs(np.asarray(X2).T @ M2 @ np.asarray(Z[1]))) <= 1e-12  # Grassmann: horizontal
    assert abs(float(np.asarray(x3)[:, 0] @ np.asarray(Z[2])[:, 0])) <= 1e-12
    assert float(np.max(np.abs(np.asarray(Z[0]) - np.asarray(_random_ambient(P, jax.random.PRNGKey(1))[0])))) > 1e-3
    for alias in (P.projection, P.to_tangent_space):
        assert all(np.array_equal(a, b) for a, b in zip(alias(X, Z), Z2))


def test_inner_norm_dist_are_factor_sums(problem):
    P, X, Ms = problem["P"], problem["X"], problem["M"]
    Z1 = P.proj(X, _random_ambient(P, jax.random.PRNGKey(2)))
    Z2 = P.proj(X, _random_ambient(P, jax.random.PRNGKey(3)))
    dense = sum(np.trace(np.asarray(a).T @ M @ np.asarray(b)) for a, b, M in zip(Z1, Z2, Ms))  # all Euclidean
    assert float(P.inner(X, Z1, Z2)) == pytest.approx(dense, rel=1e-12)
    assert float(P.inner_product(X, Z1, Z2)) == pytest.approx(dense, rel=1e-12)
    assert float(P.norm(X, Z1)) == pytest.approx(np.sqrt(float(P.inner(X, Z1, Z1))), rel=1e-14)
    xi = P.random_tangent(jax.random.PRNGKey(4), X)
    assert float(P.norm(X, xi)) == pytest.approx(1.0, rel=1e-12)
    assert min(float(S.norm(x, z)) for S, x, z in zip(P.factors, X, xi)) > 0.05  # unequal shares of ‖ξ‖ = 1


@pytest.mark.slow
def test_dist_and_log(problem):
    """Along a geodesic, dist = ‖tξ‖ = t for a unit ξ only with dist = (Σ dist_i²)^{1/2} (a plain sum of the
    factors' distances would be t Σ‖ξ_i‖ > t); log inverts exp. Two Grassmann factors: closed forms, compiled
    in a second (the Gauss–Newton log of the other factors is tested in test_geodesics)."""
    Q = Product(problem["P"].factors[1], Grassmann(None, 2, n=7))
    X = Q.random_point(jax.random.PRNGKey(5))
    xi = Q.random_tangent(jax.random.PRNGKey(6), X)
    Y = Q.exp(X, tuple(0.3 * z for z in xi))
    dist, parts, L = jax.jit(lambda X, Y: (Q.dist(X, Y), [S.dist(x, y) for S, x, y in zip(Q.factors, X, Y)],
                                           Q.log(X, Y)))(X, Y)
    parts = [float(p) for p in parts]
    assert float(dist) == pytest.approx(np.sqrt(sum(p * p for p in parts)), rel=1e-12)
    assert float(dist) == pytest.approx(0.3, rel=1e-8)
    assert sum(parts) > 0.3 * 1.1
    for l, z in zip(L, xi):
        np.testing.assert_allclose(l, 0.3 * z, atol=1e-8)


def test_retract_transport_and_points(problem):
    P, X, Ms = problem["P"], problem["X"], problem["M"]
    xi = P.random_tangent(jax.random.PRNGKey(5), X)
    Y = P.retract(X, xi)
    assert max(_gram_error(y, M) for y, M in zip(Y, Ms)) <= 1e-12
    assert float(P.dist_to_manifold(Y)) <= 1e-12
    assert all(np.array_equal(a, b) for a, b in zip(P.retraction_map(X, xi), Y))
    bent = (Y[0], 1.01 * Y[1], Y[2])  # factor 1 off by ~2 %
    assert float(P.dist_to_manifold(bent)) == pytest.approx(_gram_error(bent[1], Ms[1]), rel=1e-12)
    assert _gram_error(bent[1], Ms[1]) > 1e-2
    Q = P.project_to_manifold(bent)
    assert float(P.dist_to_manifold(Q)) <= 1e-12
    T1, T2 = P.transport_pair(Y, xi, P.zero_vector(X))
    for t, t_ref in zip(T1, P.transport(Y, xi)):
        np.testing.assert_allclose(t, t_ref, atol=1e-13)
    assert all(float(jnp.max(jnp.abs(t))) == 0.0 for t in T2)
    assert all(np.array_equal(a, b) for a, b in zip(P.transp(X, Y, xi), P.transport(Y, xi)))
    R = P.proj(Y, T1)  # transported vectors are tangent at Y
    assert max(float(jnp.max(jnp.abs(a - b))) for a, b in zip(R, T1)) <= 1e-12
    Z = P.random_tangent_vector(jax.random.PRNGKey(5), X)
    assert all(np.array_equal(a, b) for a, b in zip(Z, xi))


def test_riemannian_gradient_matches_directional_derivative(problem):
    """⟨grad F, ξ⟩ = dF(X)[ξ] for a coupled F (jvp), and the tangent residual gives the same slope."""
    P, X, F = problem["P"], problem["X"], problem["coupled"]
    G = jax.grad(F)(X)
    rg = P.egrad_to_rgrad(X, G)
    xi = P.random_tangent(jax.random.PRNGKey(6), X)
    slope = float(jax.jvp(F, (X,), (xi,))[1])
    assert float(P.inner(X, rg, xi)) == pytest.approx(slope, rel=1e-10)
    R = P.tangent_residual(X, G)
    assert sum(float(jnp.sum(r * z)) for r, z in zip(R, xi)) == pytest.approx(slope, rel=1e-10)
    assert all(np.array_equal(a, b) for a, b in zip(P.euclidean_to_riemannian_gradient(X, G), rg))
    MZ = P.mv(xi)
    for mz, z, M in zip(MZ, xi, problem["M"]):
        np.testing.assert_allclose(mz, M @ np.asarray(z), atol=1e-12)


def test_grassmann_aliases_are_its_own_maps(problem):
    """GeneralizedStiefel's aliases named its own functions: on a Grassmann they gave the Stiefel maps."""
    S, X = problem["P"].factors[1], problem["X"][1]
    Y = jax.random.normal(jax.random.PRNGKey(7), X.shape)
    np.testing.assert_array_equal(S.projection(X, Y), S.proj(X, Y))
    np.testing.assert_array_equal(S.euclidean_to_riemannian_gradient(X, Y), S.egrad_to_rgrad(X, Y))
    assert float(jnp.max(jnp.abs(S.proj(X, Y) - GeneralizedStiefel.proj(S, X, Y)))) > 1e-3


# --- slope checks ------------------------------------------------------------------------------------
@pytest.mark.slow
def test_slope_checks_pass_on_a_coupled_objective(problem):
    P, X, F = problem["P"], problem["X"], problem["coupled"]
    g = stiefel.check_gradient(F, P, X)
    assert g.passed and abs(g.slope - 2.0) <= 0.15, g
    assert g.details["tangent_error"] <= 1e-12
    h = stiefel.check_hessian(F, P, X, key=jax.random.PRNGKey(1))
    assert h.passed and abs(h.slope - 3.0) <= 0.15, h
    assert h.details["symmetry_error"] <= 1e-10 and h.details["tangent_error"] <= 1e-12
    r = stiefel.check_retraction(P, X, direction=_random_ambient(P, jax.random.PRNGKey(8)))
    assert r.passed and r.slope >= 2.85, r  # polar on every factor: second order (slope 3)


def test_gradient_check_fails_for_a_wrong_gradient(problem):
    P, X, F = problem["P"], problem["X"], problem["coupled"]

    def wrong(X, args=None):
        G = jax.grad(F)(X)
        return (G[0], G[1], 1.5 * G[2])  # the sphere factor's partial derivative off by 50 %

    g = stiefel.check_gradient(F, P, X, egrad=wrong)
    assert not g.passed and abs(g.slope - 1.0) <= 0.15, g
    with pytest.raises(ShapeError, match="direction has 2 components"):
        stiefel.check_gradient(F, P, X, direction=X[:2])


# --- solvers -----------------------------------------------------------------------------------------
SOLVERS = {
    "cg": lambda P: stiefel.RiemannianCG(P, 0.0, 1e-10),
    "lbfgs": lambda P: stiefel.RiemannianLBFGS(P, 0.0, 1e-10),
    "bb": lambda P: stiefel.RiemannianBB(P, 0.0, 1e-10),
    "tr": lambda P: stiefel.RiemannianTrustRegion(P, 0.0, 1e-10),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", SOLVERS)
def test_solvers_reach_the_sum_of_the_factor_minima(problem, name):
    P, Ms = problem["P"], problem["M"]
    X0 = P.random_point(jax.random.PRNGKey(10))
    sol = optx.minimise(problem["separable"], SOLVERS[name](P), X0, None, max_steps=3000)
    assert sol.result == optx.RESULTS.successful
    assert int(sol.stats["status"]) == stiefel.Status.CONVERGED
    assert isinstance(sol.value, tuple) and len(sol.value) == 3
    assert abs(float(problem["separable"](sol.value)) - problem["target"]) <= 1e-9 * abs(problem["target"])
    assert max(_gram_error(x, M) for x, M in zip(sol.value, Ms)) <= 1e-10
    assert float(sol.stats["dist_to_manifold"]) <= 1e-10
    assert float(sol.stats["grad_norm"]) <= 1e-10


@pytest.mark.slow
def test_coupled_solve_under_jit(problem):
    P, F = problem["P"], problem["coupled"]
    X0 = P.random_point(jax.random.PRNGKey(11))
    run = jax.jit(lambda X0: optx.minimise(F, stiefel.RiemannianLBFGS(P, 0.0, 1e-9), X0, None, max_steps=2000,
                                           throw=False))
    sol = run(X0)
    assert sol.result == optx.RESULTS.successful
    gn = float(P.norm(sol.value, P.egrad_to_rgrad(sol.value, jax.grad(F)(sol.value))))  # recomputed
    assert gn <= 1e-9
    assert float(F(sol.value)) < float(F(X0))
    assert max(_gram_error(x, M) for x, M in zip(sol.value, problem["M"])) <= 1e-10


@pytest.mark.slow
def test_one_factor_product_takes_the_same_steps_as_its_factor(problem):
    S = problem["P"].factors[0]
    X0 = S.random_point(jax.random.PRNGKey(12))
    A = jnp.asarray(_sym(np.random.default_rng(4), N1))
    F = lambda X, d: jnp.sum((X * (A @ X)) @ d)  # noqa: E731
    solver = lambda M: stiefel.RiemannianLBFGS(M, 0.0, 1e-10, memory=4)  # noqa: E731
    plain = optx.minimise(F, solver(S), X0, jnp.asarray(D), max_steps=500)
    prod = optx.minimise(lambda X, d: F(X[0], d), solver(Product(S)), (X0,), jnp.asarray(D), max_steps=500)
    assert int(prod.stats["num_steps"]) == int(plain.stats["num_steps"]) > 5
    np.testing.assert_allclose(prod.value[0], plain.value, atol=1e-13)


# --- bad input ----------------------------------------------------------------------------------------
def _sum_of_squares(X, args):  # accepts any structure: the solver, not fn, must notice a wrong one
    return sum(jnp.sum(x * x) for x in X)


def test_points_of_the_wrong_structure_are_refused(problem):
    P, X = problem["P"], problem["X"]
    for solver in (stiefel.RiemannianCG(P), stiefel.RiemannianTrustRegion(P)):
        with pytest.raises(ShapeError, match="y0 has 2 components; the Product has 3 factors"):
            optx.minimise(_sum_of_squares, solver, X[:2], None, max_steps=5)
        with pytest.raises(ShapeError, match=r"y0\[1\] must have shape \(n, k\) = \(10, 2\), got \(10, 3\)"):
            optx.minimise(_sum_of_squares, solver, (X[0], jnp.ones((N2, 3)), X[2]), None, max_steps=5)
    with pytest.raises(ShapeError, match="pass tuple"):
        P.check_point(list(X))
    P.check_point(X)
    with pytest.raises(OffManifoldError, match=r"X0\[2\] is off the manifold"):
        P.check_point((X[0], X[1], 2.0 * X[2]))


def test_unsupported_combinations_raise_named_errors(problem):
    P, X = problem["P"], problem["X"]
    for cls in (stiefel.RiemannianCG, stiefel.RiemannianLBFGS, stiefel.RiemannianBB, stiefel.RiemannianTrustRegion):
        with pytest.raises(ParameterError, match="preconditioner is not supported on a stiefel.Product"):
            cls(P, preconditioner=lambda Y: Y)
    with pytest.raises(ParameterError, match="RiemannianImplicitAdjoint does not support a stiefel.Product"):
        optx.minimise(_sum_of_squares, stiefel.RiemannianCG(P), X, None, max_steps=5,
                      adjoint=stiefel.RiemannianImplicitAdjoint())
    with pytest.raises(StiefelError, match="for a stiefel.Product, call optx.minimise"):
        stiefel.minimize(lambda X: _sum_of_squares(X, None), P, X)
    with pytest.raises(StiefelError, match="not a manifold"):
        stiefel.minimize_sequential(lambda x: jnp.sum(x * x), P, 1)
    with pytest.raises(StiefelError, match="GeneralizedStiefel or stiefel.Product"):
        stiefel.RiemannianCG(np.eye(3))
