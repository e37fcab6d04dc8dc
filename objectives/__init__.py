"""Objectives for optimisation on generalised Stiefel manifolds (docs/maths.md §4).

* ``objectives.energy.smoothings`` — the ten ℓ1 smoothings of thesis Table 6.1
  (``f0 … f9``, ``get``, ``info``, ``NAMES``).
* ``objectives.energy.energies`` — Dirichlet energy, weighted ℓ1 terms, the smoothed
  compressed-manifold-mode energy ``CMMEnergy`` and compressed eigenvalues.
* ``objectives.cmm.modes`` — ``compressed_modes(lap, k, mu, solver=...)`` and ``select_mu``;
  ``objectives.cmm.solvers`` — one immutable solver object per method: ``BlockCMM``,
  ``SequentialCMM``, ``ADMMCMM`` (exact / thesis form), ``SequentialADMMCMM``, ``FastCMM``;
  ``objectives.admm.splitting`` (Algorithm 3) and ``objectives.admm.fast`` (Algorithms 7–8).
* ``objectives.cmm.support_finish`` — ``SupportFinish`` / ``finish_support``: exact zeros by a Newton finish on
  the true ℓ1 problem restricted to the identified support; ``objectives.energy.l1_optimality`` — the exact ℓ1
  stationarity residual (docs/maths.md §9) and support statistics.
* ``objectives.cmm.batch`` — ``cmm_batch``: a batch of CMM solves (μ, ε/δ, starts) under
  ``jax.vmap``, or as a loop of the same compiled solver.
* ``objectives.bases`` — generalised manifold harmonics (GLMH), LMHs, Hamiltonian
  eigenfunctions, concatenated bases.
* ``objectives.evaluation`` — reconstruction, reconstruction errors, principal angles,
  Grassmannian distance.
* ``objectives.fmaps`` — functional maps, point-to-point extraction, ICP, Err_S/Err_T/Err_GD.

This package joins ``stiefel`` (operators) and the mesh quantities (W, A), but
imports nothing from ``mesh``: callers pass the matrices.
"""

from . import admm, bases, cmm, evaluation, fmaps
from .admm import fast
from .admm import rho as admm_rho
from .cmm import batch, differentiable, support_finish
from .cmm import solvers as cmm_solvers
from .energy import energies, l1_optimality, smoothings
# the modules under their names of the earlier flat layout (``objectives.cmm_manifold``, …)
from .cmm import active_set, padding
from .cmm import admm_solvers as cmm_admm
from .cmm import base as cmm_base
from .cmm import manifold_solvers as cmm_manifold
from .cmm import newton as cmm_newton
from .cmm import saddle as cmm_saddle
from .cmm.batch import BatchResult, cmm_batch
from .cmm.modes import CMMResult, compressed_modes, select_mu
from .cmm.differentiable import cmm_solve
from .cmm.solvers import ADMMCMM, BlockCMM, CMMSolver, FastCMM, SequentialADMMCMM, SequentialCMM, SolverOptionError
from .energy.energies import (CMMEnergy, Weighting, cmm_energy, compressed_eigenvalues, dirichlet, l1_term, l1_weights, order_by_compressed_eigenvalue)
from .energy.l1_optimality import L1Stationarity, l1_stationarity, support_stats
from .energy.smoothings import NAMES as SMOOTHING_NAMES
from .cmm.support_finish import FinishResult, SupportFinish, finish_support
from .energy.smoothings import Smoothing

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
