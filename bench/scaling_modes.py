"""The default CMM solve at scale: ``stiefel modes``' defaults on midpoint-subdivided meshes.

    python -m bench scaling-modes                                  # example:bumpy, levels 1–2 (no files needed)
    python -m bench scaling-modes --base bunny.off --levels 2 3 4  # 5.6·10⁴, 2.2·10⁵, 8.9·10⁵ vertices
    python -m bench scaling-modes --base armadillo_25479.obj --levels 1 2 3 --merge   # 1.0·10⁵ … 1.6·10⁶, added

Each level runs in its own process (its peak RSS is that process's ``ru_maxrss``, the Python/JAX runtime
included): cotangent Laplacian, ``eigsh`` for the first max(k, 2) pairs (timed: the reference of the
goal "total ≤ 20× eigsh"), then ``compressed_modes(lap, k, 2λ_(k−1))`` with the CLI's defaults
(``BlockCMM()``: four smoothing stages, saddle checks, area weights, eigenbasis start). Reported: total
solve seconds (compile apart), iterations, status, t₁ (seconds until the true objective is within 1e-3,
relative, of the final one), the ratio of solve (+ compile) to eigsh, and peak RSS. A level that does not
finish within ``--timeout`` seconds is reported as such; a level whose process fails stops the run with nothing
written. Subdivided meshes are cached as in ``bench.scaling`` (``bench.subdivided_meshes``). Writes
``docs/benchmarks/scaling-modes.md`` and ``docs/benchmarks/scaling-modes.json``; with ``--merge`` the rows already
there for other (mesh, level) pairs are kept (each row names its mesh, date and command).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # like the other benches: a shared 2-core machine

ROOT = Path(__file__).resolve().parents[1]


def time_to_final(times, values, rel: float = 1e-3) -> float:
    """t₁: the first time the values are within ``rel`` (relative) of the last one."""
    import numpy as np  # noqa: PLC0415

    times, values = np.asarray(times, dtype=float), np.asarray(values, dtype=float)
    return float(times[np.nonzero(np.abs(values - values[-1]) <= rel * abs(values[-1]))[0][0]])


def worker(base: str, level: int, k: int, cache: str) -> dict:
    import jax  # noqa: PLC0415

    jax.config.update("jax_enable_x64", True)
    import mesh  # noqa: PLC0415
    from bench.subdivided_meshes import subdivided  # noqa: PLC0415
    from objectives.cmm.modes import compressed_modes, first_eigenpairs, unpack_laplacian  # noqa: PLC0415

    V, F, _ = subdivided(base, level, Path(cache))
    m = mesh.load((V, F), warn=False)
    t0 = time.perf_counter()
    lap = mesh.laplacian(m)
    t_lap = time.perf_counter() - t0
    W, a = unpack_laplacian(lap)
    t0 = time.perf_counter()
    pairs = first_eigenpairs(W, a, max(k, 2))
    t_eig = time.perf_counter() - t0
    mu = 2.0 * float(pairs[0][-1])
    r = compressed_modes(lap, k, mu, eigenpairs=pairs)
    t_near = time_to_final(r.history["time"], r.history["objective"])
    return {"level": level, "n": len(a), "k": k, "mu": mu, "laplacian_seconds": t_lap, "eigsh_seconds": t_eig,
            "seconds": r.wall_time, "compile_seconds": r.compile_time, "iterations": r.iterations,
            "status": r.status, "objective": r.objective, "t_near": t_near,
            "orthogonality": r.orthogonality,
            "ratio_to_eigsh": (r.wall_time + r.compile_time) / max(t_eig, 1e-9),
            "peak_rss_gib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20}


def report(rows: list[dict], meta: dict) -> str:
    from bench.environment import header_lines  # noqa: PLC0415

    lines = ["# The default CMM solve at scale", "", *header_lines(meta),
             f"* meshes: midpoint-subdivided (the base mesh and the date of its run in each row); k = {meta['k']}, "
             "μ = 2λ_(k−1), area weights, "
             "`BlockCMM()` defaults (the CLI's), eigenbasis start; one process per level",
             "* eigsh: the first max(k, 2) pairs (shift-invert, the start and σ); total / eigsh: (solve + compile) "
             "seconds over eigsh's; t₁: seconds until the true objective is within 1e-3 of the final one; "
             "goal: total ≤ 20× eigsh, ≤ 16 GB at 10⁶ vertices", "",
             "| mesh (level) | run | n | eigsh s | solve s | compile s | total / eigsh | t₁ s | iterations | status | "
             "objective | peak RSS GiB |", "|---|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|"]
    for r in rows:
        head = f"| {r.get('base', meta['base'])} ({r['level']}) | {r.get('date', meta['date'])} "
        if "error" in r:
            lines.append(head + f"| – | – | – | – | – | – | – | {r['error']} | – | – |")
            continue
        t1 = "–" if r["t_near"] is None else f"{r['t_near']:.1f}"
        lines.append(head + f"| {r['n']} | {r['eigsh_seconds']:.1f} | {r['seconds']:.1f} | {r['compile_seconds']:.1f} | "
                     f"{r['ratio_to_eigsh']:.1f} | {t1} | {r['iterations']} | {r['status']} | {r['objective']:.4f} | "
                     f"{r['peak_rss_gib']:.2f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from bench.subdivided_meshes import default_cache  # noqa: PLC0415

    p = argparse.ArgumentParser(prog="python -m bench scaling-modes", description=__doc__.splitlines()[0])
    p.add_argument("--base", default="example:bumpy")
    p.add_argument("--levels", type=int, nargs="+", default=[1, 2])
    p.add_argument("-k", type=int, default=10)
    p.add_argument("--timeout", type=float, default=1800.0, help="seconds per level")
    p.add_argument("--cache", default=str(default_cache()))
    p.add_argument("--out-json", type=Path, default=None, help="default: docs/benchmarks/scaling-modes.json")
    p.add_argument("--out-md", type=Path, default=None, help="default: docs/benchmarks/scaling-modes.md")
    p.add_argument("--merge", action="store_true",
                   help="keep the rows of --out-json for other (mesh, level) pairs (their own date and command)")
    p.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker is not None:
        print(json.dumps(worker(args.base, args.worker, args.k, args.cache)), flush=True)
        return 0
    from bench.environment import results_path, run_meta, write_results  # noqa: PLC0415
    from bench.meshes import require  # noqa: PLC0415

    require([args.base])
    args.out_json = args.out_json or results_path("scaling-modes", ".json")
    args.out_md = args.out_md or results_path("scaling-modes")
    meta = run_meta("bench scaling-modes", argv, base=args.base, k=args.k)
    kept = []
    if args.merge and args.out_json.is_file():
        old = json.loads(args.out_json.read_text())
        for r in old["rows"]:  # rows from before --merge existed carry their run's base, date and command in meta
            r.setdefault("base", old["meta"]["base"])
            r.setdefault("date", old["meta"]["date"])
            r.setdefault("command", old["meta"]["command"])
            if (r["base"], r["level"]) not in {(args.base, lv) for lv in args.levels}:
                kept.append(r)
    rows = []
    for level in args.levels:
        cmd = [sys.executable, "-m", "bench.scaling_modes", "--worker", str(level), "--base", args.base,
               "-k", str(args.k), "--cache", args.cache]
        try:
            proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=args.timeout)
            if proc.returncode != 0:
                tail = [line for line in proc.stderr.splitlines() if line.strip()][-1:] or [f"exit {proc.returncode}"]
                print(f"python -m bench scaling-modes: level {level} failed ({tail[0][-200:]}); nothing written",
                      file=sys.stderr)
                return 1
            row = json.loads(proc.stdout.strip().splitlines()[-1])
        except subprocess.TimeoutExpired:
            row = {"level": level, "error": f"not finished within {args.timeout:.0f} s"}
        row.update(base=args.base, date=meta["date"], command=meta["command"])
        print(json.dumps(row), flush=True)
        rows.append(row)
    rows = sorted(kept + rows, key=lambda r: (r.get("n", 0), r["base"]))
    write_results(args.out_json, args.out_md, meta, rows, report(rows, meta))
    return 0


if __name__ == "__main__":
    sys.exit(main())
