"""Scaling benchmark: CMMs on subdivided surfaces up to ~10⁶ vertices.

A mesh (``--base``: default the generated ``example:bumpy``, 2 562 vertices; the committed results use
``bunny.off``, 3 485 vertices, closed, genus 0) is midpoint-subdivided (``trimesh.Trimesh.subdivide``; each
level ×4 faces, ≈ ×4 vertices; bunny: 1.4·10⁴, 5.6·10⁴, 2.2·10⁵ and 8.9·10⁵ vertices at levels 1–4). The subdivided meshes are cached as ``.npz`` under
``--cache`` (default ``$XDG_CACHE_HOME/stiefel-cmm/bench``, never in the repository). For every
size, in a fresh subprocess (so that its peak RSS is its own):

* load/validation (``mesh.from_arrays``) and Laplacian assembly (cotangent W, lumped A, unit area);
* ``eigsh`` shift-invert (``objectives.cmm.modes.first_eigenpairs``) for k = 10 and k = 50 — skipped
  when the time predicted from the previous size (exponent 1.5) exceeds ``--eigsh-budget``;
* the CMM block solver (``stiefel.minimize``, Riemannian CG, Cholesky retraction, residual
  preconditioning by ``(W + λ₁A)⁻¹``, Huber smoothing δ = 1e-3, μ = 0.01·n, uniform
  weighting) for a fixed ``--iters`` iterations (gtol = 0), from the eigenbasis:
  ms/iteration, split into the preconditioner's one-off SuperLU factorisation and, per
  iteration, one preconditioner application (k triangular solve pairs on the host), the
  objective+gradient evaluations (× evaluations per iteration) and the rest;
* for n ≤ ``--total-max-n``: the total time to a modest tolerance (``ftol`` = 1e-5: relative
  decrease over 20 iterations, or gtol = 1e-4, at most ``--total-iters`` iterations);
* peak RSS of the subprocess, against ``n·k·8`` bytes (one (n, k) float64 block), ``nnz(W)``
  and the LU's ``nnz(L + U)``.

Then log–log fits ``t ∝ n^p`` of every timing over the sizes (the goal: ``p ≤ 1.15`` for the solver's time
per iteration up to 10⁶ vertices).

    python -m bench scaling --base bunny.off      # levels 1–4, k = 10 and 50 (≈ 20 min on 2 cores)
    python -m bench scaling --levels 1 2 --ks 10 --iters 10 --out-json /tmp/s.json --out-md /tmp/s.md

Writes ``docs/benchmarks/scaling.json`` and ``docs/benchmarks/scaling.md`` (notes below ``<!-- notes -->`` kept)
when every level is done; a level whose process fails stops the run with nothing written.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import resource
import subprocess
import sys
import time
from pathlib import Path

# One BLAS thread (see bench/bench_mesh.py): on the shared 2-core machine threaded OpenBLAS
# made ARPACK several times slower. Set before numpy is imported; an explicit setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # benchmark script (an application), not library code

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402

from bench.environment import git_commit, results_path, write_json, write_page  # noqa: E402
from bench.meshes import require  # noqa: E402


def default_cache() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "stiefel-cmm" / "bench"


def subdivided(base: str, level: int, cache: Path) -> tuple[np.ndarray, np.ndarray, bool]:
    """``(V, F, from_cache)`` of ``base`` midpoint-subdivided ``level`` times (cached as .npz)."""
    import trimesh

    cache.mkdir(parents=True, exist_ok=True)
    path = cache / f"{Path(base).stem}_sub{level}.npz"
    if path.exists():
        z = np.load(path)
        return z["V"], z["F"], True
    from bench.meshes import load_mesh

    m, _ = load_mesh(base)
    tm = trimesh.Trimesh(m.vertices, m.faces, process=False)
    for _ in range(level):
        tm = tm.subdivide()
    V, F = np.asarray(tm.vertices, dtype=np.float64), np.asarray(tm.faces, dtype=np.int64)
    np.savez(path, V=V, F=F)
    return V, F, False


def _available_bytes() -> int | None:
    """``MemAvailable`` from /proc/meminfo (Linux), else None."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


def _rss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux: KiB


def _timed(fn, repeats=3):
    """Median seconds of ``fn()`` after a warm-up call; one timed call when it takes over a second."""
    jax.block_until_ready(fn())  # warm-up (compilation)
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t0)
        if ts[-1] > 1.0:
            break
    return float(np.median(ts))


def colamd_preconditioner(W, a, sigma):
    """``Y ↦ (W + σA)⁻¹Y`` with SuperLU in symmetric mode and a COLAMD ordering (bench-side alternative).

    The same factorisation as ``stiefel.shifted_inverse`` (diagonal pivots, symmetric mode, so the
    order stays symmetric: an LDLᵀ in disguise) except the fill-reducing ordering: COLAMD instead of
    MMD on AᵀA + A, whose *ordering step* dominated the library's factorisation time at 10⁵ vertices.
    Applied through ``jax.pure_callback``, one column at a time like the library's operator.
    """
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    K = sp.csc_matrix(sp.csr_array(W) + sigma * sp.diags_array(a))
    lu = spla.splu(K, permc_spec="COLAMD", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    if not np.array_equal(lu.perm_r, lu.perm_c) or not np.all(lu.U.diagonal() > 0):
        raise RuntimeError("COLAMD/symmetric-mode factorisation lost the symmetric order or a positive pivot")

    def host(b):
        b = np.asarray(b, dtype=np.float64)
        out = np.empty_like(b, order="F")
        for j in range(b.shape[1]):
            out[:, j] = lu.solve(np.ascontiguousarray(b[:, j]))
        return out

    def apply(Y):
        return jax.pure_callback(host, jax.ShapeDtypeStruct(Y.shape, Y.dtype), Y, vmap_method="sequential")

    return apply, lu


def worker(args) -> dict:
    """One size, in its own process: returns the row (printed as JSON by ``main``)."""
    import stiefel
    import mesh
    from objectives.cmm.modes import first_eigenpairs
    from objectives.energy.energies import cmm_energy

    V, F, cached = subdivided(args.base, args.worker, Path(args.cache))
    row: dict = {"level": args.worker, "base": args.base, "mesh_cached": cached}
    t0 = time.perf_counter()
    m = mesh.load((V, F), warn=False)
    row["load_seconds"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    lap = mesh.laplacian(m, weights="cotangent", area="lumped")
    row["assembly_seconds"] = time.perf_counter() - t0
    del V, F
    W, a = lap.W.tocsr(), np.asarray(lap.A.diagonal())
    n = int(a.shape[0])
    row.update(n=n, n_faces=int(m.n_faces), nnz_W=int(W.nnz))
    row["rss_after_assembly_bytes"] = _rss_bytes()
    prior = {(int(k) if k.isdigit() else k): v for k, v in json.loads(args.prior or "{}").items()}

    lam1 = None
    eig = {}
    evecs_by_k = {}
    for k in args.ks:
        pred = prior.get(k)
        if pred is not None and pred > args.eigsh_budget:
            eig[k] = {"seconds": None, "skipped": f"predicted {pred:.0f} s > budget {args.eigsh_budget:.0f} s"}
            continue
        t0 = time.perf_counter()
        vals, vecs = first_eigenpairs(W, a, k)
        eig[k] = {"seconds": time.perf_counter() - t0, "lambda_1": float(vals[1]), "lambda_k": float(vals[-1])}
        lam1 = float(vals[1])
        evecs_by_k[k] = vecs
        print(json.dumps({"n": n, "eigsh_k": k, **eig[k]}), file=sys.stderr, flush=True)
    row["eigsh"] = {str(k): v for k, v in eig.items()}
    row["rss_after_eigsh_bytes"] = _rss_bytes()

    if lam1 is None:  # no eigsh at all: σ of the order of the first non-zero eigenvalue of a unit-area surface
        lam1 = 10.0
    row["sigma"] = lam1
    mu = args.mu_factor * n
    energy = cmm_energy(W, a, mu, smoothing="f6", eps=1e-3, delta=1e-3, weighting="uniform")
    vg = jax.jit(lambda X: jax.value_and_grad(energy)(X))
    # preconditioners: the library's (W + σA)⁻¹ (SymmetricFactor: QDLDL/AMD by default; skipped when the
    # factorisation is predicted over budget) and the O(n) Jacobi diagonal diag(W + σA)⁻¹ (a 1-D array)
    preconds, row["factor"] = {}, {}
    pred = prior.get("factor")
    if pred is not None and pred > args.factor_budget:
        why = (f"predicted {pred:.0f} s > budget {args.factor_budget:.0f} s" if np.isfinite(pred)
               else "already over budget at a smaller size")
        row["factor"]["library"] = {"seconds": None, "skipped": why}
    else:
        t0 = time.perf_counter()
        preconds["library"] = stiefel.shifted_inverse(W, a, lam1)
        host = getattr(preconds["library"], "factor", None)  # the operator's SymmetricFactor
        row["factor"]["library"] = {"seconds": time.perf_counter() - t0,
                                        "lu_nnz": host.factor.nnz if host is not None else None,
                                        "backend": host.factor.backend if host is not None else None}
    t0 = time.perf_counter()
    preconds["superlu-colamd"], lu = colamd_preconditioner(W, a, lam1)
    row["factor"]["superlu-colamd"] = {"seconds": time.perf_counter() - t0, "lu_nnz": int(lu.L.nnz + lu.U.nnz)}
    print(json.dumps({"n": n, "factor": row["factor"]}), file=sys.stderr, flush=True)
    preconds["jacobi"] = np.asarray(W.diagonal() + lam1 * a)
    row["rss_after_factor_bytes"] = _rss_bytes()

    row["solver"] = {}
    for k in args.ks:
        manifold = stiefel.GeneralizedStiefel(a, k, retraction="cholesky")
        if k in evecs_by_k:
            X0, start = evecs_by_k[k], "eigen"
        else:
            X0, start = np.asarray(manifold.random_point(jax.random.PRNGKey(0))), "random"
        X0 = manifold.project_to_manifold(jnp.asarray(X0))
        need = args.mem_factor * n * k * 8
        avail = _available_bytes()
        if avail is not None and need > avail:  # the solver's compiled loop needs ≈ mem_factor n×k blocks
            for pname in preconds:
                row["solver"][f"{pname}_{k}"] = {"preconditioner": pname, "ms_precond_apply": None, "skipped":
                                                 f"predicted memory {need / 2**30:.0f} GiB > available "
                                                 f"{avail / 2**30:.0f} GiB"}
            continue
        fg = _timed(lambda X=X0: vg(X))
        for pname, P in preconds.items():
            Pop = P if callable(P) else stiefel.as_operator(P, check=False)
            solve_P = jax.jit(lambda Y, Pop=Pop: Pop(Y) if callable(Pop) else Pop.solve(Y))
            direct = pname in ("library", "superlu-colamd")
            iters = args.iters
            if direct:  # one column first: skip runs predicted far over budget (≈ 3.5 evaluations per iteration)
                X1 = X0[:, :1]
                guess = k * _timed(lambda: solve_P(X1), repeats=1)
                if args.min_iters * (guess + 3.5 * fg) > 2 * args.solve_budget:
                    row["solver"][f"{pname}_{k}"] = {"preconditioner": pname, "skipped":
                                                     f"{args.min_iters} iterations predicted "
                                                     f"{args.min_iters * (guess + 3.5 * fg):.0f} s",
                                                     "ms_precond_apply": 1e3 * guess}
                    continue
            apply_P = _timed(lambda: solve_P(X0), repeats=1 if direct else 3)
            # every run within its budget: ≈ 3.5 evaluations per iteration, at least min_iters iterations
            iters = int(min(args.iters, max(args.min_iters, args.solve_budget // (apply_P + 3.5 * fg))))
            res = stiefel.minimize(energy, manifold, X0, method="cg", preconditioner=Pop, gtol=0.0,
                                   max_iters=iters, check=False)
            it = int(res.iterations)
            fevals = int(res.stats["n_fevals"])
            ms_it = 1e3 * res.wall_time / max(it, 1)
            per_it_P, per_it_F = 1e3 * apply_P, 1e3 * fg * (fevals / max(it, 1))
            srow = {"preconditioner": pname, "start": start, "iterations": it, "status": res.status_name,
                    "wall_seconds": res.wall_time, "compile_seconds": res.compile_time, "ms_per_iteration": ms_it,
                    "fevals": fevals, "fevals_per_iteration": fevals / max(it, 1), "ms_precond_apply": per_it_P,
                    "ms_value_and_grad": 1e3 * fg, "ms_fevals_per_iteration": per_it_F,
                    "ms_rest_per_iteration": ms_it - per_it_P - per_it_F, "block_bytes": n * k * 8,
                    "objective_after": float(energy.true_value(res.x))}
            del res
            if pname == "library" and n <= args.total_max_n and k in args.total_ks:
                tot = stiefel.minimize(energy, manifold, X0, method="cg", preconditioner=Pop, gtol=1e-4, ftol=1e-5,
                                       max_iters=args.total_iters, check=False, monitor=energy.true_value)
                h = tot.trimmed_history()
                srow["total"] = {"seconds": tot.wall_time, "iterations": int(tot.iterations),
                                 "status": tot.status_name, "objective_start": float(h["monitor"][0]),
                                 "objective_final": float(h["monitor"][-1])}
                del tot
            row["solver"][f"{pname}_{k}"] = srow
            print(json.dumps({"n": n, "k": k, **{kk: v for kk, v in srow.items() if kk != "total"}}),
                  file=sys.stderr, flush=True)
    row["peak_rss_bytes"] = _rss_bytes()
    return row


def fit_exponent(ns, ts, last: int | None = None) -> float | None:
    """Least-squares slope of log t against log n (over the ``last`` largest measured sizes if given)."""
    pts = [(n, t) for n, t in zip(ns, ts) if t is not None and t > 0]
    if last:
        pts = pts[-last:]
    if len(pts) < 2:
        return None
    x, y = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


PRECONDS = ("library", "superlu-colamd", "jacobi")


def exponents(rows, ks, last: int | None = None) -> dict:
    ns = [r["n"] for r in rows]

    def fit(ns, ts):  # over the ``last`` largest sizes if asked
        return fit_exponent(ns, ts, last)

    out = {"load": fit(ns, [r["load_seconds"] for r in rows]),
           "assembly": fit(ns, [r["assembly_seconds"] for r in rows]),
           "nnz(W)": fit(ns, [r["nnz_W"] for r in rows]),
           "peak RSS": fit(ns, [r["peak_rss_bytes"] for r in rows])}
    for pname in PRECONDS[:2]:
        out[f"factorisation {pname}"] = fit(ns, [r["factor"][pname].get("seconds") for r in rows])
        out[f"nnz(L+U) {pname}"] = fit(ns, [r["factor"][pname].get("lu_nnz") for r in rows])
    for k in ks:
        out[f"eigsh k={k}"] = fit(ns, [r["eigsh"].get(str(k), {}).get("seconds") for r in rows])
    for k in ks:
        for pname in PRECONDS:
            sol = [r["solver"].get(f"{pname}_{k}") or {} for r in rows]
            sol = [{} if "skipped" in x else x for x in sol]  # estimates of skipped runs stay out of the fits
            out[f"ms/iteration {pname} k={k}"] = fit(ns, [x.get("ms_per_iteration") for x in sol])
            out[f"P apply {pname} k={k}"] = fit(ns, [x.get("ms_precond_apply") for x in sol])
        sol = [r["solver"].get(f"jacobi_{k}") or {} for r in rows]
        out[f"value+grad k={k}"] = fit(ns, [x.get("ms_value_and_grad") for x in sol])
        tot = [(r["solver"].get(f"library_{k}") or {}).get("total", {}).get("seconds") for r in rows]
        out[f"total to tolerance library k={k}"] = fit(ns, tot)
    return out


def _fmt(v, f="{:.2f}"):
    return "–" if v is None else f.format(v)


def markdown(meta, rows, exps, ks) -> str:
    mib = 2.0**20
    last2 = exponents(rows, ks, last=2)
    out = ["# Scaling: CMM block solver, eigsh and assembly up to ~10⁶ vertices (generated by `python -m bench scaling`)", "",
           "## Recipe", "",
           f"* date: {meta['date']}; commit: {meta.get('commit', 'unknown')}", f"* machine: {meta['machine']} (shared with other jobs: seconds are noisy)",
           f"* versions: {meta['versions']}",
           f"* JAX backend: {meta['backend']} ({meta['device']}); no GPU in this session",
           f"* OPENBLAS_NUM_THREADS={meta['openblas_threads']}, float64",
           f"* command: `{meta['command']}` (wall time {meta['total_seconds'] / 60:.1f} min"
           + (f"; levels {meta['resumed_levels']} reused from the earlier run named by --resume)"
              if meta.get("resumed_levels") else ")"),
           f"* meshes: `{meta['base']}` midpoint-subdivided (levels {meta['levels']}), cached in `{meta['cache']}`",
           f"* solver: Riemannian CG, Cholesky retraction, residual preconditioning, Huber δ = 1e-3, "
           f"μ = {meta['mu_factor']}·n, uniform weighting, eigenbasis start; {meta['iters']} iterations with "
           "gtol = 0 (fewer, at least 3, where a direct-solver run would exceed its time budget)",
           "* preconditioners: `library` = the library's `stiefel.shifted_inverse(W, A, λ₁)` "
           f"(`stiefel.linalg.sparse_factor.SymmetricFactor`, backend `{meta.get('factor_backend', 'qdldl')}`; "
           "skipped where its factorisation is predicted over budget; CHOLMOD does not report its factor's nnz); "
           "`superlu-colamd` = the same SuperLU factorisation with the COLAMD ordering (bench-side, "
           "`colamd_preconditioner`); `jacobi` = `diag(W + λ₁A)⁻¹`, O(n) (a 1-D array passed as `preconditioner=`)",
           f"* total: `library`, gtol 1e-4 / ftol 1e-5, ≤ {meta['total_iters']} iterations, k ∈ "
           f"{meta['total_ks']}, n ≤ {meta['total_max_n']:.0f}",
           "* each size ran in its own subprocess; peak RSS is that process's `ru_maxrss` (it includes the "
           "Python/JAX runtime, ~0.3 GiB)", "",
           "## Setup per size", "",
           "| n | faces | nnz(W) | load s | assembly s | " + " | ".join(f"eigsh k={k} s" for k in ks)
           + " | factor library s | nnz(factor) library | factor colamd s | nnz(L+U) colamd | fill colamd |",
           "|---:|---:|---:|---:|---:|" + "---:|" * len(ks) + "---:|---:|---:|---:|---:|"]
    for r in rows:
        eigs = []
        for k in ks:
            e = r["eigsh"].get(str(k), {})
            eigs.append(_fmt(e.get("seconds")) if e.get("seconds") is not None else f"skipped ({e.get('skipped', '')})")
        fm, fc = r["factor"]["library"], r["factor"]["superlu-colamd"]
        fm_s = _fmt(fm.get("seconds")) if fm.get("seconds") is not None else f"skipped ({fm.get('skipped')})"
        out.append(f"| {r['n']} | {r['n_faces']} | {r['nnz_W']} | {r['load_seconds']:.2f} | {r['assembly_seconds']:.2f} | "
                   + " | ".join(eigs) + f" | {fm_s} | {_fmt(fm.get('lu_nnz'), '{:d}')} | {fc['seconds']:.2f} | "
                   f"{fc['lu_nnz']} | {fc['lu_nnz'] / r['nnz_W']:.1f} |")
    out += ["", "## Block solver per iteration", "",
            "ms/it: wall time of the fixed-length run ÷ iterations (compilation apart). Split: one preconditioner "
            "application `P·Y` (Y: n×k, timed apart), objective+gradient evaluations (ms per evaluation × "
            "evaluations per iteration, line-search trials included), rest (retraction, projections, CG "
            "bookkeeping; negative where the separately timed parts overlap or the machine's load changed).", "",
            "| n | k | preconditioner | iterations | ms/it | P apply ms | value+grad ms × evals/it | rest ms | "
            "compile s | n·k·8 MiB | total: s (it., status, objective start → end) |",
            "|---:|---:|---|---:|---:|---:|---|---:|---:|---:|---|"]
    for r in rows:
        for k in ks:
            for pname in PRECONDS:
                s = r["solver"].get(f"{pname}_{k}")
                if not s:
                    continue
                if "skipped" in s:
                    out.append(f"| {r['n']} | {k} | {pname} | – | skipped ({s['skipped']}) | "
                               f"{_fmt(s['ms_precond_apply'], '{:.0f}')} | – | – | – | {r['n'] * k * 8 / mib:.1f} | – |")
                    continue
                t = s.get("total")
                tot = (f"{t['seconds']:.1f} ({t['iterations']}, {t['status']}, {t['objective_start']:.2f} → "
                       f"{t['objective_final']:.2f})") if t else "–"
                out.append(f"| {r['n']} | {k} | {pname} | {s['iterations']} | {s['ms_per_iteration']:.1f} | "
                           f"{s['ms_precond_apply']:.1f} | {s['ms_value_and_grad']:.1f} × {s['fevals_per_iteration']:.2f} | "
                           f"{s['ms_rest_per_iteration']:.1f} | {s['compile_seconds']:.1f} | "
                           f"{s['block_bytes'] / mib:.1f} | {tot} |")
    out += ["", "## Memory", "",
            "| n | peak RSS MiB | n·10·8 MiB | n·50·8 MiB | nnz(W)·12 B MiB | nnz(L+U) colamd ·12 B MiB | "
            "RSS after assembly / eigsh / factorisations MiB |",
            "|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        lu = r["factor"]["superlu-colamd"]["lu_nnz"]
        out.append(f"| {r['n']} | {r['peak_rss_bytes'] / mib:.0f} | {r['n'] * 80 / mib:.1f} | {r['n'] * 400 / mib:.1f} | "
                   f"{r['nnz_W'] * 12 / mib:.1f} | {lu * 12 / mib:.1f} | {r['rss_after_assembly_bytes'] / mib:.0f} / "
                   f"{r['rss_after_eigsh_bytes'] / mib:.0f} / {r['rss_after_factor_bytes'] / mib:.0f} |")
    out += ["", "## Fitted exponents p in t ∝ n^p (least squares in log–log over the sizes where measured)", "",
            "\"p, last two\": the slope between the two largest sizes where measured.", "",
            "| quantity | p | p, last two | sizes |", "|---|---:|---:|---:|"]
    for name, pexp in exps.items():
        out.append(f"| {name} | {_fmt(pexp)} | {_fmt(last2.get(name))} | {_count(rows, name)} |")
    return "\n".join(out) + "\n"


def _count(rows, name) -> int:
    """How many sizes entered the fit called ``name`` (for the table)."""
    return sum(1 for r in rows if _value(r, name) not in (None, 0))


def _value(r, name):
    if name.startswith("factorisation ") or name.startswith("nnz(L+U) "):
        f = r["factor"][name.split(" ", 1)[1]]
        return f.get("seconds") if name.startswith("factorisation") else f.get("lu_nnz")
    if name.startswith("eigsh k="):
        return r["eigsh"].get(name.split("=")[1], {}).get("seconds")
    if name.startswith("ms/iteration ") or name.startswith("P apply "):
        pname, k = name.rsplit(" ", 2)[-2], name.rsplit("=", 1)[1]
        return (r["solver"].get(f"{pname}_{k}") or {}).get("ms_per_iteration")
    if name.startswith("value+grad"):
        return (r["solver"].get(f"jacobi_{name.rsplit('=', 1)[1]}") or {}).get("ms_value_and_grad")
    if name.startswith("total"):
        return ((r["solver"].get(f"library_{name.rsplit('=', 1)[1]}") or {}).get("total") or {}).get("seconds")
    return 1


def _predict(row, prior, rows):
    """Predicted eigsh and library-factorisation seconds at the next size (≈ ×4 vertices), into ``prior``."""
    prev = rows[-2] if len(rows) >= 2 else None
    grow = row["n"] / prev["n"] if prev else 4.0
    for k, e in row["eigsh"].items():
        prior[int(k)] = e["seconds"] * grow**1.5 if e.get("seconds") else float("inf")
    t_f = row["factor"]["library"].get("seconds")
    if not t_f:
        prior["factor"] = float("inf")
        return
    p_f = 2.0  # measured exponent between the last two sizes, at least 2
    t_prev = prev and prev["factor"]["library"].get("seconds")
    if t_prev:
        p_f = max(p_f, float(np.log(t_f / t_prev) / np.log(grow)))
    prior["factor"] = t_f * grow**p_f


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--base", default="example:bumpy",
                   help="example:NAME, a path or a mesh in ../shared/meshes (the committed results: bunny.off)")
    p.add_argument("--levels", type=int, nargs="+", default=[1, 2, 3, 4])
    p.add_argument("--ks", type=int, nargs="+", default=[10, 50])
    p.add_argument("--iters", type=int, default=20, help="fixed iterations for the per-iteration timing")
    p.add_argument("--min-iters", type=int, default=3, help="at least this many (SuperLU runs over budget)")
    p.add_argument("--solve-budget", type=float, default=60.0, help="seconds per SuperLU-preconditioned run")
    p.add_argument("--factor-budget", type=float, default=120.0, help="skip the SuperLU factorisation when "
                   "predicted above (s)")
    p.add_argument("--total-ks", type=int, nargs="+", default=[10])
    p.add_argument("--mem-factor", type=float, default=80.0, help="skip a solver run when this many n×k float64 "
                   "blocks exceed the available memory (measured: peak RSS growth ≈ 70 blocks at n = 2.2e5, k = 50)")
    p.add_argument("--total-max-n", type=float, default=6e4, help="run to tolerance only up to this n")
    p.add_argument("--total-iters", type=int, default=150)
    p.add_argument("--mu-factor", type=float, default=0.01)
    p.add_argument("--eigsh-budget", type=float, default=240.0, help="skip eigsh when predicted above (s)")
    p.add_argument("--cache", default=str(default_cache()))
    p.add_argument("--out-json", type=Path, default=None, help="default: docs/benchmarks/scaling.json")
    p.add_argument("--out-md", type=Path, default=None, help="default: docs/benchmarks/scaling.md")
    p.add_argument("--resume", default=None, help="reuse the rows of these levels from an earlier results JSON")
    p.add_argument("--render", default=None, help="only re-render --out-md (and the fits in --out-json) "
                   "from this results JSON")
    p.add_argument("--worker", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--prior", default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.worker is not None:
        print("ROW " + json.dumps(worker(args)), flush=True)
        return 0
    out_json, out_md = args.out_json or results_path("scaling", ".json"), args.out_md or results_path("scaling")
    if args.render:  # re-render the markdown (and the fits) from a results JSON
        res = json.loads(Path(args.render).read_text())
        res["exponents"] = exponents(res["rows"], res["meta"]["ks"])
        write_json(out_json, res)
        write_page(out_md, markdown(res["meta"], res["rows"], res["exponents"], res["meta"]["ks"]))
        return 0
    require([args.base])

    rows, prior = [], {}
    t_start = time.perf_counter()
    done = {}
    if args.resume:
        done = {r["level"]: r for r in json.loads(Path(args.resume).read_text())["rows"]
                if r.get("base", args.base) == args.base}
    for level in args.levels:
        if level in done:  # measured by an earlier run (--resume): keep its row
            rows.append(done[level])
            row = done[level]
            _predict(row, prior, rows)
            continue
        cmd = [sys.executable, "-m", "bench.scaling", "--worker", str(level), "--base", args.base,
               "--ks", *map(str, args.ks), "--iters", str(args.iters), "--total-max-n", str(args.total_max_n),
               "--total-iters", str(args.total_iters), "--mu-factor", str(args.mu_factor),
               "--min-iters", str(args.min_iters), "--solve-budget", str(args.solve_budget),
               "--factor-budget", str(args.factor_budget), "--total-ks", *map(str, args.total_ks),
               "--mem-factor", str(args.mem_factor),
               "--eigsh-budget", str(args.eigsh_budget), "--cache", args.cache, "--prior", json.dumps(prior)]
        proc = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, text=True)
        line = [ln for ln in proc.stdout.splitlines() if ln.startswith("ROW ")]
        if proc.returncode or not line:
            print(f"python -m bench scaling: level {level}'s process failed (exit {proc.returncode}); nothing written",
                  file=sys.stderr)
            return 1
        row = json.loads(line[-1][4:])
        rows.append(row)
        print(json.dumps({"n": row["n"], "done_after_s": time.perf_counter() - t_start}), flush=True)
        # predict the next size's eigsh time (×4 vertices, exponent 1.5)
        _predict(row, prior, rows)
    exps = exponents(rows, args.ks)
    from stiefel.linalg.sparse_factor import default_backend

    dev = jax.devices()[0]
    meta = {"date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores, {platform.platform()}", "commit": git_commit(),
            "versions": f"python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}, "
                        f"jax {jax.__version__}",
            "factor_backend": default_backend(),
            "backend": jax.default_backend(), "device": getattr(dev, "device_kind", str(dev)),
            "openblas_threads": os.environ.get("OPENBLAS_NUM_THREADS"),
            "command": "python -m bench scaling " + " ".join(argv if argv is not None else sys.argv[1:]),
            "base": args.base, "levels": args.levels, "cache": args.cache, "mu_factor": args.mu_factor,
            "iters": args.iters, "total_iters": args.total_iters, "total_max_n": args.total_max_n,
            "ks": args.ks, "total_ks": args.total_ks, "resumed_levels": sorted(done), "total_seconds": time.perf_counter() - t_start}
    write_json(out_json, {"meta": meta, "rows": rows, "exponents": exps})
    md = markdown(meta, rows, exps, args.ks)
    write_page(out_md, md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
