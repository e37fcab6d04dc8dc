"""``stiefel`` — compressed manifold modes and Laplacian eigenpairs from the command line.

Subcommands::

    stiefel modes [MESH] -k 10 --mu 2λ --method block --smoothing huber --start eigen --out DIR [--html]
    stiefel eigs [MESH] -k 10 --out DIR [--html]
    stiefel compare-smoothings [MESH] -k 4 --smoothings huber,logcosh,f3 --out DIR
    stiefel view DIR [--output FILE]

Without ``MESH`` the built-in demo surface is used (``stiefel_cmm.cli.demo_mesh``); ``example:NAME`` picks a
generated example (``mesh.examples``). ``--mu`` is absolute (``5.2``), relative to the vertex count
(``0.01n`` = 0.01·n) or to λ_(k−1), the largest of the first k Laplacian eigenvalues (``2λ``, the
default, also written ``2lambda``); the resolved absolute μ is recorded in ``summary.json``.
``--target-sparsity S`` chooses μ instead (``objectives.select_mu``). The options carry the API's
names (``stiefel_cmm.cli.options``: ``--weights``, ``--area``, ``--smoothing`` with any alias, ``--eps``,
``--delta``, ``--continuation``, ``--optimizer``, ``--preconditioner``, ``--start``); an option the
chosen method does not have is refused before any work. Progress goes to stdout, one
line per stage, and the solver's progress to stderr (a bar on a terminal, a line every
2 s otherwise; none of either with ``--quiet``); ``--json`` prints exactly one JSON object
(the summary) on stdout and nothing else there. ``stiefel view`` (``stiefel_cmm.cli.viewer``) writes an
interactive, self-contained HTML viewer of a ``modes`` or ``eigs`` run — checked against the run's
``summary.json`` (SHA-256 of the data file), its status on the page, the page listed in that summary;
``--html`` writes it with the run (``modes.html`` / ``eigs.html``).

Compilation is cached across runs in JAX's persistent cache (``stiefel_cmm.cli.cache``: ``--cache-dir``,
``$STIEFEL_CACHE_DIR``, ``--no-cache``); ``summary.json``'s ``timings`` separate ``compile_s``,
``solve_s``, ``setup_s`` (mesh, Laplacian, eigenbasis, factorisation), ``write_s`` and ``total_s``. Errors print one line
``stiefel: error: …`` on stderr: exit code 2 for bad arguments (an empty ``--out`` included: ``Path("")``
is the working directory), 1 for bad input (missing file, non-manifold mesh, …), 3 for a run written
but short of what was asked (an unreachable ``--target-sparsity``, labelled ``best_effort``).

``--method`` picks the solver object of ``objectives.cmm.solvers`` (``block`` →
``BlockCMM``, ``sequential`` → ``SequentialCMM``, ``admm`` → ``ADMMCMM``,
``admm_sequential`` → ``SequentialADMMCMM``, ``fast`` → ``FastCMM``). ``--max-iters``
reaches every solver; ``--smoothing``, ``--gtol`` and the smoothing options the manifold solvers (the ADMM
solvers stop on their residual tolerances ``eps_abs``/``eps_rel``); ``--samples`` sets the
local functions of ``fast``. ``summary.json`` records the options passed
(``solver_options``) and all of the solver's options (``parameters``).

The subcommands live in ``stiefel_cmm.cli.commands``; their outputs go through ``stiefel_cmm.cli.run_dir``:
``DIR`` is checked, locked (``DIR/.stiefel.lock``; a second run into it is refused) and
claimed by one subcommand before anything is loaded or solved; files are staged and
swapped in only when all are written, ``summary.json`` last, listing each file with its
size and SHA-256. An interrupt or a write error leaves the previous run's outputs as they
were. Ctrl-C prints ``stiefel: interrupted`` (exit 130), SIGTERM ``stiefel: terminated``
(exit 143), without a traceback — also during the imports of JAX. The two take the same paths: once
a solve has reported progress, the first signal sets its ``stop`` (``_Signals.soft_stop``) and the
solver stops at its next check, wherever the signal landed (a compilation between continuation
rounds included): the modes reached are written, marked ``"status": "interrupted"`` in
``summary.json``, and the exit code is still 130 (143); a second signal aborts at once.

Partial results: for ``--method sequential`` the finished columns are saved to
``DIR/modes.partial.npz`` as they complete (``compressed_modes(callback=)``, passed
through to ``stiefel.minimize_sequential``) and removed when the run commits; the
other methods write their modes when the solve has finished (``summary.json`` says which
applied).

This is an application: ``main`` switches JAX to float64 (``jax_enable_x64``);
the library modules never touch JAX's global configuration.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import os
import re
import signal
import sys
import threading
from pathlib import Path
from typing import Any, Callable, Iterator, NoReturn, Sequence

# only light modules here: whatever the commands need is imported inside ``main``, where an interrupt is handled
from .options import checked as _checked
from .options import output_path as _output_path
from .outputs import INT_MAX, PROG, bounded_int, stderr_line

__all__ = ["main", "build_parser"]


def __getattr__(name: str) -> Any:
    if name == "CLIError":  # ``stiefel_cmm.cli.common.CLIError``, imported on first use
        from .common import CLIError

        return CLIError
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line on stderr and exit code 2 (no usage dump).

    A value that starts with ``-`` and a digit or a point (``--mu -1λ``, ``--gtol -1e-3``, ``--mu -.5n``) is a
    value, not an option: argparse's own pattern admits only plain negative numbers (``-1``, ``-.5``), so
    ``--mu -1λ`` said "expected one argument" instead of reaching the μ parser (no option of ``stiefel``
    starts with ``-`` and a digit)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-\.?\d")

    def error(self, message: str) -> NoReturn:
        stderr_line(f"{PROG}: error: {message} (see '{self.prog} -h')")
        raise SystemExit(2)




#: integer options are capped at a C int (``--max-iters 99999999999`` overflowed deep inside)
_positive_int = _checked(bounded_int(1, INT_MAX))
_seed_type = _checked(bounded_int(0, 2**32 - 1))


def _common(p: argparse.ArgumentParser, k_default: int) -> None:
    from .options import add_laplacian_options

    p.add_argument("mesh", nargs="?", default=None,
                   help="mesh file (OBJ/OFF/PLY/STL), or example:NAME for a generated example (bumpy, starfish, "
                        "torus, patch: mesh.examples); default: the built-in demo mesh (example:bumpy)")
    p.add_argument("-k", type=_positive_int, default=k_default, help=f"number of modes (default {k_default})")
    p.add_argument("--out", type=_checked(_output_path("--out")), default=None,
                   help="output directory (created; default: ./stiefel-<command>; an empty path is refused)")
    p.add_argument("--seed", type=_seed_type, default=0, help="random seed, 0 … 2³²−1 (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress lines or progress bar")
    p.add_argument("--json", action="store_true", help="print the summary as one JSON object on stdout")
    p.add_argument("--cache-dir", type=_checked(_output_path("--cache-dir")), default=None,
                   help="JAX compilation cache (default: $STIEFEL_CACHE_DIR, else the user cache directory)")
    p.add_argument("--no-cache", action="store_true", help="compile without the persistent compilation cache")
    add_laplacian_options(p)
    p.add_argument("--up", type=_checked(_up), default=None, metavar="AXIS",
                   help="the pictures' vertical axis: x, y, z, -x, -y, -z, or auto (default: the mesh's principal axes)")


def _up(text: str) -> str | None:
    from .render_views import check_up

    return check_up(text)


def build_parser() -> argparse.ArgumentParser:
    """The ``stiefel`` argument parser (subcommands ``modes``, ``eigs``, ``compare-smoothings``)."""
    from . import options as o

    parser = _Parser(prog=PROG, description="Compressed manifold modes and Laplacian eigenpairs on triangle meshes.",
                     epilog="examples: stiefel modes -k 6 --out out/ | stiefel modes mesh.obj -k 10 --mu 0.05n "
                            "--json --out out/ | stiefel modes example:starfish --smoothing huber --start random | "
                            "stiefel eigs mesh.off -k 20 --out eigs/")
    sub = parser.add_subparsers(dest="command", required=True, metavar="{modes,eigs,compare-smoothings,view}",
                                parser_class=_Parser)
    p = sub.add_parser("modes", help="compressed manifold modes: npz, PLY, PNG, summary.json")
    _common(p, 10)
    o.add_cmm_options(p, single_smoothing=True)
    p.add_argument("--method", choices=o.METHODS, default="block", help="solver (default block)")
    p.add_argument("--start", type=_checked(o.start_spec), default="eigen", metavar="{eigen,random,FILE}",
                   help="start: the first k eigenfunctions (default; the block method screens --starts rotations of "
                        "them), random, or a .npy/.npz file with an (n, k) array (e.g. an earlier run's modes.npz), "
                        "used as given")
    p.add_argument("--samples", type=_positive_int, default=None,
                   help="local functions for --method fast (default: max(10k, n/10))")
    p.add_argument("--no-png", action="store_true", help="skip the PNG contact sheet")
    p.add_argument("--ascii-ply", action="store_true", help="write modes.ply as ASCII (default: binary little-endian)")
    p.add_argument("--html", action="store_true",
                   help="also write modes.html, an interactive viewer (one self-contained file; stiefel view does it later)")
    p.set_defaults(run=_command("cmd_modes"))

    p = sub.add_parser("eigs", help="first k Laplacian eigenpairs: npz, PLY, PNG, summary.json")
    _common(p, 10)
    p.add_argument("--no-png", action="store_true", help="skip the PNG contact sheet")
    p.add_argument("--ascii-ply", action="store_true", help="write eigs.ply as ASCII (default: binary little-endian)")
    p.add_argument("--html", action="store_true",
                   help="also write eigs.html, an interactive viewer (one self-contained file; stiefel view does it later)")
    p.set_defaults(run=_command("cmd_eigs"))

    p = sub.add_parser("compare-smoothings", help="f0…f9 from the same start: markdown table, CSV and a figure")
    _common(p, 4)
    o.add_cmm_options(p, single_smoothing=False)
    p.add_argument("--method", choices=("block", "sequential"), default="block", help="solver (default block)")
    p.add_argument("--smoothings", type=_checked(o.smoothing_list), default=list(o.SMOOTHING_NAMES),
                   metavar="NAMES", help="comma-separated names or aliases (default: all ten, f0,…,f9)")
    p.add_argument("--no-png", action="store_true", help="skip comparison.png (smoothing × mode grid)")
    p.set_defaults(run=_command("cmd_compare"))

    from .viewer import add_parser as add_view

    add_view(sub)
    return parser


def _command(name: str) -> Callable:
    """The subcommand ``stiefel_cmm.cli.commands.<name>``, imported when it runs (``--help`` stays light)."""

    def run(args: argparse.Namespace, argv: Sequence[str] | None, run_dir: Any) -> int:
        from . import commands

        return getattr(commands, name)(args, argv, run_dir)

    return run


# ---------------------------------------------------------------------------- entry point


def _run(args: argparse.Namespace, argv: Sequence[str] | None, check: Callable[[], None]) -> int:
    """Check the cheap inputs and ``--out`` (locked, claimed) before loading or solving anything; run.

    ``check`` raises ``KeyboardInterrupt`` if an interrupt came; the commit calls it first."""
    from .commands import outputs_of
    from .common import EXAMPLE_PREFIX, CLIError, example_name
    from .options import check_applicable
    from .run_dir import RunDir

    if args.mesh is not None and not Path(args.mesh).is_file():
        if not args.mesh.startswith(EXAMPLE_PREFIX):
            raise CLIError(f"mesh file not found: {args.mesh}")
        example_name(args.mesh)
    if hasattr(args, "method"):
        try:
            check_applicable(args, args.method)
        except ValueError as e:
            raise CLIError(str(e)) from None
    out = args.out if args.out is not None else Path(f"stiefel-{args.command}")
    outputs, owned = outputs_of(args)
    with RunDir(out, args.command, outputs=outputs, owned=owned, check=check) as run:
        return int(args.run(args, argv, run))


def _main(argv: Sequence[str] | None, signals: _Signals) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as e:  # argparse: -h (0) or a usage error (2, already reported)
        return int(e.code or 0)
    if args.command == "view":  # reads a run directory and writes one HTML file: no JAX, no RunDir
        from .viewer import ViewerError, run_view

        signals.check()
        try:
            return run_view(args)
        except ViewerError as e:
            stderr_line(f"{PROG}: error: {e}")
            return 1

    import jax

    # An application may set JAX's global configuration (the library never does).
    jax.config.update("jax_enable_x64", True)
    import mesh

    from .cache import enable as enable_cache
    from .common import CLIError
    from .run_dir import OutputError

    args.cache_used, warning = enable_cache(args.cache_dir, args.no_cache)
    if warning:
        stderr_line(f"{PROG}: warning: {warning}")
    args.signals = signals

    signals.check()  # the imports are done: from here on a signal interrupts at once
    try:
        return _run(args, argv, signals.check)
    except (CLIError, OutputError, mesh.MeshError, FileNotFoundError, OSError, ValueError) as e:
        if signals.received:  # an interrupt that surfaced as another exception: reported as the interrupt
            raise
        kind = "" if isinstance(e, (CLIError, OutputError, mesh.MeshError)) else f"{type(e).__name__}: "
        stderr_line(f"{PROG}: error: {kind}{e}")
        return 1


def _in_callback(frame: Any) -> bool:
    """Whether ``frame`` runs inside a gc callback or a ``__del__``, where exceptions are dropped."""
    codes = {getattr(cb, "__code__", None) for cb in gc.callbacks}
    while frame is not None:
        if frame.f_code in codes or frame.f_code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


class SoftStop:
    """What ``_Signals.soft_stop`` yields: ``event`` (a ``threading.Event``, set by SIGINT/SIGTERM) and ``arm()``."""

    def __init__(self, armed: bool = False) -> None:
        self.event, self.armed = threading.Event(), armed

    def arm(self) -> None:
        """From now on the first signal only sets ``event`` (see ``_Signals.soft_stop``)."""
        self.armed = True


class _Signals:
    """While the CLI runs, SIGINT and SIGTERM are remembered and raise ``KeyboardInterrupt``.

    ``defer`` (during the imports of JAX and the mesh code): only remembered, raised by ``check()``
    once the imports are done — an exception inside jaxlib's initialisation surfaces as an
    ``ImportError``, an abort or a crash. Inside a gc callback or ``__del__`` (where an exception
    is printed and dropped) the signal is sent again 10 ms later, to land after it. ``check()`` also
    runs before a commit, so a run that was interrupted never replaces the previous outputs.
    Installed on the main thread only; the previous handlers are restored on exit.
    """

    def __init__(self) -> None:
        self.received: list[int] = []
        self.defer = True
        self._old: dict[int, Any] = {}
        self._soft: SoftStop | None = None

    def _handler(self, signum: int, frame: Any) -> None:
        if signum not in self.received:
            self.received.append(signum)
        if self.defer:
            return
        soft = self._soft
        if soft is not None:
            first = not soft.event.is_set()
            soft.event.set()
            if soft.armed and first:  # the solve stops at its next check and returns the iterate reached
                return
        if _in_callback(frame):
            timer = threading.Timer(0.01, os.kill, (os.getpid(), signum))  # again once the callback is done
            timer.daemon = True
            timer.start()
            return
        raise KeyboardInterrupt

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` if a signal came (and stop deferring)."""
        self.defer = False
        if self.received:
            raise KeyboardInterrupt

    @contextlib.contextmanager
    def soft_stop(self, *, armed: bool = False) -> Iterator[SoftStop]:
        """While a solve runs: SIGINT and SIGTERM also set the ``SoftStop``'s ``event`` (the solve's ``stop=``).

        Once ``arm()``-ed (the solve reported progress: there is an iterate worth keeping), the first signal only
        sets it — the solver stops at its next check, also when the signal lands outside its loop (during a
        compilation, between continuation rounds), where a ``KeyboardInterrupt`` would lose the iterate — and a
        second signal raises as usual. Before, the signal raises at once (nothing reached yet to write)."""
        stop = SoftStop(armed)
        self._soft = stop
        try:
            yield stop
        finally:
            self._soft = None

    @contextlib.contextmanager
    def installed(self) -> Iterator[_Signals]:
        if threading.current_thread() is threading.main_thread():
            self._old = {s: signal.signal(s, self._handler) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            yield self
        finally:
            for s, h in self._old.items():
                signal.signal(s, h if h is not None else signal.SIG_DFL)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; return the exit code (0 ok, 1 bad input, 2 bad arguments, 3 written but short of what was
    asked — an unreachable ``--target-sparsity`` —, 130 Ctrl-C, 143 SIGTERM).

    An interrupt at any point — the imports of JAX and the mesh code included — ends in one line on
    stderr and no traceback; a run's outputs are cleaned up on the way (``stiefel_cmm.cli.run_dir``). Called
    without ``argv`` (the command line), an interrupted run then ends the process with ``os._exit``:
    an interrupted XLA computation or compilation can crash the interpreter's normal shutdown.
    """
    signals, code = _Signals(), None
    try:
        with signals.installed():
            code = _main(argv, signals)
    except BaseException as e:
        if not (signals.received or isinstance(e, KeyboardInterrupt)):
            raise
    if code is not None and not signals.received:
        return code
    term = bool(signals.received) and signals.received[-1] == signal.SIGTERM
    stderr_line(f"{PROG}: {'terminated' if term else 'interrupted'}")
    code = 143 if term else 130
    if argv is None:  # the command line: leave now, JAX's worker threads can crash the interpreter's shutdown
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    return code


def _entry() -> None:
    sys.exit(main())


if __name__ == "__main__":
    _entry()
