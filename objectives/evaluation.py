"""Evaluating bases: reconstruction, reconstruction error, principal angles, Grassmannian distance (thesis Ch. 4; docs/maths.md §8).

* Reconstruction of ``F (n, f)`` in a basis ``B (n, k)`` (§4.2): least squares
  ``coeffs = (BᵀB)⁻¹BᵀF`` (computed by ``lstsq``, eq. 4.2.2) or "matrix manipulation"
  ``coeffs = BᵀAF`` (eq. 4.2.3, exact projection only for ``BᵀAB = I``).
  Least squares minimises the Euclidean Frobenius error, hence its reconstruction
  error is never larger in the Frobenius sense; with ``A = I`` the two coincide (§4.2.3).
  The mean per-vertex error of Def. 4.2.2 is usually, but not provably, smaller too.
* ``reconstruction_error(F, R) = mean_i ‖F_i· − R_i·‖₂`` (Def. 4.2.1–4.2.2).
* ``principal_angles(B1, B2, A)`` for A-orthonormal bases (Lemma 4.6.3) and
  ``grassmann_distance`` (Def. 4.6.4).

No ``mesh`` import: ``A`` is a scipy sparse ``(n, n)`` matrix, a dense array, or its diagonal ``(n,)``.
"""

from __future__ import annotations

import warnings

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

__all__ = [
    "NotOrthonormalError",
    "RankDeficientWarning",
    "reconstruct",
    "per_vertex_error",
    "reconstruction_error",
    "basis_reconstruction_error",
    "principal_angles",
    "grassmann_distance",
    "a_orthonormalize",
]


class NotOrthonormalError(ValueError):
    """A basis passed where an A-orthonormal one is required is not (``‖BᵀAB − I‖_max > tol``)."""


class RankDeficientWarning(UserWarning):
    """A least-squares problem is rank deficient; the minimum-norm solution (``lstsq``) is used."""


def _apply_A(A, X):
    if A is None:
        return X
    if not sp.issparse(A):
        A = np.asarray(A, dtype=np.float64)
        if A.ndim == 1:
            return A.reshape((-1,) + (1,) * (X.ndim - 1)) * X
    if A.shape[0] != X.shape[0]:
        raise ValueError(f"A has {A.shape[0]} rows but the functions have {X.shape[0]} (one per vertex)")
    return np.asarray(A @ X)


def _as2d(X, name):
    X = np.asarray(X, dtype=np.float64)
    if X.ndim == 1:
        X = X[:, None]
    if X.ndim != 2:
        raise ValueError(f"{name} must be (n, m), got shape {X.shape}")
    return X


def lstsq_coefficients(B, F, *, what: str = "basis"):
    """Least-squares coefficients ``argmin_X ‖F − BX‖_F`` (``(k, f)``) by ``lstsq``; warns when ``B`` is rank deficient.

    Numerical rank: singular values below ``max(n, k)·ε·σ_max`` count as zero.
    """
    X, _, rank, _ = sla.lstsq(B, F, cond=max(B.shape) * np.finfo(np.float64).eps, lapack_driver="gelsd")
    if rank < B.shape[1]:
        warnings.warn(f"{what} of shape {B.shape} has rank {rank} < {B.shape[1]}: least squares is "
                      "rank deficient; using the minimum-norm solution", RankDeficientWarning, stacklevel=3)
    return X


def reconstruct(F, B, A=None, *, method: str = "lstsq"):
    """Reconstruction ``R = B·coeffs`` of functions ``F`` in basis ``B`` (§4.2).

    Args:
      F: ``(n, f)`` functions as columns (or ``(n,)``).
      B: ``(n, k)`` basis.
      A: ``(n, n)`` area matrix, required for ``method="manipulation"``.
      method: ``"lstsq"`` — ``coeffs = (BᵀB)⁻¹BᵀF`` via ``lstsq`` (eq. 4.2.2; rank-deficient
        ``B`` gives the minimum-norm coefficients and a ``RankDeficientWarning``);
        ``"manipulation"`` — ``coeffs = BᵀAF`` (eq. 4.2.3).
    Returns:
      ``(R (n, f), coeffs (k, f))``.
    """
    F, B = _as2d(F, "F"), _as2d(B, "B")
    if F.shape[0] != B.shape[0]:
        raise ValueError(f"F {F.shape} and B {B.shape} must have the same number of rows (vertices)")
    if method == "lstsq":
        C = lstsq_coefficients(B, F)
    elif method == "manipulation":
        if A is None:
            raise ValueError("method='manipulation' needs the area matrix A")
        C = B.T @ _apply_A(A, F)
    else:
        raise ValueError(f"unknown method {method!r}; choose 'lstsq' or 'manipulation'")
    return B @ C, C


def per_vertex_error(F, R):
    """Reconstruction error function ``Err_f(v_i) = ‖F_i· − R_i·‖₂`` (Def. 4.2.1); ``(n,)``."""
    F, R = _as2d(F, "F"), _as2d(R, "R")
    if F.shape != R.shape:
        raise ValueError(f"F {F.shape} and its reconstruction R {R.shape} differ in shape")
    return np.linalg.norm(F - R, axis=1)


def reconstruction_error(F, R) -> float:
    """Reconstruction error ``Err(F, R) = (1/n) Σ_i ‖F_i· − R_i·‖₂`` (Def. 4.2.2)."""
    return float(np.mean(per_vertex_error(F, R)))


def basis_reconstruction_error(B1, B2, A=None, *, method: str = "lstsq") -> float:
    """Error of reconstructing the columns of basis ``B1 (n, k1)`` in basis ``B2 (n, k2)`` (§4.6): ``Err(B1, R)``."""
    R, _ = reconstruct(B1, B2, A, method=method)
    return reconstruction_error(B1, R)


def _diag_of(A):
    """The diagonal ``(n,)`` if ``A`` is diagonal (1-D, sparse or dense), else ``None``."""
    if A is None:
        return None
    if sp.issparse(A):
        d = A.diagonal()
        return d if (A - sp.diags(d)).count_nonzero() == 0 else None
    A = np.asarray(A, dtype=np.float64)
    if A.ndim == 1:
        return A
    d = np.diag(A).copy()
    return d if np.count_nonzero(A - np.diag(d)) == 0 else None


def a_orthonormalize(B, A=None):
    """A-orthonormal basis of ``span(B)`` (``(n, r)``, ``r = rank B``) by an eigen-decomposition of ``BᵀAB``.

    Columns whose Gram eigenvalue is below ``1e-12 × max`` are dropped (rank deficiency).
    """
    B = _as2d(B, "B")
    G = B.T @ _apply_A(A, B)
    w, U = np.linalg.eigh(0.5 * (G + G.T))
    keep = w > 1e-12 * max(float(w.max()), np.finfo(float).tiny)
    X = B @ (U[:, keep] / np.sqrt(w[keep]))
    # one more Cholesky pass makes it exact to working precision
    G = X.T @ _apply_A(A, X)
    R = sla.cholesky(0.5 * (G + G.T), lower=False)
    return sla.solve_triangular(R, X.T, trans="T", lower=False).T


def _check_orthonormal(B, A, tol, name):
    G = B.T @ _apply_A(A, B)
    dev = float(np.max(np.abs(G - np.eye(G.shape[0])))) if G.size else 0.0
    if not dev <= tol:
        raise NotOrthonormalError(
            f"{name} of shape {B.shape} is not A-orthonormal: max|{name}ᵀA{name} − I| = {dev:.2e} > {tol:.0e}; "
            "pass orthonormalize=True (or call a_orthonormalize) first")


def principal_angles(B1, B2, A=None, *, orthonormalize: bool = False, tol: float = 1e-8):
    """Principal angles between ``span B1`` and ``span B2`` in the A-inner product (Def. 4.6.1, Lemma 4.6.3).

    Cosines are the singular values of ``B1ᵀAB2``; for accuracy at small angles the
    sines are computed from the A-norm singular values of ``Bs − Bl(BlᵀABs)`` (``Bs`` the
    smaller basis) and ``θ = arcsin(sin)`` where ``θ < π/4`` (Knyazev & Argentati 2002).

    Args:
      B1: ``(n, k)``, B2: ``(n, l)``; A-orthonormal (``BᵀAB = I`` to ``tol``) unless
        ``orthonormalize=True``, which A-orthonormalises them first (``a_orthonormalize``).
      A: ``(n, n)`` SPD (sparse, dense, or a diagonal ``(n,)``); ``None`` = identity.
    Returns:
      ``(min(k, l),)`` angles in ``[0, π/2]``, ascending.
    Raises:
      NotOrthonormalError: a basis is not A-orthonormal and ``orthonormalize`` is False.
    """
    B1, B2 = _as2d(B1, "B1"), _as2d(B2, "B2")
    if B1.shape[0] != B2.shape[0]:
        raise ValueError(f"B1 {B1.shape} and B2 {B2.shape} live on different vertex sets")
    if orthonormalize:
        B1, B2 = a_orthonormalize(B1, A), a_orthonormalize(B2, A)
    else:
        _check_orthonormal(B1, A, tol, "B1")
        _check_orthonormal(B2, A, tol, "B2")
    Bs, Bl = (B1, B2) if B1.shape[1] <= B2.shape[1] else (B2, B1)
    m = Bs.shape[1]
    cos = np.clip(np.linalg.svd(Bl.T @ _apply_A(A, Bs), compute_uv=False), 0.0, 1.0)  # descending
    Q = Bs - Bl @ (Bl.T @ _apply_A(A, Bs))  # component of span Bs A-orthogonal to span Bl
    d = _diag_of(A) if A is not None else np.ones(Q.shape[0])
    if d is not None:
        sin = np.linalg.svd(np.sqrt(d)[:, None] * Q, compute_uv=False)[::-1]
    else:
        G = Q.T @ _apply_A(A, Q)
        sin = np.sqrt(np.clip(np.linalg.eigvalsh(0.5 * (G + G.T)), 0.0, None))
    sin = np.clip(sin[:m], 0.0, 1.0)  # ascending
    theta_c = np.arccos(cos)
    theta_s = np.arcsin(sin)
    return np.where(cos ** 2 >= 0.5, theta_s, theta_c)


def grassmann_distance(B1, B2, A=None, *, orthonormalize: bool = False, tol: float = 1e-8) -> float:
    """Grassmannian distance ``d_Gr = (Σ_i θ_i²)^{1/2}`` (Def. 4.6.4) over the ``min(k, l)`` principal angles.

    Zero iff one span contains the other. Arguments as for ``principal_angles``.
    """
    return float(np.sqrt(np.sum(principal_angles(B1, B2, A, orthonormalize=orthonormalize, tol=tol) ** 2)))
