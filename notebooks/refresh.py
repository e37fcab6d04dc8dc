"""Re-execute the notebooks and store their outputs in place (pictures visible when browsing).

Run ``python notebooks/refresh.py [NAME ...]`` from anywhere (default: every ``notebooks/*.ipynb``).
Each notebook runs in a fresh temporary working directory with the repository importable, so
nothing it does depends on where it is started; a notebook that raises is left unchanged and the
script exits 1. The tests (``tests/test_notebooks.py``) execute the same way without writing.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

NBDIR = Path(__file__).resolve().parent
ROOT = NBDIR.parent


def execute(path: Path, cwd: str, timeout: int = 600):
    """The executed notebook (``nbformat.NotebookNode``) of ``path``, run with ``cwd`` as working directory."""
    import nbclient
    import nbformat

    nb = nbformat.read(path, as_version=4)
    nbclient.NotebookClient(nb, kernel_name="python3", timeout=timeout,
                            resources={"metadata": {"path": cwd}}).execute()
    return nb


def main(argv: list[str]) -> int:
    import nbformat

    os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    paths = [NBDIR / (a if a.endswith(".ipynb") else a + ".ipynb") for a in argv] or sorted(NBDIR.glob("*.ipynb"))
    failed = 0
    for path in paths:
        t = time.perf_counter()
        try:
            with tempfile.TemporaryDirectory() as cwd:
                nb = execute(path, cwd)
        except Exception as e:  # noqa: BLE001 — report and go on with the others
            print(f"{path.name}: FAILED: {type(e).__name__}: {str(e)[:300]}", file=sys.stderr)
            failed += 1
            continue
        tmp = path.with_name(f".{path.name}.tmp")
        nbformat.write(nb, tmp)
        os.replace(tmp, path)
        print(f"{path.name}: {time.perf_counter() - t:.1f} s, {path.stat().st_size / 1e3:.0f} kB")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
