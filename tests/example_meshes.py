"""Generated meshes for the tests that used the real scans of ``../shared/meshes`` (not part of a clone).

Plain cached functions (not a conftest). Every mesh here is built on the fly by ``mesh.example`` or a
trimesh primitive: no file, no download, no randomness. Stand-ins (the scans' roles, not their shapes):

* ``HAND`` — ``starfish`` at size 0: 642 vertices, closed, genus 0, five arms of different lengths
  (the compressed modes localise on the arms' tips, as the hand's did on its fingers); it stands in
  for ``hand_868.obj`` (868 vertices) in the CMM solver tests.
* ``KNIGHT`` — the same mesh; it stands in for ``decimated-knight.off`` (502 vertices, closed, genus 0)
  in the tests of bases, functional maps and CMMs (the ``bumpy`` example at size 0, a smooth ellipsoid,
  failed two checks of tests/test_bases.py: the strong LMHs held only 70 % of their mass on the badly
  reconstructed region (> 80 % asked), and least squares' mean per-vertex error of the vertex positions was
  above matrix manipulation's for the full 20-function eigenbasis).
* ``torus_arrays`` — a bumpy torus (genus 1) with a chosen number of vertices, e.g. 864 = 4 · 216 for a
  row split over 4 devices (642 does not split evenly); ``write_obj`` writes a mesh file for the CLI tests.

The CMM solvers compile one program per mesh (its matrices' values) and solver options: a block solve costs
6–12 s of compilation on 2 cores the first time, then a fraction of a second for the same mesh and options
(in any module of the process). Tests therefore use these few meshes rather than one of their own each.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

import mesh

HAND = ("starfish", 0)
KNIGHT = HAND


@functools.lru_cache(maxsize=None)
def example_mesh(name: str, size: int = 0) -> mesh.Mesh:
    """``mesh.example(name, size)``, built once per process."""
    return mesh.example(name, size=size)


@functools.lru_cache(maxsize=None)
def example_laplacian(name: str, size: int = 0, weights: str = "cotangent", area: str = "lumped") -> mesh.Laplacian:
    """``mesh.laplacian(example_mesh(name, size), weights=…, area=…)``, built once per process (treat as read-only)."""
    return mesh.laplacian(example_mesh(name, size), weights=weights, area=area)


def hand_mesh() -> mesh.Mesh:
    return example_mesh(*HAND)


def hand_laplacian() -> mesh.Laplacian:
    return example_laplacian(*HAND)


def knight_mesh() -> mesh.Mesh:
    return example_mesh(*KNIGHT)


def knight_laplacian() -> mesh.Laplacian:
    return example_laplacian(*KNIGHT)


@functools.lru_cache(maxsize=None)
def torus_arrays(major_sections: int = 36, minor_sections: int = 24) -> tuple[np.ndarray, np.ndarray]:
    """A torus (radii 1 and 0.35, ``major_sections · minor_sections`` vertices) with the tube radius of
    ``mesh.examples``' ``torus`` (``1 + 0.15 sin(3θ) cos(φ)``), at any resolution (the example's
    smallest, size 1, has 1728 vertices)."""
    import trimesh

    t = trimesh.creation.torus(1.0, 0.35, major_sections=major_sections, minor_sections=minor_sections)
    v = np.asarray(t.vertices, dtype=np.float64)
    theta = np.arctan2(v[:, 1], v[:, 0])
    centre = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], axis=1)
    phi = np.arctan2(v[:, 2], np.linalg.norm(v[:, :2], axis=1) - 1.0)
    v = centre + (v - centre) * (1.0 + 0.15 * np.sin(3.0 * theta) * np.cos(phi))[:, None]
    return v, np.asarray(t.faces, dtype=np.int64)


def write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    """A Wavefront OBJ of ``(vertices, faces)``; coordinates written with ``repr`` (read back exactly)."""
    path = Path(path)
    path.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in np.asarray(vertices, dtype=float).tolist())
                    + "".join(f"f {i} {j} {k}\n" for i, j, k in (np.asarray(faces) + 1).tolist()))
    return path
