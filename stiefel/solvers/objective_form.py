"""One objective signature for every solver entry point: ``F(X)``, or ``F(X, args)`` as ``optx.minimise`` calls it.

``stiefel.minimize(F, S, X0)`` and ``optx.minimise(fn, solver, X0, args)`` take the same functions: an ``F(X, args)``
written for optimistix is called with ``args`` (None when not given), an ``F(X)`` without it. A signature that fits
neither — no argument, three required ones, one argument while ``args=`` is given — is an
``ObjectiveSignatureError`` at the call, naming the signature, before anything is traced.
"""

from __future__ import annotations

import inspect
from typing import Any, Callable

from ..errors import ObjectiveSignatureError

__all__ = ["takes_args"]

_POSITIONAL = (inspect.Parameter.POSITIONAL_ONLY, inspect.Parameter.POSITIONAL_OR_KEYWORD)


def _label(F: Callable, sig: inspect.Signature) -> str:
    name = getattr(F, "__name__", None) or type(F).__name__
    return f"{name}{sig}"


def takes_args(F: Callable, args: Any) -> bool:
    """True when ``F`` is to be called ``F(X, args)``, False for ``F(X)`` (module docstring). An ``F`` whose signature
    cannot be read (some C callables) is called ``F(X, args)`` when ``args`` is given, else ``F(X)``."""
    if not callable(F):
        raise ObjectiveSignatureError(f"the objective must be callable, F(X) or F(X, args); got {type(F).__name__}")
    try:
        sig = inspect.signature(F)
    except (TypeError, ValueError):
        return args is not None
    params = list(sig.parameters.values())
    positional = [p for p in params if p.kind in _POSITIONAL]
    required = [p for p in positional if p.default is inspect.Parameter.empty]
    varargs = any(p.kind == inspect.Parameter.VAR_POSITIONAL for p in params)
    keyword_only = [p.name for p in params
                    if p.kind == inspect.Parameter.KEYWORD_ONLY and p.default is inspect.Parameter.empty]
    most = float("inf") if varargs else len(positional)
    if keyword_only or len(required) > 2 or most == 0:
        raise ObjectiveSignatureError(
            f"the objective {_label(F, sig)} does not fit F(X) or F(X, args): the solvers call it with the point "
            "and, for optimistix-style functions, args (pass extra parameters through args, or bind them with "
            "functools.partial)")
    if args is not None:
        if most < 2:
            raise ObjectiveSignatureError(
                f"args= was given but the objective {_label(F, sig)} takes only the point; write it as F(X, args) "
                "or drop args")
        return True
    return len(required) == 2
