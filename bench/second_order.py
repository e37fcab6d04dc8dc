"""Second order against first order: Riemannian trust regions (exact Hessian, with and without the shifted
preconditioner) against CG and L-BFGS, and pymanopt's TrustRegions on the same problems.

    python -m bench second-order                         # quick: Brockett n = 10³; example:bumpy
    python -m bench second-order --brockett 1000 10000 100000 \\
        --meshes fandisk.off camelhead.off armadillo_25479.obj --pymanopt /path/to/python-with-pymanopt

Problems:
* generalised Brockett ``tr(XᵀWXD)`` on ``XᵀMX = I``: W a 2-D grid Laplacian + 0.01·I (n = m²), M a random
  positive diagonal, D = diag(k, …, 1), k = 5; the optimum ``Σ d_j λ_j`` from scipy's ``eigsh``;
* the final continuation stage of a CMM solve (huber f6, δ = 10⁻³, μ = 2λ_(k−1), area weights, k = 10),
  started from the result of the first three stages (``BlockCMM(continuation=3)`` to δ = 4.6·10⁻³);
  first-order solvers stop there as the CMM solver's last stage does (``solvers``), trust regions run
  alone and as a finish after L-BFGS.

Every solver runs to the Riemannian gradient norm ``--gtol`` (M-metric) from the same start, through
``optx.minimise``; compile time is measured apart (``jit(...).lower().compile()``). "W products" counts
the products of W with an n×k block actually executed (a second, untimed run whose W counts itself
through a ``jax.debug.callback``, also in the Hessian-vector products). pymanopt (2.2.1 has no generalised
Stiefel manifold) solves the isometric problem on ``St(n, k)``: ``Y = M^{1/2}X``,
``W̃ = M^{-1/2}WM^{-1/2}``, with numpy gradients and Hessians — its gradient norm is the same number as ours.
Above n = 2·10⁴ the Brockett problems run only the preconditioned solvers (unpreconditioned trust regions
had not finished after 8 minutes at n = 10⁵: the Hessian's condition number grows like n).
Writes ``docs/benchmarks/second-order.md`` (notes below ``<!-- notes -->`` kept), ``second-order.json`` and
``second-order.png`` beside it (gradient norm per iteration: local quadratic convergence).
"""

from __future__ import annotations

import argparse
import io
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg as spla  # noqa: E402

import stiefel  # noqa: E402
from bench.environment import header_lines, results_path, run_meta, write_atomic, write_json, write_page  # noqa: E402
from bench.meshes import require  # noqa: E402

COUNT = [0]
UNPRECONDITIONED_MAX_N = 20000


def _tick(columns):
    COUNT[0] += int(columns)


@jax.custom_jvp
def _counted_mv(op, x):
    jax.debug.callback(_tick, x.shape[-1] + 0 * x[0, 0])
    return op.mv(x)


@_counted_mv.defjvp
def _counted_mv_jvp(primals, tangents):
    op, x = primals
    return _counted_mv(op, x), _counted_mv(op, tangents[1])


class Counted(eqx.Module):
    """W that counts its executed products (the tangent products of a JVP too)."""

    op: stiefel.LinearOperator

    def mv(self, x):
        return _counted_mv(self.op, x)


class Brockett(eqx.Module):
    """``Σ_j d_j x_jᵀWx_j = tr((X√D)ᵀW(X√D))`` (one W product for value and gradient)."""

    W: object
    sqrt_d: jax.Array

    def __call__(self, X, args=None):
        return stiefel.linalg.operators.quadratic_form(self.W, X * self.sqrt_d)


def brockett_problem(n: int, k: int = 5, seed: int = 0) -> dict:
    m = int(round(np.sqrt(n)))
    e = np.ones(m)
    path = sp.diags([-e[:-1], 2 * e, -e[:-1]], [-1, 0, 1])
    W = (sp.kron(path, sp.identity(m)) + sp.kron(sp.identity(m), path) + 0.01 * sp.identity(m * m)).tocsr()
    M = np.random.default_rng(seed).uniform(0.5, 2.0, m * m)
    d = np.arange(k, 0, -1.0)
    lam = np.sort(spla.eigsh(W, k, M=sp.diags(M).tocsc(), sigma=0.0, which="LM")[0])
    S = stiefel.GeneralizedStiefel(M, k)
    Wop = stiefel.as_operator(W, check=False, factor=False)
    return {"label": f"Brockett n = {m * m}", "n": m * m, "k": k, "W": W, "M": M, "S": S, "Wop": Wop,
            "make": lambda Wo: Brockett(Wo, jnp.sqrt(jnp.asarray(d))), "X0": S.random_point(jax.random.PRNGKey(seed)),
            "sigma": float(lam[-1]), "optimum": float(d @ lam), "kind": "brockett", "d": d}


def cmm_problem(spec: str, k: int = 10) -> dict:
    import mesh  # noqa: PLC0415
    from bench.meshes import load_mesh  # noqa: PLC0415
    from objectives.cmm.modes import compressed_modes, first_eigenpairs, unpack_laplacian  # noqa: PLC0415
    from objectives.cmm.solvers import BlockCMM  # noqa: PLC0415
    from objectives.energy.energies import cmm_energy  # noqa: PLC0415

    m, label = load_mesh(spec)
    lap = mesh.laplacian(m)
    W, a = unpack_laplacian(lap)
    pairs = first_eigenpairs(W, a, max(k, 2))
    lam = float(pairs[0][-1])
    mu = 2.0 * lam
    stages = np.geomspace(0.1, 1e-3, 4)
    warm = compressed_modes(lap, k, mu, eigenpairs=pairs, weighting="area",
                            solver=BlockCMM(eps=stages[2], delta=stages[2], continuation=3, continuation_start=0.1))
    S = stiefel.GeneralizedStiefel(a, k, retraction="cholesky")
    X0 = S.project_to_manifold(jnp.asarray(np.asarray(warm.modes)))
    Wop = stiefel.as_operator(W, check=False, factor=False)
    return {"label": f"{label} final stage", "n": m.n_vertices, "k": k, "W": W, "M": a, "S": S, "Wop": Wop,
            "make": lambda Wo: cmm_energy(Wo, a, mu, smoothing="f6", eps=1e-3, delta=1e-3, weighting="area"),
            "X0": X0, "sigma": lam, "optimum": None, "kind": "cmm", "mu": mu, "delta": 1e-3}


def solvers(problem: dict, gtol: float) -> dict:
    """name → (solver factory, finishing solver factory or None).

    Brockett: each solver alone to ``gtol``. CMM final stages: CG + P stops as the CMM solver's last stage
    does (``gtol``, or a relative decrease ≤ 10⁻⁷ over 20 iterations), L-BFGS + P runs to ``gtol`` (or
    ``--max-steps``), TR + P alone (at most 3000 iterations), and "L-BFGS + P → TR + P" runs L-BFGS until
    its objective settles (relative decrease ≤ 10⁻¹⁰ over 50 iterations) and finishes with trust regions;
    "P_X" is the CMM energy's curvature-aware point preconditioner (``objectives.cmm.newton``).
    """
    S = problem["S"]
    P = stiefel.shifted_inverse(problem["W"], problem["M"], problem["sigma"]).solve
    tr = lambda F: stiefel.RiemannianTrustRegion(S, 0.0, gtol, history=3001)  # noqa: E731
    trp = lambda F: stiefel.RiemannianTrustRegion(S, 0.0, gtol, preconditioner=P, history=3001)  # noqa: E731
    if problem["kind"] == "brockett":
        out = {"TR": (tr, None), "TR + P": (trp, None),
               "CG + P": (lambda F: stiefel.RiemannianCG(S, 0.0, gtol, preconditioner=P, history=5001), None),
               "L-BFGS + P": (lambda F: stiefel.RiemannianLBFGS(S, 0.0, gtol, preconditioner=P, history=5001), None),
               "L-BFGS": (lambda F: stiefel.RiemannianLBFGS(S, 0.0, gtol, history=5001), None)}
        if problem["n"] > UNPRECONDITIONED_MAX_N:  # hours without a preconditioner (module docstring)
            del out["TR"], out["L-BFGS"]
        return out
    stall = dict(ftol=1e-7, ftol_window=20, stall_test=True, history=5001)
    settle = dict(ftol=1e-10, ftol_window=50, stall_test=True, history=5001)
    line = lambda F: stiefel.solvers.block_solver._Line(F, False)  # noqa: E731
    cg = lambda F: stiefel.RiemannianCG(S, 0.0, gtol, preconditioner=P, line=line(F), **stall)  # noqa: E731
    lb = lambda F: stiefel.RiemannianLBFGS(S, 0.0, gtol, preconditioner=P, line=line(F), history=5001)  # noqa: E731
    lb_settle = lambda F: stiefel.RiemannianLBFGS(S, 0.0, gtol, preconditioner=P, line=line(F), **settle)  # noqa: E731
    from objectives.cmm.newton import curvature_preconditioner  # noqa: PLC0415

    a = jnp.asarray(problem["M"])
    trx = lambda F: stiefel.RiemannianTrustRegion(  # noqa: E731
        S, 0.0, gtol, preconditioner=curvature_preconditioner(F, P, a, problem["sigma"]), history=3001)
    return {"CG + P (CMM stop)": (cg, None), "L-BFGS + P": (lb, None), "TR + P": (trp, None),
            "TR + P_X": (trx, None), "L-BFGS + P → TR + P": (lb_settle, trp), "L-BFGS + P → TR + P_X": (lb_settle, trx)}


def _solve(F, X0, first, second, steps):
    sol = optx.minimise(lambda X, a: F(X), first(F), X0, None, max_steps=steps[0], throw=False)
    if second is None:
        return sol.value, sol.stats, None
    fin = optx.minimise(lambda X, a: F(X), second(F), sol.value, None, max_steps=steps[1], throw=False)
    return fin.value, fin.stats, sol.stats


def run_one(problem: dict, name: str, first, second, max_steps: int) -> dict:
    F = problem["make"](problem["Wop"])
    X0 = problem["X0"]
    steps = (max_steps, 3000)  # the first solver's limit (``--max-steps``), the trust-region finish's
    solve = eqx.filter_jit(lambda F, X0: _solve(F, X0, first, second, steps))
    t = time.perf_counter()
    compiled = solve.lower(F, X0).compile()
    t_compile = time.perf_counter() - t
    t = time.perf_counter()
    X, st, st1 = compiled(F, X0)
    jax.block_until_ready(X)
    t_run = time.perf_counter() - t
    COUNT[0] = 0
    jax.block_until_ready(solve(problem["make"](Counted(problem["Wop"])), X0)[0])
    steps_done = int(st["num_steps"])
    gn = np.asarray(st["history"].grad_norm)[: steps_done + 1]
    if st1 is not None:  # the first solver's history, then the second's
        n1 = int(st1["num_steps"])
        gn = np.concatenate([np.asarray(st1["history"].grad_norm)[: n1 + 1], gn[1:]])
        steps_done += n1
    status = int(st["status"])
    row = {"problem": problem["label"], "n": problem["n"], "k": problem["k"], "solver": name,
           "iterations": steps_done, "status": stiefel.Status.name(status) if status >= 0 else "max_iters",
           "value": float(st["value"]), "grad_norm": float(st["grad_norm"]), "seconds": t_run,
           "compile_seconds": t_compile, "w_products": COUNT[0] / problem["k"],
           "n_hvps": int(st.get("n_hvps", 0)), "history_grad_norm": [float(g) for g in gn[:: max(1, len(gn) // 400)]],
           "dist_to_manifold": float(problem["S"].dist_to_manifold(X))}
    if st1 is not None:
        row["first_iterations"] = int(st1["num_steps"])
        row["first_grad_norm"] = float(st1["grad_norm"])
    if problem["optimum"] is not None:
        row["error_vs_eigsh"] = abs(row["value"] - problem["optimum"]) / abs(problem["optimum"])
    print(json.dumps({k: v for k, v in row.items() if k != "history_grad_norm"}), flush=True)
    return row


#: the isometric problem on St(n, k) in pymanopt (module docstring): data from ``pymanopt_subprocess``; a tail script
#: (``PYMANOPT_TR`` here, bench.peers's CG) runs an optimiser on ``problem`` and prints one JSON line
PYMANOPT_PROBLEM = r'''
import json, sys, time, numpy as np, scipy.sparse as sp
import pymanopt
from pymanopt.manifolds import Stiefel
data = np.load(sys.argv[1], allow_pickle=False)
Wt = sp.load_npz(sys.argv[2]).tocsr()
Y0, kind = data["Y0"], str(data["kind"])
n, k = Y0.shape
manifold = Stiefel(n, k)
if kind == "brockett":
    d = data["d"]
    @pymanopt.function.numpy(manifold)
    def cost(Y): return float(np.sum((Y * (Wt @ Y)) @ d))
    @pymanopt.function.numpy(manifold)
    def egrad(Y): return 2.0 * (Wt @ Y) * d
    @pymanopt.function.numpy(manifold)
    def ehess(Y, U): return 2.0 * (Wt @ U) * d
else:
    a, mu, delta = data["a"], float(data["mu"]), float(data["delta"])
    ra = np.sqrt(a)[:, None]
    def huber(x): return np.where(np.abs(x) <= delta, x * x / (2 * delta), np.abs(x) - delta / 2)
    @pymanopt.function.numpy(manifold)
    def cost(Y): return float(np.sum(Y * (Wt @ Y)) + mu * np.sum(a[:, None] * huber(Y / ra)))
    @pymanopt.function.numpy(manifold)
    def egrad(Y):
        x = Y / ra
        return 2.0 * (Wt @ Y) + mu * ra * np.where(np.abs(x) <= delta, x / delta, np.sign(x))
    @pymanopt.function.numpy(manifold)
    def ehess(Y, U):
        x = Y / ra
        return 2.0 * (Wt @ U) + mu * np.where(np.abs(x) <= delta, 1.0 / delta, 0.0) * U
problem = pymanopt.Problem(manifold, cost, euclidean_gradient=egrad, euclidean_hessian=ehess)
'''

PYMANOPT_TR = r'''
from pymanopt.optimizers import TrustRegions
opt = TrustRegions(min_gradient_norm=float(data["gtol"]), max_time=float(data["max_time"]), max_iterations=100000,
                   verbosity=0)
t = time.perf_counter()
res = opt.run(problem, initial_point=Y0)
print(json.dumps({"iterations": int(res.iterations), "seconds": time.perf_counter() - t, "value": float(res.cost),
                  "grad_norm": float(res.gradient_norm), "reason": str(res.stopping_criterion)}))
'''


def pymanopt_subprocess(problem: dict, python: str, tail: str, timeout: float, **params) -> tuple[dict | None, str]:
    """The isometric problem (``Y = M^{1/2}X``, ``W̃ = M^{-1/2}WM^{-1/2}``) and ``params`` handed to ``python``
    running ``PYMANOPT_PROBLEM + tail``; returns (its JSON line, "") or (None, the error's last line)."""
    M = np.asarray(problem["M"])
    r = np.sqrt(M)
    Wt = sp.diags(1.0 / r) @ problem["W"] @ sp.diags(1.0 / r)
    Y0 = r[:, None] * np.asarray(problem["X0"])
    extra = {"d": problem["d"]} if problem["kind"] == "brockett" else {
        "a": M, "mu": problem["mu"], "delta": problem["delta"]}
    with tempfile.TemporaryDirectory() as tmp:
        np.savez(Path(tmp) / "data.npz", Y0=Y0, kind=problem["kind"], **params, **extra)
        sp.save_npz(Path(tmp) / "W.npz", sp.csr_matrix(Wt))
        script = Path(tmp) / "run.py"
        script.write_text(PYMANOPT_PROBLEM + tail)
        proc = subprocess.run([python, str(script), str(Path(tmp) / "data.npz"), str(Path(tmp) / "W.npz")],
                              capture_output=True, text=True, timeout=timeout,
                              env={**os.environ, "OPENBLAS_NUM_THREADS": "1"})
    if proc.returncode != 0:  # the exception's own line (e.g. a MemoryError naming the array it wanted)
        last = [line for line in proc.stderr.splitlines() if line.strip()][-1:] or ["exit status " + str(proc.returncode)]
        return None, last[0][-300:]
    return json.loads(proc.stdout.strip().splitlines()[-1]), ""


def run_pymanopt(problem: dict, python: str, gtol: float, max_time: float) -> dict:
    """pymanopt's TrustRegions on the isometric problem on St(n, k) (module docstring), in ``python``."""
    out, error = pymanopt_subprocess(problem, python, PYMANOPT_TR, max_time + 600, gtol=gtol, max_time=max_time)
    if out is None:
        return {"problem": problem["label"], "solver": "pymanopt TrustRegions", "error": error}
    row = {"problem": problem["label"], "n": problem["n"], "k": problem["k"], "solver": "pymanopt TrustRegions",
           "status": "converged" if out["grad_norm"] <= gtol else f"stopped ({out['reason']})", **out}
    print(json.dumps(row), flush=True)
    return row


def plot(rows: list[dict], path: Path) -> None:
    """Gradient norm per iteration, one panel per problem (log scale): the quadratic tail of TR."""
    import matplotlib  # noqa: PLC0415

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    problems = list(dict.fromkeys(r["problem"] for r in rows if "history_grad_norm" in r))
    fig, axes = plt.subplots(1, len(problems), figsize=(4.2 * len(problems), 3.6), squeeze=False)
    for ax, name in zip(axes[0], problems):
        for r in rows:
            if r["problem"] == name and "history_grad_norm" in r:
                h = np.asarray(r["history_grad_norm"])
                stride = max(1, (r["iterations"] + 1) // max(len(h) - 1, 1))
                ax.semilogy(np.arange(len(h)) * stride, h, label=r["solver"])
        ax.set_xscale("symlog", linthresh=10)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("iteration")
        ax.set_ylabel("‖grad F‖ (M-metric)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, dpi=110, format="png")
    plt.close(fig)
    write_atomic(path, buf.getvalue())


def report(rows: list[dict], meta: dict, figure: str = "second-order.png") -> str:
    lines = ["# Second order: trust regions against CG / L-BFGS and pymanopt", "", *header_lines(meta),
             f"* target: Riemannian gradient norm ≤ {meta['gtol']:g} (Brockett) / {meta['gtol_cmm']:g} (CMM final "
             f"stage), M-metric; at most {meta['max_steps']} iterations; pymanopt limited to {meta['max_time']:g} s",
             "* W products: products of W with an n×k block actually executed (counted in a second run; 2k columns "
             "count 2); "
             "HVPs: Hessian-vector products (each one W product); seconds exclude compilation (its own column)",
             "* P: the shifted preconditioner (W + σM)⁻¹, σ = λ_k (Brockett) / λ_(k−1) (CMM), one sparse Cholesky",
             "* TR: `stiefel.RiemannianTrustRegion` (exact Hessian by autodiff); CG / L-BFGS: `stiefel.RiemannianCG` / "
             "`RiemannianLBFGS` (on CMM stages with the energy's fast line search, as the CMM solver runs them)",
             "* pymanopt 2.2.1 TrustRegions on the isometric problem on St(n, k) (numpy gradient and Hessian; "
             "module docstring)",
             "* CG + P (CMM stop) stops as `BlockCMM`'s last stage does: its status `converged` there means the stall "
             "test (relative decrease ≤ 1e-7 over 20 iterations) fired — the gradient norm is in its column",
             "* near a 1e-10 target the first-order iteration counts vary between runs by ±30 % (round-off decides "
             "when the last restarts happen)",
             "* not in the tables (measured separately on 2026-11-25, `example:bumpy`, k = 10, μ = 2λ): that final stage "
             "starts on a plateau — the CMM stop ends there at F = 1801.6 while the stage's minimum is 1713.94 — and "
             "trust regions alone crawl across it (TR + P: ~9000 iterations; L-BFGS + P comes within 1e-6 of the "
             "minimum in ~2400); after 2500 L-BFGS iterations TR + P finished in 65. There trust regions are a finish, "
             "not a replacement",
             "* P_X (CMM only): the point preconditioner of `objectives.cmm.newton` — entries pinned in the "
             "smoothing's kink (curvature μw_i s'' > σa_i) inverted by their own curvature, the free ones by P",
             *([f"* problems not rerun by this command: from {meta['earlier']['date']}, command "
                f"`{meta['earlier']['command']}`"] if meta.get("earlier") else []), "",
             f"![gradient norm per iteration]({figure})", ""]
    for name in dict.fromkeys(r["problem"] for r in rows):
        group = [r for r in rows if r["problem"] == name]
        lines += [f"## {name} (n = {group[0].get('n')}, k = {group[0].get('k')})", "",
                  "| solver | iterations | W products | HVPs | seconds | compile s | final ‖grad‖ | value | status |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|---|"]
        for r in group:
            if "error" in r:
                lines.append(f"| {r['solver']} | – | – | – | – | – | – | – | failed: {r['error']} |")
                continue
            value = f"{r['value']:.12g}" + (f" (rel. err. {r['error_vs_eigsh']:.0e})" if "error_vs_eigsh" in r else "")
            status = r["status"] + (f" (L-BFGS part: {r['first_iterations']} it., ‖grad‖ {r['first_grad_norm']:.1e})"
                                    if "first_iterations" in r else "")
            ours_cols = (f"{r['w_products']:.0f} | {r['n_hvps'] or '–'} | {r['seconds']:.2f} | {r['compile_seconds']:.2f}"
                         if "compile_seconds" in r else f"– | – | {r['seconds']:.2f} | –")
            lines.append(f"| {r['solver']} | {r['iterations']} | {ours_cols} | {r['grad_norm']:.1e} | {value} | {status} |")
        first = [r for r in group if "w_products" in r and "TR" not in r["solver"]]
        trp = [r for r in group if r["solver"] in ("TR + P", "TR + P_X") and r.get("status") == "converged"]
        if first and trp:
            best = min(first, key=lambda r: r["grad_norm"])
            t = min(trp, key=lambda r: r["w_products"])
            lines += ["", f"Best first-order run: {best['solver']}, ‖grad‖ {best['grad_norm']:.1e} after "
                      f"{best['w_products']:.0f} W products; {t['solver']}: ‖grad‖ {t['grad_norm']:.1e} after "
                      f"{t['w_products']:.0f} ({t['w_products'] / best['w_products']:.2f}×)."]
        ours = [r for r in group if r["solver"].startswith("TR") and r.get("status") == "converged"]
        peer = [r for r in group if r["solver"].startswith("pymanopt") and "error" not in r]
        if ours and peer:
            best = min(ours, key=lambda r: r["seconds"])
            p = peer[0]
            note = "" if p["status"] == "converged" else f" (pymanopt stopped at ‖grad‖ = {p['grad_norm']:.1e})"
            lines += ["", f"{best['solver']} vs pymanopt: {p['seconds'] / best['seconds']:.0f}× faster compile-excluded, "
                      f"{p['seconds'] / (best['seconds'] + best['compile_seconds']):.0f}× compile-included{note}."]
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench second-order", description=__doc__.split("\n\n")[0])
    p.add_argument("--brockett", type=int, nargs="*", default=[1000], help="sizes n of the Brockett problems")
    p.add_argument("--meshes", nargs="*", default=["example:bumpy"], help="meshes for the CMM final stage")
    p.add_argument("--gtol", type=float, default=1e-10, help="gradient-norm target, Brockett")
    p.add_argument("--gtol-cmm", type=float, default=1e-8, help="gradient-norm target, CMM final stages")
    p.add_argument("--max-steps", type=int, default=5000, help="iteration limit of the first-order solvers")
    p.add_argument("--pymanopt", default=None, help="a Python interpreter with pymanopt 2.2.1 (optional)")
    p.add_argument("--max-time", type=float, default=60.0, help="pymanopt's time limit per problem (s)")
    p.add_argument("--output", type=Path, default=None,
                   help="the page (default: docs/benchmarks/second-order.md); its .json and .png go beside it")
    p.add_argument("--merge", action="store_true",
                   help="keep the rows of the existing JSON for the problems this run does not solve")
    p.add_argument("--from-json", type=Path, default=None,
                   help="rewrite the report and the picture from a results JSON of an earlier run (no solving)")
    args = p.parse_args(argv)
    out = args.output or results_path("second-order")
    saved_path, figure = out.with_suffix(".json"), out.with_suffix(".png")
    if args.from_json is not None:
        saved = json.loads(args.from_json.read_text())
        for r in saved["rows"]:  # runs saved before the error line was shortened
            if "error" in r:
                r["error"] = [line for line in r["error"].splitlines() if line.strip()][-1][-300:]
        plot(saved["rows"], figure)
        write_page(out, report(saved["rows"], saved["meta"], figure.name))
        print(f"wrote {out}")
        return 0
    require(args.meshes)
    rows = []
    problems = [brockett_problem(n) for n in args.brockett] + [cmm_problem(spec) for spec in args.meshes]
    for problem in problems:
        gtol = args.gtol if problem["kind"] == "brockett" else args.gtol_cmm
        for name, (first, second) in solvers(problem, gtol).items():
            rows.append(run_one(problem, name, first, second, args.max_steps))
        if args.pymanopt:
            rows.append(run_pymanopt(problem, args.pymanopt, gtol, args.max_time))
    meta = run_meta("bench second-order", argv, gtol=args.gtol, gtol_cmm=args.gtol_cmm, max_steps=args.max_steps,
                    max_time=args.max_time)
    if args.merge and saved_path.exists():
        saved = json.loads(saved_path.read_text())
        solved = {r["problem"] for r in rows}
        kept = [r for r in saved["rows"] if r["problem"] not in solved]
        if kept:
            meta["earlier"] = saved["meta"].get("earlier") or {"date": saved["meta"]["date"],
                                                               "command": saved["meta"]["command"]}
        rows = kept + rows
    plot(rows, figure)
    write_json(saved_path, {"meta": meta, "rows": rows})
    write_page(out, report(rows, meta, figure.name))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
