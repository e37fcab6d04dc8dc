"""Derivatives through manifold solves: backward-pass cost against the forward solve.

``python -m bench autodiff [--subdivisions 5] [--k 10] [--repeats 3]``: on the built-in demo
surface (icosphere, ``--subdivisions 5``: n = 10 242) the smoothed CMM solve of
``objectives.cmm.differentiable.cmm_solve`` (Huber, ε = 0.5, μ = 0.05n, L-BFGS, preconditioner
``(W + σA)⁻¹``, one wider stage ε = 2 first, started from the eigenbasis), and the gradient of a non-invariant loss
``Σ c∘Ψ`` with respect to (μ, the per-vertex ℓ1 weights, ε) by the implicit adjoint. Reported,
each as the median of ``--repeats`` warm calls, compile time apart:

* forward: ``jax.jit(loss)``; forward + backward: ``jax.jit(jax.grad(loss))``; backward alone:
  the pullback of ``jax.vjp`` (the transposed adjoint solve), and its ratio to the forward solve;
* XLA's temporary-memory estimate (``compiled.memory_analysis()``) of both programs;
* unrolled reverse mode (``optx.RecursiveCheckpointAdjoint``), where it runs at all.

Writes ``docs/benchmarks/autodiff.json``; ``docs/benchmarks/autodiff.md`` quotes it.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # an application: float64 (the library never sets this)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import optimistix as optx  # noqa: E402

import mesh  # noqa: E402
import stiefel  # noqa: E402
from bench.environment import results_path, run_meta, write_atomic  # noqa: E402
from stiefel_cmm.cli.demo_mesh import demo_mesh  # noqa: E402
from objectives.cmm.modes import first_eigenpairs  # noqa: E402
from objectives.cmm.differentiable import cmm_solve  # noqa: E402
from objectives.energy.energies import CMMEnergy  # noqa: E402



def _timed(fn, *args, repeats):
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    first = time.perf_counter() - t0
    warm = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        warm.append(time.perf_counter() - t0)
    med = statistics.median(warm)
    return {"first_s": first, "warm_s": med, "compile_s": max(first - med, 0.0)}


def _temp_bytes(fn, *args):
    try:
        mem = jax.jit(fn).lower(*args).compile().memory_analysis()
        return int(mem.temp_size_in_bytes + mem.output_size_in_bytes)
    except Exception as exc:  # memory analysis is backend-dependent
        return f"unavailable ({type(exc).__name__})"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench autodiff", description=__doc__.splitlines()[0])
    ap.add_argument("--subdivisions", type=int, default=5)
    ap.add_argument("--k", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", type=Path, default=None, help="default: docs/benchmarks/autodiff.json")
    args = ap.parse_args(argv)

    V, F = demo_mesh(args.subdivisions)
    m = mesh.load((V, F))
    lap = mesh.laplacian(m)
    a = lap.A.diagonal()
    n, k = a.shape[0], args.k
    evals, evecs = first_eigenpairs(lap.W, a, k)
    P = stiefel.shifted_inverse(lap.W, a, float(evals[-1])).solve
    Wop = stiefel.linalg.operators.SparseOperator.from_scipy(lap.W)
    area = jnp.asarray(a)
    mu0 = 0.05 * n
    t0 = time.perf_counter()
    Xs, res = cmm_solve(Wop, area, jnp.asarray(evecs[:, :k]), mu0, stages=(4.0,), preconditioner=P)
    start_s = time.perf_counter() - t0
    c = jnp.asarray(np.random.default_rng(0).standard_normal((n, k)))
    X_eig = jnp.asarray(evecs[:, :k])

    def loss(theta):
        mu, w, eps = theta
        Psi, _ = cmm_solve(Wop, area, X_eig, mu, weights=w, eps=eps, stages=(4.0,), preconditioner=P, gtol=1e-9)
        return jnp.sum(c * Psi)

    theta = (jnp.asarray(mu0), area, jnp.asarray(0.5))
    fwd = _timed(jax.jit(loss), theta, repeats=args.repeats)
    both = _timed(jax.jit(jax.grad(loss)), theta, repeats=args.repeats)
    _, pullback = jax.vjp(jax.jit(loss), theta)  # the forward pass once; then the backward pass alone
    bwd = _timed(jax.jit(pullback), jnp.asarray(1.0), repeats=args.repeats)
    backward = bwd["warm_s"]
    iters = int(res.iterations)

    # unrolled reverse mode through the iterations, for comparison
    S = stiefel.GeneralizedStiefel(a, k, retraction="cholesky")
    solver = stiefel.solver_for(S, stiefel.BlockOptions(method="lbfgs", gtol=1e-9, max_iters=3000, c2=0.9),
                                preconditioner=P, history=False)

    def unrolled(mu):
        energy = CMMEnergy(W=Wop, weights=area, mu=mu, eps=jnp.asarray(0.5), delta=jnp.asarray(0.5),
                           smoothing="f6", weighting="area")
        sol = optx.minimise(lambda X, e: e(X), solver, Xs, energy, max_steps=3000, throw=False,
                            adjoint=optx.RecursiveCheckpointAdjoint())
        return jnp.sum(c * sol.value)

    try:
        jax.grad(unrolled)(jnp.asarray(mu0))
        unrolled_note = "ran"
    except Exception as exc:
        unrolled_note = f"does not run: {type(exc).__name__}: {str(exc).splitlines()[0][:160]}"

    out = {
        "meta": run_meta("bench autodiff", argv, mesh=f"demo icosphere, subdivisions={args.subdivisions}",
                         n=n, k=k, mu=mu0, smoothing="f6", eps=0.5, method="lbfgs", gtol=1e-9),
        "eager_solve_s": start_s, "last_stage_iterations": iters,
        "forward": fwd, "forward_and_backward": both, "backward": bwd, "backward_s": backward,
        "backward_over_forward": backward / fwd["warm_s"],
        "temp_bytes": {"forward": _temp_bytes(loss, theta), "forward_and_backward": _temp_bytes(jax.grad(loss), theta),
                       "X_bytes": n * k * 8},
        "recursive_checkpoint_adjoint": unrolled_note,
    }
    write_atomic(args.out or results_path("autodiff", ".json"), json.dumps(out, indent=2, default=str) + "\n")
    print(json.dumps(out, indent=2, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
