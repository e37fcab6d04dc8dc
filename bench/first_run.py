"""The first run (issue 17): whole ``stiefel`` processes, cold and warm compilation cache, size buckets,
compare-smoothings against one run, block against ADMM, progress overhead and the cost of padding.

Every CLI measurement is a fresh process (``stiefel modes MESH --no-png --quiet``, k = 10, the CLI's
other defaults) timed from outside; compile, solve, setup and write seconds come from its
``summary.json`` (``timings``). Per mesh:

* ``cold``: an empty cache directory; ``warm``: the same command again; ``bucket``: a sibling mesh
  (the mesh with the faces around its last vertices removed: fewer vertices, the same size bucket)
  with the warm cache; ``no-cache``: ``--no-cache``;
* ``admm``: ``--method admm`` (cold cache; ADMM compiles nothing) — the ratio block/ADMM of whole
  processes;
* ``compare``: ``stiefel compare-smoothings`` (all ten smoothings) with a cold cache, against ``cold``.

In one process (compile excluded): the solve time with a progress callback (reports every 0.25 s)
against none, and the time per iteration with the problem padded by 0–40 % (``objectives.cmm.padding``),
which chose ``stiefel.runtime.buckets.DEFAULT_GROWTH``.

    python -m bench first-run                       # the demo mesh (no files needed)
    python -m bench first-run --meshes demo ../shared/meshes/fandisk.off ../shared/meshes/camelhead.off
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def _stiefel(args: list[str], out: Path, cache: Path | None) -> dict:
    """Run ``stiefel ARGS`` in a fresh process; ``{"process_s", "timings", "status", "iterations", ...}``."""
    cmd = [sys.executable, "-m", "stiefel_cmm.cli.main", *args, "--out", str(out), "--quiet"]
    cmd += ["--no-cache"] if cache is None else ["--cache-dir", str(cache)]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("STIEFEL_CACHE_DIR", None)
    t0 = time.perf_counter()
    p = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({p.returncode}): {p.stderr[-1500:]}")
    summary = json.loads((out / "summary.json").read_text())
    result = summary.get("diagnostics", {})
    return {"process_s": round(wall, 3), "timings": summary.get("timings", {}),
            "objective": result.get("objective"), "iterations": result.get("iterations"),
            "status": result.get("status"), "n": summary.get("mesh", {}).get("n_vertices")}


def _sibling(path: Path, out: Path) -> tuple[Path, int, int]:
    """The mesh with the faces around its last vertices removed (unused vertices dropped), as an OFF file
    in the same size bucket: ``(path, n, n_sibling)``."""
    import mesh
    import trimesh
    from objectives.cmm.padding import PaddedProblem
    from stiefel.runtime.buckets import DEFAULT_GROWTH

    def shapes(m):
        lap = mesh.laplacian(m)
        p = PaddedProblem.build(lap.W, lap.A.diagonal(), DEFAULT_GROWTH)
        return p.size, p.width, p.factor_size

    m = mesh.load(path)
    V, F = np.asarray(m.vertices), np.asarray(m.faces)
    n, want = len(V), shapes(m)
    for frac in (0.03, 0.02, 0.01, 0.005, 0.002, 0.001):  # the largest cut that keeps every padded shape
        cut = n - max(1, int(frac * n))
        keep = F[(F < cut).all(axis=1)]
        t = trimesh.Trimesh(V, keep, process=False)
        t.remove_unreferenced_vertices()
        try:
            same = len(t.vertices) < n and shapes(mesh.load((np.asarray(t.vertices), np.asarray(t.faces)))) == want
        except mesh.MeshError:
            same = False
        if same:
            break
    target = out / f"{path.stem}-sibling.off"
    t.export(target)
    return target, n, len(t.vertices)


def cli_rows(path: Path, work: Path, *, admm: bool, compare: bool) -> dict:
    cache = work / "cache"
    base = [str(path), "-k", "10", "--no-png"]
    rows = {"cold": _stiefel(["modes", *base], work / "cold", cache)}
    rows["warm"] = _stiefel(["modes", *base], work / "warm", cache)
    sibling, n, n_sib = _sibling(path, work)
    rows["bucket"] = _stiefel(["modes", str(sibling), "-k", "10", "--no-png"], work / "bucket", cache)
    rows["bucket"]["n"] = n_sib
    rows["no-cache"] = _stiefel(["modes", *base], work / "nocache", None)
    if admm:
        rows["admm"] = _stiefel(["modes", *base, "--method", "admm"], work / "admm", work / "cache-admm")
    if compare:
        rows["compare"] = _stiefel(["compare-smoothings", *base], work / "compare", work / "cache-compare")
    return rows


def in_process(path: Path, k: int, fractions: list[float], rounds: int = 4) -> dict:
    """Progress overhead and padding cost (compile excluded), in this process."""
    import jax

    jax.config.update("jax_enable_x64", True)  # benchmark script (an application)
    import mesh
    import objectives.cmm.padding as padding
    from objectives.cmm.modes import compressed_modes
    from objectives.cmm.solvers import BlockCMM

    lap = mesh.laplacian(mesh.load(path))
    mu = 0.01 * lap.n
    out: dict = {"n": lap.n}
    runs: dict = {"none": [], "progress": []}
    lines = []
    for _ in range(5):  # alternating, best of 5 each
        for label, kw in (("none", {}), ("progress", {"progress": lambda info: lines.append(info.line())})):
            r = compressed_modes(lap, k, mu, solver=BlockCMM(bucket_growth=None), **kw)
            runs[label].append(r.wall_time)
            out[f"iterations_{label}"] = r.iterations
    runs = {label: min(v) for label, v in runs.items()}
    out["reports_per_solve"] = len(lines) / 5
    out["solve_s_no_progress"] = round(runs["none"], 4)
    out["solve_s_progress"] = round(runs["progress"], 4)
    out["progress_overhead"] = round(runs["progress"] / runs["none"] - 1.0, 4)
    original = padding.bucket
    best: dict = {}
    try:
        for _ in range(rounds):  # the fractions in turn, round after round: best ms/iteration of each
            for f in fractions:
                padding.bucket = lambda size, growth, f=f: size if growth is None else int(np.ceil(size * (1 + f)))
                r = compressed_modes(lap, k, mu, solver=BlockCMM(bucket_growth=2.0))
                if f not in best or r.wall_time / r.iterations < best[f].wall_time / best[f].iterations:
                    best[f] = r
    finally:
        padding.bucket = original
    pad_rows = [{"padding": f, "size": r.params["padded_size"], "iterations": r.iterations,
                 "solve_s": round(r.wall_time, 4), "ms_per_iteration": round(1e3 * r.wall_time / r.iterations, 3),
                 "objective": r.objective} for f, r in best.items()]
    base = pad_rows[0]["ms_per_iteration"]
    for row in pad_rows:
        row["cost"] = round(row["ms_per_iteration"] / base - 1.0, 4)
    out["padding"] = pad_rows
    return out


def _ratio(a, b):
    return round(a / b, 3) if a and b else None


def report(results: dict, meta: dict) -> str:
    lines = ["# The first run: compilation cache, size buckets, progress (issue 17)", "",
             f"{meta['date']}; {meta['machine']}; jax {meta['jax']}; command: `{meta['command']}`", "",
             "Fresh `stiefel modes MESH -k 10 --no-png --quiet` processes (other options: CLI defaults). "
             "`process` is the whole process timed from outside; compile/solve/setup/write from "
             "`summary.json`'s `timings`.", "",
             "| mesh | n | run | process s | compile s | solve s | setup s | write s | iterations | objective |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, res in results.items():
        if "error" in res:
            lines.append(f"| {name} | – | failed: {res['error'][:120]} | | | | | | | |")
            continue
        for run, row in res["stiefel_cmm.cli"].items():
            t = row["timings"]
            lines.append(f"| {name} | {row['n']} | {run} | {row['process_s']:.2f} | {t.get('compile_s', 0):.2f} | "
                         f"{t.get('solve_s', 0):.2f} | {t.get('setup_s', 0):.2f} | {t.get('write_s', 0):.2f} | "
                         f"{row['iterations']} | {row['objective'] if row['objective'] is None else format(row['objective'], '.6g')} |")
    lines += ["", "Ratios (process time; compile-excluded: process minus compile seconds):", "",
              "| mesh | block cold / ADMM | compile-excluded | compare-smoothings / modes (cold) | compile-excluded |",
              "|---|---|---|---|---|"]
    for name, res in results.items():
        if "error" in res:
            continue
        c = res["stiefel_cmm.cli"]
        cold = c["cold"]

        def excl(row):
            return row["process_s"] - row["timings"].get("compile_s", 0.0)

        admm = (_ratio(cold["process_s"], c["admm"]["process_s"]), _ratio(excl(cold), excl(c["admm"]))) \
            if "admm" in c else (None, None)
        comp = (_ratio(c["compare"]["process_s"], cold["process_s"]), _ratio(excl(c["compare"]), excl(cold))) \
            if "compare" in c else (None, None)
        lines.append(f"| {name} | {admm[0]} | {admm[1]} | {comp[0]} | {comp[1]} |")
    lines += ["", "In one process, compile excluded (best of 5, alternating): block solve with a progress callback (a report "
              "every 0.25 s) against none, and the cost of padding the problem by a fraction of its rows "
              "(`objectives.cmm.padding`; best ms per iteration of 4 interleaved rounds, relative to no padding):", ""]
    for name, res in results.items():
        ip = res.get("in_process")
        if not ip:
            continue
        lines.append(f"* {name} (n = {ip['n']}): solve {ip['solve_s_no_progress']:.3f} s without progress, "
                     f"{ip['solve_s_progress']:.3f} s with ({ip['reports_per_solve']:.0f} reports) — overhead {100 * ip['progress_overhead']:+.1f} %; "
                     "padding: " + ", ".join(f"{100 * r['padding']:.0f} % → {100 * r['cost']:+.1f} % "
                                            f"({r['ms_per_iteration']:.2f} ms/it, {r['iterations']} it)"
                                            for r in ip["padding"]))
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench first-run", description=__doc__.split("\n\n")[0])
    p.add_argument("--meshes", nargs="*", default=None, help="mesh files (default: the built-in demo mesh)")
    p.add_argument("--no-admm", action="store_true", help="skip the ADMM processes")
    p.add_argument("--no-compare", action="store_true", help="skip compare-smoothings")
    p.add_argument("--no-in-process", action="store_true", help="skip progress overhead and padding cost")
    p.add_argument("--padding", default="0,0.1,0.2,0.4", help="padding fractions for the padding cost")
    p.add_argument("--heavy-max-n", type=int, default=12000,
                   help="compare-smoothings and the in-process measurements only on meshes up to this many vertices")
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "RESULTS_first_run.md")
    p.add_argument("--json", type=Path, default=ROOT / "bench" / "results_first_run.json")
    args = p.parse_args(argv)
    from bench.environment import run_meta

    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        meshes = list(args.meshes or ["demo"])
        if "demo" in meshes:  # the built-in demo mesh, as a file
            import trimesh
            from stiefel_cmm.cli.demo_mesh import demo_mesh

            v, f = demo_mesh()
            meshes[meshes.index("demo")] = str(Path(tmp) / "demo.off")
            trimesh.Trimesh(v, f, process=False).export(Path(tmp) / "demo.off")
        sizes = {}
        for i, path in enumerate(map(Path, meshes)):
            work = Path(tmp) / f"m{i}"
            work.mkdir()
            name = path.stem
            print(f"[first-run] {name}: CLI processes", file=sys.stderr, flush=True)
            import mesh

            try:
                sizes[name] = mesh.load(path).n_vertices
                heavy = sizes[name] <= args.heavy_max_n
                results[name] = {"stiefel_cmm.cli": cli_rows(path, work, admm=not args.no_admm,
                                                 compare=heavy and not args.no_compare)}
            except (mesh.MeshError, RuntimeError) as e:  # e.g. a non-manifold mesh: recorded, the others go on
                sizes[name] = None
                results[name] = {"error": " ".join(str(e).split())[:300]}
                print(f"[first-run] {name}: {results[name]['error']}", file=sys.stderr, flush=True)
        for path in map(Path, meshes):
            if not args.no_in_process and sizes[path.stem] is not None and sizes[path.stem] <= args.heavy_max_n:
                print(f"[first-run] {path.stem}: progress overhead and padding cost", file=sys.stderr, flush=True)
                results[path.stem]["in_process"] = in_process(path, 10, [float(x) for x in args.padding.split(",")])
    meta = run_meta("bench", ["first-run", *(argv if argv is not None else sys.argv[1:])])
    text = report(results, meta)
    args.out.write_text(text)
    args.json.write_text(json.dumps({"meta": meta, "results": results}, indent=1))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
