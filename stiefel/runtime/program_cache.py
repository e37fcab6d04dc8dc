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
backend, the equinox and optimistix versions and the JAX flags that change tracing.

**A stored program is verified by content, not by its file name.** A file is ``MAGIC``, one line of
JSON (``{"format", "key", "sha256", "size"}``) and the serialised program. ``key`` is the complete
key material the program was made for (the file name is only its hash): the source digest, the
versions above, this library's version, the description of the function and its arguments and the
number of outputs. The loader reads a program only when ``key`` equals the caller's and the SHA-256
of the program bytes equals ``sha256``; only then are the bytes handed to JAX's deserialiser (which
prints MLIR's errors on the C-level stderr when fed corrupt bytes). A file that fails any check —
another program's file copied under this name, corrupt bytes, an older format, a program that does
not deserialise or compile — is *rejected*: counted in ``STATS["rejected"]`` (by reason in
``REJECTIONS``), reported in one ``logging`` INFO line (logger ``stiefel.runtime.program_cache``;
silent unless the application asks for INFO), traced afresh and stored over it. Nothing reaches
stderr: what the deserialiser prints while reading a file that passed both checks is held back and
dropped when it fails (passed on when it succeeds). Files are written atomically (a temporary file in
the same directory, then a rename); a directory that cannot be written (a read-only cache) is still
read, and programs traced in it are simply not stored (``STATS["stored"]`` counts the writes).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import json
import logging
import os
import sys
import tempfile
import threading
import types
from collections import Counter, OrderedDict
from importlib import metadata
from pathlib import Path
from typing import Any, Callable

import equinox as eqx
import jax
import numpy as np

from .compilation import compile_lowered

__all__ = ["describe", "Uncacheable", "load_or_export", "store_dir", "SUBDIR", "STATS", "REJECTIONS"]

SUBDIR = "stiefel-programs"
MAGIC = b"stiefel-program\n"  # a stored file's first line (files of earlier versions lack it: rejected)
FORMAT = 2
_PACKAGES = ("stiefel", "objectives", "mesh")
_MEMORY: OrderedDict = OrderedDict()  # key -> compiled callable (this process)
_MEMORY_SIZE = 32
_LOCK = threading.Lock()
_FD2_LOCK = threading.Lock()  # one holder of the C-level stderr at a time
_LOG = logging.getLogger(__name__)
#: counts of this process's programs: from memory, loaded from the store (verified), stored files rejected,
#: exported (traced) and stored (written; not in a read-only store)
STATS = {"memory": 0, "loaded": 0, "rejected": 0, "exported": 0, "stored": 0}
#: the rejected files of this process by reason (``"another program's key"``, ``"digest mismatch"``, ...)
REJECTIONS: Counter = Counter()


class Uncacheable(Exception):
    """A static part that ``describe`` cannot pin down (the program is traced as usual)."""


class _Rejected(Exception):
    """A stored file that is not the program asked for: ``reason`` (counted), ``detail`` (the log line)."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(reason)
        self.reason, self.detail = reason, detail


@functools.lru_cache(maxsize=1)
def _source_digest() -> str:
    """A hash of this project's Python sources, every module of ``_PACKAGES`` (any edit gives new keys)."""
    root = Path(__file__).resolve().parents[2]
    h = hashlib.blake2b(digest_size=16)
    for pkg in _PACKAGES:
        for path in sorted((root / pkg).rglob("*.py")):
            h.update(path.relative_to(root).as_posix().encode())
            h.update(b"\0")
            h.update(path.read_bytes())
    return h.hexdigest()


@functools.lru_cache(maxsize=1)
def _library_version() -> str:
    try:
        return metadata.version("stiefel-cmm")
    except metadata.PackageNotFoundError:
        return "-"


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


def _key_material(fn: Callable, args: tuple) -> dict | None:
    """Everything the program ``fn(*args)`` is made of, as stored in its file (None when a static part is not
    describable): ``name`` (its hash, the file name), the source digest, the versions and the description."""
    try:
        text = describe(fn) + "|" + describe(args)
    except Exception:  # noqa: BLE001 — Uncacheable, or anything describe did not foresee: not stored
        return None
    sources, versions = _source_digest(), _versions()
    h = hashlib.blake2b(digest_size=20)
    for part in (sources, versions, text):
        h.update(part.encode())
        h.update(b"\0")
    return {"name": h.hexdigest(), "sources": sources, "versions": versions, "library": _library_version(),
            "program": text}


def program_key(fn: Callable, args: tuple) -> str | None:
    """The store key of ``fn(*args)`` (None when a static part is not describable)."""
    material = _key_material(fn, args)
    return None if material is None else material["name"]


def _encode(key: dict, program: bytes) -> bytes:
    """A stored file: ``MAGIC``, the JSON header (the key and the program's SHA-256 and size), the program."""
    header = {"format": FORMAT, "key": key, "sha256": hashlib.sha256(program).hexdigest(), "size": len(program)}
    return MAGIC + json.dumps(header, sort_keys=True, ensure_ascii=True).encode() + b"\n" + program


def _decode(data: bytes, key: dict) -> bytes:
    """The program bytes of the stored file ``data`` when it was made for ``key`` and its digest matches;
    ``_Rejected`` otherwise."""
    if not data.startswith(MAGIC):
        raise _Rejected("unknown format", "not a stored program of this version (an older format, or another file)")
    end = data.find(b"\n", len(MAGIC))
    try:
        header = json.loads(data[len(MAGIC):end]) if end > 0 else None
    except ValueError:
        header = None
    if not isinstance(header, dict) or header.get("format") != FORMAT:
        raise _Rejected("unknown format", "its header is not readable")
    stored = header.get("key")
    if stored != key:
        stored = stored if isinstance(stored, dict) else {}
        differ = sorted(k for k in set(key) | set(stored) if stored.get(k) != key.get(k))
        raise _Rejected("another program's key", f"made for another program (its {', '.join(differ)} differ)")
    program = data[end + 1:]
    if header.get("size") != len(program) or header.get("sha256") != hashlib.sha256(program).hexdigest():
        raise _Rejected("digest mismatch", f"its program does not match the SHA-256 in its header (corrupt or "
                                           f"truncated: {len(program)} bytes, {header.get('size')} stored)")
    return program


def _flush_stderr() -> None:
    with contextlib.suppress(Exception):  # a closed or replaced stream: nothing to flush
        sys.stderr.flush()


@contextlib.contextmanager
def _c_stderr_held():
    """While the block runs, what anything in the process writes to file descriptor 2 (MLIR's deserialiser
    prints its errors there) goes to a temporary file; the list yielded receives those bytes afterwards.
    Without a file descriptor 2, nothing is held."""
    held: list[bytes] = []
    with _FD2_LOCK, contextlib.ExitStack() as stack:
        _flush_stderr()
        try:
            tmp = stack.enter_context(tempfile.TemporaryFile())
            saved = os.dup(2)
        except OSError:
            saved = None
        if saved is None:
            yield held
            return
        stack.callback(os.close, saved)
        os.dup2(tmp.fileno(), 2)
        try:
            yield held
        finally:
            _flush_stderr()
            os.dup2(saved, 2)
            tmp.seek(0)
            held.append(tmp.read())


def _lower(program: bytes, leaves: list, n_out: int):
    """``jax.jit(exported.call).lower(*leaves)`` for verified program bytes (lowering parses the program's MLIR
    module); ``_Rejected`` when JAX cannot read them or the program's inputs and outputs differ from the call's.
    What is printed meanwhile (MLIR's errors) is dropped when it fails and passed on to stderr when it succeeds
    (it may be another thread's output)."""
    from jax import export  # noqa: PLC0415

    error = None
    with _c_stderr_held() as held:
        try:
            exported = export.deserialize(bytearray(program))
            if (len(exported.in_avals) != len(leaves) or len(exported.out_avals) != n_out
                    or any(a.shape != np.shape(x) or a.dtype != x.dtype for a, x in zip(exported.in_avals, leaves))):
                raise _Rejected("different shapes", "its inputs or outputs differ from the call's")
            lowered = jax.jit(exported.call).lower(*leaves)
        except _Rejected as r:
            error = r
        except Exception as e:  # noqa: BLE001 — e.g. an incompatible program: traced afresh
            why = "".join(c if c.isprintable() else "?" for c in " ".join(f"{type(e).__name__}: {e}".split()))
            error = _Rejected("undeserialisable", f"JAX cannot read it ({why[:120]})")
    printed = b"".join(held)
    if error is not None:  # what was printed is dropped; the exception's first words name the failure
        raise error
    if printed:
        os.write(2, printed)
    return lowered


def _reject(path: Path, rejected: _Rejected) -> None:
    STATS["rejected"] += 1
    REJECTIONS[rejected.reason] += 1
    detail = " ".join((rejected.detail or rejected.reason).split())
    _LOG.info("stored program %s discarded: %s; traced again", path.name, detail)


def _load(path: Path, key: dict, leaves: list, n_out: int, optimize: bool = True):
    """The compiled program stored at ``path`` for ``key``, verified; None when there is none or it is rejected
    (counted)."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return None
    except OSError as e:
        _reject(path, _Rejected("unreadable", f"not readable ({e.strerror or type(e).__name__})"))
        return None
    try:
        lowered = _lower(_decode(data, key), leaves, n_out)
    except _Rejected as r:
        _reject(path, r)
        return None
    try:
        return compile_lowered(lowered, optimize=optimize)
    except Exception:  # noqa: BLE001 — e.g. a custom call this process lacks: traced afresh
        _reject(path, _Rejected("not compilable", "it does not compile here"))
        return None


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


def load_or_export(fn: Callable, args: tuple, out_template: Any, *, custom_calls: tuple[str, ...] = (),
                   optimize: bool = True):
    """A compiled ``fn(*args)`` (a callable taking arguments of the same structure) from this process's
    memory or the store (verified: module docstring), or traced, exported and stored now; None when the
    program is not cacheable (no store, an undescribable static part, or ``jax.export`` failing) — the caller
    then compiles as usual. ``out_template``: a pytree with the structure of ``fn``'s output (the store keeps
    the flat program only). ``custom_calls``: custom-call targets to allow in the exported program.
    ``optimize=False``: compiled with ``compilation.ONE_SHOT_OPTIONS`` (a program run once)."""
    where = store_dir()
    if where is None:
        return None
    key = _key_material(fn, args)
    if key is None:
        return None
    name = key["name"]
    with _LOCK:
        if name in _MEMORY:
            _MEMORY.move_to_end(name)
            STATS["memory"] += 1
            return _MEMORY[name]
    from jax import export  # noqa: PLC0415

    leaves, in_tree = jax.tree_util.tree_flatten(eqx.filter(args, eqx.is_array))
    static = eqx.filter(args, eqx.is_array, inverse=True)
    out_tree = jax.tree_util.tree_structure(out_template)
    key["outputs"] = out_tree.num_leaves
    path = where / f"{name}.jaxexport"
    compiled = _load(path, key, leaves, out_tree.num_leaves, optimize)
    if compiled is not None:
        STATS["loaded"] += 1
    else:
        def flat(*flat_leaves):
            dynamic = jax.tree_util.tree_unflatten(in_tree, list(flat_leaves))
            out = fn(*eqx.combine(dynamic, static))
            out_leaves, tree = jax.tree_util.tree_flatten(out)
            if tree != out_tree:
                raise Uncacheable(f"output structure {tree} differs from the template {out_tree}")
            return tuple(out_leaves)

        try:
            checks = [export.DisabledSafetyCheck.custom_call(c) for c in custom_calls]
            exported = export.export(jax.jit(flat), disabled_checks=checks)(*leaves)
            data = bytes(exported.serialize())
        except Exception:  # noqa: BLE001 — e.g. flatbuffers missing, an unlisted custom call
            return None
        STATS["exported"] += 1
        try:
            compiled = compile_lowered(jax.jit(exported.call).lower(*leaves), optimize=optimize)
        except Exception:  # noqa: BLE001 — the caller traces and compiles as usual (and reports real errors)
            return None
        try:
            _write_atomic(path, _encode(key, data))
            STATS["stored"] += 1
        except OSError:
            pass  # a read-only or full store: the program still runs

    def call(*new_args):
        new_leaves = jax.tree_util.tree_leaves(eqx.filter(new_args, eqx.is_array))
        return jax.tree_util.tree_unflatten(out_tree, compiled(*new_leaves))

    with _LOCK:
        _MEMORY[name] = call
        while len(_MEMORY) > _MEMORY_SIZE:
            _MEMORY.popitem(last=False)
    return call
