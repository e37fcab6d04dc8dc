"""Riemannian Hessian and implicit derivatives of manifold solutions (docs/maths.md §9), against
finite differences of re-solved problems, scipy's eigh and the eigenvector perturbation formula."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
import scipy.linalg as sla

import stiefel
from stiefel import GeneralizedStiefel, RiemannianImplicitAdjoint, RiemannianLBFGS

from stiefel_cases import M_KINDS, dense_of, metric_matrix

N, K = 40, 3


def _random_sym(n, seed, shift=0.0):
    B = np.random.default_rng(seed).standard_normal((n, n))
    return (B + B.T) / 2 + shift * np.eye(n)


@pytest.mark.parametrize("kind", M_KINDS)
@pytest.mark.parametrize("metric", ["euclidean", "canonical"])
def test_hessian_matches_fd_of_gradient_along_retraction(kind, metric):
    """Hess F(X)[ξ] = P_X(d/dt grad F(R_X(tξ)))|₀ (central FD), and Hess is ⟨·,·⟩_M-self-adjoint."""
    M = metric_matrix(kind, N, seed=4)
    S = GeneralizedStiefel(M, K, metric=metric, retraction="cholesky")
    W = jnp.asarray(_random_sym(N, 1))
    F = lambda X: jnp.trace(X.T @ W @ X @ jnp.diag(jnp.arange(1.0, K + 1))) + jnp.sum(jnp.cos(X))  # noqa: E731
    X = S.random_point(jax.random.PRNGKey(0))
    k1, k2 = jax.random.split(jax.random.PRNGKey(1))
    xi, eta = S.random_tangent(k1, X), S.random_tangent(k2, X)
    eu = GeneralizedStiefel(M, K, retraction="cholesky")  # the Euclidean-metric gradient field

    def grad_at(t):
        Y = S.retract(X, t * xi)
        return eu.egrad_to_rgrad(Y, jax.grad(F)(Y))

    h = 1e-5
    fd = S.proj(X, (grad_at(h) - grad_at(-h)) / (2 * h))
    hess = stiefel.riemannian_hessian(F, S, X, xi)
    assert float(jnp.max(jnp.abs(hess - fd)) / jnp.max(jnp.abs(hess))) <= 1e-7
    assert float(jnp.max(jnp.abs(S.proj(X, hess) - hess))) <= 1e-12  # tangent
    a, b = eu.inner(X, stiefel.riemannian_hessian(F, S, X, eta), xi), eu.inner(X, hess, eta)
    assert abs(float(a - b)) <= 1e-10 * abs(float(a))
    op = stiefel.hessian_operator(F, S, X)
    assert float(jnp.max(jnp.abs(op(xi) - hess))) <= 1e-12


def _eig_problem(kind):
    W0 = _random_sym(N, 2, shift=N ** 0.5 + 1.0)
    D = _random_sym(N, 3)
    M = metric_matrix(kind, N, seed=5)
    return W0, D, M


def _solve_eig(W0, D, M, theta, *, X0=None, invariant=True, throw=True, max_iters=4000, gtol=1e-11):
    S = GeneralizedStiefel(M, K, retraction="cholesky")
    F = lambda X, th: jnp.trace(X.T @ (W0 + th * D) @ X)  # noqa: E731  (invariant under X → XQ)
    X0 = S.random_point(jax.random.PRNGKey(7)) if X0 is None else X0
    res = stiefel.minimize(F, S, X0, args=theta, method="lbfgs", gtol=gtol, max_iters=max_iters,
                           adjoint=RiemannianImplicitAdjoint(invariant=invariant, throw=throw), check=False)
    return res, S


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["diagonal", pytest.param("dense", marks=pytest.mark.slow)])
def test_invariant_eigen_derivative(kind):
    """d/dθ tr(XᵀBX) and d/dθ of the projector XXᵀM for the k lowest eigenvectors of (W0 + θD, M):
    jvp, grad and jacfwd against eigh finite differences and the eigenvector perturbation formula."""
    W0, D, M = _eig_problem(kind)
    Md = dense_of(M)
    B = jnp.asarray(_random_sym(N, 9))
    theta = 0.3

    def quantity(th):
        res, S = _solve_eig(W0, D, M, th)
        X = res.x
        return jnp.trace(X.T @ B @ X) + jnp.sum((X @ (X.T @ S.op.mv(jnp.eye(N))))[:6, :6])

    def quantity_eigh(th):
        lam, V = sla.eigh(W0 + th * D, Md)
        X = V[:, :K]
        return np.trace(X.T @ np.asarray(B) @ X) + np.sum((X @ (X.T @ Md))[:6, :6])

    lam, V = sla.eigh(W0 + theta * D, Md)
    # analytic: dv_i = Σ_{j ≥ k} v_j (v_jᵀDv_i)/(λ_i − λ_j) (the in-span part does not move the projector)
    dV = np.stack([sum(V[:, j] * (V[:, j] @ D @ V[:, i]) / (lam[i] - lam[j]) for j in range(K, N))
                   for i in range(K)], axis=1)
    X = V[:, :K]
    analytic = 2 * np.trace(X.T @ np.asarray(B) @ dV) + np.sum((dV @ X.T @ Md + X @ dV.T @ Md)[:6, :6])
    h = 1e-5
    fd = (quantity_eigh(theta + h) - quantity_eigh(theta - h)) / (2 * h)
    assert abs(fd - analytic) <= 1e-6 * abs(analytic)
    jvp = float(jax.jvp(quantity, (theta,), (1.0,))[1])
    grad = float(jax.grad(quantity)(theta))
    jac = float(jax.jacfwd(quantity)(theta))
    for value in (jvp, grad, jac):
        assert abs(value - analytic) <= 1e-5 * abs(analytic), (value, analytic)


@pytest.mark.slow
def test_derivative_with_respect_to_M():
    """M = diag(m(θ)) inside the differentiated function: the derivative of tr(XᵀBX) matches eigh FD."""
    W0, D, _ = _eig_problem("diagonal")
    m0 = metric_matrix("diagonal", N, seed=6)
    dm = np.random.default_rng(8).uniform(-0.3, 0.3, N)
    B = _random_sym(N, 10)

    def quantity(th):
        S = GeneralizedStiefel(jnp.asarray(m0) + th * jnp.asarray(dm), K, retraction="cholesky")
        X0 = S.project_to_manifold(jnp.asarray(np.eye(N)[:, :K]) + 0.1)
        F = lambda X: jnp.trace(X.T @ W0 @ X)  # noqa: E731
        res = stiefel.minimize(F, S, X0, method="lbfgs", gtol=1e-11, max_iters=4000,
                               adjoint=RiemannianImplicitAdjoint(invariant=True))
        return jnp.trace(res.x.T @ B @ res.x)

    def quantity_eigh(th):
        X = sla.eigh(W0, np.diag(m0 + th * dm))[1][:, :K]
        return np.trace(X.T @ B @ X)

    h = 1e-5
    fd = (quantity_eigh(h) - quantity_eigh(-h)) / (2 * h)
    grad = float(jax.grad(quantity)(0.0))
    assert abs(grad - fd) <= 1e-5 * abs(fd), (grad, fd)


def test_noninvariant_derivative_against_resolved_fd():
    """A non-invariant objective (generalised Brockett plus a quartic) and a non-invariant loss:
    reverse and forward mode against central differences of re-solved problems (from the solution)."""
    M = metric_matrix("diagonal", N, seed=11)
    W = jnp.asarray(_random_sym(N, 12, shift=N ** 0.5 + 1.0))
    c = jnp.asarray(np.random.default_rng(13).standard_normal((N, K)))
    S = GeneralizedStiefel(M, K, retraction="cholesky")
    d = jnp.arange(K, 0, -1.0)

    def F(X, theta):
        mu, w = theta
        return jnp.sum((X * (W @ X)) @ d) + mu * jnp.sum(w[:, None] * X ** 4)

    X_start = stiefel.minimize(F, S, S.random_point(jax.random.PRNGKey(3)), args=(jnp.asarray(0.5), jnp.ones(N)),
                               method="lbfgs", gtol=1e-12, max_iters=5000).x

    def loss(theta):
        res = stiefel.minimize(F, S, X_start, args=theta, method="lbfgs", gtol=1e-12, max_iters=5000, check=False)
        return jnp.sum(c * res.x)

    # θ as arrays throughout: a Python float in args is static, and every new value would compile anew
    theta = (jnp.asarray(0.5), jnp.ones(N))
    g_mu, g_w = jax.grad(loss)(theta)
    # h = 1e-3: the central difference's O(h²) error is ~1e-9 relative here, while at h = 1e-6 the re-solves'
    # stopping noise (gtol 1e-12, 69 vs 72 iterations) divided by 2h is ~5e-5 relative (measured)
    h = 1e-3
    fd_mu = (loss((theta[0] + h, theta[1])) - loss((theta[0] - h, theta[1]))) / (2 * h)
    e3 = jnp.zeros(N).at[3].set(1.0)
    fd_w3 = (loss((theta[0], theta[1] + h * e3)) - loss((theta[0], theta[1] - h * e3))) / (2 * h)
    assert abs(float(g_mu) - float(fd_mu)) <= 1e-6 * abs(float(fd_mu))
    assert abs(float(g_w[3]) - float(fd_w3)) <= 1e-6 * abs(float(fd_w3))
    jvp_mu = jax.jvp(lambda m: loss((m, theta[1])), (theta[0],), (jnp.ones(()),))[1]
    assert abs(float(jvp_mu) - float(g_mu)) <= 1e-8 * abs(float(g_mu))


@pytest.mark.slow
def test_optx_minimise_with_adjoint_is_differentiable():
    """The optimistix idiom: optx.minimise(..., adjoint=RiemannianImplicitAdjoint()) under jax.grad."""
    W0, D, M = _eig_problem("diagonal")
    S = GeneralizedStiefel(M, K, retraction="cholesky")
    B = jnp.asarray(_random_sym(N, 14))
    X0 = S.random_point(jax.random.PRNGKey(7))

    def quantity(th, minimiser):
        fn = lambda X, t: jnp.trace(X.T @ (W0 + t * D) @ X)  # noqa: E731
        sol = optx.minimise(fn, minimiser, X0, th, max_steps=4000, adjoint=RiemannianImplicitAdjoint(invariant=True))
        return jnp.trace(sol.value.T @ B @ sol.value)

    g = float(jax.grad(quantity)(0.3, RiemannianLBFGS(S, 0.0, 1e-11)))

    def via_minimize(th):
        X = _solve_eig(W0, D, M, th)[0].x
        return jnp.trace(X.T @ B @ X)

    via_minimize = float(jax.grad(via_minimize)(0.3))
    assert abs(g - via_minimize) <= 1e-7 * abs(g)


@pytest.mark.slow
def test_nonconverged_solve_gives_nan_or_raises():
    W0, D, M = _eig_problem("diagonal")

    def quantity(th, throw):
        res, _ = _solve_eig(W0, D, M, th, max_iters=3, throw=throw)
        return jnp.sum(res.x[:4])

    assert np.isnan(float(jax.grad(lambda t: quantity(t, False))(0.3)))
    assert np.isnan(float(jax.jvp(lambda t: quantity(t, False), (0.3,), (1.0,))[1]))
    with pytest.raises(Exception, match="did not converge"):
        jax.grad(lambda t: quantity(t, True))(0.3)
    # minimize's defaults (no adjoint, no throw): the derivative is refused, not NaN; the solve itself does not raise
    S = GeneralizedStiefel(M, K, retraction="cholesky")
    X0 = S.random_point(jax.random.PRNGKey(7))

    def default(th):
        return stiefel.minimize(lambda X, t: jnp.trace(X.T @ (W0 + t * D) @ X), S, X0, args=th, max_iters=3)

    assert default(0.3).status_name == "max_iters"
    with pytest.raises(Exception, match="did not converge"):
        jax.grad(lambda t: jnp.sum(default(t).x[:4]))(0.3)
    # the primal value is still returned without derivatives, with its status
    res, _ = _solve_eig(W0, D, M, 0.3, max_iters=3, throw=False)
    assert res.status_name == "max_iters"


def test_sequential_solver_refuses_differentiation_by_name():
    M = metric_matrix("diagonal", N, seed=1)
    W = jnp.asarray(_random_sym(N, 2, shift=N ** 0.5 + 1.0))

    def value(th):
        return stiefel.minimize_sequential(lambda x: x @ ((W + th) @ x), M, 2, max_iters=5).value

    with pytest.raises(stiefel.StiefelError, match="cannot run inside jax.grad"):
        jax.grad(value)(0.1)


@pytest.mark.slow
def test_closed_over_parameters_are_differentiated():
    """θ captured by the objective's closure (no args=) gets the same derivative as θ passed as args."""
    W0, D, M = _eig_problem("diagonal")
    S = GeneralizedStiefel(M, K, retraction="cholesky")
    X0 = S.random_point(jax.random.PRNGKey(7))
    B = jnp.asarray(_random_sym(N, 15))
    adjoint = RiemannianImplicitAdjoint(invariant=True)

    def closed(th):
        X = stiefel.minimize(lambda X: jnp.trace(X.T @ (W0 + th * D) @ X), S, X0, method="lbfgs", gtol=1e-11,
                             max_iters=4000, adjoint=adjoint).x
        return jnp.trace(X.T @ B @ X)

    def passed(th):
        X = _solve_eig(W0, D, M, th)[0].x
        return jnp.trace(X.T @ B @ X)

    a, b = float(jax.grad(closed)(0.3)), float(jax.grad(passed)(0.3))
    assert abs(a - b) <= 1e-8 * abs(b)


@pytest.mark.slow
def test_failed_adjoint_cg_raises_with_its_reason_or_gives_nan():
    """A converged solve whose adjoint CG cannot finish (a budget of 2 steps at tol 1e-14): the derivative raises
    lineax's error (throw=True, the default) or is NaN (throw=False) — never the half-solved number."""
    W0, D, M = _eig_problem("diagonal")
    S = GeneralizedStiefel(M, K, retraction="cholesky")
    X0 = S.random_point(jax.random.PRNGKey(7))
    B = jnp.asarray(_random_sym(N, 14))

    def quantity(th, throw):
        fn = lambda X, t: jnp.trace(X.T @ (W0 + t * D) @ X)  # noqa: E731
        adjoint = RiemannianImplicitAdjoint(invariant=True, precondition=False, tol=1e-14, max_steps=2, throw=throw)
        sol = optx.minimise(fn, RiemannianLBFGS(S, 0.0, 1e-11), X0, th, max_steps=4000, adjoint=adjoint)
        return jnp.trace(sol.value.T @ B @ sol.value)

    assert np.isnan(float(jax.grad(lambda t: quantity(t, False))(0.3)))
    with pytest.raises(Exception, match="max_steps|maximum number of"):
        jax.grad(lambda t: quantity(t, True))(0.3)
