"""Functional maps between meshes (thesis §5.1–5.3; docs/maths.md §8).

Convention (differs from the thesis by a transpose): ``C`` is ``(k_tgt, k_src)`` and maps
source coefficients to target coefficients, ``b ≈ C a``. The thesis writes ``B ≈ CᵀA``
(eq. 5.1.7), i.e. its ``C`` is our ``Cᵀ``.

* ``functional_map`` — least squares for ``C`` from function constraints
  ``C (B_srcᵀA_src F_src) ≈ B_tgtᵀA_tgt F_tgt`` plus commutativity with operators written in
  the bases, the objective of eq. 5.1.11/5.1.12::

      ‖C a − b‖_F² + w ‖T C − C S‖_F²      (S (k_src, k_src), T (k_tgt, k_tgt)).

  Eigenbases: ``S = Λ_src``, ``T = Λ_tgt`` diagonal (``evals_*``); the second term is
  ``Σ_ij (λ^tgt_i − λ^src_j)² C_ij²`` and the problem splits into one ridge-regularised
  least-squares problem per row of ``C`` (``k_src`` unknowns each).
  Any basis (CMMs, LMHs, GLMHs; §5.3): the full ``S = ΨᵀWΨ`` (``basis_operator``, ``op_*``).
  Symmetric ``S = PΣPᵀ``, ``T = QΛQᵀ``: with ``Ĉ = QᵀCP``, ``â = Pᵀa``, ``b̂ = Qᵀb`` the objective
  is ``‖Ĉâ − b̂‖² + w‖ΛĈ − ĈΣ‖²`` (orthogonal factors leave Frobenius norms unchanged), the
  diagonal case; ``C = QĈPᵀ``. Non-symmetric operators: the ``k_tgt·k_src``-unknown Kronecker
  normal equations (dense, capped at ``KRONECKER_MAX_UNKNOWNS``). In no case is the
  ``k_tgt(f + k_src) × k_tgt·k_src`` stacked system of eq. 5.1.11 formed.
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
from jaxtyping import Float
from scipy.spatial import cKDTree

from .evaluation import RankDeficientWarning, _apply_A, _as2d, reconstruction_error

__all__ = [
    "FmapShapeError",
    "TooFewFunctionsError",
    "FmapCommutativityError",
    "KRONECKER_MAX_UNKNOWNS",
    "basis_operator",
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

#: Largest ``k_tgt·k_src`` for the dense Kronecker route (non-symmetric operators): its
#: normal matrix is ``(k_tgt·k_src)²`` doubles, 134 MB at this size.
KRONECKER_MAX_UNKNOWNS = 4096
_SYMMETRY_RTOL = 1e-10  # ‖Op − Opᵀ‖_F ≤ this · ‖Op‖_F counts as symmetric (rounding in ΨᵀWΨ is ~1e-16)
_OP_SOLVERS = ("auto", "eigh", "kronecker")
# Shape aliases (module level so that pyflakes does not parse the dimension strings as annotations).
_Basis, _Op = Float[np.ndarray, "n k"], Float[np.ndarray, "k k"]
_BasisSrc, _BasisTgt = Float[np.ndarray, "n_src k_src"], Float[np.ndarray, "n_tgt k_tgt"]
_FunSrc, _FunTgt = Float[np.ndarray, "n_src f"], Float[np.ndarray, "n_tgt f"]
_EvalsSrc, _EvalsTgt = Float[np.ndarray, " k_src"], Float[np.ndarray, " k_tgt"]
_OpSrc, _OpTgt = Float[np.ndarray, "k_src k_src"], Float[np.ndarray, "k_tgt k_tgt"]
_Map = Float[np.ndarray, "k_tgt k_src"]


class FmapShapeError(ValueError):
    """Inconsistent shapes among bases, functions, area matrices, eigenvalues or operators."""


class TooFewFunctionsError(ValueError):
    """Fewer corresponding functions than source basis vectors (f < k): C is not determined (docs/maths.md note 10)."""


class FmapCommutativityError(ValueError):
    """The commutativity term is ill-posed: negative or non-finite weight, missing or doubly given operators
    (``evals_*`` and ``op_*``), non-finite or non-symmetric operators where symmetry is needed, or a
    Kronecker system too large to form."""


def _check_basis_and_functions(B, F, A, side):
    B, F = _as2d(B, f"B_{side}"), _as2d(F, f"F_{side}")
    if B.shape[0] != F.shape[0]:
        raise FmapShapeError(f"B_{side} {B.shape} and F_{side} {F.shape} must have the same number of rows "
                             f"(vertices of the {side} mesh)")
    if A is not None and A.shape[0] != B.shape[0]:
        raise FmapShapeError(f"A_{side} has {A.shape[0]} rows but the {side} mesh has {B.shape[0]} vertices")
    return B, F


def _asymmetry(M) -> float:
    """``‖M − Mᵀ‖_F / ‖M‖_F`` (0 for the zero matrix)."""
    scale = np.linalg.norm(M)
    return float(np.linalg.norm(M - M.T) / scale) if scale > 0 else 0.0


def basis_operator(Psi: _Basis, W) -> _Op:
    """The operator ``W`` written in an A-orthonormal basis: ``sym(ΨᵀWΨ)`` (``(k, k)``; thesis §5.3).

    With ``ΨᵀAΨ = I`` this is the coefficient matrix ``S`` of ``L = A⁻¹W`` on span Ψ (``LΨ ≈ ΨS``,
    the A-orthogonal projection; eq. 5.1.5): ``diag(λ)`` for an eigenbasis ``WΦ = AΦΛ``, a full
    symmetric matrix for CMMs, LMHs and GLMHs. The rounding asymmetry of the product is removed.

    Args:
      Psi: ``(n, k)`` basis.
      W: ``(n, n)`` symmetric weight (stiffness) matrix, scipy sparse or dense, or its diagonal ``(n,)``.
    Returns:
      ``(k, k)`` symmetric, for ``op_src``/``op_tgt`` of ``functional_map``.
    Raises:
      FmapShapeError: ``Psi`` not 2-D, or ``W`` not ``(n, n)``/``(n,)`` with ``n = Psi.shape[0]``.
      FmapCommutativityError: non-finite result, or ``ΨᵀWΨ`` clearly non-symmetric (``W`` is not symmetric,
        e.g. ``L = A⁻¹W`` was passed instead of ``W``).
    """
    Psi = np.asarray(Psi, dtype=np.float64)
    if Psi.ndim != 2:
        raise FmapShapeError(f"Psi must be (n, k), got shape {Psi.shape}")
    n = Psi.shape[0]
    shape = tuple(W.shape) if hasattr(W, "shape") else np.shape(W)
    if shape not in ((n, n), (n,)):
        raise FmapShapeError(f"W has shape {shape}; expected ({n}, {n}) or its diagonal ({n},) "
                             f"to match Psi {Psi.shape}")
    M = Psi.T @ _apply_A(W, Psi)
    if not np.all(np.isfinite(M)):
        raise FmapCommutativityError("ΨᵀWΨ has non-finite entries: Psi or W contains NaN/inf")
    if _asymmetry(M) > 1e-8:
        raise FmapCommutativityError(f"ΨᵀWΨ is not symmetric (relative asymmetry {_asymmetry(M):.1e}): pass the "
                                     "symmetric weight matrix W, not the Laplacian L = A⁻¹W")
    return 0.5 * (M + M.T)


def function_coefficients(B, F, A):
    """Coefficients ``BᵀAF`` (``(k, f)``) of functions ``F (n, f)`` in an A-orthonormal basis ``B (n, k)`` (eq. 4.2.3)."""
    return B.T @ _apply_A(A, F)


def _commutativity_operators(evals_src, evals_tgt, op_src, op_tgt, k_src, k_tgt, needed):
    """Validated operators: ``(S (k_src,), T (k_tgt,))`` diagonals or ``(S, T)`` full square arrays; ``None`` if absent."""
    has_evals = evals_src is not None or evals_tgt is not None
    has_ops = op_src is not None or op_tgt is not None
    if has_evals and has_ops:
        raise FmapCommutativityError("give either evals_src/evals_tgt (eigenbases) or op_src/op_tgt (any basis, "
                                     "e.g. from basis_operator), not both")
    if has_evals:
        if evals_src is None or evals_tgt is None:
            raise FmapCommutativityError("pass both evals_src (k_src,) and evals_tgt (k_tgt,)")
        S = np.asarray(evals_src, dtype=np.float64).reshape(-1)
        T = np.asarray(evals_tgt, dtype=np.float64).reshape(-1)
        if S.shape != (k_src,) or T.shape != (k_tgt,):
            raise FmapShapeError(f"eigenvalues {S.shape}, {T.shape} do not match the bases ({k_src},), ({k_tgt},)")
    elif has_ops:
        if op_src is None or op_tgt is None:
            raise FmapCommutativityError("pass both op_src (k_src, k_src) and op_tgt (k_tgt, k_tgt)")
        S, T = np.asarray(op_src, dtype=np.float64), np.asarray(op_tgt, dtype=np.float64)
        for name, M, k, side in (("op_src", S, k_src, "k_src"), ("op_tgt", T, k_tgt, "k_tgt")):
            if M.shape != (k, k):
                raise FmapShapeError(f"{name} has shape {M.shape}; expected ({side}, {side}) = ({k}, {k}), "
                                     f"square and matching the basis (basis_operator(Psi, W) builds it)")
    elif needed:
        raise FmapCommutativityError("commutativity > 0 needs evals_src (k_src,) and evals_tgt (k_tgt,), "
                                     "or op_src (k_src, k_src) and op_tgt (k_tgt, k_tgt) from basis_operator")
    else:
        return None
    for name, M in (("source", S), ("target", T)):
        if not np.all(np.isfinite(M)):
            raise FmapCommutativityError(f"the {name} operator has {int(np.sum(~np.isfinite(M)))} non-finite "
                                         "entries; check the basis and W")
    return S, T


def _solve_diagonal(a, b, ls, lt, w):
    """``min ‖Ca − b‖² + w Σ_ij (lt_i − ls_j)² C_ij²``: row ``i`` is a stacked ``(f + k_src) × k_src`` least squares."""
    k_tgt, k_src = b.shape[0], a.shape[0]
    sw = np.sqrt(w)
    C = np.empty((k_tgt, k_src))
    rhs_pad = np.zeros(k_src)
    for i in range(k_tgt):  # row i: min ‖aᵀc − b_iᵀ‖² + w ‖D_i c‖², D_i = diag(|lt_i − ls|)
        lhs = np.vstack([a.T, np.diag(sw * np.abs(lt[i] - ls))])
        C[i] = sla.lstsq(lhs, np.concatenate([b[i], rhs_pad]), lapack_driver="gelsd")[0]
    return C


def _solve_rotated(a, b, S, T, w):
    """Symmetric ``S = PΣPᵀ``, ``T = QΛQᵀ``: the diagonal problem for ``Ĉ = QᵀCP`` with ``â = Pᵀa``, ``b̂ = Qᵀb``."""
    sig, P = np.linalg.eigh(0.5 * (S + S.T))
    lam, Q = np.linalg.eigh(0.5 * (T + T.T))
    return Q @ _solve_diagonal(P.T @ a, Q.T @ b, sig, lam, w) @ P.T


def _solve_kronecker(a, b, S, T, w):
    """Normal equations of ``‖Ca − b‖² + w‖TC − CS‖²`` in ``x = vec C`` (column-major, Lemma 5.1.6).

    ``vec(Ca) = (aᵀ ⊗ I_t) x`` and ``vec(TC − CS) = K x``, ``K = I_s ⊗ T − Sᵀ ⊗ I_t``, so
    ``(aaᵀ ⊗ I_t + w KᵀK) x = vec(baᵀ)`` with ``KᵀK = I_s ⊗ TᵀT − S ⊗ T − Sᵀ ⊗ Tᵀ + SSᵀ ⊗ I_t``.
    """
    k_tgt, k_src = b.shape[0], a.shape[0]
    I_s, I_t = np.eye(k_src), np.eye(k_tgt)
    G = np.kron(a @ a.T + w * (S @ S.T), I_t)
    G += w * (np.kron(I_s, T.T @ T) - np.kron(S, T) - np.kron(S.T, T.T))
    rhs = (b @ a.T).reshape(-1, order="F")
    try:
        x = sla.cho_solve(sla.cho_factor(G), rhs)
    except np.linalg.LinAlgError:  # singular (rank-deficient a): minimum-norm solution
        x = sla.lstsq(G, rhs, lapack_driver="gelsy")[0]
    return x.reshape((k_tgt, k_src), order="F")


def functional_map(B_src: _BasisSrc, B_tgt: _BasisTgt, F_src: _FunSrc, F_tgt: _FunTgt, A_src, A_tgt, *,
                   evals_src: _EvalsSrc | None = None, evals_tgt: _EvalsTgt | None = None,
                   op_src: _OpSrc | None = None, op_tgt: _OpTgt | None = None, commutativity: float = 0.0, op_solver: str = "auto") -> _Map:
    """Least-squares functional map ``C (k_tgt, k_src)`` (§5.1.1, eq. 5.1.11–5.1.12; §5.3 for non-eigen bases).

    Minimises ``‖C a − b‖_F² + w ‖T C − C S‖_F²`` with ``a = B_srcᵀA_src F_src`` ``(k_src, f)``,
    ``b = B_tgtᵀA_tgt F_tgt`` ``(k_tgt, f)``, ``w = commutativity`` and the operators in the bases:
    ``S = diag(evals_src)``, ``T = diag(evals_tgt)`` (eigenbases), or ``S = op_src``, ``T = op_tgt``
    (any basis; ``basis_operator(Ψ, W) = ΨᵀWΨ``, thesis §5.3). Diagonal operators (``evals_*``, or
    ``op_*`` with zero off-diagonal entries) are solved row by row; symmetric full operators by
    diagonalising them and solving the rotated diagonal problem (module docstring); non-symmetric
    ones by the Kronecker normal equations (``k_tgt·k_src ≤ KRONECKER_MAX_UNKNOWNS``).

    Args:
      B_src: ``(n_src, k_src)``, B_tgt: ``(n_tgt, k_tgt)`` bases, A-orthonormal on their meshes.
      F_src: ``(n_src, f)``, F_tgt: ``(n_tgt, f)`` corresponding functions (column j ↔ column j).
      A_src, A_tgt: area matrices (sparse ``(n, n)`` or diagonal ``(n,)``).
      evals_src: ``(k_src,)``, evals_tgt: ``(k_tgt,)`` eigenvalues (eigenbases), or
      op_src: ``(k_src, k_src)``, op_tgt: ``(k_tgt, k_tgt)`` operators; one pair is needed if ``w > 0``.
      commutativity: weight ``w ≥ 0`` of the operator constraints (5.1.8).
      op_solver: for full operators, ``"auto"`` (``"eigh"`` if both are symmetric to relative
        ``1e-10``, else ``"kronecker"``), ``"eigh"`` (symmetric only; the symmetric part is used) or
        ``"kronecker"`` (any operators, also diagonal ones).
    Returns:
      ``C (k_tgt, k_src)``.
    Raises:
      TooFewFunctionsError: ``f < k_src`` (docs/maths.md note 10).
      FmapShapeError: inconsistent shapes (bases, functions, areas, eigenvalues, non-square operators).
      FmapCommutativityError: ``w`` negative or not finite; both ``evals_*`` and ``op_*`` given, only one of
        a pair, or neither while ``w > 0``; non-finite operators; a non-symmetric operator with
        ``op_solver="eigh"``; a Kronecker system above ``KRONECKER_MAX_UNKNOWNS``.
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
    w = float(commutativity)
    if not np.isfinite(w) or w < 0:
        raise FmapCommutativityError(f"commutativity must be finite and ≥ 0, got {commutativity!r}")
    if op_solver not in _OP_SOLVERS:
        raise ValueError(f"unknown op_solver {op_solver!r}; choose one of {_OP_SOLVERS}")
    ops = _commutativity_operators(evals_src, evals_tgt, op_src, op_tgt, k_src, k_tgt, needed=w > 0)
    a = function_coefficients(B_src, F_src, A_src)  # (k_src, f)
    b = function_coefficients(B_tgt, F_tgt, A_tgt)  # (k_tgt, f)
    if w == 0.0:
        Ct, _, rank, _ = sla.lstsq(a.T, b.T, lapack_driver="gelsd")  # a.T Cᵀ = b.T
        if rank < k_src:
            warnings.warn(f"source coefficients have rank {rank} < k_src = {k_src} (repeated or dependent "
                          "functions): the map is not determined; returning the minimum-norm solution",
                          RankDeficientWarning, stacklevel=2)
        return np.ascontiguousarray(Ct.T)
    S, T = ops
    if S.ndim == 1:
        return _solve_diagonal(a, b, S, T, w)
    if op_solver == "kronecker" or (op_solver == "auto" and max(_asymmetry(S), _asymmetry(T)) > _SYMMETRY_RTOL):
        if k_src * k_tgt > KRONECKER_MAX_UNKNOWNS:
            raise FmapCommutativityError(
                f"non-symmetric operators need the dense Kronecker system with k_tgt·k_src = {k_tgt * k_src} > "
                f"KRONECKER_MAX_UNKNOWNS = {KRONECKER_MAX_UNKNOWNS} unknowns; use symmetric operators "
                "(basis_operator(Psi, W)) for the eigh route, or truncate the bases")
        return _solve_kronecker(a, b, S, T, w)
    for name, M in (("op_src", S), ("op_tgt", T)):
        if _asymmetry(M) > _SYMMETRY_RTOL:
            raise FmapCommutativityError(
                f"{name} is not symmetric (relative asymmetry {_asymmetry(M):.1e} > {_SYMMETRY_RTOL:.0e}); "
                "op_solver='eigh' needs symmetric operators: build them with basis_operator(Psi, W), "
                "or pass op_solver='kronecker' (or 'auto')")
    if not (S - np.diag(np.diag(S))).any() and not (T - np.diag(np.diag(T))).any():
        return _solve_diagonal(a, b, np.diag(S).copy(), np.diag(T).copy(), w)  # exactly the evals path
    return _solve_rotated(a, b, S, T, w)


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
