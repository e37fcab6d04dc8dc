"""The API reference (docs/build_api.py): it builds, has the key pages, and no docstring reference
to the project (``stiefel.minimize``, ``mesh.laplacian``) is broken. These tests are in the default run
(CI's ``python -m pytest -q``), so a reference that stops resolving fails CI."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

# the whole API reference is built (~20 s): in the slow suite, which CI runs too
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("build_api", ROOT / "docs" / "build_api.py")
assert _spec and _spec.loader
build_api = importlib.util.module_from_spec(_spec)
sys.modules[_spec.name] = build_api  # dataclasses look their module up
_spec.loader.exec_module(build_api)

# page -> symbols documented there (pdoc gives each member an element with id="<qualname>")
KEY_PAGES = {
    "stiefel.html": ["GeneralizedStiefel", "minimize", "minimize_sequential", "RiemannianCG", "Result"],
    "objectives.html": ["compressed_modes", "BlockCMM", "cmm_batch"],
    "objectives/cmm/modes.html": ["compressed_modes", "select_mu", "CMMResult"],
    "objectives/cmm/solvers.html": ["BlockCMM", "SequentialCMM", "ADMMCMM", "FastCMM"],
    "mesh.html": ["laplacian", "load", "Mesh", "eigenbasis"],
    "mesh/io.html": ["load", "Mesh"],
}


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> tuple[subprocess.CompletedProcess[str], Path, float]:
    """The reference built by the script in a fresh process (no x64, run from outside the repo)."""
    if os.environ.get("CI"):  # CI installs the test extras: a missing pdoc is a failure there
        import pdoc  # noqa: F401
    else:
        pytest.importorskip("pdoc")
    out = tmp_path_factory.mktemp("api")
    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, str(ROOT / "docs" / "build_api.py"), "--out", str(out)],
                          cwd=out, env=env, capture_output=True, text=True, timeout=300)
    return proc, out, time.perf_counter() - start


def test_build_succeeds_quietly(built: tuple[subprocess.CompletedProcess[str], Path, float]) -> None:
    proc, _, elapsed = built
    output = proc.stdout + proc.stderr
    assert proc.returncode == 0, output
    assert len(output.splitlines()) < 30, output
    print(f"API reference built in {elapsed:.1f} s")


def test_key_pages_document_key_symbols(built: tuple[subprocess.CompletedProcess[str], Path, float]) -> None:
    _, out, _ = built
    index = (out / "index.html").read_text(encoding="utf-8")
    for module in ("stiefel", "objectives", "objectives.cmm.modes", "mesh", "mesh.laplacian", "stiefel_cmm.cli"):
        assert f">{module}</a>" in index, module
    for page, symbols in KEY_PAGES.items():
        html = (out / page).read_text(encoding="utf-8")
        missing = [s for s in symbols if f'id="{s}"' not in html]
        assert not missing, f"{page} lacks {missing}"


def test_rendered_references_are_links(built: tuple[subprocess.CompletedProcess[str], Path, float]) -> None:
    """Cross-check with pdoc's own resolution: every project name in inline code is a link."""
    _, out, _ = built
    known = {name for _, name in build_api.KNOWN_BROKEN}
    unlinked = set()
    for page in out.rglob("*.html"):
        for code in re.findall(r"<code>(.*?)</code>", page.read_text(encoding="utf-8"), re.S):
            text = re.sub(r"<[^>]+>", "", re.sub(r"<a\b[^>]*>.*?</a>", " ", code, flags=re.S))
            unlinked |= {(page.relative_to(out).as_posix(), name)
                         for name in build_api._PROJECT_NAME.findall(text) if name not in known}
    assert not unlinked, "\n".join(f"{page}: {name}" for page, name in sorted(unlinked))


def test_no_broken_references() -> None:
    broken = build_api.broken_references(build_api.public_modules())
    assert not broken, "broken references:\n" + "\n".join(map(str, broken))


def test_public_modules_skip_private_ones() -> None:
    modules = build_api.public_modules()
    assert {"stiefel", "stiefel.solvers.sharding", "objectives.cmm.solvers", "mesh.laplacian", "stiefel_cmm.cli.main"} <= set(modules)
    assert not [m for m in modules if "._" in m]


def test_references_in_finds_project_names_and_their_lines() -> None:
    doc = ("Solve with ``stiefel.minimize`` (not ``np.linalg.norm``, nor ``lap.mesh.W``).\n"
           "\n"
           "See ``optx.minimise(fn, stiefel.RiemannianCG(S),\n"
           "  adjoint=stiefel.RiemannianImplicitAdjoint())`` and `mesh.laplacian`; mesh.load is prose.\n")
    refs = build_api.references_in(doc, "fake.py", first_line=10)
    assert [(r.line, r.name) for r in refs] == [
        (10, "stiefel.minimize"), (12, "stiefel.RiemannianCG"),
        (13, "stiefel.RiemannianImplicitAdjoint"), (13, "mesh.laplacian")]


def test_paths_are_not_references() -> None:
    doc = "Measured in ``docs/benchmarks/mesh.md`` and ``bench/stiefel.json``; see ``mesh.laplacian``."
    assert [r.name for r in build_api.references_in(doc)] == ["mesh.laplacian"]


@pytest.mark.parametrize("name, ok", [
    ("stiefel.minimize", True),
    ("stiefel.solvers.sharding.solve_sharded", True),
    ("objectives.cmm.solvers.BlockCMM", True),
    ("objectives.BlockCMM.solve", True),
    ("mesh.laplacian", True),
    ("mesh.Mesh.report", True),  # a field, no class attribute
    ("stiefel.minimise", False),
    ("objectives.cmm.solvers.BlockCMMM", False),
    ("mesh.report.lines", False),  # no module mesh.report
    ("objectives.no_such_module.f", False),
    ("stiefel.runtime.compilation", True),
    ("stiefel.runtime._compilation", False),  # private
])
def test_resolves(name: str, ok: bool) -> None:
    assert build_api.resolves(name) is ok


def test_a_broken_reference_fails_the_script(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "fake_api_module.py").write_text(
        '"""Fake module: ``stiefel.minimize`` exists.\n\nBut ``objectives.cmm.solvers.BlockCMMM`` does not."""\n'
        "def _private():\n    '''``stiefel.nope`` is not checked: not rendered.'''\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(build_api, "public_modules", lambda: ["fake_api_module"])
    monkeypatch.setattr(build_api, "build", lambda out, modules: [])
    assert build_api.main(["--out", str(tmp_path / "api")]) == 1
    err = capsys.readouterr().err
    assert "fake_api_module.py:3: objectives.cmm.solvers.BlockCMMM" in err
    assert "stiefel.minimize" not in err and "stiefel.nope" not in err
