"""Poisson-disk vertex sampling and the local-function matrix ``U`` (thesis §7.1, docs/maths.md §6).

``poisson_disk_sample`` picks vertices in random order, accepting a vertex
when no accepted sample lies within distance ``radius`` (Dijkstra along edges,
cut off at ``radius``): the result is a maximal ``radius``-separated set, so
every vertex is within ``radius`` of a sample.

``local_functions`` builds ``U`` (n × d, sparse): column ``i`` is the bump of thesis
eq. 7.1.1 as corrected in docs/maths.md note 3, with a radius ``ρ_i`` per sample,

    ũ_i(v) = (2/ρ_i³) r³ − (3/ρ_i²) r² + 1   for r = r(s_i, v) < ρ_i,   else 0,

and ``U_vi = ũ_i(v) / Σ_j ũ_j(v)`` (rows sum to 1: a partition of unity). ``r`` is the
``local_distance`` (Euclidean-corrected Dijkstra by default), ``ρ_i`` is chosen so that the
support of ``ũ_i`` holds between ``lo`` and ``hi`` other samples (``cover = (7, 15)``, as in the thesis).
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
from jaxtyping import Float, Int

from stiefel.validation import check_count, check_positive, is_integer

from .descriptors import edge_graph
from .errors import MeshError
from .io import Mesh, face_areas

__all__ = [
    "DISTANCES",
    "SLACK",
    "SamplingError",
    "poisson_disk_sample",
    "LocalFunctions",
    "local_functions",
    "local_distance",
    "bump",
]

#: the options of ``local_functions(distance=)``; the first is the default
DISTANCES = ("corrected", "dijkstra")

#: ``c`` of the corrected distance ``r = max(|x_v − x_s|, D/c)``: the largest ratio of edge path to
#: straight line on a flat grid of right triangles (two legs around the missing diagonal: 2/√2)
SLACK = float(np.sqrt(2.0))


class SamplingError(MeshError):
    """Bad input to ``poisson_disk_sample`` or ``local_functions``: a count, radius, ``cover`` pair,
    ``distance`` option or sample index out of range, or a radius too small to cover every vertex."""


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

    Raises:
      SamplingError: not exactly one of ``n_samples``/``radius``, ``n_samples`` not in ``[1, n]``,
        or ``radius`` not positive and finite.
    """
    if (n_samples is None) == (radius is None):
        raise SamplingError("give exactly one of n_samples or radius")
    if radius is None:
        check_count("n_samples", n_samples, 1, m.n_vertices, high_label=f"n = {m.n_vertices}", error=SamplingError)
        radius = _radius_for(m, n_samples)
    radius = check_positive("radius", radius, error=SamplingError)
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


def bump(r: Float[np.ndarray, "..."], rho: float | Float[np.ndarray, "..."]) -> Float[np.ndarray, "..."]:
    """``ũ(r) = (2/ρ³) r³ − (3/ρ²) r² + 1`` for ``0 ≤ r ≤ ρ``, else 0 (eq. 7.1.1, docs/maths.md note 3).

    ``rho`` is a scalar or broadcasts against ``r`` (one radius per sample).
    """
    r = np.asarray(r, dtype=np.float64)
    t = np.minimum(r / rho, 1.0)  # ũ(ρ) = 0; keeps r = inf (outside any search) NaN-free
    # 2t³ − 3t² + 1 = (1 − t)²(1 + 2t): the factored form stays > 0 for every t < 1 (no cancellation)
    return np.where(r <= rho, (1.0 - t) ** 2 * (1.0 + 2.0 * t), 0.0)


class LocalFunctions(NamedTuple):
    """Result of ``local_functions``.

    Attributes:
      U: ``(n, d)`` CSR, rows sum to 1 (partition of unity).
      samples: ``(d,)`` sample vertex of each column.
      rho: a summary support radius: the median of ``radii`` (the radius itself for ``rho=``).
      coverage: ``(d,)`` number of *other* samples inside each function's support.
      radii: ``(d,)`` support radius ``ρ_i`` of each column.
      distance: the distance ``r`` of eq. 7.1.1, ``"corrected"`` or ``"dijkstra"``.
    """

    U: sp.csr_array
    samples: Int[np.ndarray, " d"]
    rho: float
    coverage: Int[np.ndarray, " d"]
    radii: Float[np.ndarray, " d"]
    distance: str


def _local_triplets(
    G: sp.csr_array,
    V: Float[np.ndarray, "n 3"],
    sources: Int[np.ndarray, " p"],
    limits: Float[np.ndarray, " p"],
    distance: str,
    chunk: int = 64,
) -> tuple[Int[np.ndarray, " t"], Int[np.ndarray, " t"], Float[np.ndarray, " t"]]:
    """Triplets ``(source position, vertex, r)`` for every ``r ≤ limits[source]``.

    ``r`` is ``local_distance``'s: the Dijkstra distance ``D`` (``"dijkstra"``), or
    ``max(|x_v − x_s|, D/SLACK)`` (``"corrected"``; then the search runs to ``SLACK·limit``).
    ``G`` must be symmetric (``edge_graph``); it is searched as a directed graph. Sources are
    processed in chunks of similar limits so that the dense ``(chunk, n)`` block stays small.
    """
    slack = SLACK if distance == "corrected" else 1.0
    order = np.argsort(limits, kind="stable")
    rows, cols, vals = [], [], []
    for start in range(0, sources.size, chunk):
        pos = order[start : start + chunk]
        lim = slack * limits[pos]
        D = csgraph.dijkstra(G, directed=True, indices=sources[pos], limit=float(lim.max()))
        r, c = np.nonzero(np.isfinite(D) & (D <= lim[:, None]))
        dist = D[r, c]
        if slack != 1.0:
            euclid = np.linalg.norm(V[c] - V[sources[pos[r]]], axis=1)
            dist = np.maximum(euclid, dist / slack)
        keep = dist <= limits[pos[r]]
        rows.append(pos[r[keep]])
        cols.append(c[keep])
        vals.append(dist[keep])
    return tuple(np.concatenate(x) for x in (rows, cols, vals))


def local_distance(
    m: Mesh,
    sources: int | Sequence[int] | Int[np.ndarray, " p"],
    *,
    limit: float = np.inf,
    distance: str = "corrected",
) -> Float[np.ndarray, "n p"] | Float[np.ndarray, " n"]:
    """The distance ``r`` of eq. 7.1.1 from each source vertex, ``inf`` beyond ``limit``.

    ``"dijkstra"``: ``D(s, v)``, the shortest path along edges (``geodesic_distance``'s default).
    Edge paths zig-zag, so ``D`` overestimates the geodesic distance (up to ``√2`` on a grid of
    right triangles); the thesis (§7.1) corrects it with the Euclidean distance, exact for nearby
    points on a smooth surface. ``"corrected"``:

        r(s, v) = max(|x_v − x_s|, D(s, v) / c),   c = SLACK = √2,

    which is ``|x_v − x_s|`` wherever the edge path is at most ``c`` times longer than the
    straight line (everywhere on a flat grid, so there it is the exact distance), and ``D/c`` where
    the surface folds back (two sheets close in space, far apart along the surface), so such points
    stay out of a support of radius ``ρ`` unless ``D < cρ``. Always ``|x_v − x_s| ≤ r ≤ D``.

    Args:
      m: mesh with ``n`` vertices.
      sources: a vertex index or ``p`` indices.
      limit: distances above it are ``inf`` (the search stops at ``c·limit``).
      distance: ``"corrected"`` or ``"dijkstra"`` (``DISTANCES``).

    Returns:
      ``(n,)`` for a single source, else ``(n, p)``.
    """
    _check_distance(distance)
    single = np.ndim(sources) == 0
    src = _check_vertices("sources", sources, m.n_vertices, distinct=False)
    limit = check_positive("limit", limit, finite=False, error=SamplingError)
    col, vert, r = _local_triplets(edge_graph(m), m.vertices, src, np.full(src.size, limit), distance)
    out = np.full((m.n_vertices, src.size), np.inf)
    out[vert, col] = r
    return out[:, 0] if single else out


def _check_distance(distance) -> None:
    if not isinstance(distance, str) or distance not in DISTANCES:
        raise SamplingError(f"distance must be one of {DISTANCES}, got {distance!r}")


def _check_vertices(name: str, idx, n: int, distinct: bool = True) -> Int[np.ndarray, " p"]:
    """``idx`` as a 1-D int64 array of vertices in ``[0, n)`` (``distinct``: no repeats)."""
    a = np.atleast_1d(np.asarray(idx))
    if a.ndim != 1 or a.size == 0 or not np.issubdtype(a.dtype, np.integer):
        raise SamplingError(f"{name} must be a non-empty 1-D array of vertex indices, got {idx!r}")
    a = a.astype(np.int64)
    if a.min() < 0 or a.max() >= n:
        raise SamplingError(f"{name} must lie in [0, {n}) (vertex indices), got min {a.min()}, max {a.max()}")
    if distinct and np.unique(a).size != a.size:
        raise SamplingError(f"{name} has repeated vertices ({a.size - np.unique(a).size} repeats): "
                            "the local functions would be linearly dependent")
    return a


def _check_cover(cover, d: int | None) -> tuple[int, int]:
    """``(lo, hi)`` with ``hi`` capped at ``d − 1``; ``d = None`` checks the pair only."""
    ok = isinstance(cover, (tuple, list)) and len(cover) == 2 and all(is_integer(c) and c >= 1 for c in cover)
    if not ok or int(cover[0]) > int(cover[1]):
        raise SamplingError(f"cover must be a pair (lo, hi) of integers with 1 ≤ lo ≤ hi (thesis: (7, 15)), "
                            f"got {cover!r}")
    lo, hi = int(cover[0]), int(cover[1])
    if d is None:
        return lo, hi
    if lo > d - 1:
        raise SamplingError(f"cover = {cover!r} asks each function to cover at least {lo} other samples, but there "
                            f"are only d − 1 = {d - 1}: use more samples or a smaller cover")
    return lo, min(hi, d - 1)


def _nearest_samples(G, V, samples, pos_of, labels, hi, reach, distance) -> Float[np.ndarray, "d h"]:
    """``(d, hi + 1)``: distances ``δ_1 ≤ … ≤ δ_{hi+1}`` to each sample's nearest other samples
    (``inf`` past the samples of its connected component); the search widens until they are known."""
    d = samples.size
    in_comp = np.bincount(labels[samples])[labels[samples]] - 1  # other samples in the same component
    need = np.minimum(hi + 1, in_comp)
    delta = np.full((d, hi + 1), np.inf)
    todo = np.flatnonzero(need > 0)
    while todo.size:
        col, vert, r = _local_triplets(G, V, samples[todo], np.full(todo.size, reach), distance)
        other = (pos_of[vert] >= 0) & (pos_of[vert] != todo[col])
        col, r = col[other], r[other]
        order = np.lexsort((r, col))  # by source, then distance
        col, r = col[order], r[order]
        rank = np.arange(col.size) - np.searchsorted(col, col)
        first = rank <= hi
        delta[todo[col[first]], rank[first]] = r[first]
        # every other sample with r ≤ reach was found (its D ≤ c·r ≤ c·reach), so the first need ones are right
        done = np.bincount(col, minlength=todo.size) >= need[todo]
        todo = todo[~done]
        reach *= 2.0
    return delta


def _radii(delta: Float[np.ndarray, "d h"], lo: int, hi: int) -> Float[np.ndarray, " d"]:
    """Per-sample radii ``ρ_i`` covering between ``lo`` and ``hi`` other samples (0 where a sample has none).

    A radius in ``(δ_j, δ_{j+1}]`` covers exactly ``j`` others; ``m_j = (δ_j + δ_{j+1})/2`` is the middle of
    that gap, and count ``j`` is admissible when ``lo ≤ j ≤ hi`` and ``δ_j < δ_{j+1}``. The global radius
    ``ρ_g`` is the median over samples of ``m_t``, ``t = (lo + hi) // 2``, and ``ρ_i = clip(ρ_g, m_first,
    m_last)`` over sample ``i``'s admissible counts, so radii stay as equal as the cover allows. A sample with
    no admissible count (fewer than ``lo`` other samples in its component, or ties across the range) gets
    the ``m_j`` of the count nearest ``t``.
    """
    d = delta.shape[0]
    t = (lo + hi) // 2
    j = np.arange(1, hi + 1)
    low, up = delta[:, :-1], delta[:, 1:]
    gap = np.isfinite(low) & (low < up)
    mid = 0.5 * (low + np.where(np.isfinite(up), up, 2.0 * low))  # last sample of a component: 1.5·δ_j
    inside = (j >= lo) & (j <= hi)
    score = np.where(gap, 2.0 * np.abs(j - t) + (j > t) + 1e3 * ~inside, np.inf)
    best = np.argmin(score, axis=1)
    nearest = np.where(np.isfinite(score[np.arange(d), best]), mid[np.arange(d), best], 0.0)
    adm = gap & inside
    rho_g = float(np.median(nearest[nearest > 0])) if np.any(nearest > 0) else 0.0
    first = np.where(adm, mid, np.inf).min(axis=1)
    last = np.where(adm, mid, -np.inf).max(axis=1)
    return np.where(adm.any(axis=1), np.clip(rho_g, first, np.maximum(first, last)), nearest)


def _cover_every_vertex(G, V, samples, pos_of, radii, distance) -> Float[np.ndarray, " d"]:
    """Radii enlarged so that each vertex lies inside the support of its nearest sample (by Dijkstra)."""
    D, _, src = csgraph.dijkstra(G, directed=True, indices=samples, min_only=True, return_predecessors=True)
    reached = src >= 0
    v = np.flatnonzero(reached)
    s = src[reached]
    r = D[reached]
    if distance == "corrected":
        r = np.maximum(np.linalg.norm(V[v] - V[s], axis=1), r / SLACK)
    cell = np.zeros(samples.size)
    np.maximum.at(cell, pos_of[s], r)
    return np.maximum(radii, cell * (1.0 + 1e-9) + 1e-300)


def local_functions(
    m: Mesh,
    *,
    n_samples: int | None = None,
    samples: Int[np.ndarray, " d"] | None = None,
    rho: float | None = None,
    cover: tuple[int, int] = (7, 15),
    distance: str = "corrected",
    seed: int = 0,
) -> LocalFunctions:
    """The local-function matrix ``U`` of §7.1 (n × d, sparse).

    Column ``i`` is ``ũ_i(v) = (2/ρ_i³) r³ − (3/ρ_i²) r² + 1`` for ``r = r(s_i, v) < ρ_i`` (thesis
    eq. 7.1.1 with the factor ``r²`` of docs/maths.md note 3), else 0; rows are normalised,
    ``U_vi = ũ_i(v) / Σ_j ũ_j(v)``, so ``Σ_i U_vi = 1`` (a partition of unity).

    Args:
      m: mesh with ``n`` vertices.
      n_samples: approximate sample count for ``poisson_disk_sample``, or
      samples: the ``d`` sample vertices (distinct).
      rho: one support radius ``ρ`` for every function (the thesis's global ρ); then ``cover`` is
        not used, and a vertex outside every support is an error. Default: one radius ``ρ_i`` per
        sample so that its support holds between ``lo`` and ``hi`` other samples, ``cover = (lo, hi)``
        (thesis: 7 and 15) — the median over samples of the radius reaching the ``(lo + hi) // 2``-th
        nearest other sample, moved just inside each sample's admissible range where it falls outside
        — then enlarged where needed so that every vertex lies in the support of its nearest sample
        (the partition of unity needs every row non-zero; this could push a function past ``hi``, which
        never happened on the shared or shipped meshes). A single global ρ cannot meet the range at
        every sample: the former median ρ left 1–6 others at the worst sample of each shared mesh.
        Measured (8 meshes, d = 80–370): keeping the radii as equal as the range allows gives a better
        conditioned ``U`` than giving every sample exactly ``(lo + hi) // 2`` others (cond 49–60 vs 89–98
        with Dijkstra, 75–108 vs 87–251 corrected) at the same restricted-eigenvalue accuracy.
      cover: ``(lo, hi)``, integers ``1 ≤ lo ≤ hi``, ``lo ≤ d − 1`` (``hi`` is capped at ``d − 1``).
      distance: the distance ``r`` (``local_distance``): ``"corrected"`` (default) — the Euclidean
        distance, bounded below by the edge-path distance over ``√2`` so that folds stay apart (thesis
        §7.1: "a Euclidean correction of the geodesic distance as calculated via Dijkstra's
        algorithm"); ``"dijkstra"`` — the edge-path distance (the former behaviour). Default chosen by
        measurement (2026-11, 2-core CPU; same samples and radius rule for both): the mean relative
        error of the restricted eigenvalues ``λ̄_2 … λ̄_20`` (Algorithm 7) fell on 8 of 9 meshes
        (horse_976 0.050 → 0.029, bumpy.off 0.031 → 0.008, bunny 0.028 → 0.019, hand_868 0.063 →
        0.056; fandisk level, 0.022 vs 0.023), and the ``FastCMM`` objective (k = 6, μ = 0.01 n,
        uniform weights, eigen start) fell by 1–1.6 % on 13 of 18 mesh × d runs (bumpy.off 241.7 →
        237.7) but rose on the coarse hands (hand_868: 167.3 → 170.7) and on decimated-knight at
        d = 80 (+1.5 %), whose fingers are a few edges round. Cost: the search runs to ``√2·ρ_i``,
        1.5–2× the time (fandisk, n = 7229: 0.31 → 0.48 s).
      seed: sampling seed.

    Returns:
      ``LocalFunctions(U (n, d), samples (d,), rho, coverage (d,), radii (d,), distance)``;
      ``rho`` is the median of ``radii``.

    Raises:
      SamplingError: neither ``n_samples`` nor ``samples``; bad ``samples``; ``cover`` not a pair of
        positive integers ``lo ≤ hi`` or ``lo > d − 1``; unknown ``distance``; ``rho`` not positive and
        finite; with ``rho=``, a vertex outside every support.
    """
    _check_distance(distance)
    _check_cover(cover, None)
    G = edge_graph(m)
    n = m.n_vertices
    r_pd = 0.0
    if samples is None:
        if n_samples is None:
            raise SamplingError("give n_samples or samples")
        samples, r_pd = poisson_disk_sample(m, n_samples=n_samples, seed=seed, graph=G)
    samples = _check_vertices("samples", samples, n)
    d = samples.size
    pos_of = np.full(n, -1, dtype=np.int64)
    pos_of[samples] = np.arange(d)
    if rho is not None:
        radii = np.full(d, check_positive("rho", rho, error=SamplingError))
    else:
        lo, hi = _check_cover(cover, d)
        labels = csgraph.connected_components(G, directed=False)[1]
        reach = 4.0 * max(r_pd, _radius_for(m, d))
        delta = _nearest_samples(G, m.vertices, samples, pos_of, labels, hi, reach, distance)
        radii = _cover_every_vertex(G, m.vertices, samples, pos_of, _radii(delta, lo, hi), distance)
    col, vert, dist = _local_triplets(G, m.vertices, samples, radii, distance)
    keep = dist < radii[col]  # ũ(ρ) = 0
    col, vert, dist = col[keep], vert[keep], dist[keep]
    val = bump(dist, radii[col])
    rowsum = np.bincount(vert, weights=val, minlength=n)
    if np.any(rowsum <= 0):
        k = int(np.sum(rowsum <= 0))
        raise SamplingError(
            f"{k} vertices lie outside every local function's support (rho = {np.median(radii):.3e}); "
            "increase rho or the number of samples"
        )
    U = sp.csr_array(sp.coo_array((val / rowsum[vert], (vert, col)), shape=(n, d)))
    coverage = np.bincount(col[pos_of[vert] >= 0], minlength=d) - 1
    return LocalFunctions(U=U, samples=samples, rho=float(np.median(radii)), coverage=coverage.astype(np.int64),
                          radii=radii, distance=distance)
