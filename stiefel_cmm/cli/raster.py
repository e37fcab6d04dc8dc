"""The z-buffer half of :mod:`stiefel_cmm.cli.render`: :func:`rasterize` (a chunked numpy z-buffer), :func:`edges` and
:func:`orientation` (boundary edges, consistent face orientation: back faces of closed oriented surfaces
are culled) and :class:`ViewPixels` (one rasterised view as a sparse ``(pixels, n)`` interpolation matrix,
so that all ``k`` fields are coloured by one sparse product).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

__all__ = ["Raster", "ViewPixels", "edges", "orientation", "rasterize"]

_MOMENT_CHUNK = 1 << 15


# ---------------------------------------------------------------------------------------------------------------
# rasterisation

#: at most about this many candidate (face, sample) pairs are tested at once (~40 bytes each)
_SAMPLE_BUDGET = 1 << 17
#: faces per chunk
_FACE_CHUNK = 1 << 15
#: bounding-box sizes (samples) that faces are padded up to: exact to 8, then four steps per octave
_BUCKETS = np.array(sorted({*range(1, 9), *(k << e for e in range(1, 14) for k in (5, 6, 7, 8))}))


class Raster:
    """One view scan-converted: which face is nearest at each sample and where in it.

    ``face (H, W)`` int64, ``-1`` for background; ``bary (H, W, 3)`` float32 barycentric
    coordinates of the sample centre in that face; ``shade (H, W)`` float32 Lambert factor
    ``0.55 + 0.45 |cos|`` of the face's normal with the view direction (0 on background).
    Row 0 is the bottom of the picture.
    """

    __slots__ = ("face", "shade", "_wa", "_wb")

    def __init__(self, face: np.ndarray, wa: np.ndarray, wb: np.ndarray, shade: np.ndarray) -> None:
        self.face, self._wa, self._wb, self.shade = face, wa, wb, shade

    @property
    def bary(self) -> np.ndarray:
        hit = self.face >= 0
        out = np.zeros((*self.face.shape, 3), dtype=np.float32)
        out[..., 0] = np.where(hit, self._wa, 0.0)
        out[..., 1] = np.where(hit, self._wb, 0.0)
        out[..., 2] = np.where(hit, 1.0 - self._wa - self._wb, 0.0)
        return out


def _face_setup(xyz: Sequence[np.ndarray], tri: np.ndarray, width: int, height: int,
                cull: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For the faces of ``tri (c, 3)`` whose clipped bounding box holds a sample: ``ints (f, 5)`` rows
    ``[face (index into tri), first sample (y0 · width + x0), box width, box height, 0]``, ``coef (f, 9)`` rows
    ``[w_a, ∂w_a/∂x, ∂w_a/∂y, w_b, …, z, ∂z/∂x, ∂z/∂y]`` (barycentric ``w_a, w_b`` and depth at the box's
    first sample and their steps per sample), and ``shade (c,)`` float32 for every face of ``tri``; ``xyz``:
    the points' x, y and depth as contiguous ``(n,)`` arrays. ``w_a(s) = edge(b, c, s) / edge(b, c, a)`` with
    ``edge(p, q, s) = (q − p) × (s − p)``. Degenerate (edge-on) faces are dropped, and with ``cull = ±1`` the
    faces whose projected orientation is ``∓``."""
    xs, ys, zs = xyz
    idx = np.ascontiguousarray(tri.T)                         # (3, c): corner a, b, c of every face
    ax, bx, cx = xs[idx[0]], xs[idx[1]], xs[idx[2]]
    ay, by, cy = ys[idx[0]], ys[idx[1]], ys[idx[2]]
    area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)      # twice the signed projected area
    x0 = np.maximum(np.ceil(np.minimum(np.minimum(ax, bx), cx) - 0.5), 0.0)
    x1 = np.minimum(np.floor(np.maximum(np.maximum(ax, bx), cx) - 0.5), width - 1.0)
    y0 = np.maximum(np.ceil(np.minimum(np.minimum(ay, by), cy) - 0.5), 0.0)
    y1 = np.minimum(np.floor(np.maximum(np.maximum(ay, by), cy) - 0.5), height - 1.0)
    keep = (x1 >= x0) & (y1 >= y0) & (cull * area > 1e-12 if cull else np.abs(area) > 1e-12)
    face = np.flatnonzero(keep)
    ax, bx, cx, ay, by, cy, area = ax[face], bx[face], cx[face], ay[face], by[face], cy[face], area[face]
    x0, x1, y0, y1 = x0[face], x1[face], y0[face], y1[face]
    az, bz, cz = zs[idx[0, face]], zs[idx[1, face]], zs[idx[2, face]]
    ex, ey, ez, fx, fy, fz = bx - ax, by - ay, bz - az, cx - ax, cy - ay, cz - az
    normal = np.sqrt(area * area + (ey * fz - ez * fy) ** 2 + (ez * fx - ex * fz) ** 2)
    shade = np.zeros(len(tri), dtype=np.float32)
    shade[face] = 0.55 + 0.45 * np.abs(area) / np.maximum(normal, 1e-300)
    inv = 1.0 / area
    sx, sy = x0 + 0.5, y0 + 0.5
    coef = np.empty((len(face), 9))
    for k, (px, py, qx, qy) in enumerate(((bx, by, cx, cy), (cx, cy, ax, ay))):   # w_a: edge (b, c); w_b: (c, a)
        dx, dy = qx - px, qy - py
        coef[:, 3 * k] = (dx * (sy - py) - dy * (sx - px)) * inv
        coef[:, 3 * k + 1] = -dy * inv
        coef[:, 3 * k + 2] = dx * inv
    coef[:, 6:] = coef[:, 0:3] * (az - cz)[:, None] + coef[:, 3:6] * (bz - cz)[:, None]
    coef[:, 6] += cz
    xi, yi = x0.astype(np.int64), y0.astype(np.int64)
    ints = np.stack([face, yi * width + xi, x1.astype(np.int64) - xi + 1, y1.astype(np.int64) - yi + 1,
                     np.zeros_like(face)], axis=1)
    return ints, coef, shade


def rasterize(points: np.ndarray, faces: np.ndarray, width: int, height: int, *, cull: int = 0) -> Raster:
    """Z-buffer scan conversion of triangles under an orthographic projection.

    ``points (n, 3)``: column 0 and 1 are sample coordinates (x right, y up; the sample
    ``(row j, column i)`` is at ``(i + ½, j + ½)``), column 2 is depth (smaller is nearer), in the same
    unit as x and y. ``faces (m, 3)``. A sample belongs to a face when its three barycentric coordinates
    are ``≥ −1e-9`` (shared edges are covered twice, never missed, so a closed surface has no pinholes
    however small its triangles); the nearest face wins. ``cull = +1`` skips the faces that are clockwise
    on screen (back faces of a closed surface whose faces turn anticlockwise seen from outside), ``−1`` the
    anticlockwise ones, ``0`` none.

    Faces are grouped by bounding-box size (padded up to :data:`_BUCKETS`), so that each group's samples
    form a ``(faces, rows, columns)`` block evaluated by broadcasting. Memory is ``O(width · height)`` for
    the buffers plus ``O(_FACE_CHUNK + _SAMPLE_BUDGET)``, independent of ``m``.
    """
    points = np.asarray(points, dtype=np.float64)
    faces = np.asarray(faces).reshape(-1, 3)
    npix = width * height
    zbuf = np.full(npix, np.inf)
    face = np.full(npix, -1, dtype=np.int64)
    wa_buf = np.zeros(npix, dtype=np.float32)
    wb_buf = np.zeros(npix, dtype=np.float32)
    face_shade = np.empty(len(faces), dtype=np.float32)
    tol = -1e-9
    xyz = [np.ascontiguousarray(points[:, d]) for d in range(3)]
    for start in range(0, len(faces), _FACE_CHUNK):
        ints, coef, face_shade[start:start + _FACE_CHUNK] = _face_setup(
            xyz, faces[start:start + _FACE_CHUNK], width, height, cull)
        if not len(ints):
            continue
        ints[:, 0] += start
        bucket = np.searchsorted(_BUCKETS, np.arange(max(int(ints[:, 2:4].max(initial=0)), 0) + 1))
        kw, kh = bucket[ints[:, 2]], bucket[ints[:, 3]]
        key = kw * len(_BUCKETS) + kh
        order = np.argsort(key, kind="stable")
        bounds = np.r_[0, np.flatnonzero(np.diff(key[order])) + 1, len(order)]
        for g0, g1 in zip(bounds[:-1], bounds[1:]):
            bw, bh = int(_BUCKETS[kw[order[g0]]]), int(_BUCKETS[kh[order[g0]]])
            tx = np.arange(bw, dtype=np.float64)
            ty = np.arange(bh, dtype=np.float64)[:, None]
            per = max(1, _SAMPLE_BUDGET // (bw * bh))
            for s0 in range(g0, g1, per):
                r = order[s0:min(s0 + per, g1)]
                cf, it = coef[r][:, :, None, None], ints[r]
                wa = cf[:, 0] + cf[:, 1] * tx + cf[:, 2] * ty     # (g, bh, bw)
                wb = cf[:, 3] + cf[:, 4] * tx + cf[:, 5] * ty
                ok = (wa >= tol) & (wb >= tol) & (wa + wb <= 1.0 - tol)
                if bw > 8 or bh > 8:                            # padded beyond some faces' own boxes
                    ok &= (tx < it[:, 2, None, None]) & (ty < it[:, 3, None, None])
                idx = np.flatnonzero(ok)
                if not len(idx):
                    continue
                q, rem = np.divmod(idx, bw * bh)
                iy, ix = np.divmod(rem, bw)
                cq = cf[q, 6:, 0, 0]
                z = cq[:, 0] + cq[:, 1] * ix + cq[:, 2] * iy
                pix = it[q, 1] + iy * width + ix
                np.minimum.at(zbuf, pix, z)
                win = np.flatnonzero(z <= zbuf[pix])          # nearest so far (ties: any of them)
                p = pix[win]
                face[p] = it[q[win], 0]
                wa_buf[p] = wa.ravel()[idx[win]]
                wb_buf[p] = wb.ravel()[idx[win]]
    hit = face >= 0
    shade = np.zeros(npix, dtype=np.float32)
    shade[hit] = face_shade[face[hit]]
    return Raster(face.reshape(height, width), wa_buf.reshape(height, width), wb_buf.reshape(height, width),
                  shade.reshape(height, width))


#: half-edges sorted at once by :func:`orientation` (8 bytes each): more take several passes over the faces
_EDGE_BUDGET = 1 << 21


def _half_edges(faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The half-edges ``a → b`` of ``faces (c, 3)``: tails ``a`` and heads ``b``, ``(3c,)`` int64 each."""
    return faces.ravel().astype(np.int64), np.roll(faces, -1, axis=1).ravel().astype(np.int64)


def edges(faces: np.ndarray) -> tuple[bool, np.ndarray]:
    """``(oriented, boundary)``: whether every edge of ``faces (m, 3)`` lies in exactly two faces that cross it
    in opposite directions (a closed, consistently oriented surface), and the boundary edges ``(b, 2)`` (in
    exactly one face).

    The half-edge ``a → b`` is the key ``2 (min · n + max) + [a < b]``; sorted, the keys of an oriented closed
    surface come in pairs ``2K, 2K + 1``, and an edge whose undirected key ``K`` occurs once is a boundary
    edge. Keys are sorted by ranges of their smaller vertex, at most ``_EDGE_BUDGET`` at a time (memory
    ``O(n + budget + b)``)."""
    faces = np.asarray(faces).reshape(-1, 3)
    if not len(faces):
        return False, np.zeros((0, 2), dtype=np.int64)
    n, total, chunk = int(faces.max()) + 1, 3 * len(faces), 1 << 16
    if total <= _EDGE_BUDGET:
        cuts, sizes = np.array([n]), np.array([total])
    else:                                                      # vertex ranges holding ≤ budget half-edges each
        per_vertex = np.zeros(n, dtype=np.int64)               # half-edges by smaller endpoint
        for start in range(0, len(faces), chunk):
            a, b = _half_edges(faces[start:start + chunk])
            per_vertex += np.bincount(np.minimum(a, b), minlength=n)
        ends = np.cumsum(per_vertex, out=per_vertex)
        cuts = np.searchsorted(ends, np.arange(_EDGE_BUDGET, total, _EDGE_BUDGET), side="right")
        cuts = np.unique(np.r_[np.maximum(cuts, 1), n])        # a vertex with more half-edges: a range of its own
        sizes = np.diff(np.r_[0, ends[cuts - 1]])
        del per_vertex, ends
    oriented, boundary, lo = True, [], 0
    for hi, size in zip(cuts, sizes):                          # vertices [lo, hi) as smaller endpoints
        key = np.empty(int(size), dtype=np.int64)
        filled = 0
        for start in range(0, len(faces), chunk):
            a, b = _half_edges(faces[start:start + chunk])
            small, big = np.minimum(a, b), np.maximum(a, b)
            if len(cuts) > 1:
                sel = (small >= lo) & (small < hi)
                a, b, small, big = a[sel], b[sel], small[sel], big[sel]
            part = key[filled:filled + len(a)]
            np.multiply(small, n, out=part)
            part += big
            part *= 2
            part += a < b
            filled += len(a)
        key.sort()
        if oriented:
            even, odd = key[0::2], key[1::2]
            oriented = (len(key) % 2 == 0 and not np.any(even & 1) and bool(np.all(odd == even + 1))
                        and not np.any(even[1:] == even[:-1]))
            del even, odd
        if not oriented:                                       # edges whose undirected key occurs once
            key >>= 1
            once = np.ones(len(key), dtype=bool)
            once[1:] &= key[1:] != key[:-1]
            once[:-1] &= key[:-1] != key[1:]
            single = key[once]
            boundary.append(np.stack([single // n, single % n], axis=1))
        del key
        lo = hi
    return oriented, (np.concatenate(boundary) if boundary else np.zeros((0, 2), dtype=np.int64))


def orientation(faces: np.ndarray, vertices: np.ndarray, oriented: bool | None = None) -> int:
    """``+1`` if the surface is closed and its faces turn anticlockwise seen from outside (every directed edge
    ``a → b`` once, and ``b → a`` once), ``−1`` if clockwise, ``0`` otherwise (open, non-manifold or
    inconsistently oriented: nothing may be culled). ``oriented``: :func:`edges`'s answer if known."""
    faces = np.asarray(faces).reshape(-1, 3)
    if not (edges(faces)[0] if oriented is None else oriented):
        return 0
    volume = 0.0
    for start in range(0, len(faces), _MOMENT_CHUNK):
        tri = vertices[faces[start:start + _MOMENT_CHUNK]]
        volume += float(np.einsum("fd,fd->", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])))
    return 0 if volume == 0.0 else (1 if volume > 0 else -1)


class ViewPixels:
    """One view of the mesh at output resolution, ready to colour any number of fields.

    Rasterised at ``ss × ss`` samples per pixel; ``pixel (p,)`` flat indices (row 0 on top) of the ``p``
    covered pixels of the ``height × width`` picture, ``cover (p,)`` the covered fraction of each,
    ``shade (p,)`` the mean Lambert factor, and ``interp`` the sparse ``(p, n)`` matrix that averages a
    per-vertex field over a pixel's covered samples (linear in each face; ``flat=True``: the face mean).
    """

    def __init__(self, points: np.ndarray, faces: np.ndarray, width: int, height: int, ss: int,
                 flat: bool = False, cull: int = 0) -> None:
        from scipy import sparse

        r = rasterize(points, faces, width * ss, height * ss, cull=cull)

        def by_pixel(a: np.ndarray) -> np.ndarray:           # samples grouped by output pixel, bottom row first
            return a.reshape(height, ss, width, ss).transpose(0, 2, 1, 3).reshape(-1)

        fid = by_pixel(r.face)
        hit = np.flatnonzero(fid >= 0)
        count = np.bincount(hit // (ss * ss), minlength=width * height)
        covered = np.flatnonzero(count)
        per = count[covered]
        row, col = np.divmod(covered, width)
        self.pixel = (height - 1 - row) * width + col            # row 0 on top
        self.cover = per * (1.0 / ss ** 2)
        starts = np.r_[0, np.cumsum(per)[:-1]]
        self.shade = np.add.reduceat(by_pixel(r.shade)[hit].astype(np.float64), starts) / per if len(hit) \
            else np.zeros(0)
        weights = np.empty((len(hit), 3))
        if flat:
            weights[:] = 1.0 / 3.0
        else:
            weights[:, 0] = by_pixel(r._wa)[hit]
            weights[:, 1] = by_pixel(r._wb)[hit]
            weights[:, 2] = 1.0 - weights[:, 0] - weights[:, 1]
        weights /= np.repeat(per, per)[:, None]
        corners = np.asarray(faces).reshape(-1, 3)[fid[hit]]
        indptr = np.zeros(len(covered) + 1, dtype=np.int64)
        np.cumsum(3 * per, out=indptr[1:])
        self.interp = sparse.csr_array((weights.ravel(), corners.ravel(), indptr), shape=(len(covered), len(points)))
        self.shape = (height, width)
