"""Scan loading: formats, seam welding, textures, units, real scans and bad input."""
from __future__ import annotations

import os
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest

from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.io.scan import LoadedScan, load_scan



@pytest.fixture(autouse=True)
def _private_tempdir(tmp_path, monkeypatch):
    """Packed atlases and extracted GLB textures go to the process's private folder in the temp
    folder: make a new one per test, in tmp_path."""
    import tempfile

    from potflat.io import raw as scan_io

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.setattr(scan_io, "_PRIVATE_CACHE", [])


# ------------------------------------------------------------------ helpers


def _png(path: Path, size=(8, 8)) -> Path:
    from PIL import Image

    Image.new("RGB", size, (200, 100, 50)).save(path)
    return path


def _grid(nu=4, nv=3):
    """A (nu+1) x (nv+1) vertex grid on a half cylinder; faces CCW seen from outside."""
    th = np.linspace(0.0, np.pi, nu + 1)
    z = np.linspace(0.0, 2.0, nv + 1)
    T, Z = np.meshgrid(th, z, indexing="ij")
    V = np.stack([np.cos(T), np.sin(T), Z], -1).reshape(-1, 3)
    idx = np.arange(len(V)).reshape(nu + 1, nv + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    # faces must be CCW from outside (+radial): check and fix once
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    cen = V[F].mean(1)
    if np.einsum("ij,ij->i", n[:, :2], cen[:, :2]).mean() < 0:
        F = F[:, [0, 2, 1]]
    return V, F


def _uv_of(P):
    """Texture coordinate as a function of position (to check corner alignment)."""
    P = np.asarray(P)
    return np.stack([np.arctan2(P[..., 1], P[..., 0]) / np.pi, P[..., 2] / 2.0], -1)


def _write_seam_obj(tmp_path: Path, texture=True) -> tuple[Path, np.ndarray, np.ndarray]:
    """OBJ whose vertices are split into two charts at the middle column (as an atlas does):
    the seam vertices appear twice with identical positions and different vt."""
    V, F = _grid()
    nv = 3
    col = (np.arange(len(V)) // (nv + 1))  # column index of each vertex
    # chart of each face: left half (columns 0..2) or right half (2..4)
    fcol = col[F].max(axis=1)
    chart = (fcol > 2).astype(int)
    # file vertex list: chart 0 vertices (col <= 2), then chart 1 vertices (col >= 2)
    ids0 = np.flatnonzero(col <= 2)
    ids1 = np.flatnonzero(col >= 2)
    fv = np.concatenate([ids0, ids1])
    map0 = {v: k for k, v in enumerate(ids0)}
    map1 = {v: k + len(ids0) for k, v in enumerate(ids1)}
    # texture coordinates of charts placed apart in the atlas (different vt at the seam)
    tc_all = _uv_of(V[fv]) * 0.5 + np.where(np.arange(len(fv)) < len(ids0), 0.0, 0.5)[:, None]
    lines = ["mtllib seam.mtl", "o part", "usemtl paint"]
    lines += [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in V[fv]]
    lines += [f"vt {u:.17g} {v:.17g}" for u, v in tc_all]
    lines += ["vn 0 0 1"]
    expected_tc = np.zeros((len(F), 3, 2))
    for f, (tri, ch) in enumerate(zip(F, chart)):
        mp = map0 if ch == 0 else map1
        idx = [mp[v] for v in tri]
        expected_tc[f] = tc_all[idx]
        lines.append("f " + " ".join(f"{i + 1}/{i + 1}/1" for i in idx))
    obj = tmp_path / "seam.obj"
    obj.write_text("\n".join(lines) + "\n")
    if texture:
        (tmp_path / "seam.mtl").write_text("newmtl paint\nKd 1 1 1\nmap_Kd -bm 1 atlas.png\n")
        _png(tmp_path / "atlas.png")
    return obj, V[F], expected_tc


def _match_faces(mesh, tri_positions):
    """Index of each loaded face in the reference (by its sorted corner positions)."""
    ref = {tuple(np.round(np.sort(t, axis=0), 5).ravel()): k for k, t in enumerate(tri_positions)}
    got = mesh.vertices[mesh.faces]
    return np.array([ref[tuple(np.round(np.sort(t, axis=0), 5).ravel())] for t in got])


def _assert_corner_texcoords(mesh, tri_positions, expected_tc):
    """Each corner keeps its own texture coordinate (matched by position)."""
    k = _match_faces(mesh, tri_positions)
    for f, r in enumerate(k):
        for c in range(3):
            j = int(np.argmin(np.linalg.norm(tri_positions[r] - mesh.vertices[mesh.faces[f, c]], axis=1)))
            np.testing.assert_allclose(mesh.texcoords[f, c], expected_tc[r, j], atol=1e-6)


def _write_ply(path: Path, V, faces_lists, *, binary=True, endian="<", vprops=(), vextra=None,
               texcoord=None, comments=(), truncate=0):
    """Minimal PLY writer for tests: float xyz [+ extra vertex props], face list uchar int
    [+ texcoord list uchar float]."""
    n = len(V)
    fmt = "ascii" if not binary else "binary_little_endian" if endian == "<" else "binary_big_endian"
    head = ["ply", f"format {fmt} 1.0"]
    head += [f"comment {c}" for c in comments]
    head += [f"element vertex {n}", "property float x", "property float y", "property float z"]
    head += [f"property {t} {name}" for name, t in vprops]
    head += [f"element face {len(faces_lists)}", "property list uchar int vertex_indices"]
    if texcoord is not None:
        head.append("property list uchar float texcoord")
    head.append("end_header")
    codes = {"float": "f", "uchar": "B", "double": "d"}
    if binary:
        body = bytearray()
        for i in range(n):
            body += struct.pack(endian + "3f", *V[i])
            for k, (name, t) in enumerate(vprops):
                body += struct.pack(endian + codes[t], vextra[i][k])
        for f, fl in enumerate(faces_lists):
            body += struct.pack(endian + "B" + f"{len(fl)}i", len(fl), *fl)
            if texcoord is not None:
                body += struct.pack(endian + "B" + f"{len(texcoord[f])}f", len(texcoord[f]), *texcoord[f])
        data = ("\n".join(head) + "\n").encode() + bytes(body)
    else:
        rows = []
        for i in range(n):
            rows.append(" ".join([repr(float(x)) for x in V[i]] + [str(x) for x in (vextra[i] if vprops else [])]))
        for f, fl in enumerate(faces_lists):
            row = [str(len(fl))] + [str(i) for i in fl]
            if texcoord is not None:
                row += [str(len(texcoord[f]))] + [repr(float(t)) for t in texcoord[f]]
            rows.append(" ".join(row))
        data = ("\n".join(head + rows) + "\n").encode()
    path.write_bytes(data[:len(data) - truncate] if truncate else data)
    return path


def _one_line(exc: pytest.ExceptionInfo, *needles):
    msg = str(exc.value)
    assert "\n" not in msg
    for s in needles:
        assert s in msg, msg
    return msg


# ------------------------------------------------------------------ OBJ


def test_obj_welds_atlas_seam_and_keeps_corner_texcoords(tmp_path):
    obj, tri_pos, expected_tc = _write_seam_obj(tmp_path)
    scan = load_scan(obj)
    assert isinstance(scan, LoadedScan)
    mesh = scan.mesh
    V, F = _grid()
    assert len(mesh.vertices) == len(np.unique(V, axis=0)) == 20  # file has 24 (4 seam duplicates)
    assert len(mesh.faces) == len(F)
    assert scan.report.duplicate_vertices_merged == 4
    assert scan.report.kept_component_area_fractions == (1.0,)  # one surface, not two charts
    assert scan.report.boundary_loops == 1
    assert mesh.texture_path == (tmp_path / "atlas.png").resolve() and mesh.texture_path.is_absolute()
    _assert_corner_texcoords(mesh, tri_pos, expected_tc)
    assert mesh.units == "mm" and mesh.source == obj.resolve()


def test_a_repeating_texture_is_read_in_its_one_image(tmp_path):
    """Texture coordinates past [0, 1] (the image repeats, as renderers read them): each face
    is moved by whole images into the first, so it reads its painting and not the image's
    border; a face across the border of two copies is counted in the warning; coordinates
    already in the image are untouched."""
    _png(tmp_path / "t.png")
    (tmp_path / "t.mtl").write_text("newmtl m\nmap_Kd t.png\n")
    head = "mtllib t.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 2 0 0\nv 0 2 0\n"
    inside = "vt 0.1 0.2\nvt 0.4 0.2\nvt 0.1 0.6\nvt 0.4 0.6\nvt 0.9 0.2\nvt 0.1 0.9\n"
    faces = "f 1/1 2/2 3/3\nf 2/2 4/4 3/3\nf 2/2 5/5 4/4\nf 3/3 4/4 6/6\n"
    (tmp_path / "a.obj").write_text(head + inside + faces)
    plain = load_scan(tmp_path / "a.obj", clean=False)
    assert not any("repeating" in w for w in plain.report.warnings)

    moved = "".join(f"vt {u + 3:g} {v - 2:g}\n" for u, v in [(0.1, 0.2), (0.4, 0.2), (0.1, 0.6), (0.4, 0.6),
                                                           (0.9, 0.2), (0.1, 0.9)])
    (tmp_path / "b.obj").write_text(head + moved + faces)
    tiled = load_scan(tmp_path / "b.obj", clean=False)
    assert np.allclose(tiled.mesh.texcoords, plain.mesh.texcoords, atol=1e-12)
    assert any("4 faces were moved" in w for w in tiled.report.warnings)

    across = "vt 0.1 0.2\nvt 0.4 0.2\nvt 0.1 0.6\nvt 0.4 0.6\nvt 2.5 0.2\nvt 0.1 0.9\n"  # face 3: centre at u 1.1
    (tmp_path / "c.obj").write_text(head + across + faces)
    straddling = load_scan(tmp_path / "c.obj", clean=False)
    assert any("1 faces were moved" in w and "1 faces cross its border" in w for w in straddling.report.warnings)
    centres = straddling.mesh.texcoords.mean(axis=1)
    assert (centres >= 0.0).all() and (centres < 1.0).all()


def test_obj_negative_indices_polygons_and_slash_forms(tmp_path):
    text = """# a unit cube as quads, relative indices, v//vn and v/vt/vn forms
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
vn 0 0 1
f -8//1 -5//1 -6//1 -7//1
f 5 6 7 8
f 1 2 6 5
f 2 3 7 6
f 3 4 8 7
f 4 1 5 8
"""
    (tmp_path / "cube.obj").write_text(text)
    scan = load_scan(tmp_path / "cube.obj")
    assert scan.report.polygons_triangulated == 6
    assert len(scan.mesh.vertices) == 8 and len(scan.mesh.faces) == 12
    assert scan.report.boundary_loops == 0 and scan.report.orientation_conflicts == 0
    import trimesh

    tm = trimesh.Trimesh(scan.mesh.vertices, scan.mesh.faces, process=False)
    assert tm.is_winding_consistent and tm.volume == pytest.approx(1.0)  # outward


def test_obj_crlf_tabs_bom_comments(tmp_path):
    obj, tri_pos, expected_tc = _write_seam_obj(tmp_path)
    text = obj.read_text().replace(" ", "\t").replace("\n", "  # note\r\n")
    text = text.replace("mtllib\tseam.mtl  # note", "mtllib seam.mtl")  # names keep their spaces
    text = text.replace("usemtl\tpaint  # note", "usemtl paint")
    obj.write_bytes(b"\xef\xbb\xbf" + text.encode())
    mesh = load_scan(obj).mesh
    assert len(mesh.vertices) == 20
    _assert_corner_texcoords(mesh, tri_pos, expected_tc)


def test_obj_texture_named_windows_style(tmp_path):
    obj, tri_pos, expected_tc = _write_seam_obj(tmp_path)
    (tmp_path / "seam.mtl").write_text("newmtl paint\nmap_Kd C:\\Users\\someone\\scan\\ATLAS.PNG\n")
    mesh = load_scan(obj).mesh
    assert mesh.texture_path == (tmp_path / "atlas.png").resolve()
    _assert_corner_texcoords(mesh, tri_pos, expected_tc)


@pytest.mark.parametrize("suffix", ["tga", "dds"])
def test_obj_texture_opencv_does_not_read_is_converted_to_png(tmp_path, suffix):
    """A texture in a format Pillow reads and OpenCV (the decoder of every stage) does not,
    as older exports and game-engine assets have them (TGA, DDS): loaded as a PNG of its
    pixels, which every stage decodes."""
    from PIL import Image

    from potflat.io.images import read_texture

    obj, tri_pos, expected_tc = _write_seam_obj(tmp_path)
    pixels = np.random.default_rng(3).integers(0, 256, (16, 24, 3), dtype=np.uint8)
    Image.fromarray(pixels).save(tmp_path / f"atlas.{suffix}")
    (tmp_path / "seam.mtl").write_text(f"newmtl paint\nmap_Kd atlas.{suffix}\n")
    mesh = load_scan(obj).mesh
    assert mesh.texture_path.suffix == ".png"
    np.testing.assert_array_equal(read_texture(mesh.texture_path), pixels)
    _assert_corner_texcoords(mesh, tri_pos, expected_tc)


def test_obj_texture_in_a_cut_short_tga_is_refused_in_one_line(tmp_path):
    from PIL import Image

    obj, _, _ = _write_seam_obj(tmp_path)
    Image.fromarray(np.full((64, 64, 3), 90, np.uint8)).save(tmp_path / "atlas.tga", compression=None)
    data = (tmp_path / "atlas.tga").read_bytes()
    (tmp_path / "atlas.tga").write_bytes(data[:len(data) // 2])
    (tmp_path / "seam.mtl").write_text("newmtl paint\nmap_Kd atlas.tga\n")
    with pytest.raises(InvalidInputError) as e:
        load_scan(obj)
    _one_line(e, "atlas.tga", "cannot be decoded", "PNG or JPEG", "--no-texture")


def test_obj_vertex_colours_and_untextured(tmp_path):
    V, F = _grid()
    rgb = (V[:, :1] * 0 + [0.0, 0.5, 1.0])
    lines = [f"v {x} {y} {z} {r} {g} {b}" for (x, y, z), (r, g, b) in zip(V, rgb)]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F]
    (tmp_path / "col.obj").write_text("\n".join(lines) + "\n")
    mesh = load_scan(tmp_path / "col.obj").mesh
    assert mesh.texcoords is None and mesh.texture_path is None
    np.testing.assert_array_equal(mesh.vertex_colors[0], [0, 128, 255, 255])


def test_obj_same_texture_in_two_materials_is_one_atlas(tmp_path):
    obj, tri_pos, expected_tc = _write_seam_obj(tmp_path)
    text = obj.read_text().splitlines()
    k = next(i for i, ln in enumerate(text) if ln.startswith("f "))
    text.insert(k + 3, "usemtl paint2")
    obj.write_text("\n".join(text) + "\n")
    (tmp_path / "seam.mtl").write_text("newmtl paint\nmap_Kd atlas.png\nnewmtl paint2\nmap_Kd atlas.png\n")
    mesh = load_scan(obj).mesh
    _assert_corner_texcoords(mesh, tri_pos, expected_tc)


def test_obj_float_parser_matches_python(tmp_path):
    from potflat.io.obj import parse_obj

    rng = np.random.default_rng(3)
    vals = np.concatenate([rng.normal(0, 1e3, 60), rng.normal(0, 1e-4, 30), [0.0, -0.0, 1e-300, 123456789.0]])
    texts = [repr(float(x)) for x in vals] + ["1e5", "-2.5E-3", "+7", ".5", "5.", "3.14159265358979323846"]
    lines = []
    for i in range(0, len(texts) - 2, 3):
        lines.append("v " + " ".join(texts[i:i + 3]))
    buf = np.frombuffer(("\n".join(lines) + "\n").encode(), np.uint8)
    V = parse_obj(buf)[0][:, :3]
    want = np.array([[float(t) for t in ln.split()[1:]] for ln in lines])
    np.testing.assert_allclose(V, want, rtol=1e-15, atol=0)  # within a few ulp


def _obj_of_every_kind(rng) -> bytes:
    """OBJ text with every kind of line the parser reads (relative indices, polygons, materials,
    comments, blank and CRLF lines, bad numbers), in random order of blocks."""
    lines, nv, nvt = ["# made by a test", "mtllib a.mtl", ""], 0, 0
    for block in range(300):
        kind = rng.integers(6)
        if kind == 0 or nv < 4:
            for _ in range(rng.integers(1, 6)):
                lines.append("v " + " ".join(f"{x:.6g}" for x in rng.normal(size=rng.choice([3, 6]))))
                nv += 1
        elif kind == 1:
            lines.append(f"vt {rng.random():.5f} {rng.random():.5f}\r")
            nvt += 1
        elif kind == 2:  # polygons, absolute and relative corners, some with texture indices
            k = int(rng.integers(3, 6))
            corners = [int(rng.integers(1, nv + 1)) if rng.random() < 0.5 else -int(rng.integers(1, nv + 1))
                       for _ in range(k)]
            tex = [f"/{-int(rng.integers(1, nvt + 1))}" if nvt and rng.random() < 0.5 else "" for _ in range(k)]
            lines.append("f " + " ".join(f"{c}{t}" for c, t in zip(corners, tex)) + "  # a comment")
        elif kind == 3:
            lines.append(f"usemtl m{block}  ")
        elif kind == 4:
            lines.append(rng.choice(["", "   ", "# note", "g group", "s off", "vn 0 0 1"]))
        else:
            lines.append("v 1 2 x3" if rng.random() < 0.3 else "f 0 1 2")  # a bad number, a zero index
    return ("\n".join(lines) + "\n").encode()


def test_obj_ranges_parse_like_one_range():
    from potflat.io.obj import parse_obj

    rng = np.random.default_rng(11)
    for text in (_obj_of_every_kind(rng), _obj_of_every_kind(rng)[:-1], b"v 0 0 0", b""):
        buf = np.frombuffer(text, np.uint8)
        whole = parse_obj(buf, ranges=1)
        for ranges in (2, 3, 7, 64):
            for got, want in zip(parse_obj(buf, ranges=ranges), whole):
                np.testing.assert_array_equal(got, want)
    assert whole[-1] == 0 and parse_obj(np.frombuffer(_obj_of_every_kind(rng), np.uint8), ranges=5)[-1] > 0


# ------------------------------------------------------------------ PLY


@pytest.mark.parametrize("binary,endian", [(True, "<"), (True, ">"), (False, "<")])
def test_ply_face_texcoord_texturefile_roundtrip(tmp_path, binary, endian):
    V, F = _grid()
    tc = _uv_of(V[F])  # (m, 3, 2)
    _png(tmp_path / "tex.png")
    ply = _write_ply(tmp_path / "s.ply", V, F.tolist(), binary=binary, endian=endian,
                     texcoord=tc.reshape(-1, 6).tolist(), comments=["TextureFile tex.png"])
    mesh = load_scan(ply).mesh
    assert mesh.texture_path == (tmp_path / "tex.png").resolve()
    _assert_corner_texcoords(mesh, V[F], tc)  # float32 in binary files


@pytest.mark.parametrize("binary", [True, False])
def test_ply_mixed_polygons_variable_lists(tmp_path, binary):
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0]], float)
    faces = [[0, 1, 2, 3], [1, 4, 5], [1, 5, 2]]
    scan = load_scan(_write_ply(tmp_path / "p.ply", V, faces, binary=binary), min_faces=1)
    assert scan.report.polygons_triangulated == 1
    assert len(scan.mesh.faces) == 4


@pytest.mark.parametrize("names", [("texture_u", "texture_v"), ("s", "t")])
def test_ply_vertex_uv(tmp_path, names):
    V, F = _grid()
    uv = _uv_of(V)
    _png(tmp_path / "t.png")
    ply = _write_ply(tmp_path / "uv.ply", V, F.tolist(), vprops=[(names[0], "float"), (names[1], "float")],
                     vextra=uv.tolist(), comments=["TextureFile t.png"])
    mesh = load_scan(ply).mesh
    np.testing.assert_allclose(mesh.texcoords, _uv_of(mesh.vertices[mesh.faces]), atol=1e-6)


def test_ply_vertex_colours(tmp_path):
    V, F = _grid()
    cols = [[10, 20, 30]] * len(V)
    ply = _write_ply(tmp_path / "c.ply", V, F.tolist(),
                     vprops=[("red", "uchar"), ("green", "uchar"), ("blue", "uchar")], vextra=cols)
    mesh = load_scan(ply).mesh
    assert mesh.texcoords is None
    np.testing.assert_array_equal(mesh.vertex_colors, np.tile([10, 20, 30, 255], (len(mesh.vertices), 1)))


def test_ply_declared_units_and_override(tmp_path):
    V, F = _grid()
    ply = _write_ply(tmp_path / "u.ply", V, F.tolist(), comments=["units cm"])
    assert load_scan(ply).mesh.units == "cm"
    scan = load_scan(ply, units="m")
    assert scan.mesh.units == "m" and any("declares units" in w for w in scan.report.warnings)


# ------------------------------------------------------------------ STL, OFF, GLB


def _trimesh_half_cylinder():
    import trimesh

    V, F = _grid()
    return trimesh.Trimesh(V, F, process=False)


def test_stl_soup_is_welded(tmp_path):
    tm = _trimesh_half_cylinder()
    tm.export(tmp_path / "h.stl")
    scan = load_scan(tmp_path / "h.stl")
    assert len(scan.mesh.vertices) == 20 and len(scan.mesh.faces) == 24
    assert scan.report.duplicate_vertices_merged == 3 * 24 - 20
    assert scan.report.kept_component_area_fractions == (1.0,)


def test_glb_mesh_without_texcoords_is_flagged_untextured(tmp_path):
    """A scene of a textured mesh and one without TEXCOORD_0: the second's faces are flagged."""
    import trimesh
    from PIL import Image

    V, F = _grid()
    Vs, Fs = V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3)
    textured = trimesh.Trimesh(Vs, Fs, process=False, visual=trimesh.visual.TextureVisuals(
        uv=_uv_of(Vs), image=Image.new("RGB", (16, 16), (1, 2, 3))))
    plain = trimesh.Trimesh(Vs + [0.0, 0.0, 2.0], Fs, process=False)  # the grid again, above the first
    trimesh.Scene([textured, plain]).export(tmp_path / "h.glb")
    scan = load_scan(tmp_path / "h.glb")
    mesh = scan.mesh
    assert mesh.texcoords is not None and mesh.untextured_faces is not None
    upper = mesh.vertices[mesh.faces].mean(axis=1)[:, 2] > 2.0
    np.testing.assert_array_equal(mesh.untextured_faces, upper)
    assert any(w.startswith(f"{len(F)} faces (meshes without TEXCOORD_0)") for w in scan.report.warnings)


def test_gltf_files_named_with_percent_encoded_uris_are_found(tmp_path):
    """glTF URIs are percent-encoded (Blender writes ``my scan.bin`` as ``my%20scan.bin``):
    a .gltf whose buffers and texture image have spaces in their names, named encoded, loads
    with its texture, as one naming them as they are."""
    import json

    import trimesh
    from PIL import Image

    V, F = _grid()
    Vs, Fs = V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3)
    visual = trimesh.visual.TextureVisuals(uv=_uv_of(Vs), image=Image.new("RGB", (16, 16), (200, 30, 20)))
    files = trimesh.Scene([trimesh.Trimesh(Vs, Fs, process=False, visual=visual)]).export(file_type="gltf")
    doc = json.loads(files.pop("model.gltf"))
    for k, buffer in enumerate(doc["buffers"]):
        (tmp_path / f"my scan {k}.bin").write_bytes(files[buffer["uri"]])
    image = doc["images"][0]
    view = doc["bufferViews"][image.pop("bufferView")]
    blob = files[doc["buffers"][view["buffer"]]["uri"]]
    (tmp_path / "my colours.png").write_bytes(blob[view.get("byteOffset", 0):][:view["byteLength"]])
    for encoded in (True, False):
        for k, buffer in enumerate(doc["buffers"]):
            buffer["uri"] = f"my%20scan%20{k}.bin" if encoded else f"my scan {k}.bin"
        image["uri"] = "my%20colours.png" if encoded else "my colours.png"
        (tmp_path / "pot.gltf").write_text(json.dumps(doc))
        mesh = load_scan(tmp_path / "pot.gltf").mesh
        assert len(mesh.faces) == len(F) and mesh.texcoords is not None
        assert _sample(Image.open(mesh.texture_path).convert("RGB"), mesh.texcoords[0].mean(axis=0)) == (200, 30, 20)


def _glb_of_materials(path: Path, images: list) -> None:
    """A GLB of the test grid once per image, the k-th 3 k above the first, each with its own
    material and texture image (None: a material without one)."""
    import trimesh

    V, F = _grid()
    Vs, Fs = V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3)
    visuals = [trimesh.visual.TextureVisuals(uv=_uv_of(Vs), image=im) if im is not None else
               trimesh.visual.TextureVisuals(uv=_uv_of(Vs), material=trimesh.visual.material.PBRMaterial())
               for im in images]
    trimesh.Scene([trimesh.Trimesh(Vs + [0.0, 0.0, 3.0 * k], Fs, process=False, visual=visual)
                   for k, visual in enumerate(visuals)]).export(path)


def test_glb_with_a_texture_per_material_is_packed_into_one_atlas(tmp_path):
    """A GLB with a material per texture image (as photogrammetry exports a large scan): each
    mesh samples its own image in the packed atlas; a mesh whose image has the same pixels as
    another's shares its cell; a mesh whose material has no image is flagged untextured."""
    from PIL import Image

    colours, sizes = [(200, 30, 20), (20, 40, 220), (200, 30, 20)], [(16, 8), (16, 16), (16, 8)]
    _glb_of_materials(tmp_path / "multi.glb", [Image.new("RGB", size, c) for c, size in zip(colours, sizes)] + [None])
    scan = load_scan(tmp_path / "multi.glb")
    mesh = scan.mesh
    assert any(w.startswith("2 texture images") and "packed into one 32 x 16 atlas" in w
               for w in scan.report.warnings), scan.report.warnings
    atlas = Image.open(mesh.texture_path).convert("RGB")
    level = (mesh.vertices[mesh.faces].mean(axis=1)[:, 2] // 3.0).astype(int)  # the part: 0-3
    np.testing.assert_array_equal(mesh.untextured_faces, level == 3)
    for f in np.flatnonzero(level < 3):
        centre = mesh.texcoords[f].mean(axis=0)
        assert _sample(atlas, centre) == colours[level[f]], (f, level[f])


def test_glb_with_specular_glossiness_materials_packs_their_diffuse_images(tmp_path):
    """Materials of the older specular-glossiness kind (KHR_materials_pbrSpecularGlossiness, as
    older Sketchfab exports have them), one image each: each mesh samples its diffuse image as
    the file holds it (trimesh's conversion to a base colour made them white)."""
    from PIL import Image

    colours = [(200, 10, 10), (10, 10, 200)]
    _glb_of_materials(tmp_path / "sg.glb", [Image.new("RGB", (8, 8), c) for c in colours])

    def to_gloss(doc):
        for material in doc["materials"]:
            texture = material.pop("pbrMetallicRoughness")["baseColorTexture"]
            material["extensions"] = {"KHR_materials_pbrSpecularGlossiness": {"diffuseTexture": texture}}

    _edit_glb(tmp_path / "sg.glb", to_gloss)
    mesh = load_scan(tmp_path / "sg.glb").mesh
    atlas = Image.open(mesh.texture_path).convert("RGB")
    level = (mesh.vertices[mesh.faces].mean(axis=1)[:, 2] // 3.0).astype(int)
    for f in range(len(mesh.faces)):
        assert _sample(atlas, mesh.texcoords[f].mean(axis=0)) == colours[level[f]], (f, level[f])


def test_glb_with_a_corrupt_texture_among_several_is_refused_in_one_line(tmp_path):
    from PIL import Image

    _glb_of_materials(tmp_path / "multi.glb", [Image.new("RGB", (16, 16), (90 * k, 0, 0)) for k in range(2)])
    data = bytearray((tmp_path / "multi.glb").read_bytes())
    second = data.index(b"\x89PNG", data.index(b"\x89PNG") + 1)
    data[second + 16:second + 24] = b"\xff" * 8  # the second image's size: past any limit
    (tmp_path / "multi.glb").write_bytes(bytes(data))
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "multi.glb")
    _one_line(e, "multi.glb", "texture", "--no-texture")


def test_glb_texture_of_a_material_over_the_pixel_limit_is_refused(tmp_path):
    from PIL import Image

    _glb_of_materials(tmp_path / "multi.glb", [Image.new("RGB", (64, 64), (50 * k, 0, 0)) for k in range(2)])
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "multi.glb", max_texture_pixels=1000)
    _one_line(e, "multi.glb")
    assert "64 x 64 pixels, over the limit of 1000" in str(e.value)


def _write_glb(path: Path, doc: dict, blob: bytes) -> None:
    """A GLB of the glTF JSON ``doc`` and the binary chunk ``blob`` (its buffer 0)."""
    import json

    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    blob += b"\0" * (-len(blob) % 4)
    body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(blob), 0x004E4942) + blob
    path.write_bytes(struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body)


def _quantized_glb(path: Path, *, transform: bool, extensions: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The test grid as gltfpack and gltf-transform store a scan: positions as normalized
    shorts dequantized by the node's scale and translation, texture coordinates as normalized
    unsigned shorts (with ``transform`` in a quarter of their range, dequantized by the
    texture's KHR_texture_transform); returns the grid's positions and texture coordinates
    (glTF's v down) as stored, dequantized."""
    from PIL import Image
    import io

    V, F = _grid()
    lo, hi = V.min(axis=0), V.max(axis=0)
    centre, half = (lo + hi) / 2, float((hi - lo).max()) / 2
    pos = np.rint((V - centre) / half * 32767).astype("<i2")
    tc = _uv_of(V) * [0.5, 0.5] + [0.5, 0.25]  # within [0, 1]
    offset, scale = np.array([0.125, 0.0625]), np.array([4.0, 4.0])
    stored = (tc - offset) / scale if transform else tc
    quant = np.rint(stored * 65535).astype("<u2")
    png = io.BytesIO()
    Image.new("RGB", (8, 8), (10, 20, 30)).save(png, format="PNG")
    parts = [np.ascontiguousarray(np.hstack([pos, np.zeros((len(V), 1), "<i2")])).tobytes(),  # 8-byte stride
             quant.tobytes(), F.astype("<u4").tobytes(), png.getvalue()]
    offsets = np.cumsum([0] + [len(b) + (-len(b) % 4) for b in parts])
    blob = b"".join(b + b"\0" * (-len(b) % 4) for b in parts)
    texture = {"index": 0}
    if transform:
        texture["extensions"] = {"KHR_texture_transform": {"offset": list(offset), "scale": list(scale)}}
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "translation": list(centre), "scale": [half] * 3}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2, "material": 0}]}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": texture}}],
        "textures": [{"source": 0}], "images": [{"bufferView": 3, "mimeType": "image/png"}],
        "buffers": [{"byteLength": len(blob)}],
        "bufferViews": [{"buffer": 0, "byteOffset": int(offsets[0]), "byteLength": len(parts[0]), "byteStride": 8},
                        {"buffer": 0, "byteOffset": int(offsets[1]), "byteLength": len(parts[1])},
                        {"buffer": 0, "byteOffset": int(offsets[2]), "byteLength": len(parts[2])},
                        {"buffer": 0, "byteOffset": int(offsets[3]), "byteLength": len(parts[3])}],
        "accessors": [{"bufferView": 0, "componentType": 5122, "normalized": True, "count": len(V), "type": "VEC3"},
                      {"bufferView": 1, "componentType": 5123, "normalized": True, "count": len(V), "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5125, "count": F.size, "type": "SCALAR"}],
        "extensionsUsed": ["KHR_mesh_quantization"] + (["KHR_texture_transform"] if transform else []),
        "extensionsRequired": ["KHR_mesh_quantization"],
    }
    doc.update(extensions or {})
    _write_glb(path, doc, blob)
    return np.maximum(pos / 32767, -1) * half + centre, quant / 65535 * (scale if transform else 1) + (
        offset if transform else 0)


@pytest.mark.parametrize("transform", [False, True], ids=["normalized", "normalized+transform"])
def test_quantized_glb_is_read_at_its_true_size_and_texture_place(tmp_path, transform):
    """trimesh reads normalized integers as the integers (positions 32767 times too large,
    texture coordinates wrapped around) and leaves texture transforms out: the scan, its size
    and its texture coordinates come out as the file means them."""
    xyz, tc = _quantized_glb(tmp_path / "q.glb", transform=transform)
    mesh = load_scan(tmp_path / "q.glb").mesh
    assert len(mesh.vertices) == len(xyz)
    k = [int(np.argmin(np.linalg.norm(xyz - v, axis=1))) for v in mesh.vertices]
    np.testing.assert_allclose(mesh.vertices, xyz[k], atol=1e-12)
    np.testing.assert_allclose(np.ptp(mesh.vertices, axis=0), np.ptp(_grid()[0], axis=0), atol=1e-4)
    want = np.column_stack([tc[k][:, 0], 1.0 - tc[k][:, 1]])[mesh.faces]  # (v up, as potflat keeps them)
    np.testing.assert_allclose(mesh.texcoords, want, atol=1e-12)


def _second_set(doc: dict, *, through_transform: bool = False) -> None:
    """The quantized grid's texture coordinates moved to TEXCOORD_1, which its base-colour
    texture names (``texCoord``, or its KHR_texture_transform's), and TEXCOORD_0 made other
    coordinates (the positions' x and y, as a lightmap's would be)."""
    attributes = doc["meshes"][0]["primitives"][0]["attributes"]
    doc["accessors"].append(dict(doc["accessors"][0], type="VEC2"))
    attributes["TEXCOORD_0"], attributes["TEXCOORD_1"] = len(doc["accessors"]) - 1, attributes["TEXCOORD_0"]
    texture = doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]
    if through_transform:
        texture["extensions"] = {"KHR_texture_transform": {"texCoord": 1}}
        doc["extensionsUsed"].append("KHR_texture_transform")
    else:
        texture["texCoord"] = 1


@pytest.mark.parametrize("through_transform", [False, True], ids=["texCoord", "transform"])
def test_glb_texture_on_its_second_texture_coordinates_is_read_from_them(tmp_path, through_transform):
    """trimesh reads TEXCOORD_0 whichever set the base-colour texture names: the set it names is read."""
    xyz, tc = _quantized_glb(tmp_path / "q.glb", transform=False)
    _edit_glb(tmp_path / "q.glb", lambda d: _second_set(d, through_transform=through_transform))
    mesh = load_scan(tmp_path / "q.glb").mesh
    k = [int(np.argmin(np.linalg.norm(xyz - v, axis=1))) for v in mesh.vertices]
    want = np.column_stack([tc[k][:, 0], 1.0 - tc[k][:, 1]])[mesh.faces]
    np.testing.assert_allclose(mesh.texcoords, want, atol=1e-12)


def test_glb_texture_on_texture_coordinates_its_mesh_lacks_is_refused_in_one_line(tmp_path):
    _quantized_glb(tmp_path / "q.glb", transform=False)
    _edit_glb(tmp_path / "q.glb", lambda d: d["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"].update(
        texCoord=2))
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "q.glb")
    _one_line(e, "q.glb", "TEXCOORD_2", "export the scan again")


def _edit_glb(path: Path, edit) -> None:
    """Rewrite the JSON of the GLB ``path`` by ``edit(doc)``."""
    import json

    data = path.read_bytes()
    (length,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20:20 + length])
    edit(doc)
    _write_glb(path, doc, data[28 + length:])


@pytest.mark.parametrize("edit, needles", [
    (lambda d: d["accessors"][1].update(sparse={"count": 1}), ["accessor 1 cannot be read", "without quantization"]),
    (lambda d: d["meshes"][0]["primitives"].append(dict(d["meshes"][0]["primitives"][0], mode=6)),
     ["cannot be matched", "without quantization"]),
    (lambda d: d["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"]["KHR_texture_transform"]
     .update(offset=["a", 0]), ["texture transform", "not numbers"]),
    (lambda d: d["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["extensions"]["KHR_texture_transform"]
     .update(scale=[float("inf"), 1.0]), ["texture transform", "not finite"]),
], ids=["sparse", "unmatched", "words", "infinite"])
def test_quantized_glb_that_cannot_be_read_is_refused_in_one_line(tmp_path, edit, needles):
    _quantized_glb(tmp_path / "q.glb", transform=True)
    _edit_glb(tmp_path / "q.glb", edit)
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "q.glb")
    _one_line(e, "q.glb", *needles)


@pytest.mark.parametrize("seed, edit, needles", [
    ("quantized", lambda d: d["accessors"][0].update(componentType=[1]), ["accessor 0", "corrupt"]),
    ("quantized", lambda d: d.update(scenes=1.5), ["cannot be read as GLB"]),
    ("quantized", lambda d: d["accessors"][1].update(type="VEC3"), ["accessor 1", "corrupt"]),
    ("plain", lambda d: d["accessors"][1].update(type="VEC2"), ["positions are not 3D points"]),
], ids=["component-type-a-list", "scenes-a-number", "texture-coordinates-3d", "positions-2d"])
def test_gltf_values_of_the_wrong_type_are_refused_in_one_line(tmp_path, seed, edit, needles):
    """Values where glTF has another type (from a hostile or broken exporter) give one line,
    not a Python error."""
    from PIL import Image

    if seed == "quantized":
        _quantized_glb(tmp_path / "h.glb", transform=True)
    else:  # (its accessor 1: the positions)
        _glb_of_materials(tmp_path / "h.glb", [Image.new("RGB", (8, 8), (1, 2, 3))])
    _edit_glb(tmp_path / "h.glb", edit)
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "h.glb")
    _one_line(e, "h.glb", *needles)


@pytest.mark.parametrize("extension, needles", [
    ("EXT_meshopt_compression", ["EXT_meshopt_compression", "cannot decode", "Draco"]),
    ("KHR_texture_basisu", ["KTX2", "PNG or JPEG", "--no-texture"]),
], ids=["meshopt", "ktx2"])
def test_glb_with_an_extension_potflat_cannot_decode_is_refused_in_one_line(tmp_path, extension, needles):
    """Meshoptimizer compression (gltfpack -c) and KTX2 textures, which no reader potflat has
    decodes; a scan with KTX2 textures loads untextured when asked."""
    _quantized_glb(tmp_path / "x.glb", transform=False,
                   extensions={"extensionsRequired": ["KHR_mesh_quantization", extension]})
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "x.glb")
    _one_line(e, "x.glb", *needles)
    if extension == "KHR_texture_basisu":
        assert load_scan(tmp_path / "x.glb", texture="ignore").mesh.texcoords is None


def test_glb_with_a_webp_texture_is_read(tmp_path):
    """A WebP texture (EXT_texture_webp, as gltf-transform writes web scans) is the texture."""
    import trimesh
    from PIL import Image

    V, F = _grid()
    Vs, Fs = V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3)
    tm = trimesh.Trimesh(Vs, Fs, process=False, visual=trimesh.visual.TextureVisuals(
        uv=_uv_of(Vs), image=Image.new("RGB", (16, 16), (40, 90, 160))))
    tm.export(tmp_path / "w.glb", extension_webp=True)
    scan = load_scan(tmp_path / "w.glb")
    assert not scan.report.warnings
    with Image.open(scan.mesh.texture_path) as im:
        assert im.format == "WEBP" and im.size == (16, 16)
    np.testing.assert_allclose(scan.mesh.texcoords, _uv_of(scan.mesh.vertices[scan.mesh.faces]), atol=1e-6)


def test_off(tmp_path):
    V, F = _grid()
    lines = ["OFF", f"{len(V)} {len(F)} 0"] + [f"{x} {y} {z}" for x, y, z in V] + [f"3 {a} {b} {c}" for a, b, c in F]
    (tmp_path / "h.off").write_text("\n".join(lines) + "\n")
    scan = load_scan(tmp_path / "h.off", units="cm")
    np.testing.assert_allclose(scan.mesh.vertices, V)  # true scale, no rescaling
    assert scan.mesh.units == "cm"


def test_glb_textured_via_trimesh(tmp_path):
    import trimesh
    from PIL import Image

    V, F = _grid()
    # split vertices per face, as glTF exporters do at seams
    Vs, Fs = V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3)
    uv = _uv_of(Vs)
    img = Image.new("RGB", (16, 16), (1, 2, 3))
    tm = trimesh.Trimesh(Vs, Fs, process=False,
                         visual=trimesh.visual.TextureVisuals(uv=uv, image=img))
    tm.export(tmp_path / "h.glb")
    scan = load_scan(tmp_path / "h.glb")
    mesh = scan.mesh
    assert mesh.units == "m"  # glTF is in metres by definition
    assert len(mesh.vertices) == 20
    np.testing.assert_allclose(mesh.texcoords, _uv_of(mesh.vertices[mesh.faces]), atol=1e-6)
    assert mesh.texture_path.is_file() and mesh.texture_path.is_relative_to(tmp_path)
    assert load_scan(tmp_path / "h.glb", texture="ignore").mesh.texcoords is None


# ------------------------------------------------------------------ real scans


@pytest.mark.parametrize("name", ["plastic-vase.ply", "sea-vase.ply", "goblet.stl"])
def test_real_scans_load_and_clean(real_scans, name):
    path = real_scans / name
    scan = load_scan(path)
    r = scan.report
    mesh = scan.mesh
    assert mesh.units == "mm"
    assert r.output_faces == (r.input_faces - r.degenerate_faces_removed - r.duplicate_faces_removed
                              - r.faces_in_removed_components) == len(mesh.faces)
    assert r.removed_area_fraction < 0.01  # only stray bits removed, the vessel intact
    assert r.kept_component_area_fractions[0] > 0.95
    assert r.orientation_conflicts == 0
    import json

    json.dumps(r.as_dict())
    if name == "goblet.stl":  # closed, designed: nothing to repair, outward
        import trimesh

        assert r.boundary_loops == 0 and r.duplicate_vertices_merged > 0
        assert trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).volume > 0
    else:  # open scans with holes and stray fragments
        assert r.boundary_loops > 1 and r.components_removed > 0


def test_real_scan_inverted_is_turned_outward(tmp_path, real_scans):
    path = real_scans / "sea-vase.ply"
    import trimesh

    tm = trimesh.load(path, process=False)
    trimesh.Trimesh(tm.vertices, tm.faces[:, ::-1], process=False).export(tmp_path / "inv.ply")
    a, b = load_scan(path), load_scan(tmp_path / "inv.ply")
    assert b.report.components_reversed_outward == 1
    assert not any("--keep-orientation" in w for w in b.report.warnings)  # (a vessel, not a sheet)
    np.testing.assert_allclose(b.mesh.vertices, a.mesh.vertices)
    na = np.cross(*(a.mesh.vertices[a.mesh.faces[:, 1:]] - a.mesh.vertices[a.mesh.faces[:, :1]]).transpose(1, 0, 2))
    nb = np.cross(*(b.mesh.vertices[b.mesh.faces[:, 1:]] - b.mesh.vertices[b.mesh.faces[:, :1]]).transpose(1, 0, 2))
    assert np.einsum("ij,ij->i", na, nb).min() > 0  # same winding as the original


# ------------------------------------------------------------------ options


def test_units_option_validation(tmp_path):
    obj, _, _ = _write_seam_obj(tmp_path)
    assert load_scan(obj, units="cm").mesh.units == "cm"
    with pytest.raises(InvalidOptionError, match="units"):
        load_scan(obj, units="ft")
    with pytest.raises(InvalidOptionError, match="texture"):
        load_scan(obj, texture="maybe")
    with pytest.raises(InvalidOptionError, match="max_texture_pixels"):
        load_scan(obj, max_texture_pixels=0)
    with pytest.raises(InvalidOptionError, match="min_faces"):
        load_scan(obj, min_faces=0)
    with pytest.raises(InvalidOptionError, match="min_component_fraction"):
        load_scan(obj, min_component_fraction=2.0)
    with pytest.raises(InvalidOptionError, match="tolerance"):
        load_scan(obj, weld_tolerance=-1.0)


def test_clean_false_only_welds(tmp_path):
    obj, _, _ = _write_seam_obj(tmp_path)
    scan = load_scan(obj, clean=False)
    assert not scan.report.cleaned and scan.report.duplicate_vertices_merged == 4
    assert len(scan.mesh.vertices) == 20


# ------------------------------------------------------------------ bad input


def test_missing_file(tmp_path):
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "nope.obj")
    _one_line(e, "nope.obj", "does not exist")


def test_directory(tmp_path):
    (tmp_path / "d.obj").mkdir()
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "d.obj")
    _one_line(e, "d.obj", "directory")


def test_empty_file(tmp_path):
    (tmp_path / "e.ply").write_bytes(b"")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "e.ply")
    _one_line(e, "e.ply", "empty")


def test_obj_without_faces(tmp_path):
    (tmp_path / "pts.obj").write_text("v 0 0 0\nv 1 0 0\n")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "pts.obj")
    _one_line(e, "pts.obj", "no faces")


def test_unknown_extension(tmp_path):
    (tmp_path / "s.xyz").write_text("1 2 3\n")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "s.xyz")
    _one_line(e, "s.xyz", ".obj")


@pytest.mark.parametrize("packing, needles", [
    ("zip", ("a zip archive holding pot.obj", "unzip it")),
    ("zip without a scan", ("a zip archive without a scan in it", ".obj")),
    ("damaged zip", ("a damaged zip archive",)),
    ("gzip", ("gzip-compressed", "gunzip")),
])
def test_a_packed_scan_says_how_to_unpack_it(tmp_path, packing, needles):
    """A museum portal's download, a zip of the scan and its textures (or a gzip-compressed
    scan), is named as what it is, with what is in it, in one line."""
    import gzip
    import zipfile

    obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
    path = tmp_path / ("pot.obj.gz" if packing == "gzip" else "pot.zip")
    if packing == "gzip":
        path.write_bytes(gzip.compress(obj.encode()))
    else:
        with zipfile.ZipFile(path, "w") as archive:
            archive.writestr("textures/pot.png", b"not read")
            if packing != "zip without a scan":
                archive.writestr("pot.obj", obj)
        if packing == "damaged zip":
            path.write_bytes(path.read_bytes()[:60])
    with pytest.raises(InvalidInputError) as e:
        load_scan(path)
    _one_line(e, path.name, *needles)


@pytest.mark.parametrize("cut", [7, 200])
def test_truncated_binary_ply(tmp_path, cut):
    V, F = _grid()
    ply = _write_ply(tmp_path / "t.ply", V, F.tolist(), truncate=cut)
    with pytest.raises(InvalidInputError) as e:
        load_scan(ply)
    _one_line(e, "t.ply", "truncated")


def test_truncated_ascii_ply(tmp_path):
    V, F = _grid()
    ply = _write_ply(tmp_path / "t.ply", V, F.tolist(), binary=False)
    ply.write_text(ply.read_text()[:-30])
    with pytest.raises(InvalidInputError) as e:
        load_scan(ply)
    _one_line(e, "t.ply", "truncated")


def test_ply_header_errors(tmp_path):
    (tmp_path / "a.ply").write_bytes(b"solid x\n")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "a.ply")
    _one_line(e, "a.ply", "not a PLY")
    (tmp_path / "b.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\n")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "b.ply")
    _one_line(e, "b.ply", "end_header")
    (tmp_path / "c.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty quux x\nend_header\n1\n")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "c.ply")
    _one_line(e, "c.ply", "header")


def test_ply_point_cloud(tmp_path):
    (tmp_path / "pc.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\n"
                                      b"property float y\nproperty float z\nend_header\n0 0 0\n1 1 1\n")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "pc.ply")
    _one_line(e, "pc.ply", "no faces")


def test_ascii_ply_junk(tmp_path):
    V, F = _grid()
    ply = _write_ply(tmp_path / "j.ply", V, F.tolist(), binary=False)
    ply.write_text(ply.read_text().replace("\n3 ", "\n3 x", 1))
    with pytest.raises(InvalidInputError) as e:
        load_scan(ply)
    _one_line(e, "j.ply", "not a number")


@pytest.mark.parametrize("face", ["f 1 2 9", "f 1 2 0", "f -1 -2 -9", "f 1/7 2/1 3/1"])
def test_obj_faces_point_at_missing_vertices(tmp_path, face):
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1 2 3\n" + face + "\n")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "m.obj")
    _one_line(e, "m.obj", "do")


def test_obj_bad_number(tmp_path):
    (tmp_path / "n.obj").write_text("v 0 0 0\nv 1 0 zero\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "n.obj")
    _one_line(e, "n.obj", "line 2")


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf"])
def test_non_finite_coordinates_obj(tmp_path, bad):
    V, F = _grid()
    lines = [f"v {x} {y} {z}" for x, y, z in V] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in F]
    lines[3] = f"v 0 {bad} 1"
    (tmp_path / "nan.obj").write_text("\n".join(lines) + "\n")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "nan.obj")
    _one_line(e, "nan.obj", "NaN or infinite")


def test_non_finite_coordinates_ply(tmp_path):
    V, F = _grid()
    V[2, 1] = np.inf
    with pytest.raises(InvalidInputError) as e:
        load_scan(_write_ply(tmp_path / "inf.ply", V, F.tolist()))
    _one_line(e, "inf.ply", "NaN or infinite")


def test_single_triangle(tmp_path):
    (tmp_path / "one.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "one.obj")
    _one_line(e, "one.obj", "at least 4")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "one.obj", clean=False)
    _one_line(e, "one.obj", "at least 4")


def test_all_faces_degenerate(tmp_path):
    lines = [f"v {i} {2 * i} 0" for i in range(6)] + ["f 1 2 3", "f 2 3 4", "f 4 5 6", "f 1 1 2", "f 1 3 6"]
    (tmp_path / "flat.obj").write_text("\n".join(lines) + "\n")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "flat.obj")
    _one_line(e, "flat.obj", "degenerate")


def test_missing_texture_file(tmp_path):
    obj, _, _ = _write_seam_obj(tmp_path)
    (tmp_path / "atlas.png").unlink()
    with pytest.raises(InvalidInputError) as e:
        load_scan(obj)
    _one_line(e, "seam.obj", "atlas.png", "not found", "--no-texture")
    scan = load_scan(obj, texture="ignore")
    assert scan.mesh.texcoords is None and len(scan.mesh.vertices) == 20


def test_texture_name_with_a_nul_character_is_refused_in_one_line(tmp_path):
    """A corrupt MTL whose map_Kd names a file with a NUL character (no file can have it)."""
    obj, _, _ = _write_seam_obj(tmp_path)
    mtl = tmp_path / "seam.mtl"
    mtl.write_bytes(mtl.read_bytes().replace(b"atlas.png", b"at\x00las.png"))
    with pytest.raises(InvalidInputError) as e:
        load_scan(obj)
    _one_line(e, "seam.obj", "no file name", "--no-texture")


def test_missing_material_library(tmp_path):
    obj, _, _ = _write_seam_obj(tmp_path, texture=False)
    with pytest.raises(InvalidInputError) as e:
        load_scan(obj)
    _one_line(e, "seam.obj", "seam.mtl", "not found")


def test_corrupt_texture(tmp_path):
    obj, _, _ = _write_seam_obj(tmp_path)
    (tmp_path / "atlas.png").write_bytes(b"\x89PNG\r\n\x1a\n garbage, not an image")
    with pytest.raises(InvalidInputError) as e:
        load_scan(obj)
    _one_line(e, "seam.obj", "atlas.png", "not a readable image")


def test_texture_with_bad_crc(tmp_path):
    obj, _, _ = _write_seam_obj(tmp_path)
    png = bytearray((tmp_path / "atlas.png").read_bytes())
    png[-20] ^= 0xFF  # damage the last chunks
    (tmp_path / "atlas.png").write_bytes(bytes(png))
    with pytest.raises(InvalidInputError) as e:
        load_scan(obj)
    _one_line(e, "atlas.png", "not a readable image")


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def test_texture_decompression_bomb(tmp_path):
    obj, _, _ = _write_seam_obj(tmp_path)
    ihdr = struct.pack(">IIBBBBB", 100_000, 100_000, 8, 0, 0, 0, 0)  # 10 gigapixels declared
    png = b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", zlib.compress(b"\0" * 64)) + _chunk(b"IEND", b"")
    (tmp_path / "atlas.png").write_bytes(png)
    with pytest.raises(InvalidInputError) as e:
        load_scan(obj)
    _one_line(e, "atlas.png", "100000 x 100000", "decompression bomb", "--no-texture")
    # the limit is configurable: a small genuine texture over a tiny limit is refused too
    _png(tmp_path / "atlas.png", (64, 64))
    with pytest.raises(InvalidInputError):
        load_scan(obj, max_texture_pixels=100)
    assert load_scan(obj).mesh.texture_path is not None


def _sample(img, uv):
    """Colour of an image at OBJ-convention texture coordinates (nearest pixel)."""
    w, h = img.size
    x = min(int(uv[0] * w), w - 1)
    y = min(int((1.0 - uv[1]) * h), h - 1)
    return img.getpixel((x, y))[:3]


def _paint(path, size, colours):
    """An image whose left and right halves have two colours."""
    from PIL import Image

    im = Image.new("RGB", size, colours[0])
    im.paste(Image.new("RGB", (size[0] // 2, size[1]), colours[1]), (size[0] // 2, 0))
    im.save(path)


def test_several_texture_images_packed_into_one_atlas(tmp_path):
    from PIL import Image

    obj, tri_pos, expected_tc = _write_seam_obj(tmp_path)
    text = obj.read_text().splitlines()
    k = next(i for i, ln in enumerate(text) if ln.startswith("f "))
    text.insert(k + 3, "usemtl other")  # faces 3, 4, ... use the second image
    obj.write_text("\n".join(text) + "\n")
    (tmp_path / "seam.mtl").write_text("newmtl paint\nmap_Kd atlas.png\nnewmtl other\nmap_Kd b.png\n")
    _paint(tmp_path / "atlas.png", (16, 8), [(255, 0, 0), (0, 255, 0)])
    _paint(tmp_path / "b.png", (8, 12), [(0, 0, 255), (255, 255, 0)])
    scan = load_scan(obj)
    mesh = scan.mesh
    assert any("2 texture images" in w and "packed" in w for w in scan.report.warnings)
    assert Image.open(mesh.texture_path).size == (32, 12)  # two 16 x 12 cells side by side
    # image 0 in the left cell (16 x 8 at the top), image 1 in the right cell (8 x 12)
    want = expected_tc.copy()
    first = np.arange(len(want)) < 3
    want[first, :, 0] = expected_tc[first, :, 0] * 16 / 32
    want[first, :, 1] = 1 - (1 - expected_tc[first, :, 1]) * 8 / 12
    want[~first, :, 0] = (16 + expected_tc[~first, :, 0] * 8) / 32
    _assert_corner_texcoords(mesh, tri_pos, want)
    assert load_scan(obj, texture="ignore").mesh.texture_path is None
    assert load_scan(obj).mesh.texture_path == mesh.texture_path  # made once, then reused
    (tmp_path / "b.png").write_bytes(b"not an image")
    with pytest.raises(InvalidInputError) as e:
        load_scan(obj)
    _one_line(e, "b.png", "not a readable image")


def _write_texnumber_ply(path, V, F, tc, textures, which):
    """An ascii PLY naming the ``textures`` in comments, with per-face texture coordinates
    ``tc`` (m, 3, 2) and each face's ``texnumber`` ``which`` (m,) int (-1: no texture)."""
    head = ["ply", "format ascii 1.0", *[f"comment TextureFile {n}" for n in textures],
            f"element vertex {len(V)}", "property float x", "property float y", "property float z",
            f"element face {len(F)}", "property list uchar int vertex_indices", "property list uchar float texcoord",
            "property int texnumber", "end_header"]
    rows = [" ".join(map(str, v)) for v in V]
    rows += [f"3 {a} {b} {c} 6 " + " ".join(map(str, tc[f].ravel())) + f" {which[f]}" for f, (a, b, c) in enumerate(F)]
    path.write_text("\n".join(head + rows) + "\n")


def test_ply_texnumber_atlas_colours(tmp_path):
    from PIL import Image

    V, F = _grid()
    # each face samples the middle of the left half of its image: red in image 0, blue in image 1
    tc = np.tile([0.25, 0.5], (len(F), 3, 1))
    _paint(tmp_path / "t0.png", (8, 8), [(255, 0, 0), (0, 255, 0)])
    _paint(tmp_path / "t1.png", (4, 16), [(0, 0, 255), (255, 255, 0)])
    which = np.arange(len(F)) % 2
    _write_texnumber_ply(tmp_path / "tn.ply", V, F, tc, ["t0.png", "t1.png"], which)
    mesh = load_scan(tmp_path / "tn.ply").mesh
    atlas = Image.open(mesh.texture_path)
    assert atlas.size == (16, 16)
    ref = _match_faces(mesh, V[F])
    for f, r in enumerate(ref):
        want = (255, 0, 0) if which[r] == 0 else (0, 0, 255)
        for c in range(3):
            assert _sample(atlas, mesh.texcoords[f, c]) == want


@pytest.mark.parametrize("images", [1, 2])
def test_ply_texnumber_minus_one_flags_untextured_faces(tmp_path, images):
    """MeshLab's texnumber -1 (a face without texture): flagged, never given a texture image."""
    V, F = _grid()
    tc = np.tile([0.25, 0.5], (len(F), 3, 1))
    names = [f"t{k}.png" for k in range(images)]
    for name in names:
        _paint(tmp_path / name, (8, 8), [(255, 0, 0), (0, 255, 0)])
    which = np.arange(len(F)) % images
    which[::3] = -1
    _write_texnumber_ply(tmp_path / "tn.ply", V, F, tc, names, which)
    scan = load_scan(tmp_path / "tn.ply")
    ref = _match_faces(scan.mesh, V[F])
    np.testing.assert_array_equal(scan.mesh.untextured_faces, which[ref] < 0)
    assert np.all(scan.mesh.texcoords[scan.mesh.untextured_faces] == 0.0)
    assert any(w.startswith(f"{int((which < 0).sum())} faces have texnumber -1") for w in scan.report.warnings)
    _write_texnumber_ply(tmp_path / "tn.ply", V, F, tc, names, np.full(len(F), -1))
    scan = load_scan(tmp_path / "tn.ply")
    assert scan.mesh.texcoords is None and any("texnumber -1" in w for w in scan.report.warnings)


def test_truncated_binary_stl(tmp_path):
    _trimesh_half_cylinder().export(tmp_path / "h.stl")
    data = (tmp_path / "h.stl").read_bytes()
    (tmp_path / "h.stl").write_bytes(data[:-60])
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "h.stl")
    _one_line(e, "h.stl", "truncated")


def test_corrupt_glb(tmp_path):
    (tmp_path / "x.glb").write_bytes(b"glTF\x02\x00\x00\x00garbage")
    with pytest.raises(InvalidInputError) as e:
        load_scan(tmp_path / "x.glb")
    _one_line(e, "x.glb")


# ------------------------------------------------------------------ fuzzing (pytest -m fuzz)


def _fuzz_seeds(tmp: Path) -> dict[str, bytes]:
    import trimesh

    V, F = _grid()
    obj, _, _ = _write_seam_obj(tmp)
    seeds = {".obj": obj.read_bytes()}
    tc = _uv_of(V[F]).reshape(-1, 6).tolist()
    seeds[".ply"] = _write_ply(tmp / "b.ply", V, F.tolist(), texcoord=tc, comments=["TextureFile atlas.png"]).read_bytes()
    seeds[".ascii.ply"] = _write_ply(tmp / "a.ply", V, F.tolist(), binary=False).read_bytes()
    trimesh.Trimesh(V, F, process=False).export(tmp / "s.stl")
    seeds[".stl"] = (tmp / "s.stl").read_bytes()
    lines = ["OFF", f"{len(V)} {len(F)} 0"] + [f"{x} {y} {z}" for x, y, z in V] + [f"3 {a} {b} {c}" for a, b, c in F]
    seeds[".off"] = ("\n".join(lines) + "\n").encode()
    from PIL import Image

    Vs, Fs = V[F].reshape(-1, 3), np.arange(3 * len(F)).reshape(-1, 3)
    trimesh.Trimesh(Vs, Fs, process=False, visual=trimesh.visual.TextureVisuals(
        uv=_uv_of(Vs), image=Image.new("RGB", (4, 4)))).export(tmp / "g.glb")
    seeds[".glb"] = (tmp / "g.glb").read_bytes()
    return seeds


@pytest.mark.fuzz
def test_fuzz_loaders_never_crash(tmp_path_factory):
    """Random mutations of small valid files: load_scan succeeds or raises a PotflatError."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from potflat.errors import PotflatError

    tmp = tmp_path_factory.mktemp("fuzz")
    seeds = _fuzz_seeds(tmp)

    @settings(max_examples=int(os.environ.get("POTFLAT_FUZZ_EXAMPLES", "300")), deadline=None,
              derandomize="POTFLAT_FUZZ_RANDOM" not in os.environ)
    @given(st.sampled_from(sorted(seeds)), st.lists(st.tuples(st.sampled_from(["flip", "cut", "insert", "digit"]),
                                                              st.floats(0, 1), st.binary(min_size=1, max_size=4)),
                                                    min_size=1, max_size=4))
    def run(kind, edits):
        data = bytearray(seeds[kind])
        for op, where, blob in edits:
            i = int(where * (len(data) - 1))
            if op == "flip":
                data[i] ^= blob[0] or 1
            elif op == "cut":
                del data[i:]
            elif op == "insert":
                data[i:i] = blob
            else:
                data[i:i + 1] = str(blob[0] % 10).encode()
            if not data:
                break
        path = tmp / ("case" + (".ply" if kind == ".ascii.ply" else kind))
        path.write_bytes(bytes(data))
        try:
            load_scan(path)
        except PotflatError as exc:
            assert "\n" not in str(exc)

    run()


@pytest.mark.fuzz
def test_fuzz_gltf_values_never_crash(tmp_path_factory):
    """Values of any JSON type put anywhere in a quantized GLB and a GLB with a texture per
    material: load_scan succeeds or raises a PotflatError of one line."""
    import copy
    import json

    from hypothesis import given, settings
    from hypothesis import strategies as st
    from PIL import Image

    from potflat.errors import PotflatError

    tmp = tmp_path_factory.mktemp("fuzz_gltf")
    _quantized_glb(tmp / "q.glb", transform=True)
    _glb_of_materials(tmp / "m.glb", [Image.new("RGB", (16, 8), (200, 30, 20)), Image.new("RGB", (8, 8), (9, 9, 9)),
                                      None])
    seeds = {}
    for name in ("q.glb", "m.glb"):
        data = (tmp / name).read_bytes()
        (length,) = struct.unpack_from("<I", data, 12)
        seeds[name] = (json.loads(data[20:20 + length]), data[28 + length:])

    def places(node, at=()):
        if at:
            yield at
        items = node.items() if isinstance(node, dict) else enumerate(node) if isinstance(node, list) else ()
        for key, value in items:
            yield from places(value, at + (key,))

    values = st.sampled_from([None, -1, 0, 1, 3, 0.5, 2 ** 40, float("inf"), "x", "VEC2", True, [], {}, [1, 2],
                              ["a"], {"a": 1}, 5120, 5126])

    @settings(max_examples=int(os.environ.get("POTFLAT_FUZZ_EXAMPLES", "300")), deadline=None,
              derandomize="POTFLAT_FUZZ_RANDOM" not in os.environ)
    @given(st.sampled_from(sorted(seeds)), st.lists(st.tuples(st.floats(0, 1), values), min_size=1, max_size=3))
    def run(name, edits):
        doc, blob = json.loads(json.dumps(seeds[name][0])), seeds[name][1]
        for where, value in edits:
            at = list(places(doc))
            if not at:
                break
            *parents, key = at[int(where * (len(at) - 1))]
            node = doc
            for parent in parents:
                node = node[parent]
            node[key] = copy.deepcopy(value)  # (a list or object put twice would hold itself)
        _write_glb(tmp / "case.glb", doc, blob)
        try:
            load_scan(tmp / "case.glb")
        except PotflatError as exc:
            assert "\n" not in str(exc)

    run()


# ------------------------------------------------------------------ against trimesh's readers

def _textured_vessel(tmp_path):
    """A small textured vessel written by potflat_synthetic (OBJ + MTL + PNG)."""
    from potflat_synthetic.vessels import make_vessel, write_obj

    return write_obj(make_vessel("amphora", n_vertices=3000, seed=2, texture_size=64), tmp_path / "v.obj")


@pytest.mark.parametrize("form", ["obj", "binary_ply", "ascii_ply"])
def test_loader_matches_trimesh(tmp_path, form):
    """Corner by corner the same positions (and texture coordinates) as trimesh reads."""
    import trimesh

    path = _textured_vessel(tmp_path)
    if form != "obj":
        path = tmp_path / f"v_{form}.ply"
        trimesh.load(tmp_path / "v.obj", process=False).export(path, encoding=form.split("_")[0])
    tm = trimesh.load(path, process=False)
    ours = load_scan(path, clean=False).mesh
    assert len(ours.faces) == len(tm.faces)
    # PLY stores float32: potflat reads them as their shortest decimal, trimesh widens them
    np.testing.assert_allclose(ours.vertices[ours.faces], tm.vertices[tm.faces], rtol=1e-7, atol=0)
    if form == "obj":  # trimesh's PLY export names no texture file, so only the OBJ has one
        np.testing.assert_allclose(ours.texcoords, tm.visual.uv[tm.faces], rtol=0, atol=1e-12)


@pytest.mark.parametrize("scale,units,likely", [(273.0, None, "millimetres: add --units mm"),
                                                (273.0, "m", "millimetres: add --units mm"),
                                                (0.273, "mm", "metres: add --units m")])
def test_a_declared_or_given_unit_that_makes_no_vessel_names_the_unit_that_fits(tmp_path, scale, units, likely):
    """glTF says metres, but exporters also write millimetres: a 27 cm vessel in millimetres
    read as metres is 273 m across. Declared (glTF) or given, such a unit gets the one line
    naming the unit that fits, not a resolution advice later."""
    import trimesh

    from potflat.io.scan import check_plausible_size

    V, F = _grid()
    V = V / np.ptp(V, axis=0).max() * scale
    trimesh.Trimesh(V, F, process=False).export(tmp_path / "pot.glb")
    scan = load_scan(tmp_path / "pot.glb", units=units)
    with pytest.raises(InvalidInputError, match=likely):
        check_plausible_size(scan, tmp_path / "pot.glb")
    check_plausible_size(load_scan(tmp_path / "pot.glb", units="mm" if scale > 1 else "m"), tmp_path / "pot.glb")


def test_several_units_that_fit_are_named_with_the_size_each_gives(tmp_path):
    """A 40 cm vessel in centimetres written as glTF metres is 39.8 units across: as
    millimetres (40 mm), centimetres (398 mm) and inches (1012 mm) it would all be a vessel;
    centimetres, the size nearest a typical vessel's, comes first and the others with their sizes."""
    import trimesh

    from potflat.io.scan import check_plausible_size

    V, F = _grid()
    V = V / np.ptp(V, axis=0).max() * 39.84
    trimesh.Trimesh(V, F, process=False).export(tmp_path / "pot.glb")
    with pytest.raises(InvalidInputError) as err:
        check_plausible_size(load_scan(tmp_path / "pot.glb"), tmp_path / "pot.glb")
    assert "it looks like centimetres: add --units cm (398 mm across; --units in: 1012 mm, --units mm: 40 mm)" in str(
        err.value)


def test_draco_compressed_glb_is_decoded(real_scans):
    """The shared colonoware pot, Draco-compressed as museum portals ship it: positions
    within the accessor's bounds (not all zeros), every face, texture coordinates in the
    tile and the base-colour image found (not the occlusion or normal map)."""
    import json

    from PIL import Image

    path = real_scans / "colonoware-pot.glb"
    data = path.read_bytes()
    (jlen,) = struct.unpack_from("<I", data, 12)
    doc = json.loads(data[20:20 + jlen])
    assert "KHR_draco_mesh_compression" in doc["extensionsRequired"]
    acc = doc["accessors"][doc["meshes"][0]["primitives"][0]["attributes"]["POSITION"]]
    mesh = load_scan(path, clean=False).mesh
    assert len(mesh.faces) == 150000 and mesh.units == "m"
    # (Draco quantises positions: within a quantisation step of the bounds)
    np.testing.assert_allclose(mesh.vertices.min(0), acc["min"], atol=2e-5)
    np.testing.assert_allclose(mesh.vertices.max(0), acc["max"], atol=2e-5)
    assert len(mesh.vertices) == 75486  # welded across the texture seams
    assert mesh.texcoords.min() >= 0.0 and mesh.texcoords.max() <= 1.0
    image = np.asarray(Image.open(mesh.texture_path).convert("RGB"), np.float64)
    assert image.shape == (1024, 1024, 3)
    # the colour under the texture coordinates is the pot's (fired clay: red over blue), the
    # atlas's unused space is not sampled
    tc = mesh.texcoords.reshape(-1, 2)
    px = image[((1 - tc[:, 1]) * 1023).round().astype(int), (tc[:, 0] * 1023).round().astype(int)]
    assert px.std(axis=0).min() > 5 and px[:, 0].mean() > px[:, 2].mean()


def test_draco_glb_without_its_decoder_is_refused_in_one_line(real_scans, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_draco(name, *args, **kwargs):
        if name == "DracoPy":
            raise ImportError("no DracoPy")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_draco)
    with pytest.raises(InvalidInputError, match="Draco.*pip install DracoPy"):
        load_scan(real_scans / "colonoware-pot.glb")
