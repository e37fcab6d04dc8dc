"""One entry point for the benchmarks: ``python -m bench <name> [args]``.

    python -m bench --list                 # the benchmarks and whether each is present
    python -m bench suite --mesh fandisk.off
    python -m bench scaling
    python -m bench stiefel --help

Each benchmark is a module with ``main(argv=None)``, imported only when it is run (most of
them switch JAX to float64 at import, as applications may). ``python -m bench.<module>``
keeps working for every module.
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from typing import Sequence

# name -> (module, one-line description); descriptions are kept here so that --list imports nothing
BENCHMARKS: dict[str, tuple[str, str]] = {
    "suite": ("bench.suite", "all CMM solvers side by side on meshes and ManPG's 1-D problem: objective, exact zeros, time, ratios to ADMM"),
    "scaling": ("bench.scaling", "subdivided surfaces up to ~1e6 vertices: assembly, eigsh, ms/iteration, exponents"),
    "scaling-modes": ("bench.scaling_modes", "the default CMM solve (stiefel modes) on subdivided meshes up to ~10⁶ vertices: total vs eigsh, peak RSS (issue 18)"),
    "stiefel": ("bench.bench_stiefel", "manifold layer, mu = 0 on grid Laplacians (issue 2)"),
    "mesh": ("bench.bench_mesh", "mesh layer: load, Laplacian assembly, eigenbasis, W @ X (issue 3)"),
    "cmm": ("bench.bench_cmm", "block manifold solver vs ADMM on the shared meshes (issue 4)"),
    "bases": ("bench.bench_bases", "bases and functional maps (issue 5)"),
    "batch": ("bench.bench_batch", "batched solves (issue 7, batching)"),
    "precision": ("bench.bench_precision", "float32 vs float64 (issue 7, precision)"),
    "autodiff": ("bench.bench_autodiff", "implicit derivatives through CMM solves: backward vs forward (issue 16)"),
    "penalty": ("bench.bench_penalty", "penalty baseline (jaxopt L-BFGS + projection) vs the manifold solvers"),
    "first-run": ("bench.first_run", "whole stiefel processes: cold/warm cache, size buckets, progress (issue 17)"),
    "reliability": ("bench.reliability", "issue 19's fault catalogue: bad input, faults, loads -> docs/RELIABILITY.md"),
    "defaults": ("bench.defaults", "sparsity and support sizes of the CLI's default modes per mu rule (issue 21)"),
    "second-order": ("bench.second_order", "trust regions vs CG / L-BFGS / pymanopt: Brockett and CMM final stages (issue 22)"),
    "finish": ("bench.finish", "exact-support finish: block / ADMM with and without it, exact zeros, ℓ1 residual (issue 18)"),
    "thesis": ("bench.thesis.report", "the thesis reproduced claim by claim -> docs/THESIS.md (issue 20; --quick)"),
    "admm-rho": ("bench.admm_rho", "ADMM's penalty rho: increase-only vs two-way balancing, both variants, full and fast; per-step ms"),
    "saddle": ("bench.saddle", "saddle checks: block with and without them against ADMM, θ of each check (issue 18)"),
    "tails": ("bench.tails", "slow tails: time to within 1e-3 of the final objective vs after it, stall stop vs trust-region polish (issue 18)"),
    "peers": ("bench.peers", "per-iteration cost of Riemannian CG: ours (each retraction) vs pymanopt (issue 18)"),
    "render-cost": ("bench.render_cost", "PNG contact sheet: former vs current renderer, seconds per sheet (k = 10)"),
}


def available(name: str) -> bool:
    """Whether the benchmark's module exists in this checkout (without importing it)."""
    try:
        return importlib.util.find_spec(BENCHMARKS[name][0]) is not None
    except ModuleNotFoundError:
        return False


def listing() -> str:
    width = max(map(len, BENCHMARKS))
    lines = []
    for name, (module, text) in BENCHMARKS.items():
        flag = "" if available(name) else "  [not in this checkout]"
        lines.append(f"{name:<{width}}  {text}  ({module}){flag}")
    return "\n".join(lines)


USAGE = "usage: python -m bench {--list | NAME [args ...]}   (python -m bench NAME --help for NAME's options)"


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(USAGE + "\n\nbenchmarks:\n" + listing())
        return 0 if argv else 2
    if argv[0] == "--list":
        print(listing())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in BENCHMARKS:
        print(f"unknown benchmark {name!r}; choose one of {', '.join(BENCHMARKS)} (python -m bench --list)",
              file=sys.stderr)
        return 2
    module_name = BENCHMARKS[name][0]
    if not available(name):
        print(f"benchmark {name!r} needs module {module_name}, which is not in this checkout "
              f"(bench/{module_name.split('.')[-1]}.py); update the checkout or run another benchmark "
              "(python -m bench --list)", file=sys.stderr)
        return 2
    module = importlib.import_module(module_name)
    out = module.main(rest)
    return out if isinstance(out, int) else 0


if __name__ == "__main__":
    sys.exit(main())
