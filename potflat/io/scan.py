"""Loading scans: OBJ (+MTL texture), PLY, STL, OFF, GLB/glTF -> a clean :class:`Mesh`.

:func:`load_scan` reads a scan, welds vertices split at texture seams (geometry by position,
texture coordinates kept per face corner), checks the texture image (header only, with a
decompression-bomb limit), validates everything a user can get wrong with one-line
:class:`~potflat.errors.InvalidInputError` messages, and cleans the mesh with
:func:`potflat.mesh.cleaning.clean_mesh`.

OBJ and PLY are read by potflat's own parsers (OBJ by a Numba tokenizer: trimesh's OBJ
loader splits vertices at seams and is slow on multi-million-vertex scans); STL, OFF and
GLB/glTF go through trimesh.

Several texture images (OBJ materials with different ``map_Kd``, PLY ``texnumber``, glTF
materials with different base-colour textures) are packed into one atlas image (a PNG in a
temporary folder private to the process, removed at its end) with the texture coordinates
remapped, since a :class:`Mesh` has one texture.

Units: positions are never rescaled. ``units=None`` takes the unit the file declares (a PLY
``comment units X``, an STL ``UNITS=`` header, glTF's metres) and millimetres otherwise.
"""
from __future__ import annotations

import errno
import math
import os
import stat
import zipfile
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.io.gltf import _gltf_inputs, _read_gltf
from potflat.io.obj import _obj_inputs, _read_obj
from potflat.io.ply import _ply_inputs, _read_ply
from potflat.io.raw import _IGNORE_HINT, _check_fits_memory, _check_texture, _Raw
from potflat.io.stl_off import _read_trimesh
from potflat.mesh.cleaning import (
    CleaningReport,
    check_cleaning_options,
    clean_mesh,
    weld_vertices,
)
from potflat.mesh.distortion import bounds
from potflat.types import UNITS_MM, Mesh, canonical_units

#: File extensions :func:`load_scan` reads.
SCAN_EXTENSIONS = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf")
#: Largest coordinate accepted: squares and products of coordinates (areas, distances, moments)
#: must stay far from the float64 limit (1.8e308). 1e50 is beyond any length unit's scan.
MAX_COORDINATE = 1e50
#: Default limit on texture size in pixels (a 32k x 32k atlas).
MAX_TEXTURE_PIXELS = 32768 * 32768
_TEXTURE_MODES = ("use", "ignore")
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


#: Size range (mm, the longest side of the bounding box) of a vessel or sherd; outside it, the
#: unit the scan was read in is taken for a unit mistake.
PLAUSIBLE_SIZE_MM = (10.0, 2000.0)
#: The units tried for a scan of implausible size.
PLAUSIBLE_UNITS = ("mm", "m", "cm", "in", "um")
#: When several units give a plausible size, the one giving the size nearest this (mm, on a
#: log scale: a vessel of a hand's span to a storage jar) is named first.
TYPICAL_SIZE_MM = 250.0


def check_plausible_size(loaded: LoadedScan, path: str | os.PathLike) -> None:
    """Refuse a scan whose size is implausible in the unit it was read in: a 45 cm vase in
    millimetres read as metres would be 450 m tall, in metres read as millimetres 0.45 mm.
    A unit the file declares is checked too (glTF is metres by definition, but exporters
    also write millimetres), and so is a given one (a millimetre OBJ given ``--units m``).

    Raises
    ------
    InvalidInputError
        Naming the size, the unit it most likely is and the option that says so
        (``looks like millimetres: add --units mm``); when several units fit, the one giving
        the size nearest :data:`TYPICAL_SIZE_MM` first, then the size each would give.
    """
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
    fits = sorted((u for u in PLAUSIBLE_UNITS if u != mesh.units and lo <= side * UNITS_MM[u] <= hi),
                  key=lambda u: abs(math.log(side * UNITS_MM[u] / TYPICAL_SIZE_MM)))
    what = "small" if size_mm < lo else "large"
    hint = f"give its unit with --units ({', '.join(UNITS_MM)})"
    if fits:
        hint = f"it looks like {names[fits[0]]}: add --units {fits[0]}"
        if len(fits) > 1:  # the size each would give, for the user who knows the vessel
            hint += (f" ({side * UNITS_MM[fits[0]]:.0f} mm across; "
                     + ", ".join(f"--units {u}: {side * UNITS_MM[u]:.0f} mm" for u in fits[1:]) + ")")
    read = {"given": "as given", "file": "as the file declares", "default": "the default"}[loaded.units_from]
    escape = f", or --units {mesh.units} if the size is right" if loaded.units_from == "default" else ""
    raise InvalidInputError(f"{path} is {side:.4g} units across: in {names[mesh.units]} ({read}) a vessel too {what} "
                            f"to be real ({lo:g} to {hi:g} mm); {hint}{escape}")


def load_scan(path: str | os.PathLike, *, units: str | None = None, clean: bool = True,
              texture: str = "use", min_component_fraction: float = 0.01,
              weld_tolerance: float = 0.0, split_nonmanifold: bool = True,
              max_texture_pixels: int = MAX_TEXTURE_PIXELS, min_faces: int = 4,
              outward: bool = True) -> LoadedScan:
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
    outward : bool
        Turn the faces to face out of the body the scan encloses with its holes capped;
        False: keep them facing as most of them do in the file (the face of a dish or bowl
        scanned alone; :func:`potflat.mesh.cleaning.clean_mesh`).

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
                                  split_nonmanifold=split_nonmanifold, min_faces=min_faces, outward=outward)
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


def scan_inputs(path: str | os.PathLike) -> tuple[Path, ...]:
    """The files :func:`load_scan` reads besides the scan itself, found from the scan alone:
    an OBJ's material libraries and their textures, a PLY's texture, a glTF's buffers and
    images named by URI. Those that do not exist are left out (loading says so).

    Parameters
    ----------
    path : path-like
        A scan file (checked by :func:`check_scan_file`).

    Returns
    -------
    tuple of Path
        Absolute paths, in the order the scan names them.
    """
    path = Path(path)
    finder = {".obj": _obj_inputs, ".ply": _ply_inputs, ".gltf": _gltf_inputs, ".glb": _gltf_inputs}.get(
        path.suffix.lower())
    return tuple(p.resolve() for p in finder(path)) if finder is not None else ()


def check_scan_file(path: str | os.PathLike) -> Path:
    """The absolute path of a scan file that exists, is a regular non-empty file with a scan
    extension; else an :class:`InvalidInputError` naming the file and the fix.

    A directory named ``x.obj``, a device (``/dev/zero``), a FIFO, a symlink loop or a file
    too large to be read in the memory potflat may use (every format is read whole) is
    refused here, before anything reads it (the files it names included) or any output is
    written.
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
        packed = _packed(path)
        if packed:
            raise InvalidInputError(f"{path} {packed}")
        raise InvalidInputError(f"{path} has an unknown extension {ext or '(none)'!r}; "
                                f"potflat reads {' '.join(SCAN_EXTENSIONS)}: convert the scan")
    if st.st_size == 0:
        raise InvalidInputError(f"{path} is empty (0 bytes); export or copy the scan again")
    _check_fits_memory(path)
    return path


def _packed(path: Path) -> str | None:
    """What to say of ``path`` when it is an archive or compressed (a museum portal's download:
    a zip of the scan, its material and textures), from its own bytes; None otherwise."""
    extensions = " ".join(SCAN_EXTENSIONS)
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError:
        return None
    if head[:2] == b"\x1f\x8b":
        return f"is gzip-compressed; decompress it (gunzip) and give the scan (potflat reads {extensions})"
    if head != b"PK\x03\x04":
        return None
    try:
        with zipfile.ZipFile(path) as archive:
            scans = [name for name in archive.namelist() if Path(name).suffix.lower() in SCAN_EXTENSIONS]
    except (zipfile.BadZipFile, OSError):
        return "is a damaged zip archive; download or pack the scan again"
    if not scans:
        return f"is a zip archive without a scan in it ({extensions}); give the scan file itself"
    named = ", ".join(scans[:3]) + (f" and {len(scans) - 3} more" if len(scans) > 3 else "")
    return f"is a zip archive holding {named}; unzip it and give the scan inside (its textures stay beside it)"


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


# ---------------------------------------------------------------------------------------
# OBJ


# ---------------------------------------------------------------------------------------
# PLY


# ---------------------------------------------------------------------------------------
# STL, OFF (trimesh) and GLB/glTF


