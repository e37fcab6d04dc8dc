"""Derivatives of compressed manifold modes (objectives.cmm.differentiable.cmm_solve) with respect to μ,
a per-vertex ℓ1 weight, the smoothing width and the vertex positions (through mesh.laplacian_jax),
against central finite differences of re-solved problems (docs/maths.md §9)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import mesh
import stiefel
from objectives.cmm.modes import first_eigenpairs
from objectives.cmm.differentiable import cmm_solve

from mesh_fixtures import hand_laplacian, hand_mesh

K = 3


@pytest.fixture(scope="module")
def hand():
    """The hand stand-in (tests/mesh_fixtures.py: starfish, 642 vertices; it replaced hand_868.obj)."""
    m = hand_mesh()
    V0, F = jnp.asarray(m.vertices), np.asarray(m.faces)
    lap = hand_laplacian()
    a0 = lap.A.diagonal()
    n = a0.shape[0]
    P = stiefel.shifted_inverse(lap.W, a0, 50.0).solve
    X0 = jnp.asarray(first_eigenpairs(lap.W, a0, K)[1][:, :K])
    # the start for every re-solve: the solution at the base point (so FD and derivative follow one branch)
    Xs, res = cmm_solve(mesh.weight_operator_jax(V0, F), jnp.asarray(a0), X0, 0.05 * n, stages=(4.0,), preconditioner=P)
    assert res.converged
    c = jnp.asarray(np.random.default_rng(0).standard_normal((n, K)))
    return V0, F, Xs, P, c, n


def _loss(hand, mu, w_scale5, eps, V):
    V0, F, Xs, P, c, n = hand
    W, A = mesh.laplacian_jax(V, F, "lumped")
    area = A.data  # A is diagonal, stored in row order
    weights = area.at[5].multiply(w_scale5)
    Psi, _ = cmm_solve(W, area, Xs, mu, weights=weights, eps=eps, preconditioner=P, gtol=1e-10)
    return jnp.sum(c * Psi)


@pytest.mark.slow
def test_cmm_derivatives_against_resolved_fd(hand):
    V0, F, Xs, P, c, n = hand
    base = (jnp.asarray(0.05 * n), jnp.asarray(1.0), jnp.asarray(0.5), V0)  # arrays: one program for every value
    dV = jnp.asarray(np.random.default_rng(1).standard_normal(V0.shape)) * 1e-2
    grads = jax.grad(lambda mu, w5, eps, V: _loss(hand, mu, w5, eps, V), argnums=(0, 1, 2, 3))(*base)
    steps = {0: 2e-3, 1: 1e-4, 2: 1e-4, 3: 1e-4}  # FD truncation: h = 0.04 in μ was 3e-5 off
    for i, h in steps.items():
        plus, minus = list(base), list(base)
        if i == 3:
            plus[3], minus[3] = V0 + h * dV, V0 - h * dV
            analytic = float(jnp.sum(grads[3] * dV))
        else:
            plus[i], minus[i] = base[i] + h, base[i] - h
            analytic = float(grads[i])
        fd = float(_loss(hand, *plus) - _loss(hand, *minus)) / (2 * h)
        # measured on the stand-in: 8e-8 (μ), 2.6e-6 (w_5), 7e-8 (ε), 1.7e-9 (V) relative
        assert abs(analytic - fd) <= 1e-5 * abs(fd), (i, analytic, fd)
    # forward mode agrees with reverse mode (μ direction and shape direction together; measured 7e-11 relative)
    tangent = jax.jvp(lambda s: _loss(hand, base[0] + s, base[1], base[2], V0 + s * dV), (jnp.zeros(()),), (jnp.ones(()),))[1]
    assert abs(float(tangent) - (float(grads[0]) + float(jnp.sum(grads[3] * dV)))) <= 1e-8 * abs(float(tangent))


def test_bad_operator_named():
    with pytest.raises(TypeError, match="operator with .mv"):
        cmm_solve(np.eye(3), jnp.ones(3), jnp.eye(3)[:, :1], 1.0)
