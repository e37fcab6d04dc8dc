"""The ``stiefel`` command line (stiefel_cmm.cli.main): files, numbers and error reporting.

Most runs call ``stiefel_cmm.cli.main.main([...])`` in-process (JAX compiles once per
process); one run goes through ``python -m stiefel_cmm.cli.main`` in a subprocess, and one
checks that a bad argument there gives one stderr line and no traceback. How the
outputs are written (staging, lock, interrupts, full disk) is tested in
``test_cli_outputs.py``.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import mesh
from stiefel_cmm.cli.demo_mesh import demo_mesh
from stiefel_cmm.cli.main import main
from stiefel_cmm.cli.outputs import parse_mu

from mesh_fixtures import hand_mesh, write_mesh

#: the block solver's stopping at gtol = 1e-6 is not bit-reproducible run to run (the same
#: command converged in 413 iterations once and hit 5000 the next); tests use a looser
#: tolerance and a cap so that they stay fast whatever happens
FAST = ["--gtol", "1e-5", "--max-iters", "800"]
REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def hand(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A mesh file for the runs on a given path: the hand stand-in of tests/mesh_fixtures.py (the starfish
    example at size 0, 642 vertices; it replaced hand_868.obj) written as an OBJ file."""
    m = hand_mesh()
    return write_mesh(tmp_path_factory.mktemp("meshes") / "starfish_642.obj", m.vertices, m.faces)


def _a_orthonormality(modes: np.ndarray, source) -> float:
    """``max|ΨᵀAΨ − I|`` with A recomputed from the mesh."""
    lap = mesh.laplacian(mesh.load(source))
    return float(np.max(np.abs(modes.T @ (lap.A @ modes) - np.eye(modes.shape[1]))))


def _one_error_line(err: str) -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("stiefel: error: ")
    assert "Traceback" not in err
    return lines[0]


def _check_png(path: Path) -> None:
    import matplotlib.image as mpimg

    img = mpimg.imread(path)
    assert img.ndim == 3 and img.shape[0] > 100 and img.shape[1] > 100
    assert float(img[..., :3].std()) > 0.01  # not blank
    # the diverging colormap is centred at 0: both reds and blues appear
    rgb = img[..., :3].reshape(-1, 3)
    assert np.any(rgb[:, 0] - rgb[:, 2] > 0.2) or np.any(rgb[:, 2] - rgb[:, 0] > 0.2)


def _check_ply(path: Path, n: int, k: int, fmt: str = "binary_little_endian") -> None:
    """The PLY's header, and its fields equal to modes.npz beside it (read with plyfile and with trimesh)."""
    import plyfile
    import trimesh

    data = path.read_bytes()
    header = data[: data.index(b"end_header")].decode("ascii")
    assert f"format {fmt} 1.0" in header and f"element vertex {n}" in header
    assert [f"property double mode_{j}" in header for j in range(k)] == [True] * k
    npz = np.load(path.parent / "modes.npz")
    ply = plyfile.PlyData.read(str(path))
    for j in range(k):
        assert np.array_equal(ply["vertex"][f"mode_{j}"], npz["modes"][:, j])
    assert np.array_equal(np.stack([ply["vertex"][c] for c in "xyz"], axis=1), npz["vertices"])
    assert np.array_equal(np.vstack(ply["face"]["vertex_indices"]), npz["faces"])
    tm = trimesh.load(str(path), process=False)  # geometry readable by trimesh too
    assert tm.vertices.shape == (n, 3) and np.array_equal(tm.faces, npz["faces"])


def test_parse_mu() -> None:
    assert parse_mu("5.2").resolve(1000) == 5.2
    assert not parse_mu("5.2").relative
    assert parse_mu("0.01n").resolve(868) == pytest.approx(8.68)
    assert parse_mu("1e-3").resolve(10) == 1e-3
    for bad in ("abc", "-1", "0.01x", "", "n", "inf"):
        with pytest.raises(ValueError, match="invalid mu"):
            parse_mu(bad)


def test_modes_demo_mesh(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "demo"
    assert main(["modes", "-k", "3", "--mu", "0.01n", *FAST, "--out", str(out)]) == 0
    progress = capsys.readouterr().out
    assert "solving" in progress and "wrote" in progress  # one line per stage
    for name in ("modes.npz", "modes.ply", "modes.png", "summary.json"):
        assert (out / name).is_file(), name
    V, F = demo_mesh()
    z = np.load(out / "modes.npz")
    modes = z["modes"]
    assert modes.shape == (V.shape[0], 3)
    assert np.all(np.diff(z["compressed_eigenvalues"]) >= 0)
    assert _a_orthonormality(modes, (V, F)) < 1e-10
    diag = json.loads(str(z["diagnostics"]))
    assert diag["status"] in ("converged", "max_iters") and np.isfinite(diag["objective"])
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mu"] == pytest.approx(0.01 * V.shape[0])
    assert summary["parameters"]["mu"] == {"given": "0.01n", "relative": True, "unit": "times the vertex count",
                                           "value": summary["mu"]}
    assert summary["mesh"]["source"].startswith("demo:")
    for lib in ("python", "jax", "numpy", "scipy", "stiefel-cmm"):
        assert summary["versions"][lib]
    t = summary["timings"]
    assert set(t) == {"compile_s", "solve_s", "setup_s", "write_s", "total_s"} and t["solve_s"] > 0
    assert t["compile_s"] + t["solve_s"] + t["setup_s"] + t["write_s"] <= t["total_s"] * 1.001
    assert summary["compilation_cache"] is None  # STIEFEL_CACHE_DIR=off (conftest)
    assert summary["solver_options"] == {"max_iters": 800, "smoothing": "f6", "gtol": 1e-5}
    # files by role, each with its size and SHA-256; exactly the files written (stiefel_cmm.cli.run_dir)
    assert {role: rec["name"] for role, rec in summary["files"].items()} == {
        "npz": "modes.npz", "ply": "modes.ply", "png": "modes.png"}
    for rec in summary["files"].values():
        data = (out / rec["name"]).read_bytes()
        assert rec["bytes"] == len(data) and rec["sha256"] == hashlib.sha256(data).hexdigest()
    assert sorted(p.name for p in out.iterdir()) == [".stiefel.lock", "modes.npz", "modes.ply", "modes.png",
                                                     "summary.json"]
    _check_ply(out / "modes.ply", V.shape[0], 3)
    _check_png(out / "modes.png")


def test_modes_finish_records_exact_sparsity(tmp_path: Path) -> None:
    """--finish: exact zeros in modes.npz, the smooth modes beside them, the finish and ℓ1 residual in summary.json."""
    out = tmp_path / "finish"
    assert main(["modes", "-k", "3", "--mu", "2λ", *FAST, "--finish", "--no-png", "--quiet", "--out", str(out)]) == 0
    z = np.load(out / "modes.npz")
    modes, smooth = z["modes"], z["smooth_modes"]
    assert smooth.shape == modes.shape and np.mean(modes == 0.0) > 0.05 and np.mean(smooth == 0.0) < 0.01
    V, F = demo_mesh()
    assert _a_orthonormality(modes, (V, F)) < 1e-12
    diag = json.loads((out / "summary.json").read_text())["diagnostics"]
    assert diag["finish"]["status"] == "converged" and diag["objective"] <= diag["finish"]["objective_before"]
    assert diag["exact_zeros"] == pytest.approx(np.mean(modes == 0.0))
    assert diag["support_sizes"] == [int(c) for c in (modes != 0).sum(axis=0)] and diag["l1_residual"] < 1e-8


@pytest.mark.slow
def test_modes_hand_json_quiet(hand: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "hand"
    assert main(["modes", str(hand), "-k", "3", "--mu", "5.2", "--weighting", "uniform", "--seed", "1",
                 "--json", *FAST, "--out", str(out)]) == 0
    captured = capsys.readouterr()
    summary = json.loads(captured.out)  # exactly one JSON object on stdout
    assert summary == json.loads((out / "summary.json").read_text())
    assert summary["mu"] == 5.2 and summary["parameters"]["mu"]["relative"] is False
    assert summary["parameters"]["weighting"] == "uniform" and summary["seed"] == 1
    modes = np.load(out / "modes.npz")["modes"]
    assert modes.shape == (summary["mesh"]["n_vertices"], 3)
    assert _a_orthonormality(modes, hand) < 1e-10
    _check_png(out / "modes.png")
    # --quiet: nothing at all on stdout
    assert main(["eigs", str(hand), "-k", "3", "--quiet", "--out", str(tmp_path / "eigs")]) == 0
    assert capsys.readouterr().out == ""
    z = np.load(tmp_path / "eigs" / "eigs.npz")
    assert abs(z["eigenvalues"][0]) < 1e-8 and np.all(np.diff(z["eigenvalues"]) > 0)
    assert _a_orthonormality(z["eigenvectors"], hand) < 1e-10
    import plyfile  # eigs writes the eigenfunctions as PLY fields and a contact sheet too

    ply = plyfile.PlyData.read(str(tmp_path / "eigs" / "eigs.ply"))
    assert [np.array_equal(ply["vertex"][f"eig_{j}"], z["eigenvectors"][:, j]) for j in range(3)] == [True] * 3
    _check_png(tmp_path / "eigs" / "eigs.png")


@pytest.mark.slow
def test_compare_smoothings_subset(hand: Path, tmp_path: Path) -> None:
    out = tmp_path / "cmp"
    assert main(["compare-smoothings", str(hand), "-k", "3", "--smoothings", "f3,f6", "--quiet", *FAST,
                 "--out", str(out)]) == 0
    csv = (out / "comparison.csv").read_text().splitlines()
    assert csv[0].startswith("smoothing,name,c1_at_zero,status,objective,smoothed_objective,dirichlet,l1,exact_zeros,"
                             "l1_residual")
    assert [line.split(",")[0] for line in csv[1:]] == ["f3", "f6"]
    md = (out / "comparison.md").read_text()
    assert "| f6 | huber | True |" in md
    rows = json.loads((out / "summary.json").read_text())["results"]
    for r in rows:
        assert r["objective"] == pytest.approx(r["dirichlet"] + r["l1"])
        assert r["orthogonality"] < 1e-10
        # finished by default: exact zeros, never above the smoothing's own answer, status from the residual
        assert r["exact_zeros"] > 0 and r["objective"] <= r["smoothed_objective"] * (1 + 1e-12)
        assert (r["status"] == "converged") == (r["l1_residual"] <= 1e-8)
    import matplotlib.image

    img = matplotlib.image.imread(out / "comparison.png")
    assert img.shape[0] > 100 and float(img[..., :3].std()) > 0.01  # two rows of modes, not blank


@pytest.mark.slow
def test_compare_all_smoothings(hand: Path, tmp_path: Path) -> None:
    out = tmp_path / "cmp"
    assert main(["compare-smoothings", str(hand), "-k", "3", "--quiet", *FAST, "--out", str(out)]) == 0
    rows = json.loads((out / "summary.json").read_text())["results"]
    assert [r["smoothing"] for r in rows] == [f"f{i}" for i in range(10)]
    best = min(r["objective"] for r in rows if "objective" in r)
    f6 = next(r for r in rows if r["smoothing"] == "f6")
    assert f6["objective"] <= best * 1.05


@pytest.mark.parametrize("mu", ["abc", "-1", "0.01x"])
def test_bad_mu(mu: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["modes", "-k", "3", "--mu", mu, "--out", str(tmp_path)]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert "mu" in line and repr(mu) in line


def test_bad_mesh_path(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["modes", str(tmp_path / "missing.obj"), "-k", "3", "--out", str(tmp_path)]) != 0
    assert "not found" in _one_error_line(capsys.readouterr().err)


def test_non_manifold_mesh(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    # three triangles on one edge (0, 1): not edge-manifold → mesh.NonManifoldError
    path = tmp_path / "fin.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nf 1 2 3\nf 2 1 4\nf 1 2 5\n")
    assert main(["eigs", str(path), "-k", "2", "--out", str(tmp_path / "o")]) == 1
    assert "manifold" in _one_error_line(capsys.readouterr().err).lower()


def test_non_manifold_mesh_robust_laplacian(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    # a sphere with one fin triangle on an existing edge: refused by default, solved with --laplacian robust
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=2)
    a, b = sphere.faces[0][:2]
    V = np.vstack([sphere.vertices, [[0.0, 0.0, 3.0]]])
    F = np.vstack([sphere.faces, [[a, b, len(V) - 1]]])
    path = tmp_path / "fin_sphere.obj"
    path.write_text("".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in V.tolist())
                    + "".join(f"f {i} {j} {k}\n" for i, j, k in (F + 1).tolist()))
    assert main(["eigs", str(path), "-k", "4", "--out", str(tmp_path / "refused")]) == 1
    assert "--laplacian robust" in _one_error_line(capsys.readouterr().err)
    assert not (tmp_path / "refused" / "summary.json").exists()

    out = tmp_path / "robust"
    assert main(["eigs", str(path), "-k", "4", "--out", str(out), "--laplacian", "robust", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "non-manifold edge" in err  # the finding is reported, not silent
    summary = json.loads((out / "summary.json").read_text())
    assert summary["mesh"]["n_nonmanifold_edges"] == 1
    assert summary["mesh"]["cleaning_report"]["n_nonmanifold_edges"] == 1
    assert any("non-manifold edge" in line for line in summary["mesh"]["changes"])
    assert "robust" in summary["parameters"]["laplacian"]
    m = mesh.load(path, allow_nonmanifold=True, warn=False)
    ref = mesh.eigenbasis(mesh.laplacian(m, weights="robust"), 4)
    got = np.load(out / "eigs.npz")["eigenvalues"]
    np.testing.assert_allclose(got, np.asarray(ref.evals), rtol=1e-8, atol=1e-10)


def test_bad_k(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["modes", "-k", "0", "--out", str(tmp_path)]) == 2
    _one_error_line(capsys.readouterr().err)


@pytest.mark.slow
def test_subprocess_module(hand: Path, tmp_path: Path) -> None:
    out = tmp_path / "sub"
    cmd = [sys.executable, "-m", "stiefel_cmm.cli.main", "modes", str(hand), "-k", "3", "--no-png", "--json", *FAST,
           "--out", str(out)]
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    # the default μ = 2λ_(k−1)
    assert summary["parameters"]["mu"]["given"] == "2λ"
    assert summary["mu"] == pytest.approx(2 * summary["parameters"]["mu"]["eigenvalue"])
    assert (out / "modes.npz").is_file() and not (out / "modes.png").exists()
    bad = subprocess.run([sys.executable, "-m", "stiefel_cmm.cli.main", "modes", "--mu", "abc"], cwd=REPO,
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and bad.stdout == ""
    _one_error_line(bad.stderr)


def test_partial_columns(tmp_path: Path) -> None:
    from stiefel_cmm.cli.commands import _partial_writer
    from stiefel_cmm.cli.outputs import PartialColumns

    lines: list[str] = []
    saver = PartialColumns(tmp_path / "modes.partial.npz", lines.append)
    x = np.arange(5.0)
    for j in range(2):
        saver(j, {"x": x + j, "value": float(j), "status": "converged"})
        z = np.load(tmp_path / "modes.partial.npz")
        assert z["modes"].shape == (5, j + 1) and np.array_equal(z["modes"][:, j], x + j)
    saver(0, {"x": -x, "value": 0.0, "status": "converged"})  # a new stage restarts from column 0
    assert np.load(tmp_path / "modes.partial.npz")["modes"].shape == (5, 1)
    assert len(lines) == 3 and not list(tmp_path.glob("*.tmp.npz"))
    saver.discard()
    assert not (tmp_path / "modes.partial.npz").exists()

    def with_callback(lap, k, mu, *, callback=None): ...

    def without_callback(lap, k, mu): ...

    assert isinstance(_partial_writer("sequential", with_callback, tmp_path, print), PartialColumns)
    assert _partial_writer("block", with_callback, tmp_path, print) is None
    assert _partial_writer("sequential", without_callback, tmp_path, print) is None


def test_demo_mesh_is_deterministic_closed_surface() -> None:
    V, F = demo_mesh()
    V2, F2 = demo_mesh()
    assert np.array_equal(V, V2) and np.array_equal(F, F2)
    m = mesh.load((V, F))
    assert 1000 <= m.n_vertices <= 3000
    assert m.is_closed and m.n_components == 1 and m.euler_characteristic == 2


def test_compilation_cache_options(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """--cache-dir is used and recorded; a directory that cannot be written is one warning line and the run
    goes on without the cache; --no-cache records none."""
    cache = tmp_path / "cache"
    out = tmp_path / "a"
    assert main(["eigs", "-k", "3", "--quiet", "--cache-dir", str(cache), "--out", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["compilation_cache"] == str(cache)
    assert cache.is_dir()
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    capsys.readouterr()
    assert main(["eigs", "-k", "3", "--quiet", "--cache-dir", str(blocker / "sub"), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert err.count("warning: compilation cache") == 1 and "running without it" in err and "Traceback" not in err
    assert json.loads((out / "summary.json").read_text())["compilation_cache"] is None
    assert main(["eigs", "-k", "3", "--quiet", "--no-cache", "--cache-dir", str(cache), "--out", str(out)]) == 0
    assert json.loads((out / "summary.json").read_text())["compilation_cache"] is None
    import jax

    assert not jax.config.jax_compilation_cache_dir  # --no-cache turns off what an earlier run turned on


@pytest.mark.slow
def test_stored_programs_are_counted_in_the_summary(tmp_path: Path) -> None:
    """A second run with the same cache loads the solver programs instead of tracing them."""
    from stiefel import program_cache

    cache = tmp_path / "cache"
    counts = []
    for run in ("a", "b"):
        program_cache._MEMORY.clear()  # as in a new process
        assert main(["modes", "-k", "3", "--quiet", "--no-png", "--max-iters", "40", "--cache-dir", str(cache),
                     "--out", str(tmp_path / run)]) == 0
        counts.append(json.loads((tmp_path / run / "summary.json").read_text())["stored_programs"])
    assert counts[0]["stored"] >= 2 and counts[1]["loaded"] >= counts[0]["loaded"] + 2
    assert counts[1]["stored"] == counts[0]["stored"]
    assert main(["modes", "-k", "3", "--quiet", "--no-png", "--max-iters", "40", "--no-cache",
                 "--out", str(tmp_path / "c")]) == 0
    assert json.loads((tmp_path / "c" / "summary.json").read_text())["stored_programs"] is None


def test_ctrl_c_during_the_solve_writes_the_modes_reached(tmp_path: Path, capsys: pytest.CaptureFixture,
                                                          monkeypatch: pytest.MonkeyPatch) -> None:
    """SIGINT while the block solver runs: it stops at the next chunk, the modes reached are written with
    status interrupted, one stderr line, exit code 130; the solver's progress goes to stderr."""
    import os
    import signal

    import stiefel_cmm.cli.progress

    sent = []

    class Interrupting(stiefel_cmm.cli.progress.SolveProgress):
        def __call__(self, info):
            super().__call__(info)
            if info.iteration >= 20 and not sent:
                sent.append(info.iteration)
                os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr("stiefel_cmm.cli.commands.SolveProgress", Interrupting)
    out = tmp_path / "int"
    code = main(["modes", "-k", "3", "--mu", "0.01n", "--gtol", "1e-12", "--max-iters", "5000", "--no-png",
                 "--out", str(out)])
    captured = capsys.readouterr()
    assert code == 130 and sent
    assert "interrupted during the solve" in captured.err and "Traceback" not in captured.err
    assert "it " in captured.err and "f = " in captured.err  # progress lines (stderr is not a terminal here)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["diagnostics"]["status"] == "interrupted" and summary["interrupted"]["signal"] == "SIGINT"
    assert 20 <= summary["diagnostics"]["iterations"] < 5000
    modes = np.load(out / "modes.npz")["modes"]
    assert _a_orthonormality(modes, demo_mesh()) < 1e-10


def test_quiet_prints_no_progress(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["modes", "-k", "3", *FAST, "--no-png", "--quiet", "--out", str(tmp_path / "q")]) == 0
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""


@pytest.mark.slow
def test_a_corrupt_cache_never_crashes_a_run(tmp_path: Path) -> None:
    """Every file of the cache (XLA executables and stored programs) overwritten with garbage: the next
    process compiles again and gives the same modes."""
    cache = tmp_path / "cache"
    results = []
    for run in ("a", "b"):
        out = tmp_path / run
        cmd = [sys.executable, "-m", "stiefel_cmm.cli.main", "modes", "-k", "3", "--quiet", "--no-png", "--max-iters", "60",
               "--cache-dir", str(cache), "--out", str(out)]
        proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=300)
        assert proc.returncode == 0 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
        results.append(np.load(out / "modes.npz")["modes"])
        if run == "a":
            files = [p for p in cache.rglob("*") if p.is_file()]
            assert any(p.suffix == ".jaxexport" for p in files) and len(files) >= 4
            for p in files:
                p.write_bytes(b"\0garbage")
    assert np.array_equal(results[0], results[1])


@pytest.mark.slow
def test_ascii_ply_on_request(tmp_path: Path) -> None:
    out = tmp_path / "ascii"
    assert main(["modes", "-k", "2", "--quiet", "--no-png", "--max-iters", "30", "--ascii-ply", "--out", str(out)]) == 0
    _check_ply(out / "modes.ply", np.load(out / "modes.npz")["vertices"].shape[0], 2, fmt="ascii")
