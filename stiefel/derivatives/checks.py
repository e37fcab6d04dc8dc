"""Slope tests for gradients, Hessians and retractions (after Manopt's ``checkgradient``,
``checkhessian`` and ``checkretraction``; docs/maths.md §9, eq. (9.14)).

Along a curve ``γ(t)`` from ``X`` with ``γ'(0) = d`` (unit tangent), each check measures the error of a
Taylor model over several decades of ``t`` and fits the slope of ``log error`` against ``log t``:

* ``check_gradient``: ``|F(R_X(td)) − F(X) − t⟨grad F, d⟩|`` — slope ≥ 2 when the gradient is right (a wrong
  one leaves an O(t) error: slope 1; 3 where the curve's second-order term vanishes).
* ``check_hessian``: ``|F(γ(t)) − F(X) − t⟨grad F, d⟩ − ½t²⟨Hess F[d], d⟩|`` along the geodesic
  ``γ(t) = Exp_X(td)`` (``curve="retraction"`` uses ``R_X``: valid for second-order retractions such as
  ``"polar"``, or at critical points) — slope ≥ 3 (a wrong Hessian leaves an O(t²) error: slope 2; at a
  critical point of a quadratic the cubic term can vanish: slope 4, measured on the README's Brockett cost);
  plus the symmetry ``⟨Hess[a], b⟩ = ⟨a, Hess[b]⟩``,
  linearity and tangency of the Hessian.
* ``check_retraction``: ``‖R_X(td) − Exp_X(td)‖_M`` — slope ≥ 2 for a retraction (first order), 3 for a
  second-order one.

The slope is fitted on the longest run of consecutive steps where the log-log curve is a straight line
(residual ≤ 0.1 decade) and the error lies above round-off; errors at round-off everywhere mean the model
is exact along that curve (``exact``, passed). A non-differentiable or non-finite objective yields a
failed check with its slope, never an exception. ``SlopeCheck.plot()`` draws the log-log picture.
On a ``stiefel.Product``, ``X`` and the directions are tuples of arrays.
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..manifolds import tangent_algebra as ta
from .hessian import call, riemannian_hessian
from ..manifolds.manifold import GeneralizedStiefel
from ..manifolds.product import Product

Manifold = GeneralizedStiefel | Product

__all__ = ["SlopeCheck", "check_gradient", "check_hessian", "check_retraction", "fit_slope"]

STEPS = np.logspace(-8, 0, 51)
SLOPE_TOL = 0.15  # |fitted − expected| allowed
LINE_TOL = 0.1  # decades: the largest residual of a window's straight-line fit
MIN_WINDOW = 6  # points (≈ 1 decade of the default 51 over 8 decades)


@dataclasses.dataclass(frozen=True)
class SlopeCheck:
    """Outcome of a slope test (module docstring).

    Attributes:
      what: ``"gradient"``, ``"hessian"`` or ``"retraction"``; steps, errors: ``t`` and the model errors.
      slope: the fitted slope (NaN when ``exact`` or nothing could be fitted); expected: the slope a correct
        model gives; window: ``(first, last)`` indices of the fitted run (None when none).
      exact: every finite error is at round-off; passed: the verdict; details: further measured numbers
        (tangency, symmetry, ...); message: one line for people.
    """

    what: str
    steps: np.ndarray
    errors: np.ndarray
    slope: float
    expected: float
    window: tuple[int, int] | None
    exact: bool
    passed: bool
    details: dict
    message: str

    def __str__(self) -> str:
        return self.message

    def plot(self, ax=None, path: str | os.PathLike | None = None):
        """Log-log plot of the errors with the fitted window and a reference line of the expected slope;
        returns the matplotlib axes; ``path``: also save the figure there (atomically)."""
        import matplotlib  # noqa: PLC0415 — optional, only for the picture

        if ax is None:
            if path is not None:
                matplotlib.use("Agg", force=False)
            import matplotlib.pyplot as plt  # noqa: PLC0415

            _, ax = plt.subplots(figsize=(5, 4))
        good = np.isfinite(self.errors) & (self.errors > 0)
        ax.loglog(self.steps[good], self.errors[good], ".-", label="model error")
        if self.window is not None:
            i, j = self.window
            t = self.steps[i:j + 1]
            ref = self.errors[i] * (t / t[0]) ** self.expected
            ax.loglog(t, ref, "--", label=f"slope {self.expected:g} (expected)")
            ax.loglog(t, self.errors[i:j + 1], "o", mfc="none", label=f"fitted {self.slope:.2f}")
        ax.set_xlabel("t")
        ax.set_ylabel("error")
        ax.set_title(f"{self.what}: {'passed' if self.passed else 'FAILED'}")
        ax.legend()
        if path is not None:
            path = os.fspath(path)
            fd, tmp = tempfile.mkstemp(dir=os.path.dirname(os.path.abspath(path)) or ".", suffix=".png")
            os.close(fd)
            try:
                ax.figure.savefig(tmp, dpi=120)
                os.replace(tmp, path)
            except BaseException:
                os.unlink(tmp)
                raise
        return ax


def fit_slope(steps, errors, floor: float) -> tuple[float, tuple[int, int] | None, bool]:
    """``(slope, window, exact)``: the least-squares slope of log error over log t on the longest run of
    consecutive points above ``floor`` that a straight line fits to ``LINE_TOL`` decades."""
    steps, errors = np.asarray(steps, float), np.asarray(errors, float)
    finite = np.isfinite(errors)
    usable = finite & (errors > floor)
    if finite.any() and not usable.any():
        return float("nan"), None, True
    lt, le = np.log10(steps), np.log10(np.where(usable, errors, 1.0))
    n = len(steps)
    for length in range(n, MIN_WINDOW - 1, -1):
        best = None
        for i in range(0, n - length + 1):
            j = i + length
            if not usable[i:j].all():
                continue
            p = np.polyfit(lt[i:j], le[i:j], 1)
            worst = np.max(np.abs(np.polyval(p, lt[i:j]) - le[i:j]))
            if worst <= LINE_TOL and (best is None or worst < best[0]):
                best = (worst, float(p[0]), (i, j - 1))
        if best is not None:
            return best[1], best[2], False
    return float("nan"), None, False


def _call(fn: Callable, args: Any, X):
    return call(fn, X, args)


# Compiled pieces, keyed on (fn, manifold) structure: an objective that is a pytree (e.g. an
# ``objectives.CMMEnergy``) compiles once per shape whatever its parameters.
@eqx.filter_jit
def _along(fn, args, manifold, X, d, ts, use_exp: bool):
    move = manifold.exp if use_exp else manifold.retract
    return jax.vmap(lambda t: _call(fn, args, move(X, ta.tmap(lambda v: t * v, d))))(ts)


@eqx.filter_jit
def _value_and_rgrad(fn, args, egrad, manifold, X):
    value, G = jax.value_and_grad(lambda Y: _call(fn, args, Y))(X)
    if egrad is not None:
        G = _call(egrad, args, X)
    return value, manifold.egrad_to_rgrad(X, G)


@eqx.filter_jit
def _hess_apply(fn, args, hess, manifold, X, V):
    if hess is None:
        return riemannian_hessian(fn, manifold, X, V, args)
    return hess(X, V, args) if args is not None else hess(X, V)


def _direction(manifold: Manifold, X, direction, key):
    if direction is None:
        key = jax.random.fold_in(jax.random.PRNGKey(0) if key is None else key, 7)
        return manifold.random_tangent(key, X)
    if isinstance(manifold, Product):
        manifold.check_shape(direction, name="direction")
    d = manifold.proj(X, ta.tmap(lambda x, v: jnp.asarray(v, x.dtype), X, direction))
    size = manifold.norm(X, d)
    return ta.tmap(lambda v: v / size, d)


def _verdict(what, steps, errors, floor, expected, details, *, at_least=False) -> SlopeCheck:
    slope, window, exact = fit_slope(steps, errors, floor)
    if exact:
        passed, text = True, "the model is exact to round-off along this curve"
    elif window is None:
        passed = False
        text = ("no straight stretch in the log-log errors" if np.isfinite(errors).any()
                else "non-finite values along the curve")
    else:
        passed = bool(slope >= expected - SLOPE_TOL) if at_least else bool(abs(slope - expected) <= SLOPE_TOL)
        text = f"slope {slope:.3f} ({'≥ ' if at_least else ''}{expected:g} expected) over t ∈ " \
               f"[{steps[window[0]]:.1e}, {steps[window[1]]:.1e}]"
    extra = "; ".join(f"{k} {v:.2e}" for k, v in details.items() if isinstance(v, float))
    message = f"{what} check {'passed' if passed else 'FAILED'}: {text}" + (f" ({extra})" if extra else "")
    return SlopeCheck(what, np.asarray(steps), np.asarray(errors), float(slope), float(expected), window, exact,
                      passed, details, message)


def _floor(values, dtype) -> float:
    """Round-off level of differences of ``values`` computed in ``dtype``."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    return 1e2 * float(np.finfo(dtype).eps) * max(1.0, float(np.max(np.abs(v))) if v.size else 1.0)


def _checked(manifold: Manifold, X):
    """``X`` unchanged; on a ``Product``, its structure and shapes are checked first (``ShapeError``)."""
    if isinstance(manifold, Product):
        manifold.check_shape(X, name="X")
    return X


def check_gradient(fn: Callable, manifold: Manifold, X, *, args: Any = None,
                   egrad: Callable | None = None, direction=None, key=None, steps=STEPS) -> SlopeCheck:
    """Slope test of the Riemannian gradient of ``fn`` at ``X`` (module docstring).

    Args:
      fn: ``fn(X)`` or ``fn(X, args)`` (optimistix style; called with ``args = None`` when none is given) →
        scalar. egrad: the Euclidean gradient ``∂F/∂X`` to check, with
        the same signature (default ``jax.grad(fn)``: then this checks the objective's own derivatives —
        custom JVPs, smoothings — and the manifold's gradient conversion and retraction).
      direction: a tangent (projected and normalised) or None: random from ``key``.
    """
    X = _checked(manifold, X)
    value, g = _value_and_rgrad(fn, args, egrad, manifold, X)
    d = _direction(manifold, X, direction, key)
    f0 = float(value)
    slope = float(manifold.inner(X, g, d))
    dt = ta.dtype_of(X)
    values = np.asarray(_along(fn, args, manifold, X, d, jnp.asarray(steps, dt), False), float)
    errors = np.abs(values - f0 - steps * slope)
    gnorm = float(manifold.norm(X, g))
    details = {"tangent_error": float(manifold.norm(X, ta.tmap(jnp.subtract, g, manifold.proj(X, g))))
               / max(gnorm, 1e-300), "grad_norm": gnorm}
    return _verdict("gradient", steps, errors, _floor(np.r_[f0, values], dt), 2.0, details, at_least=True)


def check_hessian(fn: Callable, manifold: Manifold, X, *, args: Any = None, hess: Callable | None = None,
                  direction=None, key=None, steps=STEPS, curve: str = "exp") -> SlopeCheck:
    """Slope test of the Riemannian Hessian of ``fn`` at ``X`` (module docstring).

    ``hess(X, ξ)`` (or ``hess(X, ξ, args)``): the Riemannian Hessian to check (default
    ``stiefel.riemannian_hessian``, i.e. autodiff). ``curve``: ``"exp"`` (the geodesic; exact second-order
    model for any point) or ``"retraction"``. ``details``: ``symmetry_error`` (relative),
    ``linearity_error``, ``tangent_error``.
    """
    if curve not in ("exp", "retraction"):
        raise ValueError(f"curve must be 'exp' or 'retraction', got {curve!r}")
    X = _checked(manifold, X)
    H = lambda Y, v: _hess_apply(fn, args, hess, manifold, Y, v)  # noqa: E731
    d = _direction(manifold, X, direction, key)
    value, g = _value_and_rgrad(fn, args, None, manifold, X)
    Hd = H(X, d)
    f0 = float(value)
    a1, a2 = float(manifold.inner(X, g, d)), float(manifold.inner(X, Hd, d))
    dt = ta.dtype_of(X)
    values = np.asarray(_along(fn, args, manifold, X, d, jnp.asarray(steps, dt), curve == "exp"), float)
    errors = np.abs(values - f0 - steps * a1 - 0.5 * steps ** 2 * a2)
    # symmetry, linearity, tangency with a second random direction
    e = _direction(manifold, X, None, jax.random.fold_in(jax.random.PRNGKey(0) if key is None else key, 11))
    He = H(X, e)
    scale = max(float(manifold.norm(X, Hd)), float(manifold.norm(X, He)), 1e-300)
    lin = ta.tmap(lambda a, b: a - b, H(X, ta.tmap(lambda a, b: 2.0 * a - 3.0 * b, d, e)),
                  ta.tmap(lambda a, b: 2.0 * a - 3.0 * b, Hd, He))
    details = {"symmetry_error": abs(float(manifold.inner(X, Hd, e)) - float(manifold.inner(X, d, He))) / scale,
               "linearity_error": float(manifold.norm(X, lin)) / scale,
               "tangent_error": float(manifold.norm(X, ta.tmap(jnp.subtract, Hd, manifold.proj(X, Hd)))) / scale}
    return _verdict("hessian", steps, errors, _floor(np.r_[f0, values], dt), 3.0, details, at_least=True)


@eqx.filter_jit
def _retraction_gap(manifold, X, d, ts):
    def gap(t):
        td = ta.tmap(lambda v: t * v, d)
        diff = ta.tmap(jnp.subtract, manifold.retract(X, td), manifold.exp(X, td))
        return jnp.sqrt(jnp.maximum(ta.inner(diff, manifold.mv(diff)), 0.0))
    return jax.vmap(gap)(ts)


def check_retraction(manifold: Manifold, X, *, direction=None, key=None, steps=STEPS) -> SlopeCheck:
    """Slope test of the manifold's retraction against its exponential map (module docstring): passes for
    slope ≥ 2 (a first-order retraction); ``details["order"]`` is ``slope − 1`` (2 for second order)."""
    X = _checked(manifold, X)
    d = _direction(manifold, X, direction, key)
    dt = ta.dtype_of(X)
    errors = np.asarray(_retraction_gap(manifold, X, d, jnp.asarray(steps, dt)), float)
    far = manifold.retract(X, ta.tmap(lambda v: float(steps[-1]) * v, d))
    details = {"at_zero": float(ta.max_abs(ta.tmap(jnp.subtract, manifold.retract(X, manifold.zero_vector(X)), X))),
               "dist_to_manifold": float(manifold.dist_to_manifold(far))}
    check = _verdict("retraction", steps, errors, _floor([1.0], dt), 2.0, details, at_least=True)
    details["order"] = check.slope - 1.0 if np.isfinite(check.slope) else float("inf")
    tol = 1e4 * float(np.finfo(dt).eps)
    if check.passed and not (details["at_zero"] <= tol and details["dist_to_manifold"] <= tol):
        check = dataclasses.replace(check, passed=False, message=check.message.replace(
            "passed", "FAILED", 1) + " — R_X(0) ≠ X or R_X(td) off the manifold")
    return check
