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
from .outputs import PROG, MuSpec, PartialColumns, stderr_line, to_jsonable, write_ply
from .progress import SolveProgress
from .run_dir import RunDir

from .common import (CLIError, _Progress, _check_k, _exit_code, _finish, _interrupted_solve, _laplacian_text, _load,
                     _mu_record, _picture, _resolve_mu, _solve_signals, _start, _summary_head, _viewer)

__all__ = ["CLIError", "cmd_modes", "cmd_eigs", "cmd_compare", "outputs_of", "GTOL", "METHODS"]

PARTIAL = "modes.partial.npz"
#: ``--target-sparsity``: the sparsity measured (a key of ``CMMResult.sparsity``) and how close counts as reached
#: (passed to ``select_mu`` and used to judge its answer)
TARGET_THRESHOLD = "1e-3"
TARGET_TOL = 0.02
#: the exit code of a run whose outputs are written but fall short of what was asked (an unreachable target)
EXIT_BEST_EFFORT = 3


class _SearchInterrupted(BaseException):
    """Raised by the μ search's ``stop`` once a signal came: ends ``select_mu`` (which would go on to its next
    trial after an interrupted one); becomes the ``KeyboardInterrupt`` it stands for."""


def _search_stop(stop: Any) -> Callable[[], bool] | None:
    """``stop=`` for ``select_mu``'s solves: raises ``_SearchInterrupted`` once ``stop.event`` is set."""
    if stop is None:
        return None

    def check() -> bool:
        if stop.event.is_set():
            raise _SearchInterrupted
        return False

    return check


def _best_effort(target: float, res: Any, mu: float, trials: list, n: int) -> dict | None:
    """None when ``select_mu`` reached ``target``; else what ``summary.json`` says (``best_effort``).

    Reached: the sparsities of the solves bracket the target (some at or below it, some at or above) and the
    answer is within ``TARGET_TOL`` of it. A search that never bracketed it spent its solves widening μ
    towards a sparsity it cannot get (e.g. above ``1 − 1/n``: each mode keeps its largest entry), and its μ is
    only the last one tried."""
    reached = float(res.sparsity[TARGET_THRESHOLD])
    seen = [float(t[1]) for t in trials]
    low, high = min(seen), max(seen)
    if low <= target <= high and abs(reached - target) <= TARGET_TOL:
        return None
    if high < target:
        why = (f"all {len(trials)} solves stayed below it (the sparsest, {high:.6g}, up to "
               f"μ = {max(t[0] for t in trials):.4g})")
        if target > 1 - 1 / n:
            why += f"; no modes can be sparser than 1 − 1/n = {1 - 1 / n:.6g} (each keeps its largest entry)"
    elif low > target:
        why = (f"all {len(trials)} solves stayed above it (the least sparse, {low:.6g}, down to "
               f"μ = {min(t[0] for t in trials):.4g})")
    else:
        why = f"the closest of {len(trials)} solves has sparsity {reached:.6g}, not within ±{TARGET_TOL:g}"
    return {"reason": f"target sparsity {target:g} not reached: {why}; written: μ = {mu:.4g}, sparsity {reached:.6g}",
            "target_sparsity": target, "sparsity": reached, "mu": mu, "solves": len(trials),
            "sparsity_range": [low, high], "exit_code": EXIT_BEST_EFFORT}


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
    trials, best_effort = None, None
    # SIGINT and SIGTERM alike: the solve stops at its next check and its modes are written (_solve_signals);
    # a μ search (several solves) is abandoned instead, nothing written
    soft = target is None and args.method != "sequential"
    with _solve_signals(args, bar, soft=soft) as (progress, stop):
        try:
            if target is None:
                res = compressed_modes(lap, args.k, mu, solver=solver, weighting=args.weighting, seed=args.seed,
                                       start=start, progress=progress, stop=None if stop is None else stop.event,
                                       **extra)
            else:
                mu, res, trials = select_mu(lap, args.k, args.target_sparsity, solver=solver,
                                            weighting=args.weighting, seed=args.seed, start=start, progress=progress,
                                            stop=_search_stop(stop), threshold=TARGET_THRESHOLD, tol=TARGET_TOL,
                                            **extra)
        except _SearchInterrupted:
            raise KeyboardInterrupt from None
        finally:
            bar.close()
    stopped = stop is not None and stop.event.is_set()
    if target is not None:
        if stopped:  # a trial was interrupted and select_mu went on: the search is not complete
            raise KeyboardInterrupt
        spec = MuSpec(f"{mu!r}", mu, "")
        say(f"mu = {mu:.6g} gives sparsity {res.sparsity[TARGET_THRESHOLD]:.3f} ({len(trials)} solves)")
        best_effort = _best_effort(args.target_sparsity, res, mu, trials, m.n_vertices)
    solve_total = time.perf_counter() - t
    timings.update(compile_s=float(res.compile_time), solve_s=float(res.wall_time),
                   setup_s=timings.pop("load_s") + timings.pop("local_functions_s", 0.0)
                   + max(0.0, solve_total - res.wall_time - res.compile_time))
    interrupt = _interrupted_solve(args, res.status, stopped)
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
    params["mu"] = _mu_record(spec, mu, pairs) if target is None else {
        "target_sparsity": args.target_sparsity, "value": mu, "trials": trials, "threshold": TARGET_THRESHOLD,
        "tolerance": TARGET_TOL, "reached": best_effort is None}
    # what summary.json says of the result (the viewer page shows the same status)
    outcome: dict[str, Any] = {"command": "modes", "diagnostics": diag}
    if interrupt is not None:
        outcome["interrupted"] = interrupt
    if best_effort is not None:
        outcome["best_effort"] = best_effort
    params["laplacian"] = _laplacian_text(args.weights, args.area)
    params["start"] = str(args.start)
    run.write("npz", "modes.npz", lambda fh: np.savez_compressed(
        fh, modes=res.modes, compressed_eigenvalues=res.compressed_eigenvalues, vertices=m.vertices,
        faces=m.faces, mu=mu, diagnostics=json.dumps(to_jsonable(diag)), parameters=json.dumps(to_jsonable(params)),
        **({} if res.smooth_modes is None else {"smooth_modes": res.smooth_modes})))
    run.write("ply", "modes.ply", lambda fh: write_ply(fh, m.vertices, m.faces, res.modes, ascii=args.ascii_ply))
    viewer = _viewer(args, run, "modes.html", m, res.modes, [f"mode {j}" for j in range(args.k)],
                     [f"λ̃ = {lam:.6g} · support {100 * s:.1f} %" for lam, s in zip(res.compressed_eigenvalues, support)],
                     f"{mesh_info['source']}: compressed manifold modes (μ = {mu:.4g})", outcome)
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
    summary.update({key: outcome[key] for key in ("interrupted", "best_effort") if key in outcome})
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
    if interrupt is None and best_effort is not None:
        stderr_line(f"{PROG}: error: {best_effort['reason']} as a best effort (summary.json: best_effort); choose a "
                    f"target sparsity between {best_effort['sparsity_range'][0]:.4g} and "
                    f"{best_effort['sparsity_range'][1]:.4g}")
        return EXIT_BEST_EFFORT
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
