"""``stiefel_cmm.cli.viewer``: the self-contained HTML viewer (``write_viewer``) and ``stiefel view`` (``run_view``).

Meshes are small ellipsoids (``demo_mesh(1)``: 42 vertices) written into npz files here, like those of
``stiefel modes``/``stiefel eigs``. The ``browser`` test opens a page in headless Chromium (Debian's
``chromium``), picks a field in its menu and reads the colours of its screenshot; without Chromium it
is skipped, except when ``CI`` is set (CI installs it, so a missing browser fails there).
"""

from __future__ import annotations

import argparse
import errno
import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

import stiefel_cmm.cli.viewer as viewer
from stiefel_cmm.cli.viewer import VIEW_NAME, ViewerError, add_parser, decimate, load_run, run_view, write_viewer

REPO = Path(__file__).resolve().parents[1]


def demo_mesh(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """An ellipsoid (semi-axes 1.6, 1, 0.8) from trimesh's icosphere: 42 vertices and 80 faces at 1, 2562/5120 at 4."""
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(sphere.vertices) * [1.6, 1.0, 0.8], np.asarray(sphere.faces, dtype=np.int64)


def _fields(v: np.ndarray) -> np.ndarray:
    """Three fields (n, 3) of different ranges: x, 2.5·sin(3y), z² − 0.3."""
    return np.stack([v[:, 0], 2.5 * np.sin(3 * v[:, 1]), v[:, 2] ** 2 - 0.3], axis=1)


def _npz(path: Path, kind: str = "modes", drop: tuple[str, ...] = (), **override: object) -> Path:
    """An npz like ``stiefel modes`` (``kind="modes"``) or ``stiefel eigs`` writes, with arrays dropped/replaced."""
    v, f = demo_mesh(1)
    u = _fields(v)
    arrays: dict[str, object] = ({"modes": u, "compressed_eigenvalues": np.array([0.5, 1.5, 2.5]), "mu": 0.42,
                                  "diagnostics": json.dumps({"status": "converged"})} if kind == "modes"
                                 else {"eigenvectors": u, "eigenvalues": np.array([0.0, 1.0, 2.0])})
    arrays.update(vertices=v, faces=f)
    arrays.update(override)
    for name in drop:
        del arrays[name]
    path.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path / f"{kind}.npz", **arrays)
    return path


def _args(outdir: Path, *extra: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="stiefel")
    add_parser(parser.add_subparsers(dest="command"))
    return parser.parse_args(["view", str(outdir), *extra])


class _Refs(HTMLParser):
    """Collects the start tags and their URL-valued attributes (script text is not parsed as tags)."""

    def __init__(self) -> None:
        super().__init__()
        self.tags: list[str] = []
        self.urls: list[tuple[str, str, str]] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        self.tags.append(tag)
        for name, value in attrs:
            if name in ("src", "href", "data", "action", "poster", "srcset", "xlink:href") and value is not None:
                self.urls.append((tag, name, value))


def _spec_b64(column: np.ndarray) -> str:
    """The base64 text of a float32 column as it appears in plotly's JSON (which writes "/" as \\u002f)."""
    return viewer._spec(column, "f4")["bdata"].replace("/", "\\u002f")


# ---------------------------------------------------------------------------- the page


def test_page_is_one_self_contained_file_with_the_data(tmp_path: Path) -> None:
    v, f = demo_mesh(1)
    u = _fields(v)
    names = ["first field", "second field", "third field"]
    info = write_viewer(tmp_path / "page.html", v, f, u, names, title="Modes <of> a test",
                        subtitles=["λ̃ = 0.5", "λ̃ = 1.5", "λ̃ = 2.5"])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["page.html"]  # one file, no temporary left
    text = (tmp_path / "page.html").read_text(encoding="utf-8")
    assert info == {"vertices": 42, "faces": 80, "decimated": False, "original_vertices": 42, "original_faces": 80,
                    "bytes": len(text.encode("utf-8"))}
    refs = _Refs()
    refs.feed(text)
    assert refs.urls == [], refs.urls  # nothing is loaded from anywhere: no src=, href=, …
    assert "link" not in refs.tags and "iframe" not in refs.tags
    assert not re.search(r"url\(\s*['\"]?(https?:)?//", text)  # no CSS import of a remote file
    assert "plotly.js v" in text and "Plotly.newPlot" in text  # the library is inlined
    assert "<title>Modes &lt;of&gt; a test</title>" in text
    for name in names:
        assert f'"label":"{name}"' in text
    assert "42 vertices, 80 faces" in text
    for j in range(3):  # every field's values are embedded (float32, base64), with its symmetric limits
        assert _spec_b64(u[:, j]) in text, j
        lim = float(np.max(np.abs(u[:, j])))
        assert f'"cmax":[{lim!r}]' in text and f'"cmin":[{-lim!r}]' in text
    assert "RdBu_r" in text or '"colorscale":[[0.0,"rgb(5,48,97)"]' in text


def test_file_objects_binary_and_text(tmp_path: Path) -> None:
    import io

    v, f = demo_mesh(1)
    u = v[:, 2]  # one field given as (n,)
    bio, sio = io.BytesIO(), io.StringIO()
    a = write_viewer(bio, v, f, u, ["z"], title="t")
    b = write_viewer(sio, v, f, u, ["z"], title="t")
    assert a["bytes"] == len(bio.getvalue()) and bio.getvalue().decode("utf-8").startswith("<!doctype html>")
    assert sio.getvalue().startswith("<!doctype html>") and '"label":"z"' in sio.getvalue()
    assert b["vertices"] == a["vertices"] == 42


def test_zero_field_gets_a_range(tmp_path: Path) -> None:
    v, f = demo_mesh(1)
    write_viewer(tmp_path / "z.html", v, f, np.zeros((len(v), 1)), ["zero"], title="t")
    text = (tmp_path / "z.html").read_text()
    assert '"cmax":[1.0]' in text and '"cmin":[-1.0]' in text


def test_large_mesh_is_decimated_with_a_note(tmp_path: Path) -> None:
    v, f = demo_mesh(4)  # 2562 vertices, 5120 faces
    u = _fields(v)
    info = write_viewer(tmp_path / "big.html", v, f, u, ["a", "b", "c"], title="big", max_faces=1000)
    assert info["decimated"] and info["original_faces"] == 5120 and info["original_vertices"] == 2562
    assert 500 <= info["faces"] <= 1000 and info["vertices"] < 2562
    text = (tmp_path / "big.html").read_text()
    assert f"decimated from 2562 to {info['vertices']} vertices for display" in text
    for j in range(3):  # the limits are the full mesh's
        assert f'"cmax":[{float(np.max(np.abs(u[:, j])))!r}]' in text
    same = write_viewer(tmp_path / "same.html", v, f, u, ["a", "b", "c"], title="big", max_faces=5120)
    assert not same["decimated"] and same["faces"] == 5120
    assert "decimated" not in (tmp_path / "same.html").read_text().split("Plotly.newPlot")[-1]


def test_decimate_carries_fields_from_the_nearest_vertex() -> None:
    v, f = demo_mesh(4)
    u = _fields(v)
    v2, f2, u2 = decimate(v, f, u, 800)
    assert len(f2) <= 800 and f2.shape[1] == 3 and u2.shape == (len(v2), 3)
    assert f2.min() == 0 and f2.max() == len(v2) - 1 and len(np.unique(f2)) == len(v2)  # no unused vertex
    assert np.all(u2.min(axis=0) >= u.min(axis=0)) and np.all(u2.max(axis=0) <= u.max(axis=0))
    assert all(np.isin(u2[:, j], u[:, j]).all() for j in range(3))  # values of original vertices
    # nearest vertex: close to the field evaluated at the new positions (smooth fields, fine mesh)
    assert np.max(np.abs(u2 - _fields(v2))) < 0.5
    assert np.corrcoef(u2[:, 1], _fields(v2)[:, 1])[0, 1] > 0.98
    same = decimate(v, f, u, len(f))
    assert same[0] is v and same[1] is f and same[2] is u


@pytest.mark.parametrize("case, match", [
    ("names", r"2 names and 2 subtitles for 3 fields"),
    ("rows", r"'fields' has shape \(41, 3\), expected \(n, k\) with n = 42"),
    ("index", r"'faces' index 42 is out of range for 42 vertices"),
    ("nan", r"'fields' has 1 non-finite values"),
    ("vertices", r"'vertices' has shape \(42, 2\)"),
    ("float faces", r"'faces' has shape \(80, 3\) and dtype float64"),
])
def test_write_viewer_bad_input(tmp_path: Path, case: str, match: str) -> None:
    v, f = demo_mesh(1)
    u = _fields(v)
    names = ["a", "b", "c"]
    if case == "names":
        names = ["a", "b"]
    elif case == "rows":
        u = u[:-1]
    elif case == "index":
        f = f.copy()
        f[3, 1] = 42
    elif case == "nan":
        u = u.copy()
        u[5, 2] = np.nan
    elif case == "vertices":
        v = v[:, :2]
    elif case == "float faces":
        f = f.astype(float)
    with pytest.raises(ViewerError, match=match):
        write_viewer(tmp_path / "x.html", v, f, u, names, title="t")
    assert list(tmp_path.iterdir()) == []


def test_import_is_light() -> None:
    code = ("import sys, stiefel_cmm.cli.viewer; heavy = {'numpy', 'scipy', 'plotly', 'jax', 'fast_simplification'} "
            "& set(sys.modules); assert not heavy, heavy")
    subprocess.run([sys.executable, "-c", code], cwd=REPO, check=True, timeout=60)


# ---------------------------------------------------------------------------- stiefel view


@pytest.mark.parametrize("kind, label, symbol", [("modes", "mode", "λ̃"), ("eigs", "eigenfunction", "λ")])
def test_run_view_reads_a_run(tmp_path: Path, capsys: pytest.CaptureFixture, kind: str, label: str,
                              symbol: str) -> None:
    out = _npz(tmp_path / "run", kind)
    assert run_view(_args(out)) == 0
    page = out / VIEW_NAME
    text = page.read_text()
    assert f'"label":"{label} 0"' in text and f'"label":"{label} 2"' in text
    value = "1.5" if kind == "modes" else "1"
    assert json.dumps(f"<sup>{label} 1: {symbol} = {value}</sup>")[1:-1].replace("/", "\\u002f").replace(
        "<", "\\u003c").replace(">", "\\u003e") in text  # the subtitle of field 1, as plotly's JSON has it
    assert "42 vertices, 80 faces" in text
    assert sorted(p.name for p in out.iterdir()) == sorted([f"{kind}.npz", VIEW_NAME])
    line = capsys.readouterr().out.strip()
    assert line.startswith(f"stiefel view: wrote {page}") and "3 fields" in line
    run = load_run(out)
    assert run["source"] == out / f"{kind}.npz" and run["names"] == [f"{label} {j}" for j in range(3)]


def test_run_view_options(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = _npz(tmp_path / "run")
    target = tmp_path / "elsewhere" / "v.html"
    target.parent.mkdir()
    args = _args(out, "--output", str(target), "--title", "My modes", "--max-faces", "40", "--quiet")
    assert run_view(args) == 0 and capsys.readouterr().out == ""
    text = target.read_text()
    assert "<title>My modes</title>" in text and "decimated from 42 to" in text
    assert not (out / VIEW_NAME).exists()
    with pytest.raises(SystemExit):
        _args(out, "--max-faces", "0")


def _bad_npz(tmp_path: Path, case: str) -> Path:
    out = tmp_path / "run"
    v, f = demo_mesh(1)
    if case == "missing dir":
        return tmp_path / "nowhere"
    if case == "not a dir":
        (tmp_path / "file").write_text("x")
        return tmp_path / "file"
    if case == "empty dir":
        out.mkdir()
        return out
    if case == "garbage":
        out.mkdir()
        (out / "modes.npz").write_bytes(b"not a zip file at all")
        return out
    if case == "missing arrays":
        return _npz(out, drop=("faces", "modes"))
    if case == "rows":
        return _npz(out, modes=_fields(v)[:-2])
    if case == "index":
        return _npz(out, faces=np.where(f == 7, 99, f))
    if case == "negative index":
        return _npz(out, "eigs", faces=np.where(f == 7, -1, f))
    if case == "nan":
        u = _fields(v)
        u[0, 0] = np.inf
        return _npz(out, modes=u)
    if case == "nan vertices":
        return _npz(out, "eigs", vertices=np.where(v > 0.5, np.nan, v))
    if case == "values":
        return _npz(out, compressed_eigenvalues=np.arange(4.0))
    raise AssertionError(case)


@pytest.mark.parametrize("case, match", [
    ("missing dir", r"^run directory not found: .*nowhere: give the --out directory of 'stiefel modes'"),
    ("not a dir", r"^not a directory: .*file: give the --out directory"),
    ("empty dir", r"^no modes.npz or eigs.npz in .*run: run 'stiefel modes --out .*' or 'stiefel eigs --out"),
    ("garbage", r"modes.npz is not a readable npz file \(.*\): rerun 'stiefel modes --out"),
    ("missing arrays", r"modes.npz lacks the array\(s\) 'faces', 'modes': rerun 'stiefel modes --out"),
    ("rows", r"modes.npz: 'modes' has shape \(40, 3\), expected \(n, k\) with n = 42 rows.*: rerun 'stiefel modes"),
    ("index", r"modes.npz: 'faces' index 99 is out of range for 42 vertices: rerun"),
    ("negative index", r"eigs.npz: 'faces' index -1 is out of range for 42 vertices: rerun 'stiefel eigs --out"),
    ("nan", r"modes.npz: 'modes' has 1 non-finite values: rerun"),
    ("nan vertices", r"eigs.npz: 'vertices' has \d+ non-finite values: rerun"),
    ("values", r"modes.npz: 'compressed_eigenvalues' has shape \(4,\), expected \(3,\): rerun"),
])
def test_run_view_bad_input_named_errors(tmp_path: Path, case: str, match: str) -> None:
    outdir = _bad_npz(tmp_path, case)
    with pytest.raises(ViewerError, match=match) as e:
        run_view(_args(outdir))
    assert "\n" not in str(e.value)
    assert not any(p.name.endswith(".tmp") or p.name == VIEW_NAME for p in tmp_path.rglob("*"))


def test_failed_runs_leave_the_previous_view(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    out = _npz(tmp_path / "run")
    (out / VIEW_NAME).write_text("previous view")
    _npz(out, faces=np.full((3, 3), 100))  # bad input: fails before anything is written
    with pytest.raises(ViewerError, match="out of range"):
        run_view(_args(out))
    assert (out / VIEW_NAME).read_text() == "previous view"
    _npz(out)  # good input, but the disk fills up while the page is written

    def full(fd: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(viewer.os, "fsync", full)
    with pytest.raises(ViewerError, match=r"cannot write .*view.html: No space left on device: choose another"):
        run_view(_args(out))
    assert (out / VIEW_NAME).read_text() == "previous view"
    assert sorted(p.name for p in out.iterdir()) == ["modes.npz", VIEW_NAME]  # no temporary file left
    monkeypatch.undo()
    assert run_view(_args(out, "--quiet")) == 0
    assert (out / VIEW_NAME).read_text().startswith("<!doctype html>")
    assert (out / VIEW_NAME).stat().st_mode & 0o777 == 0o644
    assert sorted(p.name for p in out.iterdir()) == ["modes.npz", VIEW_NAME]
    with pytest.raises(ViewerError, match="directory of --output not found"):
        run_view(_args(out, "--output", str(tmp_path / "no" / "v.html")))


def _with_summary(out: Path, kind: str = "modes", **extra: object) -> Path:
    """A ``summary.json`` beside ``out/<kind>.npz`` as a run writes it: the npz listed with its size and SHA-256."""
    import hashlib

    data = (out / f"{kind}.npz").read_bytes()
    doc = {"command": kind, "files": {"npz": {"name": f"{kind}.npz", "bytes": len(data),
                                              "sha256": hashlib.sha256(data).hexdigest()}}, **extra}
    (out / "summary.json").write_text(json.dumps(doc))
    return out


@pytest.mark.parametrize("case, match", [
    ("changed", r"modes.npz does not match summary.json: its SHA-256 is [0-9a-f]{16}…, the run recorded "
                r"[0-9a-f]{16}… .*the file changed after the run wrote it; rerun 'stiefel modes --out"),
    ("missing", r"modes.npz is listed in summary.json but missing: rerun 'stiefel modes --out"),
    ("compare", r"holds the outputs of 'stiefel compare-smoothings' \(summary.json\): nothing to view"),
    ("json", r"summary.json cannot be read \(not valid JSON\)"),
    ("unlisted", r"summary.json lists no modes.npz with its SHA-256"),
])
def test_run_view_checks_the_summary(tmp_path: Path, case: str, match: str) -> None:
    out = _with_summary(_npz(tmp_path / "run"))
    if case == "changed":
        _npz(out, compressed_eigenvalues=np.array([0.5, 1.5, 2.6]))  # a valid npz, not the one the run wrote
    elif case == "missing":
        (out / "modes.npz").unlink()
    elif case == "compare":
        (out / "summary.json").write_text(json.dumps({"command": "compare-smoothings", "files": {}}))
    elif case == "json":
        (out / "summary.json").write_text("{not json")
    elif case == "unlisted":
        (out / "summary.json").write_text(json.dumps({"command": "modes", "files": {}}))
    before = sorted(p.name for p in out.iterdir())
    with pytest.raises(ViewerError, match=match) as e:
        run_view(_args(out))
    after = sorted(p.name for p in out.iterdir() if p.name != ".stiefel.lock")  # (the lock taken to read the run)
    assert "\n" not in str(e.value) and after == before  # nothing written, no staging left


def test_run_view_labels_the_status_and_lists_the_page(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = _with_summary(_npz(tmp_path / "run"), diagnostics={"status": "interrupted", "iterations": 12},
                        interrupted={"signal": "SIGINT"})
    assert run_view(_args(out)) == 0
    captured = capsys.readouterr()
    status = "INTERRUPTED by SIGINT after 12 iterations: the modes reached, not a converged result"
    assert captured.err.strip() == f"stiefel view: warning: {out} holds no converged result; run status: {status}"
    assert f"run status: {status}" in captured.out
    page = (out / VIEW_NAME).read_text()
    assert f"run status: {status}" in page and "<title>run: compressed manifold modes [INTERRUPTED]</title>" in page
    summary = json.loads((out / "summary.json").read_text())
    assert summary["files"]["view"]["sha256"] == hashlib.sha256(page.encode()).hexdigest()
    assert summary["diagnostics"]["status"] == "interrupted"  # the run's record is kept as it was
    # a converged run: the status on the page, nothing on stderr
    _with_summary(_npz(tmp_path / "ok"), diagnostics={"status": "converged", "iterations": 7})
    assert run_view(_args(tmp_path / "ok", "--quiet")) == 0
    assert capsys.readouterr().err == ""
    assert "run status: converged in 7 iterations" in (tmp_path / "ok" / VIEW_NAME).read_text()


# ---------------------------------------------------------------------------- a real browser


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        if path := shutil.which(name):
            return path
    return None


#: headless, as root, software WebGL (SwiftShader), no network (every host name fails to resolve)
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                  "--enable-unsafe-swiftshader", "--disable-dev-shm-usage", "--no-first-run", "--hide-scrollbars",
                  "--mute-audio", "--host-resolver-rules=MAP * ~NOTFOUND", "--window-size=800,600",
                  "--virtual-time-budget=3000")


def _screenshot(exe: str, page: Path, png: Path) -> np.ndarray:
    """RGB floats (h, w, 3) of ``page`` in headless Chromium."""
    from matplotlib.image import imread

    cmd = [exe, *CHROMIUM_FLAGS, f"--user-data-dir={png.parent / 'profile'}", f"--screenshot={png}", page.as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert png.is_file(), f"no screenshot (exit {proc.returncode}): {proc.stderr[-2000:]}"
    return imread(png)[:, :, :3]


#: appended to the page: a click opens the drop-down menu, a click on its second entry picks field 1
_PICK_FIELD_1 = """<script>
window.addEventListener("load", function () {
  setTimeout(function () {
    document.querySelector(".updatemenu-header").dispatchEvent(new MouseEvent("click", {bubbles: true}));
    var tries = 0;
    (function pick() {
      var items = document.querySelectorAll(".updatemenu-dropdown-button");
      if (items.length < 2 && ++tries < 50) { setTimeout(pick, 20); return; }
      items[1].dispatchEvent(new MouseEvent("click", {bubbles: true}));
    })();
  }, 100);
});
</script>
</body>"""


@pytest.mark.browser
def test_browser_shows_the_field(tmp_path: Path) -> None:
    """A flat square seen from +z with y up; field 0 is +1 everywhere (all red), field 1 is −3 on the left half
    and +3 on the right. Picking field 1 in the menu must show blue left, red right, and a ±3 colour bar."""
    exe = _chromium()
    if exe is None:
        if os.environ.get("CI"):
            pytest.fail("CI is set but no chromium binary was found: .ci/run installs it (apt-get install chromium)")
        pytest.skip("no chromium binary (apt-get install chromium); this test is required when CI is set")
    t = np.linspace(-1.0, 1.0, 16)  # an even count: no vertex on x = 0
    x, y = np.meshgrid(t, t, indexing="xy")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    idx = np.arange(256).reshape(16, 16)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    f = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    u = np.stack([np.ones(len(v)), 3.0 * np.sign(v[:, 0])], axis=1)
    page = tmp_path / "square.html"
    write_viewer(page, v, f, u, ["constant", "sign of x"], title="square",
                 camera={"eye": {"x": 0, "y": 0, "z": 1.6}, "up": {"x": 0, "y": 1, "z": 0}})
    text = page.read_text(encoding="utf-8")
    assert text.count("</body>") == 1
    page.write_text(text.replace("</body>", _PICK_FIELD_1), encoding="utf-8")
    t0 = time.perf_counter()
    img = _screenshot(exe, page, tmp_path / "square.png")
    elapsed = time.perf_counter() - t0
    h, w, _ = img.shape
    r, g, bl = img[..., 0], img[..., 1], img[..., 2]
    # the ends of RdBu, shaded: (103, 0, 31) and (5, 48, 97) times ~0.8; not plotly's bluish grey text (42, 63, 95)
    red = (r > 0.15) & (g < 0.25 * r) & (bl < 0.5 * r)
    blue = (bl > 0.15) & (r < 0.25 * bl) & (g < bl - 0.08)
    plot = np.zeros((h, w), bool)
    plot[:, : int(0.8 * w)] = True  # the scene; the colour bar is on the right
    rows, cols = np.nonzero((red | blue) & plot)
    assert len(rows) > 0.02 * h * w, f"hardly any coloured pixels: the mesh was not drawn ({elapsed:.1f} s)"
    red_cols, blue_cols = np.nonzero(red & plot)[1], np.nonzero(blue & plot)[1]
    mid = 0.5 * (np.median(red_cols) + np.median(blue_cols))
    assert len(red_cols) > 0.4 * len(cols) and len(blue_cols) > 0.4 * len(cols)  # two halves
    assert np.mean(red_cols > mid) > 0.97 and np.mean(blue_cols < mid) > 0.97  # +3 right (red), −3 left (blue)
    square = (rows.max() - rows.min(), cols.max() - cols.min())
    assert 0.8 < square[0] / square[1] < 1.25, square  # seen face-on: a square
    assert np.allclose(img[3, 3], 1.0, atol=0.02) and np.allclose(img[h - 4, 3], 1.0, atol=0.02)  # white background
    bar_red, bar_blue = np.nonzero(red & ~plot)[0], np.nonzero(blue & ~plot)[0]  # colour bar: +3 at the top
    assert len(bar_red) > 50 and len(bar_blue) > 50 and bar_red.mean() < bar_blue.mean()


def test_default_camera_faces_a_flat_patch_and_honours_up() -> None:
    """The viewer opens on the contact sheet's front view: a flat patch in the x-z plane is seen along ±y
    (face-on), the camera's up is perpendicular to the eye; ``up="z"`` makes z the vertical axis."""
    import numpy as np

    import mesh
    from stiefel_cmm.cli.viewer import default_camera

    m = mesh.example("patch")
    cam = default_camera(m.vertices, m.faces)
    eye = np.array([cam["eye"][c] for c in "xyz"])
    up = np.array([cam["up"][c] for c in "xyz"])
    assert abs(eye[1]) / np.linalg.norm(eye) > 0.85           # looking along the normal (y) of the patch
    assert abs(up[1]) < 0.1 and abs(np.linalg.norm(up) - 1) < 1e-12
    cam = default_camera(m.vertices, m.faces, up="z")
    assert [cam["up"][c] for c in "xyz"] == [0.0, 0.0, 1.0]
