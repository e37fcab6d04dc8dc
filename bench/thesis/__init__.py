"""The thesis reproduced, claim by claim: ``python -m bench thesis [--quick]`` → ``docs/THESIS.md``.

Each chapter module (``MODULES``) exposes ``claims(ctx: Context) -> list[Claim]``: it measures the claims of
its chapters on the mesh closest to the thesis's (``Context.mesh``: a shared mesh under ``../shared/meshes``
when present, else a shipped example standing in for it — the report says which) and returns one ``Claim``
per checkable statement: the thesis's number, ours, the setting, and a verdict with the measured reason.
``bench.thesis.report`` runs them and writes the report (atomically); ``--quick`` runs small sizes and
short budgets (the tests run it).
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy loads (via mesh): a shared 2-core machine

from mesh import Mesh  # noqa: E402
from bench.meshes import load_mesh, mesh_path  # noqa: E402

__all__ = ["Claim", "Context", "VERDICTS", "RULES", "MODULES"]

#: the verdicts a claim can get ("error": the measurement raised; the report shows the exception)
VERDICTS = ("reproduced", "qualitatively", "differs", "not checkable", "error")

#: the parts of the verdict rule (``bench.thesis.report.RULE``); "" only for "error" rows and old-style claims
RULES = ("number", "count", "identity", "composite", "none", "")

#: the chapter modules, in report order (``extra_claims``: the cheap checks of results the figures do not show)
MODULES = ("bench.thesis.chapter3_4", "bench.thesis.chapter5_6", "bench.thesis.chapter7_8", "bench.thesis.extra_claims")

ROOT = Path(__file__).resolve().parents[2]


@dataclasses.dataclass
class Claim:
    """One checkable statement of the thesis and what we measured.

    key: where it is in the thesis (``"Table 7.1"``, ``"Fig. 4.5"``, ``"§8 key result 2"``); subject: one line;
    thesis: the thesis's number or statement; ours: our measured number; setting: mesh (and which thesis mesh
    it stands for), k, μ, starts, budgets; verdict: one of ``VERDICTS``; reason: for "qualitatively" and
    "differs" the measured reason or the setting that reproduces the thesis (for "reproduced", optional notes);
    figures: PNG paths relative to ``docs/`` (``Context.save_figure``); seconds: the measurement's wall time;
    rule and basis: which part of the report's verdict rule decided the verdict (``RULES``) and the numbers it
    was decided from — set together with the verdict by ``bench.thesis.report``'s ``by_number``, ``by_count``,
    ``by_identity``, ``composite`` and ``worst`` (``Judgement.kwargs()``).
    """

    key: str
    subject: str
    thesis: str
    ours: str
    setting: str
    verdict: str
    reason: str = ""
    figures: list[str] = dataclasses.field(default_factory=list)
    seconds: float = 0.0
    rule: str = ""
    basis: str = ""

    def __post_init__(self) -> None:
        if self.verdict not in VERDICTS:
            raise ValueError(f"claim {self.key!r}: verdict must be one of {VERDICTS}, got {self.verdict!r}")
        if self.rule not in RULES:
            raise ValueError(f"claim {self.key!r}: rule must be one of {RULES}, got {self.rule!r}")


@dataclasses.dataclass
class Context:
    """What a chapter module gets: ``quick`` (small sizes, short budgets: seconds, not minutes), ``figures``
    (the directory the PNGs go to, normally ``docs/thesis``), ``docs`` (the report's directory; figure paths
    in claims are relative to it) and ``seed``."""

    quick: bool = False
    docs: Path = ROOT / "docs"
    figures: Path = ROOT / "docs" / "thesis"
    seed: int = 0

    def mesh(self, shared: str, stand_in: str) -> tuple[Mesh, str]:
        """The mesh ``shared`` (a name under ``../shared/meshes``) if present, else ``stand_in`` (``example:NAME``,
        shipped with the package) — ``(mesh, label)``; the label says which was used."""
        try:
            mesh_path(shared)
        except (FileNotFoundError, OSError, ValueError):
            m, label = load_mesh(stand_in)
            return m, f"{label} (stand-in for {shared})"
        return load_mesh(shared)

    def save_figure(self, fig, name: str) -> str:
        """Save a matplotlib figure as ``figures/name`` (PNG, atomically); returns its path relative to ``docs``."""
        self.figures.mkdir(parents=True, exist_ok=True)
        target = self.figures / name
        fd, tmp = tempfile.mkstemp(dir=self.figures, prefix=f".{name}.", suffix=".png")
        os.close(fd)
        try:
            fig.savefig(tmp, dpi=110, bbox_inches="tight", format="png")
            os.chmod(tmp, 0o644)  # mkstemp's 0600 would keep the figure from other readers
            os.replace(tmp, target)
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
        return os.path.relpath(target, self.docs)
