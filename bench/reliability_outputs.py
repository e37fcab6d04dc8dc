"""The fault catalogue's output cases: what a second run, a signal during the write phase, a full disk, a
concurrent run or a wrong ``--out`` leaves in the output directory.

The disk-full case mounts a 1 MiB tmpfs when the process may (root on Linux); otherwise it fails
``os.fsync`` with ``ENOSPC`` in the child instead, and says so in the table.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

from bench.reliability_harness import FAST, ROOT, Case, baseline, consistent, judge_error, run_cli, snapshot

_KILL_AT_FSYNC = ("import os, signal\n"
                  "def _f(fd, _s=signal.{sig}):\n    os.kill(os.getpid(), _s)\n"
                  "os.fsync = _f\n")


def _interrupt_during_write(sig: str) -> Callable[[Path], tuple[bool, str]]:
    def run(tmp: Path) -> tuple[bool, str]:
        out, before = baseline(tmp, f"kill_{sig}")
        p = run_cli(["modes", "--out", str(out), "-k", "4", "--max-iters", "60", "--quiet"], tmp,
                    prelude=_KILL_AT_FSYNC.format(sig=sig))
        after = snapshot(out)
        intact = before == {k: v for k, v in after.items() if k in before} and set(after) <= set(before) | {
            ".stiefel.lock"}
        tb = "Traceback" in p.stderr
        note = ""
        if sig == "SIGKILL":  # nothing runs after SIGKILL: its staging directory stays until the next run
            left = [q.name for q in out.iterdir() if "staging" in q.name]
            again = run_cli(["modes", "--out", str(out), "-k", "3", "--max-iters", "60", "--quiet"], tmp)
            gone = not [q.name for q in out.iterdir() if "staging" in q.name]
            note = (f"; staging left by the kill: {len(left)}, removed by the next run (exit {again.returncode}): "
                    f"{'yes' if gone else 'NO'}")
            intact = intact and gone and again.returncode == 0
        ok_c, why = consistent(out)
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
            first = run_cli(["eigs", "--out", str(out), "-k", "3", "--quiet", "--no-png"], tmp)  # ~300 KB: fits
            before = snapshot(out)
            st = os.statvfs(mnt)  # leave 16 KiB: the second run's eigs.npz cannot fit
            (mnt / "filler").write_bytes(b"\0" * max(0, st.f_bavail * st.f_frsize - 16384))
            p = run_cli(["eigs", "--out", str(out), "-k", "6", "--seed", "1", "--quiet", "--no-png"], tmp)
            how = "1 MiB tmpfs"
        else:
            out, before = baseline(tmp, "diskfull")
            first = None
            prelude = ("import os, errno\ndef _f(fd):\n    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))\n"
                       "os.fsync = _f\n")
            p = run_cli(["modes", "--out", str(out), "-k", "4", "--max-iters", "60", "--quiet"], tmp, prelude=prelude)
            how = "fsync fails with ENOSPC"
        after = snapshot(out)
        ok, got = judge_error(p, 1, r"no space|disk")
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
        b = run_cli(["modes", "--out", str(out)] + FAST, tmp)
        a.wait(timeout=300)
    finally:
        a.kill()
    ok_b, got_b = judge_error(b, 1, r"lock|another|in use|concurrent")
    ok_c, why = consistent(out)
    return ok_b and a.returncode == 0 and ok_c, f"second run: {got_b}; first run exit {a.returncode}; {why}"


def _no_png_after_png(tmp: Path) -> tuple[bool, str]:
    out, _ = baseline(tmp, "nopng")
    had = (out / "modes.png").is_file()
    p = run_cli(["modes", "--out", str(out)] + FAST, tmp)
    ok_c, why = consistent(out)
    gone = not (out / "modes.png").exists()
    return had and gone and ok_c and p.returncode == 0, (f"exit {p.returncode}; modes.png "
                                                         f"{'removed' if gone else 'STILL THERE'}; {why}")


def _eigs_into_modes(tmp: Path) -> tuple[bool, str]:
    out, before = baseline(tmp, "eigsmodes", ["--no-png"])
    p = run_cli(["eigs", "--out", str(out), "-k", "3", "--quiet"], tmp)
    ok, got = judge_error(p, 1, r"modes")
    return ok and snapshot(out) == before, got + ("; modes outputs intact" if snapshot(out) == before else
                                                  "; modes outputs CHANGED")


def _out_is_file(command: str) -> Callable[[Path], tuple[bool, str]]:
    def run(tmp: Path) -> tuple[bool, str]:
        f = tmp / f"afile_{command}"
        f.write_text("not a directory\n")
        t = time.perf_counter()
        args = [command, "--out", str(f), "-k", "3", "--quiet"] + (["--smoothings", "f1,f6", "--max-iters", "60"]
                                                                  if command == "compare-smoothings" else [])
        p = run_cli(args, tmp)
        dt = time.perf_counter() - t
        ok, got = judge_error(p, 1, r"out|director|file")
        return ok and f.read_text() == "not a directory\n", f"{got} ({dt:.1f} s: before any solve)"
    return run


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
