"""Per-iteration cost against a numpy peer: pymanopt's Riemannian CG beside the project's.

    python -m bench peers                                 # Brockett n = 10³, 10⁴, 10⁵ and CMM on example:bumpy
    python -m bench peers --sizes 1000 10000 --meshes example:bumpy hand_868.obj --iterations 200

The same problems as ``python -m bench second-order`` (``bench.second_order``): the generalised Brockett cost
``Σ_j d_j x_jᵀWx_j`` on ``XᵀMX = I`` (grid Laplacian + 0.01 I, random diagonal M, k = 5) and the smoothed CMM
energy's final stage (huber δ = 1e-3, μ = 2λ, k = 10, from the block solver's first three stages). Each runs
``--iterations`` steps of unpreconditioned Riemannian CG — the project's ``stiefel.RiemannianCG`` with each
block retraction (cayley, cholesky, polar), and pymanopt 2.2.1's ``ConjugateGradient`` on the isometric
problem on St(n, k) (``Y = M^{1/2}X``; pymanopt has no generalised Stiefel manifold) — and reports the time
per iteration (compile excluded; and with the compile spread over the run), the objective reached, and the
time to the worse of the two final objectives (pymanopt vs our default retraction; ours from the iteration
count at which the history reaches it × the time per iteration).

pymanopt is a bench-only dependency (``pip install -e ".[peers]"``), never imported by the library; it runs
in a subprocess (``--pymanopt PYTHON``, default: this interpreter when it has pymanopt). Writes
``docs/benchmarks/peers.md`` and ``docs/benchmarks/peers.json`` (atomically; notes below ``<!-- notes -->`` kept).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # like the other benches: a shared 2-core machine

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # an application: float64

import equinox as eqx  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402

import stiefel  # noqa: E402
from bench.environment import header_lines, results_path, run_meta, write_results  # noqa: E402
from bench.meshes import require  # noqa: E402
from bench.second_order import brockett_problem, cmm_problem, pymanopt_subprocess  # noqa: E402

RETRACTIONS = ("cayley", "cholesky", "polar")
DEFAULT_RETRACTION = stiefel.GeneralizedStiefel(np.ones(2), 1).retraction_name

#: pymanopt's CG on ``bench.second_order.PYMANOPT_PROBLEM``, with its per-iteration log
PEER_CG = r'''
from pymanopt.optimizers import ConjugateGradient
opt = ConjugateGradient(max_iterations=int(data["iterations"]), min_gradient_norm=0.0, min_step_size=0.0,
                        verbosity=0, log_verbosity=1)
t = time.perf_counter()
res = opt.run(problem, initial_point=Y0)
seconds = time.perf_counter() - t
log = res.log["iterations"]
times = np.asarray(log["time"]) - log["time"][0]
print(json.dumps({"iterations": int(res.iterations), "seconds": seconds, "value": float(res.cost),
                  "grad_norm": float(res.gradient_norm), "reason": str(res.stopping_criterion),
                  "history_value": [float(c) for c in log["cost"]], "history_time": [float(x) for x in times]}))
'''


def has_pymanopt() -> bool:
    return importlib.util.find_spec("pymanopt") is not None


def run_ours(problem: dict, retraction: str, iterations: int) -> dict:
    """``iterations`` steps of unpreconditioned ``stiefel.RiemannianCG`` with ``retraction`` (no stopping test)."""
    S = stiefel.GeneralizedStiefel(problem["M"], problem["k"], retraction=retraction)
    F = problem["make"](problem["Wop"])
    X0 = problem["X0"]
    solver = stiefel.RiemannianCG(S, 0.0, 0.0, history=iterations + 1)
    solve = eqx.filter_jit(lambda F, X0: optx.minimise(lambda X, a: F(X), solver, X0, None, max_steps=iterations,
                                                       throw=False))
    t = time.perf_counter()
    compiled = solve.lower(F, X0).compile()
    t_compile = time.perf_counter() - t
    t = time.perf_counter()
    sol = compiled(F, X0)
    jax.block_until_ready(sol.value)
    t_run = time.perf_counter() - t
    steps = max(int(sol.stats["num_steps"]), 1)
    values = np.asarray(sol.stats["history"].value)[: steps + 1]
    row = {"problem": problem["label"], "n": problem["n"], "k": problem["k"], "solver": f"ours CG ({retraction})",
           "retraction": retraction, "iterations": steps, "seconds": t_run, "compile_seconds": t_compile,
           "ms_per_iteration": 1e3 * t_run / steps, "ms_per_iteration_with_compile": 1e3 * (t_run + t_compile) / steps,
           "value": float(values[-1]), "history_value": [float(v) for v in values]}
    print(json.dumps({k: v for k, v in row.items() if not k.startswith("history")}), flush=True)
    return row


def run_peer(problem: dict, python: str, iterations: int) -> dict:
    """pymanopt's ConjugateGradient on the isometric problem on St(n, k), in ``python`` (a subprocess)."""
    out, error = pymanopt_subprocess(problem, python, PEER_CG, 3600, iterations=iterations)
    if out is None:
        return {"problem": problem["label"], "solver": "pymanopt CG", "error": error}
    steps = max(out["iterations"], 1)
    row = {"problem": problem["label"], "n": problem["n"], "k": problem["k"], "solver": "pymanopt CG",
           "ms_per_iteration": 1e3 * out["seconds"] / steps, "ms_per_iteration_with_compile": 1e3 * out["seconds"] / steps,
           "compile_seconds": 0.0, **out}
    print(json.dumps({k: v for k, v in row.items() if not k.startswith("history")}), flush=True)
    return row


def time_to(row: dict, target: float) -> float | None:
    """Seconds until the row's objective history first reaches ``target`` (None if it never does)."""
    values = np.asarray(row["history_value"])
    hit = np.flatnonzero(values <= target)
    if hit.size == 0:
        return None
    if "history_time" in row:
        return float(row["history_time"][hit[0]])
    return float(hit[0] * row["ms_per_iteration"] / 1e3)


def compare(rows: list[dict]) -> None:
    """Adds ``seconds_to_common`` (time to the worse final objective of pymanopt and our default) per row."""
    for label in dict.fromkeys(r["problem"] for r in rows):
        group = [r for r in rows if r["problem"] == label and "error" not in r]
        peer = [r for r in group if r["solver"] == "pymanopt CG"]
        ours = [r for r in group if r.get("retraction") == DEFAULT_RETRACTION]
        if not peer or not ours:
            continue
        target = max(peer[0]["value"], ours[0]["value"])
        for r in group:
            r["common_objective"] = target
            r["seconds_to_common"] = time_to(r, target)


def report(rows: list[dict], meta: dict) -> str:
    lines = ["# Per-iteration cost against pymanopt (Riemannian CG, no preconditioner)", "", *header_lines(meta),
             f"* {meta['iterations']} iterations of each method from the same start; ours: `stiefel.RiemannianCG` "
             f"(strong Wolfe, PR+), each block retraction (default: {DEFAULT_RETRACTION}); pymanopt 2.2.1 "
             "`ConjugateGradient` (its defaults: backtracking line search, Hestenes–Stiefel β) on the isometric "
             "problem on St(n, k)",
             "* ms/it: solve seconds / iterations (ours: compile excluded; 'with compile': the compile spread over "
             "the run); to common: seconds to the worse of pymanopt's and our default's final objective", "",
             "| problem | n | solver | iterations | ms/it | ms/it with compile | objective | s to common | "
             "ratio ms/it vs pymanopt |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|"]
    for label in dict.fromkeys(r["problem"] for r in rows):
        group = [r for r in rows if r["problem"] == label]
        peer = next((r for r in group if r["solver"] == "pymanopt CG" and "error" not in r), None)
        for r in group:
            if "error" in r:
                lines.append(f"| {label} | | {r['solver']} | error: {r['error']} | | | | | |")
                continue
            common = r.get("seconds_to_common")
            ratio = f"{r['ms_per_iteration'] / peer['ms_per_iteration']:.2f}" if peer else ""
            lines.append(f"| {label} | {r['n']} | {r['solver']} | {r['iterations']} | {r['ms_per_iteration']:.2f} | "
                         f"{r['ms_per_iteration_with_compile']:.2f} | {r['value']:.8g} | "
                         f"{'' if common is None else f'{common:.2f}'} | {ratio} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench peers", description=__doc__.splitlines()[0])
    p.add_argument("--sizes", nargs="*", type=int, default=[1000, 10000, 100000], help="Brockett sizes n")
    p.add_argument("--meshes", nargs="*", default=["example:bumpy"], help="CMM final stages on these meshes")
    p.add_argument("--iterations", type=int, default=200)
    p.add_argument("--pymanopt", default=sys.executable if has_pymanopt() else None,
                   help="a Python with pymanopt 2.2.1 (default: this one if it has pymanopt; pip install -e '.[peers]')")
    p.add_argument("--out-md", type=Path, default=None, help="default: docs/benchmarks/peers.md")
    p.add_argument("--out-json", type=Path, default=None, help="default: docs/benchmarks/peers.json")
    args = p.parse_args(argv)
    if args.iterations < 1:
        p.error("--iterations must be at least 1")
    require(args.meshes)
    meta = run_meta("bench peers", argv, iterations=args.iterations, pymanopt=bool(args.pymanopt))
    if not args.pymanopt:
        print("pymanopt is not installed (pip install -e '.[peers]'): only the project's rows", file=sys.stderr)
    problems = [brockett_problem(n) for n in args.sizes] + [cmm_problem(spec) for spec in args.meshes]
    rows = []
    for problem in problems:
        rows += [run_ours(problem, r, args.iterations) for r in RETRACTIONS]
        if args.pymanopt:
            rows.append(run_peer(problem, args.pymanopt, args.iterations))
    compare(rows)
    write_results(args.out_json or results_path("peers", ".json"), args.out_md or results_path("peers"), meta, rows,
                  report(rows, meta))
    return 0


if __name__ == "__main__":
    sys.exit(main())
