"""Optimisation on generalised Stiefel manifolds ``{X ∈ R^{n×k} : XᵀMX = I}`` in JAX.

Public API (docs/maths.md §1–3):

* ``GeneralizedStiefel(M, k, metric=..., retraction=...)`` — the manifold.
* ``Grassmann(M, k)`` — the quotient ``S_M/O(k)`` for rotation-invariant objectives; ``sphere(n, M)``,
  ``stiefel(n, k)`` — the named special cases (``stiefel.manifolds.grassmann``).
* ``Product(S1, S2, ...)`` — products of those (points are tuples of arrays; ``stiefel.manifolds.product``): the
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
  (``stiefel.manifolds.geodesics``).
* ``minimize`` (block solver, the convenience entry point running the same minimisers) and
  ``minimize_sequential`` (thesis Algorithm 6); ``solve_block``, the block solver as a pure
  jittable/vmappable function.
* ``RiemannianImplicitAdjoint`` — derivatives of solutions by the implicit function theorem
  (docs/maths.md §9); ``riemannian_hessian``, ``hessian_operator`` — the Riemannian Hessian;
  ``negative_curvature`` (its most negative curvature by LOBPCG: a saddle test) and ``escape_step``
  (a step off a saddle along it) — ``stiefel.solvers.saddle`` (docs/maths.md §9, eq. 9.18).
* ``Result``, ``SequentialResult``, ``Status``, ``History`` — solver outcomes; ``Progress`` — what a
  ``progress=`` callback receives between compiled chunks of iterations (``stiefel.solvers.driver``), and
  ``CallbackError`` when that callback raises.
* ``as_operator``, ``shifted_inverse`` — SPD operators and preconditioners.
* ``stiefel.solvers.sharding`` — ``row_mesh``, ``shard_rows``, ``solve_sharded``: the block solver with
  ``X`` split by rows over devices (single- or multi-host).
* Compilation: with JAX's persistent cache on (``jax.config.update("jax_compilation_cache_dir", DIR)``),
  ``stiefel.runtime.program_cache`` also stores ``minimize``'s traced programs (``jax.export``; only for this
  project's own objectives), so a new process neither traces nor compiles them;
  ``stiefel.runtime.buckets`` — the size grid on which ``objectives.BlockCMM`` pads problems so that
  similar sizes share one program.
* ``canonical_signs(X)`` — the sign convention of every basis the toolkit returns (each column's
  largest-magnitude entry is positive; ``stiefel.manifolds.signs``).
* Errors: ``StiefelError`` and its subclasses (``ParameterError`` for an option out of range,
  ``NonFiniteError``, ``RankDeficientError``, ...); ``stiefel.validation`` — the checks behind them.

float64: the solvers compute in the dtype of the manifold's operator, which is
float64 when JAX's x64 mode is on. Library code never changes JAX's global
configuration; enable it in your program with
``jax.config.update("jax_enable_x64", True)``, or pass ``dtype=jnp.float32``
explicitly to work in single precision. Sparse solves (a sparse M, the
``(W + σA)⁻¹`` preconditioner) run as CHOLMOD custom calls (``stiefel.linalg.ffi_solve``, through
sparsax) when the global x64 flag is on, and as host callbacks otherwise; the thread-local
``jax.enable_x64`` context works for diagonal and dense M only.
"""

from .solvers.block_solver import METHODS, BlockOptions, minimize, solver_for
from .solvers.block_solver import solve as solve_block
from .solvers.driver import CallbackError, Progress
from .derivatives.checks import SlopeCheck, check_gradient, check_hessian, check_retraction
from .manifolds.grassmann import Grassmann, sphere, stiefel
from .manifolds.product import Product
from .derivatives.hessian import hessian_operator, riemannian_hessian
from .solvers.saddle import Curvature, EscapeStep, escape_step, negative_curvature
from .derivatives.implicit import RiemannianImplicitAdjoint, riemannian_residual, tangent_solve
from .solvers.minimisers import RiemannianBB, RiemannianCG, RiemannianLBFGS
from .solvers.tcg import TCGStop, truncated_cg
from .solvers.trust_region import RiemannianTrustRegion
from .errors import (NonFiniteError, NotSPDError, ObjectiveSignatureError, OffManifoldError, OutOfDomainError, ParameterError, RankDeficientError, ShapeError, SolverError, StiefelError)
from .solvers.linesearch import LineSearchResult, LineSearchStatus, along_curve, strong_wolfe
from .manifolds.manifold import GeneralizedStiefel, skew, sym
from .linalg.operators import DenseOperator, DiagonalOperator, IdentityOperator, LinearOperator, SparseOperator, as_operator
from .solvers.penalty import PenaltyResult, penalty_minimize
from .solvers.preconditioning import (PRECONDITIONING_MODES, PointPreconditioner, as_preconditioner, preconditioned_gradient, preconditioned_residual, shifted_inverse)
from .result import History, Result, SequentialResult, Status
from .manifolds.signs import canonical_signs, column_signs
from .solvers.sequential import DIRECTIONS, SequentialConstraint, SequentialOptions, minimize_sequential
from . import errors, result, validation
from .linalg import ffi_solve
from .manifolds import geodesics, grassmann, product, signs
from .runtime import buckets, program_cache
from .solvers import driver, saddle, sharding

# The modules under their names of the earlier flat layout (``stiefel.operators.SparseOperator`` keeps working);
# each lives in the sub-package of its concept.
from .derivatives import checks, hessian, implicit
from .linalg import ell, operators, sparse_factor
from .manifolds import manifold, retractions, tangent_algebra
from .solvers import block_solver, block_steps, linesearch, minimisers, penalty, preconditioning, sequential, tcg, trust_region
