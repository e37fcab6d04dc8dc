"""Poisson-disk vertex sampling and the local-function matrix ``U`` (thesis §7.1, docs/maths.md §6).

``poisson_disk_sample`` picks vertices in random order, accepting a vertex
when no accepted sample lies within distance ``radius`` (Dijkstra along edges,
cut off at ``radius``): the result is a maximal ``radius``-separated set, so
every vertex is within ``radius`` of a sample.

``local_functions`` builds ``U`` (n × d, sparse): columns are the bumps
``ũ_i(v) = (2/ρ³) r³ − (3/ρ²) r² + 1`` for ``r ≤ ρ`` (eq. 7.1.1 with docs/maths.md note 3),
rows normalised to sum to 1 (a partition of unity).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
from jaxtyping import Float, Int

from .descriptors import edge_graph
from .io import Mesh, face_areas

__all__ = ["poisson_disk_sample", "LocalFunctions", "local_functions", "bump"]


def _radius_for(m: Mesh, n_samples: int) -> float:
    """Disk radius giving about ``n_samples`` samples.

    A hexagonal packing at spacing ``r`` gives one sample per ``(√3/2)·r²`` of
    area; random maximal Poisson-disk sets reach about 0.68 of that density
    (measured on the shared meshes), hence the factor ``√0.68``.
    """
    area = float(face_areas(m.vertices, m.faces).sum())
    return float(np.sqrt(0.68 * area / (n_samples * np.sqrt(3.0) / 2.0)))


def poisson_disk_sample(
    m: Mesh,
    *,
    n_samples: int | None = None,
    radius: float | None = None,
    seed: int = 0,
    graph: sp.csr_array | None = None,
) -> tuple[Int[np.ndarray, " d"], float]:
    """Poisson-disk sample of vertices (§7.1).

    Args:
      m: mesh with ``n`` vertices.
      n_samples: approximate number of samples wanted (sets ``radius``), or
      radius: the minimum (edge-path) distance between samples.
      seed: random order of candidates.
      graph: edge-length graph (``edge_graph(m)``), if already built.

    Returns:
      ``(samples (d,), radius)``: sorted by acceptance order.
    """
    if (n_samples is None) == (radius is None):
        raise ValueError("give exactly one of n_samples or radius")
    if radius is None:
        if not 1 <= n_samples <= m.n_vertices:
            raise ValueError(f"n_samples must be in [1, {m.n_vertices}], got {n_samples}")
        radius = _radius_for(m, n_samples)
    # symmetric once here, so that every Dijkstra below runs as directed (scipy would
    # symmetrise the graph again on each of the d calls with directed=False)
    G = edge_graph(m) if graph is None else sp.csr_array(graph.maximum(graph.T))
    order = np.random.default_rng(seed).permutation(m.n_vertices)
    covered = np.zeros(m.n_vertices, dtype=bool)
    samples = []
    pos = 0
    n = m.n_vertices
    while True:  # one iteration per accepted sample (d ≪ n)
        rest = ~covered[order[pos:]]
        if not rest.any():
            break
        pos += int(np.argmax(rest))
        s = int(order[pos])
        samples.append(s)
        d = csgraph.dijkstra(G, directed=True, indices=s, limit=radius)
        covered |= d < radius
        covered[s] = True
        if pos >= n:
            break
    return np.asarray(samples, dtype=np.int64), float(radius)


def bump(r: Float[np.ndarray, "..."], rho: float) -> Float[np.ndarray, "..."]:
    """``ũ(r) = (2/ρ³) r³ − (3/ρ²) r² + 1`` for ``0 ≤ r ≤ ρ``, else 0 (eq. 7.1.1, docs/maths.md note 3)."""
    r = np.asarray(r, dtype=np.float64)
    t = r / rho
    return np.where(r <= rho, 2.0 * t**3 - 3.0 * t**2 + 1.0, 0.0)


class LocalFunctions(NamedTuple):
    """Result of ``local_functions``.

    Attributes:
      U: ``(n, d)`` CSR, rows sum to 1 (partition of unity).
      samples: ``(d,)`` sample vertex of each column.
      rho: support radius.
      coverage: ``(d,)`` number of *other* samples inside each function's support.
    """

    U: sp.csr_array
    samples: Int[np.ndarray, " d"]
    rho: float
    coverage: Int[np.ndarray, " d"]


def _limited_distances(
    G: sp.csr_array, sources: np.ndarray, limit: float, chunk: int = 64
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Triplets ``(source position, vertex, distance)`` for all Dijkstra distances ``≤ limit``.

    ``G`` must be symmetric (``edge_graph``); it is searched as a directed graph. Sources are
    processed in chunks so that the dense ``(chunk, n)`` block stays small.
    """
    rows, cols, vals = [], [], []
    for start in range(0, sources.size, chunk):
        D = csgraph.dijkstra(G, directed=True, indices=sources[start : start + chunk], limit=limit)
        r, c = np.nonzero(D <= limit)
        rows.append(r + start)
        cols.append(c)
        vals.append(D[r, c])
    return tuple(np.concatenate(x) for x in (rows, cols, vals))


def _choose_rho(G: sp.csr_array, samples: np.ndarray, reach: float, target: int) -> float:
    """Median over samples of the distance to the ``target``-th nearest other sample."""
    d = samples.size
    pos_of = np.full(G.shape[0], -1, dtype=np.int64)
    pos_of[samples] = np.arange(d)
    for _ in range(12):  # widen the search until most samples see enough others
        r, c, v = _limited_distances(G, samples, reach)
        is_sample = pos_of[c] >= 0
        r, v = r[is_sample], v[is_sample]
        counts = np.bincount(r, minlength=d) - 1
        if np.median(counts) > target or d - 1 <= target:
            break
        reach *= 2.0
    order = np.lexsort((v, r))  # by source, then distance
    r, v = r[order], v[order]
    start = np.searchsorted(r, np.arange(d))
    ok = counts >= target + 1
    if not ok.any():
        return reach
    kth = v[start[ok] + target]  # entry 0 is the sample itself (distance 0)
    return float(np.median(kth))


def local_functions(
    m: Mesh,
    *,
    n_samples: int | None = None,
    samples: Int[np.ndarray, " d"] | None = None,
    rho: float | None = None,
    cover: tuple[int, int] = (7, 15),
    seed: int = 0,
) -> LocalFunctions:
    """The local-function matrix ``U`` of §7.1 (n × d, sparse).

    Args:
      m: mesh with ``n`` vertices.
      n_samples: approximate sample count for ``poisson_disk_sample``, or
      samples: the ``d`` sample vertices.
      rho: support radius; default: the median over samples of the distance to
        the ``(lo+hi)/2``-th nearest other sample, for ``cover = (lo, hi)``
        (thesis: each function covers 7–15 other samples), and at least the
        Poisson radius so that every vertex is covered. Distances are Dijkstra
        distances along edges, computed only up to the radius (``limit=``).
      seed: sampling seed.

    Returns:
      ``LocalFunctions(U, samples, rho, coverage)``.
    """
    G = edge_graph(m)
    r_pd = 0.0
    if samples is None:
        if n_samples is None:
            raise ValueError("give n_samples or samples")
        samples, r_pd = poisson_disk_sample(m, n_samples=n_samples, seed=seed, graph=G)
    samples = np.asarray(samples, dtype=np.int64)
    d = samples.size
    if rho is None:
        target = (cover[0] + cover[1]) // 2
        rho = _choose_rho(G, samples, 4.0 * max(r_pd, _radius_for(m, d)), target)
        rho = max(rho, r_pd * (1 + 1e-9))
    col, vert, dist = _limited_distances(G, samples, rho)
    keep = dist < rho  # ũ(ρ) = 0
    col, vert, dist = col[keep], vert[keep], dist[keep]
    val = bump(dist, rho)
    rowsum = np.bincount(vert, weights=val, minlength=m.n_vertices)
    if np.any(rowsum <= 0):
        k = int(np.sum(rowsum <= 0))
        raise ValueError(
            f"{k} vertices lie outside every local function's support (rho = {rho:.3e}); "
            "increase rho or the number of samples"
        )
    U = sp.csr_array(sp.coo_array((val / rowsum[vert], (vert, col)), shape=(m.n_vertices, d)))
    pos_of = np.full(m.n_vertices, -1, dtype=np.int64)
    pos_of[samples] = np.arange(d)
    coverage = np.bincount(col[pos_of[vert] >= 0], minlength=d) - 1
    return LocalFunctions(U=U, samples=samples, rho=float(rho), coverage=coverage.astype(np.int64))
