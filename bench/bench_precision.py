"""float32 vs float64: accuracy and speed of the CMM solvers in single precision.

For each mesh (cotangent W, lumped A, unit area), k modes, μ = ``mu_factor``·n, uniform ℓ1
weights, Huber-type smoothing f6 with ε = δ = 1e-3, eigenbasis start, the same solver runs
in float64 and in float32 (every array — W's ELL table, A, the ℓ1 weights, the iterate, the
preconditioner's output — in that dtype; JAX's x64 flag is on so that float64 exists):

* block Riemannian CG (``stiefel.solve_block``) with the SuperLU ``(W + λ₁A)⁻¹`` preconditioner,
  with the Jacobi (diagonal) one, and without;
* the sequential solver (thesis Algorithm 6, ``stiefel.minimize_sequential``), preconditioned;
* ADMM (``objectives.admm.splitting``) is numpy/SuperLU code in float64 only: it runs once, as the
  reference objective, and has no float32 row.

Reported per run: the true (non-smooth) objective of the returned iterate evaluated in float64,
its relative difference to the float64 run, ``max|XᵀAX − I|`` of the raw iterate (in float64
arithmetic), status, iterations, run time and compile time (apart).

    python -m bench precision                          # example:bumpy, example:torus
    python -m bench precision --meshes bunny.off fandisk.off   # the committed results

Writes ``docs/benchmarks/precision.json`` and a markdown table on stdout (``docs/benchmarks/precision.md``
quotes it).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)  # benchmark script (an application), not library code

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import mesh  # noqa: E402
from bench.environment import results_path, run_meta, write_json  # noqa: E402
from bench.meshes import load_mesh, require  # noqa: E402
import stiefel  # noqa: E402
from objectives.admm.splitting import l1_weights_np  # noqa: E402
from objectives.cmm.batch import cmm_batch, cmm_problem, default_options  # noqa: E402
from objectives.cmm.modes import compressed_modes  # noqa: E402
from objectives.cmm.solvers import ADMMCMM  # noqa: E402

DTYPES = {"float64": jnp.float64, "float32": jnp.float32}


def true_objective(W, a, mu, Psi) -> float:
    """``tr(ΨᵀWΨ) + μ Σ w_i |Ψ_ij|`` (uniform weights) in float64."""
    Psi = np.asarray(Psi, dtype=np.float64)
    w = l1_weights_np(a, "uniform")
    return float(np.sum(Psi * (W @ Psi)) + mu * np.sum(w[:, None] * np.abs(Psi)))


def orthogonality(a, Psi) -> float:
    Psi = np.asarray(Psi, dtype=np.float64)
    return float(np.max(np.abs(Psi.T @ (a[:, None] * Psi) - np.eye(Psi.shape[1]))))


def run_block(lap, k, mu, dtype, preconditioner, args):
    opts = default_options(max_iters=args.max_iters, gtol=args.gtol, ftol=args.ftol)
    r = cmm_batch(lap, k, [mu], weighting="uniform", preconditioner=preconditioner, options=opts, mode="loop",
                  dtype=dtype)
    return {"modes": r.modes[0], "status": r.status_names[0], "iterations": int(r.iterations[0]),
            "wall_time": r.wall_time, "compile_time": r.compile_time}


def run_sequential(lap, k, mu, dtype, args):
    problem, X0 = cmm_problem(lap, k, weighting="uniform", preconditioner="shifted", dtype=dtype)
    F = problem.energy.with_params(mu=mu, eps=1e-3, delta=1e-3)
    res = stiefel.minimize_sequential(F, np.asarray(lap.A.diagonal()), k, X0=X0, preconditioner=problem.precond,
                                      gtol=args.gtol, max_iters=args.seq_iters, dtype=dtype)
    names = set(res.status_names)
    status = "converged" if names == {"converged"} else ",".join(sorted(names - {"converged"}))
    return {"modes": np.asarray(res.x), "status": status, "iterations": int(np.sum(np.asarray(res.iterations))),
            "wall_time": res.wall_time, "compile_time": res.compile_time}


def run_mesh(name, args):
    m, _ = load_mesh(name)
    lap = mesh.laplacian(m, weights="cotangent", area="lumped")
    W, a = lap.W, np.asarray(lap.A.diagonal())
    n, k = lap.n, args.k
    mu = args.mu_factor * n
    rows = []
    solver = ADMMCMM(adapt_rho="increase", max_iters=10**6, time_limit=args.admm_time)
    admm = compressed_modes(lap, k, mu, solver=solver, weighting="uniform")
    ref = {"solver": "admm", "dtype": "float64", "objective": admm.objective, "orthogonality": admm.orthogonality,
           "status": admm.status, "iterations": admm.iterations, "wall_time": admm.wall_time, "compile_time": 0.0}
    rows.append(ref)
    print(json.dumps({"mesh": name, **ref}), flush=True)
    solvers = {"block_cg_superlu": lambda dt: run_block(lap, k, mu, dt, "shifted", args),
               "block_cg_jacobi": lambda dt: run_block(lap, k, mu, dt, "jacobi", args),
               "block_cg_none": lambda dt: run_block(lap, k, mu, dt, None, args)}
    if args.sequential:
        solvers["sequential_superlu"] = lambda dt: run_sequential(lap, k, mu, dt, args)
    for solver, fn in solvers.items():
        base = None
        for dname in ("float64", "float32"):
            out = fn(DTYPES[dname])
            modes = out.pop("modes")
            row = {"solver": solver, "dtype": dname, "objective": true_objective(W, a, mu, modes),
                   "orthogonality": orthogonality(a, modes), **out}
            if dname == "float64":
                base = row["objective"]
            row["rel_diff_vs_float64"] = (row["objective"] - base) / abs(base)
            row["rel_diff_vs_admm"] = (row["objective"] - ref["objective"]) / abs(ref["objective"])
            rows.append(row)
            print(json.dumps({"mesh": name, **row}), flush=True)
    return {"mesh": name, "n": n, "k": k, "mu": mu, "rows": rows}


def markdown(meta, results):
    out = [f"machine: {meta['machine']}; date {meta['date']}; commit {meta.get('commit', 'unknown')}; jax {meta['jax']}, scipy {meta['scipy']}, numpy "
           f"{meta['numpy']}; k = {meta['k']}, μ = {meta['mu_factor']}·n, uniform weighting, f6 (ε = δ = 1e-3), "
           f"eigenbasis start, gtol {meta['gtol']}, ftol {meta['ftol']}, block max_iters {meta['max_iters']}; "
           f"command `{meta['command']}`", ""]
    for res in results:
        out += [f"**{res['mesh']}** (n = {res['n']})", "",
                "| solver | dtype | objective | rel. diff vs float64 | rel. diff vs ADMM | max‖XᵀAX − I‖ | status | it. "
                "| run (s) | compile (s) |", "|---|---|---|---|---|---|---|---|---|---|"]
        for r in res["rows"]:
            rd = r.get("rel_diff_vs_float64")
            ra = r.get("rel_diff_vs_admm")
            out.append(f"| {r['solver']} | {r['dtype']} | {r['objective']:.6f} | "
                       f"{'–' if rd is None else f'{rd:+.1e}'} | {'–' if ra is None else f'{ra:+.1e}'} | "
                       f"{r['orthogonality']:.1e} | {r['status']} | {r['iterations']} | {r['wall_time']:.2f} | "
                       f"{r['compile_time']:.1f} |")
        out.append("")
    return "\n".join(out)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--meshes", nargs="+", default=["example:bumpy", "example:torus"])
    p.add_argument("-k", type=int, default=10)
    p.add_argument("--mu-factor", type=float, default=0.01)
    p.add_argument("--gtol", type=float, default=1e-6)
    p.add_argument("--ftol", type=float, default=1e-7)
    p.add_argument("--max-iters", type=int, default=600)
    p.add_argument("--sequential", action=argparse.BooleanOptionalAction, default=True)
    p.add_argument("--seq-iters", type=int, default=150)
    p.add_argument("--admm-time", type=float, default=20.0)
    p.add_argument("--out", type=Path, default=None, help="default: docs/benchmarks/precision.json")
    args = p.parse_args(argv)
    require(args.meshes)
    results = [run_mesh(name, args) for name in args.meshes]
    meta = run_meta("bench precision", argv, k=args.k,
                   mu_factor=args.mu_factor, gtol=args.gtol, ftol=args.ftol, max_iters=args.max_iters)
    write_json(args.out or results_path("precision", ".json"), {"meta": meta, "results": results})
    print(markdown(meta, results))
    return 0


if __name__ == "__main__":
    main()
