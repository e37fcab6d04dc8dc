"""The meshes a benchmark is given: ``example:NAME`` (generated, ``mesh.examples``), ``demo``, a path,
or a bare file name looked up in ``../shared/meshes`` when that directory exists beside the
repository. Defaults use the generated examples, so every bench runs from a fresh clone."""

from __future__ import annotations

from pathlib import Path

import mesh

__all__ = ["SHARED", "load_mesh", "mesh_path"]

#: the test meshes beside the repository (present on the developers' machines, not in a clone)
SHARED = Path(__file__).resolve().parents[2] / "shared" / "meshes"


def mesh_path(spec: str) -> Path:
    """The file a bare name or a path stands for (``FileNotFoundError`` naming where it looked)."""
    path = Path(spec)
    if path.is_file():
        return path
    if (SHARED / spec).is_file():
        return SHARED / spec
    raise FileNotFoundError(f"mesh {spec!r} not found (neither a file nor in {SHARED}); "
                            "example:bumpy, example:starfish, example:torus, example:patch need no file")


def load_mesh(spec: str, **load_options) -> tuple[mesh.Mesh, str]:
    """``(mesh, label)`` for ``example:NAME``, ``demo`` (= ``example:bumpy``), a path or a shared mesh name."""
    load_options.setdefault("warn", False)
    if spec == "demo":
        spec = "example:bumpy"
    if spec.startswith("example:"):
        return mesh.example(spec.split(":", 1)[1], **load_options), spec
    path = mesh_path(spec)
    return mesh.load(path, **load_options), path.name
