"""Helpers of ``bench.thesis.chapter7_8``: meshes per mode, local functions of a target size, error rows,
timing and the rendered mode sheets.

Quick mode (``ctx.quick``) always uses the generated 642-vertex examples (``mesh.example(name, size=0)``),
so ``--quick`` measures the same thing with or without ``../shared``; full mode takes the thesis's mesh
or its closest shared stand-in through ``Context.mesh``.
"""

from __future__ import annotations

import io
import time
import traceback

import numpy as np

import mesh
from bench.thesis import Claim

__all__ = ["pick_mesh", "sized_local_functions", "guarded", "timed", "mode_sheet", "fmt_s", "pct"]


def pick_mesh(ctx, shared: str, stand_in: str, thesis_mesh: str) -> tuple[mesh.Mesh, str]:
    """``(mesh, label)``: full mode ``ctx.mesh(shared, stand_in)``; quick mode the smallest generated version
    of the stand-in example (642 vertices for bumpy and starfish). The label gives n and the thesis mesh."""
    if ctx.quick:
        name = stand_in.split(":", 1)[1]
        m = mesh.example(name, size=0 if name in ("bumpy", "starfish") else 1, warn=False)
        return m, f"example:{name} small, n = {m.n_vertices} (quick stand-in; thesis: {thesis_mesh})"
    m, label = ctx.mesh(shared, stand_in)
    return m, f"{label}, n = {m.n_vertices} (thesis: {thesis_mesh})"


def sized_local_functions(m: mesh.Mesh, d_target: int, seed: int = 0) -> tuple[mesh.LocalFunctions, float]:
    """``mesh.local_functions`` with about ``d_target`` columns and its seconds (the chosen sampling only).
    The Poisson-disk count is approximate and steep near the mesh resolution (fandisk: 1000 requested → 735,
    1361 → 1326), so up to four more samplings, interpolating the request between the closest counts below
    and above the target, while more than 5 % off; the closest is kept."""
    request, best, lo, hi = d_target, None, None, None
    for _ in range(5):
        t0 = time.perf_counter()
        lf = mesh.local_functions(m, n_samples=max(request, 2), seed=seed)
        t = time.perf_counter() - t0
        d = lf.U.shape[1]
        if best is None or abs(d - d_target) < abs(best[0].U.shape[1] - d_target):
            best = (lf, t)
        if abs(d - d_target) <= 0.05 * d_target:
            break
        if d < d_target:
            lo = (request, d)
        else:
            hi = (request, d)
        if lo and hi and hi[1] > lo[1]:
            request = int(round(lo[0] + (hi[0] - lo[0]) * (d_target - lo[1]) / (hi[1] - lo[1])))
        else:
            request = int(round(request * d_target / d))
    return best


def guarded(key: str, subject: str, fn, *args, **kwargs) -> list[Claim]:
    """``fn(*args)`` as a list of claims; an exception becomes one "error" claim for ``key`` (so one failed
    measurement does not take the chapter's other rows with it)."""
    t0 = time.perf_counter()
    try:
        out = fn(*args, **kwargs)
    except Exception as e:  # noqa: BLE001 — reported in the document, never swallowed
        tb = traceback.format_exception_only(type(e), e)[-1].strip()
        return [Claim(key=key, subject=subject, thesis="", ours="", setting="", verdict="error", reason=tb,
                      seconds=time.perf_counter() - t0)]
    return out if isinstance(out, list) else [out]


def timed(fn, *args, **kwargs):
    """``(seconds, fn(*args, **kwargs))``."""
    t0 = time.perf_counter()
    out = fn(*args, **kwargs)
    return time.perf_counter() - t0, out


def mode_sheet(ctx, m: mesh.Mesh, rows: list, row_titles: list, col_titles: list, name: str, title: str) -> str:
    """Render ``rows`` (a list of ``(n, c)`` fields) as one sheet (``stiefel_cmm.cli.render.grid_sheet``: one row per
    field set, one column per function, colours symmetric per panel) and save it as ``name``."""
    import matplotlib.pyplot as plt
    from PIL import Image

    from stiefel_cmm.cli.render import grid_sheet

    buf = io.BytesIO()
    grid_sheet(buf, np.asarray(m.vertices), np.asarray(m.faces), rows, row_titles=row_titles,
               col_titles=col_titles, dpi=75, panel=1.3)
    buf.seek(0)
    im = np.asarray(Image.open(buf).convert("RGB"))
    fig = plt.figure(figsize=(im.shape[1] / 100, im.shape[0] / 100 + 0.35), dpi=100)
    ax = fig.add_axes((0.0, 0.0, 1.0, im.shape[0] / (im.shape[0] + 35)))
    ax.imshow(im, interpolation="none")
    ax.set_axis_off()
    fig.text(0.01, 0.995, title, fontsize=9, va="top")
    path = ctx.save_figure(fig, name)
    plt.close(fig)
    return path


def fmt_s(t: float) -> str:
    """Seconds with sensible digits."""
    return f"{t:.3g} s" if t < 100 else f"{t:.0f} s"


def pct(x: float) -> str:
    """A relative difference as a signed percentage."""
    return f"{100 * x:+.2f} %"
