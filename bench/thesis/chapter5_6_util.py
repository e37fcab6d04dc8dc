"""Helpers of ``bench.thesis.chapter5_6``: mesh pairs with a known correspondence and the figures.

Pairs (``twisted``, ``decimated``, ``refined``) are built from one mesh, so the ground truth is known:
a vertex-permuted copy twisted about its main axis (same connectivity, near-isometric: the thesis's
horse pairs), a decimated copy (fewer vertices, different triangulation: its fish / head pairs) and a
copy whose faces on one half are split 1-to-3 at their centroids (same surface, twice the vertex
density there: only the graph changes, the thesis's explanation of the GL basis's errors, §5.3.2).
"""

from __future__ import annotations

import io

import numpy as np
from scipy.spatial import cKDTree

import mesh

__all__ = ["decimate", "twist", "refine_half", "principal_axes", "sheet_figure", "marker_plot"]


def decimate(m: mesh.Mesh, n_target: int) -> mesh.Mesh | None:
    """Quadric decimation (``fast_simplification``) to about ``n_target`` vertices, or None when every
    aggressiveness tried gives a non-manifold or degenerate mesh (thin features, genus)."""
    import fast_simplification

    if n_target >= m.n_vertices:
        return m
    for agg in (7, 5, 3):
        V, F = fast_simplification.simplify(np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces),
                                            target_reduction=1.0 - n_target / m.n_vertices, agg=agg)
        try:
            out = mesh.load((np.asarray(V, dtype=np.float64), np.asarray(F)), warn=False)
        except mesh.MeshError:
            continue
        if out.n_vertices <= 1.15 * n_target and out.n_components == m.n_components:
            return out
    return None


def principal_axes(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(centre (3,), axes (3, 3))``: rows are the principal directions, largest spread first."""
    c = V.mean(axis=0)
    return c, np.linalg.svd(V - c, full_matrices=False)[2]


def twist(V: np.ndarray, frame: tuple[np.ndarray, np.ndarray], angle: float) -> np.ndarray:
    """Twist about the main axis of ``frame``: the rotation grows linearly from 0 to ``angle`` (radians)
    along it (a bend of the limbs; near-isometric for moderate angles)."""
    c, axes = frame
    P = (V - c) @ axes.T
    span = np.ptp(P[:, 0]) or 1.0
    th = angle * np.clip((P[:, 0] - P[:, 0].min()) / span, 0.0, 1.0)
    y = P[:, 1] * np.cos(th) - P[:, 2] * np.sin(th)
    z = P[:, 1] * np.sin(th) + P[:, 2] * np.cos(th)
    return c + np.stack([P[:, 0], y, z], axis=1) @ axes


def refine_half(m: mesh.Mesh) -> tuple[mesh.Mesh, np.ndarray]:
    """The faces whose centroid lies beyond the median along the main axis split 1-to-3 at the centroid
    (conforming: no edge is split, the surface is unchanged). Returns ``(mesh, gt)``: ``gt[i]`` is the
    vertex of ``m`` nearest to vertex ``i`` (the old vertices keep their index)."""
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    cen = V[F].mean(axis=1)
    c, axes = principal_axes(V)
    s = (cen - c) @ axes[0]
    split = s > np.median(s)
    new = np.arange(V.shape[0], V.shape[0] + int(split.sum()))
    a, b, d = F[split].T
    faces = np.vstack([F[~split], np.stack([a, b, new], 1), np.stack([b, d, new], 1), np.stack([d, a, new], 1)])
    out = mesh.load((np.vstack([V, cen[split]]), faces), warn=False)
    return out, cKDTree(V).query(out.vertices)[1]


def sheet_figure(vertices, faces, grids: list[tuple[str, list, list, list]]):
    """A matplotlib figure stacking ``stiefel_cmm.cli.render.grid_sheet`` pictures: each grid is
    ``(title, fields (list of (n, c) arrays, one per row), row titles, column titles)``."""
    import matplotlib.pyplot as plt
    from PIL import Image

    from stiefel_cmm.cli.render import grid_sheet

    images = []
    for _, fields, rows, cols in grids:
        buf = io.BytesIO()
        grid_sheet(buf, vertices, faces, fields, row_titles=rows, col_titles=cols, dpi=75, panel=1.2)
        buf.seek(0)
        images.append(np.asarray(Image.open(buf).convert("RGB")))
    width = max(im.shape[1] for im in images)
    heights = [im.shape[0] + 30 for im in images]
    fig = plt.figure(figsize=(width / 100, sum(heights) / 100), dpi=100)
    top = 1.0
    for (title, *_), im, h in zip(grids, images, heights):
        frac = h / sum(heights)
        ax = fig.add_axes((0.0, top - frac, im.shape[1] / width, frac * (im.shape[0] / h)))
        ax.imshow(im, interpolation="none")
        ax.set_axis_off()
        fig.text(0.01, top - 0.2 * (30 / sum(heights)), title, fontsize=9, va="top")
        top -= frac
    return fig


def marker_plot(ax, values: dict, ylabel: str, labels=("unrefined", "refined"), log: bool = False,
                linthresh: float | None = None) -> None:
    """The thesis's marker charts: ``values[pair][basis] = (first, second)`` — one group per pair, one
    offset per basis, the first value a filled marker, the second an open one; ``log``: log scale
    (symmetric-log, linear below ``linthresh``, when that is given: exact zeros stay visible)."""
    pairs = list(values)
    basis_names = list(next(iter(values.values())))
    markers = "osD^vP*X"
    width = 0.7 / max(len(basis_names), 1)
    for j, b in enumerate(basis_names):
        colour = f"C{j}"
        for i, p in enumerate(pairs):
            if b not in values[p]:
                continue
            v0, v1 = values[p][b]
            x = i - 0.35 + (j + 0.5) * width
            ax.plot([x - 0.1 * width], [v0], markers[j % 8], color=colour, label=f"{b} ({labels[0]})" if i == 0 else None)
            ax.plot([x + 0.1 * width], [v1], markers[j % 8], mfc="none", color=colour,
                    label=f"{b} ({labels[1]})" if i == 0 else None)
    ax.set_xticks(range(len(pairs)), pairs)
    ax.set_ylabel(ylabel)
    if log and linthresh:
        ax.set_yscale("symlog", linthresh=linthresh)
        ax.set_ylim(bottom=0.0)
    elif log:
        ax.set_yscale("log")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=6, ncol=2)
