"""The fault catalogue: bad input, faults and loads tried as a careless or unlucky user would.

    python -m bench reliability [--out docs/RELIABILITY.md] [--only SUBSTRING]

Every case runs the real thing — the ``stiefel`` command in a child process, or one API call —
and is judged by what a user sees: the exit code, whether a traceback appears, whether the one
error line names the real cause (a regular expression per case), and for the output cases whether
the directory is consistent afterwards (``summary.json`` lists exactly the run's files, with
matching SHA-256, no staging leftovers, earlier results intact). The table (input, expected, got,
verdict) is written to ``docs/RELIABILITY.md`` with machine, date, commit and command, below the page's
``MARKER`` line (the hand-written part above it is kept).

This module runs the cases and writes the page; the cases are grouped by class of failure in
``bench.reliability_outputs`` (the output directory), ``bench.reliability_meshes`` (mesh files),
``bench.reliability_command_line`` (the command's options and interrupts) and ``bench.reliability_api``
(library calls), on the harness in ``bench.reliability_harness``.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from pathlib import Path

from bench.reliability_api import API_CASES
from bench.reliability_command_line import CLI_CASES
from bench.reliability_harness import ROOT
from bench.reliability_meshes import MESH_CASES
from bench.reliability_outputs import OUTPUT_CASES


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
MARKER = ("<!-- Everything below is written by `python -m bench reliability`; edit bench/reliability.py (the page) "
          "or bench/reliability_*.py (the cases), not this part. -->")


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
