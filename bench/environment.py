"""Where a benchmark's results go, the header every results page starts with, and how they are written.

Results are documents: ``docs/benchmarks/<name>.md`` (the page) and ``docs/benchmarks/<name>.json`` (the raw
rows), named after the benchmark (``python -m bench <name>``). A page may end with hand-written notes below a
``<!-- notes -->`` line; a rerun replaces what is above that line and keeps the notes. Every file is written to
a temporary file in the target directory and renamed over the old one only when complete, so an interrupted
or failed run never leaves a half-written or partial page in place of the committed one.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the results directory (tests point it elsewhere)
RESULTS = ROOT / "docs" / "benchmarks"
#: hand-written notes of a page follow this line; a rerun keeps them
NOTES = "<!-- notes -->"


def results_path(name: str, suffix: str = ".md") -> Path:
    """``docs/benchmarks/<name><suffix>``, looked up when called (so that ``RESULTS`` can be redirected)."""
    return RESULTS / f"{name}{suffix}"


def git_commit() -> str:
    """The checkout's commit (short hash, ``+`` when the working tree has changes), or ``"unknown"``."""
    def git(*args):
        return subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=30).stdout.strip()

    try:
        head = git("rev-parse", "--short", "HEAD")
        return (head + ("+" if git("status", "--porcelain", "--untracked-files=no") else "")) or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def run_meta(command: str, argv: list[str] | None, **fields) -> dict:
    """Date (UTC), machine, commit, jax/scipy/numpy versions and the command line ``python -m <command> ARGS``,
    plus ``fields``."""
    import jax  # noqa: PLC0415 — imported when a benchmark runs, not by ``python -m bench --help``
    import numpy as np  # noqa: PLC0415
    import scipy  # noqa: PLC0415

    args = argv if argv is not None else sys.argv[1:]
    return {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores ({platform.processor() or 'cpu'})",
            "commit": git_commit(), "jax": jax.__version__, "scipy": scipy.__version__, "numpy": np.__version__, **fields,
            "command": f"python -m {command} " + " ".join(args)}


def header_lines(meta: dict) -> list[str]:
    """A results page's first bullet lines: date and machine, commit and versions, the command."""
    return [f"* date: {meta['date']}; machine: {meta['machine']} (shared with other jobs: seconds are noisy)",
            f"* commit: {meta.get('commit', 'unknown')}; jax {meta['jax']}, scipy {meta['scipy']}, numpy {meta['numpy']}",
            f"* command: `{meta['command']}`"]


def write_atomic(path: Path, data: str | bytes) -> None:
    """``data`` to ``path`` through a temporary file in the same directory and a rename: the old file stays
    in place until the new one is complete."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data.encode() if isinstance(data, str) else data)
        os.chmod(tmp, 0o644)  # mkstemp's 0600 would hide the page from other readers
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def with_notes(page: str, path: Path) -> str:
    """``page`` followed by the hand-written notes below the ``<!-- notes -->`` line of the existing ``path``."""
    path = Path(path)
    if path.is_file():
        old = path.read_text()
        if NOTES in old:
            return page.rstrip("\n") + "\n\n" + old[old.index(NOTES):]
    return page


def write_page(path: Path, page: str) -> None:
    """The generated ``page`` to ``path`` (atomically), keeping the notes of the page it replaces."""
    write_atomic(path, with_notes(page, path))


def write_json(path: Path, data, indent: int | None = 1) -> None:
    """``data`` as JSON to ``path`` (atomically); ``indent=None`` for large files."""
    write_atomic(path, json.dumps(data, indent=indent, default=float) + "\n")


def write_results(json_path: Path, md_path: Path, meta: dict, rows: list[dict], report: str) -> None:
    """A benchmark's results: ``{"meta", "rows"}`` as JSON and the markdown ``report`` (notes kept), each
    written atomically, JSON first (a page never describes rows that are not on disk)."""
    write_json(json_path, {"meta": meta, "rows": rows})
    write_page(md_path, report)
    print(f"wrote {md_path} and {json_path}", file=sys.stderr)
