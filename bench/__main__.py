"""The one entry point of the benchmarks: ``python -m bench <name> [args]``.

    python -m bench --help                 # the benchmarks, one line each
    python -m bench suite                  # every CMM solver on a generated mesh
    python -m bench suite --mesh fandisk.off --repeats 1
    python -m bench scaling --help         # a benchmark's own options

Each benchmark is a module with ``main(argv=None)``, imported only when it is run (most of them switch JAX to
float64 at import, as applications may). Its results go to ``docs/benchmarks/<name>.md`` and ``<name>.json``
(``bench.environment``); the defaults need no file outside the repository, and a mesh input that does not
exist stops the run with a one-line message before anything is measured or written.
"""

from __future__ import annotations

import importlib
import sys
from typing import Sequence

# name -> (module, one line: what it measures); kept here so that --help imports nothing
BENCHMARKS: dict[str, tuple[str, str]] = {
    "suite": ("bench.suite", "every CMM solver side by side on meshes and ManPG's 1-D problem: objective, exact "
                             "zeros, time, ratios to ADMM"),
    "exact": ("bench.exact", "the default (exactly sparse, certified) CMM answer against ADMM and the previous "
                             "smoothed default: meshes, ManPG's 24 cases, RPN-CG's; the finish's iterates"),
    "starts": ("bench.starts", "the default's screen of rotated eigenbasis starts against each start solved alone: "
                               "objectives, the pick, the cost"),
    "cmm": ("bench.bench_cmm", "the block manifold solver's variants against ADMM: time to ADMM's best objective"),
    "scaling": ("bench.scaling", "subdivided surfaces up to ~10⁶ vertices: assembly, eigsh, ms per iteration, "
                                 "fitted exponents, memory"),
    "scaling-modes": ("bench.scaling_modes", "the default CMM solve (as `stiefel modes` runs it) on subdivided "
                                             "meshes: total time against eigsh, peak memory"),
    "stiefel": ("bench.bench_stiefel", "manifold layer at μ = 0 on grid Laplacians: solvers, retractions, "
                                       "preconditioning against eigsh"),
    "default-method": ("bench.default_method", "every stiefel.minimize method on a panel with known optima "
                                               "(Brockett, eigenproblems, Procrustes, sparse PCA): the default's evidence"),
    "peers": ("bench.peers", "Riemannian CG per iteration, each retraction, against pymanopt's"),
    "second-order": ("bench.second_order", "trust regions against CG / L-BFGS and pymanopt's TrustRegions: "
                                           "Brockett and the CMM final stage"),
    "penalty": ("bench.bench_penalty", "the penalty baseline (jaxopt L-BFGS + projection) against the manifold "
                                       "solvers"),
    "mesh": ("bench.bench_mesh", "mesh layer: load, Laplacian assembly, eigenbasis, W @ X formulations"),
    "bases": ("bench.bench_bases", "GLMH bases against eigsh; functional maps and ICP"),
    "batch": ("bench.bench_batch", "batched CMM solves: jax.vmap against a Python loop"),
    "precision": ("bench.bench_precision", "float32 against float64: accuracy and speed of the CMM solvers"),
    "autodiff": ("bench.bench_autodiff", "implicit derivatives through a CMM solve: backward pass against the "
                                         "forward solve"),
    "reliability": ("bench.reliability", "the stiefel command under bad input, faults and load "
                                         "(writes docs/RELIABILITY.md)"),
    "thesis": ("bench.thesis.report", "the thesis reproduced claim by claim (writes docs/THESIS.md; --quick)"),
}


def listing() -> str:
    width = max(map(len, BENCHMARKS))
    return "\n".join(f"{name:<{width}}  {text}" for name, (_, text) in BENCHMARKS.items())


USAGE = "usage: python -m bench NAME [args ...]   (python -m bench NAME --help: NAME's options)"
FOOTER = ("results: docs/benchmarks/NAME.md (the page) and NAME.json (raw rows); docs/benchmarks/README.md "
          "is the index")


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help", "--list"):
        print(f"{USAGE}\n\nbenchmarks:\n{listing()}\n\n{FOOTER}")
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in BENCHMARKS:
        print(f"unknown benchmark {name!r}; choose one of {', '.join(BENCHMARKS)} (python -m bench --help)",
              file=sys.stderr)
        return 2
    from bench.meshes import MeshNotFound  # noqa: PLC0415

    try:
        out = importlib.import_module(BENCHMARKS[name][0]).main(rest)
    except MeshNotFound as e:  # raised before anything is measured or written
        print(f"python -m bench {name}: {e.args[0] if e.args else e}", file=sys.stderr)
        return 2
    return out if isinstance(out, int) else 0


if __name__ == "__main__":
    sys.exit(main())
