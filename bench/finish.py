"""Exact-support finish (issue 18, item 2): block solver and ADMM, each with and without the finish.

    python -m bench finish                                   # the generated examples (no files needed)
    python -m bench finish --meshes example:bumpy hand_868.obj fandisk.off camelhead.off
    python -m bench finish --meshes --manpg 128 512 2048     # ManPG's 1-D problem (no mesh files)

For each mesh (k = 10, μ = 2λ_(k−1), area ℓ1 weights, eigenbasis start): the default ``BlockCMM``, the same
modes finished by ``finish_support``, ``ADMMCMM`` (defaults) and its modes finished — true objective,
exact-zero fraction, entries below 1e-6 of their column's peak, the exact ℓ1 stationarity residual
(docs/maths.md §9, eq. 9.10, relative), orthogonality, iterations and seconds (compile apart). ``--manpg N …``
adds ManPG's 1-D compressed-modes problem (``manpg_problem``) at r = 4, 10 and μ = 0.1, 0.3 from a random start. Writes
``bench/RESULTS_finish.md`` and ``bench/results_finish.json`` (atomically).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # like the other benches: a shared 2-core machine

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # an application: float64

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402

import mesh  # noqa: E402
from bench.environment import header_lines, run_meta, write_results  # noqa: E402
from bench.meshes import load_mesh  # noqa: E402
from objectives.admm.splitting import l1_weights_np  # noqa: E402
from objectives.cmm.modes import compressed_modes, first_eigenpairs, unpack_laplacian  # noqa: E402
from objectives.cmm.solvers import ADMMCMM, BlockCMM  # noqa: E402
from objectives.energy.l1_optimality import l1_stationarity  # noqa: E402
from objectives.cmm.support_finish import SupportFinish, finish_support, true_objective  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ["example:bumpy", "example:starfish", "example:torus"]


def _row(label, n, method, Psi, W, a, w, mu, **extra) -> dict:
    orth = float(np.max(np.abs(Psi.T @ (a[:, None] * Psi) - np.eye(Psi.shape[1]))))
    peak = np.max(np.abs(Psi), axis=0, keepdims=True)
    obj = true_objective(W, w, mu, Psi)
    row = {"mesh": label, "n": n, "method": method, "objective": obj, "exact_zeros": float(np.mean(Psi == 0.0)),
           "below_1e-6": float(np.mean(np.abs(Psi) < 1e-6 * peak)),
           "l1_residual": l1_stationarity(W, a, w, mu, Psi).relative, "orthogonality": orth, **extra}
    print(json.dumps(row), flush=True)
    return row


def measure(spec: str, k: int, finish: SupportFinish) -> list[dict]:
    """A mesh: k modes at μ = 2λ_(k−1), area weights, eigenbasis start."""
    m, label = load_mesh(spec)
    W, a = unpack_laplacian(mesh.laplacian(m))
    pairs = first_eigenpairs(W, a, max(k, 2))
    return measure_problem(label, W, a, k, 2.0 * float(pairs[0][-1]), finish, dict(eigenpairs=pairs))


def manpg_problem(n: int) -> tuple:
    """ManPG's compressed-modes problem (Chen, Ma, So, Zhang, SIAM J. Optim. 2020, §6.1): ``Ĥ = −½Δ``, the periodic
    second-difference Laplacian on ``[0, 50]`` with n points, and ``XᵀX = I`` (A = I, so the area-weighted ℓ1 is
    ``μ‖X‖₁``). Returns ``(W (n, n) csr, a = ones (n,))``."""
    h = 50.0 / n
    e = np.ones(n)
    D = sp.diags([-e[:-1], 2 * e, -e[:-1]], [-1, 0, 1], format="lil")
    D[0, n - 1] = D[n - 1, 0] = -1.0
    return sp.csr_matrix(D / (2.0 * h * h)), np.ones(n)


def measure_problem(label: str, W, a, k: int, mu: float, finish: SupportFinish, start: dict) -> list[dict]:
    w = l1_weights_np(a, "area")
    rows = []
    for name, solver in (("block", BlockCMM()), ("admm", ADMMCMM())):
        r = compressed_modes((W, a), k, mu, solver=solver, **start)
        rows.append(_row(label, len(a), name, r.modes, W, a, w, mu, status=r.status, iterations=r.iterations,
                         seconds=r.wall_time, compile_seconds=r.compile_time))
        f = finish_support(W, a, w, mu, r.modes, finish)
        rows.append(_row(label, len(a), name + " + finish", f.Psi, W, a, w, mu, status=f.status,
                         iterations=r.iterations, newton=f.newton_iterations, cg=f.cg_iterations,
                         w_products=f.w_products, added=f.added, removed=f.removed,
                         seconds=r.wall_time + f.wall_time, finish_seconds=f.wall_time,
                         compile_seconds=r.compile_time))
    admm = next(x["objective"] for x in rows if x["method"] == "admm")
    for x in rows:
        x["vs_admm"] = x["objective"] / admm - 1.0
    return rows


def report(rows: list[dict], meta: dict) -> str:
    lines = ["# Exact-support finish: exact zeros on the true ℓ1 problem", "", *header_lines(meta),
             f"* k = {meta['k']}, μ = 2λ_(k−1), area ℓ1 weights, eigenbasis start; BlockCMM and ADMMCMM defaults; "
             "finish = `finish_support` with `SupportFinish()` defaults on the method's modes",
             "* objective: the true tr(ΨᵀWΨ) + μ Σ a_i|Ψ_ij|; vs ADMM: relative to ADMM's objective on the mesh; "
             "zeros: entries exactly 0; <1e-6: entries below 1e-6 of their column's peak; residual: the exact ℓ1 "
             "stationarity residual (docs/maths.md §9, eq. 9.10), relative; s: solve seconds, compile excluded "
             "(finish: host numpy/scipy, no compilation)", "",
             "| mesh | n | method | objective | vs ADMM | zeros | <1e-6 | residual | orth. | iterations | Newton / CG "
             "| s (finish) | compile s | status |",
             "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        newton = f"{r['newton']} / {r['cg']}" if "newton" in r else ""
        secs = f"{r['seconds']:.1f}" + (f" ({r['finish_seconds']:.1f})" if "finish_seconds" in r else "")
        lines.append(f"| {r['mesh']} | {r['n']} | {r['method']} | {r['objective']:.6f} | {100 * r['vs_admm']:+.3f} % | "
                     f"{r['exact_zeros']:.3f} | {r['below_1e-6']:.3f} | {r['l1_residual']:.1e} | "
                     f"{r['orthogonality']:.0e} | {r['iterations']} | {newton} | {secs} | "
                     f"{r['compile_seconds']:.1f} | {r['status']} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench finish", description=__doc__.splitlines()[0])
    p.add_argument("--meshes", nargs="*", default=EXAMPLES,
                   help="example:NAME, paths or mesh names in ../shared/meshes (default: the generated examples)")
    p.add_argument("-k", type=int, default=10)
    p.add_argument("--manpg", nargs="*", type=int, default=[], metavar="N",
                   help="also ManPG's 1-D compressed-modes problem at these n (r = 4, 10; μ = 0.1, 0.3; random start "
                        "seed 0 for every method), e.g. --manpg 128 512 2048")
    p.add_argument("--out-md", type=Path, default=ROOT / "bench" / "RESULTS_finish.md")
    p.add_argument("--out-json", type=Path, default=ROOT / "bench" / "results_finish.json")
    args = p.parse_args(argv)
    meta = run_meta("bench finish", argv, k=args.k)
    rows = [row for spec in args.meshes for row in measure(spec, args.k, SupportFinish())]
    for n in args.manpg:
        W, a = manpg_problem(n)
        for r in (4, 10):
            for mu in (0.1, 0.3):
                rows += measure_problem(f"ManPG n = {n}, r = {r}, μ = {mu}", W, a, r, mu, SupportFinish(),
                                        dict(start="random", seed=0))
    write_results(args.out_json, args.out_md, meta, rows, report(rows, meta))
    return 0


if __name__ == "__main__":
    sys.exit(main())
