"""Textured Wavefront OBJ output: ``NAME.obj`` + ``NAME.mtl`` referring to a texture image.

One ``v`` per vertex, one ``vt`` per texture coordinate, faces ``f v/vt v/vt v/vt``
(1-based, counter-clockwise seen from outside), one material whose ``map_Kd`` is the texture
beside the files: the form MeshLab, Blender and trimesh read. Both files are written
atomically, the OBJ last.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from potflat.errors import InvalidOptionError

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
    from potflat.io.atomic import atomic_path, write_bytes_atomic

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
