"""Named errors of the mesh layer.

All derive from ``MeshError`` (a ``ValueError``), so ``except ValueError``
still catches them. Each message names the problem and a fix.
"""

from __future__ import annotations

__all__ = [
    "MeshError",
    "EmptyMeshError",
    "NonFiniteVerticesError",
    "NonTriangleFacesError",
    "NonManifoldError",
    "IndexOutOfRangeError",
    "DegenerateMeshError",
    "MultipleComponentsWarning",
]


class MeshError(ValueError):
    """Base class for bad mesh input."""


class EmptyMeshError(MeshError):
    """The source holds no vertices or no faces."""


class NonFiniteVerticesError(MeshError):
    """A vertex used by a face has a NaN or infinite coordinate."""


class NonTriangleFacesError(MeshError):
    """Faces are not triangles and cannot be fan-triangulated (fewer than 3 corners)."""


class NonManifoldError(MeshError):
    """Some edge is shared by more than two faces."""


class IndexOutOfRangeError(MeshError):
    """A face refers to a vertex index outside ``[0, n)``."""


class DegenerateMeshError(MeshError):
    """Nothing usable remains after cleaning (e.g. every face has zero area)."""


class MultipleComponentsWarning(UserWarning):
    """The mesh has several connected components: its Laplacian kernel is multi-dimensional."""
