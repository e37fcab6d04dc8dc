"""Reading a run directory for ``stiefel view``: its ``summary.json``, the data file it lists (checked against the
recorded SHA-256) and the run's status (``run_status``: converged, not converged, interrupted, a best effort);
``ViewerError`` and the field checks shared with ``stiefel_cmm.cli.viewer``. numpy is imported inside the functions.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any, Mapping, Sequence

__all__ = ["ViewerError", "load_run", "run_status"]

#: the run files ``stiefel view`` reads, first found wins: (file, fields array, values array, field label, value label)
_SOURCES = (("modes.npz", "modes", "compressed_eigenvalues", "mode", "λ̃"),
            ("eigs.npz", "eigenvectors", "eigenvalues", "eigenfunction", "λ"))
#: the run's summary (``stiefel_cmm.cli.run_dir.SUMMARY``)
_SUMMARY = "summary.json"



class ViewerError(Exception):
    """Bad input to the viewer (missing run files, inconsistent arrays); one line naming the fix."""


# ---------------------------------------------------------------------------- checks and decimation


def _check(vertices: Any, faces: Any, fields: Any, *, where: str, fix: str,
           names: Sequence[str] = ("vertices", "faces", "fields")) -> tuple[Any, Any, Any]:
    """``(vertices (n, 3) float64, faces (m, 3) int64, fields (n, k) float64)`` or ``ViewerError``.

    ``where`` starts each message (e.g. the file), ``fix`` ends it; ``names`` name the three arrays."""
    import numpy as np

    def fail(problem: str) -> ViewerError:
        return ViewerError(f"{where}{problem}: {fix}")

    nv, nf, nfield = names
    try:
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces)
        u = np.asarray(fields, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise fail(f"arrays are not numeric ({e})") from None
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] < 3:
        raise fail(f"{nv!r} has shape {v.shape}, expected (n, 3) with n >= 3")
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] < 1 or not np.issubdtype(f.dtype, np.integer):
        raise fail(f"{nf!r} has shape {f.shape} and dtype {f.dtype}, expected integer (m, 3) with m >= 1")
    u = u.reshape(-1, 1) if u.ndim == 1 else u
    if u.ndim != 2 or u.shape[0] != v.shape[0] or u.shape[1] < 1:
        raise fail(f"{nfield!r} has shape {u.shape}, expected (n, k) with n = {v.shape[0]} rows (one per vertex)")
    f = f.astype(np.int64)
    if f.min() < 0 or f.max() >= v.shape[0]:
        bad = int(f.min()) if f.min() < 0 else int(f.max())
        raise fail(f"{nf!r} index {bad} is out of range for {v.shape[0]} vertices")
    for name, a in ((nv, v), (nfield, u)):
        if not np.all(np.isfinite(a)):
            raise fail(f"{name!r} has {int(np.size(a) - np.isfinite(a).sum())} non-finite values")
    return v, f, u


def run_status(summary: Mapping | None) -> tuple[str, bool] | None:
    """``(text, ok)``: what a run's ``summary.json`` says of its result; None without a summary.

    ``ok`` is False for a result that is not a converged one: an interrupted solve (the modes reached),
    a solver status other than ``converged`` (``max_iters``, ``line_search_failed``, …) or a best effort
    (an unreachable ``--target-sparsity``). ``stiefel eigs`` writes only complete results."""
    if summary is None:
        return None
    if summary.get("command") != "modes":
        return "complete", True
    diag = summary.get("diagnostics") if isinstance(summary.get("diagnostics"), Mapping) else {}
    status, iterations = diag.get("status"), diag.get("iterations")
    after = f" after {iterations} iterations" if iterations is not None else ""
    interrupt = summary.get("interrupted") if isinstance(summary.get("interrupted"), Mapping) else None
    signal_name = interrupt.get("signal") if interrupt is not None else None
    if status == "interrupted":
        text, ok = (f"INTERRUPTED{' by ' + signal_name if signal_name else ''}{after}: the modes reached, "
                    "not a converged result"), False
    elif status == "converged":
        text, ok = f"converged{after.replace('after', 'in')}", True
        if signal_name:
            text += f" ({signal_name} came as the solve ended: the result is complete)"
    elif status is None:
        text, ok = "NOT RECORDED: summary.json has no solver status", False
    else:
        text, ok = f"NOT CONVERGED: solver status {status}{after}", False
    best = summary.get("best_effort")
    if best:
        reason = best.get("reason") if isinstance(best, Mapping) else str(best)
        text, ok = f"{text}; BEST EFFORT: {reason}", False
    return text, ok


def _run_directory(outdir: str | os.PathLike) -> Path:
    """``outdir`` as a Path, or ``ViewerError`` if it is missing or not a directory."""
    out = Path(outdir)
    hint = "give the --out directory of 'stiefel modes' or 'stiefel eigs'"
    if not out.exists():
        raise ViewerError(f"run directory not found: {out}: {hint}")
    if not out.is_dir():
        raise ViewerError(f"not a directory: {out}: {hint}")
    return out


def _read_summary(out: Path) -> dict | None:
    """``out/summary.json`` as a dict, None when there is none; ``ViewerError`` for one that is not a summary."""
    path = out / _SUMMARY
    if not path.exists():
        return None
    fix = "rerun the command into that --out, or move the file away"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as e:
        reason = (e.strerror or str(e)) if isinstance(e, OSError) else "not valid JSON"
        raise ViewerError(f"{path} cannot be read ({reason}): {fix}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("command"), str) or not isinstance(doc.get("files"), dict):
        raise ViewerError(f"{path} is not a stiefel summary (no 'command' or 'files'): {fix}")
    return doc


def _listed_source(out: Path, summary: Mapping) -> tuple[tuple, dict]:
    """The ``_SOURCES`` entry and the ``files`` record of the data file ``summary.json`` lists."""
    command = summary["command"]
    hint = "give the --out directory of 'stiefel modes' or 'stiefel eigs'"
    if command not in ("modes", "eigs"):
        raise ViewerError(f"{out} holds the outputs of 'stiefel {command}' ({_SUMMARY}): nothing to view; {hint}")
    rec = summary["files"].get("npz")
    source = next((s for s in _SOURCES if isinstance(rec, Mapping) and rec.get("name") == s[0]), None)
    if source is None or not isinstance(rec.get("sha256"), str):
        raise ViewerError(f"{out / _SUMMARY} lists no {command}.npz with its SHA-256: rerun 'stiefel {command} "
                          f"--out {out}'")
    if not (out / source[0]).is_file():
        raise ViewerError(f"{out / source[0]} is listed in {_SUMMARY} but missing: rerun 'stiefel {command} "
                          f"--out {out}'")
    return source, dict(rec)


def load_run(outdir: str | os.PathLike) -> dict:
    """Read a run directory of ``stiefel modes`` (``modes.npz``, preferred) or ``stiefel eigs`` (``eigs.npz``).

    With ``summary.json`` present the data file is the one it lists, and its SHA-256 must be the recorded one
    (a file changed since the run wrote it is refused); without, the first of ``modes.npz``, ``eigs.npz``.
    Returns ``{"source": Path, "vertices" (n, 3), "faces" (m, 3), "fields" (n, k), "names": [k],
    "subtitles": [k], "summary": dict or None, "status": run_status(summary)}``; raises ``ViewerError``
    naming the problem and the fix."""
    import io
    import zipfile

    import numpy as np

    out = _run_directory(outdir)
    summary = _read_summary(out)
    record = None
    if summary is not None:
        (fname, key, values_key, label, symbol), record = _listed_source(out, summary)
    else:
        found = [s for s in _SOURCES if (out / s[0]).is_file()]
        if not found:
            raise ViewerError(f"no modes.npz or eigs.npz in {out}: run 'stiefel modes --out {out}' "
                              f"or 'stiefel eigs --out {out}' first")
        fname, key, values_key, label, symbol = found[0]
    path, fix = out / fname, f"rerun 'stiefel {fname.split('.')[0]} --out {out}'"
    try:
        data = path.read_bytes()  # read once: the bytes checked are the bytes shown
    except OSError as e:
        raise ViewerError(f"{path} cannot be read ({e.strerror or e}): {fix}") from None
    if record is not None:
        digest = hashlib.sha256(data).hexdigest()
        if digest != record["sha256"]:
            raise ViewerError(f"{path} does not match {_SUMMARY}: its SHA-256 is {digest[:16]}…, the run recorded "
                              f"{record['sha256'][:16]}… ({len(data)} bytes, recorded {record.get('bytes')}): the file "
                              f"changed after the run wrote it; {fix} (or restore the file)")
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            missing = [a for a in ("vertices", "faces", key) if a not in npz.files]
            if missing:
                raise ViewerError(f"{path} lacks the array(s) {', '.join(map(repr, missing))}: {fix}")
            arrays = {a: npz[a] for a in ("vertices", "faces", key)}
            values = npz[values_key] if values_key in npz.files else None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise ViewerError(f"{path} is not a readable npz file ({type(e).__name__}: {e}): {fix}") from None
    v, f, u = _check(arrays["vertices"], arrays["faces"], arrays[key], where=f"{path}: ", fix=fix,
                     names=("vertices", "faces", key))
    k = u.shape[1]
    subtitles = [""] * k
    if values is not None:
        values = np.asarray(values).reshape(-1)
        if values.shape != (k,) or not np.issubdtype(values.dtype, np.number):
            raise ViewerError(f"{path}: {values_key!r} has shape {values.shape}, expected ({k},): {fix}")
        subtitles = [f"{symbol} = {float(x):.6g}" for x in values]
    return {"source": path, "vertices": v, "faces": f, "fields": u, "names": [f"{label} {j}" for j in range(k)],
            "subtitles": subtitles, "summary": summary, "status": run_status(summary)}
