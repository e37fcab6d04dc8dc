"""Thesis Chapters 5 and 6, claim by claim (``python -m bench thesis --only chapter5_6``).

Chapter 5 (``chapter5_6_fmaps``): functional maps per basis type (the CMM ADMM basis at the thesis's μ/n = 0.008
of its 26000-vertex hand pair) on a mesh and three copies with a known correspondence — ICP against the true map
(Fig. 5.2), refinement and the transformation errors (Figs.
5.3–5.4), map direction (5.5–5.6), C-orthogonality (5.7–5.9), the geodesic error (5.10), §5.4's summary.
Chapter 6 (``chapter5_6_modes``): the naive f8 overflow (Fig. 6.9), sequential CMMs per smoothing and the
settings under which they are (in)consistent (Figs. 6.10–6.11), μ = 0 against eigs (Fig. 6.12).

Budgets (measured on the shared 2-core machine, 2026-11-26): full mode 1.8–2.7 min with one OpenBLAS
thread, most of it the two dozen sequential solves of Fig. 6.10 (10 000 iterations each); ``ctx.quick`` 11–15 s,
most of it one JAX compilation of the sequential solver, shared by Figs. 6.10–6.12. Figures: ``ch5_6_*.png``.
"""

from __future__ import annotations

from bench.thesis import Claim, Context
from bench.thesis import chapter5_6_fmaps, chapter5_6_modes

__all__ = ["claims"]


def claims(ctx: Context) -> list[Claim]:
    """Every claim of Chapters 5 and 6, in the thesis's order (measured cheapest first: Fig. 6.9, Chapter 5,
    then the sequential solves)."""
    out = [chapter5_6_modes.fig_6_9(ctx)]
    out += chapter5_6_fmaps.claims(ctx)
    out += chapter5_6_modes.figs_6_10_6_11(ctx)
    out.append(chapter5_6_modes.fig_6_12(ctx))
    order = {c.key: i for i, c in enumerate(out)}
    return sorted(out, key=lambda c: (c.key.lstrip("Fig. §")[0], order[c.key]))
