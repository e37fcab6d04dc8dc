"""Retractions onto the generalised Stiefel manifold ``{X : XᵀMX = I}`` (docs/maths.md §1).

Every function takes the metric operator ``M`` (anything with ``.mv``), a point
``X`` of shape ``(n, k)`` and a tangent vector ``Z`` of the same shape, and
returns ``R_X(Z)`` of shape ``(n, k)``. All are jittable and differentiable in
``Z`` (``jax.jvp`` of ``τ ↦ R_X(τZ)`` at 0 is ``Z``).
"""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
import jax.scipy.linalg as jsl
from jaxtyping import Array, Float

__all__ = ["cayley", "cayley_dense", "cholesky", "polar", "radial", "periodic", "RETRACTIONS", "BLOCK_RETRACTIONS"]

Point = Float[Array, "n k"]


def cayley(M, X: Point, Z: Point) -> Point:
    """Cayley retraction in its low-rank Woodbury form (thesis eq. 6.1.17–6.1.19).

    With ``P_X Z = Z − ½ X (XᵀMZ)``, ``U = −½[P_X Z, X]`` (n×2k) and
    ``V = [XᵀM ; −(P_X Z)ᵀM]`` (2k×n): ``R_X(Z) = X − 2U(I + VU)⁻¹VX``.
    Cost O(nk²) plus one product of M with ``[X, Z]``.
    """
    k = X.shape[1]
    MXZ = M.mv(jnp.concatenate([X, Z], axis=1))
    MX, MZ = MXZ[:, :k], MXZ[:, k:]
    XtMZ = X.T @ MZ
    XtMX = X.T @ MX
    PZ = Z - 0.5 * X @ XtMZ
    MPZ = MZ - 0.5 * MX @ XtMZ
    U = -0.5 * jnp.concatenate([PZ, X], axis=1)
    # V U and V X with V = [XᵀM; −(PZ)ᵀM]; only k×k Gram blocks are needed.
    XtMPZ = X.T @ MPZ
    PZtMPZ = PZ.T @ MPZ
    PZtMX = MPZ.T @ X
    VU = -0.5 * jnp.block([[XtMPZ, XtMX], [-PZtMPZ, -PZtMX]])
    VX = jnp.concatenate([XtMX, -PZtMX], axis=0)
    eye = jnp.eye(2 * k, dtype=X.dtype)
    return X - 2.0 * U @ jnp.linalg.solve(eye + VU, VX)


def cayley_dense(M_dense: Float[Array, "n n"], X: Point, Z: Point) -> Point:
    """Dense reference Cayley retraction (thesis Def. 6.1.13–6.1.16), O(n³): for tests only."""
    n = X.shape[0]
    P = jnp.eye(n, dtype=X.dtype) - 0.5 * X @ X.T @ M_dense
    Wz = P @ Z @ X.T - X @ Z.T @ P.T
    eye = jnp.eye(n, dtype=X.dtype)
    return jnp.linalg.solve(eye - 0.5 * Wz @ M_dense, (eye + 0.5 * Wz @ M_dense) @ X)


def cholesky(M, X: Point, Z: Point) -> Point:
    """Cholesky-QR retraction (Prop. 6.1.18): ``Y = X + Z``, ``RᵀR = YᵀMY``, ``R_X(Z) = Y R⁻¹``."""
    Y = X + Z
    G = Y.T @ M.mv(Y)
    L = jnp.linalg.cholesky(0.5 * (G + G.T))
    # Y R⁻¹ = Y L⁻ᵀ: invert the k×k factor (a triangular solve with n right-hand sides is slower on CPU).
    Linv = jsl.solve_triangular(L, jnp.eye(L.shape[0], dtype=L.dtype), lower=True)
    return Y @ Linv.T


def polar(M, X: Point, Z: Point) -> Point:
    """Polar retraction ``R_X(Z) = Y (YᵀMY)^{-1/2}``, ``Y = X + Z`` (the M-closest point of S_M)."""
    Y = X + Z
    return Y @ _inv_sqrt_spd(Y.T @ M.mv(Y))


@jax.custom_jvp
def _inv_sqrt_spd(G: Float[Array, "k k"]) -> Float[Array, "k k"]:
    """``G^{-1/2}`` for SPD ``G`` (eigendecomposition), with a well-conditioned derivative.

    Differentiating through ``eigh`` divides by eigenvalue gaps, which vanish
    near ``G = I`` (every small retraction step). The derivative of the square
    root needs only sums: in the eigenbasis ``(dG^{1/2})_ij = (QᵀdGQ)_ij/(√d_i + √d_j)``,
    and ``d(G^{-1/2}) = −G^{-1/2} dG^{1/2} G^{-1/2}``.
    """
    w, V = jnp.linalg.eigh(0.5 * (G + G.T))
    return (V / jnp.sqrt(w)) @ V.T


@_inv_sqrt_spd.defjvp
def _inv_sqrt_spd_jvp(primals, tangents):
    (G,), (dG,) = primals, tangents
    w, V = jnp.linalg.eigh(0.5 * (G + G.T))
    r = jnp.sqrt(w)
    inv_sqrt = (V / r) @ V.T
    dS = V @ ((V.T @ (0.5 * (dG + dG.T)) @ V) / (r[:, None] + r[None, :])) @ V.T
    return inv_sqrt, -inv_sqrt @ dS @ inv_sqrt


def radial(M, X: Point, Z: Point) -> Point:
    """Radial retraction for k = 1 (Def. 6.4.17): ``(x+z)/√((x+z)ᵀM(x+z))``."""
    Y = X + Z
    return Y / jnp.sqrt(jnp.sum(Y * M.mv(Y)))


def _cos_sqrt(s):
    """``cos(√s)`` for ``s ≥ 0``, smooth (and differentiable) at ``s = 0``."""
    small = s < 1e-4
    safe = jnp.where(small, 1.0, s)
    return jnp.where(small, 1.0 - s / 2.0 + s * s / 24.0, jnp.cos(jnp.sqrt(safe)))


def _sinc_sqrt(s):
    """``sin(√s)/√s`` for ``s ≥ 0``, smooth (and differentiable) at ``s = 0``."""
    small = s < 1e-4
    safe = jnp.where(small, 1.0, s)
    r = jnp.sqrt(safe)
    return jnp.where(small, 1.0 - s / 6.0 + s * s / 120.0, jnp.sin(r) / r)


def periodic(M, X: Point, Z: Point) -> Point:
    """Periodic retraction for k = 1 (Def. 6.4.20), the M-geodesic of the ellipsoid.

    For ``Z = τd`` with ``dᵀMd = 1`` it is ``cos τ · x + sin τ · d``; written in
    terms of ``Z`` alone: ``cos‖Z‖_M · x + (sin‖Z‖_M/‖Z‖_M) · Z``.
    """
    s = jnp.sum(Z * M.mv(Z))
    return _cos_sqrt(s) * X + _sinc_sqrt(s) * Z


RETRACTIONS: dict[str, Callable] = {
    "cayley": cayley,
    "cholesky": cholesky,
    "polar": polar,
    "radial": radial,
    "periodic": periodic,
}
BLOCK_RETRACTIONS = ("cayley", "cholesky", "polar")
