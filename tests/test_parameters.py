"""Every parameter is checked where it enters: a named error, naming the parameter, before
any work; ``max_iters`` is the total number of iterations of a call, for every method."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse as sp

import mesh
import stiefel
from stiefel_cmm.cli.demo_mesh import demo_mesh
from mesh.eigen import EigenInputError
from mesh.errors import MeshError
from objectives import bases
from objectives.cmm.batch import cmm_batch
from objectives.cmm.modes import compressed_modes, select_mu
from objectives.cmm.solvers import (ADMMCMM, BlockCMM, FastCMM, SequentialADMMCMM, SequentialCMM,
                                    SolverOptionError)
from objectives.cmm.differentiable import cmm_solve
from stiefel import (NonFiniteError, ParameterError, RankDeficientError, RiemannianBB, RiemannianCG,
                     RiemannianLBFGS, StiefelError)

N, K = 40, 3
NAN = float("nan")
#: max_iters values users passed: negative, zero, a bool, a float, one past int32
BAD_COUNTS = [-5, 0, True, 2.5, 99999999999]


def _problem():
    """``tr(XᵀWX)`` on ``XᵀMX = I`` (W a path graph's Laplacian plus a ramp, M diagonal)."""
    main = 2.0 + np.linspace(0.0, 1.0, N)
    W = np.diag(main) - np.diag(np.ones(N - 1), 1) - np.diag(np.ones(N - 1), -1)
    M = np.linspace(1.0, 2.0, N)
    S = stiefel.GeneralizedStiefel(M, K)
    Wj = jnp.asarray(W)
    return S, (lambda X: jnp.sum(X * (Wj @ X))), S.random_point(jax.random.PRNGKey(0)), W, M


S, F, X0, W_DENSE, M_DIAG = _problem()


@pytest.fixture(scope="module")
def lap():
    return mesh.laplacian(mesh.load(demo_mesh(subdivisions=1)))  # n = 42


def _raises(error, name, call):
    with pytest.raises(error) as info:
        call()
    assert name in str(info.value), (name, str(info.value))
    assert isinstance(info.value, ValueError)
    return info.value


# ------------------------------------------------------------------------ the manifold layer

MINIMIZE_BAD = ([("max_iters", v) for v in BAD_COUNTS] + [
    ("gtol", -1.0), ("gtol", NAN), ("xtol", NAN), ("ftol", -1e-3), ("c1", 0.0), ("c2", 1.0), ("c1", 0.5),
    ("init_step", -1.0), ("init_step", 0.0), ("init_step", NAN), ("max_move", 0.0), ("ls_max_evals", 0),
    ("ls_max_evals", True), ("ftol_window", 0), ("ftol_window", 65), ("ftol_window", 2.5), ("memory", 0),
    ("bb_gamma", 1.5), ("budget", -1), ("budget", 11), ("budget", 2.0)])


@pytest.mark.parametrize("name, value", MINIMIZE_BAD, ids=[f"{n}={v!r}" for n, v in MINIMIZE_BAD])
def test_minimize_refuses(name, value):
    kw = {name: value, "max_iters": 10} if name == "budget" else {name: value}
    if name == "c1":
        kw["c2"] = 0.4  # c1 = 0.5 > c2; c1 = 0 out of (0, 1)
    _raises(ParameterError, name, lambda: stiefel.minimize(F, S, X0, **kw))


SEQUENTIAL_BAD = ([("max_iters", v) for v in BAD_COUNTS] + [
    ("gtol", -1.0), ("gtol", NAN), ("c1", 0.5), ("c2", NAN), ("ls_max_evals", 0), ("max_step", 0.0),
    ("max_step", 4.0), ("budget", 11)])


@pytest.mark.parametrize("name, value", SEQUENTIAL_BAD, ids=[f"{n}={v!r}" for n, v in SEQUENTIAL_BAD])
def test_minimize_sequential_refuses(name, value):
    kw = {name: value, "max_iters": 10} if name == "budget" else {name: value}
    if name == "c1":
        kw["c2"] = 0.1
    f = lambda x: jnp.dot(x, jnp.asarray(W_DENSE) @ x)  # noqa: E731
    _raises(ParameterError, name, lambda: stiefel.minimize_sequential(f, M_DIAG, K, **kw))


SOLVER_BAD = [(RiemannianCG, "atol", -1.0), (RiemannianCG, "rtol", NAN), (RiemannianCG, "c1", 0.5),
              (RiemannianLBFGS, "init_step", -1.0), (RiemannianCG, "ftol_window", 2.5),
              (RiemannianCG, "ls_max_evals", 0), (RiemannianCG, "budget", -1), (RiemannianCG, "budget", True),
              (RiemannianLBFGS, "memory", 0),
              (RiemannianLBFGS, "memory", True), (RiemannianBB, "bb_gamma", -0.1), (RiemannianBB, "max_move", -1.0)]


@pytest.mark.parametrize("cls, name, value", SOLVER_BAD, ids=[f"{c.__name__}-{n}={v!r}" for c, n, v in SOLVER_BAD])
def test_optx_minimisers_refuse_concrete_values(cls, name, value):
    _raises(ParameterError, name, lambda: cls(S, **{name: value}))


def test_optx_minimisers_skip_traced_values():
    """Fields traced under jit/vmap cannot be inspected: construction must not fail there."""
    atol = jax.jit(lambda a, c1: RiemannianCG(S, atol=a, c1=c1).atol)(-1.0, 0.5)
    assert float(atol) == -1.0
    assert jax.vmap(lambda b: RiemannianCG(S, budget=b).budget)(jnp.arange(3)).tolist() == [0, 1, 2]


WOLFE_BAD = [("c1", dict(c1=0.5, c2=0.1)), ("init_step", dict(init_step=-1.0)), ("max_evals", dict(max_evals=0)),
             ("backtrack_factor", dict(backtrack_factor=1.5)), ("extrapolation", dict(extrapolation=0.5)),
             ("approx_c2", dict(approx_c2=NAN)), ("max_step", dict(max_step=-1.0))]


@pytest.mark.parametrize("name, kw", WOLFE_BAD, ids=[n for n, _ in WOLFE_BAD])
def test_strong_wolfe_refuses(name, kw):
    phi = lambda t: (t * t - t, 2 * t - 1.0)  # noqa: E731
    kw = {"init_step": 1.0, **kw}
    _raises(ParameterError, name, lambda: stiefel.strong_wolfe(phi, 0.0, -1.0, kw.pop("init_step"), **kw))


@pytest.mark.parametrize("name, call", [
    ("maxiter", lambda: stiefel.penalty_minimize(F, S, X0, maxiter=99999999999)),
    ("sigma", lambda: stiefel.shifted_inverse(W_DENSE, M_DIAG, -1.0)),
    ("sigma", lambda: stiefel.shifted_inverse(W_DENSE, M_DIAG, NAN)),
    ("max_iters", lambda: stiefel.BlockOptions(max_iters=0)),
    ("c1", lambda: stiefel.BlockOptions(c1=0.95, c2=0.9)),
    ("max_iters", lambda: stiefel.SequentialOptions(max_iters=True)),
    ("tol", lambda: stiefel.RiemannianImplicitAdjoint(tol=-1.0)),
], ids=["penalty-maxiter", "shift-negative", "shift-nan", "options-max_iters", "options-wolfe",
        "seq-options-max_iters", "adjoint-tol"])
def test_other_entry_points_refuse(name, call):
    _raises(ParameterError, name, call)


def test_rank_deficient_start_is_named_where_it_enters():
    Y = np.asarray(X0).copy()
    Y[:, 2] = Y[:, 0]  # two equal columns
    err = _raises(RankDeficientError, "numerical rank 2 of k = 3", lambda: S.project_to_manifold(jnp.asarray(Y)))
    assert isinstance(err, stiefel.OffManifoldError)
    _raises(RankDeficientError, "X0 is rank-deficient", lambda: stiefel.minimize(F, S, Y))
    _raises(RankDeficientError, "numerical rank 1", lambda: S.project_to_manifold(jnp.ones((N, K))))
    # traced (under jit) the check cannot run: no error, the caller's start is its own business there
    assert jax.jit(lambda Z: S.project_to_manifold(Z))(jnp.asarray(Y)).shape == (N, K)


def test_non_finite_matrices_are_named():
    _raises(NonFiniteError, "M has 1 non-finite", lambda: stiefel.as_operator(np.r_[1.0, NAN, 1.0], check=False))
    _raises(NonFiniteError, "M has", lambda: stiefel.GeneralizedStiefel(sp.diags([1.0, np.inf, 1.0]), 1))


# ------------------------------------------------------------------------ objectives and mesh

CMM_SOLVER_BAD = ([(cls, "max_iters", v) for cls in (BlockCMM, SequentialCMM, ADMMCMM, SequentialADMMCMM)
                   for v in BAD_COUNTS]
                  + [(BlockCMM, "gtol", -1.0), (SequentialCMM, "gtol", NAN), (BlockCMM, "stage_window", 65),
                     (ADMMCMM, "eps_abs", NAN), (ADMMCMM, "rho_tau", NAN), (SequentialADMMCMM, "adapt_every", True)])


@pytest.mark.parametrize("cls, name, value", CMM_SOLVER_BAD,
                         ids=[f"{c.__name__}-{n}={v!r}" for c, n, v in CMM_SOLVER_BAD])
def test_cmm_solver_objects_refuse(cls, name, value):
    err = _raises(SolverOptionError, name, lambda: cls(**{name: value}))
    assert isinstance(err, ParameterError) and isinstance(err, StiefelError)


def test_fast_cmm_refuses_max_iters(lap):
    U = sp.eye(lap.n, 10, format="csr")
    for v in BAD_COUNTS:
        _raises(SolverOptionError, "max_iters", lambda: FastCMM(U, max_iters=v))


@pytest.mark.parametrize("name, kw", [
    ("k", dict(k=0)), ("k", dict(k=True)), ("k", dict(k=3.0)), ("k", dict(k=43)), ("mu", dict(mu=-1.0)),
    ("mu", dict(mu=NAN)), ("seed", dict(seed=-1)), ("weighting", dict(weighting="max")),
], ids=["k=0", "k=True", "k=3.0", "k>n", "mu<0", "mu=nan", "seed", "weighting"])
def test_compressed_modes_refuses(lap, name, kw):
    call = {"k": 3, "mu": 1.0, **kw}
    _raises(ParameterError, name, lambda: compressed_modes(lap, call.pop("k"), call.pop("mu"), **call))


def test_compressed_modes_names_bad_matrices_and_starts(lap):
    W = lap.W.tolil()
    W[3, 5] = np.nan
    _raises(NonFiniteError, "W has 1 non-finite", lambda: compressed_modes((W.tocsr(), lap.A), 3, 1.0))
    A = lap.A.copy().tocsr()
    A.data[0] = np.inf
    _raises(NonFiniteError, "A has 1 non-finite", lambda: compressed_modes((lap.W, A), 3, 1.0))
    start = np.random.default_rng(0).standard_normal((lap.n, 3))
    start[:, 1] = start[:, 0]
    for solver in (BlockCMM(), SequentialCMM(), ADMMCMM()):
        _raises(RankDeficientError, "numerical rank 2 of k = 3",
                lambda: compressed_modes(lap, 3, 1.0, solver=solver, start=start))
    start[0, 0] = np.nan
    _raises(NonFiniteError, "start has", lambda: compressed_modes(lap, 3, 1.0, start=start))


def test_compressed_modes_k_equal_n_uses_the_dense_eigensolver():
    """ARPACK needs k < n; with k = n (a tiny problem) the eigenbasis start is computed densely."""
    W = sp.csr_array(np.diag(2.0 * np.ones(4)) - np.diag(np.ones(3), 1) - np.diag(np.ones(3), -1))
    res = compressed_modes((W, np.ones(4)), 4, 0.0, solver=ADMMCMM(max_iters=5))
    assert res.modes.shape == (4, 4) and res.orthogonality <= 1e-10


@pytest.mark.parametrize("name, kw", [
    ("target_sparsity", dict(target_sparsity=1.5)), ("target_sparsity", dict(target_sparsity=NAN)),
    ("tol", dict(tol=-0.1)), ("max_evals", dict(max_evals=1)), ("max_evals", dict(max_evals=True)),
    ("mu_lo", dict(mu_lo=-1.0)), ("mu_lo", dict(mu_lo=5.0, mu_hi=1.0)), ("threshold", dict(threshold="1e-4")),
    ("k", dict(k=True)),
])
def test_select_mu_refuses(lap, name, kw):
    call = {"k": 3, "target_sparsity": 0.3, **kw}
    _raises(ParameterError, name, lambda: select_mu(lap, call.pop("k"), call.pop("target_sparsity"), **call))


@pytest.mark.parametrize("name, kw", [
    ("k", dict(k=True)), ("mus", dict(mus=[1.0, -1.0])), ("eps", dict(eps=0.0)), ("delta", dict(delta=NAN)),
    ("sigma", dict(sigma=-1.0)), ("options", dict(options=dict(max_iters=5))),
])
def test_cmm_batch_refuses(lap, name, kw):
    call = {"k": 3, "mus": 1.0, **kw}
    _raises(ParameterError, name, lambda: cmm_batch(lap, call.pop("k"), call.pop("mus"), **call))


def test_cmm_batch_names_rank_deficient_starts(lap):
    starts = np.random.default_rng(0).standard_normal((2, lap.n, 3))
    starts[1, :, 2] = 0.0
    _raises(RankDeficientError, "starts[1] is rank-deficient", lambda: cmm_batch(lap, 3, [1.0, 2.0], starts=starts))


@pytest.mark.parametrize("name, kw", [
    ("max_iters", dict(max_iters=0)), ("max_iters", dict(max_iters=True)), ("gtol", dict(gtol=NAN)),
    ("eps", dict(eps=-1.0)), ("stages[0]", dict(stages=(0.0,))),
])
def test_cmm_solve_refuses(lap, name, kw):
    W = stiefel.SparseOperator.from_scipy(lap.W)
    X = np.linalg.qr(np.random.default_rng(0).standard_normal((lap.n, 3)))[0]
    _raises(ParameterError, name, lambda: cmm_solve(W, jnp.asarray(lap.A.diagonal()), jnp.asarray(X), 1.0, **kw))


@pytest.mark.parametrize("name, kw", [
    ("k", dict(k=True)), ("k", dict(k=3.0)), ("k", dict(k=42)), ("mu_perp", dict(mu_perp=-1.0)),
    ("tol", dict(tol=-1.0)), ("sigma", dict(sigma=NAN)), ("mu_V", dict(mu_V=np.inf)),
])
def test_bases_refuse(lap, name, kw):
    call = {"k": 3, **kw}
    _raises(ParameterError, name, lambda: bases.glmh(lap.W, lap.A, call.pop("k"), **call))


def test_bases_name_non_finite_matrices(lap):
    W = lap.W.tolil()
    W[0, 0] = np.nan
    _raises(NonFiniteError, "W has 1 non-finite", lambda: bases.glmh(W.tocsr(), lap.A, 3))


@pytest.mark.parametrize("k", [0, True, 3.0, 42, 43])
def test_mesh_eigenbasis_refuses_k(lap, k):
    err = _raises(EigenInputError, "k must be an integer with 1 ≤ k < n = 42", lambda: mesh.eigenbasis(lap, k))
    assert isinstance(err, MeshError)


def test_mesh_eigenbasis_names_non_finite_laplacian(lap):
    W = lap.W.tolil()
    W[2, 2] = np.nan
    bad = dataclasses.replace(lap, W=sp.csr_array(W))
    _raises(EigenInputError, "W has 1 non-finite", lambda: mesh.eigenbasis(bad, 3))
    _raises(EigenInputError, "sigma", lambda: mesh.eigenbasis(lap, 3, sigma=NAN))
    _raises(EigenInputError, "tol", lambda: mesh.eigenbasis(lap, 3, tol=-1.0))


# ------------------------------------------------------------------------ max_iters is total


def test_minimize_budget_is_a_runtime_limit():
    jax.clear_caches()  # "full" compiles here, whatever other modules in this process compiled
    full = stiefel.minimize(F, S, X0, gtol=1e-14, max_iters=20)
    part = stiefel.minimize(F, S, X0, gtol=1e-14, max_iters=20, budget=7)
    none = stiefel.minimize(F, S, X0, gtol=1e-14, max_iters=20, budget=0)
    assert int(full.iterations) == 20 and int(part.iterations) == 7 and int(none.iterations) == 0
    assert part.status_name == none.status_name == "max_iters"
    # the budget is a runtime value: one compilation for all three (the first call's)
    assert max(part.compile_time, none.compile_time) < 0.5 * full.compile_time
    np.testing.assert_allclose(part.history.value[:8], full.history.value[:8], rtol=1e-12)


@pytest.mark.slow
def test_minimize_sequential_max_iters_is_total_over_columns():
    """The k = 3 columns share the total fairly: column j may use ⌈left/(k − j)⌉, what it leaves rolls over."""
    f = lambda x: jnp.dot(x, jnp.asarray(W_DENSE) @ x)  # noqa: E731
    # gtol 1e-8: at 1e-10 two columns stall on round-off on some CPUs (AVX-512: 7e-10 and 1.2e-10 after 175 steps)
    free = stiefel.minimize_sequential(f, M_DIAG, K, gtol=1e-8, max_iters=500)
    its = [int(i) for i in free.iterations]
    assert free.converged and min(its) > 3
    cap = sum(its) - 2  # smaller than the sum of the columns, larger than any one (per column: no cap)
    res = stiefel.minimize_sequential(f, M_DIAG, K, gtol=1e-8, max_iters=cap)
    used = [int(i) for i in res.iterations]
    assert sum(used) <= cap and "max_iters" in res.status_names
    left = cap
    for j, u in enumerate(used):  # no column exceeded its share
        assert u <= -(-left // (K - j))
        left -= u
    assert float(res.stats["dist_to_manifold"]) <= 1e-10
    starved = stiefel.minimize_sequential(f, M_DIAG, K, gtol=1e-10, max_iters=2)
    assert [int(i) for i in starved.iterations] == [1, 1, 0] and starved.status_names == ["max_iters"] * 3


@pytest.fixture(scope="module")
def cmm_lap():
    return mesh.laplacian(mesh.load(demo_mesh(subdivisions=2)))  # n = 162


@pytest.mark.slow
def test_block_cmm_max_iters_is_total_over_stages(cmm_lap):
    mu = 0.01 * cmm_lap.n
    free = compressed_modes(cmm_lap, K, mu, solver=BlockCMM(continuation=3, max_iters=2000), weighting="uniform", finish=None)
    assert free.status == "converged"
    cap = free.iterations - 1  # smaller than the sum of the stages, larger than any one (per stage: no cap)
    res = compressed_modes(cmm_lap, K, mu, solver=BlockCMM(continuation=3, max_iters=cap), weighting="uniform", finish=None)
    assert res.iterations <= cap and res.status == "max_iters"
    small = compressed_modes(cmm_lap, K, mu, solver=BlockCMM(continuation=3, max_iters=3), weighting="uniform", finish=None)
    assert small.iterations == 3 and small.status == "max_iters"  # stages 2 and 3 skipped


@pytest.mark.slow
def test_sequential_cmm_max_iters_is_total_over_columns(cmm_lap):
    mu = 0.01 * cmm_lap.n
    free = compressed_modes(cmm_lap, K, mu, solver=SequentialCMM(max_iters=2000), weighting="uniform", finish=None)
    cap = free.iterations - 1
    res = compressed_modes(cmm_lap, K, mu, solver=SequentialCMM(max_iters=cap), weighting="uniform", finish=None)
    assert res.iterations <= cap and res.status == "max_iters"


@pytest.mark.parametrize("make", [lambda U: ADMMCMM(max_iters=7), lambda U: SequentialADMMCMM(max_iters=7),
                                  lambda U: FastCMM(U, max_iters=7)], ids=["admm", "admm_sequential", "fast"])
def test_admm_max_iters_is_total(cmm_lap, make):
    U = mesh.local_functions(mesh.load(demo_mesh(subdivisions=2)), n_samples=30).U
    res = compressed_modes(cmm_lap, K, 0.01 * cmm_lap.n, solver=make(U), weighting="uniform")
    assert res.iterations <= 7 and res.finish["solver_status"] == "max_iters" and res.orthogonality <= 1e-10
    # the finish certifies what it returns: the status is the exact ℓ1 residual's verdict, not the solver's
    assert res.status == ("converged" if res.l1_residual <= res.finish["tol"] else res.finish["status"])


@pytest.mark.slow
def test_cmm_solve_max_iters_is_total_over_stages(cmm_lap):
    W = stiefel.SparseOperator.from_scipy(cmm_lap.W)
    a = jnp.asarray(cmm_lap.A.diagonal())
    X = jnp.asarray(np.linalg.qr(np.random.default_rng(0).standard_normal((cmm_lap.n, K)))[0])
    _, res = cmm_solve(W, a, X, 1.0, stages=(8.0, 4.0), max_iters=4, throw=False)
    assert int(res.iterations) == 0 and res.status_name == "max_iters"  # the first stage used the total
