"""Where the camera looks from, and what it sees: the geometry half of :mod:`stiefel_cmm.cli.render`.

* :func:`principal_frame` orients a mesh by the principal axes of its surface (area-weighted, exact
  second moments of the triangles): largest spread horizontal, second vertical, smallest towards the
  viewer, so a flat patch is seen face-on. ``up="y"`` (etc.) forces the vertical axis instead. Each
  axis's sign is fixed by the third moment of the surface along it (the heavier tail goes right / up),
  so the picture does not depend on how the mesh was rotated or on the eigen-solver's signs.
* :func:`resolve_views` picks the views: front and back along the smallest principal axis, plus an
  oblique view from above unless the mesh is near-flat.
* the z-buffer (:func:`rasterize`, :class:`ViewPixels`, :func:`edges`) lives in :mod:`stiefel_cmm.cli.raster`.
"""

from __future__ import annotations

import argparse
from typing import NamedTuple, Sequence

import numpy as np

__all__ = ["BOUNDARY_BELOW", "FLATNESS", "FLAT_VIEWS", "UP_CHOICES", "VIEWS", "Frame", "RenderOptionError", "camera",
           "check_up", "principal_frame", "project", "resolve_views"]

#: accepted values of ``up`` (``None``: the principal axes decide)
UP_CHOICES: tuple[str, ...] = ("x", "y", "z", "-x", "-y", "-z")

#: named views ``(name, azimuth, elevation)`` in degrees, in the mesh's display frame: azimuth turns the
#: camera about the vertical axis (0 = front, 180 = back), elevation raises it (90 = looking down)
VIEWS: tuple[tuple[str, float, float], ...] = (("front", 0.0, 0.0), ("back", 180.0, 0.0), ("oblique", 40.0, 35.0))
#: the views of a near-flat mesh: its two faces
FLAT_VIEWS: tuple[tuple[str, float, float], ...] = VIEWS[:2]
#: an open surface is stood on its boundary when the boundary's mean height is beyond this × the vertical spread
BOUNDARY_BELOW = 0.5
#: a mesh is near-flat when its smallest principal spread is below this fraction of its largest
FLATNESS = 0.12


class RenderOptionError(argparse.ArgumentTypeError, ValueError):
    """An invalid rendering option (``up``, ``views``, ``method``, titles); raised before anything is drawn.

    A ``ValueError``; also an ``argparse.ArgumentTypeError``, so that ``type=check_up`` reports this message.
    """


def check_up(text: str | None) -> str | None:
    """Normalise an ``up`` option: ``"x"``, ``"+y"``, ``"-Z"`` … → ``"x"``, ``"y"``, ``"-z"``; ``None``, ``""``,
    ``"auto"`` or ``"none"`` → ``None`` (principal axes). Anything else raises :class:`RenderOptionError`."""
    if text is None:
        return None
    if not isinstance(text, str):
        raise RenderOptionError(f"up must be a string, one of {', '.join(UP_CHOICES)} or auto, got {text!r}")
    t = text.strip().lower()
    if t in ("", "auto", "none"):
        return None
    t = t[1:] if t.startswith("+") else t
    if t not in UP_CHOICES:
        raise RenderOptionError(f"up must be one of {', '.join(UP_CHOICES)} or auto (principal axes), got {text!r}")
    return t


# ---------------------------------------------------------------------------------------------------------------
# orientation


class Frame(NamedTuple):
    """The display frame of a mesh: ``centre (3,)`` (area centroid), ``axes (3, 3)`` orthonormal rows
    ``right, up, towards the viewer`` (a rotation: ``right × up = towards``), and ``spread (3,)`` the
    surface's standard deviation along each axis."""

    centre: np.ndarray
    axes: np.ndarray
    spread: np.ndarray

    @property
    def flat(self) -> bool:
        """Whether the surface is near-flat (smallest spread < ``FLATNESS`` × largest)."""
        return bool(self.spread[2] < FLATNESS * max(float(self.spread.max()), 1e-300))


def _apply(x: np.ndarray, mat: np.ndarray) -> np.ndarray:
    """``x (…, 3) @ mat (3, q)`` as three scaled sums: BLAS gains nothing on so thin a product, and its
    threads only contend with other work."""
    return x[..., 0, None] * mat[0] + x[..., 1, None] * mat[1] + x[..., 2, None] * mat[2]


def _lincomb(x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """``Σ_f w_f x_f`` over the first axis of ``x``, without BLAS."""
    return np.einsum("f,f...->...", w, x)


#: faces per chunk when integrating moments over the surface
_MOMENT_CHUNK = 1 << 15


class _Surface:
    """Area moments of a triangulated surface, integrated exactly per triangle: ``total`` area, area
    ``centre (3,)`` and covariance ``cov (3, 3)`` (``∫ x xᵀ = A/12 (Σ vᵢvᵢᵀ + s sᵀ)`` over a triangle,
    s = Σ vᵢ), and :meth:`third`. Without area (no faces, or all degenerate): the vertices, equally weighted.

    Works in chunks of faces on contiguous per-coordinate, per-corner arrays gathered from the vertices
    (memory: the areas, ``m`` float32, plus a chunk; no ``(m, 3, 3)`` array; no BLAS, see :func:`_apply`).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray) -> None:
        self.vertices, self.faces = vertices, faces
        ref = vertices.mean(axis=0) if len(vertices) else np.zeros(3)
        m = len(faces)
        self.area = np.empty(m, dtype=np.float32)             # weights of the third moments only
        total, first, second = 0.0, np.zeros(3), np.zeros((3, 3))
        for start, c in self._corners(ref):
            e1 = [c[d][1] - c[d][0] for d in range(3)]
            e2 = [c[d][2] - c[d][0] for d in range(3)]
            area = 0.5 * np.sqrt((e1[1] * e2[2] - e1[2] * e2[1]) ** 2 + (e1[2] * e2[0] - e1[0] * e2[2]) ** 2
                                 + (e1[0] * e2[1] - e1[1] * e2[0]) ** 2)
            self.area[start:start + len(area)] = area
            total += float(area.sum())
            s = [c[d][0] + c[d][1] + c[d][2] for d in range(3)]
            for d in range(3):
                first[d] += _lincomb(s[d], area) / 3.0
                for e in range(d, 3):
                    second[d, e] += _lincomb(c[d][0] * c[e][0] + c[d][1] * c[e][1] + c[d][2] * c[e][2]
                                             + s[d] * s[e], area) / 12.0
        second = np.triu(second) + np.triu(second, 1).T
        self.cloud = not total > 0.0
        if self.cloud:
            d = vertices - ref
            self.total, self.centre, self.cov = float(len(d)), ref, np.einsum("nd,ne->de", d, d) / max(len(d), 1)
        else:
            c0 = first / total
            self.total, self.centre, self.cov = total, ref + c0, second / total - np.outer(c0, c0)

    def _corners(self, origin: np.ndarray):
        """``(first face, c)`` per chunk, ``c[coordinate][corner]`` the ``(chunk,)`` coordinates − ``origin``."""
        for start in range(0, len(self.faces), _MOMENT_CHUNK):
            idx = np.ascontiguousarray(self.faces[start:start + _MOMENT_CHUNK].T)          # (3, c)
            yield start, [[self.vertices[idx[i], d] - origin[d] for i in range(3)] for d in range(3)]

    def third(self, axes: np.ndarray) -> np.ndarray:
        """``∫ ((x − centre)·a)³ dA / A`` for each column ``a`` of ``axes (3, q)`` (exact per triangle:
        ``A/10 · h₃(f_a, f_b, f_c)``, h₃ the complete homogeneous polynomial of degree 3 of the corner values)."""
        if self.cloud:
            return np.mean(_apply(self.vertices - self.centre, axes) ** 3, axis=0)
        out = np.zeros(axes.shape[1])
        for start, c in self._corners(self.centre):
            area = self.area[start:start + len(c[0][0])].astype(np.float64)
            for q in range(axes.shape[1]):
                a, b, cc = (c[0][i] * axes[0, q] + c[1][i] * axes[1, q] + c[2][i] * axes[2, q] for i in range(3))
                s = a + b + cc
                h3 = s * s * s + 3.0 * s * (a * a + b * b + cc * cc) + 2.0 * (a * a * a + b * b * b + cc * cc * cc)
                out[q] += _lincomb(h3, area)
        return out / (60.0 * self.total)


def _signs(right: np.ndarray, up: np.ndarray, surface: _Surface, scale: float,
           up_fixed: bool) -> tuple[float, float]:
    """Signs ``(s_r, s_u)`` for ``right``, ``up`` (``s_u = 1`` when ``up_fixed``): each axis's third moment
    positive (heavier tail on the + side). An axis of a symmetric surface (|skewness| < 1e-6 scale³) takes
    the sign that makes the third axis ``s_r right × s_u up`` skewed positively instead; only if that is
    symmetric too, the sign that makes its largest coordinate positive (then no longer rotation-invariant)."""
    axes = np.stack([right, up, np.cross(right, up)], axis=1)
    m3 = surface.third(axes)
    sure = np.abs(m3) > 1e-6 * scale ** 3
    sr = float(np.sign(m3[0])) if sure[0] else 0.0
    su = 1.0 if up_fixed else (float(np.sign(m3[1])) if sure[1] else 0.0)
    if sure[2] and (sr == 0.0) != (su == 0.0):                # the towards axis flips with either
        if sr == 0.0:
            sr = float(np.sign(m3[2])) * su
        else:
            su = float(np.sign(m3[2])) * sr
    if sr == 0.0:
        sr = 1.0 if right[np.argmax(np.abs(right))] > 0 else -1.0
    if su == 0.0:
        su = 1.0 if up[np.argmax(np.abs(up))] > 0 else -1.0
    return sr, su


def _boundary_height(vertices: np.ndarray, boundary: np.ndarray, centre: np.ndarray, axis: np.ndarray) -> float:
    """Height along ``axis`` above ``centre`` of the midpoint of the ``boundary (b, 2)`` edges, length-weighted;
    0 without boundary."""
    total = height = 0.0
    for start in range(0, len(boundary), _MOMENT_CHUNK):
        part = boundary[start:start + _MOMENT_CHUNK]
        a, b = vertices[part[:, 0]], vertices[part[:, 1]]
        length = np.linalg.norm(b - a, axis=1)
        total += float(length.sum())
        height += float(np.einsum("e,ed,d->", length, 0.5 * (a + b) - centre, axis))
    return height / total if total > 0 else 0.0


def principal_frame(vertices: np.ndarray, faces: np.ndarray, up: str | None = None, *,
                    boundary: np.ndarray | None = None) -> Frame:
    """Display frame of the surface ``vertices (n, 3)``, ``faces (m, 3)``.

    ``up=None``: right / up / towards the viewer are the principal axes of largest / middle / smallest
    spread, right and up signed by the third moment (see :func:`_signs` for symmetric surfaces), except
    that an open surface whose boundary lies clearly above or below its centre (by more than
    ``BOUNDARY_BELOW`` × the vertical spread) is turned so that the boundary is below: a scanned head
    stands on its neck. ``up`` in :data:`UP_CHOICES`: that coordinate axis is up; right is the principal
    axis of largest spread perpendicular to it (signed likewise), and the viewer looks along the remaining
    one. ``boundary (b, 2)``: the boundary edges if known (:func:`edges`), found otherwise.
    """
    up = check_up(up)
    vertices = np.asarray(vertices, dtype=np.float64)
    surface = _Surface(vertices, np.asarray(faces).reshape(-1, 3))
    centre, cov = surface.centre, surface.cov
    evals, evecs = np.linalg.eigh(cov)                        # ascending
    scale = float(np.sqrt(max(evals[-1], 0.0))) or 1.0
    if up is None:
        right, upv = evecs[:, 2], evecs[:, 1]
        sr, su = _signs(right, upv, surface, scale, up_fixed=False)
        right, upv = sr * right, su * upv
        if boundary is None:
            from .raster import edges

            boundary = edges(np.asarray(faces).reshape(-1, 3))[1]
        below = _boundary_height(vertices, boundary, centre, upv)
        if below > BOUNDARY_BELOW * np.sqrt(max(float(upv @ cov @ upv), 0.0)):
            upv = -upv                                        # an open scan stands on its cut
    else:
        upv = np.zeros(3)
        upv["xyz".index(up[-1])] = -1.0 if up.startswith("-") else 1.0
        proj = np.eye(3) - np.outer(upv, upv)
        _, v2 = np.linalg.eigh(proj @ cov @ proj)             # the up direction has eigenvalue 0
        right = v2[:, 2] - upv * (upv @ v2[:, 2])
        right /= np.linalg.norm(right)
        right *= _signs(right, upv, surface, scale, up_fixed=True)[0]
    towards = np.cross(right, upv)
    axes = np.stack([right, upv, towards])
    spread = np.sqrt(np.maximum(np.einsum("id,de,ie->i", axes, cov, axes), 0.0))
    return Frame(centre, axes, spread)


def resolve_views(views: Sequence | None, frame: Frame) -> list[tuple[str, float, float]]:
    """``[(name, azimuth, elevation), …]`` from ``views``: ``None`` → :data:`VIEWS` (:data:`FLAT_VIEWS` for a
    near-flat mesh); entries ``(azimuth, elevation)`` are named after the matching standard view or by their
    angles, ``(name, azimuth, elevation)`` are kept."""
    if views is None:
        return list(FLAT_VIEWS if frame.flat else VIEWS)
    out = []
    named = {(az % 360.0, el): name for name, az, el in VIEWS}
    for v in views:
        try:
            if len(v) == 3:
                out.append((str(v[0]), float(v[1]), float(v[2])))
            elif len(v) == 2:
                az, el = float(v[0]), float(v[1])
                out.append((named.get((az % 360.0, el), f"azimuth {az:g}°, elevation {el:g}°"), az, el))
            else:
                raise ValueError
        except (TypeError, ValueError):
            raise RenderOptionError(f"a view is (azimuth, elevation) or (name, azimuth, elevation) in degrees, "
                                    f"got {v!r}") from None
    if not out:
        raise RenderOptionError("views is empty: give at least one (azimuth, elevation), or None for automatic")
    return out


def camera(frame: Frame, azim: float, elev: float) -> np.ndarray:
    """``(3, 3)`` rows: screen right, screen up and the direction towards the camera, in mesh coordinates."""
    a, e = np.deg2rad(azim), np.deg2rad(elev)
    towards = np.array([np.sin(a) * np.cos(e), np.sin(e), np.cos(a) * np.cos(e)])
    right = np.array([np.cos(a), 0.0, -np.sin(a)])
    rows = np.stack([right, np.cross(towards, right), towards])   # in display coordinates
    return rows @ frame.axes


def project(vertices: np.ndarray, frame: Frame, azim: float, elev: float) -> np.ndarray:
    """``(n, 3)`` screen coordinates of the vertices, x right, y up, depth (smaller is nearer), in Fortran
    order (each coordinate contiguous, as :func:`rasterize` reads them)."""
    rot = camera(frame, azim, elev) * np.array([1.0, 1.0, -1.0])[:, None]
    shift = rot @ frame.centre
    p = np.empty((len(vertices), 3), order="F")
    for e in range(3):
        np.multiply(vertices[:, 0], rot[e, 0], out=p[:, e])
        p[:, e] += vertices[:, 1] * rot[e, 1]
        p[:, e] += vertices[:, 2] * rot[e, 2]
        p[:, e] -= shift[e]
    return p
