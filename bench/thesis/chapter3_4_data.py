"""Measurements behind ``bench.thesis.chapter3_4``: the CMM μ sweep (thesis Fig. 3.5) and the bases,
descriptor families and reconstructions of thesis Chapter 4 (Figs. 4.5–4.19), on one mesh each.

Everything here measures; nothing judges (the verdicts are in ``chapter3_4``). Meshes are scaled to unit
area before the descriptors are built (the thesis's radii assume it) and every Laplacian normalises its
area to 1, so μ means the same on a coarse and a fine copy of a surface (``‖AΨ‖₁`` is a quadrature of
``∫|ψ|``).

CMMs are solved by calling the ADMM solver object directly (``ADMMCMM.solve``) rather than through
``compressed_modes``: the latter's ℓ1 stationarity diagnostic builds a ``k(k+1)/2``-square matrix
(``objectives.energy.l1_optimality.MaskedGram``) — 11325² entries and minutes of work at k = 150.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

import mesh
from bench.bench_bases import MU_PERP, MU_R, _best
from objectives import bases as basis_lib
from objectives.cmm.modes import unpack_laplacian
from objectives.cmm.solvers import ADMMCMM, Start
from objectives.evaluation import a_orthonormalize, principal_angles, reconstruct, reconstruction_error
from stiefel.manifolds.signs import canonical_signs

__all__ = ["FUNCTIONS", "CMMRun", "solve_cmm", "mu_sweep", "mu_random_starts", "Chapter4", "chapter4", "reconstruction_table",
           "method_sweep", "incremental_errors", "grassmann_matrix", "grassmann_unit_gl", "basis_reconstruction",
           "lbo_family_errors", "sparsity"]

#: the descriptor families of thesis §4.1, in the thesis's order
FUNCTIONS = ("GEODISTS", "DELTAS", "NORMDIST", "HKS", "WKS", "SEG", "CONSTANT", "VERTS")
#: entries below this fraction of their column's peak count as zero (``CMMResult.sparsity["1e-3"]``)
ZERO = 1e-3


def sparsity(Psi: np.ndarray, a: np.ndarray) -> tuple[float, float]:
    """``(fraction of entries below ZERO·peak, mean area fraction of the modes' supports)``."""
    small = np.abs(Psi) < ZERO * np.abs(Psi).max(axis=0, keepdims=True)
    return float(small.mean()), float(np.mean((a @ ~small) / a.sum()))


@dataclasses.dataclass
class CMMRun:
    """Sorted CMMs (by compressed eigenvalue ``ψᵀWψ + (μ/2)‖Aψ‖₁``) and how the solve went."""

    Psi: np.ndarray
    mu: float
    iterations: int
    status: str
    seconds: float
    dirichlet: float
    l1_per_mode: np.ndarray  # ‖Aψ_j‖₁ in the sorted order
    sparsity: float
    support_area: float


def solve_cmm(lap, k: int, mu: float, evals, evecs, *, max_iters: int, time_limit: float, X0=None) -> CMMRun:
    """k CMMs by ADMM (thesis Algorithm 3, exact A-norm form) from the first k eigenfunctions, or from ``X0``
    ((n, k), A-orthonormal) with the same ρ₀ (2λ_k from ``evals``)."""
    W, a = unpack_laplacian(lap)
    solver = ADMMCMM(max_iters=max_iters, time_limit=time_limit)
    t0 = time.perf_counter()
    start = Start("eigen", np.asarray(evecs[:, :k]), np.asarray(evals[:max(k, 2)])) if X0 is None else \
        Start("random", np.asarray(X0), np.asarray(evals[:max(k, 2)]))
    run = solver.solve(W, a, k, mu, start)
    seconds = time.perf_counter() - t0
    P = run.Psi
    dir_cols = np.sum(P * (W @ P), axis=0)
    l1_cols = a @ np.abs(P)
    order = np.argsort(dir_cols + 0.5 * mu * l1_cols, kind="stable")
    P = canonical_signs(P[:, order])
    s, area = sparsity(P, a)
    return CMMRun(P, mu, int(run.iterations), run.status, seconds, float(dir_cols.sum()), l1_cols[order], s, area)


def mu_sweep(lap, k: int, mu_over_n, *, max_iters: int, time_limit: float) -> tuple[list[CMMRun], np.ndarray]:
    """Fig. 3.5: k CMMs by ADMM for each μ = (μ/n)·n, plus the eigenfunctions (μ = 0) for reference."""
    n = lap.W.shape[0]
    ev = mesh.eigenbasis(lap, max(k, 2))
    runs = [solve_cmm(lap, k, float(r) * n, ev.evals, ev.evecs, max_iters=max_iters, time_limit=time_limit)
            for r in mu_over_n]
    return runs, ev.evecs[:, :k]


def mu_random_starts(lap, k: int, mu: float, count: int, *, max_iters: int, time_limit: float) -> list[CMMRun]:
    """Fig. 3.5's remark at one μ from ``count`` random starts (seeds 1 … count, Gaussian, A-orthonormalised),
    with the eigenfunction start's ρ₀."""
    ev = mesh.eigenbasis(lap, max(k, 2))
    n = lap.W.shape[0]
    return [solve_cmm(lap, k, mu, ev.evals, ev.evecs, max_iters=max_iters, time_limit=time_limit,
                      X0=a_orthonormalize(np.random.default_rng(seed).standard_normal((n, k)), lap.A))
            for seed in range(1, count + 1)]


@dataclasses.dataclass
class Chapter4:
    """One mesh's Chapter-4 material: functions by family, bases by name (n × k), timings (s), notes."""

    label: str
    m: mesh.Mesh
    lap: object  # cotangent, lumped, area 1 (the "FEM Laplacian" of the thesis, lumped)
    gl: object  # graph weights, uniform area: A = I/n
    k: int
    k_lbo: int  # the GLMH bases: k_lbo Laplacian eigenfunctions, then k − k_lbo LMHs
    functions: dict
    bases: dict
    times: dict  # basis name -> seconds to compute it (GLMH: region + LMH solve, without Φ)
    notes: dict  # extra measurements: eigs at k − k_lbo, region seconds, orthogonality, segments, CMM run
    cmm: CMMRun


def _functions(m: mesh.Mesh, evals, evecs, n_hks: int, n_wks: int) -> tuple[dict, int]:
    """The eight descriptor families of §4.1 (mesh of unit area); also the number of SEG segments."""
    P = mesh.landmarks(m)
    D = mesh.geodesic_distance(m, P)
    seg = mesh.persistence_segmentation(m, basis=mesh.Eigenbasis(evals, evecs))
    F = {"GEODISTS": mesh.geodists(m, P), "DELTAS": mesh.deltas(D), "NORMDIST": mesh.normdist(D),
         "HKS": mesh.hks(evals, evecs, n_hks), "WKS": mesh.wks(evals, evecs, n_wks),
         "SEG": mesh.segment_indicators(seg.labels), "CONSTANT": mesh.constant(m), "VERTS": mesh.vertex_positions(m)}
    return F, int(seg.labels.max()) + 1


def chapter4(m: mesh.Mesh, label: str, *, k: int, k_lbo: int, n_eig: int, n_wks: int, mu: float,
             cmm_iters: int, cmm_time: float) -> Chapter4:
    """The thesis's bases on ``m``: LBO (k eigenfunctions), GL (graph Laplacian, A = I), GLMH_X for each
    family X (k_lbo eigenfunctions + k − k_lbo LMHs localised where X is reconstructed worst, μ_R = μ_⊥ =
    1e6) and CMM (k modes, μ, ADMM with an iteration budget); plus the descriptor functions."""
    m = mesh.scaled_to_unit_area(m)
    lap = mesh.laplacian(m)
    gl = mesh.laplacian(m, weights="graph", area="uniform")
    times, notes = {}, {}
    times["LBO"], lbo = _best(lambda: mesh.eigenbasis(lap, k), 2)
    times["GL"], glb = _best(lambda: mesh.eigenbasis(gl, k), 2)
    notes["eigs_small"], _ = _best(lambda: mesh.eigenbasis(lap, k - k_lbo), 2)
    t0 = time.perf_counter()
    spectrum = lbo if n_eig <= k else mesh.eigenbasis(lap, n_eig)
    notes["spectrum"] = time.perf_counter() - t0
    F, notes["segments"] = _functions(m, spectrum.evals, spectrum.evecs, 30, n_wks)
    Phi = lbo.evecs[:, :k_lbo]
    B = {"LBO": lbo.evecs, "GL": glb.evecs}
    notes["region"], notes["orthogonality"] = {}, {}
    for name in FUNCTIONS:
        t0 = time.perf_counter()
        _, v, _ = basis_lib.region_from_reconstruction(lap.A, Phi, F[name])
        t1 = time.perf_counter()
        res = basis_lib.lmh(lap.W, lap.A, k - k_lbo, Phi, MU_PERP, v=v, mu_R=MU_R)
        times[f"GLMH_{name}"] = time.perf_counter() - t0
        notes["region"][name] = t1 - t0
        B[f"GLMH_{name}"], notes["orthogonality"][name] = basis_lib.concatenate(Phi, res.Psi, lap.A)
    cmm = solve_cmm(lap, k, mu, lbo.evals, lbo.evecs, max_iters=cmm_iters, time_limit=cmm_time)
    B["CMM"], times["CMM"] = cmm.Psi, cmm.seconds
    return Chapter4(label, m, lap, gl, k, k_lbo, F, B, times, notes, cmm)


def _area_of(d: Chapter4, name: str):
    """Each basis's own area matrix (the one it is A-orthonormal in): GL's is I/n."""
    return d.gl.A if name == "GL" else d.lap.A


def _family_errors(functions: dict, Fall: np.ndarray, R: np.ndarray) -> np.ndarray:
    """Err(F, R) (Def. 4.2.2) of each family, from one reconstruction of all families side by side (both
    methods act column by column, so the slices are the families' own reconstructions)."""
    out, c = [], 0
    for f in FUNCTIONS:
        w = functions[f].shape[1]
        out.append(reconstruction_error(Fall[:, c:c + w], R[:, c:c + w]))
        c += w
    return np.array(out)


def _all_functions(d) -> np.ndarray:
    return np.hstack([d.functions[f] for f in FUNCTIONS])


def lbo_family_errors(m: mesh.Mesh, k: int, n_wks: int) -> dict:
    """The families' Err in the first k LBO eigenfunctions alone (HKS/WKS from those k eigenpairs), absolute and
    relative to each family's size (Err(F, 0)); with the DELTAs' support and the mean edge length (unit area)."""
    m = mesh.scaled_to_unit_area(m)
    ev = mesh.eigenbasis(mesh.laplacian(m), k)
    functions, segments = _functions(m, ev.evals, ev.evecs, 30, n_wks)
    Fall = np.hstack([functions[f] for f in FUNCTIONS])
    err = _family_errors(functions, Fall, reconstruct(Fall, ev.evecs)[0])
    size = _family_errors(functions, Fall, np.zeros_like(Fall))
    return {"n": m.n_vertices, "errors": err, "relative": err / size, "segments": segments,
            "delta_support": float(np.mean(np.count_nonzero(functions["DELTAS"], axis=0))),
            "edge": float(mesh.edge_graph(m).data.mean())}


def reconstruction_table(d: Chapter4, method: str = "lstsq") -> np.ndarray:
    """Fig. 4.13: ``E[basis, family]`` = Err(F, R) of each family in each full basis (rows ``d.bases``)."""
    Fall = _all_functions(d)
    return np.array([_family_errors(d.functions, Fall, reconstruct(Fall, B, _area_of(d, b), method=method)[0])
                     for b, B in d.bases.items()])


def method_sweep(d: Chapter4, sizes, repeats: int = 2) -> dict:
    """Fig. 4.11: for each basis size, the seconds (best of ``repeats``) to reconstruct all families at once and the
    mean error over families, by method, averaged over the bases; also the GLMH bases' mean error alone."""
    Fall = _all_functions(d)
    out = {meth: {"seconds": [], "error": [], "glmh_error": []} for meth in ("lstsq", "manipulation")}
    for s in sizes:
        for meth, rec in out.items():
            secs, errs, glmh = [], [], []
            for b, B in d.bases.items():
                t, (R, _) = _best(lambda: reconstruct(Fall, B[:, :s], _area_of(d, b), method=meth), repeats)
                e = float(np.mean(_family_errors(d.functions, Fall, R)))
                secs.append(t)
                errs.append(e)
                if b.startswith("GLMH"):
                    glmh.append(e)
            rec["seconds"].append(float(np.mean(secs)))
            rec["error"].append(float(np.mean(errs)))
            rec["glmh_error"].append(float(np.mean(glmh)))
    return out


def incremental_errors(F: np.ndarray, B: np.ndarray) -> np.ndarray:
    """Fig. 4.18: Err(F, R_j) for the least-squares reconstruction R_j of F in the first j columns of B,
    j = 1 … k (an orthogonal basis of the nested spans by one QR; equal to ``reconstruct(F, B[:, :j])``)."""
    Q, _ = np.linalg.qr(B)
    C = Q.T @ F
    R = np.array(F, dtype=np.float64, copy=True)
    out = np.empty(B.shape[1])
    for j in range(B.shape[1]):
        R -= np.outer(Q[:, j], C[j])
        out[j] = np.mean(np.linalg.norm(R, axis=1))
    return out


def grassmann_matrix(d: Chapter4, A) -> np.ndarray:
    """Fig. 4.17: d_Gr between the spans of every pair of bases in one inner product ``A`` (each basis
    A-orthonormalised first; ``principal_angles``)."""
    Q = {b: a_orthonormalize(B, A) for b, B in d.bases.items()}
    names = list(Q)
    G = np.zeros((len(names), len(names)))
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            G[i, j] = G[j, i] = float(np.sqrt(np.sum(principal_angles(Q[names[i]], Q[names[j]], A) ** 2)))
    return G


def grassmann_unit_gl(d: Chapter4, G: np.ndarray) -> np.ndarray:
    """``G`` with the GL row and column recomputed as Lemma 4.6.3 reads when the GL eigenvectors have unit
    Euclidean norm (as an eigensolver returns them for the graph Laplacian with an identity mass): the
    singular values of ``QᵀA·U_GL`` taken as cosines (clipped to [0, 1]) — not A-orthonormal, so not angles."""
    A = d.lap.A
    U = d.bases["GL"] / np.linalg.norm(d.bases["GL"], axis=0)
    names = list(d.bases)
    i = names.index("GL")
    out = G.copy()
    for j, b in enumerate(names):
        if j != i:
            c = np.linalg.svd(a_orthonormalize(d.bases[b], A).T @ (A @ U), compute_uv=False)
            out[i, j] = out[j, i] = float(np.sqrt(np.sum(np.arccos(np.clip(c, 0.0, 1.0)) ** 2)))
    return out


def basis_reconstruction(m: mesh.Mesh, *, k: int, mu: float, max_iters: int, time_limit: float) -> dict:
    """Fig. 4.18/4.19 on one mesh: k LBO eigenfunctions and k CMMs (ADMM, μ); the errors of the CMMs
    reconstructed in the first j eigenfunctions ("red") and of the eigenfunctions in the first j CMMs
    ("blue"), j = 1 … k; d_Gr between the two spans; the CMM run (its ‖Aψ_j‖₁ for Fig. 4.19)."""
    m = mesh.scaled_to_unit_area(m)
    lap = mesh.laplacian(m)
    ev = mesh.eigenbasis(lap, k)
    cmm = solve_cmm(lap, k, mu, ev.evals, ev.evecs, max_iters=max_iters, time_limit=time_limit)
    return {"red": incremental_errors(cmm.Psi, ev.evecs), "blue": incremental_errors(ev.evecs, cmm.Psi),
            "d_gr": float(np.sqrt(np.sum(principal_angles(ev.evecs, cmm.Psi, lap.A, orthonormalize=True) ** 2))),
            "cmm": cmm, "n": m.n_vertices}
