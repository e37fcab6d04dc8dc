"""Shared helpers for the mesh tests (not a conftest: plain functions, cached).

Every mesh a mesh test uses is generated here or read from a small file under ``tests/data/`` (see the
README there): the tests run from a fresh clone. ``surface(name)`` gives generated stand-ins for the real
scans the tests once read, each with the character that mattered (topology, boundary, thin parts, size)
and, where it says *irregular*, jittered vertices so that, as on a scan, many triangles are obtuse and
many cotangent weights negative:

================== ======= ================================================ ==========================
name                n       what it is                                       in the place of
================== ======= ================================================ ==========================
``torus``           864     closed, genus 1, irregular                       hand_868.obj
``torus_holes``     800     the torus with four holes: genus 1, four         hand_868_holes2.obj
                            boundary loops, χ = −4
``hand``            642     closed, genus 0, irregular: a flat palm with     decimated-knight.off,
                            four fingers and a thumb (thin parts)            hand_868's fingers
``quadruped``       642     closed, genus 0, irregular: a body with four     horse_976.obj
                            legs, a head and a tail
``bumpy``           642     ``mesh.example("bumpy", size=0)``: sphere-like   bumpy.off
``bumpy_large``     10242   ``mesh.example("bumpy", size=2)``                bunny.off
``patch_large``     14641   ``mesh.example("patch", size=3)``: one boundary  camelhead.off
``torus_large``     15552   ``mesh.example("torus", size=3)``: genus 1       fandisk.off (closed)
``quadruped_large`` 40962   the quadruped, finer                              armadillo_25479.obj
================== ======= ================================================ ==========================

``SURFACES`` lists the four small ones most tests run on; ``LARGE_SURFACES`` the large ones (tests marked
``slow``).
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
import trimesh

import mesh

DATA = Path(__file__).resolve().parent / "data"

SURFACES = ["torus", "hand", "bumpy", "torus_holes"]
CLOSED_SURFACES = ["torus", "hand", "bumpy"]
LARGE_SURFACES = ["bumpy_large", "patch_large", "torus_large", "quadruped_large"]

#: (Euler characteristic, boundary loops) of every generated surface
TOPOLOGY = {"torus": (0, 0), "torus_holes": (-4, 4), "hand": (2, 0), "quadruped": (2, 0), "bumpy": (2, 0),
            "bumpy_large": (2, 0), "patch_large": (1, 1), "torus_large": (0, 0), "quadruped_large": (2, 0)}


def _jittered_sphere(subdivisions: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """An icosphere whose vertices moved along the unit sphere by up to 0.3 × the mean edge (no face flips)."""
    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    u, F = np.asarray(s.vertices, dtype=np.float64), np.asarray(s.faces, dtype=np.int64)
    h = np.linalg.norm(u[F[:, 0]] - u[F[:, 1]], axis=1).mean()
    rng = np.random.default_rng(seed)
    t = rng.standard_normal(u.shape)
    t -= (t * u).sum(axis=1, keepdims=True) * u  # tangential
    t *= 0.3 * h * np.sqrt(rng.uniform(size=(len(u), 1))) / np.linalg.norm(t, axis=1, keepdims=True)
    u = u + t
    return u / np.linalg.norm(u, axis=1, keepdims=True), F


def _limbs(arms, scale, subdivisions: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A jittered sphere of radius 0.5 with smooth protrusions ``r(u) = 0.5 + Σ L exp(−(1 − u·d)/w)`` for
    ``arms = ((azimuth°, elevation°, L, w), …)``, then scaled along x, y, z by ``scale``."""
    u, F = _jittered_sphere(subdivisions, seed)
    r = np.full(len(u), 0.5)
    for az, el, length, width in arms:
        a, e = np.deg2rad(az), np.deg2rad(el)
        r += length * np.exp(-(1.0 - u @ [np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)]) / width)
    return u * r[:, None] * np.asarray(scale), F


#: four fingers of different lengths side by side and a thumb; the palm flattened along z
HAND = ((45, 0, 0.9, 0.01), (75, 0, 1.0, 0.01), (105, 0, 0.95, 0.01), (135, 0, 0.75, 0.01), (-10, -10, 0.65, 0.015))
#: head (+x), tail (−x), four legs pointing down; the body stretched along x
QUADRUPED = ((0, 10, 0.5, 0.02), (180, 0, 0.35, 0.01), (40, -60, 0.6, 0.01), (140, -60, 0.6, 0.01),
             (220, -60, 0.6, 0.01), (320, -60, 0.6, 0.01))


def _torus(holes=(), seed: int = 0, M: int = 48, N: int = 18) -> tuple[np.ndarray, np.ndarray]:
    """An elliptic torus (M × N vertices, parameters jittered by ±0.3 cell, each cell split along a random
    diagonal) with a bumpy tube; ``holes``: cell blocks ``(i0, j0, di, dj)`` removed (each a boundary loop)."""
    rng = np.random.default_rng(seed)
    i, j = np.meshgrid(np.arange(M), np.arange(N), indexing="ij")
    theta = 2 * np.pi * (i + 0.3 * rng.uniform(-1, 1, i.shape)) / M
    phi = 2 * np.pi * (j + 0.3 * rng.uniform(-1, 1, j.shape)) / N
    r = 0.35 * (1.0 + 0.15 * np.sin(3 * theta) * np.cos(phi) + 0.05 * np.sin(theta))
    ring = 1.0 + r * np.cos(phi)
    V = np.stack([1.3 * ring * np.cos(theta), ring * np.sin(theta), r * np.sin(phi)], axis=-1).reshape(-1, 3)
    a, b, c, d = ((i + di) % M * N + (j + dj) % N for di, dj in ((0, 0), (1, 0), (1, 1), (0, 1)))
    flip = (rng.random(i.shape) < 0.5)[..., None]
    t1 = np.where(flip, np.stack([a, b, d], -1), np.stack([a, b, c], -1))
    t2 = np.where(flip, np.stack([b, c, d], -1), np.stack([a, c, d], -1))
    keep = np.ones(i.shape, dtype=bool)
    for i0, j0, di, dj in holes:
        keep &= ~(((i - i0) % M < di) & ((j - j0) % N < dj))
    F = np.concatenate([t1[keep], t2[keep]])
    used = np.unique(F)  # drop the vertices inside the holes: the mesh loads unchanged
    index = np.full(M * N, -1)
    index[used] = np.arange(used.size)
    return V[used], index[F].astype(np.int64)


_GENERATORS: dict[str, Callable[[], tuple[np.ndarray, np.ndarray]]] = {
    "torus": _torus,
    "torus_holes": lambda: _torus(holes=((0, 0, 5, 4), (12, 9, 6, 3), (24, 2, 4, 7), (36, 11, 7, 5))),
    "hand": lambda: _limbs(HAND, (1.0, 1.0, 0.45), 3, seed=1),
    "quadruped": lambda: _limbs(QUADRUPED, (1.6, 0.6, 0.8), 3, seed=2),
    "bumpy": lambda: mesh.example_arrays("bumpy", 0),
    "bumpy_large": lambda: mesh.example_arrays("bumpy", 2),
    "patch_large": lambda: mesh.example_arrays("patch", 3),
    "torus_large": lambda: mesh.example_arrays("torus", 3),
    "quadruped_large": lambda: _limbs(QUADRUPED, (1.6, 0.6, 0.8), 6, seed=2),
}


@functools.lru_cache(maxsize=None)
def surface_arrays(name: str) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (n, 3) float64, faces (m, 3) int64)`` of the generated surface ``name`` (module table)."""
    V, F = _GENERATORS[name]()
    V.flags.writeable = F.flags.writeable = False  # shared by the tests through the cache
    return V, F


@functools.lru_cache(maxsize=None)
def surface(name: str) -> mesh.Mesh:
    """The generated surface ``name`` loaded (nothing to clean: ``report.changed`` is false)."""
    return mesh.load(surface_arrays(name))


def write_mesh(path: Path, V, F) -> Path:
    """``V``, ``F`` as an ASCII OBJ, OFF or PLY file (by ``path``'s suffix), coordinates written exactly."""
    V, F = np.asarray(V, dtype=np.float64), np.asarray(F, dtype=np.int64)
    v = "\n".join(" ".join(repr(float(x)) for x in row) for row in V)
    kind = path.suffix.lower()
    if kind == ".obj":
        text = "\n".join("v " + line for line in v.split("\n")) + "\n" + "".join(f"f {a} {b} {c}\n" for a, b, c in F + 1)
    elif kind == ".off":
        text = f"OFF\n{len(V)} {len(F)} 0\n{v}\n" + "".join(f"3 {a} {b} {c}\n" for a, b, c in F)
    elif kind == ".ply":
        text = (f"ply\nformat ascii 1.0\nelement vertex {len(V)}\nproperty double x\nproperty double y\n"
                f"property double z\nelement face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n"
                f"{v}\n" + "".join(f"3 {a} {b} {c}\n" for a, b, c in F))
    else:
        raise ValueError(f"write_mesh writes .obj, .off or .ply, not {path.name}")
    path.write_text(text)
    return path


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


# ---- stand-ins for the solver tests (CMMs, bases, functional maps, batches, the CLI): one mesh shared by all of
# them, so that a solver compiled for it in one module is reused by the others in the same process (a block solve
# compiles for 6–12 s on 2 cores the first time, then runs in a fraction of a second).
# The starfish example at size 0 (642 vertices, closed, genus 0, five arms of different lengths: the modes localise
# on the arms' tips, as they did on hand_868's fingers) plays the hand and the knight. The ``bumpy`` example failed
# two checks of tests/test_bases.py in the knight's place (the strong LMHs held 70 % of their mass on the badly
# reconstructed region, > 80 % asked; least squares' mean error above matrix manipulation's for 20 functions).

HAND_EXAMPLE = ("starfish", 0)


@functools.lru_cache(maxsize=None)
def example_mesh(name: str, size: int = 0) -> mesh.Mesh:
    """``mesh.example(name, size)``, built once per process."""
    return mesh.example(name, size=size)


@functools.lru_cache(maxsize=None)
def example_laplacian(name: str, size: int = 0, weights: str = "cotangent", area: str = "lumped") -> mesh.Laplacian:
    """``mesh.laplacian(example_mesh(name, size), weights=…, area=…)``, built once per process (treat as read-only)."""
    return mesh.laplacian(example_mesh(name, size), weights=weights, area=area)


def hand_mesh() -> mesh.Mesh:
    return example_mesh(*HAND_EXAMPLE)


def hand_laplacian() -> mesh.Laplacian:
    return example_laplacian(*HAND_EXAMPLE)


knight_mesh, knight_laplacian = hand_mesh, hand_laplacian
