"""Stage files: ``NAME.rollout.ply`` / ``NAME.relaxed.ply`` and their JSON sidecars.

The PLY is binary little-endian with vertex properties ``x y z u v`` (double), optional
``red green blue alpha`` (uchar), ``stress`` and ``importance`` (double, 0 plain to 1
painted: :attr:`potflat.types.FlatMesh.importance`); faces carry
``vertex_indices`` (uchar count, int indices) and optionally ``texcoord`` (uchar count,
6 floats: MeshLab's convention), with ``comment TextureFile NAME`` naming the texture
image relative to the PLY, and ``untextured`` (uchar, 1 for a face without texture
coordinates: :attr:`potflat.types.Mesh.untextured_faces`; only when some face has none).
``comment units mm`` records the length unit. See ``docs/formats.md``.
"""
from __future__ import annotations

import os
import shutil
import stat
from pathlib import Path

import numpy as np

from potflat.errors import InvalidInputError
from potflat.io._kernels.ply_png import float32_exact
from potflat.io.atomic import atomic_path
from potflat.io.images import check_texture_image
from potflat.io.ply import _ply_header
from potflat.io.raw import _read_bytes
from potflat.mesh.distortion import row_blocks
from potflat.types import UNITS_MM, FlatMesh, Mesh


def _texture_target(texture: Path, ply_path: Path) -> Path:
    """Where :func:`_place_texture` makes ``texture`` available beside ``ply_path``."""
    out_dir = ply_path.parent
    if os.path.samefile(texture.parent, out_dir):
        return texture
    stem = ply_path.name
    for suffix in (".ply", ".rollout", ".relaxed", ".base"):
        stem = stem[: -len(suffix)] if stem.endswith(suffix) else stem
    return out_dir / f"{stem}.texture{texture.suffix.lower()}"


def _place_texture(texture: Path, ply_path: Path) -> str:
    """Make ``texture`` available beside ``ply_path`` and return its name there.

    A texture already in that folder is used as it is. Otherwise it is copied (never linked:
    editing an output must not edit the scan's texture) as ``NAME.texture.EXT`` (NAME the stage
    name of ``ply_path``): a name no stage writes (a texture ``NAME.png`` would otherwise be
    replaced by the baked ``NAME.png``) and no other scan's texture can take (one output
    folder, several scans with a ``texture.jpg``). A stale file of that name is replaced; an
    identical copy is kept. Only an image that decodes is copied
    (:func:`~potflat.io.images.check_texture_image`).
    """
    import filecmp

    target = _texture_target(texture, ply_path)
    if target == texture:
        return target.name
    check_texture_image(texture)
    if target.is_file() and not target.is_symlink() and os.stat(target).st_nlink == 1 \
            and filecmp.cmp(target, texture, shallow=False):
        return target.name
    with atomic_path(target) as part:
        shutil.copyfile(texture, part)
    return target.name


def write_flat_ply(path: str | os.PathLike, flat: FlatMesh, *, comments: tuple[str, ...] = ()) -> Path:
    """Write ``flat`` as a binary stage PLY at ``path`` (atomically).

    A texture that is not already beside ``path`` is copied there, so the output folder is
    self-contained for baking.

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
    untextured = mesh.untextured_faces if texture_name is not None else None
    if untextured is not None:
        ffields.append(("untextured", "u1"))

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
    if untextured is not None:
        header.append("property uchar untextured")
    header.append("end_header")
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(("\n".join(header) + "\n").encode("utf-8"))
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
                if untextured is not None:
                    face["untextured"] = untextured[rows]
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
    texcoords, texture_path, untextured = None, None, None
    if mesh.texture_path is not None and mesh.texcoords is not None:
        texcoords = mesh.texcoords
        if not float32_exact(np.ascontiguousarray(texcoords, dtype=np.float64).reshape(-1)):
            texcoords = texcoords.astype(np.float32).astype(np.float64)
        # (else stored before, a rollout's: shared, 275 MB less at 3M vertices while the next stages run)
        texture_path = (path.parent / _texture_target(mesh.texture_path, path).name).resolve()
        untextured = mesh.untextured_faces
    stored = Mesh(mesh.vertices, mesh.faces, texcoords=texcoords, texture_path=texture_path,
                  vertex_colors=mesh.vertex_colors, units=mesh.units, source=path, untextured_faces=untextured)
    return FlatMesh(stored, flat.uv, stress=flat.stress, comments=_header_comments(flat, comments),
                    importance=flat.importance)


def _texture_beside(path: Path, texture_name: str) -> Path:
    """The texture a stage PLY names (``comment TextureFile NAME``): a file in the PLY's own
    folder, as :func:`write_flat_ply` places it. A name with a folder in it, an absolute path, or
    a link leading out of the folder is refused: a stage file never chooses what potflat reads or
    copies elsewhere."""
    folder = path.parent.resolve()
    try:
        texture = (folder / texture_name).resolve()
    except (OSError, RuntimeError):  # a symbolic link loop: reported as missing when it is read
        texture = folder / texture_name
    if texture_name in ("", ".", "..") or Path(texture_name).name != texture_name or texture.parent != folder:
        raise InvalidInputError(f"{path} names the texture {texture_name!r}, which is not a file beside it; put "
                                "the texture image in the stage file's folder and name it there (comment "
                                "TextureFile NAME), or roll the scan out again")
    return texture


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
        When the file is missing, truncated, or not a triangle stage PLY, or names a texture
        that is not beside it.
    """

    path = Path(path)
    try:
        if not stat.S_ISREG(path.stat().st_mode):
            raise InvalidInputError(f"{path} is not a regular file (a folder, device or pipe); give a stage file "
                                    "written by potflat")
        data = _read_bytes(path, "a stage file")
    except (OSError, RuntimeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else "a symbolic link loop"
        raise InvalidInputError(f"cannot read {path}: {reason}; give a stage file written by potflat") from None
    fmt, comment_lines, elements, body_start = _ply_header(data, path)
    if fmt != "binary_little_endian":
        raise InvalidInputError(f"{path} is {fmt or 'an unknown'} PLY; stage files are binary_little_endian (rewrite it with potflat)")
    body = memoryview(data)[body_start:]

    units, texture_name, comments = "mm", None, []
    for line in comment_lines:
        parts = line.split()
        if len(parts) >= 2 and parts[0] == "units":
            units = parts[1]
        elif len(parts) >= 2 and parts[0] == "TextureFile":
            texture_name = line.split("TextureFile", 1)[1].strip()
        else:
            comments.append(line)
    if units not in UNITS_MM:
        raise InvalidInputError(f"{path} declares unknown units {units!r}; use one of {', '.join(UNITS_MM)}")

    arrays = {}
    offset = 0
    for el in elements:
        fields = []
        for prop in el.props:
            if len(prop) == 3:
                width = {"vertex_indices": 3, "texcoord": 6}.get(prop[0])
                if width is None:
                    raise InvalidInputError(f"{path}: unsupported list property {prop[0]!r} in a stage file; "
                                            "give a stage file written by potflat")
                fields += [(prop[0] + "#n", "<" + prop[1]), (prop[0], "<" + prop[2], (width,))]
            else:
                fields.append((prop[0], "<" + prop[1]))
        try:
            dtype = np.dtype(fields)
        except (TypeError, ValueError):  # a property name given twice
            raise InvalidInputError(f"{path}: malformed {el.name} properties; give a stage file written by "
                                    "potflat") from None
        nbytes = dtype.itemsize * el.count
        if offset + nbytes > len(body):
            raise InvalidInputError(f"{path} is truncated ({el.name} data incomplete); write it again")
        arrays[el.name] = np.frombuffer(body, dtype=dtype, count=el.count, offset=offset)
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
    texcoords, texture_path, untextured = None, None, None
    if texture_name is not None and "texcoord" in face.dtype.names:
        texcoords = face["texcoord"].reshape(-1, 3, 2).astype(np.float64)
        texture_path = _texture_beside(path, texture_name)
        if "untextured" in face.dtype.names:
            if not np.isin(face["untextured"], (0, 1)).all():
                raise InvalidInputError(f"{path} has face untextured flags other than 0 and 1; write it again")
            untextured = face["untextured"] == 1
    stress = np.asarray(vert["stress"], dtype=np.float64) if "stress" in vert.dtype.names else None
    importance = None
    if "importance" in vert.dtype.names:
        importance = np.asarray(vert["importance"], dtype=np.float64)
        if not (np.isfinite(importance).all() and importance.min(initial=0.0) >= 0 and importance.max(initial=0.0) <= 1):
            raise InvalidInputError(f"{path} has importance values outside 0..1; write it again")
    mesh = Mesh(xyz, faces, texcoords=texcoords, texture_path=texture_path,
                vertex_colors=colors, units=units, source=path, untextured_faces=untextured)
    return FlatMesh(mesh, uv, stress=stress, comments=tuple(comments), importance=importance)
