"""Size buckets (``stiefel.runtime.buckets``, ``objectives.cmm.padding``): padded CMM problems give the unpadded
answer, their padded rows stay exactly zero, and two meshes of one bucket share a compiled solver
across processes (JAX's persistent cache)."""

import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse as sp

import stiefel
from objectives.cmm.modes import compressed_modes
from objectives.cmm.base import SolverOptionError
from objectives.cmm.solvers import BlockCMM
from objectives.cmm.padding import PaddedProblem
from stiefel.runtime.buckets import bucket, width_bucket
from stiefel_cases import grid_laplacian


def test_bucket_grid():
    sizes = [bucket(n, 1.2) for n in range(1, 20000, 37)]
    assert all(s >= n for s, n in zip(sizes, range(1, 20000, 37)))
    assert sizes == sorted(sizes) and all(s % 64 == 0 for s in sizes)
    assert all(s < 1.2 * n + 64 for s, n in zip(sizes, range(1, 20000, 37)))  # at most one grid step above
    assert len(set(sizes)) < 30  # a few dozen executables cover every size up to 20K
    assert bucket(7000, 1.2) == bucket(7229, 1.2) and bucket(7229, None) == 7229
    assert bucket(2 * 7229, 1.2) != bucket(7229, 1.2)
    assert width_bucket(13, 1.2) == 16 and width_bucket(16, 1.2) == 16 and width_bucket(13, None) == 13
    for bad in (1.0, 0.5, float("inf"), float("nan"), "2", True):
        with pytest.raises(ValueError, match="bucket growth"):
            bucket(10, bad)
        with pytest.raises(SolverOptionError, match="bucket growth"):
            BlockCMM(bucket_growth=bad)


def _grid(m):
    W = sp.csr_array(grid_laplacian(m))
    return W, np.full(W.shape[0], 1.0 / W.shape[0])


def test_padded_rows_stay_exactly_zero():
    """The gradient, the preconditioned direction and the retraction keep the padded rows at 0."""
    from objectives.cmm.manifold_solvers import _shifted_inverse
    from objectives.admm.splitting import orthonormalize

    W, a = _grid(9)
    padded = PaddedProblem.build(W, a, 1.5)
    assert padded.size > padded.n and padded.W.shape == (padded.size, padded.size)
    solver = BlockCMM(bucket_growth=1.5, preconditioner_shift=0.5)
    _, dt, F, _, _ = solver._setup(W, a, 2.0, None, "uniform", None, padded)
    P, _ = _shifted_inverse(W, a, 0.5, dt, padded)
    assert P.chol.rows.shape == (padded.factor_size,) and P.width == F.W.width == padded.width
    # the factor's entries follow the row bucket: size × (0.25 + 0.5 m) entries per row
    per_row = padded.factor_size / padded.size
    assert abs((per_row - 0.25) / 0.5 - round((per_row - 0.25) / 0.5)) < 2 / padded.size
    S = stiefel.GeneralizedStiefel(padded.a, 3, retraction="cholesky")
    rng = np.random.default_rng(0)
    X = jnp.asarray(padded.pad(orthonormalize(rng.standard_normal((padded.n, 3)), a)))
    G = jax.grad(F)(X)
    eta = -S.proj(X, P.solve(G))
    Y = S.retract(X, 0.3 * eta)
    for Z in (G, P.solve(G), eta, Y):
        assert np.all(np.asarray(Z)[padded.n:] == 0.0)
    # uniform weights are 1/n of the real n
    assert np.allclose(np.asarray(F.weights)[: padded.n], 1.0 / padded.n) and np.all(F.weights[padded.n:] == 0)


@pytest.mark.slow
@pytest.mark.parametrize("weighting", ["area", pytest.param("uniform", marks=pytest.mark.slow)])
def test_padded_solve_matches_exact_shapes(weighting):
    W, _ = _grid(12)
    a = np.linspace(0.5, 1.5, W.shape[0]) / W.shape[0]
    exact = compressed_modes((W, a), 4, 3.0, weighting=weighting, solver=BlockCMM(bucket_growth=None))
    run = compressed_modes((W, a), 4, 3.0, weighting=weighting, solver=BlockCMM(bucket_growth=1.5))
    assert run.params["padded_size"] > W.shape[0] and exact.params["padded_size"] == W.shape[0]
    assert run.modes.shape == exact.modes.shape and run.orthogonality <= 1e-12
    # the same iteration up to the rounding of longer sums (amplified over the iterations); the smoothed minimum is
    # flat, so modes agree to about the square root of the objective's agreement (2.3e-4 measured on AVX-512)
    assert run.objective == pytest.approx(exact.objective, rel=1e-7)
    assert np.max(np.abs(run.modes - exact.modes)) <= 1e-3 * np.max(np.abs(exact.modes))
    assert abs(run.iterations - exact.iterations) <= 3


_SAME_BUCKET = textwrap.dedent("""
    import logging, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_compilation_cache_dir", sys.argv[1])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
    import numpy as np, scipy.sparse as sp
    sys.path.insert(0, "tests")
    from stiefel_cases import grid_laplacian
    from objectives.cmm.modes import compressed_modes
    from objectives.cmm.solvers import BlockCMM
    hits = []
    class Catch(logging.Handler):
        def emit(self, record):
            msg = record.getMessage()
            if "Persistent compilation cache hit" in msg:
                hits.append(msg)
    logging.getLogger("jax._src.compiler").addHandler(Catch())
    logging.getLogger("jax._src.compiler").setLevel(logging.DEBUG)
    W = sp.csr_array(grid_laplacian(int(sys.argv[2])))
    a = np.full(W.shape[0], 1.0 / W.shape[0])
    r = compressed_modes((W, a), 3, 2.0, solver=BlockCMM(max_iters=60, bucket_growth=1.2))
    from stiefel.runtime.program_cache import STATS
    print(r.params["padded_size"], len(hits), STATS["loaded"], STATS["stored"], STATS["exported"])
""")


@pytest.mark.slow
def test_meshes_of_one_bucket_share_the_compiled_solver(tmp_path):
    """A 400-vertex problem compiles; a 441-vertex one (same bucket) in a new process loads every program the
    first stored — the solver's initial state and loop, and the saddle check's — none traced again
    (``stiefel.runtime.program_cache``), and their executables from the persistent cache."""
    script = tmp_path / "run.py"
    script.write_text(_SAME_BUCKET)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**os.environ, "PYTHONPATH": root}
    out = []
    for m in (20, 21):
        p = subprocess.run([sys.executable, str(script), str(tmp_path / "cache"), str(m)], cwd=root, env=env,
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr[-2000:]
        out.append([int(v) for v in p.stdout.split()])
    assert out[0][0] == out[1][0] == bucket(441, 1.2)
    (_, hits0, loaded0, stored0, _), (_, hits1, loaded1, stored1, exported1) = out
    assert hits0 == 0 and loaded0 == 0 and stored0 >= 2  # the solver's two programs at least
    assert loaded1 == stored0 and stored1 == exported1 == 0 and hits1 >= stored0


@pytest.mark.parametrize("growth", [None, 1.5])
def test_padded_preconditioner_is_checked_like_the_unpadded_one(growth):
    """``W + σA`` is validated before padding too: a non-symmetric W is a named error."""
    from stiefel.errors import NotSPDError

    W, a = _grid(6)
    W = W.tolil()
    W[0, 1] += 0.5
    with pytest.raises(NotSPDError, match="not symmetric"):
        compressed_modes((sp.csr_array(W), a), 2, 1.0, start="random",
                         solver=BlockCMM(bucket_growth=growth, preconditioner_shift=1.0))
