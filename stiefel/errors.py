"""Named errors of the manifold layer. All derive from ``StiefelError`` (a ``ValueError``)."""

from __future__ import annotations


class StiefelError(ValueError):
    """Base class for bad input to the manifold layer."""


class NotSPDError(StiefelError):
    """``M`` is not symmetric positive definite (or not symmetric at all)."""


class ShapeError(StiefelError):
    """Arrays do not have the shapes the operation needs (e.g. ``k > n``)."""


class OffManifoldError(StiefelError):
    """A start point does not satisfy ``XᵀMX = I``; see ``GeneralizedStiefel.project_to_manifold``."""


class SolverError(StiefelError):
    """A solver ended with a bad status and ``throw=True`` was asked for."""
