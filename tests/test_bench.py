"""The benchmark runner ``python -m bench``: its listing, where results go, what a missing input or a failed run
leaves behind (nothing), and tiny runs of the benchmarks. No test needs ``../shared`` or writes into ``docs/``."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bench import __main__ as dispatcher
from bench import environment, meshes

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture
def results(tmp_path, monkeypatch):
    """The results directory moved to a temporary one (``docs/benchmarks`` is never written by a test) and the
    shared meshes hidden, with one committed-looking page and JSON per benchmark that has mesh inputs."""
    out = tmp_path / "benchmarks"
    out.mkdir()
    monkeypatch.setattr(environment, "RESULTS", out)
    monkeypatch.setattr(meshes, "SHARED", tmp_path / "no_shared_meshes")
    for name in MESH_OPTIONS:
        (out / f"{name}.md").write_text(f"# {name}: the committed page\n\n<!-- notes -->\nkept\n")
        (out / f"{name}.json").write_text('{"meta": {}, "rows": []}\n')
    return out


def snapshot(directory: Path) -> dict:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


def test_help_lists_every_benchmark_in_one_line_each():
    out = subprocess.run([sys.executable, "-m", "bench", "--help"], cwd=ROOT, capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    listed = out.stdout.split("benchmarks:\n", 1)[1].split("\n\n", 1)[0].splitlines()
    assert [line.split()[0] for line in listed] == list(dispatcher.BENCHMARKS)
    assert all(len(line.split(None, 1)) == 2 for line in listed)  # a name and what it measures
    assert "docs/benchmarks/" in out.stdout
    import importlib.util  # noqa: PLC0415

    for module, _ in dispatcher.BENCHMARKS.values():  # every entry names a module of this checkout
        assert importlib.util.find_spec(module) is not None, module
    assert dispatcher.main([]) == 2  # no name: the listing, and a usage error


def test_unknown_name_is_named(capsys):
    assert dispatcher.main(["no-such-name"]) == 2
    assert "unknown benchmark 'no-such-name'" in capsys.readouterr().err


def test_results_go_to_docs_benchmarks(monkeypatch, tmp_path):
    assert environment.RESULTS == ROOT / "docs" / "benchmarks"
    assert environment.results_path("suite", ".json") == ROOT / "docs" / "benchmarks" / "suite.json"
    monkeypatch.setattr(environment, "RESULTS", tmp_path)
    assert environment.results_path("scaling-modes") == tmp_path / "scaling-modes.md"  # looked up when called


def test_bench_meshes_resolve_without_shared(tmp_path, monkeypatch):
    monkeypatch.setattr(meshes, "SHARED", tmp_path / "nowhere")
    m, label = meshes.load_mesh("example:torus")
    assert label == "example:torus" and m.n_vertices == 1728
    assert meshes.load_mesh("demo")[0].n_vertices == 2562
    with pytest.raises(FileNotFoundError, match="'hand_868.obj' not found .* example:bumpy"):
        meshes.load_mesh("hand_868.obj")
    meshes.require(["example:bumpy", "demo", __file__])  # generated meshes and files exist
    with pytest.raises(meshes.MeshNotFound, match="'fandisk.off'"):
        meshes.require(["example:bumpy", "fandisk.off"])


#: benchmark -> its mesh option (a shared mesh name that a fresh clone does not have)
MESH_OPTIONS = {"suite": "--mesh", "exact": "--mesh", "cmm": "--meshes", "batch": "--meshes", "precision": "--meshes",
                "bases": "--meshes", "peers": "--meshes", "second-order": "--meshes", "scaling": "--base",
                "scaling-modes": "--base"}


@pytest.mark.parametrize("name", list(MESH_OPTIONS))
def test_a_missing_mesh_exits_non_zero_in_one_line_and_writes_nothing(name, results, capsys):
    before = snapshot(results)
    rc = dispatcher.main([name, MESH_OPTIONS[name], "fandisk.off"])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and err.startswith(f"python -m bench {name}: ") and "'fandisk.off'" in err
    assert snapshot(results) == before  # the committed page and JSON untouched, nothing added


def test_a_failed_suite_run_leaves_the_committed_page(results, monkeypatch):
    from bench import suite  # noqa: PLC0415

    def boom(args):
        raise RuntimeError("a solver crashed half-way")

    monkeypatch.setattr(suite, "run_suite", boom)
    before = snapshot(results)
    with pytest.raises(RuntimeError, match="half-way"):
        dispatcher.main(["suite", "--mesh", "example:torus", "--repeats", "1"])
    assert snapshot(results) == before


def test_pages_are_written_atomically_and_keep_their_notes(tmp_path, monkeypatch):
    page = tmp_path / "x.md"
    page.write_text("# old table\n\n<!-- notes -->\n## Reading\n\nkept\n")
    environment.write_page(page, "# new table\n")
    assert page.read_text() == "# new table\n\n<!-- notes -->\n## Reading\n\nkept\n"
    environment.write_page(tmp_path / "fresh.md", "# a page\n")
    assert (tmp_path / "fresh.md").read_text() == "# a page\n"

    def interrupted(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        environment.write_page(page, "# half a table")
    assert page.read_text().startswith("# new table") and sorted(p.name for p in tmp_path.iterdir()) == [
        "fresh.md", "x.md"]  # no temporary file left


def test_reliability_keeps_the_hand_written_part_of_its_page():
    from bench import reliability  # noqa: PLC0415

    class Case:
        cls, input, expected = "mesh", "a | b", "refused"

    meta = {"machine": "m", "date": "d", "commit": "c", "jax": "j", "scipy": "s"}
    generated = reliability.catalogue([(Case, True, "exit 1")], meta)
    old = "# Reliability\n\nhand-written\n\n" + reliability.MARKER + "\n\n## The fault catalogue\n\nold rows\n"
    new = reliability.page(old, generated)
    assert new.startswith("# Reliability\n\nhand-written\n\n" + reliability.MARKER) and "old rows" not in new
    assert "| 1 | mesh | a \\| b | refused | exit 1 | ✓ |" in new and "commit: c" in new
    assert reliability.page(None, generated).startswith("# Reliability: bad input")


@pytest.mark.slow
def test_tiny_suite_writes_consistent_results(tmp_path):
    out_json, out_md = tmp_path / "suite.json", tmp_path / "suite.md"
    methods = ["block-cg-cholesky", "block-bb-cholesky", "block-default-finish", "admm", "fast", "penalty", "eigsh",
               "block-cg-mu0"]
    # the default mesh: example:starfish, no file needed; a rejected mesh is listed with its error; one ManPG case
    bad = tmp_path / "two_faces_one_edge.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\nf 1 2 5\n")
    rc = dispatcher.main(["suite", "--mesh", "example:starfish", str(bad), "--manpg", "48", "--manpg-r", "4",
                          "--manpg-mu", "0.3", "-k", "3", "--repeats", "1", "--max-iters", "25", "--admm-iters", "40",
                          "--fast-samples", "40", "--methods", *methods, "--out-json", str(out_json),
                          "--out-md", str(out_md)])
    assert rc == 0
    res = json.loads(out_json.read_text())
    meta, problems = res["meta"], res["problems"]
    assert meta["jax_backend"] and meta["device"] and meta["versions"]["jax"]
    assert meta["command"].startswith("python -m bench suite")
    assert [p["setup"]["problem"] for p in problems] == ["example:starfish", str(bad), "ManPG n = 48, r = 4, μ = 0.3"]
    assert "NonManifoldError" in problems[1]["error"] and problems[1]["rows"] == {}
    star, manpg = problems[0], problems[2]
    assert star["setup"]["n"] == 2562 and star["setup"]["k"] == 3 and list(star["rows"]) == methods
    assert manpg["setup"]["n"] == 48 and manpg["setup"]["k"] == 4 and manpg["setup"]["start"] == "random"
    assert list(manpg["rows"]) == [m for m in methods if m != "fast"]  # the fast approximation needs a surface
    for prob in (star, manpg):
        setup, rows = prob["setup"], prob["rows"]
        for name, r in rows.items():
            assert np.isfinite(r["objective"]) and r["wall_time"] >= 0 and r["compile_time"] >= 0
            assert r["orthogonality"] < 1e-8, name  # every method returns A-orthonormal modes
            assert r["smoothed_objective"] <= r["objective"] + 1e-9 * abs(r["objective"]), name  # Huber ≤ |x|
            assert len(r["support_sizes"]) == setup["k"] and 0.0 <= r["exact_zeros"] < 1.0
            assert r["tracemalloc_peak_bytes"] > 0  # the memory run (no --no-memory)
            t, f = np.asarray(r["curve"]["time"]), np.asarray(r["curve"]["objective"])
            assert t.size == f.size >= 1 and np.all(np.diff(t) >= 0)
        # the target is the best objective seen over the μ > 0 methods: nobody ends below it
        for name in ("block-cg-cholesky", "block-bb-cholesky", "block-default-finish", "admm", "penalty"):
            assert rows[name]["objective"] >= setup["target_objective"] * (1 - 1e-12)
            assert rows[name]["vs_admm"] == pytest.approx(rows[name]["objective"] / rows["admm"]["objective"] - 1)
        assert rows["admm"]["speed_vs_admm"] == pytest.approx(1.0)
        # the finish returns exact zeros, an exact-ℓ1 residual far below the smooth modes', and counts them per mode
        fin = rows["block-default-finish"]
        assert fin["exact_zeros"] > 0.0 and fin["l1_residual"] < rows["block-cg-cholesky"]["l1_residual"]
        assert sum(fin["support_sizes"]) == round((1 - fin["exact_zeros"]) * setup["n"] * setup["k"])
        # at μ = 0, Σλ (eigsh) is the minimum of tr(XᵀWX) over XᵀAX = I (Ky Fan): the solver cannot beat it
        ref = rows["eigsh"]["objective"]
        assert setup["mu0_reference"] == ref and rows["eigsh"]["l1_residual"] is None
        assert rows["block-cg-mu0"]["objective"] >= ref * (1 - 1e-10)
        assert rows["block-cg-mu0"]["objective"] <= ref * (1 + 1e-3)  # and gets close within 25 iterations
    md = out_md.read_text()
    assert "example:starfish" in md and "no GPU" in md or meta["gpu"]
    assert "## Summary" in md and "not run: NonManifoldError" in md and "| device peak MiB |" in md and "### ManPG n = 48, r = 4, μ = 0.3" in md
    for name in methods:
        assert f"| {name}" in md
    # --render rebuilds the same report from the JSON, keeping the notes below <!-- notes --> of the old file
    again = tmp_path / "again.md"
    again.write_text("an old report\n\n<!-- notes -->\n## Reading\n\nkept\n")
    assert dispatcher.main(["suite", "--render", str(out_json), "--out-md", str(again)]) == 0
    assert again.read_text() == md.rstrip("\n") + "\n\n<!-- notes -->\n## Reading\n\nkept\n"


def test_cmm_bench_tables_for_random_starts_and_reference():
    """The cmm tables: speed-up = ADMM's time / the fastest block variant's time to the same value."""
    from bench import bench_cmm

    blocks = {"shifted:cg": {"time_to_random_start_admm_best": [0.5, None], "time_to_reference_best": 0.4},
              "shifted:lbfgs": {"time_to_random_start_admm_best": [0.25, None], "time_to_reference_best": None}}
    row = {"mesh": "fandisk.off", "blocks": blocks,
           "admm_random": [{"seed": 0, "best": 950.0, "time_first_within_1e-3_of_best": 1.0,
                            "iterations_first_within_1e-3_of_best": 200},
                           {"seed": 1, "best": 940.0, "time_first_within_1e-3_of_best": 2.0,
                            "iterations_first_within_1e-3_of_best": 300}]}
    assert bench_cmm._best_block(blocks, "time_to_random_start_admm_best", 0) == ("shifted:lbfgs", 0.25)
    assert bench_cmm._best_block(blocks, "time_to_random_start_admm_best", 1) == (None, None)
    fmt = (lambda v, f="{:.2f}": "–" if v is None else f.format(v))  # noqa: E731
    lines = bench_cmm._markdown_other_baselines([row], fmt)
    seed0 = next(line for line in lines if line.startswith("| fandisk.off | 0 |"))
    assert seed0.split("|")[6:9] == [" shifted:lbfgs ", " 0.25 ", " 4.0× "]
    seed1 = next(line for line in lines if line.startswith("| fandisk.off | 1 |"))
    assert seed1.split("|")[6:9] == [" – ", " – ", " – "]  # no variant reached that (lower) value
    value, t_ref = bench_cmm.REFERENCE["fandisk.off"]
    ref = next(line for line in lines if line.startswith(f"| fandisk.off | {value:.2f} |"))
    assert ref.split("|")[4:7] == [" shifted:cg ", " 0.40 ", f" {t_ref / 0.4:.0f}× "]


@pytest.mark.slow
def test_second_order_bench_tiny(tmp_path):
    """``python -m bench second-order`` on a 100-vertex Brockett problem: every solver's row, W products counted,
    the optimum matches eigsh, the convergence picture written beside the results."""
    out = tmp_path / "second-order.md"
    assert dispatcher.main(["second-order", "--brockett", "100", "--meshes", "--max-steps", "400",
                            "--output", str(out)]) == 0
    rows = json.loads((tmp_path / "second-order.json").read_text())["rows"]
    assert [r["solver"] for r in rows] == ["TR", "TR + P", "CG + P", "L-BFGS + P", "L-BFGS"]
    tr = rows[1]
    assert tr["status"] == "converged" and tr["error_vs_eigsh"] <= 1e-12 and tr["w_products"] > tr["n_hvps"] > 0
    assert (tmp_path / "second-order.png").read_bytes()[:4] == b"\x89PNG"
    assert "| TR + P |" in out.read_text() and "![gradient norm per iteration](second-order.png)" in out.read_text()


@pytest.mark.slow
def test_peers_bench_tiny(tmp_path):
    """``python -m bench peers`` on a 100-vertex Brockett problem without pymanopt: a row per retraction with
    the time per iteration, the objective history, the default retraction named in the report."""
    out, js = tmp_path / "peers.md", tmp_path / "peers.json"
    assert dispatcher.main(["peers", "--sizes", "100", "--meshes", "--iterations", "20", "--pymanopt", "",
                            "--out-md", str(out), "--out-json", str(js)]) == 0
    rows = json.loads(js.read_text())["rows"]
    assert [r["retraction"] for r in rows] == ["cayley", "cholesky", "polar"]
    for r in rows:
        assert r["iterations"] == 20 and r["ms_per_iteration"] > 0 and len(r["history_value"]) == 21
        assert r["history_value"][-1] < r["history_value"][0]
    assert "ours CG (cholesky)" in out.read_text()


def test_scaling_modes_report_lists_every_level():
    from bench.scaling_modes import report  # noqa: PLC0415

    meta = {"date": "d", "machine": "m", "command": "c", "jax": "j", "scipy": "s", "numpy": "n", "base": "bunny.off",
            "k": 10}
    rows = [{"level": 2, "n": 55730, "k": 10, "eigsh_seconds": 0.7, "seconds": 25.5, "compile_seconds": 4.8,
             "ratio_to_eigsh": 41.0, "t_near": None, "iterations": 311, "status": "converged", "objective": 1389.4,
             "peak_rss_gib": 1.2},
            {"level": 4, "error": "not finished within 1800 s"},
            {"level": 3, "base": "armadillo_25479.obj", "date": "e", "n": 1630000, "k": 10, "eigsh_seconds": 40.0,
             "seconds": 900.0, "compile_seconds": 5.0, "ratio_to_eigsh": 22.6, "t_near": 200.0, "iterations": 300,
             "status": "converged", "objective": 1000.0, "peak_rss_gib": 8.0}]
    text = report(rows, meta)
    assert "| bunny.off (2) | d | 55730 | 0.7 | 25.5 | 4.8 | 41.0 | – | 311 | converged | 1389.4000 | 1.20 |" in text
    assert "| bunny.off (4) | d | – |" in text and "not finished within 1800 s" in text
    assert "| armadillo_25479.obj (3) | e | 1630000 | 40.0 | 900.0 | 5.0 | 22.6 | 200.0 | 300 |" in text


def test_scaling_modes_merge_keeps_other_rows(tmp_path, monkeypatch):
    """``--merge`` keeps the rows of other (mesh, level) pairs, with the date and command of their own run."""
    from bench import scaling_modes  # noqa: PLC0415

    out_json, out_md = tmp_path / "r.json", tmp_path / "r.md"
    old_row = {"level": 4, "n": 891650, "k": 10, "eigsh_seconds": 21.7, "seconds": 730.5, "compile_seconds": 5.1,
               "ratio_to_eigsh": 34.0, "t_near": 165.2, "iterations": 343, "status": "converged", "objective": 1389.3,
               "peak_rss_gib": 4.34}
    out_json.write_text(json.dumps({"meta": {"base": "bunny.off", "date": "2026-11-26 09:39 UTC",
                                             "command": "python -m bench scaling-modes --base bunny.off"},
                                    "rows": [old_row, dict(old_row, level=1, n=100)]}))

    class Done:
        returncode, stderr = 0, ""
        stdout = json.dumps(dict(old_row, level=1, n=100, seconds=1.0))

    monkeypatch.setattr(scaling_modes.subprocess, "run", lambda *a, **k: Done())
    # the input check finds a stand-in file (the level's subprocess, replaced above, would read it): no ../shared
    shared = tmp_path / "meshes"
    shared.mkdir()
    (shared / "bunny.off").write_text("OFF\n")
    monkeypatch.setattr(meshes, "SHARED", shared)
    assert scaling_modes.main(["--base", "bunny.off", "--levels", "1", "--merge", "--out-json", str(out_json),
                               "--out-md", str(out_md)]) == 0
    rows = json.loads(out_json.read_text())["rows"]
    assert [(r["level"], r["seconds"]) for r in rows] == [(1, 1.0), (4, 730.5)]  # level 1 replaced, level 4 kept
    assert rows[1]["date"] == "2026-11-26 09:39 UTC" and rows[1]["command"].endswith("--base bunny.off")
    assert "| bunny.off (4) | 2026-11-26 09:39 UTC | 891650 |" in out_md.read_text()


def test_manpg_problem_is_the_periodic_schrodinger_operator():
    """``manpg_problem``: Ĥ = −½Δ with periodic differences on [0, 50] — eigenvalues (1 − cos 2πj/n)/h²."""
    from bench.suite_methods import manpg_problem  # noqa: PLC0415

    n = 64
    W, a = manpg_problem(n)
    h = 50.0 / n
    expected = np.sort((1.0 - np.cos(2.0 * np.pi * np.arange(n) / n)) / h**2)
    assert np.allclose(np.linalg.eigvalsh(W.toarray()), expected, atol=1e-10)
    assert np.array_equal(a, np.ones(n)) and (W != W.T).nnz == 0


def test_time_to_final_is_the_first_time_within_1e3_of_the_last_value():
    from bench.scaling_modes import time_to_final  # noqa: PLC0415

    times = [0.0, 1.0, 2.0, 3.0, 10.0]
    values = [2000.0, 1010.0, 1000.9, 1000.5, 1000.0]  # 1000.9 is the first within 1e-3 of 1000
    assert time_to_final(times, values) == 2.0
    assert time_to_final([0.0, 4.0], [5.0, 5.0]) == 0.0


def test_scaling_modes_writes_nothing_when_a_level_fails(tmp_path, monkeypatch, capsys):
    from bench import scaling_modes  # noqa: PLC0415

    class Failed:
        returncode, stdout, stderr = 1, "", "Traceback ...\nMemoryError: Unable to allocate 80 GiB\n"

    monkeypatch.setattr(scaling_modes.subprocess, "run", lambda *a, **k: Failed())
    out_json, out_md = tmp_path / "r.json", tmp_path / "r.md"
    out_md.write_text("the committed page\n")
    assert scaling_modes.main(["--levels", "1", "2", "--out-json", str(out_json), "--out-md", str(out_md)]) == 1
    assert "level 1 failed (MemoryError: Unable to allocate 80 GiB); nothing written" in capsys.readouterr().err
    assert out_md.read_text() == "the committed page\n" and not out_json.exists()


def test_exact_bench_report_states_gaps_status_and_the_finish_iterates():
    """``bench exact``'s page: one row per problem with the gap to ADMM, the status and residual, an error row for a
    failed problem, the summary line's counts, and the finish's iterates for the traced problem."""
    from bench.exact import report  # noqa: PLC0415

    meta = {"date": "2026-11-28 10:00 UTC", "machine": "x", "commit": "abc", "jax": "0", "scipy": "0", "numpy": "0",
            "command": "python -m bench exact", "k": 10, "mu_factor": 0.01, "admm_time": 120.0, "problems_done": "2 of 2"}
    row = dict(problem="rpn:64:5:0.1", kind="rpn", n=64, k=5, mu=0.1, objective=1.78, gap=2e-4, previous_gap=6e-4,
               status="stalled", residual=3e-6, zeros=0.83, admm_status="converged", iterations=431, newton=9, cg=51,
               compile=5.5, solve=0.3, total=6.0, admm_iterations=2058, admm_total=0.7, speed=0.11, speed_excluded=2.4,
               trace=[[1.79, 5e-2, 5e-2, 56, 2], [1.78, 8e-13, 0.0, 56, 0]])
    page = report(meta, [row, dict(problem="manpg:128:4:0.1", kind="manpg", error="ValueError: boom")], ["rpn:64:5:0.1"])
    assert "| rpn:64:5:0.1 | 64 | 5 | 0.1 | 1.78 | +2.0e-04 | +6.0e-04 | stalled | 3.0e-06 |" in page
    assert "| manpg:128:4:0.1 | error: ValueError: boom |" in page
    assert "Converged (residual ≤ 1e-8): 0 of 1." in page and "at or below ADMM × (1 + 1e-4): 0 of 1" in page
    assert "### The finish's iterates: rpn:64:5:0.1" in page and "| 1 | 1.78 | 8.0e-13 | 0.0e+00 | 56 | 0 |" in page


def test_exact_bench_meshes_get_one_problem_per_mu_form():
    """``bench exact --mu 0.01n 2λ``: each mesh is a problem per form, labelled with it, μ resolved as the command
    resolves it (``2λ`` = 2 λ_(k−1) of the mesh's Laplacian); one form keeps the plain mesh label."""
    from bench.exact import parse, problems  # noqa: PLC0415
    from objectives.cmm.modes import first_eigenpairs  # noqa: PLC0415

    args = parse(["--mesh", "example:patch", "--mu", "0.01n", "2λ", "--manpg", "--rpn", "--k", "3"])
    built = {label: build() for label, kind, build in problems(args) if kind == "mesh"}
    assert list(built) == ["example:patch @ 0.01n", "example:patch @ 2λ"]
    W, a, k, mu_n, *_ = built["example:patch @ 0.01n"]
    assert k == 3 and mu_n == pytest.approx(0.01 * a.shape[0])
    assert built["example:patch @ 2λ"][3] == pytest.approx(2.0 * first_eigenpairs(W, a, 3)[0][-1], rel=1e-12)
    one = parse(["--mesh", "example:patch", "--mu", "2λ", "--manpg", "--rpn"])
    assert [label for label, *_ in problems(one)] == ["example:patch"]


def test_starts_bench_row_and_page_on_a_small_problem():
    """``bench starts`` on a small mesh: the default and each of its 4 starts alone, the default's objective no
    higher than the start it picked solved alone, and a page naming the pick; meshes only (no Schrödinger cases)."""
    from bench import starts  # noqa: PLC0415
    from bench.exact import problems  # noqa: PLC0415

    args = starts.parse(["--mesh", "example:patch", "--mu", "0.01n", "--k", "3"])
    cases = list(problems(args))
    assert [(label, kind) for label, kind, _ in cases] == [("example:patch", "mesh")]
    W, a, k, mu, weighting, start = cases[0][2]()

    def small():
        keep = np.arange(400)  # a 400-vertex piece of the patch: the first rows and columns of its Laplacian
        Ws = W[keep][:, keep].tolil()
        Ws.setdiag(0)
        Ws = Ws.tocsr()
        Ws = Ws - __import__("scipy").sparse.diags_array(np.asarray(Ws.sum(axis=1)).ravel())
        return Ws, a[keep], k, mu, weighting, start

    row = starts.run_problem("piece", small, 4)
    assert len(row["alone"]) == 4 and len(row["screen"]) == 4 and 0 <= row["chosen"] < 4
    assert row["objective"] <= row["alone"][row["chosen"]]["objective"] * (1 + 1e-8)
    page = starts.report({"date": "d", "machine": "m", "jax": "j", "scipy": "s", "numpy": "n", "command": "c",
                          "k": 3, "mu": ["0.01n"]}, [row, dict(problem="bad", error="ValueError: x")])
    assert f"| piece | 400 | {mu:.3g} |" in page and "| bad | error: ValueError: x |" in page
    assert "within 1e-4 of the best start alone" in page
