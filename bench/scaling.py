"""Scaling benchmark: CMMs on subdivided surfaces up to ~10⁶ vertices.

A mesh (``--base``: default the generated ``example:bumpy``, 2 562 vertices; the committed results use
``bunny.off``, 3 485 vertices, closed, genus 0) is midpoint-subdivided (``trimesh.Trimesh.subdivide``; each
level ×4 faces, ≈ ×4 vertices; bunny: 1.4·10⁴, 5.6·10⁴, 2.2·10⁵ and 8.9·10⁵ vertices at levels 1–4). The subdivided meshes are cached as ``.npz`` under
``--cache`` (default ``$XDG_CACHE_HOME/stiefel-cmm/bench``, never in the repository). For every
size, in a fresh subprocess (so that its peak RSS is its own):

* load/validation (``mesh.from_arrays``) and Laplacian assembly (cotangent W, lumped A, unit area);
* ``eigsh`` shift-invert (``objectives.cmm.modes.first_eigenpairs``) for k = 10 and k = 50 — skipped
  when the time predicted from the previous size (exponent 1.5) exceeds ``--eigsh-budget``;
* the CMM block solver (``stiefel.minimize``, Riemannian CG, Cholesky retraction, residual
  preconditioning by ``(W + λ₁A)⁻¹``, Huber smoothing δ = 1e-3, μ = 0.01·n, uniform
  weighting) for a fixed ``--iters`` iterations (gtol = 0), from the eigenbasis:
  ms/iteration, split into the preconditioner's one-off SuperLU factorisation and, per
  iteration, one preconditioner application (k triangular solve pairs on the host), the
  objective+gradient evaluations (× evaluations per iteration) and the rest;
* for n ≤ ``--total-max-n``: the total time to a modest tolerance (``ftol`` = 1e-5: relative
  decrease over 20 iterations, or gtol = 1e-4, at most ``--total-iters`` iterations);
* peak RSS of the subprocess, against ``n·k·8`` bytes (one (n, k) float64 block), ``nnz(W)``
  and the LU's ``nnz(L + U)``.

Then log–log fits ``t ∝ n^p`` of every timing over the sizes (the goal: ``p ≤ 1.15`` for the solver's time
per iteration up to 10⁶ vertices).

    python -m bench scaling --base bunny.off      # levels 1–4, k = 10 and 50 (≈ 20 min on 2 cores)
    python -m bench scaling --levels 1 2 --ks 10 --iters 10 --out-json /tmp/s.json --out-md /tmp/s.md

Writes ``docs/benchmarks/scaling.json`` and ``docs/benchmarks/scaling.md`` (notes below ``<!-- notes -->`` kept)
when every level is done; a level whose process fails stops the run with nothing written.

This module runs the sizes and writes the results; one size's measurement is ``bench.scaling_worker``, the
fits and the page ``bench.scaling_report``, the subdivided meshes and their cache ``bench.subdivided_meshes``.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import time
from pathlib import Path

# One BLAS thread (see bench/bench_mesh.py): on the shared 2-core machine threaded OpenBLAS
# made ARPACK several times slower. Set before numpy is imported; an explicit setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # benchmark script (an application), not library code

import numpy as np  # noqa: E402
import scipy  # noqa: E402

from bench.environment import git_commit, results_path, write_json, write_page  # noqa: E402
from bench.meshes import require  # noqa: E402
from bench.scaling_report import exponents, markdown  # noqa: E402
from bench.scaling_worker import worker  # noqa: E402
from bench.subdivided_meshes import default_cache  # noqa: E402


def _predict(row, prior, rows):
    """Predicted eigsh and library-factorisation seconds at the next size (≈ ×4 vertices), into ``prior``."""
    prev = rows[-2] if len(rows) >= 2 else None
    grow = row["n"] / prev["n"] if prev else 4.0
    for k, e in row["eigsh"].items():
        prior[int(k)] = e["seconds"] * grow**1.5 if e.get("seconds") else float("inf")
    t_f = row["factor"]["library"].get("seconds")
    if not t_f:
        prior["factor"] = float("inf")
        return
    p_f = 2.0  # measured exponent between the last two sizes, at least 2
    t_prev = prev and prev["factor"]["library"].get("seconds")
    if t_prev:
        p_f = max(p_f, float(np.log(t_f / t_prev) / np.log(grow)))
    prior["factor"] = t_f * grow**p_f


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base", default="example:bumpy",
                   help="example:NAME, a path or a mesh in ../shared/meshes (the committed results: bunny.off)")
    p.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3, 4])
    p.add_argument("--ks", type=int, nargs="+", default=[10, 50])
    p.add_argument("--iters", type=int, default=20, help="fixed iterations for the per-iteration timing")
    p.add_argument("--min-iters", type=int, default=3, help="at least this many (SuperLU runs over budget)")
    p.add_argument("--solve-budget", type=float, default=60.0, help="seconds per SuperLU-preconditioned run")
    p.add_argument("--factor-budget", type=float, default=120.0, help="skip the SuperLU factorisation when "
                   "predicted above (s)")
    p.add_argument("--total-ks", type=int, nargs="+", default=[10])
    p.add_argument("--mem-factor", type=float, default=80.0, help="skip a solver run when this many n×k float64 "
                   "blocks exceed the available memory (measured: peak RSS growth ≈ 70 blocks at n = 2.2e5, k = 50)")
    p.add_argument("--total-max-n", type=float, default=6e4, help="run to tolerance only up to this n")
    p.add_argument("--total-iters", type=int, default=150)
    p.add_argument("--mu-factor", type=float, default=0.01)
    p.add_argument("--eigsh-budget", type=float, default=240.0, help="skip eigsh when predicted above (s)")
    p.add_argument("--cache", default=str(default_cache()))
    p.add_argument("--out-json", type=Path, default=None, help="default: docs/benchmarks/scaling.json")
    p.add_argument("--out-md", type=Path, default=None, help="default: docs/benchmarks/scaling.md")
    p.add_argument("--resume", default=None, help="reuse the rows of these levels from an earlier results JSON")
    p.add_argument("--render", default=None, help="only re-render --out-md (and the fits in --out-json) "
                   "from this results JSON")
    p.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--prior", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker is not None:
        print("ROW " + json.dumps(worker(args)), flush=True)
        return 0
    out_json, out_md = args.out_json or results_path("scaling", ".json"), args.out_md or results_path("scaling")
    if args.render:  # re-render the markdown (and the fits) from a results JSON
        res = json.loads(Path(args.render).read_text())
        res["exponents"] = exponents(res["rows"], res["meta"]["ks"])
        write_json(out_json, res)
        write_page(out_md, markdown(res["meta"], res["rows"], res["exponents"], res["meta"]["ks"]))
        return 0
    require([args.base])

    rows, prior = [], {}
    t_start = time.perf_counter()
    done = {}
    if args.resume:
        done = {r["level"]: r for r in json.loads(Path(args.resume).read_text())["rows"]
                if r.get("base", args.base) == args.base}
    for level in args.levels:
        if level in done:  # measured by an earlier run (--resume): keep its row
            rows.append(done[level])
            row = done[level]
            _predict(row, prior, rows)
            continue
        cmd = [sys.executable, "-m", "bench.scaling", "--worker", str(level), "--base", args.base,
               "--ks", *map(str, args.ks), "--iters", str(args.iters), "--total-max-n", str(args.total_max_n),
               "--total-iters", str(args.total_iters), "--mu-factor", str(args.mu_factor),
               "--min-iters", str(args.min_iters), "--solve-budget", str(args.solve_budget),
               "--factor-budget", str(args.factor_budget), "--total-ks", *map(str, args.total_ks),
               "--mem-factor", str(args.mem_factor),
               "--eigsh-budget", str(args.eigsh_budget), "--cache", args.cache, "--prior", json.dumps(prior)]
        proc = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, text=True)
        line = [ln for ln in proc.stdout.splitlines() if ln.startswith("ROW ")]
        if proc.returncode or not line:
            print(f"python -m bench scaling: level {level}'s process failed (exit {proc.returncode}); nothing written",
                  file=sys.stderr)
            return 1
        row = json.loads(line[-1][4:])
        rows.append(row)
        print(json.dumps({"n": row["n"], "done_after_s": time.perf_counter() - t_start}), flush=True)
        # predict the next size's eigsh time (×4 vertices, exponent 1.5)
        _predict(row, prior, rows)
    exps = exponents(rows, args.ks)
    from stiefel.linalg.sparse_factor import default_backend

    dev = jax.devices()[0]
    meta = {"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.platform()}", "commit": git_commit(),
            "versions": f"python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}, "
                        f"jax {jax.__version__}",
            "factor_backend": default_backend(),
            "backend": jax.default_backend(), "device": getattr(dev, "device_kind", str(dev)),
            "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
            "command": "python -m bench scaling " + " ".join(argv if argv is not None else sys.argv[1:]),
            "base": args.base, "levels": args.levels, "cache": args.cache, "mu_factor": args.mu_factor,
            "iters": args.iters, "total_iters": args.total_iters, "total_max_n": args.total_max_n,
            "ks": args.ks, "total_ks": args.total_ks, "resumed_levels": sorted(done), "total_seconds": time.perf_counter() - t_start}
    write_json(out_json, {"meta": meta, "rows": rows, "exponents": exps})
    md = markdown(meta, rows, exps, args.ks)
    write_page(out_md, md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
