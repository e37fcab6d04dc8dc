"""The interface of the CMM solver objects (``objectives.cmm.solvers``): ``CMMSolver``, the start a solve
gets (``Start``), what it returns (``SolverRun``) and the error for bad options (``SolverOptionError``)."""

from __future__ import annotations

import dataclasses
from typing import Callable, ClassVar, NamedTuple

import numpy as np
from jaxtyping import Float

from stiefel.errors import ParameterError
from stiefel.validation import INT32_MAX, check_count, check_number

__all__ = ["CMMSolver", "Start", "SolverRun", "SolverOptionError"]


class SolverOptionError(ParameterError):
    """A CMM solver option is out of range, or an argument the solver does not take was given (a
    ``stiefel.ParameterError``, hence a ``StiefelError`` and a ``ValueError``)."""


def _require(ok: bool, message: str) -> None:
    if not ok:
        raise SolverOptionError(message)


def _is_number(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def _check_int(name: str, value, low: int, high: int = INT32_MAX) -> None:
    """``value`` an integer in ``[low, high]`` (``stiefel.validation.check_count``)."""
    check_count(name, value, low, high, error=SolverOptionError)


def _check_number(name: str, value, low: float, *, strict: bool = False, finite: bool = True) -> None:
    """``value`` a number ≥ ``low`` (> ``low`` if ``strict``; NaN fails; ±inf fails unless ``finite=False``)."""
    check_number(name, value, low=low, low_open=strict, finite=finite, error=SolverOptionError)


class Start(NamedTuple):
    """The start ``compressed_modes`` built for a solve.

    kind: ``"eigen"``, ``"random"`` or ``"array"``; X0: ``(n, k)`` float64 (None for ``FastCMM``,
    which builds its own start in ``span(U)``); evals: the first ``max(k, 2)`` generalised
    eigenvalues when they were computed (for the eigenbasis start or the default shift), else None.
    """

    kind: str
    X0: np.ndarray | None
    evals: np.ndarray | None = None


class SolverRun(NamedTuple):
    """What ``solve`` returns: ``Psi (n, k)`` A-orthonormal float64 (unsorted), iterations, status,
    wall_time and compile_time (s), history (``{"time": (T,), ...}``) and info (extra ``params``
    entries, e.g. ``rho0``, the initial ADMM penalty)."""

    Psi: np.ndarray
    iterations: int
    status: str
    wall_time: float
    compile_time: float
    history: dict
    info: dict


class CMMSolver:
    """Base of the CMM solvers: ``name``, which starts it takes, ``as_dict`` and ``solve``."""

    name: ClassVar[str]
    #: True when the solver builds its own start in a subspace (``FastCMM``): no ``(n, k)`` start
    restricted: ClassVar[bool] = False
    #: True when ``solve`` accepts ``callback=`` (``SequentialCMM``)
    supports_callback: ClassVar[bool] = False
    #: True when ``solve`` accepts ``progress=`` and ``stop=`` (``BlockCMM``)
    supports_progress: ClassVar[bool] = False

    def needs_eigenpairs(self, start: str) -> bool:
        """Whether ``compressed_modes`` must compute the first ``max(k, 2)`` eigenpairs for a ``start`` kind."""
        return start == "eigen" and not self.restricted

    def as_dict(self) -> dict:
        """The options, by field name (recorded in ``CMMResult.params``)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def solve(self, W, a: Float[np.ndarray, " n"], k: int, mu: float, start: Start, *, weighting: str = "area",
              seed: int = 0, dtype=None, callback: Callable | None = None) -> SolverRun:
        """Run the method on ``(W (n, n) csr, A = diag(a))`` from ``start``; see the subclasses."""
        raise NotImplementedError


def _no_callback(solver: CMMSolver, callback) -> None:
    _require(callback is None, f"{type(solver).__name__} takes no callback= (SequentialCMM calls one per column)")
