"""Tests for objectives.energy.energies: Dirichlet energy, CMM energy (Def. 3.2.10), compressed eigenvalues (Def. 3.2.15)."""

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import scipy.sparse as sp  # noqa: E402

import objectives  # noqa: E402
from objectives import energies as E  # noqa: E402
from stiefel.linalg.operators import DiagonalOperator, SparseOperator, as_operator  # noqa: E402

N, K = 40, 4


def random_spd(n, seed):
    """A small random sparse SPD matrix (scipy): a weighted graph Laplacian (a ring plus random
    chords, like a stiffness matrix W) plus 0.5·I; at most ~6 entries per row."""
    rng = np.random.default_rng(seed)
    i = np.concatenate([np.arange(n), rng.integers(0, n, n // 2)])
    j = np.concatenate([(np.arange(n) + 1) % n, rng.integers(0, n, n // 2)])
    keep = i != j
    i, j = i[keep], j[keep]
    wts = rng.uniform(0.5, 2.0, i.size)
    adj = sp.coo_matrix((wts, (i, j)), shape=(n, n))
    adj = (adj + adj.T).tocsr()
    lap = sp.diags(np.asarray(adj.sum(axis=1)).ravel()) - adj
    return (lap + 0.5 * sp.eye(n)).tocsr()


@pytest.fixture(scope="module")
def problem():
    rng = np.random.default_rng(0)
    Ws = random_spd(N, 1)
    area = rng.uniform(0.2, 1.8, N) / N
    X = rng.standard_normal((N, K))
    X[rng.random((N, K)) < 0.2] *= 1e-3  # some entries inside the smoothing region
    return Ws, SparseOperator.from_scipy(Ws), area, X


# ---------------------------------------------------------------------------
# reusable checker (Manopt-style checkgradient)
# ---------------------------------------------------------------------------


def check_gradient(F, X, V, *, fd_step=1e-5, rtol=1e-6):
    """Check ∇F against directional derivatives along V.

    1. ⟨jax.grad F(X), V⟩ equals jax.jvp's directional derivative;
    2. the central difference (F(X+tV) − F(X−tV))/2t matches it;
    3. the Taylor remainder |F(X+tV) − F(X) − t DF[V]| has log-log slope ≈ 2.
    Returns the fitted slope.
    """
    X, V = jnp.asarray(X), jnp.asarray(V)
    t = fd_step
    ts = np.logspace(-3, -6, 7)
    steps = jnp.asarray(np.concatenate([[t, -t, 0.0], ts]))

    @jax.jit  # one compilation: jvp, grad and F along the line X + sV
    def probe(Y, D):
        _, dF = jax.jvp(F, (Y,), (D,))
        return dF, jax.grad(F)(Y), jax.vmap(lambda s: F(Y + s * D))(steps)

    dF, g, vals = probe(X, V)
    dF, vals = float(dF), np.asarray(vals)
    np.testing.assert_allclose(float(jnp.sum(g * V)), dF, rtol=1e-12, atol=1e-12)
    fd = (vals[0] - vals[1]) / (2 * t)
    np.testing.assert_allclose(fd, dF, rtol=rtol, atol=rtol)
    rem = np.abs(vals[3:] - vals[2] - ts * dF)
    slope = np.polyfit(np.log(ts), np.log(rem), 1)[0]
    assert 1.9 < slope < 2.1, (slope, rem)
    return slope


# ---------------------------------------------------------------------------
# Dirichlet energy
# ---------------------------------------------------------------------------


def test_dirichlet_matches_dense_reference(problem):
    Ws, Wop, _, X = problem
    Wd = Ws.toarray()
    for W in (Wop, Ws, Wd, as_operator(Ws, check=False, factor=False)):
        d = E.dirichlet(W)
        np.testing.assert_allclose(float(d(jnp.asarray(X))), np.trace(X.T @ Wd @ X), rtol=1e-12)
        np.testing.assert_allclose(float(d(jnp.asarray(X[:, 1]))), X[:, 1] @ Wd @ X[:, 1], rtol=1e-12)
    diag = np.arange(1.0, N + 1)
    np.testing.assert_allclose(
        float(E.dirichlet(DiagonalOperator(jnp.asarray(diag)))(jnp.asarray(X))), np.sum(diag[:, None] * X**2), rtol=1e-12
    )


def test_dirichlet_rejects_bad_operator():
    with pytest.raises(TypeError, match="W must be"):
        E.dirichlet(np.ones(5))


# ---------------------------------------------------------------------------
# l1 term and weights
# ---------------------------------------------------------------------------


def test_l1_term_matches_reference(problem):
    _, _, area, X = problem
    eps, delta = 2e-3, 1e-3
    for name in ("f0", "f3", "huber", "logcosh"):
        term = E.l1_term(area, name, eps=eps, delta=delta)
        s = objectives.energy.smoothings.get(name, eps, delta)
        ref = float(np.sum(area[:, None] * np.asarray(s(jnp.asarray(X)))))
        np.testing.assert_allclose(float(term(jnp.asarray(X))), ref, rtol=1e-13)
    np.testing.assert_allclose(
        float(E.l1_term(area, "abs")(jnp.asarray(X))), np.sum(area[:, None] * np.abs(X)), rtol=1e-13
    )
    custom = E.l1_term(area, lambda x: x**2)  # any elementwise callable
    np.testing.assert_allclose(float(custom(jnp.asarray(X[:, 0]))), np.sum(area * X[:, 0] ** 2), rtol=1e-13)


def test_l1_weights():
    a = jnp.asarray([0.1, 0.2, 0.7])
    np.testing.assert_array_equal(E.l1_weights(a, "area"), a)
    np.testing.assert_allclose(E.l1_weights(a, "uniform"), np.full(3, 1 / 3), rtol=1e-15)
    np.testing.assert_array_equal(E.l1_weights(DiagonalOperator(a), "area"), a)
    with pytest.raises(ValueError, match="weighting"):
        E.l1_weights(a, "mass")
    with pytest.raises(ValueError, match="1-D"):
        E.l1_weights(jnp.eye(3), "area")


# ---------------------------------------------------------------------------
# CMM energy
# ---------------------------------------------------------------------------


def cmm_reference(Wd, w, mu, X, deriv_eps):
    """Dense numpy F and ∇F for smoothing f3: F = tr(XᵀWX) + μ Σ w_i f3(X_ij), f3' = x/(ε+|x|)."""
    eps = deriv_eps
    a = np.abs(X)
    f3 = a - eps * np.log1p(a / eps)
    F = np.trace(X.T @ Wd @ X) + mu * np.sum(w[:, None] * f3)
    G = 2 * Wd @ X + mu * w[:, None] * X / (eps + a)
    return F, G


@pytest.mark.parametrize("weighting", ["area", "uniform"])
def test_cmm_value_and_gradient_match_dense_reference(problem, weighting):
    Ws, Wop, area, X = problem
    mu, eps = 3.0, 1e-3
    F = E.cmm_energy(Wop, area, mu, smoothing="f3", eps=eps, weighting=weighting)
    w = area if weighting == "area" else np.full(N, 1.0 / N)
    Fref, Gref = cmm_reference(Ws.toarray(), w, mu, X, eps)
    np.testing.assert_allclose(float(F(jnp.asarray(X))), Fref, rtol=1e-12)
    np.testing.assert_allclose(np.asarray(jax.grad(F)(jnp.asarray(X))), Gref, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize(
    "smoothing,weighting", [("f3", "area"), ("f8", "uniform"), ("f6", "area"), ("f7", "uniform")]
)
def test_cmm_gradient_check(problem, smoothing, weighting):
    _, Wop, area, X = problem
    F = E.cmm_energy(Wop, area, 2.0, smoothing=smoothing, eps=1e-3, delta=2e-3, weighting=weighting)
    V = np.random.default_rng(5).standard_normal(X.shape)
    check_gradient(F, X, V)
    check_gradient(F, X[:, 2], V[:, 2])  # a single column (n,)


def test_gradient_checker_can_fail(problem):
    """The checker rejects a wrong gradient (here: the l1 part's gradient dropped)."""
    _, Wop, area, X = problem
    F = E.cmm_energy(Wop, area, 2.0)

    @jax.custom_jvp
    def wrong(Y):
        return F(Y)

    @wrong.defjvp
    def _wrong_jvp(p, t):
        (Y,), (dY,) = p, t
        return F(Y), jnp.sum(2 * Wop.mv(Y) * dY)

    V = np.random.default_rng(6).standard_normal(X.shape)
    with pytest.raises(AssertionError):
        check_gradient(wrong, X, V)


@pytest.mark.parametrize("weighting", ["area", "uniform"])
@pytest.mark.parametrize("smoothing", ["f0", "f3", "f8"])
def test_columns_sum_to_block(problem, smoothing, weighting):
    _, Wop, area, X = problem
    F = E.cmm_energy(Wop, area, 1.5, smoothing=smoothing, weighting=weighting)
    Xj = jnp.asarray(X)
    cols = sum(float(F(Xj[:, j])) for j in range(K))
    np.testing.assert_allclose(cols, float(F(Xj)), rtol=1e-13)
    d_cols = sum(float(F.parts(Xj[:, j])[0]) for j in range(K))
    np.testing.assert_allclose(d_cols, float(F.parts(Xj)[0]), rtol=1e-13)


def test_area_and_uniform_agree_with_equal_areas(problem):
    """Rem. 3.2.14: with A_ii = 1/n the two weightings coincide (and differ otherwise)."""
    _, Wop, area, X = problem
    Xj = jnp.asarray(X)
    equal = np.full(N, 1.0 / N)
    Fa = E.cmm_energy(Wop, equal, 4.0, weighting="area")
    Fu = E.cmm_energy(Wop, area, 4.0, weighting="uniform")  # uniform ignores the area values
    np.testing.assert_allclose(float(Fa(Xj)), float(Fu(Xj)), rtol=1e-14)
    np.testing.assert_allclose(np.asarray(jax.grad(Fa)(Xj)), np.asarray(jax.grad(Fu)(Xj)), rtol=1e-13, atol=1e-15)
    Fa_nonuniform = E.cmm_energy(Wop, area, 4.0, weighting="area")
    assert abs(float(Fa_nonuniform(Xj)) - float(Fu(Xj))) > 1e-6


def test_parts_and_true_value(problem):
    Ws, Wop, area, X = problem
    Xj = jnp.asarray(X)
    mu = 2.5
    F = E.cmm_energy(Ws, area, mu, smoothing="f3", eps=1e-2)
    d, l1 = F.parts(Xj)
    np.testing.assert_allclose(float(d + l1), float(F(Xj)), rtol=1e-14)
    true = np.trace(X.T @ Ws.toarray() @ X) + mu * np.sum(area[:, None] * np.abs(X))
    np.testing.assert_allclose(float(F.true_value(Xj)), true, rtol=1e-12)
    assert float(F(Xj)) < float(F.true_value(Xj))  # f3 < |x| off 0: the smoothing lowers the energy
    F0 = E.cmm_energy(Ws, area, mu, smoothing="abs")
    np.testing.assert_allclose(float(F0(Xj)), true, rtol=1e-12)


def test_energy_is_a_pytree_with_traced_parameters(problem):
    """μ, ε, δ are leaves: changing δ (continuation) reuses the compiled function."""
    _, Wop, area, X = problem
    Xj = jnp.asarray(X)
    traces = []

    @eqx.filter_jit
    def value_and_grad(F, Y):
        traces.append(1)
        return jax.value_and_grad(F)(Y)

    F = E.cmm_energy(Wop, area, 1.0, smoothing="f6", delta=0.1)
    grads = []
    for delta in (0.1, 0.01, 0.001):
        Fd = F.with_params(delta=delta)
        v, g = value_and_grad(Fd, Xj)
        grads.append(np.asarray(g))
        fresh = E.cmm_energy(Wop, area, 1.0, smoothing="f6", delta=delta)
        np.testing.assert_allclose(float(v), float(fresh(Xj)), rtol=1e-14)
    assert len(traces) == 1
    assert np.max(np.abs(grads[0] - grads[2])) > 1e-3  # δ really reached the compiled function
    assert float(F.with_params(mu=0.0)(Xj)) == pytest.approx(float(E.dirichlet(Wop)(Xj)), rel=1e-14)


def test_cmm_energy_rejects_bad_options(problem):
    _, Wop, area, _ = problem
    with pytest.raises(ValueError, match="unknown smoothing"):
        E.cmm_energy(Wop, area, 1.0, smoothing="l2")
    with pytest.raises(ValueError, match="weighting"):
        E.cmm_energy(Wop, area, 1.0, weighting="mass")
    with pytest.raises(ValueError, match="eps"):
        E.cmm_energy(Wop, area, 1.0, eps=0.0)


# ---------------------------------------------------------------------------
# compressed eigenvalues (Def. 3.2.15, Rem. 3.2.16)
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("weighting", ["area", "uniform"])
def test_compressed_eigenvalues_match_reference(problem, weighting):
    Ws, Wop, area, X = problem
    mu = 7.0
    Wd = Ws.toarray()
    w = area if weighting == "area" else np.full(N, 1.0 / N)
    ref = np.array([X[:, j] @ Wd @ X[:, j] + 0.5 * mu * np.sum(w * np.abs(X[:, j])) for j in range(K)])
    got = E.compressed_eigenvalues(Wop, area, jnp.asarray(X), mu, weighting)
    assert got.shape == (K,)
    np.testing.assert_allclose(np.asarray(got), ref, rtol=1e-12)
    np.testing.assert_allclose(float(E.compressed_eigenvalues(Ws, area, jnp.asarray(X[:, 3]), mu, weighting)), ref[3], rtol=1e-12)
    F = E.cmm_energy(Wop, area, mu, weighting=weighting)
    np.testing.assert_allclose(np.asarray(F.compressed_eigenvalues(jnp.asarray(X))), ref, rtol=1e-12)
    if weighting == "area":  # (μ/2)‖Aψ‖₁ literally, with A = diag(area)
        A = np.diag(area)
        np.testing.assert_allclose(
            ref, [X[:, j] @ Wd @ X[:, j] + 0.5 * mu * np.linalg.norm(A @ X[:, j], 1) for j in range(K)], rtol=1e-13
        )


def test_order_by_compressed_eigenvalue(problem):
    Ws, Wop, area, X = problem
    mu = 7.0
    scales = np.array([3.0, 0.5, 2.0, 1.0])  # λ grows with the scale of the column
    Psi = jnp.asarray(X[:, :1] * scales[None, :])
    perm = np.asarray(E.order_by_compressed_eigenvalue(Wop, area, Psi, mu))
    np.testing.assert_array_equal(perm, [1, 3, 2, 0])
    lam = np.asarray(E.compressed_eigenvalues(Wop, area, Psi[:, perm], mu))
    assert np.all(np.diff(lam) > 0)
    ties = jnp.asarray(np.repeat(X[:, :1], 3, axis=1))
    np.testing.assert_array_equal(np.asarray(E.order_by_compressed_eigenvalue(Ws, area, ties, mu)), [0, 1, 2])


def test_cmm_line_matches_the_retraction_curve():
    """CMMEnergy.line (k×k Gram algebra) equals F(R_X(τη)) and its τ-derivative through the Cholesky retraction."""
    import scipy.sparse as sp

    import stiefel
    from objectives import cmm_energy
    from stiefel.solvers.linesearch import along_curve

    rng = np.random.default_rng(5)
    n, k = 60, 4
    B = sp.random(n, n, density=0.08, random_state=6)
    W = sp.csr_array(B @ B.T)
    a = rng.uniform(0.5, 2.0, n) / n
    F = cmm_energy(W, a, 3.0, smoothing="f6", eps=1e-2, delta=1e-2, weighting="area")
    man = stiefel.GeneralizedStiefel(a, k, retraction="cholesky")
    X = man.random_point(jax.random.PRNGKey(0))
    eta = man.random_tangent(jax.random.PRNGKey(1), X)
    fast = F.line(man, X, eta)
    ref = along_curve(F, lambda t: man.retract(X, t * eta))
    for t in (0.0, 0.03, 0.4, 2.0):
        f1, g1 = fast(jnp.asarray(t))
        f0, g0 = ref(jnp.asarray(t))
        np.testing.assert_allclose(f1, f0, rtol=1e-11)
        np.testing.assert_allclose(g1, g0, rtol=1e-9, atol=1e-11 * abs(float(f0)))
    assert F.line(stiefel.GeneralizedStiefel(a, k, retraction="polar"), X, eta) is None


@pytest.mark.slow
def test_runtime_smoothing_equals_each_static_smoothing():
    """``runtime_smoothing=True``: the smoothing is a runtime index (lax.switch); value and gradient equal
    those of the energy with that smoothing fixed, for all ten, and one jitted function serves them all."""
    from objectives import smoothings

    rng = np.random.default_rng(5)
    Ws = random_spd(N, 2)
    area = rng.uniform(0.2, 1.8, N) / N
    X = jnp.asarray(rng.standard_normal((N, K)) * 0.01)  # near 0, where the smoothings differ most
    dyn = E.cmm_energy(Ws, area, 3.0, smoothing="f6", eps=2e-3, delta=5e-3, runtime_smoothing=True)
    assert dyn.smoothing == "runtime" and dyn.smoothing_name == "f6"
    traces = []

    @jax.jit
    def value_and_grad(energy, X):
        traces.append(1)
        return jax.value_and_grad(energy)(X)

    for name in smoothings.NAMES:
        static = E.cmm_energy(Ws, area, 3.0, smoothing=name, eps=2e-3, delta=5e-3)
        switched = dyn.with_params(smoothing=name)
        assert switched.smoothing_name == name
        v_ref, g_ref = jax.value_and_grad(static)(X)
        v, g = value_and_grad(switched, X)
        np.testing.assert_allclose(v, v_ref, rtol=1e-14)
        np.testing.assert_allclose(g, g_ref, rtol=1e-12, atol=1e-15)
    assert len(traces) == 1  # one trace (one compilation) for the ten smoothings
    assert float(dyn.with_params(smoothing="huber")(X)) == pytest.approx(
        float(E.cmm_energy(Ws, area, 3.0, smoothing=smoothings.info("huber").name, eps=2e-3, delta=5e-3)(X)), rel=1e-14)
    static = E.cmm_energy(Ws, area, 3.0, smoothing="f6")
    assert static.with_params(smoothing="f6") is static
    with pytest.raises(ValueError, match="runtime_smoothing=True"):
        static.with_params(smoothing="f3")
    with pytest.raises(ValueError, match="unknown smoothing"):
        dyn.with_params(smoothing="f11")
