"""Benchmark suite (issue 7): every CMM solver side by side, in one process, on the same inputs.

One mesh (cotangent W, lumped A, unit area), one k and μ (= ``--mu-factor``·n), uniform ℓ1
weighting, every method started from the first k eigenfunctions (the fast approximation from
the restricted eigenbasis, Algorithm 7):

* manifold solvers on the smoothed energy (Huber δ = 1e-3, ``(W + σA)⁻¹`` residual
  preconditioning with σ = λ_{k−1}, the largest of the first k eigenvalues — ``compressed_modes``'s
  default —, the same factorisation for all): block Riemannian CG with the Cholesky, Cayley
  and polar retractions, block L-BFGS and Barzilai–Borwein (Cholesky), block CG with the
  active-set preconditioner, and the thesis's sequential solver
  (Algorithm 6, ``compressed_modes(solver=SequentialCMM(...))``);
* the library's default, ``compressed_modes(solver=BlockCMM())`` (4 continuation stages, saddle checks;
  ``block-default``), and the same followed by the exact-support finish (``finish=SupportFinish()``: exact
  zeros on the true ℓ1 problem; ``block-default-finish``);
* the ADMM baseline (``compressed_modes(solver=ADMMCMM(...))``, ρ₀ = 3λ_k, increase-only);
* the fast approximation (``compressed_modes(solver=FastCMM(U, ...))``, ``--fast-samples`` local functions);
* at μ = 0: ``scipy.sparse.linalg.eigsh`` shift-invert (reference) and block CG (Cholesky) from a
  random start, whose objective is compared with the sum of the k eigenvalues.

For each: median wall time over ``--repeats`` runs (JIT compilation apart, from the first run),
iterations, final true objective ``tr(ΨᵀWΨ) + μΣ w_i|Ψ_ij|`` (after exact A-orthonormalisation),
orthogonality error ``max|ΨᵀAΨ − I|`` of the method's own output, the objective-vs-seconds curve
(stored in the JSON), and the first time within 1e-3 (relative) of the target = the best objective
over all μ > 0 methods. Memory, in one extra untimed run: ``tracemalloc`` peak of Python/numpy
allocations (JAX/XLA buffers are not seen by tracemalloc), the RSS high-water mark (reset through
``/proc/self/clear_refs`` on Linux) over the RSS before the run (on CPU XLA buffers show here), the
``ru_maxrss`` increase, plus ``jax.devices()[0].memory_stats()`` where the backend has it (GPU).

    python -m bench suite                                   # fandisk, k = 10, 3 repeats
    python -m bench suite --mesh bunny.off --repeats 1 --methods block-cg-cholesky admm eigsh

Writes ``bench/results_suite.json`` and ``bench/RESULTS_suite.md``; on a GPU machine the same
command runs the JAX parts there (see ``bench/GPU.md``).
"""

from __future__ import annotations

import argparse
import datetime
import gc
import json
import os
import platform
import resource
import sys
import time
import tracemalloc
from pathlib import Path

# One BLAS thread (see bench/bench_mesh.py); an explicit setting in the environment wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # benchmark script (an application), not library code

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402

import mesh  # noqa: E402
import stiefel  # noqa: E402
from stiefel.sparse_factor import default_backend  # noqa: E402
from objectives.admm import orthonormalize  # noqa: E402
from objectives.cmm import compressed_modes, first_eigenpairs  # noqa: E402
from objectives.cmm_solvers import ADMMCMM, BlockCMM, FastCMM, SequentialCMM  # noqa: E402
from objectives.support_finish import SupportFinish  # noqa: E402
from objectives.energies import cmm_energy  # noqa: E402

HERE = Path(__file__).resolve().parent
BLOCK = {"block-cg-cholesky": ("cg", "cholesky"), "block-cg-cayley": ("cg", "cayley"),
         "block-cg-polar": ("cg", "polar"), "block-lbfgs-cholesky": ("lbfgs", "cholesky"),
         "block-bb-cholesky": ("bb", "cholesky")}
METHODS = (*BLOCK, "block-default", "block-default-finish", "block-cg-active-set", "sequential", "admm", "fast", "eigsh",
           "block-cg-mu0")
MU0 = ("eigsh", "block-cg-mu0")
REL = 1e-3


def load_mesh(spec: str):
    from bench.meshes import load_mesh as load

    return load(spec)


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


def _orth(Psi, a):
    Psi = np.asarray(Psi, dtype=np.float64)
    return float(np.max(np.abs(Psi.T @ (a[:, None] * Psi) - np.eye(Psi.shape[1]))))


class Problem:
    """The shared inputs: W, a, μ, the eigenbasis start, the energy and the preconditioner."""

    def __init__(self, m, k, mu, args):
        self.m, self.k, self.mu, self.args = m, k, mu, args
        lap = mesh.laplacian(m, weights="cotangent", area="lumped")
        self.lap = lap
        self.W, self.a = lap.W.tocsr(), np.asarray(lap.A.diagonal())
        self.n = self.a.shape[0]
        t0 = time.perf_counter()
        self.evals, self.evecs = first_eigenpairs(self.W, self.a, k)
        self.eig_seconds = time.perf_counter() - t0
        t0 = time.perf_counter()
        self.sigma = float(self.evals[-1])  # compressed_modes's default shift
        self.P = stiefel.shifted_inverse(self.W, self.a, self.sigma)
        self.factor_seconds = time.perf_counter() - t0
        self.energy = cmm_energy(self.W, self.a, mu, smoothing="f6", eps=1e-3, delta=1e-3, weighting="uniform")
        self.energy0 = cmm_energy(self.W, self.a, 0.0, smoothing="f6", eps=1e-3, delta=1e-3, weighting="uniform")
        self.lf_seconds = None
        self.U = None

    def true_objective(self, Psi, energy=None):
        Psi = orthonormalize(np.asarray(Psi, dtype=np.float64), self.a)
        return float((energy or self.energy).true_value(jnp.asarray(Psi)))

    def local_functions(self):
        if self.U is None:
            t0 = time.perf_counter()
            self.U = mesh.local_functions(self.m, n_samples=self.args.fast_samples).U
            self.lf_seconds = time.perf_counter() - t0
        return self.U


def run_block(pb: Problem, name: str) -> dict:
    method, retraction = BLOCK[name]
    manifold = stiefel.GeneralizedStiefel(pb.a, pb.k, retraction=retraction)
    X0 = manifold.project_to_manifold(jnp.asarray(pb.evecs))
    res = stiefel.minimize(pb.energy, manifold, X0, method=method, preconditioner=pb.P, gtol=pb.args.gtol,
                           ftol=pb.args.ftol, max_iters=pb.args.max_iters, monitor=pb.energy.true_value)
    h = res.trimmed_history()
    it = int(res.iterations)
    return {"iterations": it, "status": res.status_name, "wall_time": res.wall_time,
            "compile_time": res.compile_time, "objective": pb.true_objective(res.x), "orthogonality": _orth(res.x, pb.a),
            "curve": (np.linspace(0.0, res.wall_time, it + 1), h["monitor"]), "fevals": int(res.stats["n_fevals"])}


def run_block_mu0(pb: Problem) -> dict:
    manifold = stiefel.GeneralizedStiefel(pb.a, pb.k, retraction="cholesky")
    X0 = manifold.random_point(jax.random.PRNGKey(pb.args.seed))
    res = stiefel.minimize(pb.energy0, manifold, X0, method="cg", preconditioner=pb.P, gtol=pb.args.gtol_mu0,
                           max_iters=pb.args.max_iters, monitor=pb.energy0.true_value)
    h = res.trimmed_history()
    it = int(res.iterations)
    return {"iterations": it, "status": res.status_name, "wall_time": res.wall_time,
            "compile_time": res.compile_time, "objective": pb.true_objective(res.x, pb.energy0),
            "orthogonality": _orth(res.x, pb.a), "curve": (np.linspace(0.0, res.wall_time, it + 1), h["monitor"]),
            "fevals": int(res.stats["n_fevals"])}


def run_block_active_set(pb: Problem) -> dict:
    """Block CG / Cholesky with the active-set preconditioner (``objectives.active_set``), via ``compressed_modes``."""
    solver = BlockCMM(smoothing="f6", gtol=pb.args.gtol, ftol=pb.args.ftol, max_iters=pb.args.max_iters,
                      preconditioner="active_set", preconditioner_shift=pb.sigma)
    res = compressed_modes((pb.W, pb.lap.A), pb.k, pb.mu, solver=solver, weighting="uniform")
    return _from_cmm(pb, res)


def run_block_default(pb: Problem, finish: bool = False) -> dict:
    """``compressed_modes``'s default ``BlockCMM()`` (4 continuation stages, saddle checks), optionally followed by
    the exact-support finish (``SupportFinish()``: exact zeros on the true ℓ1 problem); its curve ends at the
    finished objective after the finish's seconds."""
    res = compressed_modes((pb.W, pb.lap.A), pb.k, pb.mu, solver=BlockCMM(max_iters=pb.args.max_iters),
                           weighting="uniform", eigenpairs=(pb.evals, pb.evecs),
                           finish=SupportFinish() if finish else None)
    out = _from_cmm(pb, res)
    if finish:
        t, v = (np.asarray(c, dtype=float) for c in out["curve"])
        out["curve"] = (np.r_[t, res.wall_time], np.r_[v, res.objective])
        out["status"] = f"{res.status}; finish {res.finish['status']}"
        out["exact_zeros"] = res.exact_zeros
    return out


def run_eigsh(pb: Problem) -> dict:
    t0 = time.perf_counter()
    vals, vecs = first_eigenpairs(pb.W, pb.a, pb.k)
    wall = time.perf_counter() - t0
    return {"iterations": None, "status": "converged", "wall_time": wall, "compile_time": 0.0,
            "objective": float(np.sum(vals)), "orthogonality": _orth(vecs, pb.a),
            "curve": ([wall], [float(np.sum(vals))])}


def _from_cmm(pb: Problem, res, curve=None) -> dict:
    h = res.history
    if curve is None:
        curve = (h["time"], h["objective"]) if "objective" in h else ([res.wall_time], [res.objective])
    return {"iterations": int(res.iterations), "status": res.status, "wall_time": res.wall_time,
            "compile_time": res.compile_time, "objective": res.objective, "orthogonality": res.orthogonality,
            "curve": curve}


def run_sequential(pb: Problem) -> dict:
    solver = SequentialCMM(smoothing="f6", gtol=pb.args.gtol, max_iters=pb.args.seq_iters,
                           preconditioner_shift=pb.sigma)
    res = compressed_modes((pb.W, pb.lap.A), pb.k, pb.mu, solver=solver, weighting="uniform")
    # the sequential solver's history is per column: only the final point is on the manifold
    return _from_cmm(pb, res, curve=([res.wall_time], [res.objective]))


def _admm_options(pb: Problem) -> dict:
    """The ADMM solvers' options: ρ₀ = ``rho_factor``·λ_{k−1}, increase-only, iteration and time caps."""
    return dict(rho=pb.args.rho_factor * float(pb.evals[-1]), adapt_rho="increase",
                max_iters=pb.args.admm_iters, time_limit=pb.args.admm_time)


def run_admm(pb: Problem) -> dict:
    res = compressed_modes((pb.W, pb.lap.A), pb.k, pb.mu, solver=ADMMCMM(**_admm_options(pb)), weighting="uniform")
    return _from_cmm(pb, res)


def run_fast(pb: Problem) -> dict:
    U = pb.local_functions()
    res = compressed_modes((pb.W, pb.lap.A), pb.k, pb.mu, solver=FastCMM(U, **_admm_options(pb)),
                           weighting="uniform")
    out = _from_cmm(pb, res)
    out["d"] = int(U.shape[1])
    return out


def _device_memory():
    try:
        stats = jax.devices()[0].memory_stats()
    except Exception:  # noqa: BLE001 — backends without memory statistics
        return None
    if not stats:
        return None
    keys = ("bytes_in_use", "peak_bytes_in_use", "bytes_limit")
    return {k: int(stats[k]) for k in keys if k in stats}


def _rss():
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux: KiB


def _status_bytes(field: str):
    """``VmRSS``/``VmHWM`` of this process in bytes (Linux), else None."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def _reset_peak_rss() -> bool:
    """Reset the kernel's RSS high-water mark (Linux ≥ 4.0: ``echo 5 > /proc/self/clear_refs``)."""
    try:
        with open("/proc/self/clear_refs", "w") as fh:
            fh.write("5")
        return True
    except OSError:
        return False


def measure(fn, repeats: int, memory: bool = True) -> dict:
    """Run ``fn`` ``repeats`` times (median wall time; compile time from the first run), then once
    more under tracemalloc for memory (tracemalloc slows tracing down, so that run is not timed)."""
    runs = [fn() for _ in range(repeats)]
    mem: dict = {}
    if memory:
        gc.collect()
        dev0, rss0 = _device_memory(), _rss()
        reset = _reset_peak_rss()
        cur0 = _status_bytes("VmRSS")
        tracemalloc.start()
        fn()
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        hwm = _status_bytes("VmHWM") if reset else None
        mem = {"tracemalloc_peak_bytes": int(peak), "maxrss_increase_bytes": int(_rss() - rss0),
               "maxrss_after_bytes": int(_rss()), "rss_before_bytes": cur0,
               "peak_rss_increase_bytes": (hwm - cur0) if (hwm is not None and cur0 is not None) else None,
               "device_memory_before": dev0, "device_memory_after": _device_memory()}
    walls = [o["wall_time"] for o in runs]
    med = int(np.argsort(walls)[len(walls) // 2])
    row = dict(runs[med])
    row["wall_times"] = walls
    row["wall_time"] = float(np.median(walls))
    row["compile_time"] = runs[0]["compile_time"]
    row["_curves"] = [o["curve"] for o in runs]
    row.update(mem)
    return row


def run_suite(args) -> dict:
    m, name = load_mesh(args.mesh)
    n = m.n_vertices
    mu = args.mu_factor * n
    pb = Problem(m, args.k, mu, args)
    runners = {**{b: (lambda b=b: run_block(pb, b)) for b in BLOCK},
               "block-default": lambda: run_block_default(pb), "block-default-finish": lambda: run_block_default(pb, True),
               "block-cg-active-set": lambda: run_block_active_set(pb), "sequential": lambda: run_sequential(pb),
               "admm": lambda: run_admm(pb), "fast": lambda: run_fast(pb), "eigsh": lambda: run_eigsh(pb),
               "block-cg-mu0": lambda: run_block_mu0(pb)}
    rows = {}
    for meth in args.methods:
        row = measure(runners[meth], args.repeats, memory=not args.no_memory)
        rows[meth] = row
        print(json.dumps({"method": meth, **{k: row[k] for k in ("wall_time", "compile_time", "iterations",
                                                                "objective", "orthogonality", "status")}}),
              flush=True)
    pos = [r for mth, r in rows.items() if mth not in MU0]
    target = min([min(np.nanmin(np.asarray(c[1], dtype=float)) for c in r["_curves"]) for r in pos]
                 + [r["objective"] for r in pos]) if pos else None
    ref0 = rows["eigsh"]["objective"] if "eigsh" in rows else None
    for mth, r in rows.items():
        tgt = ref0 if mth in MU0 else target
        ts = [first_time_within(c[0], c[1], tgt) for c in r.pop("_curves")] if tgt is not None else []
        ok = [t for t in ts if t is not None]
        r["target"] = tgt
        r["time_to_target"] = float(np.median(ok)) if ok and len(ok) == len(ts) else None
        r["time_to_target_runs"] = ts
        r["relative_gap"] = (r["objective"] - tgt) / abs(tgt) if tgt else None
        r["curve"] = _downsample(*r["curve"])
    setup = {"mesh": name, "n": n, "n_faces": m.n_faces, "nnz_W": int(pb.W.nnz), "k": args.k, "mu": mu,
             "eigenbasis_seconds": pb.eig_seconds, "preconditioner_factor_seconds": pb.factor_seconds,
             "local_functions_seconds": pb.lf_seconds, "sigma": pb.sigma,
             "lambda_k": float(pb.evals[-1]), "target_objective": target, "mu0_reference": ref0}
    return {"setup": setup, "rows": rows}


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


def markdown(meta, res, args) -> str:
    s, rows = res["setup"], res["rows"]
    mib = 2.0**20
    out = ["# Benchmark suite: CMM solvers side by side (generated by bench/suite.py)", "", "## Recipe", "",
           f"* date: {meta['date']}",
           f"* machine: {meta['machine']} (load average at start {meta['load_average_at_start']:.1f}; "
           "other jobs shared the cores, seconds are noisy)",
           "* versions: " + ", ".join(f"{k} {v}" for k, v in meta["versions"].items()),
           f"* JAX backend: {meta['jax_backend']}, device `{meta['device']}` ({meta['device_kind']})"
           + (f"; {meta['note']}" if meta["note"] else ""),
           f"* OPENBLAS_NUM_THREADS={meta['openblas_threads']}, float64 (x64 on)",
           f"* command: `{meta['command']}`",
           f"* problem: `{s['mesh']}`, n = {s['n']}, nnz(W) = {s['nnz_W']}, k = {s['k']}, μ = {args.mu_factor}·n = "
           f"{s['mu']:.2f}, uniform ℓ1 weighting, cotangent W, lumped A (unit area); start: first k eigenfunctions "
           "(fast: restricted eigenbasis; block CG at μ = 0: random)",
           f"* shared setup (not in the times below): eigenbasis {s['eigenbasis_seconds']:.2f} s, preconditioner "
           f"`(W + σA)` factorisation ({default_backend()}) {s['preconditioner_factor_seconds']:.2f} s "
           f"(σ = λ_(k−1) = {s['sigma']:.4g}), "
           f"local functions {_f(s['local_functions_seconds'])} s",
           f"* manifold solvers: Huber δ = 1e-3, gtol {args.gtol}, ftol {args.ftol} (20-iteration window), at most "
           f"{args.max_iters} iterations (sequential: {args.seq_iters} per column); ADMM and fast: ρ₀ = "
           f"{args.rho_factor}·λ_k (increase-only), at most {args.admm_iters} iterations or {args.admm_time} s; fast: "
           f"{args.fast_samples} samples",
           f"* times: median of {args.repeats} run(s), compilation apart (first run); target = best objective over "
           f"the μ > 0 methods = {_f(s['target_objective'], '{:.4f}')}; μ = 0 reference = eigsh's Σλ = "
           f"{_f(s['mu0_reference'], '{:.6f}')}; \"to target\" = first time within {REL:g} (relative)",
           "* memory: one extra, untimed run per method under tracemalloc (Python/numpy allocations; XLA "
           "buffers are not seen); peak-RSS increase = the kernel's RSS high-water mark (reset before the run "
           "through /proc/self/clear_refs) minus the RSS before it, i.e. everything the run touched, XLA "
           "buffers included (compilation happened in the first timed run, so its memory is not in it)", "",
           "| method | μ | iterations | status | median s | to target s | compile s | final objective | rel. gap "
           "| orthogonality | tracemalloc peak MiB | peak-RSS increase MiB | device peak MiB |",
           "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for mth, r in rows.items():
        dev = (r.get("device_memory_after") or {}).get("peak_bytes_in_use")
        label = mth + (f" (d = {r['d']})" if "d" in r else "")
        out.append(f"| {label} | {'0' if mth in MU0 else 'μ'} | {_f(r['iterations'], '{:d}')} | {r['status']} | "
                   f"{r['wall_time']:.2f} | {_f(r['time_to_target'])} | {r['compile_time']:.2f} | "
                   f"{r['objective']:.4f} | {_f(r['relative_gap'], '{:.1e}')} | {r['orthogonality']:.1e} | "
                   f"{_f(r.get('tracemalloc_peak_bytes', 0) / mib, '{:.1f}')} | "
                   f"{_f(r.get('peak_rss_increase_bytes') and r['peak_rss_increase_bytes'] / mib, '{:.1f}')} | "

                   f"{_f(dev and dev / mib, '{:.1f}')} |")
    out += ["", "Objective-vs-seconds curves of every run are in `results_suite.json` (`rows.<method>.curve`; "
            "the block solvers' times are interpolated linearly over their iterations, the sequential solver "
            "and eigsh have only their final point).", ""]
    return "\n".join(out)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--mesh", default="example:starfish",
                   help="example:NAME (generated), 'demo', a path, or a mesh name in ../shared/meshes")
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
    p.add_argument("--admm-iters", type=int, default=10**6)
    p.add_argument("--admm-time", type=float, default=30.0)
    p.add_argument("--fast-samples", type=int, default=500, help="d, the number of local functions")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-memory", action="store_true", help="skip the extra tracemalloc run per method")
    p.add_argument("--out-json", default=str(HERE / "results_suite.json"))
    p.add_argument("--out-md", default=str(HERE / "RESULTS_suite.md"))
    p.add_argument("--render", default=None, help="only re-render --out-md from this results JSON")
    args = p.parse_args(argv)
    if args.render:  # re-render the markdown from a results JSON
        saved = json.loads(Path(args.render).read_text())
        shown = argparse.Namespace(**saved["params"])
        Path(args.out_md).write_text(markdown(saved["meta"], saved, shown))
        return 0
    meta = metadata(argv)
    res = run_suite(args)
    params = {k: v for k, v in vars(args).items() if k not in ("out_json", "out_md", "render")}
    Path(args.out_json).write_text(json.dumps({"meta": meta, "params": params, **res}, indent=1, default=float))
    md = markdown(meta, res, args)
    Path(args.out_md).write_text(md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
