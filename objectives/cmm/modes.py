"""Compressed manifold modes (thesis Def. 3.2.10, §3.2, §6.5; docs/maths.md §4–5).

``compressed_modes(lap, k, mu, solver=BlockCMM())`` minimises
``tr(ΨᵀWΨ) + μ Σ_ij w_i |Ψ_ij|`` over ``ΨᵀAΨ = I`` and returns the modes with
diagnostics. The method is a solver object (``objectives.cmm.solvers``), each holding only
its own options:

* ``BlockCMM()`` (default) — the smoothed energy over the whole matrix with Riemannian CG
  (``stiefel.minimize``), preconditioned by ``(W + σA)⁻¹`` (σ = λ_{k−1}), with continuation on the
  smoothing parameter (ε, δ from 0.1 to the target in 4 warm-started stages, the first three stopped
  early); the first k eigenfunctions and 3 rotations of them go through those three, the lowest on;
* ``SequentialCMM()`` — thesis Algorithm 6 (``stiefel.minimize_sequential``), same
  preconditioner, column by column (continuation only when asked for);
* ``ADMMCMM(variant="exact" | "thesis")`` / ``SequentialADMMCMM()`` — the ADMM baseline
  (``objectives.admm.splitting``);
* ``FastCMM(U)`` — Algorithm 8 (``objectives.admm.fast.restricted_admm``) on the span of local
  functions ``U`` (e.g. ``mesh.local_functions(m, n_samples=d).U``), started from the restricted
  eigenbasis (Algorithm 7), with ρ = 2λ̄_k (the k-th restricted eigenvalue) unless ``rho`` is given.

The Laplacian ``lap`` is anything with scipy-sparse attributes ``W`` (PSD
stiffness) and ``A`` (diagonal lumped mass), e.g. ``mesh.laplacian(m)``, or a
pair ``(W, A)``; this module imports nothing from ``mesh``.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Callable

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from stiefel.solvers.driver import Progress
from stiefel.errors import NotSPDError, ParameterError, ShapeError
from stiefel.manifolds.signs import canonical_signs
from stiefel.linalg.sparse_factor import SymmetricFactor
from stiefel.validation import (check_count, check_finite, check_full_rank, check_nonnegative, check_number,
                                check_positive, check_unit_interval)

from ..admm.splitting import l1_weights_np, orthonormalize
from ..energy.l1_optimality import l1_stationarity, support_stats
from .certify import certify
from .support_finish import SupportFinish
from .base import SolverRun, _no_callback
from .solvers import SOLVERS, BlockCMM, CMMSolver, SolverOptionError, Start

__all__ = ["CMMResult", "compressed_modes", "select_mu", "METHODS", "unpack_laplacian", "first_eigenpairs"]

METHODS = tuple(SOLVERS)  # the solvers' names, CMMResult.method
WEIGHTINGS = ("area", "uniform")
SPARSITY_THRESHOLDS = ("1e-6", "1e-3")  # the keys of CMMResult.sparsity


@dataclasses.dataclass
class CMMResult:
    """Modes and diagnostics of ``compressed_modes``.

    modes: ``(n, k)`` numpy, A-orthonormal, sorted by compressed eigenvalue.
    compressed_eigenvalues: ``(k,)`` (Def. 3.2.15), ascending.
    objective: the true, non-smooth objective ``dirichlet + l1``.
    dirichlet, l1: its parts (``l1`` includes μ).
    sparsity: fractions of entries with ``|ψ| < 1e-6·max|ψ|`` and ``< 1e-3·max|ψ|``.
    orthogonality: ``max|ΨᵀAΨ − I|``.
    iterations, wall_time (s, compile excluded; includes the preconditioner's and ADMM's
      factorisations and the finish), compile_time, method, params (the arguments; for the ADMM
      methods also ``rho0``, the initial penalty used, and ``step_times``, seconds per step — Ψ/X, E, S,
      dual, residual, objective; for ``BlockCMM`` ``saddles``, its saddle checks, when it made any).
    history: objective trace ``{"time": (T,), "objective": (T,)}`` where available.
    exact_zeros: fraction of entries exactly 0; support_sizes / support_areas: per mode, the number of
      nonzero entries and their share of the total area (``objectives.energy.l1_optimality.support_stats``).
    l1_residual: the exact ℓ1 stationarity residual (docs/maths.md §9, eq. 9.10), relative — the convergence
      measure of the non-smooth problem (meaningful for modes with exact zeros: ``finish`` or ADMM's split).
    status: ``"converged"`` iff the modes were finished and ``l1_residual ≤ finish.tol`` (``objectives.cmm.certify``),
      else the reason; unfinished (``finish=None``, μ = 0, interrupted): the smoothed solver's status.
    finish: when finished (the default), its record (status, the finish's own and the solver's status, tol,
      objective before and after, rounds, Newton and CG iterations, W products, entries added/removed,
      seconds, and ``trace``: per Newton iterate the true objective, the gradient norm on the support and the
      zeros' (9.9) violation relative to the scale of eq. 9.10, support size and CG iterations), else None; smooth_modes: then the solver's own (smoothed) modes, sorted and signed like ``modes``.
    """

    modes: np.ndarray
    compressed_eigenvalues: np.ndarray
    objective: float
    dirichlet: float
    l1: float
    sparsity: dict
    orthogonality: float
    iterations: int
    wall_time: float
    compile_time: float
    status: str
    method: str
    params: dict
    history: dict = dataclasses.field(default_factory=dict)
    exact_zeros: float = 0.0
    support_sizes: list = dataclasses.field(default_factory=list)
    support_areas: list = dataclasses.field(default_factory=list)
    l1_residual: float = float("nan")
    finish: dict | None = None
    smooth_modes: np.ndarray | None = None

    def __repr__(self) -> str:
        """One line: method, status, size, objective, sparsity, iterations and times (no arrays)."""
        n, k = np.shape(self.modes)
        return (f"CMMResult(method={self.method!r}, status={self.status!r}, n={n}, k={k}, "
                f"objective={self.objective:.10g}, sparsity(1e-3)={self.sparsity.get('1e-3', float('nan')):.1%}, "
                f"orthogonality={self.orthogonality:.1e}, iterations={self.iterations}, "
                f"solve {self.wall_time:.3f} s, compile {self.compile_time:.3f} s)")


def unpack_laplacian(lap):
    """``(W csr, a (n,))`` from a Laplacian object (``.W``, ``.A``) or a ``(W, A)`` pair.

    Raises ``ShapeError`` (sizes), ``NonFiniteError`` (NaN/inf in W or A), ``ParameterError`` (A not
    diagonal), ``NotSPDError`` (a non-positive area) — all ``stiefel.StiefelError``, hence ``ValueError``.
    """
    if isinstance(lap, tuple):
        W, A = lap
    else:
        W, A = lap.W, lap.A
    W = sp.csr_array(W, dtype=np.float64)
    check_finite("W", W)
    if sp.issparse(A):
        check_finite("A", A)
        if sp.csr_array(A - sp.diags_array(A.diagonal())).count_nonzero() > 0:
            raise ParameterError("compressed_modes needs a diagonal (lumped) area matrix A; use a lumped mass")
        a = np.asarray(A.diagonal(), dtype=np.float64)
    else:
        A = np.asarray(A, dtype=np.float64)
        check_finite("A", A)
        a = A if A.ndim == 1 else np.diag(A)
    if W.shape[0] != W.shape[1] or W.shape[0] != a.shape[0]:
        raise ShapeError(f"W {W.shape} and A ({a.shape[0]}) do not match")
    if np.any(a <= 0):
        i = int(np.argmin(a))
        raise NotSPDError(f"the area matrix must have positive diagonal entries, got A[{i}, {i}] = {a[i]:.3e}")
    return W, a


def _given_eigenpairs(pairs, n: int, m: int) -> tuple[np.ndarray, np.ndarray]:
    """The first ``m`` of precomputed eigenpairs ``(evals (≥ m,), evecs (n, ≥ m))``, checked."""
    try:
        evals, evecs = pairs
    except (TypeError, ValueError):
        raise ParameterError("eigenpairs must be a pair (evals, evecs)") from None
    evals, evecs = np.asarray(evals, dtype=np.float64), np.asarray(evecs, dtype=np.float64)
    if evals.ndim != 1 or evals.shape[0] < m or evecs.ndim != 2 or evecs.shape[0] != n or evecs.shape[1] < m:
        raise ShapeError(f"eigenpairs must hold at least max(k, 2) = {m} eigenpairs of this Laplacian: evals "
                         f"(≥ {m},), evecs ({n}, ≥ {m}); got {evals.shape} and {evecs.shape}")
    check_finite("eigenpairs (evals)", evals[:m])
    check_finite("eigenpairs (evecs)", evecs[:, :m])
    if np.any(np.diff(evals[:m]) < 0):
        raise ParameterError("eigenpairs: the eigenvalues must be in ascending order")
    return evals[:m], evecs[:, :m]


def first_eigenpairs(W, a, k):
    """The k smallest generalised eigenpairs of ``(W, diag(a))``, A-orthonormal (shift-invert eigsh).

    Deterministic: a fixed Lanczos start vector and a sign convention (the largest-magnitude
    entry of each column is positive), so repeated calls give the same start for the solvers.
    ARPACK needs ``k < n``; ``k = n`` (all eigenpairs of a tiny problem) falls back to a dense
    ``scipy.linalg.eigh``.
    """
    n = W.shape[0]
    check_count("k (eigenpairs)", k, 1, n, high_label=f"n = {n}")
    if k == n:  # ARPACK cannot return all n eigenpairs; n ≤ k is tiny, dense is fine
        vals, vecs = sla.eigh(sp.csr_array(W).toarray(), np.diag(a))
    else:
        scale = float(abs(W).sum() / n) / float(np.mean(a))
        v0 = np.random.default_rng(0).standard_normal(n)  # deterministic: same start, same result
        sigma = -1e-8 * scale
        A = sp.diags_array(a).tocsc()
        OPinv = SymmetricFactor(sp.csc_array(W) - sigma * A, check=False).as_linear_operator()
        vals, vecs = spla.eigsh(sp.csc_array(W), k=k, M=A, sigma=sigma, which="LM", v0=v0, OPinv=OPinv)
    order = np.argsort(vals)
    vals, vecs = vals[order], vecs[:, order]
    return vals, canonical_signs(orthonormalize(vecs, a))  # each column's largest-magnitude entry is positive


def _diagnostics(W, a, mu, weighting, Psi):
    w = l1_weights_np(a, weighting)
    dir_parts = np.sum(Psi * (W @ Psi), axis=0)
    l1_cols = mu * np.sum(w[:, None] * np.abs(Psi), axis=0)
    lam = dir_parts + 0.5 * l1_cols  # Def. 3.2.15: ψᵀWψ + (μ/2)‖·‖₁
    order = np.argsort(lam, kind="stable")
    Psi = canonical_signs(Psi[:, order])  # the sign convention (stiefel.manifolds.signs): largest-magnitude entry positive
    peak = np.max(np.abs(Psi), axis=0, keepdims=True)
    sparsity = {"1e-6": float(np.mean(np.abs(Psi) < 1e-6 * peak)), "1e-3": float(np.mean(np.abs(Psi) < 1e-3 * peak))}
    orth = float(np.max(np.abs(Psi.T @ (a[:, None] * Psi) - np.eye(Psi.shape[1]))))
    return Psi, lam[order], float(dir_parts.sum()), float(l1_cols.sum()), sparsity, orth


def _start_kind(start, n: int, k: int) -> str:
    """``"eigen"``, ``"random"`` or ``"array"`` (an ``(n, k)`` array)."""
    if isinstance(start, str):
        if start not in ("eigen", "random"):
            raise ParameterError(f"unknown start {start!r}; 'eigen', 'random' or an (n, k) array")
        return start
    shape = np.shape(start)
    if shape != (n, k):
        raise ShapeError(f"start must have shape {(n, k)}, got {shape}")
    return "array"


def _check_start(X, a) -> None:
    """An array start: finite, with columns linearly independent in A (else no solver can use it)."""
    X = np.asarray(X, dtype=np.float64)
    check_finite("start", X)
    check_full_rank("start", X.T @ (a[:, None] * X), metric="A")


def compressed_modes(
    lap,
    k: int,
    mu: float,
    *,
    solver: CMMSolver = BlockCMM(),
    weighting: str = "area",
    start: str | np.ndarray = "eigen",
    seed: int = 0,
    dtype=None,
    callback: Callable | None = None,
    progress: Callable | None = None,
    stop=None,
    verbose: bool = False,
    eigenpairs: tuple | None = None,
    finish: SupportFinish | None = SupportFinish(),
) -> CMMResult:
    """Compressed manifold modes of a Laplacian ``(W, A)``.

    Args:
      lap: ``mesh.Laplacian`` (``.W``, ``.A``) or a pair ``(W, A)`` (A diagonal, positive; finite entries).
      k: number of modes, an integer in ``[1, n]``; mu: sparsity weight μ ≥ 0 (absolute). At μ = 0 the
        minimisers are the first k eigenfunctions: they are returned (``first_eigenpairs``, status
        ``"converged"``, ``params["route"] = "eigenbasis"``) without a solve, except by ``FastCMM``.
      solver: ``BlockCMM`` (default), ``SequentialCMM``, ``ADMMCMM``, ``SequentialADMMCMM`` or
        ``FastCMM(U)`` (``objectives.cmm.solvers``), with its options.
      weighting: ``"area"`` or ``"uniform"`` ℓ1 weights (docs/maths.md §4).
      start: ``"eigen"`` (first k eigenfunctions — ``BlockCMM`` screens rotations of them too, its ``starts``;
        ``FastCMM``: the restricted eigenbasis),
        ``"random"`` (``seed``), or an ``(n, k)`` array (not for ``FastCMM``). The eigenpairs are
        computed only when the start or the solver (default shift σ, ADMM's ρ) uses them, once.
      seed: random seed (random starts).
      dtype: computation dtype of the manifold solvers (default float64 if x64 is enabled); the ADMM
        solvers run in float64 on the host.
      callback: ``callback(j, info)`` after each finished column, for solvers with
        ``supports_callback`` (``SequentialCMM``).
      progress: ``progress(stiefel.Progress)`` — iteration, objective, gradient norm, continuation stage,
        elapsed and estimated remaining seconds — a few times per second from solvers with
        ``supports_progress`` (``BlockCMM``; it runs compiled chunks of iterations, ``stiefel.solvers.driver``);
        the others report once, when they finish. ``verbose=True`` prints these reports on stderr.
      stop: a ``threading.Event`` (or a callable returning True) checked between chunks by solvers with
        ``supports_progress``; when set — or on Ctrl-C during such a solve — the result holds the modes
        reached, with status ``"interrupted"``.

      finish: ``SupportFinish(...)`` (default ``SupportFinish()``, ``objectives.cmm.support_finish``) finishes the
        solver's smoothed modes on the exact ℓ1 problem on their identified support: exact zeros, A-orthonormal
        to 1e-12, a true objective no higher than the solver's, and the status derived from the exact ℓ1
        stationarity residual (``"converged"`` iff ``l1_residual ≤ finish.tol``; ``objectives.cmm.certify``);
        the smoothed modes stay in ``smooth_modes``. None: the solver's smoothed modes and status. Not applied
        at μ = 0 (the eigenbasis) or to an interrupted solve.
      eigenpairs: optional ``(evals, evecs)``, the first ``m ≥ max(k, 2)`` generalised eigenpairs of
        ``(W, A)`` (ascending, A-orthonormal: ``first_eigenpairs(W, a, m)``), used instead of solving
        for them — for several solves of one Laplacian (``stiefel compare-smoothings`` computes them once).

    Everything is checked before any work: ``ParameterError`` / ``SolverOptionError`` for options,
    ``NonFiniteError`` for NaN/inf in W, A or the start, ``RankDeficientError`` for a start whose
    columns are linearly dependent in A (the numerical rank is in the message).
    """
    if not isinstance(solver, CMMSolver):
        hint = f"; use {SOLVERS[solver].__name__}(...)" if isinstance(solver, str) and solver in SOLVERS else ""
        names = ", ".join(c.__name__ for c in SOLVERS.values())
        raise SolverOptionError(f"solver must be a CMM solver object ({names}), got {solver!r}{hint}")
    W, a = unpack_laplacian(lap)
    n = a.shape[0]
    if n < 2:
        raise ShapeError(f"compressed_modes needs a Laplacian of at least 2 vertices, got n = {n}")
    k = check_count("k", k, 1, n, high_label=f"n = {n}")
    check_nonnegative("mu", mu)
    check_count("seed", seed, 0)
    if weighting not in WEIGHTINGS:
        raise ParameterError(f"unknown weighting {weighting!r}; choose one of {WEIGHTINGS}")
    kind = _start_kind(start, n, k)
    if solver.restricted and kind == "array":
        raise SolverOptionError(f"{type(solver).__name__} builds its start in span(U): use start='eigen' or 'random'")
    if kind == "array":
        _check_start(start, a)
    if finish is not None and not isinstance(finish, SupportFinish):
        raise SolverOptionError(f"finish must be None or a SupportFinish(...), got {finish!r}")
    if not solver.supports_callback:
        _no_callback(solver, callback)
    if verbose:
        progress = _printer(progress)
    live = dict(progress=progress, stop=stop) if solver.supports_progress else {}
    eigen_route = mu == 0.0 and not solver.restricted  # the minimisers are the eigenbasis: no iterative solve
    t_setup = time.perf_counter()
    if eigenpairs is not None:
        evals, evecs = _given_eigenpairs(eigenpairs, n, max(k, 2))
    elif solver.needs_eigenpairs(kind) or eigen_route:
        evals, evecs = first_eigenpairs(W, a, max(k, 2))
    else:
        evals, evecs = None, None
    if solver.restricted:
        X0 = None
    elif kind == "eigen":
        X0 = evecs[:, :k]
    elif kind == "random":
        X0 = np.random.default_rng(seed).standard_normal((n, k))
    else:
        X0 = np.asarray(start, dtype=np.float64)
    setup_time = time.perf_counter() - t_setup
    if eigen_route:
        run = SolverRun(evecs[:, :k], 0, "converged", setup_time, 0.0, {}, {"route": "eigenbasis"})
    else:
        run = solver.solve(W, a, k, mu, Start(kind, X0, evals), weighting=weighting, seed=seed, dtype=dtype,
                           callback=callback, **live)
    w = l1_weights_np(a, weighting)
    cert = certify(W, a, w, mu, run.Psi, run.status, finish)
    wall_time, residual = run.wall_time + cert.seconds, cert.residual
    smooth_modes = None if cert.smooth_modes is None else _diagnostics(W, a, mu, weighting, cert.smooth_modes)[0]
    Psi, lam, dirichlet_part, l1_part, sparsity, orth = _diagnostics(W, a, mu, weighting, cert.Psi)
    support = support_stats(Psi, a)
    if residual is None:  # (invariant under the column order and signs _diagnostics applies)
        residual = l1_stationarity(W, a, w, mu, Psi).relative
    if progress is not None and not live:  # one report at the end
        progress(Progress(iteration=int(run.iterations), max_iters=int(getattr(solver, "max_iters", run.iterations)),
                          objective=dirichlet_part + l1_part, grad_norm=float("nan"), elapsed=run.wall_time,
                          remaining=0.0, method=solver.name))
    params = dict(k=k, mu=mu, method=solver.name, weighting=weighting, seed=seed, start=kind, **solver.as_dict(),
                  **run.info, setup_time=setup_time)
    return CMMResult(
        modes=Psi, compressed_eigenvalues=lam, objective=dirichlet_part + l1_part, dirichlet=dirichlet_part,
        l1=l1_part, sparsity=sparsity, orthogonality=orth, iterations=int(run.iterations), wall_time=wall_time,
        compile_time=run.compile_time, status=cert.status, method=solver.name, params=params, history=run.history,
        exact_zeros=support["exact_zeros"], support_sizes=support["support_sizes"],
        support_areas=support["support_areas"], l1_residual=residual, finish=cert.finish, smooth_modes=smooth_modes,
    )


def _printer(progress: Callable | None) -> Callable:
    """A ``progress`` that prints each report on stderr (then calls ``progress``, if any)."""
    import sys

    def report(info: Progress) -> None:
        print(f"compressed_modes [{info.method}] {info.line()}", file=sys.stderr, flush=True)
        if progress is not None:
            progress(info)

    return report


def select_mu(lap, k: int, target_sparsity: float, *, threshold: str = "1e-3", mu_lo: float | None = None,
              mu_hi: float | None = None, tol: float = 0.02, max_evals: int = 12, **kwargs):
    """Find μ whose modes have a target sparsity (thesis §3.6, future work) by bisection in log μ.

    Sparsity is the fraction of entries below ``threshold × max|ψ|`` (``CMMResult.sparsity``); it
    grows with μ. Each solve is warm-started from the modes of the nearest μ tried so far.

    Args:
      lap, k: as in ``compressed_modes``; target_sparsity: in (0, 1).
      mu_lo, mu_hi: initial bracket (default ``1e-3·n`` and ``1·n``); widened by ×10 steps if needed.
      tol: stop when ``|sparsity − target| ≤ tol`` (in [0, 1)); max_evals: solve budget (≥ 2: the
        bracket's two ends are always solved).
      threshold: ``"1e-6"`` or ``"1e-3"`` (a key of ``CMMResult.sparsity``).
      kwargs: passed to ``compressed_modes`` (``solver=``, ``weighting=``, ``dtype=``, ...).
    Returns:
      ``(mu, CMMResult, trials)`` with ``trials`` a list of ``(mu, sparsity, objective)``.
    """
    check_unit_interval("target_sparsity", target_sparsity)
    if threshold not in SPARSITY_THRESHOLDS:
        raise ParameterError(f"unknown threshold {threshold!r}; choose one of {SPARSITY_THRESHOLDS}")
    check_number("tol", tol, low=0, high=1, high_open=True)
    check_count("max_evals", max_evals, 2)
    W, a = unpack_laplacian(lap)
    n = a.shape[0]
    check_count("k", k, 1, n, high_label=f"n = {n}")
    lo = check_positive("mu_lo", mu_lo) if mu_lo is not None else 1e-3 * n
    hi = check_positive("mu_hi", mu_hi) if mu_hi is not None else 1.0 * n
    if not lo < hi:
        raise ParameterError(f"the bracket needs mu_lo < mu_hi, got mu_lo = {lo!r}, mu_hi = {hi!r}")
    trials: list = []
    results: dict = {}

    def solve(mu):
        start = kwargs.pop("start", "eigen") if not results else results[min(results, key=lambda m: abs(np.log(m / mu)))].modes
        res = compressed_modes((W, sp.diags_array(a)), k, mu, start=start, **kwargs)
        results[mu] = res
        trials.append((mu, res.sparsity[threshold], res.objective))
        return res.sparsity[threshold]

    s_lo, s_hi = solve(lo), solve(hi)
    while s_lo > target_sparsity and len(trials) < max_evals:
        lo /= 10.0
        s_lo = solve(lo)
    while s_hi < target_sparsity and len(trials) < max_evals:
        hi *= 10.0
        s_hi = solve(hi)
    best = min(results, key=lambda m: abs(results[m].sparsity[threshold] - target_sparsity))
    while len(trials) < max_evals and abs(results[best].sparsity[threshold] - target_sparsity) > tol:
        mid = float(np.sqrt(lo * hi))
        s_mid = solve(mid)
        if s_mid < target_sparsity:
            lo = mid
        else:
            hi = mid
        best = min(results, key=lambda m: abs(results[m].sparsity[threshold] - target_sparsity))
    return best, results[best], trials
