"""Benchmark of the mesh layer: load, Laplacian assembly, eigenbasis, and ``W @ X``.

    python -m bench mesh                     # writes docs/benchmarks/mesh.md (notes below <!-- notes --> kept)
    python -m bench mesh --quick --out /tmp/mesh.md     # small meshes only

Meshes: icospheres (trimesh.creation.icosphere) with 10 242, 163 842 and 655 362 vertices (subdivisions
5, 7, 8), and the shared test meshes of ``../shared/meshes`` where that directory exists (skipped, and
said so, where it does not). Times are the
best of a few repeats (wall clock, ``time.perf_counter``), float64 throughout.

``W @ X`` (k = 10) is timed four ways: scipy CSR on the host; and three jitted
JAX formulations — ``stiefel.linalg.operators.SparseOperator`` (padded neighbour table,
"ELL"), ``jax.experimental.sparse.BCOO``, and gather + ``jax.ops.segment_sum`` —
each in the mesh's own vertex order, a random order, and reverse Cuthill–McKee
order (``mesh.reorder``).
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import signal
import sys
import time
import warnings
from pathlib import Path

# One BLAS thread: on the shared 2-core machine OpenBLAS's threads contend with other
# jobs and made ARPACK 5–15× slower (icosphere-5, k = 50: 0.54 s with 1 thread, 3.9–8.9 s
# with the default). Set before numpy is imported; an explicit setting wins.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # a benchmark script: float64 on purpose

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import scipy  # noqa: E402
import trimesh  # noqa: E402
from jax.experimental import sparse as jsparse  # noqa: E402

import mesh  # noqa: E402
from stiefel.linalg.operators import SparseOperator  # noqa: E402

from bench.environment import git_commit, results_path, write_page  # noqa: E402
from bench.meshes import SHARED as MESH_DIR  # noqa: E402 — the test meshes beside the repository, when present
SHARED = [
    "decimated-knight.off",
    "hand_868_holes2.obj",
    "hand_868.obj",
    "horse_976.obj",
    "bumpy.off",
    "bunny.off",
    "fandisk.off",
    "camelhead.off",
    "armadillo_25479.obj",
]
SPHERES = {5: "icosphere-5", 7: "icosphere-7", 8: "icosphere-8"}


def best_of(fn, *, repeats: int = 3, budget: float = 2.0) -> float:
    """Minimum wall time of ``fn()`` over up to ``repeats`` runs (fewer if over ``budget`` s)."""
    times = []
    start = time.perf_counter()
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
        if time.perf_counter() - start > budget:
            break
    return min(times)


def time_matvec(fn, X, *, min_time: float = 0.2) -> float:
    """Median seconds per call of a (jitted) ``fn(X)``, after one warm-up call."""
    out = fn(X)
    jax.block_until_ready(out)
    reps = 1
    while True:  # find a repetition count that takes ~min_time
        t = time.perf_counter()
        for _ in range(reps):
            out = fn(X)
        jax.block_until_ready(out)
        dt = time.perf_counter() - t
        if dt > min_time or reps >= 4096:
            break
        reps *= 4
    samples = []
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(reps):
            out = fn(X)
        jax.block_until_ready(out)
        samples.append((time.perf_counter() - t) / reps)
    return float(np.median(samples))


class Timeout(Exception):
    pass


def with_timeout(seconds: int, fn):
    """Run ``fn()``; raise ``Timeout`` after ``seconds`` (SIGALRM; ARPACK calls back into Python)."""

    def handler(signum, frame):
        raise Timeout()

    old = signal.signal(signal.SIGALRM, handler)
    signal.alarm(seconds)
    try:
        return fn()
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def load_all(quick: bool):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", mesh.MultipleComponentsWarning)
        for name in SHARED[:5] if quick else SHARED:
            path = MESH_DIR / name
            if not path.is_file():
                print(f"skip {name}: not found under {MESH_DIR}", file=sys.stderr)
                continue
            t_load = best_of(lambda: mesh.load(path), repeats=2)
            yield name, mesh.load(path), t_load
        for sub, name in SPHERES.items():
            if quick and sub > 5:
                continue
            ico = trimesh.creation.icosphere(subdivisions=sub)
            V, F = np.asarray(ico.vertices), np.asarray(ico.faces)
            t_load = best_of(lambda: mesh.load((V, F)), repeats=2, budget=5.0)
            yield name, mesh.load((V, F)), t_load


def bench_matvec(name: str, m: mesh.Mesh, k: int = 10) -> list[str]:
    rows = []
    rng = np.random.default_rng(0)
    X_np = rng.standard_normal((m.n_vertices, k))
    orders = {
        "as given": np.arange(m.n_vertices),
        "random": rng.permutation(m.n_vertices),
        "RCM": mesh.reorder(m)[1],
    }
    for order, perm in orders.items():
        mp = mesh.permute(m, perm)
        W = mesh.laplacian(mp).W
        X = jnp.asarray(X_np[perm])
        ell = SparseOperator.from_scipy(W, dtype=jnp.float64)
        bcoo = jsparse.BCOO.from_scipy_sparse(W)
        coo = W.tocoo()
        r, c, v = jnp.asarray(coo.row), jnp.asarray(coo.col), jnp.asarray(coo.data)
        n = m.n_vertices

        f_ell = jax.jit(lambda op, x: op.mv(x))
        f_bcoo = jax.jit(lambda M, x: M @ x)
        f_seg = jax.jit(lambda x: jax.ops.segment_sum(v[:, None] * x[c], r, num_segments=n, indices_are_sorted=True))
        ref = W @ np.asarray(X)
        for label, fn in [
            ("ELL (SparseOperator)", lambda x: f_ell(ell, x)),
            ("BCOO", lambda x: f_bcoo(bcoo, x)),
            ("gather+segment_sum", f_seg),
        ]:
            err = float(np.abs(np.asarray(fn(X)) - ref).max() / np.abs(ref).max())
            assert err < 1e-12, (label, err)
            rows.append((name, n, ell.width, order, label, time_matvec(fn, X) * 1e3))
        Xh = np.asarray(X)
        rows.append((name, n, ell.width, order, "scipy CSR (host)", time_matvec(lambda x: W @ x, Xh) * 1e3))
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="small meshes only")
    ap.add_argument("--out", type=Path, default=None, help="the page (default: docs/benchmarks/mesh.md)")
    ap.add_argument("--eig-timeout", type=int, default=150, help="seconds allowed per eigenbasis call")
    args = ap.parse_args(argv)

    t_start = time.perf_counter()
    lines = []
    say = lambda s="": (print(s, flush=True), lines.append(s))  # noqa: E731

    cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), platform.processor()) if os.path.exists("/proc/cpuinfo") else platform.processor()
    say("## Recipe")
    say()
    say(f"* date: {datetime.datetime.now(datetime.timezone.utc):%Y-%m-%d %H:%M} UTC; commit: {git_commit()}")
    say(f"* machine: {cpu}, {os.cpu_count()} logical cores (shared with other jobs; load average at start {os.getloadavg()[0]:.1f}), {platform.system()} {platform.release()}")
    say(f"* versions: python {platform.python_version()}, numpy {np.__version__}, scipy {scipy.__version__}, jax {jax.__version__}, trimesh {trimesh.__version__}")
    say(f"* OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')} (the script's default; see its comment)")
    say(f"* command: `python -m bench mesh{' --quick' if args.quick else ''}{' --out ' + str(args.out) if args.out else ''}` (float64, jax x64 on)")
    say("* times: best of up to 3 runs for load/assembly/eigenbasis; `W @ X`: median of 5 batches after warm-up, jitted, `block_until_ready`")
    say()
    say("## Load, Laplacian assembly (cotangent W + lumped A; FEM A) and eigenbasis")
    say()
    say("| mesh | n | m | load s | W+A lumped s | A fem s | µs/vertex (W+A) | eig k=10 s | eig k=50 s |")
    say("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    matvec_rows = []
    for name, m, t_load in load_all(args.quick):
        t_lap = best_of(lambda: mesh.laplacian(m))
        t_fem = best_of(lambda: mesh.area_matrix(m, "fem"))
        lap = mesh.laplacian(m)
        eig = {}
        for k in (10, 50):
            try:
                t = time.perf_counter()
                ev, _ = with_timeout(args.eig_timeout, lambda: mesh.eigenbasis(lap, k))
                eig[k] = f"{time.perf_counter() - t:.2f}"
            except Timeout:
                eig[k] = f"> {args.eig_timeout} (stopped)"
        say(
            f"| {name} | {m.n_vertices} | {m.n_faces} | {t_load:.3f} | {t_lap:.3f} | {t_fem:.3f} | "
            f"{1e6 * t_lap / m.n_vertices:.2f} | {eig[10]} | {eig[50]} |"
        )
        if name in ("bunny.off", "armadillo_25479.obj") or name.startswith("icosphere") or (args.quick and name == "bumpy.off"):
            matvec_rows += bench_matvec(name, m)
    say()
    say("## `W @ X`, X of shape (n, 10), float64 (ms per product)")
    say()
    say("| mesh | n | ELL width | vertex order | formulation | ms |")
    say("|---|---:|---:|---|---|---:|")
    for name, n, w, order, label, ms in matvec_rows:
        say(f"| {name} | {n} | {w} | {order} | {label} | {ms:.3f} |")
    say()
    say(f"Total bench time: {time.perf_counter() - t_start:.0f} s")
    out = args.out or results_path("mesh")
    write_page(out, "# Mesh layer benchmark (generated by `python -m bench mesh`)\n\n" + "\n".join(lines) + "\n")
    print(f"wrote {out}", file=sys.stderr)


if __name__ == "__main__":
    main()
