"""The default answer of ``compressed_modes``: exact zeros and a status derived from the ℓ1 residual.

A CMM solver minimises a smoothed ℓ1 energy; its modes have no exact zeros and its status speaks of the
smoothed problem. ``certify`` finishes them on the true problem (``SupportFinish``, docs/maths.md §9) and
derives the one status the pipeline reports from the exact stationarity residual (9.10):

* ``"converged"`` — exact zeros and ``residual ≤ finish.tol`` (relative), whatever the steps did;
* otherwise the finish's reason (``"stalled"``, ``"max_iters"``, ``"line_search_failed"``,
  ``"objective_increased"`` — the solver's modes kept, the finish would have raised the objective — …):
  never a claim of convergence.

Not finished (the smoothed solver's status stands): ``finish=None`` (the smoothed answer, asked for),
μ = 0 (the problem is the smooth eigenproblem; the solver's modes are its minimisers) and an interrupted solve
(the modes reached are returned as they are).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .support_finish import SupportFinish, finish_support

__all__ = ["Certified", "certify", "TRACE_COLUMNS"]

#: the columns of the finish record's ``trace["rows"]``, one row per Newton iterate (``FinishResult.trace``)
TRACE_COLUMNS = ("objective", "grad", "violation", "support", "cg")


@dataclasses.dataclass(frozen=True)
class Certified:
    """What ``certify`` hands back to ``compressed_modes``.

    Psi: ``(n, k)`` modes (finished, or the solver's); status: as in the module docstring; finish: the
    finish's record (None when not finished); smooth_modes: the solver's modes when finished, else None;
    residual: eq. (9.10) of ``Psi`` when finished, else None (computed by the caller); seconds: the finish's time.
    """

    Psi: np.ndarray
    status: str
    finish: dict | None
    smooth_modes: np.ndarray | None
    residual: float | None
    seconds: float


def certify(W, a: np.ndarray, w: np.ndarray, mu: float, Psi: np.ndarray, solver_status: str,
            finish: SupportFinish | None) -> Certified:
    """Finish the solver's modes ``Psi (n, k)`` on the exact ℓ1 problem and derive the status (module docstring).

    W: ``(n, n)`` sparse; a: ``(n,)`` diag A; w: ``(n,)`` ℓ1 weights; solver_status: the smoothed solver's status.
    """
    if finish is None or mu == 0.0 or solver_status == "interrupted":
        return Certified(Psi, solver_status, None, None, None, 0.0)
    fr = finish_support(W, a, w, mu, Psi, finish)
    residual = float(fr.stationarity.relative)
    # objective_increased: the solver's modes were kept, say so whatever their residual (a NaN residual fails ≤);
    # otherwise the finish's reason ("converged" from the finish itself already means residual ≤ tol)
    certified = fr.status != "objective_increased" and residual <= finish.tol
    status = "converged" if certified else fr.status
    record = dict(status=status, finish_status=fr.status, solver_status=solver_status, tol=finish.tol,
                  objective_before=fr.objective_before, objective=fr.objective, rounds=fr.rounds,
                  newton_iterations=fr.newton_iterations, cg_iterations=fr.cg_iterations, w_products=fr.w_products,
                  added=fr.added, removed=fr.removed, wall_time=fr.wall_time,
                  violations=fr.stationarity.violations, attempts=fr.attempts,
                  trace=dict(columns=TRACE_COLUMNS, rows=fr.trace.tolist()))
    return Certified(fr.Psi, status, record, Psi, residual, fr.wall_time)
