"""Loading scans: OBJ (+MTL texture), PLY, STL, OFF, GLB/glTF -> a clean :class:`Mesh`.

:func:`load_scan` reads a scan, welds vertices split at texture seams (geometry by position,
texture coordinates kept per face corner), checks the texture image (header only, with a
decompression-bomb limit), validates everything a user can get wrong with one-line
:class:`~potflat.errors.InvalidInputError` messages, and cleans the mesh with
:func:`potflat.mesh.cleaning.clean_mesh`.

OBJ and PLY are read by potflat's own parsers (OBJ by a Numba tokenizer: trimesh's OBJ
loader splits vertices at seams and is slow on multi-million-vertex scans); STL, OFF and
GLB/glTF go through trimesh.

Several texture images (OBJ materials with different ``map_Kd``, PLY ``texnumber``) are
packed into one atlas image (a PNG in a temporary folder private to the process, removed at its
end) with the texture coordinates remapped, since a :class:`Mesh` has one texture.

Units: positions are never rescaled. ``units=None`` takes the unit the file declares (a PLY
``comment units X``, an STL ``UNITS=`` header, glTF's metres) and millimetres otherwise.
"""
from __future__ import annotations

import base64
import errno
import hashlib
import json
import os
import re
import stat
import struct
import tempfile
import warnings as _warnings
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from potflat.mesh.cleaning import (
    CleaningReport,
    check_cleaning_options,
    clean_mesh,
    weld_vertices,
)
from potflat.mesh.distortion import bounds
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.types import UNITS_MM, Mesh, canonical_units

#: File extensions :func:`load_scan` reads.
SCAN_EXTENSIONS = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
#: Largest coordinate accepted: squares and products of coordinates (areas, distances, moments)
#: must stay far from the float64 limit (1.8e308). 1e50 is beyond any length unit's scan.
MAX_COORDINATE = 1e50
#: Default limit on texture size in pixels (a 32k x 32k atlas).
MAX_TEXTURE_PIXELS = 32768 * 32768
_TEXTURE_MODES = ("use", "ignore")
_IGNORE_HINT = "or pass texture='ignore' (CLI --no-texture) to load it untextured"
#: How far past the image (in image widths) a moved face may reach before it counts as
#: crossing into the next copy of a repeating texture (exporters round coordinates).
TILE_SLACK = 1e-6


@dataclass(frozen=True)
class LoadedScan:
    """A scan as loaded and cleaned.

    Attributes
    ----------
    mesh : Mesh
        Welded, cleaned triangle mesh in the scan's own units.
    report : CleaningReport
        What loading and cleaning did (``report.as_dict()`` for JSON).
    units_from : str
        Where ``mesh.units`` came from: ``"given"`` (the ``units`` argument), ``"file"`` (the
        file declares it) or ``"default"`` (millimetres, nothing said: see
        :func:`check_plausible_size`).
    """

    mesh: Mesh
    report: CleaningReport
    units_from: str = "default"


#: Size range (mm, the longest side of the bounding box) of a vessel or sherd scanned in
#: millimetres; outside it, a scan with no declared unit is taken for a unit mistake.
PLAUSIBLE_SIZE_MM = (10.0, 2000.0)


def check_plausible_size(loaded: LoadedScan, path: str | os.PathLike) -> None:
    """Refuse a scan whose size is implausible in the unit it was read in, unless that unit was
    given or declared by the file: a 45 cm vase in metres would be read as 0.45 mm.

    Raises
    ------
    InvalidInputError
        Naming the size, the unit it most likely is and the option that says so
        (``looks like metres: add --units m``).
    """
    if loaded.units_from != "default":
        return
    mesh = loaded.mesh
    side = 0.0
    if len(mesh.vertices):
        low, high = bounds(mesh.vertices)
        side = float((high - low).max())
    lo, hi = PLAUSIBLE_SIZE_MM
    size_mm = side * mesh.mm_per_unit
    if lo <= size_mm <= hi:
        return
    names = {"m": "metres", "cm": "centimetres", "um": "micrometres", "in": "inches", "mm": "millimetres"}
    candidates = ("m", "cm", "in") if size_mm < lo else ("um",)
    likely = next((u for u in candidates if lo <= side * UNITS_MM[u] <= hi), None)
    what = "small" if size_mm < lo else "large"
    hint = (f"it looks like {names[likely]}: add --units {likely}" if likely
            else f"give its unit with --units ({', '.join(UNITS_MM)})")
    raise InvalidInputError(f"{path} is {side:.4g} units across: in {names[mesh.units]} a vessel too {what} to be real "
                            f"({lo:g} to {hi:g} mm); {hint}, or --units {mesh.units} if the size is right")


@dataclass
class _Raw:
    """What a format reader found (before validation and welding)."""

    vertices: np.ndarray
    faces: np.ndarray
    texcoords: np.ndarray | None = None
    untextured: np.ndarray | None = None  # (m,) bool: faces without texture coordinates
    texture: Path | None = None
    colors: np.ndarray | None = None
    units: str | None = None
    polygons_triangulated: int = 0
    warnings: list[str] = field(default_factory=list)


def load_scan(path: str | os.PathLike, *, units: str | None = None, clean: bool = True,
              texture: str = "use", min_component_fraction: float = 0.01,
              weld_tolerance: float = 0.0, split_nonmanifold: bool = True,
              max_texture_pixels: int = MAX_TEXTURE_PIXELS, min_faces: int = 4) -> LoadedScan:
    """Read a scan file, weld it, check its texture and clean it.

    Parameters
    ----------
    path : path-like
        ``.obj`` (with ``.mtl`` and ``map_Kd`` texture), ``.ply`` (ascii or binary; per-face
        ``texcoord`` with ``comment TextureFile``, per-vertex ``texture_u/texture_v`` or
        ``s/t``, or vertex colours), ``.stl``, ``.off``, ``.glb`` or ``.gltf``.
    units : str or None
        Length unit of the file's coordinates (``mm``, ``cm``, ``m``, ``um``, ``in``).
        ``None``: the unit the file declares, else ``mm``. Coordinates are never rescaled;
        the unit is recorded in ``Mesh.units``.
    clean : bool
        Run :func:`potflat.mesh.cleaning.clean_mesh`; if False only exact welding and checks run.
    texture : {"use", "ignore"}
        ``"use"``: a declared texture must exist and be a readable image of sane size
        (else an error); several images are packed into one atlas; ``"ignore"``: load
        geometry (and vertex colours) only.
    min_component_fraction : float
        Remove components with less area than this fraction of the largest (stray fragments).
    weld_tolerance : float
        Weld positions closer than this fraction of the bounding-box diagonal (0: exact).
    split_nonmanifold : bool
        Split non-manifold vertices and edges into separate fans.
    max_texture_pixels : int
        Largest texture accepted (width x height, read from the header; the image is not
        decoded here).
    min_faces : int
        Fewer faces than this (after cleaning) is an error.

    Returns
    -------
    LoadedScan
        ``mesh`` (``texture_path`` absolute) and ``report``.

    Raises
    ------
    InvalidInputError
        Missing, empty, truncated or corrupt file; unknown extension; faces pointing at
        missing vertices; NaN or infinite coordinates; too few or only degenerate faces;
        missing, corrupt or oversized texture.
    InvalidOptionError
        An option out of range.
    """
    if units is not None:
        if canonical_units(units) is None:
            raise InvalidOptionError(f"unknown units {units!r}; use one of {', '.join(UNITS_MM)}")
        units = canonical_units(units)
    if texture not in _TEXTURE_MODES:
        raise InvalidOptionError(f"texture must be one of {', '.join(_TEXTURE_MODES)}, got {texture!r}")
    if not (isinstance(max_texture_pixels, (int, np.integer)) and max_texture_pixels > 0):
        raise InvalidOptionError(f"max_texture_pixels must be a positive integer, got {max_texture_pixels!r}")
    if not (isinstance(min_faces, (int, np.integer)) and min_faces >= 1):
        raise InvalidOptionError(f"min_faces must be a positive integer, got {min_faces!r}")
    check_cleaning_options(weld_tolerance=weld_tolerance, min_component_fraction=min_component_fraction)

    path = check_scan_file(path)
    ext = path.suffix.lower()
    reader = {".obj": _read_obj, ".ply": _read_ply, ".stl": _read_trimesh, ".off": _read_trimesh,
              ".glb": _read_gltf, ".gltf": _read_gltf}[ext]
    raw = reader(path, texture, max_texture_pixels)
    mesh = _validate(raw, path, units, texture, max_texture_pixels)
    if clean:
        mesh, report = clean_mesh(mesh, weld_tolerance=weld_tolerance,
                                  min_component_fraction=min_component_fraction,
                                  split_nonmanifold=split_nonmanifold, min_faces=min_faces)
    else:
        n0, m0 = len(mesh.vertices), len(mesh.faces)
        mesh, merged = weld_vertices(mesh, tolerance=weld_tolerance)
        if len(mesh.faces) < min_faces:
            raise InvalidInputError(f"{path}: only {len(mesh.faces)} faces (at least {min_faces} "
                                    "needed); give the whole scan")
        report = CleaningReport(input_vertices=n0, input_faces=m0, duplicate_vertices_merged=merged,
                                output_vertices=len(mesh.vertices), output_faces=len(mesh.faces),
                                cleaned=False)
    report = replace(report, polygons_triangulated=raw.polygons_triangulated,
                     warnings=tuple(raw.warnings) + report.warnings)
    return LoadedScan(mesh=mesh, report=report,
                      units_from="given" if units is not None else "file" if raw.units else "default")


# ---------------------------------------------------------------------------------------
# shared steps


def check_scan_file(path: str | os.PathLike) -> Path:
    """The absolute path of a scan file that exists, is a regular non-empty file with a scan
    extension; else an :class:`InvalidInputError` naming the file and the fix.

    A directory named ``x.obj``, a device (``/dev/zero``), a FIFO or a symlink loop is refused
    here, before anything reads it or any output is written.
    """
    path = Path(path).expanduser()
    ext = path.suffix.lower()
    try:
        st = path.stat()
        path = path.resolve(strict=True)
    except RuntimeError:  # symlink loop (Python < 3.13)
        raise InvalidInputError(f"{path} is a symbolic link loop; give the scan file itself") from None
    except OSError as exc:
        if isinstance(exc, FileNotFoundError):
            raise InvalidInputError(f"{path} does not exist; check the path") from None
        if exc.errno == errno.ELOOP:
            raise InvalidInputError(f"{path} is a symbolic link loop; give the scan file itself") from None
        raise InvalidInputError(f"cannot read {path}: {exc.strerror or exc}; check the path and permissions") from None
    if stat.S_ISDIR(st.st_mode):
        raise InvalidInputError(f"{path} is a directory; give a scan file ({' '.join(SCAN_EXTENSIONS)})")
    if not stat.S_ISREG(st.st_mode):
        raise InvalidInputError(f"{path} is not a regular file (a device or pipe); give a scan file")
    if ext not in SCAN_EXTENSIONS:
        raise InvalidInputError(f"{path} has an unknown extension {ext or '(none)'!r}; "
                                f"potflat reads {' '.join(SCAN_EXTENSIONS)}: convert the scan")
    if st.st_size == 0:
        raise InvalidInputError(f"{path} is empty (0 bytes); export or copy the scan again")
    return path


def _validate(raw: _Raw, path: Path, units: str | None, texture: str, max_pixels: int) -> Mesh:
    V = np.asarray(raw.vertices, dtype=np.float64)
    F = np.asarray(raw.faces, dtype=np.int64)
    if len(F) == 0 or len(V) == 0:
        raise InvalidInputError(f"{path} contains no faces (a point cloud or an empty export?); "
                                "give a triangle mesh")
    if F.min() < 0 or F.max() >= len(V):
        bad = int(F.max()) if F.max() >= len(V) else int(F.min())
        raise InvalidInputError(f"{path}: faces point at missing vertices (index {bad}, the file has "
                                f"{len(V)} vertices); the file is corrupt: export it again")
    finite = np.isfinite(V).all(axis=1)
    if not finite.all():
        raise InvalidInputError(f"{path}: {int((~finite).sum())} vertices have NaN or infinite "
                                "coordinates; repair the scan (e.g. MeshLab) or export it again")
    largest = float(np.abs(V).max(initial=0.0))
    if largest > MAX_COORDINATE:
        raise InvalidInputError(f"{path}: coordinates as large as {largest:.3g} overflow the computations (areas, "
                                f"distances; at most {MAX_COORDINATE:g}); the file is corrupt or not in a length "
                                "unit: export it again")
    tc, tex = raw.texcoords, raw.texture
    if texture == "ignore":
        tc, tex = None, None
    if tc is not None and tex is None:
        raw.warnings.append("texture coordinates without a texture image were ignored")
        tc = None
    if tc is not None and not np.isfinite(tc).all():
        raise InvalidInputError(f"{path}: texture coordinates contain NaN or infinite values; "
                                f"export the scan again {_IGNORE_HINT}")
    if tex is not None and tc is None:
        raw.warnings.append(f"texture {tex.name} declared but no texture coordinates; loaded untextured")
        tex = None
    if tex is not None:
        tex = _check_texture(tex, path, max_pixels)[0]
        tc = _into_the_tile(tc, raw.warnings)
    declared = raw.units
    if units is None:
        units = declared or "mm"
    elif declared is not None and declared != units:
        raw.warnings.append(f"the file declares units {declared!r} but units={units!r} was given; using {units!r}")
    colors = raw.colors
    return Mesh(V, F, texcoords=tc, texture_path=tex, vertex_colors=colors, units=units, source=path,
                untextured_faces=raw.untextured if tc is not None else None)


def _into_the_tile(texcoords: np.ndarray, warnings: list[str]) -> np.ndarray:
    """Texture coordinates (m, 3, 2) of a repeating texture moved into its one tile.

    Coordinates past [0, 1] mean that the image repeats (as renderers read them). Each face
    whose centre lies in another copy of the image is moved by whole images into the first,
    where the sampler reads it (else it would read the image's border: a painting lost). A
    face across the border of two copies still reads the border texels there (a warning says
    how many). Faces already in the image are untouched.
    """
    if texcoords.min() >= 0.0 and texcoords.max() <= 1.0:  # (the common case: two passes, no per-face mean)
        return texcoords
    centre = texcoords.mean(axis=1)
    shift = np.where((centre >= 0.0) & (centre <= 1.0), 0.0, np.floor(centre))  # (a centre at 1 is in the image)
    moved = (shift != 0.0).any(axis=1)
    if not moved.any():
        return texcoords
    texcoords = texcoords - shift[:, None, :]
    across = int(((texcoords < -TILE_SLACK) | (texcoords > 1.0 + TILE_SLACK)).any(axis=(1, 2)).sum())
    warnings.append(f"texture coordinates past [0, 1] (a repeating texture): {int(moved.sum())} faces were moved "
                    "into the image" + (f"; {across} faces cross its border and read the border texels there"
                                        if across else ""))
    return texcoords


def _check_texture(tex: Path, source: Path, max_pixels: int) -> tuple[Path, tuple[int, int]]:
    """Check that ``tex`` is a readable image within ``max_pixels`` (header only); return
    its absolute path and its (width, height)."""
    from PIL import Image

    from potflat.io.images import check_texture_budget

    try:
        tex = tex.resolve()
    except RuntimeError:  # a symlink loop (Python < 3.13 raises it here)
        raise InvalidInputError(f"{source}: texture {tex} is a symbolic link loop; restore the file "
                                f"{_IGNORE_HINT}") from None
    if not tex.is_file():
        raise InvalidInputError(f"{source}: texture {tex} not found; restore the file {_IGNORE_HINT}")
    old = Image.MAX_IMAGE_PIXELS
    try:
        Image.MAX_IMAGE_PIXELS = None  # our own limit below, without Pillow's lower default
        with _warnings.catch_warnings():
            _warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            with Image.open(tex) as im:
                w, h = im.size
                if w <= 0 or h <= 0 or w * h > max_pixels:
                    raise InvalidInputError(
                        f"{source}: texture {tex.name} declares {w} x {h} pixels, over the limit of "
                        f"{max_pixels} (a corrupt file or decompression bomb); restore a sane image, "
                        f"raise max_texture_pixels if it is genuine, {_IGNORE_HINT}")
                try:
                    check_texture_budget(tex, w, h, im.mode)
                except InvalidInputError as exc:
                    raise InvalidInputError(f"{source}: {exc}, {_IGNORE_HINT}") from None
                if im.format == "PNG":
                    im.verify()  # chunk CRCs, without decoding pixels
    except InvalidInputError:
        raise
    except Exception as exc:  # noqa: BLE001 - Pillow raises many types for corrupt images
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InvalidInputError(f"{source}: texture {tex.name} is not a readable image ({msg}); "
                                f"restore the file {_IGNORE_HINT}") from None
    finally:
        Image.MAX_IMAGE_PIXELS = old
    return tex, (w, h)


_PRIVATE_CACHE: list[Path] = []


def _texture_cache() -> Path:
    """Folder for generated textures (packed atlases, images extracted from GLB): private to this
    process (made by :func:`tempfile.mkdtemp`: new, mode 0700, never a pre-existing folder or a
    planted symlink), removed when the process ends. Nothing found there is ever trusted: every
    file in it was written by this process."""
    if not _PRIVATE_CACHE or not _PRIVATE_CACHE[0].is_dir():
        import atexit
        import shutil

        folder = Path(tempfile.mkdtemp(prefix="potflat-textures-"))
        atexit.register(shutil.rmtree, folder, ignore_errors=True)
        _PRIVATE_CACHE[:] = [folder]
    return _PRIVATE_CACHE[0]


def _merge_textures(paths: list[Path], which: np.ndarray, uv: np.ndarray, source: Path,
                    max_pixels: int) -> tuple[Path, np.ndarray, str]:
    """Pack several texture images into one atlas (a grid) and remap the texture coordinates.

    Parameters
    ----------
    paths : list of Path
        The images, in the order of the indices in ``which``.
    which : (m,) int64
        Image of each face, -1 for none (those keep their coordinates).
    uv : (m, 3, 2) float64
        Texture coordinates in each face's own image (OBJ convention, v up).

    Returns
    -------
    atlas : Path
        PNG in :func:`_texture_cache`, named by the sources' paths, sizes
        and modification times (made once per process).
    uv : (m, 3, 2) float64
        Coordinates in the atlas (clipped to each image: tiling cannot be packed).
    note : str
        Report line.
    """
    from PIL import Image

    from potflat.io.atomic import atomic_path

    checked = [_check_texture(p, source, max_pixels) for p in paths]
    paths = [p for p, _ in checked]
    sizes = [size for _, size in checked]
    cols = int(np.ceil(np.sqrt(len(paths))))
    rows = int(np.ceil(len(paths) / cols))
    cw, ch = max(w for w, _ in sizes), max(h for _, h in sizes)
    W, H = cols * cw, rows * ch
    if W * H > max_pixels:
        raise InvalidInputError(f"{source}: its {len(paths)} texture images would make a {W} x {H} atlas, over "
                                f"max_texture_pixels={max_pixels}; re-export with one texture {_IGNORE_HINT}")
    key = json.dumps([[str(p), p.stat().st_size, p.stat().st_mtime_ns] for p in paths]).encode()
    target = _texture_cache() / (hashlib.sha256(key).hexdigest()[:32] + ".png")
    if not target.exists():
        old = Image.MAX_IMAGE_PIXELS
        try:
            Image.MAX_IMAGE_PIXELS = None  # sizes were checked against max_pixels above
            modes = []
            for p in paths:
                with Image.open(p) as im:
                    modes.append(im.mode)
            mode = "RGBA" if any("A" in m for m in modes) else "RGB"
            atlas = Image.new(mode, (W, H))
            for k, p in enumerate(paths):
                r, c = divmod(k, cols)
                with Image.open(p) as im:
                    atlas.paste(im.convert(mode), (c * cw, r * ch))
            with atomic_path(target) as tmp:
                atlas.save(tmp, format="PNG", compress_level=1)
        except InvalidInputError:
            raise
        except Exception as exc:  # noqa: BLE001 - Pillow raises many types for corrupt images
            msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise InvalidInputError(f"{source}: its texture images cannot be decoded ({msg}); restore them "
                                    f"{_IGNORE_HINT}") from None
        finally:
            Image.MAX_IMAGE_PIXELS = old
    out = uv.copy()
    sel = which >= 0
    k = which[sel]
    r, c = np.divmod(k, cols)
    w = np.array([s[0] for s in sizes], float)[k]
    h = np.array([s[1] for s in sizes], float)[k]
    t = np.clip(uv[sel], 0.0, 1.0)
    clipped = int(np.count_nonzero((t != uv[sel]).any(axis=(1, 2))))
    out[sel, :, 0] = (c[:, None] * cw + t[..., 0] * w[:, None]) / W
    out[sel, :, 1] = 1.0 - (r[:, None] * ch + (1.0 - t[..., 1]) * h[:, None]) / H
    note = (f"{len(paths)} texture images ({', '.join(p.name for p in paths[:4])}"
            f"{', ...' if len(paths) > 4 else ''}) packed into one {W} x {H} atlas {target}")
    if clipped:
        note += f"; {clipped} faces had texture coordinates outside their image (clipped)"
    return target, out, note


def _triangulate(lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Fan-triangulate polygons given their corner counts.

    Returns the corner indices (t, 3) into the flat corner arrays, the polygon of each
    triangle, the number of polygons with more than three corners and of those with fewer
    than three (dropped).
    """
    lengths = np.asarray(lengths, dtype=np.int64)
    if (lengths == 3).all():
        m = len(lengths)
        return np.arange(3 * m).reshape(m, 3), np.arange(m), 0, 0
    start = np.concatenate([[0], np.cumsum(lengths)[:-1]]).astype(np.int64)
    ntri = np.maximum(lengths - 2, 0)
    poly = np.repeat(np.arange(len(lengths)), ntri)
    first = np.cumsum(ntri) - ntri
    j = np.arange(len(poly)) - np.repeat(first, ntri) + 1
    c0 = start[poly]
    corners = np.stack([c0, c0 + j, c0 + j + 1], axis=1)
    return corners, poly, int(np.count_nonzero(lengths > 3)), int(np.count_nonzero(lengths < 3))


def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise InvalidInputError(f"cannot read {path}: {exc.strerror or exc}; check permissions") from None


def _text(data: bytes) -> str:
    """Names and lines written by other programs: UTF-8, else Latin-1 (older Windows exports)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def _colors_to_u8(cols: np.ndarray) -> np.ndarray:
    cols = np.asarray(cols, dtype=np.float64)
    if np.issubdtype(cols.dtype, np.floating) and np.nanmax(cols, initial=0.0) <= 1.0:
        cols = cols * 255.0
    return np.clip(np.nan_to_num(np.rint(cols)), 0, 255).astype(np.uint8)


def _find_file(name: str, *dirs: Path) -> Path:
    """Resolve a file name written by another program: relative to ``dirs[0]``, absolute,
    Windows-style (backslashes, another machine's folders: the base name is looked up in
    ``dirs``), or differing in letter case (exports made on Windows)."""
    name = name.strip().strip('"')
    cand = Path(name.replace("\\", "/"))
    tried = [cand if cand.is_absolute() else dirs[0] / cand]
    tried += [d / cand.name for d in dirs]
    for p in tried:
        if p.is_file():
            return p
    for d in dirs:
        try:
            match = sorted(p for p in d.iterdir() if p.name.lower() == cand.name.lower() and p.is_file())
        except OSError:
            continue
        if match:
            return match[0]
    return tried[0]


# ---------------------------------------------------------------------------------------
# OBJ


#: Bytes of an OBJ file per thread at least: smaller files are parsed in one range.
OBJ_RANGE_BYTES = 4 << 20


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

    from potflat._jit import worker_threads
    from potflat.mesh._kernels import OBJ_CORNERS, OBJ_FACES, OBJ_MTLLIB, OBJ_TEXCOORDS, OBJ_USEMTL, \
        OBJ_VERTICES, obj_count, obj_fill

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


def _flag_untextured(raw: _Raw, untextured: np.ndarray, why: str) -> None:
    """Record the faces ``untextured`` ((m,) bool) of a textured scan that have no texture
    coordinates (their coordinates are zeros that mean nothing), with the load warning."""
    count = int(untextured.sum())
    if count:
        raw.untextured = untextured
        raw.warnings.append(f"{count} faces {why}; they are drawn as untextured surface (a shaded relief) "
                            "and left out of the painted-zone detection")


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


def _obj_material_textures(obj: Path, libs: list[str]) -> dict[str, Path]:
    """Material name -> texture path (``map_Kd``) from the OBJ's material libraries."""
    out: dict[str, Path] = {}
    for lib in libs:
        mtl = _find_file(lib, obj.parent)
        if not mtl.is_file() and " " in lib:
            parts = [_find_file(p, obj.parent) for p in lib.split()]
            if all(p.is_file() for p in parts):
                for p in parts:
                    out.update(_obj_material_textures(obj, [str(p)]))
                continue
        if not mtl.is_file():
            raise InvalidInputError(f"{obj}: material library {lib} not found; restore it beside the "
                                    f"OBJ {_IGNORE_HINT}")
        current = None
        for line in _text(_read_bytes(mtl)).splitlines():
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


# ---------------------------------------------------------------------------------------
# PLY

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


def _truncated(path: Path, element: str) -> InvalidInputError:
    return InvalidInputError(f"{path} is truncated ({element} data incomplete); "
                             "the file is cut short: copy or export it again")


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
    names = [c.split(None, 1)[1].strip() for c in comments
             if c.split(None, 1)[0:1] == ["TextureFile"] and len(c.split(None, 1)) > 1]

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


# ---------------------------------------------------------------------------------------
# STL, OFF (trimesh) and GLB/glTF


def _trimesh_load(path: Path, **kwargs):
    import trimesh

    try:
        with _warnings.catch_warnings():
            _warnings.simplefilter("ignore")
            return trimesh.load(str(path), process=False, **kwargs)
    except InvalidInputError:
        raise
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types for corrupt files
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InvalidInputError(f"{path} cannot be read as {path.suffix[1:].upper()} ({msg[:120]}); "
                                "export the scan again") from None


def _read_trimesh(path: Path, texture: str, max_pixels: int) -> _Raw:
    import trimesh

    if path.suffix.lower() == ".stl":
        _check_stl_size(path)
    tm = _trimesh_load(path, force="mesh")
    if not isinstance(tm, trimesh.Trimesh):
        raise InvalidInputError(f"{path} contains no faces; give a triangle mesh")
    raw = _Raw(vertices=np.asarray(tm.vertices, np.float64), faces=np.asarray(tm.faces, np.int64))
    vc = getattr(tm.visual, "vertex_colors", None) if tm.visual.kind == "vertex" else None
    if vc is not None and len(vc) == len(raw.vertices):
        raw.colors = np.asarray(vc, np.uint8)
    if path.suffix.lower() == ".stl":
        head = _read_bytes(path)[:80].decode("latin-1")
        m = re.search(r"UNITS\s*=\s*([A-Za-z]+)", head)
        if m and canonical_units(m.group(1)):
            raw.units = canonical_units(m.group(1))
    return raw


def _check_stl_size(path: Path) -> None:
    """A binary STL's size must match its triangle count (trimesh may not notice)."""
    with open(path, "rb") as fh:
        head = fh.read(1024)
    size = path.stat().st_size
    if head[:5].lower() == b"solid" and b"facet" in head:
        return  # ascii STL
    if len(head) < 84:
        raise _truncated(path, "header")
    (count,) = struct.unpack("<I", head[80:84])
    if size < 84 + 50 * count:
        raise _truncated(path, "triangle")


def _read_gltf(path: Path, texture: str, max_pixels: int) -> _Raw:
    import trimesh

    scene = _trimesh_load(path, force="scene")
    try:  # trimesh decodes embedded images lazily, here
        geoms = [g for g in (scene.dump() if isinstance(scene, trimesh.Scene) else [scene])
                 if isinstance(g, trimesh.Trimesh) and len(g.faces)]
        kinds = [g.visual.kind for g in geoms]
    except Exception as exc:  # noqa: BLE001 - corrupt embedded data: many exception types
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InvalidInputError(f"{path} cannot be read as {path.suffix[1:].upper()} ({msg[:120]}); "
                                "export the scan again") from None
    if not geoms:
        raise InvalidInputError(f"{path} contains no triangle meshes; export the scan as a mesh")
    verts, faces, uvs, offset = [], [], [], 0
    for g, kind in zip(geoms, kinds):
        if np.asarray(g.faces).min() < 0 or np.asarray(g.faces).max() >= len(g.vertices):
            raise InvalidInputError(f"{path}: faces point at missing vertices; the file is corrupt: export it again")
        verts.append(np.asarray(g.vertices, np.float64))
        faces.append(np.asarray(g.faces, np.int64) + offset)
        uv = getattr(g.visual, "uv", None) if kind == "texture" else None
        uvs.append(None if uv is None or len(uv) != len(g.vertices) else np.asarray(uv, np.float64)[g.faces])
        offset += len(g.vertices)
    raw = _Raw(vertices=np.concatenate(verts), faces=np.concatenate(faces), units="m")
    if all(kind == "vertex" for kind in kinds):
        raw.colors = np.concatenate([np.asarray(g.visual.vertex_colors, np.uint8) for g in geoms])
    if texture == "ignore" or all(u is None for u in uvs):
        return raw
    images = _gltf_images(path)
    if len(images) > 1:
        raise InvalidInputError(f"{path} holds {len(images)} texture images; potflat supports one texture "
                                f"atlas: re-export with a single texture {_IGNORE_HINT}")
    if not images:
        raw.warnings.append("texture coordinates but no texture image; loaded untextured")
        return raw
    raw.texcoords = np.concatenate([u if u is not None else np.zeros((len(f), 3, 2)) for u, f in zip(uvs, faces)])
    _flag_untextured(raw, np.concatenate([np.full(len(f), u is None) for u, f in zip(uvs, faces)]),
                     "(meshes without TEXCOORD_0) have no texture coordinates")
    raw.texture = images[0]
    return raw


def _gltf_images(path: Path) -> list[Path]:
    """Base-colour texture images of a glTF/GLB as files: external ones as they are, embedded ones
    extracted (content-addressed, atomically) into the private :func:`_texture_cache`."""
    try:
        return _gltf_image_files(path)
    except (KeyError, IndexError, TypeError, ValueError, AttributeError, struct.error):
        raise InvalidInputError(f"{path}: its texture images cannot be read (broken glTF structure); "
                                f"export the scan again {_IGNORE_HINT}") from None


def _gltf_image_files(path: Path) -> list[Path]:
    from potflat.io.atomic import write_bytes_atomic

    data = _read_bytes(path)
    bin_chunk = b""
    if data[:4] == b"glTF":
        try:
            (jlen,) = struct.unpack_from("<I", data, 12)
            doc = json.loads(data[20:20 + jlen])
            if len(data) > 28 + jlen:
                (blen,) = struct.unpack_from("<I", data, 20 + jlen)
                bin_chunk = data[28 + jlen:28 + jlen + blen]
        except (struct.error, ValueError):
            raise InvalidInputError(f"{path} is not a valid GLB file; export the scan again") from None
        if not isinstance(doc, dict):
            raise InvalidInputError(f"{path} is not a valid GLB file; export the scan again")
    else:
        try:
            doc = json.loads(data)
        except ValueError:
            raise InvalidInputError(f"{path} is not valid glTF JSON; export the scan again") from None
        if not isinstance(doc, dict):
            raise InvalidInputError(f"{path} is not valid glTF JSON; export the scan again")
    images = doc.get("images", [])
    textures = doc.get("textures", [])
    base = set()  # images used as base colour (not normal or roughness maps)
    for mat in doc.get("materials", []):
        for ref in ((mat.get("pbrMetallicRoughness") or {}).get("baseColorTexture"),
                    ((mat.get("extensions") or {}).get("KHR_materials_pbrSpecularGlossiness") or {})
                    .get("diffuseTexture")):
            if ref and 0 <= ref.get("index", -1) < len(textures) and "source" in textures[ref["index"]]:
                base.add(textures[ref["index"]]["source"])
    out = []
    for k, img in enumerate(images):
        if k not in base:
            continue
        uri = img.get("uri")
        blob = None
        if uri is not None and not uri.startswith("data:"):
            out.append(_find_file(uri, path.parent))
            continue
        if uri is not None:
            blob = base64.b64decode(uri.split(",", 1)[1])
        elif "bufferView" in img:
            bv = doc["bufferViews"][img["bufferView"]]
            start = bv.get("byteOffset", 0)
            blob = bin_chunk[start:start + bv["byteLength"]]
        if blob:
            ext = {"image/png": ".png", "image/jpeg": ".jpg"}.get(img.get("mimeType", ""), ".png")
            target = _texture_cache() / (hashlib.sha256(blob).hexdigest()[:32] + ext)
            if not target.exists():  # the private cache holds only what this process wrote
                write_bytes_atomic(target, blob)
            out.append(target)
    return out
