"""Thesis Chapters 3 and 4, claim by claim: the effect of μ on CMMs (Fig. 3.5) and the comparison
of bases for reconstructing functions (Figs. 4.5–4.19, §4.7).

``claims(ctx)`` measures on the shared meshes closest to the thesis's (``Context.mesh``; shipped examples
stand in when ``../shared/meshes`` is absent): bunny.off (3485 vertices) for the thesis's homer (5103) in
Fig. 3.5 and for its bunny (26002) in Chapter 4, hand_868.obj for its hands (26000) in Fig. 4.18. The
measurements are in ``chapter3_4_data``, the pictures in ``chapter3_4_plots``; the verdicts are decided
here from the measured numbers. ``ctx.quick``: hand_868 (or the torus) only, k = 30, a few dozen ADMM
iterations — seconds, and "reproduced" is reported as "qualitatively" (too small to call it reproduced).
"""

from __future__ import annotations

import time

import numpy as np

import mesh
from bench.thesis import Claim, Context
from bench.thesis import chapter3_4_data as data
from bench.thesis import chapter3_4_plots as plots
from bench.thesis.chapter3_4_claims import chapter4_claims, fmt as _g, save as _save
from bench.thesis.chapter3_4_lbo_cmm import basis_reconstruction_claims
from bench.thesis.report import by_count

__all__ = ["claims", "FULL", "QUICK"]

#: budgets of the default run: iteration caps only, no wall-clock limit (on the shared 2-core machine a time limit
#: made the results depend on its load: at k = 150 an ADMM iteration took 0.06 s idle and 6 s under load)
FULL = dict(mu_mesh=("bunny.off", "example:bumpy", "homer, 5103 vertices"), mu_k=5,
            mu_over_n=(0.001, 0.01, 0.1, 1.0), mu_iters=10000, mu_time=float("inf"), mu_starts=5,
            ch4_mesh=("bunny.off", "example:bumpy", "bunny, 26002 vertices"), k=150, k_lbo=100, n_eig=300,
            n_wks=100, cmm_mu=50.0, cmm_iters=500, cmm_time=float("inf"), sizes=(10, 50, 100, 125, 150),
            fine_mesh=("armadillo_25479.obj", "example:bumpy"),
            rec_meshes=(("bunny.off", "example:bumpy", "bunny", 26002, 500),
                        ("hand_868.obj", "example:torus", "hand 1/2", 26000, 1500)), rec_time=float("inf"))
#: ``--quick``: seconds
QUICK = dict(FULL, mu_mesh=("hand_868.obj", "example:torus", "homer, 5103 vertices"), mu_k=3,
             mu_over_n=(0.01, 0.1, 1.0), mu_iters=150, mu_time=3.0, mu_starts=2,
             ch4_mesh=("hand_868.obj", "example:torus", "bunny, 26002 vertices"), k=30, k_lbo=20, n_eig=60, n_wks=40,
             cmm_iters=30, cmm_time=5.0, sizes=(10, 20, 30), fine_mesh=None,
             rec_meshes=(("hand_868.obj", "example:torus", "hand 1/2", 26000, 30),), rec_time=5.0)
MU_OVER_N_418 = 0.008  # Fig. 4.18's μ/n on the thesis's mesh


def _guarded(key: str, subject: str, fn) -> list[Claim]:
    """``fn()`` or one "error" claim naming the exception (the other groups still run)."""
    t0 = time.perf_counter()
    try:
        return fn()
    except Exception as e:  # noqa: BLE001 — reported in the document
        return [Claim(key=key, subject=subject, thesis="", ours="", setting="", verdict="error",
                      reason=f"{type(e).__name__}: {e}", seconds=time.perf_counter() - t0)]


# ------------------------------------------------------------------------------------------------ Fig. 3.5
def _mu_claims(ctx: Context, cfg: dict) -> list[Claim]:
    shared, stand_in, stands_for = cfg["mu_mesh"]
    m, label = ctx.mesh(shared, stand_in)
    t0 = time.perf_counter()
    mu_mesh = mesh.scaled_to_unit_area(m)
    lap = mesh.laplacian(mu_mesh)
    runs, eig = data.mu_sweep(lap, cfg["mu_k"], cfg["mu_over_n"], max_iters=cfg["mu_iters"], time_limit=cfg["mu_time"])
    seconds = time.perf_counter() - t0
    a = lap.A.diagonal()
    n, k = m.n_vertices, cfg["mu_k"]
    s0, area0 = data.sparsity(eig, a)
    table = [dict(mu_over_n=r.mu / n, sparsity=r.sparsity, support_area=r.support_area, dirichlet=r.dirichlet)
             for r in runs]
    fig = plots.mu_figure(mu_mesh, [eig] + [r.Psi for r in runs],
                          ["μ = 0 (eigenfunctions)"] + [f"μ/n = {_g(r.mu / n)}" for r in runs], table)
    figures = _save(ctx, fig, "fig3_5_mu")
    sp = [s0] + [r.sparsity for r in runs]
    area = [area0] + [r.support_area for r in runs]
    en = [float(np.sum(eig * (lap.W @ eig)))] + [r.dirichlet for r in runs]
    steps = [(b >= a_ - 5e-3) for a_, b in zip(sp, sp[1:])] + [(b <= a_ + 5e-3) for a_, b in zip(area, area[1:])] \
        + [(b >= a_ * (1 - 1e-6)) for a_, b in zip(en, en[1:])]
    rows = "; ".join(f"μ/n = {_g(r.mu / n)} (μ = {_g(r.mu)}): sparsity {r.sparsity:.1%}, support {r.support_area:.1%} "
                     f"of the area, tr(ΨᵀWΨ) = {_g(r.dirichlet)}, {r.status} after {r.iterations} it." for r in runs)
    setting = (f"{label} (n = {n}; stands for the thesis's {stands_for}), area 1, k = {k}, ADMM (exact A-norm form, "
               f"ρ₀ = 2λ_k, ρ raised by residual balancing) from the first k eigenfunctions, ≤ {cfg['mu_iters']} "
               f"iterations" + (f" or {_g(cfg['mu_time'])} s" if np.isfinite(cfg["mu_time"]) else "")
               + " per μ; an entry counts as zero below 1e-3 of its mode's peak")
    j = by_count(sum(steps), len(steps), "steps in μ (μ = 0 first) with sparsity up, support down, Dirichlet "
                 "energy up")
    unconverged = [_g(r.mu / n) for r in runs if r.status != "converged"]
    reason = {"reproduced": "sparsity rises and the support shrinks monotonically with μ while the Dirichlet energy "
                            "grows, as described",
              "qualitatively": "the trend holds in most steps, not all (see ours)",
              "differs": "the trend does not hold in μ (see ours)"}[j.verdict]
    if unconverged and j.verdict != "reproduced":
        reason += (f"; ADMM stopped at its budget before converging at μ/n = {', '.join(unconverged)} (unconverged "
                   "iterates are noisy)")
    claims = [Claim(
        key="Fig. 3.5", subject="the sparsity parameter μ: larger μ, sparser and more localised CMMs",
        thesis="5 CMMs by ADMM on homer for a range of μ/n up to 1: small μ favours the Dirichlet term (smooth, "
               "eigenfunction-like modes), large μ the ℓ1 term (very sparse modes with large jumps between "
               "neighbouring vertices); the figure shows the trend, no numbers",
        ours=f"eigenfunctions (μ = 0): sparsity {s0:.1%}, support {area0:.1%}; " + rows,
        setting=setting, reason=reason, figures=figures, seconds=seconds, **j.kwargs())]
    claims.append(_largest_mu_claim(lap, cfg, runs, n, k, setting))
    return claims


def _largest_mu_claim(lap, cfg: dict, runs: list, n: int, k: int, setting: str) -> Claim:
    """Fig. 3.5's remark at μ/n = 1 ("did not converge"), from ``cfg["mu_starts"]`` starts: the eigenfunction start
    of the figure and random A-orthonormal starts (the same ρ₀; ADMM from nearly equal starts can end differently)."""
    t0 = time.perf_counter()
    big = runs[-1]
    starts = [big] + data.mu_random_starts(lap, k, big.mu, cfg["mu_starts"] - 1, max_iters=cfg["mu_iters"],
                                            time_limit=cfg["mu_time"])
    stuck = [r for r in starts if r.status != "converged"]
    its = [r.iterations for r in starts]
    j = by_count(len(stuck), len(starts), f"starts that did not converge within {cfg['mu_iters']} iterations")
    most_small = max(r.iterations for r in runs[:-1])
    return Claim(
        key="Fig. 3.5 (μ/n = 1)", subject="ADMM at the largest μ",
        thesis="at μ/n = 1 the ADMM did not converge (its ρ, stopping rule and iteration cap are not stated)",
        ours=(f"μ/n = {_g(big.mu / n)}, {len(starts)} starts (eigenfunctions, then random seeds 1–{len(starts) - 1}): "
              + ", ".join(f"{r.status} after {r.iterations} it." for r in starts)
              + f"; iterations {min(its)}–{max(its)} (median {int(np.median(its))}) against {most_small} at most for "
                f"the smaller μ from the eigenfunction start; sparsity {min(r.sparsity for r in starts):.1%}–"
                f"{max(r.sparsity for r in starts):.1%}"),
        setting=setting + f"; {len(starts)} starts at μ/n = 1 (random starts A-orthonormalised, same ρ₀)",
        reason=("ADMM converges here, slowly: a cap below the iterations it needs stops it unconverged while the "
                "smaller μ finish — the setting that would reproduce the remark; the thesis states neither its ρ nor "
                "its cap (ours: ρ₀ = 2λ_k, raised by residual balancing; Boyd's stopping test, eps_abs 1e-7, "
                "eps_rel 1e-5)") if len(stuck) < len(starts) else
               f"no start converged within {cfg['mu_iters']} iterations; the thesis's budget is not stated",
        seconds=time.perf_counter() - t0, **j.kwargs())


# ------------------------------------------------------------------------------------------------ Chapter 4
def _chapter4_claims(ctx: Context, cfg: dict) -> list[Claim]:
    shared, stand_in, stands_for = cfg["ch4_mesh"]
    m, label = ctx.mesh(shared, stand_in)
    t0 = time.perf_counter()
    d = data.chapter4(m, label, k=cfg["k"], k_lbo=cfg["k_lbo"], n_eig=cfg["n_eig"], n_wks=cfg["n_wks"],
                      mu=cfg["cmm_mu"], cmm_iters=cfg["cmm_iters"], cmm_time=cfg["cmm_time"])
    build = time.perf_counter() - t0
    setting = (f"{label} (n = {m.n_vertices}; stands for the thesis's {stands_for}), area 1; bases of k = {d.k}: "
               f"LBO (cotangent W, lumped A), GL (graph W, A = I/n), GLMH_X = {d.k_lbo} LBO + {d.k - d.k_lbo} LMHs "
               f"(region: worst-reconstructed 10 % for family X, μ_R = μ_⊥ = 1e6), CMM (μ = {_g(d.cmm.mu)}, ADMM "
               f"≤ {cfg['cmm_iters']} iterations: {d.cmm.status} after {d.cmm.iterations}, sparsity "
               f"{d.cmm.sparsity:.1%}; the thesis's were sequential); families: {len(d.functions['GEODISTS'].T)} "
               f"landmarks, HKS 30 and WKS {cfg['n_wks']} from {cfg['n_eig']} eigenpairs, {d.notes['segments']} "
               "SEG segments (persistence, default τ)")
    fine = None
    if cfg["fine_mesh"] is not None:  # the families at the thesis's resolution: only with the shared mesh
        fm, flabel = ctx.mesh(*cfg["fine_mesh"])
        if "stand-in" not in flabel:
            t0 = time.perf_counter()
            fine = dict(data.lbo_family_errors(fm, d.k, cfg["n_wks"]), label=flabel, seconds=time.perf_counter() - t0)
    return chapter4_claims(ctx, d, cfg, setting, build, fine)


def claims(ctx: Context) -> list[Claim]:
    cfg = QUICK if ctx.quick else FULL

    out = _guarded("Fig. 3.5", "the sparsity parameter μ", lambda: _mu_claims(ctx, cfg))
    out += _guarded("Figs. 4.5–4.17", "bases and reconstructions of Chapter 4", lambda: _chapter4_claims(ctx, cfg))
    out += _guarded("Figs. 4.18–4.19", "LBO and CMMs reconstructing each other",
                    lambda: basis_reconstruction_claims(ctx, cfg, MU_OVER_N_418))
    return out
