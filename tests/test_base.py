"""The base at the foot (the floor, inside): left out of the rollout and shown as its own disc,
an orthographic view along the axis, where a development would smear it; kept where the
development shows it more truly (:mod:`potflat.rollout.base`); the disc baked beside the
painting by the file layer, and gone again when a later rollout keeps the base."""
from __future__ import annotations

import json

import numpy as np
import pytest
from _revolve import cylinder, revolve
from potflat_cli.main import app
from potflat_synthetic.vessels import (
    PART_BASE,
    PART_INNER,
    make_vessel,
    write_ply_colored,
)
from typer.testing import CliRunner

from potflat.mesh.distortion import face_areas, summarize
from potflat.mesh.embedding import signed_areas
from potflat.mesh.split import CUT_SNAP
from potflat.rollout import rollout
from potflat.rollout.notes import _facing_axis_share
from potflat.rollout.walls import FaceGraph


@pytest.fixture(scope="module")
def cup():
    return make_vessel("cup", n_vertices=4000, seed=1, texture_size=128)


def _up_and_seam(res):
    """The disc's uv of the disc's vertices and their angles from the seam (radians, (-pi, pi])."""
    disc = res.base.flat
    theta = res.axis.cylindrical(disc.mesh.vertices)[2]
    return disc.uv, (theta - np.radians(res.seam_angle) + np.pi) % (2 * np.pi) - np.pi


def test_a_flat_base_is_left_out_and_shown_true_seen_from_below(cup):
    res = rollout(cup.mesh, importance="none")
    base = res.base
    assert base.left_out and base.view == "below" and base.flat is not None
    base_faces = np.flatnonzero(cup.face_part == PART_BASE)
    assert np.isin(base_faces, np.concatenate([base.disc_faces, base.cut.faces])).mean() > 0.97
    assert not np.intersect1d(base.disc_faces, res.face_index).size  # each face in one image, or cut between
    # (faces across the plane the base is cut off along are in both, in pieces: the rounded
    # corner's upper part goes with the wall)
    in_rollout = face_areas(res.flat.mesh.vertices, res.flat.mesh.faces)[cup.face_part[res.face_index] == PART_BASE]
    assert in_rollout.sum() <= 0.05 * face_areas(cup.mesh.vertices, cup.mesh.faces[base_faces]).sum()
    # a flat base seen along the axis is true, and not mirrored: every face counter-clockwise
    assert base.orthographic_error_pct[0] < 0.5 and base.unrolled_error_pct[0] > 20
    assert np.all(signed_areas(base.flat.mesh.faces, base.flat.uv) > 0)
    assert base.distortion.flipped == 0 and base.distortion.edge_rms < 0.05
    # the seam is at the top of the disc (the axis at uv 0)
    uv, off_seam = _up_and_seam(res)
    at_seam = np.abs(off_seam) < np.radians(10)
    assert at_seam.any() and np.all(uv[at_seam, 1] > 0) and np.all(np.abs(uv[at_seam, 0]) < uv[at_seam, 1])
    assert "base faces along the axis" in base.reason
    assert _facing_axis_share(res) < 0.02


def test_the_base_is_cut_off_at_one_height_and_the_wall_s_lower_edge_is_level(cup):
    res = rollout(cup.mesh, importance="none")
    cut = res.base.cut
    assert cut is not None and len(cut.faces) > 0 and "cut off along the plane" in res.base.cut_note
    # the rollout's boundary in its lower half, away from the seam's sides
    faces = res.flat.mesh.faces
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    key, count = np.unique(edges[:, 0] * len(res.flat.uv) + edges[:, 1], return_counts=True)
    boundary = np.unique(np.concatenate([key[count == 1] // len(res.flat.uv), key[count == 1] % len(res.flat.uv)]))
    h, _, theta = res.axis.cylindrical(res.flat.mesh.vertices[boundary])
    off_seam = np.abs((theta - np.radians(res.seam_angle) + np.pi) % (2 * np.pi) - np.pi) > np.radians(3.0)
    lower = h[off_seam & (h < 0.5 * res.axis.height)]
    assert len(lower) > 32  # the whole way round
    # on the plane: a vertex the splitter counts as on it is off by at most CUT_SNAP of an
    # edge across it
    face_h = res.axis.cylindrical(cup.mesh.vertices)[0][cup.mesh.faces]
    across = (face_h.min(axis=1) < cut.height) & (face_h.max(axis=1) > cut.height)
    snap = CUT_SNAP * np.ptp(face_h[across], axis=1).max()
    assert np.abs(lower - cut.height).max() <= snap
    assert np.mean(np.abs(lower - cut.height) < 1e-9 * res.axis.height) > 0.5
    # the disc's rim is the same curve: no vertex of the disc above it
    assert res.axis.cylindrical(res.base.flat.mesh.vertices)[0].max() <= cut.height + snap
    # a face is whole in one image or split between both
    assert not np.intersect1d(res.base.disc_faces, cut.faces).size
    assert np.isin(cut.faces, res.face_index).all()


def test_texture_coordinates_are_carried_exactly_into_the_pieces_of_both_images(cup):
    # texture coordinates linear in the position: a piece's corner has the value of its point
    A = np.array([[0.003, -0.001, 0.002], [0.001, 0.004, -0.002]])
    mesh = cup.mesh.replace(texcoords=cup.mesh.vertices[cup.mesh.faces] @ A.T)
    res = rollout(mesh, importance="none")
    assert len(res.base.cut.faces)
    disc = res.base.flat.mesh
    assert np.abs(disc.texcoords - disc.vertices[disc.faces] @ A.T).max() < 1e-12
    # in the rollout, a corner the seam's cut moved onto its meridian has its face's texture
    # map at the new point (its projection onto the face's plane)
    flat = res.flat.mesh
    P = cup.mesh.vertices[cup.mesh.faces[res.face_index]]
    normal = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    corners = flat.vertices[flat.faces]
    onto = corners - ((corners - P[:, :1]) * normal[:, None]).sum(axis=2)[..., None] * normal[:, None]
    assert np.abs(flat.texcoords - onto @ A.T).max() < 1e-12
    assert np.abs(flat.texcoords - corners @ A.T).max() > 1e-9  # (some corners did move)


@pytest.mark.parametrize("seam", [None, 30.0])
def test_a_sherd_s_base_is_cut_off_whether_the_seam_is_in_its_gap_or_placed(seam):
    """A sherd (270 degrees) of a pot with a wide, nearly flat base: with the seam placed by the
    user the region is unwrapped from its gap and has no side to cut; the base's plane is
    cut all the same."""
    def radius(t):
        return np.where(t < 0.4, 2.0 + 95.0 * t, 40.0 + 3.0 * (t - 0.4))

    def height(t):
        return np.where(t < 0.4, 0.5 * t, 0.2 + 100.0 * (t - 0.4))

    mesh, *_ = revolve(radius, height, n_theta=64, n_t=40, theta_range=(0.0, 4.7), jitter=0.3)
    res = rollout(mesh, importance="none", seam=seam)
    cut = res.base.cut
    assert res.base.left_out and cut is not None and len(cut.faces)
    in_rollout = np.bincount(res.face_index, face_areas(res.flat.mesh.vertices, res.flat.mesh.faces), len(mesh.faces))
    share = in_rollout[cut.faces] / face_areas(mesh.vertices, mesh.faces)[cut.faces]
    # each face across the plane is in the rollout only in part (its piece above it), if at all
    assert share.max() < 1.0 - 1e-6 and np.count_nonzero(share) > 0.5 * len(cut.faces)


def test_keep_base_keeps_it_in_the_rollout(cup):
    res = rollout(cup.mesh, importance="none", keep_base=True)
    assert not res.base.left_out and res.base.flat is None and "keep_base" in res.base.reason
    base_faces = np.flatnonzero(cup.face_part == PART_BASE)
    assert res.base.candidate_faces > 0.9 * len(base_faces)
    assert np.isin(base_faces, np.concatenate([res.face_index, res.trimmed])).all()


def test_the_floor_and_its_tondo_are_shown_seen_from_above(cup):
    res = rollout(cup.mesh, side="inner", importance="none")
    base = res.base
    assert base.left_out and base.view == "above" and np.all(cup.face_part[base.disc_faces] == PART_INNER)
    assert np.all(signed_areas(base.flat.mesh.faces, base.flat.uv) > 0)  # seen from inside: not mirrored
    tondo, = (c for c in cup.features if c.side == "inner")
    disc = base.flat
    near = np.linalg.norm(disc.mesh.vertices - tondo.centre, axis=1)
    inside = near < tondo.radius
    assert inside.sum() > 10  # the whole tondo is in the disc, at true size
    centre = disc.uv[np.argmin(near)]
    assert np.abs(np.linalg.norm(disc.uv[inside] - centre, axis=1) - near[inside]).max() < 0.01 * tondo.radius + \
        near.min()


def test_a_base_that_unrolls_truly_stays_in_the_rollout():
    # a shallow cone opening from near the axis: every face within 27 degrees of the axis, and
    # the cone's development is exact, truer than the view along the axis (10.6 % short)
    mesh, *_ = revolve(lambda t: 15.0 + 80.0 * t, lambda t: 40.0 * t, n_theta=96, n_t=24)
    res = rollout(mesh, importance="none", proxy="cone")
    assert res.base.candidate_faces > 0.9 * len(mesh.faces)
    assert not res.base.left_out and len(res.base.kept_faces) == res.base.candidate_faces
    assert res.base.unrolled_error_pct[0] < res.base.orthographic_error_pct[0]
    assert "unroll more truly" in res.base.reason


def test_a_flat_bottom_of_chords_between_rim_vertices_is_a_base():
    """A designed mesh's flat bottom (a polygon triangulated by chords, no vertex near the
    axis; the goblet scan's foot is one) is found by its faces spanning the axis."""
    mesh, *_ = cylinder(R=30.0, H=80.0, n_theta=32, n_t=12)
    rim = np.arange(32)  # the foot's ring of the open cylinder
    chords = np.array([[rim[0], rim[k + 1], rim[k]] for k in range(1, 31)])
    closed = mesh.replace(faces=np.vstack([mesh.faces, chords]))
    res = rollout(closed, importance="none")
    bottom = np.arange(len(mesh.faces), len(closed.faces))
    area = face_areas(closed.vertices, closed.faces)
    assert np.isin(res.base.disc_faces, bottom).all()  # (some slivers at the rim vertex may stay)
    assert area[res.base.disc_faces].sum() > 0.95 * area[bottom].sum()


def test_a_cap_on_a_cylinder_is_the_disc_and_the_wall_is_whole():
    mesh, *_ = cylinder(R=30.0, H=80.0, n_theta=64, n_t=24, cap=True)
    res = rollout(mesh, importance="none")
    cap = np.arange(len(mesh.faces) - 64, len(mesh.faces))
    assert np.array_equal(np.sort(res.base.disc_faces), cap)
    # (a face the seam cut is there once per piece)
    assert len(np.unique(res.face_index)) == len(mesh.faces) - 64 and not len(res.trimmed)
    assert summarize(res.base.flat.mesh.vertices, res.base.flat.uv, res.base.flat.mesh.faces).edge_rms < 1e-9


@pytest.mark.parametrize("kind, seed, why", [("kylix", 1, "no base"), ("amphora", 1, "no base"),
                                             ("lekythos", 5, "a shoulder")])
def test_no_base_no_disc(kind, seed, why):
    """A kylix's bowl over its stem faces down but is no base; an amphora's open foot has none;
    this lekythos's axis points from its wide foot to its mouth, so its shoulder faces "down",
    near the axis: but the wall goes on past it (neck and mouth), no base."""
    vessel = make_vessel(kind, n_vertices=3000, seed=seed, texture_size=64)
    res = rollout(vessel.mesh, importance="none")
    assert not res.base.left_out and res.base.flat is None and why in res.base.reason


def test_an_open_foot_facing_along_the_axis_is_no_base():
    mesh, *_ = revolve(lambda t: 40.0 + 30.0 * np.sin(np.pi * t), lambda t: 60.0 * t, n_theta=96, n_t=40)
    res = rollout(mesh, importance="none", proxy="cone")
    assert not res.base.left_out and res.base.candidate_faces == 0 and "no base" in res.base.reason


def _cli(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def test_the_run_writes_the_disc_beside_the_painting_and_a_rerun_keeping_it_removes_it(cup, tmp_path):
    scan = write_ply_colored(cup, tmp_path / "cup.ply")
    out = tmp_path / "out"
    result = _cli("run", scan, "-o", out, "--px-per-mm", 1)
    assert result.exit_code == 0, result.output
    assert "base left out of the rollout" in " ".join(result.output.split()) and "cup.base.png" in result.output
    rolled = json.loads((out / "cup.rollout.json").read_text())
    assert rolled["base"]["left_out"] and rolled["base"]["view"] == "below"
    assert rolled["base"]["faces_in_disc"] > 0 and rolled["files"]["base_ply"] == "cup.base.ply"
    baked = json.loads((out / "cup.bake.json").read_text())
    assert baked["base"]["files"]["png"] == "cup.base.png" and "off by" in baked["base"]["lengths"]
    disc = json.loads((out / "cup.base.bake.json").read_text())
    assert disc["scale_on_image"] is not None and disc["distortion"]["flipped"] == 0
    written = sorted(p.name for p in out.glob("cup.base.*"))
    assert "cup.base.png" in written and "cup.base.stress.png" in written
    # the bake alone bakes the disc beside the relaxed file too
    assert _cli("bake", out / "cup.relaxed.ply", "-o", tmp_path / "again", "--px-per-mm", 1, "-q").exit_code == 0
    assert sorted(p.name for p in (tmp_path / "again").glob("cup.base.*")) == [n for n in written if n != "cup.base.ply"]
    # kept in the rollout: the folder holds no disc any more
    result = _cli("run", scan, "-o", out, "--px-per-mm", 1, "--keep-base", "-q")
    assert result.exit_code == 0, result.output
    assert not list(out.glob("cup.base.*"))
    assert json.loads((out / "cup.rollout.json").read_text())["base"]["left_out"] is False
    assert json.loads((out / "cup.bake.json").read_text())["base"] is None


def test_the_colonoware_base_is_its_own_disc_and_the_rollout_has_a_clean_lower_edge(real_scans):
    from potflat.io.scan import load_scan

    for scan, share in (("colonoware-pot.glb", 15.0), ("dragon-jar.glb", 3.0)):
        mesh = load_scan(real_scans / scan).mesh
        res = rollout(mesh, importance="none")
        base = res.base.summary(mesh.mm_per_unit)
        assert base["left_out"] and base["percent_of_region"] > share, scan
        assert _facing_axis_share(res) < 0.02, scan
        assert res.base.distortion.flipped == 0 and base["length_error_disc_pct"][0] < 15.0, scan
        # no fragment below the wall: the rollout is one piece but for specks of a few faces
        pieces = np.bincount(FaceGraph(res.flat.mesh.faces).components())
        assert np.sort(pieces)[-2:-1].sum() < 0.001 * len(res.flat.mesh.faces), scan
