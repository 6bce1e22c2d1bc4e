"""Textured scans with some faces that have no texture coordinates (faces without ``vt``, a
second material without an image, MeshLab's hole filling, a glTF primitive without
TEXCOORD_0): the faces are flagged (``Mesh.untextured_faces``) through loading, cleaning,
rollout, the stage files, relax and bake; they are baked as relief in grey, never as the
texel at (0, 0), and carry no colour evidence into the painted-zone detection."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from potflat.errors import InvalidInputError
from potflat.types import Mesh

RED = (255, 0, 0)


def _red_pixels(rgba: np.ndarray) -> np.ndarray:
    """Covered pixels (h, w) bool whose colour is near the loud (0, 0) texel."""
    rgb = rgba[..., :3].astype(int)
    return (rgba[..., 3] > 0) & (rgb[..., 0] > 200) & (rgb[..., 1] < 60) & (rgb[..., 2] < 60)


def _patches(vessel, share: float = 0.25, cell_deg: float = 15.0, cell_mm: float = 15.0, seed: int = 1) -> np.ndarray:
    """Faces (m,) bool in a random ``share`` of the cells of a ``cell_deg`` x ``cell_mm`` grid
    about the vessel's axis: scattered blocks of untextured faces (hole fillings)."""
    F = vessel.mesh.faces
    centre = vessel.to_canonical(vessel.mesh.vertices[F].mean(axis=1))
    column = np.floor(np.degrees(np.arctan2(centre[:, 1], centre[:, 0])) / cell_deg).astype(int)
    row = np.floor(centre[:, 2] / cell_mm).astype(int)
    cell = (column - column.min()) * (row.max() - row.min() + 1) + row - row.min()
    return np.random.default_rng(seed).random(cell.max() + 1)[cell] < share


def _obj_with_untextured(vessel, path, untextured: np.ndarray, how: str):
    """Write ``vessel`` as OBJ with its texture's (0, 0) texel pure red, and the faces
    ``untextured`` (m,) bool without texture: ``how`` = ``"no vt"`` (``f v v v``) or
    ``"material"`` (in a material without ``map_Kd``, keeping their ``vt``)."""
    from potflat_synthetic.vessels import write_obj

    texture = vessel.texture.copy()
    texture[-1, 0] = RED  # row 0 is the top: texture coordinate (0, 0) is the bottom-left texel
    path = write_obj(dataclasses.replace(vessel, texture=texture), path)
    out, face, current = [], 0, None
    for line in path.read_text().splitlines():
        if line.startswith("usemtl "):
            current = line
        if line.startswith("f "):
            if how == "no vt" and untextured[face]:
                line = "f " + " ".join(corner.split("/")[0] for corner in line.split()[1:])
            elif how == "material" and (face == 0 or untextured[face] != untextured[face - 1]):
                out.append("usemtl plain" if untextured[face] else current)
            face += 1
        out.append(line)
    path.write_text("\n".join(out) + "\n")
    if how == "material":
        mtl = path.with_suffix(".mtl")
        mtl.write_text(mtl.read_text() + "newmtl plain\nKd 0.5 0.5 0.5\n")
    return path


def _original_faces(vessel, mesh: Mesh) -> np.ndarray:
    """Index (m,) of the generated vessel's face that each face of a loaded ``mesh`` is (or is
    a piece of: the seam cuts faces)."""
    from scipy.spatial import cKDTree

    V, F = vessel.mesh.vertices, vessel.mesh.faces
    p = mesh.vertices[mesh.faces].mean(axis=1)
    _, near = cKDTree(V[F].mean(axis=1)).query(p, k=8)
    # the nearest face whose triangle holds the point (barycentric coordinates in [0, 1], on its
    # plane); a face with a corner the seam's cut moved onto its meridian: the nearest face
    a, b, c = (V[F[near, i]] for i in range(3))
    e1, e2, d = b - a, c - a, p[:, None] - a
    g11, g12, g22 = (e1 * e1).sum(-1), (e1 * e2).sum(-1), (e2 * e2).sum(-1)
    r1, r2 = (d * e1).sum(-1), (d * e2).sum(-1)
    det = g11 * g22 - g12**2
    s, t = (g22 * r1 - g12 * r2) / det, (g11 * r2 - g12 * r1) / det
    off = np.linalg.norm(d - s[..., None] * e1 - t[..., None] * e2, axis=-1)
    holds = (s > -1e-6) & (t > -1e-6) & (s + t < 1 + 1e-6) & (off < 1e-3)
    assert holds.any(axis=1).mean() > 0.95
    return near[np.arange(len(p)), np.argmax(holds, axis=1)]


@pytest.fixture(scope="module")
def small_vessel():
    from potflat_synthetic.vessels import make_vessel

    return make_vessel("cone", n_vertices=3000, seed=3, texture_size=256, painting="belt")


@pytest.mark.parametrize("how", ["no vt", "material"])
def test_faces_without_texture_are_flagged_exactly(tmp_path, small_vessel, how):
    from potflat import load_scan

    untextured = _patches(small_vessel)
    scan = load_scan(_obj_with_untextured(small_vessel, tmp_path / "pot.obj", untextured, how))
    mesh = scan.mesh
    assert mesh.texcoords is not None and mesh.untextured_faces is not None
    assert mesh.untextured_faces.dtype == bool and mesh.untextured_faces.flags.c_contiguous
    np.testing.assert_array_equal(mesh.untextured_faces, untextured[_original_faces(small_vessel, mesh)])
    note = next(w for w in scan.report.warnings if "faces have no texture" in w)
    assert note.startswith(f"{int(untextured.sum())} faces") and "left out of the painted-zone detection" in note
    assert "(0, 0)" not in " ".join(scan.report.warnings)


def test_a_scan_with_every_face_textured_has_no_flag(tmp_path, small_vessel):
    from potflat import load_scan

    mesh = load_scan(_obj_with_untextured(small_vessel, tmp_path / "pot.obj",
                                          np.zeros(len(small_vessel.mesh.faces), bool), "no vt")).mesh
    assert mesh.texcoords is not None and mesh.untextured_faces is None


def test_untextured_faces_are_baked_as_relief_never_the_corner_texel(tmp_path, small_vessel):
    from potflat import load_scan
    from potflat.bake import bake
    from potflat.raster.render import Renderer
    from potflat.rollout import rollout

    untextured = _patches(small_vessel)
    mesh = load_scan(_obj_with_untextured(small_vessel, tmp_path / "pot.obj", untextured, "no vt")).mesh
    flat = rollout(mesh, importance="none").flat
    assert flat.mesh.untextured_faces is not None and flat.mesh.untextured_faces.sum() > 0.1 * len(flat.mesh.faces)
    image = bake(flat, px_per_mm=2.0, maps=()).painting
    assert not _red_pixels(image).any()
    # pixels wholly on untextured faces are grey relief; those wholly on textured faces keep the painting
    r = Renderer(flat, 2.0, distortion_maps=False)
    share = np.concatenate([r.untextured_share(r0, r1) for r0, r1 in r.strips()])
    plain = flat.replace(mesh=flat.mesh.replace(texcoords=None, untextured_faces=None, texture_path=None))
    relief = bake(plain, px_per_mm=2.0, maps=()).painting  # the scan as if it had no texture at all
    assert (share == 1.0).sum() > 1000
    np.testing.assert_array_equal(image[share == 1.0], relief[share == 1.0])
    textured = share == 0.0
    assert (image[textured] != relief[textured]).any(axis=1).mean() > 0.95  # the painting there


def test_auto_importance_ignores_untextured_faces(tmp_path):
    """A cone painted in a belt, a quarter of its surface in scattered untextured blocks whose
    (0, 0) texel is loud: the painted zone found is about the one found without them (their
    borders are not taken for detail)."""
    from potflat import load_scan
    from potflat.rollout import rollout
    from potflat_synthetic.vessels import make_vessel

    vessel = make_vessel("cone", n_vertices=8000, seed=3, painting="belt", shading=True)
    none = np.zeros(len(vessel.mesh.faces), bool)
    untextured = _patches(vessel)
    assert 0.15 < untextured.mean() < 0.35
    fractions = []
    for name, faces in (("whole", none), ("holed", untextured)):
        found = rollout(load_scan(_obj_with_untextured(vessel, tmp_path / f"{name}.obj", faces, "no vt")).mesh)
        assert found.importance.values is not None, found.importance.reason
        fractions.append(found.importance.zone_fraction)
    whole, holed = fractions
    assert 0.05 < whole < 0.3
    assert abs(holed - whole) < 0.05


def test_the_flag_survives_the_stage_files_from_rollout_to_bake(tmp_path, small_vessel):
    from PIL import Image

    from potflat.bake import BakeOptions
    from potflat.files.bake_stage import run_bake_stage
    from potflat.files.relax_stage import run_relax_stage
    from potflat.files.rollout_stage import run_rollout_stage
    from potflat.io.flat_ply import read_flat_ply
    from potflat.relax import RelaxOptions
    from potflat.rollout import RolloutOptions

    untextured = _patches(small_vessel)
    (tmp_path / "scan").mkdir()
    scan = _obj_with_untextured(small_vessel, tmp_path / "scan" / "pot.obj", untextured, "no vt")
    out = tmp_path / "out"
    rolled = run_rollout_stage(scan, out, RolloutOptions())
    from_file = read_flat_ply(rolled.paths["ply"])
    assert from_file.mesh.untextured_faces is not None
    np.testing.assert_array_equal(from_file.mesh.untextured_faces, rolled.flat.mesh.untextured_faces)  # as run hands it
    np.testing.assert_array_equal(from_file.mesh.untextured_faces,
                                  untextured[_original_faces(small_vessel, from_file.mesh)])
    relaxed = run_relax_stage(rolled.paths["ply"], out, RelaxOptions())
    relaxed_file = read_flat_ply(relaxed.paths["ply"])
    np.testing.assert_array_equal(relaxed_file.mesh.untextured_faces, from_file.mesh.untextured_faces)
    np.testing.assert_array_equal(relaxed.flat.mesh.untextured_faces, from_file.mesh.untextured_faces)
    baked = run_bake_stage(relaxed.paths["ply"], out, BakeOptions(px_per_mm=2.0, maps=()))
    image = np.asarray(Image.open(baked.paths["png"]).convert("RGBA"))
    assert (image[..., 3] > 0).sum() > 1000 and not _red_pixels(image).any()


def test_a_flattening_without_untextured_faces_writes_no_flag(tmp_path, small_vessel):
    from potflat.io.flat_ply import read_flat_ply, write_flat_ply
    from potflat.io.images import write_png
    from potflat.types import FlatMesh

    mesh = small_vessel.mesh.replace(texture_path=write_png(tmp_path / "t.png", small_vessel.texture, px_per_mm=None))
    write_flat_ply(tmp_path / "a.rollout.ply", FlatMesh(mesh, mesh.vertices[:, :2]))
    assert b"untextured" not in (tmp_path / "a.rollout.ply").read_bytes()[:2000]
    assert read_flat_ply(tmp_path / "a.rollout.ply").mesh.untextured_faces is None


@pytest.mark.parametrize("command", ["rollout", "run"])
def test_the_command_line_says_which_faces_have_no_texture(tmp_path, small_vessel, command):
    """The loader's warnings reach the user on the terminal, not only the JSON."""
    from potflat_cli.main import app
    from typer.testing import CliRunner

    untextured = _patches(small_vessel)
    scan = _obj_with_untextured(small_vessel, tmp_path / "pot.obj", untextured, "no vt")
    result = CliRunner().invoke(app, [command, str(scan), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    said = " ".join(result.output.split())  # rich wraps long lines
    assert f"warning: {int(untextured.sum())} faces have no texture coordinates" in said


def test_the_seam_choice_reads_no_colour_on_untextured_faces(tmp_path):
    """The painted share that steers the seam away from painting is 0 on flagged faces,
    whatever their (meaningless) texture coordinates point at."""
    import cv2

    from potflat.rollout.seam import _painted_share

    halves = np.zeros((64, 64, 3), np.uint8)
    halves[:, 32:] = 255  # black left, white right: a face reading both halves is part painted
    tex = tmp_path / "halves.png"
    cv2.imwrite(str(tex), halves)
    tc = np.array([[[0.1, 0.1], [0.9, 0.1], [0.9, 0.9]], [[0.1, 0.1], [0.9, 0.9], [0.1, 0.9]]])
    faces = np.arange(2)
    plain = _square(texcoords=tc, texture_path=tex)
    area = np.full(2, 0.5)
    share, source = _painted_share(plain, faces, area, np.zeros(2))
    assert source == "texture" and (share > 0).all()
    flagged, _ = _painted_share(plain.replace(untextured_faces=[False, True]), faces, area, np.zeros(2))
    assert flagged[0] == share[0] and flagged[1] == 0.0


# --- validation -----------------------------------------------------------------------------

def _square(**fields) -> Mesh:
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    return Mesh(V, F, **fields)


def test_the_flag_is_coerced_and_all_false_is_none():
    tc = np.zeros((2, 3, 2))
    assert _square(texcoords=tc, untextured_faces=[1, 0]).untextured_faces.tolist() == [True, False]
    assert _square(texcoords=tc, untextured_faces=np.zeros(2, bool)).untextured_faces is None


def test_the_flag_needs_one_entry_per_face():
    with pytest.raises(InvalidInputError, match="one flag per face"):
        _square(texcoords=np.zeros((2, 3, 2)), untextured_faces=[True, False, True])


def test_the_flag_must_be_boolean():
    with pytest.raises(InvalidInputError, match="booleans"):
        _square(texcoords=np.zeros((2, 3, 2)), untextured_faces=[0.5, 0.0])
    with pytest.raises(InvalidInputError, match="booleans"):
        _square(texcoords=np.zeros((2, 3, 2)), untextured_faces=[2, 0])


def test_the_flag_needs_texture_coordinates():
    with pytest.raises(InvalidInputError, match="give texcoords"):
        _square(untextured_faces=[True, False])


def test_a_stage_file_with_a_bad_flag_is_one_line(tmp_path):
    from potflat.io.flat_ply import read_flat_ply, write_flat_ply
    from potflat.types import FlatMesh

    (tmp_path / "t.png").write_bytes(b"")  # only its name is read here
    mesh = _square(texcoords=np.zeros((2, 3, 2)), texture_path=tmp_path / "t.png", untextured_faces=[True, False])
    path = write_flat_ply(tmp_path / "a.rollout.ply", FlatMesh(mesh, mesh.vertices[:, :2]))
    np.testing.assert_array_equal(read_flat_ply(path).mesh.untextured_faces, [True, False])
    data = bytearray(path.read_bytes())
    record = 1 + 12 + 1 + 24 + 1  # a face: count, 3 int indices, count, 6 float texcoords, the flag
    assert data[-1] == 0 and data[-1 - record] == 1  # the flags of face 1 and face 0
    data[-1] = 2
    path.write_bytes(bytes(data))
    with pytest.raises(InvalidInputError, match="untextured flags other than 0 and 1"):
        read_flat_ply(path)
