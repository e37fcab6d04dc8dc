"""Test helpers around the library's slope tests (stiefel.derivatives.checks): exact identities by jax.jvp on top."""

from __future__ import annotations

import jax
import jax.numpy as jnp

import stiefel


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
    # the library's slope test: the first-order model error decays with slope 2 (a wrong gradient: 1)
    check = stiefel.check_gradient(F, manifold, X, key=key)
    assert check.passed, check.message
