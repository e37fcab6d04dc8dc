"""Validating and cleaning ``(vertices, polygons)``, and the ``CleaningReport`` of what changed.

Order: check corner counts, index range and finiteness of used vertices; check
the scale (edges between about 1e-77 and 1e77, so that squared areas are
normal floats, else ``MeshScaleError``: nothing is rescaled silently);
triangulate polygons (``triangulate.py``); merge vertices with identical
coordinates; drop faces that repeat a vertex, zero-area faces and duplicate
faces; drop unreferenced vertices; find components and non-manifold elements
(``topology.py``).

Zero area is judged per face, independent of the rest of the mesh: with
``ℓ`` the face's longest edge, ``h = 2·area/ℓ`` its height and ``R`` the
largest absolute coordinate of its corners, the face is dropped when
``h ≤ zero_area_tol·ℓ + 64·ε·R`` (``ε`` the float64 epsilon). The first term is
the shape test (default ``1e-12``: only needles and caps flat to round-off);
the second is the resolution of the corners' own coordinates, so a
collinear triple far from the origin still counts as degenerate.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Callable

import numpy as np
from jaxtyping import Float, Int

from .arrays import unique_rows
from .errors import (DegenerateMeshError, EmptyMeshError, IndexOutOfRangeError, MeshScaleError, NonFiniteVerticesError, NonManifoldError)
from .topology import Topology, topology
from .triangulate import as_polygons, triangulate

__all__ = ["CleaningReport", "clean", "ZERO_AREA_TOL"]

ZERO_AREA_TOL = 1e-12
_CHANGES = ("triangulated_polygons", "merged_duplicate_vertices", "dropped_unreferenced_vertices",
            "dropped_collapsed_faces", "dropped_zero_area_faces", "dropped_duplicate_faces")


@dataclass(frozen=True)
class CleaningReport:
    """What ``load`` changed and found; counts refer to the input as given to ``load``.

    Use ``report.lines()`` for human-readable lines (empty for a clean,
    single-component, manifold mesh) and ``report.as_dict()`` for a JSON-ready
    dict of every field below, e.g. in a CLI::

        for line in m.report.lines():
            print(f"warning: {line}", file=sys.stderr)
        summary["mesh"]["cleaning"] = m.report.as_dict()

    Attributes:
      input_vertices, input_faces: as listed (a polygon counts as one face).
      output_vertices, output_faces: of the cleaned triangle mesh.
      triangulated_polygons: faces with more than 3 corners (``triangulated_quads``
        of them quads) that became ``triangles_from_polygons`` triangles;
        ``nonconvex_polygons`` of them are non-convex and ``nonplanar_polygons``
        far from planar (``triangulate.py``); all became triangles without flips.
      merged_duplicate_vertices: used vertices merged into an earlier one with
        identical coordinates.
      dropped_unreferenced_vertices: vertices no face uses (after merging).
      dropped_collapsed_faces, dropped_zero_area_faces, dropped_duplicate_faces:
        triangles with a repeated vertex, with zero area (``zero_area_tol``, see
        the module docstring), repeating an earlier triangle's vertex set.
      n_components: connected components found (1 for a connected mesh).
      n_nonmanifold_edges, n_nonmanifold_vertices: see ``mesh.topology``; edges
        are non-zero only with ``allow_nonmanifold=True``.
      ignored_elements: file statements not read (OBJ lines/points/curves or
        unknown keywords, extra PLY elements).
      source, file_format, compressed, encoding: the file (``None`` for arrays).
      examples: one example per non-zero count, e.g. ``{"dropped_zero_area_faces":
        "face 17, line 893"}``; faces and vertices are 0-based input indices,
        lines 1-based lines of the file.
    """

    input_vertices: int
    input_faces: int
    output_vertices: int = 0
    output_faces: int = 0
    triangulated_polygons: int = 0
    triangulated_quads: int = 0
    triangles_from_polygons: int = 0
    nonconvex_polygons: int = 0
    nonplanar_polygons: int = 0
    merged_duplicate_vertices: int = 0
    dropped_unreferenced_vertices: int = 0
    dropped_collapsed_faces: int = 0
    dropped_zero_area_faces: int = 0
    dropped_duplicate_faces: int = 0
    n_components: int = 1
    n_nonmanifold_edges: int = 0
    n_nonmanifold_vertices: int = 0
    ignored_elements: int = 0
    zero_area_tol: float = ZERO_AREA_TOL
    source: str | None = None
    file_format: str | None = None
    compressed: bool = False
    encoding: str | None = None
    examples: dict[str, str] = field(default_factory=dict)

    @property
    def changed(self) -> bool:
        """Whether any cleaning step changed the mesh (triangulated, merged or dropped anything)."""
        return any(getattr(self, f) > 0 for f in _CHANGES)

    def as_dict(self) -> dict[str, Any]:
        """Every field as plain JSON types (``json.dumps(report.as_dict())`` works)."""
        return asdict(self)

    def lines(self, *, components: bool = True) -> list[str]:
        """Human-readable lines, one per change or finding, e.g. ``"dropped 3 faces with zero area (e.g. face 17)"``.

        ``components=False`` leaves out the connected-components line (it has its own warning).
        """
        ex = {k: f" (e.g. {v})" for k, v in self.examples.items()}
        out = []
        if self.triangulated_polygons:
            quads = f" ({_n(self.triangulated_quads, 'quad')})" if self.triangulated_quads else ""
            out.append(f"triangulated {_n(self.triangulated_polygons, 'polygon')}{quads} into "
                       f"{_n(self.triangles_from_polygons, 'triangle')}")
        for key, what in (("nonconvex_polygons", "non-convex"), ("nonplanar_polygons", "far from planar")):
            if getattr(self, key):
                out.append(f"{_n(getattr(self, key), 'polygon')} {what}, triangulated without flipped triangles"
                           f"{ex.get(key, '')}")
        for key, text in (("merged_duplicate_vertices", "merged {} with identical coordinates"),
                          ("dropped_unreferenced_vertices", "dropped {} that no face uses"),
                          ("dropped_collapsed_faces", "dropped {} with a repeated vertex"),
                          ("dropped_zero_area_faces", "dropped {} with zero area"),
                          ("dropped_duplicate_faces", "dropped {} repeating an earlier face")):
            k = getattr(self, key)
            if k:
                out.append(text.format(_n(k, "vertex", "vertices") if "vertices" in key else _n(k, "face"))
                           + ex.get(key, ""))
        if self.ignored_elements:
            what = _n(self.ignored_elements, "unsupported statement or element", "unsupported statements or elements")
            out.append(f"ignored {what} of the file{ex.get('ignored_elements', '')}")
        if self.encoding == "latin-1":
            out.append("decoded the file as Latin-1 (it is not valid UTF-8)")
        if self.n_nonmanifold_edges:
            out.append(f"kept {_n(self.n_nonmanifold_edges, 'non-manifold edge')}{ex.get('n_nonmanifold_edges', '')}"
                       " (allow_nonmanifold=True): its Laplacian needs weights='robust'")
        if self.n_nonmanifold_vertices:
            out.append(f"{_n(self.n_nonmanifold_vertices, 'non-manifold vertex', 'non-manifold vertices')} (the "
                       f"surface is not a disc or half-disc there){ex.get('n_nonmanifold_vertices', '')}")
        if components and self.n_components > 1:
            out.append(f"found {self.n_components} connected components (the Laplacian kernel has dimension "
                       f"{self.n_components})")
        return out


def clean(
    vertices: Any,
    faces: Any,
    *,
    merge_duplicates: bool = True,
    allow_nonmanifold: bool = False,
    zero_area_tol: float = ZERO_AREA_TOL,
    locate: Callable[[int], dict] | None = None,
    source: dict | None = None,
    examples: dict[str, str] | None = None,
) -> tuple[Float[np.ndarray, "n 3"], Int[np.ndarray, "m 3"], CleaningReport, Topology]:
    """Validate and clean; returns ``(V (n, 3), F (m, 3), report, topology)``.

    ``locate(face)`` gives ``path=``/``line=`` for messages about input face
    ``face``; ``source`` holds the report's file fields (``source``,
    ``file_format``, ``compressed``, ``encoding``, ``ignored_elements``) and
    ``examples`` the reader's examples.
    """
    locate = locate or (lambda f: {})
    where = _describe(locate)
    path = {"path": source["source"]} if source else {}
    V = np.asarray(vertices, dtype=np.float64)
    if V.size == 0:
        raise EmptyMeshError("the mesh has no vertices; give a non-empty (n, 3) vertex array", **path)
    if V.ndim != 2 or V.shape[1] != 3:
        raise EmptyMeshError(f"vertices must have shape (n, 3), got {V.shape}", **path)
    polys = as_polygons(faces)
    n_in, m_in = V.shape[0], polys.sizes.size
    if m_in == 0:
        raise EmptyMeshError(f"no faces: point clouds are not supported (the mesh has {n_in} vertices and no "
                             "faces); give a triangle mesh", **path)
    flat = polys.flat
    outside = (flat < 0) | (flat >= n_in)
    if outside.any():
        bad = np.flatnonzero(np.add.reduceat(outside, polys.starts))
        face = int(bad[0])
        corners = polys.rows(bad[:1], int(polys.sizes[face]))[0].tolist()
        raise IndexOutOfRangeError(
            f"{bad.size} face(s) refer to vertices outside [0, {n_in}), e.g. face {face} = {corners}; check for "
            "1-based indices (subtract 1) or a truncated vertex list", **locate(face))
    used = np.zeros(n_in, dtype=bool)
    used[flat] = True
    finite = np.all(np.isfinite(V), axis=1)
    if np.any(used & ~finite):
        bad = np.flatnonzero(used & ~finite)
        raise NonFiniteVerticesError(
            f"{bad.size} vertex/vertices used by faces have NaN or infinite coordinates, e.g. vertex "
            f"{int(bad[0])} = {V[bad[0]].tolist()}; repair or remove them (and their faces)", **path)
    if np.any(polys.sizes > 3):  # keep overflow out of the triangulation (triangles are checked below)
        nxt = np.arange(flat.size) + 1
        nxt[polys.starts + polys.sizes - 1] = polys.starts
        A, B = V[flat], V[flat[nxt]]
        with np.errstate(over="ignore", invalid="ignore"):
            span = np.abs(A - B).max(axis=1)
        corner_face = np.repeat(np.arange(m_in), polys.sizes)
        _check_scale(span, np.maximum(np.abs(A), np.abs(B)).max(axis=1), corner_face, where, path)

    tri = triangulate(V, polys, locate)
    F, origin = tri.triangles, tri.origin
    ex: dict[str, str] = dict(examples or {})
    for key, ids in (("nonconvex_polygons", tri.nonconvex), ("nonplanar_polygons", tri.nonplanar)):
        if ids.size:
            ex[key] = where(int(ids[0]))

    n_merged = 0
    if merge_duplicates:
        _, first, inverse, _ = unique_rows(V)  # finite used vertices only can be merged: NaN never equals
        rep = first[inverse]
        rep[~finite] = np.flatnonzero(~finite)
        merged = used & (rep != np.arange(n_in))
        n_merged = int(merged.sum())
        if n_merged:
            v = int(np.argmax(merged))
            ex["merged_duplicate_vertices"] = f"vertex {v}, a copy of vertex {int(rep[v])}"
        F = rep[F]

    drops = {}
    keep = ~((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0]))
    drops["dropped_collapsed_faces"] = ~keep
    zero = keep & _zero_area(V[F], zero_area_tol, origin, where, path)
    drops["dropped_zero_area_faces"] = zero
    keep &= ~zero
    dup = np.zeros(F.shape[0], dtype=bool)
    live = np.flatnonzero(keep)
    _, firsts, _, _ = unique_rows(np.sort(F[live], axis=1))
    dup[live] = True
    dup[live[firsts]] = False
    drops["dropped_duplicate_faces"] = dup
    keep &= ~dup
    for key, mask in drops.items():
        if mask.any():
            ex[key] = where(int(origin[np.argmax(mask)]))
    if not keep.any():
        raise DegenerateMeshError(
            f"no faces remain after cleaning ({int(drops['dropped_collapsed_faces'].sum())} collapsed, "
            f"{int(zero.sum())} zero-area); the mesh has no usable triangles", **path)
    F = F[keep]

    ref = np.zeros(n_in, dtype=bool)
    ref[F.ravel()] = True
    ref = np.flatnonzero(ref)
    remap = np.full(n_in, -1, dtype=np.int64)
    remap[ref] = np.arange(ref.size)
    V_out, F_out = np.ascontiguousarray(V[ref]), np.ascontiguousarray(remap[F])
    unref = np.ones(n_in, dtype=bool)
    unref[ref] = False
    if merge_duplicates:
        unref &= ~merged
    if unref.any():
        ex["dropped_unreferenced_vertices"] = f"vertex {int(np.argmax(unref))}"

    topo = topology(F_out, ref.size)
    n_bad = topo.nonmanifold_edges.shape[0]
    if n_bad:
        a, b = (int(ref[i]) for i in topo.nonmanifold_edges[0])
        ex["n_nonmanifold_edges"] = f"edge ({a}, {b}) with {int(topo.nonmanifold_edge_faces[0])} faces"
        if not allow_nonmanifold:
            raise NonManifoldError(
                f"{n_bad} non-manifold edge(s) shared by more than two faces, e.g. {ex['n_nonmanifold_edges']} "
                "(input vertex indices); this looks like a volume or self-overlapping mesh: repair it (extract "
                "its boundary surface, or e.g. libigl/pymeshlab non-manifold edge repair), or load it with "
                "mesh.load(..., allow_nonmanifold=True) and use the robust Laplacian (weights='robust'; "
                "--laplacian robust on the command line)", **path)
    if topo.nonmanifold_vertices.size:
        ex["n_nonmanifold_vertices"] = f"vertex {int(ref[topo.nonmanifold_vertices[0]])}"
    report = CleaningReport(
        input_vertices=n_in, input_faces=m_in, output_vertices=int(ref.size), output_faces=int(F_out.shape[0]),
        triangulated_polygons=tri.n_polygons, triangulated_quads=tri.n_quads,
        triangles_from_polygons=int(np.sum(polys.sizes[polys.sizes > 3] - 2)),
        nonconvex_polygons=int(tri.nonconvex.size), nonplanar_polygons=int(tri.nonplanar.size),
        merged_duplicate_vertices=n_merged,
        dropped_unreferenced_vertices=int(unref.sum()),
        **{k: int(mask.sum()) for k, mask in drops.items()},
        n_components=topo.n_components, n_nonmanifold_edges=n_bad,
        n_nonmanifold_vertices=int(topo.nonmanifold_vertices.size), zero_area_tol=float(zero_area_tol),
        examples=ex, **(source or {}),
    )
    return V_out, F_out, report, topo


def _n(k: int, word: str, plural: str | None = None) -> str:
    return f"{k} {word if k == 1 else plural or word + 's'}"


def _describe(locate: Callable[[int], dict]) -> Callable[[int], str]:
    def where(face: int) -> str:
        line = locate(face).get("line")
        return f"face {face}" + (f", line {line}" if line is not None else "")

    return where


def _zero_area(
    P: Float[np.ndarray, "m 3 3"], tol: float, origin: np.ndarray, where: Callable, path: dict
) -> np.ndarray:
    """``(m,)``: ``h ≤ tol·ℓ + 64·ε·R`` (module docstring), after ``_check_scale`` on the same faces.

    ``P``: corner positions; ``origin``: input face of each (for messages).
    """
    E = P[:, [1, 2, 0]] - P  # edge c runs from corner c to c+1
    R = np.abs(P).max(axis=(1, 2))
    with np.errstate(over="ignore", invalid="ignore"):
        span = np.abs(E).max(axis=(1, 2))
    _check_scale(span, R, origin, where, path)
    twice_area = np.linalg.norm(np.cross(E[:, 0], E[:, 2]), axis=1)
    ell = np.sqrt(np.max(np.sum(E**2, axis=2), axis=1))
    return twice_area <= ell * (tol * ell + 64 * np.finfo(np.float64).eps * R)


def _check_scale(span: np.ndarray, R: np.ndarray, face: np.ndarray, where: Callable, path: dict) -> None:
    """Raise ``MeshScaleError`` where squared areas (``~ℓ⁴``) leave float64's range.

    ``span``: largest coordinate difference along an edge (``ℓ/√3 ≤ span ≤ ℓ``,
    computed without squaring), ``R``: largest absolute coordinate of its
    corners, ``face``: input face of each. Too small counts only when the edge
    is resolvable in its coordinates (``span > 64·ε·R``); otherwise the face is
    merely degenerate and the zero-area test drops it.
    """
    with np.errstate(over="ignore", invalid="ignore", under="ignore"):
        q = 9 * span**4
        over = ~np.isfinite(q)
        under = (span**4 < np.finfo(np.float64).tiny) & (span > 64 * np.finfo(np.float64).eps * R)
    if not (over.any() or under.any()):
        return
    i = int(np.argmax(over if over.any() else under))
    raise MeshScaleError(
        f"squared face areas {'overflow' if over.any() else 'underflow'} float64 ({where(int(face[i]))} has an "
        f"edge spanning {span[i]:.3g}; edges must lie between about 1e-77 and 1e77): its Laplacian would be "
        "inf, NaN or zero; rescale the vertices (e.g. divide them by their largest absolute coordinate) before "
        "loading — mesh.load does not rescale silently", **path)
