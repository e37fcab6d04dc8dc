"""The fault catalogue's harness: a case, the ``stiefel`` command run in a child process, and the judges of
what a user sees (the exit code, a traceback, the one error line, the output directory's consistency).

The cases themselves are in ``bench.reliability_outputs``, ``bench.reliability_meshes``,
``bench.reliability_command_line`` and ``bench.reliability_api``; ``bench.reliability`` runs them and
writes the page.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import subprocess
import sys
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


def run_cli(args: list[str], cwd: Path, *, prelude: str = "", timeout: float = 300) -> subprocess.CompletedProcess:
    """``stiefel ARGS`` in a child process; ``prelude`` is Python run before ``stiefel_cmm.cli.main`` (fault injection)."""
    code = f"{prelude}\nimport sys\nfrom stiefel_cmm.cli.main import _entry\nsys.argv = ['stiefel'] + {args!r}\n_entry()\n"
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-c", code], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)


def error_line(p: subprocess.CompletedProcess) -> str:
    lines = [ln for ln in p.stderr.splitlines() if ln.strip()]
    return lines[-1] if lines else ""


def judge_error(p: subprocess.CompletedProcess, rc: int, pattern: str) -> tuple[bool, str]:
    """An error run: exit ``rc``, no traceback, last stderr line matches ``pattern``."""
    line = error_line(p)
    tb = "Traceback" in p.stderr
    ok = p.returncode == rc and not tb and re.search(pattern, line, re.I) is not None
    got = f"exit {p.returncode}{', TRACEBACK' if tb else ''}: {line[:200]}"
    return ok, got


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def snapshot(out: Path) -> dict[str, str]:
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


def consistent(out: Path) -> tuple[bool, str]:
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


def baseline(tmp: Path, name: str, extra: list[str] | None = None) -> tuple[Path, dict[str, str]]:
    out = tmp / name
    p = run_cli(["modes", "--out", str(out), "-k", "3", "--max-iters", "60", "--quiet"] + (extra or []), tmp)
    if p.returncode != 0:
        raise RuntimeError(f"baseline run failed: {error_line(p)}")
    return out, snapshot(out)

