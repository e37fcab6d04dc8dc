"""Named errors of the manifold layer. All derive from ``StiefelError`` (a ``ValueError``)."""

from __future__ import annotations


class StiefelError(ValueError):
    """Base class for bad input to the manifold layer."""


class ParameterError(StiefelError):
    """An option is of the wrong type or out of its range (e.g. ``max_iters=0``, ``c1 > c2``, a NaN tolerance)."""


class NotSPDError(StiefelError):
    """``M`` is not symmetric positive definite (or not symmetric at all)."""


class NonFiniteError(StiefelError):
    """A matrix or array given as input has NaN or infinite entries."""


class ShapeError(StiefelError):
    """Arrays do not have the shapes the operation needs (e.g. ``k > n``)."""


class OffManifoldError(StiefelError):
    """A start point does not satisfy ``XᵀMX = I``; see ``GeneralizedStiefel.project_to_manifold``."""


class RankDeficientError(OffManifoldError):
    """A start's columns are linearly dependent in the M inner product: no point of the manifold is near it."""


class OutOfDomainError(StiefelError):
    """An operation outside its domain, e.g. ``log(X, Y)`` for points with no logarithm shorter than the
    injectivity radius (``stiefel.manifolds.geodesics``)."""


class SolverError(StiefelError):
    """A solver ended with a bad status and ``throw=True`` was asked for."""


class ObjectiveSignatureError(StiefelError):
    """An objective's signature does not fit the call: ``F(X)``, or ``F(X, args)`` as ``optx.minimise`` calls it."""
