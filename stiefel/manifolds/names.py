"""pymanopt's and Manopt's names for a manifold's maps, with those libraries' meaning and argument order.

Every manifold-like class here (``GeneralizedStiefel``, ``Grassmann``, ``Product``) mixes in ``ManifoldNames``; each
name calls the method it stands for *by name*, so a subclass's own ``proj`` or ``egrad_to_rgrad`` (Grassmann's
horizontal ones) is what the alias runs. The table is docs/tutorial.md, "Coming from pymanopt or Manopt", and one
test calls every name it lists (tests/test_names.py).

Random maps take the key first, as ``jax.random`` does and as ``random_point(key)``: ``random_tangent(key, X)``,
``random_tangent_vector(key, X)``, ``randvec(key, X)``, ``rand(key)`` (JAX has no global random state; the other
libraries' versions take no key). Arguments in the other order raise ``StiefelError`` naming the order.
"""

from __future__ import annotations

import jax
import numpy as np

from ..errors import StiefelError

__all__ = ["ManifoldNames", "is_key"]


def is_key(x) -> bool:
    """A JAX PRNG key: a typed key array, or a raw ``uint32`` key of shape ``(2,)`` (``jax.random.PRNGKey``)."""
    dtype = getattr(x, "dtype", None)
    if dtype is None:
        return False
    if jax.dtypes.issubdtype(dtype, jax.dtypes.prng_key):
        return True
    return np.dtype(dtype) == np.uint32 and np.shape(x) == (2,)


def _key_first(name: str, key, X) -> None:
    if not is_key(key) and is_key(X):
        raise StiefelError(f"{name} takes (key, X): the key first, as in jax.random and random_point(key); "
                           f"got the point first — call {name}(key, X)")
    if not is_key(key):
        raise StiefelError(f"{name} takes (key, X) with a JAX PRNG key first (jax.random.PRNGKey(seed) or "
                           f"jax.random.key(seed)), got {type(key).__name__} {getattr(key, 'shape', '')}")


class ManifoldNames:
    """The other libraries' names (module docstring). Needs ``proj``, ``inner``, ``egrad_to_rgrad``,
    ``ehess_to_rhess``, ``retract``, ``transport``, ``random_point``, ``random_tangent``, ``zero_vector`` and
    ``typical_dist`` on the class."""

    # --- pymanopt --------------------------------------------------------------------------------------------------
    def projection(self, X, Y):
        """pymanopt's ``projection(point, vector)``: ``proj(X, Y)``."""
        return self.proj(X, Y)

    def to_tangent_space(self, X, Y):
        """pymanopt's ``to_tangent_space(point, vector)``: ``proj(X, Y)``."""
        return self.proj(X, Y)

    def inner_product(self, X, Z1, Z2):
        """pymanopt's ``inner_product(point, a, b)``: ``inner(X, Z1, Z2)``."""
        return self.inner(X, Z1, Z2)

    def euclidean_to_riemannian_gradient(self, X, G):
        """pymanopt's name of ``egrad_to_rgrad(X, G)``."""
        return self.egrad_to_rgrad(X, G)

    def euclidean_to_riemannian_hessian(self, X, G, H, xi):
        """pymanopt's name of ``ehess_to_rhess(X, G, H, ξ)`` (point, Euclidean gradient, Euclidean Hessian at ξ, ξ)."""
        return self.ehess_to_rhess(X, G, H, xi)

    def retraction(self, X, Z):
        """pymanopt's ``retraction(point, tangent_vector)``: ``retract(X, Z)`` (the map chosen by the constructor's
        ``retraction=`` option, which is stored as ``retraction_name``)."""
        return self.retract(X, Z)

    def retraction_map(self, X, Z):
        """``retract(X, Z)`` (an older alias of this library)."""
        return self.retract(X, Z)

    def random_tangent_vector(self, key, X):
        """pymanopt's ``random_tangent_vector(point)`` with the key JAX needs, first: ``random_tangent(key, X)``
        (use a key other than the one that made ``X``: the same Gaussian draw lies in span(X))."""
        _key_first("random_tangent_vector", key, X)
        return self.random_tangent(key, X)

    # --- Manopt ----------------------------------------------------------------------------------------------------
    def tangent(self, X, Y):
        """Manopt's ``tangent(x, u)``: the projection of an ambient ``Y`` onto ``T_X`` (``proj``)."""
        return self.proj(X, Y)

    def egrad2rgrad(self, X, G):
        """Manopt's ``egrad2rgrad(x, egrad)``: ``egrad_to_rgrad(X, G)``."""
        return self.egrad_to_rgrad(X, G)

    def ehess2rhess(self, X, G, H, xi):
        """Manopt's ``ehess2rhess(x, egrad, ehess, u)``: ``ehess_to_rhess(X, G, H, ξ)``."""
        return self.ehess_to_rhess(X, G, H, xi)

    def retr(self, X, Z, t=1.0):
        """Manopt's ``retr(x, u, t)``: ``retract(X, t·Z)`` (t = 1 by default, as there)."""
        if isinstance(Z, tuple):
            return self.retract(X, tuple(t * z for z in Z))
        return self.retract(X, t * Z)

    def zerovec(self, X):
        """Manopt's ``zerovec(x)``: ``zero_vector(X)``."""
        return self.zero_vector(X)

    def randvec(self, key, X):
        """Manopt's ``randvec(x)`` with a key, first: ``random_tangent(key, X)`` (unit norm, as Manopt's)."""
        _key_first("randvec", key, X)
        return self.random_tangent(key, X)

    def rand(self, key):
        """Manopt's ``rand()`` with a key: ``random_point(key)``."""
        return self.random_point(key)

    @property
    def typicaldist(self) -> float:
        """Manopt's ``typicaldist()``: ``typical_dist``."""
        return self.typical_dist


def transport_args(X_new, Z, rest: tuple):
    """``(X_new, Z)`` from ``transport(X_new, Z)`` or pymanopt's ``transport(X, X_new, Z)``."""
    if not rest:
        return X_new, Z
    if len(rest) > 1:
        raise StiefelError(f"transport takes (X_new, Z) or pymanopt's (X, X_new, Z), got {2 + len(rest)} arguments")
    return Z, rest[0]
