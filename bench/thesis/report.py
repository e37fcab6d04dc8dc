"""``python -m bench thesis [--quick] [--only MODULE …] [--out FILE] [--rerender]``: measure, write the report.

The default run measures every claim on the closest shared mesh (``bench.thesis.Context.mesh``) and writes
``docs/THESIS.md`` with its figures in ``docs/thesis/``; ``--quick`` uses small sizes and short budgets (the
tests run it into a temporary directory). A module that raises becomes one "error" row with the exception, so
the report is always written and never claims what was not measured. Written atomically, figures first. The claims
are stored beside the figures (``thesis/claims.json``, with each module's commit, date and seconds): ``--only``
replaces one module's rows and keeps the others', ``--rerender`` writes the report from the store alone.

Verdicts follow one rule, written in the report's header (``RULE``): the chapter modules decide each verdict
from the claim's own numbers with ``by_number``, ``by_count``, ``by_identity``, ``composite`` and ``worst``,
which return a ``Judgement`` (verdict, the part of the rule used, the numbers it was decided from). The report
records the commit it was generated at; ``read_verdicts`` reads a written report back (the tests compare a
quick run's verdicts with the committed report's).
"""

from __future__ import annotations

import argparse
import dataclasses
import fractions
import importlib
import json
import math
import os
import re
import sys
import time
import traceback
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # like the other benches: a shared 2-core machine

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # an application: float64

from bench.environment import header_lines, run_meta, write_atomic  # noqa: E402
from bench.thesis import MODULES, ROOT, VERDICTS, Claim, Context  # noqa: E402

__all__ = ["run", "render", "main", "RULE", "BAND", "SHARE", "TOL", "MIN_STARTS", "Judgement", "by_number", "by_count",
           "by_identity", "composite", "worst", "not_checkable", "read_verdicts"]

#: a number within this factor of the thesis's (either way) is "reproduced"
BAND = 1.3
#: a statement over cases that holds in at least this share of them is "qualitatively" reproduced
SHARE = fractions.Fraction(2, 3)
#: an identity (a lemma or theorem, exact in exact arithmetic) holds when its relative residual is at most this
TOL = 1e-8
#: a claim that rests on a random start is measured from at least this many starts (full run)
MIN_STARTS = 5

#: the verdict rule, as the report's header states it
RULE = (
    "Verdict rule (every verdict is computed from the row's own numbers, in `bench/thesis/report.py`; the "
    "column \"basis\" names the part used and its numbers):",
    f"  * **number** — the thesis prints a number (a ratio, a time, a count) and we measure the same quantity: "
    f"*reproduced* when ours is within a factor {BAND} of the thesis's (either way); *qualitatively* when it is "
    "outside that band but on the thesis's side of the neutral value (1 for a ratio such as \"× faster\", 0 for a "
    "difference); *differs* when it is on the other side. Over several random starts the band is applied to the "
    "mean and the side must hold in every start, else *differs*. A number the thesis gives only as an order of "
    "magnitude (\"of order 1e-1\") has the band ×√10 and no side.",
    f"  * **count** — a statement over cases (\"for every pair\", \"in every basis\", a trend over a list): "
    f"*reproduced* when it holds in every case measured, *qualitatively* in at least {SHARE} of them, "
    "*differs* below that.",
    f"  * **identity** — a lemma or theorem, exact in exact arithmetic: *reproduced* when its relative residual "
    f"is at most the stated tolerance (round-off; {TOL:g} unless the row says otherwise), else *differs*.",
    "  * **composite** — a headline with details (e.g. \"function type matters more; WKS and SEG worst\"): the "
    "headline's verdict, lowered to *qualitatively* when a detail is not reproduced; two headline numbers "
    "(time and iterations) take the worse of their verdicts.",
    "  * **none** — no number or trend of the thesis can be measured here: *not checkable*, with the reason.",
    f"  * Claims resting on a random start use at least {MIN_STARTS} starts and report the spread. The stopping "
    "rule and the comparison (which solver forms are paired) are fixed in the code before the run; other "
    "stopping rules (e.g. an objective plateau) are reported as notes and never set a verdict.",
    "  * A quick run (`--quick`: reduced sizes) reports *reproduced* as *qualitatively* except for identities, "
    "whose verdict does not depend on the size; those are the rows the default tests compare with this report.",
)


@dataclasses.dataclass(frozen=True)
class Judgement:
    """A verdict with the part of ``RULE`` that gave it (``rule``) and the numbers it was decided from
    (``basis``); ``Claim(..., **j.kwargs())``."""

    verdict: str
    rule: str
    basis: str

    def kwargs(self) -> dict:
        return {"verdict": self.verdict, "rule": self.rule, "basis": self.basis}


def _g(x: float) -> str:
    return f"{x:.3g}"


def by_number(ours: float, thesis: float, *, neutral: float | None = 1.0, starts=None, band: float = BAND,
              what: str = "") -> Judgement:
    """``RULE``'s number part: ours (the mean over ``starts`` when given) against the thesis's number.

    neutral: the value that means "no effect" (1 for a ratio, 0 for a difference); the thesis's number lies on
    one side of it, and ours must lie on that side — in every start when ``starts`` (one value per start) is
    given — for "qualitatively" or better. ``neutral=None``: a number without a direction (only the band).
    """
    ours, thesis = float(ours), float(thesis)
    vals = [float(v) for v in (starts if starts is not None else [ours])]
    ratio = ours / thesis if thesis != 0 else math.inf
    in_band = thesis != 0 and ratio > 0 and abs(math.log(ratio)) <= math.log(band)
    spread = f" (starts {_g(min(vals))}–{_g(max(vals))}, {len(vals)} starts)" if starts is not None else ""
    head = f"{what + ': ' if what else ''}ours {_g(ours)}{spread} vs thesis {_g(thesis)}"
    if neutral is None:
        v = "reproduced" if in_band else "differs"
        return Judgement(v, "number", f"{head}; {'within' if in_band else 'outside'} ×{band:.3g}")
    side = math.copysign(1.0, thesis - neutral)
    same = [math.copysign(1.0, x - neutral) == side and x != neutral for x in vals]
    if in_band and all(same):
        v, why = "reproduced", f"within ×{band:.3g}"
    elif all(same):
        v, why = "qualitatively", f"outside ×{band:.3g}, on the thesis's side of {_g(neutral)}"
    else:
        v = "differs"
        why = (f"on the other side of {_g(neutral)}" if not any(same) else
               f"on the thesis's side of {_g(neutral)} in {sum(same)} of {len(vals)} starts only")
    return Judgement(v, "number", f"{head}; {why}")


def by_count(hits: int, total: int, what: str = "cases") -> Judgement:
    """``RULE``'s count part: the statement holds in ``hits`` of ``total`` cases."""
    hits, total = int(hits), int(total)
    if total <= 0:
        return Judgement("not checkable", "none", f"no {what} to count")
    v = "reproduced" if hits == total else "qualitatively" if hits >= SHARE * total else "differs"
    return Judgement(v, "count", f"{hits}/{total} {what}")


def by_identity(residual: float, tol: float = TOL, what: str = "residual") -> Judgement:
    """``RULE``'s identity part: a relative ``residual`` against ``tol``."""
    ok = bool(residual <= tol)
    return Judgement("reproduced" if ok else "differs", "identity",
                     f"{what} {float(residual):.1e} {'≤' if ok else '>'} {tol:g}")


_ORDER = {"reproduced": 0, "qualitatively": 1, "differs": 2, "not checkable": 3, "error": 4}


def worst(*parts: Judgement, names=None) -> Judgement:
    """Several headline parts of one claim (e.g. time and iterations): the worst verdict."""
    names = names or [f"part {i + 1}" for i in range(len(parts))]
    v = max((p.verdict for p in parts), key=_ORDER.__getitem__)
    return Judgement(v, "composite", "; ".join(f"{n} → {p.verdict} ({p.basis})" for n, p in zip(names, parts)))


def composite(headline: Judgement, **details: Judgement) -> Judgement:
    """A headline and details: the headline's verdict, lowered to "qualitatively" when a detail is not
    reproduced (never raised)."""
    v = headline.verdict
    if v == "reproduced" and any(d.verdict != "reproduced" for d in details.values()):
        v = "qualitatively"
    basis = f"headline → {headline.verdict} ({headline.basis})" + "".join(
        f"; {name.replace('_', ' ')} → {d.verdict} ({d.basis})" for name, d in details.items())
    return Judgement(v, "composite", basis)


def not_checkable(why: str) -> Judgement:
    """``RULE``'s none part."""
    return Judgement("not checkable", "none", why)


def run(ctx: Context, modules=MODULES) -> list[Claim]:
    """Every claim of ``modules`` (an exception in a module becomes one "error" claim)."""
    claims: list[Claim] = []
    for name in modules:
        t0 = time.perf_counter()
        try:
            found = importlib.import_module(name).claims(ctx)
        except Exception as e:  # noqa: BLE001 — reported in the document, never swallowed
            tb = traceback.format_exception_only(type(e), e)[-1].strip()
            found = [Claim(key=name.rsplit(".", 1)[-1], subject="the module's measurements", thesis="", ours="",
                           setting="", verdict="error", reason=tb, seconds=time.perf_counter() - t0)]
        for c in found:
            if ctx.quick and c.verdict == "reproduced" and c.rule != "identity":  # RULE: a quick run's sizes
                c.verdict = "qualitatively"
                c.basis = (c.basis + "; " if c.basis else "") + "quick run: at most qualitatively"
            print(f"{c.key}: {c.verdict} ({c.seconds:.1f} s)", file=sys.stderr, flush=True)
        claims.extend(found)
    return claims


def _cell(text: str) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def render(claims: list[Claim], meta: dict) -> str:
    """The markdown report: header, verdict counts, the table, then each claim's figures."""
    counts = {v: sum(c.verdict == v for c in claims) for v in VERDICTS}
    lines = ["# The thesis reproduced: claim by claim", "",
             "Generated by `python -m bench thesis` — do not edit by hand. Each row is one checkable "
             "claim of the thesis: its number, ours on the closest mesh we have, the setting and a verdict "
             "(reproduced / qualitatively / differs, with the measured reason).", "",
             *header_lines(meta), f"* mode: {'quick (small sizes, short budgets)' if meta.get('quick') else 'full'}",
             *([f"* generated per module: {meta['modules']}"] if meta.get("modules") else []),
             "* verdicts: " + ", ".join(f"{n} {v}" for v, n in counts.items() if n), "", *RULE, "",
             "| claim | subject | thesis | ours | setting | verdict | basis (rule: numbers) | reason / notes | s |",
             "|---|---|---|---|---|---|---|---|---:|"]
    for c in claims:
        basis = f"{c.rule}: {c.basis}" if c.rule else c.basis
        lines.append(f"| {_cell(c.key)} | {_cell(c.subject)} | {_cell(c.thesis)} | {_cell(c.ours)} | "
                     f"{_cell(c.setting)} | **{c.verdict}** | {_cell(basis)} | {_cell(c.reason)} | {c.seconds:.1f} |")
    pictures = [c for c in claims if c.figures]
    if pictures:
        lines += ["", "## Figures", ""]
        for c in pictures:
            lines.append(f"### {c.key}: {c.subject}")
            lines.append("")
            lines += [f"![{c.key}]({path})" for path in c.figures]
            lines.append("")
    return "\n".join(lines).rstrip() + "\n"


def read_verdicts(text: str) -> dict:
    """A written report read back: ``{"commit": str, "mode": str, "rows": {key: (verdict, rule)}}`` (rule ""
    for a report written before the rule column)."""
    commit = re.search(r"^\* commit: ([^;]+);", text, re.M)
    mode = re.search(r"^\* mode: (\w+)", text, re.M)
    rows = {}
    for line in text.splitlines():
        if line.startswith("| ") and "| **" in line:
            cells = [c.strip() for c in re.split(r"(?<!\\)\|", line)[1:-1]]
            verdict, rule = cells[5].strip("*"), ""
            if len(cells) == 9 and ":" in cells[6]:
                rule = cells[6].split(":", 1)[0]
            rows[cells[0].replace("\\|", "|")] = (verdict, rule)
    return {"commit": commit.group(1).strip() if commit else "unknown", "mode": mode.group(1) if mode else "",
            "rows": rows}


def _store(out: Path) -> Path:
    """The claims behind a report, as JSON beside its figures (``--only`` merges into it)."""
    return out.parent / "thesis" / "claims.json"


def merged(out: Path, ran: dict, meta: dict, wall: dict | None = None) -> tuple[list[Claim], dict]:
    """The claims of the modules just run (``ran``: module → claims; ``wall``: module → seconds) and, for the
    others, those stored beside ``out`` by an earlier run of the same mode (``--only`` regenerates part of a
    report); the store updated."""
    path = _store(out)
    store = {}
    if path.is_file():
        try:
            store = json.loads(path.read_text())
        except (OSError, ValueError):
            store = {}
    if store.get("mode") != ("quick" if meta.get("quick") else "full"):
        store = {}
    store["mode"] = "quick" if meta.get("quick") else "full"
    mods = store.setdefault("modules", {})
    for name, found in ran.items():
        for c in found:
            c.seconds = float(c.seconds)
        mods[name] = {"commit": meta.get("commit", "unknown"), "date": meta.get("date", ""),
                      "seconds": (wall or {}).get(name, sum(c.seconds for c in found)),
                      "claims": [dataclasses.asdict(c) for c in found]}
    claims = [Claim(**c) for name in MODULES if name in mods for c in mods[name]["claims"]]
    return claims, store


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m bench thesis", description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="small sizes and short budgets (seconds per claim)")
    p.add_argument("--only", nargs="+", choices=[m.rsplit(".", 1)[-1] for m in MODULES], metavar="MODULE",
                   help=f"run only these chapter modules ({', '.join(m.rsplit('.', 1)[-1] for m in MODULES)})")
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "THESIS.md",
                   help="the report (figures go to thesis/ beside it)")
    p.add_argument("--rerender", action="store_true",
                   help="measure nothing: write the report from the claims stored beside it (thesis/claims.json)")
    args = p.parse_args(argv)
    out = args.out.resolve()
    ctx = Context(quick=args.quick, docs=out.parent, figures=out.parent / "thesis")
    modules = MODULES if not args.only else tuple(m for m in MODULES if m.rsplit(".", 1)[-1] in args.only)
    if args.rerender:
        modules = ()
    meta = run_meta("bench thesis", argv, quick=args.quick)
    ran, wall = {}, {}
    for name in modules:
        t0 = time.perf_counter()
        ran[name] = run(ctx, (name,))
        wall[name] = time.perf_counter() - t0
        print(f"{name}: {wall[name]:.0f} s", file=sys.stderr, flush=True)
    claims, store = merged(out, ran, meta, wall)
    parts = store["modules"]
    meta["modules"] = "; ".join(f"{name.rsplit('.', 1)[-1]} at {parts[name]['commit']} ({parts[name]['date']}, "
                                f"{parts[name]['seconds'] / 60:.1f} min)" for name in MODULES if name in parts)
    out.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(_store(out), json.dumps(store, indent=1, ensure_ascii=False, default=float) + "\n")
    write_atomic(out, render(claims, meta))
    print(f"wrote {out}", file=sys.stderr)
    return 0 if all(c.verdict != "error" for found in ran.values() for c in found) else 1


if __name__ == "__main__":
    sys.exit(main())
