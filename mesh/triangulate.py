"""Polygon faces and their triangulation.

``Polygons`` holds faces with any number of corners as a flat index array and
per-face corner counts. ``triangulate`` keeps triangles and fans a polygon
(``(a, b, c, d, …) → (a,b,c), (a,c,d), …``) when no fan triangle is flipped
against its best-fit normal (Newell normal ``n̂``) and the fan's angles at
``a`` sum to less than ``2π`` — true for every convex polygon and for a
non-convex one star-shaped from ``a``; every other polygon is split
along the other diagonal (quads) or ear-clipped (``mapbox_earcut``) in that
plane. The result is accepted only if none of its ``p − 2`` triangles is
flipped against ``n̂`` in 3-D and (ear clipping) they tile the projected
polygon (shoelace area); otherwise, and for a polygon with zero vector area
that is not flat (a bowtie), the polygon is refused with
``NonTriangleFacesError`` (self-intersecting, or far from planar — e.g. a
tetrahedron written as a 4-corner face).

Reported (``Triangulation``): *non-planar* polygons have a corner more than
``0.01 ×`` their longest edge off the best-fit plane; *non-convex* ones are
the other polygons that fail the convexity test: every turn ``((p_i − p_{i−1}) × (p_{i+1} − p_i))·n̂`` is
non-negative (up to ``1e-9·|e_{i−1}||e_i|``) and the turning angles sum to at
most ``2π`` (a pentagram turns ``4π``). Collinear and repeated corners count
as convex; "flipped" uses the same relative tolerance.

Both vectorised per corner count; only ear clipping (polygons with 5 or more
corners whose fan fails) loops, one ``mapbox_earcut`` call per polygon.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import numpy as np
from jaxtyping import Float, Int

from .errors import IndexOutOfRangeError, NonTriangleFacesError

__all__ = ["Polygons", "Triangulation", "as_polygons", "triangulate"]


class Polygons(NamedTuple):
    """Faces with ``sizes[f] ≥ 3`` corners each: ``flat`` lists the corners face after face.

    Attributes:
      flat: ``(s,)`` int64 vertex indices, ``s = Σ sizes``.
      sizes: ``(m,)`` int64 corner counts.
    """

    flat: Int[np.ndarray, " s"]
    sizes: Int[np.ndarray, " m"]

    @property
    def starts(self) -> Int[np.ndarray, " m"]:
        """Offset of each face's first corner in ``flat``."""
        return np.cumsum(self.sizes) - self.sizes

    def rows(self, ids: Int[np.ndarray, " k"], p: int) -> Int[np.ndarray, "k p"]:
        """Corner indices of faces ``ids`` (all with ``p`` corners), shape ``(k, p)``."""
        return self.flat[self.starts[ids][:, None] + np.arange(p)]


class Triangulation(NamedTuple):
    """Output of ``triangulate``.

    Attributes:
      triangles: ``(t, 3)`` int64, in input face order.
      origin: ``(t,)`` input face of each triangle.
      n_polygons: faces with more than 3 corners.
      n_quads: faces with exactly 4 corners.
      nonconvex: ``(q,)`` nearly planar input faces that are not convex.
      nonplanar: ``(r,)`` input faces with a corner off their best-fit plane by
        more than ``0.01 ×`` their longest edge.
    """

    triangles: Int[np.ndarray, "t 3"]
    origin: Int[np.ndarray, " t"]
    n_polygons: int
    n_quads: int
    nonconvex: Int[np.ndarray, " q"]
    nonplanar: Int[np.ndarray, " r"]


def as_polygons(faces: Any) -> Polygons:
    """``Polygons`` from an ``(m, p)`` array or a sequence of index lists; checks corner counts and integrality."""
    if isinstance(faces, Polygons):
        return faces
    if not isinstance(faces, np.ndarray):  # lists of equal-length lists, jax arrays, …: one conversion
        try:
            arr = np.asarray(faces)
            faces = arr if arr.ndim == 2 and arr.dtype != object else faces
        except ValueError:  # ragged
            pass
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        m, p = faces.shape
        if m and p < 3:
            raise NonTriangleFacesError(
                f"faces have {p} corners each; a face needs at least 3 (give triangles or polygons)"
            )
        return Polygons(_as_index(faces).reshape(-1), np.full(m, p, dtype=np.int64))
    polys = [np.asarray(f).reshape(-1) for f in faces]
    sizes = np.array([f.size for f in polys], dtype=np.int64)
    if np.any(sizes < 3):
        bad = int(np.argmax(sizes < 3))
        raise NonTriangleFacesError(
            f"{int(np.sum(sizes < 3))} face(s) have fewer than 3 corners, e.g. face {bad} = "
            f"{polys[bad].tolist()}; remove them or fix the face list"
        )
    flat = _as_index(np.concatenate(polys)) if polys else np.zeros(0, dtype=np.int64)
    return Polygons(flat, sizes)


def _as_index(a: np.ndarray) -> np.ndarray:
    if a.size and not np.issubdtype(a.dtype, np.integer):
        if not np.issubdtype(a.dtype, np.number) or not np.all(np.isfinite(a)) or np.any(a != np.round(a)):
            raise IndexOutOfRangeError("face indices must be integers; got non-integral values")
    return a.astype(np.int64)


def triangulate(
    V: Float[np.ndarray, "n 3"], polys: Polygons, locate: Callable[[int], dict] | None = None
) -> Triangulation:
    """Triangulate ``polys`` (indices already checked to lie in ``[0, n)``, corners finite).

    ``locate(face)`` gives ``path=``/``line=`` keywords for an error about input face ``face``.
    """
    sizes = polys.sizes
    m = sizes.size
    if m == 0 or np.all(sizes == 3):
        empty = np.zeros(0, dtype=np.int64)
        return Triangulation(polys.flat.reshape(-1, 3), np.arange(m, dtype=np.int64), 0, 0, empty, empty)
    where = locate or (lambda f: {})
    tris, origin, nonconvex, nonplanar = [], [], [], []
    for p in np.unique(sizes).tolist():
        ids = np.flatnonzero(sizes == p)
        rows = polys.rows(ids, p)
        if p == 3:
            tris.append(rows)
            origin.append(ids)
            continue
        convex, normal = _convexity(V[rows])
        k = np.arange(1, p - 1)
        fans = np.stack([np.repeat(rows[:, 0], p - 2), rows[:, k].ravel(), rows[:, k + 1].ravel()], axis=1)
        fans = fans.reshape(-1, p - 2, 3)
        ok = _upright(V, fans, normal) & _fan_angle_ok(V, fans)
        twisted = np.flatnonzero(_twisted(V, fans))
        if twisted.size:
            _refuse(V, rows[twisted[0]], int(ids[twisted[0]]), where)
        tri = fans.copy()
        if p == 4:  # the other diagonal
            alt = rows[:, [1, 2, 3, 1, 3, 0]].reshape(-1, 2, 3)
            use_alt = ~ok & _upright(V, alt, normal)
            tri[use_alt] = alt[use_alt]
            ok_any = ok | use_alt
            if not ok_any.all():
                i = int(np.argmin(ok_any))
                _refuse(V, rows[i], int(ids[i]), where)
        else:
            for i in np.flatnonzero(~ok):
                tri[i] = _ear_clip(V, rows[i], normal[i], int(ids[i]), where)
        tris.append(tri.reshape(-1, 3))
        origin.append(np.repeat(ids, p - 2))
        flat = _off_plane(V[rows], normal) <= 1e-2
        nonconvex.append(ids[~convex & flat])
        nonplanar.append(ids[~flat])
    T, O = np.concatenate(tris), np.concatenate(origin)
    order = np.argsort(O, kind="stable")
    nc, npl = (np.sort(np.concatenate(x)) if x else np.zeros(0, dtype=np.int64) for x in (nonconvex, nonplanar))
    return Triangulation(T[order], O[order], int(np.sum(sizes > 3)), int(np.sum(sizes == 4)), nc, npl)


def _convexity(P: Float[np.ndarray, "k p 3"]) -> tuple[np.ndarray, np.ndarray]:
    """``(convex (k,), unit Newell normal (k, 3))`` of ``k`` polygons with ``p`` corners."""
    P = P - P.mean(axis=1, keepdims=True)
    Q = np.roll(P, -1, axis=1)
    N = np.cross(P, Q).sum(axis=1)  # Newell: 2 × vector area
    norm = np.linalg.norm(N, axis=1)
    n_hat = N / np.where(norm > 0, norm, 1.0)[:, None]
    e = Q - P  # e_i = p_{i+1} − p_i
    e_prev = np.roll(e, 1, axis=1)
    turn = np.einsum("kpd,kd->kp", np.cross(e_prev, e), n_hat)
    dot = np.einsum("kpd,kpd->kp", e_prev, e)
    scale = np.linalg.norm(e_prev, axis=2) * np.linalg.norm(e, axis=2)
    left = np.all(turn >= -1e-9 * scale, axis=1)
    winds_once = np.arctan2(turn, dot).sum(axis=1) <= 2 * np.pi + 1e-6
    return left & winds_once, n_hat


def _off_plane(P: Float[np.ndarray, "k p 3"], n_hat: Float[np.ndarray, "k 3"]) -> Float[np.ndarray, " k"]:
    """Largest distance of a corner from the best-fit plane, over the longest edge, ``(k,)``."""
    P = P - P.mean(axis=1, keepdims=True)
    edge = np.linalg.norm(P - np.roll(P, 1, axis=1), axis=2).max(axis=1)
    return np.abs(np.einsum("kpd,kd->kp", P, n_hat)).max(axis=1) / np.where(edge > 0, edge, 1.0)


def _upright(V: np.ndarray, T: Int[np.ndarray, "k t 3"], n_hat: Float[np.ndarray, "k 3"]) -> np.ndarray:
    """``(k,)``: no triangle ``T[i]`` is flipped against ``n_hat[i]`` (up to ``1e-9·|e_1||e_2|``)."""
    e1, e2 = V[T[..., 1]] - V[T[..., 0]], V[T[..., 2]] - V[T[..., 0]]
    dot = np.einsum("ktd,kd->kt", np.cross(e1, e2), n_hat)
    return np.all(dot >= -1e-9 * np.linalg.norm(e1, axis=-1) * np.linalg.norm(e2, axis=-1), axis=1)


def _fan_angle_ok(V: np.ndarray, fans: Int[np.ndarray, "k t 3"]) -> np.ndarray:
    """``(k,)``: the fan's angles at its apex sum to at most ``2π`` (it does not wind around the apex)."""
    e1, e2 = V[fans[..., 1]] - V[fans[..., 0]], V[fans[..., 2]] - V[fans[..., 0]]
    ang = np.arctan2(np.linalg.norm(np.cross(e1, e2), axis=-1), np.einsum("ktd,ktd->kt", e1, e2))
    return ang.sum(axis=1) <= 2 * np.pi * (1 - 1e-9)


def _twisted(V: np.ndarray, fans: Int[np.ndarray, "k t 3"]) -> np.ndarray:
    """``(k,)``: zero vector area although the fan triangles have area (a bowtie)."""
    C = np.cross(V[fans[..., 1]] - V[fans[..., 0]], V[fans[..., 2]] - V[fans[..., 0]])
    total = np.linalg.norm(C, axis=-1).sum(axis=1)
    return (np.linalg.norm(C.sum(axis=1), axis=1) <= 1e-9 * total) & (total > 0)


def _refuse(V: np.ndarray, corners: np.ndarray, face: int, locate: Callable) -> None:
    P = V[corners][None]
    off = float(_off_plane(P, _convexity(P)[1])[0])
    why = (f"far from planar (corners up to {off:.2g} × its longest edge off its best-fit plane; a volume "
           "element such as a tetrahedron written as a face?)" if off > 1e-2 else "self-intersecting")
    raise NonTriangleFacesError(
        f"face {face} is a polygon with {len(corners)} corners that has no triangulation without overlapping "
        f"or flipped triangles: it is {why}; give a surface mesh of simple, nearly planar polygons or triangles",
        **locate(face),
    )


def _ear_clip(V: np.ndarray, corners: np.ndarray, n_hat: np.ndarray, face: int, locate: Callable) -> np.ndarray:
    """Ear-clip one polygon in the plane ``⟂ n_hat``: ``(p − 2, 3)`` triangles oriented like ``n_hat``.

    Refused unless ``p − 2`` triangles tile the polygon (their areas sum to its
    shoelace area, which fails for a self-intersecting one) and none flips in 3-D.
    """
    import mapbox_earcut

    u = np.cross(n_hat, [1.0, 0.0, 0.0] if abs(n_hat[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n_hat, u)
    P = V[corners]
    xy = np.stack([(P - P[0]) @ u, (P - P[0]) @ v], axis=1)
    p = len(corners)
    t = np.asarray(mapbox_earcut.triangulate_float64(xy, np.array([p], dtype=np.uint32)), dtype=np.int64)
    t = t.reshape(-1, 3)
    a, b, c = xy[t[:, 0]], xy[t[:, 1]], xy[t[:, 2]]
    signed = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    nxt = np.roll(xy, -1, axis=0)
    shoelace = np.sum(xy[:, 0] * nxt[:, 1] - xy[:, 1] * nxt[:, 0])
    t[signed < 0] = t[signed < 0][:, [0, 2, 1]]
    tiles = t.shape[0] == p - 2 and abs(np.abs(signed).sum() - abs(shoelace)) <= 1e-9 * np.abs(signed).sum()
    if not tiles or not _upright(V, corners[t][None], n_hat[None])[0]:
        _refuse(V, corners, face, locate)
    return corners[t]
