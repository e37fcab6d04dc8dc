"""The options of ``stiefel modes`` / ``eigs`` / ``compare-smoothings``, named as in the API.

``add_*`` add them to an argparse parser (values checked by ``type=``, so a bad value is a usage
error before anything is loaded); ``solver_from_args`` turns them into the solver object of
``objectives.cmm.solvers``; ``check_applicable`` refuses, before any work, an option that the
chosen method does not have; ``load_start`` reads ``--start FILE`` and checks its shape.

=========================== =========================================== ==============================
option                      API                                         default
=========================== =========================================== ==============================
``--weights``               ``mesh.laplacian(m, weights=)``             cotangent
``--area``                  ``mesh.laplacian(m, area=)``                lumped
``--mu`` / ``--target-sparsity`` ``compressed_modes(mu=)`` / ``select_mu`` ``DEFAULT_MU``
``--weighting``             ``compressed_modes(weighting=)``            ``DEFAULT_WEIGHTING``
``--start``                 ``compressed_modes(start=)``: eigen, random, a file (npy/npz)
``--method``                ``compressed_modes(solver=SOLVERS[method])`` block
``--smoothing``, ``--eps``, ``--delta`` ``BlockCMM(smoothing=, eps=, delta=)`` f6 (huber), 1e-3
``--continuation``, ``--continuation-start`` ``BlockCMM(continuation=, continuation_start=)``
``--optimizer``, ``--preconditioner`` ``BlockCMM(optimizer=, preconditioner=)`` cg, shifted
``--starts``                ``BlockCMM(starts=)``                       4 (eigen/random starts)
``--gtol``, ``--max-iters`` every solver's ``gtol`` / ``max_iters``
``--finish`` / ``--no-finish`` ``compressed_modes(finish=SupportFinish() / None)`` finish (exact zeros)
=========================== =========================================== ==============================
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Any, Callable

from .outputs import INT_MAX, PROG, bounded_int, parse_mu, stderr_line

__all__ = ["checked", "output_path", "add_laplacian_options", "add_cmm_options", "smoothing_name", "smoothing_list",
           "start_spec", "load_start", "solver_from_args", "check_applicable", "DEFAULT_MU", "DEFAULT_WEIGHTING",
           "GTOL", "METHODS", "StartFile"]

GTOL = 1e-6
SMOOTHING_NAMES = tuple(f"f{i}" for i in range(10))  # objectives.energy.smoothings.NAMES
METHODS = ("block", "sequential", "admm", "admm_sequential", "fast")  # objectives.cmm.solvers.SOLVERS
#: the default sparsity weight: twice λ_{k−1} (``docs/benchmarks/defaults.md``: visibly localised modes on every
#: test mesh, the same balance on coarse and fine meshes of one shape)
DEFAULT_MU = "2λ"
DEFAULT_WEIGHTING = "area"
WEIGHTS = ("cotangent", "graph", "uniform", "robust")                      # mesh.WEIGHTS
AREAS = ("lumped", "barycentric", "voronoi", "mixed", "fem", "uniform", "degree")  # mesh.AREAS
#: options of the manifold solvers only (dest → the methods that have it)
_MANIFOLD = ("block", "sequential")
_ONLY = {"eps": _MANIFOLD, "delta": _MANIFOLD, "continuation": _MANIFOLD, "continuation_start": _MANIFOLD,
         "optimizer": ("block",), "preconditioner": ("block",), "starts": ("block",)}


def checked(parse: Callable[[str], Any]) -> Callable[[str], Any]:
    """An argparse ``type=`` whose ``ValueError`` message becomes the usage error."""

    def check(text: str) -> Any:
        try:
            return parse(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    check.__name__ = getattr(parse, "__name__", "value")
    return check


def _positive(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise ValueError(f"expected a positive number, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"expected a positive number, got {text!r}")
    return v


def _fraction(text: str) -> float:
    v = _positive(text)
    if not v < 1:
        raise ValueError(f"expected a fraction in (0, 1), got {text!r}")
    return v


def smoothing_name(text: str) -> str:
    """The canonical name (``f0`` … ``f9``) of a smoothing given by name or alias (``huber``, ``l1``, …);
    ``ValueError`` listing every name and alias otherwise."""
    from objectives import smoothings

    return smoothings.info(text.strip()).name


def smoothing_list(text: str) -> list[str]:
    """``"huber,f3,logcosh"`` → canonical names, in order, without repeats."""
    names = [smoothing_name(s) for s in text.split(",") if s.strip()]
    if not names:
        raise ValueError(f"no smoothing named in {text!r}")
    return list(dict.fromkeys(names))


class StartFile:
    """``--start FILE``: an ``(n, k')`` array in a ``.npy``, or a ``.npz`` holding ``modes`` (``stiefel modes``),
    ``eigenvectors`` (``stiefel eigs``) or a single array; its first k columns are the start."""

    def __init__(self, path: Path) -> None:
        self.path = path

    def __str__(self) -> str:
        return str(self.path)


def output_path(option: str, example: str | None = None) -> Callable[[str], Path]:
    """An argparse ``type=`` for a path the command writes (``--out``, ``--output``, ``--cache-dir``): refuses an
    empty or blank path (``Path("")`` is the working directory: a run would write its files there) and a NUL byte.

    ``example``: the end of the message (default ``"e.g. --out results (--out . is the working directory)"``)."""
    example = example or f"e.g. {option} results ({option} . is the working directory)"

    def parse(text: str) -> Path:
        if not text.strip():
            raise ValueError(f"the path is empty{'' if not text else ' (only whitespace)'}: give one, {example}")
        if "\0" in text:
            raise ValueError(f"the path {text!r} contains a NUL byte: give a path without it")
        return Path(text)

    parse.__name__ = "path"
    return parse


def start_spec(text: str) -> str | StartFile:
    """``eigen``, ``random`` or an existing ``.npy``/``.npz`` file."""
    if text in ("eigen", "random"):
        return text
    path = Path(text)
    if path.suffix.lower() not in (".npy", ".npz"):
        raise ValueError(f"--start takes eigen, random or a .npy/.npz file, got {text!r}")
    if not path.is_file():
        raise ValueError(f"start file not found: {text}")
    return StartFile(path)


#: what an array of a refused dtype kind holds (``numpy.dtype.kind``), for ``load_start``'s message
_NOT_REAL = {"b": "booleans", "c": "complex numbers", "U": "strings", "S": "byte strings", "O": "Python objects",
             "M": "dates", "m": "time spans", "V": "records"}


def load_start(spec: StartFile, n: int, k: int):
    """The ``(n, k)`` float64 start read from ``spec``; ``ValueError`` naming the file and the shapes.

    Real numbers only (float or integer): booleans, strings and complex numbers are refused by their
    dtype (a complex start would lose its imaginary part with nothing but a ``ComplexWarning``)."""
    import zipfile

    import numpy as np

    try:
        data = np.load(spec.path, allow_pickle=False)
        if isinstance(data, np.ndarray):
            X, keys = data, []
        else:
            with data:
                keys = [key for key in ("modes", "eigenvectors") if key in data.files] or data.files
                X = data[keys[0]] if keys and (len(keys) == 1 or keys[0] in ("modes", "eigenvectors")) else None
    except (OSError, EOFError, ValueError, zipfile.BadZipFile) as e:  # ValueError: e.g. a pickled object array
        raise ValueError(f"start file {spec.path} cannot be read: {' '.join(str(e).split())}") from None
    if X is None:
        names = f" ({', '.join(keys)})" if keys else ""
        raise ValueError(f"start file {spec.path} holds {len(keys)} arrays{names}; save the start as one array, or "
                         "name it 'modes'")
    X = np.asarray(X)
    if X.dtype.kind not in "iuf":
        what = _NOT_REAL.get(X.dtype.kind, "values that are not real numbers")
        fix = "save its real part (X.real) instead" if X.dtype.kind == "c" else "save it as floats instead"
        raise ValueError(f"start file {spec.path} holds {what} (dtype {X.dtype}, shape {X.shape}), not real numbers: "
                         f"--start takes float or integer values; {fix}")
    if X.ndim != 2 or X.shape[0] != n or X.shape[1] < k:
        raise ValueError(f"start file {spec.path} holds an array of shape {X.shape}; expected (n, k') = ({n}, ≥ {k}) "
                         "numbers: one row per vertex of the loaded mesh (after cleaning), at least k columns")
    X = np.asarray(X[:, :k], dtype=np.float64)
    if not np.all(np.isfinite(X)):
        raise ValueError(f"start file {spec.path} has non-finite entries")
    return X


_mu_type = checked(parse_mu)
_positive_type = checked(_positive)
_int_type = checked(bounded_int(1, INT_MAX))


def add_laplacian_options(p: argparse.ArgumentParser) -> None:
    """``--weights`` (alias ``--laplacian``) and ``--area``: ``mesh.laplacian(m, weights=, area=)``."""
    p.add_argument("--weights", "--laplacian", dest="weights", choices=WEIGHTS, default="cotangent",
                   help="Laplacian weights, as mesh.laplacian(weights=): cotangent (default), graph, uniform, or "
                        "robust (intrinsic Delaunay on the tufted cover; loads non-manifold meshes). "
                        "--laplacian is the same option")
    p.add_argument("--area", choices=AREAS, default="lumped",
                   help="vertex areas A, as mesh.laplacian(area=) (default lumped; normalised to total area 1)")


def add_cmm_options(p: argparse.ArgumentParser, *, single_smoothing: bool) -> None:
    """The sparsity weight, ℓ1 weighting, start and solver options (``compressed_modes`` and the solver objects)."""
    mu = p.add_mutually_exclusive_group()
    mu.add_argument("--mu", type=_mu_type, default=None,
                    help=f"sparsity weight μ: absolute (5.2), relative to the vertex count (0.01n) or to λ_(k−1), the "
                         f"largest of the first k Laplacian eigenvalues (2λ or 2lambda); default {DEFAULT_MU}")
    mu.add_argument("--target-sparsity", type=checked(_fraction), default=None, metavar="S",
                    help="choose μ so that a fraction S of the entries is below 1e-3 of their mode's maximum "
                         "(objectives.select_mu: several solves)")
    p.add_argument("--weighting", choices=("area", "uniform"), default=DEFAULT_WEIGHTING,
                   help=f"ℓ1 weights: A_ii (area) or 1/n (uniform); default {DEFAULT_WEIGHTING}")
    p.add_argument("--max-iters", type=_int_type, default=5000,
                   help="iteration cap of every solver, ≤ 2³¹−1 (default 5000)")
    p.add_argument("--gtol", type=_positive_type, default=None,
                   help=f"gradient tolerance of the block/sequential solvers (default {GTOL})")
    if single_smoothing:
        p.add_argument("--smoothing", type=checked(smoothing_name), default="f6", metavar="NAME",
                       help="ℓ1 smoothing by name or alias (f0 … f9; huber = f6, l1 = abs = f0, logcosh = f8, …: "
                            "objectives.energy.smoothings); default f6 (huber)")
    p.add_argument("--finish", action=argparse.BooleanOptionalAction, default=True,
                   help="finish the modes on the exact ℓ1 problem on their identified support "
                        "(objectives.SupportFinish; the default): exact zeros, the status and the ℓ1 stationarity "
                        "residual from it, the solver's own modes kept as smooth_modes (compare-smoothings: each "
                        "smoothing's objective before the finish in smoothed_objective); --no-finish: the smoothed "
                        "solver's modes and status")
    p.add_argument("--eps", type=_positive_type, default=None,
                   help="smoothing parameter ε (default 1e-3; which of ε, δ a smoothing uses: objectives.energy.smoothings)")
    p.add_argument("--delta", type=_positive_type, default=None,
                   help="smoothing parameter δ (default 1e-3; huber/f6 uses δ)")
    p.add_argument("--continuation", type=_int_type, default=None, metavar="STAGES",
                   help="smoothing stages from --continuation-start down to ε, δ (block default 4, sequential 1)")
    p.add_argument("--continuation-start", type=_positive_type, default=None, metavar="WIDTH",
                   help="width of the first continuation stage (default 0.1)")
    p.add_argument("--starts", type=checked(bounded_int(1, 64)), default=None, metavar="N",
                   help="block solver: starts screened through the intermediate smoothing stages — the eigen (or "
                        "random) start and N − 1 rotations of it; the lowest goes on (default 4; 1: the start alone; "
                        "a --start file is used as given)")
    p.add_argument("--optimizer", choices=("cg", "lbfgs"), default=None,
                   help="block solver's method: Riemannian CG (default) or L-BFGS")
    p.add_argument("--preconditioner", choices=("shifted", "active_set"), default=None,
                   help="block solver's preconditioner: (W + σA)⁻¹ (shifted, default) or with the ℓ1 curvature of "
                        "the entries pinned at zero (active_set)")


def check_applicable(args: argparse.Namespace, method: str) -> None:
    """``ValueError`` for an option the method does not have (before any work)."""
    for dest, methods in _ONLY.items():
        if getattr(args, dest, None) is not None and method not in methods:
            flag = "--" + dest.replace("_", "-")
            raise ValueError(f"{flag} applies to --method {' or '.join(methods)}, not {method}")
    start = getattr(args, "start", None)
    if isinstance(start, StartFile) and method == "fast":
        raise ValueError("--method fast builds its start from its local functions: use --start eigen or random")


def solver_from_args(args: argparse.Namespace, method: str, smoothing: str, *, local_functions: Any = None,
                     runtime_smoothing: bool = False) -> tuple[Any, dict]:
    """``(solver, options passed)``: the ``objectives.cmm.solvers`` object for ``method`` with the options given.

    Every solver gets ``--max-iters``; the manifold solvers ``smoothing``, ``--gtol``, ``--eps``, ``--delta``,
    ``--continuation``, ``--continuation-start`` (and ``runtime_smoothing`` for ``compare-smoothings``: one
    compilation for all smoothings); the block solver ``--optimizer``, ``--preconditioner`` and ``--starts``; fast its ``U``."""
    from objectives.cmm.solvers import SOLVERS, FastCMM

    passed: dict[str, Any] = {"max_iters": args.max_iters}
    if method in _MANIFOLD:
        passed.update(smoothing=smoothing, gtol=GTOL if args.gtol is None else args.gtol)
        for dest, methods in _ONLY.items():
            if method in methods and getattr(args, dest, None) is not None:
                passed[dest] = getattr(args, dest)
        if runtime_smoothing:
            passed["runtime_smoothing"] = True
        return SOLVERS[method](**passed), passed
    if args.gtol is not None:
        stderr_line(f"{PROG}: warning: --gtol applies to the block and sequential solvers; {method} stops on its "
                    "residual tolerances eps_abs/eps_rel (recorded in summary.json)")
    if method == "fast":
        return FastCMM(local_functions, **passed), passed
    return SOLVERS[method](**passed), passed
