"""Strong Armijo–Wolfe line search: reported conditions hold; bad directions give a status, not NaN."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from stiefel import GeneralizedStiefel, LineSearchStatus, along_curve, strong_wolfe

from stiefel_cases import metric_matrix

C1, C2 = 1e-4, 0.9

SCALAR_CASES = {
    "quadratic": lambda t: (t - 3.0) ** 2,
    "steep_quadratic": lambda t: 1e6 * (t - 1e-5) ** 2,
    "wiggly": lambda t: 0.01 * jnp.cos(50 * t) - t + t**4,
    "nan_beyond_half": lambda t: jnp.where(t > 0.5, jnp.nan, (t - 1.0) ** 2),
    "sine": lambda t: -jnp.sin(t),
}


def run(h, init, **kw):
    phi = lambda t: jax.value_and_grad(h)(t)  # noqa: E731
    f0, g0 = phi(0.0)
    return f0, g0, jax.jit(lambda: strong_wolfe(phi, f0, g0, init, **kw))()


@pytest.mark.parametrize("name", list(SCALAR_CASES))
@pytest.mark.parametrize("init", [1e-8, 1.0, 100.0])
def test_accepted_step_satisfies_reported_conditions(name, init):
    h = SCALAR_CASES[name]
    f0, g0, r = run(h, init, max_step=np.pi / 2 if name == "sine" else np.inf)
    assert bool(r.accepted) and float(r.step) > 0
    fs, gs = jax.value_and_grad(h)(r.step)
    np.testing.assert_allclose([r.value, r.slope], [fs, gs], rtol=1e-12)
    armijo = float(fs) <= float(f0) + C1 * float(r.step) * float(g0)
    curvature = abs(float(gs)) <= C2 * abs(float(g0))
    assert bool(r.armijo) == armijo and bool(r.curvature) == curvature
    if int(r.status) == LineSearchStatus.WOLFE:
        assert armijo and curvature
    assert armijo  # every case here admits a strong Wolfe point


def test_max_step_is_respected_and_reported():
    """Decreasing up to max_step: Armijo holds there, curvature does not → status ARMIJO."""
    f0, g0, r = run(lambda t: -t, 1.0, max_step=2.0)
    assert float(r.step) == 2.0 and int(r.status) == LineSearchStatus.ARMIJO
    assert bool(r.armijo) and not bool(r.curvature)


@pytest.mark.parametrize("h", [lambda t: t, lambda t: t**2, lambda t: jnp.nan * t])
def test_non_descent_direction_gives_status_not_nan(h):
    f0, g0, r = run(h, 1.0)
    assert int(r.status) == LineSearchStatus.NOT_DESCENT
    assert float(r.step) == 0.0 and np.isfinite(float(r.step))


def test_no_decrease_anywhere_fails_cleanly():
    """h'(0) < 0 claimed but h increases for every τ > 0 (an inconsistent slope): FAILED, step 0."""
    phi = lambda t: (jnp.abs(t) + 1.001, jnp.ones_like(t))  # noqa: E731
    r = strong_wolfe(phi, jnp.asarray(1.0), jnp.asarray(-1.0), 1.0, max_evals=10, max_backtrack=10)
    assert int(r.status) == LineSearchStatus.FAILED
    assert float(r.step) == 0.0 and float(r.value) == 1.0
    assert int(r.n_evals) <= 20


def test_backtracking_fallback_finds_armijo_step():
    """A function with a tiny basin far below the first trial: zoom budget 2, then backtracking."""
    h = lambda t: jnp.where(t < 1e-6, -t, 1.0 + t)  # noqa: E731
    phi = lambda t: (h(t), jnp.where(t < 1e-6, -1.0, 1.0))  # noqa: E731
    r = strong_wolfe(phi, jnp.asarray(0.0), jnp.asarray(-1.0), 1.0, max_evals=2, max_backtrack=20)
    assert int(r.status) == LineSearchStatus.ARMIJO and bool(r.armijo)
    assert 0 < float(r.step) < 1e-6


@pytest.mark.slow
def test_along_a_retraction_curve():
    """h(τ) = F(R_X(τd)) with h' by jvp: the accepted step satisfies strong Wolfe on the manifold."""
    S = GeneralizedStiefel(metric_matrix("diagonal", 10), 3, retraction="cayley")
    X = S.random_point(jax.random.PRNGKey(0))
    A = jnp.diag(jnp.arange(1.0, 11.0))
    F = lambda Y: jnp.sum(Y * (A @ Y))  # noqa: E731
    d = -S.egrad_to_rgrad(X, jax.grad(F)(X))
    phi = along_curve(F, lambda t: S.retract(X, t * d))
    f0, g0 = phi(jnp.asarray(0.0))
    np.testing.assert_allclose(g0, jnp.sum(jax.grad(F)(X) * d), rtol=1e-12)
    r = strong_wolfe(phi, f0, g0, 1.0)
    assert int(r.status) == LineSearchStatus.WOLFE
    Y = S.retract(X, r.step * d)
    assert float(F(Y)) < float(f0)
