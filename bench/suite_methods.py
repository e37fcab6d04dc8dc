"""The benchmark suite's problems and methods (``python -m bench suite``).

``manpg_problem`` builds ManPG's 1-D compressed-modes problem. A ``Problem`` holds what every method shares — ``W``, the mass diagonal ``a``, k, μ, the ℓ1 weighting,
the start, the eigenpairs, the ``(W + σA)⁻¹`` preconditioner (σ = λ_(k−1)) and the smoothed energy
(Huber f6, δ = 1e-3) — and ``RUNNERS`` maps each method's name to a function ``Problem -> dict`` with
the method's modes, iterations, status, seconds (compile apart) and objective-vs-seconds curve.
``measure`` runs one ``--repeats`` times, keeps the median run and adds what is measured on its modes
(true and smoothed objective, exact zeros, support sizes, ℓ1 stationarity residual, orthogonality) and,
in one extra untimed run, its memory.
"""

from __future__ import annotations

import gc
import resource
import time
import tracemalloc

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp

import mesh
import stiefel
from objectives.admm.splitting import l1_weights_np, orthonormalize
from objectives.cmm.modes import compressed_modes, first_eigenpairs
from objectives.cmm.solvers import ADMMCMM, BlockCMM, FastCMM, SequentialCMM
from objectives.energy.energies import cmm_energy
from objectives.energy.l1_optimality import l1_stationarity, support_stats
from objectives.cmm.support_finish import SupportFinish

BLOCK = {"block-cg-cholesky": ("cg", "cholesky"), "block-cg-cayley": ("cg", "cayley"),
         "block-cg-polar": ("cg", "polar"), "block-lbfgs-cholesky": ("lbfgs", "cholesky"),
         "block-bb-cholesky": ("bb", "cholesky")}
METHODS = (*BLOCK, "block-default", "block-default-finish", "block-cg-active-set", "sequential", "admm", "fast",
           "penalty", "eigsh", "block-cg-mu0")
MU0 = ("eigsh", "block-cg-mu0")
NEEDS_MESH = ("fast",)  # the fast approximation's local functions are sampled on the surface


def manpg_problem(n: int) -> tuple:
    """ManPG's compressed-modes problem (Chen, Ma, So, Zhang, SIAM J. Optim. 2020, §6.1): ``Ĥ = −½Δ``, the periodic
    second-difference Laplacian on ``[0, 50]`` with n points, and ``XᵀX = I`` (A = I, so the area-weighted ℓ1 is
    ``μ‖X‖₁``). Returns ``(W (n, n) csr, a = ones (n,))``."""
    h = 50.0 / n
    e = np.ones(n)
    D = sp.diags([-e[:-1], 2 * e, -e[:-1]], [-1, 0, 1], format="lil")
    D[0, n - 1] = D[n - 1, 0] = -1.0
    return sp.csr_matrix(D / (2.0 * h * h)), np.ones(n)


class Problem:
    """The shared inputs of one suite problem.

    ``W`` (n, n) sparse, ``a`` (n,) mass diagonal, ``k`` modes, ``mu`` (absolute), ``weighting`` of the ℓ1 term,
    ``start``: ``"eigen"`` (the first k eigenfunctions) or ``"random"`` (an A-orthonormalised Gaussian, ``seed``);
    ``m``: the mesh when there is one (the fast approximation needs it)."""

    def __init__(self, label, W, a, k, mu, args, *, m=None, weighting="uniform", start="eigen"):
        self.label, self.m, self.k, self.mu, self.args = label, m, k, mu, args
        self.weighting, self.start = weighting, start
        self.W, self.a = sp.csr_matrix(W), np.asarray(a, dtype=np.float64)
        self.n = self.a.shape[0]
        self.w = l1_weights_np(self.a, weighting)
        t0 = time.perf_counter()
        self.evals, self.evecs = first_eigenpairs(self.W, self.a, k)
        self.eig_seconds = time.perf_counter() - t0
        if start == "eigen":
            self.X0 = np.asarray(self.evecs)
        else:
            rng = np.random.default_rng(args.seed)
            self.X0 = orthonormalize(rng.standard_normal((self.n, k)), self.a)
        t0 = time.perf_counter()
        self.sigma = float(self.evals[-1])  # compressed_modes's default shift
        self.P = stiefel.shifted_inverse(self.W, self.a, self.sigma)
        self.factor_seconds = time.perf_counter() - t0
        kw = dict(smoothing="f6", eps=1e-3, delta=1e-3, weighting=weighting)
        self.energy = cmm_energy(self.W, self.a, mu, **kw)
        self.energy0 = cmm_energy(self.W, self.a, 0.0, **kw)
        self.lf_seconds = None
        self.U = None

    def cmm_kwargs(self) -> dict:
        """``compressed_modes``'s keywords for this problem's weighting and start (eigenpairs computed once)."""
        kw = dict(weighting=self.weighting, eigenpairs=(self.evals, self.evecs))
        if self.start != "eigen":
            kw["start"] = self.X0
        return kw

    def true_objective(self, Psi, energy=None) -> float:
        Psi = orthonormalize(np.asarray(Psi, dtype=np.float64), self.a)
        return float((energy or self.energy).true_value(jnp.asarray(Psi)))

    def local_functions(self):
        if self.m is None:
            raise ValueError(f"{self.label}: the fast approximation needs a mesh")
        if self.U is None:
            t0 = time.perf_counter()
            self.U = mesh.local_functions(self.m, n_samples=self.args.fast_samples).U
            self.lf_seconds = time.perf_counter() - t0
        return self.U

    def modes_stats(self, Psi, mu0: bool = False) -> dict:
        """Measured on the method's own modes: objectives, exact zeros, entries below 1e-6 of their column's
        peak, per-mode support sizes, the relative ℓ1 stationarity residual (docs/maths.md §9) and
        ``max|ΨᵀAΨ − I|``."""
        Psi = np.asarray(Psi, dtype=np.float64)
        energy = self.energy0 if mu0 else self.energy
        exact = jnp.asarray(orthonormalize(Psi, self.a))  # the objectives of the exactly A-orthonormal modes
        peak = np.max(np.abs(Psi), axis=0, keepdims=True)
        sup = support_stats(Psi, self.a)
        out = {"objective": float(energy.true_value(exact)), "smoothed_objective": float(energy(exact)),
               "exact_zeros": sup["exact_zeros"], "support_sizes": sup["support_sizes"],
               "below_1e-6": float(np.mean(np.abs(Psi) < 1e-6 * peak)),
               "orthogonality": float(np.max(np.abs(Psi.T @ (self.a[:, None] * Psi) - np.eye(Psi.shape[1]))))}
        out["l1_residual"] = None if mu0 else float(l1_stationarity(self.W, self.a, self.w, self.mu, Psi).relative)
        return out


def _from_minimize(res) -> dict:
    h = res.trimmed_history()
    it = int(res.iterations)
    return {"iterations": it, "status": res.status_name, "wall_time": res.wall_time, "compile_time": res.compile_time,
            "modes": np.asarray(res.x), "curve": (np.linspace(0.0, res.wall_time, it + 1), h["monitor"]),
            "fevals": int(res.stats["n_fevals"])}


def run_block(pb: Problem, name: str) -> dict:
    """Plain ``stiefel.minimize`` on the smoothed energy at μ (one stage), P = (W + σA)⁻¹."""
    method, retraction = BLOCK[name]
    manifold = stiefel.GeneralizedStiefel(pb.a, pb.k, retraction=retraction)
    X0 = manifold.project_to_manifold(jnp.asarray(pb.X0))
    res = stiefel.minimize(pb.energy, manifold, X0, method=method, preconditioner=pb.P, gtol=pb.args.gtol,
                           ftol=pb.args.ftol, max_iters=pb.args.max_iters, monitor=pb.energy.true_value)
    return _from_minimize(res)


def run_block_mu0(pb: Problem) -> dict:
    """μ = 0 from a random start: the objective must come down to eigsh's Σλ (Ky Fan)."""
    manifold = stiefel.GeneralizedStiefel(pb.a, pb.k, retraction="cholesky")
    X0 = manifold.random_point(jax.random.PRNGKey(pb.args.seed))
    res = stiefel.minimize(pb.energy0, manifold, X0, method="cg", preconditioner=pb.P, gtol=pb.args.gtol_mu0,
                           max_iters=pb.args.max_iters, monitor=pb.energy0.true_value)
    return _from_minimize(res)


def _from_cmm(res, curve=None) -> dict:
    h = res.history
    if curve is None:
        curve = (h["time"], h["objective"]) if "objective" in h else ([res.wall_time], [res.objective])
    return {"iterations": int(res.iterations), "status": res.status, "wall_time": res.wall_time,
            "compile_time": res.compile_time, "modes": res.modes, "curve": curve}


def run_block_active_set(pb: Problem) -> dict:
    """Block CG / Cholesky with the active-set preconditioner (``objectives.cmm.active_set``), via ``compressed_modes``."""
    solver = BlockCMM(smoothing="f6", gtol=pb.args.gtol, ftol=pb.args.ftol, max_iters=pb.args.max_iters,
                      preconditioner="active_set", preconditioner_shift=pb.sigma)
    return _from_cmm(compressed_modes((pb.W, pb.a), pb.k, pb.mu, solver=solver, **pb.cmm_kwargs()))


def run_block_default(pb: Problem, finish: bool = False) -> dict:
    """``compressed_modes``'s default ``BlockCMM()`` (4 continuation stages, saddle checks), optionally followed by
    the exact-support finish (``SupportFinish()``: exact zeros on the true ℓ1 problem); its curve ends at the
    finished objective after the finish's seconds."""
    res = compressed_modes((pb.W, pb.a), pb.k, pb.mu, solver=BlockCMM(max_iters=pb.args.max_iters),
                           finish=SupportFinish() if finish else None, **pb.cmm_kwargs())
    out = _from_cmm(res)
    if finish:
        t, v = (np.asarray(c, dtype=float) for c in out["curve"])
        out["curve"] = (np.r_[t, res.wall_time], np.r_[v, res.objective])
        out["status"] = f"{res.status}; finish {res.finish['status']}"
        out["finish_seconds"] = res.finish.get("wall_time")
    return out


def run_sequential(pb: Problem) -> dict:
    solver = SequentialCMM(smoothing="f6", gtol=pb.args.gtol, max_iters=pb.args.seq_iters,
                           preconditioner_shift=pb.sigma)
    res = compressed_modes((pb.W, pb.a), pb.k, pb.mu, solver=solver, **pb.cmm_kwargs())
    # the sequential solver's history is per column: only the final point is on the manifold
    return _from_cmm(res, curve=([res.wall_time], [res.objective]))


def _admm_options(pb: Problem) -> dict:
    """The ADMM solvers' options: ρ₀ = ``rho_factor``·λ_{k−1}, increase-only, iteration and time caps."""
    return dict(rho=pb.args.rho_factor * float(pb.evals[-1]), adapt_rho="increase",
                max_iters=pb.args.admm_iters, time_limit=pb.args.admm_time)


def run_admm(pb: Problem) -> dict:
    return _from_cmm(compressed_modes((pb.W, pb.a), pb.k, pb.mu, solver=ADMMCMM(**_admm_options(pb)),
                                      **pb.cmm_kwargs()))


def run_fast(pb: Problem) -> dict:
    U = pb.local_functions()
    kw = pb.cmm_kwargs()
    kw.pop("start", None)  # the fast approximation starts from its restricted eigenbasis
    out = _from_cmm(compressed_modes((pb.W, pb.a), pb.k, pb.mu, solver=FastCMM(U, **_admm_options(pb)), **kw))
    out["d"] = int(U.shape[1])
    return out


def run_penalty(pb: Problem) -> dict:
    """The baseline without a manifold toolkit: ``stiefel.penalty_minimize`` (jaxopt L-BFGS on
    ``F + ρ‖XᵀAX − I‖²``, ρ = λ_(k−1)·(1, 10, 100) in turn, ``--max-iters``/3 per stage), then the projection."""
    manifold = stiefel.GeneralizedStiefel(pb.a, pb.k)
    rho = [pb.args.penalty_rho * pb.sigma * f for f in (1.0, 10.0, 100.0)]
    res = stiefel.penalty_minimize(pb.energy, manifold, jnp.asarray(pb.X0), rho=rho,
                                   maxiter=max(1, pb.args.max_iters // 3), tol=pb.args.gtol)
    X = np.asarray(res.x)
    return {"iterations": int(res.iterations), "status": res.status, "wall_time": res.wall_time,
            "compile_time": res.compile_time, "modes": X,
            "curve": ([res.wall_time], [pb.true_objective(X) if res.status != "non_finite" else np.nan])}


def run_eigsh(pb: Problem) -> dict:
    t0 = time.perf_counter()
    vals, vecs = first_eigenpairs(pb.W, pb.a, pb.k)
    wall = time.perf_counter() - t0
    return {"iterations": None, "status": "converged", "wall_time": wall, "compile_time": 0.0, "modes": vecs,
            "curve": ([wall], [float(np.sum(vals))])}


RUNNERS = {**{b: (lambda pb, b=b: run_block(pb, b)) for b in BLOCK},
           "block-default": run_block_default, "block-default-finish": lambda pb: run_block_default(pb, True),
           "block-cg-active-set": run_block_active_set, "sequential": run_sequential, "admm": run_admm,
           "fast": run_fast, "penalty": run_penalty, "eigsh": run_eigsh, "block-cg-mu0": run_block_mu0}


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


def _memory(fn) -> dict:
    """One untimed run: tracemalloc peak (Python/numpy), RSS high-water increase (XLA buffers included)."""
    gc.collect()
    dev0, rss0 = _device_memory(), _rss()
    reset = _reset_peak_rss()
    cur0 = _status_bytes("VmRSS")
    tracemalloc.start()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    hwm = _status_bytes("VmHWM") if reset else None
    return {"tracemalloc_peak_bytes": int(peak), "maxrss_increase_bytes": int(_rss() - rss0),
            "maxrss_after_bytes": int(_rss()), "rss_before_bytes": cur0,
            "peak_rss_increase_bytes": (hwm - cur0) if (hwm is not None and cur0 is not None) else None,
            "device_memory_before": dev0, "device_memory_after": _device_memory()}


def failed_row(status: str, k: int) -> dict:
    """The row of a method that raised or returned non-finite modes (objective NaN, no curve point)."""
    nan = float("nan")
    return {"iterations": None, "status": status, "wall_time": nan, "compile_time": nan, "objective": nan,
            "smoothed_objective": nan, "exact_zeros": nan, "support_sizes": [], "below_1e-6": nan,
            "orthogonality": nan, "l1_residual": None, "wall_times": [], "_curves": [([], [])], "failed": True}


def measure(pb: Problem, method: str, repeats: int, memory: bool = True) -> dict:
    """Run ``method`` ``repeats`` times (median wall time; compile time from the first run) and measure the median
    run's modes; then, with ``memory``, once more under tracemalloc (which slows tracing, so it is not timed)."""
    fn = (lambda: RUNNERS[method](pb))
    try:
        runs = [fn() for _ in range(repeats)]
    except Exception as e:  # noqa: BLE001 — a method that fails is a row with its error; the others still run
        return failed_row(f"error: {type(e).__name__}: {e}"[:300], pb.k)
    walls = [o["wall_time"] for o in runs]
    row = dict(runs[int(np.argsort(walls)[len(walls) // 2])])
    modes = row.pop("modes")
    if not np.all(np.isfinite(modes)):  # nothing to measure on: an honest row without the modes' figures
        return {**failed_row(row["status"], pb.k), **{k: row[k] for k in ("iterations", "wall_time", "compile_time")}}
    row.update(pb.modes_stats(modes, mu0=method in MU0))
    row["wall_times"] = walls
    row["wall_time"] = float(np.median(walls))
    row["compile_time"] = runs[0]["compile_time"]
    row["_curves"] = [o["curve"] for o in runs]
    if memory:
        row.update(_memory(fn))
    return row
