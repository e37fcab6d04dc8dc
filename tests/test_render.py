"""The PNG contact sheet (cli/render.py): the z-buffer rasteriser paints the right faces in the right
colours, both drawings give the documented image size and layout, and rendering memory does not grow
with the number of faces (project issue 19, item 5)."""

from __future__ import annotations

import io
import tracemalloc
from pathlib import Path

import matplotlib
import matplotlib.image as mpimg
import numpy as np
import pytest

from cli.render import VIEWS, contact_sheet, rasterize

# a side view: azimuth 0, elevation 0 shows the x–z plane (screen x = x, screen y = z, depth = y)
FRONT = ((0.0, 0.0),)


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


# ------------------------------------------------------------------------------------------------ contact_sheet


def test_constant_positive_field_is_red_on_white(tmp_path: Path) -> None:
    # one large triangle in the x–z plane facing the viewer, field ≡ 2 > 0: the darkest red of RdBu_r
    # (vmax = 2 maps to the top of the colormap), unshaded (normal along the view direction)
    v = np.array([[-1.0, 0.0, -1.0], [1.0, 0.0, -1.0], [0.0, 0.0, 1.0]])
    path = tmp_path / "tri.png"
    contact_sheet(path, v, np.array([[0, 1, 2]]), np.full((3, 1), 2.0), views=FRONT)
    img = _read(path)
    assert img.shape[:2] == (176, 192)                          # 2.2 × 2.4 inches at 80 dpi
    rows, cols = np.nonzero(_coloured(img))
    # the triangle's centroid (0, −⅓) lies ⅔ of the way down its bounding box, in the middle
    cy = int(round(rows.min() + (rows.max() - rows.min()) * 2 / 3))
    cx = int(round(0.5 * (cols.min() + cols.max())))
    red = np.asarray(matplotlib.colormaps["RdBu_r"](1.0)[:3])
    np.testing.assert_allclose(img[cy - 3:cy + 4, cx - 3:cx + 4], np.broadcast_to(red, (7, 7, 3)), atol=0.01)
    # background white: the corners and the strip above the apex's sides
    for y, x in [(0, 0), (0, -1), (-1, 0), (-1, -1), (rows.min() + 2, cols.min() + 2)]:
        np.testing.assert_allclose(img[y, x], 1.0, atol=1e-6)


def test_near_triangle_hides_far_one_in_the_picture(tmp_path: Path) -> None:
    # far triangle (depth y = +1, field −1, blue) is bigger than the near one (y = −1, field +1, red)
    v = np.array([[-1.0, 1.0, -1.0], [1.0, 1.0, -1.0], [0.0, 1.0, 1.0],
                  [-0.5, -1.0, -0.5], [0.5, -1.0, -0.5], [0.0, -1.0, 0.5]])
    f = np.array([[0, 1, 2], [3, 4, 5]])
    field = np.array([-1.0, -1.0, -1.0, 1.0, 1.0, 1.0])[:, None]
    red, blue = (np.asarray(matplotlib.colormaps["RdBu_r"](t)[:3]) for t in (1.0, 0.0))
    for order in (f, f[::-1]):
        path = tmp_path / "two.png"
        contact_sheet(path, v, order, field, views=FRONT)
        img = _read(path)
        rows, cols = np.nonzero(_coloured(img))
        cx = int(round(0.5 * (cols.min() + cols.max())))
        cy = int(round(rows.min() + (rows.max() - rows.min()) * 2 / 3))   # the centroid of both
        np.testing.assert_allclose(img[cy, cx], red, atol=0.01)                       # the near triangle
        np.testing.assert_allclose(img[rows.max() - 3, cols.min() + 5], blue, atol=0.01)  # the far one's corner


@pytest.mark.parametrize("method", ["raster", "polygons"])
def test_both_drawings_write_the_documented_image(tmp_path: Path, method: str) -> None:
    v, f = _torus(24, 12)
    fields = np.stack([v[:, 0], v[:, 1] * v[:, 2]], axis=1)
    path = tmp_path / f"{method}.png"
    contact_sheet(path, v, f, fields, titles=["x", "yz"], dpi=60, method=method)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    img = _read(path)
    assert img.shape[:2] == (round(2.2 * 2 * 60), round(2.4 * len(VIEWS) * 60))
    rgb = img.reshape(-1, 3)
    assert np.any(rgb[:, 0] - rgb[:, 2] > 0.3) and np.any(rgb[:, 2] - rgb[:, 0] > 0.3)   # both signs shown
    # a binary file works too, and gets the same picture whatever the target is called
    buf = io.BytesIO()
    contact_sheet(buf, v, f, fields, titles=["x", "yz"], dpi=60, method=method)
    np.testing.assert_array_equal(mpimg.imread(io.BytesIO(buf.getvalue()), format="png")[..., :3], img)


def test_raster_keeps_the_polygon_layout(tmp_path: Path) -> None:
    # the raster sheet places every picture where tight_layout puts the polygons' axes: the painted
    # pixels agree except along the outlines (antialiased in one, jagged in the other)
    from cli.demo_mesh import demo_mesh

    import mesh

    m = mesh.load(demo_mesh())
    v, f = np.asarray(m.vertices), np.asarray(m.faces)
    fields = np.stack([v[:, 0], v[:, 1] * v[:, 2]], axis=1)
    masks = []
    for method in ("raster", "polygons"):
        contact_sheet(tmp_path / f"{method}.png", v, f, fields, method=method)
        masks.append(_painted(_read(tmp_path / f"{method}.png")))
    assert masks[0].shape == masks[1].shape
    assert np.sum(masks[0] ^ masks[1]) < 0.03 * np.sum(masks[1])


def test_unknown_method_is_named(tmp_path: Path) -> None:
    v, f = _torus(8, 4)
    with pytest.raises(ValueError, match="'raster' or 'polygons'"):
        contact_sheet(tmp_path / "x.png", v, f, v[:, :1], method="vector")


# ------------------------------------------------------------------------------------------------------ memory


def test_raster_memory_does_not_grow_with_faces(tmp_path: Path) -> None:
    # 100 352 vertices, 200 704 faces, one field: the former PolyCollection drawing peaks at 268 MiB of
    # Python-allocated memory here (measured once with method="polygons"; 11.7 GB at 407K vertices, k = 10);
    # the raster needs the O(n) projected vertices and O(pixels + chunk) buffers, ~25 MiB
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
