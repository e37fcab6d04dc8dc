"""Which method ``stiefel.minimize`` uses by default: every method on a panel of problems with known optima.

    python -m bench default-method                 # n = 10² … 10⁴, 5 starts (1 from n = 5000 on)
    python -m bench default-method --quick         # n ≤ 10³, 2 starts, no trust regions, no preconditioner
    python -m bench default-method --large         # adds n ≈ 10⁵ (a grid and a mesh)

Problems (k = 4; starts ``S.random_point(PRNGKey(seed))``, seeds 0, 1, …):

* ``brockett``: ``tr(XᵀAXD)``, D = diag(k, …, 1), A the 5-point Dirichlet Laplacian of an m×m grid, M a random
  diagonal in [0.5, 2] (n = m²); optimum ``Σ d_j λ_j`` and the eigenvectors column by column (scipy ``eigsh``);
* ``eigen-fem``: ``tr(XᵀWX)`` (rotation invariant), W the cotangent Laplacian of the demo mesh (``example:bumpy``,
  sizes 0–1; ``--large``: also size 2 and ``example:patch`` size 8), M its FEM mass matrix (sparse, not diagonal); optimum
  ``Σ λ_j`` and the span of the eigenvectors;
* ``eigen-dense``: the same with the grid's graph Laplacian and a dense SPD M = ½I + BBᵀ/n (B Gaussian);
* ``procrustes``: ``−tr(XᵀC)``, C Gaussian; optimum ``X* = M⁻¹C(CᵀM⁻¹C)^{-1/2}``, ``F* = −tr((CᵀM⁻¹C)^{1/2})``
  (dense M as above, and diagonal M);
* ``sparse-pca``: ``−‖ZX‖²/p + μΣ√(X² + ε²)`` on XᵀX = I, Z spiked data (p = 2n samples, k sparse spikes), μ = 0.01,
  ε = 0.01: no closed form, the reference is the lowest value any run reached (``known`` = no).

Methods: ``stiefel.minimize`` with ``method="cg"``, ``"lbfgs"``, ``"bb"``, and CG / L-BFGS with the shifted
preconditioner ``(A + σM)⁻¹`` (σ = λ_k) on the eigenproblems; ``stiefel.RiemannianTrustRegion``
(exact Hessian; not a ``minimize`` method) through ``optx.minimise``, plain and preconditioned; and ``default``:
``stiefel.minimize(F, S, X0)`` with no option (its method gets no row of its own). All at gtol = 1e-6 (the
default), each run capped at the default's iterations (``--max-iters``; ``--tr-steps`` for trust regions) and,
but for the default's, ``--run-limit`` seconds of solving (then ``interrupted``).

Per (problem, method): runs converged; runs that agree with the optimum (objective relative error ≤ 1e-8);
runs converged within 1000 iterations; median and largest iterations; the largest objective error and
distance to the reference (subspace sin θ; Brockett: per column; Procrustes: ‖X − X*‖_M/√k); compile seconds
(the first start; later starts reuse the program) and median solve seconds, apart.

Round-off floor: from each problem's first default solve (n < 5000), L-BFGS and CG continue at gtol = 0 until
they stop; the table gives the status, the gradient norm reached and ``stats["round_off_floor"]``.

Writes ``docs/benchmarks/default-method.md`` and ``default-method.json`` when complete (atomically, notes kept).
"""

from __future__ import annotations

import argparse
import os
import sys
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # benchmark script (an application), not library code

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402
import scipy.linalg as sla  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402

import mesh  # noqa: E402
import stiefel  # noqa: E402
from bench.environment import header_lines, results_path, run_meta, write_results  # noqa: E402
from stiefel.linalg.operators import quadratic_form  # noqa: E402
from stiefel_cmm.cli.grid_demo import grid_laplacian  # noqa: E402

AGREE = 1e-8  # objective relative error that counts as agreement with the optimum
K = 4


class Brockett(eqx.Module):
    """``tr(XᵀAXD) = tr((X√D)ᵀA(X√D))``."""

    A: stiefel.LinearOperator
    sqrt_d: jax.Array

    def __call__(self, X):
        return quadratic_form(self.A, X * self.sqrt_d)


class Rayleigh(eqx.Module):
    """``tr(XᵀAX)``: the sum of the k smallest generalised eigenvalues at the minimum."""

    A: stiefel.LinearOperator

    def __call__(self, X):
        return quadratic_form(self.A, X)


class Procrustes(eqx.Module):
    """``−tr(XᵀC)``."""

    C: jax.Array

    def __call__(self, X):
        return -jnp.sum(X * self.C)


class SparsePCA(eqx.Module):
    """``−‖ZX‖²/p + μ Σ √(X² + ε²)``."""

    Z: jax.Array
    mu: float
    eps: float

    def __call__(self, X):
        return -jnp.sum((self.Z @ X) ** 2) / self.Z.shape[0] + self.mu * jnp.sum(jnp.sqrt(X * X + self.eps ** 2))


def dirichlet_grid(m: int) -> sp.csr_array:
    """The 5-point Dirichlet Laplacian of an m×m grid (SPD)."""
    path = sp.diags_array([-np.ones(m - 1), 2.0 * np.ones(m), -np.ones(m - 1)], offsets=[-1, 0, 1])
    return sp.csr_array(sp.kron(path, sp.identity(m)) + sp.kron(sp.identity(m), path))


def dense_spd(n: int, seed: int) -> np.ndarray:
    B = np.random.default_rng(seed).standard_normal((n, n))
    return 0.5 * np.eye(n) + B @ B.T / n


def _mv(M, X):
    return M[:, None] * X if M.ndim == 1 else M @ X


def _eig(A, M, k, dense: bool):
    """The k smallest generalised eigenpairs ``AV = MVΛ`` (V M-orthonormal)."""
    if dense:
        Ad = A.toarray() if sp.issparse(A) else A
        return sla.eigh(Ad, M if M.ndim == 2 else np.diag(M), subset_by_index=[0, k - 1])
    Ms = sp.diags_array(M) if M.ndim == 1 else sp.csc_array(M)
    lam, V = spla.eigsh(sp.csc_array(A), k, M=Ms.tocsc(), sigma=-1e-3, which="LM")
    order = np.argsort(lam)
    return lam[order], V[:, order]


def _problem(family, label, A, M, F, optimum, ref, compare, sigma=None):
    S = stiefel.GeneralizedStiefel(M, K)
    dense = not sp.issparse(M) and M.ndim == 2
    P = stiefel.shifted_inverse(A.toarray() if dense else A, M, sigma) if sigma else None
    kind = ("sparse" if sp.issparse(M) else "dense" if dense else "identity" if np.all(M == 1) else "diagonal")
    return dict(family=family, label=label, n=S.n, m_kind=kind, S=S, M=M, F=F, optimum=optimum, ref=ref,
                compare=compare, P=P)


def brockett(m: int) -> dict:
    A, n = dirichlet_grid(m), m * m
    M = np.random.default_rng(0).uniform(0.5, 2.0, n)
    lam, V = _eig(A, M, K, dense=False)
    d = np.arange(K, 0, -1.0)
    F = Brockett(stiefel.as_operator(A, check=False, factor=False), jnp.sqrt(jnp.asarray(d)))
    return _problem("brockett", f"brockett grid {m}×{m}", A, M, F, float(d @ lam), V, "columns", float(lam[-1]))


def eigen_fem(name: str, size: int) -> dict:
    lap = mesh.laplacian(mesh.example(name, size), area="fem")
    A, M = lap.W, sp.csr_array(lap.A)
    lam, V = _eig(A, M, K, dense=False)
    F = Rayleigh(stiefel.as_operator(A, check=False, factor=False))
    return _problem("eigen-fem", f"eigen {name}:{size} FEM mass", A, M, F, float(lam.sum()), V, "subspace",
                    float(lam[-1]))


def eigen_dense(m: int) -> dict:
    A, n = grid_laplacian(m), m * m
    M = dense_spd(n, 1)
    lam, V = _eig(A, M, K, dense=True)
    F = Rayleigh(stiefel.as_operator(A, check=False, factor=False))
    return _problem("eigen-dense", f"eigen grid {m}×{m} dense M", A, M, F, float(lam.sum()), V, "subspace",
                    float(lam[-1]))


def procrustes(n: int, dense: bool) -> dict:
    M = dense_spd(n, 2) if dense else np.random.default_rng(2).uniform(0.5, 2.0, n)
    C = np.random.default_rng(3).standard_normal((n, K))
    MiC = np.linalg.solve(M, C) if dense else C / M[:, None]
    lam, Q = np.linalg.eigh(C.T @ MiC)
    X = MiC @ (Q / np.sqrt(lam)) @ Q.T
    return _problem("procrustes", f"procrustes n = {n} {'dense' if dense else 'diagonal'} M", None, M,
                    Procrustes(jnp.asarray(C)), float(-np.sqrt(lam).sum()), X, "point")


def sparse_pca(n: int) -> dict:
    rng = np.random.default_rng(4)
    p = 2 * n
    U = np.zeros((n, K))
    for j in range(K):  # k sparse spikes (10 % of the entries), strengths 4, 3, 2, 1.5
        idx = rng.choice(n, max(2, n // 10), replace=False)
        U[idx, j] = rng.standard_normal(idx.size)
    U, _ = np.linalg.qr(U)
    Z = rng.standard_normal((p, n)) + (rng.standard_normal((p, K)) * np.array([4.0, 3.0, 2.0, 1.5])) @ U.T
    return _problem("sparse-pca", f"sparse PCA n = {n}", None, np.ones(n), SparsePCA(jnp.asarray(Z), 0.01, 0.01),
                    None, None, "subspace")


def panel(args) -> list:
    """``(label, build)`` of every problem of this run (built one at a time)."""
    out = [(f"brockett {m}", lambda m=m: brockett(m)) for m in args.grids]
    out += [(f"eigen-fem {s}", lambda s=s: eigen_fem(s.split(":")[0], int(s.split(":")[1]))) for s in args.meshes]
    out += [(f"eigen-dense {m}", lambda m=m: eigen_dense(m)) for m in args.dense]
    out += [(f"procrustes {n}", lambda n=n: procrustes(n, True)) for n in args.procrustes_dense]
    out += [(f"procrustes {n}", lambda n=n: procrustes(n, False)) for n in args.procrustes_diag]
    out += [(f"sparse-pca {n}", lambda n=n: sparse_pca(n)) for n in args.pca]
    return out


def methods(pb: dict, quick: bool) -> dict:
    """name → ``("minimize", options)`` or ``("tr", preconditioner or None)``; the default's own method is its row."""
    default = stiefel.solvers.block_solver.DEFAULT_METHOD
    out = {f"default ({default})": ("minimize", {})}
    out.update({m: ("minimize", dict(method=m)) for m in ("lbfgs", "cg", "bb") if m != default})
    if pb["P"] is not None and not quick:
        out["cg + P"] = ("minimize", dict(method="cg", preconditioner=pb["P"]))
        out["lbfgs + P"] = ("minimize", dict(method="lbfgs", preconditioner=pb["P"]))
    if not quick:
        out["tr"] = ("tr", None)
        if pb["P"] is not None:
            out["tr + P"] = ("tr", pb["P"].solve)
    return out


def distance(pb: dict, X: np.ndarray, ref: np.ndarray) -> float:
    """sin of the largest principal angle to ``span(ref)`` (M-inner product), per column for Brockett, or
    ``‖X − ref‖_M/√k`` for Procrustes."""
    M = pb["M"]
    if pb["compare"] == "point":
        D = X - ref
        return float(np.sqrt(max(np.sum(D * _mv(M, D)), 0.0) / K))
    if pb["compare"] == "columns":
        c = np.sum(ref * _mv(M, X), axis=0)
        R = X - ref * c
        return float(np.sqrt(np.max(np.maximum(np.sum(R * _mv(M, R), axis=0), 0.0))))
    R = X - ref @ (ref.T @ _mv(M, X))
    return float(np.sqrt(max(np.linalg.eigvalsh(R.T @ _mv(M, R))[-1], 0.0)))


def time_limit(seconds: float):
    """A ``stop`` callable that is set ``seconds`` after its first call (the solve's first check, after compiling)."""
    start = []

    def stop() -> bool:
        start.append(time.perf_counter()) if not start else None
        return time.perf_counter() - start[0] > seconds

    return stop


def _tr_solver(S, P, gtol, steps):
    return stiefel.RiemannianTrustRegion(S, 0.0, gtol, preconditioner=P, history=steps + 1)


def solve(pb, kind, opts, X0, args, compiled):
    """One run: ``(x, value, grad_norm, iterations, status, n_fevals, solve s, compile s, at_floor)``."""
    if kind == "minimize":
        kw = {} if not opts or args.max_iters is None else dict(max_iters=args.max_iters)
        stop = time_limit(args.run_limit) if opts else None  # the default runs to its own cap
        r = stiefel.minimize(pb["F"], pb["S"], X0, stop=stop, **opts, **kw)
        return (np.asarray(r.x), float(r.value), float(r.grad_norm), int(r.iterations), r.status_name,
                int(r.stats["n_fevals"]), r.wall_time, r.compile_time, r.at_floor)
    solver = _tr_solver(pb["S"], opts, args.gtol, args.tr_steps)
    t_compile = 0.0
    if "tr" not in compiled:
        run = eqx.filter_jit(lambda F, s, X0: optx.minimise(lambda X, a: F(X), s, X0, None,
                                                            max_steps=args.tr_steps, throw=False))
        t = time.perf_counter()
        compiled["tr"] = run.lower(pb["F"], solver, X0).compile()
        t_compile = time.perf_counter() - t
    t = time.perf_counter()
    sol = compiled["tr"](pb["F"], solver, X0)
    jax.block_until_ready(sol.value)
    t_solve = time.perf_counter() - t
    st = sol.stats
    code = int(st["status"])
    return (np.asarray(sol.value), float(st["value"]), float(st["grad_norm"]), int(st["num_steps"]),
            stiefel.Status.name(code) if code >= 0 else "max_iters", int(st["n_fevals"]), t_solve, t_compile,
            bool(st.get("at_floor", False)))


def run_problem(pb: dict, args) -> tuple[list[dict], list[dict]]:
    """Every method from every start, then the floor runs; returns (rows, floor rows)."""
    starts = args.starts if pb["n"] < 5000 else args.large_starts
    X0s = [pb["S"].random_point(jax.random.PRNGKey(seed)) for seed in range(starts)]
    rows, first_default = [], None
    for name, (kind, opts) in methods(pb, args.quick).items():
        compiled, spent = {}, 0.0
        for seed, X0 in enumerate(X0s):
            if seed > 0 and spent > args.method_budget:  # enough time on this (problem, method)
                break
            x, value, gn, it, status, fev, t_solve, t_compile, at_floor = solve(pb, kind, opts, X0, args, compiled)
            spent += t_solve
            if name.startswith("default") and seed == 0:
                first_default = x
            rows.append(dict(problem=pb["label"], family=pb["family"], n=pb["n"], k=K, m_kind=pb["m_kind"],
                             method=name, seed=seed, status=status, iterations=it, value=value, grad_norm=gn,
                             n_fevals=fev, solve=t_solve, compile=t_compile, at_floor=at_floor,
                             x_err=distance(pb, x, pb["ref"]) if pb["ref"] is not None else None, x=x))
            print(f"{pb['label']:<32} {name:<11} seed {seed}: {status:<18} it {it:>5}  |g| {gn:.1e}  "
                  f"F {value:.12g}  solve {t_solve:.2f} s  compile {t_compile:.2f} s", flush=True)
    if pb["optimum"] is None:  # no closed form: the lowest value reached is the reference
        best = min((r for r in rows if np.isfinite(r["value"])), key=lambda r: r["value"])
        pb["optimum"] = best["value"]
        for r in rows:
            r["x_err"] = distance(pb, r["x"], best["x"])
    for r in rows:
        r["value_err"] = abs(r["value"] - pb["optimum"]) / max(abs(pb["optimum"]), 1e-300)
        r["known"] = pb["family"] != "sparse-pca"
        del r["x"]
    floors = []
    for method in ("lbfgs", "cg") if pb["n"] < 5000 else ():  # from the default's answer to the floor: gtol = 0
        cap = {} if args.max_iters is None else dict(max_iters=args.max_iters)
        r = stiefel.minimize(pb["F"], pb["S"], jnp.asarray(first_default), method=method, gtol=0.0,
                             stop=time_limit(args.run_limit), **cap)
        floor = r.stats.get("round_off_floor")
        floors.append(dict(problem=pb["label"], method=method, status=r.status_name, iterations=int(r.iterations),
                           grad_norm=float(r.grad_norm), value=float(r.value),
                           floor=None if floor is None else float(floor),
                           value_err=abs(float(r.value) - pb["optimum"]) / max(abs(pb["optimum"]), 1e-300)))
        print(f"{pb['label']:<32} floor {method}: {floors[-1]}", flush=True)
    return rows, floors


def summary(rows: list[dict]) -> list[dict]:
    """One line per (problem, method)."""
    out = []
    for key in dict.fromkeys((r["problem"], r["method"]) for r in rows):
        g = [r for r in rows if (r["problem"], r["method"]) == key]
        conv = [r for r in g if r["status"] == "converged"]
        it = [r["iterations"] for r in g]
        out.append(dict(problem=key[0], method=key[1], n=g[0]["n"], m_kind=g[0]["m_kind"], runs=len(g),
                        converged=len(conv), agree=sum(r["status"] == "converged" and r["value_err"] <= AGREE
                                                       for r in g),
                        within_1000=sum(r["iterations"] <= 1000 for r in conv), median_it=int(np.median(it)),
                        max_it=max(it), max_value_err=max(r["value_err"] for r in g),
                        max_x_err=max((r["x_err"] for r in g), default=None), compile=g[0]["compile"],
                        median_solve=float(np.median([r["solve"] for r in g])),
                        statuses=sorted({r["status"] for r in g if r["status"] != "converged"})
                        + ([f"{sum(r['at_floor'] for r in g)} converged at the floor"] if any(r["at_floor"] for r in g)
                           else []), known=g[0]["known"]))
    return out


def report(meta: dict, rows: list[dict], floors: list[dict]) -> str:
    lines = ["# The default method of `stiefel.minimize`: every method on a panel with known optima", "",
             *header_lines(meta),
             f"* gtol {meta['gtol']:g} (the default), each run capped at {meta['max_iters']} iterations (trust "
             f"regions: {meta['tr_steps']}) and, but for the default's, {meta['run_limit']:g} s of solving (then "
             f"`interrupted`); k = {K}; starts per problem: "
             f"{meta['starts']} ({meta['large_starts']} from n = 5000 on; fewer where a method spent "
             f"{meta['method_budget']:g} s)",
             f"* agree: converged and objective within {AGREE:g} (relative) of the optimum (sparse PCA: of the lowest "
             "value any run reached); ≤ 1000 it.: converged within the former default's cap; distance: sin of the "
             "largest principal angle to the reference (Brockett: per column; Procrustes: ‖X − X*‖_M/√k)",
             "* seconds: compile (first start; the other starts reuse the program) apart from solve (median over "
             "starts); `default` is `stiefel.minimize(F, S, X0)` with no option", "",
             "## By method, over the whole panel", "",
             "| method | problems | runs | converged | agree | converged ≤ 1000 it. | median it. | largest it. | "
             "largest objective error | compile s (mean) | solve s (sum of medians) |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    summ = summary(rows)
    for method in dict.fromkeys(s["method"] for s in summ):
        g = [s for s in summ if s["method"] == method]
        mine = [r for r in rows if r["method"] == method]
        lines.append(f"| {method} | {len(g)} | {sum(s['runs'] for s in g)} | {sum(s['converged'] for s in g)} | "
                     f"{sum(s['agree'] for s in g)} | {sum(s['within_1000'] for s in g)} | "
                     f"{int(np.median([r['iterations'] for r in mine]))} | {max(s['max_it'] for s in g)} | "
                     f"{max(s['max_value_err'] for s in g):.1e} | {np.mean([s['compile'] for s in g]):.1f} | "
                     f"{sum(s['median_solve'] for s in g):.1f} |")
    lines += ["", "## By problem", "",
              "| problem | n | M | method | converged | agree | ≤ 1000 it. | median it. | largest it. | largest objective "
              "error | largest distance | compile s | solve s | other statuses |",
              "|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for s in summ:
        xe = "—" if s["max_x_err"] is None else f"{s['max_x_err']:.1e}"
        lines.append(f"| {s['problem']} | {s['n']} | {s['m_kind']} | {s['method']} | {s['converged']}/{s['runs']} | "
                     f"{s['agree']}/{s['runs']} | {s['within_1000']} | {s['median_it']} | {s['max_it']} | "
                     f"{s['max_value_err']:.1e}{'' if s['known'] else ' (best)'} | {xe} | {s['compile']:.1f} | "
                     f"{s['median_solve']:.2f} | {', '.join(s['statuses']) or '—'} |")
    lines += ["", "## The round-off floor", "",
              "From the default's first answer, L-BFGS and CG continue with gtol = 0: where they stop, the status, the "
              "gradient norm and the floor `stats[\"round_off_floor\"]` (a failed line search at or below it is "
              "reported as converged).", "",
              "| problem | method | status | iterations | ‖grad‖ | floor | ‖grad‖ / floor | objective error |",
              "|---|---|---|---:|---:|---:|---:|---:|"]
    for f in floors:
        fl, ratio = ("—", "—") if f["floor"] is None else (f"{f['floor']:.1e}", f"{f['grad_norm'] / f['floor']:.2g}")
        lines.append(f"| {f['problem']} | {f['method']} | {f['status']} | {f['iterations']} | {f['grad_norm']:.1e} | "
                     f"{fl} | {ratio} | {f['value_err']:.1e} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench default-method", description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="n ≤ 10³, 2 starts, fewer methods (about 2 minutes)")
    p.add_argument("--large", action="store_true",
                   help="add example:bumpy size 2 (n = 10242) and n ≈ 10⁵: grid 316×316, example:patch size 8")
    p.add_argument("--starts", type=int, default=None, help="random starts per problem (default 5; quick: 2)")
    p.add_argument("--large-starts", type=int, default=1, help="random starts from n = 5000 on (default 1)")
    p.add_argument("--max-iters", type=int, default=None,
                   help="iteration cap of the first-order runs other than the default (default: the library's)")
    p.add_argument("--tr-steps", type=int, default=1000, help="outer iteration cap of the trust-region runs")
    p.add_argument("--run-limit", type=float, default=120.0,
                   help="seconds per run, compilation excluded (then status interrupted)")
    p.add_argument("--method-budget", type=float, default=30.0,
                   help="no further start for a (problem, method) once its solves took this many seconds")
    p.add_argument("--out", default="default-method", help="results name under docs/benchmarks")
    args = p.parse_args(argv)
    args.gtol = 1e-6
    args.starts = args.starts or (2 if args.quick else 5)
    args.grids = [20] if args.quick else [10, 20, 100] + ([316] if args.large else [])
    args.meshes = ["bumpy:0"] if args.quick else ["bumpy:0", "bumpy:1"] + (["bumpy:2", "patch:8"] if args.large else [])
    args.dense = [] if args.quick else [32]
    args.procrustes_dense = [] if args.quick else [1024]
    args.procrustes_diag = [] if args.quick else [10000]
    args.pca = [100] if args.quick else [100, 1000]
    rows, floors = [], []
    t0 = time.perf_counter()
    for label, build in panel(args):
        r, f = run_problem(build(), args)
        rows += r
        floors += f
    cap = args.max_iters or stiefel.solvers.block_solver.DEFAULT_MAX_ITERS
    meta = run_meta("bench default-method", argv, gtol=args.gtol, max_iters=cap, tr_steps=args.tr_steps,
                    run_limit=args.run_limit, starts=args.starts, large_starts=args.large_starts,
                    method_budget=args.method_budget, quick=args.quick, seconds=time.perf_counter() - t0)
    write_results(results_path(args.out, ".json"), results_path(args.out), meta,
                  rows + [dict(kind="floor", **f) for f in floors], report(meta, rows, floors))
    return 0


if __name__ == "__main__":
    sys.exit(main())
