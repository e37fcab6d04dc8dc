"""Sparse SPD solves as XLA custom calls (CHOLMOD through ``sparsax``), with no Python callback.

``SparseOperator.solve`` used to reach CHOLMOD through ``jax.pure_callback``. A computation that
contains a host callback is never served from JAX's persistent compilation cache (measured, jax
0.10: every new process compiled the solver loop again), and a callback cannot be interrupted or
report progress without one more callback. ``sparsax`` exposes CHOLMOD as an XLA FFI custom call:
the matrix is three runtime arrays (upper-triangle COO rows, columns, values), the symbolic
analysis and the numeric factor are cached inside the extension (keyed on the pattern and a hash
of the values), so a solve inside a compiled loop factors once and then only substitutes.

Measured on this project's 2-core CPU (``W + 10A``, 10 right-hand sides, jitted, best of 5):
fandisk (n = 7229) 1.9–3.3 ms with CHOLMOD's simplicial factor against 6.0–7.4 ms supernodal and
2.1–2.8 ms through the callback; armadillo_25479 6.3–6.5 ms simplicial, 20.5 ms supernodal, 6.7–7.7 ms
callback. ``sparsax`` leaves the choice to CHOLMOD ("auto" picked supernodal here), so the first
``CholeskyArrays`` built switches sparsax to simplicial factors (``sparsax.set_options``; this
changes sparsax's own setting for the process, never JAX's configuration). Set
``STIEFEL_SPARSAX_MODE`` to ``auto``, ``simplicial`` or ``supernodal`` to choose another, or to
``off`` to keep the host callback.

sparsax computes in float64 and needs JAX's x64 mode: without it (or without sparsax installed)
``available()`` is False and ``SparseOperator`` keeps its host-callback solve.
"""

from __future__ import annotations

import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from jaxtyping import Array, Float, Int

from ..runtime.compilation import host_array
from ..errors import NotSPDError

__all__ = ["CholeskyArrays", "available", "MODE_ENV"]

MODE_ENV = "STIEFEL_SPARSAX_MODE"
#: the custom-call targets of ``CholeskyArrays.solve`` (allowed in stored programs, ``stiefel.runtime.program_cache``)
CUSTOM_CALLS = ("sparsax_solve_f64",)
_MODES = ("simplicial", "auto", "supernodal")
_configured: list[str] = []


def _sparsax():
    """The ``sparsax`` module, configured once (``MODE_ENV``), or None when it is missing or switched off."""
    mode = os.environ.get(MODE_ENV, "simplicial").strip().lower() or "simplicial"
    if mode == "off":
        return None
    try:
        import sparsax
    except ImportError:
        return None
    if mode not in _MODES:
        raise ValueError(f"{MODE_ENV} must be one of {_MODES + ('off',)}, got {mode!r}")
    if not _configured or _configured[-1] != mode:
        sparsax.set_options(supernodal=mode)
        _configured.append(mode)
    return sparsax


def available() -> bool:
    """Whether sparse solves can run as XLA custom calls here (sparsax installed and JAX's x64 mode on)."""
    return bool(jax.config.jax_enable_x64) and _sparsax() is not None


@jax.jit
def _probe(rows, cols, vals, b):
    return _sparsax().solve(rows, cols, vals, b)


class CholeskyArrays(eqx.Module):
    """A sparse SPD matrix ``S (n, n)`` as the upper-triangle COO arrays a CHOLMOD custom call takes.

    rows, cols: ``(nnz_upper,)`` int32 with ``rows ≤ cols``; vals: ``(nnz_upper,)`` float64. All three
    are runtime leaves: two matrices of the same shapes share one compiled program.
    """

    rows: Int[Array, " m"]
    cols: Int[Array, " m"]
    vals: Float[Array, " m"]
    n: int = eqx.field(static=True)

    @classmethod
    def from_scipy(cls, S, *, check: bool = True, size: int | None = None) -> "CholeskyArrays":
        """The upper triangle of ``S``; with ``check``, factor it once now (``NotSPDError`` if CHOLMOD
        finds it indefinite). The factor stays in sparsax's cache, so the first solve inside a compiled
        loop does not factor again. ``size``: at least this many stored entries — the extra ones lie
        below the diagonal (row n−1, column 0, value 0), which CHOLMOD ignores (only ``rows ≤ cols`` is
        read), so only the arrays' shapes change (``stiefel.runtime.buckets``)."""
        up = sp.triu(sp.csr_array(S, dtype=np.float64)).tocoo()
        n = int(S.shape[0])
        rows, cols, vals = up.row, up.col, up.data
        extra = max(0, int(size or 0) - up.nnz)
        if extra and n < 2:
            raise ValueError("padding the stored entries of a sparse factor needs n ≥ 2")
        if extra:
            rows = np.concatenate([rows, np.full(extra, n - 1)])
            cols = np.concatenate([cols, np.zeros(extra, cols.dtype)])
            vals = np.concatenate([vals, np.zeros(extra)])
        out = cls(rows=host_array(rows, np.int32), cols=host_array(cols, np.int32),
                  vals=host_array(vals, np.float64), n=n)
        if check:
            try:
                jax.block_until_ready(_probe(out.rows, out.cols, out.vals, np.zeros((n,), np.float64)))
            except Exception as exc:  # jax.errors.JaxRuntimeError: "matrix is not positive definite"
                if "positive definite" not in str(exc):
                    raise
                raise NotSPDError(f"M is not positive definite: its sparse Cholesky factorisation "
                                  f"failed ({' '.join(str(exc).split())[:160]})") from None
        return out

    def solve(self, b: Float[Array, "n ..."]) -> Float[Array, "n ..."]:
        """``S⁻¹b`` for ``b (n,)`` or ``(n, ...)``, in ``b``'s dtype (computed in float64)."""
        flat = b.reshape(self.n, -1).astype(jnp.float64)
        x = _sparsax().solve(self.rows, self.cols, self.vals, flat[:, 0] if flat.shape[1] == 1 else flat)
        return x.reshape(b.shape).astype(b.dtype)
