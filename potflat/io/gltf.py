"""glTF and GLB scans (through trimesh), and the texture images they name or embed."""
from __future__ import annotations

import base64
import hashlib
import json
import struct
from pathlib import Path

import numpy as np

from potflat.errors import InvalidInputError
from potflat.io.atomic import write_bytes_atomic
from potflat.io.raw import (
    _IGNORE_HINT,
    _find_file,
    _flag_untextured,
    _Raw,
    _read_bytes,
    _texture_cache,
)
from potflat.io.stl_off import _trimesh_load


def _read_gltf(path: Path, texture: str, max_pixels: int) -> _Raw:
    import trimesh

    try:
        used = _gltf_document(path)[0].get("extensionsUsed")
    except InvalidInputError:
        used = None  # (a broken file: trimesh's reading says what is wrong with it)
    if isinstance(used, list) and "KHR_draco_mesh_compression" in used:
        try:  # trimesh decodes Draco with DracoPy; without it, it returns all-zero positions
            import DracoPy  # noqa: F401
        except ImportError:
            raise InvalidInputError(f"{path} is Draco-compressed (KHR_draco_mesh_compression) and its decoder is "
                                    "missing: pip install DracoPy") from None
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


def _gltf_document(path: Path) -> tuple[dict, bytes]:
    """The JSON document of a glTF/GLB and a GLB's binary chunk (empty for a .gltf)."""
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
    return doc, bin_chunk


def _gltf_image_files(path: Path) -> list[Path]:
    doc, bin_chunk = _gltf_document(path)
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
