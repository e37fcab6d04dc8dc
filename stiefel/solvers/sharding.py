"""Row sharding of the block solver: ``X (n, k)`` split by rows (vertices) across devices.

The block solver is a pure function of pytrees (``solve_block``), so sharding needs no new
solver code: every array whose leading dimension is ``n`` (the iterate ``X``, the diagonal of
``M``, a sparse ``W``'s ELL tables, ℓ1 row weights, a diagonal preconditioner) is placed with
``NamedSharding(mesh, P("rows"))`` and everything else is replicated; ``jax.jit`` then
partitions the whole ``lax.while_loop`` (GSPMD). Row-local work (elementwise terms, ``diag(d)·X``,
the ELL products' multiply-adds) runs on each device's rows; reductions over rows (``XᵀMX``,
traces, norms) become partial sums plus an all-reduce of ``k × k`` blocks; the ELL gathers
``X[cols]`` read neighbours' rows across shard boundaries, which XLA resolves by collectives.

Preconditioners: a sparse factorisation (behind ``SparseOperator.solve`` / ``shifted_inverse``: a CHOLMOD
custom call or a host callback) factors the whole matrix and cannot be partitioned — it would gather ``X``
onto one device. Use none, or a diagonal one such
as ``DiagonalOperator(diag(W) + σ·diag(M))`` (Jacobi), which shards by rows like ``M``.

Multi-host: the same code runs on several hosts, one process per host. Call
``jax.distributed.initialize()`` (coordinator address, process count and id from the
arguments or the cluster environment) in every process *before* any other JAX call, build the
global mesh with ``row_mesh(jax.devices())`` (all devices of all processes; ``jax.devices()``
is global after initialize), and call ``solve_sharded`` with the same arguments in every
process. ``shard_rows`` then places on each process only its own devices' rows
(``jax.make_array_from_callback`` over host data that every process can index), and results
are global ``jax.Array``s: read this process's rows via ``x.addressable_shards``, or gather with
``jax.experimental.multihost_utils.process_allgather``.
"""

from __future__ import annotations

from typing import Any, Callable, Sequence

import equinox as eqx
import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec
from jaxtyping import Array, Float

from .block_solver import BlockOptions
from .block_solver import solve as solve_block
from ..errors import StiefelError
from ..manifolds.manifold import GeneralizedStiefel
from ..linalg.operators import LinearOperator, SparseOperator
from ..result import Result

__all__ = ["ROWS", "row_mesh", "shard_rows", "solve_sharded"]

ROWS = "rows"


def row_mesh(devices: Sequence[jax.Device] | None = None, axis: str = ROWS) -> Mesh:
    """A 1-D device mesh named ``axis`` over ``devices`` (default: all, ``jax.devices()``)."""
    devices = jax.devices() if devices is None else list(devices)
    return Mesh(np.asarray(devices), (axis,))


def _place(leaf, n: int, mesh: Mesh, axis: str):
    sharding = NamedSharding(mesh, PartitionSpec(axis) if leaf.ndim >= 1 and leaf.shape[0] == n else PartitionSpec())
    host = np.asarray(leaf)
    return jax.make_array_from_callback(host.shape, sharding, lambda idx: host[idx])


def shard_rows(tree: Any, n: int, mesh: Mesh | Sequence[jax.Device] | None = None, *, axis: str = ROWS) -> Any:
    """Place every array leaf of ``tree`` with leading dimension ``n`` split by rows over ``mesh``;
    replicate the other array leaves. Non-array leaves (static fields) are untouched.

    ``X (n, k)`` → ``n/D`` rows per device (D devices; ``n`` must be divisible by D).
    """
    mesh = mesh if isinstance(mesh, Mesh) else row_mesh(mesh, axis)
    size = mesh.shape[axis]
    if n % size:
        raise StiefelError(f"n = {n} rows do not split evenly over {size} devices; pad the problem or use "
                           f"a device count dividing n")
    return jax.tree_util.tree_map(lambda x: _place(x, n, mesh, axis) if eqx.is_array(x) else x, tree)


@eqx.filter_jit
def _solve(F, manifold, X0, options, P):
    return solve_block(F, manifold, X0, options, preconditioner=None if P is None else P.solve)


def solve_sharded(F: Callable, manifold: GeneralizedStiefel, X0: Float[Array, "n k"],
                  options: BlockOptions = BlockOptions(), *, mesh: Mesh | Sequence[jax.Device] | None = None,
                  preconditioner: LinearOperator | None = None) -> Result:
    """``solve_block`` with ``X (n, k)`` and all row-indexed data sharded by rows over ``mesh``.

    Args:
      F: the objective ``X (n, k) → scalar`` as a pytree (an ``eqx.Module`` such as
        ``objectives.CMMEnergy``): its ``(n, ...)`` arrays are sharded with ``X``. A plain
        closure works too but keeps its arrays unsharded (replicated constants).
      manifold: ``GeneralizedStiefel`` with a diagonal or ``SparseOperator`` ``M`` (sharded
        by rows; a dense ``M`` is sharded by rows as well, its Cholesky solve will gather).
      X0: start ``(n, k)`` on the manifold.
      options: ``BlockOptions``.
      mesh: a ``Mesh`` with axis ``"rows"``, or devices (default all).
      preconditioner: None or a ``LinearOperator`` whose ``solve`` is applied (e.g. a
        ``DiagonalOperator``, Jacobi); host-callback operators are refused (module docstring).

    Returns:
      ``Result`` (``wall_time = compile_time = 0``) with ``x`` a global array sharded by rows.
    """
    if isinstance(manifold.op, SparseOperator):
        raise StiefelError("a sparse M needs M⁻¹ by a sparse Cholesky factorisation of the whole matrix, which "
                           "cannot be sharded; the sharded path supports a diagonal M (e.g. a lumped mass matrix) "
                           "or a dense one")
    if isinstance(preconditioner, SparseOperator) and (preconditioner.factor is not None
                                                       or preconditioner.chol is not None):
        raise StiefelError("a sparse-factorisation preconditioner (CHOLMOD) cannot be sharded; use None or a "
                           "DiagonalOperator (Jacobi, e.g. diag(W) + σ·diag(M))")
    if preconditioner is not None and not isinstance(preconditioner, LinearOperator):
        raise StiefelError("preconditioner must be a stiefel LinearOperator (a pytree that can be sharded)")
    n = manifold.n
    mesh = mesh if isinstance(mesh, Mesh) else row_mesh(mesh)
    F, manifold, X0, preconditioner = shard_rows((F, manifold, X0, preconditioner), n, mesh)
    return _solve(F, manifold, X0, options, preconditioner)
