"""The generated example meshes (``mesh.examples``): sizes, topology and orientation as documented,
deterministic, clean (nothing for ``mesh.load`` to change), and named errors for bad requests."""

from __future__ import annotations

import numpy as np
import pytest

import mesh
from mesh.examples import EXAMPLES, ExampleError, example_arrays

#: name → (vertices, faces, Euler characteristic, boundary loops, the axis of smallest extent or None)
TABLE = {"bumpy": (2562, 5120, 2, 0, None), "starfish": (2562, 5120, 2, 0, None),
         "torus": (1728, 3456, 0, 0, 1), "patch": (1681, 3200, 1, 1, 1)}


@pytest.mark.parametrize("name", list(EXAMPLES))
def test_example_is_as_documented(name: str) -> None:
    n, f, chi, loops, thin_axis = TABLE[name]
    m = mesh.example(name)
    assert (m.n_vertices, m.n_faces) == (n, f)
    assert m.euler_characteristic == chi and m.n_boundary_loops == loops and m.n_components == 1
    assert m.report.lines() == []                      # nothing to clean
    V, F = example_arrays(name)
    V2, F2 = example_arrays(name)
    np.testing.assert_array_equal(V, V2)               # deterministic
    np.testing.assert_array_equal(F, F2)
    assert V.dtype == np.float64 and F.dtype == np.int64
    if thin_axis is not None:                          # y-up examples: y is the thinnest extent
        ext = V.max(0) - V.min(0)
        assert np.argmin(ext) == thin_axis
    lap = mesh.laplacian(m)
    assert lap.A.diagonal().min() > 0                  # no degenerate corner areas


def test_sizes_and_errors() -> None:
    assert mesh.example("bumpy", size=-1).n_vertices == 162
    assert mesh.example("patch", size=2).n_vertices == 81 ** 2
    with pytest.raises(ExampleError, match="unknown example mesh 'cube'; choose from bumpy, starfish"):
        mesh.example("cube")
    with pytest.raises(ExampleError, match="must be an integer in −1 … 2"):
        example_arrays("starfish", 3)
    with pytest.raises(ExampleError, match="must be an integer in 1, 2"):
        example_arrays("torus", 0)
    with pytest.raises(ExampleError):
        example_arrays("torus", 1.5)
