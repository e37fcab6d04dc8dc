"""The Chapter-4 claims of ``bench.thesis.chapter3_4`` (Figs. 4.5–4.19, §4.7), decided from the measurements
of ``chapter3_4_data`` on one mesh (``Chapter4``) and, for Figs. 4.18–4.19, on the meshes of ``cfg["rec_meshes"]``."""

from __future__ import annotations

import time

import numpy as np

import mesh
from bench.thesis import Claim, Context
from bench.thesis import chapter3_4_data as data
from bench.thesis import chapter3_4_plots as plots
from objectives.evaluation import reconstruction_error

__all__ = ["chapter4_claims", "basis_reconstruction_claims", "fmt", "verdict", "save"]

F = data.FUNCTIONS
SEE = "figure: the matrices under Fig. 4.14 (left)"


def fmt(x: float) -> str:
    return f"{x:.3g}"


def verdict(ctx: Context, v: str) -> str:
    """``v``, except that quick mode reports "reproduced" as "qualitatively" (too small to call it reproduced)."""
    return "qualitatively" if ctx.quick and v == "reproduced" else v


def save(ctx: Context, fig, name: str) -> list[str]:
    try:
        return [ctx.save_figure(fig, f"ch3_4_{name}.png")]
    finally:
        plots.close(fig)


def _order(values: np.ndarray) -> str:
    """Family names by decreasing value: ``"HKS 1.3 > DELTAS 0.56 > …"``."""
    idx = np.argsort(-values)
    return " > ".join(f"{F[i]} {fmt(values[i])}" for i in idx)


def _span(x: np.ndarray) -> str:
    lo, hi = fmt(float(np.min(x))), fmt(float(np.max(x)))
    return lo if lo == hi else f"{lo}–{hi}"


def _fine_note(fine: dict, top2: set) -> str:
    e = fine["errors"]
    worst = "WKS is the worst" if int(np.argmax(e)) == F.index("WKS") else f"{F[int(np.argmax(e))]} is the worst"
    seg = int(np.sum(e > e[F.index("SEG")])) + 1
    pair = "the thesis's pair" if top2 == {"WKS", "SEG"} else f"top two {' and '.join(sorted(top2))}"
    return f". At the thesis's resolution {worst} and SEG ranks {seg} of {len(F)} ({pair})"


def _timing_claim(ctx, d, setting, build) -> Claim:
    t, k, r = d.times, d.k, d.k - d.k_lbo
    glmh = np.array([t[f"GLMH_{f}"] for f in F])
    region = np.array([d.notes["region"][f] for f in F])
    small = d.notes["eigs_small"]
    cmm_last = t["CMM"] > max(v for b, v in t.items() if b != "CMM")
    glmh_slower = glmh.min() > max(t["LBO"], t["GL"])
    ours = (f"LBO (eigs, {k}) {fmt(t['LBO'])} s; GL (eigs, {k}) {fmt(t['GL'])} s; GLMH ({r} LMHs, region included) "
            f"{fmt(glmh.min())}–{fmt(glmh.max())} s, of which the region {fmt(region.max())} s at most; CMM ({k} modes, "
            f"{d.cmm.iterations} ADMM iterations, {d.cmm.status}) {fmt(t['CMM'])} s; reference: eigs for {r} "
            f"eigenpairs {fmt(small)} s")
    solve = float(np.mean(glmh - region))
    if cmm_last and glmh_slower:
        v, reason = "reproduced", "same ordering: eigs bases < GLMH < CMM"
    else:
        v = "differs"
        reason = (f"eigs bases < CMM holds, but the {r} LMHs take {fmt(glmh.mean() / t['LBO'])}× the time of the {k} "
                  f"LBO eigenfunctions. Locating the region is {np.mean(region / glmh):.0%} of the GLMH time; the LMH "
                  f"solve costs {fmt(solve / small)}× eigs for the same {r} eigenpairs (one sparse factorisation, the "
                  f"rank-{d.k_lbo} term applied through Woodbury), while eigs for {k} eigenpairs costs "
                  f"{fmt(t['LBO'] / small)}× eigs for {r}: here the number of eigenpairs, not the localisation, "
                  "dominates. The thesis (MATLAB eigs with Woodbury) does not report its split")
        if not cmm_last:
            reason += "; and CMM is not the slowest at this iteration budget"
    fig = plots.times_figure(t, {f"eigs {r} (ref.)": small})
    return Claim(key="Fig. 4.5", subject="time to compute each basis type",
                 thesis="bases by eigs (LBO, GL: 150 functions) are fastest; GLMH bases take longer although they "
                        "add only 50 functions (region location and the extra product); CMMs (sequential, μ = 50, "
                        "10K/100K iterations, capped at 150 minutes) are slowest",
                 ours=ours, setting=setting + "; wall times: eigs best of 2, the others one run, on a shared machine",
                 verdict=verdict(ctx, v), reason=reason, figures=save(ctx, fig, "fig4_5_times"), seconds=build)


def _method_claims(ctx, d, E, Em, setting, seconds, sizes) -> list[Claim]:
    names = list(d.bases)
    lbo, gl = names.index("LBO"), names.index("GL")
    tie = np.abs(Em - E) <= 1e-12 + 1e-9 * np.abs(E)
    better, worse = (Em > E) & ~tie, (Em < E) & ~tie
    rest = [i for i in range(len(names)) if i != gl]
    figures = save(ctx, plots.methods_figure(list(F), names, E, Em), "fig4_9_10_methods")
    ties = [F[j] for j in range(len(F)) if tie[lbo, j]]
    ours = (f"LBO basis: least squares smaller for {better[lbo].sum()} of {len(F)} families, larger for "
            f"{worse[lbo].sum()}, equal for {len(ties)} ({', '.join(ties) or 'none'}); over all {len(rest)} bases "
            f"but GL: smaller in {better[rest].sum()}, larger in {worse[rest].sum()} of {tie[rest].size} "
            "(basis, family) pairs")
    v = "reproduced" if worse[lbo].sum() == 0 and better[lbo].sum() > 0 else "qualitatively"
    out = [Claim(key="Fig. 4.9", subject="least squares vs the product ΦᵀAF (LBO basis)",
                 thesis="least-squares reconstructions tend to have the smaller error (solid markers below hollow)",
                 ours=ours, setting=setting, verdict=verdict(ctx, v),
                 reason="least squares minimises the Euclidean error, ΦᵀAF the A-weighted one; Err (Def. 4.2.2) is "
                        "neither, so the ordering is usual, not guaranteed", figures=figures, seconds=seconds)]
    diff = np.abs(Em[gl] - E[gl])
    nonconst = [j for j in range(len(F)) if F[j] != "CONSTANT"]
    rel = float(np.max(diff[nonconst] / E[gl, nonconst]))
    out.append(Claim(key="Fig. 4.10", subject="graph Laplacian basis: both methods agree",
                     thesis="with A = I (graph Laplacian) both reconstructions are the same, so both markers coincide",
                     ours=f"GL basis (A = I/n): largest difference {fmt(diff.max())}, relative {fmt(rel)} "
                          "(CONSTANT: both at round-off)", setting=setting,
                     verdict=verdict(ctx, "reproduced" if rel < 1e-9 else "differs"),
                     reason="ΦᵀΦ = nI, so (ΦᵀΦ)⁻¹ΦᵀF = Φᵀ(I/n)F: identical up to round-off (§4.2.3); figure: "
                            "Fig. 4.9's, right panel (GL's ratios all 1)", seconds=0.0))
    t0 = time.perf_counter()
    sw = data.method_sweep(d, sizes, repeats=1 if ctx.quick else 2)
    secs = time.perf_counter() - t0
    ls, mm = sw["lstsq"], sw["manipulation"]
    ratio = np.array(ls["seconds"]) / np.array(mm["seconds"])
    fig = save(ctx, plots.sweep_figure(sizes, sw), "fig4_11_sweep")
    out.append(Claim(
        key="Fig. 4.11 (left)", subject="time: least squares vs the product",
        thesis="backslash (least squares) is faster than the product ΦᵀAF at every basis size; the thesis itself "
               "ties this to MATLAB 2018a's optimised backslash",
        ours=f"least-squares time / product time {fmt(ratio.min())}–{fmt(ratio.max())} over sizes {list(sizes)} (at "
             f"{sizes[-1]}: {fmt(ls['seconds'][-1] * 1e3)} vs {fmt(mm['seconds'][-1] * 1e3)} ms for all "
             f"{sum(d.functions[f].shape[1] for f in F)} functions, mean over the bases)",
        setting=setting + f"; numpy/scipy lstsq (LAPACK gelsd) against one product, best of {1 if ctx.quick else 2}",
        verdict=verdict(ctx, "reproduced" if ratio.max() < 1 else "differs"),
        reason="" if ratio.max() < 1 else
        "numpy's least squares factorises the n × k basis (an SVD, O(nk²)) while ΦᵀAF is one product (O(nkf)); "
        "the thesis's ordering came from MATLAB's backslash, which this environment does not have",
        figures=fig, seconds=secs))
    i0, i1 = list(sizes).index(d.k_lbo), len(sizes) - 1
    gap = np.array(mm["glmh_error"]) - np.array(ls["glmh_error"])
    ls_better = [s for s, a, b in zip(sizes, ls["error"], mm["error"]) if a < b]
    mm_better = [s for s, a, b in zip(sizes, ls["error"], mm["error"]) if a >= b]
    orth = np.array(list(d.notes["orthogonality"].values()))
    opens = gap[i1] > 2 * max(gap[i0], 0) and gap[i1] > 0
    v = "reproduced" if opens and not mm_better else "qualitatively" if opens else "differs"
    out.append(Claim(
        key="Fig. 4.11 (right)", subject="error: least squares vs the product; the GLMH bases past size 100",
        thesis="least squares gives the smaller error; the product's error jumps at basis size 100 because the GLMH "
               "bases' 100 eigenfunctions and 50 LMHs are not exactly A-orthogonal",
        ours=f"mean Err over bases and families, least squares vs product: {fmt(ls['error'][0])} vs "
             f"{fmt(mm['error'][0])} at {sizes[0]}, {fmt(ls['error'][i1])} vs {fmt(mm['error'][i1])} at {sizes[i1]}; "
             f"least squares smaller at sizes {ls_better}, not at {mm_better}. GLMH bases: product − least squares "
             f"{fmt(gap[i0])} at {d.k_lbo} → {fmt(gap[i1])} at {sizes[i1]} (‖Φ_{d.k_lbo}ᵀAΨ‖_F "
             f"{fmt(orth.min())}–{fmt(orth.max())})",
        setting=setting, verdict=verdict(ctx, v),
        reason=("past the first " + str(d.k_lbo) + " functions the product stops improving on the GLMH bases while "
                "least squares keeps falling, as described" + (
                    "; at small sizes the product's mean per-vertex error is the smaller one (Err is neither of the "
                    "norms the two methods minimise)" if mm_better else "")) if opens else
               (f"on the GLMH bases the product's extra error does not grow past size {d.k_lbo} here although their "
                "two halves are not exactly A-orthogonal (‖ΦᵀAΨ‖_F in ours)"),
        seconds=0.0))
    return out


def _family_claims(ctx, d, E, setting, fine) -> list[Claim]:
    names = list(d.bases)
    lap_based = [i for i, b in enumerate(names) if b != "CMM"]
    size = np.array([reconstruction_error(d.functions[f], 0 * d.functions[f]) for f in F])
    mean, rel = E.mean(axis=0), (E / size).mean(axis=0)
    figures = save(ctx, plots.matrix_figure(names, list(F), E), "fig4_13_16_matrix")
    top2 = {F[i] for i in np.argsort(-mean)[:2]}
    peak = {f: float(np.abs(d.functions[f]).max()) for f in F}
    fine_txt = fine_set = ""
    if fine is not None:
        fine_txt = (f"; at the thesis's resolution ({fine['label']}, n = {fine['n']}, LBO only, HKS/WKS from its "
                    f"{d.k} eigenpairs, {fine['segments']} segments): {_order(fine['errors'])}")
        fine_set = (f"; resolution check: {fine['label']} (the thesis's armadillo, 26002 vertices), k = {d.k}, "
                    f"{fmt(fine['seconds'])} s")
    top2_fine = None if fine is None else {F[i] for i in np.argsort(-fine["errors"])[:2]}
    out = [Claim(
        key="Fig. 4.14 (left), §4.7", subject="which families are reconstructed worst",
        thesis="averaged over the meshes, WKS and SEG have the largest reconstruction errors in every basis",
        ours=f"mean Err over the {len(names)} bases: {_order(mean)}; relative to each family's size "
             f"(Err(F, R)/Err(F, 0)): {_order(rel)}" + fine_txt,
        setting=setting + fine_set, verdict=verdict(ctx, "reproduced" if top2 == {"WKS", "SEG"} else "differs"),
        reason="" if top2 == {"WKS", "SEG"} else
        f"one mesh, not the thesis's average over 26. The unscaled Err follows each family's magnitude: HKS entries "
        f"reach {fmt(peak['HKS'])} and a DELTA's peak is {fmt(peak['DELTAS'])}, against {fmt(peak['WKS'])} for WKS "
        f"and 1 for SEG; relative to their size the localised families (DELTAS, NORMDIST) are worst. The thesis does "
        f"not state a normalisation of HKS/WKS; our SEG has {d.notes['segments']} segments on this mesh"
        + ("" if fine is None else _fine_note(fine, top2_fine)),
        figures=figures, seconds=0.0 if fine is None else fine["seconds"])]
    const = F.index("CONSTANT")
    cmax = float(E[lap_based, const].max())
    out.append(Claim(key="Fig. 4.13 (CONSTANT)", subject="the constant function in Laplacian-based bases",
                     thesis="constant functions are approximated very well (the first eigenfunction is constant)",
                     ours=f"Err of CONSTANT ≤ {fmt(cmax)} in LBO, GL and every GLMH basis", setting=setting,
                     verdict=verdict(ctx, "reproduced" if cmax < 1e-10 else "differs"), reason=SEE))
    dl = F.index("DELTAS")
    rank = int(np.sum(mean > mean[dl])) + 1
    edge = float(mesh.edge_graph(d.m).data.mean())
    support = float(np.mean(np.count_nonzero(d.functions["DELTAS"], axis=0)))
    fine_rank = None if fine is None else int(np.sum(fine["errors"] > fine["errors"][dl])) + 1
    good = rank > len(F) // 2 and (fine_rank is None or fine_rank > len(F) // 2)
    fine_txt = "" if fine is None else (
        f"; {fine['label']} (n = {fine['n']}, LBO only): rank {fine_rank}, Err {fmt(fine['errors'][dl])}, relative "
        f"{fmt(fine['relative'][dl])}, each DELTA nonzero on {fmt(fine['delta_support'])} vertices (mean edge "
        f"{fmt(fine['edge'])})")
    out.append(Claim(
        key="Fig. 4.13 (DELTAS)", subject="the delta functions",
        thesis="the highly localised DELTA functions are also approximated well (the thesis finds this surprising)",
        ours=f"DELTAS rank {rank} of {len(F)} by mean Err over the bases ({fmt(mean[dl])}); relative Err "
             f"{fmt(rel[dl])} (the residual's mean size against the function's own); each DELTA nonzero on "
             f"{fmt(support)} vertices (r = 0.01, mean edge {fmt(edge)})" + fine_txt,
        setting=setting + ("" if fine is None else f"; resolution check on {fine['label']}"),
        verdict=verdict(ctx, "reproduced" if good else "differs"),
        reason="" if good else
        f"a DELTA is a spike of height {fmt(peak['DELTAS'])} on one or a few vertices; its projection on {d.k} smooth "
        "functions misses the spike and spreads a residual over the mesh, larger in mean than the DELTA itself "
        "(relative Err > 1)" + ("" if fine is None else
                                 "; at the thesis's resolution the spike is wider and the Err smaller, but it still "
                                 f"ranks {fine_rank} of {len(F)}")))
    S = E / E.sum(axis=0, keepdims=True)
    cmm = names.index("CMM")
    others = np.delete(S.ravel(), cmm * len(F) + const)
    worst = S[cmm, const] >= S.max() and E[cmm, const] > 1e3 * max(cmax, 1e-15)
    out.append(Claim(
        key="Fig. 4.14 (right), §4.7", subject="CMMs and the constant function",
        thesis="with each family's errors scaled to sum 1, CMMs reconstruct the constant function poorly — the only "
               "basis that is noticeably poor for any family",
        ours=f"Err of CONSTANT in CMMs {fmt(E[cmm, const])} against ≤ {fmt(cmax)} in the other bases; its scaled "
             f"share {S[cmm, const]:.2f}, the next largest scaled cell {others.max():.2f}",
        setting=setting, verdict=verdict(ctx, "reproduced" if worst else "differs"),
        reason=f"the CMMs' span does not contain the constant vector, which every other basis holds as its first "
               f"eigenfunction (our CMMs: {d.cmm.sparsity:.1%} of the entries below 1e-3 of their peak); " + SEE))
    keep = [j for j in range(len(F)) if j != const]
    logE = np.log10(E[:, keep])
    across_f = float(np.median(np.ptp(logE, axis=1)))
    across_b = float(np.median(np.ptp(logE, axis=0)))
    med = np.median(logE, axis=1)
    out.append(Claim(
        key="Figs. 4.12, 4.16, §4.7", subject="family matters more than basis",
        thesis="errors form vertical stripes (by family) and no basis is markedly better or worse overall: the "
               "function type matters more than the basis type",
        ours=f"CONSTANT left out: the spread of log10 Err across families is {fmt(across_f)} decades (median over "
             f"bases) against {fmt(across_b)} across bases (median over families); the bases' median log10 Err lie "
             f"within {fmt(np.ptp(med))} decades",
        setting=setting, verdict=verdict(ctx, "reproduced" if across_f > 3 * across_b else "differs"), reason=SEE))
    ratio = {f: E[names.index(f"GLMH_{f}"), F.index(f)] / E[names.index("LBO"), F.index(f)] for f in F if f != "CONSTANT"}
    best = [f for f in ratio if int(np.argmin(E[:, F.index(f)])) == names.index(f"GLMH_{f}")]
    own = [f for f in ratio if int(np.argmin([E[names.index(f"GLMH_{g}"), F.index(f)] for g in F]))
           == F.index(f)]
    v = "reproduced" if set(best) == {"VERTS", "HKS"} else "qualitatively"
    out.append(Claim(
        key="Fig. 4.15, §4.7", subject="GLMHs built from family X reconstructing X",
        thesis="a GLMH basis is noticeably better on the family it was built from only for VERTS and HKS; the "
               "localised GLMHs do not perform as well as expected",
        ours="Err of X in GLMH_X / in LBO: " + ", ".join(f"{f} {ratio[f]:.2f}" for f in ratio)
             + f"; GLMH_X is the best of all bases on X for: {', '.join(best) or 'none'}; the best GLMH basis on X "
               f"for: {', '.join(own) or 'none'}",
        setting=setting, verdict=verdict(ctx, v),
        reason="" if v == "reproduced" else
        f"the summary holds — localising the last {d.k - d.k_lbo} functions on X's worst region does not beat "
        f"{d.k} eigenfunctions on X — but the thesis's exceptions (VERTS, HKS) do not appear here"))
    return out


def _grassmann_claims(ctx, d, setting) -> list[Claim]:
    t0 = time.perf_counter()
    names = list(d.bases)
    G = data.grassmann_matrix(d, d.lap.A)
    Gt = data.grassmann_unit_gl(d, G)
    secs = time.perf_counter() - t0
    figures = save(ctx, plots.grassmann_figure(names, G, Gt), "fig4_17_grassmann")
    nb = len(names)
    rowmean = G.sum(axis=1) / (nb - 1)
    gl, lbo, cmm = names.index("GL"), names.index("LBO"), names.index("CMM")
    far = int(np.argmax(rowmean))
    glmh = [i for i, b in enumerate(names) if b.startswith("GLMH")]
    r, cap = d.k - d.k_lbo, np.pi / 2
    t_gl = np.delete(Gt[gl], gl)
    thesis_far = bool(np.argmax(Gt.sum(axis=1)) == gl)
    out = [Claim(
        key="Fig. 4.17 (GL)", subject="Grassmann distances: is the graph-Laplacian span furthest from all?",
        thesis="the subspace spanned by the graph-Laplacian eigenfunctions is the furthest from all other subspaces",
        ours=f"one inner product (A, every basis A-orthonormalised): GL's mean d_Gr to the others {fmt(rowmean[gl])} "
             f"(furthest on average: {names[far]}, {fmt(rowmean[far])}); d_Gr(GL, LBO) = {fmt(G[gl, lbo])}, "
             f"d_Gr(GLMH_X, LBO) = {fmt(G[glmh, lbo].min())}–{fmt(G[glmh, lbo].max())} (√{r}·π/2 = "
             f"{fmt(np.sqrt(r) * cap)} for {r} orthogonal directions)",
        setting=setting + f"; d_Gr over the {d.k} principal angles (Def. 4.6.4) in the lumped cotangent A",
        verdict=verdict(ctx, "reproduced" if far == gl else "differs"),
        reason="" if far == gl else
        f"the GLMH bases share Φ_{d.k_lbo} with LBO but their {r} LMHs are nearly A-orthogonal to LBO's eigenfunctions "
        f"{d.k_lbo + 1}–{d.k}, so they sit near the cap from LBO and from each other; GL's eigenfunctions span much the "
        f"same low frequencies as LBO's. Setting that reproduces the thesis's picture: in Lemma 4.6.3's SVD of ΦᵀAΨ "
        f"taking the GL eigenvectors with unit Euclidean norm (as eigs returns them for the graph Laplacian with "
        f"identity mass) instead of A-orthonormal gives d_Gr(GL, ·) = {_span(t_gl)}, against the cap √{d.k}·π/2 = "
        f"{fmt(np.sqrt(d.k) * cap)}: " + ("GL is then the furthest from all. " if thesis_far else
                                          "GL is still not the furthest on average. ")
        + "The thesis does not state how its GL basis was normalised for this figure", figures=figures, seconds=secs)]
    rest = G[np.triu_indices(nb, 1)]
    rest = np.sort(rest[rest != G[lbo, cmm]])
    close = G[lbo, cmm] < 0.5 * rest[0]
    v = ("reproduced" if d.cmm.status == "converged" else "qualitatively") if close else "differs"
    out.append(Claim(
        key="Fig. 4.17 (CMM–LBO)", subject="CMMs and LBO span nearby subspaces on the thesis's bunny/hand meshes",
        thesis="for the meshes head 1 … hand 2 (bunny among them) the CMM bases span subspaces close to LBO's",
        ours=f"d_Gr(LBO, CMM) = {fmt(G[lbo, cmm])}; the closest other pair {fmt(rest[0])}",
        setting=setting, verdict=verdict(ctx, v),
        reason=f"the CMMs are ADMM's after {d.cmm.iterations} iterations from the LBO start ({d.cmm.status}; sparsity "
               f"{d.cmm.sparsity:.1%}): converged CMMs may lie further from LBO; the sparser CMMs of Fig. 4.18 "
               "(μ = 208) are measured there" if v == "qualitatively" else ""))
    return out


def chapter4_claims(ctx: Context, d: data.Chapter4, cfg: dict, setting: str, build: float,
                    fine: dict | None = None) -> list[Claim]:
    """Figs. 4.5, 4.9–4.17 on the Chapter-4 mesh ``d``; ``fine``: ``lbo_family_errors`` on a mesh of the
    thesis's resolution (or None)."""
    out = [_timing_claim(ctx, d, setting, build)]
    t0 = time.perf_counter()
    E, Em = data.reconstruction_table(d, "lstsq"), data.reconstruction_table(d, "manipulation")
    out += _method_claims(ctx, d, E, Em, setting, time.perf_counter() - t0, cfg["sizes"])
    out += _family_claims(ctx, d, E, setting, fine)
    out += _grassmann_claims(ctx, d, setting)
    return out


def _plateaus(curve: np.ndarray, window: int) -> list[tuple[int, int]]:
    """Runs of ≥ ``window`` consecutive j whose decrease is < 0.1 % of the curve's total fall (1-based j)."""
    drop = curve[:-1] - curve[1:]
    flat = drop < 1e-3 * max(curve[0] - curve[-1], 1e-300)
    runs, start = [], None
    for j, f in enumerate(list(flat) + [False]):
        if f and start is None:
            start = j
        elif not f and start is not None:
            if j - start >= window:
                runs.append((start + 2, j + 1))
            start = None
    return runs


def basis_reconstruction_claims(ctx: Context, cfg: dict, mu_over_n: float) -> list[Claim]:
    """Figs. 4.18 and 4.19: LBO and CMMs (ADMM, μ = (μ/n)·n of the thesis's mesh) reconstructing each other."""
    t0 = time.perf_counter()
    res, labels = {}, {}
    for shared, stand_in, thesis_name, n_thesis, iters in cfg["rec_meshes"]:
        m, label = ctx.mesh(shared, stand_in)
        mu = mu_over_n * n_thesis
        res[label] = data.basis_reconstruction(m, k=cfg["k"], mu=mu, max_iters=iters, time_limit=cfg["rec_time"])
        labels[label] = (f"{label} (n = {m.n_vertices}) for {thesis_name} ({n_thesis}): μ = {fmt(mu)}, ≤ {iters} "
                         "ADMM iterations")
    secs = time.perf_counter() - t0
    k = cfg["k"]
    setting = (f"k = {k}; μ = {mu_over_n}·n with n the thesis mesh's vertex count (area 1 makes μ‖AΨ‖₁ independent of "
               f"the resolution; {mu_over_n}·n of our coarser meshes would be a weaker μ); ADMM from the LBO start; least "
               "squares on nested spans; " + "; ".join(labels.values()))
    fig = save(ctx, plots.basis_reconstruction_figure({labels[lb]: (r["red"], r["blue"]) for lb, r in res.items()}),
               "fig4_18_basis_reconstruction")
    parts, gaps = [], []
    for lb, r in res.items():
        gap = float(np.mean(np.abs(r["red"] - r["blue"])) / np.mean(0.5 * (r["red"] + r["blue"])))
        gaps.append(gap)
        c = r["cmm"]
        parts.append(f"{lb}: d_Gr(LBO, CMM) = {fmt(r['d_gr'])}; at j = {k}: CMMs in LBO {fmt(r['red'][-1])}, LBO in "
                     f"CMMs {fmt(r['blue'][-1])}; mean |red − blue| / mean level {gap:.2f}; CMMs {c.status} after "
                     f"{c.iterations} it., sparsity {c.sparsity:.1%}")
    conv = all(r["cmm"].status == "converged" for r in res.values())
    close = max(gaps) < 0.25
    v = ("reproduced" if conv else "qualitatively") if close else "differs"
    out = [Claim(
        key="Fig. 4.18", subject="LBO and CMMs reconstructing each other",
        thesis="150 CMMs (ADMM, μ/n = 0.008): on the 20–26K-vertex meshes (bunny, hands among them) the two error "
               "curves lie close — each basis reconstructs the other about equally — and these are the meshes "
               "whose spans were close in Fig. 4.17",
        ours="; ".join(parts), setting=setting, verdict=verdict(ctx, v),
        reason=("" if v == "reproduced" else
                "the curves are close, but the CMMs are ADMM's at the iteration budget (not converged)" if close else
                "the curves separate on these meshes (see ours)"),
        figures=fig, seconds=secs)]
    window = 10 if k >= 100 else 3
    parts, any_plateau = [], False
    for lb, r in res.items():
        p = r["cmm"].l1_per_mode
        w = max(2, min(10, k // 10))
        sm = np.convolve(p, np.ones(w) / w, mode="valid")
        jump = np.abs(np.diff(sm)) / sm[:-1]
        j = int(np.argmax(jump))
        runs = _plateaus(r["blue"], window)
        any_plateau |= bool(runs)
        parts.append(f"{lb}: ‖Aψ_j‖₁ {fmt(p[0])} at j = 1 to {fmt(p[-1])} at j = {k} (cumulative {fmt(p.sum())}); largest "
                     f"change of the {w}-mode mean slope {jump[j]:.0%} near j = {j + w}; plateaus of 'LBO in CMMs' "
                     f"(≥ {window} steps falling < 0.1 % of the total): {runs or 'none'}")
    fig = save(ctx, plots.l1_figure({lb: r["cmm"].l1_per_mode for lb, r in res.items()}), "fig4_19_l1")
    out.append(Claim(
        key="Fig. 4.19", subject="cumulative sparsity ‖AΨ_j‖₁ of the CMMs",
        thesis="a marked change in the slope of the cumulative ‖AΨ_j‖₁ marks a change in the modes' sparsity and "
               "explains the plateaus of Fig. 4.18's error curves on some meshes (its first row)",
        ours="; ".join(parts), setting=setting + "; the same modes as Fig. 4.18, sorted by compressed eigenvalue",
        verdict="qualitatively" if any_plateau else "not checkable",
        reason=("plateaus appear here; compare their positions with the slope changes in ours" if any_plateau else
                "no plateau appears in either curve on these meshes, so there is nothing for a slope change to "
                "explain; the thesis does not name the meshes of its first row"),
        figures=fig, seconds=0.0))
    return out
