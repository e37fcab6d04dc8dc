"""The generalised Grassmann manifold and the named special cases of ``S_M`` (docs/maths.md §1, §9).

``Grassmann(M, k)`` is the quotient ``S_M / O(k)``: the k-dimensional subspaces of R^n, each represented by
any M-orthonormal basis ``X`` (``XᵀMX = I``). It is for objectives with ``F(XQ) = F(X)`` for orthogonal
``Q`` (traces ``tr(XᵀAX)``, projectors ``XXᵀM``, the rotation-invariant objectives of docs/maths.md §9).
Tangent vectors are *horizontal*: ``XᵀMξ = 0``, with the projection ``Π_X(Z) = Z − XXᵀMZ`` (9.7); on
them the Euclidean and canonical metrics agree (``tr(ξᵀMη)``). For an invariant F, ``XᵀG`` is symmetric,
so

    ``grad F = M⁻¹G − XXᵀG``,   ``Hess F(X)[ξ] = Π_X(M⁻¹H[ξ] − ξXᵀG)``,

and the Hessian is invertible at a non-degenerate minimiser (the vertical null space of ``S_M`` is gone),
so the trust-region method converges quadratically. Geodesics in closed form, with ``ξ = UΣVᵀ`` an
M-thin SVD (``UᵀMU = I``) and ``sinc``-type products so that no U is formed:

    ``Exp_X(ξ) = XV cos Σ Vᵀ + ξV (sin Σ / Σ) Vᵀ``,
    ``Log_X(Y) = ZV (atan Σ / Σ) Vᵀ`` with ``Z = (Y − XB)B⁻¹``, ``B = XᵀMY``, ``ZᵀMZ = VΣ²Vᵀ``,
    ``dist(X, Y) = ‖θ‖``, ``cos θ_i`` the singular values of ``XᵀMY`` (principal angles).

``Log`` needs ``B`` invertible (every principal angle below π/2, the injectivity radius);
``OutOfDomainError`` otherwise (NaN when traced). Every solver of the toolkit runs on a ``Grassmann``.

``sphere(n, M=None)`` (k = 1: the ellipsoid ``xᵀMx = 1``, points ``(n, 1)``) and ``stiefel(n, k)`` (M = I)
name the special cases of ``GeneralizedStiefel`` that pymanopt users look for.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..runtime.compilation import is_traced
from ..errors import OutOfDomainError
from .geodesics import expm
from .manifold import GeneralizedStiefel
from .names import transport_args

__all__ = ["Grassmann", "sphere", "stiefel"]

Point = Float[Array, "n k"]


def _sym_eig(G):
    w, V = jnp.linalg.eigh(0.5 * (G + G.T))
    return jnp.sqrt(jnp.maximum(w, 0.0)), V


def _atan_ratio(s):
    """``atan(s)/s`` with its limit 1 at ``s = 0``."""
    safe = jnp.where(s > 1e-8, s, 1.0)
    return jnp.where(s > 1e-8, jnp.arctan(safe) / safe, 1.0 - s * s / 3.0)


class Grassmann(GeneralizedStiefel):
    """``{span(X) : XᵀMX = I_k}`` (module docstring); the arguments of ``GeneralizedStiefel`` except
    ``metric`` (horizontal vectors: the metrics agree). ``dim = k(n − k)``."""

    def __init__(self, M, k: int, *, retraction: str = "polar", check: bool = True, dtype=None,
                 n: int | None = None):
        super().__init__(M, k, metric="euclidean", retraction=retraction, check=check, dtype=dtype, n=n)

    @property
    def dim(self) -> int:
        return self.k * (self.n - self.k)

    def proj(self, X: Point, Y: Point) -> Point:
        """Horizontal projection ``Π_X(Y) = Y − XXᵀMY``."""
        return Y - X @ (X.T @ self.op.mv(Y))

    def egrad_to_rgrad(self, X: Point, G: Point) -> Point:
        """``M⁻¹G − XXᵀG`` (for an invariant F, ``XᵀG`` is symmetric)."""
        return self.op.solve(G) - X @ (X.T @ G)

    def ehess_to_rhess(self, X: Point, G: Point, H: Point, xi: Point) -> Point:
        """``Π_X(M⁻¹H − ξXᵀG)``."""
        return self.proj(X, self.op.solve(H) - xi @ (X.T @ G))

    def transport(self, X_new: Point, Z: Point, *pymanopt) -> Point:
        X_new, Z = transport_args(X_new, Z, pymanopt)
        return self.proj(X_new, Z)

    def transport_pair(self, X_new: Point, Z1: Point, Z2: Point) -> tuple[Point, Point]:
        return self.proj(X_new, Z1), self.proj(X_new, Z2)

    def exp(self, X: Point, Z: Point) -> Point:
        """``Exp_X(ξ) = XV cos Σ Vᵀ + ξV (sin Σ/Σ) Vᵀ`` for horizontal ξ: both matrix functions of
        ``S = ξᵀMξ = VΣ²Vᵀ`` are blocks of ``expm([[0, −S], [I, 0]])`` (no eigendecomposition, so the map is
        differentiable at ξ = 0 and at repeated singular values)."""
        k = X.shape[1]
        S = Z.T @ self.op.mv(Z)
        S = 0.5 * (S + S.T)
        E = expm(jnp.block([[jnp.zeros_like(S), -S], [jnp.eye(k, dtype=S.dtype), jnp.zeros_like(S)]]))
        return X @ E[:k, :k] + Z @ E[k:, :k]

    def _log_and_margin(self, X: Point, Y: Point):
        B = X.T @ self.op.mv(Y)
        smallest = jnp.linalg.svd(B, compute_uv=False)[-1]
        Z = jnp.linalg.solve(B.T, (Y - X @ B).T).T  # (Y − XB) B⁻¹
        s, V = _sym_eig(Z.T @ self.op.mv(Z))
        return (Z @ V) @ (_atan_ratio(s)[:, None] * V.T), smallest

    def log(self, X: Point, Y: Point) -> Point:
        """``Log_X(Y)`` (module docstring); ``OutOfDomainError`` when a principal angle reaches π/2."""
        xi, smallest = self._log_and_margin(X, Y)
        ok = smallest > 1e-8
        if not is_traced(X, Y, self):
            if not bool(ok):
                raise OutOfDomainError(
                    f"Grassmann log(X, Y) is not defined: a principal angle between the subspaces is π/2 "
                    f"(smallest singular value of XᵀMY = {float(smallest):.2e}); the injectivity radius is π/2")
            return xi
        return jnp.where(ok, xi, jnp.nan)

    def dist(self, X: Point, Y: Point) -> Float[Array, ""]:
        """``‖θ‖``, θ the principal angles (defined for every pair of subspaces)."""
        return jnp.linalg.norm(self.principal_angles(X, Y))

    def principal_angles(self, X: Point, Y: Point) -> Float[Array, " k"]:
        """Angles between ``span X`` and ``span Y`` in the M inner product, ascending."""
        B = X.T @ self.op.mv(Y)
        cos = jnp.clip(jnp.linalg.svd(B, compute_uv=False), 0.0, 1.0)  # descending: angles ascending
        # arccos loses accuracy for small angles: there use the sines, from Y's part orthogonal to span X
        R = Y - X @ B
        G = R.T @ self.op.mv(R)
        sin = jnp.sqrt(jnp.clip(jnp.linalg.eigvalsh(0.5 * (G + G.T)), 0.0, 1.0))  # ascending
        return jnp.where(cos > 0.7, jnp.arcsin(sin), jnp.arccos(cos))


def sphere(n: int, M=None, **options) -> GeneralizedStiefel:
    """The unit sphere (``M = None``) or ellipsoid ``xᵀMx = 1`` in R^n: ``GeneralizedStiefel`` with k = 1;
    points are ``(n, 1)`` columns; ``retraction="periodic"`` follows great circles (the geodesics)."""
    if M is None:
        return GeneralizedStiefel(None, 1, n=n, **options)
    if np.shape(M)[0] != n:
        from ..errors import ShapeError  # noqa: PLC0415

        raise ShapeError(f"M has {np.shape(M)[0]} rows, not n = {n}")
    return GeneralizedStiefel(M, 1, **options)


def stiefel(n: int, k: int, **options) -> GeneralizedStiefel:
    """The ordinary Stiefel manifold ``XᵀX = I_k`` in R^{n×k} (``GeneralizedStiefel(None, k, n=n)``)."""
    return GeneralizedStiefel(None, k, n=n, **options)
