"""Products of generalised Stiefel manifolds ``S_1 × … × S_p`` (pymanopt's ``manifolds.Product``, Manopt's
``productmanifold``).

``Product(S1, S2, ...)`` (or ``Product([S1, S2, ...])``) of ``GeneralizedStiefel`` factors (``Grassmann``,
``sphere``, ``stiefel`` included). A point is a tuple ``X = (X_1, …, X_p)`` with ``X_i: (n_i, k_i)`` on
``S_i``; so is a tangent vector. Every operation acts factor by factor, and the metric is the sum

    ``⟨Z, W⟩_X = Σ_i ⟨Z_i, W_i⟩_{X_i}``,   ``dist(X, Y) = (Σ_i dist_i(X_i, Y_i)²)^{1/2}``,

each factor with its own M, metric and retraction. The solvers (``stiefel.RiemannianCG``,
``stiefel.RiemannianLBFGS``, ``stiefel.RiemannianBB``, ``stiefel.RiemannianTrustRegion``) and the checkers
(``stiefel.check_gradient``, ...) take a ``Product`` where they take a ``GeneralizedStiefel``; the objective
is ``fn(X, args)`` with ``X`` the tuple. Not supported (a named error): nested Products (flatten them:
``Product(*P.factors, S)``), a solver ``preconditioner=`` with a Product, ``stiefel.RiemannianImplicitAdjoint``
and the CMM drivers (``stiefel.minimize``, ``stiefel.minimize_sequential``, ``stiefel.penalty_minimize``).
"""

from __future__ import annotations

import functools
import operator
from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, PRNGKeyArray

from ..errors import ParameterError, ShapeError
from .manifold import GeneralizedStiefel
from .names import ManifoldNames, transport_args

__all__ = ["Product"]

Point = tuple[Float[Array, "n k"], ...]  # one (n_i, k_i) array per factor


def _shape_of(S: GeneralizedStiefel) -> tuple:
    """``(n, k)`` of a factor's points (``"n"`` for an identity metric built without ``n``)."""
    try:
        return (S.n, S.k)
    except ShapeError:
        return ("n", S.k)


def _sum(values):
    return functools.reduce(operator.add, values)


class Product(ManifoldNames, eqx.Module):
    """``S_1 × … × S_p`` (module docstring); points and tangent vectors are tuples of arrays.

    Args:
      *factors: ``GeneralizedStiefel`` manifolds (or one sequence of them); at least one, none a ``Product``
        (``ParameterError``).
    """

    factors: tuple[GeneralizedStiefel, ...]

    def __init__(self, *factors: GeneralizedStiefel | Sequence[GeneralizedStiefel]):
        if len(factors) == 1 and isinstance(factors[0], (tuple, list)):
            factors = tuple(factors[0])
        if not factors:
            raise ParameterError("a Product needs at least one factor, e.g. stiefel.Product(S1, S2)")
        for i, S in enumerate(factors):
            if isinstance(S, Product):
                raise ParameterError(f"factor {i} is a Product: nested Products are not supported; flatten them, "
                                     "e.g. stiefel.Product(*P.factors, S)")
            if not isinstance(S, GeneralizedStiefel):
                raise ParameterError(f"factor {i} must be a stiefel.GeneralizedStiefel (or Grassmann, sphere, "
                                     f"stiefel), got {type(S).__name__}")
        self.factors = tuple(factors)

    def _each(self, method: str, *trees) -> tuple:
        return tuple(getattr(S, method)(*parts) for S, *parts in zip(self.factors, *trees))

    # --- sizes -------------------------------------------------------------------------------
    @property
    def dim(self) -> int:
        """``Σ_i dim S_i``."""
        return sum(S.dim for S in self.factors)

    @property
    def typical_dist(self) -> float:
        """``(Σ_i typical_dist_i²)^{1/2}`` (Manopt's ``productmanifold``)."""
        return float(np.sqrt(sum(S.typical_dist ** 2 for S in self.factors)))

    @property
    def dtype(self):
        return jnp.result_type(*(S.dtype for S in self.factors))

    @property
    def metric(self) -> str:
        """``"euclidean"`` when every factor has the M-weighted metric, else ``"mixed"``."""
        return "euclidean" if all(S.metric == "euclidean" for S in self.factors) else "mixed"

    # --- geometry ----------------------------------------------------------------------------
    def proj(self, X: Point, Y: Point) -> Point:
        """``(proj_1(X_1, Y_1), …)``: each factor's tangent projection."""
        return self._each("proj", X, Y)

    def inner(self, X: Point, Z1: Point, Z2: Point) -> Float[Array, ""]:
        """``Σ_i ⟨Z1_i, Z2_i⟩_{X_i}``."""
        return _sum(self._each("inner", X, Z1, Z2))

    def norm(self, X: Point, Z: Point) -> Float[Array, ""]:
        return jnp.sqrt(jnp.maximum(self.inner(X, Z, Z), 0.0))

    def mv(self, Z: Point) -> Point:
        """``(M_1 Z_1, …)``: the ambient products with the factors' M."""
        return self._each("mv", Z)

    def tangent_residual(self, X: Point, G: Point) -> Point:
        """``(G_i − M_iX_i sym(X_iᵀG_i))_i`` (``GeneralizedStiefel.tangent_residual``)."""
        return self._each("tangent_residual", X, G)

    def egrad_to_rgrad(self, X: Point, G: Point) -> Point:
        """Riemannian gradient from the tuple of partial derivatives ``G_i = ∂F/∂X_i``."""
        return self._each("egrad_to_rgrad", X, G)

    def weighted_rgrad(self, X: Point, G: Point) -> Point:
        """Gradient of the M-weighted metric, factor by factor (``GeneralizedStiefel.weighted_rgrad``)."""
        return self._each("weighted_rgrad", X, G)

    def ehess_to_rhess(self, X: Point, G: Point, H: Point, xi: Point) -> Point:
        """Riemannian Hessian factor by factor from ``G``, ``H = ∇²F(X)[ξ]`` (tuples; the cross terms of a
        coupled F are in ``H``)."""
        return tuple(S.ehess_to_rhess(*parts) for S, *parts in zip(self.factors, X, G, H, xi))

    def retract(self, X: Point, Z: Point) -> Point:
        return self._each("retract", X, Z)

    def transport(self, X_new: Point, Z: Point, *pymanopt) -> Point:
        X_new, Z = transport_args(X_new, Z, pymanopt)
        return self._each("transport", X_new, Z)

    def transport_pair(self, X_new: Point, Z1: Point, Z2: Point) -> tuple[Point, Point]:
        pairs = self._each("transport_pair", X_new, Z1, Z2)
        return tuple(p[0] for p in pairs), tuple(p[1] for p in pairs)

    # --- points ------------------------------------------------------------------------------
    def project_to_manifold(self, Y: Point) -> Point:
        return self._each("project_to_manifold", Y)

    def random_point(self, key: PRNGKeyArray) -> Point:
        """A random point (one split of ``key`` per factor)."""
        keys = jax.random.split(key, len(self.factors))
        return tuple(S.random_point(k) for S, k in zip(self.factors, keys))

    def random_tangent(self, key: PRNGKeyArray, X: Point) -> Point:
        """A random tangent vector at ``X`` of unit norm in the product metric."""
        keys = jax.random.split(key, len(self.factors))
        Z = tuple(S.proj(x, jax.random.normal(k, x.shape, dtype=x.dtype)) for S, x, k in zip(self.factors, X, keys))
        scale = 1.0 / self.norm(X, Z)
        return tuple(scale * z for z in Z)

    def zero_vector(self, X: Point) -> Point:
        return tuple(jnp.zeros_like(x) for x in X)

    def transp(self, X: Point, Y: Point, Z: Point) -> Point:
        """Manopt's ``transp(x1, x2, d)``: ``transport(Y, Z)``."""
        return self.transport(Y, Z)

    def exp(self, X: Point, Z: Point) -> Point:
        return self._each("exp", X, Z)

    def log(self, X: Point, Y: Point) -> Point:
        return self._each("log", X, Y)

    def dist(self, X: Point, Y: Point) -> Float[Array, ""]:
        """``(Σ_i dist_i(X_i, Y_i)²)^{1/2}``."""
        return jnp.sqrt(_sum([d * d for d in self._each("dist", X, Y)]))

    def dist_to_manifold(self, X: Point) -> Float[Array, ""]:
        """``max_i max |X_iᵀM_iX_i − I|``."""
        return functools.reduce(jnp.maximum, self._each("dist_to_manifold", X))

    def check_shape(self, X, *, name: str = "X0") -> None:
        """Raise ``ShapeError`` unless ``X`` is a tuple with one ``(n_i, k_i)`` array per factor (host-side;
        shapes only, so it works on traced values)."""
        p = len(self.factors)
        want = tuple(_shape_of(S) for S in self.factors)
        if not isinstance(X, tuple):
            hint = f"; pass tuple({name})" if isinstance(X, list) else ""
            raise ShapeError(f"{name} must be a tuple of {p} arrays of shapes {want}, one per factor of the Product, "
                             f"got {type(X).__name__}{hint}")
        if len(X) != p:
            got = tuple(tuple(np.shape(x)) for x in X)
            raise ShapeError(f"{name} has {len(X)} components; the Product has {p} factors: {name} must be a tuple of "
                             f"shapes {want}, got {got}")
        for i, (S, x) in enumerate(zip(self.factors, X)):
            S.check_shape(x, name=f"{name}[{i}]")

    def check_point(self, X, *, atol: float = 1e-8, name: str = "X0") -> None:
        """``check_shape``, then each factor's ``check_point`` (``ShapeError``/``OffManifoldError`` naming the
        component, e.g. ``X0[1]``)."""
        self.check_shape(X, name=name)
        for i, (S, x) in enumerate(zip(self.factors, X)):
            S.check_point(x, atol=atol, name=f"{name}[{i}]")
