"""Every pymanopt/Manopt name that docs/tutorial.md lists works, with that library's meaning and argument order."""

import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import stiefel
from stiefel.errors import StiefelError

jax.config.update("jax_enable_x64", True)

TUTORIAL = Path(__file__).resolve().parents[1] / "docs" / "tutorial.md"


def listed_names() -> set[str]:
    """The method names of the table's pymanopt and Manopt columns (rows up to ``dim``; the factory rows after)."""
    text = TUTORIAL.read_text()
    table = text[text.index("| pymanopt | Manopt | here"):]
    names = set()
    for line in table.splitlines()[2:]:
        if not line.startswith("|") or "Sphere(n)" in line:
            break
        cells = line.split("|")[1:3]
        for cell in cells:
            names |= {m.split("(")[0] for m in re.findall(r"`([A-Za-z_0-9]+(?:\([^`]*\))?)`", cell)}
    return names


def test_the_table_lists_the_names_this_test_checks():
    assert listed_names() == set(CALLS), "docs/tutorial.md's table and tests/test_names.py disagree"


def _allclose(a, b):
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b)):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-12, atol=1e-12)


K1, K2 = jax.random.PRNGKey(11), jax.random.PRNGKey(12)

# name -> (call with the other library's argument order, what it means here)
CALLS = {
    "projection": (lambda S, X, Y, Z, G, H: S.projection(X, G), lambda S, X, Y, Z, G, H: S.proj(X, G)),
    "to_tangent_space": (lambda S, X, Y, Z, G, H: S.to_tangent_space(X, G), lambda S, X, Y, Z, G, H: S.proj(X, G)),
    "proj": (lambda S, X, Y, Z, G, H: S.proj(X, G), lambda S, X, Y, Z, G, H: S.proj(X, G)),
    "tangent": (lambda S, X, Y, Z, G, H: S.tangent(X, G), lambda S, X, Y, Z, G, H: S.proj(X, G)),
    "inner_product": (lambda S, X, Y, Z, G, H: S.inner_product(X, Z, Z), lambda S, X, Y, Z, G, H: S.inner(X, Z, Z)),
    "inner": (lambda S, X, Y, Z, G, H: S.inner(X, Z, Z), lambda S, X, Y, Z, G, H: S.norm(X, Z) ** 2),
    "norm": (lambda S, X, Y, Z, G, H: S.norm(X, Z), lambda S, X, Y, Z, G, H: jnp.sqrt(S.inner(X, Z, Z))),
    "euclidean_to_riemannian_gradient": (lambda S, X, Y, Z, G, H: S.euclidean_to_riemannian_gradient(X, G),
                                         lambda S, X, Y, Z, G, H: S.egrad_to_rgrad(X, G)),
    "egrad2rgrad": (lambda S, X, Y, Z, G, H: S.egrad2rgrad(X, G), lambda S, X, Y, Z, G, H: S.egrad_to_rgrad(X, G)),
    "euclidean_to_riemannian_hessian": (lambda S, X, Y, Z, G, H: S.euclidean_to_riemannian_hessian(X, G, H, Z),
                                        lambda S, X, Y, Z, G, H: S.ehess_to_rhess(X, G, H, Z)),
    "ehess2rhess": (lambda S, X, Y, Z, G, H: S.ehess2rhess(X, G, H, Z),
                    lambda S, X, Y, Z, G, H: S.ehess_to_rhess(X, G, H, Z)),
    "retraction": (lambda S, X, Y, Z, G, H: S.retraction(X, Z), lambda S, X, Y, Z, G, H: S.retract(X, Z)),
    "retr": (lambda S, X, Y, Z, G, H: S.retr(X, Z, 0.5),
             lambda S, X, Y, Z, G, H: S.retract(X, jax.tree_util.tree_map(lambda z: 0.5 * z, Z))),
    "exp": (lambda S, X, Y, Z, G, H: S.exp(X, Z), lambda S, X, Y, Z, G, H: S.exp(X, Z)),
    "log": (lambda S, X, Y, Z, G, H: S.log(X, S.exp(X, Z)), lambda S, X, Y, Z, G, H: Z),
    "dist": (lambda S, X, Y, Z, G, H: S.dist(X, S.exp(X, Z)), lambda S, X, Y, Z, G, H: S.norm(X, Z)),
    "transport": (lambda S, X, Y, Z, G, H: S.transport(X, Y, Z), lambda S, X, Y, Z, G, H: S.proj(Y, Z)),
    "transp": (lambda S, X, Y, Z, G, H: S.transp(X, Y, Z), lambda S, X, Y, Z, G, H: S.proj(Y, Z)),
    "zero_vector": (lambda S, X, Y, Z, G, H: S.zero_vector(X),
                    lambda S, X, Y, Z, G, H: jax.tree_util.tree_map(jnp.zeros_like, X)),
    "zerovec": (lambda S, X, Y, Z, G, H: S.zerovec(X), lambda S, X, Y, Z, G, H: S.zero_vector(X)),
    "random_tangent_vector": (lambda S, X, Y, Z, G, H: S.random_tangent_vector(K1, X),
                              lambda S, X, Y, Z, G, H: S.random_tangent(K1, X)),
    "randvec": (lambda S, X, Y, Z, G, H: S.randvec(K1, X), lambda S, X, Y, Z, G, H: S.random_tangent(K1, X)),
    "random_point": (lambda S, X, Y, Z, G, H: S.random_point(K2), lambda S, X, Y, Z, G, H: S.rand(K2)),
    "rand": (lambda S, X, Y, Z, G, H: S.rand(K2), lambda S, X, Y, Z, G, H: S.random_point(K2)),
    "dim": (lambda S, X, Y, Z, G, H: S.dim, lambda S, X, Y, Z, G, H: S.dim),
    "typical_dist": (lambda S, X, Y, Z, G, H: S.typical_dist, lambda S, X, Y, Z, G, H: S.typicaldist),
    "typicaldist": (lambda S, X, Y, Z, G, H: S.typicaldist, lambda S, X, Y, Z, G, H: S.typical_dist),
}

MANIFOLDS = {
    "stiefel": lambda: stiefel.GeneralizedStiefel(jnp.linspace(1.0, 3.0, 12), 3),
    "grassmann": lambda: stiefel.Grassmann(jnp.linspace(1.0, 2.0, 10), 2),
    "product": lambda: stiefel.Product(stiefel.GeneralizedStiefel(jnp.linspace(1.0, 3.0, 8), 2), stiefel.sphere(5)),
}


@pytest.mark.slow
@pytest.mark.parametrize("which", list(MANIFOLDS))
def test_every_listed_name_means_what_it_says(which):
    S = MANIFOLDS[which]()
    X = S.random_point(jax.random.PRNGKey(0))
    Y = S.random_point(jax.random.PRNGKey(1))
    Z = jax.tree_util.tree_map(lambda z: 0.3 * z, S.random_tangent(jax.random.PRNGKey(2), X))
    G = jax.tree_util.tree_map(lambda x: jax.random.normal(jax.random.PRNGKey(3), x.shape), X)
    H = jax.tree_util.tree_map(lambda x: jax.random.normal(jax.random.PRNGKey(4), x.shape), X)
    for name, (call, meaning) in CALLS.items():
        try:
            _allclose(call(S, X, Y, Z, G, H), meaning(S, X, Y, Z, G, H))
        except Exception as e:  # noqa: BLE001 — name the alias that failed
            raise AssertionError(f"{which}: {name}: {type(e).__name__}: {e}") from e
    assert S.retraction_name if which != "product" else True  # the constructor's choice keeps a name


def test_keys_come_first_and_the_other_order_is_named():
    S = MANIFOLDS["stiefel"]()
    X = S.random_point(jax.random.PRNGKey(0))
    for name in ("random_tangent_vector", "randvec"):
        with pytest.raises(StiefelError, match=r"takes \(key, X\)"):
            getattr(S, name)(X, jax.random.PRNGKey(1))
    Z = S.random_tangent_vector(jax.random.key(3), X)  # typed keys too
    assert float(jnp.max(jnp.abs(S.proj(X, Z) - Z))) < 1e-12
    with pytest.raises(StiefelError, match="3 arguments|4 arguments"):
        S.transport(X, X, Z, Z)
