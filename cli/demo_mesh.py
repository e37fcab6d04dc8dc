"""The built-in demo mesh: a deterministic bumpy, elongated icosphere.

Provenance: our own — generated on the fly with ``trimesh.creation.icosphere``
and the closed-form deformation below; no file, no randomness.
"""

from __future__ import annotations

import numpy as np
import trimesh

__all__ = ["demo_mesh", "DEMO_NAME"]

DEMO_NAME = "demo:bumpy-icosphere"


def demo_mesh(subdivisions: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Vertices ``(n, 3)`` float64 and faces ``(m, 3)`` int64 of the demo surface.

    An icosphere (``subdivisions=4``: n = 2562, m = 5120) stretched to an
    ellipsoid with semi-axes (1.6, 1.0, 0.8), with radial bumps
    ``r = 1 + 0.12 sin(3x) cos(2y) + 0.08 sin(5z)`` evaluated on the unit sphere
    — smooth, closed, genus 0, and asymmetric enough that the modes are not
    degenerate.
    """
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
    p = np.asarray(sphere.vertices, dtype=np.float64)
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    r = 1.0 + 0.12 * np.sin(3.0 * x) * np.cos(2.0 * y) + 0.08 * np.sin(5.0 * z)
    v = p * r[:, None] * np.array([1.6, 1.0, 0.8])
    return v, np.asarray(sphere.faces, dtype=np.int64)
