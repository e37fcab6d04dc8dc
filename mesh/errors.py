"""Named errors and warnings of the mesh layer.

All errors derive from ``MeshError`` (a ``ValueError``), so ``except ValueError``
still catches them. Each message names the problem and a fix. An error about a
file carries ``path`` and, where it points at one line, ``line`` (1-based); its
message then starts with ``path:line:`` as compilers write it.
"""

from __future__ import annotations

__all__ = [
    "MeshError",
    "MeshFormatError",
    "EmptyMeshError",
    "NonFiniteVerticesError",
    "MeshScaleError",
    "NonTriangleFacesError",
    "NonManifoldError",
    "IndexOutOfRangeError",
    "DegenerateMeshError",
    "MultipleComponentsWarning",
    "MeshCleaningWarning",
]


class MeshError(ValueError):
    """Base class for bad mesh input.

    Args:
      message: what is wrong and how to fix it.
      path: the file it was read from, if any.
      line: the 1-based line (text formats) the problem is on, if known.
    """

    def __init__(self, message: str, *, path: object = None, line: int | None = None):
        self.path = None if path is None else str(path)
        self.line = line
        where = ""
        if self.path is not None:
            where = f"{self.path}:{line}: " if line is not None else f"{self.path}: "
        super().__init__(where + message)


class MeshFormatError(MeshError):
    """The file is not a valid OBJ/OFF/PLY/STL (truncated, garbled, wrong header, unknown format)."""


class EmptyMeshError(MeshError):
    """The source holds no vertices or no faces."""


class NonFiniteVerticesError(MeshError):
    """A vertex used by a face has a NaN or infinite coordinate."""


class MeshScaleError(MeshError):
    """Coordinates so large (or small) that squared edge lengths or areas leave float64's range."""


class NonTriangleFacesError(MeshError):
    """A face has fewer than 3 corners, or a polygon cannot be triangulated."""


class NonManifoldError(MeshError):
    """Some edge is shared by more than two faces (at load, or for a cotangent Laplacian)."""


class IndexOutOfRangeError(MeshError):
    """A face refers to a vertex index outside ``[0, n)`` (or, in an OBJ file, ``[1, n]``)."""


class DegenerateMeshError(MeshError):
    """Nothing usable remains after cleaning (e.g. every face has zero area)."""


class MultipleComponentsWarning(UserWarning):
    """The mesh has several connected components: its Laplacian kernel is multi-dimensional."""


class MeshCleaningWarning(UserWarning):
    """``load`` changed the input (faces dropped, vertices merged, polygons triangulated, …).

    One warning per load; its message joins ``CleaningReport.lines()``.
    """
