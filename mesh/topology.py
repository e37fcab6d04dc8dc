"""Topology of a triangle list: components, boundary loops, non-manifold edges and vertices.

Definitions (also used by ``Mesh``):

* a *non-manifold edge* is shared by more than two faces;
* a *non-manifold vertex* is one where the surface is not locally a disc or
  half-disc: an endpoint of a non-manifold edge, or a vertex where several
  fans of faces meet (a "bowtie"). Fans are the connected components of the
  vertex's corners, two corners being joined when their faces share an edge
  through the vertex;
* *boundary loops* are the connected components of the graph of boundary
  edges (edges with exactly one face). Edges with more than two faces are
  neither boundary nor interior, so on a non-edge-manifold mesh a "loop" may
  branch; it is still counted once.

All vectorised: one sort of the ``3m`` half-edges and sparse connected components.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
from jaxtyping import Int

from .arrays import half_edges, unique_counts

__all__ = ["Topology", "topology"]


class Topology(NamedTuple):
    """Topological counts of ``(n, m)`` mesh; see the module docstring for definitions.

    Attributes:
      n_edges: unique undirected edges.
      n_components: connected components of the vertex graph.
      component: ``(n,)`` component label of each vertex.
      n_boundary_loops: components of the boundary-edge graph.
      nonmanifold_edges: ``(k, 2)`` vertex pairs of edges with more than two faces.
      nonmanifold_edge_faces: ``(k,)`` number of faces on each of them.
      nonmanifold_vertices: ``(j,)`` sorted indices of non-manifold vertices.
    """

    n_edges: int
    n_components: int
    component: Int[np.ndarray, " n"]
    n_boundary_loops: int
    nonmanifold_edges: Int[np.ndarray, "k 2"]
    nonmanifold_edge_faces: Int[np.ndarray, " k"]
    nonmanifold_vertices: Int[np.ndarray, " j"]


def topology(F: Int[np.ndarray, "m 3"], n: int) -> Topology:
    """Components, boundary loops and non-manifold elements of triangles ``F`` on ``n`` vertices."""
    H = half_edges(F)
    und = np.sort(H, axis=1)
    key = und[:, 0].astype(np.int64) * n + und[:, 1]
    order = np.argsort(key, kind="stable")  # half-edges grouped by undirected edge
    ks = key[order]
    start = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
    counts = np.diff(np.r_[start, ks.size])
    uniq = np.stack([ks[start] // n, ks[start] % n], axis=1)
    adj = sp.coo_array((np.ones(uniq.shape[0]), (uniq[:, 0], uniq[:, 1])), shape=(n, n))
    n_comp, labels = csgraph.connected_components(adj, directed=False)
    bad = counts > 2
    flag = np.zeros(n, dtype=bool)
    flag[uniq[bad].ravel()] = True
    flag[_bowtie_vertices(H, order, start, counts, n)] = True
    return Topology(
        n_edges=int(uniq.shape[0]),
        n_components=int(n_comp),
        component=labels.astype(np.int64),
        n_boundary_loops=_count_loops(uniq[counts == 1]),
        nonmanifold_edges=uniq[bad],
        nonmanifold_edge_faces=counts[bad],
        nonmanifold_vertices=np.flatnonzero(flag),
    )


def _count_loops(bnd: Int[np.ndarray, "b 2"]) -> int:
    """Connected components of the graph of boundary edges ``bnd``."""
    if bnd.shape[0] == 0:
        return 0
    bverts = unique_counts(bnd.ravel())[0]
    loc = np.searchsorted(bverts, bnd)
    badj = sp.coo_array((np.ones(bnd.shape[0]), (loc[:, 0], loc[:, 1])), shape=(bverts.size,) * 2)
    return int(csgraph.connected_components(badj, directed=False)[0])


def _bowtie_vertices(H: np.ndarray, order: np.ndarray, start: np.ndarray, counts: np.ndarray, n: int) -> np.ndarray:
    """Vertices whose corners form more than one fan (see the module docstring).

    ``H``: the ``3m`` half-edges; ``order`` groups them by undirected edge, group
    ``g`` starting at ``order[start[g]]`` with ``counts[g]`` members. Corner
    ``(f, c)`` has id ``c·m + f``, the id of half-edge ``(F[f,c], F[f,c+1])``,
    whose head corner is ``((c+1) mod 3)·m + f``. Half-edges on one undirected
    edge are joined to the first of them: tail to tail and head to head when
    they run the same way, tail to head otherwise.
    """
    h3 = H.shape[0]
    head = (np.arange(h3) + h3 // 3) % h3
    first = order[np.repeat(start, counts)]
    keep = order != first
    a, b = first[keep], order[keep]
    same_way = H[a, 0] == H[b, 0]
    src = np.concatenate([a, head[a]])
    dst = np.concatenate([np.where(same_way, b, head[b]), np.where(same_way, head[b], b)])
    g = sp.coo_array((np.ones(src.size), (src, dst)), shape=(h3, h3))
    _, fan = csgraph.connected_components(g, directed=False)
    pairs = unique_counts(H[:, 0].astype(np.int64) * h3 + fan)[0]  # (vertex of corner, its fan)
    fans = np.bincount(pairs // h3, minlength=n)
    return np.flatnonzero(fans > 1)
