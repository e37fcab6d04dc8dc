"""Build the HTML API reference with pdoc, and fail on broken references in the docstrings.

    python docs/build_api.py [--out docs/api]

Documents every public module of ``stiefel``, ``objectives``, ``mesh`` and ``stiefel_cmm.cli`` (no part of
the dotted name starts with ``_``); a package page shows what its ``__init__`` exports.
pdoc links the names it can resolve and silently leaves the others as plain code, so this
script checks the references itself: every dotted name in a backticked span of a public
docstring that starts with one of the packages (``stiefel.minimize``,
``objectives.cmm.solvers.BlockCMM``) must resolve by importing its longest module prefix and
getattr'ing the rest. Broken ones are listed as ``file:line: name`` and the script exits 1.

Needs only the working tree and pdoc (no test data, no JAX configuration changes).
"""

from __future__ import annotations

import argparse
import ast
import importlib
import pkgutil
import re
import sys
import time
import warnings
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("stiefel", "objectives", "mesh", "stiefel_cmm.cli")

# Broken references in files their owners are editing right now, as (file, name): tolerated
# until fixed there. Keep this empty otherwise.
KNOWN_BROKEN: frozenset[tuple[str, str]] = frozenset()

_CODE_SPAN = re.compile(r"(`+)(.+?)(?<!`)\1(?!`)", re.S)
_PROJECT_NAME = re.compile(r"(?<![\w./])(?:%s)(?:\.[A-Za-z_]\w*)+" % "|".join(PACKAGES))


@dataclass(frozen=True, order=True)
class Reference:
    """A project name in a backticked span of a docstring, and where it is."""

    file: str
    line: int
    name: str

    def __str__(self) -> str:
        return f"{self.file}:{self.line}: {self.name}"


def public_modules(packages: tuple[str, ...] = PACKAGES) -> list[str]:
    """The packages and all their submodules with no ``_``-prefixed part, sorted."""
    names = []
    for pkg in packages:
        names.append(pkg)
        path = importlib.import_module(pkg).__path__
        names += [m.name for m in pkgutil.walk_packages(path, pkg + ".")
                  if not any(part.startswith("_") for part in m.name.split("."))]
    return sorted(names)


def references_in(text: str, file: str = "<docstring>", first_line: int = 1) -> list[Reference]:
    """The project names in the backticked spans of ``text`` (which starts at ``first_line``)."""
    refs = []
    for span in _CODE_SPAN.finditer(text):
        for m in _PROJECT_NAME.finditer(span.group(2)):
            line = first_line + text.count("\n", 0, span.start(2) + m.start())
            refs.append(Reference(file, line, m.group(0)))
    return refs


def _is_public(name: str) -> bool:
    return not name.startswith("_") or name == "__init__"


def _docstrings(body: list[ast.stmt]) -> list[ast.Constant]:
    """The docstrings pdoc renders for a module or class body: its own, those of its public
    classes and functions (recursively for classes), and attribute docstrings."""
    found = []
    for i, node in enumerate(body):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            prev = body[i - 1] if i else None
            targets = (prev.targets if isinstance(prev, ast.Assign)
                       else [prev.target] if isinstance(prev, ast.AnnAssign) else [])
            if i == 0 or any(isinstance(t, ast.Name) and _is_public(t.id) for t in targets):
                found.append(node.value)
        elif isinstance(node, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and _is_public(node.name):
            found += _docstrings(node.body) if isinstance(node, ast.ClassDef) else _docstrings(node.body[:1])
    return found


def module_references(modname: str) -> list[Reference]:
    """The project references in the public docstrings of one module's source."""
    path = Path(importlib.import_module(modname).__file__ or "")
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    file = str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)
    return [ref for doc in _docstrings(tree.body) for ref in references_in(doc.value, file, doc.lineno)]


def resolves(name: str) -> bool:
    """Whether a dotted name exists and is public: import its longest module prefix, getattr the rest.

    A field declared on a class (dataclass / equinox / annotated, no class attribute) counts, and
    what follows it (attributes of the field's value) is not checked.
    """
    parts = name.split(".")
    if any(p.startswith("_") and not (p.startswith("__") and p.endswith("__")) for p in parts):
        return False  # private: not in the reference
    for i in range(len(parts), 0, -1):
        modname = ".".join(parts[:i])
        try:
            obj: object = importlib.import_module(modname)
            break
        except ModuleNotFoundError as e:  # only "no such module": a failing import is an error
            if not e.name or not (modname == e.name or modname.startswith(e.name + ".")):
                raise
    else:
        return False
    for attr in parts[i:]:
        if hasattr(obj, attr):
            obj = getattr(obj, attr)
        elif isinstance(obj, type) and any(attr in vars(c).get("__annotations__", {}) for c in obj.__mro__):
            return True
        else:
            return False
    return True


def broken_references(modules: list[str]) -> list[Reference]:
    """The references in the modules' public docstrings that do not resolve (minus KNOWN_BROKEN)."""
    refs = sorted({ref for mod in modules for ref in module_references(mod)})
    return [r for r in refs if (r.file, r.name) not in KNOWN_BROKEN and not resolves(r.name)]


def _exports(pkg: ModuleType) -> list[str]:
    """The public names a package's ``__init__`` binds by relative imports (``from .x import y``)."""
    tree = ast.parse(Path(pkg.__file__ or "").read_text(encoding="utf-8"))
    names = [a.asname or a.name for node in tree.body
             if isinstance(node, ast.ImportFrom) and node.level > 0 for a in node.names]
    return [n for n in names if not n.startswith("_") and n != "*"]


def build(out: Path, modules: list[str]) -> list[str]:
    """Render the HTML reference of ``modules`` into ``out`` (a page each, index.html, search.js);
    return pdoc's warnings, the first line of each distinct one."""
    import pdoc.doc
    import pdoc.render

    # pdoc documents a package's re-exported names only when __all__ lists them; a package
    # without __all__ (stiefel) gets, for this process only, the names its __init__ imports.
    shimmed = []
    for name in PACKAGES:
        pkg = importlib.import_module(name)
        if not hasattr(pkg, "__all__"):
            pkg.__all__ = _exports(pkg)  # type: ignore[attr-defined]
            shimmed.append(pkg)
    # No "view source" (highlighting every function would double the build time).
    pdoc.render.configure(docformat="google", show_source=False, footer_text="stiefel-cmm API reference")
    try:
        # pdoc.pdoc() without its module walk, which would drop the submodules that a package's
        # __all__ does not list (mesh, objectives).
        with warnings.catch_warnings(record=True) as caught:
            docs = {name: pdoc.doc.Module.from_name(name) for name in modules}
            for name, module in docs.items():
                page = out / f"{name.replace('.', '/')}.html"
                page.parent.mkdir(parents=True, exist_ok=True)
                page.write_text(pdoc.render.html_module(module, docs), encoding="utf-8")
            (out / "index.html").write_text(pdoc.render.html_index(docs), encoding="utf-8")
            (out / "search.js").write_text(pdoc.render.search_index(docs), encoding="utf-8")
    finally:
        for pkg in shimmed:
            del pkg.__all__
    return list(Counter(str(w.message).splitlines()[0] for w in caught))


def main(argv: list[str] | None = None) -> int:
    """Build into ``--out``, print a short summary; exit status 1 when a reference is broken."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "api", help="output directory (docs/api)")
    args = parser.parse_args(argv)
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))  # document the working tree, installed or not

    start = time.perf_counter()
    modules = public_modules()
    pdoc_warnings = build(args.out, modules)
    broken = broken_references(modules)
    elapsed = time.perf_counter() - start

    # pdoc cannot evaluate the string annotations of NamedTuple constructors (their globals are
    # not the module's): it shows them as written. One line for those, the others in full.
    unevaluated = [m for m in pdoc_warnings if m.startswith("Error parsing type annotation")]
    if unevaluated:
        print(f"pdoc: {len(unevaluated)} annotations shown as written (could not evaluate them)")
    others = [m for m in pdoc_warnings if m not in unevaluated]
    for message in others[:10]:
        print(f"pdoc warning: {message[:200]}")
    if len(others) > 10:
        print(f"... and {len(others) - 10} more pdoc warnings")
    print(f"API reference: {len(modules)} modules in {args.out / 'index.html'} ({elapsed:.1f} s)")
    if broken:
        print(f"{len(broken)} broken references (no such module or attribute):", file=sys.stderr)
        for ref in broken:
            print(f"  {ref}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
