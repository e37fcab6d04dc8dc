"""JAX's persistent compilation cache for the CLI: compile a solver once per machine, not once per run.

The CLI (an application, not the library) turns the cache on before the first compilation:
``--cache-dir DIR`` > ``$STIEFEL_CACHE_DIR`` > the user's cache directory (``platformdirs``, e.g.
``~/.cache/stiefel/jax`` on Linux); ``--no-cache`` (or ``STIEFEL_CACHE_DIR=off``) leaves it off. Every compilation is cached
(also the small ones: the thresholds ``jax_persistent_cache_min_compile_time_secs`` and
``jax_persistent_cache_min_entry_size_bytes`` are set to 0). A directory that exists and can be read
but not written (a read-only cache, e.g. one shared by an administrator) is used read-only, without a
word: compiled executables and stored programs are loaded from it, and nothing is written (JAX's
minimum compile time for writing is set to infinity; ``stiefel.runtime.program_cache`` finds the
directory unwritable and keeps new programs in memory). A directory that cannot be created or read
gives one warning line and the run goes on without the cache. A corrupt stored program is rejected
by ``stiefel.runtime.program_cache`` (verified by key and SHA-256, counted in ``summary.json``'s
``stored_programs``); an unreadable or corrupt XLA executable is JAX's business: it warns and
compiles again.

Library users turn the same cache on in their own programs with::

    jax.config.update("jax_compilation_cache_dir", "/path/to/cache")
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)

(the library itself never changes JAX's configuration). Only programs without Python host
callbacks are cached; the solvers' sparse solves are XLA custom calls for that reason
(``stiefel.linalg.ffi_solve``).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["ENV", "default_dir", "enable"]

ENV = "STIEFEL_CACHE_DIR"


def default_dir() -> Path:
    """``$STIEFEL_CACHE_DIR`` if set, else ``<user cache dir>/stiefel/jax``."""
    env = os.environ.get(ENV, "").strip()
    if env:
        return Path(env).expanduser()
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("stiefel", appauthor=False)) / "jax"


def _readable(path: Path) -> bool:
    """Whether ``path`` is a directory whose files can be listed and read."""
    return path.is_dir() and os.access(path, os.R_OK | os.X_OK)


def _writable(path: Path) -> str | None:
    """None when ``path`` exists (or was created) and a file can be written in it, else the reason."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path, prefix=".probe-", delete=True):
            pass
    except OSError as e:
        return e.strerror or type(e).__name__
    return None


def _disable() -> None:
    """No persistent cache for this run, also after an earlier in-process run that turned it on."""
    import jax

    if jax.config.jax_compilation_cache_dir:
        from jax.experimental.compilation_cache import compilation_cache

        jax.config.update("jax_compilation_cache_dir", None)
        compilation_cache.reset_cache()


def enable(cache_dir: Path | None, disabled: bool) -> tuple[str | None, str | None]:
    """Turn JAX's persistent compilation cache on (before any compilation), read-only where the directory
    cannot be written; return ``(directory used or None, warning or None)``."""
    if disabled or (cache_dir is None and os.environ.get(ENV, "").strip().lower() == "off"):
        _disable()
        return None, None
    path = Path(cache_dir).expanduser() if cache_dir is not None else default_dir()
    why = _writable(path)
    if why is not None and not _readable(path):
        _disable()
        return None, f"compilation cache {path} is not usable ({why}); running without it"
    import jax
    from jax.experimental.compilation_cache import compilation_cache

    jax.config.update("jax_compilation_cache_dir", str(path))
    # read-only: JAX writes an executable only when its compilation took at least this long, i.e. never
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0 if why is None else float("inf"))
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    compilation_cache.reset_cache()  # JAX decides once whether to use a cache: let it decide again (``main`` in-process)
    return str(path), None
