"""Loading, validating and cleaning triangle meshes.

``load`` accepts a path (OBJ, OFF, PLY, STL, read by trimesh with
``process=False`` so that every cleaning step is done — and reported — here),
a ``trimesh.Trimesh``, or a ``(vertices, faces)`` pair, and returns an
immutable ``Mesh`` with a ``CleaningReport`` and its topology (boundary loops,
connected components, Euler characteristic).

Cleaning, in order: fan-triangulate polygons; check indices and finiteness;
merge vertices with identical coordinates; drop faces that repeat a vertex or
have (numerically) zero area; drop duplicate faces; drop unreferenced vertices.
Then edges shared by more than two faces raise ``NonManifoldError``.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import scipy.sparse as sp
import scipy.sparse.csgraph as csgraph
from jaxtyping import Float, Int

from .errors import (
    DegenerateMeshError,
    EmptyMeshError,
    IndexOutOfRangeError,
    MultipleComponentsWarning,
    NonFiniteVerticesError,
    NonManifoldError,
    NonTriangleFacesError,
)

__all__ = ["CleaningReport", "Mesh", "load", "from_arrays", "edges_of", "face_areas"]


@dataclass(frozen=True)
class CleaningReport:
    """What ``load`` changed. All counts refer to the input as given to ``load``."""

    input_vertices: int
    input_faces: int
    triangulated_polygons: int = 0
    merged_duplicate_vertices: int = 0
    dropped_unreferenced_vertices: int = 0
    dropped_collapsed_faces: int = 0
    dropped_zero_area_faces: int = 0
    dropped_duplicate_faces: int = 0

    @property
    def changed(self) -> bool:
        """Whether any cleaning step did anything."""
        return any(
            getattr(self, f) > 0
            for f in (
                "triangulated_polygons",
                "merged_duplicate_vertices",
                "dropped_unreferenced_vertices",
                "dropped_collapsed_faces",
                "dropped_zero_area_faces",
                "dropped_duplicate_faces",
            )
        )


@dataclass(frozen=True, eq=False)
class Mesh:
    """A cleaned, edge-manifold triangle mesh (immutable value).

    Attributes:
      vertices: ``(n, 3)`` float64 positions.
      faces: ``(m, 3)`` int64 vertex indices, every vertex referenced.
      report: what cleaning changed.
      n_components: number of connected components (``> 1`` is allowed but
        flagged: the Laplacian kernel then has that dimension).
      component: ``(n,)`` component label of each vertex.
      n_boundary_loops: number of closed boundary curves (0 for a closed mesh).
      euler_characteristic: ``χ = V − E + F``.
    """

    vertices: Float[np.ndarray, "n 3"]
    faces: Int[np.ndarray, "m 3"]
    report: CleaningReport
    n_components: int
    component: Int[np.ndarray, " n"] = field(repr=False)
    n_boundary_loops: int
    euler_characteristic: int

    @property
    def n_vertices(self) -> int:
        return int(self.vertices.shape[0])

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def is_closed(self) -> bool:
        return self.n_boundary_loops == 0

    @property
    def has_multiple_components(self) -> bool:
        return self.n_components > 1

    @property
    def edges(self) -> Int[np.ndarray, "e 2"]:
        """Unique undirected edges ``(i, j)`` with ``i < j``."""
        return edges_of(self.faces)

    @property
    def total_area(self) -> float:
        return float(face_areas(self.vertices, self.faces).sum())

    def __repr__(self) -> str:
        return (
            f"Mesh(n_vertices={self.n_vertices}, n_faces={self.n_faces}, "
            f"n_components={self.n_components}, n_boundary_loops={self.n_boundary_loops}, "
            f"euler_characteristic={self.euler_characteristic})"
        )


def face_areas(vertices: Float[np.ndarray, "n 3"], faces: Int[np.ndarray, "m 3"]) -> Float[np.ndarray, " m"]:
    """Triangle areas ``|(v1 − v0) × (v2 − v0)| / 2``, shape ``(m,)``."""
    v0, v1, v2 = (vertices[faces[:, c]] for c in range(3))
    return 0.5 * np.linalg.norm(np.cross(v1 - v0, v2 - v0), axis=1)


def edges_of(faces: Int[np.ndarray, "m 3"]) -> Int[np.ndarray, "e 2"]:
    """Unique undirected edges ``(i, j)``, ``i < j``, of a triangle list, shape ``(e, 2)``."""
    und = np.sort(_half_edges(faces), axis=1)
    n = int(faces.max()) + 1 if faces.size else 0
    return _unique_edges(und, n)[0]


def _unique_rows(R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Unique rows of a 2-D array: ``(uniq, first, inverse, counts)`` as ``np.unique(axis=0)``.

    A stable lexicographic sort and a neighbour comparison: several times faster
    than ``np.unique(axis=0)``, which compares rows as opaque byte strings.
    ``first`` is the first occurrence in input order.
    """
    if R.shape[0] == 0:
        e = np.zeros(0, dtype=np.int64)
        return R, e, e, e
    order = np.lexsort(R.T[::-1])
    Rs = R[order]
    new = np.empty(R.shape[0], dtype=bool)
    new[0] = True
    new[1:] = np.any(Rs[1:] != Rs[:-1], axis=1)
    inverse = np.empty(R.shape[0], dtype=np.int64)
    inverse[order] = np.cumsum(new) - 1
    counts = np.diff(np.flatnonzero(np.append(new, True)))
    return Rs[new], order[new], inverse, counts


def _unique_edges(und: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Unique rows of an ``(e, 2)`` array of sorted vertex pairs, and their counts (int64 keys)."""
    key = und[:, 0].astype(np.int64) * n + und[:, 1]
    ukey, counts = np.unique(key, return_counts=True)
    return np.stack([ukey // n, ukey % n], axis=1), counts


def _half_edges(faces: np.ndarray) -> np.ndarray:
    """The ``3m`` directed edges ``(f0,f1), (f1,f2), (f2,f0)`` of every face."""
    return np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=0)


def load(source: Any, *, merge_duplicates: bool = True, warn: bool = True) -> Mesh:
    """Load, validate and clean a triangle mesh.

    Args:
      source: a path (``str`` or ``os.PathLike``; OBJ, OFF, PLY, STL — anything
        trimesh reads), a ``trimesh.Trimesh``, or a ``(vertices, faces)`` pair
        where ``faces`` is an ``(m, p)`` array or a list of index lists
        (polygons are fan-triangulated).
      merge_duplicates: merge vertices with bit-identical coordinates (OBJ
        readers split vertices by normal/texture index; merging restores the
        surface's connectivity).
      warn: emit ``MultipleComponentsWarning`` for a mesh with several components.

    Returns:
      a ``Mesh``.

    Raises:
      EmptyMeshError, NonFiniteVerticesError, NonTriangleFacesError,
      IndexOutOfRangeError, NonManifoldError, DegenerateMeshError (all
      ``MeshError``, a ``ValueError``); ``FileNotFoundError`` for a missing path.
    """
    vertices, faces = _read(source)
    m = from_arrays(vertices, faces, merge_duplicates=merge_duplicates, warn=warn)
    if isinstance(source, (str, os.PathLike)):
        n_poly = _polygons_in_file(Path(source))
        if n_poly:  # trimesh fan-triangulated them while reading
            from dataclasses import replace

            m = replace(m, report=replace(m.report, triangulated_polygons=n_poly))
    return m


def _polygons_in_file(path: Path) -> int:
    """Number of faces with more than 3 corners in an OBJ or OFF file (0 for other formats).

    trimesh triangulates polygons while reading; this recovers the count for the report.
    """
    suffix = path.suffix.lower()
    try:
        if suffix == ".obj":
            n = 0
            with open(path, "r", errors="replace") as fh:
                for line in fh:
                    if line.startswith("f ") and len(line.split()) > 4:
                        n += 1
            return n
        if suffix == ".off":
            tokens = [ln.split("#")[0].split() for ln in open(path, "r", errors="replace")]
            tokens = [t for t in tokens if t]
            head = tokens[0]
            start = 1
            if head[0].upper().endswith("OFF"):
                head = head[1:] or tokens[1]
                start = 1 if len(tokens[0]) > 1 else 2
            nv, nf = int(head[0]), int(head[1])
            rows = tokens[start + nv : start + nv + nf]
            return sum(1 for r in rows if int(r[0]) > 3)
    except (OSError, ValueError, IndexError):
        return 0
    return 0


def _read(source: Any) -> tuple[np.ndarray, Any]:
    import trimesh

    if isinstance(source, (str, os.PathLike)):
        path = Path(source)
        if not path.is_file():
            raise FileNotFoundError(f"no mesh file at {path}")
        if path.stat().st_size == 0:
            raise EmptyMeshError(f"{path} is an empty file; give a mesh file with vertices and faces")
        try:
            tm = trimesh.load(path, process=False, force="mesh")
        except Exception as exc:  # trimesh raises assorted errors on malformed files
            raise EmptyMeshError(
                f"trimesh could not read a mesh from {path} ({type(exc).__name__}: {exc}); "
                "check that the file is a non-empty OBJ/OFF/PLY/STL with faces"
            ) from exc
        return np.asarray(tm.vertices), np.asarray(tm.faces)
    if isinstance(source, trimesh.Trimesh):
        return np.asarray(source.vertices), np.asarray(source.faces)
    if isinstance(source, Sequence) and len(source) == 2:
        return np.asarray(source[0]), source[1]
    raise TypeError(
        "mesh.load expects a path, a trimesh.Trimesh or a (vertices, faces) pair, "
        f"got {type(source).__name__}"
    )


def _triangulate(faces: Any) -> tuple[np.ndarray, int]:
    """Fan-triangulate polygons: ``(a, b, c, d, …) → (a,b,c), (a,c,d), …``. Returns triangles, #polygons."""
    if isinstance(faces, np.ndarray) and faces.ndim == 2:
        rows = faces
        p = rows.shape[1]
        if rows.shape[0] == 0:
            return np.zeros((0, 3), dtype=np.int64), 0
        if p < 3:
            raise NonTriangleFacesError(
                f"faces have {p} corners each; a face needs at least 3 (give triangles or polygons)"
            )
        if not np.issubdtype(rows.dtype, np.integer):
            if not np.all(np.isfinite(rows)) or np.any(rows != np.round(rows)):
                raise IndexOutOfRangeError("face indices must be integers; got non-integral values")
        rows = rows.astype(np.int64)
        if p == 3:
            return rows, 0
        k = np.arange(1, p - 1)
        tris = np.stack(
            [np.repeat(rows[:, 0], p - 2), rows[:, k].reshape(-1), rows[:, k + 1].reshape(-1)], axis=1
        )
        return tris, rows.shape[0]
    polys = [np.asarray(f, dtype=np.int64).reshape(-1) for f in faces]
    if not polys:
        return np.zeros((0, 3), dtype=np.int64), 0
    lengths = np.array([len(f) for f in polys])
    if np.any(lengths < 3):
        bad = int(np.argmax(lengths < 3))
        raise NonTriangleFacesError(
            f"{int(np.sum(lengths < 3))} face(s) have fewer than 3 corners, e.g. face {bad} = "
            f"{polys[bad].tolist()}; remove them or fix the face list"
        )
    flat = np.concatenate(polys)
    starts = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    n_tri = lengths - 2
    face_of_tri = np.repeat(np.arange(len(polys)), n_tri)
    local = np.arange(n_tri.sum()) - np.repeat(np.cumsum(n_tri) - n_tri, n_tri) + 1
    base = starts[face_of_tri]
    tris = np.stack([flat[base], flat[base + local], flat[base + local + 1]], axis=1)
    return tris, int(np.sum(lengths > 3))


def from_arrays(
    vertices: Any, faces: Any, *, merge_duplicates: bool = True, warn: bool = True
) -> Mesh:
    """Validate and clean ``(vertices, faces)``; see ``load``."""
    V = np.asarray(vertices, dtype=np.float64)
    if V.size == 0:
        raise EmptyMeshError("the mesh has no vertices; give a non-empty (n, 3) vertex array")
    if V.ndim != 2 or V.shape[1] != 3:
        raise EmptyMeshError(f"vertices must have shape (n, 3), got {V.shape}")
    F, n_poly = _triangulate(faces)
    n_in, m_in = V.shape[0], F.shape[0]
    if m_in == 0:
        raise EmptyMeshError(
            f"the mesh has {n_in} vertices but no faces (a point cloud?); give a triangle mesh"
        )
    if F.min() < 0 or F.max() >= n_in:
        bad = np.flatnonzero((F < 0).any(1) | (F >= n_in).any(1))
        raise IndexOutOfRangeError(
            f"{bad.size} face(s) refer to vertices outside [0, {n_in}), e.g. face {int(bad[0])} = "
            f"{F[bad[0]].tolist()}; check for 1-based indices (subtract 1) or a truncated vertex list"
        )
    used = np.zeros(n_in, dtype=bool)
    used[F.ravel()] = True
    finite = np.all(np.isfinite(V), axis=1)
    if np.any(used & ~finite):
        bad = np.flatnonzero(used & ~finite)
        raise NonFiniteVerticesError(
            f"{bad.size} vertex/vertices used by faces have NaN or infinite coordinates, e.g. vertex "
            f"{int(bad[0])} = {V[bad[0]].tolist()}; repair or remove them (and their faces)"
        )

    # merge bit-identical vertices (only among finite ones)
    n_merged = 0
    if merge_duplicates:
        Vf = np.where(finite[:, None], V, 0.0)
        key = np.concatenate([Vf, (~finite)[:, None] * np.arange(n_in)[:, None]], axis=1)
        _, first, inverse, _ = _unique_rows(key)
        rep = first[inverse]  # representative (first occurrence) of each vertex
        n_merged = int(np.sum(rep[used] != np.flatnonzero(used)))
        F = rep[F]

    # collapsed faces (a repeated index)
    collapsed = (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])
    F = F[~collapsed]
    # zero-area faces
    if F.shape[0]:
        ext = np.ptp(V[np.unique(F)], axis=0).max()
        areas = face_areas(V, F)
        zero = areas <= 64 * np.finfo(np.float64).eps * ext**2  # round-off level for this extent
        F = F[~zero]
    else:
        zero = np.zeros(0, dtype=bool)
    # duplicate faces (same vertex set)
    n_dup = 0
    if F.shape[0]:
        _, keep, _, _ = _unique_rows(np.sort(F, axis=1))
        keep = np.sort(keep)
        n_dup = F.shape[0] - keep.size
        F = F[keep]
    if F.shape[0] == 0:
        raise DegenerateMeshError(
            f"no faces remain after cleaning ({int(collapsed.sum())} collapsed, {int(zero.sum())} "
            "zero-area); the mesh has no usable triangles"
        )

    # drop unreferenced vertices, compact indices
    ref = np.unique(F)
    remap = np.full(n_in, -1, dtype=np.int64)
    remap[ref] = np.arange(ref.size)
    V_out = np.ascontiguousarray(V[ref])
    F_out = np.ascontiguousarray(remap[F])
    n_unref = n_in - n_merged - ref.size

    _check_manifold(F_out, ref)
    report = CleaningReport(
        input_vertices=n_in,
        input_faces=m_in,
        triangulated_polygons=n_poly,
        merged_duplicate_vertices=n_merged,
        dropped_unreferenced_vertices=int(n_unref),
        dropped_collapsed_faces=int(collapsed.sum()),
        dropped_zero_area_faces=int(zero.sum()),
        dropped_duplicate_faces=int(n_dup),
    )
    return _with_topology(V_out, F_out, report, warn=warn)


def _check_manifold(F: np.ndarray, original: np.ndarray) -> None:
    """Raise ``NonManifoldError`` if some undirected edge has more than two faces.

    ``original[i]`` is the input index of cleaned vertex ``i`` (named in the message).
    """
    und = np.sort(_half_edges(F), axis=1)
    uniq, counts = _unique_edges(und, int(F.max()) + 1)
    bad = counts > 2
    if np.any(bad):
        e = uniq[np.argmax(bad)]
        raise NonManifoldError(
            f"{int(bad.sum())} non-manifold edge(s) shared by more than two faces, e.g. edge "
            f"({int(original[e[0]])}, {int(original[e[1]])}) with {int(counts[np.argmax(bad)])} faces "
            "(input vertex indices); "
            "this looks like a volume or self-overlapping mesh: extract its boundary surface, or "
            "repair it (e.g. libigl/pymeshlab non-manifold edge repair) before loading"
        )


def _with_topology(V: np.ndarray, F: np.ndarray, report: CleaningReport, *, warn: bool) -> Mesh:
    n = V.shape[0]
    und = np.sort(_half_edges(F), axis=1)
    uniq, counts = _unique_edges(und, n)
    n_edges = uniq.shape[0]
    # connected components of the vertex graph
    adj = sp.coo_array((np.ones(n_edges), (uniq[:, 0], uniq[:, 1])), shape=(n, n))
    n_comp, labels = csgraph.connected_components(adj, directed=False)
    # boundary loops: components of the graph of boundary edges (counted on their vertices)
    bnd = uniq[counts == 1]
    if bnd.shape[0]:
        bverts = np.unique(bnd)
        loc = np.searchsorted(bverts, bnd)
        badj = sp.coo_array((np.ones(bnd.shape[0]), (loc[:, 0], loc[:, 1])), shape=(bverts.size,) * 2)
        n_loops, _ = csgraph.connected_components(badj, directed=False)
    else:
        n_loops = 0
    chi = n - n_edges + F.shape[0]
    if n_comp > 1 and warn:
        warnings.warn(
            f"mesh has {n_comp} connected components: its Laplacian has a {n_comp}-dimensional kernel "
            "(one zero eigenvalue per component); use mesh.component to split it if that is not intended",
            MultipleComponentsWarning,
            stacklevel=3,
        )
    return Mesh(
        vertices=V,
        faces=F,
        report=report,
        n_components=int(n_comp),
        component=labels.astype(np.int64),
        n_boundary_loops=int(n_loops),
        euler_characteristic=int(chi),
    )
