"""Laplacian eigenpairs ``Wφ = λAφ`` (thesis §2.5.2, eq. 2.5.34).

Shift-invert Lanczos (``scipy.sparse.linalg.eigsh``) around a slightly
negative shift ``σ = −1e-8·s`` (``s`` a spectral scale of ``A⁻¹W``), with one
sparse LU factorisation of ``W − σA``, which is non-singular even though ``W``
has a kernel (one constant per connected component). Works with a
non-diagonal (FEM) ``A``.

Performance note (measured on the shared 2-core machine): ARPACK's dense
work goes through OpenBLAS, whose worker threads contend with other processes;
``OPENBLAS_NUM_THREADS=1`` made ``eigenbasis`` 5–15× faster there (icosphere with
10 242 vertices, k = 50: 0.54 s vs 3.9–8.9 s). This module does not change
thread settings (a global side effect); set the variable before starting Python.
"""

from __future__ import annotations

import time
from typing import Callable, NamedTuple

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from jaxtyping import Float

from stiefel.solvers.driver import Progress
from stiefel.manifolds.signs import canonical_signs
from stiefel.linalg.sparse_factor import SymmetricFactor
from stiefel.validation import check_finite, check_number, is_integer

from .errors import MeshError
from .laplacian import Laplacian

__all__ = ["Eigenbasis", "eigenbasis", "EigenInputError"]


class EigenInputError(MeshError):
    """The eigenproblem cannot be posed: ``k`` is not an integer in ``[1, n − 1]``, an option is out of
    range, or ``W``/``A`` has NaN or infinite entries."""


class Eigenbasis(NamedTuple):
    """The first ``k`` eigenpairs; unpacks as ``evals, evecs = eigenbasis(lap, k)``.

    Attributes:
      evals: ``(k,)`` ascending eigenvalues ``λ_1 ≤ … ≤ λ_k`` (Rem. 2.5.29).
      evecs: ``(n, k)`` eigenvectors, ``ΦᵀAΦ = I`` (Prop. 2.5.28); each column's
        entry of largest magnitude is positive (a permutation-equivariant sign).
    """

    evals: Float[np.ndarray, " k"]
    evecs: Float[np.ndarray, "n k"]


def _spectral_scale(lap: Laplacian) -> float:
    """A scale of ``A⁻¹W``'s spectrum: ``max_i W_ii / A_ii`` (≥ λ_max/2 by Geršgorin, Prop. 2.5.21)."""
    a = lap.mass_diagonal
    w = lap.W.diagonal()
    return float(np.max(np.abs(w) / np.maximum(np.abs(a), np.finfo(float).tiny)))


def _check_inputs(lap: Laplacian, k, sigma, tol, seed) -> None:
    """Everything ``eigenbasis`` needs, before any factorisation (``EigenInputError`` naming the cause)."""
    n = lap.n
    if not is_integer(k) or not 1 <= int(k) < n:
        raise EigenInputError(
            f"k must be an integer with 1 ≤ k < n = {n} (ARPACK's shift-invert Lanczos needs k < n; there is "
            f"no dense fallback: for all n eigenpairs of a small mesh use scipy.linalg.eigh(W.toarray(), "
            f"A.toarray())), got k = {k!r}")
    if sigma is not None:
        check_number("sigma (None: −1e-8·s)", sigma, error=EigenInputError)
    check_number("tol (0: machine precision)", tol, low=0, finite=False, error=EigenInputError)
    if not is_integer(seed) or seed < 0:
        raise EigenInputError(f"seed must be an integer ≥ 0, got {seed!r}")
    for name, M in (("W", lap.W), ("A", lap.A)):
        check_finite(name, M, error=EigenInputError)


class _Reporter:
    """Counts the shift-invert solves of an ARPACK run and reports them (``eigenbasis(progress=)``)."""

    def __init__(self, progress: Callable, interval: float = 0.25):
        self.progress, self.interval = progress, interval
        self.count, self.t0, self.last = 0, time.perf_counter(), float("-inf")

    def wrap(self, op: spla.LinearOperator) -> spla.LinearOperator:
        def matvec(x):
            self.count += 1
            self.tick()
            return op.matvec(x)

        return spla.LinearOperator(op.shape, matvec=matvec, dtype=op.dtype)

    def tick(self, final: bool = False) -> None:
        now = time.perf_counter()
        if final or now - self.last >= self.interval:
            self.last = now
            self.progress(Progress(iteration=self.count, max_iters=0, objective=float("nan"),
                                   grad_norm=float("nan"), elapsed=now - self.t0,
                                   remaining=0.0 if final else None, method="eigsh"))


def eigenbasis(
    lap: Laplacian,
    k: int,
    *,
    sigma: float | None = None,
    tol: float = 0.0,
    seed: int = 0,
    progress: Callable | None = None,
) -> Eigenbasis:
    """The first ``k`` generalised eigenpairs of ``Wφ = λAφ``, A-orthonormal, ascending.

    Args:
      lap: the Laplacian (``W``, ``A`` of shape ``(n, n)``).
      k: number of eigenpairs, an integer with ``1 ≤ k < n``.
      sigma: shift (default ``−1e-8·s``, ``s`` a spectral scale).
      tol: ARPACK tolerance (0: machine precision).
      seed: seeds ARPACK's start vector (deterministic results).
      progress: optional ``progress(stiefel.Progress)``, at most every 0.25 s while ARPACK iterates and
        once at the end: ``iteration`` counts the shift-invert solves (Lanczos steps; ``max_iters`` 0:
        no fixed cap), objective and gradient norm are NaN (ARPACK reports no residual on the way),
        ``method="eigsh"``.

    Returns:
      ``Eigenbasis(evals (k,), evecs (n, k))``.

    Raises:
      EigenInputError: (a ``MeshError``) before any work, when ``k`` is not an integer in ``[1, n − 1]``
        (``bool`` refused; ARPACK needs ``k < n`` and there is no dense fallback), ``sigma`` is not
        finite, ``tol < 0``, or ``W``/``A`` has NaN/inf entries.
    """
    _check_inputs(lap, k, sigma, tol, seed)
    n, k = lap.n, int(k)
    W = sp.csc_matrix(lap.W, dtype=np.float64)
    A = sp.csc_matrix(lap.A, dtype=np.float64)
    if sigma is None:
        sigma = -1e-8 * _spectral_scale(lap)
    op_inv = SymmetricFactor(W - sigma * A, check=False).as_linear_operator()
    report = None if progress is None else _Reporter(progress)
    if report is not None:
        op_inv = report.wrap(op_inv)
    v0 = np.random.default_rng(seed).standard_normal(n)
    ncv = min(n, max(3 * k, 30))
    evals, evecs = spla.eigsh(
        W, k=k, M=A, sigma=sigma, which="LM", OPinv=op_inv, v0=v0, tol=tol, ncv=ncv
    )
    if report is not None:
        report.tick(final=True)
    order = np.argsort(evals)
    evals, evecs = evals[order], evecs[:, order]
    # A-orthonormalise (ARPACK's vectors are A-orthogonal to working precision; this
    # makes it exact within repeated eigenvalues, e.g. the kernel of a multi-component mesh)
    gram = evecs.T @ (A @ evecs)
    gram = 0.5 * (gram + gram.T)
    C = sla.cholesky(gram, lower=False)
    evecs = sla.solve_triangular(C, evecs.T, trans="T", lower=False).T
    return Eigenbasis(evals=evals, evecs=canonical_signs(evecs))  # the largest-magnitude entry of each column is positive
