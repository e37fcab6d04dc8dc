"""Exponential map, logarithm and distance of S_M (stiefel.manifolds.geodesics) for both metrics: the geodesic
equations by autodiff, the isometry X ↦ LᵀX with an explicit Cholesky factor, the ellipsoid's closed form,
log ∘ exp = id, and the domain errors."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import stiefel
from stiefel import GeneralizedStiefel

from stiefel_cases import M_KINDS, dense_of, metric_matrix

N = 24


def _setup(kind, k, metric, seed=0):
    S = GeneralizedStiefel(metric_matrix(kind, N, seed=seed), k, metric=metric)
    X = S.random_point(jax.random.PRNGKey(seed))
    xi = S.random_tangent(jax.random.PRNGKey(seed + 100), X)
    return S, X, xi


@pytest.mark.parametrize("kind", ["diagonal", pytest.param("dense", marks=pytest.mark.slow),
                                  pytest.param("sparse", marks=pytest.mark.slow)])
@pytest.mark.slow
def test_euclidean_exp_solves_the_geodesic_equation(kind):
    """γ(t) = Exp_X(tξ): γ(0) = X, γ'(0) = ξ, γ stays on S_M, its acceleration is M-normal (P_γ(γ'') = 0,
    the geodesic equation of the M-weighted embedded metric), and its speed is constant."""
    S, X, xi = _setup(kind, 3, "euclidean")
    gamma = lambda t: S.exp(X, t * xi)  # noqa: E731
    assert float(jnp.max(jnp.abs(gamma(0.0) - X))) <= 1e-14
    velocity = jax.jacfwd(gamma)
    assert float(jnp.max(jnp.abs(velocity(0.0) - xi))) <= 1e-12
    for t in (0.6, 2.9):
        Y = gamma(t)
        assert float(S.dist_to_manifold(Y)) <= 1e-12
        acc = jax.jacfwd(velocity)(t)
        assert float(jnp.max(jnp.abs(S.proj(Y, acc)))) <= 1e-10 * float(jnp.max(jnp.abs(acc)))
        assert abs(float(S.norm(Y, velocity(t))) - 1.0) <= 1e-12


@pytest.mark.slow
def test_canonical_exp_solves_the_canonical_geodesic_equation():
    """M = I: Y'' + Y'Y'ᵀY + Y((YᵀY')² + Y'ᵀY') = 0 (Edelman, Arias, Smith 1998, eq. 2.41)."""
    S = GeneralizedStiefel(None, 3, n=N, metric="canonical")
    X = S.random_point(jax.random.PRNGKey(1))
    xi = S.random_tangent(jax.random.PRNGKey(2), X)
    gamma = lambda t: S.exp(X, t * xi)  # noqa: E731
    v = jax.jacfwd(gamma)
    assert float(jnp.max(jnp.abs(v(0.0) - xi))) <= 1e-12
    for t in (0.4, 1.7):
        Y, Yd, Ydd = gamma(t), v(t), jax.jacfwd(v)(t)
        residual = Ydd + Yd @ Yd.T @ Y + Y @ ((Y.T @ Yd) @ (Y.T @ Yd) + Yd.T @ Yd)
        assert float(jnp.max(jnp.abs(residual))) <= 1e-10
        assert abs(float(S.norm(Y, Yd)) - 1.0) <= 1e-12


@pytest.mark.parametrize("metric", ["euclidean", "canonical"])
def test_exp_is_the_isometry_conjugate_of_the_stiefel_exp(metric):
    """Exp_X(ξ) = L⁻ᵀ Exp_{LᵀX}(Lᵀξ) with an explicit Cholesky factor M = LLᵀ (dense M)."""
    S, X, xi = _setup("dense", 3, metric, seed=3)
    L = np.linalg.cholesky(dense_of(metric_matrix("dense", N, seed=3)))
    St = GeneralizedStiefel(None, 3, n=N, metric=metric)
    Y = np.asarray(St.exp(jnp.asarray(L.T @ np.asarray(X)), jnp.asarray(L.T @ np.asarray(2.0 * xi))))
    expected = np.linalg.solve(L.T, Y)
    assert np.max(np.abs(np.asarray(S.exp(X, 2.0 * xi)) - expected)) <= 1e-12


@pytest.mark.slow
def test_ellipsoid_closed_form():
    """k = 1: Exp_x(tξ) = cos(t)x + sin(t)ξ for ‖ξ‖_M = 1 (a great ellipse), both metrics; dist beyond π
    wraps around: the shortest way to Exp_x(3.5ξ) has length 2π − 3.5."""
    for metric in ("euclidean", "canonical"):
        S, x, xi = _setup("diagonal", 1, metric, seed=4)
        for t in (0.3, 2.0, 3.5):
            assert float(jnp.max(jnp.abs(S.exp(x, t * xi) - (np.cos(t) * x + np.sin(t) * xi)))) <= 1e-13
        assert abs(float(S.dist(x, S.exp(x, 3.5 * xi))) - (2 * np.pi - 3.5)) <= 1e-10


@pytest.mark.slow
@pytest.mark.parametrize("kind", M_KINDS)
@pytest.mark.parametrize("metric", ["euclidean", "canonical"])
def test_log_inverts_exp(kind, metric):
    k = 1 if kind == "sparse" else 3
    S, X, xi = _setup(kind, k, metric, seed=5)
    for length in (1e-3, 1.0, 2.5):
        Y = S.exp(X, length * xi)
        Z = S.log(X, Y)
        assert float(jnp.max(jnp.abs(Z - length * xi))) <= 1e-10
        assert float(jnp.max(jnp.abs(S.proj(X, Z) - Z))) <= 1e-12  # tangent
        assert abs(float(S.dist(X, Y)) - length) <= 1e-10
        assert abs(float(S.dist(Y, X)) - length) <= 1e-10  # symmetric
    assert float(jnp.max(jnp.abs(S.log(X, X)))) <= 1e-14


@pytest.mark.slow
def test_log_within_the_span_of_x():
    """Y = X·Q (Q orthogonal): the logarithm is vertical, XΩ, and Exp brings it back (rank-deficient Y⊥)."""
    S, X, _ = _setup("diagonal", 3, "euclidean", seed=6)
    Omega = jnp.asarray([[0.0, 0.4, -0.2], [-0.4, 0.0, 0.3], [0.2, -0.3, 0.0]])
    Y = S.exp(X, X @ Omega)
    Z = S.log(X, Y)
    assert float(jnp.max(jnp.abs(Z - X @ Omega))) <= 1e-10


@pytest.mark.slow
def test_log_outside_its_domain():
    S = GeneralizedStiefel(metric_matrix("diagonal", 6, seed=7), 1)
    x = S.random_point(jax.random.PRNGKey(7))
    with pytest.raises(stiefel.OutOfDomainError, match="injectivity radius"):
        S.log(x, -x)
    with pytest.raises(stiefel.OutOfDomainError):
        S.dist(x, -x)
    assert bool(jnp.all(jnp.isnan(eqx.filter_jit(S.log)(x, -x))))  # traced: NaN, no exception


def test_expm_matches_scipy():
    import scipy.linalg as sla

    from stiefel.manifolds.geodesics import expm

    rng = np.random.default_rng(9)
    for scale in (1e-6, 0.5, 4.0, 40.0):
        B = scale * rng.standard_normal((6, 6))
        ref = sla.expm(B)
        assert np.max(np.abs(np.asarray(expm(jnp.asarray(B))) - ref)) <= 1e-13 * max(1.0, np.max(np.abs(ref)))
