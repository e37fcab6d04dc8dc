"""The default CMM answer — exactly sparse and certified — against ADMM and the previous (smoothed) default.

Each problem is solved twice, in one process, on the same inputs:

* ``default``: ``compressed_modes(lap, k, μ)`` with every default (``BlockCMM()`` on the smoothed energy, then the
  exact-support finish ``SupportFinish()``, status derived from the exact ℓ1 residual). Its record also gives the
  previous default's answer: the smoothed modes before the finish (``finish["objective_before"]``);
* ``admm``: ``compressed_modes(..., solver=ADMMCMM(time_limit=--admm-time))``, the project's ADMM as a user gets it
  (finished and certified like the default: its own iterate has no exact zeros).

Problems: meshes (cotangent W, lumped A, unit area; k = ``--k``, one panel per form of ``--mu``, read as
``stiefel modes --mu`` reads it: ``0.01n`` — the configuration the held-out beetle/face runs used — and ``2λ``, the
command's default; uniform ℓ1 weights; from the first k eigenfunctions) and ManPG's 1-D compressed-modes
problem (Chen, Ma, So, Zhang 2020, §6.1; ``bench.suite_methods.manpg_problem``; ``μ‖X‖₁``, one random orthonormal
start, seed 0, shared by both methods) for every n of ``--manpg``, r of ``--manpg-r`` and μ of ``--manpg-mu``
(ManPG's 24 cases: n = 128 … 4096, r = 4, 10, μ = 0.1, 0.3), and RPN-CG's cases (Si & Huang; ``--rpn``: n = 64 …
512, r = 5, μ = 0.1).

Per problem: objectives (default, previous default, ADMM) and the relative gaps to ADMM; exact zeros, the exact ℓ1
stationarity residual (docs/maths.md §9, relative) and status of each; the block solver's iterations, the finish's
Newton and CG iterations; seconds compile apart (``compile``), solve (compile excluded) and total, for the default and
ADMM, with their ratio. The finish's residual per Newton iterate (gradient on the support and the zeros' violation,
relative to the scale of eq. 9.10) is tabled for the problems named by ``--trace`` (default: the first three meshes
and the first RPN-CG case).

    python -m bench exact                                     # generated meshes, ManPG n = 128, 256, RPN n = 64, 128
    python -m bench exact --all-shared --manpg 128 256 512 1024 2048 4096 --rpn 64 128 256 512

Writes ``docs/benchmarks/<--out>.md`` and ``.json`` (committed: ``exact-meshes``, ``exact-schrodinger``) when every
problem is done (atomically, notes kept): an interrupted run never replaces the committed page (the rows are printed as
they come).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # benchmark script (an application), not library code

import numpy as np  # noqa: E402

import mesh  # noqa: E402
from bench.environment import header_lines, results_path, run_meta, write_results  # noqa: E402
from bench.meshes import load_mesh, require  # noqa: E402
from bench.suite import shared_meshes  # noqa: E402
from bench.suite_methods import manpg_problem  # noqa: E402
from objectives.cmm.modes import compressed_modes, first_eigenpairs  # noqa: E402
from objectives.cmm.solvers import ADMMCMM  # noqa: E402
from stiefel_cmm.cli.outputs import parse_mu  # noqa: E402

GENERATED = ("example:bumpy", "example:starfish", "example:torus", "example:patch")
LOADS_NOT = ("cube_40k.obj",)  # bad input by design (non-manifold volume faces): rejected, not a problem
#: the meshes' μ panels: the held-out beetle/face runs' setting and the command's default (``stiefel modes``)
DEFAULT_MUS = ("0.01n", "2λ")


def problems(args):
    """Yield ``(label, kind, build)`` — RPN-CG's cases, ManPG's, then the meshes; ``build()`` returns
    ``(W, a, k, mu, weighting, start)``."""
    for group, ns, rs, mus in (("rpn", args.rpn, (5,), (0.1,)), ("manpg", args.manpg, args.manpg_r, args.manpg_mu)):
        for n in ns:
            for r in rs:
                for mu in mus:
                    def build(n=n, r=r, mu=mu):
                        W, a = manpg_problem(n)
                        return W, a, r, mu, "area", "random"
                    yield f"{group}:{n}:{r}:{mu}", group, build
    for spec in args.mesh:
        for mu_spec in args.mu:
            def build(spec=spec, mu_spec=mu_spec):
                m, _ = load_mesh(spec)
                lap = mesh.laplacian(m)
                W, a = lap.W, lap.A.diagonal()
                lam = float(first_eigenpairs(W, a, max(args.k, 2))[0][-1]) if mu_spec.unit == "λ" else None
                return W, a, args.k, mu_spec.resolve(m.n_vertices, lam), "uniform", "eigen"
            yield (spec if len(args.mu) == 1 else f"{spec} @ {mu_spec.text}"), "mesh", build


def run_problem(label: str, kind: str, build, args) -> dict:
    W, a, k, mu, weighting, start = build()
    kw = dict(weighting=weighting, start=start, seed=0)
    t0 = time.perf_counter()
    d = compressed_modes((W, a), k, mu, **kw)
    d_total = time.perf_counter() - t0
    t0 = time.perf_counter()
    ad = compressed_modes((W, a), k, mu, solver=ADMMCMM(time_limit=args.admm_time), **kw)
    a_total = time.perf_counter() - t0
    fin = d.finish or {}
    prev = fin.get("objective_before", d.objective)
    return dict(
        problem=label, kind=kind, n=int(a.shape[0]), k=k, mu=mu, weighting=weighting, start=start,
        objective=d.objective, previous=prev, admm=ad.objective,
        gap=d.objective / ad.objective - 1.0, previous_gap=prev / ad.objective - 1.0,
        status=d.status, residual=d.l1_residual, zeros=d.exact_zeros, orthogonality=d.orthogonality,
        iterations=d.iterations, newton=fin.get("newton_iterations"), cg=fin.get("cg_iterations"),
        finish_status=fin.get("finish_status"), finish_seconds=fin.get("wall_time"),
        compile=d.compile_time, solve=d.wall_time, total=d_total,
        admm_previous=(ad.finish or {}).get("objective_before", ad.objective), admm_status=ad.status,
        admm_residual=ad.l1_residual, admm_zeros=ad.exact_zeros, admm_iterations=ad.iterations,
        admm_solve=ad.wall_time, admm_total=a_total,
        speed=a_total / d_total if d_total > 0 else None,
        speed_excluded=ad.wall_time / d.wall_time if d.wall_time > 0 else None,
        trace=(fin.get("trace") or {}).get("rows", []))


def _mus(meta: dict) -> str:
    """The meshes' μ forms (results written before ``--mu`` recorded ``mu_factor``)."""
    return " and ".join(meta["mu"]) if "mu" in meta else f"{meta['mu_factor']}·n"


def _g(x, fmt=".3g"):
    return "—" if x is None else format(x, fmt)


def report(meta: dict, rows: list[dict], traced: list[str]) -> str:
    lines = ["# The exactly sparse default against ADMM and the previous default", "", *header_lines(meta),
             f"* problems measured: {meta.get('problems_done', len(rows))}",
             f"* meshes: k = {meta['k']}, μ = {_mus(meta)} (λ = λ_(k−1), as `stiefel modes --mu` reads them), "
             "uniform ℓ1 weights, eigenfunction start; "
             "ManPG / RPN-CG: μ‖X‖₁, random orthonormal start (seed 0)",
             f"* ADMM: `ADMMCMM(time_limit={meta['admm_time']})` with the default finish (as a user gets it)",
             "* gap = objective / ADMM's − 1 (negative: lower than ADMM); previous = the smoothed modes before the "
             "finish (the default before it finished); residual: exact ℓ1 stationarity (9.10), relative",
             "* seconds: compile / solve (compile excluded, finish included) / whole call; speed = ADMM's whole call / "
             "the default's (compile included), excl. = the same compile excluded", "",
             "| problem | n | k | μ | objective | gap | previous gap | status | residual | zeros | ADMM status | "
             "block it. | Newton / CG | compile | solve | total | ADMM it. | ADMM s | speed | excl. |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['problem']} | error: {r['error']} |" + " |" * 18)
            continue
        lines.append(
            f"| {r['problem']} | {r['n']} | {r['k']} | {_g(r['mu'])} | {r['objective']:.10g} | {r['gap']:+.1e} | "
            f"{r['previous_gap']:+.1e} | {r['status']} | {r['residual']:.1e} | {r['zeros']:.3f} | "
            f"{r['admm_status']} | {r['iterations']} | {_g(r['newton'], 'd')} / {_g(r['cg'], 'd')} | "
            f"{r['compile']:.1f} | {r['solve']:.1f} | {r['total']:.1f} | {r['admm_iterations']} | "
            f"{r['admm_total']:.1f} | {_g(r['speed'], '.2f')} | {_g(r['speed_excluded'], '.2f')} |")
    ok = [r for r in rows if "error" not in r]
    if ok:
        worst = max(ok, key=lambda r: r["gap"])
        conv = sum(r["status"] == "converged" for r in ok)
        lines += ["", f"Converged (residual ≤ 1e-8): {conv} of {len(ok)}. Largest gap to ADMM: {worst['gap']:+.1e} "
                  f"({worst['problem']}); at or below ADMM × (1 + 1e-4): {sum(r['gap'] <= 1e-4 for r in ok)} of "
                  f"{len(ok)}; default faster than ADMM (compile included): "
                  f"{sum((r['speed'] or 0) > 1 for r in ok)} of {len(ok)}."]
    for r in ok:
        if r["problem"] not in traced or not r["trace"]:
            continue
        lines += ["", f"### The finish's iterates: {r['problem']}", "",
                  "| Newton it. | objective | ‖grad‖ on support | zeros' violation | support | CG |", "|---|---|---|---|---|---|"]
        for i, (f, g, v, s, c) in enumerate(r["trace"]):
            lines.append(f"| {i} | {f:.12g} | {g:.1e} | {v:.1e} | {int(s)} | {int(c)} |")
    return "\n".join(lines) + "\n"


def parse(argv):
    p = argparse.ArgumentParser(prog="python -m bench exact", description=__doc__.split("\n\n")[0])
    p.add_argument("--mesh", nargs="*", default=list(GENERATED), help="meshes (default: the generated examples)")
    p.add_argument("--all-shared", action="store_true", help="add every loadable mesh of ../shared/meshes")
    p.add_argument("--k", type=int, default=10)
    p.add_argument("--mu", type=parse_mu, nargs="+", default=[parse_mu(x) for x in DEFAULT_MUS],
                   help="meshes: μ in the CLI's forms, each a panel (default: 0.01n 2λ — the held-out runs' "
                        "setting and the command's default)")
    p.add_argument("--manpg", type=int, nargs="*", default=[128, 256], help="ManPG problem sizes n")
    p.add_argument("--manpg-r", type=int, nargs="*", default=[4, 10])
    p.add_argument("--manpg-mu", type=float, nargs="*", default=[0.1, 0.3])
    p.add_argument("--rpn", type=int, nargs="*", default=[64, 128], help="RPN-CG's sizes n (r = 5, μ = 0.1)")
    p.add_argument("--admm-time", type=float, default=300.0, help="ADMM's time limit per problem (s)")
    p.add_argument("--trace", nargs="*", default=None, help="problems whose finish iterates are tabled")
    p.add_argument("--out", default="exact", help="results name under docs/benchmarks (default exact)")
    args = p.parse_args(argv)
    if args.all_shared:
        args.mesh += [s for s in shared_meshes() if s not in LOADS_NOT]
    require(args.mesh)
    return args


def main(argv=None) -> int:
    args = parse(argv)
    meta = run_meta("bench exact", argv, k=args.k, mu=[m.text for m in args.mu], admm_time=args.admm_time)
    rows = []
    for label, kind, build in problems(args):
        try:
            row = run_problem(label, kind, build, args)
        except Exception as e:  # noqa: BLE001 — a problem that fails is a row with its error; the others still run
            row = dict(problem=label, kind=kind, error=f"{type(e).__name__}: {e}"[:200])
        rows.append(row)
        print({k: row.get(k) for k in ("problem", "n", "objective", "gap", "previous_gap", "status", "residual",
                                       "zeros", "total", "admm_total", "error") if k in row}, flush=True)
    meta["problems_done"] = f"{len(rows)} of {len(rows)}"
    meshes = [r["problem"] for r in rows if r["kind"] == "mesh"][:3]
    rpn = [r["problem"] for r in rows if r["kind"] == "rpn"][:1]
    traced = args.trace if args.trace is not None else meshes + rpn
    write_results(results_path(args.out, ".json"), results_path(args.out), meta, rows, report(meta, rows, traced))
    return 0


if __name__ == "__main__":
    sys.exit(main())
