"""Every retraction × every kind of M: R_X(0) = X, dR = Z (jvp), on the manifold for ‖Z‖ up to 1e3."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stiefel import GeneralizedStiefel, StiefelError
from stiefel.manifolds.retractions import cayley_dense

from checkers import check_retraction
from stiefel_cases import M_KINDS, dense_of, metric_matrix

N = 12


@pytest.mark.parametrize("kind", M_KINDS)
@pytest.mark.parametrize("retraction", ["cayley", "cholesky", "polar"])
@pytest.mark.parametrize("k", [1, 4])
def test_block_retractions(kind, retraction, k):
    S = GeneralizedStiefel(metric_matrix(kind, N), k, retraction=retraction)
    key1, key2 = jax.random.split(jax.random.PRNGKey(k))
    X = S.random_point(key1)
    check_retraction(S, X, S.random_tangent(key2, X))


@pytest.mark.parametrize("kind", M_KINDS)
@pytest.mark.parametrize("retraction", ["radial", "periodic"])
def test_ellipsoid_retractions(kind, retraction):
    S = GeneralizedStiefel(metric_matrix(kind, N), 1, retraction=retraction)
    key1, key2 = jax.random.split(jax.random.PRNGKey(7))
    X = S.random_point(key1)
    check_retraction(S, X, S.random_tangent(key2, X))


@pytest.mark.parametrize("kind", M_KINDS)
def test_periodic_is_the_M_geodesic(kind):
    """For M-unit tangent d: R_x(τd) = cos τ x + sin τ d, 2π-periodic (Def. 6.4.20)."""
    S = GeneralizedStiefel(metric_matrix(kind, N), 1, retraction="periodic")
    key1, key2 = jax.random.split(jax.random.PRNGKey(3))
    x = S.random_point(key1)
    d = S.random_tangent(key2, x)
    for tau in (0.3, 1.0, 2.5, 4.0):
        np.testing.assert_allclose(S.retract(x, tau * d), np.cos(tau) * x + np.sin(tau) * d, atol=1e-13)
        np.testing.assert_allclose(S.retract(x, (tau + 2 * np.pi) * d), S.retract(x, tau * d), atol=1e-12)


@pytest.mark.parametrize("kind", M_KINDS)
@pytest.mark.parametrize("k", [1, 3])
def test_low_rank_cayley_equals_dense_formula(kind, k):
    """Woodbury form (6.1.17–6.1.19) equals (I − ½W_Z M)⁻¹(I + ½W_Z M)X (6.1.13)."""
    M = metric_matrix(kind, N)
    S = GeneralizedStiefel(M, k, retraction="cayley")
    key1, key2 = jax.random.split(jax.random.PRNGKey(11))
    X = S.random_point(key1)
    Z = S.random_tangent(key2, X)
    for s in (1e-3, 0.5, 3.0):
        dense = cayley_dense(jnp.asarray(dense_of(M)), X, s * Z)
        np.testing.assert_allclose(S.retract(X, s * Z), dense, atol=1e-12)


def test_cayley_dense_reference_is_a_retraction():
    """Guard the reference itself: it must map onto the manifold too."""
    M = metric_matrix("dense", N)
    S = GeneralizedStiefel(M, 3)
    X = S.random_point(jax.random.PRNGKey(0))
    Z = S.random_tangent(jax.random.PRNGKey(1), X)
    Y = cayley_dense(jnp.asarray(dense_of(M)), X, 2.0 * Z)
    assert float(S.dist_to_manifold(Y)) < 1e-12
    assert float(jnp.max(jnp.abs(Y - X))) > 1e-2


@pytest.mark.parametrize("retraction", ["radial", "periodic"])
def test_ellipsoid_retractions_refuse_k_above_one(retraction):
    with pytest.raises(StiefelError, match="only for k = 1"):
        GeneralizedStiefel(metric_matrix("diagonal", N), 2, retraction=retraction)


@settings(max_examples=6, deadline=None)  # 12 cost 21 s of the default run
@given(n=st.integers(3, 16), data=st.data(), seed=st.integers(0, 2**16),
       kind=st.sampled_from(M_KINDS), retraction=st.sampled_from(["cayley", "cholesky", "polar"]))
@pytest.mark.slow
def test_retraction_properties_over_shapes(n, data, seed, kind, retraction):
    k = data.draw(st.integers(1, min(n, 4)))
    S = GeneralizedStiefel(metric_matrix(kind, n, seed=seed), k, retraction=retraction)
    key1, key2 = jax.random.split(jax.random.PRNGKey(seed))
    X = S.random_point(key1)
    check_retraction(S, X, S.random_tangent(key2, X), dist_tol=1e-11)
