"""The library's slope tests (stiefel.check_gradient / check_hessian / check_retraction) on every objective
and retraction the project ships, and their failures: a wrong gradient or Hessian, a non-differentiable or
non-finite objective, a retraction's order."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import objectives
import stiefel
from stiefel import GeneralizedStiefel

from stiefel_cases import grid_laplacian, metric_matrix

K = 3


@pytest.fixture(scope="module")
def cmm():
    """A 6×6 grid Laplacian with random lumped areas; the energy selects its smoothing at run time, so
    every smoothing shares one compiled check. ε = δ = 0.3 keeps the smoothings' curvature on the scale of
    the entries (with ε ≪ |X_ij| an entry crossing zero along the curve bends the error curve)."""
    W = grid_laplacian(6)
    a = np.random.default_rng(0).uniform(0.5, 1.5, 36) / 36
    S = GeneralizedStiefel(a, K)
    X = S.random_point(jax.random.PRNGKey(0))
    return W, a, S, X


@pytest.mark.slow
@pytest.mark.parametrize("weighting", ["area", "uniform"])
def test_every_cmm_energy_passes_gradient_and_hessian_checks(cmm, weighting):
    W, a, S, X = cmm
    E = objectives.cmm_energy(W, a, mu=2.0, eps=0.3, delta=0.3, runtime_smoothing=True, weighting=weighting)
    for name in objectives.energy.smoothings.NAMES:
        F = E.with_params(smoothing=name)
        g = stiefel.check_gradient(F, S, X)
        h = stiefel.check_hessian(F, S, X)
        assert g.passed and abs(g.slope - 2) <= 0.15, (name, g.message)
        assert h.passed and abs(h.slope - 3) <= 0.15, (name, h.message)
        assert g.details["tangent_error"] <= 1e-12
        assert h.details["symmetry_error"] <= 1e-12 and h.details["linearity_error"] <= 1e-12


def test_dirichlet_and_brockett_with_args(cmm):
    W, a, S, X = cmm
    Wop = stiefel.as_operator(W, check=False, factor=False)
    brockett = lambda Y, d: jnp.sum((Y * Wop.mv(Y)) @ d)  # noqa: E731
    d = jnp.arange(K, 0, -1.0)
    assert stiefel.check_gradient(brockett, S, X, args=d).passed
    assert stiefel.check_hessian(brockett, S, X, args=d).passed
    # along the polar retraction (second order) the Hessian model is good too; Cholesky-QR is first order
    polar = GeneralizedStiefel(a, K, retraction="polar")
    assert stiefel.check_hessian(brockett, polar, X, args=d, curve="retraction").passed


@pytest.mark.slow
def test_wrong_derivatives_fail(cmm):
    W, a, S, X = cmm
    Wop = stiefel.as_operator(W, check=False, factor=False)
    F = lambda Y: jnp.sum(Y * Wop.mv(Y)) + jnp.sum(jnp.cos(Y))  # noqa: E731
    wrong_grad = stiefel.check_gradient(F, S, X, egrad=lambda Y: 2.0 * Wop.mv(Y))  # the cos term missing
    assert not wrong_grad.passed and abs(wrong_grad.slope - 1.0) <= 0.15, wrong_grad.message
    assert "FAILED" in str(wrong_grad)
    right = stiefel.check_gradient(F, S, X, egrad=lambda Y: 2.0 * Wop.mv(Y) - jnp.sin(Y))
    assert right.passed
    wrong_hess = stiefel.check_hessian(F, S, X, hess=lambda Y, V: S.proj(Y, 2.0 * V))
    assert not wrong_hess.passed and abs(wrong_hess.slope - 2.0) <= 0.15, wrong_hess.message

    # a smoothing whose first derivative is right and second is not (stop_gradient in a custom JVP)
    @jax.custom_jvp
    def s(x):
        return jnp.sqrt(x * x + 0.09)

    @s.defjvp
    def s_jvp(primals, tangents):
        (x,), (dx,) = primals, tangents
        return s(x), x / jax.lax.stop_gradient(jnp.sqrt(x * x + 0.09)) * dx

    G = lambda Y: jnp.sum(Y * Wop.mv(Y)) + 5.0 * jnp.sum(s(Y))  # noqa: E731
    assert stiefel.check_gradient(G, S, X).passed
    bad = stiefel.check_hessian(G, S, X)
    assert not bad.passed and bad.slope < 2.5, bad.message


def test_nondifferentiable_and_nonfinite_objectives_are_reported(cmm):
    _, a, S, _ = cmm
    corner = jnp.zeros((36, K)).at[jnp.arange(K), jnp.arange(K)].set(1.0 / jnp.sqrt(jnp.asarray(a[:K])))
    kink = stiefel.check_gradient(lambda Y: jnp.sum(jnp.abs(Y)), S, corner)  # |x| at exact zeros
    assert not kink.passed and abs(kink.slope - 1.0) <= 0.15, kink.message
    X = S.random_point(jax.random.PRNGKey(3))
    nan = stiefel.check_gradient(lambda Y: jnp.sum(jnp.sqrt(Y)), S, X)  # negative entries: NaN
    assert not nan.passed and "non-finite" in nan.message
    linear = stiefel.check_gradient(lambda Y: 0.0 * jnp.sum(Y), S, X)  # zero model error: exact
    assert linear.passed and linear.exact


@pytest.mark.parametrize("kind", ["diagonal", pytest.param("dense", marks=pytest.mark.slow),
                                  pytest.param("sparse", marks=pytest.mark.slow)])
@pytest.mark.slow
def test_every_retraction(kind):
    """Cayley and Cholesky-QR are first order (slope 2), polar and radial (M-projections) second order
    (slope 3), periodic is the geodesic itself (exact)."""
    orders = {"cayley": 1, "cholesky": 1, "polar": 2, "radial": 2, "periodic": None}
    M = metric_matrix(kind, 16, seed=2)
    for name, order in orders.items():
        k = 1 if name in ("radial", "periodic") else K
        S = GeneralizedStiefel(M, k, retraction=name)
        X = S.random_point(jax.random.PRNGKey(4))
        check = stiefel.check_retraction(S, X)
        assert check.passed, (name, check.message)
        if order is None:
            assert check.exact, check.message
        else:
            assert abs(check.details["order"] - order) <= 0.15, (name, check.message)


def test_plot_writes_a_png(tmp_path, cmm):
    _, _, S, X = cmm
    check = stiefel.check_retraction(S, X)
    path = tmp_path / "retraction.png"
    ax = check.plot(path=path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert ax.get_xscale() == "log" and [p.name for p in tmp_path.iterdir()] == ["retraction.png"]


def test_fit_slope_on_synthetic_curves():
    t = np.logspace(-8, 0, 51)
    slope, window, exact = stiefel.derivatives.checks.fit_slope(t, 3.0 * t ** 2 + 1e-15, 1e-13)
    assert abs(slope - 2.0) <= 0.02 and not exact and window is not None
    assert stiefel.derivatives.checks.fit_slope(t, np.full_like(t, 1e-16), 1e-13)[2]  # all at round-off
    assert np.isnan(stiefel.derivatives.checks.fit_slope(t, np.full_like(t, np.nan), 1e-13)[0])


def test_optimistix_style_objectives_without_args(cmm):
    """``fn(X, args)`` as optimistix takes it, checked with no args: called with args = None."""
    _, _, S, X = cmm
    fn = lambda Y, args: jnp.sum(jnp.cos(Y))  # noqa: E731
    assert stiefel.check_gradient(fn, S, X).passed and stiefel.check_hessian(fn, S, X).passed
    assert stiefel.riemannian_hessian(fn, S, X, S.random_tangent(jax.random.PRNGKey(1), X)).shape == X.shape
