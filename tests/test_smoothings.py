"""Tests for objectives.energy.smoothings: thesis Table 6.1, Def. 6.5.1, docs/maths.md §4 and note 5–6."""

import functools

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from objectives import smoothings as S  # noqa: E402

NAMES = [f"f{i}" for i in range(10)]
C1_EXPECTED = {"f3", "f6", "f7", "f8"}  # Table 6.1 analysis (docs/maths.md §4)


# ---------------------------------------------------------------------------
# independent references: the printed Table 6.1 formulas (numpy, naive forms)
# ---------------------------------------------------------------------------


def ref_value(name, x, eps, delta):
    """Table 6.1 f(x) as printed (f7 outer branch per docs/maths.md note 5), naive numpy."""
    x = np.asarray(x, dtype=np.float64)
    a = np.abs(x)
    if name == "f0":
        return a
    if name == "f1":
        return a + eps / (1 + a) - eps
    if name == "f2":
        return a - eps / (2 * (1 + a)) - eps * np.log(eps + a) + eps / 2 + eps * np.log(eps)
    if name == "f3":
        return a - eps * np.log(eps + a) + eps * np.log(eps)
    if name == "f4":
        return a + eps * np.exp(-a) - eps
    if name == "f5":
        return a + eps * np.exp(-eps * a) - eps
    if name == "f6":
        return np.where(a <= delta, x**2 / (2 * delta), a - delta / 2)
    if name == "f7":

        def inner(t):
            return (eps + delta) / delta * (t + eps * np.log(eps / (eps + t)))

        return np.where(a <= delta, inner(a), a - delta + inner(delta))
    if name == "f8":  # naive where cosh is finite; beyond, e^{-2|x|/ε} underflows anyway
        z = np.minimum(a / eps, 700.0)
        return np.where(a / eps < 700.0, eps * np.log(np.cosh(z)), a - eps * np.log(2.0))
    if name == "f9":
        return a - delta * eps * np.log(eps + a) + delta * eps * np.log(eps)
    raise KeyError(name)


def ref_derivative(name, x, eps, delta):
    """Table 6.1 ∂f/∂x as printed (sgn(0) = 0), numpy."""
    x = np.asarray(x, dtype=np.float64)
    a, sg = np.abs(x), np.sign(x)
    if name == "f0":
        return sg
    if name == "f1":
        return sg - eps * sg / (1 + a) ** 2
    if name == "f2":
        return sg + eps * sg / (2 * (1 + a) ** 2) - eps * sg / (eps + a)
    if name == "f3":
        return sg - eps * sg / (eps + a)
    if name == "f4":
        return sg - eps * sg * np.exp(-a)
    if name == "f5":
        return sg - eps**2 * sg * np.exp(-eps * a)
    if name == "f6":
        return np.where(a <= delta, x / delta, sg)
    if name == "f7":
        return np.where(a <= delta, (eps + delta) / delta * (sg - eps * sg / (eps + a)), sg)
    if name == "f8":
        return np.tanh(x / eps)
    if name == "f9":
        return sg - delta * eps * sg / (eps + a)
    raise KeyError(name)


@functools.lru_cache(maxsize=None)
def _jitted(name):
    fn = S.info(name).fn
    return jax.jit(fn), jax.jit(jax.vmap(jax.grad(fn), in_axes=(0, None, None)))


def value(name, x, eps, delta):
    """f(x) elementwise, jitted with ε, δ traced (one compilation per name and shape)."""
    return _jitted(name)[0](jnp.asarray(x), eps, delta)


def grad(name, x, eps, delta):
    """jax.grad of f at each entry of the 1-D array x."""
    return _jitted(name)[1](jnp.asarray(x), eps, delta)


GRID = np.concatenate(
    [
        np.linspace(-3.0, 3.0, 601),
        np.logspace(-12, 3, 61),
        -np.logspace(-12, 3, 61),
        [1e-3, -1e-3, 5e-4, -5e-4, 2e-3, -2e-3, 0.0],
    ]
)
PARAMS = [(1e-3, 1e-3), (2e-3, 5e-4), (3e-4, 4e-3), (0.1, 0.05)]


# ---------------------------------------------------------------------------
# registry and metadata
# ---------------------------------------------------------------------------


def test_registry_names_aliases_and_errors():
    assert S.NAMES == tuple(NAMES)
    for alias, target in [("abs", "f0"), ("huber", "f6"), ("logcosh", "f8"), ("log", "f3"), ("F3", "f3")]:
        assert S.info(alias).name == target
    x = jnp.linspace(-1, 1, 11)
    np.testing.assert_array_equal(S.get("huber", 1e-3, 0.2)(x), S.f6(x, 1e-3, 0.2))
    with pytest.raises(ValueError, match="unknown smoothing"):
        S.get("f10")
    with pytest.raises(ValueError, match="eps"):
        S.get("f3", eps=0.0)
    with pytest.raises(ValueError, match="delta"):
        S.get("f6", delta=-1.0)
    with pytest.raises(Exception):
        S.info("f3").c1_at_zero = False  # frozen


@pytest.mark.parametrize("name", NAMES)
def test_c1_metadata_matches_one_sided_derivatives(name):
    """Left and right derivative limits at 0 agree iff info(name).c1_at_zero."""
    eps, delta = 1e-3, 2e-3
    h = 1e-10
    f_plus, f_zero, f_minus = np.asarray(value(name, [h, 0.0, -h], eps, delta))
    right_fd = (f_plus - f_zero) / h
    left_fd = (f_zero - f_minus) / h
    right_ad, left_ad = np.asarray(grad(name, [1e-12, -1e-12], eps, delta))
    c1_fd = abs(right_fd - left_fd) < 1e-5
    c1_ad = abs(right_ad - left_ad) < 1e-5
    assert c1_fd == c1_ad == S.info(name).c1_at_zero == (name in C1_EXPECTED)
    if not S.info(name).c1_at_zero:  # a genuine kink: slopes ±s with s > 0
        assert right_fd > 1e-4 and left_fd < -1e-4


@pytest.mark.parametrize("name", sorted(C1_EXPECTED))
def test_second_derivative_at_zero(name):
    """The C¹ smoothings are C² at 0; jax.hessian(0) equals a finite-difference f''(0)."""
    eps, delta = 1e-3, 4e-3
    expected = {"f3": 1 / eps, "f6": 1 / delta, "f7": (eps + delta) / (eps * delta), "f8": 1 / eps}[name]
    h = 1e-7
    f_plus, f_zero, f_minus = np.asarray(value(name, [h, 0.0, -h], eps, delta))
    fd = (f_plus - 2 * f_zero + f_minus) / h**2
    np.testing.assert_allclose(fd, expected, rtol=1e-3)
    second = jax.jit(jax.vmap(jax.grad(jax.grad(S.info(name).fn)), in_axes=(0, None, None)))
    np.testing.assert_allclose(np.asarray(second(jnp.zeros(1), eps, delta)), [expected], rtol=1e-10)


# ---------------------------------------------------------------------------
# Def. 6.5.1: f(0) = 0, f → |x|, f' → sgn x
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", NAMES)
def test_zero_at_zero(name):
    for eps, delta in PARAMS + [(1e-12, 1e-12), (1.0, 1.0)]:
        assert float(value(name, [0.0], eps, delta)[0]) == 0.0
        assert float(grad(name, [0.0], eps, delta)[0]) == 0.0  # sgn(0) = 0 convention
    assert float(S.get(name)(0.0)) == 0.0  # the public path, eagerly


@pytest.mark.parametrize("name", NAMES)
def test_converges_to_abs(name):
    x = jnp.asarray(np.linspace(-2.0, 2.0, 2001))
    errs = []
    for eps in [1e-2, 1e-3, 1e-4, 1e-5]:
        delta = eps if name in ("f6", "f7") else 1e-3
        errs.append(float(jnp.max(jnp.abs(value(name, x, eps, delta) - jnp.abs(x)))))
    errs = np.array(errs)
    assert errs[-1] < 2e-4, errs
    if name == "f0":
        assert np.all(errs == 0.0)
    else:
        assert np.all(np.diff(errs) < 0), errs


@pytest.mark.parametrize("name", NAMES)
def test_derivative_converges_to_sign(name):
    x = np.concatenate([np.linspace(-2.0, -0.05, 300), np.linspace(0.05, 2.0, 300)])
    errs = []
    for eps in [1e-2, 1e-3, 1e-4, 1e-5]:
        delta = eps if name in ("f6", "f7") else 1e-3
        g = grad(name, x, eps, delta)
        errs.append(float(np.max(np.abs(np.asarray(g) - np.sign(x)))))
    errs = np.array(errs)
    assert errs[-1] < 1e-3, errs
    assert np.all(np.diff(errs) <= 0), errs


# ---------------------------------------------------------------------------
# agreement with the printed Table 6.1
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("eps,delta", PARAMS)
@pytest.mark.parametrize("name", NAMES)
def test_value_matches_table(name, eps, delta):
    x = GRID[np.abs(GRID) <= 3.0]  # where the naive printed forms are accurate
    got = np.asarray(value(name, x, eps, delta))
    np.testing.assert_allclose(got, ref_value(name, x, eps, delta), rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize("eps,delta", PARAMS)
@pytest.mark.parametrize("name", NAMES)
def test_grad_matches_table_derivative(name, eps, delta):
    got = np.asarray(grad(name, GRID, eps, delta))
    np.testing.assert_allclose(got, ref_derivative(name, GRID, eps, delta), rtol=1e-11, atol=1e-14)


# ---------------------------------------------------------------------------
# robustness: extreme inputs, docs/maths.md note 5 and 6
# ---------------------------------------------------------------------------

EXTREME64 = [0.0, 1e-300, -1e-300, 1e10, -1e10, 1e300, -1e300, 1.7e308, -1.7e308, 5e-324]


@pytest.mark.parametrize("name", NAMES)
def test_finite_at_extremes_float64(name):
    x = jnp.asarray(EXTREME64, dtype=jnp.float64)
    for eps, delta in [(1e-3, 1e-3), (1e-8, 1e-6), (0.5, 0.5)]:
        v, g = value(name, x, eps, delta), grad(name, x, eps, delta)
        assert v.dtype == jnp.float64
        assert bool(jnp.all(jnp.isfinite(v))) and bool(jnp.all(jnp.isfinite(g))), (eps, delta, v, g)
        # far from 0 the smoothing is |x| up to a bounded shift, the slope sgn x
        big = np.abs(np.asarray(x)) >= 1e10
        # |f(x) − |x|| ≤ ε log(1 + |x|/ε) + ε: relative 1e-8 at |x| = 1e10, ε = 0.5
        np.testing.assert_allclose(np.asarray(v)[big], np.abs(np.asarray(x)[big]), rtol=1e-8)
        np.testing.assert_allclose(np.asarray(g)[big], np.sign(np.asarray(x)[big]), rtol=1e-9)


@pytest.mark.parametrize("name", NAMES)
def test_finite_at_extremes_float32(name):
    x = jnp.asarray([1e10, -1e10, 0.0, 1e-30, 3e38], dtype=jnp.float32)
    v, g = value(name, x, 1e-3, 1e-3), grad(name, x, 1e-3, 1e-3)
    assert v.dtype == jnp.float32 and g.dtype == jnp.float32
    assert bool(jnp.all(jnp.isfinite(v))) and bool(jnp.all(jnp.isfinite(g))), (v, g)
    np.testing.assert_allclose(np.asarray(v[:2]), [1e10, 1e10], rtol=1e-6)
    np.testing.assert_allclose(np.asarray(g[:2]), [1.0, -1.0], rtol=1e-6)


@pytest.mark.parametrize("eps,delta", [(1e-3, 5e-3), (5e-3, 1e-3), (1e-3, 1e-3), (0.2, 0.01)])
def test_f7_continuous_at_delta(eps, delta):
    """docs/maths.md note 5: f7 is continuous (and C¹) at |x| = δ for every ε, δ."""
    h = 1e-9 * delta
    for sgn in (1.0, -1.0):
        lo, hi = sgn * (delta - h), sgn * (delta + h)
        assert abs(float(S.f7(hi, eps, delta) - S.f7(lo, eps, delta))) < 3 * h
        assert abs(float(jax.grad(S.f7)(hi, eps, delta) - jax.grad(S.f7)(lo, eps, delta))) < 1e-6
    # the thesis's printed outer constant jumps unless ε = δ (so this test can tell them apart)
    inner = (eps + delta) / delta * (delta + eps * np.log(eps / (eps + delta)))
    printed = delta + eps * (1 + (eps + delta) / delta * np.log(delta / (eps + delta)))
    assert (abs(printed - inner) > 1e-6 * delta) == (eps != delta)


def test_f8_matches_naive_logcosh_and_survives_overflow():
    eps = 1e-3
    x = np.linspace(-0.6, 0.6, 4001)  # |x|/ε ≤ 600 < 710: naive cosh finite
    naive = eps * np.log(np.cosh(x / eps))
    np.testing.assert_allclose(np.asarray(S.f8(jnp.asarray(x), eps)), naive, rtol=1e-12, atol=1e-16)
    with np.errstate(over="ignore"):
        assert np.isinf(eps * np.log(np.cosh(1.0 / eps)))  # Fig. 6.9: the naive form overflows
    np.testing.assert_allclose(float(S.f8(1.0, eps)), 1.0 - eps * np.log(2.0), rtol=1e-15)
    # the switch between the near-zero and far forms is seamless
    s = 30 * eps
    for t in (s * (1 - 1e-12), s * (1 + 1e-12)):
        np.testing.assert_allclose(float(S.f8(t, eps)), eps * np.log(np.cosh(t / eps)), rtol=1e-14)


# ---------------------------------------------------------------------------
# purity / tracing, and structural properties
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", NAMES)
def test_jit_with_traced_parameters(name):
    x = jnp.linspace(-0.02, 0.02, 41)
    fn = S.info(name).fn
    jitted = jax.jit(jax.vmap(fn, in_axes=(None, 0, 0)))
    eps = jnp.asarray([1e-3, 3e-3, 1e-2])
    delta = jnp.asarray([2e-3, 1e-3, 5e-3])
    out = jitted(x, eps, delta)
    for i in range(3):
        np.testing.assert_allclose(out[i], fn(x, float(eps[i]), float(delta[i])), rtol=1e-13, atol=1e-18)


finite_x = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False, allow_infinity=False)
param = st.floats(min_value=1e-6, max_value=1.0)


@jax.jit
def _all_values(x, eps, delta):
    return jnp.stack([S.info(n).fn(x, eps, delta) for n in NAMES])


@settings(max_examples=60, deadline=None)
@given(xs=st.lists(finite_x, min_size=16, max_size=16), eps=param, delta=param)
def test_bounds_and_symmetry_property(xs, eps, delta):
    """For ε, δ ∈ (0, 1]: 0 ≤ f(x) ≤ |x| and f is even (each Table 6.1 entry)."""
    x = jnp.asarray(xs, dtype=jnp.float64)
    a = np.abs(np.asarray(x))
    v = np.asarray(_all_values(x, eps, delta))
    v_neg = np.asarray(_all_values(-x, eps, delta))
    tol = 1e-12 * (1 + a)
    for name, vi, vi_neg in zip(NAMES, v, v_neg):
        assert np.all(vi >= -tol), (name, vi)
        assert np.all(vi <= a + tol), (name, vi - a)
        np.testing.assert_allclose(vi_neg, vi, rtol=1e-14, atol=1e-300)


@pytest.mark.parametrize("name", ["f2", "f3", "f7", "f9", "f8", "f6"])
def test_parameter_derivatives_match_finite_differences(name):
    """∂f/∂ε and ∂f/∂δ by jax.grad (through the custom JVP) equal central differences."""
    x = jnp.asarray([-0.7, -2e-3, -4e-4, 3e-4, 1.5e-3, 0.02, 1.3])
    eps, delta = 1e-3, 2e-3
    fn = S.info(name).fn
    d_eps, d_delta = jax.jit(jax.vmap(jax.grad(fn, argnums=(1, 2)), in_axes=(0, None, None)))(x, eps, delta)
    h = 1e-8
    fd_eps = (value(name, x, eps + h, delta) - value(name, x, eps - h, delta)) / (2 * h)
    fd_delta = (value(name, x, eps, delta + h) - value(name, x, eps, delta - h)) / (2 * h)
    np.testing.assert_allclose(np.asarray(d_eps), np.asarray(fd_eps), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(np.asarray(d_delta), np.asarray(fd_delta), rtol=1e-5, atol=1e-7)
