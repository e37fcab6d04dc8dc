"""A self-contained interactive HTML viewer of per-vertex fields on a triangle mesh (``stiefel view``).

``write_viewer`` draws the mesh with plotly (``go.Mesh3d``: WebGL, mouse orbit/zoom, a colour bar,
a drop-down menu that picks the field) and writes ONE HTML file with plotly.js and the data
embedded: it opens offline, from disk, in any browser. Each field is shown on a symmetric
diverging colour map (``RdBu_r``: blue < 0 < red) with limits ±max|field|. Meshes above
``max_faces`` faces are decimated for display (``fast_simplification``, quadric error) and each
shown vertex takes the field values of its nearest original vertex (``scipy.spatial.cKDTree``),
so the shown values stay within each field's range; the page says so.

``add_parser``/``run_view`` are the ``stiefel view OUTDIR`` subcommand: it reads the ``modes.npz``
of ``stiefel modes`` (or the ``eigs.npz`` of ``stiefel eigs``) and writes ``OUTDIR/view.html``
atomically. Bad input raises ``ViewerError`` (one line naming the problem and the fix).
numpy, plotly and scipy are imported inside the functions: importing this module is cheap.
"""

from __future__ import annotations

import argparse
import contextlib
import html
import io
import operator
import os
import tempfile
from pathlib import Path
from typing import IO, Any, Mapping, Sequence

from .outputs import INT_MAX, PROG, bounded_int

__all__ = ["ViewerError", "write_viewer", "decimate", "load_run", "add_parser", "run_view", "DEFAULT_MAX_FACES",
           "VIEW_NAME"]

#: meshes with more faces are decimated to this many for display
DEFAULT_MAX_FACES = 80_000
#: the file ``stiefel view OUTDIR`` writes in OUTDIR by default
VIEW_NAME = "view.html"
#: the run files ``stiefel view`` reads, first found wins: (file, fields array, values array, field label, value label)
_SOURCES = (("modes.npz", "modes", "compressed_eigenvalues", "mode", "λ̃"),
            ("eigs.npz", "eigenvectors", "eigenvalues", "eigenfunction", "λ"))
_BACKGROUND = "white"


class ViewerError(Exception):
    """Bad input to the viewer (missing run files, inconsistent arrays); one line naming the fix."""


# ---------------------------------------------------------------------------- checks and decimation


def _check(vertices: Any, faces: Any, fields: Any, *, where: str, fix: str,
           names: Sequence[str] = ("vertices", "faces", "fields")) -> tuple[Any, Any, Any]:
    """``(vertices (n, 3) float64, faces (m, 3) int64, fields (n, k) float64)`` or ``ViewerError``.

    ``where`` starts each message (e.g. the file), ``fix`` ends it; ``names`` name the three arrays."""
    import numpy as np

    def fail(problem: str) -> ViewerError:
        return ViewerError(f"{where}{problem}: {fix}")

    nv, nf, nfield = names
    try:
        v = np.asarray(vertices, dtype=np.float64)
        f = np.asarray(faces)
        u = np.asarray(fields, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise fail(f"arrays are not numeric ({e})") from None
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] < 3:
        raise fail(f"{nv!r} has shape {v.shape}, expected (n, 3) with n >= 3")
    if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] < 1 or not np.issubdtype(f.dtype, np.integer):
        raise fail(f"{nf!r} has shape {f.shape} and dtype {f.dtype}, expected integer (m, 3) with m >= 1")
    u = u.reshape(-1, 1) if u.ndim == 1 else u
    if u.ndim != 2 or u.shape[0] != v.shape[0] or u.shape[1] < 1:
        raise fail(f"{nfield!r} has shape {u.shape}, expected (n, k) with n = {v.shape[0]} rows (one per vertex)")
    f = f.astype(np.int64)
    if f.min() < 0 or f.max() >= v.shape[0]:
        bad = int(f.min()) if f.min() < 0 else int(f.max())
        raise fail(f"{nf!r} index {bad} is out of range for {v.shape[0]} vertices")
    for name, a in ((nv, v), (nfield, u)):
        if not np.all(np.isfinite(a)):
            raise fail(f"{name!r} has {int(np.size(a) - np.isfinite(a).sum())} non-finite values")
    return v, f, u


def decimate(vertices: Any, faces: Any, fields: Any, max_faces: int) -> tuple[Any, Any, Any]:
    """The mesh with at most ``max_faces`` faces: ``(vertices (n', 3), faces (m', 3), fields (n', k))``.

    Unchanged if it has ``m <= max_faces`` faces; else quadric decimation (``fast_simplification``)
    and each new vertex takes the fields of its nearest original vertex (``cKDTree``): every shown
    value is one of the original ones."""
    import fast_simplification
    import numpy as np
    from scipy.spatial import cKDTree

    vertices, faces, fields = np.asarray(vertices), np.asarray(faces), np.asarray(fields)
    if len(faces) <= max_faces:
        return vertices, faces, fields
    v2, f2 = fast_simplification.simplify(np.ascontiguousarray(vertices, dtype=np.float64),
                                          np.ascontiguousarray(faces, dtype=np.int64),
                                          target_reduction=1.0 - max_faces / len(faces))
    used, f2 = np.unique(np.asarray(f2, dtype=np.int64), return_inverse=True)  # drop unreferenced vertices
    v2 = np.asarray(v2, dtype=np.float64)[used]
    _, nearest = cKDTree(vertices).query(v2)
    return v2, f2.reshape(-1, 3), fields[nearest]


# ---------------------------------------------------------------------------- the page


def _spec(a: Any, dtype: str) -> dict:
    """A plotly.js typed-array spec ``{"dtype", "bdata"}`` (base64, little-endian) for ``a``."""
    import base64

    import numpy as np

    data = np.ascontiguousarray(a, dtype=f"<{dtype}").tobytes()
    return {"dtype": dtype, "bdata": base64.b64encode(data).decode("ascii")}


def _figure(v: Any, f: Any, u: Any, limits: Any, names: Sequence[str], subtitles: Sequence[str], title: str,
            note: str, camera: Mapping | None) -> Any:
    """The plotly figure: one ``Mesh3d`` coloured by field 0, a menu restyling it to field j."""
    import plotly.graph_objects as go

    def heading(j: int) -> str:
        sub = f"{names[j]}{': ' + subtitles[j] if subtitles[j] else ''}"
        return f"{html.escape(title)}<br><sup>{html.escape(sub)}</sup>"

    def shown(j: int) -> dict:  # the trace attributes that change with the field
        return {"intensity": _spec(u[:, j], "f4"), "cmin": -limits[j], "cmax": limits[j],
                "colorbar.title.text": html.escape(names[j]),
                "hovertemplate": f"{html.escape(names[j])} = %{{intensity:.4g}}<extra></extra>"}

    first = shown(0)
    fig = go.Figure(go.Mesh3d(
        x=_spec(v[:, 0], "f4"), y=_spec(v[:, 1], "f4"), z=_spec(v[:, 2], "f4"),
        i=_spec(f[:, 0], "i4"), j=_spec(f[:, 1], "i4"), k=_spec(f[:, 2], "i4"), intensitymode="vertex",
        intensity=first["intensity"], cmin=first["cmin"], cmax=first["cmax"], hovertemplate=first["hovertemplate"],
        colorscale="RdBu_r", colorbar={"title": {"text": first["colorbar.title.text"]}}, flatshading=False))
    buttons = [{"label": html.escape(names[j]), "method": "update",
                "args": [{key: [value] for key, value in shown(j).items()}, {"title.text": heading(j)}]}
               for j in range(len(names))]
    axis = {"visible": False, "showspikes": False}
    scene: dict[str, Any] = {"xaxis": axis, "yaxis": axis, "zaxis": axis, "aspectmode": "data",
                             "dragmode": "orbit", "bgcolor": _BACKGROUND}
    if camera is not None:
        scene["camera"] = dict(camera)
    fig.update_layout(
        title={"text": heading(0), "x": 0.5, "xanchor": "center"}, scene=scene, paper_bgcolor=_BACKGROUND,
        margin={"l": 0, "r": 0, "t": 70, "b": 30},
        updatemenus=[{"buttons": buttons, "direction": "down", "showactive": True, "x": 0.01, "xanchor": "left",
                      "y": 0.99, "yanchor": "top"}],
        annotations=[{"text": html.escape(note), "showarrow": False, "xref": "paper", "yref": "paper",
                      "x": 0.01, "y": 0.0, "xanchor": "left", "yanchor": "bottom", "font": {"size": 12}}])
    return fig


def _page(fig: Any, title: str) -> str:
    """The full HTML document: plotly.js inlined (no network), a ``<title>``, the plot filling the window."""
    doc = fig.to_html(include_plotlyjs=True, full_html=True, include_mathjax=False, default_width="100%",
                      default_height="100%", config={"displaylogo": False, "showSendToCloud": False,
                                                     "scrollZoom": True, "responsive": True})
    meta = '<meta charset="utf-8" />'
    extra = f"\n    <title>{html.escape(title)}</title>\n    <style>html, body {{margin: 0; overflow: hidden;}}</style>"
    doc = doc.replace(meta, meta + extra, 1) if meta in doc else doc.replace("<head>", "<head>" + extra, 1)
    return doc if doc.lstrip().lower().startswith("<!doctype") else "<!doctype html>\n" + doc  # not quirks mode


def _write_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in its directory, fsync, ``os.replace``."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            os.fchmod(fh.fileno(), 0o644)
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    with contextlib.suppress(OSError):  # make the rename durable too (best effort)
        dfd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)


def default_camera(vertices: Any, faces: Any, up: str | None = None) -> dict:
    """A plotly ``scene.camera`` that opens on the contact sheet's front view (``stiefel_cmm.cli.render_views.principal_frame``:
    the mesh's principal axes, or ``up`` forced), seen from a little above and to the right, the whole mesh in view."""
    import numpy as np

    from .render_views import principal_frame

    frame = principal_frame(np.asarray(vertices, dtype=np.float64), np.asarray(faces), up)
    right, upv, towards = frame.axes
    eye = towards + 0.35 * upv + 0.25 * right
    eye = 2.4 * eye / np.linalg.norm(eye)  # plotly's scene box spans ±1 along the longest axis: the whole mesh in view
    return {"eye": dict(zip("xyz", map(float, eye))), "up": dict(zip("xyz", map(float, upv))),
            "center": {"x": 0.0, "y": 0.0, "z": 0.0}}


def write_viewer(target: str | os.PathLike | IO, vertices: Any, faces: Any, fields: Any, names: Sequence[str], *,
                 title: str, subtitles: Sequence[str] | None = None, max_faces: int = DEFAULT_MAX_FACES,
                 camera: Mapping | None = None, up: str | None = None) -> dict:
    """Write the interactive viewer of ``fields`` on the mesh as one self-contained HTML file.

    target: a path (written atomically: temporary file, fsync, rename) or an open binary or text file.
    vertices ``(n, 3)``, faces ``(m, 3)``, fields ``(n, k)`` (or ``(n,)``), names: k labels of the menu;
    subtitles: k texts shown under the title with the field (e.g. ``"λ̃ = 0.12"``); meshes with more
    than ``max_faces`` faces are decimated for display; camera: a plotly ``scene.camera`` dict
    (e.g. ``{"eye": {"x": 0, "y": 0, "z": 2}, "up": {"x": 0, "y": 1, "z": 0}}``), default
    ``default_camera(vertices, faces, up)`` (``up``: as the contact sheet's ``--up``).
    Returns ``{"vertices", "faces"`` (shown), ``"decimated", "original_vertices", "original_faces", "bytes"}``.
    Raises ``ViewerError`` for inconsistent arrays or labels.
    """
    import numpy as np

    v, f, u = _check(vertices, faces, fields, where="write_viewer: ",
                     fix="pass vertices (n, 3), faces (m, 3) indexing them and finite fields (n, k)")
    names = [str(s) for s in names]
    subtitles = [""] * len(names) if subtitles is None else [str(s) for s in subtitles]
    if len(names) != u.shape[1] or len(subtitles) != u.shape[1]:
        raise ViewerError(f"write_viewer: {len(names)} names and {len(subtitles)} subtitles for {u.shape[1]} "
                          "fields: give one of each per column of fields")
    try:
        max_faces = operator.index(max_faces)
    except TypeError:
        max_faces = -1
    if max_faces < 4:
        raise ViewerError("write_viewer: max_faces must be an integer >= 4")
    limits = np.max(np.abs(u), axis=0)
    limits = np.where(limits > 0, limits, 1.0)  # an all-zero field: a range around 0 all the same
    v2, f2, u2 = decimate(v, f, u, max_faces)
    decimated = len(f2) < len(f)
    note = (f"decimated from {len(v)} to {len(v2)} vertices for display ({len(f)} → {len(f2)} faces)" if decimated
            else f"{len(v)} vertices, {len(f)} faces")
    if camera is None:
        camera = default_camera(v, f, up)
    page = _page(_figure(v2, f2, u2, limits.tolist(), names, subtitles, title, note, camera), title)
    data = page.encode("utf-8")
    if isinstance(target, (str, os.PathLike)):
        _write_atomic(Path(target), data)
    elif isinstance(target, io.TextIOBase):
        target.write(page)
    else:
        target.write(data)
    return {"vertices": int(len(v2)), "faces": int(len(f2)), "decimated": bool(decimated),
            "original_vertices": int(len(v)), "original_faces": int(len(f)), "bytes": len(data)}


# ---------------------------------------------------------------------------- stiefel view


def load_run(outdir: str | os.PathLike) -> dict:
    """Read a run directory of ``stiefel modes`` (``modes.npz``, preferred) or ``stiefel eigs`` (``eigs.npz``).

    Returns ``{"source": Path, "vertices" (n, 3), "faces" (m, 3), "fields" (n, k), "names": [k],
    "subtitles": [k]}``; raises ``ViewerError`` naming the problem and the fix."""
    import zipfile

    import numpy as np

    out = Path(outdir)
    hint = "give the --out directory of 'stiefel modes' or 'stiefel eigs'"
    if not out.exists():
        raise ViewerError(f"run directory not found: {out}: {hint}")
    if not out.is_dir():
        raise ViewerError(f"not a directory: {out}: {hint}")
    found = [s for s in _SOURCES if (out / s[0]).is_file()]
    if not found:
        raise ViewerError(f"no modes.npz or eigs.npz in {out}: run 'stiefel modes --out {out}' "
                          f"or 'stiefel eigs --out {out}' first")
    fname, key, values_key, label, symbol = found[0]
    path, fix = out / fname, f"rerun 'stiefel {fname.split('.')[0]} --out {out}'"
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [a for a in ("vertices", "faces", key) if a not in npz.files]
            if missing:
                raise ViewerError(f"{path} lacks the array(s) {', '.join(map(repr, missing))}: {fix}")
            arrays = {a: npz[a] for a in ("vertices", "faces", key)}
            values = npz[values_key] if values_key in npz.files else None
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as e:
        raise ViewerError(f"{path} is not a readable npz file ({type(e).__name__}: {e}): {fix}") from None
    v, f, u = _check(arrays["vertices"], arrays["faces"], arrays[key], where=f"{path}: ", fix=fix,
                     names=("vertices", "faces", key))
    k = u.shape[1]
    subtitles = [""] * k
    if values is not None:
        values = np.asarray(values).reshape(-1)
        if values.shape != (k,) or not np.issubdtype(values.dtype, np.number):
            raise ViewerError(f"{path}: {values_key!r} has shape {values.shape}, expected ({k},): {fix}")
        subtitles = [f"{symbol} = {float(x):.6g}" for x in values]
    return {"source": path, "vertices": v, "faces": f, "fields": u, "names": [f"{label} {j}" for j in range(k)],
            "subtitles": subtitles}


def _max_faces(text: str) -> int:
    try:
        return bounded_int(4, INT_MAX)(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _up(text: str) -> str | None:
    from .render_views import check_up

    return check_up(text)


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``view`` subcommand to an argparse subparsers object; return its parser."""
    p = sub.add_parser("view", help="interactive HTML viewer (one self-contained file) of a modes/eigs run",
                       description="Write OUTDIR/view.html: the mesh of a 'stiefel modes' (modes.npz) or "
                                   "'stiefel eigs' (eigs.npz) run coloured by a chosen mode; opens offline.")
    p.add_argument("outdir", type=Path, metavar="OUTDIR",
                   help="the --out directory of 'stiefel modes' or 'stiefel eigs'")
    p.add_argument("--output", "-o", type=Path, default=None, help=f"HTML file to write (default: OUTDIR/{VIEW_NAME})")
    p.add_argument("--title", default=None, help="page title (default: the run directory's name and the kind of run)")
    p.add_argument("--max-faces", type=_max_faces, default=DEFAULT_MAX_FACES,
                   help=f"decimate larger meshes to this many faces for display (default {DEFAULT_MAX_FACES})")
    p.add_argument("--up", type=_up, default=None, metavar="AXIS",
                   help="the vertical axis the viewer opens with: x, y, z, -x, -y, -z, or auto (principal axes)")
    p.add_argument("--quiet", action="store_true", help="no 'wrote …' line")
    return p


def run_view(args: argparse.Namespace) -> int:
    """``stiefel view``: read ``args.outdir``, write the viewer (``args.output`` or ``OUTDIR/view.html``); 0."""
    run = load_run(args.outdir)
    target = Path(args.output) if args.output is not None else Path(args.outdir) / VIEW_NAME
    if not target.parent.is_dir():
        raise ViewerError(f"directory of --output not found: {target.parent}: create it or choose another file")
    kind = "compressed manifold modes" if run["source"].name == "modes.npz" else "Laplacian eigenfunctions"
    title = args.title if args.title is not None else f"{Path(args.outdir).resolve().name}: {kind}"
    try:
        info = write_viewer(target, run["vertices"], run["faces"], run["fields"], run["names"], title=title,
                            subtitles=run["subtitles"], max_faces=args.max_faces, up=getattr(args, "up", None))
    except OSError as e:
        raise ViewerError(f"cannot write {target}: {e.strerror or e}: choose another --output") from None
    if not getattr(args, "quiet", False):
        shown = (f"decimated from {info['original_vertices']} to {info['vertices']} vertices" if info["decimated"]
                 else f"{info['vertices']} vertices")
        print(f"{PROG} view: wrote {target} ({len(run['names'])} fields, {shown}, {info['bytes']} bytes)")
    return 0
