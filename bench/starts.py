"""The default's screen of starts (``BlockCMM(starts=4)``) against each of its starts solved alone.

Per mesh problem (``bench.exact``'s meshes and μ panels: cotangent W, lumped A, k = ``--k``, uniform ℓ1 weights), in
one process, on the same inputs:

* ``default``: ``compressed_modes(lap, k, μ)`` with every default — the eigenbasis and 3 rotations of it
  (``objectives.cmm.block_stages.rotated_starts``) through the intermediate smoothing stages, the lowest on to the
  last stage, then the exact-support finish;
* ``alone j``: the same solve from start j only (``BlockCMM(starts=1)``; j = 0 is the eigenbasis, the default before
  the screen), finished.

Reported: each start's finished objective, the best of them, the default's objective against the eigenbasis start's
(the gain of the screen) and the best's (what a perfect pick would give), which start the screen picked, and seconds
(compile apart) with the default's cost over the eigenbasis start's.

    python -m bench starts                                    # the generated meshes
    python -m bench starts --all-shared --out starts          # + every shared mesh (docs/benchmarks/starts.md)
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # benchmark script (an application), not library code

import numpy as np  # noqa: E402

from bench import exact  # noqa: E402
from bench.environment import header_lines, results_path, run_meta, write_results  # noqa: E402
from objectives.cmm.block_stages import rotated_starts  # noqa: E402
from objectives.cmm.modes import compressed_modes, first_eigenpairs  # noqa: E402
from objectives.cmm.solvers import BlockCMM  # noqa: E402

STARTS = 4  # BlockCMM's default


def run_problem(label: str, build, k_starts: int) -> dict:
    W, a, k, mu, weighting, _ = build()
    d = compressed_modes((W, a), k, mu, weighting=weighting)
    _, U = first_eigenpairs(W, a, max(k, 2))
    alone = []
    for j, X0 in enumerate(rotated_starts(U[:, :k], k_starts, 0)):
        r = compressed_modes((W, a), k, mu, weighting=weighting, start="eigen" if j == 0 else X0,
                             solver=BlockCMM(starts=1))
        alone.append(dict(objective=r.objective, status=r.status, iterations=r.iterations, solve=r.wall_time,
                          compile=r.compile_time))
    screened = d.params.get("screened_starts", [])
    chosen = next((c["start"] for c in screened if c["chosen"]), 0)
    best = min(range(len(alone)), key=lambda j: alone[j]["objective"])
    e = alone[0]
    c = max(d.compile_time, e["compile"])
    return dict(problem=label, n=int(a.shape[0]), k=k, mu=mu, objective=d.objective, status=d.status,
                iterations=d.iterations, solve=d.wall_time, compile=d.compile_time, chosen=chosen, best=best,
                screen=[c["objective"] for c in screened], alone=alone,
                gain=d.objective / e["objective"] - 1.0, to_best=d.objective / alone[best]["objective"] - 1.0,
                cost=d.wall_time / e["solve"] if e["solve"] > 0 else None,
                # one compiled program for every start: a fresh process compiles it once, whichever runs
                cost_included=(d.wall_time + c) / (e["solve"] + c))


def report(meta: dict, rows: list[dict]) -> str:
    lines = ["# Screening starts: the default against each of its starts alone", "", *header_lines(meta),
             f"* meshes: k = {meta['k']}, μ = {' and '.join(meta['mu'])}, uniform ℓ1 weights, cotangent W, lumped A; "
             "every solve finished (`SupportFinish()`)",
             "* start 0 = the eigenbasis (the default before the screen), 1–3 = its rotations U·Q; gain = default / "
             "start 0 alone − 1 (negative: lower); to best = default / the best start alone − 1",
             "* seconds compile excluded (finish included); cost = default / start 0 alone, compile excluded; "
             "incl. = the same with the compile time (one program for all starts, compiled by the process's first call) added to both", "",
             "| problem | n | μ | default | status | gain | to best | picked | best | start 0 … 3 alone | "
             "screen objectives | it. | s | cost | incl. |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['problem']} | error: {r['error']} |" + " |" * 13)
            continue
        alone = " / ".join(f"{x['objective']:.6g}" for x in r["alone"])
        screen = " / ".join(f"{x:.6g}" for x in r["screen"])
        lines.append(f"| {r['problem']} | {r['n']} | {r['mu']:.3g} | {r['objective']:.10g} | {r['status']} | "
                     f"{r['gain']:+.1e} | {r['to_best']:+.1e} | {r['chosen']} | {r['best']} | {alone} | {screen} | "
                     f"{r['iterations']} | {r['solve']:.1f} | {r['cost']:.2f} | {r['cost_included']:.2f} |")
    ok = [r for r in rows if "error" not in r]
    if ok:
        lower = sum(r["gain"] < -1e-6 for r in ok)
        higher = [r for r in ok if r["gain"] > 1e-6]
        worst = max(ok, key=lambda r: r["gain"])
        costs = np.array([r["cost"] for r in ok])
        lines += ["", f"Lower than the eigenbasis start alone (by more than 1e-6): {lower} of {len(ok)}; higher: "
                  f"{len(higher)} (largest {worst['gain']:+.1e}, {worst['problem']}); within 1e-4 of the best start "
                  f"alone: {sum(r['to_best'] <= 1e-4 for r in ok)} of {len(ok)}. Cost (compile excluded): median "
                  f"{np.median(costs):.2f}×, {costs.min():.2f}–{costs.max():.2f}×; in all "
                  f"{sum(r['solve'] for r in ok):.0f} s against {sum(r['alone'][0]['solve'] for r in ok):.0f} s."]
    return "\n".join(lines) + "\n"


def parse(argv):
    p = argparse.ArgumentParser(prog="python -m bench starts", description=__doc__.split("\n\n")[0])
    p.add_argument("--mesh", nargs="*", default=list(exact.GENERATED), help="meshes (default: the generated examples)")
    p.add_argument("--all-shared", action="store_true", help="add every loadable mesh of ../shared/meshes")
    p.add_argument("--k", type=int, default=10)
    p.add_argument("--mu", type=exact.parse_mu, nargs="+", default=[exact.parse_mu(x) for x in exact.DEFAULT_MUS],
                   help="μ in the CLI's forms, each a panel (default: 0.01n 2λ)")
    p.add_argument("--out", default="starts", help="results name under docs/benchmarks (default starts)")
    args = p.parse_args(argv)
    if args.all_shared:
        args.mesh += [s for s in exact.shared_meshes() if s not in exact.LOADS_NOT]
    exact.require(args.mesh)
    args.rpn, args.manpg, args.manpg_r, args.manpg_mu = [], [], [], []  # meshes only: the Schrödinger cases start from a given array (no screen)
    return args


def main(argv=None) -> int:
    args = parse(argv)
    meta = run_meta("bench starts", argv, k=args.k, mu=[m.text for m in args.mu], starts=STARTS)
    rows = []
    for label, _, build in exact.problems(args):
        try:
            row = run_problem(label, build, STARTS)
        except Exception as e:  # noqa: BLE001 — a problem that fails is a row with its error; the others still run
            row = dict(problem=label, error=f"{type(e).__name__}: {e}"[:200])
        rows.append(row)
        print({k: row.get(k) for k in ("problem", "objective", "gain", "to_best", "chosen", "best", "cost", "error")
               if k in row}, flush=True)
    meta["problems_done"] = f"{len(rows)} of {len(rows)}"
    write_results(results_path(args.out, ".json"), results_path(args.out), meta, rows, report(meta, rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
