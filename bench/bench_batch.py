"""Batching: ``jax.vmap`` over μ values / random starts vs a Python loop of the same solver.

On one mesh (cotangent W, lumped A, unit area), k modes, uniform ℓ1 weights, f6 with
ε = δ = 1e-3, ``objectives.cmm.batch.cmm_batch`` solves a batch of B problems:

* ``mu``: B μ values, geometric from ``mu_lo``·n to ``mu_hi``·n, eigenbasis start;
* ``starts``: B random starts at μ = 0.01·n;

each in two modes — ``vmap`` (one compiled vmapped program) and ``loop`` (the single-problem
program compiled once, called B times from Python) — for each preconditioner: the sparse
Cholesky factor of ``W + λA`` (CHOLMOD as an XLA custom call, one native call per batch),
Jacobi (its diagonal, pure JAX), none. With ``--until fixed`` every member runs exactly
``--iters`` CG iterations (``gtol`` = 0), so both modes do the same arithmetic and the ratio of
run times is the speed-up of batching; with ``--until converged`` each member stops on the
solver's own tests (``objectives.cmm.batch.default_options``, ``--iters`` the cap), so the vmapped
loop runs as long as its slowest member. Compile time is reported apart; run times are the best
of ``--repeats`` runs (a first call pays one-time costs).

    python -m bench batch                               # starfish, torus; B = 8, 60 iterations
    python -m bench batch --meshes fandisk.off --until converged --iters 2000

Writes ``docs/benchmarks/batch.json`` and a markdown table on stdout (``docs/benchmarks/batch.md`` quotes it).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)  # benchmark script (an application), not library code

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import mesh  # noqa: E402
from bench.environment import results_path, run_meta, write_json  # noqa: E402
from bench.meshes import load_mesh, require  # noqa: E402
from objectives.cmm.batch import cmm_batch, cmm_problem, default_options  # noqa: E402

CONFIGS = {  # --preconditioners name: (table label, cmm_batch preconditioner); "shifted" is CHOLMOD as an XLA
    # custom call (stiefel.linalg.ffi_solve) under x64
    "cholmod": ("cholmod (custom call)", "shifted"),
    "jacobi": ("jacobi", "jacobi"),
    "none": ("none", None),
}


def _time(fn, *a, repeats=20):
    """Milliseconds per call of a jitted ``fn`` (compiled and warmed up first)."""
    fn = jax.jit(fn)
    jax.block_until_ready(fn(*a))
    t0 = time.perf_counter()
    for _ in range(repeats):
        jax.block_until_ready(fn(*a))
    return 1e3 * (time.perf_counter() - t0) / repeats


def profile_pieces(lap, k, B):
    """Per-call cost of the pieces of one CG iteration: B separate calls vs one vmapped call."""
    problem, X0 = cmm_problem(lap, k, weighting="uniform", preconditioner="shifted")
    F = problem.energy.with_params(mu=0.01 * lap.n, eps=1e-3, delta=1e-3)
    S = problem.manifold
    X = jnp.stack([S.project_to_manifold(jnp.asarray(X0))] * B)
    Z = 1e-2 * jnp.asarray(np.random.default_rng(1).standard_normal(X.shape))
    pieces = {
        "energy F(X)": (lambda x: F(x), (X,)),
        "value_and_grad F": (lambda x: jax.value_and_grad(lambda y: F(y))(x), (X,)),
        "jvp along Z (line search)": (lambda x, z: jax.jvp(lambda y: F(y), (x,), (z,)), (X, Z)),
        "W·X (ELL gathers)": (lambda x: F.W.mv(x), (X,)),
        "Σ X∘(W·X) (gathers fused into a reduction)": (lambda x: jnp.sum(x * F.W.mv(x)), (X,)),
        "sparse Cholesky P·X (custom call)": (lambda x: problem.precond.solve(x), (X,)),
        "Cholesky retraction": (lambda x, z: S.retract(x, z), (X, Z)),
    }
    rows = []
    for name, (fn, args) in pieces.items():
        single = _time(fn, *(a[0] for a in args))
        batched = _time(jax.vmap(fn), *args)
        rows.append({"piece": name, "single_ms": single, "B_times_single_ms": B * single, "vmap_ms": batched,
                     "gain": B * single / batched})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def run_mesh(name, args):
    m, _ = load_mesh(name)
    lap = mesh.laplacian(m, weights="cotangent", area="lumped")
    n, k, B = lap.n, args.k, args.batch
    fixed = args.until == "fixed"
    opts = default_options(max_iters=args.iters, gtol=0.0, ftol=0.0) if fixed else default_options(max_iters=args.iters)
    mus = np.geomspace(args.mu_lo, args.mu_hi, B) * n
    starts = np.random.default_rng(0).standard_normal((B, n, k))
    rows = []
    for kind in args.kinds:
        batch = {"mu": dict(mus=mus), "starts": dict(mus=0.01 * n, starts=starts)}[kind]
        for label, prec in (CONFIGS[name] for name in args.preconditioners):
            res = {}
            for mode in ("loop", "vmap"):
                runs = [cmm_batch(lap, k, weighting="uniform", preconditioner=prec, options=opts, mode=mode, **batch)
                        for _ in range(args.repeats)]
                r = min(runs, key=lambda x: x.wall_time)  # best of repeats: first calls pay one-time costs
                r.compile_time = runs[0].compile_time
                res[mode] = r
            lo, vm = res["loop"], res["vmap"]
            its = int(lo.iterations.sum())
            row = {"batch": kind, "preconditioner": label, "B": B, "until": args.until,
                   "iterations_loop": lo.iterations.tolist(), "iterations_vmap": vm.iterations.tolist(),
                   "loop_run_s": lo.wall_time, "loop_compile_s": lo.compile_time,
                   "vmap_run_s": vm.wall_time, "vmap_compile_s": vm.compile_time,
                   "speedup": lo.wall_time / vm.wall_time,
                   "speedup_with_compile": (lo.wall_time + lo.compile_time) / (vm.wall_time + vm.compile_time),
                   "ms_per_member_iteration_loop": 1e3 * lo.wall_time / its,
                   "ms_per_member_iteration_vmap": 1e3 * vm.wall_time / (B * int(vm.iterations.max())),
                   "max_abs_dx_vmap_vs_loop": float(np.max(np.abs(lo.modes - vm.modes))),
                   "max_rel_dobjective": float(np.max(np.abs(lo.objective - vm.objective) / np.abs(lo.objective))),
                   "max_orthogonality_vmap": float(np.max(vm.orthogonality)),
                   "status_vmap": vm.status_names, "objectives_vmap": vm.objective.tolist()}
            rows.append(row)
            print(json.dumps(row), flush=True)
    pieces = profile_pieces(lap, k, B) if args.profile else []
    return {"mesh": name, "n": n, "k": k, "rows": rows, "pieces": pieces}


def markdown(meta, results):
    out = [f"machine: {meta['machine']}; date {meta['date']}; commit {meta.get('commit', 'unknown')}; jax {meta['jax']}, scipy {meta['scipy']}, numpy "
           f"{meta['numpy']}; k = {meta['k']}, B = {meta['batch']}, "
           + (f"{meta['iters']} CG iterations per member (fixed)" if meta.get('until', 'fixed') == 'fixed' else
              f"each member to convergence (at most {meta['iters']} iterations)") + f", best of {meta['repeats']} runs, μ ∈ [{meta['mu_lo']}, "
           f"{meta['mu_hi']}]·n (geometric) or random starts at μ = 0.01·n; uniform weighting, f6, ε = δ = 1e-3; "
           f"command `{meta['command']}`", ""]
    for result in results:
        out += _table(result)
    return "\n".join(out)


def _table(result):
    out = [f"**{result['mesh']}** (n = {result['n']})", "",
           "| batch | preconditioner | iterations (members) | loop run (s) | vmap run (s) | speed-up | with compile "
           "| loop ms/member-it. | vmap ms/member-it. | compile loop / vmap (s) | max‖ΔX‖ vmap vs loop "
           "| max rel. Δobjective | max‖XᵀAX − I‖ |",
           "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        its = r.get("iterations_loop", [])
        span = f"{min(its)}–{max(its)}" if its and min(its) != max(its) else (str(its[0]) if its else "")
        out.append(f"| {r['batch']} | {r['preconditioner']} | {span} | {r['loop_run_s']:.2f} | {r['vmap_run_s']:.2f} | "
                   f"{r['speedup']:.2f}× | {r.get('speedup_with_compile', float('nan')):.2f}× | "
                   f"{r['ms_per_member_iteration_loop']:.2f} | "
                   f"{r['ms_per_member_iteration_vmap']:.2f} | {r['loop_compile_s']:.1f} / {r['vmap_compile_s']:.1f} | "
                   f"{r['max_abs_dx_vmap_vs_loop']:.1e} | {r['max_rel_dobjective']:.1e} | "
                   f"{r['max_orthogonality_vmap']:.1e} |")
    out.append("")
    if result["pieces"]:
        out += [f"Pieces of one iteration ({result['mesh']}, B = {result['rows'][0]['B']}): B separate calls vs one "
                "vmapped call", "", "| piece | single (ms) | B × single (ms) | vmap (ms) | gain |", "|---|---|---|---|---|"]
        for p in result["pieces"]:
            out.append(f"| {p['piece']} | {p['single_ms']:.2f} | {p['B_times_single_ms']:.2f} | {p['vmap_ms']:.2f} | "
                       f"{p['gain']:.2f}× |")
        out.append("")
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--meshes", nargs="+", default=["example:starfish", "example:torus"])
    p.add_argument("-k", type=int, default=10)
    p.add_argument("--batch", type=int, default=8)
    p.add_argument("--iters", type=int, default=60)
    p.add_argument("--mu-lo", type=float, default=0.003)
    p.add_argument("--mu-hi", type=float, default=0.03)
    p.add_argument("--repeats", type=int, default=2, help="runs per mode; the fastest is reported")
    p.add_argument("--profile", action=argparse.BooleanOptionalAction, default=True,
                   help="also time the pieces of one iteration, single vs vmapped")
    p.add_argument("--preconditioners", nargs="+", default=list(CONFIGS), choices=list(CONFIGS))
    p.add_argument("--until", choices=["fixed", "converged"], default="fixed",
                   help="fixed: --iters iterations per member (equal work); converged: the solver's own stopping tests")
    p.add_argument("--kinds", nargs="+", default=["mu", "starts"], choices=["mu", "starts"])
    p.add_argument("--out", type=Path, default=None, help="default: docs/benchmarks/batch.json")
    args = p.parse_args(argv)
    require(args.meshes)
    results = [run_mesh(name, args) for name in args.meshes]
    meta = run_meta("bench batch", argv, batch=args.batch, k=args.k,
                   iters=args.iters, until=args.until, repeats=args.repeats, mu_lo=args.mu_lo, mu_hi=args.mu_hi)
    write_json(args.out or results_path("batch", ".json"), {"meta": meta, "results": results})
    print(markdown(meta, results))
    return 0


if __name__ == "__main__":
    main()
