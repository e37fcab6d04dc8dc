"""PNG contact sheets of per-vertex fields on a triangle mesh (numpy rasteriser, FreeType text, zlib).

:func:`contact_sheet`: one row per field, one column per view. :func:`grid_sheet`: rows × columns of fields
(e.g. smoothings × modes), one view each. Both:

* orient the mesh by the principal axes of its surface (:func:`stiefel_cmm.cli.render_views.principal_frame`:
  largest spread horizontal, second vertical, smallest towards the viewer — a flat patch is seen
  face-on), or with ``up="y"`` etc. a forced vertical axis; the views are front and back along the
  smallest axis plus an oblique view from above (only front and back for a near-flat mesh);
* colour with a diverging map centred at 0 (``RdBu_r``: −max blue, 0 white, +max red), Lambert-shaded
  from the viewer, with a colour bar per row and labelled rows and columns.

Drawing: each view is rasterised once (:func:`rasterize`, a numpy z-buffer, ``SUPERSAMPLE²`` samples
per pixel) into a sparse ``(pixels, n)`` matrix that averages a field over each pixel's samples, so
all fields of a view cost one sparse product, a colour-table look-up and a paste into a ``uint8``
canvas (``method="polygons"``: flat facets, each face coloured by the mean of its vertex values, as the
former ``PolyCollection`` drawing showed them). Back faces of closed, consistently oriented surfaces are
culled. Text is matplotlib's DejaVu Sans drawn by FreeType through PIL (glyph clusters cached) straight
into the canvas; there is no ``Figure``, and the default colormap is built here, so a sheet does not
import matplotlib at all (that import alone costs about twice the sheet). The PNG is written by
:func:`png_bytes` (PIL, zlib level 1). Costs against the former renderer: ``docs/benchmarks/render-cost.md``.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Sequence

import numpy as np

from .raster import Raster, ViewPixels, edges, orientation, rasterize
from .render_layout import _INK, Box, Label, Layout, draw_text, sheet_layout
from .render_views import (FLAT_VIEWS, UP_CHOICES, VIEWS, Frame, RenderOptionError, check_up, principal_frame, project, resolve_views)

__all__ = ["FLAT_VIEWS", "SUPERSAMPLE", "UP_CHOICES", "VIEWS", "Label", "Layout", "Raster", "RenderOptionError",
           "check_up", "contact_sheet", "grid_sheet", "png_bytes", "principal_frame", "rasterize", "sheet_layout"]

#: samples per output pixel along each axis
SUPERSAMPLE = 2
#: colour of NaN values
_NAN = (0.6, 0.6, 0.6)


def _vmax(field: np.ndarray) -> float:
    """``max |field|`` over its finite values; 1 if there are none or all are 0."""
    a = np.abs(np.asarray(field, dtype=np.float64))
    return float(np.max(a, where=np.isfinite(a), initial=0.0)) or 1.0


def _tick(v: float) -> str:
    """A colour-bar limit: 3 significant digits, a true minus sign."""
    text = f"{abs(v):.3g}" if 1e-3 <= abs(v) < 1e4 or v == 0 else f"{abs(v):.2e}"
    return text if v == 0 else ("−" if v < 0 else "+") + text


# ---------------------------------------------------------------------------------------------------------------
# painting


#: ColorBrewer's RdBu, red to blue in 11 steps (8-bit RGB): matplotlib's ``RdBu`` interpolates them linearly
_RDBU = ((103, 0, 31), (178, 24, 43), (214, 96, 77), (244, 165, 130), (253, 219, 199), (247, 247, 247),
         (209, 229, 240), (146, 197, 222), (67, 147, 195), (33, 102, 172), (5, 48, 97))


@functools.lru_cache(maxsize=8)
def _lut(cmap: str) -> np.ndarray:
    """``(N, 3)`` float32 RGB table of the matplotlib colormap ``cmap``; ``RdBu`` and ``RdBu_r`` are built here
    (the same 256 entries) so that the default sheet does not import matplotlib."""
    if cmap in ("RdBu", "RdBu_r"):
        stops = np.asarray(_RDBU if cmap == "RdBu" else _RDBU[::-1]) / 255.0
        x = np.linspace(0.0, 1.0, len(stops))
        t = np.linspace(0.0, 1.0, 256)
        lut = np.stack([np.interp(t, x, stops[:, ch]) for ch in range(3)], axis=1).astype(np.float32)
    else:
        from matplotlib import colormaps

        try:
            cm = colormaps[cmap]
        except (KeyError, ValueError, TypeError):
            raise RenderOptionError(f"unknown colormap {cmap!r} (any matplotlib colormap name, e.g. 'RdBu_r')") \
                from None
        lut = cm(np.arange(cm.N))[:, :3].astype(np.float32)
    lut.flags.writeable = False
    return lut


def _colour(values: np.ndarray, vmax, lut: np.ndarray) -> np.ndarray:
    """``(…, 3)`` RGB of ``values (…)`` mapped from ``[−vmax, vmax]`` (``vmax`` broadcast against ``values``) as
    ``Normalize`` + ``Colormap`` do; NaN grey."""
    n = len(lut)
    t = values * (0.5 * n / np.asarray(vmax, dtype=np.float64))
    t += 0.5 * n
    bad = np.isnan(t)
    if bad.any():
        t[bad] = 0.0
    np.clip(t, 0, n - 1, out=t)
    rgb = lut[t.astype(np.intp)]
    if bad.any():
        rgb[bad] = _NAN
    return rgb


def _paint(canvas: np.ndarray, view: ViewPixels, values: np.ndarray, vmax: np.ndarray, boxes: Sequence[Box],
           lut: np.ndarray) -> None:
    """Composite column ``j`` of ``values (p, q)`` (a field at the view's covered pixels, limits ``±vmax[j]``)
    into ``boxes[j]`` of the white canvas ``(H, W, 3)`` uint8, the picture centred in the box: pixel value
    ``255 (1 − cover) + 255 cover · shade · rgb``."""
    h, w = view.shape
    row, col = np.divmod(view.pixel, w)
    flat = canvas.reshape(-1, 3)
    offset = row * canvas.shape[1] + col
    base = (255.0 * (1.0 - view.cover) + 0.5).astype(np.float32)[:, None, None]      # + ½: round on astype
    gain = (255.0 * view.cover * view.shade).astype(np.float32)[:, None, None]
    step = 16                                                   # columns at a time: memory O(16 p)
    for j0 in range(0, values.shape[1], step):
        rgb = _colour(values[:, j0:j0 + step], vmax[j0:j0 + step], lut)            # (p, q, 3)
        rgb *= gain
        rgb += base
        out = np.minimum(rgb, 255.0, out=rgb).astype(np.uint8)
        for j, box in enumerate(boxes[j0:j0 + step]):
            corner = (box.y + (box.h - h) // 2) * canvas.shape[1] + box.x + (box.w - w) // 2
            flat[corner + offset] = out[:, j]


def _draw_bar(canvas: np.ndarray, box: Box, lut: np.ndarray) -> None:
    """Vertical colour bar, +max at the top, −max at the bottom, with an outline and three ticks."""
    t = np.linspace(1.0, -1.0, box.h)
    rgb = _colour(t, 1.0, lut)
    canvas[box.y:box.y + box.h, box.x:box.x + box.w] = np.round(255.0 * rgb[:, None, :]).astype(np.uint8)
    ink = np.asarray(_INK, np.uint8)
    canvas[box.y, box.x:box.x + box.w] = canvas[box.y + box.h - 1, box.x:box.x + box.w] = ink
    canvas[box.y:box.y + box.h, box.x] = canvas[box.y:box.y + box.h, box.x + box.w - 1] = ink
    tick = max(2, box.w // 3)
    for y in (box.y, box.y + (box.h - 1) // 2, box.y + box.h - 1):
        canvas[y, box.x + box.w:box.x + box.w + tick] = ink


def _fit(lo: np.ndarray, hi: np.ndarray, width: int, height: int) -> tuple[int, int, float, np.ndarray]:
    """Equal-aspect fit of the data box ``[lo, hi]`` (``(2,)`` each) in ``width × height`` pixels: the picture's
    pixel size ``(w, h)``, the data length of one pixel and the data point at the picture's lower-left corner."""
    span = np.maximum(hi - lo, 1e-300)
    scale = min(width / span[0], height / span[1])
    w, h = max(1, min(width, int(round(span[0] * scale)))), max(1, min(height, int(round(span[1] * scale))))
    size = float(max(span[0] / w, span[1] / h))
    origin = 0.5 * (lo + hi) - 0.5 * size * np.array([w, h])
    return w, h, size, origin


class _Scene:
    """A mesh in its display frame with its views' data boxes (3 % padding)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, up: str | None, views: Sequence | None) -> None:
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces).reshape(-1, 3)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3 or not len(self.vertices):
            raise RenderOptionError(f"vertices must be (n, 3) with n ≥ 1, got shape {self.vertices.shape}")
        if not np.all(np.isfinite(self.vertices)):
            raise RenderOptionError("vertices must be finite")
        oriented, boundary = edges(self.faces)
        self.cull = orientation(self.faces, self.vertices, oriented)      # closed and oriented: cull back faces
        self.frame: Frame = principal_frame(self.vertices, self.faces, up, boundary=boundary)
        self.views = resolve_views(views, self.frame)
        self.boxes = []                                       # projected again when drawn: memory O(n)
        for _, az, el in self.views:
            p = project(self.vertices, self.frame, az, el)
            lo, hi = p[:, :2].min(axis=0), p[:, :2].max(axis=0)
            pad = 0.03 * float(np.max(hi - lo)) or 1.0
            self.boxes.append((lo - pad, hi + pad))

    def aspect(self, views: Sequence[int]) -> float:
        """Largest height/width of the given views' data boxes."""
        return max(float((hi - lo)[1] / (hi - lo)[0]) for lo, hi in (self.boxes[i] for i in views))

    def pixels(self, i: int, width: int, height: int, flat: bool) -> ViewPixels:
        """View ``i`` rasterised into a ``width × height`` panel (equal aspect, the picture's own size)."""
        lo, hi = self.boxes[i]
        w, h, size, origin = _fit(lo, hi, width, height)
        _, az, el = self.views[i]
        ss = SUPERSAMPLE
        pts = project(self.vertices, self.frame, az, el)      # sample units: x, y from the corner, depth
        pts[:, :2] -= origin
        pts *= ss / size
        return ViewPixels(pts, self.faces, w, h, ss, flat=flat, cull=self.cull)


def _panel_size(scene: _Scene, views: Sequence[int], width_in: float, dpi: float) -> tuple[int, int]:
    w = max(8, int(round(width_in * dpi)))
    return w, max(8, int(round(w * min(max(scene.aspect(views), 0.45), 1.3))))


def _check_method(method: str) -> bool:
    if method not in ("raster", "polygons"):
        raise RenderOptionError(f"method must be 'raster' or 'polygons', got {method!r}")
    return method == "polygons"


def png_bytes(rgb: np.ndarray, dpi: float = 72.0, compress_level: int = 1) -> bytes:
    """An 8-bit RGB PNG of ``rgb (H, W, 3)`` uint8 by PIL's encoder at zlib ``compress_level``, with the
    resolution ``dpi`` (level 1: about 0.07 s for a k = 10 sheet; a hand-written Sub-filter encoder measured
    0.03 s, not worth owning: ``docs/benchmarks/render-cost.md``)."""
    import io

    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(rgb, dtype=np.uint8), mode="RGB").save(
        buf, format="png", compress_level=compress_level, dpi=(dpi, dpi))
    return buf.getvalue()


def _save(path, canvas: np.ndarray, dpi: float, compress_level: int) -> None:
    data = png_bytes(canvas, dpi, compress_level)
    if hasattr(path, "write"):
        path.write(data)
    else:
        Path(path).write_bytes(data)


def _finish(path, canvas: np.ndarray, layout: Layout, lut: np.ndarray, dpi: float, compress_level: int) -> None:
    """Draw the colour bars and the labels of ``layout`` into ``canvas`` and save it as a PNG."""
    for bar in layout.bars:
        _draw_bar(canvas, bar, lut)
    for label in layout.labels:
        draw_text(canvas, label, dpi)
    _save(path, canvas, dpi, compress_level)


def _titles(given: Sequence[str] | None, count: int, what: str, of: str, default: str) -> list[str]:
    if given is None:
        return [default.format(j) for j in range(count)]
    out = [str(t) for t in given]
    if len(out) != count:
        raise RenderOptionError(f"{len(out)} {what} for {count} {of}")
    return out


# ---------------------------------------------------------------------------------------------------------------


def contact_sheet(path: Path, vertices: np.ndarray, faces: np.ndarray, fields: np.ndarray, *,
                  titles: Sequence[str] | None = None, views: Sequence | None = None, up: str | None = None,
                  cmap: str = "RdBu_r", dpi: int = 80, method: str = "raster", panel: float = 2.3,
                  compress_level: int = 1) -> Layout:
    """Write a PNG to ``path`` (a path or binary file): one row per field (column of ``fields (n, k)``),
    one column per view, a colour bar per row. Returns the :class:`Layout` drawn.

    ``titles``: the ``k`` row labels (default ``"mode j"``). ``views``: ``None`` (front, back, oblique; front
    and back for a near-flat mesh), or ``(azimuth, elevation)`` / ``(name, azimuth, elevation)`` pairs in
    degrees in the display frame. ``up``: ``None`` (principal axes) or one of :data:`UP_CHOICES`.
    Colours: ``cmap`` with limits ``±max|field|`` per row (0 is white for ``RdBu_r``).
    ``method``: ``"raster"`` (colours interpolated in each face) or ``"polygons"`` (flat facets: each face
    coloured by the mean of its vertex values). ``panel``: panel width in inches at ``dpi``.
    Invalid options raise :class:`RenderOptionError` before anything is drawn.
    """
    flat = _check_method(method)
    up = check_up(up)
    lut = _lut(cmap)
    scene = _Scene(vertices, faces, up, views)
    fields = np.asarray(fields)
    n = scene.vertices.shape[0]
    if fields.size % max(n, 1) or (fields.ndim == 2 and fields.shape[0] != n):
        raise RenderOptionError(f"fields must be (n, k) with n = {n} vertices, got shape {fields.shape}")
    fields = fields.reshape(n, -1)
    k = fields.shape[1]
    titles = _titles(titles, k, "titles", "rows (fields)", "mode {}")
    vmax = [_vmax(fields[:, j]) for j in range(k)]
    nv = len(scene.views)
    pw, ph = _panel_size(scene, range(nv), panel, dpi)
    layout = sheet_layout(titles, [name for name, _, _ in scene.views], [(_tick(v), "0", _tick(-v)) for v in vmax],
                          panel_width=pw, panel_height=ph, dpi=dpi)
    canvas = np.full((layout.height, layout.width, 3), 255, dtype=np.uint8)
    boxes = {(b.row, b.col): b for b in layout.panels}
    for i in range(nv):
        view = scene.pixels(i, pw, ph, flat)
        values = view.interp @ fields.astype(np.float64, copy=False)      # (pixels, k)
        _paint(canvas, view, values, np.asarray(vmax), [boxes[j, i] for j in range(k)], lut)
    _finish(path, canvas, layout, lut, dpi, compress_level)
    return layout


def grid_sheet(path: Path, vertices: np.ndarray, faces: np.ndarray, fields, *, row_titles: Sequence[str],
               col_titles: Sequence[str], up: str | None = None, view: Sequence | None = None,
               cmap: str = "RdBu_r", dpi: int = 80, method: str = "raster", panel: float = 1.7,
               compress_level: int = 1) -> Layout:
    """Write a PNG grid (and return its :class:`Layout`): row r, column c shows ``fields[r][:, c]``
    (``fields``: ``(r, n, c)`` or a list of ``r`` arrays ``(n, c)``), e.g. rows = smoothings, columns =
    modes, all in one view (``view``: ``None`` = the front view of :func:`contact_sheet`, or
    ``(azimuth, elevation)`` / ``(name, azimuth, elevation)``).

    Colours are symmetric per panel (``±max|field|`` of that panel, printed under it); each row's colour bar
    is in those per-panel units (−max, 0, +max). ``row_titles`` (r) and ``col_titles`` (c) label the grid;
    ``up``, ``cmap``, ``dpi``, ``method``, ``panel``: as in :func:`contact_sheet`.
    """
    flat = _check_method(method)
    up = check_up(up)
    lut = _lut(cmap)
    scene = _Scene(vertices, faces, up, None if view is None else [view])
    n = scene.vertices.shape[0]
    rows = [np.asarray(f) for f in fields]
    rows = [f.reshape(n, -1) if f.size == n * (f.size // max(n, 1)) and (f.ndim < 2 or f.shape[0] == n) else None
            for f in rows]
    if not rows or any(f is None for f in rows) or len({f.shape[1] for f in rows}) != 1:
        raise RenderOptionError(f"fields must be (r, n, c) or a list of r arrays (n, c) with n = {n} vertices "
                                "and the same c")
    r, c = len(rows), rows[0].shape[1]
    row_titles = _titles(row_titles, r, "row_titles", "rows", "row {}")
    col_titles = _titles(col_titles, c, "col_titles", "columns", "column {}")
    vmax = [[_vmax(f[:, i]) for i in range(c)] for f in rows]
    pw, ph = _panel_size(scene, [0], panel, dpi)
    layout = sheet_layout(row_titles, col_titles, [("+max", "0", "−max")] * r, panel_width=pw, panel_height=ph,
                          dpi=dpi, captions=[[f"±{_tick(v)[1:]}" for v in vr] for vr in vmax])
    canvas = np.full((layout.height, layout.width, 3), 255, dtype=np.uint8)
    boxes = {(b.row, b.col): b for b in layout.panels}
    view = scene.pixels(0, pw, ph, flat)
    for j, f in enumerate(rows):
        values = view.interp @ f.astype(np.float64, copy=False)
        _paint(canvas, view, values, np.asarray(vmax[j]), [boxes[j, i] for i in range(c)], lut)
    _finish(path, canvas, layout, lut, dpi, compress_level)
    return layout
