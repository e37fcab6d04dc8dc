"""Objectives for optimisation on generalised Stiefel manifolds (MATH.md §4).

* ``objectives.smoothings`` — the ten ℓ1 smoothings of thesis Table 6.1
  (``f0 … f9``, ``get``, ``info``, ``NAMES``).
* ``objectives.energies`` — Dirichlet energy, weighted ℓ1 terms, the smoothed
  compressed-manifold-mode energy ``CMMEnergy`` and compressed eigenvalues.

This package joins ``stiefel`` (operators) and the mesh quantities (W, A), but
imports nothing from ``mesh``: callers pass the matrices.
"""

from . import smoothings
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
from .smoothings import NAMES as SMOOTHING_NAMES
from .smoothings import Smoothing

__all__ = [
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
