"""Writers and small parsers for the CLI: μ strings, bounded integers, provenance, PLY, JSON values.

Nothing here imports numpy or JAX at module level (a Ctrl-C during the CLI's start-up must reach
``stiefel_cmm.cli.main.main``); they are imported where used.
"""

from __future__ import annotations

import math
import os
import platform
import re
import sys
from pathlib import Path
from typing import Any, BinaryIO, Callable

__all__ = ["PROG", "MuSpec", "PartialColumns", "parse_mu", "bounded_int", "INT_MAX", "versions", "to_jsonable",
           "write_ply", "stderr_line"]

#: the command's name, first word of every message it prints
PROG = "stiefel"
#: the largest integer option the CLI accepts (a C ``int``; larger values overflow deep inside)
INT_MAX = 2**31 - 1

_MU_RE = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*(n|λ|lambda|lam|)\s*$")
#: a number followed by anything (for naming an unknown unit)
_MU_NUMBER_RE = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*(.*?)\s*$")


class MuSpec:
    """A sparsity weight as given on the command line: absolute (``"5.2"``), relative to the vertex
    count (``"0.01n"``) or to the spectrum (``"2λ"``, also written ``2lambda``/``2lam``).

    ``resolve(n, lam)`` gives the absolute μ: ``value``, ``value · n`` (n = number of vertices) or
    ``value · λ`` with ``λ = λ_{k−1}``, the largest of the first k Laplacian eigenvalues (``Wφ = λAφ``,
    areas normalised to total 1): the scale of the Dirichlet energy of the k modes sought, so ``2λ``
    asks for the same balance of smoothness and sparsity on a coarse and a fine mesh of one shape.
    """

    def __init__(self, text: str, value: float, unit: str) -> None:
        self.text, self.value, self.unit = text, value, unit
        self.relative = unit == "n"  # (kept: summary.json's mu.relative)

    def resolve(self, n: int, lam: float | None = None) -> float:
        """Absolute μ for a mesh with ``n`` vertices (and ``lam`` = λ_{k−1} when the unit is λ)."""
        if self.unit == "λ":
            if lam is None:
                raise ValueError(f"mu {self.text!r} is relative to λ_(k−1): the eigenvalue is needed")
            return self.value * float(lam)
        return self.value * n if self.unit == "n" else self.value

    def __repr__(self) -> str:
        return f"MuSpec({self.text!r})"


def parse_mu(text: str) -> MuSpec:
    """Parse ``"5.2"``, ``"1e-3"``, ``"0.01n"`` or ``"2λ"`` (``2lambda``, ``2lam``); raise ``ValueError``
    naming the fix otherwise.

    Used as an argparse ``type=``: argparse turns the error into a usage error (exit 2).
    """
    m = _MU_RE.match(text)
    if m is None:
        forms = ("give a non-negative number (e.g. 5.2), a multiple of the vertex count (e.g. 0.01n) or of the k-th "
                 "Laplacian eigenvalue λ_(k−1) (e.g. 2λ or 2lambda)")
        stripped = text.strip()
        if stripped.startswith("-") and _MU_RE.match(stripped[1:]):
            raise ValueError(f"invalid mu {text!r}: μ must be ≥ 0 (it weighs the ℓ1 term; 0 gives the "
                             f"eigenfunctions): {forms}")
        number = _MU_NUMBER_RE.match(text)
        if number is not None and number.group(2):
            raise ValueError(f"invalid mu {text!r}: unknown unit {number.group(2)!r} after {number.group(1)}; "
                             f"{forms}")
        raise ValueError(f"invalid mu {text!r}: {forms}")
    value = float(m.group(1))
    if not math.isfinite(value):
        raise ValueError(f"invalid mu {text!r}: must be finite")
    unit = {"": "", "n": "n"}.get(m.group(2), "λ")
    return MuSpec(text, value, unit)


def bounded_int(low: int, high: int = INT_MAX) -> Callable[[str], int]:
    """An argparse ``type=``: an integer in ``[low, high]``, else ``ValueError`` naming the range."""

    def parse(text: str) -> int:
        try:
            v = int(text)
        except ValueError:
            raise ValueError(f"expected an integer in [{low}, {high}], got {text!r}") from None
        if not low <= v <= high:
            raise ValueError(f"expected an integer in [{low}, {high}], got {v}")
        return v

    parse.__name__ = "integer"
    return parse


def _version(dist: str) -> str | None:
    from importlib import metadata

    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def versions() -> dict[str, str | None]:
    """Versions of python, jax, jaxlib, numpy, scipy, trimesh and this package (``stiefel-cmm``)."""
    import jax
    import numpy as np
    import scipy
    import trimesh

    return {
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxlib": _version("jaxlib"),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "trimesh": trimesh.__version__,
        "stiefel-cmm": _version("stiefel-cmm") or "0.1.0 (not installed)",
        "platform": platform.platform(),
    }


def to_jsonable(obj: Any) -> Any:
    """Recursively turn numpy scalars/arrays, tuples and paths into JSON-serialisable values."""
    import numpy as np

    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, Path):
        return str(obj)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_ply(target: BinaryIO, vertices: Any, faces: Any, fields: Any, names: list[str] | None = None,
              *, ascii: bool = False) -> None:
    """PLY (binary little-endian, or ASCII with ``ascii=True``) written by ``plyfile``, with one float64
    vertex property per column of ``fields``, to a binary file (the CLI passes a staged file of
    ``stiefel_cmm.cli.run_dir.RunDir``, which makes the write atomic).

    vertices: ``(n, 3)`` (float64 x, y, z); faces: ``(m, 3)`` (``vertex_indices``, uchar count and
    int32 indices); fields: ``(n, k)``, written as properties ``mode_0 … mode_{k-1}`` (or ``names``)
    after x, y, z. Read them back with ``plyfile.PlyData.read(path)["vertex"]["mode_0"]`` (also
    meshio, MeshLab, Blender).
    """
    import numpy as np
    import plyfile

    vertices = np.asarray(vertices, dtype=np.float64)
    fields = np.asarray(fields, dtype=np.float64).reshape(vertices.shape[0], -1)
    names = names or [f"mode_{j}" for j in range(fields.shape[1])]
    vdata = np.empty(vertices.shape[0], dtype=[(c, "<f8") for c in ("x", "y", "z", *names)])
    for j, c in enumerate("xyz"):
        vdata[c] = vertices[:, j]
    for j, name in enumerate(names):
        vdata[name] = fields[:, j]
    fdata = np.empty(len(faces), dtype=[("vertex_indices", "<i4", (3,))])
    fdata["vertex_indices"] = np.asarray(faces, dtype=np.int64)
    elements = [plyfile.PlyElement.describe(vdata, "vertex"),
                plyfile.PlyElement.describe(fdata, "face", len_types={"vertex_indices": "u1"},
                                            val_types={"vertex_indices": "i4"})]
    plyfile.PlyData(elements, text=ascii, byte_order="<",
                    comments=["stiefel-cmm compressed manifold modes"]).write(target)


def stderr_line(msg: str) -> None:
    """Print one line to stderr (newlines collapsed)."""
    print(" ".join(str(msg).split()), file=sys.stderr)


class PartialColumns:
    """Callback ``(j, info)`` that saves finished columns to ``path`` as they arrive.

    Made for ``stiefel.minimize_sequential``'s ``callback(j, {"x": (n,), "value", "status", …})``:
    after column ``j`` the file holds ``modes (n, j+1)`` (solve order, not yet
    sorted by compressed eigenvalue), ``values`` and ``status``. Written to a
    temporary name, fsynced and renamed, so a reader never sees half a file. ``say``,
    if given, gets one progress line per column.
    """

    #: appended to the file name while it is written
    TMP_SUFFIX = ".tmp.npz"

    def __init__(self, path: Path, say: Callable[[str], None] | None = None) -> None:
        self.path, self.say = Path(path), say
        self.columns: list[Any] = []
        self.values: list[float] = []
        self.status: list[str] = []

    @property
    def tmp(self) -> Path:
        """The temporary name the file is written to before the rename."""
        return self.path.with_name(self.path.name + self.TMP_SUFFIX)

    def __call__(self, j: int, info: dict) -> None:
        import numpy as np

        if j < len(self.columns):  # a new continuation stage restarts the columns
            del self.columns[j:], self.values[j:], self.status[j:]
        self.columns.append(np.asarray(info["x"], dtype=np.float64))
        self.values.append(float(info.get("value", np.nan)))
        self.status.append(str(info.get("status", "")))
        try:
            with open(self.tmp, "wb") as fh:
                np.savez(fh, modes=np.stack(self.columns, axis=1), values=np.array(self.values),
                         status=np.array(self.status))
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(self.tmp, self.path)
        except BaseException:
            self.tmp.unlink(missing_ok=True)
            raise
        if self.say is not None:
            self.say(f"column {j} done ({self.status[-1]}), saved {self.path}")

    def discard(self) -> None:
        """Remove the partial file (the complete result has been written)."""
        self.path.unlink(missing_ok=True)
