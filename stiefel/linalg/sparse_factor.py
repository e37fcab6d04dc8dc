"""One host-side factorisation recipe for sparse symmetric positive definite matrices.

Every sparse solve in the toolkit (the ``M⁻¹`` and preconditioner solves of
``SparseOperator``, shift-invert eigensolvers, GLMH bases, ADMM's E-step) goes
through ``SymmetricFactor``, a sparse Cholesky or ``LDLᵀ`` factorisation with three
backends:

* ``"cholmod"`` (default when the ``cholespy`` package is installed; it is a
  dependency): CHOLMOD's supernodal Cholesky with its own fill-reducing ordering,
  which solves all right-hand sides of a block at once (level-3 BLAS). Measured on
  this project's 2-core CPU (``W + 10A``, 10 right-hand sides, against QDLDL):
  fandisk 1.1 vs 4.3 ms per solve batch, camelhead 2.9 vs 6.7 ms, armadillo_25479
  4.6 vs 13.1 ms; one right-hand side 0.23 vs 0.38 ms (fandisk); the factorisation
  itself is 1.8–2.8× slower (fandisk 37 vs 20 ms), so callers that factor often and
  solve one column per factor (``objectives.cmm.active_set``) ask for ``"qdldl"``.
  Cholesky exists only for positive definite matrices: with ``check=False`` an
  indefinite matrix (e.g. a shift inside the spectrum) is factored by QDLDL
  instead, and ``backend`` says so.
* ``"qdldl"`` (a dependency): QDLDL's ``LDLᵀ`` with its AMD ordering; handles
  symmetric quasi-definite (indefinite) matrices. Measured against SuperLU on this
  project's 2-core CPU (``W + A``, 10 right-hand sides): camelhead 6.5 vs 10.6 ms per solve batch,
  armadillo_25479 12.7 vs 22.3 ms, factorisation 2–4× faster.
* ``"superlu"`` (scipy, always available): the matrix is renumbered by reverse
  Cuthill–McKee, then SuperLU orders it by minimum degree on ``S + Sᵀ`` in
  symmetric mode with diagonal pivots only. Both choices were measured: partial
  pivoting destroys the fill-reducing order (armadillo_25479: 19 s instead of
  0.4 s), and the minimum-degree ordering is pathologically slow on some input
  orders (an icosphere of 41k vertices: 74 s as given, 0.3 s after RCM).

With ``check=True`` a failed Cholesky factorisation, an ``LDLᵀ`` with a
non-positive pivot (or, for SuperLU, one that needed off-diagonal pivoting) raises
``NotSPDError`` (Sylvester: a symmetric matrix is positive definite exactly when
every pivot of its ``LDLᵀ`` is, and exactly when its Cholesky factor exists).
"""

from __future__ import annotations

import atexit
import contextlib
import os
import sys
import weakref

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from jaxtyping import Float
from scipy.sparse.csgraph import reverse_cuthill_mckee

from ..errors import NotSPDError

__all__ = ["SymmetricFactor", "BACKENDS", "default_backend", "ldl_backend"]

BACKENDS = ("cholmod", "qdldl", "superlu")


def _importable(module: str) -> bool:
    try:
        __import__(module)
    except ImportError:
        return False
    return True


def default_backend() -> str:
    """``"cholmod"`` when ``cholespy`` imports, else ``"qdldl"`` when ``qdldl`` does, else ``"superlu"``."""
    if _importable("cholespy"):
        return "cholmod"
    return "qdldl" if _importable("qdldl") else "superlu"


def ldl_backend() -> str:
    """The ``LDLᵀ`` backend for matrices that may be indefinite: ``"qdldl"`` if installed, else ``"superlu"``."""
    return "qdldl" if _importable("qdldl") else "superlu"


@contextlib.contextmanager
def _quiet_stderr():
    """Silence C-level writes to stderr (CHOLMOD prints a warning before it reports failure)."""
    try:
        sys.stderr.flush()
        fd = os.dup(2)
    except (OSError, ValueError):  # no real stderr (embedded interpreters)
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(fd, 2)
        os.close(fd)


_LIVE_CHOLMOD: "weakref.WeakSet[SymmetricFactor]" = weakref.WeakSet()


@atexit.register
def _release_cholmod_factors() -> None:
    """Free the CHOLMOD factors still referenced at exit (e.g. by JAX's compile caches) before the
    interpreter tears the extension down; otherwise nanobind reports them as leaks on stderr."""
    for factor in list(_LIVE_CHOLMOD):
        factor._chol = None


def _cholmod(csr: sp.csr_matrix):
    """A CHOLMOD factor of the SPD ``csr`` (cholespy), or None when it is not positive definite."""
    from cholespy import CholeskySolverD, MatrixType

    coo = csr.tocoo()
    with _quiet_stderr():
        try:
            return CholeskySolverD(csr.shape[0], coo.row.astype(np.int32), coo.col.astype(np.int32),
                                   np.ascontiguousarray(coo.data, dtype=np.float64), MatrixType.COO)
        except ValueError:  # "Matrix is not positive definite!"
            return None


class SymmetricFactor:
    """``b ↦ S⁻¹b`` for a sparse symmetric ``S`` (``(n, n)``), factored once at construction.

    Args:
      S: any ``scipy.sparse`` matrix (or dense array), symmetric.
      reorder: (SuperLU) renumber by reverse Cuthill–McKee before SuperLU's own ordering.
      check: raise ``NotSPDError`` unless the factorisation proves ``S`` positive definite.
      backend: ``"cholmod"``, ``"qdldl"``, ``"superlu"`` or None (``default_backend()``).

    ``backend`` holds the backend that did the factorisation (``"qdldl"`` after a
    ``"cholmod"`` request on an indefinite matrix with ``check=False``).
    """

    def __init__(self, S, *, reorder: bool = True, check: bool = True, backend: str | None = None):
        backend = backend or default_backend()
        if backend not in BACKENDS:
            raise ValueError(f"unknown backend {backend!r}; choose one of {BACKENDS}")
        self.backend = backend
        csr = sp.csr_matrix(S, dtype=np.float64)
        self.n = csr.shape[0]
        self.perm = None
        self._chol = None
        if backend == "cholmod":
            self._chol = _cholmod(csr)
            if self._chol is None:
                if check:
                    raise NotSPDError("M is not positive definite: its sparse Cholesky factorisation failed")
                backend = self.backend = ldl_backend()  # indefinite (check=False): LDLᵀ instead
            else:
                self._pivots, self._nnz, self._solve1 = None, None, None
                _LIVE_CHOLMOD.add(self)
                return
        if backend == "qdldl":
            import qdldl

            try:
                self._qdldl = qdldl.Solver(sp.csc_matrix(sp.triu(csr)), upper=True)
            except RuntimeError as exc:  # zero pivot or structurally empty diagonal
                raise NotSPDError(f"M is singular: sparse factorisation failed ({exc}); M must be SPD") from exc
            L, D, _ = self._qdldl.factors()
            self._pivots, self._nnz, self._solve1 = np.asarray(D), 2 * int(L.nnz) + self.n, self._qdldl.solve
        else:
            self.perm = reverse_cuthill_mckee(csr, symmetric_mode=True) if reorder else None
            if self.perm is not None:
                csr = csr[self.perm][:, self.perm]
            try:
                lu = spla.splu(sp.csc_matrix(csr), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                               options={"SymmetricMode": True})
            except RuntimeError as exc:  # exactly singular
                raise NotSPDError(f"M is singular: sparse factorisation failed ({exc}); M must be SPD") from exc
            if check and not np.array_equal(lu.perm_r, lu.perm_c):
                raise NotSPDError("M is not positive definite: the factorisation needed off-diagonal pivoting")
            self._pivots, self._nnz, self._solve1 = lu.U.diagonal(), int(lu.L.nnz + lu.U.nnz), lu.solve
        if check and not np.all(self._pivots > 0):
            bad = int(np.sum(self._pivots <= 0))
            raise NotSPDError(f"M is not positive definite: {bad} non-positive pivot(s) in its LDLᵀ "
                              f"factorisation (smallest {self._pivots.min():.3e})")

    @property
    def nnz(self) -> int | None:
        """Stored entries of the two triangular factors (fill-in measure); None for CHOLMOD (not exposed)."""
        return self._nnz

    def solve(self, b: Float[np.ndarray, "n ..."]) -> Float[np.ndarray, "n ..."]:
        """``S⁻¹b`` for ``b`` of shape ``(n,)`` or ``(n, ...)`` (float64).

        CHOLMOD solves all right-hand sides at once; the ``LDLᵀ`` backends one column at a
        time (SuperLU's multi-right-hand-side solve was slower: fandisk, 20 columns,
        104 ms vs 27 ms).
        """
        b = np.asarray(b, dtype=np.float64)
        flat = b.reshape(self.n, -1)
        if self._chol is not None:
            rhs = flat[:, 0] if flat.shape[1] == 1 else flat
            if not (rhs.flags.c_contiguous and rhs.flags.writeable):  # cholespy takes writeable C arrays only
                rhs = np.array(rhs, order="C")
            x = np.empty_like(rhs)
            self._chol.solve(rhs, x)
            return x.reshape(b.shape)
        if self.perm is not None:
            flat = flat[self.perm]
        out = np.empty(flat.shape, dtype=np.float64, order="F")
        for j in range(flat.shape[1]):
            out[:, j] = self._solve1(np.ascontiguousarray(flat[:, j]))
        if self.perm is not None:
            res = np.empty_like(out)
            res[self.perm] = out
            out = res
        return out.reshape(b.shape)

    __call__ = solve

    def as_linear_operator(self) -> spla.LinearOperator:
        """The inverse as a ``scipy.sparse.linalg.LinearOperator`` (e.g. ``OPinv`` for ``eigsh``)."""
        return spla.LinearOperator((self.n, self.n), matvec=self.solve, matmat=self.solve, dtype=np.float64)
