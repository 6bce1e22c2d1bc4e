"""STL and OFF scans, through trimesh."""
from __future__ import annotations

import re
import struct
import warnings as _warnings
from pathlib import Path

import numpy as np

from potflat.errors import InvalidInputError, out_of_memory
from potflat.io.raw import _check_fits_memory, _first_line, _Raw, _truncated
from potflat.types import canonical_units


def _trimesh_load(path: Path, **kwargs):
    import trimesh

    _check_fits_memory(path)  # trimesh reads the file whole
    try:
        with _warnings.catch_warnings():
            _warnings.simplefilter("ignore")
            return trimesh.load(str(path), process=False, **kwargs)
    except InvalidInputError:
        raise
    except MemoryError:
        raise out_of_memory(path) from None
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types for corrupt files
        msg = _first_line(exc)
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
        with open(path, "rb") as fh:
            head = fh.read(80).decode("latin-1")
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
