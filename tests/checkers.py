"""Reusable checkers (after Manopt's checkretraction / checkgradient)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np


def check_retraction(manifold, X, Z, *, jvp_tol=1e-10, dist_tol=1e-12, norms=(1e-6, 1e-3, 1.0, 1e3)):
    """R_X(0) = X, d/dτ R_X(τZ)|₀ = Z (by jax.jvp), and R_X(sZ) on the manifold for every norm s."""
    R0 = manifold.retract(X, jnp.zeros_like(Z))
    assert float(jnp.max(jnp.abs(R0 - X))) <= 1e-14, "R_X(0) != X"
    _, velocity = jax.jvp(lambda t: manifold.retract(X, t * Z), (0.0,), (1.0,))
    err = float(jnp.max(jnp.abs(velocity - Z)))
    assert err <= jvp_tol, f"d/dτ R_X(τZ) at 0 differs from Z by {err:.2e}"
    unit = Z / manifold.norm(X, Z)
    for s in norms:
        dist = float(manifold.dist_to_manifold(manifold.retract(X, s * unit)))
        assert dist <= dist_tol, f"R_X(Z) off the manifold by {dist:.2e} at ‖Z‖ = {s:g}"


def check_gradient(F, manifold, X, key, *, tol=1e-10):
    """⟨grad F, Z⟩ = DF(X)[Z] (jax.jvp) for random tangent Z, grad tangent, and the first-order
    Taylor remainder of F along R_X(tZ) decays with slope 2 in log-log."""
    G = jax.grad(F)(X)
    xi = manifold.egrad_to_rgrad(X, G)
    XtMxi = X.T @ manifold.op.mv(xi)
    skew_err = float(jnp.max(jnp.abs(XtMxi + XtMxi.T)))
    # round-off in XᵀMξ scales with its entries (a large gradient, an ill-conditioned M): relative bound
    scale = max(1.0, float(jnp.max(jnp.abs(XtMxi))))
    assert skew_err <= 1e-10 * scale, f"gradient not tangent: |sym(XᵀMξ)| = {skew_err:.2e} (scale {scale:.1e})"
    for sub in jax.random.split(key, 3):
        Z = manifold.random_tangent(sub, X)
        _, dF = jax.jvp(F, (X,), (Z,))
        lhs = float(manifold.inner(X, xi, Z))
        assert abs(lhs - float(dF)) <= tol * max(1.0, abs(float(dF))), f"⟨grad, Z⟩ = {lhs} vs DF[Z] = {float(dF)}"
    # Taylor remainder |F(R(tZ)) − F(X) − t⟨grad, Z⟩| = O(t²): halving t divides it by ~4
    # (a wrong gradient leaves an O(t) remainder: ratio ~2)
    Z = manifold.random_tangent(key, X)
    slope_term = float(manifold.inner(X, xi, Z))
    ts = 1e-2 / 2.0 ** np.arange(5)
    rem = np.array([abs(float(F(manifold.retract(X, t * Z))) - float(F(X)) - t * slope_term) for t in ts])
    if rem.max() < 1e-12:
        return
    ratios = rem[:-1] / np.maximum(rem[1:], 1e-300)
    assert np.any((ratios > 3.5) & (ratios < 4.6)), f"Taylor remainder ratios {ratios}, expected ~4 (order 2)"
