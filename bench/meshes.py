"""The meshes a benchmark is given: ``example:NAME`` (generated, ``mesh.examples``), ``demo``, a path,
or a bare file name looked up in ``../shared/meshes`` when that directory exists beside the
repository. Defaults use the generated examples, so every benchmark runs from a fresh clone; the
shared meshes are an opt-in input.

A benchmark checks its mesh inputs with :func:`require` before it measures anything: a missing one
raises :class:`MeshNotFound`, which ``python -m bench`` reports in one line, exiting non-zero with
nothing written."""

from __future__ import annotations

from pathlib import Path
from typing import Iterable

import mesh

__all__ = ["SHARED", "MeshNotFound", "load_mesh", "mesh_path", "require"]

#: the test meshes beside the repository (present on the developers' machines, not in a clone)
SHARED = Path(__file__).resolve().parents[2] / "shared" / "meshes"


class MeshNotFound(FileNotFoundError):
    """A mesh input that is neither generated, nor a file, nor in ``../shared/meshes``."""


def mesh_path(spec: str) -> Path:
    """The file a bare name or a path stands for (``MeshNotFound`` naming where it looked)."""
    path = Path(spec)
    if path.is_file():
        return path
    if (SHARED / spec).is_file():
        return SHARED / spec
    raise MeshNotFound(f"mesh {spec!r} not found (neither a file nor in {SHARED}); "
                       "example:bumpy, example:starfish, example:torus, example:patch need no file")


def _generated(spec: str) -> bool:
    return spec == "demo" or spec.startswith("example:")


def require(specs: Iterable[str]) -> None:
    """Every mesh input exists (generated meshes always do); else ``MeshNotFound`` for the first missing one."""
    for spec in specs:
        if not _generated(spec):
            mesh_path(spec)


def load_mesh(spec: str, **load_options) -> tuple[mesh.Mesh, str]:
    """``(mesh, label)`` for ``example:NAME``, ``demo`` (= ``example:bumpy``), a path or a shared mesh name."""
    load_options.setdefault("warn", False)
    if spec == "demo":
        spec = "example:bumpy"
    if spec.startswith("example:"):
        return mesh.example(spec.split(":", 1)[1], **load_options), spec
    path = mesh_path(spec)
    return mesh.load(path, **load_options), path.name
