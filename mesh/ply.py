"""A strict PLY reader (ASCII and binary, either endianness).

trimesh loads a truncated ASCII PLY as a partial mesh and fans polygons
silently, so the format is read here: the header's element counts are checked
against the body (too little data: truncated; data left over: the header
undercounts), ASCII errors name the line, binary ones the byte offset.
Fixed-size records, and list records whose lists all have the first record's
length (the usual all-triangle file), are read with one ``np.frombuffer``;
ragged binary lists fall back to a per-record loop. Returns
``readers.RawMesh`` with the ``vertex`` element's ``x, y, z`` and the ``face``
element's ``vertex_indices`` (or ``vertex_index``) lists; other elements are
skipped and counted.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from .errors import MeshFormatError
from .raw import RawMesh, decode_text
from .triangulate import Polygons

__all__ = ["read_ply"]

_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
          "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
          "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_INDEX_NAMES = ("vertex_indices", "vertex_index")


class _Element:
    def __init__(self, name: str, count: int):
        self.name, self.count = name, count
        self.props: list[tuple[str, str, str | None]] = []  # (name, type, list item type or None)

    def index_prop(self) -> int | None:
        lists = [i for i, p in enumerate(self.props) if p[2] is not None]
        named = [i for i in lists if self.props[i][0] in _INDEX_NAMES]
        return named[0] if named else (lists[0] if len(lists) == 1 else None)


def read_ply(data: bytes, path: Path) -> RawMesh:
    """Parse PLY ``data`` read from ``path``; see the module docstring."""
    if not data.startswith(b"ply"):
        raise MeshFormatError("not a valid PLY file: it does not start with 'ply'", path=path, line=1)
    end = re.search(rb"^end_header[ \t]*\r?\n", data, re.M)
    if end is None:
        raise MeshFormatError("not a valid PLY file: no 'end_header' line (truncated or garbled header)", path=path)
    header, _ = decode_text(data[: end.start()], path, "ply")
    fmt, elements = _parse_header(header, path)
    n_header_lines = header.count("\n") + 1
    if fmt == "ascii":
        text, encoding = decode_text(data[end.end():], path, "ply")
        found, face_lines = _ascii_body(text, elements, n_header_lines, path)
    else:
        endian = "<" if fmt == "binary_little_endian" else ">"
        found, encoding = _binary_body(data, end.end(), elements, endian, path), None
        face_lines = None
    V = found.get("vertex", np.zeros((0, 3)))
    faces = found.get("face", Polygons(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)))
    skipped = [e for e in elements if e.name not in ("vertex", "face") and e.count]
    return RawMesh(
        V, faces, str(path), "ply", encoding=encoding,
        face_line=(lambda f: int(face_lines[f]) if face_lines is not None and 0 <= f < len(face_lines) else None),
        ignored=sum(e.count for e in skipped),
        ignored_example=f"element {skipped[0].name!r}" if skipped else None,
    )


def _parse_header(header: str, path: Path) -> tuple[str, list[_Element]]:
    fmt, elements = None, []
    for lineno, line in enumerate(header.split("\n"), 1):
        tok = line.split()
        if not tok or tok[0] in ("ply", "comment", "obj_info"):
            continue
        try:
            if tok[0] == "format":
                fmt = tok[1]
                if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
                    raise ValueError
            elif tok[0] == "element":
                elements.append(_Element(tok[1], int(tok[2])))
                if elements[-1].count < 0:
                    raise ValueError
            elif tok[0] == "property" and tok[1] == "list":
                elements[-1].props.append((tok[4], _TYPES[tok[2]], _TYPES[tok[3]]))
            elif tok[0] == "property":
                elements[-1].props.append((tok[2], _TYPES[tok[1]], None))
            else:
                raise ValueError
        except (ValueError, IndexError, KeyError):
            raise MeshFormatError(f"malformed PLY header line {line.strip()[:60]!r}", path=path, line=lineno) from None
    if fmt is None:
        raise MeshFormatError("PLY header has no 'format' line", path=path)
    for e in elements:
        if e.name == "vertex" and not {"x", "y", "z"} <= {p[0] for p in e.props}:
            raise MeshFormatError("the 'vertex' element has no x, y, z properties", path=path)
        if e.name == "face" and e.count and e.index_prop() is None:
            raise MeshFormatError("the 'face' element has no 'vertex_indices' list", path=path)
        if e.name == "tristrips" and e.count:
            raise MeshFormatError("triangle strips ('tristrips') are not supported; convert to faces", path=path)
    return fmt, elements


def _collect(e: _Element, columns: dict[str, np.ndarray], found: dict) -> None:
    if e.name == "vertex":
        found["vertex"] = np.stack([np.asarray(columns[c], dtype=np.float64) for c in "xyz"], axis=1)
    elif e.name == "face":
        found["face"] = columns["_faces"]


def _ascii_body(text: str, elements: list[_Element], offset: int, path: Path) -> tuple[dict, np.ndarray | None]:
    lines = text.split("\n")
    rows = [i for i, ln in enumerate(lines) if ln.strip()]
    found: dict = {}
    face_lines = None
    pos = 0
    for e in elements:
        take = rows[pos : pos + e.count]
        line_no = np.asarray(take, dtype=np.int64) + offset + 1
        if len(take) < e.count:
            raise MeshFormatError(f"truncated: the header declares {e.count} {e.name!r} records, the file ends "
                                  f"after {len(take)}", path=path, line=int(offset + (rows[-1] + 1 if rows else 1)))
        pos += e.count
        if e.name not in ("vertex", "face") or not e.count:
            continue
        cols = _ascii_records([lines[i] for i in take], line_no, e, path)
        _collect(e, cols, found)
        if e.name == "face":
            face_lines = line_no
    if pos < len(rows):
        raise MeshFormatError(f"unexpected data after the last element declared in the header: "
                              f"{lines[rows[pos]].strip()[:40]!r} (does the header undercount?)",
                              path=path, line=offset + rows[pos] + 1)
    return found, face_lines


def _ascii_records(rows: list[str], line_no: np.ndarray, e: _Element, path: Path) -> dict[str, np.ndarray]:
    ip = e.index_prop() if e.name == "face" else None
    try:
        A = np.loadtxt(rows, dtype=np.float64, ndmin=2)
        k = int(A[0, ip]) if ip is not None else 0
        width = len(e.props) + k
        one_list = all(p[2] is None or i == ip for i, p in enumerate(e.props))
        if one_list and A.shape[1] == width and (ip is None or np.all(A[:, ip] == k)):
            cols, c = {}, 0
            for i, (name, _, item) in enumerate(e.props):
                if item is None:
                    cols[name], c = A[:, c], c + 1
                else:
                    idx = A[:, c + 1 : c + 1 + k].reshape(-1)
                    cols["_faces"] = _as_faces(idx, np.full(len(rows), k), line_no, path)
                    c += 1 + k
            return cols
    except ValueError:
        pass
    values: dict[str, list] = {p[0]: [] for p in e.props}
    flat, sizes = [], []
    for row, line in zip(rows, line_no):
        tok, t = row.split(), 0
        try:
            for i, (name, _, item) in enumerate(e.props):
                if item is None:
                    values[name].append(float(tok[t]))
                    t += 1
                else:
                    k = int(tok[t])
                    items = [float(x) for x in tok[t + 1 : t + 1 + k]]
                    if len(items) < k:
                        raise IndexError
                    if i == ip:
                        flat.extend(items)
                        sizes.append(k)
                    t += 1 + k
            if t != len(tok):
                raise IndexError
        except (ValueError, IndexError):
            raise MeshFormatError(f"{e.name!r} record does not match the header's properties: {row.strip()[:40]!r}",
                                  path=path, line=int(line)) from None
    cols = {k: np.asarray(v) for k, v in values.items()}
    if ip is not None:
        cols["_faces"] = _as_faces(np.asarray(flat), np.asarray(sizes), line_no, path)
    return cols


def _as_faces(flat: np.ndarray, sizes: np.ndarray, line_no: np.ndarray | None, path: Path) -> Polygons:
    if np.any(flat != np.round(flat)):
        bad = int(np.searchsorted(np.cumsum(sizes), np.argmax(flat != np.round(flat)), side="right"))
        raise MeshFormatError("face index is not an integer", path=path,
                              line=int(line_no[bad]) if line_no is not None else None)
    return Polygons(flat.astype(np.int64), sizes.astype(np.int64))


def _binary_body(data: bytes, start: int, elements: list[_Element], endian: str, path: Path) -> dict:
    found: dict = {}
    pos = start
    for e in elements:
        ip = e.index_prop() if e.name == "face" else None
        if all(p[2] is None for p in e.props):
            dt = np.dtype([(name, endian + t) for name, t, _ in e.props])
            _need(data, pos, dt.itemsize * e.count, e, path)
            rec = np.frombuffer(data, dt, e.count, pos)
            pos += dt.itemsize * e.count
            cols = {name: rec[name] for name in dt.names}
        else:
            cols, pos = _binary_lists(data, pos, e, ip, endian, path)
        _collect(e, cols, found)
    if data[pos:].strip():
        raise MeshFormatError(f"{len(data) - pos} bytes after the last element declared in the header, at offset "
                              f"{pos} (does the header undercount?)", path=path)
    return found


def _need(data: bytes, pos: int, size: int, e: _Element, path: Path) -> None:
    if pos + size > len(data):
        raise MeshFormatError(f"truncated: the {e.count} {e.name!r} records need {size} bytes from offset {pos}, "
                              f"the file has {len(data) - pos}", path=path)


def _binary_lists(data: bytes, pos: int, e: _Element, ip: int | None, endian: str, path: Path) -> tuple[dict, int]:
    """Records with list properties: one ``frombuffer`` if every list has record 0's length, else a loop."""
    fields, p = [], pos
    try:
        for i, (name, t, item) in enumerate(e.props):
            if item is None:
                fields.append((name, endian + t))
                p += np.dtype(t).itemsize
            else:
                k = int(np.frombuffer(data, endian + t, 1, p)[0]) if e.count else 0
                fields += [(f"_n{i}", endian + t), (f"_l{i}", endian + item, (k,))]
                p += np.dtype(t).itemsize + k * np.dtype(item).itemsize
    except ValueError:
        raise MeshFormatError(f"truncated: the file ends inside the first {e.name!r} record", path=path) from None
    dt = np.dtype(fields)
    if pos + dt.itemsize * e.count <= len(data):
        rec = np.frombuffer(data, dt, e.count, pos)
        counts = [(i, rec[f"_n{i}"]) for i, prop in enumerate(e.props) if prop[2] is not None]
        if all(np.all(c == dt[f"_l{i}"].shape[0]) for i, c in counts):
            cols = {name: rec[name] for name, _, item in e.props if item is None}
            if ip is not None:
                idx = rec[f"_l{ip}"]
                cols["_faces"] = _as_faces(idx.reshape(-1), np.full(e.count, idx.shape[1]), None, path)
            return cols, pos + dt.itemsize * e.count
    values: dict[str, list] = {prop[0]: [] for prop in e.props}
    flat, sizes = [], []
    try:
        for _ in range(e.count):
            for i, (name, t, item) in enumerate(e.props):
                if item is None:
                    values[name].append(np.frombuffer(data, endian + t, 1, pos)[0])
                    pos += np.dtype(t).itemsize
                else:
                    k = int(np.frombuffer(data, endian + t, 1, pos)[0])
                    pos += np.dtype(t).itemsize
                    items = np.frombuffer(data, endian + item, k, pos)
                    pos += k * np.dtype(item).itemsize
                    if i == ip:
                        flat.append(items)
                        sizes.append(k)
    except ValueError:
        raise MeshFormatError(f"truncated: the file ends inside the {e.count} {e.name!r} records (offset "
                              f"{pos} of {len(data)})", path=path) from None
    cols = {k: np.asarray(v) for k, v in values.items()}
    if ip is not None:
        cols["_faces"] = _as_faces(np.concatenate(flat) if flat else np.zeros(0), np.asarray(sizes), None, path)
    return cols, pos
