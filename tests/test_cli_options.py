"""The API's options on the command line (``stiefel_cmm.cli.options``): Laplacian weights and areas, smoothing names
and aliases, continuation, optimiser, start (eigen / random / file), μ relative to λ, target sparsity,
generated example meshes — and their named errors before any solve."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import mesh
from stiefel_cmm.cli.main import main
from stiefel_cmm.cli.outputs import parse_mu

FAST = ["--gtol", "1e-5", "--max-iters", "400", "--no-png", "--quiet"]
SMALL = "example:patch"  # 1681 vertices, one boundary loop


def _error(capsys: pytest.CaptureFixture) -> str:
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("stiefel: error: "), lines
    return lines[0]


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def test_parse_mu_units() -> None:
    assert parse_mu("2λ").resolve(100, 7.0) == 14.0
    assert parse_mu("2lambda").resolve(100, 7.0) == 14.0 and parse_mu("0.5lam").unit == "λ"
    assert parse_mu("0.01n").resolve(100) == 1.0 and parse_mu("3").resolve(100) == 3.0
    with pytest.raises(ValueError, match="eigenvalue is needed"):
        parse_mu("2λ").resolve(100)
    with pytest.raises(ValueError, match="2λ or 2lambda"):
        parse_mu("2mu")


@pytest.mark.slow
def test_options_reach_the_solver_and_the_summary(tmp_path: Path) -> None:
    out = tmp_path / "o"
    argv = ["modes", SMALL, "-k", "3", "--smoothing", "logcosh", "--eps", "0.01", "--delta", "0.02",
            "--continuation", "2", "--continuation-start", "0.05", "--optimizer", "lbfgs", "--starts", "2", "--weights", "graph",
            "--area", "uniform", "--weighting", "uniform", "--mu", "1.5λ", "--start", "random", "--out", str(out),
            *FAST]
    assert main(argv) == 0
    s = _summary(out)
    opts = s["solver_options"]
    assert opts["smoothing"] == "f8" and opts["eps"] == 0.01 and opts["delta"] == 0.02
    assert opts["continuation"] == 2 and opts["continuation_start"] == 0.05 and opts["optimizer"] == "lbfgs"
    assert opts["starts"] == 2
    params = s["parameters"]
    assert params["smoothing"] == "f8" and params["optimizer"] == "lbfgs" and params["start"] == "random"
    assert "graph weights, uniform areas" in params["laplacian"] and params["weighting"] == "uniform"
    # μ = 1.5 λ_(k−1) of the graph Laplacian with uniform areas, computed independently
    lap = mesh.laplacian(mesh.example("patch"), weights="graph", area="uniform")
    lam = mesh.eigenbasis(lap, 3).evals
    assert s["mu"] == pytest.approx(1.5 * lam[-1], rel=1e-6)
    assert params["mu"]["eigenvalue"] == pytest.approx(lam[-1], rel=1e-6)


@pytest.mark.slow
def test_start_file_round_trip_and_bad_shapes(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    first = tmp_path / "first"
    assert main(["modes", SMALL, "-k", "3", "--out", str(first), *FAST]) == 0
    modes = np.load(first / "modes.npz")["modes"]
    # restarting from the modes reached, at the final smoothing only: the solver starts near a stationary point
    again = tmp_path / "again"
    assert main(["modes", SMALL, "-k", "3", "--start", str(first / "modes.npz"), "--continuation", "1",
                 "--out", str(again), *FAST]) == 0
    s = _summary(again)
    assert s["parameters"]["start"].endswith("modes.npz")
    assert s["diagnostics"]["iterations"] < _summary(first)["diagnostics"]["iterations"] / 3
    np.testing.assert_allclose(np.load(again / "modes.npz")["modes"], modes, atol=2e-3)
    # a start with too few rows, a missing file, the wrong suffix: named errors, nothing solved
    np.save(tmp_path / "short.npy", modes[:-5])
    assert main(["modes", SMALL, "-k", "3", "--start", str(tmp_path / "short.npy"), "--out",
                 str(tmp_path / "x"), *FAST]) == 1
    err = _error(capsys)
    assert "short.npy" in err and "(1676, 3)" in err and "(1681, ≥ 3)" in err
    assert not (tmp_path / "x" / "summary.json").exists()
    assert main(["modes", SMALL, "--start", str(tmp_path / "none.npy"), "--out", str(tmp_path / "y")]) == 2
    assert "start file not found" in _error(capsys)
    assert main(["modes", SMALL, "--start", "first.txt"]) == 2
    assert "eigen, random or a .npy/.npz file" in _error(capsys)
    # a fast solve cannot take a start file
    assert main(["modes", SMALL, "--method", "fast", "--start", str(tmp_path / "short.npy"),
                 "--out", str(tmp_path / "z")]) == 1
    assert "--start eigen or random" in _error(capsys)


def test_bad_options_are_named_before_any_work(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["modes", "--smoothing", "hubber", "--out", str(tmp_path / "a")]) == 2
    err = _error(capsys)
    assert "unknown smoothing 'hubber'" in err and "f9" in err and "huber" in err and "logcosh" in err
    assert main(["compare-smoothings", "--smoothings", "huber,nope", "--out", str(tmp_path / "b")]) == 2
    assert "unknown smoothing 'nope'" in _error(capsys)
    assert main(["modes", "--method", "admm", "--optimizer", "lbfgs", "--out", str(tmp_path / "c")]) == 1
    assert "--optimizer applies to --method block, not admm" in _error(capsys)
    assert main(["modes", "--method", "sequential", "--starts", "2", "--out", str(tmp_path / "s")]) == 1
    assert "--starts applies to --method block, not sequential" in _error(capsys)
    assert main(["modes", "--starts", "65", "--out", str(tmp_path / "s")]) == 2
    assert "expected an integer in [1, 64], got 65" in _error(capsys)
    assert main(["modes", "--method", "fast", "--eps", "0.1", "--out", str(tmp_path / "d")]) == 1
    assert "--eps applies to --method block or sequential" in _error(capsys)
    assert main(["modes", "--mu", "1", "--target-sparsity", "0.5"]) == 2
    assert "not allowed with argument" in _error(capsys)
    assert main(["modes", "--target-sparsity", "1.5"]) == 2
    assert "fraction in (0, 1)" in _error(capsys)
    assert main(["modes", "example:cube", "--out", str(tmp_path / "e")]) == 1
    err = _error(capsys)
    assert "unknown example mesh 'cube'" in err and "example:starfish" in err
    assert main(["eigs", "--area", "cotangent"]) == 2
    assert "invalid choice: 'cotangent'" in _error(capsys)
    for name in "abcde":
        assert not (tmp_path / name / "summary.json").exists()


@pytest.mark.slow
def test_smoothing_aliases_in_compare_and_grid(tmp_path: Path) -> None:
    out = tmp_path / "cmp"
    assert main(["compare-smoothings", SMALL, "-k", "2", "--smoothings", "huber,logcosh,f6", "--out", str(out),
                 "--gtol", "1e-5", "--max-iters", "300", "--quiet"]) == 0
    rows = _summary(out)["results"]
    assert [r["smoothing"] for r in rows] == ["f6", "f8"]            # aliases resolved, repeats dropped
    assert [r["name"] for r in rows] == ["huber", "logcosh"]
    md = (out / "comparison.md").read_text()
    assert "| f6 | huber |" in md and "| f8 | logcosh |" in md
    assert (out / "comparison.png").is_file()


@pytest.mark.slow
def test_target_sparsity(tmp_path: Path) -> None:
    out = tmp_path / "t"
    code = main(["modes", "example:bumpy", "-k", "2", "--target-sparsity", "0.5", "--out", str(out), *FAST])
    s = _summary(out)
    mu = s["parameters"]["mu"]
    assert mu["target_sparsity"] == 0.5 and mu["value"] == s["mu"] and len(mu["trials"]) >= 2
    # select_mu's tolerance (0.02) is met unless its budget ran out: then exit 3 and a best_effort record
    met = abs(s["diagnostics"]["sparsity"]["1e-3"] - 0.5) <= 0.02
    assert met or len(mu["trials"]) == 12
    assert mu["reached"] == met and code == (0 if met else 3) and ("best_effort" in s) == (not met)


def test_html_viewer_with_the_run_and_stiefel_view(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "h"
    assert main(["eigs", SMALL, "-k", "3", "--html", "--no-png", "--quiet", "--out", str(out)]) == 0
    s = _summary(out)
    assert s["files"]["html"]["name"] == "eigs.html" and s["viewer"]["vertices"] == 1681
    page = (out / "eigs.html").read_text()
    assert "eigenfunction 2" in page and "<script" in page and 'src="http' not in page
    # stiefel view on the same directory: view.html next to the run's files, listed in its summary (role view) and
    # removed by the next run into the directory (it showed the old run), which it does not block
    assert main(["view", str(out), "--quiet"]) == 0
    assert (out / "view.html").is_file() and _summary(out)["files"]["view"]["name"] == "view.html"
    assert main(["eigs", SMALL, "-k", "3", "--html", "--no-png", "--quiet", "--out", str(out)]) == 0
    assert not (out / "view.html").exists() and "view" not in _summary(out)["files"]
    # a directory without a run, and a run whose npz does not match its mesh: one-line named errors
    assert main(["view", str(tmp_path)]) == 1
    assert "no modes.npz or eigs.npz" in _error(capsys)
    z = dict(np.load(out / "eigs.npz"))
    z["eigenvectors"] = z["eigenvectors"][:-1]
    bad = tmp_path / "bad"
    bad.mkdir()
    np.savez(bad / "eigs.npz", **z)
    assert main(["view", str(bad)]) == 1
    assert "1680" in _error(capsys) and not (bad / "view.html").exists()
