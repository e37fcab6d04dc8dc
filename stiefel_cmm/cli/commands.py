"""The ``stiefel`` subcommands ``modes``, ``eigs`` and ``compare-smoothings`` (parsed by ``stiefel_cmm.cli.main``).

Each ``cmd_*(args, argv, run)`` loads the mesh, solves, stages its files in ``run``
(``stiefel_cmm.cli.run_dir.RunDir``, already validated and locked) and commits them with ``summary.json``
last. Nothing heavy is imported at module level (``mesh``, ``objectives``, numpy are imported
by the commands), so a Ctrl-C during start-up reaches ``stiefel_cmm.cli.main.main``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any, Callable, Sequence

from .options import GTOL, METHODS, solver_from_args
from .outputs import MuSpec, PartialColumns, to_jsonable, write_ply
from .progress import SolveProgress
from .run_dir import RunDir

from .common import (CLIError, _Progress, _check_k, _exit_code, _finish, _interrupted_solve, _laplacian_text, _load, _mu_record, _picture, _resolve_mu, _start, _summary_head, _viewer)

__all__ = ["CLIError", "cmd_modes", "cmd_eigs", "cmd_compare", "outputs_of", "GTOL", "METHODS"]

PARTIAL = "modes.partial.npz"


def cmd_modes(args: argparse.Namespace, argv: Sequence[str] | None, run: RunDir) -> int:
    import mesh
    import numpy as np
    from objectives import smoothings
    from objectives.cmm.modes import compressed_modes, select_mu

    say, t_all, out = _Progress(args.quiet, args.json), time.perf_counter(), run.path
    timings: dict[str, float] = {}
    t = time.perf_counter()
    m, lap, mesh_info = _load(args.mesh, args.weights, args.area)
    _check_k(args.k, m.n_vertices)
    start = _start(args, m.n_vertices)
    say(f"mesh {mesh_info['source']}: n = {m.n_vertices} vertices, {m.n_faces} faces")
    extra: dict[str, Any] = {}
    pairs = None
    if args.target_sparsity is None:
        spec, mu, pairs = _resolve_mu(args, lap, m.n_vertices)
        if pairs is not None:  # computed for μ: the solve reuses them (start, preconditioner shift)
            extra["eigenpairs"] = pairs
    timings["load_s"] = time.perf_counter() - t
    U = None
    if args.method == "fast":
        d = args.samples or max(10 * args.k, m.n_vertices // 10)
        d = min(d, m.n_vertices)
        t = time.perf_counter()
        U = mesh.local_functions(m, n_samples=d).U
        timings["local_functions_s"] = time.perf_counter() - t
        say(f"local functions: d = {d}")
    solver, passed = solver_from_args(args, args.method, args.smoothing, local_functions=U)
    smoothing = f"{args.smoothing} ({smoothings.info(args.smoothing).note.split(' ')[0].lower()})"
    target = f"target sparsity {args.target_sparsity:g}" if args.target_sparsity is not None else None
    say(f"solving: k = {args.k}, mu = {target or f'{mu:.6g} ({spec.text})'}, method = {args.method}, "
        f"smoothing = {smoothing}, weighting = {args.weighting}, start = {args.start}")
    if not args.finish:
        extra["finish"] = None  # the smoothed solver's modes and status (the default finishes them)
    partial = _partial_writer(args.method, compressed_modes, out, say)
    if partial is not None:
        extra["callback"] = partial
    t = time.perf_counter()
    bar = SolveProgress(quiet=args.quiet, label=f"{args.method}")
    trials = None
    try:
        if target is None:
            res = compressed_modes(lap, args.k, mu, solver=solver, weighting=args.weighting, seed=args.seed,
                                   start=start, progress=bar, **extra)
        else:
            mu, res, trials = select_mu(lap, args.k, args.target_sparsity, solver=solver, weighting=args.weighting,
                                        seed=args.seed, start=start, progress=bar, **extra)
            spec = MuSpec(f"{mu!r}", mu, "")
            say(f"mu = {mu:.6g} gives sparsity {res.sparsity['1e-3']:.3f} ({len(trials)} solves)")
    finally:
        bar.close()
    solve_total = time.perf_counter() - t
    timings.update(compile_s=float(res.compile_time), solve_s=float(res.wall_time),
                   setup_s=timings.pop("load_s") + timings.pop("local_functions_s", 0.0)
                   + max(0.0, solve_total - res.wall_time - res.compile_time))
    interrupt = _interrupted_solve(args, res.status)
    say(f"solved: status = {res.status}, iterations = {res.iterations}, objective = {res.objective:.6g}, "
        f"orthogonality = {res.orthogonality:.2e}")
    if res.finish is not None:
        say(f"finish: status = {res.finish['status']}, objective {res.finish['objective_before']:.6g} -> "
            f"{res.objective:.6g}, exact zeros {100 * res.exact_zeros:.1f} %, l1 residual {res.l1_residual:.1e}, "
            f"{res.finish['wall_time']:.2f} s")

    t = time.perf_counter()
    support = res.support_areas  # measured: the share of the area where a mode is not exactly zero
    diag = {"objective": res.objective, "dirichlet": res.dirichlet, "l1": res.l1, "sparsity": res.sparsity,
            "support_area": support, "orthogonality": res.orthogonality, "iterations": res.iterations,
            "status": res.status, "exact_zeros": res.exact_zeros, "support_sizes": res.support_sizes,
            "support_areas": res.support_areas, "l1_residual": res.l1_residual, "finish": res.finish}
    params = dict(res.params)
    params["mu"] = _mu_record(spec, mu, pairs) if target is None else {"target_sparsity": args.target_sparsity,
                                                                 "value": mu, "trials": trials}
    params["laplacian"] = _laplacian_text(args.weights, args.area)
    params["start"] = str(args.start)
    run.write("npz", "modes.npz", lambda fh: np.savez_compressed(
        fh, modes=res.modes, compressed_eigenvalues=res.compressed_eigenvalues, vertices=m.vertices,
        faces=m.faces, mu=mu, diagnostics=json.dumps(to_jsonable(diag)), parameters=json.dumps(to_jsonable(params)),
        **({} if res.smooth_modes is None else {"smooth_modes": res.smooth_modes})))
    run.write("ply", "modes.ply", lambda fh: write_ply(fh, m.vertices, m.faces, res.modes, ascii=args.ascii_ply))
    viewer = _viewer(args, run, "modes.html", m, res.modes, [f"mode {j}" for j in range(args.k)],
                     [f"λ̃ = {lam:.6g} · support {100 * s:.1f} %" for lam, s in zip(res.compressed_eigenvalues, support)],
                     f"{mesh_info['source']}: compressed manifold modes (μ = {mu:.4g})")
    picture_error = None
    if not args.no_png:
        from .render import contact_sheet

        titles = [f"mode {j} · λ̃ = {lam:.4g} · support {100 * s:.1f} %"
                  for j, (lam, s) in enumerate(zip(res.compressed_eigenvalues, support))]
        picture_error = _picture(run, "modes.png", lambda path: contact_sheet(
            path, m.vertices, m.faces, res.modes, titles=titles, up=args.up))
    summary = _summary_head(args, argv, mesh_info)
    summary.update(parameters=params, solver_options=passed, mu=mu, diagnostics=diag,
                   compressed_eigenvalues=res.compressed_eigenvalues, timings=timings,
                   partial_results=_PARTIAL_NOTE if partial is None else "modes.partial.npz during the solve")
    if interrupt is not None:
        summary["interrupted"] = interrupt
    if viewer is not None:
        summary["viewer"] = viewer
    if picture_error:
        summary["picture_error"] = picture_error
    timings["write_s"] = time.perf_counter() - t  # the commit (summary.json and the move) is not included
    timings["total_s"] = time.perf_counter() - t_all
    _finish(args, run, summary)
    say(f"wrote {out / 'modes.npz'} and {out / 'modes.ply'}")
    if "png" in run.files:
        say(f"wrote {out / 'modes.png'}")
    say(f"wrote {out / 'summary.json'}")
    return _exit_code(interrupt)


_PARTIAL_NOTE = ("modes are written when the solve finishes (only --method sequential reports its columns "
                 "as they complete)")


def _partial_writer(method: str, solve: Callable, out: Path, say: Callable[[str], None]) -> PartialColumns | None:
    """A ``PartialColumns`` saver for ``method="sequential"`` when ``solve`` accepts ``callback=``, else None."""
    import inspect

    if method != "sequential" or "callback" not in inspect.signature(solve).parameters:
        return None
    return PartialColumns(out / PARTIAL, say)


def cmd_eigs(args: argparse.Namespace, argv: Sequence[str] | None, run: RunDir) -> int:
    import mesh
    import numpy as np

    say, t_all, out = _Progress(args.quiet, args.json), time.perf_counter(), run.path
    m, lap, mesh_info = _load(args.mesh, args.weights, args.area)
    _check_k(args.k, m.n_vertices)
    t_setup = time.perf_counter() - t_all
    say(f"mesh {mesh_info['source']}: n = {m.n_vertices} vertices, {m.n_faces} faces")
    t = time.perf_counter()
    bar = SolveProgress(quiet=args.quiet, label="eigsh")
    try:
        eb = mesh.eigenbasis(lap, args.k, seed=args.seed, progress=bar)
    finally:
        bar.close()
    t_eig = time.perf_counter() - t
    t = time.perf_counter()
    evals, evecs = np.asarray(eb.evals), np.asarray(eb.evecs)
    orth = float(np.max(np.abs(evecs.T @ (lap.A @ evecs) - np.eye(args.k))))
    resid = float(np.max(np.linalg.norm(lap.W @ evecs - (lap.A @ evecs) * evals, axis=0)))
    say(f"eigenpairs: k = {args.k}, λ = {', '.join(f'{v:.4g}' for v in evals[:6])}{' …' if args.k > 6 else ''}")
    run.write("npz", "eigs.npz", lambda fh: np.savez_compressed(fh, eigenvalues=evals, eigenvectors=evecs,
                                                                vertices=m.vertices, faces=m.faces))
    run.write("ply", "eigs.ply", lambda fh: write_ply(fh, m.vertices, m.faces, evecs,
                                                      [f"eig_{j}" for j in range(args.k)], ascii=args.ascii_ply))
    viewer = _viewer(args, run, "eigs.html", m, evecs, [f"eigenfunction {j}" for j in range(args.k)],
                     [f"λ = {lam:.6g}" for lam in evals], f"{mesh_info['source']}: Laplacian eigenfunctions")
    picture_error = None
    if not args.no_png:
        from .render import contact_sheet

        titles = [f"eigenfunction {j}  λ = {lam:.4g}" for j, lam in enumerate(evals)]
        picture_error = _picture(run, "eigs.png", lambda path: contact_sheet(path, m.vertices, m.faces, evecs,
                                                                              titles=titles, up=args.up))
    summary = _summary_head(args, argv, mesh_info)
    summary.update(parameters={"k": args.k, "laplacian": _laplacian_text(args.weights, args.area)},
                   eigenvalues=evals, diagnostics={"orthogonality": orth, "max_residual": resid},
                   timings={"compile_s": 0.0, "solve_s": t_eig, "setup_s": t_setup,
                            "write_s": time.perf_counter() - t, "total_s": time.perf_counter() - t_all})
    if viewer is not None:
        summary["viewer"] = viewer
    if picture_error:
        summary["picture_error"] = picture_error
    _finish(args, run, summary)
    say(f"wrote {out / 'eigs.npz'}, {out / 'eigs.ply'}{', ' + str(out / 'eigs.png') if 'png' in run.files else ''} "
        f"and {out / 'summary.json'}")
    return 0


def outputs_of(args: argparse.Namespace) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``(names this run may write, names the command always owns)`` for ``RunDir``."""
    png = (() if getattr(args, "no_png", True) else ("png",)) + (("html",) if getattr(args, "html", False) else ())
    if args.command == "modes":
        return ("modes.npz", "modes.ply") + tuple(f"modes.{e}" for e in png), (PARTIAL, PARTIAL + PartialColumns.TMP_SUFFIX)
    if args.command == "eigs":
        return ("eigs.npz", "eigs.ply") + tuple(f"eigs.{e}" for e in png), ()
    return ("comparison.md", "comparison.csv") + tuple(f"comparison.{e}" for e in png), ()


def cmd_compare(args: argparse.Namespace, argv: Sequence[str] | None, run: RunDir) -> int:
    """``stiefel compare-smoothings`` (``stiefel_cmm.cli.compare``)."""
    from .compare import cmd_compare as run_compare

    return run_compare(args, argv, run)
