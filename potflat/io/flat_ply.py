"""Stage files: ``NAME.rollout.ply`` / ``NAME.relaxed.ply`` and their JSON sidecars.

The PLY is binary little-endian with vertex properties ``x y z u v`` (double), optional
``red green blue alpha`` (uchar), ``stress`` and ``importance`` (double, 0 plain to 1
painted: :attr:`potflat.types.FlatMesh.importance`); faces carry
``vertex_indices`` (uchar count, int indices) and optionally ``texcoord`` (uchar count,
6 floats: MeshLab's convention), with ``comment TextureFile NAME`` naming the texture
image relative to the PLY. ``comment units mm`` records the length unit. See
``docs/formats.md``.
"""
from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

from potflat.mesh.distortion import row_blocks
from potflat.errors import InvalidInputError
from potflat.io.atomic import atomic_path
from potflat.types import UNITS_MM, FlatMesh, Mesh

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "<i2", "int16": "<i2", "ushort": "<u2", "uint16": "<u2",
    "int": "<i4", "int32": "<i4", "uint": "<u4", "uint32": "<u4",
    "float": "<f4", "float32": "<f4", "double": "<f8", "float64": "<f8",
}


def _texture_target(texture: Path, ply_path: Path) -> Path:
    """Where :func:`_place_texture` makes ``texture`` available beside ``ply_path``."""
    out_dir = ply_path.parent
    if os.path.samefile(texture.parent, out_dir):
        return texture
    stem = ply_path.name
    for suffix in (".ply", ".rollout", ".relaxed"):
        stem = stem[: -len(suffix)] if stem.endswith(suffix) else stem
    return out_dir / f"{stem}.texture{texture.suffix.lower()}"


def _place_texture(texture: Path, ply_path: Path) -> str:
    """Make ``texture`` available beside ``ply_path`` and return its name there.

    A texture already in that folder is used as it is. Otherwise it is hard-linked (or
    copied) as ``NAME.texture.EXT`` (NAME the stage name of ``ply_path``): a name no stage
    writes (a texture ``NAME.png`` would otherwise be replaced by the baked ``NAME.png``) and
    no other scan's texture can take (one output folder, several scans with a
    ``texture.jpg``). A stale file of that name is replaced.
    """
    target = _texture_target(texture, ply_path)
    if target == texture or (target.exists() and os.path.samefile(target, texture)):
        return target.name
    tmp = target.parent / f".{target.name}.{os.getpid()}.part"
    try:  # link under a temporary name, then rename (atomic_path would chmod the scan's texture)
        tmp.unlink(missing_ok=True)
        os.link(texture, tmp)
        os.replace(tmp, target)
    except OSError:
        tmp.unlink(missing_ok=True)
        with atomic_path(target) as part:
            shutil.copyfile(texture, part)
    return target.name


def write_flat_ply(path: str | os.PathLike, flat: FlatMesh, *, comments: tuple[str, ...] = ()) -> Path:
    """Write ``flat`` as a binary stage PLY at ``path`` (atomically).

    A texture that is not already beside ``path`` is hard-linked (or copied) there, so the
    output folder is self-contained for baking.

    Parameters
    ----------
    path : path-like
        Output file, normally ``NAME.rollout.ply`` or ``NAME.relaxed.ply``.
    flat : FlatMesh
        The flattened mesh.
    comments : tuple of str
        Extra header comment lines (provenance).

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    mesh = flat.mesh
    n, m = len(mesh.vertices), len(mesh.faces)
    texture_name = None
    if mesh.texture_path is not None and mesh.texcoords is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        texture_name = _place_texture(mesh.texture_path, path)

    vfields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("u", "<f8"), ("v", "<f8")]
    if mesh.vertex_colors is not None:
        vfields += [("red", "u1"), ("green", "u1"), ("blue", "u1"), ("alpha", "u1")]
    if flat.stress is not None:
        vfields.append(("stress", "<f8"))
    if flat.importance is not None:
        vfields.append(("importance", "<f8"))
    ffields = [("n", "u1"), ("idx", "<i4", (3,))]
    if texture_name is not None:
        ffields += [("nt", "u1"), ("tc", "<f4", (6,))]

    header = ["ply", "format binary_little_endian 1.0", f"comment units {mesh.units}"]
    header += [f"comment {c}" for c in _header_comments(flat, comments)]
    if texture_name is not None:
        header.append(f"comment TextureFile {texture_name}")
    header.append(f"element vertex {n}")
    ply_names = {"<f8": "double", "u1": "uchar"}
    header += [f"property {ply_names[t]} {name}" for name, t in vfields]
    header.append(f"element face {m}")
    header.append("property list uchar int vertex_indices")
    if texture_name is not None:
        header.append("property list uchar float texcoord")
    header.append("end_header")
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(("\n".join(header) + "\n").encode("ascii"))
            for rows in row_blocks(n):  # records built and written in blocks: no copy of the mesh
                vert = np.empty(rows.stop - rows.start, dtype=vfields)
                vert["x"], vert["y"], vert["z"] = mesh.vertices[rows].T
                vert["u"], vert["v"] = flat.uv[rows].T
                if mesh.vertex_colors is not None:
                    for k, name in enumerate(("red", "green", "blue", "alpha")):
                        vert[name] = mesh.vertex_colors[rows, k]
                if flat.stress is not None:
                    vert["stress"] = flat.stress[rows]
                if flat.importance is not None:
                    vert["importance"] = flat.importance[rows]
                fh.write(vert.data)
            for rows in row_blocks(m):
                face = np.empty(rows.stop - rows.start, dtype=ffields)
                face["n"] = 3
                face["idx"] = mesh.faces[rows]
                if texture_name is not None:
                    face["nt"] = 6
                    face["tc"] = mesh.texcoords[rows].reshape(-1, 6)
                fh.write(face.data)
            fh.flush()
            os.fsync(fh.fileno())
    return path


def _header_comments(flat: FlatMesh, comments: tuple[str, ...]) -> tuple[str, ...]:
    return tuple(c for c in (*flat.comments, *comments) if "\n" not in c)


def as_stored(flat: FlatMesh, path: str | os.PathLike, *, comments: tuple[str, ...] = ()) -> FlatMesh:
    """The flattening :func:`read_flat_ply` returns for the file ``write_flat_ply(path, flat,
    comments=comments)`` wrote, without reading it: texture coordinates at the file's float32
    precision, the texture beside ``path``, the header comments. So the next stage gets in
    memory exactly what it would read from the file.

    Parameters
    ----------
    flat : FlatMesh
        What was written.
    path : path-like
        The stage PLY it was written to (and its texture placed beside).
    comments : tuple of str
        The ``comments`` given to :func:`write_flat_ply`.

    Returns
    -------
    FlatMesh
    """
    path = Path(path)
    mesh = flat.mesh
    texcoords, texture_path = None, None
    if mesh.texture_path is not None and mesh.texcoords is not None:
        texcoords = mesh.texcoords.astype(np.float32).astype(np.float64)
        texture_path = (path.parent / _texture_target(mesh.texture_path, path).name).resolve()
    stored = Mesh(mesh.vertices, mesh.faces, texcoords=texcoords, texture_path=texture_path,
                  vertex_colors=mesh.vertex_colors, units=mesh.units, source=path)
    return FlatMesh(stored, flat.uv, stress=flat.stress, comments=_header_comments(flat, comments),
                    importance=flat.importance)


def read_flat_ply(path: str | os.PathLike) -> FlatMesh:
    """Read a stage PLY written by :func:`write_flat_ply` (or any tool using its layout).

    Parameters
    ----------
    path : path-like
        A ``NAME.rollout.ply`` or ``NAME.relaxed.ply``.

    Returns
    -------
    FlatMesh
        With the texture path resolved relative to the file.

    Raises
    ------
    InvalidInputError
        When the file is missing, truncated, or not a triangle stage PLY.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InvalidInputError(f"cannot read {path}: {exc.strerror or exc}") from None
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply") or end < 0:
        raise InvalidInputError(f"{path} is not a PLY file (no 'ply' header); give a stage file written by potflat")
    lines = data[:end].decode("ascii", "replace").splitlines()
    body = memoryview(data)[end + len("end_header\n"):]
    fmt = next((ln.split()[1] for ln in lines if ln.startswith("format")), "")
    if fmt != "binary_little_endian":
        raise InvalidInputError(f"{path} is {fmt or 'an unknown'} PLY; stage files are binary_little_endian (rewrite it with potflat)")

    units, texture_name, comments = "mm", None, []
    elements: list[tuple[str, int, list]] = []
    for ln in lines:
        parts = ln.split()
        if not parts:
            continue
        if parts[0] == "comment":
            if len(parts) >= 3 and parts[1] == "units":
                units = parts[2]
            elif len(parts) >= 3 and parts[1] == "TextureFile":
                texture_name = ln.split("TextureFile", 1)[1].strip()
            else:
                comments.append(ln[len("comment "):])
        elif parts[0] == "element":
            elements.append((parts[1], int(parts[2]), []))
        elif parts[0] == "property" and elements:
            elements[-1][2].append(parts[1:])
    if units not in UNITS_MM:
        raise InvalidInputError(f"{path} declares unknown units {units!r}; use one of {', '.join(UNITS_MM)}")

    arrays = {}
    offset = 0
    for name, count, props in elements:
        fields = []
        for prop in props:
            try:
                if prop[0] == "list":
                    fields.append((prop[3] + "#n", _PLY_TYPES[prop[1]]))
                    width = 3 if prop[3] == "vertex_indices" else 6 if prop[3] == "texcoord" else None
                    if width is None:
                        raise InvalidInputError(f"{path}: unsupported list property {prop[3]!r} in a stage file")
                    fields.append((prop[3], _PLY_TYPES[prop[2]], (width,)))
                else:
                    fields.append((prop[1], _PLY_TYPES[prop[0]]))
            except KeyError:
                raise InvalidInputError(f"{path}: unknown PLY type in property {' '.join(prop)}") from None
        dtype = np.dtype(fields)
        nbytes = dtype.itemsize * count
        if offset + nbytes > len(body):
            raise InvalidInputError(f"{path} is truncated ({name} data incomplete); write it again")
        arrays[name] = np.frombuffer(body, dtype=dtype, count=count, offset=offset)
        offset += nbytes

    vert, face = arrays.get("vertex"), arrays.get("face")
    if vert is None or face is None or not {"x", "y", "z", "u", "v"} <= set(vert.dtype.names or ()):
        raise InvalidInputError(f"{path} lacks vertex x y z u v or faces; give a stage file written by potflat rollout")
    if "vertex_indices" not in face.dtype.names or np.any(face["vertex_indices#n"] != 3):
        raise InvalidInputError(f"{path} has non-triangle faces; stage files hold triangles only")
    faces = face["vertex_indices"].astype(np.int64)
    if faces.size and (faces.min() < 0 or faces.max() >= len(vert)):
        raise InvalidInputError(f"{path} has faces pointing at missing vertices; write it again")
    xyz = np.stack([vert["x"], vert["y"], vert["z"]], axis=1).astype(np.float64)
    uv = np.stack([vert["u"], vert["v"]], axis=1).astype(np.float64)
    if not (np.isfinite(xyz).all() and np.isfinite(uv).all()):
        raise InvalidInputError(f"{path} has NaN or infinite coordinates; write it again")
    colors = None
    if {"red", "green", "blue"} <= set(vert.dtype.names):
        alpha = vert["alpha"] if "alpha" in vert.dtype.names else np.full(len(vert), 255, np.uint8)
        colors = np.stack([vert["red"], vert["green"], vert["blue"], alpha], axis=1).astype(np.uint8)
    texcoords, texture_path = None, None
    if texture_name is not None and "texcoord" in face.dtype.names:
        texcoords = face["texcoord"].reshape(-1, 3, 2).astype(np.float64)
        texture_path = (path.parent / texture_name).resolve()
    stress = np.asarray(vert["stress"], dtype=np.float64) if "stress" in vert.dtype.names else None
    importance = None
    if "importance" in vert.dtype.names:
        importance = np.asarray(vert["importance"], dtype=np.float64)
        if not (np.isfinite(importance).all() and importance.min(initial=0.0) >= 0 and importance.max(initial=0.0) <= 1):
            raise InvalidInputError(f"{path} has importance values outside 0..1; write it again")
    mesh = Mesh(xyz, faces, texcoords=texcoords, texture_path=texture_path,
                vertex_colors=colors, units=units, source=path)
    return FlatMesh(mesh, uv, stress=stress, comments=tuple(comments), importance=importance)
