"""The benchmarks' midpoint-subdivided meshes: ``base`` subdivided ``level`` times with
``trimesh.Trimesh.subdivide`` (each level ×4 faces, ≈ ×4 vertices), cached as ``.npz`` outside the
repository (``$XDG_CACHE_HOME/stiefel-cmm/bench`` by default). Used by ``python -m bench scaling`` and
``python -m bench scaling-modes``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np


def default_cache() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "stiefel-cmm" / "bench"


def subdivided(base: str, level: int, cache: Path) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(V, F, from_cache)`` of ``base`` midpoint-subdivided ``level`` times (cached as .npz)."""
    import trimesh

    cache.mkdir(parents=True, exist_ok=True)
    path = cache / f"{Path(base).stem}_sub{level}.npz"
    if path.exists():
        z = np.load(path)
        return z["V"], z["F"], True
    from bench.meshes import load_mesh

    m, _ = load_mesh(base)
    tm = trimesh.Trimesh(m.vertices, m.faces, process=False)
    for _ in range(level):
        tm = tm.subdivide()
    V, F = np.asarray(tm.vertices, dtype=np.float64), np.asarray(tm.faces, dtype=np.int64)
    np.savez(path, V=V, F=F)
    return V, F, False
