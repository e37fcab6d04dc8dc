"""The generalised Stiefel manifold ``S_M = {X ∈ R^{n×k} : XᵀMX = I_k}`` (docs/maths.md §1, thesis §6.1)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from . import geodesics as _geodesics
from ..errors import OffManifoldError, ShapeError, StiefelError
from ..linalg.operators import IdentityOperator, LinearOperator, as_operator
from .names import ManifoldNames, transport_args
from .retractions import BLOCK_RETRACTIONS, RETRACTIONS, _inv_sqrt_spd
from ..validation import check_full_rank, is_integer

__all__ = ["GeneralizedStiefel", "sym", "skew"]

Point = Float[Array, "n k"]
METRICS = ("euclidean", "canonical")


def sym(B):
    """``(B + Bᵀ)/2``."""
    return 0.5 * (B + B.T)


def skew(B):
    """``(B − Bᵀ)/2``."""
    return 0.5 * (B - B.T)


class GeneralizedStiefel(ManifoldNames, eqx.Module):
    """``{X : XᵀMX = I_k}`` for an SPD ``M`` (diagonal, dense or ``scipy.sparse``).

    Args:
      M: 1-D array (the diagonal of M), dense SPD ``(n, n)`` array, ``scipy.sparse``
        SPD matrix (never densified; factored once for ``M⁻¹``), a
        ``stiefel.linalg.operators.LinearOperator``, or None: ``M = I``, the ordinary Stiefel manifold
        ``XᵀX = I`` (``n`` optional: it is taken from the points; ``random_point``, ``dim`` and
        ``check_point`` need it).
      k: number of columns, ``1 ≤ k ≤ n``.
      n: the number of rows, for ``M = None`` only.
      metric: ``"euclidean"`` (``tr(Z1ᵀMZ2)``) or ``"canonical"``
        (``tr(Z1ᵀM(I − ½XXᵀM)Z2)``).
      retraction: ``"polar"`` (default: the fastest per iteration, docs/benchmarks/peers.md), ``"cholesky"``,
        ``"cayley"`` (low-rank, the thesis's); for ``k = 1`` also ``"radial"`` and ``"periodic"``.
      check: validate that M is SPD (raises ``NotSPDError``).
      dtype: dtype of the stored operator (default float64 when x64 is enabled).

    Points are arrays of shape ``(n, k)``; all methods are pure and jittable. The chosen retraction's name is
    ``retraction_name``; ``retraction(X, Z)``, ``retr`` and the other pymanopt/Manopt names are methods
    (``stiefel.manifolds.names``).
    """

    op: LinearOperator
    k: int = eqx.field(static=True)
    metric: str = eqx.field(static=True)
    retraction_name: str = eqx.field(static=True)

    def __init__(self, M, k: int, *, metric: str = "euclidean", retraction: str = "polar",
                 check: bool = True, dtype=None, n: int | None = None):
        if M is None:
            if n is not None and not (is_integer(n) and int(n) >= 1):
                raise ShapeError(f"n must be a positive integer, got n = {n!r}")
            dt = np.dtype(dtype or (jnp.float64 if jax.config.jax_enable_x64 else jnp.float32))
            op = IdentityOperator(None if n is None else int(n), dt)
        elif n is not None:
            raise ShapeError("n is only for M = None (the ordinary Stiefel manifold); M gives the size otherwise")
        else:
            op = as_operator(M, check=check, dtype=dtype)
        size = op.size if isinstance(op, IdentityOperator) else op.n
        if not is_integer(k) or not 1 <= int(k) <= (size if size is not None else int(k)):
            raise ShapeError(f"k must be an integer with 1 ≤ k ≤ n = {size}, got k = {k!r}")
        if metric not in METRICS:
            raise StiefelError(f"unknown metric {metric!r}; choose one of {METRICS}")
        if retraction not in RETRACTIONS:
            raise StiefelError(f"unknown retraction {retraction!r}; choose one of {tuple(RETRACTIONS)}")
        if retraction not in BLOCK_RETRACTIONS and int(k) > 1:
            raise StiefelError(
                f"the {retraction!r} retraction exists only for k = 1 (the ellipsoid xᵀMx = 1); "
                f"it does not extend to k = {k} > 1 (thesis Rem. 6.4.23). Use 'cayley', 'cholesky' or 'polar', "
                "or solve column by column with stiefel.minimize_sequential."
            )
        self.op = op
        self.k = int(k)
        self.metric = metric
        self.retraction_name = retraction

    # --- sizes -------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        return self.op.n

    @property
    def dim(self) -> int:
        """Manifold dimension ``nk − k(k+1)/2``."""
        return self.n * self.k - self.k * (self.k + 1) // 2

    @property
    def typical_dist(self) -> float:
        """A typical distance between points, ``√k`` (Manopt's ``typicaldist``; the trust-region radius scale)."""
        return float(np.sqrt(self.k))

    @property
    def dtype(self):
        if isinstance(self.op, IdentityOperator):
            return self.op.dtype
        return self.op.diagonal().dtype

    # --- geometry ----------------------------------------------------------------------------
    def proj(self, X: Point, Y: Point) -> Point:
        """M-orthogonal projection of ambient ``Y`` onto ``T_X S_M``: ``Y − X sym(XᵀMY)``."""
        return Y - X @ sym(X.T @ self.op.mv(Y))

    def inner(self, X: Point, Z1: Point, Z2: Point) -> Float[Array, ""]:
        """Metric on ``T_X S_M`` (Euclidean = M-weighted, or canonical)."""
        MZ2 = self.op.mv(Z2)
        value = jnp.sum(Z1 * MZ2)
        if self.metric == "canonical":
            value = value - 0.5 * jnp.sum((X.T @ self.op.mv(Z1)) * (X.T @ MZ2))
        return value

    def norm(self, X: Point, Z: Point) -> Float[Array, ""]:
        return jnp.sqrt(jnp.maximum(self.inner(X, Z, Z), 0.0))

    def mv(self, Z: Point) -> Point:
        """``MZ``: the ambient product with M (``tr(Z1ᵀ·mv(Z2))`` is the M-weighted metric)."""
        return self.op.mv(Z)

    def tangent_residual(self, X: Point, G: Point) -> Point:
        """``R = G − MX sym(XᵀG)`` for the Euclidean gradient ``G``: ``tr(RᵀZ) = tr(GᵀZ)`` for tangent Z, and
        R vanishes at critical points (the slopes of ``stiefel.solvers.block_steps``; ``M·grad`` of the M-weighted
        metric)."""
        return G - self.op.mv(X) @ sym(X.T @ G)

    def egrad_to_rgrad(self, X: Point, G: Point) -> Point:
        """Riemannian gradient from the Euclidean partial derivative ``G = ∂F/∂X`` (docs/maths.md §1).

        Euclidean metric: ``M⁻¹G − X sym(XᵀG)``; canonical: ``M⁻¹G − X GᵀX``.
        """
        MinvG = self.op.solve(G)
        if self.metric == "canonical":
            return MinvG - X @ (G.T @ X)
        return MinvG - X @ sym(X.T @ G)

    def weighted_rgrad(self, X: Point, G: Point) -> Point:
        """The Riemannian gradient of the M-weighted metric ``tr(Z1ᵀMZ2)``, ``M⁻¹G − X sym(XᵀG)``, whatever
        the manifold's metric (the trust-region model's; ``egrad_to_rgrad`` for ``metric="euclidean"``)."""
        if self.metric == "euclidean":
            return self.egrad_to_rgrad(X, G)
        return self.op.solve(G) - X @ sym(X.T @ G)

    def ehess_to_rhess(self, X: Point, G: Point, H: Point, xi: Point) -> Point:
        """Riemannian Hessian ``P_X(M⁻¹H − ξ sym(XᵀG))`` from the Euclidean gradient ``G`` and the
        Euclidean Hessian action ``H = ∇²F(X)[ξ]`` at tangent ``ξ`` (docs/maths.md §9; both metrics,
        see ``stiefel.derivatives.hessian``)."""
        return self.proj(X, self.op.solve(H) - xi @ sym(X.T @ G))

    def retract(self, X: Point, Z: Point) -> Point:
        """``R_X(Z)`` with the manifold's retraction."""
        return RETRACTIONS[self.retraction_name](self.op, X, Z)

    def transport(self, X_new: Point, Z: Point, *pymanopt) -> Point:
        """Vector transport by projection onto ``T_{X_new}``; pymanopt's ``transport(X, X_new, Z)`` too."""
        X_new, Z = transport_args(X_new, Z, pymanopt)
        return self.proj(X_new, Z)

    def transport_pair(self, X_new: Point, Z1: Point, Z2: Point) -> tuple[Point, Point]:
        """``(transport(X_new, Z1), transport(X_new, Z2))`` with one ``(k × 2k)`` Gram product."""
        k = Z1.shape[-1]
        Z = jnp.concatenate([Z1, Z2], axis=-1)
        B = X_new.T @ self.op.mv(Z)
        T = Z - X_new @ jnp.concatenate([sym(B[:, :k]), sym(B[:, k:])], axis=-1)
        return T[:, :k], T[:, k:]

    # --- points ------------------------------------------------------------------------------
    def project_to_manifold(self, Y: Point) -> Point:
        """The M-closest point of ``S_M`` to a full-rank ``Y``: ``Y (YᵀMY)^{-1/2}``.

        A concrete ``Y`` (not traced) whose columns are linearly dependent in the M inner product
        raises ``RankDeficientError`` with its numerical rank (``stiefel.validation.check_full_rank``).
        """
        G = Y.T @ self.op.mv(Y)
        check_full_rank("Y", G)
        return Y @ _inv_sqrt_spd(G)

    def random_point(self, key: PRNGKeyArray) -> Point:
        """A random point (Gaussian ``Y`` projected to the manifold)."""
        Y = jax.random.normal(key, (self.n, self.k), dtype=self.dtype)
        return self.project_to_manifold(Y)

    def random_tangent(self, key: PRNGKeyArray, X: Point) -> Point:
        """A random tangent vector at ``X`` of unit norm in the manifold's metric."""
        Z = self.proj(X, jax.random.normal(key, X.shape, dtype=X.dtype))
        return Z / self.norm(X, Z)

    def zero_vector(self, X: Point) -> Point:
        """The zero tangent vector at ``X`` (pymanopt's and Manopt's ``zero_vector``/``zerovec``)."""
        return jnp.zeros_like(X)

    def transp(self, X: Point, Y: Point, Z: Point) -> Point:
        """Manopt's ``transp(x1, x2, d)`` / pymanopt's ``transport(point_a, point_b, tangent_vector_a)``: the
        tangent ``Z`` at ``X`` moved to ``T_Y`` by projection (``transport(Y, Z)``; ``X`` is not needed)."""
        return self.transport(Y, Z)

    # --- geodesics (stiefel.manifolds.geodesics: closed forms with M-products only; the isometry X ↦ LᵀX implicit) ---
    def exp(self, X: Point, Z: Point) -> Point:
        """The exponential map ``Exp_X(Z)`` of the manifold's metric (closed form, O(nk²) + one product with M)."""
        return _geodesics.exp(self, X, Z)

    def log(self, X: Point, Y: Point) -> Point:
        """``Log_X(Y)``: the tangent at ``X`` of the shortest geodesic to ``Y`` (Gauss–Newton shooting in
        ``span(X, Y)``); ``OutOfDomainError`` unless it is shorter than the injectivity radius (NaN when traced)."""
        return _geodesics.log(self, X, Y)

    def dist(self, X: Point, Y: Point) -> Float[Array, ""]:
        """Geodesic distance ``‖Log_X(Y)‖`` (same domain as ``log``)."""
        return _geodesics.dist(self, X, Y)

    def dist_to_manifold(self, X: Point) -> Float[Array, ""]:
        """``max |XᵀMX − I|``."""
        return jnp.max(jnp.abs(X.T @ self.op.mv(X) - jnp.eye(X.shape[1], dtype=X.dtype)))

    def check_shape(self, X, *, name: str = "X0") -> None:
        """Raise ``ShapeError`` unless ``X`` (an array or its ``jax.ShapeDtypeStruct``) has shape ``(n, k)``."""
        shape = tuple(np.shape(X))
        sized = not (isinstance(self.op, IdentityOperator) and self.op.size is None)
        if len(shape) != 2 or shape[1] != self.k or shape[0] < self.k or (sized and shape[0] != self.n):
            want = (self.n if sized else "n ≥ k", self.k)
            raise ShapeError(f"{name} must have shape (n, k) = {want}, got {shape}")

    def check_point(self, X, *, atol: float = 1e-8, name: str = "X0") -> None:
        """Raise ``ShapeError``/``OffManifoldError`` unless ``X`` is an ``(n, k)`` point of S_M (host-side);
        ``RankDeficientError`` (an ``OffManifoldError``) names a start with dependent columns."""
        self.check_shape(X, name=name)
        Xj = jnp.asarray(X, dtype=self.dtype)
        if not bool(jnp.all(jnp.isfinite(Xj))):
            raise OffManifoldError(f"{name} has non-finite entries")
        err = float(self.dist_to_manifold(Xj))
        if not err <= atol:
            check_full_rank(name, Xj.T @ self.op.mv(Xj))
            raise OffManifoldError(
                f"{name} is off the manifold: max|XᵀMX − I| = {err:.3e} > {atol:.1e}; "
                "use manifold.project_to_manifold(X) to move it onto the manifold"
            )
