"""Loading, cleaning and validation (mesh.load, mesh/io.py)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import trimesh

import mesh
from mesh_fixtures import grid, quiet_load, shared_mesh, shared_path, sphere, two_spheres

# every cleaning step warns once (MeshCleaningWarning); tests/test_mesh_loading_faults.py checks that
pytestmark = pytest.mark.filterwarnings("ignore::mesh.MeshCleaningWarning")


@pytest.mark.parametrize(
    "name, chi, loops",
    [("hand_868.obj", 0, 0), ("decimated-knight.off", 2, 0), ("bumpy.off", 2, 0), ("hand_868_holes2.obj", -4, 4)],
)
def test_shared_small_meshes_topology(name, chi, loops):
    m = shared_mesh(name)
    assert m.vertices.dtype == np.float64 and m.vertices.shape[1] == 3
    assert m.faces.shape[1] == 3 and m.faces.min() == 0 and m.faces.max() == m.n_vertices - 1
    assert m.n_components == 1
    assert m.euler_characteristic == chi
    assert m.n_boundary_loops == loops
    assert m.is_closed == (loops == 0)
    assert not m.report.changed


def test_horse_normals_do_not_split_vertices():
    # 976 positions, 5844 normals, faces "f v//vn": the strict OBJ reader indexes positions, so
    # nothing needs cleaning (trimesh split every position per normal: 5844 vertices, merged back)
    m = mesh.load(shared_path("horse_976.obj"))
    r = m.report
    assert r.input_vertices == 976 and r.input_faces == 1948
    assert m.n_vertices == 976 and m.n_faces == 1948
    assert not r.changed and r.lines() == []
    assert m.n_components == 1 and m.is_closed and m.euler_characteristic == 2


def test_cube_40k_volume_faces_raise_non_manifold():
    with pytest.raises(mesh.NonManifoldError) as info:
        mesh.load(shared_path("cube_40k.obj"))
    msg = str(info.value)
    assert "non-manifold edge" in msg and "e.g. edge (" in msg and "repair" in msg
    assert isinstance(info.value, ValueError) and isinstance(info.value, mesh.MeshError)
    assert "allow_nonmanifold=True" in msg
    # its 4-corner "faces" are tetrahedra: on request it loads, every count reported
    m = mesh.load(shared_path("cube_40k.obj"), allow_nonmanifold=True)
    r = m.report
    assert (r.triangulated_quads, r.nonplanar_polygons, r.dropped_duplicate_faces) == (48000, 48000, 8000)
    assert m.n_nonmanifold_edges == r.n_nonmanifold_edges == 55580 and not m.is_edge_manifold


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
@pytest.mark.parametrize(
    "name, chi, loops",
    [("bunny.off", 2, 0), ("fandisk.off", 2, 0), ("camelhead.off", 1, 1), ("armadillo_25479.obj", 2, 0)],
)
def test_shared_large_meshes_topology(name, chi, loops):
    m = shared_mesh(name)
    assert (m.euler_characteristic, m.n_boundary_loops, m.n_components) == (chi, loops, 1)
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
