"""Optimisation on generalised Stiefel manifolds ``{X ∈ R^{n×k} : XᵀMX = I}`` in JAX.

Public API (docs/maths.md §1–3):

* ``GeneralizedStiefel(M, k, metric=..., retraction=...)`` — the manifold.
* ``Grassmann(M, k)`` — the quotient ``S_M/O(k)`` for rotation-invariant objectives; ``sphere(n, M)``,
  ``stiefel(n, k)`` — the named special cases (``stiefel.grassmann``).
* ``Product(S1, S2, ...)`` — products of those (points are tuples of arrays; ``stiefel.product``): the
  ``optimistix`` minimisers and the slope checks accept one.
* ``SequentialConstraint`` — ``{x : ΦᵀMx = 0, xᵀMx = 1}`` for column-by-column solves.
* ``strong_wolfe``, ``along_curve``, ``LineSearchStatus`` — the line search.
* ``RiemannianCG``, ``RiemannianLBFGS``, ``RiemannianBB`` — ``optimistix`` minimisers:
  ``optx.minimise(fn, stiefel.RiemannianCG(S, rtol, atol), X0, args,
  adjoint=stiefel.RiemannianImplicitAdjoint())``.
* ``RiemannianTrustRegion`` — second order: Riemannian trust regions with truncated CG (exact
  Hessian by autodiff, or finite differences of the gradient), the same ``optx.minimise`` idiom.
* ``check_gradient``, ``check_hessian``, ``check_retraction`` — Manopt-style slope tests returning a
  ``SlopeCheck`` (fitted slope, verdict, ``.plot()``); ``GeneralizedStiefel.exp``/``log``/``dist``
  (``stiefel.geodesics``).
* ``minimize`` (block solver, the convenience entry point running the same minimisers) and
  ``minimize_sequential`` (thesis Algorithm 6); ``solve_block``, the block solver as a pure
  jittable/vmappable function.
* ``RiemannianImplicitAdjoint`` — derivatives of solutions by the implicit function theorem
  (docs/maths.md §9); ``riemannian_hessian``, ``hessian_operator`` — the Riemannian Hessian;
  ``negative_curvature`` (its most negative curvature by LOBPCG: a saddle test) and ``escape_step``
  (a step off a saddle along it) — ``stiefel.saddle`` (docs/maths.md §9, eq. 9.18).
* ``Result``, ``SequentialResult``, ``Status``, ``History`` — solver outcomes; ``Progress`` — what a
  ``progress=`` callback receives between compiled chunks of iterations (``stiefel.driver``), and
  ``CallbackError`` when that callback raises.
* ``as_operator``, ``shifted_inverse`` — SPD operators and preconditioners.
* ``stiefel.sharding`` — ``row_mesh``, ``shard_rows``, ``solve_sharded``: the block solver with
  ``X`` split by rows over devices (single- or multi-host).
* Compilation: with JAX's persistent cache on (``jax.config.update("jax_compilation_cache_dir", DIR)``),
  ``stiefel.program_cache`` also stores ``minimize``'s traced programs (``jax.export``; only for this
  project's own objectives), so a new process neither traces nor compiles them;
  ``stiefel.buckets`` — the size grid on which ``objectives.BlockCMM`` pads problems so that
  similar sizes share one program.
* ``canonical_signs(X)`` — the sign convention of every basis the toolkit returns (each column's
  largest-magnitude entry is positive; ``stiefel.signs``).
* Errors: ``StiefelError`` and its subclasses (``ParameterError`` for an option out of range,
  ``NonFiniteError``, ``RankDeficientError``, ...); ``stiefel.validation`` — the checks behind them.

float64: the solvers compute in the dtype of the manifold's operator, which is
float64 when JAX's x64 mode is on. Library code never changes JAX's global
configuration; enable it in your program with
``jax.config.update("jax_enable_x64", True)``, or pass ``dtype=jnp.float32``
explicitly to work in single precision. Sparse solves (a sparse M, the
``(W + σA)⁻¹`` preconditioner) run as CHOLMOD custom calls (``stiefel.ffi_solve``, through
sparsax) when the global x64 flag is on, and as host callbacks otherwise; the thread-local
``jax.enable_x64`` context works for diagonal and dense M only.
"""

from .block_solver import METHODS, BlockOptions, minimize, solver_for
from .block_solver import solve as solve_block
from .driver import CallbackError, Progress
from .checks import SlopeCheck, check_gradient, check_hessian, check_retraction
from .grassmann import Grassmann, sphere, stiefel
from .product import Product
from .hessian import hessian_operator, riemannian_hessian
from .saddle import Curvature, EscapeStep, escape_step, negative_curvature
from .implicit import RiemannianImplicitAdjoint, riemannian_residual, tangent_solve
from .minimisers import RiemannianBB, RiemannianCG, RiemannianLBFGS
from .tcg import TCGStop, truncated_cg
from .trust_region import RiemannianTrustRegion
from .errors import (NonFiniteError, NotSPDError, OffManifoldError, OutOfDomainError, ParameterError, RankDeficientError, ShapeError,
                     SolverError, StiefelError)
from .linesearch import LineSearchResult, LineSearchStatus, along_curve, strong_wolfe
from .manifold import GeneralizedStiefel, skew, sym
from .operators import DenseOperator, DiagonalOperator, IdentityOperator, LinearOperator, SparseOperator, as_operator
from .penalty import PenaltyResult, penalty_minimize
from .preconditioning import (
    PRECONDITIONING_MODES,
    PointPreconditioner,
    as_preconditioner,
    preconditioned_gradient,
    preconditioned_residual,
    shifted_inverse,
)
from .result import History, Result, SequentialResult, Status
from .signs import canonical_signs, column_signs
from .sequential import DIRECTIONS, SequentialConstraint, SequentialOptions, minimize_sequential
from . import sharding, validation
