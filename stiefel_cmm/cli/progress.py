"""Solver progress on stderr: a tqdm bar on a terminal, plain periodic lines otherwise, nothing with --quiet.

``SolveProgress`` is the ``progress=`` callback the commands pass to ``compressed_modes``; it receives
``stiefel.Progress`` reports (a few per second at most, ``stiefel.solvers.driver``). On a terminal it draws a
``tqdm`` counter (iterations, rate, objective, gradient norm, continuation stage, estimated time left);
when stderr is not a terminal (a log file, CI) it prints one line every ``period`` seconds and the last
report. Always stderr, so ``--json`` keeps stdout to its one JSON object.
"""

from __future__ import annotations

import math
import sys
import time
from typing import Any, TextIO

__all__ = ["SolveProgress"]


class SolveProgress:
    """``progress=`` for the solvers (module docstring); ``close()`` ends the bar."""

    def __init__(self, *, quiet: bool = False, label: str = "solve", stream: TextIO | None = None,
                 period: float = 2.0) -> None:
        self.quiet, self.label, self.period = quiet, label, period
        self.stream = stream if stream is not None else sys.stderr
        self.bar: Any = None
        self.last_line = float("-inf")
        self.pending: Any = None
        self.reports = 0

    def _tty(self) -> bool:
        try:
            return bool(self.stream.isatty())
        except (AttributeError, ValueError):
            return False

    def __call__(self, info: Any) -> None:
        if self.quiet:
            return
        self.reports += 1
        if self._tty():
            self._draw(info)
            return
        now = time.perf_counter()
        if now - self.last_line >= self.period:
            self._print(info)
            self.last_line, self.pending = now, None
        else:
            self.pending = info

    def _draw(self, info: Any) -> None:
        if self.bar is None:
            from tqdm import tqdm

            self.bar = tqdm(desc=self.label, unit="it", file=self.stream, dynamic_ncols=True, leave=True)
        self.bar.update(max(0, info.iteration - self.bar.n))
        post = {}
        if math.isfinite(info.objective):  # NaN: not known (eigsh)
            post["f"] = f"{info.objective:.6g}"
        if math.isfinite(info.grad_norm):
            post["|g|"] = f"{info.grad_norm:.1e}"
        if info.n_stages > 1:
            post["stage"] = f"{info.stage + 1}/{info.n_stages}"
        if info.remaining is not None and info.remaining > 0:
            post["left"] = f"~{info.remaining:.0f}s"
        self.bar.set_postfix(post, refresh=True)

    def _print(self, info: Any) -> None:
        print(f"{self.label}: {info.line()}", file=self.stream, flush=True)

    def close(self) -> None:
        """Finish the bar, or print the last report not yet printed."""
        if self.bar is not None:
            self.bar.close()
            self.bar = None
        elif self.pending is not None and not self.quiet:
            self._print(self.pending)
            self.pending = None
