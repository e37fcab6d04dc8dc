"""Text and layout of the contact sheets (:mod:`stiefel_cmm.cli.render`): rows, columns, colour bars and labels in
pixels (:func:`sheet_layout`), and text drawn straight into the ``uint8`` canvas — DejaVu Sans (the font
matplotlib ships) through PIL's FreeType, glyph clusters cached — so a sheet imports no matplotlib.
"""

from __future__ import annotations

import functools
from typing import NamedTuple, Sequence

import numpy as np

__all__ = ["Box", "Label", "Layout", "sheet_layout", "draw_text", "FONT_ROW", "FONT_COLUMN", "FONT_TICK"]

#: font sizes in points: row titles, column titles, colour-bar ticks and panel captions
FONT_ROW, FONT_COLUMN, FONT_TICK = 8.5, 9.0, 7.0
#: colour of text and outlines
_INK = (30, 30, 30)


# ---------------------------------------------------------------------------------------------------------------
# text: DejaVu Sans through PIL's FreeType, drawn straight into the canvas


@functools.lru_cache(maxsize=1)
def _font_path() -> str:
    """DejaVu Sans as shipped with matplotlib, found without importing matplotlib (~0.3 s: the sheet itself
    takes about half that); matplotlib's default font otherwise."""
    import importlib.util
    import os

    spec = importlib.util.find_spec("matplotlib")
    for folder in (spec.submodule_search_locations or []) if spec else []:
        path = os.path.join(folder, "mpl-data", "fonts", "ttf", "DejaVuSans.ttf")
        if os.path.isfile(path):
            return path
    from matplotlib import font_manager

    return font_manager.findfont(font_manager.FontProperties())


@functools.lru_cache(maxsize=16)
def _font(size_px: float):
    from PIL import ImageFont

    return ImageFont.truetype(_font_path(), size_px)


@functools.lru_cache(maxsize=4096)
def _cluster_bitmap(cluster: str, size_px: float) -> tuple[np.ndarray, int, float, float]:
    """One character and its combining marks, rendered by FreeType (through PIL, shaped by libraqm where
    PIL has it): ``(alpha (h, w) uint8, baseline row, x of column 0 from the pen, advance)`` in pixels."""
    font = _font(size_px)
    mask, (left, top) = font.getmask2(cluster, "L", anchor="ls")
    img = np.array(mask, dtype=np.uint8).reshape(mask.size[1], mask.size[0])
    return img, -top, float(left), float(font.getlength(cluster))


@functools.lru_cache(maxsize=1024)
def _text_bitmap(text: str, size_px: float) -> tuple[np.ndarray, int, int]:
    """``(alpha (h, w) uint8, baseline row, x offset)`` of ``text`` at ``size_px`` pixels per em: cached glyph
    clusters (a character and its combining marks) side by side at their advances (no kerning; shaping
    whole strings costs ~0.5 ms each, a cluster is drawn once per sheet)."""
    import unicodedata

    clusters: list[str] = []
    for ch in text:
        if clusters and unicodedata.combining(ch):
            clusters[-1] += ch
        else:
            clusters.append(ch)
    parts, pen = [], 0.0
    for cl in clusters:
        img, base, left, advance = _cluster_bitmap(cl, size_px)
        parts.append((img, base, int(round(pen + left))))
        pen += advance
    x0 = min((x for _, _, x in parts), default=0)
    above = max((base for _, base, _ in parts), default=0)
    below = max((img.shape[0] - base for img, base, _ in parts), default=0)
    width = max((x + img.shape[1] for img, _, x in parts), default=0) - x0
    out = np.zeros((above + below, max(width, 0)), dtype=np.uint8)
    for img, base, x in parts:
        region = out[above - base:above - base + img.shape[0], x - x0:x - x0 + img.shape[1]]
        np.maximum(region, img, out=region)
    out.flags.writeable = False
    return out, above, x0


def _text_width(text: str, pt: float, dpi: float) -> int:
    return _text_bitmap(text, pt * dpi / 72.0)[0].shape[1] if text else 0


def draw_text(canvas: np.ndarray, label: Label, dpi: float) -> None:
    """Blend ``label`` (dark ink) into ``canvas (H, W, 3)`` uint8; clipped at the canvas's edges."""
    if not label.text:
        return
    img, base, off = _text_bitmap(label.text, label.size * dpi / 72.0)
    h, w = img.shape
    x = label.x + off - (w // 2 if label.ha == "center" else w if label.ha == "right" else 0)
    y = label.y - base
    y0, x0 = max(y, 0), max(x, 0)
    y1, x1 = min(y + h, canvas.shape[0]), min(x + w, canvas.shape[1])
    if y1 <= y0 or x1 <= x0:
        return
    a = img[y0 - y:y1 - y, x0 - x:x1 - x, None].astype(np.float32) * (1.0 / 255.0)
    region = canvas[y0:y1, x0:x1]
    region[...] = np.round(region * (1.0 - a) + np.asarray(_INK, np.float32) * a)


# ---------------------------------------------------------------------------------------------------------------
# layout (pixels, row 0 on top)


class Label(NamedTuple):
    """Text ``text`` with its baseline at row ``y``, anchored at column ``x`` (``ha``: left, center, right),
    ``size`` in points; ``role``: ``"row"``, ``"column"``, ``"tick"`` or ``"caption"``."""

    text: str
    x: int
    y: int
    size: float
    ha: str
    role: str


class Box(NamedTuple):
    """A rectangle ``(x, y)`` (top-left) ``w × h`` of row ``row`` and column ``col`` (``-1``: the row's bar)."""

    row: int
    col: int
    x: int
    y: int
    w: int
    h: int


class Layout(NamedTuple):
    """The sheet: ``width × height`` pixels, ``panels`` (one picture each), ``bars`` (one colour bar per row,
    +max at the top) and ``labels``."""

    width: int
    height: int
    panels: list[Box]
    bars: list[Box]
    labels: list[Label]


def sheet_layout(row_titles: Sequence[str], col_titles: Sequence[str], bar_ticks: Sequence[Sequence[str]], *,
                 panel_width: int, panel_height: int, dpi: float,
                 captions: Sequence[Sequence[str]] | None = None) -> Layout:
    """Rows of panels, each under its row title, with column titles on top and a colour bar at the right of
    every row; ``bar_ticks[j]`` = ``(top, middle, bottom)`` tick labels of row j's bar; ``captions[j][i]``
    (optional) a small line under panel ``(j, i)``. All sizes scale with ``dpi`` (80 is the reference)."""
    s = dpi / 80.0
    rows, cols = len(row_titles), len(col_titles)
    margin, gap_x, gap_y = round(8 * s), round(4 * s), round(6 * s)
    header = round(16 * s) if any(col_titles) else 0
    title_band = round(15 * s)
    caption_band = round(12 * s) if captions is not None else 0
    bar_w = round(10 * s)
    row_h = title_band + panel_height + caption_band + gap_y
    panels_w = cols * panel_width + (cols - 1) * gap_x
    bar_x = margin + panels_w + round(10 * s)
    tick_x = bar_x + bar_w + round(5 * s)
    tick_w = max((_text_width(t, FONT_TICK, dpi) for ticks in bar_ticks for t in ticks), default=0)
    width = max(tick_x + tick_w + margin,
                max((_text_width(t, FONT_ROW, dpi) for t in row_titles), default=0) + 2 * margin)
    height = margin + header + rows * row_h - gap_y + margin
    labels = [Label(t, margin + i * (panel_width + gap_x) + panel_width // 2, margin + round(11 * s), FONT_COLUMN,
                    "center", "column") for i, t in enumerate(col_titles)]
    panels, bars = [], []
    tick_lift = round(0.35 * FONT_TICK * dpi / 72.0)           # baseline below the tick: text centred on it
    for j, title in enumerate(row_titles):
        top = margin + header + j * row_h
        labels.append(Label(title, margin, top + round(11 * s), FONT_ROW, "left", "row"))
        y = top + title_band
        for i in range(cols):
            panels.append(Box(j, i, margin + i * (panel_width + gap_x), y, panel_width, panel_height))
            if captions is not None:
                labels.append(Label(captions[j][i], margin + i * (panel_width + gap_x) + panel_width // 2,
                                    y + panel_height + round(9 * s), FONT_TICK, "center", "caption"))
        bar_h = max(round(0.8 * panel_height), 3)
        bar_y = y + (panel_height - bar_h) // 2
        bars.append(Box(j, -1, bar_x, bar_y, bar_w, bar_h))
        for t, ty in zip(bar_ticks[j], (bar_y, bar_y + (bar_h - 1) // 2, bar_y + bar_h - 1)):
            labels.append(Label(t, tick_x, ty + tick_lift, FONT_TICK, "left", "tick"))
    return Layout(int(width), int(height), panels, bars, labels)
