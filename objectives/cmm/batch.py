"""Batches of compressed-manifold-mode solves on one mesh: ``jax.vmap`` over μ, ε/δ and starts.

``cmm_batch(lap, k, mus, ...)`` minimises the smoothed CMM energy (docs/maths.md §4, thesis
Def. 3.2.10) ``tr(XᵀWX) + μ_b Σ_ij w_i s_{ε_b,δ_b}(X_ij)`` over ``XᵀAX = I`` for a batch
``b = 1..B`` of parameters and starts, with ``stiefel.solve_block`` (Riemannian CG) under
``jax.vmap``: one compiled program, one ``lax.while_loop`` that runs until every member has
stopped (finished members are frozen by the batched loop's select, so each member's result
is the one it would have had alone, up to rounding of batched reductions).

What can be batched: anything that is a pytree *leaf* of the problem — μ, ε, δ (the
smoothing's parameters) and the start ``X0``. What cannot: the smoothing *function*
(``CMMEnergy.smoothing`` is static) and the shapes (``n``, ``k``); a sequence of
different smoothings is run as a Python loop over one vmapped group per smoothing.

``mode="loop"`` runs the *same* single-problem solver, compiled once, in a Python loop
over the batch: the reference the vmapped batch is measured against
(``bench/bench_batch.py``), and what ``mode="auto"`` (the default) runs on a CPU, where it is
faster; accelerators get the vmapped program.

Preconditioners: ``"shifted"`` applies ``(W + σA)⁻¹`` by CHOLMOD as an XLA custom call
(``stiefel.linalg.ffi_solve``; one native call for the whole batch) where available, else by the sparse
factorisation (``stiefel.linalg.sparse_factor``) on the host
(``jax.pure_callback``; under vmap one host call per member, or with
``callback_vmap="expand_dims"`` one call for the whole batch), ``"jacobi"`` its diagonal
(pure JAX), ``None`` none.
"""

from __future__ import annotations

import dataclasses
import time
from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from jaxtyping import Array, ArrayLike, Float

import stiefel
from stiefel.errors import ParameterError, ShapeError
from stiefel.linalg.operators import SparseOperator
from stiefel.manifolds.signs import canonical_signs
from stiefel.validation import check_count, check_finite, check_full_rank, check_number, check_positive

from .modes import first_eigenpairs, unpack_laplacian
from ..energy.energies import CMMEnergy, cmm_energy

__all__ = ["BatchResult", "CMMProblem", "cmm_batch", "cmm_problem", "default_options", "PRECONDITIONERS"]

PRECONDITIONERS = ("shifted", "jacobi", None)


def default_options(**overrides) -> stiefel.BlockOptions:
    """``BlockOptions`` as ``compressed_modes(solver=BlockCMM())`` uses them (CG, c2 = 0.1, ftol = 1e-7)."""
    base = dict(method="cg", c2=0.1, gtol=1e-6, ftol=1e-7, max_iters=5000)
    base.update(overrides)
    return stiefel.BlockOptions(**base)


@dataclasses.dataclass
class BatchResult:
    """Stacked outcome of ``cmm_batch`` (batch size B).

    modes: ``(B, n, k)`` final iterates (not re-sorted, not re-orthonormalised; signs as ``stiefel.manifolds.signs``).
    value: ``(B,)`` smoothed objective; objective: ``(B,)`` true objective (f0 = |·|).
    iterations, status: ``(B,)`` ints (``stiefel.Status`` codes); orthogonality: ``(B,)``
    ``max|XᵀAX − I|``. wall_time: run seconds (compile excluded); compile_time: seconds;
    mode: ``"vmap"`` or ``"loop"``; params: ``{"mu", "eps", "delta", "smoothing"}`` per member.
    """

    modes: np.ndarray
    value: np.ndarray
    objective: np.ndarray
    iterations: np.ndarray
    status: np.ndarray
    orthogonality: np.ndarray
    wall_time: float
    compile_time: float
    mode: str
    params: dict

    @property
    def status_names(self) -> list[str]:
        return [stiefel.Status.name(s) for s in self.status]


class CMMProblem(eqx.Module):
    """The pieces of a CMM solve, as one pytree (arrays traced, the rest static).

    energy: ``CMMEnergy`` (its μ, ε, δ are replaced per solve); manifold: ``XᵀAX = I`` with A
    diagonal, ``(n, k)`` points; precond: an operator whose ``solve`` applies the preconditioner
    (``SparseOperator`` with its host factorisation, ``DiagonalOperator``), or None.
    """

    energy: CMMEnergy
    manifold: stiefel.GeneralizedStiefel
    precond: eqx.Module | None


def _solve_one(problem: CMMProblem, mu: Float[Array, ""], eps: Float[Array, ""], delta: Float[Array, ""],
               X0: Float[Array, "n k"], options: stiefel.BlockOptions):
    """One CMM solve: ``(X (n, k), smoothed value, true value, iterations, status, max|XᵀAX − I|)``."""
    F = problem.energy.with_params(mu=mu, eps=eps, delta=delta)
    P = None if problem.precond is None else problem.precond.solve
    res = stiefel.solve_block(F, problem.manifold, X0, options, preconditioner=P)
    return (res.x, res.value, F.true_value(res.x), res.iterations, res.status,
            problem.manifold.dist_to_manifold(res.x))


def cmm_problem(lap, k: int, *, smoothing: str = "f6", weighting: str = "area",
                preconditioner: str | None = "shifted", sigma: float | None = None, dtype=None,
                callback_vmap: str = "sequential", solve_backend: str | None = None) -> tuple[CMMProblem, np.ndarray]:
    """The energy, manifold (A-orthonormality, Cholesky retraction) and preconditioner of a CMM
    problem in ``dtype``, and the eigenbasis start ``(n, k)`` (float64 numpy).

    ``sigma`` (the shift of ``W + σA``) defaults to the largest of the first k eigenvalues (λ₁ for
    k ≤ 2), as in ``compressed_modes``. ``solve_backend`` and ``callback_vmap``: how the shifted
    preconditioner is solved (``SparseOperator.from_scipy``: ``"ffi"``, the CHOLMOD custom call, where
    available, or ``"callback"``, a host factorisation whose batching ``callback_vmap`` chooses).
    """
    if preconditioner not in PRECONDITIONERS:
        raise ParameterError(f"preconditioner must be one of {PRECONDITIONERS}, got {preconditioner!r}")
    if callback_vmap not in ("sequential", "expand_dims"):
        raise ParameterError(f"callback_vmap must be 'sequential' or 'expand_dims', got {callback_vmap!r}")
    if solve_backend not in (None, "ffi", "callback"):
        raise ParameterError(f"solve_backend must be 'ffi', 'callback' or None, got {solve_backend!r}")
    W, a = unpack_laplacian(lap)
    check_count("k", k, 1, a.shape[0], high_label=f"n = {a.shape[0]}")
    if sigma is not None:
        check_positive("sigma", sigma)
    dtype = np.dtype(dtype or (jnp.float64 if jax.config.jax_enable_x64 else jnp.float32))
    evals, evecs = first_eigenpairs(W, a, max(k, 2))
    sigma = float(max(evals[-1], 1e-12)) if sigma is None else float(sigma)
    Wop = SparseOperator.from_scipy(W, dtype=dtype)
    energy = cmm_energy(Wop, jnp.asarray(a, dtype=dtype), 1.0, smoothing=smoothing, weighting=weighting)
    manifold = stiefel.GeneralizedStiefel(a, k, retraction="cholesky", dtype=dtype)
    K = sp.csr_array(W) + sigma * sp.diags_array(a)
    if preconditioner == "shifted":
        precond = SparseOperator.from_scipy(K, factor=True, dtype=dtype, vmap_method=callback_vmap,
                                            solve_backend=solve_backend)
    elif preconditioner == "jacobi":
        precond = stiefel.DiagonalOperator(jnp.asarray(K.diagonal(), dtype=dtype))
    else:
        precond = None
    return CMMProblem(energy, manifold, precond), evecs[:, :k]


def _check_batch(mus, eps, delta, starts, a, k: int) -> None:
    """μ ≥ 0, ε, δ > 0 (finite) per member; starts finite with A-independent columns."""
    for name, values, low_open in (("mus", mus, False), ("eps", eps, True), ("delta", delta, True)):
        for i, v in enumerate(np.ravel(values)):
            check_number(f"{name}[{i}]" if np.ndim(values) else name, float(v), low=0, low_open=low_open)
    if starts is None:
        return
    X = np.asarray(starts, dtype=np.float64)
    check_finite("starts", X)
    if X.ndim not in (2, 3) or X.shape[-2:] != (a.shape[0], k):
        raise ShapeError(f"starts must be (n, k) or (B, n, k) with (n, k) = {(a.shape[0], k)}, got shape {X.shape}")
    for i, Xi in enumerate(X.reshape((-1,) + X.shape[-2:])):
        check_full_rank(f"starts[{i}]" if X.ndim == 3 else "starts", Xi.T @ (a[:, None] * Xi), metric="A")


def _broadcast(mus, eps, delta, starts, default_start, batch):
    mus, eps, delta = (np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (mus, eps, delta))
    if starts is None:
        starts = default_start
    starts = np.asarray(starts, dtype=np.float64)
    sizes = {len(mus), len(eps), len(delta), starts.shape[0] if starts.ndim == 3 else 1, batch or 1} - {1}
    if len(sizes) > 1:
        raise ValueError(f"batch sizes disagree: mus {len(mus)}, eps {len(eps)}, delta {len(delta)}, "
                         f"starts {starts.shape}; give each as a scalar/(n, k) or with one common length B")
    B = sizes.pop() if sizes else 1
    if starts.ndim == 2:
        starts = np.broadcast_to(starts, (B,) + starts.shape)
    return [np.broadcast_to(v, (B,)) for v in (mus, eps, delta)] + [starts]


def cmm_batch(
    lap,
    k: int,
    mus: Float[ArrayLike, " B"] | float,
    *,
    starts: Float[ArrayLike, "B n k"] | Float[ArrayLike, "n k"] | None = None,
    smoothing: str | Sequence[str] = "f6",
    eps: Float[ArrayLike, " B"] | float = 1e-3,
    delta: Float[ArrayLike, " B"] | float = 1e-3,
    weighting: str = "area",
    preconditioner: str | None = "shifted",
    sigma: float | None = None,
    options: stiefel.BlockOptions | None = None,
    mode: str = "auto",
    callback_vmap: str = "sequential",
    solve_backend: str | None = None,
    dtype=None,
) -> BatchResult:
    """Solve a batch of CMM problems on one mesh (module docstring).

    Args:
      lap: ``mesh.Laplacian`` (``.W``, ``.A``) or a pair ``(W, A)``, A diagonal.
      k: number of modes.
      mus: μ, a scalar or ``(B,)``.
      starts: None (the first k eigenfunctions, shared), an ``(n, k)`` start shared by all,
        or ``(B, n, k)`` starts (projected onto ``XᵀAX = I`` here).
      smoothing: a smoothing name, or a sequence of B names (one vmapped group per name).
      eps, delta: smoothing parameters, scalars or ``(B,)``.
      weighting: ``"area"`` or ``"uniform"`` ℓ1 weights.
      preconditioner: ``"shifted"`` ((W + σA)⁻¹, sparse LDLᵀ on the host), ``"jacobi"`` (its
        diagonal, pure JAX) or None.
      sigma: σ; default the largest of the first k eigenvalues (as ``compressed_modes``).
      options: ``stiefel.BlockOptions`` (default ``default_options()``); ``options.max_iters`` caps each
        member's solve (one solve per member: the total of its iterations).
      mode: ``"vmap"`` (one vmapped program), ``"loop"`` (the single-problem program, compiled
        once, called B times from Python) or ``"auto"``: the loop on a CPU backend, where it was the
        faster in every measured case (B = 8 to convergence: vmap at 0.51–0.54× the loop's speed on
        fandisk, n = 7229; 0.59–0.92× on starfish and hand_868 — the batch runs until its slowest
        member stops, and a member-iteration costs about as much batched as alone;
        ``docs/benchmarks/batch.md``), the vmapped program on an accelerator. ``BatchResult.mode``
        says which ran.
      callback_vmap, solve_backend: how the shifted preconditioner is solved and batched
        (``cmm_problem``).
      dtype: float32 / float64 (default: float64 if x64 is enabled).

    Returns:
      ``BatchResult`` with ``(B, ...)`` stacked arrays; compile time reported apart.

    Checked before any work: ``ParameterError`` (k, μ ≥ 0, ε, δ > 0, σ > 0, options), ``NonFiniteError``
    and ``RankDeficientError`` for the starts.
    """
    if mode not in ("auto", "vmap", "loop"):
        raise ParameterError(f"mode must be 'auto', 'vmap' or 'loop', got {mode!r}")
    if mode == "auto":
        mode = "loop" if jax.default_backend() == "cpu" else "vmap"
    options = options or default_options()
    if not isinstance(options, stiefel.BlockOptions):
        raise ParameterError(f"options must be a stiefel.BlockOptions (e.g. default_options(...)), got {options!r}")
    names = [smoothing] if isinstance(smoothing, str) else list(smoothing)
    B_smooth = 0 if isinstance(smoothing, str) else len(names)
    W, a = unpack_laplacian(lap)
    check_count("k", k, 1, a.shape[0], high_label=f"n = {a.shape[0]}")
    _check_batch(mus, eps, delta, starts, a, k)
    problem, X_eig = cmm_problem((W, a), k, smoothing=names[0], weighting=weighting, preconditioner=preconditioner,
                                 sigma=sigma, dtype=dtype, callback_vmap=callback_vmap,
                                 solve_backend=solve_backend)
    mus_b, eps_b, delta_b, starts_b = _broadcast(mus, eps, delta, starts, X_eig, B_smooth)
    B = len(mus_b)
    per_member = names * B if len(names) == 1 else names
    dt = problem.manifold.dtype
    X0 = jax.vmap(problem.manifold.project_to_manifold)(jnp.asarray(starts_b, dtype=dt))
    outs: list = [None] * B
    wall = compile_t = 0.0
    for name in dict.fromkeys(per_member):  # one compiled group per smoothing function
        idx = np.array([i for i, s in enumerate(per_member) if s == name])
        prob = CMMProblem(_with_smoothing(problem.energy, name), problem.manifold, problem.precond)
        args = [jnp.asarray(v[idx], dtype=dt) for v in (mus_b, eps_b, delta_b)] + [X0[idx]]
        group, t_c, t_r = _run_group(prob, args, options, mode)
        wall, compile_t = wall + t_r, compile_t + t_c
        for j, i in enumerate(idx):
            outs[i] = [np.asarray(o[j]) for o in group]
    X, value, true, it, status, orth = (np.stack([o[m] for o in outs]) for m in range(6))
    X = np.stack([canonical_signs(x) for x in X])  # each column's largest-magnitude entry positive (stiefel.manifolds.signs)
    return BatchResult(modes=X, value=value, objective=true, iterations=it, status=status, orthogonality=orth,
                       wall_time=wall, compile_time=compile_t, mode=mode,
                       params={"mu": mus_b.copy(), "eps": eps_b.copy(), "delta": delta_b.copy(),
                               "smoothing": per_member})


def _with_smoothing(energy: CMMEnergy, name: str) -> CMMEnergy:
    """``energy`` with another smoothing function (a static field: a new compiled program)."""
    from ..energy.smoothings import info

    return CMMEnergy(W=energy.W, weights=energy.weights, mu=energy.mu, eps=energy.eps, delta=energy.delta,
                     smoothing=info(name).name, weighting=energy.weighting)


def _run_group(problem: CMMProblem, args: list, options: stiefel.BlockOptions, mode: str):
    """Compile once (timed apart), then run the group vmapped or as a Python loop."""
    dyn, static = eqx.partition(problem, eqx.is_array)

    def one(dyn, mu, eps, delta, X0):
        return _solve_one(eqx.combine(dyn, static), mu, eps, delta, X0, options)

    if mode == "vmap":
        fn = jax.jit(jax.vmap(one, in_axes=(None, 0, 0, 0, 0)))
        t0 = time.perf_counter()
        compiled = fn.lower(dyn, *args).compile()
        t1 = time.perf_counter()
        out = jax.block_until_ready(compiled(dyn, *args))
        return out, t1 - t0, time.perf_counter() - t1
    fn = jax.jit(one)
    t0 = time.perf_counter()
    compiled = fn.lower(dyn, *(x[0] for x in args)).compile()
    t1 = time.perf_counter()
    rows = [jax.block_until_ready(compiled(dyn, *(x[i] for x in args))) for i in range(args[0].shape[0])]
    out = tuple(jnp.stack(parts) for parts in zip(*rows))
    return out, t1 - t0, time.perf_counter() - t1
