"""PNG contact sheet of per-vertex fields on a triangle mesh (matplotlib, Agg backend).

Each field is drawn as flat-shaded faces (``PolyCollection``, face colour = mean
of its vertex values) under an orthographic view, painter's-algorithm ordered,
with a diverging colormap centred at 0 (symmetric limits per field).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["VIEWS", "contact_sheet"]

#: (azimuth, elevation) in degrees
VIEWS: tuple[tuple[float, float], ...] = ((0.0, 15.0), (180.0, 15.0), (90.0, 60.0))


def _rotation(azim: float, elev: float) -> np.ndarray:
    """``(3, 3)`` rotation: rotate by azimuth about z, then tilt by elevation about x."""
    a, e = np.deg2rad(azim), np.deg2rad(elev)
    rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    # look along -y after rotation: screen x = x, screen y = z, depth = y
    rx = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(e), -np.sin(e)], [0.0, np.sin(e), np.cos(e)]])
    return rx @ rz


def _draw(ax, vertices: np.ndarray, faces: np.ndarray, values: np.ndarray, azim: float, elev: float,
          vmax: float, cmap: str) -> None:
    from matplotlib import colormaps
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import Normalize

    p = (vertices - vertices.mean(axis=0)) @ _rotation(azim, elev).T
    tri = p[faces]                                   # (m, 3, 3)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    depth = tri[:, :, 1].mean(axis=1)
    order = np.argsort(-depth)                        # far (large y) first
    xy = tri[order][:, :, [0, 2]]
    face_val = values[faces].mean(axis=1)[order]
    colors = colormaps[cmap](Normalize(-vmax, vmax)(face_val))
    # simple Lambert shading from the viewer direction (−y)
    n_unit = normal[order] / np.maximum(np.linalg.norm(normal[order], axis=1, keepdims=True), 1e-300)
    shade = 0.55 + 0.45 * np.abs(n_unit[:, 1])
    colors[:, :3] *= shade[:, None]
    ax.add_collection(PolyCollection(xy, facecolors=colors, edgecolors="none", antialiased=False))
    lo, hi = p[:, [0, 2]].min(axis=0), p[:, [0, 2]].max(axis=0)
    pad = 0.03 * float(np.max(hi - lo))
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal")
    ax.axis("off")


def contact_sheet(path: Path, vertices: np.ndarray, faces: np.ndarray, fields: np.ndarray, *,
                  titles: list[str] | None = None, views: tuple[tuple[float, float], ...] = VIEWS,
                  cmap: str = "RdBu_r", dpi: int = 80) -> None:
    """Write a PNG: one row per field (column of ``fields (n, k)``), one column per view.

    Colours: ``cmap`` with limits ``±max|field|`` (0 is white for ``RdBu_r``).
    """
    # an explicit Agg canvas: no pyplot, no global backend switch, no display needed
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fields = np.asarray(fields, dtype=np.float64).reshape(vertices.shape[0], -1)
    k, nv = fields.shape[1], len(views)
    fig = Figure(figsize=(2.4 * nv, 2.2 * k))
    FigureCanvasAgg(fig)
    for j in range(k):
        vmax = float(np.max(np.abs(fields[:, j]))) or 1.0
        for i, (azim, elev) in enumerate(views):
            ax = fig.add_subplot(k, nv, j * nv + i + 1)
            _draw(ax, vertices, faces, fields[:, j], azim, elev, vmax, cmap)
            if i == 0:
                ax.set_title(titles[j] if titles else f"mode {j}", fontsize=8, loc="left")
    fig.tight_layout()
    fig.savefig(path, dpi=dpi)
