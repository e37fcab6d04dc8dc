"""Descriptor functions on meshes (thesis §4.1, docs/maths.md §8).

Point-based functions (Def. 4.1.1) at landmarks — geodesic distance
(GEODISTS), DELTAS, NORMDIST — the multi-scale HKS and WKS, CONSTANT and VERTS,
and the extremal and central landmark points (Def. 4.1.3–4.1.4).

Distances are measured on the mesh as given; pass an area-normalised mesh
(``mesh.scaled_to_unit_area``) to use the thesis's radii (``r = 0.01``,
``r = 0.1``), which assume total area 1 (Rem. 2.5.31).
"""

from __future__ import annotations

from typing import Literal, Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
from jaxtyping import Float, Int

from .io import Mesh, edges_of, face_areas

__all__ = [
    "edge_graph",
    "geodesic_distance",
    "geodists",
    "deltas",
    "normdist",
    "hks",
    "hks_times",
    "wks",
    "wks_energies",
    "constant",
    "vertex_positions",
    "extremal_points",
    "central_points",
    "landmarks",
    "scaled_to_unit_area",
]


def scaled_to_unit_area(m: Mesh) -> Mesh:
    """A copy of ``m`` with vertices scaled by ``1/sqrt(total area)`` (Rem. 2.5.31)."""
    from dataclasses import replace

    s = 1.0 / np.sqrt(float(face_areas(m.vertices, m.faces).sum()))
    return replace(m, vertices=m.vertices * s)


def edge_graph(m: Mesh) -> sp.csr_array:
    """Symmetric ``(n, n)`` CSR matrix of Euclidean edge lengths ``|v_i − v_j|``."""
    e = edges_of(m.faces)
    w = np.linalg.norm(m.vertices[e[:, 0]] - m.vertices[e[:, 1]], axis=1)
    n = m.n_vertices
    G = sp.csr_array(
        sp.coo_array((np.concatenate([w, w]), (np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]]))), shape=(n, n))
    )
    return G


def geodesic_distance(
    m: Mesh,
    sources: int | Sequence[int] | Int[np.ndarray, " p"],
    *,
    method: Literal["dijkstra", "heat", "fast_marching"] = "dijkstra",
    limit: float = np.inf,
) -> Float[np.ndarray, "n p"] | Float[np.ndarray, " n"]:
    """Distance from each source vertex to every vertex.

    Args:
      m: mesh with ``n`` vertices.
      sources: a vertex index or ``p`` indices.
      method: ``"dijkstra"`` — shortest paths along edges (the thesis's
        approximate geodesic distance, §4.1; scipy.sparse.csgraph), honours
        ``limit`` (``inf`` beyond it); ``"heat"`` — heat method (potpourri3d);
        ``"fast_marching"`` — fast marching (potpourri3d). Unreachable vertices
        (another component) get ``inf`` for Dijkstra.
      limit: Dijkstra only: stop at this distance.

    Returns:
      ``(n,)`` for a single source, else ``(n, p)``.
    """
    single = np.ndim(sources) == 0
    src = np.atleast_1d(np.asarray(sources, dtype=np.int64))
    if src.size and (src.min() < 0 or src.max() >= m.n_vertices):
        raise IndexError(f"source vertices must be in [0, {m.n_vertices}), got {src.tolist()}")
    if method == "dijkstra":
        D = csgraph.dijkstra(edge_graph(m), directed=False, indices=src, limit=limit).T
    elif method in ("heat", "fast_marching"):
        import potpourri3d as pp3d

        if method == "heat":
            solver = pp3d.MeshHeatMethodDistanceSolver(m.vertices, m.faces)
        else:
            solver = pp3d.MeshFastMarchingDistanceSolver(m.vertices, m.faces)
        cols = []
        for s in src:
            cols.append(solver.compute_distance(int(s)) if method == "heat" else solver.compute_distance([[(int(s), [])]]))
        D = np.stack(cols, axis=1)
    else:
        raise ValueError(f"unknown method {method!r}; choose 'dijkstra', 'heat' or 'fast_marching'")
    return D[:, 0] if single else D


def geodists(m: Mesh, sources: Sequence[int] | Int[np.ndarray, " p"]) -> Float[np.ndarray, "n p"]:
    """GEODISTS (§4.1): Dijkstra distance from each landmark, scaled to ``[0, 1]`` per column."""
    D = geodesic_distance(m, np.atleast_1d(sources))
    finite = np.where(np.isfinite(D), D, np.nan)
    return D / np.nanmax(finite, axis=0, keepdims=True)


def deltas(dist: Float[np.ndarray, "n ..."], r: float = 0.01) -> Float[np.ndarray, "n ..."]:
    """DELTAS (§4.1): ``exp(−(d/r)²)/(|r|√π)`` for ``d ≤ r``, else 0 (thesis: ``r = 0.01``)."""
    d = np.asarray(dist)
    return np.where(d <= r, np.exp(-((d / r) ** 2)) / (abs(r) * np.sqrt(np.pi)), 0.0)


def normdist(dist: Float[np.ndarray, "n ..."], r: float = 0.1) -> Float[np.ndarray, "n ..."]:
    """NORMDIST (§4.1): ``exp(−(d/(2σ))²)`` for ``d ≤ r``, else 0, with ``σ = max_v d / 3``.

    The thesis's factor ``1/√(2πσ²)`` is dropped by the scaling to ``f(p) = 1``.
    ``σ`` is taken per column over the finite distances.
    """
    d = np.asarray(dist, dtype=np.float64)
    sigma = np.nanmax(np.where(np.isfinite(d), d, np.nan), axis=0, keepdims=True) / 3.0
    return np.where(d <= r, np.exp(-((d / (2.0 * sigma)) ** 2)), 0.0)


def _positive(evals: np.ndarray, evecs: np.ndarray, rtol: float = 1e-8):
    """Drop the (near-)zero eigenvalues of the kernel; HKS/WKS use ``λ > 0``."""
    keep = evals > rtol * np.max(np.abs(evals))
    return evals[keep], evecs[:, keep]


def hks_times(evals: Float[np.ndarray, " k"], n_times: int = 30) -> Float[np.ndarray, " t"]:
    """HKS times (§4.1, Sun et al. §5): log-spaced on ``[4 ln10/λ_k, 4 ln10/λ_10]``.

    ``λ_10`` is the 10th eigenvalue, ``λ_k`` the largest computed (thesis: k = 300).
    """
    lam = np.sort(np.asarray(evals))
    if lam.size < 10:
        raise ValueError(f"HKS times need at least 10 eigenvalues, got {lam.size}")
    lo = np.log10(4.0 * np.log(10.0) / abs(lam[-1]))
    hi = np.log10(4.0 * np.log(10.0) / abs(lam[9]))
    return np.logspace(lo, hi, n_times)


def hks(
    evals: Float[np.ndarray, " k"],
    evecs: Float[np.ndarray, "n k"],
    times: Float[np.ndarray, " t"] | int = 30,
) -> Float[np.ndarray, "n t"]:
    """Heat kernel signature ``HKS(v, t) = Σ_i e^{−λ_i t} φ_i(v)²`` (§4.1), shape ``(n, t)``.

    ``times`` is an array or a count for ``hks_times`` (thesis: 30 times from 300 eigenpairs).
    Sums over all given eigenpairs including the kernel.
    """
    evals = np.asarray(evals)
    t = hks_times(evals, times) if np.ndim(times) == 0 else np.asarray(times)
    return (np.asarray(evecs) ** 2) @ np.exp(-np.outer(np.maximum(evals, 0.0), t))


def wks_energies(
    evals: Float[np.ndarray, " k"], n_energies: int = 100, alpha: float = 7.0
) -> tuple[Float[np.ndarray, " e"], float]:
    """WKS log-energies and width (§4.1, Aubry et al. §2.3).

    With ``s = α(ln λ_k − ln λ_2)/N`` (``λ_2`` the first positive eigenvalue,
    ``N = n_energies``) the energies are ``N`` points linearly spaced on
    ``[ln λ_2 + 2s, ln λ_k − 2s]`` and ``σ = α(ln λ_k − ln λ_2)/(N + 4α)``. (The
    thesis writes ``ln λ_2 − ln λ_k``, which is negative; the magnitude is meant.)
    """
    lam = np.sort(np.asarray(evals))
    lam = lam[lam > 1e-8 * np.max(np.abs(lam))]
    if lam.size < 2:
        raise ValueError("WKS needs at least two positive eigenvalues")
    e_lo, e_hi = np.log(lam[0]), np.log(lam[-1])
    s = alpha * (e_hi - e_lo) / n_energies
    lo, hi = e_lo + 2 * s, e_hi - 2 * s
    if not lo < hi:
        raise ValueError(
            f"WKS energy interval is empty for n_energies={n_energies}, alpha={alpha}: "
            f"need n_energies > 4·alpha = {4 * alpha:g} (thesis: 100 energies)"
        )
    sigma = alpha * (e_hi - e_lo) / (n_energies + 4 * alpha)
    return np.linspace(lo, hi, n_energies), float(sigma)


def wks(
    evals: Float[np.ndarray, " k"],
    evecs: Float[np.ndarray, "n k"],
    n_energies: int = 100,
    alpha: float = 7.0,
) -> Float[np.ndarray, "n e"]:
    """Wave kernel signature (§4.1): ``WKS(x, e) = Σ_k φ_k(x)² C_ke / Σ_k C_ke``, ``C_ke = exp(−(e − ln λ_k)²/(2σ²))``.

    Uses the positive eigenvalues only. Shape ``(n, n_energies)``.
    """
    lam, phi = _positive(np.asarray(evals), np.asarray(evecs))
    e, sigma = wks_energies(lam, n_energies, alpha)
    C = np.exp(-((e[None, :] - np.log(lam)[:, None]) ** 2) / (2 * sigma**2))  # (k, e)
    return (phi**2 @ C) / C.sum(axis=0, keepdims=True)


def constant(m: Mesh) -> Float[np.ndarray, "n 1"]:
    """CONSTANT (§4.1): the function 1, shape ``(n, 1)``."""
    return np.ones((m.n_vertices, 1))


def vertex_positions(m: Mesh) -> Float[np.ndarray, "n 3"]:
    """VERTS (§4.1): the three coordinate functions, shape ``(n, 3)``."""
    return np.array(m.vertices, copy=True)


def extremal_points(m: Mesh) -> Int[np.ndarray, " p"]:
    """Extremal vertices (Def. 4.1.3): for each coordinate, a vertex attaining its max and its min.

    Returns the sorted unique indices (at most 6; ties broken by lowest index).
    """
    V = m.vertices
    return np.unique(np.concatenate([np.argmax(V, axis=0), np.argmin(V, axis=0)]))


def central_points(m: Mesh) -> Int[np.ndarray, " p"]:
    """Central vertices (Def. 4.1.4): ``|p_i − r_i| ≤ |v_i − r_i|`` for all ``i`` and all ``v``.

    ``r`` is the bounding-box centre. Such a vertex need not exist; then the
    vertex closest to ``r`` (Euclidean) is returned as the relaxation.
    Returns a sorted index array (length ≥ 1).
    """
    V = m.vertices
    r = 0.5 * (V.max(axis=0) + V.min(axis=0))
    dev = np.abs(V - r)
    best = dev.min(axis=0)
    exact = np.flatnonzero(np.all(dev <= best, axis=1))
    if exact.size:
        return exact
    return np.array([int(np.argmin(np.linalg.norm(V - r, axis=1)))])


def landmarks(m: Mesh) -> Int[np.ndarray, " p"]:
    """The landmark set 𝒫 of §4.1: all extremal and central points, sorted, unique."""
    return np.unique(np.concatenate([extremal_points(m), central_points(m)]))
