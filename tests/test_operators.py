"""SPD operators: products and solves against dense references; sparse stays sparse."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.sparse as sp

from stiefel import (DenseOperator, DiagonalOperator, NonFiniteError, NotSPDError, ShapeError, SparseOperator,
                     as_operator)

from stiefel_cases import M_KINDS, dense_of, metric_matrix


@pytest.mark.parametrize("kind", M_KINDS)
def test_mv_and_solve_match_dense(kind):
    M = metric_matrix(kind, 13, seed=1)
    Md = dense_of(M)
    op = as_operator(M)
    X = np.random.default_rng(2).standard_normal((13, 4))
    np.testing.assert_allclose(op.mv(jnp.asarray(X)), Md @ X, atol=1e-13)
    np.testing.assert_allclose(op.solve(jnp.asarray(X)), np.linalg.solve(Md, X), atol=1e-12)
    np.testing.assert_allclose(op.mv(jnp.asarray(X[:, 0])), Md @ X[:, 0], atol=1e-13)
    np.testing.assert_allclose(op.diagonal(), np.diag(Md), atol=0)


def test_kinds_are_chosen_by_input():
    assert isinstance(as_operator(metric_matrix("diagonal", 5)), DiagonalOperator)
    assert isinstance(as_operator(metric_matrix("dense", 5)), DenseOperator)
    op = as_operator(metric_matrix("sparse", 5))
    assert isinstance(op, SparseOperator) and op.width == 3  # tridiagonal: 3 slots per row, not n


@pytest.mark.parametrize("backend", ["ffi", "callback"])
def test_sparse_solve_is_jittable_and_differentiable(backend):
    M = metric_matrix("sparse", 11)
    op = SparseOperator.from_scipy(M, factor=True, solve_backend=backend)
    assert (op.chol is not None) == (backend == "ffi") and (op.factor is not None) == (backend == "callback")
    Y = jnp.asarray(np.random.default_rng(0).standard_normal((11, 2)))
    Md = dense_of(M)
    np.testing.assert_allclose(jax.jit(lambda y: op.solve(y))(Y), np.linalg.solve(Md, Y), atol=1e-12)
    # d/dY sum(M⁻¹Y ⊙ C) = M⁻¹C (M symmetric)
    C = jnp.asarray(np.random.default_rng(1).standard_normal((11, 2)))
    g = jax.grad(lambda y: jnp.sum(op.solve(y) * C))(Y)
    np.testing.assert_allclose(g, np.linalg.solve(Md, C), atol=1e-12)
    v = jax.vmap(op.solve, in_axes=1, out_axes=1)(Y)
    np.testing.assert_allclose(v, np.linalg.solve(Md, Y), atol=1e-12)
    # forward mode, and the derivative with respect to the matrix's values (through the product rule of
    # custom_linear_solve): d(M⁻¹y)[dM] = −M⁻¹ dM M⁻¹ y
    t = jax.jvp(op.solve, (Y,), (C,))[1]
    np.testing.assert_allclose(t, np.linalg.solve(Md, C), atol=1e-12)
    dvals = jnp.where((op.cols == jnp.arange(11)[:, None]) & (op.vals != 0), 1.0, 0.0)  # dM = I (not the padding)
    rebuilt = lambda v: SparseOperator(cols=op.cols, vals=v, chol=op.chol, factor=op.factor, csr=op.csr)  # noqa: E731
    dx = jax.jvp(lambda v: rebuilt(v).solve(Y), (op.vals,), (dvals,))[1]
    np.testing.assert_allclose(dx, -np.linalg.solve(Md, np.linalg.solve(Md, Y)), atol=1e-11)


def test_ffi_solve_has_no_host_callback_and_batches_matrices():
    """The default sparse solve is an XLA custom call: no callback in the program (so JAX's persistent
    cache can serve it); under vmap over different matrices each member is solved with its own."""
    M = metric_matrix("sparse", 12, seed=3)
    op = as_operator(M)
    assert op.chol is not None and op.factor is None
    Y = jnp.ones((12, 3))
    text = str(jax.make_jaxpr(lambda y: op.solve(y))(Y))
    assert "callback" not in text and "custom_linear_solve" in text
    cb = SparseOperator.from_scipy(M, factor=True, solve_backend="callback")
    assert "callback" in str(jax.make_jaxpr(lambda y: cb.solve(y))(Y))
    vals = jnp.stack([op.chol.vals, 2.0 * op.chol.vals])
    solve = jax.vmap(lambda v: type(op.chol)(rows=op.chol.rows, cols=op.chol.cols, vals=v, n=12).solve(Y))
    out = solve(vals)
    Md = dense_of(M)
    np.testing.assert_allclose(out[0], np.linalg.solve(Md, Y), atol=1e-12)
    np.testing.assert_allclose(out[1], np.linalg.solve(2 * Md, Y), atol=1e-12)
    # float32 operands are solved in float64 and returned in float32
    np.testing.assert_allclose(op.chol.solve(Y.astype(jnp.float32)), np.linalg.solve(Md, Y), rtol=1e-6)
    assert op.chol.solve(Y.astype(jnp.float32)).dtype == jnp.float32


def test_solve_backend_is_checked_and_switchable(monkeypatch):
    from stiefel import ffi_solve

    M = metric_matrix("sparse", 6)
    with pytest.raises(ValueError, match="solve_backend"):
        SparseOperator.from_scipy(M, factor=True, solve_backend="cholmod")
    monkeypatch.setenv(ffi_solve.MODE_ENV, "off")
    assert not ffi_solve.available()
    assert as_operator(M).factor is not None  # the callback path
    with pytest.raises(ValueError, match="sparsax"):
        SparseOperator.from_scipy(M, factor=True, solve_backend="ffi")
    monkeypatch.setenv(ffi_solve.MODE_ENV, "fastest")
    with pytest.raises(ValueError, match=ffi_solve.MODE_ENV):
        ffi_solve.available()


def test_sparse_matvec_on_irregular_rows():
    rng = np.random.default_rng(3)
    A = sp.random(40, 40, density=0.1, random_state=4, format="csr")
    A = A + A.T + sp.diags(rng.uniform(5, 6, 40))
    op = SparseOperator.from_scipy(A)
    X = rng.standard_normal((40, 3))
    np.testing.assert_allclose(op.mv(jnp.asarray(X)), A @ X, atol=1e-12)
    assert sp.issparse(op.to_scipy())


def test_sparse_matvec_batches_and_differentiates_like_the_dense_product():
    """``stiefel.linalg.ell``: the per-member batching rule and the JVP rule against the dense matrix."""
    rng = np.random.default_rng(5)
    A = sp.random(30, 30, density=0.15, random_state=6, format="csr")
    A = (A + A.T + sp.diags(rng.uniform(3, 4, 30))).tocsr()
    D = A.toarray()
    op = SparseOperator.from_scipy(A)
    X = jnp.asarray(rng.standard_normal((4, 30, 3)))
    T = jnp.asarray(rng.standard_normal((4, 30, 3)))
    np.testing.assert_allclose(jax.vmap(op.mv)(X), np.einsum("ij,bjk->bik", D, X), atol=1e-12)
    np.testing.assert_allclose(jax.vmap(op.mv)(X[:, :, 0]), X[:, :, 0] @ D.T, atol=1e-12)  # (n,) members
    # forward and reverse mode in X, batched and not
    _, dy = jax.vmap(lambda x, t: jax.jvp(op.mv, (x,), (t,)))(X, T)
    np.testing.assert_allclose(dy, np.einsum("ij,bjk->bik", D, T), atol=1e-12)
    g = jax.vmap(jax.grad(lambda x: jnp.sum(jnp.sin(op.mv(x)))))(X)
    np.testing.assert_allclose(g, np.einsum("ij,bjk->bik", D.T, np.cos(np.einsum("ij,bjk->bik", D, X))), atol=1e-12)
    # derivative in the stored values: d(S X)/dvals · dV against a finite difference
    dV = jnp.asarray(rng.standard_normal(op.vals.shape)) * (op.vals != 0)
    shifted = lambda h: eqx.tree_at(lambda o: o.vals, op, op.vals + h * dV).mv(X[0])  # noqa: E731
    jv = jax.jvp(lambda v: eqx.tree_at(lambda o: o.vals, op, v).mv(X[0]), (op.vals,), (dV,))[1]
    np.testing.assert_allclose(jv, (shifted(1e-6) - shifted(-1e-6)) / 2e-6, atol=1e-8)
    # a batch of tables (a vmap over matrices) keeps the default batching
    ops = jax.vmap(lambda s: eqx.tree_at(lambda o: o.vals, op, s * op.vals))(jnp.array([1.0, 2.0]))
    Y = jax.vmap(lambda o, x: o.mv(x))(ops, X[:2])
    np.testing.assert_allclose(Y, np.stack([D @ X[0], 2 * D @ X[1]]), atol=1e-12)


@pytest.mark.parametrize(
    "M, message",
    [
        (np.array([1.0, -2.0, 3.0]), "positive"),
        (np.array([[2.0, 1.0], [0.0, 2.0]]), "not symmetric"),
        (np.array([[1.0, 2.0], [2.0, 1.0]]), "not positive definite"),
        (sp.csr_matrix(np.array([[1.0, 2.0, 0], [2.0, 1.0, 0], [0, 0, 1.0]])), "not positive definite"),
        (sp.csr_matrix(np.array([[1.0, 0.5], [0.0, 1.0]])), "not symmetric"),
        (sp.csr_matrix(np.array([[1.0, 1.0], [1.0, 1.0]])), "M"),
    ],
)
def test_non_spd_is_rejected_with_a_named_error(M, message):
    with pytest.raises(NotSPDError, match=message):
        as_operator(M)


@pytest.mark.parametrize("M", [np.array([1.0, np.nan, 3.0]), np.array([[1.0, np.inf], [np.inf, 1.0]]),
                               sp.csr_matrix(np.array([[1.0, 0.0], [0.0, np.nan]]))])
@pytest.mark.parametrize("check", [True, False])
def test_non_finite_matrix_is_rejected_whatever_check(M, check):
    with pytest.raises(NonFiniteError, match="M has 1 non-finite|M has 2 non-finite"):
        as_operator(M, check=check)


def test_non_square_is_rejected():
    with pytest.raises(ShapeError):
        as_operator(np.ones((3, 4)))


def test_equal_matrices_give_equal_static_parts():
    """Operators built from equal matrices compare equal in their static fields (JAX's compile cache
    reuses the executable); different matrices do not."""
    M = metric_matrix("sparse", 9)
    build = lambda M: SparseOperator.from_scipy(M, factor=True, solve_backend="callback")  # noqa: E731
    a, b = build(M), build(M.copy())
    assert a.factor == b.factor and hash(a.factor) == hash(b.factor) and a.csr == b.csr
    c = build(M * 2.0)
    assert a.factor != c.factor and a.csr != c.csr


@pytest.mark.parametrize("backend,reorder", [("cholmod", True), ("qdldl", True), ("superlu", True), ("superlu", False)])
def test_symmetric_factor_solves_against_dense(backend, reorder):
    from stiefel.linalg.sparse_factor import SymmetricFactor

    rng = np.random.default_rng(3)
    n = 40
    B = sp.random(n, n, density=0.1, random_state=4)
    S = sp.csr_matrix(B @ B.T + sp.eye(n))
    f = SymmetricFactor(S, reorder=reorder, backend=backend)
    assert f.backend == backend
    b1, b2 = rng.standard_normal(n), rng.standard_normal((n, 3))
    dense = S.toarray()
    np.testing.assert_allclose(f.solve(b1), np.linalg.solve(dense, b1), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(f(b2), np.linalg.solve(dense, b2), rtol=1e-10, atol=1e-12)
    op = f.as_linear_operator()
    np.testing.assert_allclose(op.matmat(b2), np.linalg.solve(dense, b2), rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(f(b2[:, :1]), np.linalg.solve(dense, b2[:, :1]), rtol=1e-10, atol=1e-12)
    if backend == "cholmod":
        assert f.nnz is None  # not exposed by cholespy
    else:
        assert f.nnz >= S.nnz // 2


def test_symmetric_factor_cholmod_is_the_default_and_falls_back_on_indefinite(capfd):
    """CHOLMOD (cholespy, a dependency) is the default; an indefinite matrix raises with
    ``check`` and is factored by LDLᵀ without it — the backend says which, stderr stays clean."""
    from stiefel.linalg.sparse_factor import SymmetricFactor, default_backend, ldl_backend

    assert default_backend() == "cholmod"
    S = sp.csr_matrix(np.array([[2.0, 1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 0.0, 3.0]]))
    with pytest.raises(NotSPDError, match="Cholesky"):
        SymmetricFactor(S)
    f = SymmetricFactor(S, check=False)
    assert f.backend == ldl_backend()
    np.testing.assert_allclose(S @ f.solve(np.ones(3)), np.ones(3), atol=1e-14)
    assert "CHOLMOD" not in capfd.readouterr().err
    with pytest.raises(NotSPDError):
        SymmetricFactor(sp.csr_matrix(np.array([[1.0, 1.0], [1.0, 1.0]])))


@pytest.mark.parametrize("backend", ["qdldl", "superlu"])
def test_symmetric_factor_rejects_indefinite_only_when_checking(backend):
    from stiefel.linalg.sparse_factor import SymmetricFactor

    S = sp.csr_matrix(np.array([[2.0, 1.0, 0.0], [1.0, -1.0, 0.0], [0.0, 0.0, 3.0]]))
    with pytest.raises(NotSPDError, match="non-positive pivot"):
        SymmetricFactor(S, backend=backend)
    x = SymmetricFactor(S, check=False, backend=backend).solve(np.ones(3))
    np.testing.assert_allclose(S @ x, np.ones(3), atol=1e-14)
    with pytest.raises(NotSPDError, match="singular"):
        SymmetricFactor(sp.csr_matrix(np.array([[1.0, 1.0], [1.0, 1.0]])), backend=backend)


@pytest.mark.parametrize("k", [None, 3, pytest.param(40, marks=pytest.mark.slow)])
def test_quadratic_form_value_and_derivatives(k):
    """tr(XᵀWX) and its custom JVP: gradient 2WX, Hessian 2W, derivative in W's values."""
    from stiefel.linalg.operators import quadratic_form

    n = 50
    B = sp.random(n, n, density=0.1, random_state=0)
    W = sp.csr_array(B + B.T + sp.eye(n))
    op = SparseOperator.from_scipy(W)
    rng = np.random.default_rng(1)
    X = jnp.asarray(rng.standard_normal((n,) if k is None else (n, k)))
    Xn = np.asarray(X)
    np.testing.assert_allclose(quadratic_form(op, X), np.sum(Xn * (W @ Xn)), rtol=1e-12)
    g = jax.jit(jax.grad(lambda X: quadratic_form(op, X)))(X)
    np.testing.assert_allclose(g, 2 * (W @ Xn), rtol=1e-12, atol=1e-12)
    V = jnp.asarray(rng.standard_normal(X.shape))
    hv = jax.jvp(jax.grad(lambda X: quadratic_form(op, X)), (X,), (V,))[1]
    np.testing.assert_allclose(hv, 2 * (W @ np.asarray(V)), rtol=1e-12, atol=1e-12)

    def rebuilt(vals):
        return SparseOperator(cols=op.cols, vals=vals, factor=None, csr=op.csr)

    g_vals = jax.grad(lambda v: quadratic_form(rebuilt(v), X))(op.vals)
    ref = jax.grad(lambda v: jnp.sum(X * rebuilt(v).mv(X)))(op.vals)
    assert float(jnp.max(jnp.abs(ref))) > 0
    np.testing.assert_allclose(g_vals, ref, rtol=1e-12, atol=1e-12)
    batched = jax.vmap(lambda Y: quadratic_form(op, Y))(jnp.stack([X, 2 * X]))
    np.testing.assert_allclose(batched, [np.sum(Xn * (W @ Xn)), 4 * np.sum(Xn * (W @ Xn))], rtol=1e-12)


def test_dense_operator_without_factor_is_product_only():
    M = jnp.asarray([[1.0, -1.0], [-1.0, 1.0]])  # singular: a graph Laplacian
    op = DenseOperator(M)
    np.testing.assert_allclose(op.mv(jnp.ones(2)), [0.0, 0.0])
    with pytest.raises(ValueError, match="no Cholesky factor"):
        op.solve(jnp.ones(2))
