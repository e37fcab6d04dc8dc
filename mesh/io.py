"""Loading triangle meshes: ``load`` and the immutable ``Mesh``.

``load`` accepts a path (OBJ, OFF, PLY, STL, optionally gzip-compressed; read
strictly by ``readers.py``/``ply.py``), a ``trimesh.Trimesh``, or a
``(vertices, faces)`` pair; cleans it (``cleaning.py``: triangulation,
merging, dropping degenerate faces, each counted in ``Mesh.report``) and
records its topology (``topology.py``: components, boundary loops, Euler
characteristic, non-manifold edges and vertices).

Edges shared by more than two faces raise ``NonManifoldError`` unless
``allow_nonmanifold=True``; such a mesh then needs ``laplacian(m,
weights="robust")``.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
from jaxtyping import Float, Int

from .arrays import edges_of, face_areas
from .cleaning import ZERO_AREA_TOL, CleaningReport, clean
from .errors import MeshCleaningWarning, MultipleComponentsWarning
from .readers import read_mesh_file

__all__ = ["CleaningReport", "Mesh", "load", "from_arrays", "edges_of", "face_areas"]


@dataclass(frozen=True, eq=False)
class Mesh:
    """A cleaned triangle mesh (immutable value).

    Attributes:
      vertices: ``(n, 3)`` float64 positions.
      faces: ``(m, 3)`` int64 vertex indices, every vertex referenced.
      report: what cleaning changed and found (``report.lines()``, ``report.as_dict()``).
      n_components: number of connected components (``> 1`` is allowed but
        flagged: the Laplacian kernel then has that dimension).
      component: ``(n,)`` component label of each vertex.
      n_boundary_loops: components of the graph of boundary edges (edges with one
        face); 0 for a closed mesh. On a non-edge-manifold mesh such a "loop" may
        branch at a non-manifold vertex and still counts once.
      euler_characteristic: ``χ = V − E + F``.
      n_nonmanifold_edges: edges with more than two faces (non-zero only when
        loaded with ``allow_nonmanifold=True``).
      n_nonmanifold_vertices: vertices not surrounded by one disc or half-disc
        (endpoints of non-manifold edges, and "bowtie" vertices where face fans meet).
    """

    vertices: Float[np.ndarray, "n 3"]
    faces: Int[np.ndarray, "m 3"]
    report: CleaningReport
    n_components: int
    component: Int[np.ndarray, " n"] = field(repr=False)
    n_boundary_loops: int
    euler_characteristic: int
    n_nonmanifold_edges: int = 0
    n_nonmanifold_vertices: int = 0

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
    def is_edge_manifold(self) -> bool:
        """No edge has more than two faces (the cotangent Laplacian needs this)."""
        return self.n_nonmanifold_edges == 0

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
        nm = "" if self.is_edge_manifold else f", n_nonmanifold_edges={self.n_nonmanifold_edges}"
        return (
            f"Mesh(n_vertices={self.n_vertices}, n_faces={self.n_faces}, "
            f"n_components={self.n_components}, n_boundary_loops={self.n_boundary_loops}, "
            f"euler_characteristic={self.euler_characteristic}{nm})"
        )


def load(
    source: Any,
    *,
    merge_duplicates: bool = True,
    warn: bool = True,
    allow_nonmanifold: bool = False,
    zero_area_tol: float = ZERO_AREA_TOL,
) -> Mesh:
    """Load, validate and clean a triangle mesh.

    Args:
      source: a path (``str`` or ``os.PathLike``; ``.obj``, ``.off``, ``.ply``,
        ``.stl``, each optionally ``.gz``), a ``trimesh.Trimesh``, or a
        ``(vertices, faces)`` pair where ``faces`` is an ``(m, p)`` array or a
        list of index lists (polygons are triangulated: convex ones fanned,
        non-convex ones ear-clipped).
      merge_duplicates: merge vertices with bit-identical coordinates (STL and
        some exporters split vertices per face; merging restores connectivity).
      warn: emit one ``MeshCleaningWarning`` summarising ``report.lines()`` when
        anything changed or was found, and ``MultipleComponentsWarning`` for
        several components.
      allow_nonmanifold: load meshes with edges shared by more than two faces
        (counted in ``Mesh.n_nonmanifold_edges``); use ``weights="robust"`` for
        their Laplacian.
      zero_area_tol: drop a face whose height is at most ``zero_area_tol`` times
        its longest edge (plus round-off of its coordinates; ``cleaning.py``).

    Returns:
      a ``Mesh``; ``Mesh.report.lines()`` says what changed.

    Raises:
      MeshFormatError (bad file: message starts ``path:line:``),
      EmptyMeshError (no vertices, or no faces: point clouds are not supported),
      NonFiniteVerticesError, MeshScaleError (coordinates too large or small for
      float64 areas: rescale), NonTriangleFacesError, IndexOutOfRangeError,
      NonManifoldError, DegenerateMeshError (all ``MeshError``, a
      ``ValueError``); ``FileNotFoundError`` for a missing path.
    """
    kw = dict(merge_duplicates=merge_duplicates, warn=warn, allow_nonmanifold=allow_nonmanifold,
              zero_area_tol=zero_area_tol)
    if isinstance(source, (str, os.PathLike)):
        raw = read_mesh_file(source)
        info = {"source": raw.path, "file_format": raw.file_format, "compressed": raw.compressed,
                "encoding": raw.encoding, "ignored_elements": raw.ignored}
        return _build(raw.vertices, raw.faces, locate=lambda f: {"path": raw.path, "line": raw.face_line(f)},
                      source=info, examples={"ignored_elements": raw.ignored_example} if raw.ignored else None, **kw)
    if isinstance(source, Sequence) and not isinstance(source, bytes) and len(source) == 2:
        return _build(np.asarray(source[0]), source[1], **kw)
    import trimesh

    if isinstance(source, trimesh.Trimesh):
        return _build(np.asarray(source.vertices), np.asarray(source.faces), **kw)
    raise TypeError(
        "mesh.load expects a path, a trimesh.Trimesh or a (vertices, faces) pair, "
        f"got {type(source).__name__}"
    )


def from_arrays(vertices: Any, faces: Any, **kw: Any) -> Mesh:
    """Validate and clean ``(vertices, faces)``; keywords as ``load``."""
    return _build(vertices, faces, **kw)


def _build(vertices: Any, faces: Any, *, warn: bool = True, **kw: Any) -> Mesh:
    V, F, report, topo = clean(vertices, faces, **kw)
    if warn:
        lines = report.lines(components=False)
        if lines:
            where = f"{report.source}: " if report.source else ""
            warnings.warn(f"mesh.load changed or found: {where}" + "; ".join(lines), MeshCleaningWarning, stacklevel=3)
        if topo.n_components > 1:
            warnings.warn(
                f"mesh has {topo.n_components} connected components: its Laplacian has a "
                f"{topo.n_components}-dimensional kernel (one zero eigenvalue per component); use "
                "mesh.component to split it if that is not intended",
                MultipleComponentsWarning,
                stacklevel=3,
            )
    return Mesh(
        vertices=V,
        faces=F,
        report=report,
        n_components=topo.n_components,
        component=topo.component,
        n_boundary_loops=topo.n_boundary_loops,
        euler_characteristic=int(V.shape[0] - topo.n_edges + F.shape[0]),
        n_nonmanifold_edges=int(topo.nonmanifold_edges.shape[0]),
        n_nonmanifold_vertices=int(topo.nonmanifold_vertices.size),
    )
