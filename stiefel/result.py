"""Solver outcomes: status codes, per-iteration history, the result object."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .errors import SolverError

__all__ = ["Status", "History", "Result", "SequentialResult"]


class Status:
    """Integer codes of ``Result.status``."""

    CONVERGED = 0  #: gradient norm ≤ gtol (or step ≤ xtol), or a line search failed at the round-off floor
    MAX_ITERS = 1  #: ran out of iterations
    LINE_SEARCH_FAILED = 2  #: no acceptable step along a descent direction
    NON_FINITE = 3  #: the objective or its gradient became non-finite (last finite iterate kept)
    INTERRUPTED = 4  #: stopped from outside (``stop``, Ctrl-C, a raising ``progress`` callback); iterate kept
    TRUST_REGION_COLLAPSED = 5  #: trust regions: the radius fell below its minimum with no acceptable step
    INDEFINITE_PRECONDITIONER = 6  #: trust regions: ``⟨Pr, r⟩ ≤ 0`` for a residual ``r ≠ 0`` in the inner solve

    names = ("converged", "max_iters", "line_search_failed", "non_finite", "interrupted", "trust_region_collapsed",
             "indefinite_preconditioner")
    FAILURES = (LINE_SEARCH_FAILED, NON_FINITE, TRUST_REGION_COLLAPSED, INDEFINITE_PRECONDITIONER)

    @classmethod
    def name(cls, code) -> str:
        return cls.names[int(code)]


class History(eqx.Module):
    """Per-iteration record; entry 0 is the start, entries past ``iterations`` are NaN.

    value: objective; grad_norm: Riemannian gradient norm (manifold metric);
    step: accepted step length τ (entry 0 is 0); monitor: the value of the solver's
    ``monitor`` function at each iterate (e.g. a true, non-smooth objective), NaN if none.
    """

    value: Float[Array, "... T"]
    grad_norm: Float[Array, "... T"]
    step: Float[Array, "... T"]
    monitor: Float[Array, "... T"]

    @staticmethod
    def empty(length: int, dtype, lead: tuple = ()) -> "History":
        nan = jnp.full(lead + (length,), jnp.nan, dtype=dtype)
        return History(nan, nan, nan, nan)

    def record(self, i, value, grad_norm, step, monitor=jnp.nan) -> "History":
        return History(
            self.value.at[..., i].set(value),
            self.grad_norm.at[..., i].set(grad_norm),
            self.step.at[..., i].set(step),
            self.monitor.at[..., i].set(monitor),
        )


def _concrete(x):
    """``x`` as a numpy value, or None when it is traced (a repr inside ``jit``/``vmap``)."""
    if isinstance(x, jax.core.Tracer):
        return None
    try:
        return np.asarray(x)
    except Exception:  # noqa: BLE001 — anything without a concrete value
        return None


def _short(name: str, value, fmt: str) -> str:
    v = _concrete(value)
    if v is None:
        return f"{name}=<traced>"
    if v.ndim == 0:
        return f"{name}={format(v.item(), fmt)}"
    flat = v.ravel()
    shown = ", ".join(format(x.item(), fmt) for x in flat[:4]) + (", …" if flat.size > 4 else "")
    return f"{name}=[{shown}]"


def _status_text(status) -> str:
    v = _concrete(status)
    if v is None:
        return "<traced>"
    names = sorted({Status.name(s) for s in np.ravel(v)})
    return repr(names[0]) if len(names) == 1 else repr(names)


class Result(eqx.Module):
    """Outcome of ``stiefel.minimize``.

    Attributes:
      x: final point ``(n, k)`` (the last iterate with a finite objective).
      value: ``F(x)``; grad_norm: Riemannian gradient norm at ``x``.
      iterations: iterations taken; status: a ``Status`` code.
      history: ``History`` of length ``max_iters + 1``.
      stats: counters (objective/gradient evaluations, line-search trials, ...); ``round_off_floor``, the
        gradient norm that rounding allows (``stiefel.solvers.linesearch.round_off_floor``), and ``at_floor``:
        the run converged there (its line search failed with the gradient norm at or below the floor; ``gtol``
        was below what rounding allows).
      wall_time: seconds for the solve (compiled), compile_time: seconds to trace and compile.
    """

    x: Float[Array, "n k"]
    value: Float[Array, ""]
    grad_norm: Float[Array, ""]
    iterations: Int[Array, ""]
    status: Int[Array, ""]
    history: History
    stats: dict
    wall_time: float = 0.0
    compile_time: float = 0.0

    def __repr__(self) -> str:
        """One line: status, iterations, value, gradient norm, shape and times (no arrays)."""
        shape = "×".join(map(str, np.shape(self.x)))
        floor = " at the round-off floor" if self.at_floor else ""
        return (f"Result(status={_status_text(self.status)}{floor}, {_short('iterations', self.iterations, 'd')}, "
                f"{_short('value', self.value, '.10g')}, {_short('grad_norm', self.grad_norm, '.3e')}, x: {shape}, "
                f"solve {self.wall_time:.3f} s, compile {self.compile_time:.3f} s)")

    @property
    def status_name(self) -> str:
        return Status.name(self.status)

    @property
    def converged(self) -> bool:
        return int(self.status) == Status.CONVERGED

    @property
    def at_floor(self) -> bool:
        """Converged at the round-off floor (``stats["at_floor"]``); False when not recorded or traced."""
        v = _concrete(self.stats.get("at_floor", False)) if isinstance(self.stats, dict) else None
        return bool(v is not None and np.all(v))

    def trimmed_history(self) -> dict:
        """History as numpy arrays cut to ``iterations + 1`` entries."""
        t = int(self.iterations) + 1
        return {f: np.asarray(getattr(self.history, f))[..., :t] for f in ("value", "grad_norm", "step", "monitor")}

    def raise_for_status(self) -> "Result":
        """Raise ``SolverError`` unless the solver converged (or only ran out of iterations)."""
        if int(self.status) in Status.FAILURES:
            raise SolverError(
                f"solver stopped with status {self.status_name!r} after {int(self.iterations)} iterations "
                f"(objective {float(self.value):.6e}, gradient norm {float(self.grad_norm):.3e})"
            )
        return self


class SequentialResult(eqx.Module):
    """Outcome of ``stiefel.minimize_sequential``: one column at a time (thesis Algorithm 6).

    Attributes:
      x: ``(n, k)`` columns, M-orthonormal.
      value: ``Σ_j f(x_j)``; values: ``(k,)`` per-column objective.
      grad_norm, iterations, status: ``(k,)`` per column.
      history: ``History`` with leading axis ``k``.
      wall_time: total seconds; column_times: ``(k,)`` seconds per column.
    """

    x: Float[Array, "n k"]
    value: Float[Array, ""]
    values: Float[Array, " k"]
    grad_norm: Float[Array, " k"]
    iterations: Int[Array, " k"]
    status: Int[Array, " k"]
    history: History
    stats: dict
    wall_time: float = 0.0
    compile_time: float = 0.0
    column_times: tuple = ()

    def __repr__(self) -> str:
        """One line: statuses, iterations, value, shape and times (no arrays)."""
        shape = "×".join(map(str, np.shape(self.x)))
        return (f"SequentialResult(status={_status_text(self.status)}, {_short('iterations', self.iterations, 'd')}, "
                f"{_short('value', self.value, '.10g')}, x: {shape}, solve {self.wall_time:.3f} s, "
                f"compile {self.compile_time:.3f} s)")

    @property
    def status_names(self) -> list[str]:
        return [Status.name(s) for s in np.asarray(self.status)]

    @property
    def converged(self) -> bool:
        return bool(np.all(np.asarray(self.status) == Status.CONVERGED))

    def raise_for_status(self) -> "SequentialResult":
        bad = [j for j, s in enumerate(np.asarray(self.status)) if s in Status.FAILURES]
        if bad:
            j = bad[0]
            raise SolverError(
                f"column {j} stopped with status {Status.name(self.status[j])!r} after "
                f"{int(self.iterations[j])} iterations"
            )
        return self
