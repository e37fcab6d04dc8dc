"""Symmetric linear operators for the metric matrix ``M`` (and any sparse ``W``).

A manifold or solver never asks whether ``M`` is diagonal, dense or sparse: it
calls ``op.mv(X)`` (``M @ X``) and ``op.solve(Y)`` (``M⁻¹ Y``) on arrays of
shape ``(n,)`` or ``(n, k)``. Three implementations:

* ``DiagonalOperator`` — ``M = diag(d)``; O(nk) products and solves.
* ``DenseOperator`` — a dense SPD matrix, Cholesky-factored once.
* ``SparseOperator`` — a ``scipy.sparse`` matrix stored as a padded
  neighbour table ("ELL": ``(n, w)`` column indices and values, ``w`` the
  largest row length). ``mv`` is ``w`` fused gathers with no scatter, which on
  CPU beat BCOO and ``segment_sum`` (see ``docs/benchmarks/cmm.md``). ``solve``
  uses one sparse factorisation computed on the host at construction
  (``stiefel.linalg.ffi_solve``: CHOLMOD as an XLA custom call through ``sparsax``, when JAX's x64 mode is
  on — no Python callback, so compiled solvers are served from JAX's persistent cache; otherwise
  ``stiefel.linalg.sparse_factor.SymmetricFactor`` — CHOLMOD, QDLDL or SuperLU — on the host through
  ``jax.pure_callback``), inside ``lax.custom_linear_solve``, so it is jittable and differentiable.
  The matrix is never densified.

``as_operator`` builds the right one and, with ``check=True``, validates that
the matrix is symmetric positive definite (raising ``NotSPDError``).
"""

from __future__ import annotations

from typing import Any

import hashlib
from functools import partial

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from jax.custom_derivatives import SymbolicZero
from jaxtyping import Array, Float, Int

from . import ffi_solve
from ..runtime.compilation import host_array
from .ell import ell_matvec
from ..errors import NotSPDError, ShapeError
from .sparse_factor import SymmetricFactor
from ..validation import check_finite

__all__ = [
    "LinearOperator",
    "DiagonalOperator",
    "IdentityOperator",
    "DenseOperator",
    "SparseOperator",
    "as_operator",
    "quadratic_form",
]


class LinearOperator(eqx.Module):
    """A symmetric ``(n, n)`` linear operator acting on ``(n,)`` or ``(n, k)`` arrays."""

    @property
    def n(self) -> int:
        raise NotImplementedError

    def mv(self, x: Float[Array, "n ..."]) -> Float[Array, "n ..."]:
        """``M @ x``."""
        raise NotImplementedError

    def solve(self, y: Float[Array, "n ..."]) -> Float[Array, "n ..."]:
        """``M⁻¹ @ y`` (only for SPD operators)."""
        raise NotImplementedError

    def diagonal(self) -> Float[Array, " n"]:
        raise NotImplementedError

    def __matmul__(self, x):
        return self.mv(x)


class DiagonalOperator(LinearOperator):
    """``M = diag(d)``."""

    d: Float[Array, " n"]

    @property
    def n(self) -> int:
        return self.d.shape[0]

    def _bcast(self, x):
        return self.d.reshape(self.d.shape + (1,) * (x.ndim - 1))

    def mv(self, x):
        return self._bcast(x) * x

    def solve(self, y):
        return y / self._bcast(y)

    def diagonal(self):
        return self.d


class IdentityOperator(LinearOperator):
    """``M = I`` (the ordinary Stiefel manifold): products and solves return their argument.

    ``size`` may be None (unknown until a point is seen): then only ``n`` and ``diagonal`` — which
    need it — raise ``ShapeError``.
    """

    size: int | None = eqx.field(static=True, default=None)
    dtype: Any = eqx.field(static=True, default=None)

    @property
    def n(self) -> int:
        if self.size is None:
            raise ShapeError("this identity metric (the ordinary Stiefel manifold) was built without n; pass "
                             "GeneralizedStiefel(None, k, n=n) to draw random points or check point shapes")
        return self.size

    def mv(self, x):
        return x

    def solve(self, y):
        return y

    def diagonal(self):
        return jnp.ones((self.n,), dtype=self.dtype)


class DenseOperator(LinearOperator):
    """A dense symmetric matrix with its lower Cholesky factor ``L`` (``M = L Lᵀ``) when SPD.

    ``chol=None`` gives a product-only operator (e.g. a singular stiffness matrix W).
    """

    matrix: Float[Array, "n n"]
    chol: Float[Array, "n n"] | None = None

    @property
    def n(self) -> int:
        return self.matrix.shape[0]

    def mv(self, x):
        return self.matrix @ x

    def solve(self, y):
        if self.chol is None:
            raise ValueError("this DenseOperator has no Cholesky factor (built for products only); no solve")
        return jax.scipy.linalg.cho_solve((self.chol, True), y)

    def diagonal(self):
        return jnp.diagonal(self.matrix)


def _fingerprint(csr: sp.csr_array) -> str:
    """A content hash of a CSR matrix (shape, structure and values)."""
    h = hashlib.blake2b(digest_size=16)
    h.update(np.asarray(csr.shape, dtype=np.int64).tobytes())
    for part in (csr.indptr, csr.indices, csr.data):
        h.update(np.ascontiguousarray(part).tobytes())
    return h.hexdigest()


class _ByContent:
    """Static-field base: equal (and equally hashed) when the matrices behind are equal, so JAX's
    compile cache recognises a new operator built from the same matrix (no recompilation)."""

    key: tuple

    def __hash__(self):
        return hash(self.key)

    def __eq__(self, other):
        return type(other) is type(self) and other.key == self.key


class _HostFactor(_ByContent):
    """Host-side factorisation of a symmetric matrix (a static field, compared by the matrix's content)."""

    def __init__(self, factor: SymmetricFactor, dtype: np.dtype, fingerprint: str = ""):
        self.factor = factor
        self.dtype = dtype
        self.key = ("lu", fingerprint or str(id(self)), np.dtype(dtype).str)

    def __call__(self, b: np.ndarray) -> np.ndarray:
        # Host callbacks see JAX's *global* x64 flag: under the thread-local
        # ``jax.enable_x64`` context the argument may arrive as float32. Return the
        # traced dtype regardless; for full float64 accuracy set the global flag.
        return self.factor.solve(b).astype(self.dtype, copy=False)

    def batched(self, b: np.ndarray, ndim: int) -> np.ndarray:
        """Solve for ``b`` of shape ``batch + (n, ...)``: the ``b.ndim − ndim`` leading axes are a
        ``vmap`` batch (``vmap_method="expand_dims"``), moved behind ``n`` so one host call solves
        every batch member (the same solves, one callback instead of one per member)."""
        lead = b.ndim - ndim
        if lead == 0:
            return self(b)
        moved = np.moveaxis(np.asarray(b), tuple(range(lead)), tuple(range(-lead, 0)))
        out = self(moved)
        return np.moveaxis(out, tuple(range(-lead, 0)), tuple(range(lead)))


class SparseOperator(LinearOperator):
    """A sparse symmetric matrix as a padded neighbour table (ELL format).

    ``cols[i, j]`` is the column of the ``j``-th stored entry of row ``i`` and
    ``vals[i, j]`` its value (padding: column ``i``, value 0). ``chol`` (the matrix as CHOLMOD
    custom-call arrays, ``stiefel.linalg.ffi_solve``) or ``factor`` (a host factorisation behind a
    callback) serves ``solve``; at most one is set.
    """

    cols: Int[Array, "n w"]
    vals: Float[Array, "n w"]
    chol: ffi_solve.CholeskyArrays | None = None
    factor: Any = eqx.field(static=True, default=None)
    csr: Any = eqx.field(static=True, default=None)
    vmap_method: str = eqx.field(static=True, default="sequential")

    @classmethod
    def from_scipy(cls, matrix, *, factor: bool = False, dtype=None, vmap_method: str = "sequential",
                   solve_backend: str | None = None, width: int | None = None,
                   factor_size: int | None = None) -> "SparseOperator":
        """Build from any ``scipy.sparse`` matrix; ``factor=True`` prepares ``solve`` (and checks that
        the matrix is positive definite: ``NotSPDError``).

        ``solve_backend``: ``"ffi"`` (CHOLMOD as an XLA custom call, ``stiefel.linalg.ffi_solve``; needs
        sparsax and JAX's x64 mode), ``"callback"`` (a host factorisation behind ``jax.pure_callback``)
        or None (``"ffi"`` where available). ``vmap_method`` is how the callback batches under
        ``jax.vmap``: ``"sequential"`` (one host call per batch member) or ``"expand_dims"`` (one
        host call for the whole batch; ``bench/bench_batch.py`` compares them); the custom call
        always solves a batch in one native call.

        ``width`` and ``factor_size`` are lower bounds for the neighbour table's width and the custom
        call's number of stored entries (padding that changes nothing but the shapes: operators of
        different matrices with equal shapes share one compiled program, ``stiefel.runtime.buckets``).
        """
        if vmap_method not in ("sequential", "expand_dims"):
            raise ValueError(f"vmap_method must be 'sequential' or 'expand_dims', got {vmap_method!r}")
        csr = sp.csr_array(matrix)
        csr.sum_duplicates()
        csr.sort_indices()
        n = csr.shape[0]
        dtype = np.dtype(dtype or (jnp.float64 if jax.config.jax_enable_x64 else jnp.float32))
        lengths = np.diff(csr.indptr)
        width = max(int(lengths.max(initial=0)), 1, int(width or 0))
        rows = np.repeat(np.arange(n), lengths)
        slot = np.arange(csr.nnz) - np.repeat(csr.indptr[:-1], lengths)
        cols = np.tile(np.arange(n)[:, None], (1, width))
        vals = np.zeros((n, width), dtype=np.float64)
        cols[rows, slot] = csr.indices
        vals[rows, slot] = csr.data
        if solve_backend not in (None, "ffi", "callback"):
            raise ValueError(f"solve_backend must be 'ffi', 'callback' or None, got {solve_backend!r}")
        if solve_backend == "ffi" and not ffi_solve.available():
            raise ValueError("solve_backend='ffi' needs the sparsax package and JAX's x64 mode "
                             "(jax.config.update('jax_enable_x64', True))")
        host, chol = None, None
        if factor and solve_backend != "callback" and ffi_solve.available():
            chol = ffi_solve.CholeskyArrays.from_scipy(csr, size=factor_size)
        elif factor:
            host = _HostFactor(SymmetricFactor(csr), dtype, _fingerprint(csr))
        return cls(  # converted on the host: a dtype conversion on the device would compile a program
            cols=host_array(cols, np.int32),
            vals=host_array(vals, dtype),
            chol=chol,
            factor=host,
            csr=_Frozen(csr),
            vmap_method=vmap_method,
        )

    @property
    def n(self) -> int:
        return self.cols.shape[0]

    @property
    def width(self) -> int:
        return self.cols.shape[1]

    def to_scipy(self) -> sp.csr_array:
        """The matrix as ``scipy.sparse.csr_array`` (as given, float64)."""
        return self.csr.value

    def mv(self, x):
        return ell_matvec(self.vals, self.cols, x)  # w gathers, no scatter; batches per member (stiefel.linalg.ell)

    def solve(self, y):
        if self.chol is not None:
            chol = self.chol
            return jax.lax.custom_linear_solve(self.mv, y, lambda _matvec, b: chol.solve(b), symmetric=True)
        if self.factor is None:
            raise ValueError("this SparseOperator was built without factor=True; no solve available")
        host, method = self.factor, self.vmap_method

        def _callback_solve(_matvec, b):
            shape = jax.ShapeDtypeStruct(b.shape, b.dtype)
            if method == "sequential":
                return jax.pure_callback(host, shape, b, vmap_method="sequential")
            return jax.pure_callback(partial(host.batched, ndim=b.ndim), shape, b, vmap_method="expand_dims")

        return jax.lax.custom_linear_solve(self.mv, y, _callback_solve, symmetric=True)

    def diagonal(self):
        is_diag = self.cols == jnp.arange(self.n)[:, None]
        return jnp.sum(jnp.where(is_diag, self.vals, 0.0), axis=1)


class _Frozen(_ByContent):
    """Wraps a host CSR matrix as a static pytree field, compared by content (host-only: no compiled
    program reads it, ``stiefel.runtime.program_cache``)."""

    program_irrelevant = True

    def __init__(self, value):
        self.value = value
        self.key = ("csr", _fingerprint(value))


def _check_symmetric(asym: float, scale: float, what: str) -> None:
    if asym > 1e-10 * max(scale, np.finfo(float).tiny):
        raise NotSPDError(f"{what} is not symmetric: max|M − Mᵀ| = {asym:.3e} (max|M| = {scale:.3e})")


def as_operator(M, *, check: bool = True, factor: bool = True, dtype=None, width: int | None = None,
                factor_size: int | None = None) -> LinearOperator:
    """Wrap ``M`` as a ``LinearOperator``.

    Args:
      M: a 1-D array (the diagonal), a dense ``(n, n)`` array, a
        ``scipy.sparse`` matrix, or a ``LinearOperator`` (returned unchanged). A traced JAX array
        (inside ``jax.grad``/``jit``) gives a diagonal or dense operator without host checks, so
        solutions can be differentiated with respect to M.
      check: validate symmetry and positive definiteness (raises ``NotSPDError``). NaN or infinite
        entries are refused whatever ``check`` (``NonFiniteError``; O(nnz)).
      factor: for sparse M, factor it once so that ``solve`` works.
      dtype: floating dtype of the stored values (default: float64 if x64 is on).
      width, factor_size: for sparse M, lower bounds of the stored shapes (``SparseOperator.from_scipy``;
        size buckets, ``stiefel.runtime.buckets``).
    """
    if isinstance(M, LinearOperator):
        return M
    dtype = np.dtype(dtype or (jnp.float64 if jax.config.jax_enable_x64 else jnp.float32))
    if isinstance(M, jax.core.Tracer):  # a traced M (e.g. differentiated): no host checks, no host factorisation
        if M.ndim == 1:
            return DiagonalOperator(M.astype(dtype))
        if M.ndim == 2 and M.shape[0] == M.shape[1]:
            return DenseOperator(M.astype(dtype), jnp.linalg.cholesky(0.5 * (M + M.T)).astype(dtype))
        raise ShapeError(f"a traced M must be 1-D (diagonal) or square 2-D, got shape {M.shape}")
    if sp.issparse(M):
        if M.ndim != 2 or M.shape[0] != M.shape[1]:
            raise ShapeError(f"M must be square, got shape {M.shape}")
        csr = sp.csr_array(M, dtype=np.float64)
        check_finite("M", csr)
        if check:
            scale = float(abs(csr).max()) if csr.nnz else 0.0
            asym = float(abs(csr - csr.T).max()) if csr.nnz else 0.0
            _check_symmetric(asym, scale, "M")
            if np.any(csr.diagonal() <= 0):
                raise NotSPDError("M is not positive definite: it has a non-positive diagonal entry")
            if not factor:
                SymmetricFactor(csr)
        return SparseOperator.from_scipy(csr, factor=factor, dtype=dtype, width=width, factor_size=factor_size)
    arr = np.asarray(M, dtype=np.float64)
    check_finite("M", arr)
    if arr.ndim == 1:
        if check:
            if np.any(arr <= 0):
                i = int(np.argmin(arr))
                raise NotSPDError(f"diagonal M must be positive: M[{i}] = {arr[i]:.3e}")
        return DiagonalOperator(host_array(arr, dtype))
    if arr.ndim == 2:
        if arr.shape[0] != arr.shape[1]:
            raise ShapeError(f"M must be square, got shape {arr.shape}")
        if check:
            _check_symmetric(float(np.max(np.abs(arr - arr.T))), float(np.max(np.abs(arr))), "M")
        try:
            chol = np.linalg.cholesky(0.5 * (arr + arr.T))
        except np.linalg.LinAlgError as exc:
            raise NotSPDError("M is not positive definite: its Cholesky factorisation failed") from exc
        return DenseOperator(jnp.asarray(arr, dtype=dtype), jnp.asarray(chol, dtype=dtype))
    raise ShapeError(f"M must be 1-D (diagonal), 2-D (dense) or scipy.sparse, got ndim={arr.ndim}")



def _total(Y: Array) -> Array:
    """``Σ Y`` as a product with a ones vector (see ``_pairing``)."""
    if Y.ndim == 0:
        return Y
    if Y.ndim == 1:
        return jnp.ones_like(Y) @ Y
    flat = Y.reshape(Y.shape[0], -1)
    return jnp.sum(jnp.ones(flat.shape[0], flat.dtype) @ flat)


def _pairing(X: Array, Y: Array) -> Array:
    """``tr(XᵀY) = Σ X∘Y`` in the form the CPU backend runs fastest after a gather matvec.

    Measured (jax 0.10 CPU, armadillo_25479, k = 10, ``Y = W.mv(X)``; value / value-and-gradient
    of ``tr(XᵀWX)``): ``jnp.sum(X * Y)`` 9.6 / – ms (lowered to a library reduce fused with the
    gathers), ones-vector product 0.9 / 5.3 ms (each gather written out for two consumers),
    ``jnp.vdot`` 13 / 1.3 ms, ``tr(XᵀY)`` 1.0 / 1.1 ms, against 0.5 ms for the matvec alone.
    ``tr(XᵀY)`` costs ``nk²`` flops, so it is used for ``k ≤ 32`` only.
    """
    if X.ndim == 2 and X.shape[1] <= 32:
        return jnp.trace(X.T @ Y)
    if X.ndim == 1:
        return X @ Y
    return _total(X * Y)


@jax.custom_jvp
def _quadratic_form(op: LinearOperator, X: Array) -> Array:
    return _pairing(X, op.mv(X))


def _quadratic_form_jvp(primals, tangents):
    op, X = primals
    d_op, dX = tangents
    WX = op.mv(X)
    value = _pairing(X, WX)
    tangent = jnp.zeros_like(value)
    if not isinstance(dX, SymbolicZero):
        tangent = tangent + 2.0 * _pairing(dX, WX)  # symmetric operator: d tr(XᵀWX) = 2 tr(dXᵀWX)
    leaves = jax.tree_util.tree_leaves(d_op, is_leaf=lambda t: isinstance(t, SymbolicZero))
    if any(not isinstance(t, SymbolicZero) for t in leaves):  # derivative with respect to the operator
        d_op = jax.tree_util.tree_map(
            lambda t: np.zeros(t.aval.shape, t.aval.dtype) if isinstance(t, SymbolicZero) else t, d_op,
            is_leaf=lambda t: isinstance(t, SymbolicZero))
        tangent = tangent + jax.jvp(lambda o: _pairing(X, o.mv(X)), (op,), (d_op,))[1]
    return value, tangent


_quadratic_form.defjvp(_quadratic_form_jvp, symbolic_zeros=True)


def quadratic_form(op: LinearOperator, X: Float[Array, "n *k"]) -> Float[Array, ""]:
    """``tr(XᵀOX)`` (``xᵀOx`` for a column) for a symmetric operator ``O``; a scalar.

    Differentiable in ``X`` and in the operator's arrays; the derivative in ``X`` is
    ``2·O X`` from the forward product (a custom JVP), so reverse mode never transposes
    ``SparseOperator``'s gathers into scatters (armadillo_25479, k = 10: the plain
    ``jax.grad`` of ``jnp.sum(X * W.mv(X))`` took ~40 ms, the rule ~1 ms; see ``_pairing``).
    """
    return _quadratic_form(op, X)
