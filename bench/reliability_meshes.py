"""The fault catalogue's mesh files: truncated, miscounted, mis-indexed, non-manifold, badly encoded or
compressed files, huge or NaN coordinates, point clouds, directories and unknown formats, each given to
``stiefel modes``.
"""

from __future__ import annotations

import gzip
import re
from pathlib import Path

from bench.reliability_harness import FAST, Case, judge_error, run_cli

_TET_V = "0 0 0\n1 0 0\n0 1 0\n0 0 1\n"
_TET_F = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]


def _off(nv: int, nf: int, body_faces: list[tuple[int, ...]], verts: str = _TET_V) -> str:
    faces = "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n" for f in body_faces)
    return f"OFF\n{nv} {nf} 0\n{verts}{faces}"


def _obj(verts: str, faces: list[tuple[int, ...]], base: int = 1) -> str:
    v = "".join(f"v {ln}\n" for ln in verts.strip().splitlines())
    return v + "".join("f " + " ".join(str(i + base) for i in f) + "\n" for f in faces)


def _sphere_with_stray(tmp: Path) -> Path:
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=3)
    V = s.vertices * 0.01
    far = V[s.faces[0]] + 1e4
    V2 = __import__("numpy").vstack([V, far])
    F2 = __import__("numpy").vstack([s.faces, [[len(V), len(V) + 1, len(V) + 2]]])
    path = tmp / "stray.obj"
    path.write_text(_obj("\n".join(" ".join(f"{c:.17g}" for c in row) for row in V2), [tuple(f) for f in F2]))
    return path


def _mesh_case(text_or_bytes, name: str, rc: int, pattern: str, extra: list[str] | None = None):
    def run(tmp: Path) -> tuple[bool, str]:
        path = tmp / name
        if isinstance(text_or_bytes, bytes):
            path.write_bytes(text_or_bytes)
        elif callable(text_or_bytes):
            path = text_or_bytes(tmp)
        else:
            path.write_text(text_or_bytes, encoding="utf-8")
        p = run_cli(["modes", str(path), "--out", str(tmp / ("o_" + name))] + FAST + (extra or []), tmp)
        if rc == 0:
            ok = p.returncode == 0 and "Traceback" not in p.stderr and re.search(pattern, p.stderr, re.I)
            return bool(ok), f"exit {p.returncode}; stderr: {' | '.join(p.stderr.strip().splitlines())[:220]}"
        return judge_error(p, rc, pattern)
    return run


def _quads() -> str:
    # a closed cube made of 6 quads
    v = "0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n1 1 1\n0 1 1\n"
    quads = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    return _obj(v, quads)


def _nonconvex() -> str:
    # an L-shaped hexagon (non-convex at vertex 3) closed by a fan to an apex
    v = "0 0 0\n2 0 0\n2 1 0\n1 1 0\n1 2 0\n0 2 0\n0.7 0.7 1\n"
    faces = [(5, 4, 3, 2, 1, 0)] + [(i, (i + 1) % 6, 6) for i in range(6)]
    return _obj(v, faces)


def _nonmanifold() -> str:
    # a tetrahedron plus one fin triangle on edge (0, 1): three faces share that edge
    v = _TET_V + "0.5 -0.5 0.5\n"
    return _obj(v, _TET_F + [(0, 1, 4)])


def _big_coords() -> str:
    return _obj("\n".join(" ".join(f"{float(c) * 1e150:.17g}" for c in ln.split()) for ln in _TET_V.splitlines()),
                _TET_F)


MESH_CASES: list[Case] = [
    Case("mesh", "sphere (r = 0.01) plus one far-away triangle (10⁴ away)", "no face dropped, the extra component "
         "reported", _mesh_case(_sphere_with_stray, "stray.obj", 0, r"component")),
    Case("mesh", "truncated OFF (header says 4 faces, file ends after 2)", "named error with the line number",
         _mesh_case(_off(4, 4, _TET_F[:2]), "trunc.off", 1, r"line|truncat|expected")),
    Case("mesh", "OFF header undercounts faces (says 2, file has 4)", "named error (extra data) with the line",
         _mesh_case(_off(4, 2, _TET_F), "under.off", 1, r"line|more|extra|header")),
    Case("mesh", "OBJ with index 0", "named error: OBJ indices start at 1, with the line",
         _mesh_case(_obj(_TET_V, _TET_F, base=0), "zero.obj", 1, r"index 0|0.*1-based|start at 1|line")),
    Case("mesh", "OBJ index past the vertex count", "named error with the index and the line",
         _mesh_case(_obj(_TET_V, _TET_F[:3] + [(1, 2, 9)]), "range.obj", 1, r"range|index|line")),
    Case("mesh", "non-convex hexagon in an OBJ", "triangulated correctly (reported), or refused by name",
         _mesh_case(_nonconvex(), "nonconvex.obj", 0, r"triangulat|polygon")),
    Case("mesh", "closed cube of 6 quads", "loads; the triangulation is reported",
         _mesh_case(_quads(), "quads.obj", 0, r"triangulat|quad|polygon")),
    Case("mesh", "Latin-1 OBJ (a comment with 'é' in Latin-1)", "loads",
         _mesh_case(("# caf\xe9\n" + _quads()).encode("latin-1"), "latin1.obj", 0, r".*")),
    Case("mesh", "gzip-compressed OBJ (cube.obj.gz)", "loads, or a named error saying gzip is not read",
         _mesh_case(gzip.compress(_quads().encode()), "cube.obj.gz", 0, r".*")),
    Case("mesh", "binary garbage named .obj", "named error: not a valid OBJ",
         _mesh_case(bytes(range(256)) * 8, "garbage.obj", 1, r"obj|valid|pars|format")),
    Case("mesh", "point-cloud PLY (vertices, no faces)", "'no faces: point clouds are not supported'",
         _mesh_case("ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
                    "property float z\nend_header\n" + _TET_V, "cloud.ply", 1, r"no faces|point cloud")),
    Case("mesh", "one non-manifold edge (tetrahedron plus a fin)", "named error naming --laplacian robust",
         _mesh_case(_nonmanifold(), "nonmanifold.obj", 1, r"robust")),
    Case("mesh", "the same with --laplacian robust", "runs the whole pipeline",
         _mesh_case(_nonmanifold(), "nonmanifold2.obj", 0, r".*", ["--laplacian", "robust", "-k", "2"])),
    Case("mesh", "coordinates of 1e150", "named error (or a correct run): no ArpackError",
         _mesh_case(_big_coords(), "huge.obj", 1, r"large|rescale|overflow|finite|scale")),
    Case("mesh", "a NaN coordinate", "named error naming the vertex",
         _mesh_case(_obj(_TET_V.replace("0 1 0", "0 nan 0"), _TET_F), "nan.obj", 1, r"finite|nan")),
    Case("mesh", "an empty file", "named error", _mesh_case("", "empty.off", 1, r"empty|no |valid")),
    Case("mesh", "a directory given as the mesh", "named error", _mesh_case(lambda t: t, "dir", 1, r"not a file|"
                                                                                                    r"director|found")),
    Case("mesh", "an unknown extension (.xyz)", "named error listing the formats",
         _mesh_case(_TET_V, "pts.xyz", 1, r"obj|off|ply|format")),
]
