"""The default CMM solve at scale (issue 18, item 6): ``stiefel modes``' defaults on midpoint-subdivided meshes.

    python -m bench scaling-modes                                  # example:bumpy, levels 1–2 (no files needed)
    python -m bench scaling-modes --base bunny.off --levels 2 3 4  # 5.6·10⁴, 2.2·10⁵, 8.9·10⁵ vertices
    python -m bench scaling-modes --base armadillo_25479.obj --levels 1 2 3 --merge   # 1.0·10⁵ … 1.6·10⁶, added

Each level runs in its own process (its peak RSS is that process's ``ru_maxrss``, the Python/JAX runtime
included): cotangent Laplacian, ``eigsh`` for the first max(k, 2) pairs (timed: the reference of the
goal "total ≤ 20× eigsh"), then ``compressed_modes(lap, k, 2λ_(k−1))`` with the CLI's defaults
(``BlockCMM()``: four smoothing stages, saddle checks, area weights, eigenbasis start). Reported: total
solve seconds (compile apart), iterations, status, t₁ (seconds until the true objective is within 1e-3,
relative, of the final one), the ratio of solve (+ compile) to eigsh, and peak RSS. A level that does not
finish within ``--timeout`` seconds is reported as such. Subdivided meshes are cached as in
``bench.scaling``. Writes ``bench/RESULTS_scaling_modes.md`` and ``bench/results_scaling_modes.json``; with
``--merge`` the rows already there for other (mesh, level) pairs are kept (each row names its mesh, date and command).

``--coarse-start`` adds, in the same process, a coarse-to-fine run: the mesh one subdivision level lower is solved
with the same defaults and μ, its modes are carried to the fine vertices (inverse-distance weights of the three
nearest coarse vertices, then A-orthonormalised) and the fine solve starts from them with one smoothing stage
(``BlockCMM(continuation=1)``). It measures how much of the fine solve a near-converged start saves.
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


def carry_modes(Vc, modes, Vf, a):
    """Coarse modes ``(n_c, k)`` at vertices ``Vc (n_c, 3)`` carried to the vertices ``Vf (n, 3)``: inverse-distance
    weights of the 3 nearest coarse vertices (constants carry exactly), then A-orthonormalised (``XᵀAX = I``,
    ``a = diag A (n,)``) by the Cholesky factor of the Gram matrix."""
    import numpy as np  # noqa: PLC0415
    from scipy.spatial import cKDTree  # noqa: PLC0415

    dist, idx = cKDTree(Vc).query(Vf, k=3)
    weights = 1.0 / np.maximum(dist, 1e-300)
    weights /= weights.sum(axis=1, keepdims=True)
    X = np.einsum("nj,njk->nk", weights, modes[idx])
    chol = np.linalg.cholesky(X.T @ (a[:, None] * X))
    return np.linalg.solve(chol, X.T).T


def coarse_to_fine(base: str, level: int, k: int, cache: Path, mu: float, lap, pairs, default: float) -> dict:
    """The coarse-to-fine run of ``--coarse-start`` (module docstring): seconds of the coarse problem (Laplacian,
    eigsh, solve and compile), of the carry and of the fine solve; fine iterations; the objective against the
    default run's (``default``)."""
    import numpy as np  # noqa: PLC0415

    import mesh  # noqa: PLC0415
    from bench.scaling import subdivided  # noqa: PLC0415
    from bench.tails import tail_times  # noqa: PLC0415
    from objectives.cmm.modes import compressed_modes, first_eigenpairs, unpack_laplacian  # noqa: PLC0415
    from objectives.cmm.solvers import BlockCMM  # noqa: PLC0415

    Vc, Fc, _ = subdivided(base, level - 1, cache)
    Vf, _, _ = subdivided(base, level, cache)
    t0 = time.perf_counter()
    lap_c = mesh.laplacian(mesh.load((Vc, Fc), warn=False))
    Wc, ac = unpack_laplacian(lap_c)
    coarse = compressed_modes(lap_c, k, mu, eigenpairs=first_eigenpairs(Wc, ac, max(k, 2)))
    t_coarse = time.perf_counter() - t0
    t0 = time.perf_counter()
    X = carry_modes(Vc, np.asarray(coarse.modes), Vf, unpack_laplacian(lap)[1])
    t_carry = time.perf_counter() - t0
    r = compressed_modes(lap, k, mu, solver=BlockCMM(continuation=1), start=X, eigenpairs=pairs)
    t_near, _ = tail_times(np.asarray(r.history["time"], dtype=float), np.asarray(r.history["objective"], dtype=float))
    return {"n_coarse": len(Vc), "coarse_seconds": t_coarse, "coarse_iterations": coarse.iterations,
            "coarse_status": coarse.status, "carry_seconds": t_carry, "seconds": r.wall_time,
            "compile_seconds": r.compile_time, "iterations": r.iterations, "status": r.status,
            "objective": r.objective, "vs_default": r.objective / default - 1.0, "t_near": t_near}


def worker(base: str, level: int, k: int, cache: str, coarse_start: bool = False) -> dict:
    import jax  # noqa: PLC0415

    jax.config.update("jax_enable_x64", True)
    import numpy as np  # noqa: PLC0415

    import mesh  # noqa: PLC0415
    from bench.scaling import subdivided  # noqa: PLC0415
    from bench.tails import tail_times  # noqa: PLC0415 — t₁: within 1e-3 of the final objective
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
    t_near, _ = tail_times(np.asarray(r.history["time"], dtype=float), np.asarray(r.history["objective"], dtype=float))
    extra = {}
    if coarse_start and level >= 1:
        c = coarse_to_fine(base, level, k, Path(cache), mu, lap, pairs, r.objective)
        # the fine solve reuses the default run's compilation here; a coarse-to-fine run alone would pay it
        fine_compile = max(c["compile_seconds"], r.compile_time)
        c["ratio_to_eigsh"] = (c["coarse_seconds"] + c["carry_seconds"] + c["seconds"] + fine_compile) / t_eig
        extra["coarse_start"] = c
    return {**extra, "level": level, "n": len(a), "k": k, "mu": mu, "laplacian_seconds": t_lap, "eigsh_seconds": t_eig,
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
             "goal (issue 18, item 6): total ≤ 20× eigsh, ≤ 16 GB at 10⁶ vertices", "",
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
    warm = [r for r in rows if "coarse_start" in r]
    if warm:
        lines += ["", "### Coarse-to-fine start (`--coarse-start`)", "",
                  "The level below solved with the same defaults and μ, its modes carried to the fine vertices "
                  "(inverse-distance weights of the 3 nearest coarse vertices, A-orthonormalised), then "
                  "`BlockCMM(continuation=1)` from them; same process as the default run of the row above. "
                  "coarse s: Laplacian, eigsh, solve and compile of the coarse mesh; total / eigsh: (coarse + carry + "
                  "fine solve + the default run's compile, which the fine solve reuses here but would pay alone) over the "
                  "fine eigsh; vs default: the fine objective relative to the default run's", "",
                  "| mesh (level) | run | n | coarse n | coarse s (it.) | carry s | fine solve s | fine compile s | "
                  "fine iterations | fine t₁ s | total / eigsh | vs default | status |",
                  "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
        for r in warm:
            c = r["coarse_start"]
            t1 = "–" if c["t_near"] is None else f"{c['t_near']:.1f}"
            lines.append(f"| {r.get('base', meta['base'])} ({r['level']}) | {r.get('date', meta['date'])} | {r['n']} | "
                         f"{c['n_coarse']} | {c['coarse_seconds']:.1f} ({c['coarse_iterations']}) | "
                         f"{c['carry_seconds']:.2f} | {c['seconds']:.1f} | {c['compile_seconds']:.1f} | "
                         f"{c['iterations']} | {t1} | {c['ratio_to_eigsh']:.1f} | {c['vs_default']:+.1e} | "
                         f"{c['status']} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    from bench.scaling import default_cache  # noqa: PLC0415

    p = argparse.ArgumentParser(prog="python -m bench scaling-modes", description=__doc__.splitlines()[0])
    p.add_argument("--base", default="example:bumpy")
    p.add_argument("--levels", type=int, nargs="+", default=[1, 2])
    p.add_argument("-k", type=int, default=10)
    p.add_argument("--timeout", type=float, default=1800.0, help="seconds per level")
    p.add_argument("--cache", default=str(default_cache()))
    p.add_argument("--out-json", type=Path, default=ROOT / "bench" / "results_scaling_modes.json")
    p.add_argument("--out-md", type=Path, default=ROOT / "bench" / "RESULTS_scaling_modes.md")
    p.add_argument("--merge", action="store_true",
                   help="keep the rows of --out-json for other (mesh, level) pairs (their own date and command)")
    p.add_argument("--coarse-start", action="store_true",
                   help="also solve each level from the level below's modes (module docstring), same process")
    p.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker is not None:
        print(json.dumps(worker(args.base, args.worker, args.k, args.cache, args.coarse_start)), flush=True)
        return 0
    from bench.environment import run_meta, write_results  # noqa: PLC0415

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
               "-k", str(args.k), "--cache", args.cache] + (["--coarse-start"] if args.coarse_start else [])
        try:
            proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=args.timeout)
            if proc.returncode == 0:
                row = json.loads(proc.stdout.strip().splitlines()[-1])
            else:
                tail = [line for line in proc.stderr.splitlines() if line.strip()][-1:] or [f"exit {proc.returncode}"]
                row = {"level": level, "error": tail[0][-200:]}
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
