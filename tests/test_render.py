"""The PNG contact sheets (stiefel_cmm/cli/render.py, stiefel_cmm/cli/render_views.py, stiefel_cmm/cli/raster.py): the z-buffer rasteriser paints the right
faces; meshes are oriented by their principal axes (a flat patch face-on, the same picture however the
mesh is rotated) or by ``up=``; colours are symmetric about 0 with a colour bar and labelled rows and
columns; the grid of smoothings × modes; rendering memory does not grow with the number of faces."""

from __future__ import annotations

import argparse
import io
import tracemalloc
from pathlib import Path

import matplotlib
import matplotlib.image as mpimg
import numpy as np
import pytest

from stiefel_cmm.cli.demo_mesh import demo_mesh
from stiefel_cmm.cli.render import (VIEWS, Layout, RenderOptionError, check_up, contact_sheet, grid_sheet, png_bytes,
                        principal_frame, rasterize)

FRONT = (("front", 0.0, 0.0),)
RED, WHITE, BLUE = (np.asarray(matplotlib.colormaps["RdBu_r"](t)[:3]) for t in (1.0, 0.5, 0.0))


def _torus(nu: int, nv: int) -> tuple[np.ndarray, np.ndarray]:
    """Closed bumpy torus, ``nu · nv`` vertices and ``2 nu nv`` faces (self-occluding in every view)."""
    u, w = np.meshgrid(np.linspace(0, 2 * np.pi, nu, endpoint=False), np.linspace(0, 2 * np.pi, nv, endpoint=False),
                       indexing="ij")
    r = 0.35 * (1.0 + 0.15 * np.sin(5 * u) * np.cos(3 * w))
    v = np.stack([(1 + r * np.cos(w)) * np.cos(u), (1 + r * np.cos(w)) * np.sin(u), r * np.sin(w)], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    a, b = i * nv + j, (i + 1) % nu * nv + j
    c, d = (i + 1) % nu * nv + (j + 1) % nv, i * nv + (j + 1) % nv
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return v, faces


def _read(path: Path) -> np.ndarray:
    """``(H, W, 3)`` float RGB in [0, 1] of a PNG."""
    return mpimg.imread(path)[..., :3]


def _painted(img: np.ndarray) -> np.ndarray:
    """Mask of the pixels that are not (near) white."""
    return img.min(axis=-1) < 0.97


def _coloured(img: np.ndarray) -> np.ndarray:
    """Mask of the coloured pixels (not white, grey or the black title text)."""
    return img.max(axis=-1) - img.min(axis=-1) > 0.2


# --------------------------------------------------------------------------------------------------- rasterize


def test_rasterize_covers_the_triangle_and_nothing_else() -> None:
    # right triangle with legs 8 along x and y from (1, 1): samples (i + ½, j + ½) with i + j ≤ 7, i, j ≥ 1
    pts = np.array([[1.0, 1.0, 0.0], [9.0, 1.0, 0.0], [1.0, 9.0, 0.0]])
    r = rasterize(pts, np.array([[0, 1, 2]]), 12, 10)
    assert r.face.shape == (10, 12) and r.bary.shape == (10, 12, 3)
    jj, ii = np.mgrid[0:10, 0:12]
    cx, cy = ii + 0.5, jj + 0.5
    inside = (cx >= 1) & (cy >= 1) & (cx + cy <= 10)
    np.testing.assert_array_equal(r.face >= 0, inside)
    # barycentric coordinates reproduce the sample position; shade 1 for a face seen head-on
    xy = np.einsum("hwk,kd->hwd", r.bary, pts[:, :2])
    np.testing.assert_allclose(xy[inside], np.stack([cx, cy], -1)[inside], atol=1e-5)
    np.testing.assert_allclose(r.shade[inside], 1.0, atol=1e-6)
    assert np.all(r.shade[~inside] == 0)


@pytest.mark.parametrize("order", [(0, 1), (1, 0)])
def test_rasterize_nearer_face_wins(order: tuple[int, int]) -> None:
    # two triangles over the same samples, depth 1 (face 0, near) and depth 5 (face 1, far), in either order
    pts = np.array([[0, 0, 1], [20, 0, 1], [0, 20, 1], [0, 0, 5], [20, 0, 5], [0, 20, 5.0]])
    tris = np.array([[0, 1, 2], [3, 4, 5]])[list(order)]
    r = rasterize(pts, tris, 20, 20)
    near = list(order).index(0)
    covered = r.face >= 0
    assert covered.sum() > 150
    assert np.all(r.face[covered] == near)


def test_rasterize_tilted_faces_use_interpolated_depth() -> None:
    # two crossing planes: face 0 rises in depth along x, face 1 falls; each wins on its near half
    pts = np.array([[0, 0, 0], [16, 0, 10], [0, 16, 0], [16, 16, 10],
                    [0, 0, 10], [16, 0, 0], [0, 16, 10], [16, 16, 0.0]])
    tris = np.array([[0, 1, 2], [1, 3, 2], [4, 5, 6], [5, 7, 6]])
    r = rasterize(pts, tris, 16, 16)
    left = r.face[:, :7]
    right = r.face[:, 9:]
    assert np.all(left <= 1) and np.all(right >= 2)


def test_rasterize_has_no_pinholes_with_subpixel_triangles() -> None:
    # a 30 × 30 sample square tiled by 120 × 120 quads (triangles a sixteenth of a sample): every sample
    # centre inside the square is covered although most triangles contain no sample centre
    n = 121
    g = np.linspace(0.0, 30.0, n)
    x, y = np.meshgrid(g, g, indexing="ij")
    rng = np.random.default_rng(0)
    pts = np.stack([x.ravel(), y.ravel(), rng.random(n * n)], -1)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a, b, c, d = i * n + j, (i + 1) * n + j, (i + 1) * n + j + 1, i * n + j + 1
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    r = rasterize(pts, faces, 32, 32)
    assert np.all(r.face[:30, :30] >= 0)
    assert np.all(r.face[30:, :] == -1) and np.all(r.face[:, 30:] == -1)




def _grid(nu: int, nv: int, plane: str = "xz", lx: float = 2.0, ly: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Flat ``lx × ly`` patch of ``nu · nv`` vertices in the coordinate ``plane`` (``"xz"``: normal along y)."""
    s, t = np.meshgrid(np.linspace(-lx / 2, lx / 2, nu), np.linspace(-ly / 2, ly / 2, nv), indexing="ij")
    v = np.zeros((nu * nv, 3))
    v[:, "xyz".index(plane[0])], v[:, "xyz".index(plane[1])] = s.ravel(), t.ravel()
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="ij")
    a, b, c, d = i * nv + j, (i + 1) * nv + j, (i + 1) * nv + j + 1, i * nv + j + 1
    return v, np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])


def _panel(img: np.ndarray, layout: Layout, row: int = 0, col: int = 0) -> np.ndarray:
    """The pixels of one panel of a sheet."""
    box = next(b for b in layout.panels if (b.row, b.col) == (row, col))
    return img[box.y:box.y + box.h, box.x:box.x + box.w]


def test_rasterize_culls_clockwise_faces() -> None:
    # the same triangle anticlockwise (kept by cull=+1) and clockwise (kept by cull=−1) on screen
    pts = np.array([[1.0, 1.0, 0.0], [9.0, 1.0, 0.0], [1.0, 9.0, 0.0]])
    ccw, cw = np.array([[0, 1, 2]]), np.array([[0, 2, 1]])
    assert np.any(rasterize(pts, ccw, 12, 10, cull=1).face >= 0)
    assert np.all(rasterize(pts, cw, 12, 10, cull=1).face == -1)
    assert np.any(rasterize(pts, cw, 12, 10, cull=-1).face >= 0)
    np.testing.assert_array_equal(rasterize(pts, cw, 12, 10).face >= 0, rasterize(pts, ccw, 12, 10).face >= 0)


@pytest.mark.parametrize("budget", [1 << 21, 7, 1])
def test_edges_find_orientation_and_boundary(monkeypatch: pytest.MonkeyPatch, budget: int) -> None:
    # closed and oriented (cull back faces), or not; the boundary edges; the same in several passes
    from collections import Counter

    import stiefel_cmm.cli.raster as rv

    monkeypatch.setattr(rv, "_EDGE_BUDGET", budget)
    v, f = _torus(12, 6)
    assert rv.edges(f)[0] and len(rv.edges(f)[1]) == 0
    assert rv.orientation(f, v) == 1 and rv.orientation(f[:, ::-1], v) == -1
    turned = f.copy()
    turned[0] = turned[0, ::-1]
    assert rv.orientation(turned, v) == 0 and rv.orientation(np.r_[f, f[:1]], v) == 0 and rv.orientation(f[1:], v) == 0
    gv, gf = _grid(5, 4, "xy")
    oriented, boundary = rv.edges(gf)
    count = Counter(tuple(sorted(e)) for a, b, c in gf.tolist() for e in ((a, b), (b, c), (c, a)))
    assert not oriented and sorted(map(tuple, boundary.tolist())) == sorted(e for e, c in count.items() if c == 1)


def test_culling_a_closed_surface_changes_nothing(tmp_path: Path) -> None:
    # the torus is closed and oriented: culled back faces were hidden anyway, with either face winding
    v, f = _torus(40, 20)
    v *= np.array([1.3, 1.0, 1.0])                            # distinct principal axes: a well-defined frame
    field = (v[:, 0] * v[:, 2])[:, None]
    contact_sheet(tmp_path / "a.png", v, f, field, views=[(30.0, 20.0)])
    contact_sheet(tmp_path / "b.png", v, f[:, ::-1], field, views=[(30.0, 20.0)])
    a, b = _read(tmp_path / "a.png"), _read(tmp_path / "b.png")
    np.testing.assert_allclose(a, b, atol=2 / 255)


def test_front_view_shows_the_nearer_surface(tmp_path: Path) -> None:
    # two parallel rectangles, the small one (+1, red) in front of the big one (−1, blue) for a viewer on the
    # towards-side of the frame: the front view shows red in the middle, blue around; the back view all blue
    # or all red, whichever rectangle is nearer from behind
    small, sf = _grid(13, 5, "xz", lx=3.0, ly=1.0)
    big, bf = _grid(13, 5, "xz", lx=6.0, ly=2.0)
    for y, part in ((-0.5, small), (0.5, big)):
        part[:, 1] = y
    v, f = np.r_[small, big], np.r_[sf, bf + len(small)]
    field = np.r_[np.ones(len(small)), -np.ones(len(big))]
    frame = principal_frame(v, f, "z")
    nearer_front = "small" if -0.5 * frame.axes[2, 1] > 0.5 * frame.axes[2, 1] else "big"
    layout = contact_sheet(tmp_path / "two.png", v, f, field[:, None], up="z",
                           views=[("front", 0.0, 0.0), ("back", 180.0, 0.0)])
    img = _read(tmp_path / "two.png")
    for col, nearer in ((0, nearer_front), (1, "big" if nearer_front == "small" else "small")):
        panel = _panel(img, layout, 0, col)
        centre = panel[panel.shape[0] // 2, panel.shape[1] // 2]
        np.testing.assert_allclose(centre, RED if nearer == "small" else BLUE, atol=0.02)


# ------------------------------------------------------------------------------------------------- orientation


@pytest.mark.parametrize("plane", ["xz", "xy", "yz"])
def test_flat_patch_is_seen_face_on(tmp_path: Path, plane: str) -> None:
    # a flat patch in any coordinate plane (in x–z: a y-up mesh lying flat; in x–y: a z-up height field,
    # which the former z-up renderer saw edge-on): the principal axes put its two large extents on screen,
    # and a near-flat mesh gets only its front and back
    v, f = _grid(30, 30, plane)
    assert principal_frame(v, f).flat
    layout = contact_sheet(tmp_path / "flat.png", v, f, v[:, :1] + v[:, 1:2])
    assert [lab.text for lab in layout.labels if lab.role == "column"] == ["front", "back"]
    img = _read(tmp_path / "flat.png")
    for col in (0, 1):
        assert np.mean(_painted(_panel(img, layout, 0, col))) > 0.8
    # forcing its normal up shows it edge-on: hardly any mesh pixels
    normal = ({"x", "y", "z"} - set(plane)).pop()
    layout = contact_sheet(tmp_path / "edge.png", v, f, v[:, :1], up=normal, views=FRONT)
    assert np.mean(_painted(_panel(_read(tmp_path / "edge.png"), layout))) < 0.1


def _random_rotation(seed: int) -> np.ndarray:
    q, r = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    q *= np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


@pytest.mark.parametrize("seed", [0, 1])
def test_rotated_mesh_gives_the_same_picture(tmp_path: Path, seed: int) -> None:
    # principal axes signed by the third moment: the picture does not depend on the mesh's placement
    v, f = demo_mesh(3)
    fields = np.stack([v[:, 0] + 0.3 * v[:, 1], np.sin(2 * v[:, 2]) * v[:, 1]], axis=1)
    rot = _random_rotation(seed)
    contact_sheet(tmp_path / "a.png", v, f, fields)
    contact_sheet(tmp_path / "b.png", v @ rot.T + np.array([5.0, -2.0, 1.0]), f, fields)
    a, b = _read(tmp_path / "a.png"), _read(tmp_path / "b.png")
    assert a.shape == b.shape
    diff = np.abs(a - b).max(axis=-1)
    assert np.mean(diff) < 2e-3 and np.mean(diff > 0.1) < 2e-3
    # a mirror image is a different picture (the frame is a rotation, never a reflection)
    contact_sheet(tmp_path / "c.png", v * np.array([-1.0, 1.0, 1.0]), f[:, ::-1], fields)
    assert np.mean(np.abs(_read(tmp_path / "c.png") - a).max(axis=-1) > 0.1) > 0.02


def test_up_forces_the_vertical_axis(tmp_path: Path) -> None:
    # an ellipsoid tall along y: automatic axes lay its longest extent horizontal, up="y" stands it up
    v, f = demo_mesh(3)
    v = v[:, [2, 0, 1]] * np.array([1.0, 2.0, 1.0])           # longest now along y
    auto = principal_frame(v, f)
    assert abs(auto.axes[0, 1]) > 0.99                       # screen right is ±y
    for up, sign in (("y", 1.0), ("-y", -1.0), ("+Y", 1.0)):
        frame = principal_frame(v, f, up)
        np.testing.assert_allclose(frame.axes[1], [0.0, sign, 0.0], atol=1e-12)
        np.testing.assert_allclose(frame.axes @ frame.axes.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(frame.axes) > 0
    layout = contact_sheet(tmp_path / "tall.png", v, f, v[:, 1:2], up="y", views=FRONT)
    rows, cols = np.nonzero(_painted(_panel(_read(tmp_path / "tall.png"), layout)))
    assert np.ptp(rows) > 1.5 * np.ptp(cols)
    # the top of the standing mesh is red (field = y > 0), its bottom blue
    img = _panel(_read(tmp_path / "tall.png"), layout)
    top, bottom = img[rows.min() + 3, int(np.median(cols))], img[rows.max() - 3, int(np.median(cols))]
    assert top[0] > top[2] + 0.15 and bottom[2] > bottom[0] + 0.15


def test_open_scan_stands_on_its_boundary() -> None:
    # a hemisphere-like cup open at one end: whichever way it is turned, its rim ends up below
    v, f = demo_mesh(3)
    for flip in (1.0, -1.0):
        w = v * np.array([1.0, 1.8 * flip, 0.8])
        keep = np.all(w[f][:, :, 1] * flip > -0.9, axis=1)    # cut away the far end of the long axis
        used = np.unique(f[keep])
        remap = np.full(len(w), -1)
        remap[used] = np.arange(len(used))
        frame = principal_frame(w[used], remap[f[keep]])
        rim = w[used][np.abs(w[used][:, 1] * flip + 0.9) < 0.15]
        assert np.all((rim - frame.centre) @ frame.axes[1] < 0)


def test_invalid_up_is_named_before_drawing(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert [check_up(t) for t in ("x", "-z", "+Y", " y ", None, "auto", "")] == ["x", "-z", "y", "y", None, None, None]
    for bad in ("w", "up", "xy", "--x", 3):
        with pytest.raises(RenderOptionError, match=r"x, y, z, -x, -y, -z"):
            check_up(bad)
    v, f = _torus(8, 4)
    with pytest.raises(RenderOptionError, match="got 'sideways'"):
        contact_sheet(tmp_path / "x.png", v, f, v[:, :1], up="sideways")
    with pytest.raises(ValueError):                           # a RenderOptionError is a ValueError
        grid_sheet(tmp_path / "x.png", v, f, [v[:, :1]], row_titles=["a"], col_titles=["b"], up="q")
    assert not (tmp_path / "x.png").exists()
    # argparse's type= reports the message itself
    parser = argparse.ArgumentParser(prog="stiefel")
    parser.add_argument("--up", type=check_up)
    assert parser.parse_args(["--up=-y"]).up == "-y" and parser.parse_args(["--up", "Z"]).up == "z"
    with pytest.raises(SystemExit):
        parser.parse_args(["--up", "w"])
    assert "up must be one of x, y, z, -x, -y, -z" in capsys.readouterr().err


def test_other_invalid_options_are_named(tmp_path: Path) -> None:
    v, f = _torus(8, 4)
    with pytest.raises(RenderOptionError, match="'raster' or 'polygons'"):
        contact_sheet(tmp_path / "x.png", v, f, v[:, :1], method="vector")
    with pytest.raises(RenderOptionError, match=r"2 titles for 1 rows \(fields\)"):
        contact_sheet(tmp_path / "x.png", v, f, v[:, :1], titles=["a", "b"])
    with pytest.raises(RenderOptionError, match="view"):
        contact_sheet(tmp_path / "x.png", v, f, v[:, :1], views=[(1.0, 2.0, 3.0, 4.0)])
    with pytest.raises(RenderOptionError, match="colormap"):
        contact_sheet(tmp_path / "x.png", v, f, v[:, :1], cmap="no-such-map")
    with pytest.raises(RenderOptionError, match="n = 32"):
        contact_sheet(tmp_path / "x.png", v, f, np.ones((31, 2)))
    with pytest.raises(RenderOptionError, match="same c"):
        grid_sheet(tmp_path / "x.png", v, f, [v[:, :1], v[:, :2]], row_titles=["a", "b"], col_titles=["c"])
    assert not (tmp_path / "x.png").exists()


# ------------------------------------------------------------------------------------------------ colours, labels


def test_colours_are_symmetric_about_zero_with_a_colour_bar(tmp_path: Path) -> None:
    # a flat patch seen face-on (unshaded): field −3 on one third, 0 in the middle, +3 on the other third;
    # limits ±3, so +3 is the darkest red, 0 white and −3 the darkest blue
    v, f = _grid(61, 21, "xy", lx=3.0, ly=1.0)
    field = np.where(v[:, 0] > 0.5, 3.0, np.where(v[:, 0] < -0.5, -3.0, 0.0))
    layout = contact_sheet(tmp_path / "c.png", v, f, field[:, None], views=FRONT)
    img = _read(tmp_path / "c.png")
    panel = _panel(img, layout)
    rows, cols = np.nonzero(_painted(panel))
    cy = int(np.median(rows))
    x0, x1 = cols.min(), cols.max()
    span = x1 - x0
    # the right or left end is red, the other blue: the patch's sign along x is set by its third moment (0 here)
    ends = [panel[cy, x0 + span // 8], panel[cy, x1 - span // 8]]
    np.testing.assert_allclose(sorted(ends, key=lambda c: c[0] - c[2]), [BLUE, RED], atol=0.02)
    np.testing.assert_allclose(panel[cy, (x0 + x1) // 2], WHITE, atol=0.02)
    # the colour bar: red on top, white in the middle, blue at the bottom (inside its outline); ticks +3, 0, −3
    bar = layout.bars[0]
    column = img[bar.y:bar.y + bar.h, bar.x + bar.w // 2]
    expected = matplotlib.colormaps["RdBu_r"](np.linspace(1.0, 0.0, bar.h))[:, :3]
    np.testing.assert_allclose(column[1:-1], expected[1:-1], atol=0.02)
    assert column[1, 0] > 0.38 and column[1, 2] < 0.2 and column[-2, 2] > 0.35 and column[-2, 0] < 0.1
    assert [lab.text for lab in layout.labels if lab.role == "tick"] == ["+3", "0", "−3"]


def test_asymmetric_field_uses_its_largest_magnitude(tmp_path: Path) -> None:
    # values in [−1, 4]: limits ±4; −1 is a pale blue, not the darkest
    v, f = _grid(61, 21, "xy", lx=3.0, ly=1.0)
    field = np.where(v[:, 0] > 0, 4.0, -1.0)
    layout = contact_sheet(tmp_path / "a.png", v, f, field[:, None], views=FRONT)
    assert [lab.text for lab in layout.labels if lab.role == "tick"] == ["+4", "0", "−4"]
    panel = _panel(_read(tmp_path / "a.png"), layout)
    rows, cols = np.nonzero(_painted(panel))
    cy, span = int(np.median(rows)), cols.max() - cols.min()
    ends = sorted([panel[cy, cols.min() + span // 6], panel[cy, cols.max() - span // 6]], key=lambda c: c[0] - c[2])
    pale = np.asarray(matplotlib.colormaps["RdBu_r"](0.5 - 1 / 8)[:3])
    np.testing.assert_allclose(ends, [pale, RED], atol=0.03)


def test_nan_zero_and_infinite_values(tmp_path: Path) -> None:
    # NaN is grey, an all-zero field white with limits ±1, ±inf saturate without setting the limits
    v, f = _grid(61, 21, "xy", lx=3.0, ly=1.0)
    fields = np.stack([np.where(v[:, 0] > 0, np.nan, 1.0), np.zeros(len(v)),
                       np.where(v[:, 0] > 0.5, np.inf, np.where(v[:, 0] < -0.5, -np.inf, 0.5))], axis=1)
    layout = contact_sheet(tmp_path / "n.png", v, f, fields, views=FRONT)
    assert [lab.text for lab in layout.labels if lab.role == "tick"] == ["+1", "0", "−1", "+1", "0", "−1",
                                                                         "+0.5", "0", "−0.5"]
    img = _read(tmp_path / "n.png")
    for row in range(3):
        panel = _panel(img, layout, row)
        cy = panel.shape[0] // 2
        colours = sorted([panel[cy, 20], panel[cy, -20]], key=lambda c: c[0] - c[2])
        if row == 0:
            assert any(np.allclose(c, 0.6, atol=0.02) for c in colours) and any(c[0] > c[2] + 0.2 for c in colours)
        elif row == 1:
            np.testing.assert_allclose(colours, [WHITE, WHITE], atol=0.02)
        else:
            np.testing.assert_allclose(colours, [BLUE, RED], atol=0.02)
    with pytest.raises(RenderOptionError, match="finite"):
        contact_sheet(tmp_path / "x.png", v * np.nan, f, fields)


def test_labels_name_rows_columns_and_limits(tmp_path: Path) -> None:
    v, f = demo_mesh(2)
    titles = ["mode 3 · λ̃ = 12.4 · support 8.1 %", "mode 4 · λ̃ = 13 · support 9 %"]
    fields = np.stack([v[:, 0], 0.01 * v[:, 1]], axis=1)
    layout = contact_sheet(tmp_path / "l.png", v, f, fields, titles=titles)
    by_role = {role: [lab for lab in layout.labels if lab.role == role] for role in ("row", "column", "tick")}
    assert [lab.text for lab in by_role["row"]] == titles
    assert [lab.text for lab in by_role["column"]] == [name for name, _, _ in VIEWS]
    assert len(by_role["tick"]) == 6 and by_role["tick"][1].text == "0"
    vmax = np.abs(0.01 * v[:, 1]).max()
    assert by_role["tick"][3].text == f"+{vmax:.3g}" and by_role["tick"][5].text == f"−{vmax:.3g}"
    # each label is drawn: dark ink where it stands, above its row's panels
    img = _read(tmp_path / "l.png")
    for lab in layout.labels:
        ink = img[lab.y - 8:lab.y + 1, max(lab.x - 40, 0):lab.x + 40].min(axis=-1)
        assert ink.min() < 0.35, lab
    for lab, panel in zip(by_role["row"], [b for b in layout.panels if b.col == 0]):
        assert lab.y < panel.y
    assert img.shape[:2] == (layout.height, layout.width)


def test_both_drawings_write_the_layout(tmp_path: Path) -> None:
    # "raster" interpolates inside faces, "polygons" colours each face by its mean: same picture outline
    v, f = _torus(24, 12)
    fields = np.stack([v[:, 0], v[:, 1] * v[:, 2]], axis=1)
    masks = []
    for method in ("raster", "polygons"):
        path = tmp_path / f"{method}.png"
        layout = contact_sheet(path, v, f, fields, titles=["x", "yz"], dpi=60, method=method)
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        img = _read(path)
        assert img.shape[:2] == (layout.height, layout.width)
        rgb = img.reshape(-1, 3)
        assert np.any(rgb[:, 0] - rgb[:, 2] > 0.3) and np.any(rgb[:, 2] - rgb[:, 0] > 0.3)   # both signs
        masks.append(_painted(img))
        # a binary file works too, and gets the same picture
        buf = io.BytesIO()
        contact_sheet(buf, v, f, fields, titles=["x", "yz"], dpi=60, method=method)
        np.testing.assert_array_equal(mpimg.imread(io.BytesIO(buf.getvalue()), format="png")[..., :3], img)
    assert np.sum(masks[0] ^ masks[1]) < 0.02 * np.sum(masks[0])


def test_sheet_size_grows_with_rows_and_dpi(tmp_path: Path) -> None:
    v, f = demo_mesh(2)
    sizes = [contact_sheet(tmp_path / "s.png", v, f, np.tile(v[:, :1], (1, k))) for k in (1, 2, 3)]
    assert sizes[0].width == sizes[1].width == sizes[2].width
    assert sizes[2].height - sizes[1].height == sizes[1].height - sizes[0].height > 0
    big = contact_sheet(tmp_path / "s.png", v, f, v[:, :1], dpi=160)
    assert abs(big.width / sizes[0].width - 2.0) < 0.1 and abs(big.height / sizes[0].height - 2.0) < 0.1


def test_png_bytes_round_trip() -> None:
    from PIL import Image

    rgb = np.random.default_rng(0).integers(0, 256, (17, 23, 3), dtype=np.uint8)
    img = Image.open(io.BytesIO(png_bytes(rgb, dpi=96)))
    np.testing.assert_array_equal(np.asarray(img), rgb)
    assert round(img.info["dpi"][0]) == 96


# ---------------------------------------------------------------------------------------------------- grid_sheet


def test_grid_sheet_shape_labels_and_per_panel_colours(tmp_path: Path) -> None:
    # rows × columns of panels; image size linear in each; every panel coloured by its own ±max
    v, f = demo_mesh(2)
    base = np.stack([v[:, 0], v[:, 1], v[:, 2], v[:, 0] * v[:, 1]], axis=1)
    layouts = {}
    for r, c in ((1, 3), (2, 3), (3, 3), (2, 2), (2, 4)):
        fields = np.stack([base[:, :c] * (10.0 ** j) for j in range(r)])             # (r, n, c)
        rows = [f"smoothing {j} · objective {j * 1.5:.1f} · sparsity {40 + j} %" for j in range(r)]
        cols = [f"mode {i}" for i in range(c)]
        path = tmp_path / f"g{r}{c}.png"
        layouts[r, c] = lay = grid_sheet(path, v, f, fields, row_titles=rows, col_titles=cols)
        img = _read(path)
        assert img.shape[:2] == (lay.height, lay.width)
        assert len(lay.panels) == r * c and len(lay.bars) == r
        assert [lab.text for lab in lay.labels if lab.role == "row"] == rows
        assert [lab.text for lab in lay.labels if lab.role == "column"] == cols
        assert len([lab for lab in lay.labels if lab.role == "caption"]) == r * c
    dh = layouts[2, 3].height - layouts[1, 3].height
    assert dh > 0 and layouts[3, 3].height - layouts[2, 3].height == dh
    assert layouts[1, 3].width == layouts[2, 3].width == layouts[3, 3].width
    dw = layouts[2, 3].width - layouts[2, 2].width
    assert dw > 0 and layouts[2, 4].width - layouts[2, 3].width == dw
    # a panel 100× larger in amplitude looks the same: colours are per panel
    img = _read(tmp_path / "g33.png")
    lay = layouts[3, 3]
    np.testing.assert_allclose(_panel(img, lay, 0, 1), _panel(img, lay, 2, 1), atol=2 / 255)
    captions = [lab.text for lab in lay.labels if lab.role == "caption"]
    assert captions[1] == f"±{np.abs(v[:, 1]).max():.3g}" and captions[7] == f"±{100 * np.abs(v[:, 1]).max():.3g}"


def test_grid_sheet_accepts_a_list_of_arrays(tmp_path: Path) -> None:
    v, f = _grid(20, 20, "xz")
    lay = grid_sheet(tmp_path / "g.png", v, f, [v[:, [0, 2]], -v[:, [0, 2]]], row_titles=["a", "b"],
                     col_titles=["x", "z"])
    img = _read(tmp_path / "g.png")
    assert np.mean(_painted(_panel(img, lay, 1, 1))) > 0.6                               # face-on
    # row 1 is row 0 negated: red and blue swap
    p0, p1 = _panel(img, lay, 0, 0), _panel(img, lay, 1, 0)
    s0, s1 = p0[..., 0] - p0[..., 2], p1[..., 0] - p1[..., 2]
    strong = np.abs(s0) > 0.2
    assert strong.mean() > 0.3 and np.all(np.sign(s0[strong]) == -np.sign(s1[strong]))


# ------------------------------------------------------------------------------------------------------ memory


def test_raster_memory_does_not_grow_with_faces(tmp_path: Path) -> None:
    # 100 352 vertices, 200 704 faces, one field: the former PolyCollection drawing peaks at 268 MiB of
    # Python-allocated memory here (measured once with method="polygons"; 11.7 GB at 407K vertices, k = 10);
    # the raster needs the O(n) projected vertices and O(pixels + chunk) buffers
    v, f = _torus(448, 224)
    field = (v[:, 0] * v[:, 2])[:, None]
    contact_sheet(tmp_path / "warm.png", *_torus(8, 4), np.ones((32, 1)))     # imports and font caches
    tracemalloc.start()
    try:
        contact_sheet(tmp_path / "big.png", v, f, field)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 64 * 2**20, f"peak {peak / 2**20:.1f} MiB"
