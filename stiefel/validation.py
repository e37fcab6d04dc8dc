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

Inputs that may be traced (a differentiable function's parameters) go through the ``checked_*`` helpers,
which return the value (unchanged, or carrying a run-time check) to be used in its place:

* ``known_value(v)`` — the number of ``v`` when the host knows it: a concrete value, or a tracer that
  carries one (the primal under ``jax.grad``/``jax.jvp`` outside ``jit``); None under ``jit``/``vmap``;
* ``checked_number(name, v, ...)``, ``checked_finite(name, A)``, ``checked_entries(name, A, low=...)``,
  ``checked_order(name_a, a, name_b, b, rule=...)`` — a known value is checked now (the error names the
  parameter, the value and, for arrays, the first bad entry's index); a traced one gets ``eqx.error_if``,
  which raises when the program runs (an ``EquinoxRuntimeError`` naming the parameter, under
  ``jit``/``grad``/``vmap``): never a silent number.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from jaxtyping import Float

from .errors import NonFiniteError, ParameterError, RankDeficientError

__all__ = ["INT32_MAX", "is_traced_value", "is_integer", "check_count", "check_number", "check_positive",
           "check_nonnegative", "check_unit_interval", "check_wolfe", "check_finite", "check_full_rank",
           "known_value", "checked_number", "checked_finite", "checked_entries", "checked_order"]

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


# --- inputs that may be traced ---------------------------------------------------------------------------
_RUNTIME = "checked when the program runs: the value is traced"


def known_value(value) -> np.ndarray | None:
    """``value`` as a numpy array when the host knows its number: a concrete array or scalar, or a tracer
    that carries its value (the primal of ``jax.grad``/``jax.jvp`` outside ``jit``); None when the number
    exists only when the compiled program runs (under ``jit``/``vmap``) or ``value`` is no number."""
    if is_traced_value(value):
        try:
            from jax._src.core import to_concrete_value  # not public; where absent, the run-time checks remain
            value = to_concrete_value(value)
        except Exception:  # noqa: BLE001  (a private API: any failure means not known on the host)
            return None
        if value is None:
            return None
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError):  # not convertible: no number
        return None
    return arr if np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_ else None


def _traced_scalar(name: str, value, error) -> None:
    dtype = jnp.result_type(value)
    if np.ndim(value) != 0 or not (jnp.issubdtype(dtype, jnp.floating) or jnp.issubdtype(dtype, jnp.integer)):
        raise error(f"{name} must be a real number, got a traced array of shape {tuple(np.shape(value))} "
                    f"and dtype {dtype}")


def checked_number(name: str, value, *, low: float | None = None, high: float | None = None,
                   low_open: bool = False, high_open: bool = False, finite: bool = True,
                   error: type[Exception] = ParameterError):
    """``check_number`` for a value that may be traced; returns ``value`` (module docstring): known → checked
    now (``error`` naming the value); traced → a real scalar now, its range when the program runs."""
    known = known_value(value)
    if known is not None:
        check_number(name, known, low=low, high=high, low_open=low_open,
                     high_open=high_open, finite=finite, error=error)
        return value
    if not is_traced_value(value):  # not a number at all: check_number names it
        check_number(name, value, low=low, high=high, low_open=low_open, high_open=high_open, finite=finite,
                     error=error)
    _traced_scalar(name, value, error)
    ok, message = traced_range(name, value, low=low, high=high, low_open=low_open, high_open=high_open,
                               finite=finite)
    return eqx.error_if(value, ~ok, message)


def traced_range(name: str, value, *, low: float | None = None, high: float | None = None, low_open: bool = False,
                 high_open: bool = False, finite: bool = True) -> tuple:
    """``(ok, message)`` for a traced scalar: ``ok`` a traced boolean (the range of ``check_number``), the
    message naming the rule, for ``eqx.error_if`` on whatever array carries the check into the computation."""
    ok = ~jnp.isnan(value)
    if finite:
        ok = ok & jnp.isfinite(value)
    if low is not None:
        ok = ok & ((value > low) if low_open else (value >= low))
    if high is not None:
        ok = ok & ((value < high) if high_open else (value <= high))
    bounds = _describe(low, high, low_open, high_open)
    return ok, f"{name} must be a {'finite ' if finite else ''}number{' ' + bounds if bounds else ''} ({_RUNTIME})"


def checked_finite(name: str, array, *, error: type[Exception] = NonFiniteError):
    """``check_finite`` for an array that may be traced; returns ``array`` (module docstring). A known array's
    error names the count and the first bad entry's index."""
    if not is_traced_value(array):
        check_finite(name, array, error=error)
        return array
    known = known_value(array)
    if known is not None:
        check_finite(name, known, error=error)
        return array
    return eqx.error_if(array, ~jnp.all(jnp.isfinite(array)), f"{name} has non-finite entries (NaN or inf) "
                                                               f"({_RUNTIME}); clean the input")


def checked_entries(name: str, array, *, low: float, low_open: bool = False, what: str = "",
                    error: type[Exception] = ParameterError):
    """Every entry of ``array`` ``≥ low`` (``> low`` when ``low_open``; NaN fails) for an array that may be
    traced; returns ``array``. ``what`` follows the rule in the message (e.g. ``" (a mass diagonal)"``)."""
    rule = f"{name} must have entries {'>' if low_open else '≥'} {low}{what}"
    known = known_value(array)
    if known is not None:
        bad = ~((known > low) if low_open else (known >= low))
        if bad.any():
            first = tuple(int(i[0]) for i in np.nonzero(bad)) if known.ndim else ()
            at = first[0] if len(first) == 1 else first
            shown = f"{name}[{at}]" if known.ndim else name
            raise error(f"{rule}; {int(bad.sum())} are not, e.g. {shown} = {known[first].item()!r}")
        return array
    if not is_traced_value(array):
        return array
    ok = jnp.all((array > low) if low_open else (array >= low))
    return eqx.error_if(array, ~ok, f"{rule} ({_RUNTIME})")


def checked_order(name_a: str, a, name_b: str, b, *, rule: str, error: type[Exception] = ParameterError):
    """``a ≤ b`` for two options that may be traced; returns ``(a, b)``. Known: ``error("{name_a} = a exceeds
    {name_b} = b; {rule}")`` now; traced: the check rides on ``b`` (``eqx.error_if``) and runs with the program."""
    ka, kb = known_value(a), known_value(b)
    if ka is not None and kb is not None:
        if not float(ka) <= float(kb):
            raise error(f"{name_a} = {float(ka):g} exceeds {name_b} = {float(kb):g}; {rule}")
        return a, b
    b = jnp.asarray(b)  # an array to thread the check on (b may be a Python number while a is traced)
    return a, eqx.error_if(b, ~(jnp.asarray(a) <= b), f"{name_a} exceeds {name_b}; {rule} ({_RUNTIME})")
