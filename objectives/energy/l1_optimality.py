"""Exact (non-smoothed) ℓ1 optimality of compressed modes (docs/maths.md §9, eqs. (9.9), (9.10), (9.15)).

The CMM problem ``min tr(ΦᵀWΦ) + μ Σ_ij w_i |Φ_ij|`` over ``ΦᵀAΦ = I`` (A diagonal, ``a = diag A``)
is stationary at Φ iff there are a symmetric ``Λ (k, k)`` and ``Z (n, k)`` with ``Z_ij = sign Φ_ij``
where ``Φ_ij ≠ 0`` and ``|Z_ij| ≤ 1`` where ``Φ_ij = 0`` such that

    2WΦ + μ w∘Z = AΦΛ                                                            (9.9)

(``P_Φ(A⁻¹(2WΦ + μ w∘Z)) = 0``: the normal space at Φ is ``{ΦΛ : Λ = Λᵀ}``). The residual

    res(Φ) = min_{Λ, Z admissible} ‖2WΦ + μ w∘Z − AΦΛ‖_{A⁻¹}                    (9.10)

is the A-norm of the smallest projected subgradient. For fixed Λ the best Z is entrywise (the sign on
the support, a clipped value off it), so ``res² = min_Λ Σ_ij q_ij(Λ)²/a_i`` with
``q = v + μ w∘sign Φ`` on the support and ``q = shrink(v, μ w)`` off it, ``v = 2WΦ − AΦΛ``: a convex,
piecewise quadratic function of the ``k(k+1)/2`` entries of Λ, minimised here by a semismooth Newton
method whose generalised Hessian is the masked Gram map

    L_D(Λ) = sym(Φᵀ(D∘(AΦΛ)))      (D: the entries where q depends on Λ)          (9.15)

— the same map that projects onto the tangent space of a support-restricted Stiefel manifold
(``objectives.cmm.support_finish``). Everything here runs on the host (numpy/scipy).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from jaxtyping import Float

__all__ = ["L1Stationarity", "l1_stationarity", "MaskedGram", "support_stats", "DENSE_MAX_ENTRIES"]


#: the semismooth Newton step of ``l1_stationarity`` falls back to Levenberg–Marquardt when it fails: shifts of
#: ``LM_START`` × the map's largest diagonal, × 100 per retry, at most ``LM_TRIES`` solves in all (measured on
#: example:starfish, k = 10, μ = 2λ, at the finish's last iterate: the plain step was 2.4e24 and the method stopped
#: at a residual of 5.5e-2 with ∂φ/∂Λ = 4.9e-3, i.e. not at the minimum over Λ)
LM_START, LM_TRIES = 1e-6, 6
#: ``l1_stationarity`` stops on a stalled decrease only where ``‖sym(Φᵀq)‖_F ≤ GRAD_TOL · √k ‖q‖_{A⁻¹}``
GRAD_TOL = 1e-9

#: above this many multiplier entries k(k+1)/2 the map is solved matrix-free by CG (the dense inverse costs
#: O(k⁶) time and O(k⁴) memory: minutes and gigabytes at k = 150)
DENSE_MAX_ENTRIES = 1000


class MaskedGram:
    """The map ``L_D(Λ) = sym(Φᵀ(D∘(a ⊙ ΦΛ)))`` on symmetric ``(k, k)`` matrices (eq. 9.15), inverted.

    Phi: ``(n, k)``; a: ``(n,)`` the diagonal of A; D: ``(n, k)`` 0/1 mask (None: all ones).
    ``solve(R)`` returns the symmetric Λ with ``L_D(Λ) = sym(R)``; ``apply(Λ)`` the map itself. The map is
    self-adjoint and positive semi-definite in ``⟨Γ, Λ⟩ = tr(ΓΛ)`` (``⟨Γ, L_D(Λ)⟩ = Σ_ij a_i D_ij (ΦΓ)_ij (ΦΛ)_ij``);
    a pair of columns with disjoint masked supports has an identically zero row and column (its constraint
    holds for every Λ): the rest is inverted and that multiplier entry is 0. Small k (``k(k+1)/2 ≤
    DENSE_MAX_ENTRIES``): the dense matrix on the upper entries, built from ``T[b] = Φᵀ diag(a∘D_b) Φ``
    (O(nk³)) and inverted (pseudo-inverse if singular); larger k: Jacobi-preconditioned CG, O(nk²) a step.
    """

    def __init__(self, Phi: Float[np.ndarray, "n k"], a: Float[np.ndarray, " n"], D=None):
        n, k = Phi.shape
        self.k, self.Phi = k, Phi
        self.weights = a[:, None] * (np.ones((n, k)) if D is None else D)  # (n, k): column b's weights a∘D_b
        self.iu = np.triu_indices(k)
        m = len(self.iu[0])
        C = (Phi * Phi).T @ self.weights  # C[b, a] = Σ_i Φ_ib² a_i D_ia
        # the diagonal of the map in the Frobenius-orthonormal basis of symmetric matrices
        self.diagonal = 0.5 * (C + C.T)
        scale = max(float(np.max(np.abs(self.diagonal))), 1e-300)
        self.live = np.abs(self.diagonal) > 1e-14 * scale
        self.singular, self.cg_iterations = False, 0
        self.dense = m <= DENSE_MAX_ENTRIES
        if self.dense:
            self._dense_inverse(m)

    def _dense_inverse(self, m: int) -> None:
        k, Phi, weights = self.k, self.Phi, self.weights
        T = np.stack([Phi.T @ (weights[:, b:b + 1] * Phi) for b in range(k)])  # T[b] (k, k)
        basis = np.zeros((m, k, k))
        basis[np.arange(m), self.iu[0], self.iu[1]] = 1.0
        basis[np.arange(m), self.iu[1], self.iu[0]] = 1.0
        # L_D(B)_{ab} = ½ (Σ_c T[b]_{ac} B_{cb} + Σ_c T[a]_{bc} B_{ca})
        half = np.einsum("bac,rcb->rab", T, basis)
        images = 0.5 * (half + np.transpose(half, (0, 2, 1)))
        self.matrix = images[:, self.iu[0], self.iu[1]].T  # (m, m): columns are the images of the basis
        live = self.live[self.iu]
        self._inverse = np.zeros_like(self.matrix)
        block = self.matrix[np.ix_(live, live)]
        try:
            inverse = np.linalg.inv(block)
            self.singular = not np.all(np.isfinite(inverse))
        except np.linalg.LinAlgError:
            self.singular = True
        if self.singular:  # a column without support, or a rank-deficient one: least squares
            inverse = np.linalg.pinv(block)
        self._inverse[np.ix_(live, live)] = inverse

    def _to_matrix(self, vec: np.ndarray) -> np.ndarray:
        L = np.zeros((self.k, self.k))
        L[self.iu] = vec
        L[(self.iu[1], self.iu[0])] = vec
        return L

    def _map(self, Lam: np.ndarray) -> np.ndarray:
        Z = self.Phi.T @ (self.weights * (self.Phi @ Lam))
        return 0.5 * (Z + Z.T)

    def solve(self, R: Float[np.ndarray, "k k"], *, shift: float = 0.0, rtol: float = 1e-14, max_iters: int = 1000
              ) -> Float[np.ndarray, "k k"]:
        """Symmetric Λ with ``L_D(Λ) + shift·Λ = sym(R)`` on the live entries (the others 0); ``shift > 0``
        (Levenberg–Marquardt) makes the map positive definite however ill-conditioned ``L_D`` is."""
        S = 0.5 * (R + R.T)
        if self.dense and shift > 0.0:
            live = self.live[self.iu]
            x = np.zeros(len(live))
            x[live] = np.linalg.solve(self.matrix[np.ix_(live, live)] + shift * np.eye(int(live.sum())), S[self.iu][live])
            return self._to_matrix(x)
        if self.dense:
            return self._to_matrix(self._inverse @ S[self.iu])
        live = self.live
        b = np.where(live, S, 0.0)
        inv_diag = np.where(live, 1.0 / np.where(live, self.diagonal + shift, 1.0), 0.0)
        X = b * inv_diag
        r = b - np.where(live, self._map(X) + shift * X, 0.0)
        z = r * inv_diag
        p, rz = z, float(np.sum(r * z))
        target = rtol * max(float(np.linalg.norm(b)), 1e-300)
        for it in range(1, max_iters + 1):
            if np.linalg.norm(r) <= target or rz <= 0.0:
                break
            Ap = np.where(live, self._map(p) + shift * p, 0.0)
            pAp = float(np.sum(p * Ap))
            if pAp <= 0.0:
                break
            alpha = rz / pAp
            X, r = X + alpha * p, r - alpha * Ap
            z = r * inv_diag
            rz_new = float(np.sum(r * z))
            p, rz = z + (rz_new / rz) * p, rz_new
            self.cg_iterations += 1
        return X

    def apply(self, Lam: Float[np.ndarray, "k k"]) -> Float[np.ndarray, "k k"]:
        """``L_D(Λ)`` for symmetric Λ."""
        if self.dense:
            return self._to_matrix(self.matrix @ Lam[self.iu])
        return self._map(Lam)


@dataclasses.dataclass(frozen=True)
class L1Stationarity:
    """The exact ℓ1 stationarity residual (eq. 9.10) of a basis Φ.

    residual: ``min ‖2WΦ + μ w∘Z − AΦΛ‖_{A⁻¹}``; relative: residual / scale with
    ``scale = ‖2WΦ‖_{A⁻¹} + μ‖w ⊗ 1_k‖_{A⁻¹}`` (the size of the two parts of a subgradient);
    multiplier: the minimising Λ ``(k, k)``; violations: entries with ``Φ_ij = 0`` whose
    ``|v_ij| = |(2WΦ − AΦΛ)_ij|`` exceeds ``μ w_i`` (they would lower the objective if freed);
    exact_zeros: the fraction of entries exactly 0; iterations: semismooth Newton steps.
    """

    residual: float
    relative: float
    multiplier: np.ndarray
    violations: int
    exact_zeros: float
    iterations: int


def _q(v: np.ndarray, zero: np.ndarray, signs: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The residual entries: ``v + t·sign`` on the support, ``shrink(v, t)`` off it (t = μ w, (n, 1))."""
    shrunk = np.sign(v) * np.maximum(np.abs(v) - t, 0.0)
    return np.where(zero, shrunk, v + t * signs)


def l1_stationarity(W, a: Float[np.ndarray, " n"], w: Float[np.ndarray, " n"], mu: float,
                    Phi: Float[np.ndarray, "n k"], *, WPhi=None, tol: float = 1e-14,
                    max_iters: int = 50) -> L1Stationarity:
    """The exact ℓ1 stationarity residual (eq. 9.10) of Φ for ``tr(ΦᵀWΦ) + μ Σ w_i|Φ_ij|`` on ``ΦᵀAΦ = I``.

    W: ``(n, n)`` sparse symmetric; a: ``(n,)`` diag A; w: ``(n,)`` ℓ1 weights; Phi: ``(n, k)``, A-orthonormal.
    ``WPhi``: ``W @ Phi`` if already known. Semismooth Newton on Λ with backtracking, from the
    least-squares multiplier of the support equations; stops when the decrease stalls (``tol``).
    Entries that are exactly zero get the box ``|Z| ≤ 1``; every other entry its sign — a smoothed
    solver's tiny entries therefore count in full (report this residual only for exact-zero methods).
    """
    Phi = np.asarray(Phi, dtype=np.float64)
    a = np.asarray(a, dtype=np.float64)
    G = 2.0 * np.asarray(W @ Phi if WPhi is None else WPhi, dtype=np.float64)
    zero = Phi == 0.0
    signs = np.sign(Phi)
    t = mu * np.asarray(w, dtype=np.float64)[:, None]
    inv_a = 1.0 / a[:, None]

    def value(Lam):
        q = _q(G - a[:, None] * (Phi @ Lam), zero, signs, t)
        return 0.5 * float(np.sum(q * q * inv_a)), q

    # start: the multiplier of the support equations (Z = sign on the support, 0 off it)
    Lam = MaskedGram(Phi, a).solve(Phi.T @ (G + t * signs))
    phi, q = value(Lam)
    it = 0
    for it in range(1, max_iters + 1):
        v = G - a[:, None] * (Phi @ Lam)
        active = (~zero) | (np.abs(v) > t)
        grad = Phi.T @ q  # −∂φ/∂Λ, symmetrised inside solve
        if not np.any(grad + grad.T):  # ∇φ = 0: the minimum (no step, shifted or not, can descend)
            break
        gram = MaskedGram(Phi, a, active.astype(np.float64))
        shift, accepted = 0.0, False
        for _ in range(LM_TRIES):
            step = gram.solve(grad, shift=shift)
            slope = float(np.sum(0.5 * (grad + grad.T) * step))
            if np.isfinite(slope) and slope > 0.0:
                s = 1.0
                for _ in range(40):
                    trial, q_trial = value(Lam + s * step)
                    if trial <= phi - 1e-4 * s * slope:
                        accepted = True
                        break
                    s *= 0.5
            if accepted:
                break
            # the generalised Hessian is too ill-conditioned for its step (two modes whose active entries barely
            # overlap): Levenberg–Marquardt, the shift growing from a millionth of the map's largest diagonal
            shift = LM_START * max(float(np.max(gram.diagonal)), 1e-300) if shift == 0.0 else 100.0 * shift
        if not accepted:
            break
        decrease = phi - trial
        Lam, phi, q = Lam + s * step, trial, q_trial
        if phi == 0.0 or decrease <= 0.0:
            # no measurable decrease (the Armijo test passed only by rounding): φ is at its round-off, and the
            # gradient test below cannot pass either — ∂φ/∂Λ carries the round-off of v = 2WΦ − AΦΛ, ~ε·scale, which
            # exceeds GRAD_TOL·residual once the residual is below ~1e-7 of the scale (measured: fandisk, k = 10,
            # μ = 2λ, the finish's last iterates at residuals 1.2e-9 and 4.5e-14: 50 iterations each, 22
            # backtracks per iteration at the second, 3.6 of the finish's 8.5 s)
            break
        if decrease <= tol * max(phi, 1e-300):
            # a step can cross a kink of φ and gain next to nothing with the minimum still away (measured: 3e-4
            # above the minimum, relative): stop only once ∂φ/∂Λ = −sym(Φᵀq) is small too (Cauchy–Schwarz bounds
            # |⟨Γ, Φᵀq⟩| by ‖ΦΓ‖_A ‖q‖_{A⁻¹}, so the relative size is ≤ 1 for A-orthonormal Φ)
            g = Phi.T @ q
            if np.linalg.norm(0.5 * (g + g.T)) <= GRAD_TOL * np.sqrt(2.0 * phi * Phi.shape[1]):
                break
    residual = float(np.sqrt(2.0 * phi))
    scale = float(np.sqrt(np.sum(G * G * inv_a)) + np.sqrt(np.sum(t * t * inv_a) * Phi.shape[1]))
    v = G - a[:, None] * (Phi @ Lam)
    violations = int(np.sum(zero & (np.abs(v) > t * (1 + 1e-9))))
    return L1Stationarity(residual=residual, relative=residual / scale if scale > 0 else residual,
                          multiplier=Lam, violations=violations, exact_zeros=float(np.mean(zero)), iterations=it)


def support_stats(Phi: Float[np.ndarray, "n k"], a: Float[np.ndarray, " n"] | None = None) -> dict:
    """Exact sparsity of a basis: ``exact_zeros`` (fraction of entries == 0), ``support_sizes`` (nonzeros
    per column) and, with areas ``a``, ``support_areas`` (the area of each column's support / total area)."""
    nonzero = np.asarray(Phi) != 0.0
    out = {"exact_zeros": float(1.0 - np.mean(nonzero)), "support_sizes": [int(c) for c in nonzero.sum(axis=0)]}
    if a is not None:
        a = np.asarray(a, dtype=np.float64)
        out["support_areas"] = [float(x) for x in (a @ nonzero) / a.sum()]
    return out
