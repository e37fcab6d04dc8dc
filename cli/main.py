"""``stiefel`` — compressed manifold modes and Laplacian eigenpairs from the command line.

Subcommands::

    stiefel modes [MESH] -k 10 --mu 0.01n --method block --smoothing f6 --out DIR
    stiefel eigs [MESH] -k 10 --out DIR
    stiefel compare-smoothings [MESH] -k 4 --mu 0.01n --out DIR

Without ``MESH`` the built-in demo surface is used (``cli.demo_mesh``). ``--mu``
is absolute (``5.2``) or relative to the vertex count (``0.01n`` = 0.01·n); the
resolved absolute μ is recorded in ``summary.json``. Progress goes to stdout, one
line per stage (none with ``--quiet``); ``--json`` prints exactly one JSON object
(the summary) on stdout and nothing else there. Errors print one line
``stiefel: error: …`` on stderr: exit code 2 for bad arguments, 1 for bad input
(missing file, non-manifold mesh, …).

``--method`` picks the solver object of ``objectives.cmm_solvers`` (``block`` →
``BlockCMM``, ``sequential`` → ``SequentialCMM``, ``admm`` → ``ADMMCMM``,
``admm_sequential`` → ``SequentialADMMCMM``, ``fast`` → ``FastCMM``); ``--smoothing``,
``--gtol`` and ``--max-iters`` set the manifold solvers' options (the ADMM solvers keep
their own defaults), ``--samples`` the local functions of ``fast``.

Partial results: for ``--method sequential`` the finished columns are saved to
``DIR/modes.partial.npz`` as they complete (``compressed_modes(callback=)``, passed
through to ``stiefel.minimize_sequential``) and removed once the modes are written; the
other methods write their modes when the solve has finished (``summary.json`` says which
applied).

This is an application: ``main`` switches JAX to float64 (``jax_enable_x64``);
the library modules never touch JAX's global configuration.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path
from typing import Any, NoReturn, Sequence

import numpy as np

from .outputs import MuSpec, PartialColumns, parse_mu, stderr_line, to_jsonable, versions, write_json, write_ply

__all__ = ["main", "build_parser", "CLIError"]

PROG = "stiefel"
METHODS = ("block", "sequential", "admm", "admm_sequential", "fast")  # objectives.cmm_solvers.SOLVERS
SMOOTHINGS = tuple(f"f{i}" for i in range(10))


class CLIError(Exception):
    """Bad input detected by the CLI; reported as one line, exit code 1."""


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line on stderr and exit code 2 (no usage dump)."""

    def error(self, message: str) -> NoReturn:
        stderr_line(f"{PROG}: error: {message} (see '{self.prog} -h')")
        raise SystemExit(2)


def _mu_type(text: str) -> MuSpec:
    try:
        return parse_mu(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}") from None
    if not (np.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return v


def _common(p: argparse.ArgumentParser, k_default: int) -> None:
    p.add_argument("mesh", nargs="?", default=None,
                   help="mesh file (OBJ/OFF/PLY/STL); default: the built-in demo mesh")
    p.add_argument("-k", type=_positive_int, default=k_default, help=f"number of modes (default {k_default})")
    p.add_argument("--out", type=Path, default=None, help="output directory (created; default: ./stiefel-<command>)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object on stdout")


def _cmm_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--mu", type=_mu_type, default=parse_mu("0.01n"),
                   help="sparsity weight μ: absolute (5.2) or relative to the vertex count (0.01n); default 0.01n")
    p.add_argument("--weighting", choices=("area", "uniform"), default="area", help="ℓ1 weights (default area)")
    p.add_argument("--max-iters", type=_positive_int, default=5000, help="solver iteration cap (default 5000)")
    p.add_argument("--gtol", type=_positive_float, default=1e-6, help="gradient tolerance (default 1e-6)")


def build_parser() -> argparse.ArgumentParser:
    """The ``stiefel`` argument parser (subcommands ``modes``, ``eigs``, ``compare-smoothings``)."""
    parser = _Parser(prog=PROG, description="Compressed manifold modes and Laplacian eigenpairs on triangle meshes.",
                     epilog="examples: stiefel modes -k 6 --out out/ | stiefel modes mesh.obj -k 10 --mu 0.05n "
                            "--json --out out/ | stiefel eigs mesh.off -k 20 --out eigs/")
    sub = parser.add_subparsers(dest="command", required=True, metavar="{modes,eigs,compare-smoothings}",
                                parser_class=_Parser)
    p = sub.add_parser("modes", help="compressed manifold modes: npz, PLY, PNG, summary.json")
    _common(p, 10)
    _cmm_options(p)
    p.add_argument("--method", choices=METHODS, default="block", help="solver (default block)")
    p.add_argument("--smoothing", choices=SMOOTHINGS, default="f6", help="ℓ1 smoothing (default f6)")
    p.add_argument("--samples", type=_positive_int, default=None,
                   help="local functions for --method fast (default: max(10k, n/10))")
    p.add_argument("--no-png", action="store_true", help="skip the PNG contact sheet")
    p.set_defaults(run=_cmd_modes)

    p = sub.add_parser("eigs", help="first k Laplacian eigenpairs: npz and summary.json")
    _common(p, 10)
    p.set_defaults(run=_cmd_eigs)

    p = sub.add_parser("compare-smoothings", help="f0…f9 from the same start: markdown table, CSV and a figure")
    _common(p, 4)
    _cmm_options(p)
    p.add_argument("--method", choices=("block", "sequential"), default="block", help="solver (default block)")
    p.add_argument("--smoothings", default=",".join(SMOOTHINGS), help="comma-separated subset (default f0,…,f9)")
    p.add_argument("--no-png", action="store_true", help="skip comparison.png (first mode of each smoothing)")
    p.set_defaults(run=_cmd_compare)
    return parser


# ---------------------------------------------------------------------------- helpers


class _Progress:
    """One line per stage on stdout (stderr with --json); silent with --quiet."""

    def __init__(self, quiet: bool, as_json: bool) -> None:
        self.quiet, self.as_json, self.t0 = quiet, as_json, time.perf_counter()

    def __call__(self, msg: str) -> None:
        if self.quiet:
            return
        stream = sys.stderr if self.as_json else sys.stdout
        print(f"[{time.perf_counter() - self.t0:7.2f}s] {msg}", file=stream, flush=True)


def _load(source: str | None) -> tuple[Any, dict]:
    """``(mesh.Mesh, description)`` for a path or the demo mesh."""
    import mesh

    if source is None:
        from .demo_mesh import DEMO_NAME, demo_mesh

        m = mesh.load(demo_mesh())
        name = DEMO_NAME
    else:
        path = Path(source)
        if not path.is_file():
            raise CLIError(f"mesh file not found: {source}")
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", mesh.MultipleComponentsWarning)
            m = mesh.load(path)
        name = str(path.resolve())
        if caught:
            stderr_line(f"{PROG}: warning: {caught[0].message}")
    info = {"source": name, "n_vertices": m.n_vertices, "n_faces": m.n_faces, "n_components": m.n_components,
            "n_boundary_loops": m.n_boundary_loops, "euler_characteristic": m.euler_characteristic}
    return m, info


def _out_dir(args: argparse.Namespace) -> Path:
    out = args.out if args.out is not None else Path(f"stiefel-{args.command}")
    out.mkdir(parents=True, exist_ok=True)
    return out


def _check_k(k: int, n: int) -> None:
    if k >= n:
        raise CLIError(f"k = {k} must be smaller than the number of vertices n = {n}")


def _summary_head(args: argparse.Namespace, argv: Sequence[str] | None, mesh_info: dict) -> dict:
    return {"command": args.command, "argv": list(argv) if argv is not None else sys.argv[1:],
            "mesh": mesh_info, "seed": args.seed, "versions": versions(),
            "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def _mu_record(spec: MuSpec, mu: float) -> dict:
    return {"given": spec.text, "relative": spec.relative, "value": mu}


def _finish(args: argparse.Namespace, out: Path, summary: dict) -> None:
    write_json(out / "summary.json", summary)
    if args.json:
        print(json.dumps(to_jsonable(summary), ensure_ascii=False))


# ---------------------------------------------------------------------------- commands


def _cmd_modes(args: argparse.Namespace, argv: Sequence[str] | None) -> int:
    import mesh
    from objectives.cmm import compressed_modes

    say, t_all = _Progress(args.quiet, args.json), time.perf_counter()
    timings: dict[str, float] = {}
    t = time.perf_counter()
    m, mesh_info = _load(args.mesh)
    _check_k(args.k, m.n_vertices)
    lap = mesh.laplacian(m)
    timings["load_and_laplacian"] = time.perf_counter() - t
    mu = args.mu.resolve(m.n_vertices)
    say(f"mesh {mesh_info['source']}: n = {m.n_vertices} vertices, {m.n_faces} faces")
    out = _out_dir(args)
    extra: dict[str, Any] = {}
    U = None
    if args.method == "fast":
        d = args.samples or max(10 * args.k, m.n_vertices // 10)
        d = min(d, m.n_vertices)
        t = time.perf_counter()
        U = mesh.local_functions(m, n_samples=d).U
        timings["local_functions"] = time.perf_counter() - t
        say(f"local functions: d = {d}")
    solver = _solver(args, args.method, args.smoothing, local_functions=U)
    say(f"solving: k = {args.k}, mu = {mu:.6g} ({args.mu.text}), method = {args.method}, "
        f"smoothing = {args.smoothing}, weighting = {args.weighting}")
    partial = _partial_writer(args.method, compressed_modes, out, say)
    if partial is not None:
        extra["callback"] = partial
    t = time.perf_counter()
    res = compressed_modes(lap, args.k, mu, solver=solver, weighting=args.weighting, seed=args.seed, **extra)
    timings["solve_total"] = time.perf_counter() - t
    timings["solve_wall"] = float(res.wall_time)
    timings["compile"] = float(res.compile_time)
    say(f"solved: status = {res.status}, iterations = {res.iterations}, objective = {res.objective:.6g}, "
        f"orthogonality = {res.orthogonality:.2e}")

    t = time.perf_counter()
    diag = {"objective": res.objective, "dirichlet": res.dirichlet, "l1": res.l1, "sparsity": res.sparsity,
            "orthogonality": res.orthogonality, "iterations": res.iterations, "status": res.status}
    params = dict(res.params)
    params["mu"] = _mu_record(args.mu, mu)
    files = {"npz": "modes.npz", "ply": "modes.ply"}
    np.savez_compressed(out / "modes.npz", modes=res.modes, compressed_eigenvalues=res.compressed_eigenvalues,
                        vertices=m.vertices, faces=m.faces, mu=mu,
                        diagnostics=json.dumps(to_jsonable(diag)), parameters=json.dumps(to_jsonable(params)))
    write_ply(out / "modes.ply", m.vertices, m.faces, res.modes)
    say(f"wrote {out / 'modes.npz'} and {out / 'modes.ply'}")
    if not args.no_png:
        from .render import contact_sheet

        titles = [f"mode {j}  λ̃ = {lam:.4g}" for j, lam in enumerate(res.compressed_eigenvalues)]
        contact_sheet(out / "modes.png", m.vertices, m.faces, res.modes, titles=titles)
        files["png"] = "modes.png"
        say(f"wrote {out / 'modes.png'}")
    timings["write"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t_all
    summary = _summary_head(args, argv, mesh_info)
    summary.update(parameters=params, mu=mu, diagnostics=diag,
                   compressed_eigenvalues=res.compressed_eigenvalues, timings=timings, files=files,
                   partial_results=_PARTIAL_NOTE if partial is None else "modes.partial.npz during the solve")
    _finish(args, out, summary)
    if partial is not None:
        partial.discard()
    say(f"wrote {out / 'summary.json'}")
    return 0


_PARTIAL_NOTE = ("modes are written when the solve finishes (only --method sequential reports its columns "
                 "as they complete)")


def _solver(args: argparse.Namespace, method: str, smoothing: str, *, local_functions=None):
    """The ``objectives.cmm_solvers`` object for ``--method`` with the flags that apply to it: the manifold
    solvers take ``--smoothing``, ``--gtol`` and ``--max-iters``; ADMM keeps its defaults; fast takes U."""
    from objectives.cmm_solvers import SOLVERS, FastCMM

    if method in ("block", "sequential"):
        return SOLVERS[method](smoothing=smoothing, gtol=args.gtol, max_iters=args.max_iters)
    if method == "fast":
        return FastCMM(local_functions)
    return SOLVERS[method]()


def _partial_writer(method: str, solve, out: Path, say) -> PartialColumns | None:
    """A ``PartialColumns`` saver for ``method="sequential"`` when ``solve`` accepts ``callback=``, else None."""
    import inspect

    if method != "sequential" or "callback" not in inspect.signature(solve).parameters:
        return None
    return PartialColumns(out / "modes.partial.npz", say)


def _cmd_eigs(args: argparse.Namespace, argv: Sequence[str] | None) -> int:
    import mesh

    say, t_all = _Progress(args.quiet, args.json), time.perf_counter()
    m, mesh_info = _load(args.mesh)
    _check_k(args.k, m.n_vertices)
    say(f"mesh {mesh_info['source']}: n = {m.n_vertices} vertices, {m.n_faces} faces")
    lap = mesh.laplacian(m)
    t = time.perf_counter()
    eb = mesh.eigenbasis(lap, args.k, seed=args.seed)
    t_eig = time.perf_counter() - t
    evals, evecs = np.asarray(eb.evals), np.asarray(eb.evecs)
    orth = float(np.max(np.abs(evecs.T @ (lap.A @ evecs) - np.eye(args.k))))
    resid = float(np.max(np.linalg.norm(lap.W @ evecs - (lap.A @ evecs) * evals, axis=0)))
    say(f"eigenpairs: k = {args.k}, λ = {', '.join(f'{v:.4g}' for v in evals[:6])}{' …' if args.k > 6 else ''}")
    out = _out_dir(args)
    np.savez_compressed(out / "eigs.npz", eigenvalues=evals, eigenvectors=evecs, vertices=m.vertices, faces=m.faces)
    summary = _summary_head(args, argv, mesh_info)
    summary.update(parameters={"k": args.k, "laplacian": "cotangent, lumped area, normalised to total area 1"},
                   eigenvalues=evals, diagnostics={"orthogonality": orth, "max_residual": resid},
                   timings={"eigs": t_eig, "total": time.perf_counter() - t_all}, files={"npz": "eigs.npz"})
    _finish(args, out, summary)
    say(f"wrote {out / 'eigs.npz'} and {out / 'summary.json'}")
    return 0


_COLUMNS = ("smoothing", "c1_at_zero", "status", "objective", "dirichlet", "l1", "sparsity_1e-3",
            "orthogonality", "iterations", "time_s")


def _cmd_compare(args: argparse.Namespace, argv: Sequence[str] | None) -> int:
    import mesh
    from objectives import smoothings
    from objectives.cmm import compressed_modes

    names = [s.strip() for s in args.smoothings.split(",") if s.strip()]
    bad = [s for s in names if s not in SMOOTHINGS]
    if bad or not names:
        raise CLIError(f"unknown smoothing(s) {bad or names}; choose from {', '.join(SMOOTHINGS)}")
    say, t_all = _Progress(args.quiet, args.json), time.perf_counter()
    m, mesh_info = _load(args.mesh)
    _check_k(args.k, m.n_vertices)
    lap = mesh.laplacian(m)
    mu = args.mu.resolve(m.n_vertices)
    say(f"mesh {mesh_info['source']}: n = {m.n_vertices}; k = {args.k}, mu = {mu:.6g}, method = {args.method}")
    rows: list[dict] = []
    first_modes: list[tuple[str, np.ndarray]] = []
    for name in names:
        row: dict[str, Any] = {"smoothing": name, "c1_at_zero": smoothings.info(name).c1_at_zero}
        t = time.perf_counter()
        try:
            r = compressed_modes(lap, args.k, mu, solver=_solver(args, args.method, name), weighting=args.weighting,
                                 seed=args.seed, start="eigen")
            row.update(status=r.status, objective=r.objective, dirichlet=r.dirichlet, l1=r.l1,
                       **{"sparsity_1e-3": r.sparsity["1e-3"]}, orthogonality=r.orthogonality,
                       iterations=r.iterations, time_s=time.perf_counter() - t)
            first_modes.append((name, r.modes[:, 0]))
        except Exception as e:  # a smoothing that breaks the solver (f0) is reported, not fatal
            row.update(status=f"failed: {type(e).__name__}: {' '.join(str(e).split())[:120]}",
                       time_s=time.perf_counter() - t)
        rows.append(row)
        say(f"{name}: {row['status']}, objective = {row.get('objective', float('nan')):.6g}, "
            f"{row['time_s']:.2f}s")
    out = _out_dir(args)
    _write_table(out, rows)
    files = {"markdown": "comparison.md", "csv": "comparison.csv"}
    if first_modes and not args.no_png:
        from .render import contact_sheet

        # the first mode of each smoothing, one row each (cf. thesis Fig. 6.10–6.11)
        contact_sheet(out / "comparison.png", m.vertices, m.faces, np.stack([f for _, f in first_modes], axis=1),
                      titles=[f"{n}: first mode" for n, _ in first_modes])
        files["png"] = "comparison.png"
    summary = _summary_head(args, argv, mesh_info)
    summary.update(parameters={"k": args.k, "mu": _mu_record(args.mu, mu), "method": args.method,
                               "weighting": args.weighting, "start": "eigen", "gtol": args.gtol,
                               "max_iters": args.max_iters},
                   mu=mu, results=rows, timings={"total": time.perf_counter() - t_all}, files=files)
    _finish(args, out, summary)
    say(f"wrote {out / 'comparison.md'}, {out / 'comparison.csv'} and {out / 'summary.json'}")
    return 0


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return "" if v is None else str(v)


def _write_table(out: Path, rows: list[dict]) -> None:
    """``comparison.csv`` and ``comparison.md`` with the columns ``_COLUMNS``."""
    import csv

    with open(out / "comparison.csv", "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=_COLUMNS, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({c: r.get(c, "") for c in _COLUMNS})
    lines = ["| " + " | ".join(_COLUMNS) + " |", "|" + "---|" * len(_COLUMNS)]
    lines += ["| " + " | ".join(_fmt(r.get(c)) for c in _COLUMNS) + " |" for r in rows]
    (out / "comparison.md").write_text("\n".join(lines) + "\n", encoding="utf-8")


# ---------------------------------------------------------------------------- entry point


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; return the exit code (0 ok, 1 bad input, 2 bad arguments)."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse: -h (0) or a usage error (2, already reported)
        return int(e.code or 0)

    import jax

    # An application may set JAX's global configuration (the library never does).
    jax.config.update("jax_enable_x64", True)
    import mesh

    try:
        return int(args.run(args, argv))
    except (CLIError, mesh.MeshError, FileNotFoundError, OSError, ValueError) as e:
        kind = "" if isinstance(e, (CLIError, mesh.MeshError)) else f"{type(e).__name__}: "
        stderr_line(f"{PROG}: error: {kind}{e}")
        return 1
    except KeyboardInterrupt:
        stderr_line(f"{PROG}: error: interrupted")
        return 130


def _entry() -> None:
    sys.exit(main())


if __name__ == "__main__":
    _entry()
