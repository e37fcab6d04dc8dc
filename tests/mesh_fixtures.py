"""Shared helpers for the mesh tests (not a conftest: plain functions, cached)."""

from __future__ import annotations

import functools
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

import mesh

MESH_DIR = Path(__file__).resolve().parents[2] / "shared" / "meshes"
SMALL = ["hand_868.obj", "decimated-knight.off", "bumpy.off", "hand_868_holes2.obj"]
LARGE = ["bunny.off", "fandisk.off", "camelhead.off", "armadillo_25479.obj"]
CLOSED_SMALL = ["hand_868.obj", "decimated-knight.off", "bumpy.off"]


def shared_path(name: str) -> Path:
    """Path of a shared mesh; skips the test when the shared folder (or file) is missing."""
    p = MESH_DIR / name
    if not p.is_file():
        pytest.skip(f"shared mesh {name} not found under {MESH_DIR}")
    return p


@functools.lru_cache(maxsize=None)
def _load_cached(name: str) -> mesh.Mesh:
    return mesh.load(MESH_DIR / name)


def shared_mesh(name: str) -> mesh.Mesh:
    shared_path(name)
    return _load_cached(name)


@functools.lru_cache(maxsize=None)
def sphere(subdivisions: int = 2, radius: float = 1.0) -> mesh.Mesh:
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return mesh.load((np.asarray(s.vertices), np.asarray(s.faces)))


def two_spheres(subdivisions: int = 2) -> tuple[np.ndarray, np.ndarray]:
    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    V = np.vstack([s.vertices, s.vertices * 0.5 + [3.0, 0.0, 0.0]])
    F = np.vstack([s.faces, s.faces + len(s.vertices)])
    return V, F


def grid(nx: int = 5, ny: int = 5, jitter: float = 0.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Flat (nx × ny)-vertex grid on [0, 1]², split into triangles; optional in-plane jitter."""
    x, y = np.meshgrid(np.linspace(0, 1, nx), np.linspace(0, 1, ny), indexing="ij")
    V = np.stack([x.ravel(), y.ravel(), np.zeros(nx * ny)], axis=1)
    if jitter:
        rng = np.random.default_rng(seed)
        V[:, :2] += jitter * rng.uniform(-1, 1, (nx * ny, 2)) / max(nx, ny)
    idx = np.arange(nx * ny).reshape(nx, ny)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return V, F


def quiet_load(source, **kw) -> mesh.Mesh:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mesh.MultipleComponentsWarning)
        return mesh.load(source, **kw)
