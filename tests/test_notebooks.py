"""Execute every notebook in ``notebooks/`` with nbclient (no cell may raise), from a working directory
outside the repository, and check that the committed notebooks carry their outputs (pictures).

The notebooks need no file outside the repository (their meshes are ``mesh.example``'s). Skipped
when nbclient/nbformat/ipykernel are not installed. The kernel is this interpreter (``sys.executable``): if the installed
``python3`` kernelspec would start some other Python, a temporary ``python3`` kernelspec
pointing to ``sys.executable`` is written and put first on ``JUPYTER_PATH``. The
repository root is put on the kernel's ``PYTHONPATH`` so the notebooks import
``mesh``/``objectives`` without an installed package. Notebooks run in a temporary working
directory; the executed copy is never written back (``python notebooks/refresh.py`` does that).
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")
kernelspec = pytest.importorskip("jupyter_client.kernelspec")

ROOT = Path(__file__).resolve().parents[1]
NBDIR = ROOT / "notebooks"
NOTEBOOKS = sorted(NBDIR.glob("*.ipynb"))
PY_ALIASES = {"python", "python3", f"python{sys.version_info[0]}.{sys.version_info[1]}"}


def _same_interpreter(exe: str) -> bool:
    """Would a kernelspec whose argv[0] is ``exe`` start this interpreter?"""
    if exe in PY_ALIASES:  # jupyter_client replaces these with sys.executable
        return True
    path = shutil.which(exe) or exe
    try:
        return Path(path).resolve() == Path(sys.executable).resolve() or Path(path).samefile(sys.executable)
    except OSError:
        return False


@pytest.fixture
def kernel_env(tmp_path, monkeypatch):
    """Make ``python3`` start ``sys.executable`` with the repository importable."""
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))
    try:
        spec = kernelspec.KernelSpecManager().get_kernel_spec("python3")
        ok = _same_interpreter(spec.argv[0])
    except Exception:  # noqa: BLE001 — no (usable) python3 kernelspec
        ok = False
    if not ok:
        kdir = tmp_path / "jupyter" / "kernels" / "python3"
        kdir.mkdir(parents=True)
        (kdir / "kernel.json").write_text(json.dumps({
            "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
            "display_name": "Python 3 (test)",
            "language": "python",
        }))
        monkeypatch.setenv("JUPYTER_PATH", os.pathsep.join(
            filter(None, [str(tmp_path / "jupyter"), os.environ.get("JUPYTER_PATH")])))
    spec = kernelspec.KernelSpecManager().get_kernel_spec("python3")
    assert _same_interpreter(spec.argv[0]), f"python3 kernelspec {spec.argv} does not start {sys.executable}"


def test_there_are_notebooks():
    assert NOTEBOOKS, f"no notebooks in {NBDIR}"


# the quick start runs in the default run; the others (20–35 s each, every one compiling its own solvers) in the
# slow run, which CI runs too
QUICK = "01_quickstart.ipynb"


@pytest.mark.parametrize("path", [pytest.param(p, id=p.name, marks=[] if p.name == QUICK else [pytest.mark.slow])
                                  for p in NOTEBOOKS])
@pytest.mark.slow
def test_notebook_executes(path, kernel_env, tmp_path):
    nb = nbformat.read(path, as_version=4)
    cwd = tmp_path / "elsewhere"
    cwd.mkdir()
    client = nbclient.NotebookClient(nb, kernel_name="python3", timeout=300,
                                     resources={"metadata": {"path": str(cwd)}})
    client.execute()  # raises CellExecutionError on the first failing cell
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors, errors


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_is_committed_with_outputs(path):
    """Every code cell ran (an execution count), none failed, and there is at least one picture."""
    nb = nbformat.read(path, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code" and c.source.strip()]
    assert code and all(c.get("execution_count") for c in code), f"{path.name}: run python notebooks/refresh.py"
    outputs = [o for c in code for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"], path.name
    assert any("image/png" in o.get("data", {}) for o in outputs), f"{path.name} shows no picture"
    text = path.read_text()
    assert "shared/meshes" not in text and "../shared" not in text
