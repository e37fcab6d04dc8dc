"""One objective signature: stiefel.minimize takes optx.minimise's fn(X, args) as well as F(X)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import stiefel
from stiefel.solvers.objective_form import takes_args

jax.config.update("jax_enable_x64", True)

A = jnp.diag(jnp.arange(1.0, 9.0))
S = stiefel.GeneralizedStiefel(jnp.linspace(1.0, 2.0, 8), 2)
X0 = S.random_point(jax.random.PRNGKey(0))


@pytest.mark.slow
def test_an_optimistix_objective_runs_unchanged_in_minimize():
    fn = lambda X, args: jnp.trace(X.T @ A @ X)  # noqa: E731 — written for optx.minimise
    res = stiefel.minimize(fn, S, X0, method="lbfgs", gtol=1e-9)
    sol = optx.minimise(fn, stiefel.RiemannianLBFGS(S, rtol=0.0, atol=1e-9), X0, None, max_steps=1000)
    assert res.status_name == "converged"
    np.testing.assert_allclose(float(res.value), float(fn(sol.value, None)), rtol=1e-12)
    ref = stiefel.minimize(lambda X: jnp.trace(X.T @ A @ X), S, X0, method="lbfgs", gtol=1e-9)
    np.testing.assert_allclose(np.asarray(res.x), np.asarray(ref.x), atol=1e-12)  # same function, same solve


@pytest.mark.parametrize("F, args, expected", [
    (lambda X: 0.0, None, False), (lambda X, args: 0.0, None, True), (lambda X, args: 0.0, 1.0, True),
    (lambda X, args=None: 0.0, None, False), (lambda X, args=None: 0.0, 2.0, True), (lambda *a: 0.0, 3.0, True),
    (functools.partial(lambda X, t: 0.0, t=1.0), None, False), (functools.partial(lambda t, X, args: 0.0, 1.0), None, True),
])
def test_the_call_form_follows_the_signature(F, args, expected):
    assert takes_args(F, args) is expected


@pytest.mark.parametrize("F, args, match", [
    (lambda X: 0.0, 1.0, "args= was given but the objective"),
    (lambda: 0.0, None, "does not fit F"),
    (lambda X, a, b: 0.0, None, "does not fit F"),
    (lambda X, *, scale: 0.0, None, "does not fit F"),
    (3.0, None, "must be callable"),
])
def test_a_signature_that_fits_neither_is_a_one_line_named_error(F, args, match):
    with pytest.raises(stiefel.ObjectiveSignatureError, match=match) as info:
        stiefel.minimize(F, S, X0, args=args)
    assert "\n" not in str(info.value)
