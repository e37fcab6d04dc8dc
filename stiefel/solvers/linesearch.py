"""Strong Armijo–Wolfe line search on a scalar function (docs/maths.md §3, thesis Def. 6.2.6).

The search works on ``h(τ) = F(R_X(τ d))`` given as ``phi(τ) -> (h(τ), h'(τ))``;
``along_curve`` builds ``phi`` with ``h'`` from ``jax.jvp`` (exact for every
retraction). The algorithm is bracketing + zoom with safeguarded cubic
interpolation (Nocedal & Wright, Alg. 3.5/3.6), written as one
``lax.while_loop`` so it is jittable and vmappable. Two fallbacks:

* *approximate Wolfe* (Hager & Zhang 2005): near a minimiser, ``h(τ) − h(0)``
  is below rounding error and the Armijo test is noise; a step whose
  derivative satisfies ``c2 h'(0) ≤ h'(τ) ≤ (1 − 2c1)|h'(0)|`` and whose value
  is within ``approx_tol·|h(0)|`` of ``h(0)`` is accepted and reported as such
  (only then: the test is for the rounding regime, not a looser Wolfe test);
* *backtracking Armijo* (thesis Algorithm 5): if the zoom uses up its
  evaluations without a sufficient decrease, the smallest step tried is
  shrunk by ``backtrack_factor`` until Armijo holds.

Below a gradient norm of ``round_off_floor`` the computed slopes themselves are
rounding noise and a search may find no acceptable step: the solvers report
such a failure as convergence at the floor (``stiefel.solvers.minimisers.settled_status``).

Why not jaxopt's ``ZoomLineSearch`` or optimistix? optimistix has no Wolfe
search, and jaxopt (archived) works on the ambient vector with its own
gradient, which is not the derivative along the retraction curve. The search
here is ~150 lines, works on the exact scalar ``h`` and reports which
condition held.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from ..validation import (check_count, check_nonnegative, check_number, check_positive, check_unit_interval, check_wolfe)

__all__ = ["LineSearchStatus", "LineSearchResult", "strong_wolfe", "along_curve", "round_off_floor", "FLOOR_FACTOR"]

#: the margin of ``round_off_floor`` over the rounding estimate ``√N·ε·scale``
FLOOR_FACTOR = 10.0


class LineSearchStatus:
    """Integer codes of ``LineSearchResult.status``."""

    WOLFE = 0  #: strong Armijo–Wolfe conditions hold
    APPROX_WOLFE = 1  #: approximate Wolfe (value within rounding of h(0), derivative condition holds)
    ARMIJO = 2  #: only the sufficient-decrease (Armijo) condition holds (fallback or max_step reached)
    NOT_DESCENT = 3  #: h'(0) ≥ 0 or h(0), h'(0) non-finite: no step taken
    FAILED = 4  #: no step with sufficient decrease was found: no step taken

    names = ("wolfe", "approx_wolfe", "armijo", "not_descent", "failed")


class LineSearchResult(eqx.Module):
    """Outcome of a line search; ``step = 0`` unless a step was accepted."""

    step: Float[Array, ""]
    value: Float[Array, ""]  #: h(step)
    slope: Float[Array, ""]  #: h'(step)
    status: Int[Array, ""]
    armijo: Bool[Array, ""]  #: h(step) ≤ h(0) + c1·step·h'(0)
    curvature: Bool[Array, ""]  #: |h'(step)| ≤ c2|h'(0)|
    n_evals: Int[Array, ""]

    @property
    def accepted(self) -> Bool[Array, ""]:
        return self.status <= LineSearchStatus.ARMIJO


def along_curve(F: Callable, curve: Callable) -> Callable:
    """``phi(τ) = (F(curve(τ)), d/dτ F(curve(τ)))`` with the derivative from ``jax.jvp``."""

    def phi(tau):
        return jax.jvp(lambda t: F(curve(t)), (tau,), (jnp.ones_like(tau),))

    return phi


def round_off_floor(value: Float[Array, ""], value_scale: Float[Array, ""], size: int) -> Float[Array, ""]:
    """The Riemannian gradient norm that rounding allows: ``FLOOR_FACTOR·√N·ε·(|F| + |value_scale|)``.

    ``value``: the objective ``F`` at the iterate; ``value_scale``: its typical size (the solvers pass
    ``F(X0)``, the scale of the search's approximate Wolfe test, so that objectives with a minimum near 0 keep
    a floor); ``size``: ``N``, the number of entries of ``X`` (all blocks of a ``Product``); ε: the machine
    epsilon of ``value``'s dtype. The computed gradient carries errors of ε relative to the objective's
    terms, accumulated over sums of up to N products (√N·ε, the probabilistic bound; Higham & Mary 2019);
    ``FLOOR_FACTOR`` = 10 is the margin. Measured (docs/benchmarks/default-method.md): L-BFGS's searches fail
    4.5–140× below this level, while CG's searches fail 700–6.5·10⁵× above it (a failure of the method, not
    of rounding: L-BFGS goes on from there).
    """
    dtype = jnp.result_type(value, float)
    scale = jnp.abs(jnp.asarray(value, dtype)) + jnp.abs(jnp.asarray(value_scale, dtype))
    return FLOOR_FACTOR * float(np.sqrt(size)) * jnp.finfo(dtype).eps * scale


class _State(NamedTuple):
    stage: Int[Array, ""]  # 0 bracket, 1 zoom, 2 backtrack, 3 done
    a: Float[Array, ""]  # next trial step
    a_lo: Float[Array, ""]
    f_lo: Float[Array, ""]
    g_lo: Float[Array, ""]
    a_hi: Float[Array, ""]
    f_hi: Float[Array, ""]
    g_hi: Float[Array, ""]
    a_min_tried: Float[Array, ""]
    n_evals: Int[Array, ""]
    out_a: Float[Array, ""]
    out_f: Float[Array, ""]
    out_g: Float[Array, ""]
    out_status: Int[Array, ""]


def _cubic_min(a0, f0, g0, a1, f1, g1):
    """Minimiser of the cubic interpolating (a0, f0, g0), (a1, f1, g1), safeguarded to the inner 80%."""
    lo, hi = jnp.minimum(a0, a1), jnp.maximum(a0, a1)
    width = hi - lo
    diff = jnp.where(a0 == a1, 1.0, a0 - a1)
    d1 = g0 + g1 - 3.0 * (f0 - f1) / diff
    disc = d1 * d1 - g0 * g1
    d2 = jnp.sign(a1 - a0) * jnp.sqrt(jnp.maximum(disc, 0.0))
    denom = g1 - g0 + 2.0 * d2
    a = a1 - (a1 - a0) * (g1 + d2 - d1) / jnp.where(denom == 0, 1.0, denom)
    ok = (disc >= 0) & (denom != 0) & jnp.isfinite(a) & jnp.isfinite(f1) & jnp.isfinite(g1)
    a = jnp.where(ok, a, 0.5 * (lo + hi))
    return jnp.clip(a, lo + 0.1 * width, hi - 0.1 * width)


def strong_wolfe(
    phi: Callable,
    phi0: Float[Array, ""],
    dphi0: Float[Array, ""],
    init_step: Float[Array, ""] | float = 1.0,
    *,
    c1: float = 1e-4,
    c2: float = 0.9,
    max_step: float = jnp.inf,
    max_evals: int = 30,
    max_backtrack: int = 30,
    extrapolation: float = 2.0,
    backtrack_factor: float = 0.1,
    approx_tol: float = 1e-12,
    approx_c2: float = 0.9,
    value_scale: Float[Array, ""] | float = 0.0,
) -> LineSearchResult:
    """Find ``τ > 0`` with ``h(τ) ≤ h(0) + c1 τ h'(0)`` and ``|h'(τ)| ≤ c2 |h'(0)|``.

    Args:
      phi: ``τ -> (h(τ), h'(τ))`` (scalars), e.g. from ``along_curve``.
      phi0, dphi0: ``h(0)`` and ``h'(0)``; the search needs ``h'(0) < 0``.
      init_step: first trial step (clipped to ``max_step``).
      c1, c2: Armijo and curvature constants, ``0 < c1 < c2 < 1``.
      max_step: largest step (e.g. π/2 for the periodic retraction, Cor. 6.4.25).
      max_evals: evaluations for bracketing + zoom; then up to ``max_backtrack``
        backtracking-Armijo evaluations.
      approx_tol, approx_c2, value_scale: the approximate Wolfe test accepts
        ``|h(τ) − h(0)| ≤ approx_tol·(|h(0)| + value_scale)`` (the change is at
        rounding level; ``value_scale`` is the typical size of the objective's
        terms, e.g. its value at the start, for objectives whose minimum is 0) with
        ``approx_c2·h'(0) ≤ h'(τ) ≤ (1 − 2c1)|h'(0)|`` (Hager–Zhang's σ = 0.9).
    Returns:
      A ``LineSearchResult``; ``status`` says which conditions held
      (``LineSearchStatus``). A non-descent direction or a failed search gives
      ``step = 0`` and a status, never a NaN.

    Concrete options are checked (``ParameterError``): ``0 < c1 < c2 < 1``, ``init_step > 0``,
    ``max_step > 0``, counts ≥ 1, ``extrapolation > 1``, ``0 < backtrack_factor < 1``,
    ``approx_tol ≥ 0``, ``0 < approx_c2 < 1``; traced ones (inside a solver's loop) are not.
    """
    check_wolfe(c1, c2)
    check_positive("init_step", init_step)
    check_positive("max_step", max_step, finite=False)
    check_count("max_evals", max_evals)
    check_count("max_backtrack", max_backtrack, 0)
    check_number("extrapolation", extrapolation, low=1, low_open=True)
    check_unit_interval("backtrack_factor", backtrack_factor)
    check_nonnegative("approx_tol", approx_tol)
    check_unit_interval("approx_c2", approx_c2)
    dtype = jnp.result_type(phi0, dphi0, float)
    phi0 = jnp.asarray(phi0, dtype)
    dphi0 = jnp.asarray(dphi0, dtype)
    zero = jnp.zeros((), dtype)
    max_step = jnp.asarray(max_step, dtype)
    a0 = jnp.minimum(jnp.asarray(init_step, dtype), max_step)
    valid = jnp.isfinite(phi0) & jnp.isfinite(dphi0) & (dphi0 < 0) & (a0 > 0)
    f_tol = approx_tol * (jnp.abs(phi0) + jnp.abs(jnp.asarray(value_scale, dtype)) + jnp.finfo(dtype).tiny)

    init = _State(
        stage=jnp.where(valid, 0, 3),
        a=a0,
        a_lo=zero, f_lo=phi0, g_lo=dphi0,
        a_hi=zero, f_hi=phi0, g_hi=dphi0,
        a_min_tried=jnp.asarray(jnp.inf, dtype),
        n_evals=jnp.zeros((), jnp.int32),
        out_a=zero, out_f=phi0, out_g=dphi0,
        out_status=jnp.asarray(jnp.where(valid, LineSearchStatus.FAILED, LineSearchStatus.NOT_DESCENT), jnp.int32),
    )

    def cond(s: _State):
        return s.stage < 3

    def body(s: _State) -> _State:
        a = s.a
        f, g = phi(a)
        f = jnp.asarray(f, dtype)
        g = jnp.asarray(g, dtype)
        n_evals = s.n_evals + 1
        finite = jnp.isfinite(f) & jnp.isfinite(g)
        armijo = finite & (f <= phi0 + c1 * a * dphi0)
        curv = finite & (jnp.abs(g) <= c2 * jnp.abs(dphi0))
        approx = finite & (jnp.abs(f - phi0) <= f_tol) & (g >= approx_c2 * dphi0) & (g <= (1.0 - 2.0 * c1) * jnp.abs(dphi0))
        wolfe = armijo & curv
        accept = wolfe | approx
        code = jnp.where(wolfe, LineSearchStatus.WOLFE, LineSearchStatus.APPROX_WOLFE)
        a_min_tried = jnp.minimum(s.a_min_tried, a)

        # --- stage 0: bracketing -------------------------------------------------------------
        too_far = ~armijo | ((n_evals > 1) & (f >= s.f_lo))
        rising = ~too_far & (g >= 0)
        at_max = ~too_far & ~rising & (a >= max_step)
        # new bracket (lo, hi) when too_far: (previous lo, a); when rising: (a, previous lo)
        br_lo = jnp.where(rising, a, s.a_lo)
        br_flo = jnp.where(rising, f, s.f_lo)
        br_glo = jnp.where(rising, g, s.g_lo)
        br_hi = jnp.where(rising, s.a_lo, a)
        br_fhi = jnp.where(rising, s.f_lo, f)
        br_ghi = jnp.where(rising, s.g_lo, g)
        # otherwise keep extrapolating: a becomes the new lo
        ex_lo = jnp.where(too_far | rising, br_lo, a)
        ex_flo = jnp.where(too_far | rising, br_flo, f)
        ex_glo = jnp.where(too_far | rising, br_glo, g)

        # --- stage 1: zoom ---------------------------------------------------------------------
        z_hi_is_a = ~armijo | (f >= s.f_lo)
        flip = ~z_hi_is_a & (g * (s.a_hi - s.a_lo) >= 0)
        z_lo = jnp.where(z_hi_is_a, s.a_lo, a)
        z_flo = jnp.where(z_hi_is_a, s.f_lo, f)
        z_glo = jnp.where(z_hi_is_a, s.g_lo, g)
        z_hi = jnp.where(z_hi_is_a, a, jnp.where(flip, s.a_lo, s.a_hi))
        z_fhi = jnp.where(z_hi_is_a, f, jnp.where(flip, s.f_lo, s.f_hi))
        z_ghi = jnp.where(z_hi_is_a, g, jnp.where(flip, s.g_lo, s.g_hi))

        in_bracket = s.stage == 0
        in_zoom = s.stage == 1
        in_back = s.stage == 2
        new_lo = jnp.where(in_bracket, ex_lo, jnp.where(in_zoom, z_lo, s.a_lo))
        new_flo = jnp.where(in_bracket, ex_flo, jnp.where(in_zoom, z_flo, s.f_lo))
        new_glo = jnp.where(in_bracket, ex_glo, jnp.where(in_zoom, z_glo, s.g_lo))
        new_hi = jnp.where(in_bracket, br_hi, jnp.where(in_zoom, z_hi, s.a_hi))
        new_fhi = jnp.where(in_bracket, br_fhi, jnp.where(in_zoom, z_fhi, s.f_hi))
        new_ghi = jnp.where(in_bracket, br_ghi, jnp.where(in_zoom, z_ghi, s.g_hi))

        goes_zoom = in_bracket & (too_far | rising)
        zooming = in_zoom | goes_zoom
        next_zoom = _cubic_min(new_lo, new_flo, new_glo, new_hi, new_fhi, new_ghi)
        collapsed = jnp.abs(new_hi - new_lo) <= 1e-14 * jnp.maximum(jnp.abs(new_hi), jnp.abs(new_lo))
        next_bracket = jnp.minimum(extrapolation * a, max_step)
        next_back = backtrack_factor * a_min_tried

        # --- decisions ---------------------------------------------------------------------------
        done_accept = accept & ~in_back
        done_max = in_bracket & at_max & ~accept  # Armijo holds at max_step, curvature does not
        done_back = in_back & armijo
        have_lo = new_lo > 0  # an Armijo point with decrease exists
        out_of_evals = n_evals >= max_evals
        stop_zoom = zooming & ~done_accept & (out_of_evals | collapsed)
        # fallback: the best Armijo point (lo) if there is one, else backtracking
        fallback_lo = stop_zoom & have_lo
        to_back = (stop_zoom & ~have_lo) | (in_bracket & out_of_evals & ~done_accept & ~done_max & ~goes_zoom)
        back_exhausted = in_back & ~armijo & (n_evals >= max_evals + max_backtrack)

        out_a = jnp.where(done_accept | done_max | done_back, a, jnp.where(fallback_lo, new_lo, s.out_a))
        out_f = jnp.where(done_accept | done_max | done_back, f, jnp.where(fallback_lo, new_flo, s.out_f))
        out_g = jnp.where(done_accept | done_max | done_back, g, jnp.where(fallback_lo, new_glo, s.out_g))
        out_status = jnp.where(
            done_accept,
            code,
            jnp.where(done_max | done_back | fallback_lo, LineSearchStatus.ARMIJO, s.out_status),
        ).astype(jnp.int32)
        finished = done_accept | done_max | done_back | fallback_lo | back_exhausted
        stage = jnp.where(
            finished, 3,
            jnp.where(to_back | in_back, 2, jnp.where(zooming, 1, 0)),
        )
        next_a = jnp.where(stage == 2, jnp.where(to_back, backtrack_factor * a_min_tried, next_back),
                           jnp.where(stage == 1, next_zoom, next_bracket))
        return _State(
            stage=stage.astype(jnp.int32), a=next_a,
            a_lo=new_lo, f_lo=new_flo, g_lo=new_glo,
            a_hi=new_hi, f_hi=new_fhi, g_hi=new_ghi,
            a_min_tried=a_min_tried, n_evals=n_evals,
            out_a=out_a, out_f=out_f, out_g=out_g, out_status=out_status,
        )

    s = jax.lax.while_loop(cond, body, init)
    step = s.out_a
    ok = s.out_status <= LineSearchStatus.ARMIJO
    armijo = ok & (s.out_f <= phi0 + c1 * step * dphi0)
    curvature = ok & (jnp.abs(s.out_g) <= c2 * jnp.abs(dphi0))
    return LineSearchResult(
        step=jnp.where(ok, step, zero),
        value=jnp.where(ok, s.out_f, phi0),
        slope=jnp.where(ok, s.out_g, dphi0),
        status=s.out_status,
        armijo=armijo,
        curvature=curvature,
        n_evals=s.n_evals,
    )
