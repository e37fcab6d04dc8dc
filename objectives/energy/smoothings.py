"""Smoothings of the ℓ1 norm (thesis §6.5, Table 6.1; docs/maths.md §4 and notes 5–6).

A smoothing ``f_ε`` of ``|x|`` (thesis Def. 6.5.1) satisfies ``f_ε(0) = 0``,
``f_ε(x) → |x|`` and ``f_ε'(x) → sgn x`` as ``ε → 0``. The ten functions of
Table 6.1 are ``f0 … f9``; each has the signature ``f(x, eps=1e-3, delta=1e-3)``,
acts elementwise on an array of any shape, is pure and jittable, and ``eps`` /
``delta`` may be traced (so a continuation in δ does not recompile).

Numerics (checked by ``tests/test_smoothings.py``):

* value and ``jax.grad`` are finite for every finite float input (0, ±1e-300,
  ±1e10, ±1e300 in float64; ±1e10 in float32);
* ``sgn(0) = 0``: at ``x = 0`` every ``jax.grad`` is 0 (for the functions that
  are not C¹ at 0 this is the minimum-norm subgradient; for ``f0 = |x|`` it
  differs from ``jax.grad(jnp.abs)(0.) == 1``);
* the C¹ ones (f3, f6, f7, f8) also have the correct second derivative at 0
  (``jax.hessian`` gives ``1/ε``, ``1/δ``, ``(ε+δ)/(εδ)``, ``1/ε``);
* ``f8`` never overflows (docs/maths.md note 6) and ``f7`` is continuous at ``|x| = δ``
  (docs/maths.md note 5); ``jnp.where`` branches use the "double where" so the branch not
  taken cannot inject NaN into a gradient.

Where ``f`` is not C¹ at 0 (f0, f1, f2, f4, f5, f9) a gradient solver still runs
but the convergence theory of the smooth solver does not apply; ``info(name)``
records this.

Registry: ``get(name, eps, delta)`` returns an elementwise callable; names are
``"f0" … "f9"`` or the aliases in ``ALIASES`` (``"abs"``, ``"huber"``,
``"logcosh"``, …); ``NAMES`` lists the canonical names and ``info(name)`` the
``Smoothing`` metadata.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Callable

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "f0",
    "f1",
    "f2",
    "f3",
    "f4",
    "f5",
    "f6",
    "f7",
    "f8",
    "f9",
    "NAMES",
    "ALIASES",
    "Smoothing",
    "get",
    "info",
]

_LOG2 = math.log(2.0)


# ---------------------------------------------------------------------------
# private building blocks
# ---------------------------------------------------------------------------


@jax.custom_jvp
def _abs(x):
    """``|x|`` with derivative ``sgn(x)`` (so 0 at ``x = 0``, unlike ``jnp.abs``)."""
    return jnp.abs(x)


@_abs.defjvp
def _abs_jvp(primals, tangents):
    (x,), (t,) = primals, tangents
    return jnp.abs(x), jnp.sign(x) * t


def _log1p_ratio(a, eps):
    """``log(1 + a/ε)`` for ``a ≥ 0`` without overflow of ``a/ε`` (double where)."""
    small = a <= 1.0
    a_small = jnp.where(small, a, 0.0)
    a_big = jnp.where(small, 1.0, a)
    return jnp.where(small, jnp.log1p(a_small / eps), jnp.log(eps + a_big) - jnp.log(eps))


@jax.custom_jvp
def _abs_log(x, eps):
    """``h(x, ε) = |x| − ε log(1 + |x|/ε)`` (= f3), the log-barrier core of f2, f3, f7, f9.

    Derivatives: ``∂h/∂x = x/(ε+|x|)`` (written without ``sgn`` so that the
    second derivative at 0 is the correct ``1/ε``) and
    ``∂h/∂ε = |x|/(ε+|x|) − log(1 + |x|/ε)``.
    """
    a = jnp.abs(x)
    return a - eps * _log1p_ratio(a, eps)


@_abs_log.defjvp
def _abs_log_jvp(primals, tangents):
    x, eps = primals
    tx, teps = tangents
    a = _abs(x)
    value = _abs_log(x, eps)
    dx = x / (eps + a)
    deps = a / (eps + a) - _log1p_ratio(a, eps)
    return value, dx * tx + deps * teps


# ---------------------------------------------------------------------------
# Table 6.1
# ---------------------------------------------------------------------------


def f0(x: Float[ArrayLike, "*s"], eps: float = 1e-3, delta: float = 1e-3) -> Float[Array, "*s"]:
    """``f0(x) = |x|``; ``f0'(x) = sgn x`` (0 at 0). Not C¹ at 0. ``eps``/``delta`` unused."""
    del eps, delta
    return _abs(jnp.asarray(x))


def f1(x: Float[ArrayLike, "*s"], eps: float = 1e-3, delta: float = 1e-3) -> Float[Array, "*s"]:
    """``f1(x) = |x| + ε/(1+|x|) − ε = |x| − ε|x|/(1+|x|)``.

    ``f1'(x) = sgn(x) (1 − ε/(1+|x|)²)``. Not C¹ at 0: one-sided slopes ``±(1−ε)``.
    """
    del delta
    a = _abs(jnp.asarray(x))
    return a - eps * a / (1.0 + a)


def f2(x: Float[ArrayLike, "*s"], eps: float = 1e-3, delta: float = 1e-3) -> Float[Array, "*s"]:
    """``f2(x) = |x| − ε/(2(1+|x|)) − ε log(ε+|x|) + ε/2 + ε log ε``.

    Computed as ``|x| + ε|x|/(2(1+|x|)) − ε log(1+|x|/ε)``.
    ``f2'(x) = sgn(x) (1 + ε/(2(1+|x|)²) − ε/(ε+|x|))``. Not C¹ at 0: one-sided
    slopes ``±ε/2``.
    """
    del delta
    x = jnp.asarray(x)
    a = _abs(x)
    return _abs_log(x, eps) + 0.5 * eps * a / (1.0 + a)


def f3(x: Float[ArrayLike, "*s"], eps: float = 1e-3, delta: float = 1e-3) -> Float[Array, "*s"]:
    """``f3(x) = |x| − ε log(ε+|x|) + ε log ε = |x| − ε log(1+|x|/ε)``.

    ``f3'(x) = sgn(x) − ε sgn(x)/(ε+|x|) = x/(ε+|x|)``. C¹ (indeed C²) at 0,
    ``f3''(0) = 1/ε``.
    """
    del delta
    return _abs_log(jnp.asarray(x), eps)


def f4(x: Float[ArrayLike, "*s"], eps: float = 1e-3, delta: float = 1e-3) -> Float[Array, "*s"]:
    """``f4(x) = |x| + ε e^{−|x|} − ε`` (computed with ``expm1``).

    ``f4'(x) = sgn(x) (1 − ε e^{−|x|})``. Not C¹ at 0: one-sided slopes ``±(1−ε)``.
    """
    del delta
    a = _abs(jnp.asarray(x))
    return a + eps * jnp.expm1(-a)


def f5(x: Float[ArrayLike, "*s"], eps: float = 1e-3, delta: float = 1e-3) -> Float[Array, "*s"]:
    """``f5(x) = |x| + ε e^{−ε|x|} − ε`` (computed with ``expm1``).

    ``f5'(x) = sgn(x) (1 − ε² e^{−ε|x|})``. Not C¹ at 0: one-sided slopes ``±(1−ε²)``.
    """
    del delta
    a = _abs(jnp.asarray(x))
    return a + eps * jnp.expm1(-eps * a)


def f6(x: Float[ArrayLike, "*s"], eps: float = 1e-3, delta: float = 1e-3) -> Float[Array, "*s"]:
    """Huber function / Moreau envelope of ``|·|`` with width δ (``eps`` unused).

    ``f6(x) = x²/(2δ)`` if ``|x| ≤ δ``, else ``|x| − δ/2``;
    ``f6'(x) = x/δ`` if ``|x| ≤ δ``, else ``sgn x``. C¹ everywhere, ``f6''(0) = 1/δ``.
    """
    del eps
    x = jnp.asarray(x)
    a = _abs(x)
    inside = a <= delta
    x_in = jnp.where(inside, x, 0.0)
    return jnp.where(inside, x_in * x_in / (2.0 * delta), a - 0.5 * delta)


def _f7_inner(x, eps, delta):
    return ((eps + delta) / delta) * _abs_log(x, eps)


def f7(x: Float[ArrayLike, "*s"], eps: float = 1e-3, delta: float = 1e-3) -> Float[Array, "*s"]:
    """Moreau-type envelope built from f3 (Table 6.1, with docs/maths.md note 5).

    ``g(x) = ((ε+δ)/δ)(|x| + ε log(ε/(ε+|x|)))`` for ``|x| ≤ δ``, and
    ``|x| − δ + g(δ)`` for ``|x| > δ``, so f7 is continuous at ``|x| = δ`` for any
    ε, δ (the thesis's printed constant is right only when ε = δ).
    ``f7'(x) = ((ε+δ)/δ) x/(ε+|x|)`` for ``|x| ≤ δ`` (which equals ``sgn x`` at
    ``|x| = δ``), else ``sgn x``. C¹ everywhere; C² at 0 with
    ``f7''(0) = (ε+δ)/(εδ)``.
    """
    x = jnp.asarray(x)
    a = _abs(x)
    inside = a <= delta
    x_in = jnp.where(inside, x, 0.0)
    outer = a - delta + _f7_inner(jnp.asarray(delta, dtype=x.dtype), eps, delta)
    return jnp.where(inside, _f7_inner(x_in, eps, delta), outer)


# Beyond |x| = _F8_SWITCH·ε, e^{−2|x|/ε} < 1e-26 and the log-cosh form is not needed.
_F8_SWITCH = 30.0


def f8(x: Float[ArrayLike, "*s"], eps: float = 1e-3, delta: float = 1e-3) -> Float[Array, "*s"]:
    """``f8(x) = ε log cosh(x/ε)`` in the overflow-free form (docs/maths.md note 6)

    ``f8(x) = |x| + ε log(1 + e^{−2|x|/ε}) − ε log 2``.

    ``f8'(x) = tanh(x/ε)``. Smooth; ``f8''(0) = 1/ε``. Near 0 (``|x| ≤ 30ε``) it is
    evaluated as ``ε log(1 + 2 sinh²(x/(2ε)))`` (= ``ε log cosh(x/ε)``, no
    cancellation, no ``|x|``) so that value and derivatives keep their relative
    accuracy and the derivatives at 0 are exact; ``delta`` unused.
    """
    del delta
    x = jnp.asarray(x)
    a = _abs(x)
    near = a <= _F8_SWITCH * eps
    z = jnp.where(near, x, 0.0) / eps
    sh = jnp.sinh(0.5 * z)
    inner = eps * jnp.log1p(2.0 * sh * sh)  # log cosh z = log(1 + 2 sinh²(z/2))
    outer = a + eps * jnp.log1p(jnp.exp(-2.0 * a / eps)) - eps * _LOG2
    return jnp.where(near, inner, outer)


def f9(x: Float[ArrayLike, "*s"], eps: float = 1e-3, delta: float = 1e-3) -> Float[Array, "*s"]:
    """``f9(x) = |x| − δε log(ε+|x|) + δε log ε = |x| − δε log(1+|x|/ε)``.

    ``f9'(x) = sgn(x) (1 − δε/(ε+|x|))``. Not C¹ at 0: one-sided slopes ``±(1−δ)``.
    """
    a = _abs(jnp.asarray(x))
    return a - delta * eps * _log1p_ratio(a, eps)


# ---------------------------------------------------------------------------
# registry
# ---------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Smoothing:
    """Metadata of one Table 6.1 smoothing.

    Attributes:
      name: canonical name, ``"f0"`` … ``"f9"``.
      fn: the function ``fn(x, eps=1e-3, delta=1e-3)``.
      c1_at_zero: whether ``fn`` is continuously differentiable at 0 (the
        smooth-solver theory needs it).
      note: one line: what it is and its one-sided slopes at 0.
    """

    name: str
    fn: Callable
    c1_at_zero: bool
    note: str


_TABLE: dict[str, Smoothing] = {
    s.name: s
    for s in (
        Smoothing("f0", f0, False, "|x| itself; one-sided slopes ±1 (grad at 0 taken as 0)"),
        Smoothing("f1", f1, False, "rational; one-sided slopes ±(1−ε)"),
        Smoothing("f2", f2, False, "rational + log; one-sided slopes ±ε/2"),
        Smoothing("f3", f3, True, "log barrier; f' = x/(ε+|x|), C² at 0 (thesis default)"),
        Smoothing("f4", f4, False, "exponential; one-sided slopes ±(1−ε)"),
        Smoothing("f5", f5, False, "scaled exponential; one-sided slopes ±(1−ε²)"),
        Smoothing("f6", f6, True, "Huber / Moreau envelope of width δ; C¹, C² at 0"),
        Smoothing("f7", f7, True, "Moreau-type envelope from f3 (the constant of docs/maths.md note 5); C¹, C² at 0"),
        Smoothing("f8", f8, True, "ε log cosh(x/ε), overflow-free (docs/maths.md note 6); smooth"),
        Smoothing("f9", f9, False, "f3 with log term scaled by δ; one-sided slopes ±(1−δ)"),
    )
}

#: canonical names, in Table 6.1 order
NAMES: tuple[str, ...] = tuple(_TABLE)

#: descriptive aliases → canonical names
ALIASES: dict[str, str] = {
    "abs": "f0",
    "l1": "f0",
    "rational": "f1",
    "rational_log": "f2",
    "log": "f3",
    "log_barrier": "f3",
    "exp": "f4",
    "exp_scaled": "f5",
    "huber": "f6",
    "moreau": "f6",
    "moreau_log": "f7",
    "logcosh": "f8",
    "log_cosh": "f8",
    "log_scaled": "f9",
}


def _canonical(name: str) -> str:
    key = str(name).lower()
    key = ALIASES.get(key, key)
    if key not in _TABLE:
        known = ", ".join(NAMES) + "; aliases: " + ", ".join(sorted(ALIASES))
        raise ValueError(f"unknown smoothing {name!r}; choose one of {known}")
    return key


def info(name: str) -> Smoothing:
    """The ``Smoothing`` record for ``name`` (canonical name or alias)."""
    return _TABLE[_canonical(name)]


def _check_positive(value, what: str) -> None:
    try:
        v = float(value)
    except (TypeError, jax.errors.ConcretizationTypeError):
        return  # traced: cannot check here
    if not (v > 0.0 and math.isfinite(v)):
        raise ValueError(f"{what} must be a positive finite number, got {v!r}")


def get(name: str, eps: float = 1e-3, delta: float = 1e-3) -> Callable[[Array], Array]:
    """Elementwise callable ``x ↦ f_name(x, eps, delta)`` (Table 6.1).

    Args:
      name: ``"f0"`` … ``"f9"`` or an alias (``"abs"``, ``"huber"``, ``"logcosh"``, …).
      eps, delta: smoothing parameters ε, δ > 0 (thesis default 1e-3).

    Raises:
      ValueError: unknown name, or a concrete ``eps``/``delta`` that is not > 0.
    """
    fn = info(name).fn
    _check_positive(eps, "eps")
    _check_positive(delta, "delta")

    def smoothing(x: Float[ArrayLike, "*s"]) -> Float[Array, "*s"]:
        return fn(x, eps, delta)

    smoothing.__name__ = f"{fn.__name__}(eps={eps}, delta={delta})"
    smoothing.__doc__ = fn.__doc__
    return smoothing
