"""Benchmark of the manifold layer: μ = 0 on grid Laplacians, k = 10.

For each grid size, each solver × retraction × direction × preconditioning: iterations and
seconds (compile time apart) to reach a Riemannian gradient norm of ``gtol`` (1e-8), the
eigenvalue error against ``scipy.sparse.linalg.eigsh`` and the orthogonality error.

    python -m bench stiefel                    # n = 1e4 and 1e5 (about 10 minutes)
    python -m bench stiefel --sizes 10 --quick

``W`` is the graph Laplacian of an m×m grid; ``M`` a random positive diagonal in [0.5, 2];
the preconditioner is ``(W + σM)⁻¹`` with σ = λ₁/2 (one sparse LU, like an ADMM E-step).
Results go to ``docs/benchmarks/stiefel.json`` and a markdown table on stdout (``docs/benchmarks/stiefel.md``
quotes it).
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)  # benchmark script (an application), not library code

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg as sla  # noqa: E402

import stiefel  # noqa: E402
from bench.environment import git_commit, results_path, write_json  # noqa: E402
from stiefel_cmm.cli.grid_demo import grid_laplacian  # noqa: E402


def run_case(kind, W, M, ref, *, gtol, max_iters, precond, **kw):
    Wop = stiefel.as_operator(W, check=False, factor=False)
    k = len(ref)
    t0 = time.perf_counter()
    P = stiefel.shifted_inverse(W, M, 0.5 * ref[1]) if precond else None
    t_factor = time.perf_counter() - t0 if precond else 0.0
    if kind == "sequential":
        res = stiefel.minimize_sequential(lambda x: jnp.dot(x, Wop.mv(x)), M, k, gtol=gtol, max_iters=max_iters,
                                          preconditioner=P, direction=kw["direction"])
        values = np.asarray(res.values)
        iters = [int(i) for i in np.asarray(res.iterations)]
        status = res.status_names
        value_err = float(np.max(np.abs(values - ref)) / ref[-1])
        orth = res.stats["dist_to_manifold"]
        fevals = int(np.sum(res.stats["n_fevals"]))
    else:
        S = stiefel.GeneralizedStiefel(M, k, retraction=kw["retraction"])
        X0 = S.random_point(jax.random.PRNGKey(0))
        res = stiefel.minimize(lambda X: jnp.sum(X * Wop.mv(X)), S, X0, method=kw["method"], gtol=gtol,
                               max_iters=max_iters, preconditioner=P)
        iters = [int(res.iterations)]
        status = [res.status_name]
        value_err = float(abs(float(res.value) - ref.sum()) / ref.sum())
        orth = float(res.stats["dist_to_manifold"])
        fevals = int(res.stats["n_fevals"])
    return {
        "solver": kind, **kw, "preconditioned": precond, "iterations": iters, "max_iters_per_column": max(iters),
        "status": status, "seconds": res.wall_time, "compile_seconds": res.compile_time,
        "factor_seconds": t_factor, "value_error": value_err, "orthogonality": orth, "n_fevals": fevals,
    }


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", type=int, nargs="+", default=[100, 316], help="grid sides m (n = m²)")
    p.add_argument("-k", type=int, default=10)
    p.add_argument("--gtol", type=float, default=1e-8)
    p.add_argument("--quick", action="store_true", help="preconditioned runs only")
    p.add_argument("--out", type=Path, default=None, help="default: docs/benchmarks/stiefel.json")
    args = p.parse_args(argv)

    cases = []
    for precond in ([True] if args.quick else [True, False]):
        for direction in ("cg", "momentum", "gd"):
            cases.append(("sequential", dict(direction=direction), precond))
        for method in ("cg", "bb"):
            for retraction in ("cayley", "cholesky", "polar"):
                cases.append(("block", dict(method=method, retraction=retraction), precond))

    # warm-up: the first execution in a process pays a one-off runtime start (~1 s)
    Wt = grid_laplacian(5)
    run_case("sequential", Wt, np.ones(25), np.array([0.0, 0.1, 0.2]), gtol=1e-6, max_iters=5, precond=False,
             direction="gd")
    rows = []
    for m in args.sizes:
        W = grid_laplacian(m)
        n = W.shape[0]
        M = np.random.default_rng(0).uniform(0.5, 2.0, n)
        t0 = time.perf_counter()
        ref = sla.eigsh(sp.csc_array(W), k=args.k, M=sp.diags_array(M).tocsc(), sigma=-1e-6, which="LM")[0]
        t_eigsh = time.perf_counter() - t0
        rows.append({"solver": "eigsh (shift-invert)", "n": n, "seconds": t_eigsh})
        print(f"n = {n}: eigsh {t_eigsh:.2f} s", flush=True)
        for kind, kw, precond in cases:
            # unpreconditioned runs are capped: plain gradient methods need ~10³–10⁴ iterations here
            max_iters = 1000 if precond else (2000 if n <= 10_000 else 300)
            row = run_case(kind, W, M, ref, gtol=args.gtol, max_iters=max_iters, precond=precond, **kw)
            row["n"] = n
            rows.append(row)
            print(json.dumps(row), flush=True)

    meta = {
        "date": time.strftime("%Y-%m-%d"), "commit": git_commit(), "machine": f"{platform.processor() or platform.machine()}, "
        f"{__import__('os').cpu_count()} cores", "python": platform.python_version(), "jax": jax.__version__,
        "numpy": np.__version__, "scipy": scipy.__version__, "k": args.k, "gtol": args.gtol,
        "command": "python -m bench stiefel " + " ".join(argv or []),
    }
    write_json(args.out or results_path("stiefel", ".json"), {"meta": meta, "rows": rows})
    print(markdown(meta, rows))


def markdown(meta, rows) -> str:
    lines = [f"machine: {meta['machine']}; date {meta['date']}; commit {meta.get('commit', 'unknown')}; jax {meta['jax']}, scipy {meta['scipy']}; "
             f"k = {meta['k']}, gtol = {meta['gtol']:g}; command `{meta['command'].strip()}`", "",
             "| n | solver | variant | precond. | iterations (max per column) | status | seconds | compile s "
             "| eigenvalue error | orthogonality |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["solver"].startswith("eigsh"):
            lines.append(f"| {r['n']} | eigsh | shift-invert | – | – | – | {r['seconds']:.2f} | – | ref | – |")
            continue
        variant = r.get("direction") or f"{r['method']} / {r['retraction']}"
        st = sorted(set(r["status"]))
        lines.append(
            f"| {r['n']} | {r['solver']} | {variant} | {'yes' if r['preconditioned'] else 'no'} | "
            f"{sum(r['iterations'])} ({r['max_iters_per_column']}) | {', '.join(st)} | {r['seconds']:.2f} | "
            f"{r['compile_seconds']:.1f} | {r['value_error']:.1e} | {r['orthogonality']:.1e} |")
    return "\n".join(lines)


if __name__ == "__main__":
    main()
