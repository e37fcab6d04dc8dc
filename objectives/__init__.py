"""Objectives for optimisation on generalised Stiefel manifolds (docs/maths.md §4).

* ``objectives.smoothings`` — the ten ℓ1 smoothings of thesis Table 6.1
  (``f0 … f9``, ``get``, ``info``, ``NAMES``).
* ``objectives.energies`` — Dirichlet energy, weighted ℓ1 terms, the smoothed
  compressed-manifold-mode energy ``CMMEnergy`` and compressed eigenvalues.
* ``objectives.cmm`` — ``compressed_modes(lap, k, mu, solver=...)`` and ``select_mu``;
  ``objectives.cmm_solvers`` — one immutable solver object per method: ``BlockCMM``,
  ``SequentialCMM``, ``ADMMCMM`` (exact / thesis form), ``SequentialADMMCMM``, ``FastCMM``;
  ``objectives.admm`` (Algorithm 3) and ``objectives.fast`` (Algorithms 7–8).
* ``objectives.support_finish`` — ``SupportFinish`` / ``finish_support``: exact zeros by a Newton finish on
  the true ℓ1 problem restricted to the identified support; ``objectives.l1_optimality`` — the exact ℓ1
  stationarity residual (docs/maths.md §9) and support statistics.
* ``objectives.batch`` — ``cmm_batch``: a batch of CMM solves (μ, ε/δ, starts) under
  ``jax.vmap``, or as a loop of the same compiled solver.
* ``objectives.bases`` — generalised manifold harmonics (GLMH), LMHs, Hamiltonian
  eigenfunctions, concatenated bases.
* ``objectives.evaluation`` — reconstruction, reconstruction errors, principal angles,
  Grassmannian distance.
* ``objectives.fmaps`` — functional maps, point-to-point extraction, ICP, Err_S/Err_T/Err_GD.

This package joins ``stiefel`` (operators) and the mesh quantities (W, A), but
imports nothing from ``mesh``: callers pass the matrices.
"""

from . import (admm, bases, batch, cmm, cmm_solvers, differentiable, evaluation, fast, fmaps, l1_optimality, smoothings,
               support_finish)
from .batch import BatchResult, cmm_batch
from .cmm import CMMResult, compressed_modes, select_mu
from .differentiable import cmm_solve
from .cmm_solvers import ADMMCMM, BlockCMM, CMMSolver, FastCMM, SequentialADMMCMM, SequentialCMM, SolverOptionError
from .energies import (
    CMMEnergy,
    Weighting,
    cmm_energy,
    compressed_eigenvalues,
    dirichlet,
    l1_term,
    l1_weights,
    order_by_compressed_eigenvalue,
)
from .l1_optimality import L1Stationarity, l1_stationarity, support_stats
from .smoothings import NAMES as SMOOTHING_NAMES
from .support_finish import FinishResult, SupportFinish, finish_support
from .smoothings import Smoothing

__all__ = [
    "SupportFinish",
    "FinishResult",
    "finish_support",
    "support_finish",
    "l1_optimality",
    "L1Stationarity",
    "l1_stationarity",
    "support_stats",
    "cmm_solve",
    "differentiable",
    "admm",
    "bases",
    "batch",
    "BatchResult",
    "cmm_batch",
    "cmm",
    "evaluation",
    "fast",
    "fmaps",
    "CMMResult",
    "compressed_modes",
    "select_mu",
    "cmm_solvers",
    "CMMSolver",
    "BlockCMM",
    "SequentialCMM",
    "ADMMCMM",
    "SequentialADMMCMM",
    "FastCMM",
    "SolverOptionError",
    "smoothings",
    "Smoothing",
    "SMOOTHING_NAMES",
    "CMMEnergy",
    "Weighting",
    "cmm_energy",
    "compressed_eigenvalues",
    "dirichlet",
    "l1_term",
    "l1_weights",
    "order_by_compressed_eigenvalue",
]
