"""PNG contact sheet of per-vertex fields on a triangle mesh (matplotlib, Agg backend).

Every panel is an orthographic view of the mesh coloured by one field with a
diverging colormap centred at 0 (symmetric limits ``±max|field|`` per field),
Lambert-shaded from the viewer direction. Two ways of drawing a panel:

``"polygons"``
    flat-shaded faces in a ``PolyCollection`` (face colour = mean of its vertex
    values), painter's-algorithm ordered. Exact facets, but every panel keeps its
    own ``(m, 3, 2)`` polygon list alive until the figure is saved: memory and
    time grow like ``k · views · m`` (11.7 GB at 407K vertices, k = 10).
``"raster"``
    a numpy z-buffer rasteriser (:func:`rasterize`): each view is scan-converted
    once, in chunks of faces bounded by a sample budget, into a per-sample winning
    face and its barycentric coordinates; each field then costs a per-sample
    interpolation and a colour-table look-up, pasted pixel for pixel into the Agg
    canvas that drew the titles (same layout as ``tight_layout`` gives the
    polygons). Peak extra memory is ``O(n)`` for the projected vertices plus
    ``O(pixels + chunk)``, whatever ``m`` is (``bench/RESULTS_render_memory.md``).
    ``SUPERSAMPLE²`` samples per pixel, averaged: silhouettes are antialiased, and
    colours are interpolated linearly in each face (the P1 field itself).

``method="raster"`` is the default: it is faster at every mesh size measured (100
faces up), its memory does not grow with ``k · m``, and on the built-in demo mesh it
gives the same layout with smoother colours and antialiased outlines.
``method="polygons"`` keeps the former drawing (facets with face-mean colours).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["VIEWS", "contact_sheet", "rasterize"]

#: (azimuth, elevation) in degrees
VIEWS: tuple[tuple[float, float], ...] = ((0.0, 15.0), (180.0, 15.0), (90.0, 60.0))

#: samples per output pixel along each axis in the raster path
SUPERSAMPLE = 2

#: at most about this many candidate (face, sample) pairs are tested at once (~150 bytes each)
_SAMPLE_BUDGET = 1 << 16
#: faces per chunk when counting candidate samples
_FACE_CHUNK = 1 << 15


def _rotation(azim: float, elev: float) -> np.ndarray:
    """``(3, 3)`` rotation: rotate by azimuth about z, then tilt by elevation about x."""
    a, e = np.deg2rad(azim), np.deg2rad(elev)
    rz = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    # look along -y after rotation: screen x = x, screen y = z, depth = y
    rx = np.array([[1.0, 0.0, 0.0], [0.0, np.cos(e), -np.sin(e)], [0.0, np.sin(e), np.cos(e)]])
    return rx @ rz


def _shade(normal: np.ndarray) -> np.ndarray:
    """Lambert factor ``0.55 + 0.45 |n̂_y|`` for face normals ``(f, 3)`` in view coordinates (viewer along −y)."""
    norm = np.maximum(np.linalg.norm(normal, axis=1), 1e-300)
    return 0.55 + 0.45 * np.abs(normal[:, 1]) / norm


def _project(vertices: np.ndarray, centre: np.ndarray, azim: float, elev: float) -> np.ndarray:
    """``(n, 3)`` view coordinates ``R (v − centre)`` (screen x, depth, screen y), one ``(n, 3)`` allocation."""
    rot = _rotation(azim, elev)
    p = vertices @ rot.T
    p -= rot @ centre
    return p


def _frame(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Data limits ``(lo, hi)`` (each ``(2,)``, screen x and y) of projected vertices ``p (n, 3)``, 3 % padding."""
    lo = np.array([p[:, 0].min(), p[:, 2].min()])
    hi = np.array([p[:, 0].max(), p[:, 2].max()])
    pad = 0.03 * float(np.max(hi - lo))
    return lo - pad, hi + pad


# ---------------------------------------------------------------------------------------------------------------
# polygons: the former drawing, memory O(k · views · m)


def _draw_polygons(ax, p: np.ndarray, faces: np.ndarray, values: np.ndarray, vmax: float, cmap: str) -> None:
    from matplotlib import colormaps
    from matplotlib.collections import PolyCollection
    from matplotlib.colors import Normalize

    tri = p[faces]                                   # (m, 3, 3)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    order = np.argsort(-tri[:, :, 1].mean(axis=1))   # far (large y) first
    xy = tri[order][:, :, [0, 2]]
    colors = colormaps[cmap](Normalize(-vmax, vmax)(values[faces].mean(axis=1)[order]))
    colors[:, :3] *= _shade(normal[order])[:, None]
    ax.add_collection(PolyCollection(xy, facecolors=colors, edgecolors="none", antialiased=False))


# ---------------------------------------------------------------------------------------------------------------
# raster: a chunked numpy z-buffer


class Raster:
    """One view scan-converted: which face is nearest at each sample and where in it.

    ``face (H, W)`` int64, ``-1`` for background; ``bary (H, W, 3)`` float32 barycentric
    coordinates of the sample centre in that face; ``shade (H, W)`` float32 Lambert factor
    (0 on background). Row 0 is the bottom of the picture.
    """

    __slots__ = ("face", "bary", "shade")

    def __init__(self, face: np.ndarray, bary: np.ndarray, shade: np.ndarray) -> None:
        self.face, self.bary, self.shade = face, bary, shade


def _candidate_groups(xy: np.ndarray, faces: np.ndarray, width: int, height: int, face_ids: np.ndarray):
    """Split ``face_ids`` (rows of ``faces (m, 3)``) into runs whose bounding boxes hold about
    ``_SAMPLE_BUDGET`` sample centres at most (a single face's box may exceed it).

    ``xy (n, 2)`` pixel coordinates (sample ``(i, j)`` has centre ``(i + ½, j + ½)``). Yields
    ``(ids, x0, y0, bw, count)`` per run: first sample column/row, box width and sample count per face.
    """
    tri = faces[face_ids]
    a, b, c = xy[tri[:, 0]], xy[tri[:, 1]], xy[tri[:, 2]]   # (c, 2) each
    lo = np.ceil(np.minimum(np.minimum(a, b), c) - 0.5).astype(np.int64)
    hi = np.floor(np.maximum(np.maximum(a, b), c) - 0.5).astype(np.int64)
    np.maximum(lo, 0, out=lo)
    hi[:, 0] = np.minimum(hi[:, 0], width - 1)
    hi[:, 1] = np.minimum(hi[:, 1], height - 1)
    size = np.maximum(hi - lo + 1, 0)
    count = size[:, 0] * size[:, 1]
    keep = count > 0
    ids, lo, bw, count = face_ids[keep], lo[keep], size[keep, 0], count[keep]
    group = np.cumsum(count) // _SAMPLE_BUDGET
    cuts = np.flatnonzero(np.diff(group)) + 1
    for a, b in zip(np.r_[0, cuts], np.r_[cuts, len(ids)]):
        yield ids[a:b], lo[a:b, 0], lo[a:b, 1], bw[a:b], count[a:b]


def _plane_coefficients(xy: np.ndarray, depth: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per face ``tri (g, 3)``: barycentric coordinates ``w_a, w_b`` and depth ``z`` as affine functions
    of the sample point, ``(g, 9)`` rows ``[∂w_a/∂x, ∂w_a/∂y, w_a(0), ∂w_b/∂x, …, z(0)]``; and ``(g,)``
    which faces have a non-zero projected area.

    ``w_a(s) = edge(b, c, s) / edge(b, c, a)`` with ``edge(p, q, s) = (q − p) × (s − p)`` (2-D cross product),
    and ``z = z_c + w_a (z_a − z_c) + w_b (z_b − z_c)``.
    """
    a, b, c = xy[tri[:, 0]], xy[tri[:, 1]], xy[tri[:, 2]]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    ok = np.abs(area) > 1e-12
    inv = np.where(ok, 1.0 / np.where(ok, area, 1.0), 0.0)
    coef = np.empty((len(tri), 9))
    for row, (p, q) in enumerate(((b, c), (c, a))):           # w_a from edge (b, c), w_b from edge (c, a)
        dx, dy = q[:, 0] - p[:, 0], q[:, 1] - p[:, 1]
        coef[:, 3 * row] = -dy * inv
        coef[:, 3 * row + 1] = dx * inv
        coef[:, 3 * row + 2] = (dy * p[:, 0] - dx * p[:, 1]) * inv
    za, zb, zc = depth[tri[:, 0]], depth[tri[:, 1]], depth[tri[:, 2]]
    coef[:, 6:] = zc[:, None] * np.array([0.0, 0.0, 1.0]) + coef[:, 0:3] * (za - zc)[:, None] \
        + coef[:, 3:6] * (zb - zc)[:, None]
    return coef, ok


def rasterize(points: np.ndarray, faces: np.ndarray, width: int, height: int) -> Raster:
    """Z-buffer scan conversion of triangles under an orthographic projection.

    ``points (n, 3)``: column 0 and 1 are pixel coordinates (x right, y up; the sample
    ``(row j, column i)`` is at ``(i + ½, j + ½)``), column 2 is depth (smaller is nearer).
    ``faces (m, 3)``. A sample belongs to a face when its three barycentric coordinates are
    ``≥ −1e-9`` (shared edges are covered twice, never missed, so a closed surface has no
    pinholes however small its triangles); the nearest face wins.

    Faces are processed in chunks: memory is ``O(width · height)`` for the buffers plus
    ``O(_FACE_CHUNK + _SAMPLE_BUDGET)`` per chunk, independent of ``m``.
    """
    points = np.asarray(points, dtype=np.float64)
    faces = np.asarray(faces)
    xy, depth = points[:, :2], points[:, 2]
    npix = width * height
    zbuf = np.full(npix, np.inf)
    face = np.full(npix, -1, dtype=np.int64)
    bary = np.zeros((npix, 3), dtype=np.float32)
    for start in range(0, len(faces), _FACE_CHUNK):
        chunk = np.arange(start, min(start + _FACE_CHUNK, len(faces)))
        for ids, x0, y0, bw, count in _candidate_groups(xy, faces, width, height, chunk):
            coef, ok = _plane_coefficients(xy, depth, faces[ids])
            if not ok.all():                         # degenerate (edge-on) faces cover nothing
                ids, x0, y0, bw, count, coef = ids[ok], x0[ok], y0[ok], bw[ok], count[ok], coef[ok]
            # sample s of face r: local index t = s − first sample of r, column t % bw, row t // bw
            rep = np.repeat(np.arange(len(ids)), count)
            t = np.arange(len(rep)) - np.repeat(np.cumsum(count) - count, count)
            bw_s = bw[rep]
            px = x0[rep] + t % bw_s
            py = y0[rep] + t // bw_s
            del t, bw_s
            sx, sy = px + 0.5, py + 0.5
            cs = coef[rep]                           # (s, 9): rows of w_a, w_b, z as affine functions of (x, y)
            wa = cs[:, 0] * sx + cs[:, 1] * sy + cs[:, 2]
            wb = cs[:, 3] * sx + cs[:, 4] * sy + cs[:, 5]
            wc = 1.0 - wa - wb
            inside = np.flatnonzero((wa >= -1e-9) & (wb >= -1e-9) & (wc >= -1e-9))
            z = (cs[:, 6] * sx + cs[:, 7] * sy + cs[:, 8])[inside]
            del cs, sx, sy
            rep, wa, wb, wc = rep[inside], wa[inside], wb[inside], wc[inside]
            pix = (py * width + px)[inside]
            np.minimum.at(zbuf, pix, z)
            win = z <= zbuf[pix]                      # nearest so far (ties: any of them)
            pix = pix[win]
            face[pix] = ids[rep[win]]
            bary[pix] = np.stack([wa[win], wb[win], wc[win]], axis=1)
    hit = face >= 0
    shade = np.zeros(npix, dtype=np.float32)
    if hit.any():
        tri = points[faces[face[hit]]]               # (hits, 3, 3), pixel units in x, y
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        shade[hit] = _shade(normal[:, [0, 2, 1]])   # view coordinates: depth is the y axis
    return Raster(face.reshape(height, width), bary.reshape(height, width, 3), shade.reshape(height, width))


class _Painter:
    """Colours one rasterised view for many fields: the covered samples' corner vertices, weights, shades
    and output pixels are gathered once (``O(samples)``); each field then costs one gather, one colour-table
    look-up and a per-pixel sum (``np.bincount``) over the ``ss × ss`` samples of each pixel."""

    def __init__(self, raster: Raster, faces: np.ndarray, ss: int) -> None:
        height, width = raster.face.shape
        self.shape, self.ss = (height // ss, width // ss), ss
        hit = np.flatnonzero(raster.face >= 0)
        self.corners = faces[raster.face.ravel()[hit]]                       # (hits, 3)
        self.weights = raster.bary.reshape(-1, 3)[hit]                       # (hits, 3) float32
        self.shade = raster.shade.ravel()[hit]
        self.pixel = (hit // width // ss) * self.shape[1] + (hit % width) // ss
        self.covered = np.bincount(self.pixel, minlength=self.shape[0] * self.shape[1])

    def rgba(self, field: np.ndarray, vmax: float, lut: np.ndarray) -> np.ndarray:
        """``(H/ss, W/ss, 4)`` float straight-alpha image, row 0 at the bottom: the ``lut (N, 4)`` colour of
        ``field`` mapped from ``[−vmax, vmax]`` as ``Normalize`` + ``Colormap`` do, × shade, averaged over the
        covered samples of each pixel; alpha = the covered fraction."""
        val = np.einsum("ij,ij->i", field[self.corners], self.weights)
        n = len(lut)
        idx = np.clip(((val / vmax + 1.0) * (0.5 * n)).astype(np.int64), 0, n - 1)
        npix = self.shape[0] * self.shape[1]
        img = np.empty((npix, 4))
        for ch in range(3):
            img[:, ch] = np.bincount(self.pixel, weights=lut[idx, ch] * self.shade, minlength=npix)
        img[:, :3] /= np.maximum(self.covered, 1)[:, None]
        img[:, 3] = self.covered * (1.0 / self.ss**2)
        return img.reshape(*self.shape, 4)


def _layout(fig, titles: list[str], k: int, nv: int, aspect: float) -> tuple[float, float, float, float, float]:
    """Panel grid in figure pixels, as ``fig.tight_layout()`` places ``k × nv`` axis-free subplots with left titles.

    ``aspect``: height / width of the first view's data box (its panel carries the title).
    Returns ``(pad, width, height, title_space, title_pad)``: every panel box is ``width × height``;
    column ``i`` starts at ``pad + i (width + pad)``, row ``j`` (0 on top) at
    ``pad + (k − 1 − j)(height + pad + title_space)`` from the bottom. ``title_space`` is what the
    title (pad + ascent) sticks out above the box once the picture is fitted into it, centred.
    """
    import matplotlib as mpl

    px = fig.dpi / 72.0
    pad = 1.08 * float(mpl.rcParams["font.size"]) * px          # tight_layout's default pad
    title_pad = float(mpl.rcParams["axes.titlepad"]) * px
    renderer = fig.canvas.get_renderer()
    probe = fig.text(0.0, 0.0, "", fontsize=8, va="baseline")
    ascent = 0.0
    for t in titles:
        probe.set_text(t)
        ascent = max(ascent, probe.get_window_extent(renderer).y1)
    probe.remove()
    width = (fig.bbox.width - (nv + 1) * pad) / nv
    height0 = (fig.bbox.height - pad - k * pad) / k             # box height without title space
    above = title_pad + ascent
    # title on top of a centred picture of height h_pic in a box of height h = height0 − space:
    # (h + h_pic)/2 + above ≤ h + space
    h_pic = aspect * width                                      # if the picture is width-limited
    space = max(0.0, 2.0 * above - (height0 - h_pic))
    if h_pic > height0 - space:                                 # height-limited: the picture fills the box
        space = above
    return pad, width, height0 - space, space, title_pad


def _fit(lo: np.ndarray, hi: np.ndarray, x0: float, y0: float, width: float, height: float, ss: int):
    """Equal-aspect, centred placement of the data box ``[lo, hi]`` in a pixel box.

    Returns ``(ix, iy, iw, ih, origin, size)``: the integer pixel rectangle, and the data point at its
    lower-left corner and the data length of one sample (``ss`` samples per pixel).
    """
    span = hi - lo
    scale = min(width / span[0], height / span[1])              # pixels per data unit
    iw, ih = max(1, int(round(span[0] * scale))), max(1, int(round(span[1] * scale)))
    ix, iy = int(round(x0 + 0.5 * (width - iw))), int(round(y0 + 0.5 * (height - ih)))
    size = float(max(span[0] / iw, span[1] / ih)) / ss
    origin = 0.5 * (lo + hi) - 0.5 * ss * size * np.array([iw, ih])
    return ix, iy, iw, ih, origin, size


def _sheet_polygons(fig, vertices, faces, fields, titles, views, cmap, vmax) -> None:
    """The exact matplotlib drawing: one ``Axes`` per panel holding a ``PolyCollection`` of all faces."""
    k, nv = fields.shape[1], len(views)
    centre = vertices.mean(axis=0)
    for j in range(k):
        for i, (azim, elev) in enumerate(views):
            ax = fig.add_subplot(k, nv, j * nv + i + 1)
            p = _project(vertices, centre, azim, elev)
            _draw_polygons(ax, p, faces, np.asarray(fields[:, j], dtype=np.float64), vmax[j], cmap)
            lo, hi = _frame(p)
            ax.set_xlim(lo[0], hi[0])
            ax.set_ylim(lo[1], hi[1])
            ax.set_aspect("equal")
            ax.axis("off")
            if i == 0:
                ax.set_title(titles[j], fontsize=8, loc="left")
    fig.tight_layout()


def _sheet_raster(fig, vertices, faces, fields, titles, views, cmap, vmax) -> np.ndarray:
    """The sheet as an ``(H, W, 4)`` uint8 RGBA array, row 0 on top, in the layout of :func:`_sheet_polygons`.

    The titles are ``fig.text`` drawn by the Agg canvas; the pictures are pasted into its pixel buffer.
    Each view is rasterised once and shared by all fields.
    """
    from matplotlib import colormaps

    k, nv = fields.shape[1], len(views)
    ss = SUPERSAMPLE
    lut = colormaps[cmap](np.arange(colormaps[cmap].N)).astype(np.float32)
    centre = vertices.mean(axis=0)
    lo, hi = _frame(_project(vertices, centre, *views[0]))
    pad, width, height, title_space, title_pad = _layout(fig, titles, k, nv, float((hi - lo)[1] / (hi - lo)[0]))
    boxes = []                                                   # per view: pixel rectangle and data frame
    for i, (azim, elev) in enumerate(views):
        lo, hi = _frame(_project(vertices, centre, azim, elev)) if i else (lo, hi)
        boxes.append(_fit(lo, hi, pad + i * (width + pad), 0.0, width, height, ss))
    row_y = [int(round(pad + (k - 1 - j) * (height + pad + title_space))) for j in range(k)]
    ix, iy, _, ih, _, _ = boxes[0]
    for j in range(k):
        fig.text(ix / fig.bbox.width, (row_y[j] + iy + ih + title_pad) / fig.bbox.height, titles[j], fontsize=8,
                 ha="left", va="baseline")
    fig.canvas.draw()
    sheet = np.array(fig.canvas.buffer_rgba())                  # (H, W, 4) uint8, row 0 on top
    for (azim, elev), (ix, iy, iw, ih, origin, size) in zip(views, boxes):
        p = _project(vertices, centre, azim, elev)
        # sample coordinates x, y and depth (the rotated y axis; smaller is nearer), all in sample lengths
        p[:, 0] = (p[:, 0] - origin[0]) / size
        p[:, 1], p[:, 2] = (p[:, 2] - origin[1]) / size, p[:, 1] / size
        painter = _Painter(rasterize(p, faces, iw * ss, ih * ss), faces, ss)
        del p
        for j in range(k):
            img = painter.rgba(np.asarray(fields[:, j], dtype=np.float64), vmax[j], lut)[::-1]
            top = sheet.shape[0] - (row_y[j] + iy + ih)
            under = sheet[top:top + ih, ix:ix + iw].astype(np.float32) / 255.0
            alpha = img[..., 3:]
            under[..., :3] = img[..., :3] * alpha + under[..., :3] * (1.0 - alpha)
            under[..., 3:] = alpha + under[..., 3:] * (1.0 - alpha)
            sheet[top:top + ih, ix:ix + iw] = np.round(255.0 * np.clip(under, 0.0, 1.0))
    return sheet


# ---------------------------------------------------------------------------------------------------------------


def contact_sheet(path: Path, vertices: np.ndarray, faces: np.ndarray, fields: np.ndarray, *,
                  titles: list[str] | None = None, views: tuple[tuple[float, float], ...] = VIEWS,
                  cmap: str = "RdBu_r", dpi: int = 80, method: str = "raster") -> None:
    """Write a PNG to ``path`` (a path or binary file): one row per field (column of ``fields (n, k)``),
    one column per view.

    Colours: ``cmap`` with limits ``±max|field|`` (0 is white for ``RdBu_r``).
    ``method``: ``"raster"`` (memory ``O(n + pixels)``) or ``"polygons"`` (the former
    ``PolyCollection`` drawing, memory ``O(k · len(views) · m)``); see the module docstring.
    The image is ``2.4 · len(views) × 2.2 · k`` inches at ``dpi`` either way.
    """
    # an explicit Agg canvas: no pyplot, no global backend switch, no display needed
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if method not in ("raster", "polygons"):
        raise ValueError(f"method must be 'raster' or 'polygons', got {method!r}")
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    fields = np.asarray(fields)                       # columns are converted one at a time: no (n, k) float64 copy
    fields = fields.reshape(vertices.shape[0], -1)
    k, nv = fields.shape[1], len(views)
    titles = list(titles) if titles else [f"mode {j}" for j in range(k)]
    vmax = [float(np.max(np.abs(fields[:, j]))) or 1.0 for j in range(k)]
    fig = Figure(figsize=(2.4 * nv, 2.2 * k), dpi=dpi)
    FigureCanvasAgg(fig)
    if method == "polygons":
        _sheet_polygons(fig, vertices, faces, fields, titles, views, cmap, vmax)
        fig.savefig(path, dpi=dpi)
    else:
        # what savefig does with the Agg buffer, after the pictures are pasted into it; the sheet is opaque,
        # and RGB at zlib level 3 encodes ~3× faster than RGBA at level 6, in a smaller file
        from PIL import Image

        sheet = _sheet_raster(fig, vertices, faces, fields, titles, views, cmap, vmax)
        Image.fromarray(np.ascontiguousarray(sheet[..., :3])).save(path, format="png", dpi=(dpi, dpi),
                                                                   compress_level=3)
