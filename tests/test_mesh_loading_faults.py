"""Faults users met when loading meshes: one test per class of fault.

Bad files are written into ``tmp_path``; every error must be a named ``MeshError``
whose message names the file and, for text formats, the line.
"""

from __future__ import annotations

import gzip
import importlib.metadata as md
import json
import re
import struct
import sys
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest
import trimesh

import mesh
from mesh_fixtures import sphere, surface

pytestmark = pytest.mark.filterwarnings("ignore::mesh.MeshCleaningWarning", "ignore::mesh.MultipleComponentsWarning")

TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n"


def _write(path: Path, text: str | bytes) -> Path:
    path.write_bytes(text.encode() if isinstance(text, str) else text)
    return path


def _icosphere(sub: int = 1) -> tuple[np.ndarray, np.ndarray]:
    s = trimesh.creation.icosphere(sub)
    return np.asarray(s.vertices), np.asarray(s.faces)


# ---------------------------------------------------------------- zero area is scale-free


def test_zero_area_is_judged_per_face_not_by_distant_parts():
    V, F = _icosphere(2)
    stray = np.array([[3e7, 0, 0], [3e7 + 1, 0, 0], [3e7, 1, 0]])  # far away; dropped 479 hand faces before
    m = mesh.load((np.vstack([V, stray]), np.vstack([F, [[len(V), len(V) + 1, len(V) + 2]]])))
    assert m.n_faces == len(F) + 1 and m.report.dropped_zero_area_faces == 0
    # a thin sliver (height 1e-6 × its edge) is a face; a collinear triple is not, near or far from the origin
    d = np.array([1.0, 0.7, 0.3])
    for offset in (0.0, 1e3):
        P = offset + 1e-3 * np.array([0 * d, d, 0.5 * d + [0, 0, 1e-6], 0.3 * d])
        r = mesh.load((P, [[0, 1, 2], [0, 3, 1]])).report  # (0, 3, 1) collinear (to round-off)
        assert (r.dropped_zero_area_faces, r.output_faces) == (1, 1)
        assert r.examples["dropped_zero_area_faces"] == "face 1"
    # an irregular scan-sized surface (170 units across, face areas from 1 to 60 units²; hand_868.obj: 200, 0.7
    # to 380) with the stray face far away keeps all its faces
    scan = surface("torus")
    Vs = 45.0 * scan.vertices
    n, m = scan.n_vertices, scan.n_faces
    assert np.ptp(Vs, axis=0).max() > 150 and mesh.load((Vs, scan.faces)).n_faces == m
    Fs = np.vstack([scan.faces, [[n, n + 1, n + 2]]])
    assert mesh.load((np.vstack([Vs, stray]), Fs)).n_faces == m + 1


# ---------------------------------------------------------------- report: counts, lines, dict, one warning


def test_every_change_is_counted_rendered_and_warned_once(tmp_path):
    obj = ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 2 0 0\nv 2 1 0\nv 9 9 9\nv 1 0 0\n"
           "v 5 0 0\nv 6 0 0\nv 5 1 0\n"
           "f 1 2 3 4\nf 8 5 6 3\nf 1 2 2\nf 1 2 5\nf 3 4 1\nf 9 10 11\n")
    path = _write(tmp_path / "messy.obj", obj)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        m = mesh.load(path)
    r = m.report
    assert (r.input_vertices, r.input_faces, r.output_vertices, r.output_faces) == (11, 6, 9, 5)
    assert (r.triangulated_polygons, r.triangulated_quads, r.triangles_from_polygons) == (2, 2, 4)
    assert r.merged_duplicate_vertices == 1
    assert r.examples["merged_duplicate_vertices"] == "vertex 7, a copy of vertex 1"
    assert r.dropped_unreferenced_vertices == 1 and r.examples["dropped_unreferenced_vertices"] == "vertex 6"
    assert r.dropped_collapsed_faces == 1 and r.examples["dropped_collapsed_faces"] == "face 2, line 14"
    assert r.dropped_zero_area_faces == 1 and r.examples["dropped_zero_area_faces"] == "face 3, line 15"
    assert r.dropped_duplicate_faces == 1 and r.examples["dropped_duplicate_faces"] == "face 4, line 16"
    assert r.n_components == 2 and r.changed
    lines = r.lines()
    assert lines[0] == "triangulated 2 polygons (2 quads) into 4 triangles"
    assert "dropped 1 face with zero area (e.g. face 3, line 15)" in lines
    assert "merged 1 vertex with identical coordinates (e.g. vertex 7, a copy of vertex 1)" in lines
    assert lines[-1].startswith("found 2 connected components")
    d = json.loads(json.dumps(r.as_dict()))
    assert d["dropped_duplicate_faces"] == 1 and d["source"] == str(path) and d["file_format"] == "obj"
    kinds = [type(w.message) for w in caught]
    assert kinds.count(mesh.MeshCleaningWarning) == 1 and kinds.count(mesh.MultipleComponentsWarning) == 1
    text = str(next(w.message for w in caught if w.category is mesh.MeshCleaningWarning))
    assert "zero area" in text and "connected components" not in text
    # a clean mesh: no lines, no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        clean = mesh.load(_icosphere(1))
    assert clean.report.lines() == [] and not clean.report.changed
    assert mesh.load(path, warn=False).report == r


# ---------------------------------------------------------------- truncated / miscounted / bad indices


@pytest.mark.parametrize(
    "name, text, error, line, words",
    [
        ("trunc.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n", mesh.MeshFormatError, 7, "truncated"),
        ("trunc_v.off", "OFF\n4 2 0\n0 0 0\n1 0 0\n", mesh.MeshFormatError, 4, "truncated"),
        ("under.off", "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n", mesh.MeshFormatError, 8,
         "undercount"),
        ("under_v.off", "# c\nOFF\n3 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n", mesh.MeshFormatError, 7, "face"),
        ("bad_index.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n", mesh.IndexOutOfRangeError, 6, "0-based"),
        ("zero.obj", TRI + "f 1 2 3\nf 0 1 2\n", mesh.MeshFormatError, 6, "start at 1"),
        ("range.obj", TRI + "f 1 2 3\nf 2 4 5\n", mesh.IndexOutOfRangeError, 6, "5 > 4"),
        ("rel.obj", TRI + "f -1 -2 -5\n", mesh.IndexOutOfRangeError, 5, "before the first vertex"),
        ("short.obj", TRI + "f 1 2\n", mesh.MeshFormatError, 5, "2 corners"),
        ("coord.obj", "v 0 0 0\nv 1 x 0\nv 0 1 0\nf 1 2 3\n", mesh.MeshFormatError, 2, "not numbers"),
        ("trunc.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
         "element face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
         mesh.MeshFormatError, 13, "truncated"),
        ("trunc.stl", "solid s\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n", mesh.MeshFormatError,
         6, "truncated"),
    ],
)
def test_bad_text_files_name_file_and_line(tmp_path, name, text, error, line, words):
    path = _write(tmp_path / name, text)
    with pytest.raises(error, match=re.escape(words)) as info:
        mesh.load(path)
    assert info.value.path == str(path) and info.value.line == line
    assert str(info.value).startswith(f"{path}:{line}: ")


def test_truncated_binary_files(tmp_path):
    V, F = _icosphere(1)
    s = trimesh.Trimesh(V, F, process=False)
    for ext, cut in (("ply", 30), ("stl", 50)):
        data = s.export(file_type=ext)
        with pytest.raises(mesh.MeshFormatError, match="truncated") as info:
            mesh.load(_write(tmp_path / f"t.{ext}", data[:-cut]))
        assert info.value.path.endswith(f"t.{ext}")
        with pytest.raises(mesh.MeshFormatError, match="undercount" if ext == "ply" else "not a valid STL"):
            mesh.load(_write(tmp_path / f"long.{ext}", data + b"\x01" * 50))


def test_obj_relative_indices_and_slash_syntax(tmp_path):
    ref = mesh.load(_write(tmp_path / "plain.obj", TRI + "f 1 2 3\nf 2 4 3\n"))
    variants = [
        TRI + "vt 0 0\nvn 0 0 1\nf 1/1/1 2/1/1 3/1/1\nf 2/1/1 4/1/1 3/1/1\n",
        TRI + "vn 0 0 1\nf 1//1 2//1 3//1\nf 2//1 4//1 3//1\n",
        TRI + "vt 0 0\nf 1/1 2/1 3/1\nf 2/1 4/1 3/1\n",
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 1 1 0\nf -3/1/1 -1 -2\n",  # relative to the vertices so far
        "\ufeff# BOM, CRLF\r\n" + TRI.replace("\n", "\r\n") + "f 1 2 3 # comment\r\nf 2 4 3\r\n",
    ]
    for i, text in enumerate(variants):
        m = mesh.load(_write(tmp_path / f"v{i}.obj", text))
        np.testing.assert_array_equal(m.faces, ref.faces)
        np.testing.assert_array_equal(m.vertices, ref.vertices)


# ---------------------------------------------------------------- polygons


def test_nonconvex_polygons_are_triangulated_without_flips_or_refused(tmp_path):
    # L-shaped hexagon, counter-clockwise: a fan from corner 0 would flip a triangle
    L = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0]], float)
    for start in range(6):
        poly = np.roll(np.arange(6), -start)
        m = mesh.load((L, [poly]))
        normals = np.cross(*(m.vertices[m.faces[:, k]] - m.vertices[m.faces[:, 0]] for k in (1, 2)))
        assert m.n_faces == 4 and np.all(normals[:, 2] > 0)
        np.testing.assert_allclose(m.total_area, 3.0)
        assert m.report.nonconvex_polygons == 1 and m.report.examples["nonconvex_polygons"] == "face 0"
    # a dart quad fans only from its reflex corner; the other diagonal is taken when needed
    dart = np.array([[0, 0, 0], [2, 0, 0], [0.5, 0.5, 0], [0, 2, 0]])
    for quad in ([0, 1, 2, 3], [1, 2, 3, 0]):
        m = mesh.load((dart, [quad]))
        np.testing.assert_allclose(m.total_area, 1.0)
        assert "1 polygon non-convex" in m.report.lines()[1]
    # a skew quad has a valid split; it is reported as far from planar, not as non-convex
    skew = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.5], [0, 1, 0]])
    r = mesh.load((skew, [[0, 1, 2, 3]])).report
    assert (r.nonplanar_polygons, r.nonconvex_polygons, r.output_faces) == (1, 0, 2)
    # bowtie quad and pentagram: refused, with the file line
    _write(tmp_path / "bowtie.obj", "v 0 0 0\nv 1 1 0\nv 1 0 0\nv 0 1 0\nf 1 2 3 4\n")
    with pytest.raises(mesh.NonTriangleFacesError, match="self-intersecting") as info:
        mesh.load(tmp_path / "bowtie.obj")
    assert info.value.line == 5
    a = np.pi / 2 + 2 * np.pi * np.arange(5) / 5
    star = np.stack([np.cos(a), np.sin(a), 0 * a], axis=1)
    with pytest.raises(mesh.NonTriangleFacesError, match="self-intersecting"):
        mesh.load((star, [[0, 2, 4, 1, 3]]))


def test_polygon_files_report_quads_in_every_format(tmp_path):
    # pentagon (non-convex), quad, triangle, in OBJ, OFF, ASCII PLY and ragged binary PLY
    V = np.array([[0, 0, 0], [2, 0, 0], [2, 2, 0], [1, 0.5, 0], [0, 2, 0], [3, 0, 0], [3, 2, 0], [4, 1, 0]], float)
    polys = [[0, 1, 2, 3, 4], [1, 5, 6, 2], [5, 7, 6]]
    head = "".join(f"v {x} {y} {z}\n" for x, y, z in V)
    files = {
        "p.obj": head + "".join("f " + " ".join(str(i + 1) for i in p) + "\n" for p in polys),
        "p.off": f"OFF\n{len(V)} {len(polys)} 0\n" + head.replace("v ", "")
        + "".join(f"{len(p)} " + " ".join(map(str, p)) + "\n" for p in polys),
        "p.ply": "ply\nformat ascii 1.0\nelement vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 3\nproperty list uchar int vertex_indices\nend_header\n" + head.replace("v ", "")
        + "".join(f"{len(p)} " + " ".join(map(str, p)) + "\n" for p in polys),
    }
    hdr = ("ply\nformat binary_little_endian 1.0\nelement vertex 8\nproperty double x\nproperty double y\n"
           "property double z\nelement face 3\nproperty list uchar uint vertex_indices\nend_header\n").encode()
    body = V.astype("<f8").tobytes() + b"".join(struct.pack(f"<B{len(p)}I", len(p), *p) for p in polys)
    for name, data in [*files.items(), ("b.ply", hdr + body)]:
        r = mesh.load(_write(tmp_path / name, data)).report
        assert (r.input_faces, r.output_faces, r.triangulated_polygons, r.triangulated_quads) == (3, 6, 2, 1), name
        assert r.nonconvex_polygons == 1, name


# ---------------------------------------------------------------- encodings, gzip, garbage, dependencies


def test_latin1_gzip_garbage_and_unknown_formats(tmp_path):
    latin = "# modèle été\ng tête\n".encode("latin-1") + (TRI + "f 1 2 3\n").encode()
    m = mesh.load(_write(tmp_path / "latin.obj", latin))
    assert m.report.encoding == "latin-1" and any("Latin-1" in line for line in m.report.lines())
    assert mesh.load(_write(tmp_path / "utf8.obj", "# modèle\n" + TRI + "f 1 2 3\n")).report.encoding == "utf-8"
    V, F = _icosphere(1)
    s = trimesh.Trimesh(V, F, process=False)
    for ext in ("obj", "off", "ply", "stl"):
        data = s.export(file_type=ext)
        data = data.encode() if isinstance(data, str) else data
        m = mesh.load(_write(tmp_path / f"s.{ext}.gz", gzip.compress(data)))
        assert (m.n_vertices, m.n_faces) == (42, 80) and m.report.compressed and m.report.file_format == ext
    with pytest.raises(mesh.MeshFormatError, match="not gzip"):
        mesh.load(_write(tmp_path / "fake.obj.gz", TRI))
    junk = np.random.default_rng(0).bytes(4000)
    for ext in ("obj", "off", "ply", "stl"):
        with pytest.raises(mesh.MeshFormatError, match=f"not a valid {ext.upper()}"):
            mesh.load(_write(tmp_path / f"junk.{ext}", junk))
    with pytest.raises(mesh.MeshFormatError, match="not a valid OFF"):
        mesh.load(_write(tmp_path / "words.off", "hello world\n1 2 3\n"))
    with pytest.raises(mesh.MeshFormatError, match="not a valid OBJ.*line 2: 'bonjour à tous'"):
        mesh.load(_write(tmp_path / "words.obj", "# salut\nbonjour à tous\n"))
    with pytest.raises(mesh.MeshFormatError, match="unknown mesh format '.dae'"):
        mesh.load(_write(tmp_path / "x.dae", "<xml/>"))


def test_loader_imports_only_declared_dependencies(tmp_path):
    before = set(sys.modules)
    V, F = _icosphere(1)
    s = trimesh.Trimesh(V, F, process=False)
    for ext in ("obj", "off", "ply", "stl"):
        data = s.export(file_type=ext)
        mesh.load(_write(tmp_path / f"d.{ext}.gz", gzip.compress(data.encode() if isinstance(data, str) else data)))
    pent = b"v 0 0 0\nv 2 0 0\nv 2 2 0\nv 1 .5 0\nv 0 2 0\nf 1 2 3 4 5\n"  # Latin-1, ear clipping
    mesh.load(_write(tmp_path / "p.obj", "# é\n".encode("latin-1") + pent))
    new = {name.split(".")[0] for name in set(sys.modules) - before} - set(sys.stdlib_module_names) - {"mesh"}
    project = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]
    declared = {re.split(r"[<>=!~ \[;]", d)[0].lower().replace("_", "-") for d in project["dependencies"]}
    deps_of_declared = set()
    for d in declared:
        for req in md.requires(d) or []:
            deps_of_declared.add(re.split(r"[<>=!~ \[;(]", req)[0].lower().replace("_", "-"))
    assert "mapbox-earcut" in declared and "charset_normalizer" not in new
    owners = md.packages_distributions()
    for name in sorted(new - {"_distutils_hack"}):
        dists = {o.lower().replace("_", "-") for o in owners.get(name, [name])}
        assert dists & (declared | deps_of_declared), f"loader imported {name} ({dists}), not a declared dependency"


# ---------------------------------------------------------------- point clouds, scale


def test_point_cloud_ply_says_no_faces(tmp_path):
    ply = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
           "end_header\n0 0 0\n1 0 0\n0 1 0\n")
    for name, text in (("pc.ply", ply), ("pc.obj", "v 0 0 0\nv 1 0 0\n")):
        with pytest.raises(mesh.EmptyMeshError, match="no faces: point clouds are not supported"):
            mesh.load(_write(tmp_path / name, text))


@pytest.mark.parametrize("scale, word", [(1e150, "overflow"), (1e80, "overflow"), (1e-80, "underflow"),
                                         (1e-200, "underflow")])
def test_coordinates_beyond_float64_area_range_are_named(scale, word):
    V, F = _icosphere(1)
    with pytest.raises(mesh.MeshScaleError, match=f"{word}.*rescale the vertices"):
        mesh.load((V * scale, F))


def test_large_but_representable_coordinates_work():
    V, F = _icosphere(1)
    lap = mesh.laplacian(mesh.load((V * 1e70, F)))
    np.testing.assert_allclose(mesh.eigenbasis(lap, 4).evals, mesh.eigenbasis(mesh.laplacian(sphere(1)), 4).evals,
                               atol=1e-8)


# ---------------------------------------------------------------- non-manifold path


def _sphere_with_fin() -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
    """Closed icosphere plus one triangle on an existing edge: that edge has 3 faces."""
    V, F = _icosphere(1)
    a, b = (int(i) for i in F[0, :2])
    tip = 1.8 * (V[a] + V[b]) / 2
    return np.vstack([V, tip]), np.vstack([F, [[a, b, len(V)]]]), (min(a, b), max(a, b))


def test_nonmanifold_mesh_loads_on_request_and_gets_the_robust_laplacian():
    V, F, edge = _sphere_with_fin()
    with pytest.raises(mesh.NonManifoldError, match=r"allow_nonmanifold=True.*--laplacian robust") as info:
        mesh.load((V, F))
    assert f"edge {edge} with 3 faces" in str(info.value)
    with pytest.warns(mesh.MeshCleaningWarning, match="kept 1 non-manifold edge"):
        m = mesh.load((V, F), allow_nonmanifold=True)
    assert not m.is_edge_manifold and (m.n_nonmanifold_edges, m.n_nonmanifold_vertices) == (1, 2)
    assert m.report.n_nonmanifold_edges == 1 and m.n_boundary_loops == 1 and not m.is_closed
    assert m.euler_characteristic == 43 - (120 + 2) + 81  # V − E + F still counts (= 2 here)
    with pytest.raises(mesh.NonManifoldError, match="weights='robust'"):
        mesh.laplacian(m)
    for lap in (mesh.laplacian(m, weights="robust"), mesh.robust_laplacian(m)):
        W = lap.W.toarray()
        np.testing.assert_allclose(W, W.T, atol=1e-14)
        np.testing.assert_allclose(W @ np.ones(m.n_vertices), 0.0, atol=1e-12)
        assert np.linalg.eigvalsh(W).min() > -1e-10 * np.abs(W).max()
        evals, evecs = mesh.eigenbasis(lap, 4)
        assert abs(evals[0]) < 1e-8 and evals[1] > 1e-3
        np.testing.assert_allclose(evecs[:, 0], evecs[0, 0], rtol=1e-6)
    assert mesh.laplacian(m, weights="graph").n == m.n_vertices


def test_bowtie_vertex_is_reported_but_loads():
    V, F = _icosphere(1)
    W = np.vstack([V, V + [3.0, 0, 0]])
    W[len(V) + 0] = V[0]  # the second sphere's vertex 0 sits on the first's: merged into one vertex
    m = mesh.load((W, np.vstack([F, F + len(V)])))
    assert m.is_edge_manifold and m.n_nonmanifold_vertices == 1 and m.n_components == 1
    assert any("1 non-manifold vertex" in line for line in m.report.lines())
