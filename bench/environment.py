"""The machine-and-versions header shared by the benchmark scripts' results files."""

from __future__ import annotations

import os
import platform
import sys
import json
import time
from pathlib import Path

import jax
import numpy as np
import scipy


def run_meta(module: str, argv: list[str] | None, **fields) -> dict:
    """Date (UTC), machine, jax/scipy/numpy versions and the command line of ``python -m <module>``, plus ``fields``."""
    args = argv if argv is not None else sys.argv[1:]
    return {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores ({platform.processor() or 'cpu'})",
            "jax": jax.__version__, "scipy": scipy.__version__, "numpy": np.__version__, **fields,
            "command": f"python -m {module} " + " ".join(args)}


def header_lines(meta: dict) -> list[str]:
    """The results files' first bullet lines: date and machine, versions, the command."""
    return [f"* date: {meta['date']}; machine: {meta['machine']} (shared with other jobs: seconds are noisy)",
            f"* jax {meta['jax']}, scipy {meta['scipy']}, numpy {meta['numpy']}",
            f"* command: `{meta['command']}`"]


def write_atomic(path: Path, text: str) -> None:
    """``text`` to ``path`` atomically (a temporary file beside it, then a rename): an interrupted run
    never leaves a half-written results file."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def write_results(json_path: Path, md_path: Path, meta: dict, rows: list[dict], report: str) -> None:
    """A benchmark's results: ``{"meta", "rows"}`` as JSON and the markdown ``report``, each written atomically
    (JSON first, so a report never describes rows that are not on disk)."""
    write_atomic(json_path, json.dumps({"meta": meta, "rows": rows}, indent=1) + "\n")
    write_atomic(md_path, report)
    print(f"wrote {md_path} and {json_path}", file=sys.stderr)
