"""Size buckets: array sizes rounded up to a fixed grid so that problems of similar size share one
compiled program (in a process, and from JAX's persistent compilation cache across processes).

A compiled solver is specialised to its arrays' shapes: the number of rows ``n``, the width of a
``SparseOperator``'s neighbour table and the number of stored entries of a sparse factor. Rounding
each up to a bucket and padding with entries that stay exactly zero (``objectives.cmm.manifold_solvers``
pads a CMM problem) lets every mesh of a bucket reuse one executable, at the price of the padded
rows' arithmetic. The grid is ``base · growthᵐ`` rounded up to a multiple of ``base`` — the same
for every process, so a bucket's program is found again in the persistent cache.
"""

from __future__ import annotations

import math

__all__ = ["bucket", "width_bucket", "check_growth", "DEFAULT_GROWTH"]

#: growth of the size grid used by default (``BlockCMM.bucket_growth``). Measured on fandisk (k = 10,
#: ``docs/benchmarks/first-run.md``): padding by 10 / 20 / 40 % costs about 4 / 7 / 22 % more time per
#: iteration, so 1.1 (padding 0–10 %, mean 5 %) costs ≲ 4 % (mean ≈ 2 %) and still lets meshes within
#: about 10 % of each other's size share a program
DEFAULT_GROWTH = 1.1


def check_growth(growth) -> None:
    """``growth`` must be None (no buckets) or a finite number > 1 (``ValueError`` otherwise)."""
    ok = growth is None or (isinstance(growth, (int, float)) and not isinstance(growth, bool)
                            and math.isfinite(growth) and growth > 1.0)
    if not ok:
        raise ValueError(f"bucket growth must be None (exact sizes) or a finite number > 1, got {growth!r}")


def bucket(size: int, growth: float | None, *, base: int = 64) -> int:
    """The smallest grid value ``≥ size``; the grid starts at ``base`` and each value is the previous
    one times ``growth``, rounded up to a multiple of ``base``. ``growth=None``: ``size`` itself.

    >>> bucket(7229, 1.1), bucket(7000, 1.1), bucket(7229, None)
    (7360, 7360, 7229)
    """
    check_growth(growth)
    size = int(size)
    if size < 0:
        raise ValueError(f"size must be ≥ 0, got {size}")
    if growth is None:
        return size
    value = base
    while value < size:
        value = base * math.ceil(value * growth / base)
    return value


def width_bucket(width: int, growth: float | None, *, step: int = 4) -> int:
    """A neighbour-table width rounded up to a multiple of ``step`` (``growth=None``: unchanged)."""
    check_growth(growth)
    if growth is None:
        return int(width)
    return step * max(1, math.ceil(int(width) / step))
