"""Execute every notebook in ``notebooks/`` with nbclient (a smoke test: no cell may raise).

Skipped when nbclient/nbformat/ipykernel are not installed or the shared meshes are
missing. The kernel is this interpreter (``sys.executable``): if the installed
``python3`` kernelspec would start some other Python, a temporary ``python3`` kernelspec
pointing to ``sys.executable`` is written and put first on ``JUPYTER_PATH``. The
repository root is put on the kernel's ``PYTHONPATH`` so the notebooks import
``mesh``/``objectives`` without an installed package. Notebooks run with ``notebooks/``
as working directory; the executed copy is never written back.
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
MESHES = ROOT.parent / "shared" / "meshes"
NOTEBOOKS = sorted(NBDIR.glob("*.ipynb"))
PY_ALIASES = {"python", "python3", f"python{sys.version_info[0]}.{sys.version_info[1]}"}

pytestmark = pytest.mark.skipif(not MESHES.is_dir(), reason=f"shared meshes not found at {MESHES}")


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


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.name for p in NOTEBOOKS])
def test_notebook_executes(path, kernel_env):
    nb = nbformat.read(path, as_version=4)
    client = nbclient.NotebookClient(nb, kernel_name="python3", timeout=300,
                                     resources={"metadata": {"path": str(NBDIR)}})
    client.execute()  # raises CellExecutionError on the first failing cell
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors, errors
