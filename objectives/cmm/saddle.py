"""Saddle checks of the block CMM solver's final stage (docs/maths.md §9, ``stiefel.solvers.saddle``).

The smoothed CMM energy has saddle points whose neighbourhood is a long plateau: started from the
eigenbasis, the block solver on ``example:bumpy`` (k = 10, μ = 2λ₉) creeps along one from iteration
~150 and its stall test stopped it there at 1802.50 (gradient norm 1.9, three negative Hessian
eigenvalues, the most negative −88.7 against σ = λ₉ = 114); without the stall test it leaves after
~700 more iterations and ends at 1714.8 (ADMM: 1714.65). When the final stage stalls, ``check`` measures
the smallest curvature (``stiefel.negative_curvature``) and, where it is clearly negative, steps off
along it (``stiefel.escape_step``); the stage then resumes.

The search is confined to the entries with ``|X_ij| > MASK_FACTOR·max(ε, δ)``: elsewhere the smoothing's
curvature ``μ w_i s''`` (∝ 1/δ) makes the Hessian too stiff for the ``(W + σA)⁻¹``-preconditioned LOBPCG,
and no escape direction lives there (measured on bumpy: 20 products reach θ = −79 with the mask, 80 without
it only −39). A check costs about as much as 20 iterations.
"""

from __future__ import annotations

import numpy as np
import jax.numpy as jnp

from stiefel.solvers.driver import run_program
from stiefel.solvers.saddle import Curvature, EscapeStep, escape_step, negative_curvature

__all__ = ["check", "MASK_FACTOR", "LOBPCG_STEPS"]

#: the escape direction's search space: entries above this multiple of the smoothing width
MASK_FACTOR = 10.0
#: LOBPCG steps (Hessian products) per check
LOBPCG_STEPS = 20


def _curvature(F, manifold, X, P, mask):
    return negative_curvature(F, manifold, X, preconditioner=P, mask=mask, max_iters=LOBPCG_STEPS)


def check(F, manifold, X, P, *, width: float, threshold: float) -> tuple:
    """One saddle check at ``X`` (the final stage's stalled iterate, padded rows zero).

    Args:
      F: the smoothed energy (``CMMEnergy``); manifold; X: ``(n, k)``; P: the preconditioner operator
        (``.solve`` applies ``(W + σA)⁻¹``) or None; width: the smoothing width ``max(ε, δ)``;
      threshold: a step is taken only when the curvature θ < −threshold.

    Returns:
      ``(X_new or None, record, run seconds, compile seconds)``; record: θ, its relative residual, LOBPCG
      steps, the step length and the (smoothed) objective decrease, seconds. The escape step is compiled
      only when a check first needs it.
    """
    mask = (jnp.abs(X) > MASK_FACTOR * width).astype(X.dtype)
    solve = None if P is None else P.solve
    # both run once or twice a solve: compiled without the backend's optimisation passes (ONE_SHOT_OPTIONS), and
    # stored with the solver's programs when the persistent cache is on (a later process loads them untraced)
    curv, t_compile, t_run = run_program(_curvature, (F, manifold, X, solve, mask), Curvature(0, 0, 0, 0),
                                         optimize=False)
    theta = float(curv.value)
    record = {"curvature": theta, "residual": float(curv.residual), "lobpcg_steps": int(curv.iterations),
              "step": 0.0, "decrease": 0.0}
    X_new = None
    if np.isfinite(theta) and theta < -threshold:
        step, c2, r2 = run_program(escape_step, (F, manifold, X, curv), EscapeStep(0, 0, 0, 0, 0, 0), optimize=False)
        t_compile, t_run = t_compile + c2, t_run + r2
        if bool(step.accepted):
            X_new = step.X
            record.update(step=float(step.step), decrease=float(step.start_value - step.value))
    record["seconds"] = t_run
    return X_new, record, t_run, t_compile
