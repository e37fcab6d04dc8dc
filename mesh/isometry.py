"""Discrete isometry (thesis Def. 3.4.8).

Meshes ``P`` and ``N`` with Laplacians ``(W_P, A_P)``, ``(W_N, A_N)`` are
isometric under the vertex bijection ``Π`` (``Π_{i, perm[i]} = 1``) when
``A_N = Π A_P Πᵀ`` and ``W_N = Π W_P Πᵀ``. Then ``(Πφ, λ)`` are eigenpairs of
``L_N`` for each eigenpair ``(φ, λ)`` of ``L_P`` (Prop. 3.4.12).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from jaxtyping import Int

from .laplacian import Laplacian
from .ordering import _check_perm

__all__ = ["isometry_defect", "is_isometric"]


def _conjugate(M: sp.csr_array, perm: np.ndarray) -> sp.csr_array:
    """``Π M Πᵀ`` = ``M[perm][:, perm]``."""
    return sp.csr_array(sp.csr_array(M)[perm][:, perm])


def isometry_defect(lap_P: Laplacian, lap_N: Laplacian, perm: Int[np.ndarray, " n"]) -> tuple[float, float]:
    """``(max|A_N − Π A_P Πᵀ|, max|W_N − Π W_P Πᵀ|)`` for the bijection ``perm`` (Def. 3.4.8)."""
    if lap_P.n != lap_N.n:
        return float("inf"), float("inf")
    perm = _check_perm(perm, lap_P.n)

    def dev(X, Y):
        D = sp.csr_array(X - Y)
        return float(np.max(np.abs(D.data))) if D.nnz else 0.0

    return dev(lap_N.A, _conjugate(lap_P.A, perm)), dev(lap_N.W, _conjugate(lap_P.W, perm))


def is_isometric(
    lap_P: Laplacian, lap_N: Laplacian, perm: Int[np.ndarray, " n"], atol: float = 1e-12
) -> bool:
    """Whether ``perm`` is a discrete isometry ``P → N`` (Def. 3.4.8), entrywise to ``atol``.

    ``atol`` is relative to ``max|W_P|`` for ``W`` and ``max|A_P|`` for ``A``.
    """
    if lap_P.n != lap_N.n:
        return False
    dA, dW = isometry_defect(lap_P, lap_N, perm)
    sA = float(np.max(np.abs(lap_P.A.data))) if lap_P.A.nnz else 1.0
    sW = float(np.max(np.abs(lap_P.W.data))) if lap_P.W.nnz else 1.0
    return dA <= atol * sA and dW <= atol * sW
