"""PLY scans: potflat's own reader (ASCII and binary, texture coordinates per face corner or
vertex, vertex colours, MeshLab's ``TextureFile`` comments)."""
from __future__ import annotations

import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from potflat.errors import InvalidInputError
from potflat.io.raw import (
    _IGNORE_HINT,
    _colors_to_u8,
    _find_file,
    _flag_untextured,
    _merge_textures,
    _Raw,
    _read_bytes,
    _triangulate,
    _truncated,
)
from potflat.types import canonical_units

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


@dataclass
class _PlyElement:
    name: str
    count: int
    props: list  # (name, type) or (name, count_type, item_type) for lists
    data: dict = field(default_factory=dict)  # name -> array, or (lengths, flat) for lists


def _ply_header(data: bytes, path: Path):
    if not data.startswith(b"ply"):
        raise InvalidInputError(f"{path} is not a PLY file (no 'ply' header); export the scan again")
    end = data.find(b"end_header")
    if end < 0:
        raise InvalidInputError(f"{path} has an incomplete PLY header (no end_header); the file is cut short: copy it again")
    nl = data.find(b"\n", end)
    body_start = len(data) if nl < 0 else nl + 1
    fmt, comments, elements = None, [], []
    try:  # names (TextureFile) in UTF-8, or Latin-1 from older tools
        text = data[:end].decode("utf-8")
    except UnicodeDecodeError:
        text = data[:end].decode("latin-1")
    for line in text.splitlines():
        parts = line.split()
        if not parts:
            continue
        try:
            if parts[0] == "format":
                fmt = parts[1]
            elif parts[0] in ("comment", "obj_info"):
                comments.append(line.split(None, 1)[1] if len(parts) > 1 else "")
            elif parts[0] == "element":
                elements.append(_PlyElement(parts[1], int(parts[2]), []))
            elif parts[0] == "property":
                if parts[1] == "list":
                    elements[-1].props.append((parts[4], _PLY_TYPES[parts[2]], _PLY_TYPES[parts[3]]))
                else:
                    elements[-1].props.append((parts[2], _PLY_TYPES[parts[1]]))
        except (IndexError, KeyError, ValueError):
            raise InvalidInputError(f"{path}: malformed PLY header line {line.strip()!r}; export the scan again") from None
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise InvalidInputError(f"{path}: unknown PLY format {fmt!r}; export as ascii or binary PLY")
    if any(e.count < 0 for e in elements):
        raise InvalidInputError(f"{path}: negative element count in the PLY header; export the scan again")
    return fmt, comments, elements, body_start


def _ply_list_bytes(k: int, item_bytes: int, left: int, path: Path, element: str) -> int:
    """Bytes of a PLY list of ``k`` items; a negative length or one beyond the ``left`` bytes of
    the file is an error (a hostile or corrupt header cannot make potflat allocate it)."""
    if k < 0:
        raise InvalidInputError(f"{path}: a {element} list has a negative length ({k}); the file is corrupt: "
                                "export it again")
    if k * item_bytes > left:
        raise _truncated(path, element)
    return k * item_bytes


def _ply_binary(body: memoryview, elements: list[_PlyElement], endian: str, path: Path) -> None:
    offset = 0
    for el in elements:
        lists = [p for p in el.props if len(p) == 3]
        if not lists:
            dt = np.dtype([(p[0], endian + p[1]) for p in el.props])
            need = dt.itemsize * el.count
            if offset + need > len(body):
                raise _truncated(path, el.name)
            arr = np.frombuffer(body, dtype=dt, count=el.count, offset=offset)
            el.data = {p[0]: arr[p[0]] for p in el.props}
            offset += need
            continue
        if el.count == 0:
            el.data = {p[0]: (np.zeros(0, np.int64), np.zeros(0)) if len(p) == 3 else np.zeros(0)
                       for p in el.props}
            continue
        # try a fixed list length (all triangles, say), read from the first row
        fields, pos = [], offset
        try:
            for p in el.props:
                if len(p) == 3:
                    cdt = np.dtype(endian + p[1])
                    k = int(np.frombuffer(body, cdt, 1, pos)[0])
                    pos += cdt.itemsize + _ply_list_bytes(k, np.dtype(p[2]).itemsize, len(body) - pos, path, el.name)
                    fields += [(p[0] + "#n", cdt), (p[0], endian + p[2], (k,))]
                else:
                    fields.append((p[0], endian + p[1]))
                    pos += np.dtype(p[1]).itemsize
        except InvalidInputError:
            raise
        except ValueError:
            raise _truncated(path, el.name) from None
        dt = np.dtype(fields)
        need = dt.itemsize * el.count
        if offset + need <= len(body):
            arr = np.frombuffer(body, dtype=dt, count=el.count, offset=offset)
            if all((arr[p[0] + "#n"] == arr.dtype[p[0]].shape[0]).all() for p in lists):
                el.data = {p[0]: arr[p[0]] if len(p) == 2 else
                           (np.full(el.count, arr.dtype[p[0]].shape[0], np.int64), arr[p[0]].reshape(-1))
                           for p in el.props}
                offset += need
                continue
        offset = _ply_binary_rows(body, offset, el, endian, path)


def _ply_binary_rows(body: memoryview, offset: int, el: _PlyElement, endian: str, path: Path) -> int:
    """Row-by-row reading of an element with variable-length lists (slow path)."""
    bo = "<" if endian == "<" else ">"
    codes = {"i1": "b", "u1": "B", "i2": "h", "u2": "H", "i4": "i", "u4": "I", "f4": "f", "f8": "d"}
    cols: dict[str, list] = {p[0]: [] for p in el.props}
    lens: dict[str, list] = {p[0]: [] for p in el.props if len(p) == 3}
    try:
        for _ in range(el.count):
            for p in el.props:
                if len(p) == 3:
                    (k,) = struct.unpack_from(bo + codes[p[1]], body, offset)
                    offset += struct.calcsize(codes[p[1]])
                    _ply_list_bytes(k, struct.calcsize(codes[p[2]]), len(body) - offset, path, el.name)
                    cols[p[0]].extend(struct.unpack_from(f"{bo}{k}{codes[p[2]]}", body, offset))
                    offset += k * struct.calcsize(codes[p[2]])
                    lens[p[0]].append(k)
                else:
                    cols[p[0]].append(struct.unpack_from(bo + codes[p[1]], body, offset)[0])
                    offset += struct.calcsize(codes[p[1]])
    except struct.error:
        raise _truncated(path, el.name) from None
    el.data = {p[0]: (np.array(lens[p[0]], np.int64), np.array(cols[p[0]])) if len(p) == 3
               else np.array(cols[p[0]]) for p in el.props}
    return offset


def _ply_ascii(body: bytes, elements: list[_PlyElement], path: Path) -> None:
    try:
        tok = np.array(body.split(), dtype=np.float64) if body.strip() else np.zeros(0)
    except ValueError:
        raise InvalidInputError(f"{path}: the ascii PLY data contains something that is not a number; "
                                "export the scan again") from None
    pos = 0
    for el in elements:
        lists = [p for p in el.props if len(p) == 3]
        if el.count == 0:
            el.data = {p[0]: (np.zeros(0, np.int64), np.zeros(0)) if len(p) == 3 else np.zeros(0)
                       for p in el.props}
            continue
        # width of the first row, then check that every row has it
        widths, w, ok = [], 0, True
        for p in el.props:
            if len(p) == 3:
                if pos + w >= len(tok):
                    raise _truncated(path, el.name)
                k = int(tok[pos + w])
                _ply_list_bytes(k, 1, len(tok) - pos - w - 1, path, el.name)
                widths.append((p[0], w, k))
                w += 1 + k
            else:
                widths.append((p[0], w, None))
                w += 1
        if pos + w * el.count > len(tok) and not lists:
            raise _truncated(path, el.name)
        if pos + w * el.count <= len(tok):
            block = tok[pos:pos + w * el.count].reshape(el.count, w)
            ok = all((block[:, c] == k).all() for _, c, k in widths if k is not None)
        else:
            ok = False
        if ok:
            el.data = {name: block[:, c] if k is None else
                       (np.full(el.count, k, np.int64), block[:, c + 1:c + 1 + k].reshape(-1))
                       for name, c, k in widths}
            pos += w * el.count
            continue
        cols: dict[str, list] = {p[0]: [] for p in el.props}
        lens: dict[str, list] = {p[0]: [] for p in lists}
        for _ in range(el.count):
            for p in el.props:
                if pos >= len(tok):
                    raise _truncated(path, el.name)
                if len(p) == 3:
                    k = int(tok[pos])
                    _ply_list_bytes(k, 1, len(tok) - pos - 1, path, el.name)
                    cols[p[0]].append(tok[pos + 1:pos + 1 + k])
                    lens[p[0]].append(k)
                    pos += 1 + k
                else:
                    cols[p[0]].append(tok[pos])
                    pos += 1
        el.data = {p[0]: (np.array(lens[p[0]], np.int64), np.concatenate(cols[p[0]]) if cols[p[0]] else np.zeros(0))
                   if len(p) == 3 else np.array(cols[p[0]]) for p in el.props}


def _texture_names(comments: list[str]) -> list[str]:
    """The texture images a PLY header names (MeshLab's ``comment TextureFile NAME``)."""
    return [c.split(None, 1)[1].strip() for c in comments
            if c.split(None, 1)[0:1] == ["TextureFile"] and len(c.split(None, 1)) > 1]


#: Bytes of a PLY read for its header alone (:func:`_ply_inputs`).
PLY_HEADER_BYTES = 1 << 20


def _ply_inputs(path: Path) -> list[Path]:
    """The files loading the PLY at ``path`` reads besides it: the texture images its header
    names (those that exist); only the header is read."""
    with open(path, "rb") as fh:
        head = fh.read(PLY_HEADER_BYTES)
    try:
        comments = _ply_header(head, path)[1]
    except InvalidInputError:  # no header in the first megabyte: the load says what is wrong
        return []
    return [p for p in (_find_file(name, path.parent) for name in _texture_names(comments)) if p.is_file()]


def _read_ply(path: Path, texture: str, max_pixels: int) -> _Raw:
    data = _read_bytes(path)
    fmt, comments, elements, body_start = _ply_header(data, path)
    if fmt == "ascii":
        _ply_ascii(data[body_start:], elements, path)
    else:
        _ply_binary(memoryview(data)[body_start:], elements, "<" if fmt == "binary_little_endian" else ">", path)
    by_name = {e.name: e for e in elements}
    vert, face = by_name.get("vertex"), by_name.get("face")
    if vert is not None:  # list properties of vertices are never coordinates, colours or uv
        vert.data = {k: v for k, v in vert.data.items() if isinstance(v, np.ndarray)}
    if vert is None or not {"x", "y", "z"} <= set(vert.data):
        raise InvalidInputError(f"{path} has no vertex x y z; export the scan as a mesh")
    V = np.stack([vert.data[c] for c in "xyz"], axis=1).astype(np.float64)
    key = None if face is None else next((k for k in ("vertex_indices", "vertex_index") if k in face.data), None)
    if key is None or isinstance(face.data[key], np.ndarray):
        raise InvalidInputError(f"{path} has no faces (a point cloud?); potflat needs a triangle mesh: mesh it "
                                "first (e.g. surface reconstruction in MeshLab)")
    lengths, flat = face.data[key]
    corners, poly, n_poly, n_short = _triangulate(lengths)
    flat = np.asarray(flat)
    if flat.size and (not np.isfinite(flat).all() or (flat != np.round(flat)).any()):
        raise InvalidInputError(f"{path}: face indices are not integers; export the scan again")
    raw = _Raw(vertices=V, faces=flat.astype(np.int64)[corners], polygons_triangulated=n_poly)
    if n_short:
        raw.warnings.append(f"{n_short} faces with fewer than 3 corners were ignored")

    for c in comments:
        parts = c.split()
        if len(parts) >= 2 and parts[0] == "units" and canonical_units(parts[1]):
            raw.units = canonical_units(parts[1])
    names = _texture_names(comments)

    colors = [k for k in (("red", "green", "blue"), ("r", "g", "b"),
                          ("diffuse_red", "diffuse_green", "diffuse_blue")) if set(k) <= set(vert.data)]
    if colors:
        rgb = np.stack([vert.data[c] for c in colors[0]], axis=1)
        alpha_key = {"red": "alpha", "r": "a", "diffuse_red": "diffuse_alpha"}[colors[0][0]]
        cols = np.concatenate([rgb, vert.data[alpha_key][:, None]], axis=1) if alpha_key in vert.data else rgb
        is_float = any(vert.props[[p[0] for p in vert.props].index(c)][1].startswith("f") for c in colors[0])
        raw.colors = _colors_to_u8(cols) if is_float else np.clip(cols, 0, 255).astype(np.uint8)

    if texture == "ignore" or not names:
        return raw
    tc = None
    if "texcoord" in face.data and not isinstance(face.data["texcoord"], np.ndarray):
        tl, tflat = face.data["texcoord"]
        if not np.array_equal(tl, 2 * lengths):
            raise InvalidInputError(f"{path}: face texcoord lists do not have 2 numbers per corner; "
                                    f"export the scan again {_IGNORE_HINT}")
        tc = np.asarray(tflat, np.float64).reshape(-1, 2)[corners]
    else:
        uvk = next((k for k in (("texture_u", "texture_v"), ("s", "t"), ("texture_s", "texture_t"), ("u", "v"))
                    if set(k) <= set(vert.data)), None)
        if uvk is not None:
            uv = np.stack([vert.data[k] for k in uvk], axis=1).astype(np.float64)
            tc = uv[np.clip(raw.faces, 0, len(uv) - 1)]
    if tc is None:
        return raw
    tn = face.data.get("texnumber")
    which = np.asarray(tn, np.int64)[poly] if isinstance(tn, np.ndarray) else None
    untextured = which < 0 if which is not None else np.zeros(len(poly), bool)  # texnumber -1: no texture
    if untextured.all():
        raw.warnings.append("every face has texnumber -1 (no texture); loaded untextured")
        return raw
    if untextured.any():
        tc = np.where(untextured[:, None, None], 0.0, tc)  # (their coordinates mean nothing)
    if len(names) > 1:
        if which is None:
            raise InvalidInputError(f"{path} names {len(names)} texture images but its faces do not say which "
                                    f"(no texnumber); re-export with a single texture {_IGNORE_HINT}")
        if which.min() < -1 or which.max() >= len(names):
            raise InvalidInputError(f"{path}: face texnumber out of range (the file names {len(names)} "
                                    f"textures); export it again {_IGNORE_HINT}")
        used = np.unique(which[~untextured])
        if len(used) > 1:
            raw.texture, raw.texcoords, note = _merge_textures(
                [_find_file(names[k], path.parent) for k in used],
                np.where(untextured, -1, np.searchsorted(used, which)), tc, path, max_pixels)
            raw.warnings.append(note)
            _flag_untextured(raw, untextured, "have texnumber -1 (no texture)")
            return raw
        names = [names[int(used[0])]]
    raw.texture = _find_file(names[0], path.parent)
    raw.texcoords = tc
    _flag_untextured(raw, untextured, "have texnumber -1 (no texture)")
    return raw
