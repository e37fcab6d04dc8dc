"""Functional maps between meshes (thesis §5.1–5.2; docs/maths.md §8).

Convention (differs from the thesis by a transpose): ``C`` is ``(k_tgt, k_src)`` and maps
source coefficients to target coefficients, ``b ≈ C a``. The thesis writes ``B ≈ CᵀA``
(eq. 5.1.7), i.e. its ``C`` is our ``Cᵀ``.

* ``functional_map`` — least squares for ``C`` from function constraints
  ``C (B_srcᵀA_src F_src) ≈ B_tgtᵀA_tgt F_tgt`` plus commutativity with diagonal
  operators (Laplacian eigenvalues), the objective of eq. 5.1.11/5.1.12::

      ‖C a − b‖_F² + w ‖Λ_tgt C − C Λ_src‖_F².

  With diagonal ``Λ`` the second term is ``Σ_ij (λ^tgt_i − λ^src_j)² C_ij²``, so the
  problem splits into one ridge-regularised least-squares problem per row of ``C``
  (``k_src`` unknowns each); the ``k² × k²`` Kronecker system is never formed.
* ``p2p_from_fmap`` — nearest neighbours in coefficient space (§5.1.4, cKDTree).
* ``icp_refine`` — alternate p2p extraction and orthogonal Procrustes (§5.1.5).
* Errors (§5.2): ``err_s`` (5.2.23), ``err_t`` (5.2.24), ``err_gd`` (5.2.26, the mean:
  docs/maths.md note 9), ``orthogonality_error`` ``‖CᵀC − I‖_F`` and
  ``c_orthogonality_error`` ``‖D − Cᵀ‖_F`` (Def. 5.2.5).
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.linalg as sla
from scipy.spatial import cKDTree

from .evaluation import RankDeficientWarning, _apply_A, _as2d, reconstruction_error

__all__ = [
    "FmapShapeError",
    "TooFewFunctionsError",
    "function_coefficients",
    "functional_map",
    "p2p_from_fmap",
    "icp_refine",
    "err_s",
    "err_t",
    "err_gd",
    "mean_edge_length",
    "orthogonality_error",
    "c_orthogonality_error",
]


class FmapShapeError(ValueError):
    """Inconsistent shapes among bases, functions, area matrices or eigenvalues."""


class TooFewFunctionsError(ValueError):
    """Fewer corresponding functions than source basis vectors (f < k): C is not determined (docs/maths.md note 10)."""


def _check_basis_and_functions(B, F, A, side):
    B, F = _as2d(B, f"B_{side}"), _as2d(F, f"F_{side}")
    if B.shape[0] != F.shape[0]:
        raise FmapShapeError(f"B_{side} {B.shape} and F_{side} {F.shape} must have the same number of rows "
                             f"(vertices of the {side} mesh)")
    if A is not None and A.shape[0] != B.shape[0]:
        raise FmapShapeError(f"A_{side} has {A.shape[0]} rows but the {side} mesh has {B.shape[0]} vertices")
    return B, F


def function_coefficients(B, F, A):
    """Coefficients ``BᵀAF`` (``(k, f)``) of functions ``F (n, f)`` in an A-orthonormal basis ``B (n, k)`` (eq. 4.2.3)."""
    return B.T @ _apply_A(A, F)


def functional_map(B_src, B_tgt, F_src, F_tgt, A_src, A_tgt, *, evals_src=None, evals_tgt=None,
                   commutativity: float = 0.0):
    """Least-squares functional map ``C (k_tgt, k_src)`` (§5.1.1, eq. 5.1.11–5.1.12).

    Minimises ``‖C a − b‖_F² + w Σ_ij (λ^tgt_i − λ^src_j)² C_ij²`` with ``a = B_srcᵀA_src F_src``
    ``(k_src, f)``, ``b = B_tgtᵀA_tgt F_tgt`` ``(k_tgt, f)`` and ``w = commutativity``.
    Row ``i`` of ``C`` solves ``min ‖aᵀc − b_iᵀ‖² + w ‖D_i c‖²``, ``D_i = diag(|λ^tgt_i − λ^src|)``,
    as a stacked ``(f + k_src) × k_src`` least-squares problem (no Kronecker system).

    Args:
      B_src: ``(n_src, k_src)``, B_tgt: ``(n_tgt, k_tgt)`` bases, A-orthonormal on their meshes.
      F_src: ``(n_src, f)``, F_tgt: ``(n_tgt, f)`` corresponding functions (column j ↔ column j).
      A_src, A_tgt: area matrices (sparse ``(n, n)`` or diagonal ``(n,)``).
      evals_src: ``(k_src,)``, evals_tgt: ``(k_tgt,)`` eigenvalues (needed if ``commutativity > 0``).
      commutativity: weight ``w ≥ 0`` of the operator constraints (5.1.8).
    Returns:
      ``C (k_tgt, k_src)``.
    Raises:
      TooFewFunctionsError: ``f < k_src`` (docs/maths.md note 10).
      FmapShapeError: inconsistent shapes.
    Warns:
      RankDeficientWarning: ``f ≥ k_src`` but the source coefficients have rank < k_src
        (e.g. repeated functions) and ``commutativity == 0``; the minimum-norm C is returned.
    """
    B_src, F_src = _check_basis_and_functions(B_src, F_src, A_src, "src")
    B_tgt, F_tgt = _check_basis_and_functions(B_tgt, F_tgt, A_tgt, "tgt")
    if F_src.shape[1] != F_tgt.shape[1]:
        raise FmapShapeError(f"F_src has {F_src.shape[1]} functions but F_tgt has {F_tgt.shape[1]}; "
                             "they must correspond column by column")
    k_src, k_tgt, f = B_src.shape[1], B_tgt.shape[1], F_src.shape[1]
    if f < k_src:
        raise TooFewFunctionsError(f"{f} functions cannot determine a map from {k_src} basis vectors: "
                                   f"need f ≥ k_src (docs/maths.md note 10); add descriptors or truncate the basis")
    if commutativity < 0:
        raise ValueError("commutativity must be ≥ 0")
    a = function_coefficients(B_src, F_src, A_src)  # (k_src, f)
    b = function_coefficients(B_tgt, F_tgt, A_tgt)  # (k_tgt, f)
    if commutativity == 0.0:
        Ct, _, rank, _ = sla.lstsq(a.T, b.T, lapack_driver="gelsd")  # a.T Cᵀ = b.T
        if rank < k_src:
            warnings.warn(f"source coefficients have rank {rank} < k_src = {k_src} (repeated or dependent "
                          "functions): the map is not determined; returning the minimum-norm solution",
                          RankDeficientWarning, stacklevel=2)
        return np.ascontiguousarray(Ct.T)
    if evals_src is None or evals_tgt is None:
        raise ValueError("commutativity > 0 needs evals_src (k_src,) and evals_tgt (k_tgt,)")
    ls = np.asarray(evals_src, dtype=np.float64).reshape(-1)
    lt = np.asarray(evals_tgt, dtype=np.float64).reshape(-1)
    if ls.shape != (k_src,) or lt.shape != (k_tgt,):
        raise FmapShapeError(f"eigenvalues {ls.shape}, {lt.shape} do not match the bases ({k_src},), ({k_tgt},)")
    sw = np.sqrt(commutativity)
    C = np.empty((k_tgt, k_src))
    rhs_pad = np.zeros(k_src)
    for i in range(k_tgt):  # k_tgt small problems of size (f + k_src) × k_src
        lhs = np.vstack([a.T, np.diag(sw * np.abs(lt[i] - ls))])
        C[i] = sla.lstsq(lhs, np.concatenate([b[i], rhs_pad]), lapack_driver="gelsd")[0]
    return C


def p2p_from_fmap(C, B_src, B_tgt, *, direction: str = "tgt_to_src"):
    """Point-to-point map from a functional map by nearest neighbours in coefficient space (§5.1.4).

    The delta at source vertex ``x`` has (scaled) coefficients ``B_src[x]``; ``C`` sends it to
    ``C B_src[x]`` (row ``x`` of ``B_src Cᵀ``, ``(n_src, k_tgt)``), compared with target vertex
    ``y``'s coefficients ``B_tgt[y]`` (``‖x − y‖_A = ‖a − b‖₂``, App. A.11).

    Args:
      C: ``(k_tgt, k_src)``; B_src: ``(n_src, k_src)``; B_tgt: ``(n_tgt, k_tgt)``.
      direction: ``"tgt_to_src"`` (default; the usual convention, since a functional map
        ``f ↦ f∘T⁻¹`` corresponds to a pointwise map target → source): returns ``p (n_tgt,)``
        with ``p[y] = argmin_x ‖C B_src[x] − B_tgt[y]‖``. ``"src_to_tgt"`` (the thesis's
        §5.1.4 formulation): ``p (n_src,)`` with ``p[x] = argmin_y ‖C B_src[x] − B_tgt[y]‖``.
    Returns:
      integer array of vertex indices.
    """
    C, B_src, B_tgt = _as2d(C, "C"), _as2d(B_src, "B_src"), _as2d(B_tgt, "B_tgt")
    if C.shape != (B_tgt.shape[1], B_src.shape[1]):
        raise FmapShapeError(f"C has shape {C.shape}; expected (k_tgt, k_src) = ({B_tgt.shape[1]}, {B_src.shape[1]})")
    mapped = B_src @ C.T  # (n_src, k_tgt)
    if direction == "tgt_to_src":
        return cKDTree(mapped).query(B_tgt, k=1)[1]
    if direction == "src_to_tgt":
        return cKDTree(B_tgt).query(mapped, k=1)[1]
    raise ValueError(f"unknown direction {direction!r}; choose 'tgt_to_src' or 'src_to_tgt'")


def icp_refine(C, B_src, B_tgt, iters: int = 10):
    """ICP refinement of a functional map (§5.1.5).

    Alternates (i) ``p = p2p_from_fmap(C, B_src, B_tgt)`` (target → source) and (ii) the
    orthogonal Procrustes step ``C = argmin_{CᵀC=I} Σ_y ‖C B_src[p[y]] − B_tgt[y]‖²
    = U Vᵀ`` with ``U S Vᵀ = B_tgtᵀ B_src[p]`` (``(k_tgt, k_src)``). Stops early when ``p``
    no longer changes.

    Returns:
      ``(C (k_tgt, k_src) with orthonormal rows or columns, p (n_tgt,) the last p2p map)``.
    """
    C = _as2d(C, "C")
    p = p2p_from_fmap(C, B_src, B_tgt)
    for _ in range(int(iters)):
        U, _, Vt = np.linalg.svd(B_tgt.T @ B_src[p], full_matrices=False)
        C = U @ Vt
        p_new = p2p_from_fmap(C, B_src, B_tgt)
        if np.array_equal(p_new, p):
            break
        p = p_new
    return C, p


def err_s(C, B_tgt, a, G) -> float:
    """Simple transformation error ``Err_S(C) = ‖G − Ψ C a‖_F`` (eq. 5.2.23, our ``C`` = thesis ``Cᵀ``).

    Args: C ``(k_tgt, k_src)``; B_tgt = Ψ ``(n_tgt, k_tgt)``; a ``(k_src, f)`` source coefficients;
      G ``(n_tgt, f)`` target functions (or their reconstruction ``Ψb`` for Thm. 5.3.1).
    """
    return float(np.linalg.norm(_as2d(G, "G") - B_tgt @ (C @ a)))


def err_t(C, B_tgt, a, G) -> float:
    """Function transformation error ``Err_T(C) = Err(G, Ψ C a)`` (eq. 5.2.24, Def. 4.2.2)."""
    return reconstruction_error(G, B_tgt @ (C @ a))


def mean_edge_length(V, faces) -> float:
    """Mean length of the unique edges of a triangle mesh (``V (n, 3)``, ``faces (m, 3)``)."""
    faces = np.asarray(faces)
    e = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    e = np.unique(e, axis=0)
    V = np.asarray(V, dtype=np.float64)
    return float(np.mean(np.linalg.norm(V[e[:, 0]] - V[e[:, 1]], axis=1)))


def err_gd(p2p, ground_truth, V, edge_length: float) -> float:
    """Geodesic functional map error (eq. 5.2.26), as the **mean** over mapped vertices (docs/maths.md note 9).

    ``mean_i ‖V[gt_i] − V[ρ_i]‖₂ / edge_length`` — Euclidean distances on the mesh the
    indices point into (``V (n, 3)``), in average-edge-length units.
    Args: p2p, ground_truth: ``(m,)`` vertex indices into ``V``; edge_length: e.g. ``mean_edge_length``.
    """
    p2p, gt = np.asarray(p2p), np.asarray(ground_truth)
    if p2p.shape != gt.shape:
        raise FmapShapeError(f"p2p {p2p.shape} and ground truth {gt.shape} differ in shape")
    V = np.asarray(V, dtype=np.float64)
    return float(np.mean(np.linalg.norm(V[p2p] - V[gt], axis=1)) / edge_length)


def orthogonality_error(C) -> float:
    """``‖CᵀC − I‖_F`` (§5.2; zero for an isometry with A-orthonormal bases, property (4))."""
    C = _as2d(C, "C")
    return float(np.linalg.norm(C.T @ C - np.eye(C.shape[1])))


def c_orthogonality_error(C, D) -> float:
    """C-orthogonality error ``‖D − Cᵀ‖_F`` (Def. 5.2.5), ``D`` the map in the opposite direction."""
    C, D = _as2d(C, "C"), _as2d(D, "D")
    if D.shape != C.T.shape:
        raise FmapShapeError(f"D {D.shape} must have the shape of Cᵀ {C.T.shape}")
    return float(np.linalg.norm(D - C.T))
