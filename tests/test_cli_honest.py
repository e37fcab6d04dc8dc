"""Every output of ``stiefel`` says what it is ("Nothing silent", round 3).

* ``--out ""`` (the working directory in disguise) and other blank paths are usage errors;
* ``stiefel view DIR`` lists its page in ``DIR/summary.json``, so the next run removes it; files no run wrote
  stay and are named in ``other_files``;
* ``stiefel view`` checks the data file against ``summary.json`` (SHA-256) and shows the run's status;
* an unreachable ``--target-sparsity`` ends with exit code 3 and a ``best_effort`` record;
* SIGTERM takes SIGINT's path: a signal that lands outside the solver's loop still writes the modes reached;
* ``--start`` arrays of the wrong dtype and negative ``--mu`` values get messages that name the real problem.

Runs use a 162-vertex sphere (``--method admm --max-iters 3``: host numpy, no compilation) or ``stiefel eigs``;
the signal tests run the block solver on it with a few iterations.
"""

from __future__ import annotations

import hashlib
import json
import signal
import warnings
from pathlib import Path

import numpy as np
import pytest

from stiefel_cmm.cli.main import main
from stiefel_cmm.cli.run_dir import LOCK

from mesh_fixtures import write_mesh

QUICK = ["--method", "admm", "--max-iters", "3", "--no-png", "--quiet"]


@pytest.fixture(scope="module")
def sphere(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 162-vertex icosphere as an OBJ file."""
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=2)
    return write_mesh(tmp_path_factory.mktemp("meshes") / "sphere_162.obj", s.vertices * [1.4, 1.0, 0.8], s.faces)


def _lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.strip()]


def _one_error_line(err: str) -> str:
    lines = _lines(err)
    assert len(lines) == 1 and lines[0].startswith("stiefel: error: ") and "Traceback" not in err, err
    return lines[0]


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def _consistent(out: Path) -> dict:
    """``summary.json`` lists exactly the files present (but the lock and ``other_files``), with right hashes."""
    summary = _summary(out)
    listed = {rec["name"]: rec for rec in summary["files"].values()}
    others = {name.rstrip("/") for name in summary.get("other_files", [])}
    present = {p.name for p in out.iterdir()} - {"summary.json", LOCK}
    assert set(listed) == present - others, (sorted(listed), sorted(present), sorted(others))
    for name, rec in listed.items():
        data = (out / name).read_bytes()
        assert rec["bytes"] == len(data) and rec["sha256"] == hashlib.sha256(data).hexdigest(), name
    return summary


# ----------------------------------------------------------------------------- 1. degenerate output paths


@pytest.mark.parametrize("argv, option", [
    (["modes", "--out", ""], "--out"),
    (["eigs", "--out", "   "], "--out"),
    (["compare-smoothings", "--out", "\t"], "--out"),
    (["eigs", "--cache-dir", "", "--out", "x"], "--cache-dir"),
    (["view", ""], "OUTDIR"),
    (["view", ".", "--output", ""], "--output"),
])
def test_blank_output_paths_are_refused(argv: list[str], option: str, tmp_path: Path,
                                        monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert f"argument {option}" in line and "the path is empty" in line
    assert list(tmp_path.iterdir()) == []  # nothing written into the working directory


# ----------------------------------------------------------------------------- 2. view.html and other files


def test_view_page_is_listed_and_removed_by_the_next_run(sphere: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "d"
    assert main(["eigs", str(sphere), "-k", "3", "--no-png", "--quiet", "--out", str(out)]) == 0
    assert main(["view", str(out), "--quiet"]) == 0
    summary = _consistent(out)
    assert summary["files"]["view"]["name"] == "view.html" and summary["other_files"] == []
    assert main(["view", str(out), "--output", str(out / "second.html"), "--quiet"]) == 0
    assert _consistent(out)["files"]["view:second.html"]["name"] == "second.html"
    (out / "notes.txt").write_text("mine\n")  # not stiefel's: never touched, but named
    (out / "keep").mkdir()
    assert main(["eigs", str(sphere), "-k", "2", "--no-png", "--quiet", "--out", str(out)]) == 0
    summary = _consistent(out)
    assert not (out / "view.html").exists() and not (out / "second.html").exists()
    assert set(summary["files"]) == {"npz", "ply"} and summary["other_files"] == ["keep/", "notes.txt"]
    assert (out / "notes.txt").read_text() == "mine\n"
    capsys.readouterr()
    # the page may not take the name of a file of the run, nor of the summary
    for name in ("eigs.npz", "summary.json"):
        before = (out / name).read_bytes()
        assert main(["view", str(out), "--output", str(out / name), "--quiet"]) == 1
        assert name in _one_error_line(capsys.readouterr().err) and (out / name).read_bytes() == before
    _consistent(out)


# ----------------------------------------------------------------------------- 3. view reads summary.json


def test_view_refuses_a_data_file_changed_since_the_run(sphere: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "d"
    assert main(["eigs", str(sphere), "-k", "3", "--no-png", "--quiet", "--out", str(out)]) == 0
    z = dict(np.load(out / "eigs.npz"))
    z["eigenvectors"] = -z["eigenvectors"]  # still a valid npz of the right shapes
    np.savez_compressed(out / "eigs.npz", **z)
    capsys.readouterr()
    assert main(["view", str(out)]) == 1
    line = _one_error_line(capsys.readouterr().err)
    assert "eigs.npz does not match summary.json" in line and "SHA-256" in line and "rerun 'stiefel eigs" in line
    assert not (out / "view.html").exists()
    assert main(["view", str(out), "--output", str(tmp_path / "elsewhere.html")]) == 1  # wherever the page goes
    assert not (tmp_path / "elsewhere.html").exists()


def test_view_shows_the_status_of_a_run(sphere: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    from stiefel_cmm.cli.viewer import run_status

    out = tmp_path / "m"
    assert main(["modes", str(sphere), "-k", "2", *QUICK, "--html", "--out", str(out)]) == 0
    status = _summary(out)["diagnostics"]["status"]
    assert f"run status: {status}" in (out / "modes.html").read_text()  # the run's own page says it too
    capsys.readouterr()
    assert main(["view", str(out)]) == 0
    captured = capsys.readouterr()
    assert f"run status: {run_status(_summary(out))[0]}" in captured.out
    assert f"run status: {status}" in (out / "view.html").read_text()
    assert ("warning" in captured.err) == (status != "converged")
    # the status as summary.json records it, for each kind of run
    assert run_status({"command": "eigs", "files": {}}) == ("complete", True)
    assert run_status(None) is None
    text, ok = run_status({"command": "modes", "diagnostics": {"status": "interrupted", "iterations": 40},
                           "interrupted": {"signal": "SIGTERM"}})
    assert not ok and text.startswith("INTERRUPTED by SIGTERM after 40 iterations")
    text, ok = run_status({"command": "modes", "diagnostics": {"status": "max_iters", "iterations": 9}})
    assert not ok and text == "NOT CONVERGED: solver status max_iters after 9 iterations"
    text, ok = run_status({"command": "modes", "diagnostics": {"status": "converged", "iterations": 9},
                           "best_effort": {"reason": "target sparsity 0.99 not reached"}})
    assert not ok and "BEST EFFORT: target sparsity 0.99 not reached" in text
    assert run_status({"command": "modes", "diagnostics": {"status": "converged", "iterations": 9}}) == (
        "converged in 9 iterations", True)


# ----------------------------------------------------------------------------- 4. an unreachable target


def test_unreachable_target_sparsity_is_a_labelled_best_effort(sphere: Path, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "t"
    assert main(["modes", str(sphere), "-k", "2", *QUICK, "--target-sparsity", "0.999999", "--out", str(out)]) == 3
    line = _one_error_line(capsys.readouterr().err)
    assert "target sparsity 0.999999 not reached" in line and "1 − 1/n = 0.993827" in line and "best effort" in line
    summary = _consistent(out)  # the outputs are written, and say what they are
    assert summary["parameters"]["mu"]["reached"] is False
    best = summary["best_effort"]
    assert best["exit_code"] == 3 and best["sparsity"] == summary["diagnostics"]["sparsity"]["1e-3"]
    assert best["sparsity_range"][1] < 0.999999 and best["solves"] == len(summary["parameters"]["mu"]["trials"])


def test_best_effort_rule() -> None:
    """Reached: the solves bracket the target and the answer is within the tolerance; a search that only
    widened μ (never bracketing) is not, however close its last sparsity."""
    from types import SimpleNamespace

    from stiefel_cmm.cli.commands import _best_effort

    def res(s: float) -> SimpleNamespace:
        return SimpleNamespace(sparsity={"1e-3": s})

    assert _best_effort(0.5, res(0.51), 3.0, [(1.0, 0.1, 0), (9.0, 0.9, 0), (3.0, 0.51, 0)], 100) is None
    assert _best_effort(0.5, res(0.45), 3.0, [(1.0, 0.1, 0), (9.0, 0.9, 0), (3.0, 0.45, 0)], 100)["sparsity"] == 0.45
    near = _best_effort(0.995, res(0.99), 9e9, [(1.0, 0.1, 0), (9e9, 0.99, 0)], 1000)  # within 0.02, never above
    assert near is not None and "all 2 solves stayed below it" in near["reason"] and "1 − 1/n" not in near["reason"]
    low = _best_effort(0.001, res(0.01), 1e-9, [(1.0, 0.2, 0), (1e-9, 0.01, 0)], 100)
    assert low is not None and "stayed above it" in low["reason"]


# ----------------------------------------------------------------------------- 5. SIGTERM as SIGINT


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_soft_stop_once_armed_and_a_second_signal_aborts(sig: int) -> None:
    """While a solve runs (``_Signals.soft_stop``), SIGTERM and SIGINT alike: before the first progress report a
    signal raises (and sets the event), once armed the first one only sets the event — the solver's ``stop`` —
    and a second one raises; the handlers are restored after."""
    from stiefel_cmm.cli.main import _Signals

    signals = _Signals()
    with signals.installed():
        signals.check()  # the imports are done
        with signals.soft_stop() as stop:
            with pytest.raises(KeyboardInterrupt):
                signal.raise_signal(sig)
                _spin()
            assert stop.event.is_set()
        with signals.soft_stop() as stop:
            stop.arm()
            signal.raise_signal(sig)
            _spin()  # not raised
            assert stop.event.is_set() and signals.received == [sig]
            with pytest.raises(KeyboardInterrupt):
                signal.raise_signal(sig)
                _spin()
        signals.received.clear()
        with pytest.raises(KeyboardInterrupt):  # outside the solve: raised at once
            signal.raise_signal(sig)
            _spin()
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def _spin(seconds: float = 0.05) -> None:
    """Run Python bytecode (where pending signal handlers run) for ``seconds``."""
    import time

    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pass


@pytest.mark.slow  # compiles the block solver (~15 s on 2 busy cores)
@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_outside_the_solver_loop_still_writes_the_modes_reached(
        sig: int, code: int, sphere: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture) -> None:
    """The signal lands while the driver builds a progress report, outside the ``try`` that turns a
    ``KeyboardInterrupt`` into an interrupted solve (as one landing in a compilation between continuation
    rounds does): the solve stops at its next check and its modes are written, for SIGTERM as for SIGINT."""
    from stiefel.solvers import driver

    reports: list[int] = []

    class Signalling(driver.Progress):
        def __new__(cls, *args, **kwargs):
            info = super().__new__(cls, *args, **kwargs)
            reports.append(info.iteration)
            if len(reports) == 3:
                signal.raise_signal(sig)
            return info

    monkeypatch.setattr(driver, "Progress", Signalling)
    out = tmp_path / "sig"
    assert main(["modes", str(sphere), "-k", "3", "--mu", "0.01n", "--gtol", "1e-14", "--max-iters", "100000",
                 "--no-png", "--quiet", "--out", str(out)]) == code
    err = capsys.readouterr().err
    word = "terminated" if sig == signal.SIGTERM else "interrupted"
    assert _lines(err) == [f"stiefel: {word} during the solve; the modes reached were written (status interrupted)"]
    summary = _consistent(out)
    name = "SIGTERM" if sig == signal.SIGTERM else "SIGINT"
    assert summary["diagnostics"]["status"] == "interrupted" and summary["interrupted"]["signal"] == name
    assert 0 < summary["diagnostics"]["iterations"] < 100000 and np.load(out / "modes.npz")["modes"].shape[1] == 3
    # and the viewer says so
    assert main(["view", str(out), "--quiet"]) == 0
    assert f"INTERRUPTED by {name}" in capsys.readouterr().err
    assert f"run status: INTERRUPTED by {name}" in (out / "view.html").read_text()


def test_a_signal_ends_the_target_sparsity_search(sphere: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture) -> None:
    """SIGTERM in the first solve of a μ search: the search stops (it used to go on to its next μ), nothing
    is written, exit 143."""
    import stiefel_cmm.cli.progress
    from objectives.cmm import modes

    solves: list[float] = []
    real = modes.compressed_modes

    def counting(lap, k, mu, **kwargs):
        solves.append(mu)
        return real(lap, k, mu, **kwargs)

    class Terminating(stiefel_cmm.cli.progress.SolveProgress):
        def __call__(self, info):
            super().__call__(info)
            if len(solves) == 1:
                signal.raise_signal(signal.SIGTERM)

    monkeypatch.setattr(modes, "compressed_modes", counting)
    monkeypatch.setattr("stiefel_cmm.cli.commands.SolveProgress", Terminating)
    out = tmp_path / "t"
    assert main(["modes", str(sphere), "-k", "2", "--method", "admm", "--max-iters", "50", "--no-png", "--quiet",
                 "--target-sparsity", "0.5", "--out", str(out)]) == 143
    assert _lines(capsys.readouterr().err) == ["stiefel: terminated"]
    assert len(solves) <= 2 and not (out / "summary.json").exists()


# ----------------------------------------------------------------------------- 6. messages that name the problem


@pytest.mark.parametrize("array, what", [
    (np.ones((162, 3), dtype=bool), "booleans (dtype bool"),
    (np.full((162, 3), "0.5"), "strings (dtype <U3"),
    (np.ones((162, 3), dtype=complex), "complex numbers (dtype complex128"),
])
def test_start_of_the_wrong_dtype_is_named(array: np.ndarray, what: str, sphere: Path, tmp_path: Path,
                                           capsys: pytest.CaptureFixture) -> None:
    start = tmp_path / "start.npy"
    np.save(start, array)
    with warnings.catch_warnings():
        warnings.simplefilter("error", np.exceptions.ComplexWarning)  # no silent cast of a complex start
        assert main(["modes", str(sphere), "-k", "3", *QUICK, "--start", str(start), "--out", str(tmp_path / "o")]) == 1
    line = _one_error_line(capsys.readouterr().err)
    assert what in line and "shape (162, 3)" in line and "not real numbers" in line
    assert "expected (n, k')" not in line  # the shape is right: the message is about the dtype
    assert not (tmp_path / "o" / "summary.json").exists()


@pytest.mark.parametrize("mu, expected", [
    ("-1λ", "μ must be ≥ 0"), ("-0.5n", "μ must be ≥ 0"), ("-2", "μ must be ≥ 0"), ("-1e-3", "μ must be ≥ 0"),
    ("2x", "unknown unit 'x' after 2"), ("-.5λ", "μ must be ≥ 0"),
])
def test_mu_messages_name_the_form(mu: str, expected: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["modes", "--mu", mu, "--out", str(tmp_path / "o")]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert "argument --mu" in line and expected in line and "expected one argument" not in line
    assert not (tmp_path / "o").exists()


def test_negative_values_reach_their_parsers(capsys: pytest.CaptureFixture) -> None:
    assert main(["modes", "--gtol", "-1e-3"]) == 2
    assert "argument --gtol: expected a positive number, got '-1e-3'" in _one_error_line(capsys.readouterr().err)
    assert main(["modes", "--mu", "--quiet"]) == 2  # a missing value is still one
    assert "expected one argument" in _one_error_line(capsys.readouterr().err)
