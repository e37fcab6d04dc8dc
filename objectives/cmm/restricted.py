"""The support-restricted CMM problem (9.16) of the exact-support finish (docs/maths.md §9, eqs. 9.15–9.17).

``min tr(ΦᵀWΦ) + μ Σ_S w_i s_ij Φ_ij`` over ``ΦᵀAΦ = I`` with ``Φ_ij = 0`` off the support ``S`` and fixed signs
``s`` on it: value, Riemannian gradient and Hessian in the A-metric, tangent projection by the masked Gram map,
the restoration onto the constraint along the masked normal space (zeros stay exactly zero), the orthant-wise
retraction, the preconditioner, and truncated CG for the Newton system. Host code (numpy/scipy); used by
``objectives.cmm.support_finish``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from stiefel.linalg.sparse_factor import SymmetricFactor

from ..energy.l1_optimality import MaskedGram, l1_stationarity

__all__ = ["_Restricted", "_truncated_cg"]


class _Restricted:
    """Problem (9.16) on the support ``mask`` with signs ``signs``: value, gradient, Hessian, retraction, and the
    preconditioner: one sparse Cholesky factor of ``2(W + σA)`` for all columns and supports, applied as
    ``P(r) = proj(S∘K⁻¹(a∘(S∘r)))`` — a principal block of an SPD inverse, so SPD on every support. Measured
    against a factor of each column's support block (refactored as supports changed), same minima and
    residuals: example:bumpy 3.4 → 3.1 s, torus 1.4 → 0.8 s, patch 1.8 → 0.9 s (k = 10, μ = 0.01n), ManPG
    n = 1024 0.20 → 0.16 s — more CG iterations (508 → 811 on bumpy), each one k-column solve instead of k."""

    def __init__(self, W, a, w, mu, mask, signs, sigma):
        self.W, self.a, self.w, self.mu, self.sigma = sp.csr_matrix(W), a, w, mu, sigma
        self.products = 0
        self.factor = SymmetricFactor((2.0 * (self.W + sp.diags(sigma * a))).tocsc(), check=False)
        self.factorizations = 1
        self.set_support(mask, signs)

    def set_support(self, mask, signs):
        """A new support and sign pattern (no refactoring: the preconditioner does not depend on them)."""
        self.mask, self.signs = mask.copy(), signs * mask
        self.lin = self.mu * self.w[:, None] * self.signs  # μ w∘s on the support

    def violations(self, Phi, WPhi, margin: float):
        """Zero entries violating (9.9) (``|v_ij| > (1 + margin) μ w_i``, ``v = 2WΦ − AΦΛ*``), the
        ``A⁻¹``-norm of their excess and v. Λ* is the certifying multiplier of (9.10) (``l1_stationarity``),
        not the least-squares multiplier of the support equations: when two modes barely overlap the masked
        Gram map is nearly singular and that multiplier is huge (horse_976, k = 10, μ = 2λ: |Λ| 3.1e3 against
        191), so it saw ~370 false violators, added and dropped again every step (1.25·10⁵ of each in 300
        steps, max_iters at residual 2.9e-3; with Λ*: converged in 14 steps)."""
        stat = l1_stationarity(self.W, self.a, self.w, self.mu, Phi, WPhi=WPhi)
        v = 2.0 * WPhi - self.a[:, None] * (Phi @ stat.multiplier)
        t = self.mu * self.w[:, None]
        free = self.mask == 0
        excess = np.where(free, np.maximum(np.abs(v) - t, 0.0), 0.0)
        violate = free & (np.abs(v) > (1.0 + margin) * t)
        return violate, float(np.sqrt(np.sum(excess**2 / self.a[:, None]))), v

    def matvec(self, X):
        self.products += 1
        return np.asarray(self.W @ X)

    def value(self, Phi, WPhi):
        """The true objective (equal to (9.16) while the signs hold)."""
        return float(np.sum(Phi * WPhi) + self.mu * np.sum(self.w[:, None] * np.abs(Phi)))

    def point(self, Phi, WPhi):
        """Gram map at Φ, multiplier Λ and Riemannian gradient (eq. 9.17)."""
        gram = MaskedGram(Phi, self.a, self.mask)
        egrad = 2.0 * WPhi + self.lin
        lam = gram.solve(Phi.T @ (self.mask * egrad))
        grad = self.mask * (egrad / self.a[:, None] - Phi @ lam)
        return gram, lam, grad

    def project(self, gram, Phi, V):
        return V - self.mask * (Phi @ gram.solve(Phi.T @ (self.a[:, None] * V)))

    def hess(self, gram, Phi, lam, xi):
        return self.project(gram, Phi, self.mask * (2.0 * self.matvec(xi) / self.a[:, None] - xi @ lam))

    def precondition(self, gram, Phi, r):
        z = self.factor.solve(self.a[:, None] * (self.mask * r))
        return self.project(gram, Phi, self.mask * z)

    def inner(self, x, y):
        return float(np.sum(self.a[:, None] * x * y))

    def restore(self, Y, mask, max_iters: int = 60, tol: float = 1e-14, gram: MaskedGram | None = None):
        """Newton along the normal space: ``Z = Y + mask∘(YΛ)`` with ``ZᵀAZ = I``; None if it fails. ``gram``: a
        Gram map near Y (e.g. the base point's) used for chord steps while they contract fast."""
        k = Y.shape[1]
        Z, last = Y, np.inf
        for _ in range(max_iters):
            C = Z.T @ (self.a[:, None] * Z) - np.eye(k)
            err = float(np.max(np.abs(C)))
            if not np.isfinite(err) or err > 1e6:
                return None
            if err <= tol:
                return Z
            if gram is None or err > 0.5 * last:  # chord steps while they contract, else a fresh map
                gram = MaskedGram(Z, self.a, mask)
            last = err
            delta = gram.solve(-0.5 * C)
            Z = Z + mask * (Z @ delta)
        C = Z.T @ (self.a[:, None] * Z) - np.eye(k)
        return Z if float(np.max(np.abs(C))) <= 1e-12 else None

    def orthant_retract(self, Y, gram: MaskedGram | None = None):
        """Entries that left their sign's orthant set to 0 and dropped, then ``restore``; (Z, mask) or None."""
        mask = self.mask.copy()
        for _ in range(30):  # a restore can push a few small entries across zero: drop them too
            crossed = (mask > 0) & (Y * self.signs < 0)
            mask[crossed] = 0.0
            Z = self.restore(mask * Y, mask, gram=gram)
            if Z is None:
                return None
            if not np.any((mask > 0) & (Z * self.signs < 0)):
                return Z, mask
            Y = Z
        return None


def _truncated_cg(prob: _Restricted, gram, Phi, lam, grad, rtol: float, max_cg: int):
    """Preconditioned CG on ``Hess η = −grad`` in the tangent space (A-inner product); stops at
    negative curvature (returns the iterate so far, or the preconditioned gradient at the first step) and where the
    preconditioned residual is not positive (``−grad`` if at the start)."""
    r = -grad
    z = prob.precondition(gram, Phi, r)
    p, eta = z, np.zeros_like(grad)
    rz = prob.inner(r, z)
    r0 = np.sqrt(max(prob.inner(r, r), 0.0))
    if not rz > 0.0:  # the projected preconditioner lost definiteness (a singular Gram map): steepest descent
        return r, 0
    it = 0
    for it in range(1, max_cg + 1):
        Hp = prob.hess(gram, Phi, lam, p)
        curvature = prob.inner(p, Hp)
        if curvature <= 0.0 or not np.isfinite(curvature):
            if it == 1:
                eta = z
            break
        alpha = rz / curvature
        eta = eta + alpha * p
        r = r - alpha * Hp
        if np.sqrt(max(prob.inner(r, r), 0.0)) <= rtol * r0:
            break
        z = prob.precondition(gram, Phi, r)
        rz_new = prob.inner(r, z)
        if not rz_new > 0.0:  # (measured: ManPG n = 256, r = 10, μ = 0.1 from ADMM's modes — it divided by 0)
            break
        p = z + (rz_new / rz) * p
        rz = rz_new
    return eta, it
