"""A mesh file's contents before cleaning, and the text decoding every text reader shares.

``RawMesh`` is what ``mesh.readers`` and ``mesh.ply`` return; ``mesh.cleaning`` turns it into a ``Mesh``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from jaxtyping import Float

from .errors import MeshFormatError
from .triangulate import Polygons

__all__ = ["RawMesh", "decode_text"]


@dataclass(frozen=True)
class RawMesh:
    """A file's contents before cleaning.

    Attributes:
      vertices: ``(n, 3)`` float64 positions as listed.
      faces: polygons with 0-based indices into ``vertices``.
      path, file_format, compressed, encoding: where it came from and how it was
        decoded (``encoding`` is ``None`` for binary data).
      face_line: 1-based line of input face ``f`` (``None`` where not known).
      ignored: number of statements skipped (OBJ lines, points, curves, …) and
        an example of them.
    """

    vertices: Float[np.ndarray, "n 3"]
    faces: Polygons
    path: str
    file_format: str
    compressed: bool = False
    encoding: str | None = None
    face_line: Callable[[int], int | None] = lambda f: None
    ignored: int = 0
    ignored_example: str | None = None


_CONTROL = re.compile(rb"[\x00-\x08\x0e-\x1f\x7f]")
_NOT_CONTROL = bytes(b for b in range(256) if not _CONTROL.match(bytes([b])))


def decode_text(data: bytes, path: Path, fmt: str) -> tuple[str, str]:
    """``(text, encoding)``: UTF-8 (BOM stripped), else Latin-1; control bytes are refused."""
    bad = _CONTROL.search(data) if data.translate(None, _NOT_CONTROL) else None  # translate: 10× faster scan
    if bad:
        line = data.count(b"\n", 0, bad.start()) + 1
        raise MeshFormatError(
            f"not a valid {fmt.upper()} file: binary byte 0x{data[bad.start()]:02x} at offset {bad.start()} "
            f"in a text format (corrupt file, or another format renamed .{fmt}?)",
            path=path,
            line=line,
        )
    try:
        return data.decode("utf-8-sig"), "utf-8"
    except UnicodeDecodeError:
        return data.decode("latin-1"), "latin-1"
