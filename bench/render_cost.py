"""What the PNG contact sheet costs: the former renderer (``git show REV:cli/render.py``) against
``cli/render.py`` now, side by side in one process, k fields on each mesh.

Fields: the first ``k`` Laplacian eigenvectors (``mesh.eigenbasis``), as ``stiefel eigs`` draws them.
Each repeat draws the old sheet and then the new one (interleaved, so that load from other processes
hits both alike); the table gives the median and the best wall-clock seconds, and the best CPU seconds
of this process (``time.process_time``), per mesh. The new renderer's text cache is cleared before each
of its repeats (a real run draws new titles). Row titles are like ``stiefel modes``'s.

    python -m bench render-cost                                   # the demo mesh at 2.5K, 10K and 41K vertices
    python -m bench render-cost --meshes ../shared/meshes/fandisk.off ../shared/meshes/camelhead.off \\
        ../shared/meshes/armadillo_25479.obj --out-md bench/RESULTS_render.md
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

#: the last commit of the former renderer (z-up views, matplotlib Figure for the titles, PIL's PNG writer)
OLD_REV = "ed11ffa69599de64f1fbc9f628bc0a2df6e7b599"


def _old_renderer(rev: str, tmp: Path):
    """The module ``cli/render.py`` at git revision ``rev``, imported from a temporary file; None without git."""
    try:
        src = subprocess.run(["git", "show", f"{rev}:cli/render.py"], cwd=ROOT, capture_output=True, text=True,
                             check=True).stdout
    except (OSError, subprocess.CalledProcessError) as exc:
        print(f"old renderer unavailable ({exc}); timing the new one only", file=sys.stderr)
        return None
    path = tmp / "render_old.py"
    path.write_text(src)
    spec = importlib.util.spec_from_file_location("render_old", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _mesh(spec: str) -> tuple[str, np.ndarray, np.ndarray]:
    """``demo`` / ``demo:S`` (the built-in surface at S subdivisions) or a mesh file."""
    import mesh
    from cli.demo_mesh import demo_mesh

    if spec.startswith("demo"):
        sub = int(spec.split(":")[1]) if ":" in spec else 4
        m = mesh.load(demo_mesh(sub), warn=False)
        name = f"demo (subdivisions {sub})"
    else:
        m = mesh.load(spec, warn=False)
        name = Path(spec).name
    return name, np.asarray(m.vertices), np.asarray(m.faces)


def _time(fn) -> tuple[float, float]:
    w, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w, time.process_time() - c


def measure(spec: str, k: int, repeats: int, old, tmp: Path) -> dict:
    import mesh
    from cli import render

    name, v, f = _mesh(spec)
    eb = mesh.eigenbasis(mesh.laplacian(mesh.load((v, f), warn=False)), k)
    fields, lam = np.asarray(eb.evecs), np.asarray(eb.evals)
    titles = [f"mode {j}  λ̃ = {x:.4g}" for j, x in enumerate(lam)]
    out = {"mesh": name, "n": int(len(v)), "m": int(len(f)), "k": k}
    runs = {"new": lambda p: render.contact_sheet(p, v, f, fields, titles=titles)}
    if old is not None:
        runs["old"] = lambda p: old.contact_sheet(p, v, f, fields, titles=titles)
    for which, fn in runs.items():                               # warm: imports, fonts, colormaps
        fn(tmp / f"warm_{which}.png")
    times: dict[str, list[tuple[float, float]]] = {w: [] for w in runs}
    for _ in range(repeats):
        for which in sorted(runs, reverse=True):                 # old first, then new
            if which == "new":
                render._text_bitmap.cache_clear()
                render._cluster_bitmap.cache_clear()
            times[which].append(_time(lambda: runs[which](tmp / f"{which}.png")))
    for which, ts in times.items():
        wall, cpu = [t[0] for t in ts], [t[1] for t in ts]
        out[which] = {"wall_median_s": round(statistics.median(wall), 4), "wall_best_s": round(min(wall), 4),
                      "cpu_best_s": round(min(cpu), 4), "png_bytes": (tmp / f"{which}.png").stat().st_size}
    return out


def table(rows: list[dict]) -> str:
    lines = ["| mesh | n | old: median / best wall (s) | old: best CPU (s) | new: median / best wall (s) "
             "| new: best CPU (s) | speed-up (best CPU) | PNG old → new (KB) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        o, n = r.get("old"), r["new"]
        old_cells = f"{o['wall_median_s']:.3f} / {o['wall_best_s']:.3f} | {o['cpu_best_s']:.3f}" if o else "– | –"
        speed = f"{o['cpu_best_s'] / n['cpu_best_s']:.1f}×" if o else "–"
        png = f"{o['png_bytes'] / 1024:.0f} → {n['png_bytes'] / 1024:.0f}" if o else f"{n['png_bytes'] / 1024:.0f}"
        lines.append(f"| {r['mesh']} | {r['n']} | {old_cells} | {n['wall_median_s']:.3f} / {n['wall_best_s']:.3f} "
                     f"| {n['cpu_best_s']:.3f} | {speed} | {png} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench render-cost", description=__doc__.split("\n\n")[0])
    p.add_argument("--meshes", nargs="+", default=["demo:4", "demo:5", "demo:6"],
                   help="mesh files, or demo:S for the built-in surface at S subdivisions")
    p.add_argument("-k", type=int, default=10, help="fields (rows of the sheet)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--old-rev", default=OLD_REV, help="git revision of the former cli/render.py")
    p.add_argument("--out-json", default=None)
    p.add_argument("--out-md", default=None, help="write the table with the machine header here")
    args = p.parse_args(argv)
    from bench.environment import run_meta

    meta = run_meta("bench", ["render-cost", *(argv if argv is not None else sys.argv[1:])], k=args.k,
                    repeats=args.repeats, old_rev=args.old_rev)
    with tempfile.TemporaryDirectory() as tmp:
        old = _old_renderer(args.old_rev, Path(tmp))
        rows = []
        for spec in args.meshes:
            rows.append(measure(spec, args.k, args.repeats, old, Path(tmp)))
            print(json.dumps(rows[-1]), flush=True)
    text = table(rows)
    print(text)
    if args.out_json:
        Path(args.out_json).write_text(json.dumps({"meta": meta, "rows": rows}, indent=1, ensure_ascii=False))
    if args.out_md:
        head = "\n".join(f"* {key}: {value}" for key, value in meta.items())
        Path(args.out_md).write_text(f"# Contact-sheet cost (old vs new renderer)\n\n{head}\n\n{text}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
