"""Helpers of ``bench.thesis.extra_claims``: the mesh its rows measure on, that mesh's Laplacian unpacked, and
the verdict of an exact statement checked by several exact tests."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

import mesh
from bench.thesis import Context
from bench.thesis.chapter7_8_util import pick_mesh
from bench.thesis.report import Judgement
from objectives.cmm.modes import unpack_laplacian

__all__ = ["mesh_for", "laplacian_for", "all_hold"]


def mesh_for(ctx: Context, thesis: str) -> tuple[mesh.Mesh, str]:
    """``(mesh, label)``: hand_868 (quick: the generated 642-vertex bumpy example) standing in for ``thesis``."""
    return pick_mesh(ctx, "hand_868.obj", "example:bumpy", thesis)


def laplacian_for(ctx: Context, thesis: str) -> tuple[mesh.Mesh, str, mesh.Laplacian, sp.csr_array, np.ndarray]:
    """``(mesh, label, laplacian, W, a)``: ``mesh_for``'s mesh, its cotangent Laplacian and that unpacked (W csr,
    a the lumped areas)."""
    m, label = mesh_for(ctx, thesis)
    lap = mesh.laplacian(m)
    W, a = unpack_laplacian(lap)
    return m, label, lap, W, a


def all_hold(checks: dict, what: str) -> Judgement:
    """An exact statement checked by several exact tests (``RULE``'s identity part): reproduced when all hold."""
    failed = [name for name, ok in checks.items() if not ok]
    return Judgement("differs" if failed else "reproduced", "identity",
                     f"{len(checks) - len(failed)}/{len(checks)} {what}" + (f"; failed: {', '.join(failed)}" if failed
                                                                           else ""))
