"""objectives.cmm.batch: a vmapped batch of CMM solves equals the same solves one at a time."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import stiefel
from objectives.cmm.batch import cmm_batch, cmm_problem, default_options
from objectives.energy.energies import cmm_energy

from mesh_fixtures import hand_laplacian

K = 4


@pytest.fixture(scope="module")
def lap():
    """The hand stand-in (tests/mesh_fixtures.py: starfish, 642 vertices; it replaced hand_868.obj)."""
    return hand_laplacian()


def _assert_same(a, b, *, x_tol=1e-8):
    """Same iterations and statuses; modes and objectives equal up to rounding."""
    np.testing.assert_array_equal(a.iterations, b.iterations)
    np.testing.assert_array_equal(a.status, b.status)
    assert np.max(np.abs(a.modes - b.modes)) <= x_tol
    np.testing.assert_allclose(a.value, b.value, rtol=1e-10)  # batched and single CHOLMOD calls round apart (2e-11)
    np.testing.assert_allclose(a.objective, b.objective, rtol=1e-10)


@pytest.mark.slow
@pytest.mark.parametrize("preconditioner", ["shifted", None])
def test_vmap_over_mu_equals_loop(lap, preconditioner):
    """A fixed iteration budget, so both runs take the same steps: the vmapped batch of three μ
    values equals the Python loop of the same compiled single solver, member by member."""
    mus = np.array([0.005, 0.01, 0.03]) * lap.n
    opts = default_options(max_iters=12, gtol=1e-12, ftol=0.0)
    kw = dict(weighting="uniform", preconditioner=preconditioner, options=opts)
    batched = cmm_batch(lap, K, mus, mode="vmap", **kw)
    looped = cmm_batch(lap, K, mus, mode="loop", **kw)
    assert batched.modes.shape == (3, lap.n, K)
    _assert_same(batched, looped)
    assert np.all(batched.iterations == 12) and batched.status_names == ["max_iters"] * 3
    assert np.max(batched.orthogonality) <= 1e-10
    # the members really differ (μ is batched, not broadcast from one member)
    assert np.all(np.diff(batched.objective) > 0)
    assert np.max(np.abs(batched.modes[0] - batched.modes[2])) > 1e-3


@pytest.mark.slow
def test_loop_member_equals_stiefel_minimize(lap):
    """The loop's single solver is the block solver of ``stiefel.minimize`` (same energy, start,
    preconditioner and options)."""
    mu = 0.01 * lap.n
    opts = default_options(max_iters=12, gtol=1e-12, ftol=0.0)
    looped = cmm_batch(lap, K, [mu], weighting="uniform", options=opts, mode="loop")
    problem, X0 = cmm_problem(lap, K, weighting="uniform")
    F = cmm_energy(lap.W, lap.A.diagonal(), mu, smoothing="f6", weighting="uniform")
    S = problem.manifold
    ref = stiefel.minimize(F, S, S.project_to_manifold(jnp.asarray(X0)), method="cg", c2=0.1,
                           preconditioner=problem.precond, gtol=1e-12, max_iters=12)
    assert int(ref.iterations) == int(looped.iterations[0])
    assert np.max(np.abs(np.asarray(ref.x) - looped.modes[0])) <= 1e-9
    assert float(ref.value) == pytest.approx(float(looped.value[0]), rel=1e-12)


@pytest.mark.slow  # 17 s; test_vmap_over_mu_equals_loop covers vmap in the default run
def test_vmap_over_starts_and_smoothings(lap):
    """Random starts and ε/δ are batched too; a list of different smoothing functions runs one
    vmapped group per function and equals the per-smoothing batches."""
    rng = np.random.default_rng(0)
    starts = rng.standard_normal((3, lap.n, K))
    opts = default_options(max_iters=10, gtol=1e-12, ftol=0.0)
    mu = 0.01 * lap.n
    kw = dict(weighting="uniform", preconditioner="jacobi", options=opts, mode="vmap")
    batched = cmm_batch(lap, K, mu, starts=starts, eps=[1e-3, 1e-2, 1e-1], delta=[1e-3, 1e-2, 1e-1], **kw)
    looped = cmm_batch(lap, K, mu, starts=starts, eps=[1e-3, 1e-2, 1e-1], delta=[1e-3, 1e-2, 1e-1],
                       **{**kw, "mode": "loop"})
    _assert_same(batched, looped)
    assert np.max(batched.orthogonality) <= 1e-10
    mixed = cmm_batch(lap, K, [mu, mu, 2 * mu], smoothing=["f6", "f3", "f6"], **kw)
    f6 = cmm_batch(lap, K, [mu, 2 * mu], smoothing="f6", **kw)
    f3 = cmm_batch(lap, K, [mu], smoothing="f3", **kw)
    assert mixed.params["smoothing"] == ["f6", "f3", "f6"]
    np.testing.assert_allclose(mixed.value[[0, 2]], f6.value, rtol=1e-11)
    np.testing.assert_allclose(mixed.value[1], f3.value[0], rtol=1e-11)
    assert abs(mixed.value[0] - mixed.value[1]) > 1e-6 * abs(mixed.value[0])


@pytest.mark.slow
def test_expand_dims_callback_matches_sequential(lap):
    """The host-factorisation preconditioner batched as one host call (``expand_dims``) gives the same
    batch as one call per member, and both the same as the CHOLMOD custom call."""
    mus = np.array([0.005, 0.02]) * lap.n
    opts = default_options(max_iters=8, gtol=1e-12, ftol=0.0)
    kw = dict(weighting="uniform", options=opts, mode="vmap")
    seq = cmm_batch(lap, K, mus, callback_vmap="sequential", solve_backend="callback", **kw)
    one = cmm_batch(lap, K, mus, callback_vmap="expand_dims", solve_backend="callback", **kw)
    _assert_same(seq, one, x_tol=1e-12)
    _assert_same(seq, cmm_batch(lap, K, mus, **kw))


@pytest.mark.slow
def test_auto_mode_is_the_loop_on_cpu_and_vmap_elsewhere(lap, monkeypatch):
    """``mode="auto"`` (the default) runs the loop on a CPU backend (measured faster there) and says so."""
    opts = default_options(max_iters=3, gtol=1e-12, ftol=0.0)
    out = cmm_batch(lap, K, [0.01 * lap.n, 0.02 * lap.n], weighting="uniform", preconditioner=None, options=opts)
    assert out.mode == ("loop" if jax.default_backend() == "cpu" else "vmap")
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    on_gpu = cmm_batch(lap, K, [0.01 * lap.n, 0.02 * lap.n], weighting="uniform", preconditioner=None, options=opts)
    assert on_gpu.mode == "vmap"
    _assert_same(out, on_gpu)


def test_bad_batch_input(lap):
    with pytest.raises(ValueError, match="batch sizes disagree"):
        cmm_batch(lap, K, [1.0, 2.0], eps=[1e-3, 1e-2, 1e-1])
    with pytest.raises(ValueError, match="mode"):
        cmm_batch(lap, K, [1.0], mode="pmap")
    with pytest.raises(ValueError, match="preconditioner"):
        cmm_batch(lap, K, [1.0], preconditioner="ilu")
    with pytest.raises(ValueError, match="solve_backend"):  # checked even where no sparse solve would use it
        cmm_batch(lap, K, [1.0], preconditioner=None, solve_backend="umfpack")
    with pytest.raises(ValueError, match="callback_vmap"):
        cmm_batch(lap, K, [1.0], preconditioner=None, callback_vmap="parallel")
