"""A CMM problem padded to bucket sizes (``stiefel.runtime.buckets``), so meshes of similar size share one
compiled block solver.

The padded problem appends ``size − n`` rows to everything: zero rows and columns of ``W``, mass
``a = 1``, ℓ1 weight 0, zero rows of the start. The padded rows then stay exactly zero at every
iterate — their gradient is ``2(WX)_i + μ w_i s'(X_ij) = 0``, the preconditioner ``(W + σA)⁻¹``
maps zero rows to zero rows, the Cholesky retraction ``(X + τη)L⁻ᵀ`` keeps them zero — and they add
nothing to ``XᵀAX``, ``tr(XᵀWX)`` or the ℓ1 term: the real rows follow the unpadded iteration
(up to the rounding of longer sums).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.sparse as sp

from stiefel.runtime.buckets import bucket, width_bucket

__all__ = ["PaddedProblem"]


def _density_bucket(density: float) -> float:
    """Stored factor entries per row rounded up to the grid ``0.25 + 0.5 m`` (a triangle mesh has about
    4 — 1 + E/V — so meshes with and without boundary, of any genus, land on 4.25). The extra entries
    are ignored by CHOLMOD and cost a pass over the arrays only, so the factor's size follows the row
    bucket instead of adding a third size that two similar meshes must share."""
    return 0.25 + 0.5 * math.ceil((density - 0.25) / 0.5)


@dataclasses.dataclass(frozen=True)
class PaddedProblem:
    """``W (n, n)`` and ``a (n,)`` padded to ``size`` rows; ``width`` (neighbour-table width) rounded up
    to its bucket and ``factor_size`` (stored upper-triangle entries of ``W + σA``) to ``size`` times
    a bucketed number of entries per row."""

    n: int
    size: int
    width: int
    factor_size: int
    W: sp.csr_array
    a: np.ndarray

    @classmethod
    def build(cls, W, a, growth: float | None) -> "PaddedProblem":
        """Pad ``(W, a)``; ``growth=None``: no padding (exact shapes)."""
        csr = sp.csr_array(W, dtype=np.float64)
        n = csr.shape[0]
        pattern = abs(csr) + sp.eye_array(n, format="csr")  # the pattern of W + σA (diagonal included)
        pattern.sum_duplicates()
        lengths = np.diff(pattern.indptr)
        size = bucket(n, growth)
        width = width_bucket(max(int(lengths.max(initial=0)), 1), growth)
        upper = int(sp.triu(pattern).nnz) + (size - n)  # the padded rows' diagonal entries
        factor_size = upper if growth is None else int(math.ceil(size * _density_bucket(upper / size)))
        a = np.asarray(a, dtype=np.float64)
        if size > n:
            csr = sp.block_diag((csr, sp.csr_array((size - n, size - n))), format="csr")
            a = np.concatenate([a, np.ones(size - n)])
        return cls(n=n, size=size, width=width, factor_size=factor_size, W=csr, a=a)

    def pad(self, X: np.ndarray) -> np.ndarray:
        """``X (n, ...)`` with ``size − n`` zero rows appended."""
        X = np.asarray(X)
        if self.size == self.n:
            return X
        return np.concatenate([X, np.zeros((self.size - self.n,) + X.shape[1:], X.dtype)])

    def unpad(self, X) -> np.ndarray:
        """The first ``n`` rows of ``X``."""
        return np.asarray(X)[: self.n]
