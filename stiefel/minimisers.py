"""Riemannian block minimisers as ``optimistix.AbstractMinimiser`` subclasses (MATH.md §1, §3).

``optx.minimise(fn, RiemannianCG(S, rtol=..., atol=...), X0, args, max_steps=...,
adjoint=stiefel.RiemannianImplicitAdjoint())`` minimises ``fn(X, args)`` over
``X ∈ S_M = {XᵀMX = I}``. Three methods share one state and one step:

* ``RiemannianCG`` — nonlinear CG (Polak–Ribière+, restart on non-descent), strong
  Armijo–Wolfe search on the exact ``h(τ) = F(R_X(τη))``, transport by projection.
* ``RiemannianLBFGS`` — limited-memory BFGS (Nocedal & Wright Alg. 7.4); the ``memory``
  pairs ``s = τη``, ``y = ξ⁺ − ξ`` are kept as ambient matrices and the direction is
  projected onto the current tangent space once. The initial inverse Hessian is the
  preconditioner (``q ↦ proj_X(P M q)``), or ``⟨s, y⟩/⟨y, y⟩·I`` without one.
* ``RiemannianBB`` — gradient descent with alternating Barzilai–Borwein steps (capped by
  ``max_move``) and the Zhang–Hager nonmonotone Armijo backtracking (Wen & Yin 2013).

Convergence: the Riemannian gradient norm (manifold metric) ``≤ atol + rtol·|F(X)|``,
or (``ftol > 0``) a relative decrease ``≤ ftol`` over the last ``ftol_window`` iterations,
or (``xtol > 0``) an accepted step that moves X by ``≤ xtol``. ``optx.RESULTS``: converged →
``successful``; out of steps → ``nonlinear_max_steps_reached``; non-finite objective or
gradient → ``nonfinite``; no acceptable step along a descent direction → ``nonlinear_divergence``
(optimistix has no line-search code; the exact ``stiefel.Status`` is ``sol.stats["status"]``).
Tolerances and line-search constants are runtime values (arrays): changing them never
recompiles. Derivatives of the solution: use ``stiefel.RiemannianImplicitAdjoint`` —
``optx.ImplicitAdjoint`` differentiates "Euclidean gradient = 0", which is wrong on S_M.
"""

from __future__ import annotations

from typing import Any, Callable, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from . import block_steps as _steps
from .block_steps import State
from .errors import StiefelError
from .manifold import GeneralizedStiefel
from .preconditioning import PRECONDITIONING_MODES
from .result import Status

__all__ = ["RiemannianCG", "RiemannianLBFGS", "RiemannianBB", "STALL_WINDOW_MAX", "to_optx_result"]

STALL_WINDOW_MAX = 64  # ring buffer of recent objective values for the ftol test


def _scalar(x):
    return x if isinstance(x, jax.Array) and x.ndim == 0 else jnp.asarray(x)


def _concrete(x) -> float | None:
    """``float(x)`` when ``x`` is concrete (not traced), else None (validation is skipped under tracing)."""
    try:
        return float(x)
    except (TypeError, jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        return None


def to_optx_result(status):
    """``stiefel.Status`` code (traced or not) → ``optx.RESULTS`` item; −1 (running) → successful."""
    R = optx.RESULTS
    return R.where(status == Status.NON_FINITE, R.nonfinite,
                   R.where(status == Status.LINE_SEARCH_FAILED, R.nonlinear_divergence,
                           R.where(status == Status.MAX_ITERS, R.nonlinear_max_steps_reached, R.successful)))


class _RiemannianMinimiser(optx.AbstractMinimiser):
    """Shared fields and the optimistix protocol; subclasses fix ``method`` and add their own options.

    Fields (all scalars are runtime arrays):
      manifold: the ``GeneralizedStiefel`` (its metric, retraction and M).
      rtol, atol: stop when ``‖grad F‖ ≤ atol + rtol·|F|`` (manifold metric).
      preconditioner: None or a callable ``Y ↦ PY`` (P SPD, e.g. ``op.solve`` of
        ``stiefel.shifted_inverse(W, M, σ)``); ``precondition``: ``"residual"`` or ``"metric"``.
      c1, c2: Armijo / curvature constants; ls_max_evals: evaluations per line search.
      init_step: first step in units of 1/‖grad‖; max_move: cap on τ‖η‖ per step.
      ftol, ftol_window: stall test (0 disables; window ≤ ``STALL_WINDOW_MAX``); xtol: step test.
      monitor: optional ``X ↦ scalar`` recorded per iterate; history: iterations recorded
        (``stats["history"]``, 0 = none); line: optional fast ``(manifold, X, η, args) ↦ φ``
        with ``φ(τ) = (F(R_X(τη)), d/dτ)`` (e.g. ``objectives.CMMEnergy.line``).
      norm: unused (optimistix's interface); gradient norms use the manifold metric.
    """

    manifold: GeneralizedStiefel
    rtol: jax.Array = eqx.field(converter=_scalar, default=0.0)
    atol: jax.Array = eqx.field(converter=_scalar, default=1e-6)
    preconditioner: Callable | None = None
    precondition: str = eqx.field(static=True, default="residual")
    c1: jax.Array = eqx.field(converter=_scalar, default=1e-4)
    c2: jax.Array = eqx.field(converter=_scalar, default=0.9)
    ls_max_evals: int = eqx.field(static=True, default=30)
    init_step: jax.Array = eqx.field(converter=_scalar, default=1.0)
    max_move: jax.Array = eqx.field(converter=_scalar, default=1.0)
    ftol: jax.Array = eqx.field(converter=_scalar, default=0.0)
    ftol_window: jax.Array = eqx.field(converter=_scalar, default=20)
    stall_test: bool = eqx.field(static=True, default=False)
    xtol: jax.Array = eqx.field(converter=_scalar, default=0.0)
    monitor: Callable | None = None
    history: int = eqx.field(static=True, default=0)
    line: Callable | None = None
    norm: Any = eqx.field(static=True, default=None)

    method: ClassVar[str] = ""
    memory_size: ClassVar[int] = 0

    def __check_init__(self):
        if not isinstance(self.manifold, GeneralizedStiefel):
            raise StiefelError(f"the first argument must be a stiefel.GeneralizedStiefel, got {type(self.manifold).__name__}")
        if self.precondition not in PRECONDITIONING_MODES:
            raise StiefelError(f"unknown precondition mode {self.precondition!r}; choose one of {PRECONDITIONING_MODES}")
        if not (isinstance(self.ls_max_evals, int) and self.ls_max_evals >= 1):
            raise StiefelError(f"ls_max_evals must be an integer ≥ 1, got {self.ls_max_evals!r}")
        if not (isinstance(self.history, int) and self.history >= 0):
            raise StiefelError(f"history must be an integer ≥ 0, got {self.history!r}")
        vals = {name: _concrete(getattr(self, name)) for name in
                ("rtol", "atol", "c1", "c2", "init_step", "max_move", "ftol", "ftol_window", "xtol")}
        for name in ("rtol", "atol", "ftol", "xtol"):
            if vals[name] is not None and not vals[name] >= 0:
                raise StiefelError(f"{name} must be ≥ 0, got {vals[name]}")
        for name in ("init_step", "max_move"):
            if vals[name] is not None and not vals[name] > 0:
                raise StiefelError(f"{name} must be > 0, got {vals[name]}")
        c1, c2 = vals["c1"], vals["c2"]
        if c1 is not None and c2 is not None and not 0 < c1 < c2 < 1:
            raise StiefelError(f"the line-search constants need 0 < c1 < c2 < 1, got c1 = {c1}, c2 = {c2}")
        w = vals["ftol_window"]
        if w is not None and not (w == int(w) and 1 <= w <= STALL_WINDOW_MAX):
            raise StiefelError(f"ftol_window must be an integer in [1, {STALL_WINDOW_MAX}], got {w}")

    # --- optimistix protocol -------------------------------------------------------------------
    def init(self, fn, y, args, options, f_struct, aux_struct, tags) -> State:
        return _steps.init_state(self, fn, y, args)

    def step(self, fn, y, args, options, state: State, tags):
        state = _steps.step(self, fn, args, state)
        return state.X, state, state.aux

    def terminate(self, fn, y, args, options, state: State, tags):
        return state.status >= 0, to_optx_result(state.status)

    def postprocess(self, fn, y, aux, args, options, state: State, tags, result):
        stats = {"value": state.F, "grad_norm": state.gnorm, "status": state.status,
                 "n_fevals": state.n_fevals, "n_grads": state.it + 1, "n_restarts": state.n_restarts,
                 "dist_to_manifold": self.manifold.dist_to_manifold(state.X), "history": state.history}
        return y, aux, stats


class RiemannianCG(_RiemannianMinimiser):
    """Riemannian nonlinear CG (PR+) with a strong Wolfe search (module docstring).

    ``RiemannianCG(S, rtol=0.0, atol=1e-6, *, preconditioner=None, c2=0.1, ...)``; CG needs a
    tight curvature condition (``c2 = 0.1``; 0.9 stalled in tests).
    """

    c2: jax.Array = eqx.field(converter=_scalar, default=0.1)
    method: ClassVar[str] = "cg"


class RiemannianLBFGS(_RiemannianMinimiser):
    """Riemannian L-BFGS with ``memory`` pairs (≥ 1) and a strong Wolfe search (``c2 = 0.9``)."""

    memory: int = eqx.field(static=True, default=8)
    method: ClassVar[str] = "lbfgs"

    def __check_init__(self):
        if not (isinstance(self.memory, int) and self.memory >= 1):
            raise StiefelError(f"memory must be an integer ≥ 1 for L-BFGS, got {self.memory!r}")


class RiemannianBB(_RiemannianMinimiser):
    """Barzilai–Borwein steps with the Zhang–Hager nonmonotone Armijo search (``bb_gamma`` ∈ [0, 1])."""

    bb_gamma: jax.Array = eqx.field(converter=_scalar, default=0.85)
    method: ClassVar[str] = "bb"

    def __check_init__(self):
        g = _concrete(self.bb_gamma)
        if g is not None and not 0 <= g <= 1:
            raise StiefelError(f"bb_gamma must lie in [0, 1], got {g}")


METHOD_CLASSES = {"cg": RiemannianCG, "lbfgs": RiemannianLBFGS, "bb": RiemannianBB}
