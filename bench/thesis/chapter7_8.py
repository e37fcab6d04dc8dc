"""Thesis Chapters 7 and 8, claim by claim (``python -m bench thesis --only chapter7_8``).

Chapter 7 (fast approximation): ``chapter7_8_local`` — local functions and the restricted eigenproblem
(Lemmas 7.1.2–7.1.3, the 7–15 coverage, Figs. 7.1–7.3); ``chapter7_8_restrict`` — Proposition 7.1.4
(restricted eigenfunctions commute with isometry), the sparsity of the restricted matrices (Fig. 7.4) and
§7.4's restricted LMHs; ``chapter7_8_admm`` — Algorithm 8 against ADMM (Tables 7.1–7.2, Fig. 7.5).
Chapter 8 (key results): ``chapter7_8_ch8`` — each checkable key result, one claim each.

Budgets: Table 7.1's runs dominate — 5 random starts × ADMM/fast × exact/printed forms on fandisk, 5 × the
printed pair on the humanoid at ScapeMan001's size (12500) and at 3000 and 6000 vertices for the size trend; the
full module's time is in the report's header (``docs/THESIS.md``: generated per module). ``ctx.quick``: 642-vertex
generated meshes, 2 starts, 800 ADMM iterations (seconds, most of them the JAX compilations of the §6.1 and
Algorithm 6 checks).
Figures: ``ch7_8_*.png``.
"""

from __future__ import annotations

from bench.thesis import Claim, Context
from bench.thesis import chapter7_8_admm as admm
from bench.thesis import chapter7_8_ch8 as ch8
from bench.thesis import chapter7_8_local, chapter7_8_restrict
from bench.thesis.chapter7_8_util import guarded

__all__ = ["claims"]


def claims(ctx: Context) -> list[Claim]:
    """Every claim of Chapters 7 and 8, in thesis order."""
    out = chapter7_8_local.claims(ctx)
    out += chapter7_8_restrict.claims(ctx)
    held: dict = {}

    def measure() -> list:
        held["data"] = admm.runs(ctx)
        return []

    table = guarded("Tables 7.1–7.2, Fig. 7.5", "Algorithm 8 vs ADMM (the runs)", measure)
    data = held.get("data")
    if data is not None:
        t71 = guarded("Table 7.1", "fast approximation vs ADMM", admm.table_7_1, data)
        table = t71 + guarded("Table 7.2", "per-step times", admm.table_7_2, data)
        table += guarded("Fig. 7.5", "CMMs: fast vs ADMM", admm.fig_7_5, ctx, data)
    lmh = [c for c in out if c.key.startswith("§7.4")]
    out = [c for c in out if not c.key.startswith("§7.4")] + table + lmh
    out += guarded("§8 key result: isometry", "LMHs and CMMs commute with isometry", ch8.isometry, ctx)
    out += guarded("§8 key result: function type", "function type vs basis type", ch8.reconstruction, ctx)
    out += guarded("§8 key result: §6.1", "generalised Stiefel manifolds", ch8.stiefel_properties, ctx)
    out += guarded("§8 key result: Algorithm 6", "the sequential algorithm", ch8.sequential, ctx)
    if data is not None:
        out += guarded("§8 key result: Algorithm 8", "fast CMMs", ch8.algorithm_8, data, t71)
        out += guarded("§8 conclusions: CMM subspace", "CMMs vs eigenfunctions", ch8.cmm_subspace, data)
    return out
