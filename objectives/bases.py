"""Bases from generalised eigenproblems: GLMHs, LMHs, Hamiltonian eigenfunctions (thesis §3.1, §3.3; docs/maths.md §4).

Generalised localised manifold harmonics (Def. 3.3.1 with ``μ_f = 0``, Thm. 3.3.7,
Def. 3.3.9) are the ``k`` smallest generalised eigenpairs of ``(sym(Q), M)``::

    Q = W + μ_V A diag(V) + μ_⊥ (AΦ)(AΦ)ᵀ,        ΨᵀMΨ = I,

covering Laplacian eigenfunctions (``μ_V = μ_⊥ = 0``), LMHs (eq. 3.1.5, ``V = v`` the
region penalty of eq. 3.1.2) and Hamiltonian eigenfunctions (eq. 3.1.9 with the
constraint ``ΨᵀAΨ = I``, docs/maths.md note 7).

The rank-``r`` term ``μ_⊥ BBᵀ`` (``B = AΦ``, ``n × r``) is never formed: ``Q`` is a
``LinearOperator`` and shift-invert Lanczos (``eigsh``) applies
``(K + μ_⊥BBᵀ − σM)⁻¹`` through the Woodbury identity (thesis Thm. 6.1.17 / App. G)
with one sparse LU of the sparse part ``K − σM``, ``K = W + μ_V sym(A diag(V))``.

This module imports nothing from ``mesh``: callers pass ``W`` and ``A`` (scipy
sparse, ``(n, n)``) and functions as arrays.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from stiefel.errors import ShapeError
from stiefel.manifolds.signs import canonical_signs
from stiefel.linalg.sparse_factor import SymmetricFactor
from stiefel.validation import (check_count, check_finite, check_nonnegative, check_number, check_unit_interval)

from .evaluation import per_vertex_error, reconstruct

__all__ = [
    "BasisResult",
    "glmh",
    "lmh",
    "hamiltonian",
    "region_from_reconstruction",
    "potential_from_reconstruction",
    "concatenate",
]


class BasisResult(NamedTuple):
    """``(evals (k,), Psi (n, k))``; ascending ``λ_i = ψ_iᵀ sym(Q) ψ_i``, ``ΨᵀMΨ = I``.

    Each column's entry of largest magnitude is positive (a permutation-equivariant sign,
    the same convention as ``mesh.eigenbasis``).
    """

    evals: np.ndarray
    Psi: np.ndarray


def _as_csc(X, n: int | None = None, name: str = "matrix") -> sp.csc_matrix:
    if not sp.issparse(X):
        X = np.asarray(X, dtype=np.float64)
        if X.ndim == 1:
            X = sp.diags(X)
        else:
            X = sp.csc_matrix(X)
    X = sp.csc_matrix(X, dtype=np.float64)
    if X.shape[0] != X.shape[1] or (n is not None and X.shape[0] != n):
        raise ShapeError(f"{name} has shape {X.shape}; expected ({n}, {n}) to match W")
    check_finite(name, X)
    return X


def _woodbury_inverse(S: sp.csc_matrix, B: np.ndarray | None, c: float) -> spla.LinearOperator:
    """``(S + c BBᵀ)⁻¹`` as a ``LinearOperator`` via Woodbury: ``S⁻¹ − S⁻¹B (I/c + BᵀS⁻¹B)⁻¹ BᵀS⁻¹``.

    ``S``: ``(n, n)`` sparse, non-singular; ``B``: ``(n, r)`` dense; ``c > 0``.
    Cost per application: one sparse triangular solve pair plus ``O(nr)``.
    """
    n = S.shape[0]
    solve = SymmetricFactor(S, check=False).solve
    if B is None or c == 0.0:
        return spla.LinearOperator((n, n), matvec=solve, matmat=solve, dtype=np.float64)
    SiB = solve(B)  # (n, r)
    cap = np.eye(B.shape[1]) / c + B.T @ SiB  # (r, r) capacitance matrix
    cap_lu = sla.lu_factor(0.5 * (cap + cap.T))

    def apply(x):
        y = solve(x)
        return y - SiB @ sla.lu_solve(cap_lu, B.T @ y)

    return spla.LinearOperator((n, n), matvec=apply, matmat=apply, dtype=np.float64)


def glmh(W, A, k: int, *, mu_V: float = 0.0, V=None, mu_perp: float = 0.0, Phi=None, M=None,
         sigma: float | None = None, tol: float = 0.0, seed: int = 0) -> BasisResult:
    """Generalised localised manifold harmonics (Def. 3.3.9; Thm. 3.3.7): smallest ``k`` eigenpairs of ``(sym(Q), M)``.

    ``Q = W + μ_V A diag(V) + μ_⊥ AΦΦᵀA`` (docs/maths.md §4). The rank-``r`` term is applied as a
    matvec and inverted by Woodbury; no dense ``n × n`` matrix is formed.

    Args:
      W: ``(n, n)`` sparse symmetric weight matrix (PSD, Def. 2.5.20).
      A: ``(n, n)`` sparse area matrix (or its diagonal ``(n,)``).
      k: number of eigenpairs, ``1 ≤ k < n``.
      mu_V, V: potential weight and diagonal potential ``V (n,)`` (region penalty ``v``
        of eq. 3.1.2 for LMHs, a potential for eq. 3.1.9).
      mu_perp, Phi: orthogonality penalty and the basis ``Φ (n, r)`` to stay
        A-orthogonal to (eq. 3.1.4–3.1.5).
      M: ``(n, n)`` SPD constraint matrix (default ``A``).
      sigma: shift for shift-invert; default ``−1e-8·s`` (``s = max W_ii/M_ii``) below
        ``min(μ_V V)`` when the potential is negative somewhere (valid for ``M = A``
        diagonal; pass ``sigma`` below the spectrum otherwise).
      tol, seed: ARPACK tolerance (0: machine precision) and start-vector seed.

    Returns:
      ``BasisResult(evals (k,), Psi (n, k))``, ascending, ``ΨᵀMΨ = I``.

    Checked before any work: ``ParameterError`` (k an integer in ``[1, n − 1]`` — ARPACK needs
    ``k < n``; μ's and σ finite, ``μ_⊥ ≥ 0``, ``tol ≥ 0``), ``NonFiniteError`` (W, A, M, V, Φ),
    ``ShapeError``.
    """
    W = _as_csc(W, name="W")
    n = W.shape[0]
    A = _as_csc(A, n, "A")
    M = A if M is None else _as_csc(M, n, "M")
    check_count("k", k, 1, n - 1, high_label=f"n − 1 = {n - 1} (ARPACK's eigsh needs k < n)")
    check_number("mu_V", mu_V)
    check_nonnegative("mu_perp", mu_perp)
    check_nonnegative("tol", tol)
    check_count("seed", seed, 0)
    if sigma is not None:
        check_number("sigma", sigma)
    K = sp.csc_matrix(W)
    vmin = 0.0
    if mu_V != 0.0:
        if V is None:
            raise ValueError("mu_V ≠ 0 needs a potential V of shape (n,)")
        V = np.asarray(V, dtype=np.float64).reshape(-1)
        if V.shape != (n,):
            raise ShapeError(f"potential V has shape {V.shape}; expected ({n},)")
        check_finite("V", V)
        AV = A @ sp.diags(V)
        K = sp.csc_matrix(K + mu_V * 0.5 * (AV + AV.T))
        vmin = float(np.min(mu_V * V))
    B = None
    if mu_perp != 0.0:
        if Phi is None:
            raise ValueError("mu_perp ≠ 0 needs the basis Phi of shape (n, r)")
        Phi = np.asarray(Phi, dtype=np.float64)
        if Phi.ndim != 2 or Phi.shape[0] != n:
            raise ShapeError(f"Phi has shape {Phi.shape}; expected ({n}, r)")
        check_finite("Phi", Phi)
        B = np.asarray(A @ Phi)  # (n, r)
    if sigma is None:
        scale = float(np.max(np.abs(W.diagonal()) / np.maximum(np.abs(M.diagonal()), np.finfo(float).tiny)))
        sigma = min(vmin, 0.0) - 1e-8 * max(scale, 1.0)

    def q_matvec(x):
        y = K @ x
        if B is not None:
            y = y + mu_perp * (B @ (B.T @ x))
        return y

    Qop = spla.LinearOperator((n, n), matvec=q_matvec, matmat=q_matvec, dtype=np.float64)
    OPinv = _woodbury_inverse(sp.csc_matrix(K - sigma * M), B, mu_perp)
    v0 = np.random.default_rng(seed).standard_normal(n)
    ncv = min(n, max(3 * k, 30))
    evals, Psi = spla.eigsh(Qop, k=k, M=M, sigma=sigma, which="LM", OPinv=OPinv, v0=v0, tol=tol, ncv=ncv)
    order = np.argsort(evals)
    evals, Psi = evals[order], Psi[:, order]
    # exact M-orthonormalisation (ARPACK's vectors are M-orthogonal to working precision)
    gram = Psi.T @ (M @ Psi)
    R = sla.cholesky(0.5 * (gram + gram.T), lower=False)
    Psi = sla.solve_triangular(R, Psi.T, trans="T", lower=False).T
    return BasisResult(evals=evals, Psi=canonical_signs(Psi))  # the largest-magnitude entry of each column is positive


def lmh(W, A, k: int, Phi_k, mu_perp: float, *, v=None, mu_R: float = 0.0, **kwargs) -> BasisResult:
    """Localised manifold harmonics, eq. 3.1.5 (Def. 3.1.2).

    ``min tr(Ψᵀ(W + μ_R A diag(v) + μ_⊥ AΦ_kΦ_kᵀA)Ψ)`` s.t. ``ΨᵀAΨ = I``.

    Args:
      W, A: ``(n, n)`` sparse; ``k``: number of LMHs.
      Phi_k: ``(n, r)`` the (A-orthonormal) basis to complement.
      mu_perp: weight of the orthogonality term (eq. 3.1.4).
      v: ``(n,)`` region penalty ``v = (1 − u)²`` (eq. 3.1.2; from
        ``region_from_reconstruction``); ``mu_R`` its weight. ``v=None``: no localisation.
      kwargs: passed to ``glmh`` (``sigma``, ``tol``, ``seed``).
    Returns:
      ``BasisResult(evals (k,), Psi (n, k))``.
    """
    return glmh(W, A, k, mu_V=mu_R if v is not None else 0.0, V=v, mu_perp=mu_perp, Phi=Phi_k, **kwargs)


def hamiltonian(W, A, k: int, potential, mu_V: float, **kwargs) -> BasisResult:
    """Hamiltonian eigenfunctions, eq. 3.1.7/3.1.9 (Def. 3.1.5): ``(W + μ_V A V)ψ = λAψ``, ``ΨᵀAΨ = I``.

    ``potential``: ``(n,)`` diagonal of ``V`` (e.g. ``potential_from_reconstruction``).
    """
    return glmh(W, A, k, mu_V=mu_V, V=potential, **kwargs)


def _default_functions(F):
    if F is None:
        raise ValueError("pass the function set F (n, f); the thesis's default is the vertex positions (§3.1.1)")
    F = np.asarray(F, dtype=np.float64)
    return F[:, None] if F.ndim == 1 else F


def region_from_reconstruction(A, Phi, F, *, threshold: float | None = None, quantile: float = 0.9,
                               method: str = "manipulation"):
    """The region ``R`` of badly reconstructed vertices and its penalty ``v`` (§3.1.1, eq. 3.1.2).

    Reconstruct ``F`` in ``Φ`` (``evaluation.reconstruct``), take the per-vertex error
    ``e_i = ‖F_i· − R_i·‖₂`` (Def. 4.2.1) and select ``R = {i : e_i > t}`` with ``t`` the
    given ``threshold`` or else the ``quantile`` of ``e``.

    Args:
      A: ``(n, n)`` sparse area matrix; Phi: ``(n, k)`` basis; F: ``(n, f)`` functions
        (vertex positions in the thesis).
    Returns:
      ``(u (n,) bool indicator of R, v (n,) = (1 − u)² penalty, e (n,) per-vertex errors)``.
    """
    check_unit_interval("quantile", quantile, closed=True)
    if threshold is not None:
        check_number("threshold", threshold)
    F = _default_functions(F)
    R, _ = reconstruct(F, Phi, A, method=method)
    e = per_vertex_error(F, R)
    t = float(np.quantile(e, quantile)) if threshold is None else float(threshold)
    u = e > t
    return u, (1.0 - u.astype(np.float64)) ** 2, e


def potential_from_reconstruction(A, Phi, F, *, method: str = "manipulation"):
    """Hamiltonian potential from reconstruction error (§3.1.2): ``V_i = 1 − e_i / max e``.

    Badly reconstructed vertices get a small potential, well reconstructed ones a large
    one, so a large ``μ_V`` pushes the eigenfunctions onto the badly reconstructed area.
    Returns ``(n,)`` in ``[0, 1]`` (all ones if ``F`` is reconstructed exactly, i.e.
    ``max e ≤ 1e-12 max_i ‖F_i·‖``: round-off has no preferred area).
    """
    F = _default_functions(F)
    R, _ = reconstruct(F, Phi, A, method=method)
    e = per_vertex_error(F, R)
    m = float(e.max())
    scale = float(np.max(np.linalg.norm(F, axis=1)))
    return np.ones_like(e) if m <= 1e-12 * scale else 1.0 - e / m


def concatenate(Phi, Psi, A):
    """The concatenated basis ``X = [Φ Ψ]`` (§3.1.1) and its orthogonality failure ``‖ΦᵀAΨ‖_F`` (§4.3.1).

    Args: Phi ``(n, k)``, Psi ``(n, l)``, A ``(n, n)`` sparse.
    Returns: ``(X (n, k + l), err float)``.
    """
    Phi = np.asarray(Phi, dtype=np.float64)
    Psi = np.asarray(Psi, dtype=np.float64)
    if Phi.ndim != 2 or Psi.ndim != 2 or Phi.shape[0] != Psi.shape[0]:
        raise ValueError(f"Phi {Phi.shape} and Psi {Psi.shape} must be (n, k) and (n, l) with the same n")
    return np.hstack([Phi, Psi]), float(np.linalg.norm(Phi.T @ (A @ Psi)))
