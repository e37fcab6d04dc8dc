"""Compiled solver programs kept across processes without tracing them again (``jax.export``).

JAX's persistent compilation cache saves XLA's work, but every new process still traces and lowers
the solver (0.5–0.7 s for the CMM block solver on this project's 2-core machine) before the cache
can be asked. Here the lowered program itself is stored with ``jax.export`` next to that cache
(``<jax_compilation_cache_dir>/stiefel-programs``) under a key that pins everything the program
depends on; a later process deserialises it (milliseconds), lowers the call (tens of milliseconds)
and gets the executable from JAX's cache.

Only when JAX's persistent cache is on (``jax_compilation_cache_dir`` set; the library never sets
it, the CLI does) and only for programs whose static parts are *described* completely by
``describe``: this project's own functions and modules (their source files are part of the key),
strings, numbers, None and arrays (by shape and dtype). A user's own objective function, a host
callback or anything unknown makes the program uncached (traced as before), so a stored program can
never stand in for different code. The key also holds the JAX, jaxlib and sparsax versions, the
backend, the equinox and optimistix versions and the JAX flags that change tracing. An unreadable or corrupt entry is ignored (traced
and stored again); entries are written atomically.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import os
import tempfile
import threading
import types
from collections import OrderedDict
from pathlib import Path
from typing import Any, Callable

import equinox as eqx
import jax
import numpy as np

__all__ = ["describe", "Uncacheable", "load_or_export", "store_dir", "SUBDIR", "STATS"]

SUBDIR = "stiefel-programs"
_PACKAGES = ("stiefel", "objectives", "mesh")
_MEMORY: OrderedDict = OrderedDict()  # key -> compiled callable (this process)
_MEMORY_SIZE = 32
_LOCK = threading.Lock()
#: counts of this process's programs: from memory, loaded from the store, exported (traced) and stored
STATS = {"memory": 0, "loaded": 0, "exported": 0}


class Uncacheable(Exception):
    """A static part that ``describe`` cannot pin down (the program is traced as usual)."""


@functools.lru_cache(maxsize=1)
def _source_digest() -> str:
    """A hash of this project's Python sources (any edit gives new keys)."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.blake2b(digest_size=16)
    for pkg in _PACKAGES:
        for path in sorted((root / pkg).glob("*.py")):
            h.update(path.name.encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def _ours(obj) -> bool:
    module = getattr(obj, "__module__", "") or ""
    return module.split(".")[0] in _PACKAGES


def describe(obj, depth: int = 0, embedded: bool = False) -> str:
    """A description of ``obj`` that is the same in every process exactly when its effect on a traced
    program is: arrays by shape and dtype (program inputs; by content where ``embedded``, i.e. inside
    a static field, whose arrays become constants of the program), plain values by ``repr``, this
    project's modules field by field and its functions by name. Raises ``Uncacheable`` for anything
    else."""
    if depth > 40:
        raise Uncacheable("nested too deeply")
    d = functools.partial(describe, depth=depth + 1, embedded=embedded)
    if obj is None or isinstance(obj, (bool, int, str, bytes, np.dtype)):
        return repr(obj)
    if isinstance(obj, float):
        return repr(float(obj))
    if isinstance(obj, (jax.Array, np.ndarray, np.generic, jax.ShapeDtypeStruct)):
        weak = getattr(obj, "weak_type", False)
        text = f"a{tuple(np.shape(obj))}{np.dtype(obj.dtype).str}{'w' if weak else ''}"
        if embedded and not isinstance(obj, jax.ShapeDtypeStruct):
            text += hashlib.blake2b(np.ascontiguousarray(np.asarray(obj)).tobytes(), digest_size=16).hexdigest()
        return text
    if isinstance(obj, tuple) and hasattr(obj, "_fields") and _ours(type(obj)):  # our NamedTuples
        return f"{type(obj).__qualname__}(" + ",".join(d(v) for v in obj) + ")"
    if isinstance(obj, (tuple, list)):
        return ("(" if isinstance(obj, tuple) else "[") + ",".join(d(v) for v in obj) + ")"
    if isinstance(obj, dict):
        return "{" + ",".join(f"{d(k)}:{d(v)}" for k, v in sorted(obj.items(), key=repr)) + "}"
    if getattr(obj, "program_irrelevant", False):  # host-only data (e.g. SparseOperator.csr)
        return f"<{type(obj).__qualname__}>"
    if isinstance(obj, types.MethodType) or type(obj).__name__ == "BoundMethod":
        func = getattr(obj, "__func__", None) or getattr(obj, "__wrapped__", None)
        name = getattr(func, "__qualname__", None) or getattr(obj, "__qualname__", "?")
        # equinox's BoundMethod is a pytree (its object's arrays are program inputs); a plain bound
        # method is a leaf, so its object's arrays would be constants of the program
        inner = embedded or isinstance(obj, types.MethodType)
        return f"{describe(obj.__self__, depth + 1, inner)}.{name}"
    if isinstance(obj, functools.partial):
        return f"partial({d(obj.func)},{d(obj.args)},{d(obj.keywords)})"
    if isinstance(obj, types.FunctionType):
        if not _ours(obj) or obj.__closure__ or "<lambda>" in obj.__qualname__ or "<locals>" in obj.__qualname__:
            raise Uncacheable(f"function {obj.__module__}.{obj.__qualname__}")
        return f"{obj.__module__}.{obj.__qualname__}"
    if isinstance(obj, type):
        if not _ours(obj):
            raise Uncacheable(f"type {obj!r}")
        return f"{obj.__module__}.{obj.__qualname__}"
    if isinstance(obj, eqx.Module) and _ours(type(obj)):
        fields = ",".join(f"{f.name}={describe(getattr(obj, f.name), depth + 1, embedded or bool(f.metadata.get('static')))}"
                          for f in dataclasses.fields(obj))
        return f"{type(obj).__module__}.{type(obj).__qualname__}({fields})"
    raise Uncacheable(f"{type(obj).__module__}.{type(obj).__qualname__}")


def store_dir() -> Path | None:
    """``<jax_compilation_cache_dir>/stiefel-programs``, or None when JAX's persistent cache is off."""
    base = jax.config.jax_compilation_cache_dir
    if not base or not jax.config.jax_enable_compilation_cache:
        return None
    return Path(base) / SUBDIR


def _versions() -> str:
    try:
        import sparsax  # noqa: PLC0415

        sparsax_version = sparsax.__version__
    except ImportError:
        sparsax_version = "-"
    import jaxlib  # noqa: PLC0415
    import optimistix  # noqa: PLC0415

    flags = (jax.config.jax_enable_x64, jax.config.jax_default_matmul_precision,
             jax.config.jax_numpy_dtype_promotion, jax.config.jax_numpy_rank_promotion)
    return (f"{jax.__version__}|{jaxlib.__version__}|{eqx.__version__}|{optimistix.__version__}|{sparsax_version}|"
            f"{jax.default_backend()}|{flags}")


def program_key(fn: Callable, args: tuple) -> str | None:
    """The store key of ``fn(*args)`` (None when a static part is not describable)."""
    try:
        text = describe(fn) + "|" + describe(args)
    except Exception:  # noqa: BLE001 — Uncacheable, or anything describe did not foresee: not stored
        return None
    h = hashlib.blake2b(digest_size=20)
    for part in (_source_digest(), _versions(), text):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


def _write_atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".part")
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def load_or_export(fn: Callable, args: tuple, out_template: Any, *, custom_calls: tuple[str, ...] = ()):
    """A compiled ``fn(*args)`` (a callable taking arguments of the same structure) from this process's
    memory or the store, or traced, exported and stored now; None when the program is not cacheable
    (no store, an undescribable static part, or ``jax.export`` failing) — the caller then compiles as
    usual. ``out_template``: a pytree with the structure of ``fn``'s output (the store keeps the flat
    program only). ``custom_calls``: custom-call targets to allow in the exported program."""
    where = store_dir()
    if where is None:
        return None
    key = program_key(fn, args)
    if key is None:
        return None
    with _LOCK:
        if key in _MEMORY:
            _MEMORY.move_to_end(key)
            STATS["memory"] += 1
            return _MEMORY[key]
    from jax import export  # noqa: PLC0415

    leaves, in_tree = jax.tree_util.tree_flatten(eqx.filter(args, eqx.is_array))
    static = eqx.filter(args, eqx.is_array, inverse=True)
    out_tree = jax.tree_util.tree_structure(out_template)
    path = where / f"{key}.jaxexport"
    exported = None
    try:
        exported = export.deserialize(bytearray(path.read_bytes()))
        avals = [jax.ShapeDtypeStruct(np.shape(x), x.dtype) for x in leaves]
        if (len(exported.in_avals) != len(avals) or len(exported.out_avals) != out_tree.num_leaves
                or any(a.shape != b.shape or a.dtype != b.dtype for a, b in zip(exported.in_avals, avals))):
            exported = None
    except Exception:  # noqa: BLE001 — missing, unreadable or corrupt: trace and store again
        exported = None
    if exported is None:
        def flat(*flat_leaves):
            dynamic = jax.tree_util.tree_unflatten(in_tree, list(flat_leaves))
            out = fn(*eqx.combine(dynamic, static))
            out_leaves, tree = jax.tree_util.tree_flatten(out)
            if tree != out_tree:
                raise Uncacheable(f"output structure {tree} differs from the template {out_tree}")
            return tuple(out_leaves)

        try:
            checks = [export.DisabledSafetyCheck.custom_call(name) for name in custom_calls]
            exported = export.export(jax.jit(flat), disabled_checks=checks)(*leaves)
            data = exported.serialize()
        except Exception:  # noqa: BLE001 — e.g. flatbuffers missing, an unlisted custom call
            return None
        try:
            _write_atomic(path, bytes(data))
        except OSError:
            pass  # an unwritable store: the program still runs
        STATS["exported"] += 1
    else:
        STATS["loaded"] += 1
    try:
        compiled = jax.jit(exported.call).lower(*leaves).compile()
    except Exception:  # noqa: BLE001 — the caller traces and compiles as usual (and reports real errors)
        return None

    def call(*new_args):
        new_leaves = jax.tree_util.tree_leaves(eqx.filter(new_args, eqx.is_array))
        return jax.tree_util.tree_unflatten(out_tree, compiled(*new_leaves))

    with _LOCK:
        _MEMORY[key] = call
        while len(_MEMORY) > _MEMORY_SIZE:
            _MEMORY.popitem(last=False)
    return call
