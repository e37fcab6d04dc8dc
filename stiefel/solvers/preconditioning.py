"""Preconditioned Riemannian gradients on the generalised Stiefel manifold.

A preconditioner is an SPD operator ``P ≈ (∇²F)⁻¹`` (e.g. ``P = (W + σM)⁻¹``
for Dirichlet-type energies). It defines the metric ``g_X(Z1, Z2) = tr(Z1ᵀP⁻¹Z2)``
on ``T_X S_M``, and the Riemannian gradient in that metric is

    ξ = P (G − M X Λ),   Λ symmetric with  BΛ + ΛB = 2 sym(XᵀMPG),   B = XᵀMPMX,

(the symmetric ``Λ`` makes ``XᵀMξ`` skew, i.e. ξ tangent). Because
``g(ξ, Z) = tr(GᵀZ)`` for every tangent ``Z``, ``tr(Gᵀξ) = g(ξ, ξ) > 0``: ``−ξ``
is always a descent direction. With ``P = M⁻¹`` it is the Euclidean-metric
gradient ``M⁻¹G − X sym(XᵀG)``.

For the sequential constraint set ``{x : CᵀMx = 0 (C = [Φ x])}`` the multiplier
is a vector: ``ξ = P(g − MCλ)`` with ``(CᵀMPMC) λ = CᵀMPg``.

The cheaper *residual* form (the default in the solvers) preconditions the
residual ``R = G − MX sym(XᵀG)`` (``= M·grad_e``, zero exactly at critical points)
and projects: ``ξ = proj_X(P R)``. It needs P on k columns instead of 2k, and it
is a descent direction too: ``tr(Gᵀξ) = tr(RᵀPR) > 0``, because ``XᵀR`` is skew
so the projection's correction is orthogonal to R.
"""

from __future__ import annotations

from typing import Callable

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Float

from ..manifolds.manifold import sym
from ..linalg.operators import LinearOperator, as_operator
from ..validation import check_positive

__all__ = [
    "PointPreconditioner",
    "at_point",
    "as_preconditioner",
    "shifted_inverse",
    "preconditioned_gradient",
    "preconditioned_residual",
    "constrained_preconditioned_gradient",
    "PRECONDITIONING_MODES",
]

PRECONDITIONING_MODES = ("residual", "metric")


class PointPreconditioner(eqx.Module):
    """A preconditioner that depends on the point (Manopt's ``precon(x, d)``): ``apply(X, Y) = P_X Y``
    with ``P_X`` SPD on ``R^{n×k}`` for every X on the manifold, e.g. an approximate inverse of the
    objective's Hessian at X. The solvers take it as ``preconditioner=`` and apply ``P_X`` at their
    current iterate (trust regions: to every inner CG residual of an outer iteration; CG / L-BFGS / BB:
    to the gradient at X). ``apply`` must be jittable; its closed-over arrays are traced leaves."""

    apply: Callable

    def at(self, X) -> Callable:
        """``Y ↦ P_X Y``."""
        return lambda Y: self.apply(X, Y)


def at_point(P, X) -> Callable | None:
    """The preconditioner to use at ``X``: ``P.at(X)`` for a ``PointPreconditioner``, else ``P`` itself."""
    return P.at(X) if isinstance(P, PointPreconditioner) else P


def as_preconditioner(P) -> Callable | PointPreconditioner | None:
    """Normalise a preconditioner argument to a callable ``Y ↦ P Y`` (or None).

    ``P`` may be None, a callable applying an SPD ``P`` to ``(n, k)`` arrays, or an
    SPD matrix / ``LinearOperator`` ``K`` (dense, diagonal or ``scipy.sparse``)
    whose *inverse* is applied: ``P = K⁻¹`` (sparse K is factored once). A
    ``PointPreconditioner`` is returned as it is (the solvers apply it at each point).
    """
    if P is None or isinstance(P, PointPreconditioner):
        return P
    if isinstance(P, LinearOperator):
        return P.solve
    if callable(P):
        return P
    return as_operator(P).solve


def shifted_inverse(W, M, sigma: float) -> LinearOperator:
    """The operator ``K = W + σM`` (factored once); pass it as ``preconditioner=`` to apply ``K⁻¹``.

    ``W`` and ``M`` are ``scipy.sparse`` matrices (or dense arrays); ``σ > 0`` makes ``K``
    SPD when ``W`` is positive semi-definite. A good σ is of the order of the
    smallest eigenvalues sought. ``σ`` must be a finite number > 0 (``ParameterError``).
    """
    import scipy.sparse as sp

    check_positive("sigma", sigma)

    if sp.issparse(W) or sp.issparse(M):
        M_mat = sp.diags(M) if getattr(M, "ndim", 2) == 1 and not sp.issparse(M) else M
        K = sp.csr_array(W) + sigma * sp.csr_array(M_mat)
    else:
        W_arr, M_arr = jnp.asarray(W), jnp.asarray(M)
        K = W_arr + sigma * (jnp.diag(M_arr) if M_arr.ndim == 1 else M_arr)
    return as_operator(K)


def _lyapunov_sym(B: Float[Array, "k k"], R: Float[Array, "k k"]) -> Float[Array, "k k"]:
    """Solve ``BΛ + ΛB = R`` for SPD ``B`` and symmetric ``R`` (eigenbasis of B)."""
    d, Q = jnp.linalg.eigh(sym(B))
    Rt = Q.T @ R @ Q
    return Q @ (Rt / (d[:, None] + d[None, :])) @ Q.T


def preconditioned_gradient(M: LinearOperator, apply_P: Callable, X: Float[Array, "n k"],
                            G: Float[Array, "n k"]) -> Float[Array, "n k"]:
    """Riemannian gradient of the P⁻¹-metric (module docstring); one application of P to ``[G, MX]``."""
    k = X.shape[1]
    MX = M.mv(X)
    PGM = apply_P(jnp.concatenate([G, MX], axis=1))
    PG, PMX = PGM[:, :k], PGM[:, k:]
    B = MX.T @ PMX
    Lam = _lyapunov_sym(B, 2.0 * sym(MX.T @ PG))
    return PG - PMX @ Lam


def constrained_preconditioned_gradient(apply_P: Callable, MC: Float[Array, "n c"], PMC: Float[Array, "n c"],
                                        active: Float[Array, " c"], g: Float[Array, " n"]) -> Float[Array, " n"]:
    """``ξ = P(g − MCλ)`` tangent to ``{CᵀMx = 0}`` for the active columns of ``C`` (inactive: zero columns)."""
    Pg = apply_P(g[:, None])[:, 0]
    S = MC.T @ PMC
    mask2 = active[:, None] * active[None, :]
    S = S * mask2 + jnp.diag(1.0 - active)
    lam = jnp.linalg.solve(sym(S), active * (MC.T @ Pg))
    return Pg - PMC @ lam


def preconditioned_residual(manifold, apply_P: Callable, X: Float[Array, "n k"],
                            R: Float[Array, "n k"]) -> Float[Array, "n k"]:
    """``proj_X(P R)`` for the residual ``R = G − MX sym(XᵀG)`` (module docstring): k columns of P."""
    return manifold.proj(X, apply_P(R))
