"""The host loop over compiled chunks (stiefel.solvers.driver): same iterates as one loop, bounded progress reports,
clean stops, no callback in the compiled program, and the persistent compilation cache serves it."""

import math
import os
import subprocess
import sys
import textwrap
import threading

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from stiefel import (CallbackError, GeneralizedStiefel, Progress, Status, as_operator, minimize, shifted_inverse,
                     solve_block)
from stiefel.solvers.block_solver import BlockOptions

from stiefel_cases import grid_laplacian, metric_matrix

K = 3


@pytest.fixture(scope="module")
def problem():
    W = grid_laplacian(7)
    M = metric_matrix("sparse", W.shape[0], seed=2)
    Wop = as_operator(W, check=False, factor=False)
    S = GeneralizedStiefel(M, K, retraction="cholesky")
    X0 = S.random_point(jax.random.PRNGKey(3))
    return W, M, (lambda X: jnp.sum(X * Wop.mv(X))), S, X0


@pytest.mark.slow
def test_chunked_iterates_equal_one_loop(problem):
    """``minimize`` (host loop over chunks, tiny chunks forced) and ``solve_block`` (optx.minimise, one
    while_loop) take the same iterations to the same point."""
    W, M, F, S, X0 = problem
    P = shifted_inverse(W, M, 0.1)
    reports = []
    res = minimize(F, S, X0, gtol=1e-10, max_iters=400, preconditioner=P, progress=reports.append,
                   progress_interval=1e-6)
    ref = solve_block(F, S, X0, BlockOptions(gtol=1e-10, max_iters=400), preconditioner=P.solve)
    assert res.converged and int(ref.status) == Status.CONVERGED
    assert int(res.iterations) == int(ref.iterations)
    np.testing.assert_allclose(np.asarray(res.x), np.asarray(ref.x), atol=1e-9)
    np.testing.assert_allclose(res.trimmed_history()["value"], ref.trimmed_history()["value"], rtol=1e-12)
    assert len(reports) >= 3  # many chunks, one report each
    its = [r.iteration for r in reports]
    assert its == sorted(its) and its[-1] == int(res.iterations)
    assert all(isinstance(r, Progress) and r.max_iters == 400 and np.isfinite(r.objective) for r in reports)
    assert reports[-1].remaining == 0.0 and reports[-1].grad_norm <= 1e-10
    assert float(S.dist_to_manifold(res.x)) <= 1e-12 and float(res.stats["dist_to_manifold"]) <= 1e-12


@pytest.mark.slow
def test_reports_are_rate_limited(problem):
    """With the default interval the reports come at most a few per second, whatever the iteration speed."""
    _, _, F, S, X0 = problem
    reports = []
    res = minimize(F, S, X0, gtol=1e-14, max_iters=3000, progress=reports.append, progress_interval=0.2)
    elapsed = reports[-1].elapsed
    its = int(res.iterations)
    assert its > 50
    # gtol 1e-14 is out of reach: the run ends on the round-off floor (line_search_failed), after the warm-up
    # chunks of 1, 4, 16, … iterations (at most 1 + ⌈log₄ its⌉), the start's and the end's reports
    warmup = 1 + math.ceil(math.log(its, 4))
    assert len(reports) <= 2 + warmup + elapsed / 0.2 * 1.5


@pytest.mark.slow
def test_stop_event_and_ctrl_c_interrupt_with_the_current_iterate(problem):
    _, _, F, S, X0 = problem
    stop = threading.Event()

    def second_report_stops(info):
        if info.iteration > 1:
            stop.set()

    res = minimize(F, S, X0, gtol=1e-14, max_iters=3000, progress=second_report_stops, progress_interval=1e-6,
                   stop=stop)
    assert res.status_name == "interrupted" and 1 < int(res.iterations) < 3000
    assert float(S.dist_to_manifold(res.x)) <= 1e-12
    assert float(res.value) == pytest.approx(float(F(res.x)), rel=1e-12)  # the iterate and its value agree

    def ctrl_c(info):
        if info.iteration >= 5:
            raise KeyboardInterrupt

    res = minimize(F, S, X0, gtol=1e-14, max_iters=3000, progress=ctrl_c, progress_interval=1e-6)
    assert res.status_name == "interrupted" and int(res.iterations) >= 5
    already = threading.Event()
    already.set()
    res = minimize(F, S, X0, max_iters=100, stop=already)  # set before the start: no iteration
    assert res.status_name == "interrupted" and int(res.iterations) == 0
    np.testing.assert_array_equal(np.asarray(res.x), np.asarray(X0))


def test_a_raising_callback_is_a_named_error_with_the_iterate(problem):
    _, _, F, S, X0 = problem

    def broken(info):
        if info.iteration >= 3:
            raise RuntimeError("plot window closed")

    with pytest.raises(CallbackError, match="RuntimeError: plot window closed") as err:
        minimize(F, S, X0, gtol=1e-14, max_iters=500, progress=broken, progress_interval=1e-6)
    res = err.value.result
    assert res.status_name == "interrupted" and int(res.iterations) >= 3
    assert isinstance(err.value.__cause__, RuntimeError)
    with pytest.raises(ValueError, match="progress_interval"):
        minimize(F, S, X0, progress_interval=0.0)


def test_compiled_loop_has_no_host_callback(problem):
    """The chunk program of a problem with a sparse M and a sparse preconditioner calls no Python."""
    from stiefel import driver
    from stiefel.solvers.block_solver import _NoArgs, solver_for

    W, M, F, S, X0 = problem
    solver = solver_for(S, BlockOptions(max_iters=10), F=F, preconditioner=shifted_inverse(W, M, 0.1).solve)
    fn = driver._NoAux(_NoArgs(F))
    state = driver._init(solver, fn, X0, None)
    text = str(jax.make_jaxpr(lambda s: driver._advance(solver, fn, None, s, jnp.asarray(5)))(state))
    assert "callback" not in text and "custom_linear_solve" in text


@pytest.mark.slow
def test_progress_and_stop_reach_the_block_cmm_stages():
    from objectives.cmm.modes import compressed_modes
    from objectives.cmm.solvers import BlockCMM

    W = grid_laplacian(9)
    a = np.full(W.shape[0], 1.0 / W.shape[0])
    reports = []
    r = compressed_modes((W, a), 4, 2.0, solver=BlockCMM(max_iters=2000), progress=reports.append)
    assert r.status == "converged"
    assert {p.stage for p in reports} == {0, 1, 2, 3} and all(p.n_stages == 4 and p.method == "block" for p in reports)
    assert reports[-1].iteration == r.iterations
    assert all(p.remaining is None or p.remaining > 0 for p in reports[:-1])  # stage ends are not "0 s left"
    stop = threading.Event()

    def halt(info):
        if info.stage == 1:
            stop.set()

    r2 = compressed_modes((W, a), 4, 2.0, solver=BlockCMM(max_iters=2000), progress=halt, stop=stop)
    assert r2.status == "interrupted" and r2.iterations < r.iterations
    assert r2.orthogonality <= 1e-12


_CACHED = textwrap.dedent("""
    import logging, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    jax.config.update("jax_compilation_cache_dir", sys.argv[1])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
    import jax.numpy as jnp
    sys.path.insert(0, "tests")
    from stiefel_cases import grid_laplacian, metric_matrix
    from stiefel import GeneralizedStiefel, as_operator, minimize, shifted_inverse
    W = grid_laplacian(6)
    M = metric_matrix("sparse", W.shape[0], seed=1)
    Wop = as_operator(W, check=False, factor=False)
    S = GeneralizedStiefel(M, 2, retraction="cholesky")
    hits = []
    class Catch(logging.Handler):
        def emit(self, record):
            msg = record.getMessage()
            if "Persistent compilation cache hit" in msg and "jit__call" in msg:
                hits.append(msg)
    logging.getLogger("jax._src.compiler").addHandler(Catch())
    logging.getLogger("jax._src.compiler").setLevel(logging.DEBUG)
    res = minimize(lambda X: jnp.sum(X * Wop.mv(X)), S, S.random_point(jax.random.PRNGKey(0)), gtol=1e-8,
                   preconditioner=shifted_inverse(W, M, 0.2))
    print(res.status_name, len(hits))
""")


@pytest.mark.slow
def test_persistent_cache_serves_the_solver_in_a_new_process(tmp_path):
    """Two fresh processes: the second one loads both solver programs (init and advance) from the cache —
    impossible while a sparse solve was a host callback."""
    script = tmp_path / "run.py"
    script.write_text(_CACHED)
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    env = {**os.environ, "PYTHONPATH": root}
    out = []
    for _ in range(2):
        p = subprocess.run([sys.executable, str(script), str(tmp_path / "cache")], cwd=root, env=env,
                           capture_output=True, text=True, timeout=300)
        assert p.returncode == 0, p.stderr[-2000:]
        out.append(p.stdout.split())
    assert out[0] == ["converged", "0"]
    assert out[1][0] == "converged" and int(out[1][1]) >= 2


@pytest.mark.slow
@pytest.mark.parametrize("method", ["admm", "admm_sequential", "fast", "sequential"])
def test_every_cmm_solver_reports_progress_and_stops(method):
    """Progress reaches every CMM solver (ADMM ones a few times per second, the sequential one per column,
    the last report at the end); they stop on ``stop`` with the iterate reached (sequential: between columns)."""
    import mesh
    from stiefel_cmm.cli.demo_mesh import demo_mesh
    from objectives.cmm.modes import compressed_modes
    from objectives.cmm.solvers import ADMMCMM, FastCMM, SequentialADMMCMM, SequentialCMM

    m = mesh.load(demo_mesh())
    lap = mesh.laplacian(m)
    make = {"admm": lambda: ADMMCMM(max_iters=300), "admm_sequential": lambda: SequentialADMMCMM(max_iters=300),
            "fast": lambda: FastCMM(mesh.local_functions(m, n_samples=60).U, max_iters=300),
            "sequential": lambda: SequentialCMM(max_iters=300)}[method]
    reports = []
    r = compressed_modes(lap, 3, 0.01 * lap.n, solver=make(), progress=reports.append)
    assert reports and reports[-1].iteration == r.iterations and reports[-1].remaining == 0.0
    assert all(p.method == method for p in reports)
    stop = threading.Event()
    if method == "sequential":
        assert [p.stage for p in reports] == [0, 1, 2] and all(p.n_stages == 3 for p in reports)
        # stopped after the first column: the other two keep their (projected) starts
        r2 = compressed_modes(lap, 3, 0.01 * lap.n, solver=make(), progress=lambda info: stop.set(), stop=stop)
        assert r2.status == "interrupted" and r2.iterations < r.iterations and r2.orthogonality <= 1e-10
        return

    r2 = compressed_modes(lap, 3, 0.01 * lap.n, solver=make(), progress=lambda info: stop.set(), stop=stop)
    assert r2.status == "interrupted" and r2.iterations < min(r.iterations, 300) and r2.orthogonality <= 1e-10


def test_host_monitor_rate_limit_and_errors():
    from stiefel.solvers.driver import HostMonitor

    calls = []
    mon = HostMonitor(calls.append, max_iters=100, method="x", interval=3600.0)
    assert not mon.tick(1, 5.0, 1e-2)  # the first report is due at once
    assert not mon.tick(2, 4.0, 1e-3)  # the next one only after an hour
    assert not mon.tick(3, 3.0, 1e-4, final=True)  # the last one always
    assert [c.iteration for c in calls] == [1, 3] and calls[-1].remaining == 0.0

    def boom(info):
        raise OSError("disk full")

    with pytest.raises(CallbackError, match="OSError: disk full") as err:
        HostMonitor(boom, max_iters=10).tick(1, 1.0, 1.0, error_result="X")
    assert err.value.result == "X"

    def ctrl_c(info):
        raise KeyboardInterrupt

    mon = HostMonitor(ctrl_c, max_iters=10)
    assert mon.tick(1, 1.0, 1.0) and mon.interrupted


def test_one_shot_programs_compile_without_optimisation_and_agree():
    """``optimize=False`` compiles with ``ONE_SHOT_OPTIONS`` (the backend's optimisation level 0): the program's
    results equal the optimised program's, and a refused option would raise here rather than be ignored."""
    from stiefel.runtime.compilation import ONE_SHOT_OPTIONS, compile_aot, run_compiled

    assert ONE_SHOT_OPTIONS == {"xla_backend_optimization_level": 0}

    def f(X, t):
        return jnp.sum(jnp.sin(X) ** 2 * t) + jnp.linalg.norm(X @ X.T)

    X = jnp.linspace(-1.0, 1.0, 60).reshape(12, 5)
    t = jnp.asarray(0.3)
    fast, _, _ = run_compiled(f, X, t)
    plain, compile_s, _ = run_compiled(f, X, t, optimize=False)
    assert compile_s > 0.0 and float(plain) == pytest.approx(float(fast), rel=1e-15)
    assert float(compile_aot(f, X, t, optimize=False)(X, t)) == pytest.approx(float(fast), rel=1e-15)
