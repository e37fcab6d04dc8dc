"""stiefel.solvers.saddle: the most negative curvature (LOBPCG) against a dense Hessian, and the escape step."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.linalg as sla

import stiefel
from stiefel.solvers.saddle import escape_step, negative_curvature

from stiefel_cases import metric_matrix

N, K = 30, 3


def _problem(seed: int = 0):
    """Generalised Brockett ``F = tr(XᵀAX N)`` on ``XᵀMX = I`` (diagonal M), its generalised eigenpairs."""
    rng = np.random.default_rng(seed)
    B = rng.standard_normal((N, N))
    A = B @ B.T / N + np.diag(np.linspace(0.0, 3.0, N))
    m = metric_matrix("diagonal", N, seed)
    lam, V = sla.eigh(A, np.diag(m))  # VᵀMV = I
    weights = jnp.asarray([3.0, 2.0, 1.0])

    def F(X):
        return jnp.sum((X * (jnp.asarray(A) @ X)) * weights)

    return F, stiefel.GeneralizedStiefel(m, K), m, lam, V


def _dense_min_curvature(F, S, m, X) -> float:
    """Smallest eigenvalue of the Riemannian Hessian on T_X from its dense matrix in M^{1/2} coordinates."""
    sq = np.sqrt(m)[:, None]
    Y = np.asarray(X) * sq
    # the tangent space in Y coordinates is the range of the orthogonal projector Q
    Q = lambda E: E - Y @ (0.5 * (Y.T @ E + E.T @ Y))  # noqa: E731
    P = np.stack([Q(e.reshape(N, K)).ravel() for e in np.eye(N * K)], 1)
    U, s, _ = np.linalg.svd(P)
    T = U[:, s > 0.5]  # orthonormal basis of the tangent space (Y coordinates)
    hvp = jax.jit(lambda xi: stiefel.riemannian_hessian(F, S, X, xi))
    H = np.stack([(np.asarray(hvp(jnp.asarray(t.reshape(N, K) / sq))) * sq).ravel() for t in T.T], 1)
    Hr = T.T @ H
    return float(np.linalg.eigvalsh(0.5 * (Hr + Hr.T))[0])


@pytest.fixture(scope="module")
def problem():
    return _problem()


def test_curvature_matches_dense_hessian_at_a_saddle(problem):
    F, S, m, lam, V = problem
    X = jnp.asarray(V[:, [5, 0, 1]])  # a critical point that is not the minimum: a saddle
    reference = _dense_min_curvature(F, S, m, X)
    assert reference < -1e-2
    c = jax.jit(lambda X: negative_curvature(F, S, X, max_iters=200, rtol=1e-9))(X)
    assert float(c.value) == pytest.approx(reference, rel=1e-7)
    d = np.asarray(c.direction)
    XtMd = np.asarray(X).T @ (m[:, None] * d)
    assert np.max(np.abs(XtMd + XtMd.T)) < 1e-12  # tangent
    assert float(S.inner(X, c.direction, c.direction)) == pytest.approx(1.0, abs=1e-12)


def test_curvature_is_nonnegative_at_the_minimum(problem):
    F, S, m, lam, V = problem
    X = jnp.asarray(V[:, [0, 1, 2]])
    reference = _dense_min_curvature(F, S, m, X)
    assert reference > 0
    c = negative_curvature(F, S, X, max_iters=200, rtol=1e-9)
    assert float(c.value) == pytest.approx(reference, rel=1e-6)
    step = escape_step(F, S, X, c)
    assert not bool(step.accepted) and float(step.step) == 0.0
    assert np.array_equal(np.asarray(step.X), np.asarray(X))


def test_escape_step_decreases_and_stays_on_the_manifold(problem):
    F, S, m, lam, V = problem
    X = jnp.asarray(V[:, [5, 0, 1]]) + 0.0
    c = negative_curvature(F, S, X, max_iters=60)
    step = escape_step(F, S, X, c)
    assert bool(step.accepted) and float(step.step) > 0
    t, f0 = float(step.step), float(F(X))
    slope = -abs(float(jnp.sum(jax.grad(F)(X) * c.direction)))
    assert float(step.value) <= f0 + 0.5 * (t * slope + 0.5 * float(c.value) * t * t)
    assert float(step.value) == pytest.approx(float(F(step.X)), rel=1e-12)
    Xn = np.asarray(step.X)
    assert np.max(np.abs(Xn.T @ (m[:, None] * Xn) - np.eye(K))) < 1e-12


def test_preconditioned_search_agrees(problem):
    F, S, m, lam, V = problem
    X = jnp.asarray(V[:, [5, 0, 1]])
    reference = _dense_min_curvature(F, S, m, X)
    rng = np.random.default_rng(3)
    B = rng.standard_normal((N, N))
    K_spd = B @ B.T / N + np.eye(N)  # any SPD preconditioner: the answer must not change
    c = negative_curvature(F, S, X, preconditioner=K_spd, max_iters=200, rtol=1e-9)
    assert float(c.value) == pytest.approx(reference, rel=1e-7)


@pytest.mark.slow
def test_mask_excludes_zero_padding_rows(problem):
    """Zero rows appended (a padded problem): their Hessian is −ξ sym(XᵀG), negative, and would be reported
    as curvature unless masked out; with the mask the padded problem's answer is the unpadded one's."""
    F, S, m, lam, V = problem
    X = jnp.asarray(V[:, [0, 1, 2]])  # the minimum: no true negative curvature
    pad = 5
    mp = np.r_[m, np.ones(pad)]
    Sp = stiefel.GeneralizedStiefel(mp, K)
    Xp = jnp.concatenate([X, jnp.zeros((pad, K))])

    def Fp(Z):
        return F(Z[:N])

    unmasked = negative_curvature(Fp, Sp, Xp, max_iters=200, rtol=1e-9)
    assert float(unmasked.value) < 0  # the padding's spurious curvature
    rows = np.r_[np.ones(N), np.zeros(pad)]
    masked = negative_curvature(Fp, Sp, Xp, mask=rows, max_iters=200, rtol=1e-9)
    assert float(masked.value) == pytest.approx(_dense_min_curvature(F, S, m, X), rel=1e-6)
    assert np.all(np.asarray(masked.direction)[N:] == 0.0)
