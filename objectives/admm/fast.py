"""Fast approximation by restriction to local functions (thesis Chapter 7, Algorithms 7–8; docs/maths.md §6).

With a row-normalised local-function matrix ``U`` (n × d, sparse; from
``mesh.local_functions``) every function is sought as ``UX`` for ``X ∈ R^{d×k}``:

* Algorithm 7 — ``restricted_eigenbasis``: the generalised eigenproblem of
  ``(Q̄, M̄) = (UᵀQU, UᵀMU)`` (d × d), lifted ``Φ̄ = Uφ̄``. The lifts are exactly
  M-orthonormal (Lemma 7.1.2) and their energies ``φ̄ᵀQ̄φ̄`` equal the restricted
  eigenvalues (Lemma 7.1.3). ``Q`` may be sparse, or carry the GLMH low-rank term.
* Algorithm 8 — ``restricted_admm``: ADMM on the restricted CMM problem (7.3.5); ``variant="thesis"``
  runs it as printed (Frobenius penalties, A ≈ I/n, with the corrections of docs/maths.md note 4, see
  ``restricted_admm``); the default ``"exact"`` form measures the penalties in the A-norm:
  ``X, E ∈ R^{d×k}``, ``S, U^S ∈ R^{n×k}``, ``U^E ∈ R^{d×k}``.

  X-step: maximise ``tr(XᵀB)``, ``B = Ā(E − U^E) + UᵀA(S − U^S)``, over ``XᵀĀX = I``:
  ``X = Ā^{-1/2} polar(Ā^{-1/2} B) = Ā⁻¹B (BᵀĀ⁻¹B)^{-1/2}`` (the latter form: one sparse solve).
  E-step: ``(2W̄ + ρĀ) E = ρĀ(X + U^E)`` (d × d sparse, factored once per ρ).
  S-step: ``S = shrink(UX + U^S, μ w_i/(ρ a_i))``.
  Duals: ``U^E += X − E``, ``U^S += UX − S``. The final X is re-orthonormalised exactly.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from stiefel.errors import NotSPDError
from stiefel.linalg.sparse_factor import SymmetricFactor
from stiefel.validation import check_count, check_nonnegative

from .splitting import ADMMOptions, ADMMResult, _History, _true_objective, l1_weights_np, orthonormalize, soft_threshold
from .rho import RhoRule, StepClock, check_variant

__all__ = ["restricted_matrices", "restricted_eigenbasis", "restricted_admm"]


def _restricted_sparse(Q, M, U):
    """``(UᵀQU, UᵀMU)`` as sparse symmetric d × d csr arrays (each local function meets only its neighbours')."""
    U = sp.csr_array(U)
    Ut = U.T.tocsr()
    Qbar, Mbar = sp.csr_array(Ut @ sp.csr_array(Q @ U)), sp.csr_array(Ut @ sp.csr_array(M @ U))
    return sp.csr_array(0.5 * (Qbar + Qbar.T)), sp.csr_array(0.5 * (Mbar + Mbar.T))


def restricted_matrices(Q, M, U):
    """``(UᵀQU, UᵀMU)`` as dense symmetric d × d arrays (d ≪ n; for the dense eigensolver of Algorithm 7)."""
    Qbar, Mbar = _restricted_sparse(Q, M, U)
    return Qbar.toarray(), Mbar.toarray()


def restricted_eigenbasis(Q, M, U, k: int, *, low_rank=None):
    """Algorithm 7: the k smallest eigenpairs of ``(UᵀQU, UᵀMU)``, lifted by U.

    Args:
      Q: ``(n, n)`` sparse symmetric (e.g. W, or W + μ_V A V).
      M: ``(n, n)`` sparse SPD (e.g. A).
      U: ``(n, d)`` sparse local functions.
      k: number of eigenpairs (≤ d).
      low_rank: optional ``(B, c)`` adding ``c·BBᵀ`` to Q (``B = AΦ`` for the GLMH term
        ``μ_⊥ AΦΦᵀA``); restricted as ``c (UᵀB)(UᵀB)ᵀ`` without an n × n matrix.
    Returns:
      ``(evals (k,), lifted (n, k), coeffs (d, k))`` with ``liftedᵀ M lifted = I``.
    """
    Qbar, Mbar = restricted_matrices(Q, M, U)
    if low_rank is not None:
        B, c = low_rank
        UB = np.asarray(sp.csr_array(U).T @ B)
        Qbar = Qbar + c * (UB @ UB.T)
    d = Qbar.shape[0]
    check_count("k", k, 1, d, high_label=f"d = {d} (the number of local functions)")
    evals, coeffs = sla.eigh(Qbar, Mbar, subset_by_index=(0, k - 1))
    return evals, np.asarray(sp.csr_array(U) @ coeffs), coeffs


def _a_orthonormal_maximiser(B, Abar_factor):
    """``argmax tr(XᵀB)`` over ``XᵀĀX = I``: ``X = Ā⁻¹B (BᵀĀ⁻¹B)^{-1/2}`` (= ``Ā^{-1/2} polar(Ā^{-1/2}B)``).

    One sparse solve with the factored ``Ā`` and a k × k eigendecomposition; eigenvalues of
    ``BᵀĀ⁻¹B`` below 1e-14 of the largest are clipped (rank-deficient B).
    """
    Y = Abar_factor.solve(B).reshape(B.shape)
    vals, vecs = np.linalg.eigh(0.5 * (B.T @ Y + Y.T @ B))
    vals = np.maximum(vals, 1e-14 * max(vals.max(), 1e-300))
    return Y @ ((vecs / np.sqrt(vals)) @ vecs.T)


def _thesis_x_step(E, UE, S, US, Ut, G_factor, G, sqrt_n):
    """Algorithm 8's printed X-step (with docs/maths.md note 4): ``S̃ = (UᵀU)⁻¹Uᵀ(S − U^S)``,
    ``Z = E − U^E + S̃``, ``ṼD̃Ṽᵀ = ZᵀUᵀUZ``, ``X = √n Z Ṽ D̃^{-1/2} Ṽᵀ`` — the maximiser of the Frobenius
    penalties' ``tr(XᵀUᵀUZ)`` over ``(UX)ᵀ(rI)(UX) = I``, i.e. with ``Ā`` replaced by ``rUᵀU``, r = 1/n.
    Eigenvalues of ``ZᵀUᵀUZ`` below 1e-14 of the largest are clipped (rank-deficient Z)."""
    S_tilde = G_factor.solve(Ut @ (S - US)).reshape(E.shape)
    Z = E - UE + S_tilde
    vals, vecs = np.linalg.eigh(Z.T @ (G @ Z))
    vals = np.maximum(vals, 1e-14 * max(vals.max(), 1e-300))
    return sqrt_n * (Z @ ((vecs / np.sqrt(vals)) @ vecs.T))


def restricted_admm(W, area_diag, U, k: int, mu: float, *, weighting: str = "area", X0=None, seed: int = 0,
                    options: ADMMOptions = ADMMOptions(), monitor=None) -> ADMMResult:
    """Algorithm 8: ADMM for CMMs restricted to ``span(U)``; returns lifted modes ``Ψ = UX``.

    ``options.variant``:

    * ``"exact"`` (default): penalties in the A-norm; the restricted matrices ``W̄ = UᵀWU`` and ``Ā = UᵀAU``
      stay sparse (d × d): the X-step solves with ``Ā`` (factored once), the E-step with ``2W̄ + ρĀ``
      (once per ρ), both by ``stiefel.linalg.sparse_factor.SymmetricFactor``.
    * ``"thesis"``: Algorithm 8 as printed (with docs/maths.md note 4): Frobenius penalties on the
      lifted constraints ``UX = UE``, ``UX = S`` with ``A ≈ rI``, ``r = 1/n``; X-step ``_thesis_x_step``
      (solves with ``UᵀU``, factored once), E-step ``(2W̄ + ρUᵀU)E = ρUᵀU(X + U^E)``, S-step threshold
      ``μw_i/ρ`` (the printed ``μ/(ρn)`` for uniform weights; ``μA_ii/ρ`` as in Algorithm 3 for area
      weights), default ρ₀ divided by n (``objectives.admm.rho.default_rho``). Residuals in the Frobenius norm.

    Either way the final X is re-orthonormalised exactly in Ā, so ``ΨᵀAΨ = I``. The per-iteration objective
    is ``tr(XᵀW̄X) + μ Σ w_i|(UX)_ij|`` (``(UX)ᵀW(UX) = XᵀW̄X``), of X itself (not re-orthonormalised: the
    thesis variant's ``(UX)ᵀA(UX)`` is only ≈ I). The result's ``step_times`` hold the seconds of each step
    (thesis Table 7.2; ``psi`` is the X-step). ``monitor``: a ``stiefel.solvers.driver.HostMonitor`` (progress, stop
    checks); a stop or Ctrl-C ends the run with status ``"interrupted"`` and the current X.
    """
    W = sp.csr_array(W, dtype=np.float64)
    a = np.asarray(area_diag, dtype=np.float64)
    U = sp.csr_array(U, dtype=np.float64)
    n, d = U.shape
    check_count("k", k, 1, d, high_label=f"d = {d} (the number of local functions)")
    check_nonnegative("mu", mu)
    w = l1_weights_np(a, weighting)
    exact = check_variant(options.variant) == "exact"
    Wbar, Abar = _restricted_sparse(W, sp.diags_array(a), U)
    try:
        Abar_factor = SymmetricFactor(Abar)
    except NotSPDError as exc:
        raise ValueError("UᵀAU is singular: the local functions are linearly dependent") from exc
    Ut = U.T.tocsr()
    if exact:  # penalty metrics: Ā on the d-side, A on the n-side
        ME, ms, ME_factor = Abar, a, Abar_factor
    else:  # Frobenius on the lifted constraints: UᵀU on the d-side, I on the n-side
        G = sp.csr_array(Ut @ U)
        ME, ms = sp.csr_array(0.5 * (G + G.T)), np.ones(n)
        try:
            ME_factor = SymmetricFactor(ME)
        except NotSPDError as exc:
            raise ValueError("UᵀU is singular: the local functions are linearly dependent") from exc
    ms_col = ms[:, None]
    thresh = mu * (w / ms)[:, None]
    sqrt_n = np.sqrt(n)

    def objective(X, UX):
        return float(np.sum(X * (Wbar @ X)) + mu * np.sum(w[:, None] * np.abs(UX)))

    if X0 is None:
        X0 = np.random.default_rng(seed).standard_normal((d, k))
    X = orthonormalize(np.asarray(X0, dtype=np.float64), Abar)
    if not exact:
        X = sqrt_n * orthonormalize(X, ME)  # (UX)ᵀ(UX) = nI: the printed iteration's scale
    E = X.copy()
    S = U @ X
    UE = np.zeros_like(X)
    US = np.zeros_like(S)
    rho = rho0 = options.initial_rho(mu, n)
    factors: dict = {}
    status = "max_iters"
    rule = RhoRule(options, n)
    clock = StepClock()
    x_scale = np.sqrt(k) if exact else np.sqrt(n * k)  # ‖UX‖ in the penalty norm
    t0 = time.perf_counter()
    hist = _History(t0)
    it = 0
    try:
        for it in range(1, options.max_iters + 1):
            clock.mark()
            if exact:
                X = _a_orthonormal_maximiser(Abar @ (E - UE) + Ut @ (a[:, None] * (S - US)), Abar_factor)
            else:
                X = _thesis_x_step(E, UE, S, US, Ut, ME_factor, ME, sqrt_n)
            clock.lap("psi")
            E_old, S_old = E, S
            if rho not in factors:
                factors[rho] = SymmetricFactor(2.0 * Wbar + rho * ME)
            E = factors[rho].solve(rho * (ME @ (X + UE))).reshape(X.shape)
            clock.lap("E")
            UX = U @ X
            S = soft_threshold(UX + US, thresh / rho)
            clock.lap("S")
            UE += X - E
            US += UX - S
            clock.lap("dual")
            XE = X - E
            primal = np.sqrt(np.sum(XE * (ME @ XE)) + np.sum(ms_col * (UX - S) ** 2))
            dE = E - E_old
            dual = rho * np.sqrt(np.sum(dE * (ME @ dE)) + np.sum(ms_col * (S - S_old) ** 2))
            primal_scale = max(np.sqrt(2.0) * x_scale, np.sqrt(np.sum(E * (ME @ E)) + np.sum(ms_col * S**2)))
            dual_scale = rho * np.sqrt(np.sum(UE * (ME @ UE)) + np.sum(ms_col * US**2))
            tol = np.sqrt(n * k) * options.eps_abs + options.eps_rel * x_scale
            converged = primal <= tol and dual <= tol + options.eps_rel * rho * np.sqrt(np.sum(ms_col * US**2))
            clock.lap("residual")
            obj = objective(X, UX)
            elapsed = hist.record(objective=obj, primal=primal, dual=dual, rho=rho)
            clock.lap("objective")
            if converged:
                status = "converged"
                break
            if elapsed > options.time_limit:
                status = "time_limit"
                break
            if monitor is not None and monitor.tick(it, obj, primal, error_result=X):
                status = "interrupted"
                break
            clock.mark()
            rho = rule.apply(it, primal, dual, rho, UE, US, primal_scale=primal_scale, dual_scale=dual_scale,
                                  primal_tol=tol)
            clock.lap("dual")
    except KeyboardInterrupt:  # Ctrl-C: the current iterate, status interrupted
        status = "interrupted"
    X = orthonormalize(X, Abar)
    Psi = U @ X
    return ADMMResult(
        Psi=Psi, objective=_true_objective(W, w, mu, Psi), iterations=it, status=status,
        history=hist.arrays(), wall_time=time.perf_counter() - t0,
        factor_time=0.0, n_factorizations=len(factors), rho0=rho0, step_times=clock.totals,
    )
