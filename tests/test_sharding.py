"""stiefel.solvers.sharding: the block solver with X split by rows over 4 (virtual CPU) devices equals the
single-device solver. The device count must be set before JAX starts, so the check runs in a
subprocess with ``XLA_FLAGS=--xla_force_host_platform_device_count=4``."""

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import stiefel
from stiefel.solvers.sharding import shard_rows, solve_sharded

from mesh_fixtures import surface_arrays, write_mesh

# a subprocess with four virtual devices compiles its own solver (~15 s): in the slow suite, which CI runs too
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]

CHILD = textwrap.dedent(
    """
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp, numpy as np
    import mesh, stiefel
    from stiefel.solvers.sharding import solve_sharded
    from objectives.cmm.batch import cmm_problem, default_options

    lap = mesh.laplacian(mesh.load(sys.argv[1]), weights="cotangent", area="lumped")
    problem, X0 = cmm_problem(lap, 4, weighting="uniform", preconditioner="jacobi")
    F = problem.energy.with_params(mu=0.01 * lap.n, eps=1e-3, delta=1e-3)
    S = problem.manifold
    X0 = S.project_to_manifold(jnp.asarray(X0))
    # a fixed budget: sharded reductions round differently, and over hundreds of CG steps on this
    # non-smooth-ish energy (μ/δ curvature) the two runs drift apart; 25 steps stay at rounding level
    opts = default_options(max_iters=25, gtol=1e-12, ftol=0.0)
    single = jax.jit(lambda F, S, X0, P: stiefel.solve_block(F, S, X0, opts, preconditioner=P.solve))(
        F, S, X0, problem.precond)
    sharded = solve_sharded(F, S, X0, opts, preconditioner=problem.precond)
    x = sharded.x
    try:
        from stiefel.solvers.sharding import shard_rows
        shard_rows(jnp.ones((lap.n + 1, 2)), lap.n + 1)
        uneven = ""
    except stiefel.StiefelError as exc:
        uneven = str(exc)
    print(json.dumps({
        "uneven_error": uneven,
        "n": lap.n,
        "devices": len(jax.devices()),
        "x_devices": sorted(d.id for d in x.sharding.device_set),
        "x_spec": str(x.sharding.spec),
        "shard_shapes": [list(s.data.shape) for s in x.addressable_shards],
        "shard_rows": [[s.index[0].start, s.index[0].stop] for s in x.addressable_shards],
        "iterations": [int(single.iterations), int(sharded.iterations)],
        "status": [int(single.status), int(sharded.status)],
        "max_dx": float(jnp.max(jnp.abs(single.x - x))),
        "values": [float(single.value), float(sharded.value)],
        "start_value": float(F(X0)),
        "dist": float(S.dist_to_manifold(x)),
    }))
    """
)


@pytest.fixture(scope="module")
def child_report(tmp_path_factory):
    # the generated genus-1 torus of 48 × 18 = 864 vertices (tests/mesh_fixtures.py; it replaced hand_868.obj,
    # 868 = 4 · 217): the rows must split evenly over the 4 devices, which the 642-vertex stand-ins do not
    path = write_mesh(tmp_path_factory.mktemp("sharding") / "torus_864.obj", *surface_arrays("torus"))
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4", JAX_PLATFORMS="cpu",
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.run([sys.executable, "-c", CHILD, str(path)], env=env, cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_x_is_split_by_rows_over_four_devices(child_report):
    r = child_report
    assert r["devices"] == 4 and r["x_devices"] == [0, 1, 2, 3]
    assert "rows" in r["x_spec"]
    q = r["n"] // 4
    assert r["shard_shapes"] == [[q, 4]] * 4
    assert sorted(map(tuple, r["shard_rows"])) == [(i * q, (i + 1) * q) for i in range(4)]
    assert "do not split evenly over 4 devices" in r["uneven_error"]


def test_sharded_result_equals_single_device(child_report):
    r = child_report
    assert r["iterations"] == [25, 25] and r["status"][0] == r["status"][1]
    assert r["max_dx"] <= 1e-10
    assert abs(r["values"][0] - r["values"][1]) <= 1e-12 * abs(r["values"][0])
    assert r["values"][1] < r["start_value"]  # the solver moved
    assert r["dist"] <= 1e-10


def test_host_callback_preconditioner_and_sparse_metric_are_refused():
    n, k = 8, 2
    W = np.diag(np.arange(1.0, n + 1))
    S = stiefel.GeneralizedStiefel(np.ones(n), k)
    X0 = S.random_point(jax.random.PRNGKey(0))
    F = lambda X: jnp.sum(X * (W @ X))  # noqa: E731
    import scipy.sparse as sp

    with pytest.raises(stiefel.StiefelError, match="cannot be sharded"):
        solve_sharded(F, S, X0, preconditioner=stiefel.as_operator(sp.csr_array(W)))
    with pytest.raises(stiefel.StiefelError, match="sparse M"):
        solve_sharded(F, stiefel.GeneralizedStiefel(sp.identity(n, format="csr"), k), X0)


def test_shard_rows_places_row_arrays_only():
    """On however many devices this process has, row arrays are sharded and the rest replicated."""
    n = 4 * len(jax.devices())
    tree = {"X": jnp.ones((n, 3)), "small": jnp.ones((3, 3)), "static": "keep"}
    out = shard_rows(tree, n)
    assert out["static"] == "keep"
    assert "rows" in str(out["X"].sharding.spec) and out["small"].sharding.is_fully_replicated
