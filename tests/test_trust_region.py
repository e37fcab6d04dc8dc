"""Riemannian trust regions (stiefel.RiemannianTrustRegion, stiefel.truncated_cg): the optimum against
scipy's eigh, local quadratic convergence, the finite-difference Hessian, preconditioning, statuses,
bad input, runtime options, implicit derivatives through a trust-region solve."""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
import scipy.linalg as sla

import stiefel
from stiefel import GeneralizedStiefel, RiemannianImplicitAdjoint, RiemannianTrustRegion, Status, TCGStop

from stiefel_cases import M_KINDS, dense_of, grid_laplacian, metric_matrix

K = 3


def _brockett(kind="diagonal", m=7, shift=0.5):
    """tr(XᵀWXD) with W a grid Laplacian + shift·I (SPD), M of the given kind; optimum from scipy."""
    W = grid_laplacian(m) + shift * np.eye(m * m)
    M = metric_matrix(kind, m * m, seed=1)
    Wop = stiefel.as_operator(W, check=False, factor=False)
    d = jnp.arange(K, 0, -1.0)
    F = lambda X, args: jnp.sum((X * Wop.mv(X)) @ args)  # noqa: E731
    vals = sla.eigh(dense_of(W), dense_of(M), eigvals_only=True)[:K]
    return W, M, F, d, float(vals @ np.arange(K, 0, -1.0))


def _order(gnorms):
    """Estimated order of convergence from the last three gradient norms above round-off."""
    g = np.asarray(gnorms)
    g = g[g > 1e-14]
    a, b, c = np.log(g[-3:])
    return (c - b) / (b - a)


@pytest.mark.parametrize("kind", [k if k != "sparse" else pytest.param(k, marks=pytest.mark.slow) for k in M_KINDS])
def test_optimum_and_quadratic_convergence(kind):
    W, M, F, d, target = _brockett(kind)
    S = GeneralizedStiefel(M, K)
    X0 = S.random_point(jax.random.PRNGKey(2))
    sol = optx.minimise(F, RiemannianTrustRegion(S, 0.0, 1e-11, history=200), X0, d, max_steps=200)
    st = sol.stats
    assert int(st["status"]) == Status.CONVERGED and sol.result == optx.RESULTS.successful
    assert abs(float(st["value"]) - target) <= 1e-11 * abs(target)
    assert float(S.dist_to_manifold(sol.value)) <= 1e-12
    assert float(st["grad_norm"]) <= 1e-11
    hist = np.asarray(st["history"].grad_norm)[: int(st["num_steps"]) + 1]
    accepted = hist[np.r_[True, np.diff(hist) != 0]]
    assert _order(accepted) >= 1.6, accepted  # θ = 1: quadratic (a linear method gives ≈ 1)
    assert int(st["n_hvps"]) == int(st["n_inner"]) > 0
    assert int(st["n_accepted"]) <= int(st["num_steps"])


@pytest.mark.slow
def test_finite_difference_hessian_and_first_order_agree():
    W, M, F, d, target = _brockett()
    S = GeneralizedStiefel(M, K)
    X0 = S.random_point(jax.random.PRNGKey(3))
    exact = optx.minimise(F, RiemannianTrustRegion(S, 0.0, 1e-10), X0, d, max_steps=200).stats
    fd = optx.minimise(F, RiemannianTrustRegion(S, 0.0, 1e-10, hessian="fd"), X0, d, max_steps=200).stats
    assert int(fd["status"]) == Status.CONVERGED
    assert abs(float(fd["value"]) - target) <= 1e-11 * abs(target)
    # the FD Hessian costs one gradient per product; the exact one one gradient per outer iteration
    assert int(fd["n_grads"]) >= int(fd["n_hvps"])
    assert int(exact["n_grads"]) == 2 * int(exact["num_steps"]) + 1


def test_truncated_cg_solves_the_newton_system_inside_the_region():
    """Large radius, tight target: η solves Hess[η] = −g (a dense reference on the tangent space)."""
    W, M, F, d, _ = _brockett(m=4)
    S = GeneralizedStiefel(M, K)
    X = S.random_point(jax.random.PRNGKey(4))
    f = lambda Y: F(Y, d)  # noqa: E731
    g = S.egrad_to_rgrad(X, jax.grad(f)(X))
    hess = stiefel.hessian_operator(f, S, X)
    inner = lambda a, b: S.inner(X, a, b)  # noqa: E731
    # shift by a multiple of the identity so the model is convex (the Brockett Hessian is indefinite here)
    shifted = lambda v: hess(v) + 50.0 * v  # noqa: E731
    out = stiefel.truncated_cg(shifted, None, inner, lambda Z: S.proj(X, Z), g, 1e6, max_inner=500,
                               kappa=1e-13, theta=0.0)
    assert int(out.stop) == TCGStop.CONVERGED and not bool(out.limited)
    assert float(jnp.max(jnp.abs(shifted(out.eta) + g))) <= 1e-10 * float(jnp.max(jnp.abs(g)))
    assert float(jnp.max(jnp.abs(out.Heta - shifted(out.eta)))) <= 1e-9 * float(jnp.max(jnp.abs(g)))
    # a small radius: the step lies on the boundary
    small = stiefel.truncated_cg(shifted, None, inner, lambda Z: S.proj(X, Z), g, 1e-3, max_inner=500,
                                 kappa=1e-13, theta=0.0)
    assert bool(small.limited) and abs(float(S.norm(X, small.eta)) - 1e-3) <= 1e-12
    # negative curvature: the unshifted indefinite model along −g
    neg = stiefel.truncated_cg(lambda v: -v, None, inner, lambda Z: S.proj(X, Z), g, 0.5, max_inner=5,
                               kappa=0.1, theta=1.0)
    assert int(neg.stop) == TCGStop.NEGATIVE_CURVATURE and abs(float(S.norm(X, neg.eta)) - 0.5) <= 1e-12


@pytest.mark.slow
def test_preconditioner_cuts_inner_iterations():
    W, M, F, d, target = _brockett(m=12)
    S = GeneralizedStiefel(M, K)
    X0 = S.random_point(jax.random.PRNGKey(5))
    P = stiefel.shifted_inverse(W, M, 0.5).solve
    plain = optx.minimise(F, RiemannianTrustRegion(S, 0.0, 1e-10), X0, d, max_steps=300).stats
    prec = optx.minimise(F, RiemannianTrustRegion(S, 0.0, 1e-10, preconditioner=P), X0, d, max_steps=300).stats
    assert int(prec["status"]) == Status.CONVERGED
    assert abs(float(prec["value"]) - target) <= 1e-11 * abs(target)
    assert int(prec["n_inner"]) < 0.5 * int(plain["n_inner"]), (int(prec["n_inner"]), int(plain["n_inner"]))


@pytest.mark.slow
def test_statuses():
    W, M, F, d, _ = _brockett()
    S = GeneralizedStiefel(M, K)
    X0 = S.random_point(jax.random.PRNGKey(0))
    sol = optx.minimise(F, RiemannianTrustRegion(S, 0.0, 1e-12), X0, d, max_steps=2, throw=False)
    assert sol.result == optx.RESULTS.nonlinear_max_steps_reached
    budget = optx.minimise(F, RiemannianTrustRegion(S, 0.0, 1e-12, budget=1), X0, d, max_steps=50, throw=False)
    assert int(budget.stats["status"]) == Status.MAX_ITERS and int(budget.stats["num_steps"]) == 1
    # a non-finite start
    nan_start = lambda X, a: jnp.sum(X) * jnp.nan  # noqa: E731
    bad = optx.minimise(nan_start, RiemannianTrustRegion(S), X0, None, max_steps=5, throw=False)
    assert bad.result == optx.RESULTS.nonfinite and int(bad.stats["status"]) == Status.NON_FINITE
    # non-finite trial points are rejected (the radius shrinks), never accepted
    wall = lambda X, a: F(X, a) + jnp.where(jnp.max(jnp.abs(X - X0)) > 0.05, jnp.nan, 0.0)  # noqa: E731
    walled = optx.minimise(wall, RiemannianTrustRegion(S, 0.0, 1e-12), X0, d, max_steps=60, throw=False).stats
    assert np.isfinite(float(walled["value"])) and float(walled["value"]) < float(F(X0, d))
    # an indefinite preconditioner that slips past the probe (traced): the status says so
    minus = lambda Y: -Y  # noqa: E731
    run = jax.jit(lambda s: optx.minimise(F, RiemannianTrustRegion(S, preconditioner=lambda Y: s * Y), X0, d,
                                          max_steps=5, throw=False).stats["status"])
    assert int(run(-1.0)) == Status.INDEFINITE_PRECONDITIONER
    assert Status.name(Status.INDEFINITE_PRECONDITIONER) == "indefinite_preconditioner"
    with pytest.raises(stiefel.ParameterError, match="not positive definite"):
        RiemannianTrustRegion(S, preconditioner=minus)
    # a kink at the start (|·| has derivative 0 at 0 in JAX): every step is rejected, the region collapses
    kink = lambda X, a: F(X, a) + 1e3 * jnp.sum(jnp.abs(X - X0))  # noqa: E731
    tiny = optx.minimise(kink, RiemannianTrustRegion(S, 0.0, 1e-12), X0, d, max_steps=200, throw=False)
    assert tiny.result == optx.RESULTS.nonlinear_divergence
    assert int(tiny.stats["status"]) == Status.TRUST_REGION_COLLAPSED


@pytest.mark.parametrize("kwargs,match", [
    (dict(radius=0.0), "radius .* must be a finite number > 0"),
    (dict(radius=-1.0), "radius"),
    (dict(max_radius=0.0), "max_radius must be a finite number > 0"),
    (dict(radius=2.0, max_radius=1.0), "exceeds max_radius"),
    (dict(rho_prime=0.3), "rho_prime"),
    (dict(kappa=1.0), "kappa"),
    (dict(theta=-1.0), "theta"),
    (dict(max_inner=0), "max_inner"),
    (dict(hessian="bfgs"), "unknown hessian"),
    (dict(atol=float("nan")), "atol"),
])
def test_options_validated(kwargs, match):
    S = GeneralizedStiefel(np.ones(6), 2)
    with pytest.raises(stiefel.StiefelError, match=match):
        RiemannianTrustRegion(S, **kwargs)


@pytest.mark.slow
def test_runtime_options_do_not_recompile_and_vmap():
    W, M, F, d, target = _brockett()
    S = GeneralizedStiefel(M, K)
    traces = []

    @jax.jit
    def run(X0, atol, radius):
        traces.append(1)
        sol = optx.minimise(F, RiemannianTrustRegion(S, 0.0, atol, radius=radius, max_radius=4.0), X0, d,
                            max_steps=100, throw=False)
        return sol.stats["value"], sol.stats["num_steps"]

    X0 = S.random_point(jax.random.PRNGKey(1))
    v1, n1 = run(X0, 1e-1, 1.0)
    v2, n2 = run(X0, 1e-10, 0.1)
    assert len(traces) == 1 and int(n1) < int(n2)
    starts = jax.vmap(S.random_point)(jax.random.split(jax.random.PRNGKey(2), 3))
    values, _ = jax.vmap(run, in_axes=(0, None, None))(starts, 1e-10, 0.5)
    assert np.allclose(np.asarray(values), target, rtol=1e-10)


@pytest.mark.slow
def test_implicit_derivative_through_trust_region_solve():
    """d/dθ of a non-invariant quantity of the solution of tr(XᵀW(θ)XD) against re-solved central FDs."""
    W, M, F, d, _ = _brockett()
    S = GeneralizedStiefel(M, K)
    Wd = jnp.asarray(dense_of(W))
    B = jnp.asarray(np.random.default_rng(3).standard_normal((49, 49)))
    Bs = (B + B.T) / 2
    c = jnp.asarray(np.random.default_rng(4).standard_normal((49, K)))
    fn = lambda X, th: jnp.sum((X * ((Wd + th * Bs * 0.01) @ X)) @ d)  # noqa: E731
    X_start = optx.minimise(fn, RiemannianTrustRegion(S, 0.0, 1e-12), S.random_point(jax.random.PRNGKey(6)), 0.3,
                            max_steps=200).value

    def loss(th):
        sol = optx.minimise(fn, RiemannianTrustRegion(S, 0.0, 1e-12), X_start, th, max_steps=200,
                            adjoint=RiemannianImplicitAdjoint())
        return jnp.sum(c * sol.value)

    g = float(jax.grad(loss)(0.3))
    h = 1e-4
    fd = (float(loss(0.3 + h)) - float(loss(0.3 - h))) / (2 * h)
    assert abs(g - fd) <= 1e-6 * max(abs(fd), 1.0), (g, fd)
