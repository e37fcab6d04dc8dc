"""Ahead-of-time compile a pure solver core, so compile time and run time are measured apart."""

from __future__ import annotations

import time
from functools import partial

import equinox as eqx
import jax
import numpy as np


def _captured(obj, depth: int = 3) -> list:
    """Values a callable closes over (closure cells, ``functools.partial`` arguments, ``__self__``)."""
    if depth == 0 or not callable(obj):
        return []
    out = list(getattr(obj, "args", ()) or ()) + list((getattr(obj, "keywords", None) or {}).values())
    for cell in getattr(obj, "__closure__", None) or ():
        try:
            out.append(cell.cell_contents)
        except ValueError:  # an empty cell
            continue
    if getattr(obj, "__self__", None) is not None:
        out.append(obj.__self__)
    for value in list(out):
        out.extend(_captured(value, depth - 1))
    return out


def is_traced(*trees) -> bool:
    """Whether a JAX transformation is tracing this call: a tracer among the leaves of ``trees`` or
    among the values their callables close over, or (where JAX exposes it) an active trace."""
    try:
        from jax._src.core import trace_state_clean  # noqa: PLC0415

        if not trace_state_clean():
            return True
    except ImportError:  # not in every JAX version: the leaves below still catch the usual cases
        pass
    leaves = jax.tree_util.tree_leaves(trees)
    for leaf in list(leaves):
        leaves.extend(jax.tree_util.tree_leaves(_captured(leaf)))
    return any(isinstance(leaf, jax.core.Tracer) for leaf in leaves)


#: XLA options of a program that runs once or twice (a saddle check): the backend's optimisation
#: passes cost more than they save there (measured on example:patch, k = 10, under load: the saddle check's LOBPCG
#: 7.9 → 2.7 s to compile, its run and the solution unchanged to the last digit); the solver loop keeps them
#: (without: 6.5 → 4.2 s to compile but 5.8 → 8.8 s to run)
ONE_SHOT_OPTIONS = {"xla_backend_optimization_level": 0}


def compile_lowered(lowered, *, optimize: bool = True):
    """``lowered.compile()``; with ``optimize=False`` the ``ONE_SHOT_OPTIONS`` (per program: no global state)."""
    return lowered.compile() if optimize else lowered.compile(compiler_options=dict(ONE_SHOT_OPTIONS))


@partial(jax.jit, static_argnums=(1,))
def _call(dynamic, static):
    fn, static_args = static
    return fn(*eqx.combine(dynamic, static_args))


def run_compiled(fn, *args, optimize: bool = True):
    """Run ``fn(*args)`` jitted; return ``(out, compile_seconds, run_seconds)``.

    Arrays in ``args`` are traced; everything else (callables, options, static
    fields of manifolds) is static and must be hashable. JAX caches both the
    lowering and the executable, so a repeated call with the same static parts
    and shapes costs no compilation (and reports ~0 compile time). ``optimize=False``: compiled with
    ``ONE_SHOT_OPTIONS`` (for programs run once or twice).
    """
    dynamic, static_args = eqx.partition(args, eqx.is_array)
    t0 = time.perf_counter()
    compiled = compile_lowered(_call.lower(dynamic, (fn, static_args)), optimize=optimize)
    t1 = time.perf_counter()
    out = compiled(dynamic)
    out = jax.block_until_ready(out)
    t2 = time.perf_counter()
    return out, t1 - t0, t2 - t1


def compile_aot(fn, *args, optimize: bool = True):
    """Trace, lower and compile ``fn(*args)`` once (arrays traced, the rest static, as in ``run_compiled``);
    return a callable taking arguments of the same structure (new array values) that runs the executable.
    ``optimize=False``: ``ONE_SHOT_OPTIONS``."""
    dynamic, static_args = eqx.partition(args, eqx.is_array)
    compiled = compile_lowered(_call.lower(dynamic, (fn, static_args)), optimize=optimize)

    def call(*new_args):
        return compiled(eqx.partition(new_args, eqx.is_array)[0])

    return call


def host_array(x, dtype=None):
    """``jnp.asarray(x, dtype)`` for host data without compiling anything.

    In jax 0.10 ``jnp.asarray`` of a numpy array compiles a small staging program per shape and dtype
    (and a conversion to another dtype one more): a dozen such compilations cost 0.3–0.8 s at the start
    of a solve. ``jax.device_put`` of a numpy array (converted on the host) compiles nothing; Python
    scalars keep their weak type as with ``jnp.asarray``. JAX arrays and tracers are passed through
    (``astype`` when a dtype is asked for).
    """
    if isinstance(x, jax.Array):
        return x if dtype is None or x.dtype == np.dtype(dtype) else x.astype(dtype)
    if dtype is None:
        return jax.device_put(x if isinstance(x, (bool, int, float, complex)) else np.asarray(x))
    return jax.device_put(np.asarray(x, dtype=dtype))
