"""Compressed manifold modes (thesis Def. 3.2.10, §3.2, §6.5; MATH.md §4–5).

``compressed_modes(lap, k, mu, method=...)`` minimises
``tr(ΨᵀWΨ) + μ Σ_ij w_i |Ψ_ij|`` over ``ΨᵀAΨ = I`` and returns the modes with
diagnostics. Methods:

* ``"block"`` (default) — the smoothed energy over the whole matrix with
  Riemannian CG (``stiefel.minimize``), preconditioned by ``(W + σA)⁻¹`` (σ = λ_{k−1}), started
  from the first k eigenfunctions, with continuation on the smoothing parameter
  (ε, δ from 0.1 to the target in 4 warm-started stages, the first three stopped early);
* ``"sequential"`` — thesis Algorithm 6 (``stiefel.minimize_sequential``), same
  preconditioner, column by column (continuation only when asked for);
* ``"admm"`` / ``"admm_sequential"`` — the ADMM baseline (``objectives.admm``);
* ``"fast"`` — Algorithm 8 (``objectives.fast.restricted_admm``) on the span of
  local functions ``U`` (pass ``local_functions=``, e.g. ``mesh.local_functions(m, n_samples=d).U``),
  started from the restricted eigenbasis (Algorithm 7), with ρ = 2λ̄_k (the k-th restricted
  eigenvalue) unless ``admm_options.rho`` is given.

The Laplacian ``lap`` is anything with scipy-sparse attributes ``W`` (PSD
stiffness) and ``A`` (diagonal lumped mass), e.g. ``mesh.laplacian(m)``, or a
pair ``(W, A)``; this module imports nothing from ``mesh``.
"""

from __future__ import annotations

import dataclasses
import time

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import stiefel
from stiefel.operators import SparseOperator
from stiefel.sparse_factor import SymmetricFactor

from .active_set import ActiveSetPreconditioner
from .admm import ADMMOptions, admm, admm_sequential, l1_weights_np, orthonormalize
from .energies import cmm_energy

__all__ = ["CMMResult", "compressed_modes", "select_mu", "METHODS", "unpack_laplacian", "first_eigenpairs"]

METHODS = ("block", "sequential", "admm", "admm_sequential", "fast")
PRECONDITIONERS = ("shifted", "active_set")
OPTIMIZERS = ("cg", "lbfgs")


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
      factorisations), compile_time, status, method, params (the arguments; for the ADMM
      methods also ``rho0``, the initial penalty used).
    history: objective trace ``{"time": (T,), "objective": (T,)}`` where available.
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


def unpack_laplacian(lap):
    """``(W csr, a (n,))`` from a Laplacian object (``.W``, ``.A``) or a ``(W, A)`` pair."""
    if isinstance(lap, tuple):
        W, A = lap
    else:
        W, A = lap.W, lap.A
    W = sp.csr_array(W, dtype=np.float64)
    if sp.issparse(A):
        if sp.csr_array(A - sp.diags_array(A.diagonal())).count_nonzero() > 0:
            raise ValueError("compressed_modes needs a diagonal (lumped) area matrix A; use a lumped mass")
        a = np.asarray(A.diagonal(), dtype=np.float64)
    else:
        A = np.asarray(A, dtype=np.float64)
        a = A if A.ndim == 1 else np.diag(A)
    if W.shape[0] != W.shape[1] or W.shape[0] != a.shape[0]:
        raise ValueError(f"W {W.shape} and A ({a.shape[0]}) do not match")
    if np.any(a <= 0) or not np.all(np.isfinite(a)):
        raise ValueError("the area matrix must have positive, finite diagonal entries")
    return W, a


def first_eigenpairs(W, a, k):
    """The k smallest generalised eigenpairs of ``(W, diag(a))``, A-orthonormal (shift-invert eigsh).

    Deterministic: a fixed Lanczos start vector and a sign convention (the largest-magnitude
    entry of each column is positive), so repeated calls give the same start for the solvers.
    """
    scale = float(abs(W).sum() / W.shape[0]) / float(np.mean(a))
    v0 = np.random.default_rng(0).standard_normal(W.shape[0])  # deterministic: same start, same result
    sigma = -1e-8 * scale
    A = sp.diags_array(a).tocsc()
    OPinv = SymmetricFactor(sp.csc_array(W) - sigma * A, check=False).as_linear_operator()
    vals, vecs = spla.eigsh(sp.csc_array(W), k=k, M=A, sigma=sigma, which="LM", v0=v0, OPinv=OPinv)
    order = np.argsort(vals)
    vals, vecs = vals[order], vecs[:, order]
    peak = vecs[np.argmax(np.abs(vecs), axis=0), np.arange(vecs.shape[1])]
    vecs = vecs * np.sign(peak)  # sign convention: each column's largest-magnitude entry is positive
    return vals, orthonormalize(vecs, a)


def _diagnostics(W, a, mu, weighting, Psi):
    w = l1_weights_np(a, weighting)
    dir_parts = np.sum(Psi * (W @ Psi), axis=0)
    l1_cols = mu * np.sum(w[:, None] * np.abs(Psi), axis=0)
    lam = dir_parts + 0.5 * l1_cols  # Def. 3.2.15: ψᵀWψ + (μ/2)‖·‖₁
    order = np.argsort(lam, kind="stable")
    Psi = Psi[:, order]
    peak = np.max(np.abs(Psi), axis=0, keepdims=True)
    sparsity = {"1e-6": float(np.mean(np.abs(Psi) < 1e-6 * peak)), "1e-3": float(np.mean(np.abs(Psi) < 1e-3 * peak))}
    orth = float(np.max(np.abs(Psi.T @ (a[:, None] * Psi) - np.eye(Psi.shape[1]))))
    return Psi, lam[order], float(dir_parts.sum()), float(l1_cols.sum()), sparsity, orth


def _continuation(eps: float, steps: int, start: float) -> list[float]:
    if steps <= 1 or start <= eps:
        return [eps]
    return list(np.geomspace(start, eps, steps))


def _block_rounds(F, manifold, X, P, *, gtol: float, ftol: float, max_iters: int, refresh: int | None = None,
                  optimizer: str = "cg", ftol_window: int = 20):
    """Riemannian CG/L-BFGS (``optimizer``) on the block, in one run (fixed ``P``) or in rounds of ``refresh``
    iterations with an ``ActiveSetPreconditioner`` rebuilt before each round.

    Returns ``(X, iterations, status, run seconds (incl. refreshes), compile seconds,
    history {"time", "value", "monitor"})``; a round that ends converged ends the run.
    """
    if not isinstance(P, ActiveSetPreconditioner):
        res = stiefel.minimize(F, manifold, X, method=optimizer, preconditioner=P, gtol=gtol, ftol=ftol,
                               ftol_window=ftol_window, max_iters=max_iters, monitor=F.true_value)
        h = res.trimmed_history()
        h["time"] = np.linspace(0.0, res.wall_time, len(h["value"]))
        return res.x, int(res.iterations), res.status_name, res.wall_time, res.compile_time, h
    done, wall, compile_t, status = 0, 0.0, 0.0, "max_iters"
    parts: dict = {"time": [], "value": [], "monitor": []}
    while done < max_iters:
        t0 = time.perf_counter()
        P.refresh(X)
        wall += time.perf_counter() - t0
        res = stiefel.minimize(F, manifold, X, method=optimizer, preconditioner=P.apply, gtol=gtol, ftol=ftol,
                               ftol_window=ftol_window, max_iters=min(refresh, max_iters - done), monitor=F.true_value,
                               check=False)
        h = res.trimmed_history()
        first = 0 if done == 0 else 1  # a later round's entry 0 repeats the previous round's last
        parts["time"].append(wall + np.linspace(0.0, res.wall_time, len(h["value"]))[first:])
        parts["value"].append(h["value"][first:])
        parts["monitor"].append(h["monitor"][first:])
        wall += res.wall_time
        compile_t += res.compile_time
        done += int(res.iterations)
        X = res.x
        if res.status_name != "max_iters":
            status = res.status_name
            break
    return X, done, status, wall, compile_t, {key: np.concatenate(v) for key, v in parts.items()}


def compressed_modes(
    lap,
    k: int,
    mu: float,
    *,
    method: str = "block",
    smoothing: str = "f6",
    eps: float = 1e-3,
    delta: float = 1e-3,
    weighting: str = "area",
    seed: int = 0,
    start: str | np.ndarray = "eigen",
    gtol: float = 1e-6,
    ftol: float = 1e-7,
    max_iters: int = 5000,
    continuation: int | None = None,
    continuation_start: float = 1e-1,
    stage_ftol: float = 3e-4,
    stage_window: int = 5,
    preconditioner_shift: float | None = None,
    preconditioner: str = "shifted",
    refresh: int = 50,
    optimizer: str = "cg",
    admm_options: ADMMOptions | None = None,
    local_functions=None,
    callback=None,
    dtype=None,
) -> CMMResult:
    """Compressed manifold modes of a Laplacian ``(W, A)``.

    Args:
      lap: ``mesh.Laplacian`` (``.W``, ``.A``) or a pair ``(W, A)`` (A diagonal).
      k: number of modes; mu: sparsity weight μ (absolute).
      method: one of ``METHODS``.
      smoothing, eps, delta: the ℓ1 smoothing (``objectives.smoothings``) for the manifold
        methods; both ε and δ follow the continuation.
      weighting: ``"area"`` or ``"uniform"`` ℓ1 weights (MATH.md §4).
      seed: random seed (random starts, ADMM start).
      start: ``"eigen"`` (first k eigenfunctions), ``"random"``, or an ``(n, k)`` array.
      gtol, max_iters: per continuation stage (manifold methods).
      ftol: the block solver's last stage also stops when its objective decreased by less than
        ``ftol`` (relative) over 20 iterations (the smoothed problem's gradient norm can
        stall above gtol in the rounding regime).
      continuation: number of smoothing stages, geometric from ``continuation_start`` to
        the target ε/δ; None (default): 4 for ``method="block"``, 1 (none) for ``"sequential"``.
        The block solver's intermediate stages stop early (``stage_ftol``), so the stages only
        settle the arrangement of the modes, which a wide smoothing does in far fewer
        iterations; the last stage runs to ``gtol``/``ftol``. Measured (k = 10, μ = 0.01n,
        shifted CG, ``bench/RESULTS.md``): iterations to ADMM's best 337 → 67 on camelhead,
        203 → 67 on armadillo, 38 → 29 on fandisk, 72 → 36 on bunny; same final objectives.
      stage_ftol, stage_window: the block solver's intermediate stages end once the smoothed
        objective decreased by less than ``stage_ftol`` (relative) over ``stage_window``
        iterations.
      preconditioner_shift: σ in ``(W + σA)⁻¹`` (default: the largest of the first k eigenvalues,
        λ_{k−1} (λ₁ for k ≤ 2), the scale of the modes sought — against λ₁ it cut the block
        solver's iterations to ADMM's best from 87 to 38 (fandisk), 836 to 322 (camelhead) and
        553 to 209 (armadillo), k = 10, ``bench/RESULTS.md``).
      preconditioner: manifold methods' preconditioner: ``"shifted"`` (``(W + σA)⁻¹``, one
        factorisation) or, for ``method="block"``, ``"active_set"``
        (``objectives.active_set``: per column, ``W + σA`` plus the ℓ1 curvature on the entries
        pinned at zero, rebuilt every ``refresh`` iterations).
      refresh: iterations per round of the active-set preconditioner.
      optimizer: the block solver's method, ``"cg"`` (Riemannian CG) or ``"lbfgs"`` (Riemannian
        L-BFGS, ``stiefel.minimize``); each round of the active-set preconditioner starts a new
        L-BFGS memory.
      admm_options: ``ADMMOptions`` for the ADMM methods.
      local_functions: ``(n, d)`` sparse U for ``method="fast"``.
      callback: for ``method="sequential"``, ``callback(j, info)`` after each finished column
        (``stiefel.minimize_sequential``'s; every continuation stage restarts at column 0), so a
        long run can save its columns as they complete.
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")
    W, a = unpack_laplacian(lap)
    n = a.shape[0]
    if not 1 <= k <= n:
        raise ValueError(f"k must satisfy 1 ≤ k ≤ n = {n}, got {k}")
    if not (np.isfinite(mu) and mu >= 0):
        raise ValueError(f"mu must be a finite non-negative number, got {mu}")
    if continuation is None:
        continuation = 4 if method == "block" else 1
    if continuation < 1 or stage_window < 1 or not stage_ftol >= 0:
        raise ValueError(f"continuation and stage_window must be ≥ 1 and stage_ftol ≥ 0, got "
                         f"{continuation}, {stage_window}, {stage_ftol}")
    params = dict(k=k, mu=mu, method=method, smoothing=smoothing, eps=eps, delta=delta, weighting=weighting,
                  seed=seed, start=start if isinstance(start, str) else "array", gtol=gtol, ftol=ftol,
                  max_iters=max_iters, continuation=continuation, continuation_start=continuation_start,
                  stage_ftol=stage_ftol, stage_window=stage_window,
                  optimizer=optimizer)
    t_setup = time.perf_counter()
    if method == "fast" and local_functions is None:
        raise ValueError("method='fast' needs local_functions=U (n × d), e.g. mesh.local_functions(m, n_samples=d).U")
    need_eigs = method != "fast" and ((isinstance(start, str) and start == "eigen")
                                      or (method in ("block", "sequential") and preconditioner_shift is None))
    evals, evecs = first_eigenpairs(W, a, max(k, 2)) if need_eigs else (None, None)
    if method == "fast":
        X0 = None
    elif isinstance(start, str):
        if start == "eigen":
            X0 = evecs[:, :k]
        elif start == "random":
            X0 = np.random.default_rng(seed).standard_normal((n, k))
        else:
            raise ValueError(f"unknown start {start!r}; 'eigen', 'random' or an (n, k) array")
    else:
        X0 = np.asarray(start, dtype=np.float64)
        if X0.shape != (n, k):
            raise ValueError(f"start must have shape {(n, k)}, got {X0.shape}")
    setup_time = time.perf_counter() - t_setup
    history: dict = {}

    if method == "fast":
        from .fast import restricted_admm, restricted_eigenbasis

        opts = admm_options or ADMMOptions()
        Xr = None
        if isinstance(start, str) and start == "eigen":
            evals_r, _, Xr = restricted_eigenbasis(W, sp.diags_array(a), local_functions, max(k, 2))
            Xr = Xr[:, :k]
            if opts.rho is None:  # as for the full ADMM below: ρ of the order of the modes' spectrum
                opts = dataclasses.replace(opts, rho=2.0 * float(evals_r[k - 1] if k > 1 else evals_r[1]))
        params["rho0"] = float(opts.rho if opts.rho is not None else max(mu, 1.0))
        res = restricted_admm(W, a, local_functions, k, mu, weighting=weighting, X0=Xr, seed=seed, options=opts)
        Psi, iters, wall, compile_t, status = res.Psi, res.iterations, res.wall_time, 0.0, res.status
        history = {"time": res.history["time"], "objective": res.history["objective"]}
    elif method in ("admm", "admm_sequential"):
        opts = admm_options or ADMMOptions()
        if opts.rho is None and evals is not None:
            # ρ of the order of the spectrum of the modes sought: too small a ρ diverges
            opts = dataclasses.replace(opts, rho=2.0 * float(evals[k - 1] if k > 1 else evals[1]))
        params["rho0"] = float(opts.rho if opts.rho is not None else max(mu, 1.0))
        run = admm if method == "admm" else admm_sequential
        res = run(W, a, k, mu, weighting=weighting, Psi0=X0, seed=seed, options=opts)
        Psi, iters, wall, compile_t, status = res.Psi, res.iterations, res.wall_time, 0.0, res.status
        history = {"time": res.history["time"], "objective": res.history["objective"]}
    else:
        sigma = preconditioner_shift if preconditioner_shift is not None else float(max(evals[-1], 1e-12))
        if preconditioner not in PRECONDITIONERS:
            raise ValueError(f"unknown preconditioner {preconditioner!r}; choose one of {PRECONDITIONERS}")
        if preconditioner == "active_set" and method != "block":
            raise ValueError("preconditioner='active_set' needs method='block'")
        if refresh < 1:
            raise ValueError(f"refresh must be ≥ 1, got {refresh}")
        if optimizer not in OPTIMIZERS:
            raise ValueError(f"unknown optimizer {optimizer!r}; choose one of {OPTIMIZERS}")
        if optimizer != "cg" and method != "block":
            raise ValueError(f"optimizer={optimizer!r} needs method='block' (the sequential solver uses CG)")
        # every array of the problem in the computation dtype (float32 runs stay float32)
        dt = np.dtype(dtype or (jnp.float64 if jax.config.jax_enable_x64 else jnp.float32))
        t_factor = time.perf_counter()  # the preconditioner's factorisation is part of the run, as ADMM's E-step is
        P = stiefel.as_operator(W + sp.diags_array(sigma * a), dtype=dt) if preconditioner == "shifted" else None
        t_factor = time.perf_counter() - t_factor
        energy = cmm_energy(SparseOperator.from_scipy(W, dtype=dt), jnp.asarray(a, dtype=dt), mu, smoothing=smoothing,
                            eps=eps, delta=delta, weighting=weighting)
        schedule = _continuation(min(eps, delta), continuation, continuation_start)
        ratio_e, ratio_d = eps / min(eps, delta), delta / min(eps, delta)
        X = jnp.asarray(X0, dtype=dt)
        iters, wall, compile_t, status = 0, t_factor, 0.0, "converged"
        times, values, true_values = [], [], []
        manifold = stiefel.GeneralizedStiefel(a, k, retraction="cholesky", dtype=dtype) if method == "block" else None
        if manifold is not None:
            X = manifold.project_to_manifold(X)
        for stage, s in enumerate(schedule):
            F = energy.with_params(eps=s * ratio_e, delta=s * ratio_d)
            if method == "block":
                # intermediate stages only need the arrangement of the modes: stop once they stall
                last = stage == len(schedule) - 1
                stop = dict(ftol=ftol) if last else dict(ftol=max(ftol, stage_ftol), ftol_window=stage_window)
                if P is None:
                    if stage == 0:
                        active = ActiveSetPreconditioner(W, a, sigma, mu, l1_weights_np(a, weighting), s)
                    active.set_width(s)
                    run = _block_rounds(F, manifold, X, active, gtol=gtol, max_iters=max_iters,
                                        refresh=refresh, optimizer=optimizer, **stop)
                else:
                    run = _block_rounds(F, manifold, X, P, gtol=gtol, max_iters=max_iters, optimizer=optimizer, **stop)
                X, it_stage, st, t_run, t_compile, h = run
                iters += it_stage
                first = 0 if stage == 0 else 1  # a later stage's entry 0 is the previous stage's last iterate
                true_values.extend(list(h["monitor"][first:]))
                times.extend(list(wall + h["time"][first:]))
                values.extend(list(h["value"][first:]))
                wall += t_run
                compile_t += t_compile
            else:
                res = stiefel.minimize_sequential(F, a, k, X0=np.asarray(X), preconditioner=P, gtol=gtol,
                                                  max_iters=max_iters, dtype=dtype, callback=callback)
                X = res.x
                iters += int(np.sum(np.asarray(res.iterations)))
                names = set(res.status_names)
                st = "converged" if names == {"converged"} else sorted(names - {"converged"})[0]
                times.append(wall + res.wall_time)
                values.append(float(res.value))
                wall += res.wall_time
                compile_t += res.compile_time
            if st != "converged":
                status = st
        Psi = np.asarray(X, dtype=np.float64)
        history = {"time": np.asarray(times), "smoothed_objective": np.asarray(values)}
        if true_values:
            history["objective"] = np.asarray(true_values)
        Psi = orthonormalize(Psi, a)  # exact A-orthonormality of the returned modes
    Psi, lam, dirichlet_part, l1_part, sparsity, orth = _diagnostics(W, a, mu, weighting, Psi)
    params["setup_time"] = setup_time
    return CMMResult(
        modes=Psi, compressed_eigenvalues=lam, objective=dirichlet_part + l1_part, dirichlet=dirichlet_part,
        l1=l1_part, sparsity=sparsity, orthogonality=orth, iterations=iters, wall_time=wall,
        compile_time=compile_t, status=status, method=method, params=params, history=history,
    )


def select_mu(lap, k: int, target_sparsity: float, *, threshold: str = "1e-3", mu_lo: float | None = None,
              mu_hi: float | None = None, tol: float = 0.02, max_evals: int = 12, **kwargs):
    """Find μ whose modes have a target sparsity (thesis §3.6, future work) by bisection in log μ.

    Sparsity is the fraction of entries below ``threshold × max|ψ|`` (``CMMResult.sparsity``); it
    grows with μ. Each solve is warm-started from the modes of the nearest μ tried so far.

    Args:
      lap, k: as in ``compressed_modes``; target_sparsity: in (0, 1).
      mu_lo, mu_hi: initial bracket (default ``1e-3·n`` and ``1·n``); widened by ×10 steps if needed.
      tol: stop when ``|sparsity − target| ≤ tol``; max_evals: solve budget.
      kwargs: passed to ``compressed_modes`` (method, weighting, smoothing, ...).
    Returns:
      ``(mu, CMMResult, trials)`` with ``trials`` a list of ``(mu, sparsity, objective)``.
    """
    if not 0.0 < target_sparsity < 1.0:
        raise ValueError("target_sparsity must lie in (0, 1)")
    W, a = unpack_laplacian(lap)
    n = a.shape[0]
    lo = mu_lo if mu_lo is not None else 1e-3 * n
    hi = mu_hi if mu_hi is not None else 1.0 * n
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
