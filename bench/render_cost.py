"""What the PNG contact sheet costs: the former renderer (``git show REV:stiefel_cmm.stiefel_cmm/cli/render.py``) against
``stiefel_cmm.stiefel_cmm/cli/render.py`` now, side by side in one process, k fields on each mesh.

Fields: the first ``k`` Laplacian eigenvectors (``mesh.eigenbasis``), as ``stiefel eigs`` draws them.
Each repeat draws the old sheet and then the new one (interleaved, so that load from other processes
hits both alike); the table gives the median and the best wall-clock seconds, and the best CPU seconds
of this process (``time.process_time``), per mesh. The new renderer's text cache is cleared before each
of its repeats (a real run draws new titles). Row titles are like ``stiefel modes``'s. A second table
splits the new renderer's CPU time into stages (orientation and views, rasterisation with the
interpolation matrices, colouring and pasting, layout, text, PNG encoding). First, the time of the
first sheet in a fresh process that has imported the CLI, as in a ``stiefel`` run: the renderer's own
imports included (the former one imports matplotlib's Figure machinery; the new one no matplotlib at
all for the default colormap).

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
    """The module ``stiefel_cmm.stiefel_cmm/cli/render.py`` at git revision ``rev``, imported from a temporary file; None without git."""
    try:
        src = subprocess.run(["git", "show", f"{rev}:stiefel_cmm.stiefel_cmm/cli/render.py"], cwd=ROOT, capture_output=True, text=True,
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
    from stiefel_cmm.cli.demo_mesh import demo_mesh

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


#: the new renderer's stages: (module attribute, owner name) timed by wrapping them during extra repeats
STAGES = {"orient": ("_Scene", "__init__"), "rasterise": ("_Scene", "pixels"), "colour": (None, "_paint"),
          "labels": (None, "sheet_layout"), "text": (None, "draw_text"), "png": (None, "png_bytes")}


def _stage_times(run, repeats: int) -> dict[str, float]:
    """Best CPU seconds per stage of :mod:`stiefel_cmm.cli.render` over ``repeats`` calls of ``run()`` (text caches cleared)."""
    from stiefel_cmm.cli import render

    spent: dict[str, float] = {}
    saved = []

    def wrap(name, fn):
        def timed(*a, **kw):
            t = time.process_time()
            try:
                return fn(*a, **kw)
            finally:
                spent[name] = spent.get(name, 0.0) + time.process_time() - t
        return timed

    for name, (owner, attr) in STAGES.items():
        obj = getattr(render, owner) if owner else render
        saved.append((obj, attr, getattr(obj, attr)))
        setattr(obj, attr, wrap(name, getattr(obj, attr)))
    best: dict[str, float] = {}
    try:
        for _ in range(repeats):
            spent.clear()
            render._text_bitmap.cache_clear()
            render._cluster_bitmap.cache_clear()
            t = time.process_time()
            run()
            spent["total"] = time.process_time() - t
            for name, sec in spent.items():
                best[name] = min(best.get(name, np.inf), sec)
    finally:
        for obj, attr, fn in saved:
            setattr(obj, attr, fn)
    return {name: round(sec, 4) for name, sec in best.items()}


_CHILD = r'''
import json, sys, time
sys.path.insert(0, sys.argv[1])
import numpy as np
import stiefel_cmm.cli.main, mesh                      # what a stiefel process has loaded when it draws
d = np.load(sys.argv[3])
if sys.argv[2] == "new":
    from stiefel_cmm.cli import render
else:
    import importlib.util
    spec = importlib.util.spec_from_file_location("render_old", sys.argv[4])
    render = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(render)
t = time.perf_counter()
render.contact_sheet(sys.argv[5], d["v"], d["f"], d["x"], titles=[str(s) for s in d["t"]])
print(json.dumps({"first_s": time.perf_counter() - t, "matplotlib": "matplotlib" in sys.modules}))
'''


def _fresh(which: str, data: Path, old_path: Path, out: Path) -> dict:
    """The first sheet of a fresh process that has already imported the CLI (imports of the renderer's own
    dependencies included, as in a ``stiefel`` run)."""
    p = subprocess.run([sys.executable, "-c", _CHILD, str(ROOT), which, str(data), str(old_path), str(out)],
                       capture_output=True, text=True, check=True)
    return json.loads(p.stdout.strip().splitlines()[-1])


def measure(spec: str, k: int, repeats: int, old, tmp: Path, fresh: int = 3) -> dict:
    import mesh
    from stiefel_cmm.cli import render

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
    out["new"]["stages_cpu_best_s"] = _stage_times(lambda: runs["new"](tmp / "stages.png"), repeats)
    if fresh:
        data = tmp / "sheet.npz"
        np.savez(data, v=v, f=f, x=fields, t=np.array(titles))
        firsts: dict[str, list[dict]] = {w: [] for w in runs}
        for _ in range(fresh):
            for which in sorted(runs, reverse=True):
                firsts[which].append(_fresh(which, data, tmp / "render_old.py", tmp / f"fresh_{which}.png"))
        for which, rs in firsts.items():
            out[which]["fresh_first_median_s"] = round(statistics.median(r["first_s"] for r in rs), 4)
            out[which]["imports_matplotlib"] = rs[0]["matplotlib"]
    return out


def table(rows: list[dict]) -> str:
    lines = ["First sheet of a fresh process that has imported the CLI (median, wall seconds):", "",
             "| mesh | n | old | new | ratio |", "|---|---|---|---|---|"]
    for r in rows:
        o, n = r.get("old", {}), r["new"]
        if "fresh_first_median_s" in n:
            of, nf = o.get("fresh_first_median_s"), n["fresh_first_median_s"]
            ratio = f"{of / nf:.1f}×" if of else "–"
            old_s = f"{of:.3f}" if of is not None else "–"
            lines.append(f"| {r['mesh']} | {r['n']} | {old_s} | {nf:.3f} | {ratio} |")
    lines += ["", "Warm (same process, after one warm-up sheet):", "",
              "| mesh | n | old: median / best wall (s) | old: best CPU (s) | new: median / best wall (s) "
              "| new: best CPU (s) | speed-up (best CPU) | PNG old → new (KB) |",
              "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        o, n = r.get("old"), r["new"]
        old_cells = f"{o['wall_median_s']:.3f} / {o['wall_best_s']:.3f} | {o['cpu_best_s']:.3f}" if o else "– | –"
        speed = f"{o['cpu_best_s'] / n['cpu_best_s']:.1f}×" if o else "–"
        png = f"{o['png_bytes'] / 1024:.0f} → {n['png_bytes'] / 1024:.0f}" if o else f"{n['png_bytes'] / 1024:.0f}"
        lines.append(f"| {r['mesh']} | {r['n']} | {old_cells} | {n['wall_median_s']:.3f} / {n['wall_best_s']:.3f} "
                     f"| {n['cpu_best_s']:.3f} | {speed} | {png} |")
    names = list(STAGES) + ["total"]
    lines += ["", "New renderer, best CPU seconds per stage (each stage's best over the repeats):", "",
              "| mesh | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for r in rows:
        st = r["new"]["stages_cpu_best_s"]
        lines.append(f"| {r['mesh']} | " + " | ".join(f"{st.get(n, 0.0):.3f}" for n in names) + " |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench render-cost", description=__doc__.split("\n\n")[0])
    p.add_argument("--meshes", nargs="+", default=["demo:4", "demo:5", "demo:6"],
                   help="mesh files, or demo:S for the built-in surface at S subdivisions")
    p.add_argument("-k", type=int, default=10, help="fields (rows of the sheet)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--fresh", type=int, default=3, help="fresh processes per renderer for the first-sheet time "
                   "(0: skip)")
    p.add_argument("--old-rev", default=OLD_REV, help="git revision of the former stiefel_cmm.stiefel_cmm/cli/render.py")
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
            rows.append(measure(spec, args.k, args.repeats, old, Path(tmp), args.fresh))
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
