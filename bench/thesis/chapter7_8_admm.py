"""Thesis §7.3 for ``bench.thesis.chapter7_8``: Algorithm 8 (``FastCMM``) against ADMM (``ADMMCMM``) —
Table 7.1 (time, iterations), Table 7.2 (per-step times), Fig. 7.5 (the modes).

Table 7.1's setting: k = 10, μ = n/100 (the thesis's 64 for n = 6457), d ≈ n/40 local functions, random
starts (the thesis averages 10; we run 3, quick 1), each solver in its exact (A-norm penalties) and its
printed thesis form (Frobenius penalties, A ≈ I/n), default ρ₀ and rule, ``eps_abs``/``eps_rel`` defaults,
at most 3000 iterations (quick: 800). The humanoid row (ScapeMan001 → armadillo) runs once, the printed forms.
``runs`` measures; ``table_7_1``, ``table_7_2`` and ``fig_7_5`` judge.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

import mesh
from bench.thesis import Claim
from bench.thesis.chapter7_8_util import mode_sheet, pct, pick_mesh, sized_local_functions, timed
from stiefel_cmm.cli.compare import match_modes
from objectives.cmm.modes import compressed_modes, unpack_laplacian
from objectives.cmm.solvers import ADMMCMM, FastCMM
from objectives.admm.fast import restricted_matrices
from stiefel.linalg.sparse_factor import SymmetricFactor

__all__ = ["runs", "pairs", "table_7_1", "table_7_2", "fig_7_5", "SOLVERS"]

SOLVERS = (("ADMM", "exact"), ("ADMM", "thesis"), ("fast", "exact"), ("fast", "thesis"))
THESIS = {"fandisk": dict(admm_s=53.2174, admm_it=1489, fast_s=6.1890, fast_it=326, restrict_s=0.9057,
                          total_s=7.1082, n=6457, d=162),
          "ScapeMan001": dict(admm_s=31.7624, admm_it=676, fast_s=13.8918, fast_it=214, restrict_s=3.0367,
                              total_s=17.0057, n=12500, d=313)}
#: thesis Table 7.2, fandisk: seconds per iteration of the Ψ/X-, E- and S-steps
STEPS_72 = {"ADMM": (0.0019, 0.0298, 0.0005), "fast": (0.0106, 0.0016, 0.0016)}
TOLS = (1e-2, 1e-3)  # an objective-plateau stopping rule: within tol of the final value from then on


def _plateau(obj: np.ndarray, tol: float) -> int:
    """The first iteration from which the objective stays within ``tol``·|final| of its final value."""
    obj = np.asarray(obj, dtype=np.float64)
    off = np.abs(obj - obj[-1]) > tol * abs(obj[-1])
    return int(np.flatnonzero(off)[-1]) + 2 if off.any() else 1


def _solve(lap, k, mu, solver, seed) -> dict:
    r = compressed_modes(lap, k, mu, solver=solver, start="random", seed=seed)
    st = dict(r.params["step_times"])
    it = max(r.iterations, 1)
    stop = {t: _plateau(r.history["objective"], t) for t in TOLS}
    return dict(objective=r.objective, iterations=r.iterations, status=r.status, seconds=r.wall_time,
                ms={key: 1e3 * v / it for key, v in st.items()}, rho0=r.params["rho0"], modes=r.modes,
                sparsity=r.sparsity["1e-3"], plateau=stop,
                plateau_s={t: float(r.history["time"][i - 1]) for t, i in stop.items()})


def runs(ctx) -> dict:
    """Table 7.1's runs on fandisk (all four forms, every seed) and on the humanoid (printed forms, seed 0)."""
    out = {}
    seeds = [ctx.seed] if ctx.quick else [ctx.seed + i for i in range(3)]
    max_iters = 800 if ctx.quick else 3000
    for name, shared, stand, solvers, ss in (
            ("fandisk", "fandisk.off", "example:bumpy", SOLVERS, seeds),
            ("ScapeMan001", "armadillo_25479.obj", "example:starfish", (("ADMM", "thesis"), ("fast", "thesis")),
             seeds[:1])):
        t0 = time.perf_counter()
        m, label = pick_mesh(ctx, shared, stand, f"{name}, n = {THESIS[name]['n']}")
        lap = mesh.laplacian(m)
        n, k = m.n_vertices, 10
        mu = n / 100.0
        lf, t_lf = sized_local_functions(m, max(n // 40, 3 * k), ctx.seed)
        W, a = unpack_laplacian(lap)
        t_rm, _ = timed(restricted_matrices, W, sp.diags_array(a), lf.U)
        res = {}
        for kind, variant in solvers:
            opts = dict(variant=variant, max_iters=max_iters)
            solver = ADMMCMM(**opts) if kind == "ADMM" else FastCMM(lf.U, **opts)
            res[kind, variant] = [_solve(lap, k, mu, solver, s) for s in ss]
        e_factor, _ = timed(lambda: [SymmetricFactor(sp.csc_matrix(2 * W + mu * sp.diags_array(a))) for _ in range(3)])
        out[name] = dict(m=m, label=label, n=n, k=k, mu=mu, d=lf.U.shape[1], seeds=ss, max_iters=max_iters,
                         restrict_s=t_lf + t_rm, res=res, factor_s=e_factor / 3, a=a,
                         seconds=time.perf_counter() - t0)
    return out


def _mean(rows: list, key: str) -> float:
    return float(np.mean([r[key] for r in rows]))


def pairs(R: dict) -> list[dict]:
    """Every (ADMM form, fast form) pair: speed-up (the fast total includes restricting), ratios of iterations
    and of cost per iteration, objective gap, and the same ratios under the objective-plateau rule."""
    res, out = R["res"], []
    for av in ("exact", "thesis"):
        for fv in ("exact", "thesis"):
            if ("ADMM", av) not in res or ("fast", fv) not in res:
                continue
            A, F = res["ADMM", av], res["fast", fv]
            per_a, per_f = _mean(A, "seconds") / _mean(A, "iterations"), _mean(F, "seconds") / _mean(F, "iterations")
            out.append(dict(
                admm=av, fast=fv, speed=_mean(A, "seconds") / (_mean(F, "seconds") + R["restrict_s"]),
                iters=_mean(A, "iterations") / _mean(F, "iterations"), per_it=per_f / per_a,
                gap=_mean(F, "objective") / _mean(A, "objective") - 1.0,
                plateau={t: np.mean([r["plateau"][t] for r in A]) / np.mean([r["plateau"][t] for r in F]) for t in TOLS},
                plateau_speed={t: np.mean([r["plateau_s"][t] for r in A])
                               / (np.mean([r["plateau_s"][t] for r in F]) + R["restrict_s"]) for t in TOLS}))
    return out


def _row(rows: list) -> str:
    conv = sum(r["status"] == "converged" for r in rows)
    return (f"{_mean(rows, 'seconds'):.2f} s, {_mean(rows, 'iterations'):.0f} it. ({conv}/{len(rows)} converged), "
            f"objective {_mean(rows, 'objective'):.2f}")


def _setting(R: dict) -> str:
    return (f"{R['label']}; k = {R['k']}, μ = n/100 = {R['mu']:.1f}, d = {R['d']} (≈ n/40), area ℓ1 weights, "
            f"{len(R['seeds'])} random start(s) (thesis: 10), default ρ₀ (max(μ, 1), /n for the thesis forms) and "
            f"rule ('increase'), eps_abs 1e-7, eps_rel 1e-5, ≤ {R['max_iters']} iterations")


def _near(x: float, target: float) -> bool:
    """"reproduced": within 30 % of the thesis's ratio."""
    return 0.7 <= x / target <= 1.4


def table_7_1(data: dict) -> list[Claim]:
    R = data["fandisk"]
    th = THESIS["fandisk"]
    t_speed, t_iters = th["admm_s"] / th["total_s"], th["admm_it"] / th["fast_it"]
    t_per_it = (th["fast_s"] / th["fast_it"]) / (th["admm_s"] / th["admm_it"])
    ps = pairs(R)
    b = min(ps, key=lambda p: abs(np.log(p["speed"] / t_speed)) + abs(np.log(p["iters"] / t_iters)))
    speed_ok, iters_ok = _near(b["speed"], t_speed), _near(b["iters"], t_iters)
    runs_txt = "; ".join(f"{k} {v}: {_row(rows)}" for (k, v), rows in R["res"].items())
    pair_txt = "; ".join(f"ADMM {p['admm']}/fast {p['fast']}: {p['speed']:.2f}× faster, {p['iters']:.2f}× fewer it., "
                         f"objective {pct(p['gap'])}" for p in ps)
    plateau = {t: ", ".join(f"{p['admm']}/{p['fast']} {p['plateau'][t]:.2f}×" for p in ps) for t in TOLS}
    conv = {key: sum(r["status"] == "converged" for r in rows) for key, rows in R["res"].items()}
    budget = "" if all(c == len(R["seeds"]) for c in conv.values()) else (
        f" Not every run passed the stopping test within {R['max_iters']} iterations ("
        + ", ".join(f"{k} {v} {c}/{len(R['seeds'])}" for (k, v), c in conv.items()) + "): those counts are the budget's.")
    admm_it = np.mean([_mean(R["res"]["ADMM", v], "iterations") for v in ("exact", "thesis")])
    fast_it = np.mean([_mean(R["res"]["fast", v], "iterations") for v in ("exact", "thesis")])
    why_time = (f"time ratio = iteration ratio × per-iteration cost ratio (+ restricting): thesis {t_iters:.1f}× fewer "
                f"iterations at {t_per_it:.2f}× the cost per iteration; ours (closest pair) {b['iters']:.2f}× at "
                f"{b['per_it']:.2f}× — the per-iteration ratio "
                + ("matches the thesis's (within 30 %)" if _near(b["per_it"], t_per_it) else "differs from the thesis's")
                + ", the iteration ratio " + ("does too" if iters_ok else "does not (next row)") + ". Our ADMM factors "
                f"2W + ρA once per ρ (one factorisation: {1e3 * R['factor_s']:.0f} ms here; the thesis's ADMM E-step "
                f"took 29.8 ms per iteration)." + budget)
    bp = min(ps, key=lambda p: abs(np.log(p["plateau_speed"][1e-3] / t_speed)) + abs(np.log(p["plateau"][1e-3] / t_iters)))
    closest = (f" Closest setting measured: ADMM {bp['admm']} vs fast {bp['fast']} stopped at the 0.1 % objective "
               f"plateau, {bp['plateau_speed'][1e-3]:.1f}× faster with {bp['plateau'][1e-3]:.1f}× fewer iterations "
               f"(thesis {t_speed:.1f}×, {t_iters:.1f}×).")
    why_time += closest
    tail = {kind: np.mean([_mean(R["res"][kind, v], "iterations") / np.mean([r["plateau"][1e-3] for r in R["res"][kind, v]])
                           for v in ("exact", "thesis")]) for kind in ("ADMM", "fast")}
    settle = ", ".join(f"{k} {v} {np.mean([r['plateau'][1e-3] for r in rows]):.0f}" for (k, v), rows in R["res"].items())
    why_iters = (f"mean iterations: ADMM {admm_it:.0f} (thesis {th['admm_it']}), fast {fast_it:.0f} (thesis "
                 f"{th['fast_it']}); the objective settles (0.1 %) at iteration {settle}. The thesis states neither "
                 f"its tolerances nor how the residuals of the mixed-size duals (U^E: d × k, U^S: n × k) enter its "
                 f"test (§7.4 leaves that open); ours measure both in the lifted n-space norm"
                 + (", and the fast forms keep iterating long after their objective has settled, so the stopping rule "
                    "decides much of the ratio." if tail["fast"] > 1.3 * tail["ADMM"] else ".")
                 + closest + budget)
    claims = [
        Claim(key="Table 7.1 (time)", subject="fast approximation vs ADMM on fandisk: total time",
              thesis=f"ADMM {th['admm_s']:.1f} s; fast {th['fast_s']:.2f} s + {th['restrict_s']:.2f} s restricting = "
                     f"{th['total_s']:.2f} s: {t_speed:.1f}× faster (n = 6457, d = 162, μ = 64, mean of 10 random starts)",
              ours=(f"{runs_txt}; restricting (sampling, U, W̄, Ā) {R['restrict_s']:.2f} s. Pairs: {pair_txt}. "
                    f"Closest to the thesis: ADMM {b['admm']} vs fast {b['fast']}. Stopped instead where the objective "
                    f"settles within 0.1 % of its final value: "
                    + ", ".join(f"{p['admm']}/{p['fast']} {p['plateau_speed'][1e-3]:.2f}×" for p in ps)),
              setting=_setting(R), verdict="reproduced" if speed_ok else ("qualitatively" if b["speed"] > 1 else "differs"),
              reason=why_time, seconds=R["seconds"]),
        Claim(key="Table 7.1 (iterations)", subject="fast approximation vs ADMM on fandisk: iterations to converge",
              thesis=f"ADMM {th['admm_it']} iterations, fast {th['fast_it']}: {t_iters:.1f}× fewer",
              ours=("mean iterations: " + ", ".join(f"{k} {v} {_mean(rows, 'iterations'):.0f}"
                                                    for (k, v), rows in R["res"].items())
                    + "; ratio ADMM/fast per pair: " + ", ".join(f"{p['admm']}/{p['fast']} {p['iters']:.2f}×" for p in ps)
                    + f". With an objective-plateau rule instead (first iteration within 0.1 % of the final objective "
                    f"from then on): {plateau[1e-3]}; within 1 %: {plateau[1e-2]}"),
              setting=_setting(R), verdict="reproduced" if iters_ok else ("qualitatively" if b["iters"] > 1 else "differs"),
              reason=why_iters),
    ]
    h = data.get("ScapeMan001")
    if h:
        th2 = THESIS["ScapeMan001"]
        A, F = h["res"]["ADMM", "thesis"][0], h["res"]["fast", "thesis"][0]
        sp2 = A["seconds"] / (F["seconds"] + h["restrict_s"])
        it2 = A["iterations"] / max(F["iterations"], 1)
        t2 = th2["admm_s"] / th2["total_s"]
        claims.append(Claim(
            key="Table 7.1 (ScapeMan001 row)", subject="fast vs ADMM on a humanoid: time and iterations",
            thesis=f"ADMM {th2['admm_s']:.1f} s / {th2['admm_it']} it.; fast {th2['total_s']:.1f} s total / "
                   f"{th2['fast_it']} it.: {t2:.1f}× faster, {th2['admm_it'] / th2['fast_it']:.1f}× fewer iterations",
            ours=(f"ADMM thesis form {A['seconds']:.1f} s / {A['iterations']} it. ({A['status']}); fast thesis form "
                  f"{F['seconds']:.1f} s + {h['restrict_s']:.2f} s restricting / {F['iterations']} it. ({F['status']}): "
                  f"{sp2:.2f}× faster, {it2:.2f}× fewer iterations, objective {pct(F['objective'] / A['objective'] - 1)}"),
            setting=_setting(h),
            verdict="reproduced" if _near(sp2, t2) and it2 > 1 else ("qualitatively" if sp2 > 1 else "differs"),
            reason=(("faster" if sp2 > 1 else "not faster") + (", with fewer iterations" if it2 > 1 else
                    ", but in more iterations: the per-iteration saving carries it") + "; a different mesh (the "
                    f"armadillo has {h['n'] / th2['n']:.1f}× ScapeMan001's vertices) and one start, so the ratios are "
                    "indicative only"),
            seconds=h["seconds"]))
    return claims


def table_7_2(data: dict) -> Claim:
    R = data["fandisk"]
    ms = {key: {s: float(np.mean([r["ms"][s] for r in rows])) for s in rows[0]["ms"]} for key, rows in R["res"].items()}
    txt = "; ".join(f"{k} {v}: Ψ/X {d['psi']:.2f}, E {d['E']:.2f}, S {d['S']:.2f}, update {d['dual']:.2f}, residuals "
                    f"{d['residual']:.2f}, objective {d['objective']:.2f} ms/it" for (k, v), d in ms.items())
    ratios = {v: tuple(ms["fast", v][s] / ms["ADMM", v][s] for s in ("psi", "E", "S")) for v in ("exact", "thesis")}
    t_ratio = tuple(f / a for f, a in zip(STEPS_72["fast"], STEPS_72["ADMM"]))
    share = {v: ms["ADMM", v]["E"] / sum(ms["ADMM", v][s] for s in ("psi", "E", "S")) for v in ("exact", "thesis")}
    t_share = STEPS_72["ADMM"][1] / sum(STEPS_72["ADMM"])
    e_ok = all(r[1] < 0.25 for r in ratios.values())
    s_ok = all(r[2] > 1 for r in ratios.values())
    x_ok = all(r[0] > 1 for r in ratios.values())
    return Claim(
        key="Table 7.2", subject="per-step ADMM times: which step dominates, how restriction changes it",
        thesis=(f"fandisk, ms/it: ADMM Ψ 1.9, E 29.8, S 0.5; fast X 10.6, E 1.6, S 1.6 — fast/ADMM: X {t_ratio[0]:.2f}×, "
                f"E {t_ratio[1]:.3f}×, S {t_ratio[2]:.2f}×; the E-step is {100 * t_share:.0f} % of ADMM's step time"),
        ours=(txt + ". fast/ADMM (Ψ/X, E, S): " + "; ".join(f"{v} forms {r[0]:.2f}×, {r[1]:.3f}×, {r[2]:.2f}×"
                                                           for v, r in ratios.items())
              + "; E-step share of ADMM's Ψ+E+S: " + ", ".join(f"{v} {100 * s:.0f} %" for v, s in share.items())),
        setting=_setting(R) + "; step_times from compressed_modes' params, mean over the starts",
        verdict="reproduced" if e_ok and s_ok and x_ok else ("qualitatively" if e_ok else "differs"),
        reason=(f"E-step {'/'.join(f'{1 / r[1]:.0f}×' for r in ratios.values())} cheaper (thesis {1 / t_ratio[1]:.0f}×)"
                + ("" if e_ok else ", less than the 4× taken as a cut")
                + ("; S-step slower (as in the thesis)" if s_ok else "; S-step not slower (the thesis's is)")
                + ("; X-step slower (as in the thesis)" if x_ok else
                   "; but our X-step is faster than the Ψ-step: it solves with a sparse Cholesky factor of UᵀU (Ā for "
                   "the exact form) made once, where the thesis multiplies by (UᵀU)⁻¹Uᵀ each iteration")
                + f". The E-step is {100 * min(share.values()):.0f}–{100 * max(share.values()):.0f} % of ADMM's step "
                  f"time here against the thesis's {100 * t_share:.0f} % because we factor 2W + ρA once per ρ; "
                  f"re-factoring each iteration (the setting that matches the thesis's 29.8 ms) costs "
                  f"{1e3 * R['factor_s']:.0f} ms here"),
        seconds=0.0)


def fig_7_5(ctx, data: dict) -> Claim:
    t0 = time.perf_counter()
    parts, figs = [], []
    for name, (av, fv) in (("fandisk", ("exact", "thesis")), ("ScapeMan001", ("thesis", "thesis"))):
        R = data.get(name)
        if not R or ("ADMM", av) not in R["res"]:
            continue
        A, F = R["res"]["ADMM", av][0], R["res"]["fast", fv][0]
        a = R["a"]
        order, signs = match_modes(A["modes"], F["modes"], a)
        Fm = F["modes"][:, order] * signs
        corr = np.abs(np.sum(A["modes"] * (a[:, None] * Fm), axis=0))
        moved = int(np.sum(order != np.arange(len(order))))
        cols = list(range(min(5, R["k"])))
        figs.append(mode_sheet(ctx, R["m"], [A["modes"][:, cols], Fm[:, cols]], [f"ADMM ({av})", f"fast ({fv})"],
                               [f"ψ_{c + 1}" for c in cols], f"ch7_8_fig7_5_{name.lower()}.png",
                               f"Fig. 7.5: CMMs on {R['label'].split(',')[0]}: ADMM (top) and the fast approximation "
                               f"matched to them (bottom), seed {R['seeds'][0]}"))
        parts.append(dict(name=name, label=R["label"].split(",")[0], corr=corr, moved=moved, k=R["k"],
                          gap=F["objective"] / A["objective"] - 1, sp=(A["sparsity"], F["sparsity"]), av=av, fv=fv))
    ours = "; ".join(f"{p['label']} (ADMM {p['av']} vs fast {p['fv']}): {int(np.sum(p['corr'] >= 0.9))} of {p['k']} "
                     f"modes have a partner (matched |⟨ψ, ψ̄⟩_A| ≥ 0.9; median {np.median(p['corr']):.3f}, min "
                     f"{p['corr'].min():.3f}); {p['moved']} of {p['k']} change rank; objective {pct(p['gap'])}; entries "
                     f"below 1e-3·max: {100 * p['sp'][0]:.0f} % (ADMM) vs {100 * p['sp'][1]:.0f} % (fast)" for p in parts)
    share = [float(np.mean(p["corr"] >= 0.9)) for p in parts]
    similar = bool(parts) and min(share) >= 0.8
    reason = (f"{', '.join(f'{100 * x:.0f} %' for x in share)} of the modes have a partner; the fast modes cost "
              f"{', '.join(pct(p['gap']) for p in parts)} in objective (they live in span U)")
    return Claim(key="Fig. 7.5", subject="CMMs via the fast approximation vs unrestricted ADMM",
                 thesis="pictures (fandisk, ScapeMan001): the functions are very similar, with some change in ordering",
                 ours=ours, setting="Table 7.1's runs, first random start (ADMM and fast from different random "
                 "starts); modes sorted by compressed eigenvalue, the fast ones matched to ADMM's (stiefel_cmm.cli.compare.match_modes)",
                 verdict="reproduced" if similar else ("qualitatively" if parts and max(share) >= 0.8 else "differs"),
                 reason=reason + ("" if similar else "; from different random starts the two solvers can end in "
                                  "different local minima"),
                 figures=figs, seconds=time.perf_counter() - t0)
