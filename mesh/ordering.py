"""Vertex permutations: ``permute`` and the reverse Cuthill–McKee ``reorder``.

Convention: ``permute(m, perm)`` returns the mesh ``N`` whose vertex ``i`` is
vertex ``perm[i]`` of ``m``. With ``Π_{i, perm[i]} = 1`` this is the bijection of
Def. 3.4.8: ``A_N = Π A_P Πᵀ``, ``W_N = Π W_P Πᵀ`` and eigenfunctions map as
``φ_N = Π φ_P`` (= ``φ_P[perm]``, Prop. 3.4.12).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee
from jaxtyping import Int

from .io import Mesh, edges_of

__all__ = ["permute", "inverse_permutation", "permutation_matrix", "reorder"]


def inverse_permutation(perm: Int[np.ndarray, " n"]) -> Int[np.ndarray, " n"]:
    """``inv`` with ``inv[perm[i]] = i``."""
    perm = np.asarray(perm, dtype=np.int64)
    inv = np.empty_like(perm)
    inv[perm] = np.arange(perm.size)
    return inv


def _check_perm(perm: np.ndarray, n: int) -> np.ndarray:
    perm = np.asarray(perm, dtype=np.int64).reshape(-1)
    if perm.size != n or not np.array_equal(np.sort(perm), np.arange(n)):
        raise ValueError(f"perm must be a permutation of range({n}) (shape ({n},))")
    return perm


def permutation_matrix(perm: Int[np.ndarray, " n"]) -> sp.csr_array:
    """``Π`` with ``Π_{i, perm[i]} = 1`` (so ``(ΠX)[i] = X[perm[i]]``), shape ``(n, n)``."""
    perm = np.asarray(perm, dtype=np.int64)
    n = perm.size
    return sp.csr_array((np.ones(n), (np.arange(n), perm)), shape=(n, n))


def permute(m: Mesh, perm: Int[np.ndarray, " n"]) -> Mesh:
    """The same mesh with vertices renumbered: new vertex ``i`` is old vertex ``perm[i]``."""
    perm = _check_perm(perm, m.n_vertices)
    inv = inverse_permutation(perm)
    return replace(
        m,
        vertices=np.ascontiguousarray(m.vertices[perm]),
        faces=np.ascontiguousarray(inv[m.faces]),
        component=m.component[perm],
    )


def reorder(m: Mesh) -> tuple[Mesh, Int[np.ndarray, " n"]]:
    """Reverse Cuthill–McKee renumbering (bandwidth reduction) of the vertex graph.

    Neighbouring vertices get nearby indices, so the gathers of the ELL matvec
    ``W @ X`` touch nearby memory (measured in ``docs/benchmarks/mesh.md``).
    Never applied silently: returns ``(permute(m, perm), perm)``; map results
    back with ``X_original = X_reordered[inverse_permutation(perm)]``.
    """
    e = edges_of(m.faces)
    n = m.n_vertices
    adj = sp.csr_matrix((np.ones(2 * e.shape[0]), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])), shape=(n, n))
    perm = np.asarray(reverse_cuthill_mckee(adj, symmetric_mode=True), dtype=np.int64)
    return permute(m, perm), perm
