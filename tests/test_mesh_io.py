"""Loading, cleaning and validation (mesh.load, mesh/io.py)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

import mesh
from mesh_fixtures import (DATA, LARGE_SURFACES, SURFACES, TOPOLOGY, grid, quiet_load, sphere, surface,
                           surface_arrays, two_spheres, write_mesh)

# every cleaning step warns once (MeshCleaningWarning); tests/test_mesh_loading_faults.py checks that
pytestmark = pytest.mark.filterwarnings("ignore::mesh.MeshCleaningWarning")


@pytest.mark.parametrize("suffix", [".obj", ".off", ".ply"])
@pytest.mark.parametrize("name", SURFACES)
def test_small_surfaces_load_from_files_with_their_topology(tmp_path, name, suffix):
    """The generated surfaces written to files and read back: exact coordinates, nothing to clean, and the
    topology they stand in for (a closed torus, a torus with four holes, closed genus-0 surfaces)."""
    V, F = surface_arrays(name)
    m = mesh.load(write_mesh(tmp_path / f"{name}{suffix}", V, F))
    assert m.vertices.dtype == np.float64 and m.vertices.shape[1] == 3
    assert m.faces.shape[1] == 3 and m.faces.min() == 0 and m.faces.max() == m.n_vertices - 1
    np.testing.assert_array_equal(m.vertices, V)
    np.testing.assert_array_equal(m.faces, F)
    chi, loops = TOPOLOGY[name]
    assert m.n_components == 1
    assert m.euler_characteristic == chi
    assert m.n_boundary_loops == loops
    assert m.is_closed == (loops == 0)
    assert not m.report.changed


@pytest.mark.parametrize("name", ["torus", "torus_holes", "hand", "quadruped"])
def test_generated_surfaces_are_irregular_like_scans(name):
    """The stand-ins for scanned meshes are irregular as scans are: many obtuse triangles and negative
    cotangent weights; their faces are oriented consistently, outwards where the surface is closed."""
    m = surface(name)
    V, F = m.vertices, m.faces
    e = [V[F[:, (i + 1) % 3]] - V[F[:, i]] for i in range(3)]
    obtuse = sum(int(np.sum(np.einsum("ij,ij->i", e[i], -e[i - 1]) < 0)) for i in range(3))
    assert obtuse > 0.3 * m.n_faces
    assert mesh.laplacian(m).n_negative_weights > 0.1 * m.n_vertices
    t = trimesh.Trimesh(V, F, process=False)
    assert t.is_winding_consistent and (not m.is_closed or t.volume > 0)


def test_normals_do_not_split_vertices():
    # 6 positions, 24 normals (one per face corner), faces "f v//vn" (as horse_976.obj): the strict OBJ
    # reader indexes positions, so nothing needs cleaning (trimesh split every position per normal)
    path = DATA / "octahedron_normals.obj"
    assert path.read_text().count("\nvn ") == 24
    m = mesh.load(path)
    r = m.report
    assert r.input_vertices == 6 and r.input_faces == 8
    assert m.n_vertices == 6 and m.n_faces == 8
    assert not r.changed and r.lines() == []
    assert m.n_components == 1 and m.is_closed and m.euler_characteristic == 2
    np.testing.assert_allclose(m.total_area, 8 * np.sqrt(3) / 2, rtol=1e-14)  # eight faces of edge √2


def _fan_triangles(path):
    """The triangles the fan ``(a, b, c, d) → (a, b, c), (a, c, d)`` makes of the file's quads (0-based)."""
    quads = np.array([line.split()[1:] for line in path.read_text().splitlines() if line.startswith("f ")], int) - 1
    return np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]), len(quads)


def test_volume_faces_raise_non_manifold():
    # a 2 × 2 × 2 grid of cubes, six tetrahedra per cube, each written as a 4-corner "face" (as cube_40k.obj)
    path = DATA / "volume_grid.obj"
    with pytest.raises(mesh.NonManifoldError) as info:
        mesh.load(path)
    msg = str(info.value)
    assert "non-manifold edge" in msg and "e.g. edge (" in msg and "repair" in msg
    assert isinstance(info.value, ValueError) and isinstance(info.value, mesh.MeshError)
    assert "allow_nonmanifold=True" in msg
    # its 4-corner "faces" are tetrahedra: on request it loads, every count reported. The fan of the path
    # 000 → e_a → e_a + e_b → 111 gives (000, e_a, e_a + e_b), six different ones per cube, and
    # (000, e_a + e_b, 111), three different ones twice: 8 × 3 repeated faces, 8 × 9 kept
    m = mesh.load(path, allow_nonmanifold=True)
    r = m.report
    assert (r.triangulated_quads, r.nonplanar_polygons, r.dropped_duplicate_faces) == (48, 48, 24)
    fans, n_quads = _fan_triangles(path)
    assert n_quads == 48 and m.n_vertices == 27
    kept = np.unique(np.sort(fans, axis=1), axis=0)
    assert len(kept) == m.n_faces == 72
    np.testing.assert_array_equal(np.unique(np.sort(m.faces, axis=1), axis=0), kept)
    _, count = np.unique(np.sort(np.concatenate([kept[:, [0, 1]], kept[:, [1, 2]], kept[:, [0, 2]]]), axis=1),
                             axis=0, return_counts=True)
    assert m.n_nonmanifold_edges == r.n_nonmanifold_edges == int(np.sum(count > 2)) == 50
    assert not m.is_edge_manifold


def test_nan_coordinate_of_a_used_vertex_raises():
    s = trimesh.creation.icosphere(1)
    V = np.array(s.vertices)
    V[3, 1] = np.nan
    with pytest.raises(mesh.NonFiniteVerticesError, match="vertex 3"):
        mesh.load((V, s.faces))


def test_nan_coordinate_of_an_unused_vertex_is_dropped():
    s = trimesh.creation.icosphere(1)
    V = np.vstack([s.vertices, [[np.inf, 0.0, 0.0]]])
    m = mesh.load((V, s.faces))
    assert m.n_vertices == len(s.vertices)
    assert m.report.dropped_unreferenced_vertices == 1
    assert np.all(np.isfinite(m.vertices))


def test_degenerate_faces_are_dropped_and_reported():
    V, F = grid(4, 4)
    extra = np.array([[0, 0, 5], [0, 1, 2], [5, 6, 7]])  # repeated index; collinear; collinear
    V2 = V.copy()
    m0 = mesh.load((V, F))
    m = mesh.load((V2, np.vstack([F, extra, F[:2]])))
    assert m.report.dropped_collapsed_faces == 1
    assert m.report.dropped_zero_area_faces == 2
    assert m.report.dropped_duplicate_faces == 2
    np.testing.assert_array_equal(m.faces, m0.faces)


def test_all_faces_degenerate_raises():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    with pytest.raises(mesh.DegenerateMeshError):
        mesh.load((V, [[0, 1, 2]]))


def test_two_disjoint_spheres_load_flagged():
    V, F = two_spheres(1)
    with pytest.warns(mesh.MultipleComponentsWarning, match="2 connected components"):
        m = mesh.load((V, F))
    assert m.n_components == 2 and m.has_multiple_components
    assert np.bincount(m.component).tolist() == [42, 42]
    assert m.euler_characteristic == 4


def test_empty_inputs(tmp_path):
    p = tmp_path / "empty.obj"
    p.write_text("")
    with pytest.raises(mesh.EmptyMeshError, match="empty file"):
        mesh.load(p)
    q = tmp_path / "points.obj"
    q.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(mesh.EmptyMeshError):
        mesh.load(q)
    with pytest.raises(mesh.EmptyMeshError, match="no vertices"):
        mesh.load((np.zeros((0, 3)), np.zeros((0, 3), int)))
    with pytest.raises(mesh.EmptyMeshError, match="no faces"):
        mesh.load((np.eye(3), np.zeros((0, 3), int)))
    with pytest.raises(FileNotFoundError):
        mesh.load(tmp_path / "missing.off")


def test_index_out_of_range():
    with pytest.raises(mesh.IndexOutOfRangeError, match="1-based"):
        mesh.load((np.eye(3), [[1, 2, 3]]))


def test_polygons_are_fan_triangulated():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 1.5, 0], [2, 0, 0]])
    m = mesh.load((V, [[0, 1, 2, 4, 3], [1, 5, 2]]))
    assert m.n_faces == 4 and m.report.triangulated_polygons == 1
    np.testing.assert_array_equal(m.faces[:3], [[0, 1, 2], [0, 2, 4], [0, 4, 3]])
    np.testing.assert_allclose(m.total_area, 1.25 + 0.5)
    quads = np.array([[0, 1, 2, 3]])
    mq = mesh.load((V[:4], quads))
    np.testing.assert_array_equal(mq.faces, [[0, 1, 2], [0, 2, 3]])
    with pytest.raises(mesh.NonTriangleFacesError, match="fewer than 3"):
        mesh.load((V, [[0, 1, 2], [3, 4]]))
    with pytest.raises(mesh.NonTriangleFacesError):
        mesh.load((V, np.array([[0, 1], [1, 2]])))


def test_non_manifold_fin_raises():
    V = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]])
    F = [[0, 1, 2], [1, 0, 3], [0, 1, 4]]
    with pytest.raises(mesh.NonManifoldError, match=r"1 non-manifold edge\(s\).*\(0, 1\) with 3 faces \(input vertex"):
        mesh.load((V, F))


@pytest.mark.parametrize("ext", ["obj", "off", "ply", "stl"])
def test_file_formats_round_trip(tmp_path, ext):
    s = trimesh.creation.icosphere(2)
    path = tmp_path / f"sphere.{ext}"
    s.export(path)
    m = mesh.load(path)
    ref = sphere(2)
    # STL stores unshared corners: merging duplicates restores the connectivity
    assert m.n_vertices == ref.n_vertices and m.n_faces == ref.n_faces
    assert m.n_components == 1 and m.euler_characteristic == 2
    np.testing.assert_allclose(m.total_area, ref.total_area, rtol=1e-6)
    if ext == "stl":
        assert m.report.merged_duplicate_vertices == 3 * ref.n_faces - ref.n_vertices


def test_trimesh_source_and_merge_switch():
    s = trimesh.creation.icosphere(1)
    m = mesh.load(s)
    assert m.n_vertices == 42
    soup = (s.vertices[s.faces].reshape(-1, 3), np.arange(3 * len(s.faces)).reshape(-1, 3))
    with warnings.catch_warnings():
        warnings.simplefilter("error", mesh.MultipleComponentsWarning)
        assert mesh.load(soup).n_vertices == 42
    unmerged = quiet_load(soup, merge_duplicates=False)
    assert unmerged.n_components == len(s.faces)
    with pytest.raises(TypeError):
        mesh.load(3.0)


@pytest.mark.slow
@pytest.mark.parametrize("name", LARGE_SURFACES)
def test_large_surfaces_topology(tmp_path, name):
    m = mesh.load(write_mesh(tmp_path / f"{name}.off", *surface_arrays(name)))
    assert (m.euler_characteristic, m.n_boundary_loops, m.n_components) == (*TOPOLOGY[name], 1)
    assert not m.report.changed


def test_non_manifold_message_uses_input_indices():
    # an unused vertex 0 shifts the cleaned indices by one; the message names input indices
    V = np.array([[9.0, 9, 9], [0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1]])
    F = [[1, 2, 3], [2, 1, 4], [1, 2, 5]]
    with pytest.raises(mesh.NonManifoldError, match=r"\(1, 2\) with 3 faces"):
        mesh.load((V, F))


def test_polygons_in_files_are_reported(tmp_path):
    obj = tmp_path / "quads.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\nf 1 2 3 4\nf 2 5 6 3\n")
    m = mesh.load(obj)
    assert m.n_faces == 4 and m.report.triangulated_polygons == 2
    off = tmp_path / "pent.off"
    off.write_text("OFF\n5 1 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0.5 1.5 0\n5 0 1 2 4 3\n")
    m = mesh.load(off)
    assert m.n_faces == 3 and m.report.triangulated_polygons == 1
    np.testing.assert_allclose(m.total_area, 1.25)


@pytest.mark.parametrize("ci", ["", "1"])
def test_ci_fails_a_test_that_skips_for_a_missing_mesh(monkeypatch, ci):
    """tests/conftest.py: with CI set, a skip whose reason names a missing mesh or file is a failure."""
    import conftest
    from _pytest.reports import TestReport

    monkeypatch.setenv("CI", ci)

    def outcome(reason: str) -> str:
        report = TestReport("t.py::t", ("t.py", 0, "t"), {}, "skipped", ("t.py", 1, f"Skipped: {reason}"), "call")
        hook = conftest.pytest_runtest_makereport(None, None)
        next(hook)
        with pytest.raises(StopIteration) as done:
            hook.send(report)
        return done.value.value.outcome

    for reason in ("shared mesh hand_868.obj not found under /x", "/x/hand_868.obj not present"):
        assert outcome(reason) == ("failed" if ci else "skipped")
    assert outcome("no chromium binary (apt-get install chromium)") == "skipped"
