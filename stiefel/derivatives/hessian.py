"""The Riemannian Hessian on ``S_M = {XᵀMX = I}`` (docs/maths.md §9).

For ``F: R^{n×k} → R`` with Euclidean gradient ``G = ∇F(X)`` and Hessian action
``H[ξ] = ∇²F(X)[ξ]`` (a ``jax.jvp`` of ``jax.grad F``), the Riemannian Hessian of the
M-weighted metric ``⟨ξ, η⟩ = tr(ξᵀMη)`` is

    ``Hess F(X)[ξ] = P_X(M⁻¹ H[ξ] − ξ sym(XᵀG))``,   ``P_X(Z) = Z − X sym(XᵀMZ)``,

for tangent ``ξ`` (the projection of the ambient derivative of the gradient field: the
Levi-Civita connection of the embedded metric). It is self-adjoint in ``⟨·,·⟩``. For the
canonical metric the same operator is returned: at a critical point the Hessian does not
depend on the metric, and docs/maths.md §9 prescribes this form for second-order work.
On a ``stiefel.Product`` ``X``, ``ξ`` and the result are tuples: ``H[ξ]`` carries the cross terms of a
coupled F, and the formula applies factor by factor (``Product.ehess_to_rhess``).
"""

from __future__ import annotations

import inspect
from typing import Any, Callable

import jax
from jaxtyping import Array, Float

from ..manifolds.manifold import GeneralizedStiefel
from ..manifolds.product import Product

__all__ = ["riemannian_hessian", "hessian_operator"]


def _needs_args(fn: Callable) -> bool:
    """Whether ``fn`` requires a second positional argument (an optimistix-style ``fn(X, args)``)."""
    try:
        params = list(inspect.signature(fn).parameters.values())
    except (TypeError, ValueError):  # no signature (a builtin): call it with X alone
        return False
    positional = [p for p in params if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    return len(positional) >= 2 and positional[1].default is inspect.Parameter.empty


def call(fn: Callable, X, args: Any = None):
    """``fn(X, args)`` when ``args`` is given or ``fn`` requires it (then with ``args = None``), else ``fn(X)``."""
    return fn(X, args) if args is not None or _needs_args(fn) else fn(X)


def _euclidean(fn: Callable, args: Any):
    return lambda X: call(fn, X, args)


def riemannian_hessian(fn: Callable, manifold: GeneralizedStiefel | Product, X: Float[Array, "n k"],
                       xi: Float[Array, "n k"], args: Any = None) -> Float[Array, "n k"]:
    """``Hess F(X)[ξ]`` for tangent ``ξ`` (module docstring); ``fn(X)`` or ``fn(X, args)`` → scalar (an
    optimistix-style ``fn(X, args)`` is called with ``args = None`` when none is given).

    Costs one forward-over-reverse product (``jax.jvp`` of ``jax.grad``), one ``M⁻¹`` solve
    and one product with M.
    """
    G, H = jax.jvp(jax.grad(_euclidean(fn, args)), (X,), (xi,))
    return manifold.ehess_to_rhess(X, G, H, xi)


def hessian_operator(fn: Callable, manifold: GeneralizedStiefel | Product, X: Float[Array, "n k"],
                     args: Any = None) -> Callable[[Float[Array, "n k"]], Float[Array, "n k"]]:
    """``ξ ↦ Hess F(X)[ξ]`` with the gradient linearised once (``jax.linearize``): repeated
    products (e.g. inside CG) cost one linearised Hessian action each."""
    G, hvp = jax.linearize(jax.grad(_euclidean(fn, args)), X)
    return lambda xi: manifold.ehess_to_rhess(X, G, hvp(xi), xi)
