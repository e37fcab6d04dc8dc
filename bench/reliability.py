"""The fault catalogue: bad input, faults and loads tried as a careless or unlucky user would.

    python -m bench reliability [--out docs/RELIABILITY.md] [--only SUBSTRING]

Every case runs the real thing — the ``stiefel`` command in a child process, or one API call —
and is judged by what a user sees: the exit code, whether a traceback appears, whether the one
error line names the real cause (a regular expression per case), and for the output cases whether
the directory is consistent afterwards (``summary.json`` lists exactly the run's files, with
matching SHA-256, no staging leftovers, earlier results intact). The table (input, expected, got,
verdict) is written to ``docs/RELIABILITY.md`` with machine, date, commit and command, below the page's
``MARKER`` line (the hand-written part above it is kept).

The disk-full case mounts a 256 KiB tmpfs when the process may (root on Linux); otherwise it
fails ``os.fsync`` with ``ENOSPC`` in the child instead, and says so in the table.
"""

from __future__ import annotations

import argparse
import gzip
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

ROOT = Path(__file__).resolve().parents[1]
FAST = ["-k", "3", "--max-iters", "60", "--no-png", "--quiet"]


@dataclass
class Case:
    cls: str          # class of failure (outputs, mesh, parameters, …)
    input: str        # what was tried
    expected: str     # what a user should see
    run: Callable[[Path], tuple[bool, str]]   # (passed, what happened)


# ----------------------------------------------------------------------------- running the CLI


def _cli(args: list[str], cwd: Path, *, prelude: str = "", timeout: float = 300) -> subprocess.CompletedProcess:
    """``stiefel ARGS`` in a child process; ``prelude`` is Python run before ``stiefel_cmm.cli.main`` (fault injection)."""
    code = f"{prelude}\nimport sys\nfrom stiefel_cmm.cli.main import _entry\nsys.argv = ['stiefel'] + {args!r}\n_entry()\n"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)


def _err_line(p: subprocess.CompletedProcess) -> str:
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    return lines[-1] if lines else ""


def _judge_error(p: subprocess.CompletedProcess, rc: int, pattern: str) -> tuple[bool, str]:
    """An error run: exit ``rc``, no traceback, last stderr line matches ``pattern``."""
    line = _err_line(p)
    tb = "Traceback" in p.stderr
    ok = p.returncode == rc and not tb and re.search(pattern, line, re.I) is not None
    got = f"exit {p.returncode}{', TRACEBACK' if tb else ''}: {line[:200]}"
    return ok, got


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _snapshot(out: Path) -> dict[str, str]:
    return {p.name: _sha(p) for p in sorted(out.iterdir()) if p.is_file()} if out.is_dir() else {}


def _listed(summary: dict) -> dict[str, dict]:
    """``{file name: {"bytes", "sha256"}}`` from a summary's ``files`` (roles → names or records)."""
    out = {}
    for v in summary.get("files", {}).values():
        if isinstance(v, str):
            out[v] = {}
        elif isinstance(v, dict) and "name" in v:
            out[v["name"]] = v
    return out


_OURS = re.compile(r"^(modes|eigs|comparison)\.|^summary\.json$")


def _consistent(out: Path) -> tuple[bool, str]:
    """summary.json present, lists exactly the stiefel files present, hashes match, no staging left."""
    s = out / "summary.json"
    if not s.is_file():
        return False, "no summary.json"
    summary = json.loads(s.read_text())
    listed = _listed(summary)
    present = {p.name for p in out.iterdir() if p.is_file() and _OURS.search(p.name)} - {"summary.json"}
    leftovers = [p.name for p in out.iterdir() if "staging" in p.name or p.name.endswith((".tmp", ".partial"))]
    problems = []
    if set(listed) != present:
        problems.append(f"listed {sorted(listed)} but present {sorted(present)}")
    for name, rec in listed.items():
        if (out / name).is_file() and rec.get("sha256") and rec["sha256"] != _sha(out / name):
            problems.append(f"{name}: SHA-256 mismatch")
        if not rec.get("sha256"):
            problems.append(f"{name}: no SHA-256 in summary")
    if leftovers:
        problems.append(f"leftovers {leftovers}")
    return not problems, "; ".join(problems) or "consistent (summary lists exactly the files, hashes match)"


def _baseline(tmp: Path, name: str, extra: list[str] | None = None) -> tuple[Path, dict[str, str]]:
    out = tmp / name
    p = _cli(["modes", "--out", str(out), "-k", "3", "--max-iters", "60", "--quiet"] + (extra or []), tmp)
    if p.returncode != 0:
        raise RuntimeError(f"baseline run failed: {_err_line(p)}")
    return out, _snapshot(out)


# ----------------------------------------------------------------------------- output cases

_KILL_AT_FSYNC = ("import os, signal\n"
                  "def _f(fd, _s=signal.{sig}):\n    os.kill(os.getpid(), _s)\n"
                  "os.fsync = _f\n")


def _interrupt_during_write(sig: str) -> Callable[[Path], tuple[bool, str]]:
    def run(tmp: Path) -> tuple[bool, str]:
        out, before = _baseline(tmp, f"kill_{sig}")
        p = _cli(["modes", "--out", str(out), "-k", "4", "--max-iters", "60", "--quiet"], tmp,
                 prelude=_KILL_AT_FSYNC.format(sig=sig))
        after = _snapshot(out)
        intact = before == {k: v for k, v in after.items() if k in before} and set(after) <= set(before) | {
            ".stiefel.lock"}
        tb = "Traceback" in p.stderr
        note = ""
        if sig == "SIGKILL":  # nothing runs after SIGKILL: its staging directory stays until the next run
            left = [q.name for q in out.iterdir() if "staging" in q.name]
            again = _cli(["modes", "--out", str(out), "-k", "3", "--max-iters", "60", "--quiet"], tmp)
            gone = not [q.name for q in out.iterdir() if "staging" in q.name]
            note = (f"; staging left by the kill: {len(left)}, removed by the next run (exit {again.returncode}): "
                    f"{'yes' if gone else 'NO'}")
            intact = intact and gone and again.returncode == 0
        ok_c, why = _consistent(out)
        return intact and ok_c and not tb, (f"exit {p.returncode}{', TRACEBACK' if tb else ''}; previous outputs "
                                            f"{'byte-identical' if intact else 'CHANGED'}; {why}{note}")
    return run


def _disk_full(tmp: Path) -> tuple[bool, str]:
    mnt = tmp / "tinyfs"
    mnt.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(mnt)],
                             capture_output=True).returncode == 0 if os.geteuid() == 0 else False
    try:
        if mounted:
            out = mnt / "out"
            first = _cli(["eigs", "--out", str(out), "-k", "3", "--quiet", "--no-png"], tmp)  # ~300 KB: fits
            before = _snapshot(out)
            st = os.statvfs(mnt)  # leave 16 KiB: the second run's eigs.npz cannot fit
            (mnt / "filler").write_bytes(b"\0" * max(0, st.f_bavail * st.f_frsize - 16384))
            p = _cli(["eigs", "--out", str(out), "-k", "6", "--seed", "1", "--quiet", "--no-png"], tmp)
            how = "1 MiB tmpfs"
        else:
            out, before = _baseline(tmp, "diskfull")
            first = None
            prelude = ("import os, errno\ndef _f(fd):\n    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))\n"
                       "os.fsync = _f\n")
            p = _cli(["modes", "--out", str(out), "-k", "4", "--max-iters", "60", "--quiet"], tmp, prelude=prelude)
            how = "fsync fails with ENOSPC"
        after = _snapshot(out)
        ok, got = _judge_error(p, 1, r"no space|disk")
        intact = after == before
        leftovers = [q.name for q in out.iterdir() if "staging" in q.name] if out.is_dir() else []
        base = "" if first is None or first.returncode == 0 else f" (first run exit {first.returncode})"
        return ok and intact and not leftovers, (f"{how}: {got}; earlier outputs "
                                                 f"{'intact' if intact else 'CHANGED'}{base}"
                                                 f"{'; leftovers ' + str(leftovers) if leftovers else ''}")
    finally:
        if mounted:
            subprocess.run(["umount", str(mnt)], capture_output=True)


def _concurrent(tmp: Path) -> tuple[bool, str]:
    out = tmp / "conc"
    code = ("import sys\nfrom stiefel_cmm.cli.main import _entry\n"
            f"sys.argv = ['stiefel', 'modes', '--out', {str(out)!r}, '-k', '4', '--max-iters', '400']\n_entry()\n")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    a = subprocess.Popen([sys.executable, "-c", code], cwd=tmp, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    try:
        for line in a.stdout:  # wait until A has loaded its mesh (it holds the lock from the start)
            if "solving" in line:
                break
        b = _cli(["modes", "--out", str(out)] + FAST, tmp)
        a.wait(timeout=300)
    finally:
        a.kill()
    ok_b, got_b = _judge_error(b, 1, r"lock|another|in use|concurrent")
    ok_c, why = _consistent(out)
    return ok_b and a.returncode == 0 and ok_c, f"second run: {got_b}; first run exit {a.returncode}; {why}"


def _no_png_after_png(tmp: Path) -> tuple[bool, str]:
    out, _ = _baseline(tmp, "nopng")
    had = (out / "modes.png").is_file()
    p = _cli(["modes", "--out", str(out)] + FAST, tmp)
    ok_c, why = _consistent(out)
    gone = not (out / "modes.png").exists()
    return had and gone and ok_c and p.returncode == 0, (f"exit {p.returncode}; modes.png "
                                                         f"{'removed' if gone else 'STILL THERE'}; {why}")


def _eigs_into_modes(tmp: Path) -> tuple[bool, str]:
    out, before = _baseline(tmp, "eigsmodes", ["--no-png"])
    p = _cli(["eigs", "--out", str(out), "-k", "3", "--quiet"], tmp)
    ok, got = _judge_error(p, 1, r"modes")
    return ok and _snapshot(out) == before, got + ("; modes outputs intact" if _snapshot(out) == before else
                                                   "; modes outputs CHANGED")


def _out_is_file(command: str) -> Callable[[Path], tuple[bool, str]]:
    def run(tmp: Path) -> tuple[bool, str]:
        f = tmp / f"afile_{command}"
        f.write_text("not a directory\n")
        t = time.perf_counter()
        args = [command, "--out", str(f), "-k", "3", "--quiet"] + (["--smoothings", "f1,f6", "--max-iters", "60"]
                                                                  if command == "compare-smoothings" else [])
        p = _cli(args, tmp)
        dt = time.perf_counter() - t
        ok, got = _judge_error(p, 1, r"out|director|file")
        return ok and f.read_text() == "not a directory\n", f"{got} ({dt:.1f} s: before any solve)"
    return run


# ----------------------------------------------------------------------------- mesh files

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
        p = _cli(["modes", str(path), "--out", str(tmp / ("o_" + name))] + FAST + (extra or []), tmp)
        if rc == 0:
            ok = p.returncode == 0 and "Traceback" not in p.stderr and re.search(pattern, p.stderr, re.I)
            return bool(ok), f"exit {p.returncode}; stderr: {' | '.join(p.stderr.strip().splitlines())[:220]}"
        return _judge_error(p, rc, pattern)
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

# ----------------------------------------------------------------------------- CLI parameters


def _usage(args: list[str], pattern: str, rc: int = 2):
    def run(tmp: Path) -> tuple[bool, str]:
        return _judge_error(_cli(args + ["--out", str(tmp / "u")], tmp), rc, pattern)
    return run


def _admm_cap(tmp: Path) -> tuple[bool, str]:
    out = tmp / "admmcap"
    p = _cli(["modes", "--method", "admm", "--max-iters", "40", "-k", "3", "--no-png", "--quiet", "--json",
              "--out", str(out)], tmp)
    if p.returncode != 0:
        return False, f"exit {p.returncode}: {_err_line(p)}"
    it = json.loads(p.stdout)["diagnostics"]["iterations"]
    return it <= 40, f"{it} iterations with a cap of 40"


def _interrupt_imports(tmp: Path) -> tuple[bool, str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    a = subprocess.Popen([sys.executable, "-m", "stiefel_cmm.cli.main", "modes", "--out", str(tmp / "imp")], cwd=tmp, env=env,
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(0.4)
    a.send_signal(signal.SIGINT)
    _, err = a.communicate(timeout=60)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    ok = a.returncode == 130 and "Traceback" not in err and len(lines) <= 1
    return ok, f"exit {a.returncode}, {len(lines)} stderr line(s): {lines[-1][:120] if lines else ''}"


def _sigterm_solve(tmp: Path) -> tuple[bool, str]:
    """SIGTERM once the solve has reported progress (there is an iterate to keep): the modes reached are written and
    labelled interrupted, as with SIGINT; a clean exit 143 (130), no traceback."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    a = subprocess.Popen([sys.executable, "-m", "stiefel_cmm.cli.main", "modes", "--out", str(tmp / "term"), "-k", "6",
                          "--max-iters", "5000", "--no-png"], cwd=tmp, env=env, stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True)
    seen = []
    for line in a.stderr:  # progress lines ("block: it 1/5000 …") go to stderr
        seen.append(line)
        if " it " in line:
            break
    a.send_signal(signal.SIGTERM)
    _, err = a.communicate(timeout=120)
    err = "".join(seen) + err
    summary = tmp / "term" / "summary.json"
    status = json.loads(summary.read_text()).get("diagnostics", {}).get("status") if summary.is_file() else None
    ok = a.returncode in (130, 143) and "Traceback" not in err and status == "interrupted"
    return ok, f"exit {a.returncode}, summary status {status}"


CLI_CASES: list[Case] = [
    Case("parameters", "--max-iters 0", "usage error, exit 2", _usage(["modes", "--max-iters", "0"], r"max-iters")),
    Case("parameters", "--max-iters -5", "usage error, exit 2", _usage(["modes", "--max-iters", "-5"], r"max-iters")),
    Case("parameters", "--max-iters 2.5", "usage error, exit 2", _usage(["modes", "--max-iters", "2.5"],
                                                                         r"max-iters")),
    Case("parameters", "--max-iters 99999999999", "usage error naming the bound, exit 2",
         _usage(["modes", "--max-iters", "99999999999"], r"max-iters")),
    Case("parameters", "-k 0", "usage error", _usage(["modes", "-k", "0"], r"-k|\bk\b")),
    Case("parameters", "-k 3.0", "usage error", _usage(["modes", "-k", "3.0"], r"-k|\bk\b|integer")),
    Case("parameters", "-k 2562 (= n of the demo mesh)", "error naming k < n, exit 1",
         _usage(["modes", "-k", "2562"], r"\bk\b.*\bn\b|vertices", rc=1)),
    Case("parameters", "eigs -k 2562", "error naming k < n, exit 1",
         _usage(["eigs", "-k", "2562"], r"\bk\b.*\bn\b|vertices", rc=1)),
    Case("parameters", "--mu -1", "usage error", _usage(["modes", "--mu", "-1"], r"mu")),
    Case("parameters", "--mu nan", "usage error", _usage(["modes", "--mu", "nan"], r"mu")),
    Case("parameters", "--mu inf", "usage error", _usage(["modes", "--mu", "inf"], r"mu")),
    Case("parameters", "--gtol 0", "usage error", _usage(["modes", "--gtol", "0"], r"gtol|positive")),
    Case("parameters", "--gtol -1", "usage error", _usage(["modes", "--gtol", "-1"], r"gtol|positive")),
    Case("parameters", "--smoothings f1,f42", "error listing the names before any solve",
         _usage(["compare-smoothings", "--smoothings", "f1,f42"], r"f42|smoothing", rc=1)),
    Case("parameters", "--method admm --max-iters 40", "at most 40 iterations", _admm_cap),
    Case("tracebacks", "Ctrl-C 0.4 s after start (during the imports)", "exit 130, one line, no traceback",
         _interrupt_imports),
    Case("tracebacks", "SIGTERM during the solve", "clean exit (130/143), no traceback, the modes reached written and "
                                                   "labelled interrupted", _sigterm_solve),
]

OUTPUT_CASES: list[Case] = [
    Case("outputs", "SIGKILL during the write phase (second run into the same --out)",
         "previous outputs byte-identical, summary consistent; the kill's staging directory removed by the next run",
         _interrupt_during_write("SIGKILL")),
    Case("outputs", "SIGINT during the write phase", "previous outputs byte-identical, exit 130",
         _interrupt_during_write("SIGINT")),
    Case("outputs", "SIGTERM during the write phase", "previous outputs byte-identical",
         _interrupt_during_write("SIGTERM")),
    Case("outputs", "disk full during the write", "exit 1 with one line; earlier outputs intact; no partial files",
         _disk_full),
    Case("outputs", "two runs into one --out at once", "the second refused (lock); the first completes",
         _concurrent),
    Case("outputs", "--no-png after a run with the picture", "modes.png removed; summary lists exactly the files",
         _no_png_after_png),
    Case("outputs", "stiefel eigs into a modes directory", "refused before solving; modes outputs intact",
         _eigs_into_modes),
    Case("outputs", "--out is a regular file (modes)", "refused before any solve", _out_is_file("modes")),
    Case("outputs", "--out is a regular file (compare-smoothings)", "refused before any solve",
         _out_is_file("compare-smoothings")),
]

# ----------------------------------------------------------------------------- API


def _api(expr: str, error: str | None, pattern: str, setup: str = ""):
    """Run ``expr`` in a child: passes when it raises ``error`` (a class name) with ``pattern`` in the message,
    or, for ``error=None``, when it returns."""
    code = (
        "import jax; jax.config.update('jax_enable_x64', True)\n"
        "import numpy as np, scipy.sparse as sp, jax.numpy as jnp\n"
        "import stiefel, mesh, objectives\nfrom stiefel_cmm.cli.demo_mesh import demo_mesh\n"
        f"{setup}\n"
        "try:\n"
        f"    r = {expr}\n    print('RESULT accepted: ' + repr(r)[:160])\n"
        "except Exception as e:\n"
        "    mro = [c.__name__ for c in type(e).__mro__]\n"
        "    print('RESULT ' + type(e).__name__ + ' ' + ','.join(mro) + ' :: ' + ' '.join(str(e).split())[:200])\n"
    )

    def run(tmp: Path) -> tuple[bool, str]:
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        p = subprocess.run([sys.executable, "-c", code], cwd=tmp, env=env, capture_output=True, text=True,
                           timeout=300)
        line = next((ln for ln in p.stdout.splitlines() if ln.startswith("RESULT")), p.stderr.strip()[-200:])
        ok = error is None and line.startswith("RESULT accepted")
        if line.startswith("RESULT ") and not line.startswith("RESULT accepted"):
            name, mro, msg = line[7:].split(" ", 2)[0], line[7:].split(" ", 2)[1], line.split(" :: ", 1)[-1]
            ok = error is not None and error in mro.split(",") and re.search(pattern, msg, re.I) is not None
            line = f"{name}: {msg}"
        return ok, line[:240]
    return run


_SETUP_S = ("S = stiefel.GeneralizedStiefel(np.ones(30), 3)\nf = lambda X: jnp.sum(X ** 2 * jnp.arange(30.)[:, None])\n"
            "X0 = S.random_point(jax.random.PRNGKey(0))\n")
_SETUP_M = "m = mesh.load(demo_mesh(2))\nlap = mesh.laplacian(m)\n"

API_CASES: list[Case] = [
    Case("parameters", "minimize(max_iters=-5)", "StiefelError naming max_iters",
         _api("stiefel.minimize(f, S, X0, max_iters=-5)", "StiefelError", r"max_iters", _SETUP_S)),
    Case("parameters", "minimize(max_iters=True)", "StiefelError naming max_iters",
         _api("stiefel.minimize(f, S, X0, max_iters=True)", "StiefelError", r"max_iters", _SETUP_S)),
    Case("parameters", "minimize(gtol=-1)", "StiefelError naming gtol",
         _api("stiefel.minimize(f, S, X0, gtol=-1.0)", "StiefelError", r"gtol", _SETUP_S)),
    Case("parameters", "minimize(gtol=nan)", "StiefelError naming gtol",
         _api("stiefel.minimize(f, S, X0, gtol=float('nan'))", "StiefelError", r"gtol", _SETUP_S)),
    Case("parameters", "RiemannianCG(S, c1=0.9, c2=0.1)", "StiefelError: 0 < c1 < c2 < 1",
         _api("stiefel.RiemannianCG(S, c1=0.9, c2=0.1)", "StiefelError", r"c1", _SETUP_S)),
    Case("parameters", "RiemannianLBFGS(S, init_step=-1)", "StiefelError naming init_step",
         _api("stiefel.RiemannianLBFGS(S, init_step=-1.0)", "StiefelError", r"init_step", _SETUP_S)),
    Case("parameters", "minimize_sequential(max_iters=0)", "StiefelError naming max_iters",
         _api("stiefel.minimize_sequential(lambda x: x @ x, np.ones(30), 2, max_iters=0)", "StiefelError",
              r"max_iters", _SETUP_S)),
    Case("parameters", "GeneralizedStiefel(M, k=True)", "StiefelError naming k",
         _api("stiefel.GeneralizedStiefel(np.ones(5), True)", "StiefelError", r"\bk\b", _SETUP_S)),
    Case("parameters", "mesh.eigenbasis(lap, k=3.0)", "MeshError naming k (no SystemError from ARPACK)",
         _api("mesh.eigenbasis(lap, 3.0)", "MeshError", r"\bk\b", _SETUP_M)),
    Case("parameters", "mesh.eigenbasis(lap, k=n)", "MeshError naming k < n (no TypeError from scipy)",
         _api("mesh.eigenbasis(lap, lap.W.shape[0])", "MeshError", r"\bk\b", _SETUP_M)),
    Case("parameters", "a NaN in a user Laplacian (eigenbasis)", "named error: non-finite entries",
         _api("mesh.eigenbasis(badlap, 3)",
              "ValueError", r"finite|nan",
              _SETUP_M + "import dataclasses\nbad = lap.W.copy(); bad.data[0] = np.nan\n"
                         "badlap = dataclasses.replace(lap, W=bad)\n")),
    Case("parameters", "a NaN in a user Laplacian (compressed_modes)", "named error: non-finite entries",
         _api("objectives.compressed_modes((bad, lap.A), 3, 1.0)", "ValueError", r"finite|nan",
              _SETUP_M + "bad = lap.W.copy(); bad.data[0] = np.nan\n")),
    Case("parameters", "a rank-deficient start (two equal columns)", "named error: rank-deficient start",
         _api("objectives.compressed_modes(lap, 3, 1.0, start=np.repeat(np.ones((lap.W.shape[0], 1)), 3, 1))",
              "StiefelError", r"rank", _SETUP_M)),
    Case("parameters", "BlockCMM(max_iters=2.5)", "SolverOptionError (a StiefelError) naming max_iters",
         _api("objectives.BlockCMM(max_iters=2.5)", "StiefelError", r"max_iters")),
    Case("parameters", "ADMMCMM(max_iters=0)", "SolverOptionError naming max_iters",
         _api("objectives.ADMMCMM(max_iters=0)", "StiefelError", r"max_iters")),
    Case("mesh", "mesh.load of a non-manifold mesh, allow_nonmanifold=True, robust Laplacian", "works",
         _api("mesh.eigenbasis(mesh.laplacian(mesh.load((np.array([[0,0,0],[1,0,0],[0,1,0],[0,0,1],[.5,-.5,.5]],"
              "float), np.array([[0,2,1],[0,1,3],[0,3,2],[1,2,3],[0,1,4]])), allow_nonmanifold=True), "
              "weights='robust'), 2).evals", None, r"")),
]


# ----------------------------------------------------------------------------- report


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench reliability", description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "RELIABILITY.md")
    ap.add_argument("--only", default=None, help="run only cases whose input contains this text")
    args = ap.parse_args(argv)
    cases = OUTPUT_CASES + MESH_CASES + CLI_CASES + API_CASES
    if args.only:
        cases = [c for c in cases if args.only.lower() in (c.input + c.cls).lower()]
    rows = []
    t_all = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="stiefel-faults-") as d:
        for i, c in enumerate(cases, 1):
            tmp = Path(d) / f"case{i:02d}"
            tmp.mkdir()
            t = time.perf_counter()
            try:
                ok, got = c.run(tmp)
            except Exception as e:  # the harness itself failed: that is a failed case
                ok, got = False, f"harness: {type(e).__name__}: {' '.join(str(e).split())[:200]}"
            rows.append((c, ok, got))
            print(f"[{'ok' if ok else 'FAIL'}] {c.cls}: {c.input} -> {got} ({time.perf_counter() - t:.1f} s)",
                  flush=True)
            shutil.rmtree(tmp, ignore_errors=True)
    n_ok = sum(ok for _, ok, _ in rows)
    print(f"{n_ok}/{len(rows)} cases as expected ({time.perf_counter() - t_all:.0f} s)")
    if not args.only:
        _write(args.out, rows, argv)
    return 0 if n_ok == len(rows) else 1


#: the line of docs/RELIABILITY.md below which this script writes; the hand-written part above it is kept
MARKER = "<!-- Everything below is written by `python -m bench reliability`; edit bench/reliability.py, not this part. -->"


def catalogue(rows, meta: dict) -> str:
    """The generated part of the page: the fault catalogue's table with machine, date, commit and command."""
    esc = lambda s: str(s).replace("|", "\\|")  # noqa: E731
    lines = [
        "## The fault catalogue",
        "",
        "Classes of failure, each tried for real: the `stiefel` command in a child process",
        "(faults injected in that child where a real one cannot be arranged) or one API call. A case",
        "passes when the user sees what the *expected* column says: for errors, the exit code, no",
        "traceback, and one line naming the real cause; for outputs, a consistent directory",
        "(`summary.json` lists exactly the run's files with matching SHA-256, earlier results intact).",
        "",
        f"* machine: {meta['machine']}; date: {meta['date']}; commit: {meta.get('commit', 'unknown')}; "
        f"jax {meta['jax']}, scipy {meta['scipy']}",
        "* command: `python -m bench reliability` (writes this file; `--only TEXT` runs a subset)",
        f"* result: **{sum(ok for _, ok, _ in rows)} of {len(rows)}** cases as expected",
        "",
        "| # | class | input | expected | got | ✓ |",
        "|---|---|---|---|---|---|",
    ]
    for i, (c, ok, got) in enumerate(rows, 1):
        lines.append(f"| {i} | {c.cls} | {esc(c.input)} | {esc(c.expected)} | {esc(got)} | {'✓' if ok else '✗'} |")
    lines += ["", "The fast versions of these checks run in the default test suite (`tests/test_cli_outputs.py`,",
              "`tests/test_mesh_loading_faults.py`, `tests/test_parameters.py`, `tests/test_render.py`); rendering",
              "memory is measured in [benchmarks/render-memory.md](benchmarks/render-memory.md).", ""]
    return "\n".join(lines)


def page(old: str | None, generated: str) -> str:
    """The whole page: the existing page's hand-written part down to ``MARKER`` (a title where there is none),
    then the generated catalogue."""
    head = (old[:old.index(MARKER)] if old and MARKER in old else "# Reliability: bad input, faults and loads\n\n")
    return head + MARKER + "\n\n" + generated


def _write(path: Path, rows, argv) -> None:
    from bench.environment import run_meta, write_atomic

    old = path.read_text(encoding="utf-8") if path.is_file() else None
    write_atomic(path, page(old, catalogue(rows, run_meta("bench reliability", argv))))
    print(f"wrote {path}")


if __name__ == "__main__":
    sys.exit(main())
