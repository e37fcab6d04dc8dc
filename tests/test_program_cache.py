"""Stored solver programs (``stiefel.runtime.program_cache``): keys that pin the program, no store for code the
key cannot pin, the same answer from a stored program, and corrupt entries ignored."""

import functools
import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from stiefel import program_cache as pc


def test_describe_pins_static_parts_and_refuses_unknown_code():
    from objectives.energy.energies import cmm_energy
    from stiefel.linalg.operators import SparseOperator
    from stiefel_cases import grid_laplacian

    W = grid_laplacian(5)
    a = np.full(25, 0.04)
    e1 = cmm_energy(SparseOperator.from_scipy(W), a, 1.0, smoothing="f6")
    e2 = cmm_energy(SparseOperator.from_scipy(2 * W), 2 * a, 3.0, smoothing="f6")  # other values
    e3 = cmm_energy(SparseOperator.from_scipy(W), a, 1.0, smoothing="f3")  # another smoothing
    e4 = cmm_energy(SparseOperator.from_scipy(grid_laplacian(6)), np.full(36, 1 / 36), 1.0, smoothing="f6")
    assert pc.describe(e1) == pc.describe(e2)  # runtime values do not matter, nor the host matrix
    assert pc.describe(e1) != pc.describe(e3)  # static fields do
    assert pc.describe(e1) != pc.describe(e4)  # shapes do
    assert pc.describe(e1.true_value) != pc.describe(e1.__call__)
    assert pc.describe((1.0, 2, "x", None)) == "(1.0,2,'x',None)"
    assert pc.describe(jnp.zeros((2, 3))) != pc.describe(jnp.zeros((2, 3), jnp.int32))

    def local(x):
        return x

    for bad in (lambda x: x, local, np.sum, functools.partial(local, 1), object(), jnp.sin):
        with pytest.raises(pc.Uncacheable):
            pc.describe(bad)
    assert pc.program_key(lambda x: x, ()) is None


@pytest.mark.filterwarnings("ignore:A JAX array is being set as static")
def test_arrays_in_static_fields_are_described_by_content():
    """A static field's arrays are constants of the traced program: their values are part of the key."""
    import equinox as eqx

    class Holder(eqx.Module):
        table: np.ndarray = eqx.field(static=True)
        x: jax.Array

    Holder.__module__ = "stiefel.tests_only"  # a module of this project, for describe
    one = Holder(np.arange(3.0), jnp.zeros(2))
    assert pc.describe(one) == pc.describe(Holder(np.arange(3.0), jnp.ones(2)))  # x is an input
    assert pc.describe(one) != pc.describe(Holder(np.arange(3.0) + 1, jnp.zeros(2)))  # table is a constant


@pytest.mark.skipif(bool(jax.config.jax_compilation_cache_dir), reason="JAX's persistent cache is on here")
def test_no_store_without_jax_cache_dir():
    from stiefel.solvers.driver import _init

    assert pc.store_dir() is None and pc.load_or_export(_init, (), None) is None


_RUN = textwrap.dedent("""
    import json, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    if sys.argv[1] != "-":
        jax.config.update("jax_compilation_cache_dir", sys.argv[1])
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
    import numpy as np, scipy.sparse as sp
    import jax.numpy as jnp
    sys.path.insert(0, "tests")
    from stiefel_cases import grid_laplacian
    from objectives.cmm.modes import compressed_modes
    from objectives.cmm.solvers import BlockCMM
    from stiefel import program_cache, minimize, GeneralizedStiefel, as_operator
    W = sp.csr_array(grid_laplacian(int(sys.argv[2])))
    a = np.full(W.shape[0], 1.0 / W.shape[0])
    r = compressed_modes((W, a), 3, 2.0, solver=BlockCMM(max_iters=200, smoothing=sys.argv[3]))
    out = {"objective": r.objective, "iterations": r.iterations, **program_cache.STATS}
    if len(sys.argv) > 4:  # a user's own function: never stored
        Wop = as_operator(W, check=False, factor=False)
        S = GeneralizedStiefel(a, 2)
        before = dict(program_cache.STATS)
        res = minimize(lambda X: jnp.sum(X * Wop.mv(X)), S, S.random_point(jax.random.PRNGKey(0)), max_iters=20)
        out["user_function_stored"] = program_cache.STATS != before
    print(json.dumps(out))
""")


def _run(tmp_path, cache, m, smoothing="f6", *extra):
    script = tmp_path / "run.py"
    script.write_text(_RUN)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**os.environ, "PYTHONPATH": root}
    p = subprocess.run([sys.executable, str(script), str(cache), str(m), smoothing, *extra], cwd=root, env=env,
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr[-2000:]
    import json

    return json.loads(p.stdout.strip().splitlines()[-1])


@pytest.mark.slow  # six processes (~40 s); test_buckets checks the loading of stored programs in the default run
def test_stored_programs_serve_new_processes_with_the_same_answer(tmp_path):
    cache = tmp_path / "cache"
    plain = _run(tmp_path, "-", 8)  # no cache: traced as usual
    assert plain["exported"] == plain["loaded"] == 0
    first = _run(tmp_path, cache, 8, "f6", "user")
    assert first["exported"] == 2 and first["loaded"] == 0 and first["memory"] >= 1  # later stages from memory
    assert not first["user_function_stored"]
    stored = sorted((cache / pc.SUBDIR).glob("*.jaxexport"))
    assert len(stored) == 2
    second = _run(tmp_path, cache, 8)
    assert second["loaded"] == 2 and second["exported"] == 0
    for run in (first, second):
        assert run["iterations"] == plain["iterations"]
        assert run["objective"] == pytest.approx(plain["objective"], rel=1e-12)
    # another smoothing is another program; a corrupt entry is ignored (traced and stored again)
    other = _run(tmp_path, cache, 8, "f3")
    assert other["exported"] == 2 and other["loaded"] == 0
    for path in stored:
        path.write_bytes(b"not a program")
    again = _run(tmp_path, cache, 8)
    assert again["exported"] == 2 and again["objective"] == pytest.approx(plain["objective"], rel=1e-12)
