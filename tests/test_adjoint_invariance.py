"""Invariant objectives need no opt-in: the default adjoint detects F(XQ) = F(X) at the solution (the Hessian
vanishes on vertical directions XΩ) and differentiates invariant quantities right — it was NaN."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import stiefel
from stiefel.derivatives.implicit import INVARIANCE_RATIO, riemannian_residual, vertical_ratio

jax.config.update("jax_enable_x64", True)

n, k = 30, 3
M = jnp.linspace(1.0, 2.0, n)
S = stiefel.GeneralizedStiefel(M, k)
rng = np.random.default_rng(0)
Wr = rng.standard_normal((n, n))
W = jnp.asarray(Wr @ Wr.T / n + np.diag(np.arange(n, dtype=float)))
D = jnp.asarray(np.diag(rng.standard_normal(n)))
B = jnp.asarray(np.diag(np.linspace(0.0, 1.0, n)))
X0 = S.random_point(jax.random.PRNGKey(1))
invariant_F = lambda X, t: jnp.trace(X.T @ (W + t * D) @ X)  # noqa: E731 — F(XQ) = F(X)
brockett_F = lambda X, t: jnp.trace(X.T @ (W + t * D) @ X @ jnp.diag(jnp.array([3.0, 2.0, 1.0])))  # noqa: E731


def _loss(F, t, **kw):
    X = stiefel.minimize(F, S, X0, args=t, method="lbfgs", gtol=1e-10, max_iters=3000, **kw).x
    return jnp.trace(X.T @ B @ X)


@pytest.mark.slow
def test_invariant_objective_derivative_by_default_matches_resolved_finite_differences():
    """stiefel.minimize's defaults (CG, the default adjoint) at gtol 1e-8: NaN before the detection (measured; the
    tangent-space CG fails on the singular Hessian), now the re-solved finite difference to 1e-6."""
    t, h = 0.3, 1e-5

    def default_loss(s):
        X = stiefel.minimize(invariant_F, S, X0, args=s, gtol=1e-8, max_iters=3000).x
        return jnp.trace(X.T @ B @ X)

    g = float(jax.grad(default_loss)(t))
    fd = (float(_loss(invariant_F, t + h)) - float(_loss(invariant_F, t - h))) / (2 * h)
    assert np.isfinite(g) and abs(g - fd) <= 1e-6 * max(1.0, abs(fd))


@pytest.mark.slow
def test_the_vertical_ratio_tells_invariant_from_isolated_minimisers():
    for F, invariant in ((invariant_F, True), (brockett_F, False)):
        X = stiefel.minimize(F, S, X0, args=0.3, method="lbfgs", gtol=1e-10, max_iters=3000).x
        _, jac = jax.linearize(lambda Y: riemannian_residual(lambda Z, a: (F(Z, a), None), S, Y, 0.3), X)
        ratio = float(vertical_ratio(jac, S, X))
        assert (ratio <= INVARIANCE_RATIO) is invariant, ratio
