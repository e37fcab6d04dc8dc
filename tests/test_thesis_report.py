"""bench.thesis: the reproduction report's framework (claims, rendering, error rows, atomic figures), its verdict
rule, and the committed report kept current (a quick run's verdicts against docs/THESIS.md's)."""

from __future__ import annotations

import subprocess
import sys
import types

import pytest

from bench.thesis import ROOT, VERDICTS, Claim, Context
from bench.thesis import report

COMMITTED = ROOT / "docs" / "THESIS.md"


def test_claim_refuses_an_unknown_verdict():
    with pytest.raises(ValueError, match="verdict must be one of"):
        Claim(key="Fig. 1.1", subject="s", thesis="t", ours="o", setting="x", verdict="maybe")
    assert "differs" in VERDICTS and "error" in VERDICTS


def test_a_module_that_raises_becomes_one_error_row(monkeypatch):
    good = types.ModuleType("fake_good")
    good.claims = lambda ctx: [Claim(key="Table 7.1", subject="fast vs ADMM", thesis="7.5×", ours="2.0×",
                                     setting="fandisk | k = 10", verdict="differs", reason="a|b")]
    bad = types.ModuleType("fake_bad")

    def boom(ctx):
        raise RuntimeError("no mesh")

    bad.claims = boom
    monkeypatch.setitem(sys.modules, "fake_good", good)
    monkeypatch.setitem(sys.modules, "fake_bad", bad)
    claims = report.run(Context(quick=True), modules=("fake_good", "fake_bad"))
    assert [c.verdict for c in claims] == ["differs", "error"]
    assert "RuntimeError: no mesh" in claims[1].reason
    text = report.render(claims, {"date": "d", "machine": "m", "jax": "j", "scipy": "s", "numpy": "n",
                                  "command": "c", "quick": True})
    row = next(line for line in text.splitlines() if line.startswith("| Table 7.1"))
    assert "fandisk \\| k = 10" in row and "a\\|b" in row and "**differs**" in row  # pipes escaped
    assert "1 differs, 1 error" in text and "quick" in text


def test_figures_are_written_atomically_and_linked(tmp_path):
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ctx = Context(quick=True, docs=tmp_path, figures=tmp_path / "thesis")
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    rel = ctx.save_figure(fig, "ch0_test.png")
    plt.close(fig)
    assert rel == "thesis/ch0_test.png" and (tmp_path / rel).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in (tmp_path / "thesis").iterdir()] == ["ch0_test.png"]  # no temporary left
    c = Claim(key="Fig. 3.5", subject="μ", thesis="", ours="", setting="", verdict="qualitatively", figures=[rel])
    text = report.render([c], {"date": "d", "machine": "m", "jax": "j", "scipy": "s", "numpy": "n", "command": "c"})
    assert "![Fig. 3.5](thesis/ch0_test.png)" in text


def test_context_falls_back_to_the_shipped_stand_in():
    m, label = Context(quick=True).mesh("no_such_mesh.off", "example:torus")
    assert m.n_vertices > 0 and label == "example:torus (stand-in for no_such_mesh.off)"


@pytest.mark.slow  # ~45 s: a benchmark's report (python -m bench thesis --quick); the parts have fast tests here
def test_quick_report_runs_every_chapter(tmp_path, monkeypatch):
    """``python -m bench thesis --quick``: every chapter module measures its claims (no error row), every claim
    has a verdict and a setting, and every figure the report links exists. On the generated stand-ins
    (``Context.mesh``), as from a fresh clone: ``../shared/meshes`` is hidden even where it exists."""
    import bench.meshes

    monkeypatch.setattr(bench.meshes, "SHARED", tmp_path / "no_shared_meshes")
    out = tmp_path / "THESIS.md"
    rc = report.main(["--quick", "--out", str(out)])
    text = out.read_text()
    assert rc == 0, text
    rows = [line for line in text.splitlines() if line.startswith("| ") and "**" in line]
    keys = {line.split("|")[1].strip() for line in rows}
    assert len(rows) >= 30 and {"Table 7.2", "Fig. 3.5", "Fig. 6.9"} <= keys, keys
    assert any(key.startswith("Table 7.1") for key in keys), keys
    assert "**error**" not in text
    for path in (line.split("](", 1)[1].rstrip(")") for line in text.splitlines() if line.startswith("![")):
        assert (tmp_path / path).is_file(), path


# ------------------------------------------------------------------------------------------------ the verdict rule
def test_by_number_bands_sides_and_starts():
    assert report.by_number(7.0, 7.5).verdict == "reproduced"  # within ×1.3
    assert report.by_number(2.0, 7.5).verdict == "qualitatively"  # outside the band, still faster
    j = report.by_number(0.54, 4.6, what="× fewer it.")
    assert j.verdict == "differs" and j.rule == "number" and "other side of 1" in j.basis
    # over starts: the band on the mean, the side in every start
    assert report.by_number(1.5, 4.6, starts=[1.2, 1.6, 1.7]).verdict == "qualitatively"
    j = report.by_number(1.05, 7.5, starts=[0.9, 1.1, 1.15])
    assert j.verdict == "differs" and "2 of 3 starts" in j.basis and "0.9–1.15" in j.basis
    assert report.by_number(0.06, 0.0525).verdict == "reproduced"  # a ratio below 1: the side is "< 1"
    assert report.by_number(1.2, 0.0525).verdict == "differs"
    assert report.by_number(0.3, 0.1, neutral=None, band=10 ** 0.5).verdict == "reproduced"  # order of magnitude
    assert report.by_number(0.01, 0.1, neutral=None, band=10 ** 0.5).verdict == "differs"


def test_by_count_identity_composite_worst():
    assert report.by_count(24, 24).verdict == "reproduced"
    assert report.by_count(16, 24).verdict == "qualitatively"  # exactly 2/3: no rounding at the threshold
    assert report.by_count(15, 24).verdict == "differs"
    assert report.by_count(1, 2).verdict == "differs"
    assert report.by_count(0, 0).verdict == "not checkable"
    assert report.by_identity(1e-15).verdict == "reproduced" and report.by_identity(1e-6).verdict == "differs"
    assert report.by_identity(1e-5, 1e-4).rule == "identity"
    good, bad = report.by_count(5, 5), report.by_count(0, 2)
    assert report.composite(good, detail=bad).verdict == "qualitatively"  # a detail lowers, never raises
    assert report.composite(bad, detail=good).verdict == "differs"
    assert report.composite(good, detail=good).verdict == "reproduced"
    j = report.worst(good, report.by_number(0.54, 4.6), names=["time", "iterations"])
    assert j.verdict == "differs" and j.rule == "composite" and "iterations → differs" in j.basis


def test_quick_runs_report_at_most_qualitatively_except_identities(monkeypatch):
    mod = types.ModuleType("fake_rule")
    mod.claims = lambda ctx: [
        Claim(key="Lemma 0", subject="s", thesis="t", ours="o", setting="x", **report.by_identity(0.0).kwargs()),
        Claim(key="Fig. 0", subject="s", thesis="t", ours="o", setting="x", **report.by_count(3, 3).kwargs())]
    monkeypatch.setitem(sys.modules, "fake_rule", mod)
    claims = report.run(Context(quick=True), modules=("fake_rule",))
    assert [c.verdict for c in claims] == ["reproduced", "qualitatively"]
    assert [c.verdict for c in report.run(Context(quick=False), modules=("fake_rule",))] == ["reproduced"] * 2


def test_rendered_report_states_the_rule_and_reads_back():
    claims = [Claim(key="Table 7.1 (iterations)", subject="a|b", thesis="t", ours="o", setting="s",
                    **report.by_number(0.54, 4.6).kwargs()),
              Claim(key="Lemma 7.1.2", subject="s", thesis="t", ours="o", setting="s",
                    **report.by_identity(1e-14).kwargs())]
    text = report.render(claims, {"date": "d", "machine": "m", "jax": "j", "scipy": "s", "numpy": "n",
                                  "command": "c", "commit": "abc1234"})
    assert "Verdict rule" in text and "within a factor 1.3" in text and "2/3" in text
    back = report.read_verdicts(text)
    assert back["commit"] == "abc1234" and back["mode"] == "full"
    assert back["rows"] == {"Table 7.1 (iterations)": ("differs", "number"), "Lemma 7.1.2": ("reproduced", "identity")}


def test_only_regenerates_part_of_a_report_and_keeps_the_rest(tmp_path, monkeypatch):
    """``--only MODULE`` replaces that module's rows in the stored claims (docs/thesis/claims.json) and keeps the
    others, each with the commit and date it was generated at; a different mode starts afresh."""
    monkeypatch.setattr(report, "MODULES", ("fake_a", "fake_b"))
    out = tmp_path / "THESIS.md"
    row = lambda key, v: Claim(key=key, subject="s", thesis="t", ours="o", setting="x",  # noqa: E731
                               **report.by_count(v, 1).kwargs())
    _, store = report.merged(out, {"fake_a": [row("A", 1)], "fake_b": [row("B", 1)]}, {"commit": "c1", "date": "d1"})
    report._store(out).parent.mkdir(parents=True)
    report._store(out).write_text(report.json.dumps(store))
    claims, store = report.merged(out, {"fake_b": [row("B", 0)]}, {"commit": "c2", "date": "d2"}, {"fake_b": 3.0})
    assert [(c.key, c.verdict) for c in claims] == [("A", "reproduced"), ("B", "differs")]
    assert store["modules"]["fake_a"]["commit"] == "c1" and store["modules"]["fake_b"]["commit"] == "c2"
    assert store["modules"]["fake_b"]["seconds"] == 3.0
    claims, _ = report.merged(out, {"fake_b": [row("B", 0)]}, {"commit": "c3", "date": "d3", "quick": True})
    assert [c.key for c in claims] == ["B"]


# ------------------------------------------------------------------------------------------------ the committed report
def _committed() -> dict:
    if not COMMITTED.is_file():
        pytest.skip("docs/THESIS.md is not in this checkout")
    return report.read_verdicts(COMMITTED.read_text())


def test_committed_report_records_its_commit_and_a_rule_for_every_verdict():
    got = _committed()
    assert got["mode"] == "full", "the committed report must be a full run (python -m bench thesis)"
    commit = got["commit"].rstrip("+")
    assert commit not in ("", "unknown"), "the report must record the commit it was generated at"
    try:
        rc = subprocess.run(["git", "merge-base", "--is-ancestor", commit, "HEAD"], cwd=ROOT, capture_output=True,
                            timeout=30).returncode
    except (OSError, subprocess.SubprocessError):
        rc = None
    if rc is not None and rc != 128:  # 128: no git history here (an exported tree)
        assert rc == 0, f"the report's commit {commit} is not an ancestor of HEAD: regenerate docs/THESIS.md"
    rows = got["rows"]
    assert len(rows) >= 60
    missing = [key for key, (verdict, rule) in rows.items() if verdict != "error" and not rule]
    assert not missing, f"rows without the rule that decided them: {missing}"
    assert all(verdict != "error" for verdict, _ in rows.values())


def _compare(claims: list, rows: dict) -> list[str]:
    """Disagreements between a quick run's identity rows and the committed report's."""
    bad = []
    for c in claims:
        if c.rule != "identity":
            continue
        if c.key not in rows:
            bad.append(f"{c.key}: not in docs/THESIS.md")
        elif rows[c.key][0] != c.verdict:
            bad.append(f"{c.key}: quick run {c.verdict} ({c.basis}), committed {rows[c.key][0]}")
    return bad


def test_quick_identities_agree_with_the_committed_report():
    """The cheap exact results (``extra_claims.CHEAP``, ~12 s in quick mode) measured now give the committed
    report's verdicts: a change that breaks a reproduced identity is seen here, not at the next full run."""
    from bench.thesis import extra_claims

    rows = _committed()["rows"]
    ctx = Context(quick=True)
    claims = []
    for name in extra_claims.CHEAP:
        found = getattr(extra_claims, name)(ctx)
        claims += found if isinstance(found, list) else [found]
    assert len(claims) >= 10 and all(c.rule == "identity" for c in claims)
    assert not _compare(claims, rows), _compare(claims, rows)


@pytest.mark.slow  # a few minutes: the whole quick report
def test_quick_report_agrees_with_the_committed_report_on_every_identity(tmp_path):
    """Every identity row of ``python -m bench thesis --quick`` (all chapters) has the committed report's verdict."""
    rows = _committed()["rows"]
    out = tmp_path / "THESIS.md"
    assert report.main(["--quick", "--out", str(out)]) == 0
    claims = [Claim(**c) for mod in report.json.loads((tmp_path / "thesis" / "claims.json").read_text())["modules"]
              .values() for c in mod["claims"]]
    assert sum(c.rule == "identity" for c in claims) >= 20
    assert not _compare(claims, rows), _compare(claims, rows)
