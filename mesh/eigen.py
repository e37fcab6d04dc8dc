"""Laplacian eigenpairs ``Wφ = λAφ`` (thesis §2.5.2, eq. 2.5.34).

Shift-invert Lanczos (``scipy.sparse.linalg.eigsh``) around a slightly
negative shift ``σ = −1e-8·s`` (``s`` a spectral scale of ``A⁻¹W``), with one
sparse LU factorisation of ``W − σA``, which is non-singular even though ``W``
has a kernel (one constant per connected component). Works with a
non-diagonal (FEM) ``A``.

Performance note (measured on the shared 2-core machine): ARPACK's dense
work goes through OpenBLAS, whose worker threads contend with other processes;
``OPENBLAS_NUM_THREADS=1`` made ``eigenbasis`` 5–15× faster there (icosphere with
10 242 vertices, k = 50: 0.54 s vs 3.9–8.9 s). This module does not change
thread settings (a global side effect); set the variable before starting Python.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import reverse_cuthill_mckee
from jaxtyping import Float

from .laplacian import Laplacian

__all__ = ["Eigenbasis", "eigenbasis"]


class Eigenbasis(NamedTuple):
    """The first ``k`` eigenpairs; unpacks as ``evals, evecs = eigenbasis(lap, k)``.

    Attributes:
      evals: ``(k,)`` ascending eigenvalues ``λ_1 ≤ … ≤ λ_k`` (Rem. 2.5.29).
      evecs: ``(n, k)`` eigenvectors, ``ΦᵀAΦ = I`` (Prop. 2.5.28); each column's
        entry of largest magnitude is positive (a permutation-equivariant sign).
    """

    evals: Float[np.ndarray, " k"]
    evecs: Float[np.ndarray, "n k"]


def _shifted_inverse(M: sp.csc_matrix) -> spla.LinearOperator:
    """``x ↦ M⁻¹x`` for symmetric positive definite ``M`` (here ``W − σA``), factored once.

    The matrix is first renumbered by reverse Cuthill–McKee, then SuperLU orders
    it by minimum degree on ``Mᵀ+M`` with symmetric mode and diagonal pivots (an
    LDLᵀ in effect). Both matter: partial pivoting destroys the fill-reducing
    order (armadillo_25479: 19 s instead of 0.4 s), and the minimum-degree
    ordering is pathologically slow on some input orders (icosphere, 41k
    vertices: 74 s as given, 0.3 s after RCM).
    """
    n = M.shape[0]
    p = reverse_cuthill_mckee(sp.csr_matrix(M), symmetric_mode=True)
    lu = spla.splu(
        sp.csc_matrix(M[p][:, p]),
        permc_spec="MMD_AT_PLUS_A",
        diag_pivot_thresh=0.0,
        options={"SymmetricMode": True},
    )

    def solve(x: np.ndarray) -> np.ndarray:
        y = np.empty_like(x)
        y[p] = lu.solve(np.ascontiguousarray(x[p]))
        return y

    return spla.LinearOperator((n, n), matvec=solve, matmat=solve, dtype=np.float64)


def _spectral_scale(lap: Laplacian) -> float:
    """A scale of ``A⁻¹W``'s spectrum: ``max_i W_ii / A_ii`` (≥ λ_max/2 by Geršgorin, Prop. 2.5.21)."""
    a = lap.mass_diagonal
    w = lap.W.diagonal()
    return float(np.max(np.abs(w) / np.maximum(np.abs(a), np.finfo(float).tiny)))


def eigenbasis(
    lap: Laplacian,
    k: int,
    *,
    sigma: float | None = None,
    tol: float = 0.0,
    seed: int = 0,
) -> Eigenbasis:
    """The first ``k`` generalised eigenpairs of ``Wφ = λAφ``, A-orthonormal, ascending.

    Args:
      lap: the Laplacian (``W``, ``A`` of shape ``(n, n)``).
      k: number of eigenpairs, ``1 ≤ k < n``.
      sigma: shift (default ``−1e-8·s``, ``s`` a spectral scale).
      tol: ARPACK tolerance (0: machine precision).
      seed: seeds ARPACK's start vector (deterministic results).

    Returns:
      ``Eigenbasis(evals (k,), evecs (n, k))``.
    """
    n = lap.n
    if not 1 <= k < n:
        raise ValueError(f"k must satisfy 1 ≤ k < n = {n}, got k = {k}")
    W = sp.csc_matrix(lap.W, dtype=np.float64)
    A = sp.csc_matrix(lap.A, dtype=np.float64)
    if sigma is None:
        sigma = -1e-8 * _spectral_scale(lap)
    op_inv = _shifted_inverse(sp.csc_matrix(W - sigma * A))
    v0 = np.random.default_rng(seed).standard_normal(n)
    ncv = min(n, max(3 * k, 30))
    evals, evecs = spla.eigsh(
        W, k=k, M=A, sigma=sigma, which="LM", OPinv=op_inv, v0=v0, tol=tol, ncv=ncv
    )
    order = np.argsort(evals)
    evals, evecs = evals[order], evecs[:, order]
    # A-orthonormalise (ARPACK's vectors are A-orthogonal to working precision; this
    # makes it exact within repeated eigenvalues, e.g. the kernel of a multi-component mesh)
    gram = evecs.T @ (A @ evecs)
    gram = 0.5 * (gram + gram.T)
    C = sla.cholesky(gram, lower=False)
    evecs = sla.solve_triangular(C, evecs.T, trans="T", lower=False).T
    # deterministic, permutation-equivariant sign
    idx = np.argmax(np.abs(evecs), axis=0)
    signs = np.sign(evecs[idx, np.arange(k)])
    signs[signs == 0] = 1.0
    evecs = evecs * signs
    return Eigenbasis(evals=evals, evecs=evecs)
