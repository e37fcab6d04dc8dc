"""ADMM's penalty ρ: rules ``"increase"`` vs ``"both"``, both variants, full (Algorithm 3) and fast (Algorithm 8).

    python -m bench.admm_rho                                   # the generated examples (no files needed)
    python -m bench.admm_rho --meshes example:bumpy example:starfish fandisk.off --starts random eigen

For each mesh: k = 10, μ = n/100 (thesis Table 7.1's scale; area ℓ1 weights), a fixed budget of ``--iters``
iterations, the same start for every run of a solver (``random``: seed 0, ρ₀ the solver's default
``objectives.admm.rho.default_rho`` = ``max(μ, 1)``, divided by n for the thesis variant; ``eigen``: the first k
eigenfunctions — restricted ones for the fast method — with ρ₀ = 2λ_(k−1), /n for the thesis variant, as
``ADMMCMM``/``FastCMM`` choose). Rows: solver (``admm``: Algorithm 3; ``fast``: Algorithm 8 on d = n/40 local
functions), variant, rule, ρ₀, the true objective of the final A-orthonormal modes, iterations, status,
seconds, the last primal and dual residuals, the last ρ and how often it was raised and lowered, and the
mean milliseconds per iteration of each step (``ADMMResult.step_times``, thesis Table 7.2). With
``random`` starts the thesis variant is also run at its former ρ₀ = max(μ, 1) (n times too stiff).
Writes ``bench/RESULTS_admm_rho.md`` and ``bench/results_admm_rho.json`` (atomically).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # like the other benches: a shared 2-core machine
if not __package__:  # run as ``python bench/admm_rho.py``: the repository root on the path
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402

import mesh  # noqa: E402
from bench.environment import header_lines, run_meta, write_results  # noqa: E402
from bench.meshes import load_mesh  # noqa: E402
from objectives.admm.splitting import ADMMOptions, admm  # noqa: E402
from objectives.admm.rho import STEPS, penalty_scale  # noqa: E402
from objectives.cmm.modes import first_eigenpairs, unpack_laplacian  # noqa: E402
from objectives.admm.fast import restricted_admm, restricted_eigenbasis  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ["example:bumpy", "example:starfish", "example:torus"]
RULES = ("increase", "both")
VARIANTS = ("exact", "thesis")


def _row(res, **fields) -> dict:
    h = res.history
    rho = np.asarray(h["rho"])
    steps = np.diff(rho)
    it = max(res.iterations, 1)
    row = {**fields, "rho0": res.rho0, "objective": res.objective, "iterations": res.iterations,
           "status": res.status, "seconds": res.wall_time, "primal": float(h["primal"][-1]),
           "dual": float(h["dual"][-1]), "rho_last": float(rho[-1]), "raised": int(np.sum(steps > 0)),
           "lowered": int(np.sum(steps < 0)),
           "ms_per_iteration": {key: 1e3 * res.step_times[key] / it for key in STEPS}}
    print(json.dumps(row), flush=True)
    return row


def measure(spec: str, k: int, iters: int, starts: list[str], samples: int | None) -> list[dict]:
    m, label = load_mesh(spec)
    W, a = unpack_laplacian(mesh.laplacian(m))
    n = len(a)
    mu = n / 100.0
    U = mesh.local_functions(m, n_samples=samples or max(10 * k, n // 40)).U
    d = U.shape[1]
    base = dict(mesh=label, n=n, k=k, mu=mu)
    rows = []
    for start in starts:
        if start == "random":
            X0, Xr = np.random.default_rng(0).standard_normal((n, k)), np.random.default_rng(0).standard_normal((d, k))
            lam = lam_r = None
        else:
            evals, evecs = first_eigenpairs(W, a, max(k, 2))
            X0, lam = evecs[:, :k], 2.0 * float(evals[k - 1])
            evals_r, _, Xr = restricted_eigenbasis(W, sp.diags_array(a), U, max(k, 2))
            Xr, lam_r = Xr[:, :k], 2.0 * float(evals_r[k - 1])
        for variant in VARIANTS:
            scale = penalty_scale(variant, n)
            for rule in RULES:
                opts = ADMMOptions(variant=variant, adapt_rho=rule, max_iters=iters,
                                   rho=None if lam is None else lam * scale)
                rows.append(_row(admm(W, a, k, mu, Psi0=X0, options=opts), **base, solver="admm", start=start,
                                 variant=variant, rule=rule))
            if variant == "thesis" and start == "random":  # the former default ρ₀ = max(μ, 1): n times too stiff
                for rule in RULES:
                    opts = ADMMOptions(variant=variant, adapt_rho=rule, max_iters=iters, rho=max(mu, 1.0))
                    rows.append(_row(admm(W, a, k, mu, Psi0=X0, options=opts), **base, solver="admm", start=start,
                                     variant=variant, rule=f"{rule} (former ρ₀)"))
            for rule in RULES:
                opts = ADMMOptions(variant=variant, adapt_rho=rule, max_iters=iters,
                                   rho=None if lam_r is None else lam_r * scale)
                rows.append(_row(restricted_admm(W, a, U, k, mu, X0=Xr, options=opts), **base, d=d, solver="fast",
                                 start=start, variant=variant, rule=rule))
    return rows


def report(rows: list[dict], meta: dict) -> str:
    lines = ["# ADMM's penalty ρ: increase-only vs two-way residual balancing", "", *header_lines(meta),
             f"* k = {meta['k']}, μ = n/100, area ℓ1 weights, {meta['iters']} iterations at most; admm = Algorithm 3, "
             "fast = Algorithm 8 on d = n/40 local functions; exact = A-norm penalties, thesis = Frobenius "
             "penalties with A ≈ I/n (ρ on a scale n times smaller)",
             "* objective: the true tr(ΨᵀWΨ) + μ Σ a_i|Ψ_ij| of the final A-orthonormal modes (compare within a "
             "mesh, start and solver only); primal / dual: the last residuals in the variant's penalty norm; "
             "↑/↓: how often ρ was raised / lowered; ms/it: mean milliseconds per iteration of the Ψ(X)-, E-, "
             "S-steps, dual+ρ updates, residuals, recorded objective", "",
             "| mesh | n | start | solver | variant | rule | ρ₀ | objective | iterations | status | s | primal | "
             "dual | last ρ | ↑/↓ | ms/it Ψ, E, S, dual, res., obj. |",
             "|---|---:|---|---|---|---|---:|---:|---:|---|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        ms = ", ".join(f"{r['ms_per_iteration'][key]:.2f}" for key in STEPS)
        solver = r["solver"] + (f" (d = {r['d']})" if "d" in r else "")
        lines.append(f"| {r['mesh']} | {r['n']} | {r['start']} | {solver} | {r['variant']} | {r['rule']} | "
                     f"{r['rho0']:.3g} | {r['objective']:.2f} | {r['iterations']} | {r['status']} | "
                     f"{r['seconds']:.1f} | {r['primal']:.1e} | {r['dual']:.1e} | {r['rho_last']:.3g} | "
                     f"{r['raised']}/{r['lowered']} | {ms} |")
    lines += ["", *summary(rows)]
    return "\n".join(lines) + "\n"


def summary(rows: list[dict]) -> list[str]:
    """The rules compared pair by pair (same mesh, start, solver, variant and default ρ₀)."""
    pairs: dict = {}
    for r in rows:
        pairs.setdefault((r["mesh"], r["start"], r["solver"], r["variant"]), {})[r["rule"]] = r
    pairs = {key: v for key, v in pairs.items() if set(RULES) <= set(v)}
    rel = [v["both"]["objective"] / v["increase"]["objective"] - 1.0 for v in pairs.values()]
    conv = {rule: sum(v[rule]["status"] == "converged" for v in pairs.values()) for rule in RULES}
    if not rel:
        return []
    return [f"**Summary** ({len(rel)} pairs: same mesh, start, solver and variant): \"both\" ends lower in "
            f"{sum(x < -1e-5 for x in rel)}, \"increase\" in {sum(x > 1e-5 for x in rel)}, within 1e-5 in "
            f"{sum(abs(x) <= 1e-5 for x in rel)}; the largest difference is {100 * max(map(abs, rel)):.2f} %. "
            f"Converged within the budget: \"increase\" {conv['increase']}, \"both\" {conv['both']}."]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench admm-rho", description=__doc__.splitlines()[0])
    p.add_argument("--meshes", nargs="*", default=EXAMPLES,
                   help="example:NAME, paths or mesh names in ../shared/meshes (default: the generated examples)")
    p.add_argument("-k", type=int, default=10)
    p.add_argument("--iters", type=int, default=2000, help="iteration budget of every run (default 2000)")
    p.add_argument("--starts", nargs="*", default=["random"], choices=["random", "eigen"])
    p.add_argument("--samples", type=int, default=None, help="local functions of the fast method (default n/40)")
    p.add_argument("--out-md", type=Path, default=ROOT / "bench" / "RESULTS_admm_rho.md")
    p.add_argument("--out-json", type=Path, default=ROOT / "bench" / "results_admm_rho.json")
    args = p.parse_args(argv)
    meta = run_meta("bench.admm_rho", argv, k=args.k, iters=args.iters)
    t0 = time.perf_counter()
    rows = [row for spec in args.meshes for row in measure(spec, args.k, args.iters, args.starts, args.samples)]
    meta["seconds"] = time.perf_counter() - t0
    write_results(args.out_json, args.out_md, meta, rows, report(rows, meta))
    return 0


if __name__ == "__main__":
    sys.exit(main())
