"""The sign convention of every basis the toolkit returns (docs/maths.md §8).

A basis of eigenfunctions or compressed modes is defined up to the sign of each column
(both energies are even in ψ). The toolkit fixes it: **in each column the entry of
largest magnitude is positive** (ties: the first such row; a zero column is left as is).
The rule commutes with a permutation of the rows (vertices), so permuted meshes get
permuted bases, and it is idempotent.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["canonical_signs", "column_signs"]


def column_signs(X: Any) -> Any:
    """``(k,)`` signs ``s_j = sign(X[i*, j])`` with ``i* = argmax_i |X_ij|`` (``+1`` for a zero column).

    ``X``: ``(n, k)`` numpy or JAX array (JAX: jittable, vmappable; the signs carry no derivative)."""
    if isinstance(X, np.ndarray):
        peak = X[np.argmax(np.abs(X), axis=0), np.arange(X.shape[1])]
        return np.where(peak < 0, -1.0, 1.0).astype(X.dtype, copy=False)
    import jax
    import jax.numpy as jnp

    Xs = jax.lax.stop_gradient(X)
    peak = jnp.take_along_axis(Xs, jnp.argmax(jnp.abs(Xs), axis=0)[None, :], axis=0)[0]
    return jnp.where(peak < 0, -1.0, 1.0).astype(X.dtype)


def canonical_signs(X: Any) -> Any:
    """``X`` with each column multiplied by its sign (``column_signs``): the largest-magnitude entry is positive."""
    return X * column_signs(X)[None, :]
