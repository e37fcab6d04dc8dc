"""Active-set preconditioner for the smoothed CMM energy (block solver).

The smoothed energy ``F(X) = tr(XᵀWX) + μ Σ_ij w_i s(X_ij)`` has Euclidean Hessian
``2W + μ diag(w ∘ s''(X_:j))`` per column. For the Huber smoothing (f6) ``s''`` is
``1/δ`` on the flat zone ``|x| < δ`` and 0 outside, and ``μw_i/δ`` dwarfs the
entries of ``W``; the shifted preconditioner ``(W + σA)⁻¹`` ignores it, which is
why the block solver needed hundreds of iterations where the modes are sparse.

Per column j this module uses instead (docs/maths.md §4 notation)

    P_j = (W + σA + diag(c ∘ 1[pinned_j]))⁻¹,   c_i = μ w_i / (2δ),

where an entry is *pinned* when it sits in the flat zone and satisfies the
subgradient condition of the non-smooth problem there,
``|(2WX − AXΛ)_ij| ≤ μ w_i`` with ``Λ = sym(XᵀG)`` (G the smoothed gradient):
an entry whose smooth-part residual exceeds the ℓ1 bound wants to leave zero and
is left free (pinning those stalled the support in tests). Because ``c_i`` is
orders of magnitude above the rest of its row, ``P_j`` is applied as its block
diagonal: the restriction of ``W + σA`` to the free rows (factored once per
refresh, ``stiefel.linalg.sparse_factor.SymmetricFactor``) and ``1/(K_ii + c_i)`` on
the pinned rows — so each application also gets cheaper as the modes get sparser.

The pinned sets move as X does, so the solver runs in rounds of ``refresh``
iterations with the factors rebuilt between rounds (``objectives.cmm.modes``); the
preconditioner is SPD in every round, so each round is a valid preconditioned
Riemannian CG run. For smoothings other than f6 the flat-zone width and
curvature are taken as ``min(ε, δ)`` and ``1/min(ε, δ)``.
"""

from __future__ import annotations

import time

import jax
import numpy as np
import scipy.sparse as sp
from jaxtyping import Array, Float

from stiefel.linalg.sparse_factor import SymmetricFactor, ldl_backend

__all__ = ["ActiveSetPreconditioner"]


class ActiveSetPreconditioner:
    """Host-side per-column preconditioner ``P_j`` (module docstring), refreshed between solver rounds.

    Args:
      W: ``(n, n)`` scipy-sparse stiffness; a: ``(n,)`` lumped areas; sigma: shift σ > 0.
      mu: μ; weights: ``(n,)`` ℓ1 row weights w; width: flat-zone width δ.

    ``refresh(X)`` recomputes the pinned sets and factors; ``apply`` is the jittable
    ``Y ↦ [P_j Y_j]_j`` for the block solver (a host callback; the same object for
    every round, so the solver compiles once).
    """

    def __init__(self, W, a: np.ndarray, sigma: float, mu: float, weights: np.ndarray, width: float):
        self.W = sp.csr_matrix(W, dtype=np.float64)
        self.a = np.asarray(a, dtype=np.float64)
        self.K = sp.csr_matrix(self.W + sp.diags(sigma * self.a))
        self.K_diag = self.K.diagonal()
        self.mu, self.width = float(mu), float(width)
        self.w = np.asarray(weights, dtype=np.float64)
        self.c = self.mu * self.w / (2.0 * self.width)
        self.columns: list = []
        self._cache: dict = {}
        # k factorisations per refresh, one right-hand side each: the LDLᵀ backend factors ~2×
        # faster than CHOLMOD, which only wins on multi-column solves (stiefel.linalg.sparse_factor)
        self._backend = ldl_backend()
        self.factor_time = 0.0
        self.pinned_fraction = 0.0

    def pinned(self, X: Float[np.ndarray, "n k"]) -> np.ndarray:
        """Boolean ``(n, k)`` mask of pinned entries at ``X`` (module docstring)."""
        WX2 = 2.0 * (self.W @ X)
        bound = self.mu * self.w[:, None]
        G = WX2 + bound * np.clip(X / self.width, -1.0, 1.0)
        Lam = 0.5 * (X.T @ G + G.T @ X)
        Rs = WX2 - self.a[:, None] * (X @ Lam)
        return (np.abs(X) < self.width) & (np.abs(Rs) <= bound)

    def set_width(self, width: float) -> None:
        """A new flat-zone width δ (a continuation stage); takes effect at the next ``refresh``.
        The same object (and so the same compiled solver) serves every stage."""
        self.width = float(width)
        self.c = self.mu * self.w / (2.0 * self.width)

    def refresh(self, X) -> None:
        """Rebuild the pinned sets and the per-column factors at ``X`` (``(n, k)``)."""
        t0 = time.perf_counter()
        X = np.asarray(X, dtype=np.float64)
        mask = self.pinned(X)
        cache, columns = {}, []
        for j in range(X.shape[1]):
            free = np.flatnonzero(~mask[:, j])
            key = hash(free.tobytes())
            entry = self._cache.get(key) or cache.get(key)
            if entry is None or not np.array_equal(entry[0], free):
                factor = SymmetricFactor(self.K[free][:, free], check=False, backend=self._backend) if free.size else None
                entry = (free, factor)
            cache[key] = entry
            columns.append(entry)
        self._cache, self.columns = cache, columns
        self.pinned_fraction = float(mask.mean())
        self.diag_inv = 1.0 / (self.K_diag + self.c)
        self.factor_time += time.perf_counter() - t0

    def __call__(self, Y: np.ndarray) -> np.ndarray:
        Y = np.asarray(Y, dtype=np.float64)
        out = Y * self.diag_inv[:, None]
        for j, (free, factor) in enumerate(self.columns):
            if factor is not None:
                out[free, j] = factor.solve(Y[free, j])
        return out

    def apply(self, Y: Float[Array, "n k"]) -> Float[Array, "n k"]:
        """``[P_j Y_j]_j`` inside jit (a ``pure_callback``); ``Y`` has the solver's k columns."""
        shape = jax.ShapeDtypeStruct(Y.shape, Y.dtype)
        return jax.pure_callback(lambda y: self(y).astype(y.dtype), shape, Y, vmap_method="sequential")
