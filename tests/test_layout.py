"""The layout of the code: no import cycles, the layers import downwards only, modules stay small (the
benchmarks' too), and the packages expose the names they exposed before (tests/data/public_api.json)."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("stiefel", "mesh", "objectives", "stiefel_cmm")
SIZE_CHECKED = PACKAGES + ("bench",)  # the size check also covers the benchmarks (not the import rules)
MAX_LINES = 450  # "about 400": a module longer than this is two ideas

# the order of the layers: a module may import only from its own layer or those before it
LAYERS = {
    "stiefel": ["stiefel.errors", "stiefel.validation", "stiefel.result", "stiefel.runtime", "stiefel.linalg",
                "stiefel.manifolds", "stiefel.derivatives", "stiefel.solvers", "stiefel"],
    "objectives": ["objectives.evaluation", "objectives.energy", "objectives.admm", "objectives.cmm",
                   "objectives.bases", "objectives.fmaps", "objectives"],
}
# which top-level packages each may import
ALLOWED = {"stiefel": {"stiefel"}, "mesh": {"mesh", "stiefel"}, "objectives": {"objectives", "stiefel"},
           "stiefel_cmm": set(PACKAGES)}


def _modules(packages: tuple[str, ...] = PACKAGES) -> dict[str, Path]:
    out = {}
    for pkg in packages:
        for f in sorted((ROOT / pkg).rglob("*.py")):
            parts = f.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = f
    return out


MODULES = _modules()


def _imports(name: str, path: Path) -> set[str]:
    """Every module ``name`` imports, at module level or inside a function."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            subs = [f"{target}.{a.name}" for a in node.names if f"{target}.{a.name}" in MODULES]
            found.update(subs or [target])
    return {m for m in found if m.split(".")[0] in PACKAGES}


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _cycles() -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan); a package's ``__init__`` importing its
    own submodules is not a cycle unless a submodule imports the package back."""
    index, low, stack, on, comps, counter = {}, {}, [], set(), [], [0]

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in GRAPH.get(v, ()):
            if w not in GRAPH:
                continue
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                comps.append(sorted(comp))

    for v in GRAPH:
        if v not in index:
            visit(v)
    return comps


def test_no_import_cycles() -> None:
    assert _cycles() == []


def _layer(name: str, layers: list[str]) -> int:
    best = -1
    for i, prefix in enumerate(layers):
        if name == prefix or name.startswith(prefix + "."):
            if best < 0 or len(prefix) > len(layers[best]):
                best = i
    return best


@pytest.mark.parametrize("top", sorted(LAYERS))
def test_layers_import_downwards(top: str) -> None:
    layers = LAYERS[top]
    bad = []
    for name, deps in GRAPH.items():
        if name.split(".")[0] != top or name == top:
            continue
        for dep in deps:
            if dep.split(".")[0] == top and _layer(dep, layers) > _layer(name, layers):
                bad.append(f"{name} -> {dep}")
    assert bad == []


def test_packages_import_only_what_is_below_them() -> None:
    bad = [f"{name} -> {dep}" for name, deps in GRAPH.items() for dep in deps
           if dep.split(".")[0] not in ALLOWED[name.split(".")[0]]]
    assert bad == []


def test_modules_are_small() -> None:
    long = {name: n for name, path in _modules(SIZE_CHECKED).items()
            if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert long == {}


def test_every_package_says_what_it_holds() -> None:
    bare = [name for name, path in MODULES.items() if path.name == "__init__.py" and not ast.get_docstring(
        ast.parse(path.read_text()))]
    assert bare == []


@pytest.mark.parametrize("package", ["stiefel", "objectives", "mesh"])
def test_public_names_kept(package: str) -> None:
    import importlib

    before = set(json.loads((ROOT / "tests" / "data" / "public_api.json").read_text())[package])
    now = {n for n in dir(importlib.import_module(package)) if not n.startswith("_")}
    assert sorted(before - now) == []
