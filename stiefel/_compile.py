"""Ahead-of-time compile a pure solver core, so compile time and run time are measured apart."""

from __future__ import annotations

import time
from functools import partial

import equinox as eqx
import jax


@partial(jax.jit, static_argnums=(1,))
def _call(dynamic, static):
    fn, static_args = static
    return fn(*eqx.combine(dynamic, static_args))


def run_compiled(fn, *args):
    """Run ``fn(*args)`` jitted; return ``(out, compile_seconds, run_seconds)``.

    Arrays in ``args`` are traced; everything else (callables, options, static
    fields of manifolds) is static and must be hashable. JAX caches both the
    lowering and the executable, so a repeated call with the same static parts
    and shapes costs no compilation (and reports ~0 compile time).
    """
    dynamic, static_args = eqx.partition(args, eqx.is_array)
    t0 = time.perf_counter()
    compiled = _call.lower(dynamic, (fn, static_args)).compile()
    t1 = time.perf_counter()
    out = compiled(dynamic)
    out = jax.block_until_ready(out)
    t2 = time.perf_counter()
    return out, t1 - t0, t2 - t1
