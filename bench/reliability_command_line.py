"""The fault catalogue's command-line cases: out-of-range, mistyped and non-finite options of the
``stiefel`` command, an iteration cap that must hold, and interrupts (Ctrl-C during the imports, SIGTERM
during the solve) that must end without a traceback.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from bench.reliability_harness import ROOT, Case, error_line, judge_error, run_cli

def _usage(args: list[str], pattern: str, rc: int = 2):
    def run(tmp: Path) -> tuple[bool, str]:
        return judge_error(run_cli(args + ["--out", str(tmp / "u")], tmp), rc, pattern)
    return run


def _admm_cap(tmp: Path) -> tuple[bool, str]:
    out = tmp / "admmcap"
    p = run_cli(["modes", "--method", "admm", "--max-iters", "40", "-k", "3", "--no-png", "--quiet", "--json",
                 "--out", str(out)], tmp)
    if p.returncode != 0:
        return False, f"exit {p.returncode}: {error_line(p)}"
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
