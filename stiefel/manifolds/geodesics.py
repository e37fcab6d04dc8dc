"""Geodesics of ``S_M = {XᵀMX = I}``: the exponential map, the logarithm and the distance, for both metrics
(docs/maths.md §9, eqs. (9.4), (9.11), (9.12)).

With ``M = LLᵀ``, ``X ↦ LᵀX`` is an isometry of ``S_M`` onto the ordinary Stiefel manifold ``St(n, k)``, so
``Exp_X(ξ) = L⁻ᵀ Exp_{LᵀX}(Lᵀξ)``. Written out, every ``L`` cancels: the closed forms below need only
products with ``M`` (no factor of M, no triangular solve), O(nk²) work plus one ``M``-product per call.

* Euclidean (M-weighted) metric (Edelman, Arias, Smith 1998, eq. 2.7, conjugated): with
  ``A = XᵀMξ`` (skew) and ``S = ξᵀMξ``,
  ``Exp_X(ξ) = [X, ξ] · expm([[A, −S], [I, A]]) [I; 0] · expm(−A)``.
* Canonical metric (ibid. eq. 2.45, conjugated): ``A = XᵀMξ``, ``ξ⊥ = ξ − XA = QR`` with ``QᵀMQ = I``,
  ``Exp_X(ξ) = [X, Q] · expm([[A, −Rᵀ], [R, 0]]) [I; 0]``. Every power of that block matrix applied to
  ``[I; 0]`` has a lower block ``R·(·)`` and upper blocks in ``A`` and ``RᵀR = ξ⊥ᵀMξ⊥ =: S⊥`` only, so
  without any factorisation (differentiable, rank-deficient ``ξ⊥`` allowed):
  ``Exp_X(ξ) = [X, ξ⊥] · expm([[A, −S⊥], [I, 0]]) [I; 0]``.
* Logarithm: ``Log_X(Y)`` is sought in ``span(X, Y)`` (the reduction to ``St(2k, k)`` Zimmermann and Hüper
  use; that sub-manifold is totally geodesic): with ``B0 = XᵀMY``, ``Y⊥ = Y − X B0`` and
  ``R = (Y⊥ᵀMY⊥)^{1/2}``, the tangent ``[Ω; D]`` at ``[I; 0] ∈ St(2k, k)`` with
  ``Exp_{[I;0]}([Ω; D]) = [B0; R]`` is found by damped Gauss–Newton shooting (``(3k² − k)/2`` unknowns),
  and ``Log_X(Y) = XΩ + Y⊥R⁺D``. The result is checked in the full space (``‖Exp_X(ξ) − Y‖_M``) and must
  be shorter than the injectivity radius — ``π`` for the Euclidean metric (Zimmermann & Stoye 2024), at
  least ``√(4/5)·π`` for the canonical one (Rentmeesters 2013) — so it is *the* minimising geodesic;
  otherwise ``OutOfDomainError`` (eagerly) or NaN (under ``jit``/``vmap``).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..runtime.compilation import is_traced
from ..errors import OutOfDomainError

__all__ = ["exp", "log", "dist", "INJECTIVITY_RADIUS"]

#: a radius within which every geodesic is the unique shortest path (per metric, on every S_M)
INJECTIVITY_RADIUS = {"euclidean": float(np.pi), "canonical": float(np.sqrt(0.8) * np.pi)}
LOG_ITERS = 60


def _sym(B):
    return 0.5 * (B + B.T)


def _skew(B):
    return 0.5 * (B - B.T)


_PADE13 = (64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0, 129060195264000.0,
           10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0, 40840800.0, 960960.0, 16380.0, 182.0, 1.0)
_THETA13 = 5.371920351148152  # ‖B‖₁ up to which Padé 13 is accurate to double precision (Higham 2005)
_MAX_SQUARINGS = 30


def expm(B: Float[Array, "m m"]) -> Float[Array, "m m"]:
    """Matrix exponential by scaling and squaring with the [13/13] Padé approximant (Higham 2005): one
    branch-free program (a fixed-length, masked squaring loop), so it compiles quickly and differentiates
    in both modes; ``jax.scipy.linalg.expm`` builds every Padé order and took ~1 s to compile here."""
    b = _PADE13
    norm1 = jnp.max(jnp.sum(jnp.abs(B), axis=0))
    s = jnp.clip(jnp.ceil(jnp.log2(jnp.maximum(norm1, 1e-300) / _THETA13)), 0, _MAX_SQUARINGS)
    s = jax.lax.stop_gradient(s)
    A = B / 2.0 ** s
    I = jnp.eye(B.shape[0], dtype=B.dtype)
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A4 @ A2
    U = A @ (A6 @ (b[13] * A6 + b[11] * A4 + b[9] * A2) + b[7] * A6 + b[5] * A4 + b[3] * A2 + b[1] * I)
    V = A6 @ (b[12] * A6 + b[10] * A4 + b[8] * A2) + b[6] * A6 + b[4] * A4 + b[2] * A2 + b[0] * I
    R = jnp.linalg.solve(V - U, V + U)
    return jax.lax.fori_loop(0, _MAX_SQUARINGS, lambda i, R: jnp.where(i < s, R @ R, R), R)


def _psd_sqrt_and_pinv(G):
    """``(G^{1/2}, G^{+1/2})`` of a symmetric PSD ``(k, k)`` matrix (eigenvalues ≤ k·ε·max clipped to 0)."""
    w, V = jnp.linalg.eigh(_sym(G))
    tol = G.shape[0] * jnp.finfo(G.dtype).eps * jnp.maximum(jnp.max(jnp.abs(w)), 1.0)
    keep = w > tol
    root = jnp.sqrt(jnp.where(keep, w, 0.0))
    inv = jnp.where(keep, 1.0 / jnp.where(keep, root, 1.0), 0.0)
    return (V * root) @ V.T, (V * inv) @ V.T


def _exp_frame(metric: str, mv, X, xi):
    """``(frame (n, 2k), coefficients (2k, k))`` with ``Exp_X(ξ) = frame @ coefficients``."""
    k = X.shape[1]
    I = jnp.eye(k, dtype=X.dtype)
    Mxi = mv(xi)
    A = _skew(X.T @ Mxi)
    if metric == "euclidean":
        S = _sym(xi.T @ Mxi)
        E = expm(jnp.block([[A, -S], [I, A]]))[:, :k] @ expm(-A)
        return jnp.concatenate([X, xi], axis=1), E
    perp = xi - X @ A
    S = _sym(perp.T @ mv(perp))
    E = expm(jnp.block([[A, -S], [I, jnp.zeros_like(A)]]))[:, :k]
    return jnp.concatenate([X, perp], axis=1), E


def _exp(metric: str, mv, X, xi):
    frame, E = _exp_frame(metric, mv, X, xi)
    return frame @ E


@eqx.filter_jit
def exp(manifold, X: Float[Array, "n k"], xi: Float[Array, "n k"]) -> Float[Array, "n k"]:
    """``Exp_X(ξ)`` of the manifold's metric (module docstring)."""
    return _exp(manifold.metric, manifold.op.mv, X, xi)


def _unpack(p, k):
    il = jnp.tril_indices(k, -1)
    m = k * (k - 1) // 2
    L = jnp.zeros((k, k), p.dtype).at[il].set(p[:m])
    return L - L.T, p[m:].reshape(k, k)


def _pack(Omega, D):
    il = jnp.tril_indices(Omega.shape[0], -1)
    return jnp.concatenate([Omega[il], D.ravel()])


def _log_small(metric: str, B0, R):
    """``[Ω; D]`` at ``[I; 0] ∈ St(2k, k)`` with ``Exp([Ω; D]) = [B0; R]`` (damped Gauss–Newton)."""
    k = B0.shape[0]
    y0 = jnp.concatenate([jnp.eye(k, dtype=B0.dtype), jnp.zeros_like(B0)])
    target = jnp.concatenate([B0, R])
    ident = lambda Y: Y  # noqa: E731

    def resid(p):
        Omega, D = _unpack(p, k)
        return (_exp(metric, ident, y0, jnp.concatenate([Omega, D])) - target).ravel()

    def body(c):
        p, r, it = c
        J = jax.jacfwd(resid)(p)
        step = jnp.linalg.lstsq(J, -r)[0]
        nr = jnp.linalg.norm(r)

        def shrink(s):
            t, _, _ = s
            return 0.5 * t, resid(p + 0.5 * t * step), None

        def worse(s):
            t, rt, _ = s
            return (jnp.linalg.norm(rt) >= nr) & (t > 1e-4)

        t, r_new, _ = jax.lax.while_loop(worse, shrink, (jnp.ones((), p.dtype), resid(p + step), None))
        better = jnp.linalg.norm(r_new) < nr
        return jnp.where(better, p + t * step, p), jnp.where(better, r_new, r), jnp.where(better, it + 1, LOG_ITERS)

    tol = 1e-13 * jnp.sqrt(jnp.asarray(2 * k * k, B0.dtype))
    p0 = _pack(_skew(B0), R)
    p, r, _ = jax.lax.while_loop(lambda c: (jnp.linalg.norm(c[1]) > tol) & (c[2] < LOG_ITERS), body,
                                 (p0, resid(p0), jnp.zeros((), jnp.int32)))
    return _unpack(p, k)


@eqx.filter_jit
def _log_core(manifold, X, Y):
    """``(ξ, ‖Exp_X(ξ) − Y‖_M, ‖ξ‖)`` for the shooting's answer ξ (compiled once per shape and metric)."""
    metric, mv = manifold.metric, manifold.op.mv
    B0 = X.T @ mv(Y)
    perp = Y - X @ B0
    R, Rinv = _psd_sqrt_and_pinv(perp.T @ mv(perp))
    Omega, D = _log_small(metric, B0, R)
    xi = X @ Omega + perp @ (Rinv @ D)
    miss = _exp(metric, mv, X, xi) - Y
    return xi, jnp.sqrt(jnp.maximum(jnp.sum(miss * mv(miss)), 0.0)), manifold.norm(X, xi)


def log(manifold, X: Float[Array, "n k"], Y: Float[Array, "n k"], *, tol: float = 1e-9) -> Float[Array, "n k"]:
    """``Log_X(Y)`` on ``manifold`` (module docstring): ``OutOfDomainError`` when it fails, NaN under a trace."""
    metric = manifold.metric
    xi, err, length = _log_core(manifold, X, Y)
    ok = (err <= tol * jnp.sqrt(X.shape[1])) & (length < INJECTIVITY_RADIUS[metric])
    if not is_traced(X, Y, manifold):
        if not bool(ok):
            raise OutOfDomainError(
                f"log(X, Y) is not defined here: the shooting found a geodesic of length {float(length):.6g} that "
                f"misses Y by {float(err):.2e} (M-norm); the logarithm is returned only for a geodesic shorter than "
                f"the injectivity radius {INJECTIVITY_RADIUS[metric]:.6g} ({metric} metric) that reaches Y "
                "(e.g. Y = −X on the ellipsoid k = 1 has no unique logarithm)")
        return xi
    return jnp.where(ok, xi, jnp.nan)


def dist(manifold, X, Y) -> Float[Array, ""]:
    """Geodesic distance ``‖Log_X(Y)‖`` (same domain as ``log``)."""
    return manifold.norm(X, log(manifold, X, Y))
