"""glTF and GLB scans (through trimesh), and the texture images they name or embed."""
from __future__ import annotations

import base64
import hashlib
import json
import struct
import urllib.parse
import warnings
from pathlib import Path

import numpy as np

from potflat.errors import InvalidInputError
from potflat.io.atomic import write_bytes_atomic
from potflat.io.raw import (
    _IGNORE_HINT,
    _find_file,
    _first_line,
    _flag_untextured,
    _merge_textures,
    _Raw,
    _read_bytes,
    _texture_cache,
)
from potflat.io.stl_off import _trimesh_load


def _read_gltf(path: Path, texture: str, max_pixels: int) -> _Raw:
    import trimesh

    doc, bin_length = _gltf_json(path)
    _check_gltf_sizes(path, doc, bin_length)
    _check_gltf_nodes(path, doc)
    used = doc.get("extensionsUsed")
    if isinstance(used, list) and "KHR_draco_mesh_compression" in used:
        try:  # trimesh decodes Draco with DracoPy; without it, it returns all-zero positions
            import DracoPy  # noqa: F401
        except ImportError:
            raise InvalidInputError(f"{path} is Draco-compressed (KHR_draco_mesh_compression) and its decoder is "
                                    "missing: pip install DracoPy") from None
    required = doc.get("extensionsRequired")
    required = required if isinstance(required, list) else []
    if "EXT_meshopt_compression" in required:
        raise InvalidInputError(f"{path} is compressed with meshoptimizer (EXT_meshopt_compression), which potflat "
                                "cannot decode; export it without that compression (gltfpack without -c, "
                                "gltf-transform without meshopt) or with Draco")
    if "KHR_texture_basisu" in required and texture != "ignore":
        raise InvalidInputError(f"{path} has KTX2 textures (KHR_texture_basisu), which potflat cannot decode; "
                                f"export it with PNG or JPEG textures {_IGNORE_HINT}")
    scene = _trimesh_load(path, force="scene", resolver=_resolver(path))
    if isinstance(scene, trimesh.Scene):
        _dequantize(path, doc, scene)
    try:  # trimesh decodes embedded images lazily, here, and applies the nodes' transforms
        with warnings.catch_warnings():  # (a broken transform's NaN: the positions are checked later)
            warnings.simplefilter("ignore")
            geoms = [g for g in (scene.dump() if isinstance(scene, trimesh.Scene) else [scene])
                     if isinstance(g, trimesh.Trimesh) and len(g.faces)]
            kinds = [g.visual.kind for g in geoms]
    except Exception as exc:  # noqa: BLE001 - corrupt embedded data: many exception types
        msg = _first_line(exc)
        raise InvalidInputError(f"{path} cannot be read as {path.suffix[1:].upper()} ({msg[:120]}); "
                                "export the scan again") from None
    if not geoms:
        raise InvalidInputError(f"{path} contains no triangle meshes; export the scan as a mesh")
    verts, faces, uvs, offset = [], [], [], 0
    for g, kind in zip(geoms, kinds):
        if np.asarray(g.faces).min() < 0 or np.asarray(g.faces).max() >= len(g.vertices):
            raise InvalidInputError(f"{path}: faces point at missing vertices; the file is corrupt: export it again")
        if np.asarray(g.vertices).ndim != 2 or np.asarray(g.vertices).shape[1] != 3:
            raise InvalidInputError(f"{path}: its positions are not 3D points; the file is corrupt: export it again")
        verts.append(np.asarray(g.vertices, np.float64))
        faces.append(np.asarray(g.faces, np.int64) + offset)
        uv = getattr(g.visual, "uv", None) if kind == "texture" else None
        uv = None if uv is None else np.asarray(uv, np.float64)
        uvs.append(None if uv is None or uv.shape != (len(g.vertices), 2) else uv[g.faces])
        offset += len(g.vertices)
    raw = _Raw(vertices=np.concatenate(verts), faces=np.concatenate(faces), units="m")
    if all(kind == "vertex" for kind in kinds):
        raw.colors = np.concatenate([np.asarray(g.visual.vertex_colors, np.uint8) for g in geoms])
    if texture == "ignore" or all(u is None for u in uvs):
        return raw
    images = _gltf_images(path)
    if not images:
        raw.warnings.append("texture coordinates but no texture image; loaded untextured")
        return raw
    if len(images) == 1:  # the image as the file holds it
        raw.texcoords = np.concatenate([u if u is not None else np.zeros((len(f), 3, 2))
                                        for u, f in zip(uvs, faces)])
        _flag_untextured(raw, np.concatenate([np.full(len(f), u is None) for u, f in zip(uvs, faces)]),
                         "(meshes without TEXCOORD_0) have no texture coordinates")
        raw.texture = next(iter(images.values()))
        return raw
    # several images (a material per texture atlas, as photogrammetry exports a large scan):
    # each mesh's own, by its primitive's material, as the file holds it, packed into one atlas
    primitives = _primitives(doc)
    if not _matched(doc, scene, primitives):
        raise InvalidInputError(f"{path}: its meshes cannot be matched to the materials of its {len(images)} "
                                f"texture images; re-export the scan with one texture {_IGNORE_HINT}")
    primitive_of = {name: primitives[k] for k, name in enumerate(scene.geometry)}
    files, names, which = [], [], []
    for g, uv, f in zip(geoms, uvs, faces):
        material = (primitive_of.get(g.metadata.get("name")) or {}).get("material")
        image = images.get(_material_image(doc, material)) if uv is not None else None
        if image is not None and image not in files:
            files.append(image)
            named = _item(doc.get("materials"), material).get("name")  # (a material of an image: an object)
            names.append(f"material {named if isinstance(named, str) and named else material}")
        which.append(np.full(len(f), files.index(image) if image is not None else -1, np.int64))
    which = np.concatenate(which)
    uv = np.concatenate([u if u is not None else np.zeros((len(f), 3, 2)) for u, f in zip(uvs, faces)])
    if not files:
        raw.warnings.append("texture coordinates but no texture image; loaded untextured")
        return raw
    if len(files) == 1:
        raw.texture, raw.texcoords = files[0], uv
    else:
        raw.texture, raw.texcoords, note = _merge_textures(files, which, uv, path, max_pixels, names=names)
        raw.warnings.append(note)
    _flag_untextured(raw, which < 0, "(meshes without TEXCOORD_0 or a base-colour texture) have no texture")
    return raw


def _item(items, index):
    """``items[index]`` when ``items`` is a list and ``index`` an int (not a bool) within it, else
    None: a glTF's references, whatever a broken file puts there."""
    ok = isinstance(items, list) and isinstance(index, int) and not isinstance(index, bool)
    return items[index] if ok and 0 <= index < len(items) else None


def _primitives(doc: dict) -> list[dict]:
    """The primitives of a glTF's meshes, in the document's order (trimesh's order of meshes)."""
    meshes = doc.get("meshes") if isinstance(doc.get("meshes"), list) else []
    return [p for m in meshes if isinstance(m, dict)
            for p in (m.get("primitives") if isinstance(m.get("primitives"), list) else []) if isinstance(p, dict)]


def _matched(doc: dict, scene, primitives: list[dict]) -> bool:
    """Whether trimesh's meshes of ``scene`` are ``primitives`` one by one, in order: as many,
    each with its primitive's POSITION count of vertices."""
    geoms = list(scene.geometry.values())
    if len(geoms) != len(primitives):
        return False
    for g, p in zip(geoms, primitives):
        attributes = p.get("attributes") if isinstance(p.get("attributes"), dict) else {}
        accessor = _item(doc.get("accessors"), attributes.get("POSITION"))
        if not isinstance(accessor, dict) or len(getattr(g, "vertices", ())) != accessor.get("count"):
            return False
    return True


def _base_colour_ref(doc: dict, material) -> dict | None:
    """The base-colour texture reference (``{"index": ...}``) of material index ``material``:
    its metallic-roughness base colour, or the specular-glossiness diffuse texture."""
    m = _item(doc.get("materials"), material)
    m = m if isinstance(m, dict) else {}
    pbr = m.get("pbrMetallicRoughness") if isinstance(m.get("pbrMetallicRoughness"), dict) else {}
    extensions = m.get("extensions") if isinstance(m.get("extensions"), dict) else {}
    gloss = extensions.get("KHR_materials_pbrSpecularGlossiness")
    for ref in (pbr.get("baseColorTexture"), gloss.get("diffuseTexture") if isinstance(gloss, dict) else None):
        if isinstance(ref, dict):
            return ref
    return None


def _material_image(doc: dict, material) -> int | None:
    """The image index of material index ``material``'s base-colour texture (its source, or its
    EXT_texture_webp source), or None."""
    ref = _base_colour_ref(doc, material)
    texture = _item(doc.get("textures"), ref.get("index")) if ref is not None else None
    texture = texture if isinstance(texture, dict) else {}
    source = texture.get("source")
    if source is None:  # a WebP image (with no PNG or JPEG fallback)
        extensions = texture.get("extensions") if isinstance(texture.get("extensions"), dict) else {}
        webp = extensions.get("EXT_texture_webp")
        source = webp.get("source") if isinstance(webp, dict) else None
    return source if isinstance(source, int) and not isinstance(source, bool) else None


#: Largest value of each integer component type of glTF: a ``normalized`` accessor's values
#: divided by it (signed ones no lower than -1).
_NORMALIZED = {5120: 127.0, 5121: 255.0, 5122: 32767.0, 5123: 65535.0}
#: File suffix of each image type a glTF embeds.
_IMAGE_SUFFIXES = {"image/png": ".png", "image/jpeg": ".jpg", "image/webp": ".webp"}
#: NumPy type of each component type of glTF.
_COMPONENT_DTYPES = {5120: "<i1", 5121: "<u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}


def _dequantize(path: Path, doc: dict, scene) -> None:
    """Apply, in place on the meshes of ``scene`` (trimesh's reading of ``doc``), what trimesh
    leaves out: positions and texture coordinates stored as ``normalized`` integers
    (KHR_mesh_quantization, as gltfpack and gltf-transform write them), which it reads as the
    integers (texture coordinates wrapped around), read here from the file; and the
    base-colour texture's KHR_texture_transform (with which gltfpack dequantizes texture
    coordinates) and its set of texture coordinates (``texCoord``: trimesh reads TEXCOORD_0
    whichever the texture uses). trimesh keeps a mesh per primitive, in the document's order;
    each is matched to its primitive by its vertex count."""
    import trimesh

    def normalized(index) -> int | None:
        accessor = _item(doc.get("accessors"), index)
        return index if isinstance(accessor, dict) and accessor.get("normalized") is True else None

    primitives = _primitives(doc)
    jobs = []
    for p in primitives:
        attributes = p.get("attributes") if isinstance(p.get("attributes"), dict) else {}
        which = _texcoord_set(doc, p.get("material"))
        if which == 0:
            tex = normalized(attributes.get("TEXCOORD_0"))
        elif isinstance(_item(doc.get("accessors"), attributes.get(f"TEXCOORD_{which}")), dict):
            tex = attributes[f"TEXCOORD_{which}"]
        else:
            raise InvalidInputError(f"{path}: a material's base-colour texture reads texture coordinates "
                                    f"TEXCOORD_{which}, which its mesh does not have; the file is corrupt: export "
                                    "the scan again")
        jobs.append((normalized(attributes.get("POSITION")), tex, _texture_transform(path, doc, p.get("material"))))
    if all(pos is None and tex is None and move is None for pos, tex, move in jobs):
        return
    if not _matched(doc, scene, primitives):
        raise InvalidInputError(f"{path}: its quantized meshes (KHR_mesh_quantization), texture transforms "
                                "(KHR_texture_transform) or second texture coordinates cannot be matched to the "
                                "meshes read; export the scan without quantization, with one set of texture "
                                "coordinates")
    buffers = _gltf_buffers(path, doc) if any(pos is not None or tex is not None for pos, tex, _ in jobs) else []
    for g, (pos, tex, move) in zip(scene.geometry.values(), jobs):
        if pos is not None:
            g.vertices = _accessor_values(path, doc, buffers, pos, width=3)
        uv = getattr(g.visual, "uv", None)
        if tex is not None or (uv is not None and move is not None):
            # glTF's texture coordinates (v down; trimesh turns v up)
            if tex is None and np.shape(uv)[1:] != (2,):
                continue  # (not texture coordinates: the mesh is read untextured)
            flat = (_accessor_values(path, doc, buffers, tex, width=2) if tex is not None
                    else np.column_stack([uv[:, 0], 1.0 - uv[:, 1]]))
            if move is not None:
                flat = flat @ move[:, :2].T + move[:, 2]
            if len(flat) != len(g.vertices):
                raise InvalidInputError(f"{path}: a mesh has {len(flat)} texture coordinates for {len(g.vertices)} "
                                        "vertices; the file is corrupt: export the scan again")
            if uv is None:  # (texture coordinates in another set than TEXCOORD_0 alone)
                g.visual = trimesh.visual.TextureVisuals(uv=np.zeros((len(flat), 2)))
            g.visual.uv = np.column_stack([flat[:, 0], 1.0 - flat[:, 1]])


def _uri_file(path: Path, uri: str) -> Path:
    """The file that ``uri``, a relative URI in the glTF at ``path``, names: as written, else
    percent-decoded (glTF URIs are RFC 3986 references: Blender writes a space as ``%20``,
    other exporters leave it); what :func:`potflat.io.raw._find_file` gives when neither is
    there."""
    found = _find_file(uri, path.parent)
    decoded = urllib.parse.unquote(uri)
    if not found.is_file() and decoded != uri:
        other = _find_file(decoded, path.parent)
        return other if other.is_file() else found
    return found


def _resolver(path: Path):
    """trimesh's resolver of the files the glTF at ``path`` names, found by :func:`_uri_file`."""
    from trimesh.resolvers import FilePathResolver

    class UriResolver(FilePathResolver):
        def get(self, name: str) -> bytes:
            found = _uri_file(path, name)
            return _read_bytes(found, "a glTF's file") if found.is_file() else super().get(name)

    return UriResolver(str(path))


def _gltf_buffers(path: Path, doc: dict) -> list[bytes]:
    """The data of every buffer of a glTF/GLB (a GLB's own: its binary chunk; others: their
    ``.bin`` file or ``data:`` URI), sizes checked by :func:`_check_gltf_sizes`."""
    _, bin_chunk = _gltf_document(path)
    out = []
    for buffer in doc.get("buffers") or []:
        uri = buffer.get("uri")
        if uri is None:
            out.append(bin_chunk)
        elif isinstance(uri, str) and uri.startswith("data:"):
            out.append(base64.b64decode(uri.split(",", 1)[1]))
        else:
            out.append(_read_bytes(_uri_file(path, str(uri))))
    return out


def _accessor_values(path: Path, doc: dict, buffers: list[bytes], index: int, *, width: int) -> np.ndarray:
    """The values of accessor ``index``, of ``width`` components, as (count, width) float64,
    ``normalized`` integers divided to [-1, 1] or [0, 1]."""
    a = doc["accessors"][index]
    broken = InvalidInputError(f"{path}: accessor {index} cannot be read (sparse, compressed, of another type or "
                               "past its data); export the scan without quantization")
    kind = a.get("componentType")
    if ("sparse" in a or "bufferView" not in a or not isinstance(kind, int) or kind not in _COMPONENT_DTYPES
            or a.get("type") != ("VEC3" if width == 3 else "VEC2")):
        raise broken
    view = doc["bufferViews"][a["bufferView"]]
    dtype = np.dtype(_COMPONENT_DTYPES[kind])
    stride = view.get("byteStride") or width * dtype.itemsize
    start = view.get("byteOffset", 0) + a.get("byteOffset", 0)
    count = a["count"]
    data = buffers[view.get("buffer", 0)]
    if (count == 0 or not isinstance(stride, int) or stride < width * dtype.itemsize
            or start + (count - 1) * stride + width * dtype.itemsize > len(data)):
        raise broken
    values = np.ndarray((count, width), dtype=dtype, buffer=data, offset=start,
                        strides=(stride, dtype.itemsize)).astype(np.float64)
    if a.get("normalized") is True and kind in _NORMALIZED:
        values = np.maximum(values / _NORMALIZED[kind], -1.0)
    return values


def _texcoord_set(doc: dict, material) -> int:
    """Which set of texture coordinates (``TEXCOORD_n``) material index ``material``'s
    base-colour texture reads: its ``texCoord``, or its KHR_texture_transform's (0 when
    neither says, or says something other than a count)."""
    ref = _base_colour_ref(doc, material)
    if ref is None:
        return 0
    which = ref.get("texCoord", 0)
    extensions = ref.get("extensions")
    move = extensions.get("KHR_texture_transform") if isinstance(extensions, dict) else None
    if isinstance(move, dict) and "texCoord" in move:
        which = move["texCoord"]
    return which if isinstance(which, int) and not isinstance(which, bool) and which >= 0 else 0


def _texture_transform(path: Path, doc: dict, material) -> np.ndarray | None:
    """The KHR_texture_transform of material index ``material``'s base-colour texture as a
    (2, 3) affine map of glTF texture coordinates (translation, rotation, scale, in that order
    of the extension), or None without one."""
    ref = _base_colour_ref(doc, material)
    extensions = ref.get("extensions") if ref is not None else None
    move = extensions.get("KHR_texture_transform") if isinstance(extensions, dict) else None
    if not isinstance(move, dict):
        return None
    try:
        ox, oy = (float(x) for x in move.get("offset", (0.0, 0.0)))
        sx, sy = (float(x) for x in move.get("scale", (1.0, 1.0)))
        angle = float(move.get("rotation", 0.0))
    except (TypeError, ValueError):
        raise InvalidInputError(f"{path}: a texture transform (KHR_texture_transform) is not numbers; the file "
                                "is corrupt: export the scan again") from None
    if not np.isfinite([ox, oy, sx, sy, angle]).all():
        raise InvalidInputError(f"{path}: a texture transform (KHR_texture_transform) is not finite; the file "
                                "is corrupt: export the scan again")
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c * sx, s * sy, ox], [-s * sx, c * sy, oy]])


#: Most data a glTF may embed as base64 text (``data:`` URIs), decoded: decoding takes about five
#: times as much memory (the text, its copies, the bytes); a larger scan comes as a GLB or with
#: a ``.bin`` file.
MAX_EMBEDDED_BYTES = 256 << 20
#: Most JSON a glTF/GLB holds besides its embedded data (nodes, accessors, materials).
MAX_JSON_BYTES = 64 << 20
#: Bytes of each glTF component type.
_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
#: Components of each accessor type.
_TYPE_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}


def _gltf_json(path: Path) -> tuple[dict, int]:
    """The JSON of a glTF or GLB (read alone: of a GLB its JSON chunk, never its binary chunk)
    and the length of a GLB's binary chunk (0 for a .gltf).

    Raises
    ------
    InvalidInputError
        For JSON over :data:`MAX_JSON_BYTES` plus :data:`MAX_EMBEDDED_BYTES` as base64 (checked
        from the file's size or the GLB's chunk header, before reading), or not a glTF.
    """
    most = MAX_JSON_BYTES + MAX_EMBEDDED_BYTES * 4 // 3
    size = path.stat().st_size
    with open(path, "rb") as fh:
        head = fh.read(20)
        glb = head[:4] == b"glTF"
        if glb:
            if len(head) < 20:
                raise InvalidInputError(f"{path} is not a valid GLB file (cut short); export the scan again")
            length = struct.unpack_from("<I", head, 12)[0]
            if 20 + length > size:  # (random bytes after the magic word declare any length)
                raise InvalidInputError(f"{path} is not a valid GLB file (its JSON chunk declares {length} bytes, "
                                        f"the file holds {size}: cut short or corrupt); export the scan again")
        else:
            length = size
        if length > most:
            raise InvalidInputError(f"{path} holds {length / 2**20:.0f} MiB of glTF JSON, over the "
                                    f"{most / 2**20:.0f} MiB limit (data embedded as base64 text); export the scan as "
                                    "GLB or glTF with a .bin file")
        text = fh.read(length) if glb else head + fh.read()
        bin_length = 0
        if glb:
            chunk = fh.read(8)
            bin_length = struct.unpack_from("<I", chunk)[0] if len(chunk) == 8 else 0
            bin_length = min(bin_length, max(0, size - 28 - length))  # what the file holds
    try:
        doc = json.loads(text)
    except ValueError:
        doc = None
    if not isinstance(doc, dict):
        raise InvalidInputError(f"{path} is not valid glTF{' (GLB)' if glb else ''} JSON; export the scan again")
    return doc, bin_length


def _check_gltf_sizes(path: Path, doc: dict, bin_length: int) -> None:
    """Refuse, before anything is decoded, a glTF whose declared sizes its data cannot back or
    memory cannot hold: more than :data:`MAX_EMBEDDED_BYTES` embedded as ``data:`` URIs, a
    buffer longer than its data (the base64 text, the GLB's binary chunk, the ``.bin`` file) or
    than the memory the process may use, views past their buffer, accessors past their view."""
    from potflat.io.raw import memory_limit

    def broken(what: str) -> InvalidInputError:
        return InvalidInputError(f"{path}: {what}; the file is corrupt or hostile: export the scan again")

    def items(key: str) -> list[dict]:
        value = doc.get(key) or []
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise broken(f"'{key}' is not a list of objects")
        return value

    def number(item: dict, key: str, default: int | None = None) -> int:
        value = item.get(key, default)
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise broken(f"{key} {value!r} is not a count of bytes or items")
        return value

    embedded = sum(len(item["uri"]) * 3 // 4 for key in ("buffers", "images") for item in items(key)
                   if isinstance(item.get("uri"), str) and item["uri"].startswith("data:"))
    if embedded > MAX_EMBEDDED_BYTES:
        raise InvalidInputError(f"{path} embeds {embedded / 2**20:.0f} MiB as base64 text (data: URIs), over the "
                                f"{MAX_EMBEDDED_BYTES / 2**20:.0f} MiB limit; export the scan as GLB or glTF "
                                "with a .bin file")
    budget = memory_limit()
    lengths = []
    for k, buffer in enumerate(items("buffers")):
        declared = number(buffer, "byteLength")
        uri = buffer.get("uri")
        if uri is None:
            held, where = bin_length, "the GLB's binary chunk"
        elif isinstance(uri, str) and uri.startswith("data:"):
            held, where = len(uri.split(",", 1)[-1]) * 3 // 4, "its base64 text"
        else:
            source = _uri_file(path, str(uri))
            if not source.is_file():
                raise InvalidInputError(f"{path}: its buffer file {uri} is not there; put it beside the glTF "
                                        "(or export the scan as one GLB)")
            held, where = source.stat().st_size, f"the file {uri}"
        if declared > held:
            raise broken(f"buffer {k} declares {declared} bytes but {where} holds {held}")
        if budget is not None and declared > budget:
            raise InvalidInputError(f"{path}: buffer {k} is {declared / 2**30:.1f} GiB, more than the memory potflat "
                                    "may use here; give a smaller scan (decimate it)")
        lengths.append(declared)
    views = []
    for k, view in enumerate(items("bufferViews")):
        buffer, offset, length = number(view, "buffer"), number(view, "byteOffset", 0), number(view, "byteLength")
        if buffer >= len(lengths) or offset + length > lengths[buffer]:
            raise broken(f"buffer view {k} reaches past its buffer")
        views.append(length)
    for k, accessor in enumerate(items("accessors")):
        count = number(accessor, "count")
        kind, width = accessor.get("componentType"), accessor.get("type")
        element = (_COMPONENT_BYTES.get(kind, 4) if isinstance(kind, int) else 4) * (
            _TYPE_COMPONENTS.get(width, 16) if isinstance(width, str) else 16)
        if "bufferView" in accessor:
            view = number(accessor, "bufferView")
            if view >= len(views) or number(accessor, "byteOffset", 0) + count * element > views[view]:
                raise broken(f"accessor {k} ({count} items) reaches past its buffer view")
        elif budget is not None and count * element > budget:  # zeros, or compressed (Draco): decoded here
            raise InvalidInputError(f"{path}: accessor {k} declares {count} items ({count * element / 2**30:.1f} "
                                    "GiB), more than the memory potflat may use here; give a smaller scan")


def _check_gltf_nodes(path: Path, doc: dict) -> None:
    """Refuse a glTF whose nodes are no hierarchy of objects (glTF 2.0: disjoint trees, each
    node the child of one node at most, the scenes' nodes roots): a node among its own
    descendants, a node with two parents or a scene listing a child would make a reader loop,
    or draw the same part twice."""
    nodes = doc.get("nodes") or []
    if not isinstance(nodes, list):
        nodes = []
    parent: dict[int, int] = {}
    for k, node in enumerate(nodes):
        children = node.get("children") or [] if isinstance(node, dict) else []
        for child in children if isinstance(children, list) else []:
            if not isinstance(child, int) or isinstance(child, bool) or not 0 <= child < len(nodes):
                raise InvalidInputError(f"{path}: node {k} names a child {child!r} that does not exist; the file is "
                                        "corrupt: export the scan again")
            if child in parent or child == k:
                why = "is its own child" if child == k else f"has two parents (nodes {parent[child]} and {k})"
                raise InvalidInputError(f"{path}: node {child} {why}: its nodes are no tree of objects; the file is "
                                        "corrupt: export the scan again")
            parent[child] = k
    for k in parent:  # a cycle: following the parents from k comes back to k
        seen, at = {k}, parent[k]
        while at in parent:
            if at in seen:
                raise InvalidInputError(f"{path}: node {at} is among its own descendants (a cycle of nodes): its "
                                        "nodes are no tree of objects; the file is corrupt: export the scan again")
            seen.add(at)
            at = parent[at]
    scenes = doc.get("scenes")
    for scene in scenes if isinstance(scenes, list) else []:
        roots = scene.get("nodes") or [] if isinstance(scene, dict) else []
        listed = [r for r in roots if isinstance(r, int) and r in parent] if isinstance(roots, list) else []
        if listed:
            raise InvalidInputError(f"{path}: a scene lists node {listed[0]}, a child of node {parent[listed[0]]}, "
                                    "as a root: it would be drawn twice; the file is corrupt: export the scan again")


def _gltf_inputs(path: Path) -> list[Path]:
    """The files loading the glTF/GLB at ``path`` reads besides it: the buffers and images it
    names by URI (those that exist; embedded data is part of the file). Of a GLB only the JSON
    chunk is read."""
    try:
        doc = _gltf_json(path)[0]
    except InvalidInputError:  # the load says what is wrong
        return []
    uris = [item.get("uri") for key in ("buffers", "images")
            for item in (doc.get(key) or []) if isinstance(item, dict)]
    found = (_uri_file(path, uri) for uri in uris if isinstance(uri, str) and not uri.startswith("data:"))
    return [p for p in found if p.is_file()]


def _gltf_images(path: Path) -> dict[int, Path]:
    """Base-colour texture images of a glTF/GLB as files, by image index: external ones as they
    are, embedded ones extracted (content-addressed, atomically) into the private
    :func:`_texture_cache`."""
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


def _gltf_image_files(path: Path) -> dict[int, Path]:
    doc, bin_chunk = _gltf_document(path)
    images = doc.get("images", [])
    # images used as base colour (not normal or roughness maps)
    materials = doc.get("materials") if isinstance(doc.get("materials"), list) else []
    base = {_material_image(doc, k) for k in range(len(materials))}
    out = {}
    for k, img in enumerate(images):
        if k not in base:
            continue
        uri = img.get("uri")
        blob = None
        if uri is not None and not uri.startswith("data:"):
            out[k] = _uri_file(path, uri)
            continue
        if uri is not None:
            blob = base64.b64decode(uri.split(",", 1)[1])
        elif "bufferView" in img:
            bv = doc["bufferViews"][img["bufferView"]]
            start = bv.get("byteOffset", 0)
            blob = bin_chunk[start:start + bv["byteLength"]]
        if blob:
            ext = _IMAGE_SUFFIXES.get(img.get("mimeType", ""), ".png")
            target = _texture_cache() / (hashlib.sha256(blob).hexdigest()[:32] + ext)
            if not target.exists():  # the private cache holds only what this process wrote
                write_bytes_atomic(target, blob)
            out[k] = target
    return out
