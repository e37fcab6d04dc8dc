"""Benchmark suite: every CMM solver side by side, in one process, on the same inputs.

Each problem — a mesh (cotangent W, lumped A, unit area; k, μ = ``--mu-factor``·n, uniform ℓ1 weighting, the first
k eigenfunctions as start) or ManPG's 1-D compressed-modes problem (``--manpg N …``: Chen, Ma, So, Zhang, SIAM J.
Optim. 2020, §6.1; ``Ĥ = −½Δ`` periodic on [0, 50], ``XᵀX = I``, r = 4, 10, μ = 0.1, 0.3, ℓ1 = μ‖X‖₁, one random
start shared by every method) — is solved by (``bench.suite_methods``):

* manifold solvers on the smoothed energy (Huber f6, δ = 1e-3) with the ``(W + σA)⁻¹`` preconditioner, σ = λ_(k−1):
  block Riemannian CG with the Cholesky, Cayley and polar retractions, block L-BFGS and Barzilai–Borwein
  (Cholesky), block CG with the active-set preconditioner, the thesis's sequential solver (Algorithm 6);
* the library's default ``BlockCMM()`` (continuation stages, saddle checks; ``block-default``) and the same followed
  by the exact-support finish (``SupportFinish()``: exact zeros on the true ℓ1 problem; ``block-default-finish``);
* ADMM (ρ₀ = 3λ_(k−1), increase-only), the fast approximation (meshes only: its local functions live on the
  surface) and the penalty baseline (``stiefel.penalty_minimize``: jaxopt L-BFGS on F + ρ‖XᵀAX − I‖², projected);
* at μ = 0: ``eigsh`` shift-invert (reference) and block CG from a random start.

For each: median wall time over ``--repeats`` runs (compilation apart, from the first run), iterations, status,
the true objective ``tr(ΨᵀWΨ) + μΣ w_i|Ψ_ij|`` and the smoothed one (after exact A-orthonormalisation), the
fraction of exact zeros, of entries below 1e-6 of their column's peak, the per-mode support sizes, the relative
exact ℓ1 stationarity residual (docs/maths.md §9), ``max|ΨᵀAΨ − I|`` of the method's own output, the first time
within 1e-3 of the best objective over the μ > 0 methods, and the ratios to ADMM (objective, and speed compile
excluded and included). Memory (unless ``--no-memory``), in one extra untimed run: tracemalloc's peak and the RSS
high-water increase (reset through ``/proc/self/clear_refs``; XLA buffers included).

    python -m bench suite                                    # example:starfish, every method, 3 repeats
    python -m bench suite --mesh bunny.off fandisk.off --repeats 1 --methods block-default admm
    python -m bench suite --all-shared --manpg 128 512 2048 8192 --repeats 1 --no-memory

A mesh file that does not exist stops the run before anything is measured; a mesh that cannot be loaded (e.g.
rejected bad input) is listed with its error. Writes ``docs/benchmarks/suite.json`` and ``docs/benchmarks/suite.md``
when every problem is done (atomically; notes below a ``<!-- notes -->`` line of the existing page are kept); on a
GPU machine the JAX parts run there (see ``docs/benchmarks/gpu.md``).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
from pathlib import Path

# One BLAS thread (see bench/bench_mesh.py); an explicit setting in the environment wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # benchmark script (an application), not library code

import numpy as np  # noqa: E402
import scipy  # noqa: E402

import mesh  # noqa: E402
from bench.environment import git_commit, results_path, write_json, write_page  # noqa: E402
from bench.meshes import SHARED, MeshNotFound, load_mesh, require  # noqa: E402
from bench.suite_methods import METHODS, MU0, NEEDS_MESH, Problem, manpg_problem, measure  # noqa: E402
from stiefel.linalg.sparse_factor import default_backend  # noqa: E402

REL = 1e-3
MESH_SUFFIXES = (".obj", ".off", ".ply", ".stl")


def first_time_within(times, values, target, rel=REL):
    values = np.asarray(values, dtype=float)
    ok = np.nonzero(values <= target + rel * abs(target))[0]
    return float(np.asarray(times)[ok[0]]) if ok.size else None


def _downsample(times, values, max_points=400):
    times, values = np.asarray(times, dtype=float), np.asarray(values, dtype=float)
    if times.size > max_points:
        idx = np.unique(np.r_[np.linspace(0, times.size - 1, max_points).astype(int), times.size - 1])
        times, values = times[idx], values[idx]
    return {"time": times.tolist(), "objective": values.tolist()}


def shared_meshes() -> list[str]:
    """Every mesh file in ``../shared/meshes`` (the developers' test meshes), smallest file first."""
    if not SHARED.is_dir():
        raise MeshNotFound(f"--all-shared: {SHARED} does not exist (it sits beside the repository on the "
                                "developers' machines only)")
    files = [p for p in SHARED.iterdir() if p.suffix.lower() in MESH_SUFFIXES]
    return [p.name for p in sorted(files, key=lambda p: p.stat().st_size)]


def problems(args):
    """Yield ``(label, build)`` per problem; ``build()`` returns a ``Problem`` or raises (bad input)."""
    for spec in args.mesh:
        def build(spec=spec):
            m, name = load_mesh(spec)
            lap = mesh.laplacian(m, weights="cotangent", area="lumped")
            return Problem(name, lap.W, lap.A.diagonal(), args.k, args.mu_factor * m.n_vertices, args, m=m)
        yield spec, build
    for n in args.manpg:
        for r in args.manpg_r:
            for mu in args.manpg_mu:
                def build(n=n, r=r, mu=mu):
                    W, a = manpg_problem(n)
                    return Problem(f"ManPG n = {n}, r = {r}, μ = {mu}", W, a, r, mu, args, weighting="area",
                                   start="random")
                yield f"manpg:{n}:{r}:{mu}", build


def run_problem(pb: Problem, args) -> dict:
    rows = {}
    for meth in args.methods:
        if meth in NEEDS_MESH and pb.m is None:
            continue
        row = measure(pb, meth, args.repeats, memory=not args.no_memory)
        rows[meth] = row
        print(json.dumps({"problem": pb.label, "method": meth, **{k: row[k] for k in (
            "wall_time", "compile_time", "iterations", "objective", "exact_zeros", "orthogonality", "status")}}),
            flush=True)
    pos = [r for mth, r in rows.items() if mth not in MU0 and not r.get("failed")]
    target = min([min(np.nanmin(np.asarray(c[1], dtype=float)) for c in r["_curves"]) for r in pos]
                 + [r["objective"] for r in pos]) if pos else None
    ref0 = rows["eigsh"]["objective"] if "eigsh" in rows else None
    admm = rows.get("admm")
    for mth, r in rows.items():
        tgt = ref0 if mth in MU0 else target
        curves = r.pop("_curves")
        if r.get("failed"):
            r.update(target=tgt, time_to_target=None, time_to_target_runs=[], relative_gap=None,
                     curve={"time": [], "objective": []})
            continue
        ts = [first_time_within(c[0], c[1], tgt) for c in curves] if tgt is not None else []
        ok = [t for t in ts if t is not None]
        r["target"] = tgt
        r["time_to_target"] = float(np.median(ok)) if ok and len(ok) == len(ts) else None
        r["time_to_target_runs"] = ts
        r["relative_gap"] = (r["objective"] - tgt) / abs(tgt) if tgt else None
        r["curve"] = _downsample(*r["curve"])
        if admm is not None and not admm.get("failed") and mth not in MU0:
            r["vs_admm"] = r["objective"] / admm["objective"] - 1.0
            r["speed_vs_admm"] = admm["wall_time"] / r["wall_time"] if r["wall_time"] > 0 else None
            total = r["wall_time"] + r["compile_time"]
            r["speed_vs_admm_with_compile"] = (admm["wall_time"] + admm["compile_time"]) / total if total > 0 else None
    setup = {"problem": pb.label, "n": pb.n, "nnz_W": int(pb.W.nnz), "k": pb.k, "mu": pb.mu,
             "weighting": pb.weighting, "start": pb.start, "n_faces": pb.m.n_faces if pb.m is not None else None,
             "eigenbasis_seconds": pb.eig_seconds, "preconditioner_factor_seconds": pb.factor_seconds,
             "local_functions_seconds": pb.lf_seconds, "sigma": pb.sigma, "lambda_k": float(pb.evals[-1]),
             "target_objective": target, "mu0_reference": ref0}
    return {"setup": setup, "rows": rows}


def run_suite(args) -> list[dict]:
    """Every problem in turn (a problem whose input is rejected becomes a row with its error)."""
    out = []
    for label, build in problems(args):
        try:
            pb = build()
        except Exception as e:  # noqa: BLE001 — bad input is reported, the other problems still run
            out.append({"setup": {"problem": label}, "error": f"{type(e).__name__}: {e}", "rows": {}})
            print(json.dumps({"problem": label, "error": out[-1]["error"]}), flush=True)
            continue
        out.append(run_problem(pb, args))
    return out


def metadata(argv) -> dict:
    import equinox
    import jaxlib

    dev = jax.devices()[0]
    cpu = platform.processor()
    if os.path.exists("/proc/cpuinfo"):
        cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), cpu)
    backend = jax.default_backend()
    return {"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": f"{cpu}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()}",
            "commit": git_commit(),
            "load_average_at_start": os.getloadavg()[0],
            "versions": {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__,
                         "jax": jax.__version__, "jaxlib": jaxlib.__version__, "equinox": equinox.__version__},
            "jax_backend": backend, "device": str(dev), "device_kind": getattr(dev, "device_kind", None),
            "gpu": backend == "gpu",
            "note": None if backend == "gpu" else "no GPU in this session: CPU only",
            "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS"), "x64": bool(jax.config.jax_enable_x64),
            "command": "python -m bench suite " + " ".join(argv if argv is not None else sys.argv[1:])}


def _f(v, fmt="{:.2f}"):
    return "–" if v is None else fmt.format(v)


def _pct(v):
    return "–" if v is None else f"{100 * v:+.3f} %"


def _x(v):
    return "–" if v is None else f"{v:.2f}×"


def summary_table(results: list[dict]) -> list[str]:
    """One line per problem: the default (and finished) against ADMM, the lowest objective and who reached it."""
    out = ["| problem | n | k | μ | ADMM objective | default vs ADMM | default + finish vs ADMM | zeros: default + "
           "finish / ADMM | speed vs ADMM (default; excl. / incl. compile) | lowest objective by |",
           "|---|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for res in results:
        s, rows = res["setup"], res["rows"]
        if "error" in res:
            out.append(f"| {s['problem']} | – | – | – | – | – | – | – | – | not run: {res['error']} |")
            continue
        admm, dflt, fin = rows.get("admm"), rows.get("block-default"), rows.get("block-default-finish")
        pos = {m: r for m, r in rows.items() if m not in MU0 and not r.get("failed")}
        best = min(pos, key=lambda m: pos[m]["objective"]) if pos else None
        zeros = f"{_f(fin and fin['exact_zeros'], '{:.3f}')} / {_f(admm and admm['exact_zeros'], '{:.3f}')}"
        speed = (f"{_x(dflt.get('speed_vs_admm'))} / {_x(dflt.get('speed_vs_admm_with_compile'))}" if dflt else "–")
        out.append(f"| {s['problem']} | {s['n']} | {s['k']} | {s['mu']:.4g} | {_f(admm and admm['objective'], '{:.4f}')} "
                   f"| {_pct(dflt and dflt.get('vs_admm'))} | {_pct(fin and fin.get('vs_admm'))} | {zeros} | {speed} "
                   f"| {best} |")
    return out


def problem_table(res: dict, memory: bool) -> list[str]:
    s, rows = res["setup"], res["rows"]
    mib = 2.0**20
    out = [f"### {s['problem']}", "",
           f"n = {s['n']}, nnz(W) = {s['nnz_W']}, k = {s['k']}, μ = {s['mu']:.4g}, {s['weighting']} ℓ1 weights, "
           f"{s['start']} start; setup (not in the times): eigenbasis {s['eigenbasis_seconds']:.2f} s, "
           f"(W + σA) factorisation {s['preconditioner_factor_seconds']:.2f} s (σ = {s['sigma']:.4g}), local "
           f"functions {_f(s['local_functions_seconds'])} s; target = {_f(s['target_objective'], '{:.6f}')}, "
           f"μ = 0 reference (Σλ) = {_f(s['mu0_reference'], '{:.6f}')}", "",
           "| method | its | status | s | to target s | compile s | true objective | smoothed | vs ADMM | zeros "
           "| <1e-6 | support (median) | ℓ1 residual | orth. | speed vs ADMM (excl. / incl. compile) |"
           + (" tracemalloc MiB | peak-RSS increase MiB | device peak MiB |" if memory else ""),
           "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|" + ("---:|---:|---:|" if memory else "")]
    for mth, r in rows.items():
        label = mth + (f" (d = {r['d']})" if "d" in r else "")
        sup = int(np.median(r["support_sizes"])) if r.get("support_sizes") else None
        speed = f"{_x(r.get('speed_vs_admm'))} / {_x(r.get('speed_vs_admm_with_compile'))}" if "speed_vs_admm" in r \
            else "–"
        dev = (r.get("device_memory_after") or {}).get("peak_bytes_in_use")
        line = (f"| {label} | {_f(r['iterations'], '{:d}')} | {r['status']} | {r['wall_time']:.2f} | "
                f"{_f(r['time_to_target'])} | {r['compile_time']:.2f} | {r['objective']:.6f} | "
                f"{r['smoothed_objective']:.6f} | {_pct(r.get('vs_admm'))} | {r['exact_zeros']:.3f} | "
                f"{r['below_1e-6']:.3f} | {_f(sup, '{:d}')} | {_f(r['l1_residual'], '{:.1e}')} | "
                f"{r['orthogonality']:.1e} | {speed} |")
        if memory:
            line += (f" {_f(r.get('tracemalloc_peak_bytes', 0) / mib, '{:.1f}')} | "
                     f"{_f(r.get('peak_rss_increase_bytes') and r['peak_rss_increase_bytes'] / mib, '{:.1f}')} | "
                     f"{_f(dev and dev / mib, '{:.1f}')} |")
        out.append(line)
    return out + [""]


def markdown(meta, results, args) -> str:
    out = ["# Benchmark suite: CMM solvers side by side (generated by `python -m bench suite`)", "", "## Recipe", "",
           f"* date: {meta['date']}; commit: {meta.get('commit', 'unknown')}",
           f"* machine: {meta['machine']} (load average at start {meta['load_average_at_start']:.1f}; "
           "other jobs shared the cores, seconds are noisy)",
           "* versions: " + ", ".join(f"{k} {v}" for k, v in meta["versions"].items()),
           f"* JAX backend: {meta['jax_backend']}, device `{meta['device']}` ({meta['device_kind']})"
           + (f"; {meta['note']}" if meta["note"] else ""),
           f"* OPENBLAS_NUM_THREADS={meta['openblas_threads']}, float64 (x64 on); sparse factor backend "
           f"{default_backend()}",
           f"* command: `{meta['command']}`",
           f"* meshes: cotangent W, lumped A (unit area), μ = {args.mu_factor}·n, uniform ℓ1 weights (w = 1/n), "
           "start: the first k eigenfunctions (fast: its restricted eigenbasis); ManPG: W = Ĥ, A = I, ℓ1 = μ‖X‖₁, "
           f"one random start (seed {args.seed}) for every method; block CG at μ = 0: random start",
           f"* manifold solvers: Huber f6 δ = 1e-3, gtol {args.gtol}, ftol {args.ftol}, at most {args.max_iters} "
           f"iterations (sequential: {args.seq_iters} per column); ADMM and fast: ρ₀ = {args.rho_factor}·λ_(k−1) "
           f"(increase-only), at most {args.admm_iters} iterations or {args.admm_time} s; fast: {args.fast_samples} "
           f"samples; penalty: ρ = {args.penalty_rho}·λ_(k−1)·(1, 10, 100), {max(1, args.max_iters // 3)} L-BFGS "
           "iterations per stage, tol = gtol",
           f"* times: median of {args.repeats} run(s), compilation apart (first run); s includes the finish's host "
           "seconds; \"to target\" = first time within 1e-3 (relative) of the best objective over the μ > 0 methods; "
           "vs ADMM: true objective relative to ADMM's; speed vs ADMM: ADMM's seconds / the method's (> 1: faster), "
           "without and with compilation; zeros: entries exactly 0; <1e-6: below 1e-6 of the column's peak; support: "
           "nonzero entries per mode; ℓ1 residual: docs/maths.md §9, relative",
           "", "## Summary", "", *summary_table(results), "", "## Problems", ""]
    memory = not args.no_memory
    for res in results:
        if "error" in res:
            out += [f"### {res['setup']['problem']}", "", f"Not run: {res['error']}", ""]
        else:
            out += problem_table(res, memory)
    out += ["Objective-vs-seconds curves of every run are in `suite.json` (`problems[i].rows.<method>.curve`;"
            " the block solvers' times are interpolated linearly over their iterations; the sequential solver, the "
            "penalty and eigsh have only their final point).", ""]
    return "\n".join(out)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mesh", nargs="*", default=None,
                   help="example:NAME (generated), 'demo', paths, or mesh names in ../shared/meshes "
                        "(default: example:starfish unless --all-shared or --manpg)")
    p.add_argument("--all-shared", action="store_true", help="every mesh in ../shared/meshes (developers only)")
    p.add_argument("--manpg", nargs="*", type=int, default=[], metavar="N",
                   help="ManPG's 1-D problem at these n (each with every --manpg-r and --manpg-mu)")
    p.add_argument("--manpg-r", nargs="+", type=int, default=[4, 10], metavar="R")
    p.add_argument("--manpg-mu", nargs="+", type=float, default=[0.1, 0.3], metavar="MU")
    p.add_argument("-k", type=int, default=10)
    p.add_argument("--mu-factor", type=float, default=0.01)
    p.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--gtol", type=float, default=1e-6)
    p.add_argument("--gtol-mu0", type=float, default=1e-8)
    p.add_argument("--ftol", type=float, default=1e-7)
    p.add_argument("--max-iters", type=int, default=1500)
    p.add_argument("--seq-iters", type=int, default=300)
    p.add_argument("--rho-factor", type=float, default=3.0)
    p.add_argument("--penalty-rho", type=float, default=1.0, help="the penalty's first ρ in units of λ_(k−1)")
    p.add_argument("--admm-iters", type=int, default=10**6)
    p.add_argument("--admm-time", type=float, default=30.0)
    p.add_argument("--fast-samples", type=int, default=500, help="d, the number of local functions")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-memory", action="store_true", help="skip the extra tracemalloc run per method")
    p.add_argument("--out-json", type=Path, default=None, help="default: docs/benchmarks/suite.json")
    p.add_argument("--out-md", type=Path, default=None, help="default: docs/benchmarks/suite.md")
    p.add_argument("--render", nargs="+", default=None, metavar="JSON",
                   help="only re-render --out-md from these results JSONs (several: also combined into --out-json)")
    args = p.parse_args(argv)
    args.out_json = args.out_json or results_path("suite", ".json")
    args.out_md = args.out_md or results_path("suite")
    if args.render:  # re-render the markdown from results JSONs (several: their problems in turn, the first's recipe)
        saved = [json.loads(Path(f).read_text()) for f in args.render]
        meta = dict(saved[0]["meta"])
        if len(saved) > 1:
            meta["command"] = " ; ".join(s["meta"]["command"] for s in saved)
        problems_ = [p for s in saved for p in s["problems"]]
        shown = argparse.Namespace(**saved[0]["params"])
        if len(saved) > 1:
            write_json(args.out_json, {"meta": meta, "params": saved[0]["params"], "problems": problems_}, indent=None)
        write_page(args.out_md, markdown(meta, problems_, shown))
        return 0
    if args.repeats < 1:
        p.error("--repeats must be ≥ 1")
    meshes = list(args.mesh or [])
    if args.all_shared:
        meshes += [m for m in shared_meshes() if m not in meshes]
    if not meshes and not args.manpg:
        meshes = ["example:starfish"]
    require(meshes)
    args.mesh = meshes
    meta = metadata(argv)
    params = {k: v for k, v in vars(args).items() if k not in ("out_json", "out_md", "render")}
    results = run_suite(args)
    md = markdown(meta, results, args)
    write_json(args.out_json, {"meta": meta, "params": params, "problems": results}, indent=None)
    write_page(args.out_md, md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
