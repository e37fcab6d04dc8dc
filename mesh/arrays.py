"""Vectorised element helpers shared by loading, topology and the Laplacians.

Face areas, half-edges, unique edges and unique rows;
all O(m) or O(m log m) numpy, no Python loops over faces.
"""

from __future__ import annotations

import numpy as np
from jaxtyping import Float, Int

__all__ = ["face_areas", "edges_of", "half_edges", "unique_rows", "unique_edges", "unique_counts"]


def face_areas(vertices: Float[np.ndarray, "n 3"], faces: Int[np.ndarray, "m 3"]) -> Float[np.ndarray, " m"]:
    """Triangle areas ``|(v1 − v0) × (v2 − v0)| / 2``, shape ``(m,)``."""
    v0, v1, v2 = (vertices[faces[:, c]] for c in range(3))
    return 0.5 * np.linalg.norm(np.cross(v1 - v0, v2 - v0), axis=1)


def half_edges(faces: Int[np.ndarray, "m 3"]) -> Int[np.ndarray, "h 2"]:
    """The ``h = 3m`` directed edges: row ``c·m + f`` is ``(F[f, c], F[f, c+1 mod 3])``."""
    return np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=0)


def unique_counts(a: Int[np.ndarray, " k"]) -> tuple[Int[np.ndarray, " u"], Int[np.ndarray, " u"]]:
    """Sorted unique values of a 1-D integer array and their counts, by one sort.

    (``np.unique`` of numpy 2.4 took 12.8 s on 6·10⁶ random int64 keys here, its
    ``return_counts`` path 0.85 s, this 0.16 s.)
    """
    s = np.sort(a)
    new = np.empty(s.size, dtype=bool)
    new[:1] = True
    np.not_equal(s[1:], s[:-1], out=new[1:])
    starts = np.flatnonzero(new)
    return s[starts], np.diff(np.append(starts, s.size))


def unique_edges(und: Int[np.ndarray, "e 2"], n: int) -> tuple[Int[np.ndarray, "u 2"], Int[np.ndarray, " u"]]:
    """Unique rows of sorted vertex pairs ``(i < j)`` and their multiplicities (int64 keys ``i·n + j``)."""
    key = und[:, 0].astype(np.int64) * n + und[:, 1]
    ukey, counts = unique_counts(key)
    return np.stack([ukey // n, ukey % n], axis=1), counts


def edges_of(faces: Int[np.ndarray, "m 3"]) -> Int[np.ndarray, "e 2"]:
    """Unique undirected edges ``(i, j)``, ``i < j``, of a triangle list, shape ``(e, 2)``."""
    und = np.sort(half_edges(faces), axis=1)
    n = int(faces.max()) + 1 if faces.size else 0
    return unique_edges(und, n)[0]


def unique_rows(R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Unique rows of a 2-D array: ``(uniq, first, inverse, counts)`` as ``np.unique(axis=0)``.

    A stable lexicographic sort and a neighbour comparison: several times faster
    than ``np.unique(axis=0)``, which compares rows as opaque byte strings.
    ``first`` is the first occurrence in input order.
    """
    if R.shape[0] == 0:
        e = np.zeros(0, dtype=np.int64)
        return R, e, e, e
    order = np.lexsort(R.T[::-1])
    Rs = R[order]
    new = np.empty(R.shape[0], dtype=bool)
    new[0] = True
    new[1:] = np.any(Rs[1:] != Rs[:-1], axis=1)
    inverse = np.empty(R.shape[0], dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    counts = np.diff(np.flatnonzero(np.append(new, True)))
    return Rs[new], order[new], inverse, counts
