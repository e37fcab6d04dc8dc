"""Linear algebra on tangent vectors that are arrays or pytrees of arrays (``stiefel.Product`` points).

The solvers' steps are written once with these helpers. For a single array each one is exactly the
array expression it replaces (``inner(a, b) = jnp.sum(a * b)``, ``where = jnp.where``, one leaf: no
extra additions), so the single-array programs are unchanged; for a tuple they act leaf by leaf and
inner products sum over the leaves: ``⟨a, b⟩ = Σ_i tr(a_iᵀ b_i)``.
"""

from __future__ import annotations

import functools
import operator
from typing import Any, Callable

import jax
import jax.numpy as jnp

__all__ = ["tmap", "inner", "where", "all_finite", "dtype_of", "zeros_like", "stacked_zeros", "take", "set_at",
           "max_abs"]

Tree = Any


def tmap(f: Callable, *trees: Tree) -> Tree:
    """``f`` applied leaf by leaf (``jax.tree_util.tree_map``; an array is one leaf)."""
    return jax.tree_util.tree_map(f, *trees)


def _total(values, op=operator.add):
    return functools.reduce(op, values)


def inner(a: Tree, b: Tree) -> jax.Array:
    """``Σ_leaves sum(a * b)`` (the Frobenius inner product ``tr(aᵀb)`` for one array)."""
    return _total([jnp.sum(x * y) for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b))])


def where(cond, a: Tree, b: Tree) -> Tree:
    """``jnp.where(cond, a, b)`` leaf by leaf (``cond`` a scalar)."""
    return tmap(lambda x, y: jnp.where(cond, x, y), a, b)


def all_finite(a: Tree) -> jax.Array:
    """Whether every entry of every leaf is finite."""
    return _total([jnp.all(jnp.isfinite(x)) for x in jax.tree_util.tree_leaves(a)], operator.and_)


def max_abs(a: Tree) -> jax.Array:
    """``max |a|`` over all leaves."""
    return _total([jnp.max(jnp.abs(x)) for x in jax.tree_util.tree_leaves(a)], jnp.maximum)


def dtype_of(a: Tree):
    """The common dtype of the leaves (the array's own for one array)."""
    leaves = jax.tree_util.tree_leaves(a)
    return leaves[0].dtype if len(leaves) == 1 else jnp.result_type(*leaves)


def zeros_like(a: Tree) -> Tree:
    return tmap(jnp.zeros_like, a)


def stacked_zeros(m: int, a: Tree, dtype) -> Tree:
    """Leaves of shape ``(m,) + leaf.shape``: a buffer of ``m`` tangent vectors (L-BFGS memory)."""
    return tmap(lambda x: jnp.zeros((m,) + x.shape, dtype), a)


def take(buffer: Tree, i) -> Tree:
    """The ``i``-th vector of a ``stacked_zeros`` buffer."""
    return tmap(lambda x: x[i], buffer)


def set_at(buffer: Tree, i, value: Tree) -> Tree:
    """``buffer.at[i].set(value)`` leaf by leaf (in place inside a loop)."""
    return tmap(lambda x, v: x.at[i].set(v), buffer, value)
