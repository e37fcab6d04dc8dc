"""Writers and small parsers for the CLI: μ strings, provenance, npz / PLY / JSON.

Nothing here imports JAX at module level; ``versions()`` imports it lazily.
"""

from __future__ import annotations

import json
import platform
import re
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["MuSpec", "PartialColumns", "parse_mu", "versions", "to_jsonable", "write_json", "write_ply"]

_MU_RE = re.compile(r"^\s*([0-9]*\.?[0-9]+(?:[eE][+-]?[0-9]+)?)\s*(n?)\s*$")


class MuSpec:
    """A sparsity weight as given on the command line: absolute (``"5.2"``) or relative (``"0.01n"``).

    ``resolve(n)`` gives the absolute μ: ``value`` or ``value · n`` (n = number of vertices).
    """

    def __init__(self, text: str, value: float, relative: bool) -> None:
        self.text, self.value, self.relative = text, value, relative

    def resolve(self, n: int) -> float:
        """Absolute μ for a mesh with ``n`` vertices."""
        return self.value * n if self.relative else self.value

    def __repr__(self) -> str:
        return f"MuSpec({self.text!r})"


def parse_mu(text: str) -> MuSpec:
    """Parse ``"5.2"``, ``"1e-3"`` or ``"0.01n"``; raise ``ValueError`` naming the fix otherwise.

    Used as an argparse ``type=``: argparse turns the error into a usage error (exit 2).
    """
    m = _MU_RE.match(text)
    if m is None:
        raise ValueError(f"invalid mu {text!r}: give a non-negative number (e.g. 5.2) "
                         "or a multiple of the vertex count (e.g. 0.01n)")
    value = float(m.group(1))
    if not np.isfinite(value):
        raise ValueError(f"invalid mu {text!r}: must be finite")
    return MuSpec(text, value, bool(m.group(2)))


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def versions() -> dict[str, str | None]:
    """Versions of python, jax, jaxlib, numpy, scipy, trimesh and this package (``stiefel-cmm``)."""
    import jax
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
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def write_json(path: Path, obj: dict) -> None:
    """Write ``obj`` as indented UTF-8 JSON."""
    path.write_text(json.dumps(to_jsonable(obj), indent=2, ensure_ascii=False) + "\n", encoding="utf-8")


def write_ply(path: Path, vertices: np.ndarray, faces: np.ndarray, fields: np.ndarray,
              names: list[str] | None = None) -> None:
    """ASCII PLY with one float64 vertex property per column of ``fields``.

    vertices: ``(n, 3)``; faces: ``(m, 3)``; fields: ``(n, k)``, written as
    properties ``mode_0 … mode_{k-1}`` (or ``names``) after x, y, z.
    """
    fields = np.asarray(fields, dtype=np.float64).reshape(vertices.shape[0], -1)
    names = names or [f"mode_{j}" for j in range(fields.shape[1])]
    header = ["ply", "format ascii 1.0", "comment stiefel-cmm compressed manifold modes",
              f"element vertex {vertices.shape[0]}", "property double x", "property double y", "property double z"]
    header += [f"property double {name}" for name in names]
    header += [f"element face {faces.shape[0]}", "property list uchar int vertex_indices", "end_header"]
    vdata = np.hstack([np.asarray(vertices, dtype=np.float64), fields])
    with open(path, "w", encoding="ascii") as fh:
        fh.write("\n".join(header) + "\n")
        np.savetxt(fh, vdata, fmt="%.17g")
        np.savetxt(fh, np.hstack([np.full((faces.shape[0], 1), 3), faces]), fmt="%d")


def stderr_line(msg: str) -> None:
    """Print one line to stderr (newlines collapsed)."""
    print(" ".join(str(msg).split()), file=sys.stderr)


class PartialColumns:
    """Callback ``(j, info)`` that saves finished columns to ``path`` as they arrive.

    Made for ``stiefel.minimize_sequential``'s ``callback(j, {"x": (n,), "value", "status", …})``:
    after column ``j`` the file holds ``modes (n, j+1)`` (solve order, not yet
    sorted by compressed eigenvalue), ``values`` and ``status``. Written to a
    temporary name and renamed, so a reader never sees half a file. ``say``, if
    given, gets one progress line per column.
    """

    def __init__(self, path: Path, say=None) -> None:
        self.path, self.say = Path(path), say
        self.columns: list[np.ndarray] = []
        self.values: list[float] = []
        self.status: list[str] = []

    def __call__(self, j: int, info: dict) -> None:
        import os

        if j < len(self.columns):  # a new continuation stage restarts the columns
            del self.columns[j:], self.values[j:], self.status[j:]
        self.columns.append(np.asarray(info["x"], dtype=np.float64))
        self.values.append(float(info.get("value", np.nan)))
        self.status.append(str(info.get("status", "")))
        tmp = self.path.with_name(self.path.name + ".tmp.npz")
        np.savez(tmp, modes=np.stack(self.columns, axis=1), values=np.array(self.values),
                 status=np.array(self.status))
        os.replace(tmp, self.path)
        if self.say is not None:
            self.say(f"column {j} done ({self.status[-1]}), saved {self.path}")

    def discard(self) -> None:
        """Remove the partial file (the complete result has been written)."""
        self.path.unlink(missing_ok=True)
