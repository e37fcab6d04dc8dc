"""bench.thesis: the reproduction report's framework (claims, rendering, error rows, atomic figures)."""

from __future__ import annotations

import sys
import types

import pytest

from bench.thesis import VERDICTS, Claim, Context
from bench.thesis import report


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
    assert len(rows) >= 30 and {"Table 7.2", "Fig. 3.5", "Fig. 6.9"} <= keys and any(key.startswith("Table 7.1") for key in keys), keys
    assert "**error**" not in text
    for path in (line.split("](", 1)[1].rstrip(")") for line in text.splitlines() if line.startswith("![")):
        assert (tmp_path / path).is_file(), path
