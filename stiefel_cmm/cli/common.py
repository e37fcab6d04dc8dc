"""What the ``stiefel`` subcommands share: the mesh source, μ, the summary's head, pictures, interrupts.

``stiefel_cmm.cli.commands`` (``modes``, ``eigs``) and ``stiefel_cmm.cli.compare`` (``compare-smoothings``)
both build on these; nothing heavy is imported at module level.
"""


import argparse
import contextlib
import json
import signal
import sys
import time
import warnings
from pathlib import Path
from typing import Any, Callable, Iterator, Sequence

from .options import DEFAULT_MU, StartFile, load_start
from .outputs import PROG, MuSpec, parse_mu, stderr_line, to_jsonable, versions
from .run_dir import RunDir

class CLIError(Exception):
    """Bad input detected by the CLI; reported as one line, exit code 1."""


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


def _laplacian_text(weights: str, area: str) -> str:
    kind = ("intrinsic-Delaunay cotangent (robust_laplacian, tufted cover)" if weights == "robust" else weights)
    return f"{kind} weights, {area} areas, normalised to total area 1"


EXAMPLE_PREFIX = "example:"


def example_name(source: str) -> str:
    """The name of ``mesh.examples`` that ``example:NAME`` asks for (``CLIError`` naming the choices)."""
    from mesh.examples import EXAMPLES

    name = source[len(EXAMPLE_PREFIX):]
    if name not in EXAMPLES:
        raise CLIError(f"unknown example mesh {name!r} in {source!r}; choose from "
                       f"{', '.join(EXAMPLE_PREFIX + e for e in EXAMPLES)}")
    return name


def _load(source: str | None, weights: str = "cotangent", area: str = "lumped") -> tuple[Any, Any, dict]:
    """``(mesh.Mesh, mesh.Laplacian, description)`` for a path, ``example:NAME`` or the demo mesh.

    Every change ``mesh.load`` made (``report.lines()``) and every warning is printed to stderr
    and recorded in the description (``summary.json``'s ``mesh``); ``weights="robust"`` admits
    non-manifold meshes.
    """
    import mesh

    robust = weights == "robust"
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if source is None:
            from .demo_mesh import DEMO_NAME, demo_mesh

            m = mesh.load(demo_mesh(), warn=False, allow_nonmanifold=robust)
            name = DEMO_NAME
        elif source.startswith(EXAMPLE_PREFIX) and not Path(source).is_file():
            m = mesh.example(example_name(source), allow_nonmanifold=robust)
            name = source
        else:
            path = Path(source)
            if not path.is_file():
                raise CLIError(f"mesh file not found: {source}")
            m = mesh.load(path, warn=False, allow_nonmanifold=robust)  # NonManifoldError names --laplacian robust
            name = str(path.resolve())
        report = m.report.lines()
        for line in report:
            stderr_line(f"{PROG}: mesh changed or found: {line}")
        lap = mesh.laplacian(m, weights=weights, area=area)
    messages = [" ".join(str(w.message).split()) for w in caught]
    for msg in dict.fromkeys(messages):  # each distinct warning once
        stderr_line(f"{PROG}: warning: {msg}")
    info = {"source": name, "n_vertices": m.n_vertices, "n_faces": m.n_faces, "n_components": m.n_components,
            "n_boundary_loops": m.n_boundary_loops, "euler_characteristic": m.euler_characteristic,
            "n_nonmanifold_edges": m.n_nonmanifold_edges, "laplacian": _laplacian_text(weights, area),
            "changes": report, "cleaning_report": m.report.as_dict(), "warnings": list(dict.fromkeys(messages))}
    return m, lap, info


def _check_k(k: int, n: int) -> None:
    if k >= n:
        raise CLIError(f"k = {k} must be smaller than the number of vertices n = {n}")


def _program_counts() -> dict:
    """This process's solver programs (``stiefel.runtime.program_cache``): ``loaded`` from the store (key and
    SHA-256 verified), ``rejected`` stored files (another program's, corrupt, an older format, unreadable by
    JAX: traced again; ``rejected_reasons`` counts them by reason), ``traced`` (and exported), ``stored``
    (written; 0 in a read-only cache) and ``reused`` from memory."""
    from stiefel.runtime.program_cache import REJECTIONS, STATS

    return {"loaded": STATS["loaded"], "rejected": STATS["rejected"], "traced": STATS["exported"],
            "stored": STATS["stored"], "reused": STATS["memory"], "rejected_reasons": dict(sorted(REJECTIONS.items()))}


def _summary_head(args: argparse.Namespace, argv: Sequence[str] | None, mesh_info: dict) -> dict:
    return {"command": args.command, "argv": list(argv) if argv is not None else sys.argv[1:],
            "mesh": mesh_info, "seed": args.seed, "versions": versions(),
            "compilation_cache": getattr(args, "cache_used", None),
            # this run's solver programs: from the store (no tracing), traced and stored, reused in the run
            "stored_programs": _program_counts() if getattr(args, "cache_used", None) else None,
            "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}


def _mu_record(spec: MuSpec, mu: float, pairs: Any = None) -> dict:
    unit = {"": "absolute", "n": "times the vertex count", "λ": "times λ_(k−1)"}[spec.unit]
    record = {"given": spec.text, "relative": spec.relative, "unit": unit, "value": mu}
    if spec.unit == "λ" and pairs is not None:
        record["eigenvalue"] = float(pairs[0][-1])  # λ_(k−1), the largest of the first max(k, 2) eigenvalues
    return record


def _encode(summary: dict) -> str:
    return json.dumps(to_jsonable(summary), indent=2, ensure_ascii=False) + "\n"


def _picture(run: RunDir, name: str, fill: Callable[[Path], object]) -> str | None:
    """Stage the PNG ``name``; a failure of the picture itself (not of the disk) is reported on
    stderr and returned (for ``summary.json``), and the run goes on without it."""
    try:
        run.write_path("png", name, fill)
    except Exception as e:  # noqa: BLE001 — OutputError (disk) is not caught: it ends the run
        from .run_dir import OutputError

        if isinstance(e, (OSError, OutputError)):
            raise
        msg = f"{name} not written: {type(e).__name__}: {' '.join(str(e).split())[:200]}"
        stderr_line(f"{PROG}: warning: {msg}")
        return msg
    return None


def _viewer(args: argparse.Namespace, run: RunDir, name: str, m: Any, fields: Any, names: list[str],
            subtitles: list[str], title: str, summary: dict | None = None) -> dict | None:
    """With ``--html``: stage the interactive viewer ``name`` (``stiefel_cmm.cli.viewer.write_viewer``); what it shows.

    ``summary``: what the run's ``summary.json`` will say of its result (``command``, ``diagnostics``,
    ``interrupted``, ``best_effort``): its status is shown on the page (``stiefel_cmm.cli.viewer.run_status``)."""
    if not getattr(args, "html", False):
        return None
    from .viewer import run_status, write_viewer

    status, ok = run_status(summary) or (None, True)
    info: dict = {}
    run.write("html", name, lambda fh: info.update(write_viewer(fh, m.vertices, m.faces, fields, names, title=title,
                                                                 subtitles=subtitles, up=args.up, status=status,
                                                                 status_ok=ok)))
    return info


@contextlib.contextmanager
def _solve_signals(args: argparse.Namespace, bar: Callable, *, soft: bool = True) -> Iterator[tuple[Callable, Any]]:
    """``(progress, stop)`` for one solve: SIGINT and SIGTERM alike stop it and keep the iterate reached.

    ``stop`` is the ``stiefel_cmm.cli.main.SoftStop`` of ``signals.soft_stop()`` (None outside the CLI's
    ``main``); ``progress`` calls ``bar`` and, with ``soft``, arms it at the first report: from then on a signal
    sets ``stop.event`` (the solver's ``stop=``, checked between chunks) instead of raising, so one that lands
    outside the solver's loop (a compilation, a continuation round starting) still ends in the modes reached,
    written. ``soft=False`` for solvers that catch the interrupt themselves between long steps
    (``--method sequential``: one compiled solve per column) and for the μ search."""
    signals = getattr(args, "signals", None)
    if signals is None:
        yield bar, None
        return
    with signals.soft_stop() as stop:
        def progress(info: Any) -> None:
            if soft:
                stop.arm()
            bar(info)

        yield progress, stop


def _interrupted_solve(args: argparse.Namespace, status: str, stopped: bool = False) -> dict | None:
    """For a solve that stopped on Ctrl-C/SIGTERM (status ``interrupted``, or ``stopped``: the signal set its
    ``stop`` and the solve returned): take the signal over from ``stiefel_cmm.cli.main`` (the outputs are
    written, a second signal still aborts them) and describe it."""
    signals = getattr(args, "signals", None)
    if signals is None or not signals.received or not (status == "interrupted" or stopped):
        return None
    signum = signals.received[-1]
    signals.received.clear()
    name = "SIGTERM" if signum == signal.SIGTERM else "SIGINT"
    note = ("the solve was stopped by the signal; the outputs hold the iterate it had reached, not a converged "
            "result" if status == "interrupted" else
            f"the signal came as the solve was ending; the outputs are its complete result (status {status})")
    return {"signal": name, "exit_code": 143 if name == "SIGTERM" else 130, "status": status, "note": note}


def _exit_code(interrupt: dict | None) -> int:
    if interrupt is None:
        return 0
    word = "terminated" if interrupt["signal"] == "SIGTERM" else "interrupted"
    if interrupt.get("status", "interrupted") == "interrupted":
        stderr_line(f"{PROG}: {word} during the solve; the modes reached were written (status interrupted)")
    else:
        stderr_line(f"{PROG}: {word} as the solve ended; its complete result was written (status "
                    f"{interrupt['status']})")
    return int(interrupt["exit_code"])


def _finish(args: argparse.Namespace, run: RunDir, summary: dict) -> None:
    """Commit the run (``summary.json`` last); ``--json`` prints the summary as written."""
    written = run.commit(summary, _encode)
    if args.json:
        print(json.dumps(to_jsonable(written), ensure_ascii=False))


# ---------------------------------------------------------------------------- commands


def _resolve_mu(args: argparse.Namespace, lap: Any, n: int) -> tuple[MuSpec, float, Any]:
    """``(spec, μ, eigenpairs or None)``: ``--mu`` (default ``DEFAULT_MU``) resolved on this mesh; the first
    ``max(k, 2)`` eigenpairs are computed here when μ is relative to λ (and handed on to the solve)."""
    from objectives.cmm.modes import first_eigenpairs, unpack_laplacian

    spec = args.mu if args.mu is not None else parse_mu(DEFAULT_MU)
    pairs = None
    if spec.unit == "λ":
        pairs = first_eigenpairs(*unpack_laplacian(lap), max(args.k, 2))
    return spec, spec.resolve(n, None if pairs is None else float(pairs[0][-1])), pairs


def _start(args: argparse.Namespace, n: int) -> Any:
    """``--start``: ``"eigen"``, ``"random"`` or the ``(n, k)`` array of the file (``CLIError`` for a bad one)."""
    if not isinstance(args.start, StartFile):
        return args.start
    try:
        return load_start(args.start, n, args.k)
    except ValueError as e:
        raise CLIError(str(e)) from None
