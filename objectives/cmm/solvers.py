"""One immutable solver object per CMM method (thesis §3.2, §6.5, Ch. 7; docs/maths.md §4–6).

``compressed_modes(lap, k, mu, solver=...)`` (``objectives.cmm.modes``) minimises
``tr(ΨᵀWΨ) + μ Σ_ij w_i |Ψ_ij|`` over ``ΨᵀAΨ = I`` with one of:

* ``BlockCMM`` — the smoothed energy over the whole ``(n, k)`` block with Riemannian CG or
  L-BFGS (``stiefel.minimize``), preconditioned by ``(W + σA)⁻¹`` or the active-set
  preconditioner (``objectives.cmm.active_set``), with continuation on ε, δ;
* ``SequentialCMM`` — thesis Algorithm 6 (``stiefel.minimize_sequential``), column by column;
* ``ADMMCMM`` — the ADMM baseline, Algorithm 3 (``objectives.admm.splitting``), ``variant="exact"``
  (A-norm penalties) or ``"thesis"`` (Frobenius penalties, eq. 3.2.24);
* ``SequentialADMMCMM`` — ADMM one mode at a time (§3.2.2, exact form only);
* ``FastCMM`` — Algorithm 8 on ``span(U)`` (``objectives.admm.fast``), from Algorithm 7's basis.

Each is a frozen dataclass holding only its own options, checked on construction
(``SolverOptionError``), and compared/hashed by value (``FastCMM``: its ``U`` by identity).
``solver.solve(W, a, k, mu, start, ...)`` runs the method and returns a ``SolverRun``.
"""

from __future__ import annotations

from .admm_solvers import ADMMCMM, FastCMM, SequentialADMMCMM
from .base import CMMSolver, SolverOptionError, SolverRun, Start
from .manifold_solvers import OPTIMIZERS, PRECONDITIONERS, BlockCMM, SequentialCMM

__all__ = ["CMMSolver", "BlockCMM", "SequentialCMM", "ADMMCMM", "SequentialADMMCMM", "FastCMM", "SOLVERS",
           "SolverOptionError", "Start", "SolverRun", "PRECONDITIONERS", "OPTIMIZERS"]

#: the solver classes by method name (``CMMResult.method``; the CLI's ``--method``)
SOLVERS: dict[str, type[CMMSolver]] = {cls.name: cls for cls in (BlockCMM, SequentialCMM, ADMMCMM,
                                                                   SequentialADMMCMM, FastCMM)}
