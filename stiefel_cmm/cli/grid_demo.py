"""Demo of the manifold layer: the first k generalised eigenpairs of a grid Laplacian.

Run ``python -m stiefel_cmm.cli.grid_demo [--grid 60] [-k 10]``. It minimises ``xᵀWx`` column by
column on ``{ΦᵀMx = 0, xᵀMx = 1}`` (thesis Algorithm 6 with μ = 0, docs/maths.md §2) and
compares with ``scipy.sparse.linalg.eigsh``; then runs the block solver on
``tr(XᵀWX)``. ``W`` is the graph Laplacian of an m×m grid, ``M`` a random
positive diagonal.
"""

from __future__ import annotations

import argparse
import sys

import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla


def grid_laplacian(m: int) -> sp.csr_array:
    """Graph Laplacian ``Deg − Adj`` of an m×m grid (n = m²)."""
    e = np.ones(m)
    path = sp.diags_array([-e[:-1], np.r_[1.0, 2.0 * e[2:], 1.0], -e[:-1]], offsets=[-1, 0, 1])
    eye = sp.identity(m)
    return sp.csr_array(sp.kron(path, eye) + sp.kron(eye, path))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m stiefel_cmm.cli.grid_demo", description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=60, help="grid side m (n = m²), default 60")
    parser.add_argument("-k", type=int, default=10, help="number of eigenpairs, default 10")
    parser.add_argument("--gtol", type=float, default=1e-8)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    import stiefel

    # An application (this demo) may set JAX's global configuration; the library never does.
    jax.config.update("jax_enable_x64", True)
    W = grid_laplacian(args.grid)
    n = W.shape[0]
    M = np.random.default_rng(args.seed).uniform(0.5, 2.0, n)
    ref = sla.eigsh(sp.csc_array(W), k=args.k, M=sp.diags_array(M).tocsc(), sigma=-1e-6, which="LM")[0]
    Wop = stiefel.as_operator(W, check=False, factor=False)
    P = stiefel.shifted_inverse(W, M, sigma=0.5 * ref[1])

    def f(x):
        return jnp.dot(x, Wop.mv(x))

    print(f"grid {args.grid}×{args.grid}: n = {n}, k = {args.k}, gtol = {args.gtol:g} (float64)")
    res = stiefel.minimize_sequential(f, M, args.k, gtol=args.gtol, max_iters=2000, preconditioner=P,
                                      seed=args.seed)
    print("\nsequential solver (Algorithm 6, CG directions, preconditioner (W + σM)⁻¹):")
    print(f"{'j':>3} {'λ_j (solver)':>22} {'λ_j (eigsh)':>22} {'err/λ_k':>9} {'iters':>6} status")
    for j in range(args.k):
        v, r = float(res.values[j]), float(ref[j])
        err = abs(v - r) / abs(float(ref[-1]))
        print(f"{j:>3} {v:>22.15e} {r:>22.15e} {err:>9.1e} {int(res.iterations[j]):>6} {res.status_names[j]}")
    print(f"orthogonality max|XᵀMX − I| = {res.stats['dist_to_manifold']:.1e}; "
          f"{res.wall_time:.2f} s (+{res.compile_time:.2f} s compile)")

    S = stiefel.GeneralizedStiefel(M, args.k, retraction="cholesky")

    def F(X):
        return jnp.sum(X * Wop.mv(X))

    block = stiefel.minimize(F, S, S.random_point(jax.random.PRNGKey(args.seed)), method="cg",
                             gtol=args.gtol, max_iters=2000, preconditioner=P)
    print(f"\nblock solver (Riemannian CG, Cholesky retraction): tr(XᵀWX) = {float(block.value):.15e}, "
          f"Σλ = {ref.sum():.15e}, {int(block.iterations)} iterations, {block.status_name}, "
          f"{block.wall_time:.2f} s (+{block.compile_time:.2f} s compile)")
    ok = res.converged and block.converged and np.allclose(np.asarray(res.values), ref, rtol=1e-6, atol=1e-10)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
