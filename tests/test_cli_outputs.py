"""The CLI's outputs are all-or-nothing and its options reach the solvers.

Runs use the built-in demo mesh with ``--method admm --max-iters 3`` (host numpy, no JAX
compilation: a fraction of a second) and ``--no-png`` unless the picture is the point. Faults
are injected where they happen: ``stiefel_cmm.cli.run_dir._write_all`` (every staged byte goes through it)
for a full disk and for signals mid-write, in a child process where the signal is SIGKILL.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import stiefel_cmm.cli.run_dir as run_dir
from stiefel_cmm.cli.main import _Signals, build_parser, main
from stiefel_cmm.cli.run_dir import LOCK, STAGING_PREFIX

REPO = Path(__file__).resolve().parents[1]
QUICK = ["--method", "admm", "--max-iters", "3", "--no-png", "--quiet"]


def _modes(out: Path, *extra: str, k: int = 2) -> int:
    return main(["modes", "-k", str(k), *QUICK, *extra, "--out", str(out)])


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _snapshot(out: Path) -> dict[str, str]:
    """SHA-256 of every regular file in ``out`` but the (empty) lock file."""
    return {p.name: _sha(p) for p in sorted(out.iterdir()) if p.is_file() and p.name != LOCK}


def _one_error_line(err: str, start: str = "stiefel: error: ") -> str:
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(start) and "Traceback" not in err, err
    return lines[0]


def _consistent(out: Path, foreign: frozenset[str] = frozenset()) -> dict:
    """``summary.json`` lists exactly the files present (but the lock and ``foreign``), with right hashes."""
    summary = json.loads((out / "summary.json").read_text())
    listed = {rec["name"]: rec for rec in summary["files"].values()}
    present = {p.name for p in out.iterdir()} - {"summary.json", LOCK} - set(foreign)
    assert set(listed) == present, (sorted(listed), sorted(present))
    for name, rec in listed.items():
        data = (out / name).read_bytes()
        assert rec["bytes"] == len(data) and rec["sha256"] == hashlib.sha256(data).hexdigest(), name
    return summary


@pytest.fixture
def previous(tmp_path: Path) -> tuple[Path, dict[str, str]]:
    """A finished ``modes -k 2`` run and the hashes of its files."""
    out = tmp_path / "out"
    assert _modes(out) == 0
    _consistent(out)
    return out, _snapshot(out)


# ----------------------------------------------------------------------------- the summary and stale files


def test_no_png_after_png_removes_the_picture(tmp_path: Path) -> None:
    out = tmp_path / "out"
    assert main(["modes", "-k", "2", *QUICK[:-2], "--quiet", "--out", str(out)]) == 0  # with the PNG
    summary = _consistent(out)
    assert set(summary["files"]) == {"npz", "ply", "png"} and (out / "modes.png").is_file()
    (out / "notes.txt").write_text("mine\n")                 # not stiefel's: never touched
    (out / "modes.partial.npz").write_bytes(b"stale")        # a killed sequential run's columns
    assert _modes(out, k=3) == 0
    summary = _consistent(out, foreign=frozenset({"notes.txt"}))
    assert set(summary["files"]) == {"npz", "ply"}
    assert not (out / "modes.png").exists() and not (out / "modes.partial.npz").exists()
    assert (out / "notes.txt").read_text() == "mine\n"
    assert np.load(out / "modes.npz")["modes"].shape[1] == 3


def test_failing_picture_still_commits_the_run(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture) -> None:
    # the renderer running out of memory must not cost the solve: summary.json names what happened
    import stiefel_cmm.cli.render

    def _oom(*args, **kwargs):
        raise MemoryError("cannot allocate the canvas")

    monkeypatch.setattr(stiefel_cmm.cli.render, "contact_sheet", _oom)
    out = tmp_path / "out"
    assert main(["modes", "-k", "2", *QUICK[:-2], "--quiet", "--out", str(out)]) == 0
    summary = _consistent(out)
    assert set(summary["files"]) == {"npz", "ply"} and not (out / "modes.png").exists()
    assert "MemoryError" in summary["picture_error"]
    assert "modes.png not written" in capsys.readouterr().err


def test_summary_hashes_match_and_json_is_the_summary(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "eigs"
    assert main(["eigs", "-k", "2", "--json", "--quiet", "--out", str(out)]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed == _consistent(out) and printed["files"]["npz"]["name"] == "eigs.npz"


# ----------------------------------------------------------------------------- interrupts and write errors


_CHILD = """
import os, signal, sys
import stiefel_cmm.cli.run_dir as rd
real, seen = rd._write_all, [0]
def write_all(fd, data):
    seen[0] += memoryview(data).nbytes
    if seen[0] > {after}:  # midway through the run's second file (modes.ply)
        os.kill(os.getpid(), signal.{sig})
    return real(fd, data)
rd._write_all = write_all
from stiefel_cmm.cli.main import _entry
sys.argv = ["stiefel"] + {argv!r}
_entry()
"""


@pytest.mark.parametrize("sig", ["SIGKILL", "SIGINT", "SIGTERM"])
def test_signal_while_writing_keeps_the_previous_run(sig: str, previous: tuple[Path, dict[str, str]]) -> None:
    out, before = previous
    argv = ["modes", "-k", "3", *QUICK, "--out", str(out)]
    code = _CHILD.format(after=_into_the_ply(out), sig=sig, argv=argv)
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    expected = {"SIGKILL": -signal.SIGKILL, "SIGINT": 130, "SIGTERM": 143}[sig]
    assert proc.returncode == expected, proc.stderr
    assert _snapshot(out) == before          # byte-identical, summary.json included
    _consistent(out, foreign=frozenset(p.name for p in out.glob(STAGING_PREFIX + "*")))
    staging = list(out.glob(STAGING_PREFIX + "*"))
    if sig == "SIGKILL":                     # nothing can clean up after SIGKILL: the next run does
        assert staging and any(p.name == "modes.npz" for p in staging[0].iterdir())
        assert _modes(out, k=3) == 0
        assert not list(out.glob(STAGING_PREFIX + "*"))
        assert np.load(out / "modes.npz")["modes"].shape[1] == 3
    else:
        word = "interrupted" if sig == "SIGINT" else "terminated"
        assert proc.stderr.strip() == f"stiefel: {word}" and not staging


def _into_the_ply(out: Path) -> int:
    """A byte count past the next run's modes.npz (a little larger than the last one), inside its modes.ply."""
    return json.loads((out / "summary.json").read_text())["files"]["npz"]["bytes"] + 40_000


@pytest.mark.parametrize("name", ["modes.npz", "modes.ply"])
def test_disk_full_keeps_the_previous_run(name: str, previous: tuple[Path, dict[str, str]],
                                          monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    out, before = previous
    budget = 1_000 if name == "modes.npz" else _into_the_ply(out)
    real, written = run_dir._write_all, [0]

    def full_disk(fd: int, data) -> int:
        n = memoryview(data).nbytes
        room = budget - written[0]
        if n > room:
            real(fd, memoryview(data).cast("B")[:max(room, 0)])
            written[0] = budget
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        written[0] += n
        return real(fd, data)

    monkeypatch.setattr(run_dir, "_write_all", full_disk)
    capsys.readouterr()
    assert _modes(out, k=3) == 1
    line = _one_error_line(capsys.readouterr().err)
    assert line == f"stiefel: error: could not write {out / name}: No space left on device"
    assert _snapshot(out) == before and not list(out.glob(STAGING_PREFIX + "*"))
    _consistent(out)


def test_disk_full_on_the_summary_changes_nothing(previous: tuple[Path, dict[str, str]],
                                                  monkeypatch: pytest.MonkeyPatch,
                                                  capsys: pytest.CaptureFixture) -> None:
    out, before = previous
    real = run_dir._write_all

    def full_at_summary(fd: int, data) -> int:
        if os.readlink(f"/proc/self/fd/{fd}").endswith("summary.json"):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, data)

    monkeypatch.setattr(run_dir, "_write_all", full_at_summary)
    capsys.readouterr()
    assert _modes(out, k=3) == 1
    assert "summary.json: No space left on device" in _one_error_line(capsys.readouterr().err)
    assert _snapshot(out) == before and not list(out.glob(STAGING_PREFIX + "*"))


def test_interrupt_during_commit_is_held_back(previous: tuple[Path, dict[str, str]],
                                              monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    out, _ = previous
    real, sent = os.replace, []

    def replace(src, dst) -> None:
        if not sent:
            sent.append(True)
            os.kill(os.getpid(), signal.SIGINT)
        real(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    assert _modes(out, k=3) == 130 and sent
    assert capsys.readouterr().err.strip() == "stiefel: interrupted"
    summary = _consistent(out)                 # the new run, complete: Ctrl-C came after the commit
    assert len(summary["compressed_eigenvalues"]) == 3
    assert np.load(out / "modes.npz")["modes"].shape[1] == 3


@pytest.mark.parametrize("sig, code, word", [("SIGINT", 130, "interrupted"), ("SIGTERM", 143, "terminated")])
def test_signal_during_the_imports(sig: str, code: int, word: str, tmp_path: Path) -> None:
    child = ("import builtins, os, signal, sys\n"
             "real = builtins.__import__\n"
             "def imp(name, *a, **k):\n"
             f"    if name == 'jax': os.kill(os.getpid(), signal.{sig})\n"
             "    return real(name, *a, **k)\n"
             "builtins.__import__ = imp\n"
             "from stiefel_cmm.cli.main import _entry\n"
             f"sys.argv = ['stiefel', 'eigs', '--out', {str(tmp_path / 'o')!r}]\n"
             "_entry()\n")
    proc = subprocess.run([sys.executable, "-c", child], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert proc.returncode == code and proc.stderr.strip() == f"stiefel: {word}", proc.stderr


def test_deferred_signal_is_raised_by_check() -> None:
    signals = _Signals()
    with signals.installed():
        try:
            os.kill(os.getpid(), signal.SIGINT)  # during the imports: only remembered
            _spin()
        except KeyboardInterrupt:
            pytest.fail("the signal was raised during the imports")
        assert signals.received == [signal.SIGINT]
        with pytest.raises(KeyboardInterrupt):
            signals.check()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


_GC_SIGNAL = """
import gc, os, signal, sys, time
from stiefel_cmm.cli.main import _Signals

def spin(seconds):  # run Python bytecode, where pending signal handlers run
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pass

dropped, fired = [], []
sys.unraisablehook = dropped.append  # where an exception raised in a gc callback goes

def callback(phase, info):
    if phase == "start" and not fired:
        fired.append(1)
        os.kill(os.getpid(), signal.SIGINT)
        spin(0.05)  # the handler runs here, inside the callback

signals = _Signals()
with signals.installed():
    signals.check()  # imports done: signals interrupt
    gc.callbacks.append(callback)
    try:
        gc.collect()
        spin(2.0)  # ... and this one arrives once the callback has returned
        print("not raised", fired, len(dropped), signals.received)
    except KeyboardInterrupt:
        print("raised", fired, len(dropped), signals.received)
"""


def test_signal_inside_a_gc_callback_is_not_lost() -> None:
    # in a fresh process, as the CLI runs (one run per process): earlier in-process runs leave
    # gc callbacks and allocation counts that make the moment of the collection unpredictable
    p = subprocess.run([sys.executable, "-c", _GC_SIGNAL], cwd=REPO, capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == f"raised [1] 0 [{int(signal.SIGINT)}]", p.stdout + p.stderr


def _spin(seconds: float = 0.05) -> None:
    """Run Python bytecode (where pending signal handlers run) for ``seconds``."""
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        pass


# ----------------------------------------------------------------------------- refusals before any solve


def test_second_run_refused_by_the_lock(previous: tuple[Path, dict[str, str]], monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture) -> None:
    out, before = previous
    with open(out / LOCK, "a") as held:
        fcntl.flock(held, fcntl.LOCK_EX | fcntl.LOCK_NB)   # another run, as far as the CLI can tell
        with monkeypatch.context() as m:
            m.setattr("mesh.load", _must_not_run)
            capsys.readouterr()
            assert _modes(out, k=3) == 1
        line = _one_error_line(capsys.readouterr().err)
        assert "another stiefel run" in line and LOCK in line
    assert _snapshot(out) == before
    assert _modes(out, k=3) == 0                           # lock released: the same run goes through
    assert _snapshot(out) != before


def _must_not_run(*args, **kwargs):
    raise AssertionError("the mesh was loaded: the check must come before")


@pytest.mark.parametrize("command", ["eigs", "compare-smoothings"])
def test_other_command_refused_before_loading(command: str, previous: tuple[Path, dict[str, str]],
                                              monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    out, before = previous
    monkeypatch.setattr("mesh.load", _must_not_run)
    capsys.readouterr()
    assert main([command, "-k", "2", "--quiet", "--out", str(out)]) == 1
    line = _one_error_line(capsys.readouterr().err)
    assert "'stiefel modes'" in line and f"'stiefel {command}'" in line and "another --out" in line
    assert _snapshot(out) == before


def test_foreign_file_with_an_output_name_is_not_overwritten(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                             capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "mine"
    out.mkdir()
    (out / "eigs.npz").write_bytes(b"not stiefel's")
    monkeypatch.setattr("mesh.load", _must_not_run)
    assert main(["eigs", "-k", "2", "--quiet", "--out", str(out)]) == 1
    assert "eigs.npz was not written by" in _one_error_line(capsys.readouterr().err)
    assert (out / "eigs.npz").read_bytes() == b"not stiefel's" and not (out / "summary.json").exists()


@pytest.mark.parametrize("where", ["file", "under_file"])
def test_out_that_cannot_be_a_directory(where: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture) -> None:
    f = tmp_path / "afile"
    f.write_text("keep\n")
    out = f if where == "file" else f / "sub"
    monkeypatch.setattr("mesh.load", _must_not_run)
    assert _modes(out) == 1
    line = _one_error_line(capsys.readouterr().err)
    assert str(out) in line and ("not a directory" in line.lower())
    assert f.read_text() == "keep\n"


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores directory permissions")
def test_read_only_out(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "ro"
    out.mkdir()
    out.chmod(0o555)
    try:
        monkeypatch.setattr("mesh.load", _must_not_run)
        assert _modes(out) == 1
        assert "not writable" in _one_error_line(capsys.readouterr().err)
    finally:
        out.chmod(0o755)


# ----------------------------------------------------------------------------- options reach the solvers


@pytest.mark.parametrize("method", ["admm", "admm_sequential", "fast"])
def test_max_iters_reaches_every_method(method: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / method
    assert main(["modes", "-k", "2", "--method", method, "--max-iters", "3", "--no-png", "--quiet", "--json",
                 "--out", str(out)]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["solver_options"] == {"max_iters": 3} and summary["parameters"]["max_iters"] == 3
    assert 1 <= summary["diagnostics"]["iterations"] <= 3      # the ADMM default is 20 000


def test_gtol_is_not_silently_dropped(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["modes", "-k", "2", *QUICK, "--gtol", "1e-3", "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert err.startswith("stiefel: warning: --gtol applies to the block and sequential solvers")


@pytest.mark.parametrize("args, option", [(["--max-iters", "99999999999"], "--max-iters"),
                                          (["--max-iters", "2147483648"], "--max-iters"),
                                          (["-k", "99999999999"], "-k"), (["--samples", "1e3"], "--samples"),
                                          (["--seed", str(2**40)], "--seed"), (["--seed", "-1"], "--seed")])
def test_integer_options_are_bounded(args: list[str], option: str, tmp_path: Path,
                                     capsys: pytest.CaptureFixture) -> None:
    assert main(["modes", *args, "--out", str(tmp_path / "o")]) == 2
    line = _one_error_line(capsys.readouterr().err)
    assert f"argument {option}" in line and "expected an integer in [" in line
    assert not (tmp_path / "o").exists()


def test_largest_integers_are_accepted() -> None:
    args = build_parser().parse_args(["modes", "--max-iters", str(2**31 - 1), "--seed", str(2**32 - 1)])
    assert args.max_iters == 2**31 - 1 and args.seed == 2**32 - 1
