"""Wavefront OBJ: scans in (potflat's own reader: a Numba tokenizer over ranges of lines,
materials' ``map_Kd`` textures through the MTL files) and the flat textured OBJ out
(``NAME.flat.obj`` + ``NAME.mtl`` referring to a texture image)."""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from potflat._jit import worker_threads
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.io._kernels.obj import (
    OBJ_CORNERS,
    OBJ_FACES,
    OBJ_MTLLIB,
    OBJ_TEXCOORDS,
    OBJ_USEMTL,
    OBJ_VERTICES,
    obj_count,
    obj_fill,
)
from potflat.io.atomic import atomic_path, write_bytes_atomic
from potflat.io.raw import (
    _IGNORE_HINT,
    _colors_to_u8,
    _find_file,
    _flag_untextured,
    _merge_textures,
    _Raw,
    _read_bytes,
    _text,
    _triangulate,
)

#: Bytes of an OBJ file per thread at least: smaller files are parsed in one range.
OBJ_RANGE_BYTES = 4 << 20
#: Largest material library (MTL) read: text of a few lines per material.
MTL_MAX_BYTES = 16 << 20


def parse_obj(buf: np.ndarray, ranges: int | None = None) -> tuple:
    """Parse an OBJ file's bytes: ranges of whole lines side by side in threads (the serial
    kernels :func:`potflat.mesh._kernels.obj_count` and ``obj_fill`` release the GIL), each
    range counted, then filled at its rows; the result does not depend on the ranges.

    Parameters
    ----------
    buf : (nbytes,) uint8
        The file's content (after a byte-order mark).
    ranges : int, optional
        How many ranges; default one per Numba thread (``--threads``), at most one per
        :data:`OBJ_RANGE_BYTES`.

    Returns
    -------
    V : (nv, 6) float64
    vcols : (nv,) int64
    VT : (nvt, 2) float64
    corner_v, corner_vt : (nc,) int64
    face_ptr : (nf + 1,) int64
    use_spans : (nuse, 3) int64
    lib_spans : (nlib, 2) int64
    bad_line : int
        As :func:`potflat.mesh._kernels.obj_fill` describes them, for the whole file.
    """
    from concurrent.futures import ThreadPoolExecutor

    n = len(buf)
    if ranges is None:
        ranges = min(worker_threads(), 1 + n // OBJ_RANGE_BYTES)
    ranges = max(1, min(int(ranges), n))
    cuts = [0]
    for k in range(1, ranges):  # each range ends after a newline (a file of one line: one range)
        cut = _line_start(buf, max(n * k // ranges, cuts[-1]))
        if cut < n:
            cuts.append(cut)
    cuts = sorted(set(cuts + [n]))
    spans = list(zip(cuts[:-1], cuts[1:])) or [(0, 0)]
    with ThreadPoolExecutor(len(spans), thread_name_prefix="potflat-obj") as pool:
        counts = list(pool.map(lambda span: obj_count(buf, *span), spans))
        before = np.cumsum([np.zeros(7, np.int64)] + counts, axis=0)
        total = before[-1]
        V = np.full((total[OBJ_VERTICES], 6), np.nan)
        vcols = np.zeros(total[OBJ_VERTICES], np.int64)
        VT = np.zeros((total[OBJ_TEXCOORDS], 2))
        corner_v = np.empty(total[OBJ_CORNERS], np.int64)
        corner_vt = np.empty(total[OBJ_CORNERS], np.int64)
        face_ptr = np.zeros(total[OBJ_FACES] + 1, np.int64)
        use_spans = np.zeros((total[OBJ_USEMTL], 3), np.int64)
        lib_spans = np.zeros((total[OBJ_MTLLIB], 2), np.int64)
        bad = list(pool.map(lambda k: obj_fill(buf, *spans[k], before[k], V, vcols, VT, corner_v, corner_vt,
                                               face_ptr, use_spans, lib_spans), range(len(spans))))
    bad_line = next((b for b in bad if b), 0)  # the ranges in file order: the first bad line
    return V, vcols, VT, corner_v, corner_vt, face_ptr, use_spans, lib_spans, bad_line


def _line_start(buf: np.ndarray, pos: int) -> int:
    """Index of the first byte after the first newline at or after ``pos`` (``len(buf)`` if none)."""
    window = 1 << 12
    while pos < len(buf):
        hit = np.flatnonzero(buf[pos:pos + window] == 10)
        if len(hit):
            return pos + int(hit[0]) + 1
        pos += window
        window *= 2
    return len(buf)


def _read_obj(path: Path, texture: str, max_pixels: int) -> _Raw:
    data = _read_bytes(path)
    buf = np.frombuffer(data, dtype=np.uint8, offset=3 if data.startswith(b"\xef\xbb\xbf") else 0)  # BOM
    V6, vcols, VT, cv, cvt, face_ptr, use_spans, lib_spans, bad_line = parse_obj(buf)
    names = [_text(buf[s:e].tobytes()) for s, e, _ in use_spans]
    libs = [_text(buf[s:e].tobytes()) for s, e in lib_spans]
    del buf, data  # the file's bytes are the largest array here
    if bad_line:
        raise InvalidInputError(f"{path} line {bad_line}: not a number; repair the file or export it again")
    if len(V6) and vcols.min() < 3:
        line = int(np.argmax(vcols < 3)) + 1
        raise InvalidInputError(f"{path}: vertex {line} has fewer than 3 coordinates; export the scan again")
    raw = _Raw(vertices=np.ascontiguousarray(V6[:, :3]), faces=np.zeros((0, 3), np.int64))
    if len(V6) and vcols.min() >= 6:
        raw.colors = _colors_to_u8(V6[:, 3:6])
    nv = len(V6)
    del V6
    lengths = np.diff(face_ptr)
    corners, poly, n_poly, n_short = _triangulate(lengths)
    raw.polygons_triangulated = n_poly
    if n_short:
        raw.warnings.append(f"{n_short} faces with fewer than 3 corners were ignored")
    nvt = len(VT)
    bad = (cv < 0) | (cv >= nv)
    if bad.any():
        idx = int(np.flatnonzero(bad)[0])
        fno = int(np.searchsorted(face_ptr, idx, side="right"))
        raise InvalidInputError(f"{path}: face {fno} points at a vertex that does not exist (the file "
                                f"has {nv} vertices); the file is corrupt or cut short: export it again")
    raw.faces = cv[corners]
    del cv
    if texture == "ignore":
        return raw
    if nvt == 0:
        if (cvt >= 0).any():  # f v/vt ... naming coordinates the file lacks
            raise InvalidInputError(f"{path}: its faces name texture coordinates (f v/vt) but the file has no 'vt' "
                                    "lines, so the painting cannot be placed (an export cut short?); export the "
                                    f"scan again with texture coordinates, {_IGNORE_HINT} (a grey relief)")
        return raw
    badt = (cvt < -1) | (cvt >= nvt)
    if badt.any():
        raise InvalidInputError(f"{path}: faces point at texture coordinates that do not exist (the file "
                                f"has {nvt}); export it again {_IGNORE_HINT}")
    tri_vt = cvt[corners]
    del cvt
    has_vt = (tri_vt >= 0).all(axis=1)
    if not has_vt.any():
        return raw

    # materials: which texture each triangle uses
    textures = _obj_material_textures(path, libs)
    if len(names):
        mat_of_poly = np.searchsorted(use_spans[:, 2], np.arange(len(lengths)), side="right") - 1
        tex_of_name = [textures.get(nm) for nm in names]
        tex_ids = {t: k for k, t in enumerate(dict.fromkeys(t for t in tex_of_name if t is not None))}
        code = np.array([tex_ids[t] if t is not None else -1 for t in tex_of_name] + [-1], np.int64)
        tri_tex = code[mat_of_poly][poly]  # -1 index -> the trailing -1
    elif len(set(textures.values())) == 1:  # no usemtl, a single textured material
        tex_ids, tri_tex = {next(iter(textures.values())): 0}, np.zeros(len(poly), np.int64)
    else:
        tex_ids, tri_tex = {}, np.full(len(poly), -1, np.int64)
    used = np.unique(tri_tex[has_vt & (tri_tex >= 0)])
    inv = {k: t for t, k in tex_ids.items()}
    if len(used) > 1:
        ok = has_vt & (tri_tex >= 0)
        uv = np.zeros((len(poly), 3, 2))
        uv[ok] = np.take(VT, tri_vt[ok], axis=0)
        which = np.searchsorted(used, tri_tex)
        raw.texture, raw.texcoords, note = _merge_textures([inv[int(k)] for k in used], np.where(ok, which, -1),
                                                           uv, path, max_pixels)
        raw.warnings.append(note)
        _flag_untextured(raw, ~ok, "have no texture coordinates or no textured material")
        return raw
    if len(used) == 0:
        if lib_spans.shape[0] == 0:
            raw.warnings.append("texture coordinates but no material library (mtllib); loaded untextured")
        else:
            raw.warnings.append("no material with a texture image (map_Kd); loaded untextured")
        return raw
    raw.texture = inv[int(used[0])]
    ok = has_vt & (tri_tex == used[0])
    if ok.all():
        uv = np.take(VT, tri_vt, axis=0)  # (NumPy's take gathers rows 3-5x faster than indexing)
    else:
        uv = np.zeros((len(poly), 3, 2))
        uv[ok] = np.take(VT, tri_vt[ok], axis=0)
        _flag_untextured(raw, ~ok, "have no texture coordinates or another material")
    raw.texcoords = uv
    return raw


_MAP_OPTION_ARGS = {"-blendu": 1, "-blendv": 1, "-cc": 1, "-clamp": 1, "-texres": 1, "-imfchan": 1,
                    "-bm": 1, "-boost": 1, "-mm": 2, "-o": 3, "-s": 3, "-t": 3, "-type": 1}


def _map_kd_file(args: str) -> str:
    """The file name of a ``map_Kd`` statement, skipping its options."""
    toks = args.split()
    i = 0
    while i < len(toks) and toks[i].lower() in _MAP_OPTION_ARGS:
        k = _MAP_OPTION_ARGS[toks[i].lower()]
        i += 1
        for _ in range(k):  # -o/-s/-t take 1 to 3 numbers
            if i < len(toks) - 1 and re.fullmatch(r"[-+]?[\d.eE+-]+|on|off", toks[i]):
                i += 1
    return " ".join(toks[i:])


def _material_libraries(obj: Path, libs: list[str], *, strict: bool = True) -> list[Path]:
    """The MTL files the OBJ's ``mtllib`` statements name (one statement may name several,
    separated by spaces); a missing one raises (``strict``) or is left out."""
    out = []
    for lib in libs:
        mtl = _find_file(lib, obj.parent)
        if not mtl.is_file() and " " in lib:
            parts = [_find_file(p, obj.parent) for p in lib.split()]
            if all(p.is_file() for p in parts):
                out += parts
                continue
        if mtl.is_file():
            out.append(mtl)
        elif strict:
            raise InvalidInputError(f"{obj}: material library {lib} not found; restore it beside the "
                                    f"OBJ {_IGNORE_HINT}")
    return out


#: An OBJ's ``mtllib`` statement (a line of its own), as :func:`parse_obj` finds it.
_MTLLIB_LINE = re.compile(rb"^[ \t]*mtllib[ \t]+([^\r\n]*)", re.MULTILINE)


def _obj_inputs(path: Path, *, block: int = 8 << 20) -> list[Path]:
    """The files loading the OBJ at ``path`` reads besides it: its material libraries and their
    texture images (those that exist). The OBJ is read in blocks of ``block`` bytes."""
    libs, carry, skipping = [], b"", False
    with open(path, "rb") as fh:
        while data := fh.read(block):
            if skipping:  # inside a line longer than a block: no mtllib statement
                newline = data.find(b"\n")
                if newline < 0:
                    continue
                data, skipping = data[newline + 1:], False
            data = carry + data
            cut = data.rfind(b"\n") + 1
            libs += [_text(m.group(1)).strip() for m in _MTLLIB_LINE.finditer(data, 0, cut)]
            carry = data[cut:]
            if len(carry) > block:
                carry, skipping = b"", True
    if not skipping:
        libs += [_text(m.group(1)).strip() for m in _MTLLIB_LINE.finditer(carry)]
    mtls = _material_libraries(path, [lib for lib in libs if lib], strict=False)
    textures = _obj_material_textures(path, [str(m) for m in mtls])
    return list(dict.fromkeys([*mtls, *(t for t in textures.values() if t.is_file())]))


def _obj_material_textures(obj: Path, libs: list[str]) -> dict[str, Path]:
    """Material name -> texture path (``map_Kd``) from the OBJ's material libraries."""
    out: dict[str, Path] = {}
    for mtl in _material_libraries(obj, libs):
        current = None
        for line in _text(_read_bytes(mtl, "a material library", MTL_MAX_BYTES)).splitlines():
            parts = line.strip().split(None, 1)
            if not parts:
                continue
            key = parts[0].lower()
            if key == "newmtl":
                current = parts[1].strip() if len(parts) > 1 else ""
            elif key == "map_kd" and current is not None and len(parts) > 1:
                name = _map_kd_file(parts[1])
                if name:
                    out[current] = _find_file(name, mtl.parent, obj.parent)
    return out


#: Rows formatted per write (bounds the text held in memory).
ROWS_PER_WRITE = 200_000


def _format_rows(fh, fmt: str, rows: np.ndarray) -> None:
    for i in range(0, len(rows), ROWS_PER_WRITE):
        part = rows[i:i + ROWS_PER_WRITE]
        fh.write((fmt * len(part)) % tuple(part.ravel().tolist()))


def write_textured_obj(path: str | os.PathLike, vertices: np.ndarray, faces: np.ndarray, texcoords: np.ndarray,
                       corner_texcoords: np.ndarray, texture_name: str, *, header: str = "",
                       material: str = "painted", vertex_format: str = "%.9g") -> Path:
    """Write a textured mesh as ``path`` (``.obj``) and the MTL beside it (same stem).

    Parameters
    ----------
    path : path-like
        Output ``.obj`` path.
    vertices : (n, 3) float64
        Positions, written with ``vertex_format`` (default 9 significant digits).
    faces : (m, 3) int64
        0-based vertex indices, counter-clockwise seen from outside.
    texcoords : (t, 2) float64
        The ``vt`` table (OBJ convention: ``(0, 0)`` bottom left of the image, ``v`` up).
    corner_texcoords : (m, 3) int64
        0-based ``vt`` index of every face corner.
    texture_name : str
        The texture image's file name, relative to the MTL (``map_Kd``).
    header : str
        Comment line(s) written at the top of the OBJ (units, provenance).
    material : str
        Material name.
    vertex_format : str
        printf format of one coordinate.

    Returns
    -------
    Path
        The OBJ path.
    """

    path = Path(path)
    if path.suffix.lower() != ".obj":
        raise InvalidOptionError(f"{path} does not end in .obj; give an .obj output path")
    faces = np.asarray(faces, np.int64)
    corner_texcoords = np.asarray(corner_texcoords, np.int64)
    if corner_texcoords.shape != faces.shape:
        raise InvalidOptionError("corner_texcoords must have one index per face corner")
    mtl = path.with_suffix(".mtl")
    write_bytes_atomic(mtl, (f"# {header.splitlines()[0] if header else 'potflat'}\n"
                             f"newmtl {material}\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\n"
                             f"map_Kd {texture_name}\n").encode())
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
            for line in header.splitlines():
                fh.write(f"# {line}\n")
            fh.write(f"mtllib {mtl.name}\nusemtl {material}\n")
            _format_rows(fh, "v " + " ".join([vertex_format] * 3) + "\n", np.asarray(vertices, np.float64))
            _format_rows(fh, "vt %.7f %.7f\n", np.asarray(texcoords, np.float64))
            _format_rows(fh, "f %d/%d %d/%d %d/%d\n", np.stack([faces + 1, corner_texcoords + 1], axis=2).reshape(-1, 6))
            fh.flush()
            os.fsync(fh.fileno())
    return path
