"""Checks of options and inputs where they enter a public function.

Each validator raises a named error (``ParameterError`` unless ``error=`` says otherwise, e.g.
``objectives.SolverOptionError``) whose message names the parameter, the value and the allowed
range, and returns the value as a Python number. Values traced by a JAX transformation (fields
of a minimiser under ``jit``/``vmap``) cannot be inspected and are returned unchecked.

* ``check_count(name, v, low=1, high=INT32_MAX)`` — an integer (``bool`` refused) in ``[low, high]``;
* ``check_number(name, v, low=, high=, ...)`` — a real number (NaN refused) in a range;
  ``check_positive``, ``check_nonnegative``, ``check_unit_interval`` are its usual cases;
* ``check_wolfe(c1, c2)`` — line-search constants ``0 < c1 < c2 < 1``;
* ``check_finite(name, A)`` — no NaN/inf entries in a dense or ``scipy.sparse`` array;
* ``check_full_rank(name, gram)`` — ``k`` columns independent, from their Gram matrix ``YᵀMY``.
"""

from __future__ import annotations

import jax
import numpy as np
import scipy.sparse as sp
from jaxtyping import Float

from .errors import NonFiniteError, ParameterError, RankDeficientError

__all__ = ["INT32_MAX", "is_traced_value", "is_integer", "check_count", "check_number", "check_positive",
           "check_nonnegative", "check_unit_interval", "check_wolfe", "check_finite", "check_full_rank"]

#: the largest count that fits the solvers' int32 loop counters
INT32_MAX = 2**31 - 1


def is_traced_value(value) -> bool:
    """Whether ``value`` is a JAX tracer (its number is unknown until run time)."""
    return isinstance(value, jax.core.Tracer)


def _scalar_kind(value) -> str | None:
    """``"int"``, ``"real"`` or None (not a real scalar: bool, complex, string, array of size ≠ 1, ...)."""
    if isinstance(value, (bool, np.bool_)):
        return None
    if isinstance(value, (int, np.integer)):
        return "int"
    if isinstance(value, (float, np.floating)):
        return "real"
    if isinstance(value, (np.ndarray, jax.Array)) and value.ndim == 0:
        if np.issubdtype(value.dtype, np.integer):
            return "int"
        if np.issubdtype(value.dtype, np.floating):
            return "real"
    return None


def _show(value) -> str:
    """``repr`` of a value, a 0-d array shown as its number (as the user wrote it)."""
    if isinstance(value, (np.ndarray, jax.Array)) and value.ndim == 0:
        return repr(value.item())
    return repr(value)


def is_integer(value) -> bool:
    """An integer scalar (Python or numpy/JAX 0-d integer), not a ``bool`` and not a float like ``2.0``."""
    return _scalar_kind(value) == "int"


def check_count(name: str, value, low: int = 1, high: int = INT32_MAX, *, high_label: str | None = None,
                error: type[Exception] = ParameterError) -> int:
    """``value`` an integer in ``[low, high]`` (``high_label`` names the bound, e.g. ``"n = 50"``)."""
    if is_traced_value(value):
        return value
    if is_integer(value) and low <= int(value) <= high:
        return int(value)
    hint = " (a bool is not a count)" if isinstance(value, (bool, np.bool_)) else ""
    raise error(f"{name} must be an integer ≥ {low} and ≤ {high_label or high}, got {_show(value)}{hint}")


def _describe(low, high, low_open, high_open) -> str:
    parts = []
    if low is not None:
        parts.append(f"{'>' if low_open else '≥'} {low}")
    if high is not None:
        parts.append(f"{'<' if high_open else '≤'} {high}")
    return " and ".join(parts)


def check_number(name: str, value, *, low: float | None = None, high: float | None = None, low_open: bool = False,
                 high_open: bool = False, finite: bool = True, error: type[Exception] = ParameterError) -> float:
    """``value`` a real number (NaN refused; ±inf refused when ``finite``) with ``low ≤ value ≤ high``
    (strict where ``low_open``/``high_open``; None: unbounded)."""
    if is_traced_value(value):
        return value
    ok = _scalar_kind(value) is not None
    if ok:
        v = float(value)
        ok = not np.isnan(v) and (np.isfinite(v) or not finite)
        ok = ok and (low is None or (v > low if low_open else v >= low))
        ok = ok and (high is None or (v < high if high_open else v <= high))
    if ok:
        return v
    bounds = _describe(low, high, low_open, high_open)
    raise error(f"{name} must be a {'finite ' if finite else ''}number{' ' + bounds if bounds else ''}, "
                f"got {_show(value)}")


def check_positive(name: str, value, *, finite: bool = True, error: type[Exception] = ParameterError) -> float:
    """``value > 0`` (finite unless ``finite=False``)."""
    return check_number(name, value, low=0, low_open=True, finite=finite, error=error)


def check_nonnegative(name: str, value, *, finite: bool = True, error: type[Exception] = ParameterError) -> float:
    """``value ≥ 0`` (finite unless ``finite=False``)."""
    return check_number(name, value, low=0, finite=finite, error=error)


def check_unit_interval(name: str, value, *, closed: bool = False, error: type[Exception] = ParameterError) -> float:
    """``0 < value < 1`` (``closed``: ``0 ≤ value ≤ 1``)."""
    return check_number(name, value, low=0, high=1, low_open=not closed, high_open=not closed, error=error)


def check_wolfe(c1, c2, *, error: type[Exception] = ParameterError) -> None:
    """The strong Wolfe constants: ``0 < c1 < c2 < 1`` (Nocedal & Wright §3.1)."""
    c1 = check_unit_interval("c1 (the Armijo constant)", c1, error=error)
    c2 = check_unit_interval("c2 (the curvature constant)", c2, error=error)
    if not (is_traced_value(c1) or is_traced_value(c2)) and not c1 < c2:
        raise error(f"the line-search constants need 0 < c1 < c2 < 1, got c1 = {_show(c1)}, c2 = {_show(c2)}")


def check_finite(name: str, array, *, error: type[Exception] = NonFiniteError) -> None:
    """No NaN or infinite entry in ``array`` (dense or ``scipy.sparse``; traced arrays are not checked)."""
    if is_traced_value(array):
        return
    if sp.issparse(array):
        coo = sp.coo_array(array)
        bad = ~np.isfinite(coo.data)
        where = (coo.row[bad], coo.col[bad]) if bad.any() else None
    else:
        arr = np.asarray(array)
        if not np.issubdtype(arr.dtype, np.number):
            return
        bad = ~np.isfinite(arr)
        where = np.nonzero(bad) if bad.any() else None
    if where is not None:
        first = tuple(int(i[0]) for i in where)
        at = first[0] if len(first) == 1 else first
        raise error(f"{name} has {int(bad.sum())} non-finite entries (NaN or inf), e.g. at {at}; "
                    "clean the input (a degenerate mesh, a division by zero upstream?)")


def check_full_rank(name: str, gram: Float[np.ndarray, "k k"], *, metric: str = "M", eps: float | None = None) -> None:
    """Raise ``RankDeficientError`` unless the ``k`` columns of ``Y`` with Gram matrix ``YᵀMY`` are
    linearly independent: the numerical rank counts eigenvalues of ``YᵀMY`` above ``10·k·ε·λ_max``
    (``ε`` of the computation dtype; below it the Gram matrix cannot tell them from 0)."""
    if is_traced_value(gram):
        return
    G = np.asarray(gram, dtype=np.float64)
    k = G.shape[0]
    eps = float(np.finfo(np.asarray(gram).dtype).eps) if eps is None else eps
    lam = np.linalg.eigvalsh(0.5 * (G + G.T))
    if not np.all(np.isfinite(lam)):
        raise NonFiniteError(f"{name} has non-finite entries (its Gram matrix {name}ᵀ{metric}{name} is not finite)")
    tol = 10.0 * k * eps * max(float(lam[-1]), 0.0)
    rank = int(np.sum(lam > tol))
    if rank < k:
        raise RankDeficientError(
            f"{name} is rank-deficient in the {metric} inner product: numerical rank {rank} of k = {k} columns "
            f"(eigenvalues of {name}ᵀ{metric}{name} from {lam[0]:.3e} to {lam[-1]:.3e}; tolerance {tol:.1e}); "
            "give linearly independent start columns (e.g. no two equal or zero columns)")
