"""The scaling benchmark's measurement of one size, run in its own process (``python -m bench.scaling
--worker LEVEL``, so that its peak RSS is its own): load and assembly, ``eigsh`` for each k, the
preconditioners' factorisations and the block solver's time per iteration, split into its parts.

It relies on what ``bench.scaling`` sets before importing it: one BLAS thread and float64.
"""

from __future__ import annotations

import json
import resource
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from bench.subdivided_meshes import subdivided


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
