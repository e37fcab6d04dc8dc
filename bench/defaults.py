"""How localised the CLI's default modes are: sparsity and support sizes for candidate default μ.

    python -m bench defaults                       # the generated examples (no files needed)
    python -m bench defaults --meshes example:bumpy example:starfish example:torus example:patch \\
        hand_868.obj decimated-knight.off bumpy.off bunny.off fandisk.off hand_868_holes2.obj horse_976.obj \\
        camelhead.off armadillo_25479.obj

For each mesh and each μ rule (``--rules``, CLI syntax: ``0.01n`` the former default, ``2λ`` = 2·λ_(k−1),
the current one, …), ``stiefel modes``' solve as the CLI runs it (``BlockCMM`` defaults, area ℓ1
weights, eigenbasis start, k = 10) and per-mode measures: the sparsity (fraction of entries below
1e-3 of the column's maximum, ``CMMResult.sparsity``) and the support (fraction of the surface's area
where ``|ψ| ≥ 1e-3 max|ψ|``, median and largest over the modes). Writes ``bench/RESULTS_defaults.md``
and ``bench/results_defaults.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # like the other benches: a shared 2-core machine

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # an application: float64

import numpy as np  # noqa: E402

import mesh  # noqa: E402
from bench.environment import header_lines, run_meta  # noqa: E402
from bench.meshes import load_mesh  # noqa: E402
from stiefel_cmm.cli.outputs import parse_mu  # noqa: E402
from objectives.cmm.modes import compressed_modes, first_eigenpairs, unpack_laplacian  # noqa: E402
from objectives.cmm.solvers import BlockCMM  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ["example:bumpy", "example:starfish", "example:torus", "example:patch"]


def measure(spec: str, rules: list[str], k: int, max_iters: int) -> list[dict]:
    m, label = load_mesh(spec)
    lap = mesh.laplacian(m)
    W, a = unpack_laplacian(lap)
    pairs = first_eigenpairs(W, a, max(k, 2))
    lam = float(pairs[0][-1])
    rows = []
    for rule in rules:
        mu = parse_mu(rule).resolve(m.n_vertices, lam)
        t = time.perf_counter()
        r = compressed_modes(lap, k, mu, solver=BlockCMM(max_iters=max_iters), weighting="area", eigenpairs=pairs)
        seconds = time.perf_counter() - t
        P = np.abs(np.asarray(r.modes))
        support = (a[:, None] * (P >= 1e-3 * P.max(axis=0))).sum(axis=0) / a.sum()
        rows.append({"mesh": label, "n": m.n_vertices, "rule": rule, "mu": mu, "lambda_k_minus_1": lam,
                     "sparsity_1e-3": r.sparsity["1e-3"], "sparsity_1e-6": r.sparsity["1e-6"],
                     "support_median": float(np.median(support)), "support_max": float(support.max()),
                     "iterations": r.iterations, "status": r.status, "seconds": seconds})
        print(json.dumps(rows[-1]), flush=True)
    return rows


def report(rows: list[dict], meta: dict) -> str:
    lines = ["# Default μ: how localised are the CLI's modes?", "", *header_lines(meta),
             f"* k = {meta['k']}, BlockCMM defaults (huber f6, δ = 1e-3, 4 continuation stages), area ℓ1 weights, "
             f"eigenbasis start, at most {meta['max_iters']} iterations",
             "* sparsity: fraction of entries below 1e-3 of their mode's maximum; support: fraction of the area where "
             "|ψ| ≥ 1e-3 max|ψ| (median and largest over the k modes); λ = λ_(k−1), the largest of the first k "
             "eigenvalues (areas normalised to total 1)", "",
             "| mesh | n | rule | μ | sparsity | support median | support max | iterations | status | s |",
             "|---|---:|---|---:|---:|---:|---:|---:|---|---:|"]
    for r in rows:
        lines.append(f"| {r['mesh']} | {r['n']} | {r['rule']} | {r['mu']:.4g} | {r['sparsity_1e-3']:.2f} | "
                     f"{r['support_median']:.2f} | {r['support_max']:.2f} | {r['iterations']} | {r['status']} | "
                     f"{r['seconds']:.1f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench defaults", description=__doc__.splitlines()[0])
    p.add_argument("--meshes", nargs="+", default=EXAMPLES,
                   help="example:NAME, paths or mesh names in ../shared/meshes (default: the generated examples)")
    p.add_argument("--rules", nargs="+", default=["0.01n", "2λ"], help="μ rules in the CLI's syntax")
    p.add_argument("-k", type=int, default=10)
    p.add_argument("--max-iters", type=int, default=5000)
    p.add_argument("--out-md", type=Path, default=ROOT / "bench" / "RESULTS_defaults.md")
    p.add_argument("--out-json", type=Path, default=ROOT / "bench" / "results_defaults.json")
    args = p.parse_args(argv)
    for rule in args.rules:
        parse_mu(rule)  # a bad rule is refused before any solve
    meta = run_meta("bench defaults", argv, k=args.k, max_iters=args.max_iters)
    rows = [row for spec in args.meshes for row in measure(spec, args.rules, args.k, args.max_iters)]
    args.out_json.write_text(json.dumps({"meta": meta, "rows": rows}, indent=1) + "\n")
    args.out_md.write_text(report(rows, meta))
    print(f"wrote {args.out_md} and {args.out_json}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
