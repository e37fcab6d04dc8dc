"""Tangent projection, metrics and Riemannian gradients (docs/maths.md §1 and note 1)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stiefel import GeneralizedStiefel, preconditioned_gradient, SequentialConstraint, as_operator

from checkers import check_gradient
from stiefel_cases import M_KINDS, dense_of, metric_matrix

N, K = 12, 3


def objective(n, k, seed=0):
    """A generic smooth non-quadratic F(X)."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((n, n))
    A = jnp.asarray(A + A.T)
    B = jnp.asarray(rng.standard_normal((k, k)))
    C = jnp.asarray(rng.standard_normal((n, k)))
    return lambda X: jnp.sum(X * (A @ X @ B)) + jnp.sum(jnp.sin(X * C)) + jnp.sum(X**4)


@pytest.mark.parametrize("kind", M_KINDS)
@pytest.mark.parametrize("metric", ["euclidean", "canonical"])
def test_riemannian_gradient_is_the_directional_derivative(kind, metric):
    S = GeneralizedStiefel(metric_matrix(kind, N), K, metric=metric)
    X = S.random_point(jax.random.PRNGKey(0))
    check_gradient(objective(N, K), S, X, jax.random.PRNGKey(1))


@pytest.mark.parametrize("kind", M_KINDS)
def test_projection_is_tangent_idempotent_and_M_orthogonal(kind):
    M = metric_matrix(kind, N)
    S = GeneralizedStiefel(M, K)
    X = S.random_point(jax.random.PRNGKey(2))
    Y = jax.random.normal(jax.random.PRNGKey(3), X.shape)
    PY = S.proj(X, Y)
    XtMZ = X.T @ S.op.mv(PY)
    assert float(jnp.max(jnp.abs(XtMZ + XtMZ.T))) < 1e-12
    np.testing.assert_allclose(S.proj(X, PY), PY, atol=1e-12)
    # the residual Y − PY is M-orthogonal to every tangent vector
    Z = S.random_tangent(jax.random.PRNGKey(4), X)
    assert abs(float(jnp.sum((Y - PY) * S.op.mv(Z)))) < 1e-12


@pytest.mark.parametrize("kind", M_KINDS)
def test_transport_pair_is_two_transports(kind):
    """The block solver's fused transport equals two projections (to rounding)."""
    S = GeneralizedStiefel(metric_matrix(kind, N), K)
    X = S.random_point(jax.random.PRNGKey(5))
    Z1, Z2 = (jax.random.normal(jax.random.PRNGKey(s), X.shape) for s in (6, 7))
    T1, T2 = S.transport_pair(X, Z1, Z2)
    np.testing.assert_allclose(T1, S.transport(X, Z1), atol=1e-13)
    np.testing.assert_allclose(T2, S.transport(X, Z2), atol=1e-13)
    assert not np.allclose(T1, Z1)  # the projection did something


def test_metrics_differ_only_on_rotations():
    """Canonical metric halves the weight of the XᵀMZ (rotation) part (docs/maths.md §1)."""
    M = metric_matrix("diagonal", N)
    Se, Sc = GeneralizedStiefel(M, K), GeneralizedStiefel(M, K, metric="canonical")
    X = Se.random_point(jax.random.PRNGKey(5))
    Om = jnp.asarray([[0.0, 1.0, -2.0], [-1.0, 0.0, 0.5], [2.0, -0.5, 0.0]])
    Z_rot = X @ Om  # XᵀM(XΩ) = Ω skew: a pure rotation
    assert abs(float(Sc.inner(X, Z_rot, Z_rot)) - 0.5 * float(Se.inner(X, Z_rot, Z_rot))) < 1e-12
    Y = jax.random.normal(jax.random.PRNGKey(6), X.shape)
    Z_perp = Y - X @ (X.T @ Se.op.mv(Y))  # XᵀMZ = 0
    assert abs(float(Sc.inner(X, Z_perp, Z_perp)) - float(Se.inner(X, Z_perp, Z_perp))) < 1e-12


@pytest.mark.parametrize("kind", M_KINDS)
def test_preconditioned_gradient_in_its_metric(kind):
    """g_P(ξ, Z) = tr(ξᵀP⁻¹Z) = tr(GᵀZ) for tangent Z, ξ tangent; P = M⁻¹ gives grad_e."""
    M = metric_matrix(kind, N)
    S = GeneralizedStiefel(M, K)
    X = S.random_point(jax.random.PRNGKey(7))
    G = jax.grad(objective(N, K))(X)
    rng = np.random.default_rng(8)
    B = rng.standard_normal((N, N))
    K_mat = B @ B.T + N * np.eye(N)  # P = K⁻¹
    P = as_operator(K_mat)
    xi = preconditioned_gradient(S.op, P.solve, X, G)
    XtMxi = X.T @ S.op.mv(xi)
    assert float(jnp.max(jnp.abs(XtMxi + XtMxi.T))) < 1e-11
    for sub in jax.random.split(jax.random.PRNGKey(9), 3):
        Z = S.random_tangent(sub, X)
        np.testing.assert_allclose(jnp.sum(xi * (K_mat @ Z)), jnp.sum(G * Z), rtol=1e-10, atol=1e-12)
    xi_M = preconditioned_gradient(S.op, S.op.solve, X, G)
    np.testing.assert_allclose(xi_M, S.egrad_to_rgrad(X, G), atol=1e-11)


@pytest.mark.parametrize("kind", M_KINDS)
def test_sequential_constraint_set(kind):
    """{x : ΦᵀMx = 0, xᵀMx = 1}: projection, tangent projector, gradient (docs/maths.md §2)."""
    M = metric_matrix(kind, N)
    S = GeneralizedStiefel(M, K)
    Phi = S.random_point(jax.random.PRNGKey(10))
    C = SequentialConstraint(M, Phi)
    Md = dense_of(M)
    x = C.project(jax.random.normal(jax.random.PRNGKey(11), (N,)))
    np.testing.assert_allclose(Phi.T @ Md @ x, 0, atol=1e-12)
    assert abs(float(x @ Md @ x) - 1) < 1e-12
    v = jax.random.normal(jax.random.PRNGKey(12), (N,))
    z = C.proj(x, v)
    np.testing.assert_allclose(jnp.concatenate([Phi.T @ Md @ z, jnp.atleast_1d(x @ Md @ z)]), 0, atol=1e-12)
    np.testing.assert_allclose(C.proj(x, z), z, atol=1e-12)
    f = lambda y: jnp.sum(jnp.cos(y)) + y @ jnp.arange(N, dtype=y.dtype) * y.sum()  # noqa: E731
    xi = C.egrad_to_rgrad(x, jax.grad(f)(x))
    _, df = jax.jvp(f, (x,), (z,))
    np.testing.assert_allclose(C.inner(x, xi, z), df, rtol=1e-10)
    y = C.retract(x, 0.7 * z / jnp.sqrt(C.inner(x, z, z)))
    np.testing.assert_allclose(Phi.T @ Md @ y, 0, atol=1e-12)
    assert abs(float(y @ Md @ y) - 1) < 1e-12


@settings(max_examples=4, deadline=None)  # 8 cost 18 s of the default run
@given(n=st.integers(3, 14), data=st.data(), seed=st.integers(0, 2**16),
       kind=st.sampled_from(M_KINDS), metric=st.sampled_from(["euclidean", "canonical"]))
@pytest.mark.slow
def test_gradient_identity_over_shapes(n, data, seed, kind, metric):
    k = data.draw(st.integers(1, min(n, 4)))
    S = GeneralizedStiefel(metric_matrix(kind, n, seed=seed), k, metric=metric, retraction="polar")
    X = S.random_point(jax.random.PRNGKey(seed))
    check_gradient(objective(n, k, seed), S, X, jax.random.PRNGKey(seed + 1))


class _ThesisSlip:
    """The manifold with docs/maths.md note 1 re-introduced: the gradient projects G itself, without M⁻¹."""

    def __init__(self, S):
        self._S = S

    def __getattr__(self, name):
        return getattr(self._S, name)

    def egrad_to_rgrad(self, X, G):
        return self._S.proj(X, G)


def test_checker_rejects_the_thesis_gradient_slip():
    """docs/maths.md note 1: proj(G) is not the gradient for non-uniform M; the checker must notice."""
    S = GeneralizedStiefel(metric_matrix("diagonal", N), K)
    X = S.random_point(jax.random.PRNGKey(0))
    with pytest.raises(AssertionError):
        check_gradient(objective(N, K), _ThesisSlip(S), X, jax.random.PRNGKey(1))


@pytest.mark.parametrize("kind", M_KINDS)
def test_preconditioned_residual_is_descent_and_vanishes_at_critical_points(kind):
    """ξ = proj_X(P R), R = G − MX sym(XᵀG): tangent, tr(Gᵀξ) = tr(RᵀPR) > 0, ξ = 0 at a critical point."""
    from stiefel import preconditioned_residual
    from stiefel.manifolds.manifold import sym

    M = metric_matrix(kind, N)
    S = GeneralizedStiefel(M, K)
    X = S.random_point(jax.random.PRNGKey(13))
    G = jax.grad(objective(N, K))(X)
    R = G - S.op.mv(X) @ sym(X.T @ G)
    rng = np.random.default_rng(14)
    B = rng.standard_normal((N, N))
    P = jnp.asarray(np.linalg.inv(B @ B.T + N * np.eye(N)))
    xi = preconditioned_residual(S, lambda Y: P @ Y, X, R)
    XtMxi = X.T @ S.op.mv(xi)
    assert float(jnp.max(jnp.abs(XtMxi + XtMxi.T))) < 1e-11
    np.testing.assert_allclose(jnp.sum(G * xi), jnp.sum(R * (P @ R)), rtol=1e-10)
    assert float(jnp.sum(G * xi)) > 0
    # critical point of tr(XᵀWX): generalised eigenvectors of (W, M)
    Wd = B + B.T
    Md = dense_of(M)
    L = np.linalg.cholesky(Md)
    _, Y = np.linalg.eigh(np.linalg.solve(L, np.linalg.solve(L, Wd).T).T)
    Xc = jnp.asarray(np.linalg.solve(L.T, Y[:, :K]))
    Gc = 2.0 * jnp.asarray(Wd) @ Xc
    Rc = Gc - S.op.mv(Xc) @ sym(Xc.T @ Gc)
    assert float(jnp.max(jnp.abs(preconditioned_residual(S, lambda Y: P @ Y, Xc, Rc)))) < 1e-10


@pytest.mark.slow
def test_ordinary_stiefel_manifold_from_none():
    """``GeneralizedStiefel(None, k)`` is ``XᵀX = I``: the same solve as an explicit identity metric; ``n``
    is optional and only what needs it asks for it."""
    import jax
    import jax.numpy as jnp
    import numpy as np
    import pytest

    import stiefel
    from stiefel.errors import ShapeError

    n, k = 30, 3
    A = np.diag(np.arange(1.0, n + 1))
    N = jnp.diag(jnp.arange(k, 0, -1.0))

    def brockett(X):
        return jnp.trace(X.T @ A @ X @ N)

    X0 = stiefel.GeneralizedStiefel(np.ones(n), k).random_point(jax.random.PRNGKey(1))
    # gtol 1e-8: the value is exact long before; below ~1e-9 the gradient stalls on round-off on some CPUs (AVX-512)
    ref = stiefel.minimize(brockett, stiefel.GeneralizedStiefel(np.ones(n), k), X0, gtol=1e-8)
    for S in (stiefel.GeneralizedStiefel(None, k), stiefel.GeneralizedStiefel(None, k, n=n)):
        got = stiefel.minimize(brockett, S, X0, gtol=1e-8)
        assert got.status_name == ref.status_name == "converged"
        assert float(got.value) == pytest.approx(float(ref.value), rel=1e-12)
        assert float(jnp.max(jnp.abs(got.x.T @ got.x - jnp.eye(k)))) <= 1e-12
    assert float(ref.value) == pytest.approx(float(np.sum(np.arange(1.0, k + 1) * np.arange(k, 0, -1.0))), rel=1e-9)
    sized = stiefel.GeneralizedStiefel(None, k, n=n)
    assert sized.random_point(jax.random.PRNGKey(0)).shape == (n, k) and sized.dim == n * k - k * (k + 1) // 2
    with pytest.raises(ShapeError, match="n=n"):
        stiefel.GeneralizedStiefel(None, k).random_point(jax.random.PRNGKey(0))
    with pytest.raises(ShapeError, match="k must be"):
        stiefel.GeneralizedStiefel(None, 5, n=4)
    with pytest.raises(ShapeError, match="only for M = None"):
        stiefel.GeneralizedStiefel(np.ones(n), k, n=n)
    with pytest.raises(ShapeError, match="shape"):
        stiefel.GeneralizedStiefel(None, k).check_point(np.zeros((n, k + 1)))


def test_pymanopt_and_manopt_names() -> None:
    """zero_vector, random_tangent_vector, transp and to_tangent_space mean what pymanopt/Manopt mean."""
    S = GeneralizedStiefel(jnp.linspace(1.0, 3.0, 12), 3)
    X = S.random_point(jax.random.PRNGKey(0))
    Y = S.random_point(jax.random.PRNGKey(1))
    assert float(jnp.max(jnp.abs(S.zero_vector(X)))) == 0.0 and S.zero_vector(X).shape == X.shape
    Z = S.random_tangent_vector(jax.random.PRNGKey(7), X)
    np.testing.assert_array_equal(np.asarray(Z), np.asarray(S.random_tangent(jax.random.PRNGKey(7), X)))
    assert abs(float(S.norm(X, Z)) - 1.0) < 1e-12
    assert float(jnp.max(jnp.abs(S.proj(X, Z) - Z))) < 1e-12                              # tangent at X
    W = S.random_tangent_vector(jax.random.PRNGKey(5), X)
    assert float(jnp.max(jnp.abs(W - Z))) > 1e-3
    T = S.transp(X, Y, Z)
    np.testing.assert_allclose(np.asarray(T), np.asarray(S.transport(Y, Z)), atol=0)
    B = Y.T @ S.op.mv(T)
    assert float(jnp.max(jnp.abs(B + B.T))) < 1e-12                                       # tangent at Y
    G = jax.random.normal(jax.random.PRNGKey(2), X.shape)
    np.testing.assert_array_equal(np.asarray(S.to_tangent_space(X, G)), np.asarray(S.proj(X, G)))
