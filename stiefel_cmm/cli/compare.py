"""``stiefel compare-smoothings``: the ℓ1 smoothings of ``objectives.energy.smoothings`` from one start.

Every smoothing is solved by one compiled solver (``runtime_smoothing=True``) from the same eigenbasis
start; the table (``comparison.md``, ``comparison.csv``) gives each smoothing's real name, objective,
sparsity and times, and ``comparison.png`` a smoothing × mode grid of the modes, matched across the
smoothings (each row's modes permuted and signed to best agree with the first row's).
"""

from __future__ import annotations

import argparse
import time
from typing import Any, Sequence

from .common import (_check_k, _exit_code, _finish, _interrupted_solve, _laplacian_text, _load, _mu_record, _picture,
                     _Progress, _resolve_mu, _solve_signals, _summary_head)
from .options import GTOL, solver_from_args
from .progress import SolveProgress
from .run_dir import RunDir

__all__ = ["cmd_compare", "match_modes"]


_COLUMNS = ("smoothing", "name", "c1_at_zero", "status", "objective", "smoothed_objective", "dirichlet", "l1",
            "exact_zeros", "l1_residual", "sparsity_1e-3", "orthogonality", "iterations", "time_s", "compile_s")


def display_name(name: str) -> str:
    """``"huber (f6)"``: a smoothing's first alias in ``objectives.energy.smoothings.ALIASES`` and its Table 6.1 name."""
    from objectives import smoothings

    alias = next((a for a, c in smoothings.ALIASES.items() if c == name), None)
    return f"{alias} ({name})" if alias else name


def match_modes(ref: Any, X: Any, area: Any) -> tuple[Any, Any]:
    """``(order (k,), signs (k,))`` so that ``X[:, order] * signs`` best matches ``ref`` column by column:
    the assignment maximising ``Σ_j |⟨ref_j, X_order(j)⟩_A|`` (``scipy.optimize.linear_sum_assignment``),
    each column signed to a non-negative A-inner product with its match. ``ref, X``: ``(n, k)``; ``area``: ``(n,)``."""
    import numpy as np
    from scipy.optimize import linear_sum_assignment

    G = np.asarray(ref).T @ (np.asarray(area)[:, None] * np.asarray(X))   # (k, k) A-inner products
    _, order = linear_sum_assignment(-np.abs(G))
    signs = np.where(G[np.arange(G.shape[0]), order] < 0, -1.0, 1.0)
    return order, signs


def cmd_compare(args: argparse.Namespace, argv: Sequence[str] | None, run: RunDir) -> int:
    from objectives import smoothings
    from objectives.cmm.modes import compressed_modes, first_eigenpairs, unpack_laplacian

    names = list(args.smoothings)
    say, t_all, out = _Progress(args.quiet, args.json), time.perf_counter(), run.path
    m, lap, mesh_info = _load(args.mesh, args.weights, args.area)
    _check_k(args.k, m.n_vertices)
    spec, mu, pairs = _resolve_mu(args, lap, m.n_vertices)
    if pairs is None:
        pairs = first_eigenpairs(*unpack_laplacian(lap), max(args.k, 2))  # the start of every smoothing, once
    say(f"mesh {mesh_info['source']}: n = {m.n_vertices}; k = {args.k}, mu = {mu:.6g} ({spec.text}), "
        f"method = {args.method}")
    t_setup = time.perf_counter() - t_all
    rows: list[dict] = []
    solved: list[tuple[dict, Any]] = []
    passed: dict[str, Any] = {}
    interrupt = None
    totals = {"compile_s": 0.0, "solve_s": 0.0}
    for name in names:
        row: dict[str, Any] = {"smoothing": name, "name": display_name(name).split(" ")[0],
                               "c1_at_zero": smoothings.info(name).c1_at_zero}
        if interrupt is not None:
            rows.append({**row, "status": "not run (interrupted)"})
            continue
        t = time.perf_counter()
        bar = SolveProgress(quiet=args.quiet, label=name)
        try:
            solver, passed = solver_from_args(args, args.method, name, runtime_smoothing=True)
            # SIGINT/SIGTERM: this smoothing stops at its next check, its modes are kept, the rest are not run
            with _solve_signals(args, bar, soft=args.method != "sequential") as (progress, stop):
                r = compressed_modes(lap, args.k, mu, solver=solver, weighting=args.weighting, seed=args.seed,
                                     start="eigen", progress=progress, stop=None if stop is None else stop.event,
                                     eigenpairs=pairs, **({} if args.finish else {"finish": None}))
            stopped = stop is not None and stop.event.is_set()
            # smoothed_objective: the smoothing's own answer (before the finish; = objective with --no-finish)
            row.update(status=r.status, objective=r.objective, dirichlet=r.dirichlet, l1=r.l1,
                       smoothed_objective=r.finish["objective_before"] if r.finish else r.objective,
                       exact_zeros=r.exact_zeros, l1_residual=r.l1_residual,
                       **{"sparsity_1e-3": r.sparsity["1e-3"]}, orthogonality=r.orthogonality,
                       iterations=r.iterations, time_s=time.perf_counter() - t, compile_s=r.compile_time)
            totals["compile_s"] += r.compile_time
            totals["solve_s"] += r.wall_time
            solved.append((row, r.modes))
            interrupt = _interrupted_solve(args, r.status, stopped)
        except Exception as e:  # a smoothing that breaks the solver (f0) is reported, not fatal
            row.update(status=f"failed: {type(e).__name__}: {' '.join(str(e).split())[:120]}",
                       time_s=time.perf_counter() - t)
        finally:
            bar.close()
        rows.append(row)
        say(f"{display_name(name)}: {row['status']}, objective = {row.get('objective', float('nan')):.6g}, "
            f"{row['time_s']:.2f}s")
    t = time.perf_counter()
    md, csv_text = _tables(rows)
    run.write_text("markdown", "comparison.md", md)
    run.write_text("csv", "comparison.csv", csv_text)
    picture_error = None
    if solved and not args.no_png:
        picture_error = _picture(run, "comparison.png", lambda path: _grid(path, m, lap, solved, args.up))
    summary = _summary_head(args, argv, mesh_info)
    summary.update(parameters={"k": args.k, "mu": _mu_record(spec, mu, pairs), "method": args.method,
                               "laplacian": _laplacian_text(args.weights, args.area),
                               "weighting": args.weighting, "start": "eigen",
                               "gtol": GTOL if args.gtol is None else args.gtol, "max_iters": args.max_iters,
                               "finish": bool(args.finish)},
                   solver_options={k: v for k, v in passed.items() if k != "smoothing"},
                   mu=mu, results=rows)
    if interrupt is not None:
        summary["interrupted"] = interrupt
    if picture_error:
        summary["picture_error"] = picture_error
    write_s, total_s = time.perf_counter() - t, time.perf_counter() - t_all
    # setup: the mesh and Laplacian, and each solve's eigenbasis and factorisation
    setup_s = t_setup + max(0.0, total_s - t_setup - write_s - totals["compile_s"] - totals["solve_s"])
    summary["timings"] = {**totals, "setup_s": setup_s, "write_s": write_s, "total_s": total_s}
    _finish(args, run, summary)
    say(f"wrote {out / 'comparison.md'}, {out / 'comparison.csv'} and {out / 'summary.json'}")
    return _exit_code(interrupt)


def _grid(path: Any, m: Any, lap: Any, solved: list[tuple[dict, Any]], up: str | None) -> None:
    """``comparison.png``: smoothing × mode, each row's modes matched to the first row's (``match_modes``)."""
    import numpy as np

    from .render import grid_sheet

    area = np.asarray(lap.A.diagonal())
    ref = np.asarray(solved[0][1])
    fields, titles = [], []
    for row, modes in solved:
        order, signs = match_modes(ref, modes, area)
        fields.append(np.asarray(modes)[:, order] * signs)
        titles.append(f"{display_name(row['smoothing'])} · objective {row['objective']:.5g} · "
                      f"sparsity {100 * row['sparsity_1e-3']:.0f} %")
    cols = [f"mode {j}" for j in range(ref.shape[1])]
    grid_sheet(path, m.vertices, m.faces, fields, row_titles=titles, col_titles=cols, up=up)


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    return "" if v is None else str(v)


def _tables(rows: list[dict]) -> tuple[str, str]:
    """``(markdown, csv)`` texts of ``rows`` with the columns ``_COLUMNS``."""
    import csv
    import io

    buf = io.StringIO(newline="")
    w = csv.DictWriter(buf, fieldnames=_COLUMNS, extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow({c: r.get(c, "") for c in _COLUMNS})
    lines = ["| " + " | ".join(_COLUMNS) + " |", "|" + "---|" * len(_COLUMNS)]
    lines += ["| " + " | ".join(_fmt(r.get(c)) for c in _COLUMNS) + " |" for r in rows]
    return "\n".join(lines) + "\n", buf.getvalue()


