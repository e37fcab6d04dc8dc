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
atomically. Where the run's ``summary.json`` is present it is read first: the data file is the one it
lists, and one whose SHA-256 differs from the recorded one is refused; the run's status
(``run_status``: converged, not converged, interrupted, a best effort) is shown on the page and, when
it is not a converged result, on stderr. A page written into ``OUTDIR`` beside a ``summary.json`` is
added to that summary (``stiefel_cmm.cli.run_dir.RunDir.amend``, under the directory's lock), so the next
run into ``OUTDIR`` removes it with the other files of the old run. Bad input raises ``ViewerError``
(one line naming the problem and the fix). numpy, plotly and scipy are imported inside the functions:
importing this module is cheap.
"""

from __future__ import annotations

import argparse
import contextlib
import html
import io
import json
import operator
import os
import tempfile
from pathlib import Path
from typing import IO, Any, Mapping, Sequence

from .outputs import INT_MAX, PROG, bounded_int, stderr_line
from .view_run import (_SOURCES, _SUMMARY, ViewerError, _check, _read_summary, _run_directory, load_run,  # noqa: F401
                       run_status)

__all__ = ["ViewerError", "write_viewer", "decimate", "load_run", "run_status", "add_parser", "run_view",
           "DEFAULT_MAX_FACES", "VIEW_NAME"]

#: meshes with more faces are decimated to this many for display
DEFAULT_MAX_FACES = 80_000
#: the file ``stiefel view OUTDIR`` writes in OUTDIR by default
VIEW_NAME = "view.html"
_BACKGROUND = "white"
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
            note: str, camera: Mapping | None, status: str | None = None, status_ok: bool = True) -> Any:
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
    if status is not None:  # the run's status, top right: boxed in red when the result is not a converged one
        colour = "#2e7d32" if status_ok else "#b00020"
        fig.add_annotation(text=html.escape(f"run status: {status}"), showarrow=False, xref="paper", yref="paper",
                           x=0.99, y=0.99, xanchor="right", yanchor="top", align="right",
                           font={"size": 13 if status_ok else 15, "color": colour},
                           bordercolor=colour, borderwidth=0 if status_ok else 2, borderpad=4,
                           bgcolor="rgba(255,255,255,0.85)")
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
                 camera: Mapping | None = None, up: str | None = None, status: str | None = None,
                 status_ok: bool = True) -> dict:
    """Write the interactive viewer of ``fields`` on the mesh as one self-contained HTML file.

    target: a path (written atomically: temporary file, fsync, rename) or an open binary or text file.
    vertices ``(n, 3)``, faces ``(m, 3)``, fields ``(n, k)`` (or ``(n,)``), names: k labels of the menu;
    subtitles: k texts shown under the title with the field (e.g. ``"λ̃ = 0.12"``); meshes with more
    than ``max_faces`` faces are decimated for display; camera: a plotly ``scene.camera`` dict
    (e.g. ``{"eye": {"x": 0, "y": 0, "z": 2}, "up": {"x": 0, "y": 1, "z": 0}}``), default
    ``default_camera(vertices, faces, up)`` (``up``: as the contact sheet's ``--up``); status: the run's status
    (``run_status``), shown at the top right, in a red box when ``status_ok`` is false.
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
    page = _page(_figure(v2, f2, u2, limits.tolist(), names, subtitles, title, note, camera, status, status_ok),
                 title if status_ok or status is None else f"{title} [{status.split(' ')[0]}]")
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


def _max_faces(text: str) -> int:
    try:
        return bounded_int(4, INT_MAX)(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _up(text: str) -> str | None:
    from .render_views import check_up

    return check_up(text)


def _path(option: str, example: str) -> Any:
    from .options import checked, output_path

    return checked(output_path(option, example))


def add_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``view`` subcommand to an argparse subparsers object; return its parser."""
    p = sub.add_parser("view", help="interactive HTML viewer (one self-contained file) of a modes/eigs run",
                       description="Write OUTDIR/view.html: the mesh of a 'stiefel modes' (modes.npz) or "
                                   "'stiefel eigs' (eigs.npz) run coloured by a chosen mode; opens offline. "
                                   "The run's summary.json, when present, is checked (the data file's SHA-256) "
                                   "and its status shown; the page is listed in it.")
    p.add_argument("outdir", type=_path("OUTDIR", "e.g. stiefel view results (stiefel view . for the working directory)"),
                   metavar="OUTDIR",
                   help="the --out directory of 'stiefel modes' or 'stiefel eigs'")
    p.add_argument("--output", "-o", type=_path("--output", "e.g. --output view.html"), default=None,
                   help=f"HTML file to write (default: OUTDIR/{VIEW_NAME})")
    p.add_argument("--title", default=None, help="page title (default: the run directory's name and the kind of run)")
    p.add_argument("--max-faces", type=_max_faces, default=DEFAULT_MAX_FACES,
                   help=f"decimate larger meshes to this many faces for display (default {DEFAULT_MAX_FACES})")
    p.add_argument("--up", type=_up, default=None, metavar="AXIS",
                   help="the vertical axis the viewer opens with: x, y, z, -x, -y, -z, or auto (principal axes)")
    p.add_argument("--quiet", action="store_true", help="no 'wrote …' line")
    return p


def _inside(target: Path, outdir: Path) -> bool:
    """Whether ``target`` is a file directly in ``outdir`` (the same folder, however written)."""
    try:
        return target.parent.resolve() == outdir.resolve()
    except OSError:
        return False


def _encode(doc: dict) -> str:
    return json.dumps(doc, indent=2, ensure_ascii=False) + "\n"


def run_view(args: argparse.Namespace) -> int:
    """``stiefel view``: read ``args.outdir``, write the viewer (``args.output`` or ``OUTDIR/view.html``); 0.

    A run that is not a converged result (``run_status``) is labelled on the page and named on stderr."""
    outdir = _run_directory(args.outdir)
    target = Path(args.output) if args.output is not None else outdir / VIEW_NAME
    if not target.parent.is_dir():
        raise ViewerError(f"directory of --output not found: {target.parent}: create it or choose another file")
    info: dict = {}

    def write(dest: Any, run: dict) -> None:
        kind = "compressed manifold modes" if run["source"].name == "modes.npz" else "Laplacian eigenfunctions"
        title = args.title if args.title is not None else f"{outdir.resolve().name}: {kind}"
        text, ok = run["status"] if run["status"] is not None else (None, True)
        info.update(write_viewer(dest, run["vertices"], run["faces"], run["fields"], run["names"], title=title,
                                 subtitles=run["subtitles"], max_faces=args.max_faces, up=getattr(args, "up", None),
                                 status=text, status_ok=ok))

    summary = _read_summary(outdir)
    if summary is not None and _inside(target, outdir):  # listed in the run's summary, under its lock
        run = _view_into_run(outdir, summary["command"], target, write)
    else:
        run = load_run(outdir)
        try:
            write(target, run)
        except OSError as e:
            raise ViewerError(f"cannot write {target}: {e.strerror or e}: choose another --output") from None
    if run["status"] is not None and not run["status"][1]:
        stderr_line(f"{PROG} view: warning: {outdir} holds no converged result; run status: {run['status'][0]}")
    if not getattr(args, "quiet", False):
        shown = (f"decimated from {info['original_vertices']} to {info['vertices']} vertices" if info["decimated"]
                 else f"{info['vertices']} vertices")
        status = f", run status: {run['status'][0]}" if run["status"] is not None else ""
        print(f"{PROG} view: wrote {target} ({len(run['names'])} fields, {shown}, {info['bytes']} bytes{status})")
    return 0


def _view_into_run(outdir: Path, command: str, target: Path, write: Any) -> dict:
    """Read the run and write the page into its folder under the folder's lock, the page listed in its
    ``summary.json`` (``RunDir.amend``): the next run into the folder removes it with the old run's files."""
    from .run_dir import OutputError, RunDir

    if not os.access(outdir, os.W_OK | os.X_OK):
        raise ViewerError(f"cannot write in {outdir} (not writable): choose another --output")
    role = "view" if target.name == VIEW_NAME else f"view:{target.name}"
    try:
        with RunDir(outdir, command) as rd:
            run = load_run(outdir)
            rd.write(role, target.name, lambda fh: write(fh, run))
            rd.amend(_encode)
    except OutputError as e:
        raise ViewerError(str(e).replace("choose another --out", "write the page elsewhere (--output FILE)")) from None
    return run
