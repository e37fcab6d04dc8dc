"""Riemannian block minimisers as ``optimistix.AbstractMinimiser`` subclasses (docs/maths.md §1, §3).

``optx.minimise(fn, RiemannianCG(S, rtol=..., atol=...), X0, args, max_steps=...,
adjoint=stiefel.RiemannianImplicitAdjoint())`` minimises ``fn(X, args)`` over
``X ∈ S_M = {XᵀMX = I}`` (or over a ``stiefel.Product`` of such manifolds, ``X`` a tuple). Three
methods share one state and one step:

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
Reaching the round-off floor is convergence: a search that fails with the gradient norm at or below
``stiefel.solvers.linesearch.round_off_floor`` (``sol.stats["round_off_floor"]``; ``sol.stats["at_floor"]``
says it happened) ends ``CONVERGED`` / ``successful`` (``settled_status``), any other failed search
``LINE_SEARCH_FAILED``.
Tolerances and line-search constants are runtime values (arrays): changing them never
recompiles. Derivatives of the solution: use ``stiefel.RiemannianImplicitAdjoint`` —
``optx.ImplicitAdjoint`` differentiates "Euclidean gradient = 0", which is wrong on S_M.
"""

from __future__ import annotations

from typing import Any, Callable, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from . import block_steps as _steps
from ..runtime.compilation import host_array
from .block_steps import STALL_WINDOW_MAX, State
from .linesearch import round_off_floor
from ..errors import ParameterError, StiefelError
from ..manifolds.manifold import GeneralizedStiefel
from .preconditioning import PRECONDITIONING_MODES
from ..manifolds.product import Product
from ..result import Status
from ..validation import (check_count, check_nonnegative, check_positive, check_unit_interval, check_wolfe, is_traced_value,
                          known_value, traced_range)

__all__ = ["RiemannianCG", "RiemannianLBFGS", "RiemannianBB", "STALL_WINDOW_MAX", "to_optx_result", "settled_status"]



def _scalar(x):
    return x if isinstance(x, jax.Array) and x.ndim == 0 else host_array(x)


def _budget(x):
    """The runtime iteration limit as an int32 array (checked first: ``True`` or ``2.5`` is no count)."""
    return None if x is None else host_array(check_count("budget", x, 0), np.int32)


def _check_manifold(manifold, preconditioner) -> None:
    """A solver's manifold is a ``GeneralizedStiefel`` or a ``Product`` (then without a preconditioner)."""
    if not isinstance(manifold, (GeneralizedStiefel, Product)):
        raise StiefelError(f"the first argument must be a stiefel.GeneralizedStiefel or stiefel.Product, "
                           f"got {type(manifold).__name__}")
    if isinstance(manifold, Product) and preconditioner is not None:
        raise ParameterError("a preconditioner is not supported on a stiefel.Product (it acts on one (n, k) "
                             "array); pass preconditioner=None")


def settled_status(state: State) -> tuple[Int[Array, ""], Float[Array, ""], Bool[Array, ""]]:
    """``(status, floor, at_floor)``: ``state.status`` with a failed line search at the round-off floor counted
    as ``CONVERGED``; ``floor`` is ``round_off_floor(F(X), F(X0), N)`` (N: the entries of ``state.X``, (n, k)
    or a ``Product``'s tuple) and ``at_floor`` says the search failed with ``‖grad F‖ ≤ floor``. Traced or not."""
    size = sum(int(np.size(x)) for x in jax.tree_util.tree_leaves(state.X))
    floor = round_off_floor(state.F, state.history.value[..., 0], size)
    at_floor = (state.status == Status.LINE_SEARCH_FAILED) & (state.gnorm <= floor)
    return jnp.where(at_floor, Status.CONVERGED, state.status).astype(jnp.int32), floor, at_floor


def to_optx_result(status):
    """``stiefel.Status`` code (traced or not) → ``optx.RESULTS`` item; −1 (running) → successful;
    ``INTERRUPTED`` (only set by the host loop of ``stiefel.solvers.driver``) → max steps reached; the trust-region
    failures (collapsed radius, indefinite preconditioner) → ``nonlinear_divergence``."""
    R = optx.RESULTS
    failed = ((status == Status.LINE_SEARCH_FAILED) | (status == Status.TRUST_REGION_COLLAPSED)
              | (status == Status.INDEFINITE_PRECONDITIONER))
    return R.where(status == Status.NON_FINITE, R.nonfinite,
                   R.where(failed, R.nonlinear_divergence,
                           R.where((status == Status.MAX_ITERS) | (status == Status.INTERRUPTED),
                                   R.nonlinear_max_steps_reached, R.successful)))


class _RiemannianMinimiser(optx.AbstractMinimiser):
    """Shared fields and the optimistix protocol; subclasses fix ``method`` and add their own options.

    Fields (all scalars are runtime arrays):
      manifold: the ``GeneralizedStiefel`` (its metric, retraction and M), or a ``stiefel.Product`` of them
        (points are tuples); ``ShapeError`` at ``init`` for a start of the wrong structure or shapes.
      rtol, atol: stop when ``‖grad F‖ ≤ atol + rtol·|F|`` (manifold metric).
      preconditioner: None, a callable ``Y ↦ PY`` (P SPD, e.g. ``op.solve`` of
        ``stiefel.shifted_inverse(W, M, σ)``) or a ``stiefel.PointPreconditioner`` (``P_X``, applied at the
        current iterate); ``precondition``: ``"residual"`` or ``"metric"``. Not with a
        ``Product`` (``ParameterError``).
      c1, c2: Armijo / curvature constants; ls_max_evals: evaluations per line search.
      init_step: first step in units of 1/‖grad‖; max_move: cap on τ‖η‖ per step.
      ftol, ftol_window: stall test (0 disables; window ≤ ``STALL_WINDOW_MAX``); xtol: step test.
      monitor: optional ``X ↦ scalar`` recorded per iterate; history: iterations recorded
        (``stats["history"]``, 0 = none); line: optional fast ``(manifold, X, η, args) ↦ φ``
        with ``φ(τ) = (F(R_X(τη)), d/dτ)`` (e.g. ``objectives.CMMEnergy.line``).
      budget: optional runtime iteration limit (≤ optimistix's ``max_steps``, which fixes the compiled loop
        bound): the status becomes ``MAX_ITERS`` when it ends the run; 0 takes no step. A loop of warm-started
        stages sharing one total passes what is left here and compiles once.
      norm: unused (optimistix's interface); gradient norms use the manifold metric.

    Concrete options are checked on construction (``ParameterError``); traced ones (under ``jit``/``vmap``)
    cannot be and are not.
    """

    manifold: GeneralizedStiefel | Product
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
    budget: jax.Array | None = eqx.field(converter=_budget, default=None)
    norm: Any = eqx.field(static=True, default=None)

    method: ClassVar[str] = ""
    memory_size: ClassVar[int] = 0

    def __check_init__(self):
        _check_manifold(self.manifold, self.preconditioner)
        if self.precondition not in PRECONDITIONING_MODES:
            raise StiefelError(f"unknown precondition mode {self.precondition!r}; choose one of {PRECONDITIONING_MODES}")
        check_count("ls_max_evals", self.ls_max_evals)
        check_count("history", self.history, 0)
        for name in ("rtol", "atol", "ftol", "xtol"):
            check_nonnegative(name, getattr(self, name))
        check_positive("init_step", self.init_step)
        check_positive("max_move", self.max_move, finite=False)
        check_wolfe(self.c1, self.c2)
        w = self.ftol_window  # an array (a runtime value): 20.0 counts as the integer 20, 2.5 does not
        if not is_traced_value(w):
            w = w.item()
            check_count("ftol_window", int(w) if isinstance(w, float) and w.is_integer() else w, 1, STALL_WINDOW_MAX)

    def _ranges(self) -> list:
        """``(name, value, range keywords of check_number)`` of the runtime options."""
        rules = [(name, getattr(self, name), dict(low=0.0)) for name in ("rtol", "atol", "ftol", "xtol")]
        return rules + [("init_step", self.init_step, dict(low=0.0, low_open=True)),
                        ("max_move", self.max_move, dict(low=0.0, low_open=True, finite=False)),
                        ("c1", self.c1, dict(low=0.0, high=1.0, low_open=True, high_open=True)),
                        ("c2", self.c2, dict(low=0.0, high=1.0, low_open=True, high_open=True))]

    def _checked_start(self, y):
        """``y`` carrying the range checks of the options that are traced (unknown when the solver was built, so
        ``__check_init__`` let them pass): they fail when the program runs, naming the option."""
        for name, value, rule in self._ranges():
            if is_traced_value(value) and known_value(value) is None:
                ok, message = traced_range(name, value, **rule)
                y = eqx.error_if(y, ~ok, message)
        if is_traced_value(self.c1) or is_traced_value(self.c2):
            y = eqx.error_if(y, ~(self.c1 < self.c2), "c1 < c2 is required (the strong Wolfe constants; checked "
                                                      "when the program runs: the values are traced)")
        return y

    # --- optimistix protocol -------------------------------------------------------------------
    def init(self, fn, y, args, options, f_struct, aux_struct, tags) -> State:
        self.manifold.check_shape(y, name="y0")  # where the start enters the solver (shapes only: works traced)
        return _steps.init_state(self, fn, self._checked_start(y), args)

    def step(self, fn, y, args, options, state: State, tags):
        state = _steps.step(self, fn, args, state)
        return state.X, state, state.aux

    def terminate(self, fn, y, args, options, state: State, tags):
        return state.status >= 0, to_optx_result(settled_status(state)[0])

    def postprocess(self, fn, y, aux, args, options, state: State, tags, result):
        status, floor, at_floor = settled_status(state)
        stats = {"value": state.F, "grad_norm": state.gnorm, "status": status, "round_off_floor": floor,
                 "at_floor": at_floor,
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
        check_count("memory (L-BFGS pairs)", self.memory)


class RiemannianBB(_RiemannianMinimiser):
    """Barzilai–Borwein steps with the Zhang–Hager nonmonotone Armijo search (``bb_gamma`` ∈ [0, 1])."""

    bb_gamma: jax.Array = eqx.field(converter=_scalar, default=0.85)
    method: ClassVar[str] = "bb"

    def __check_init__(self):
        check_unit_interval("bb_gamma", self.bb_gamma, closed=True)

    def _ranges(self) -> list:
        return super()._ranges() + [("bb_gamma", self.bb_gamma, dict(low=0.0, high=1.0))]


METHOD_CLASSES = {"cg": RiemannianCG, "lbfgs": RiemannianLBFGS, "bb": RiemannianBB}
