"""Rollout of real vessels: painted side, attachments, folded border, profile files, real scans."""
import json

import numpy as np
import pytest
from _vessel_meshes import revolve
from potflat_synthetic.vessels import (
    PART_BASE,
    PART_HANDLE,
    PART_INNER,
    PART_OUTER,
    make_vessel,
    write_ply_colored,
)
from typer.testing import CliRunner

from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.files.rollout_stage import run_rollout_stage
from potflat.io.flat_ply import read_flat_ply
from potflat.mesh.boundary import edges_and_boundary
from potflat.mesh.distortion import edge_length_error
from potflat.mesh.embedding import signed_areas
from potflat.rollout.border import border_folds, crossing_segments, untangle
from potflat.rollout.folds import overlapping_faces
from potflat.rollout.unroll import RolloutOptions, rollout
from potflat.rollout.walls import OUTER
from potflat.types import Mesh

#: The shared real scans (CI has ../shared beside the repository).
SCANS = ("goblet.stl", "plastic-vase.ply", "sea-vase.ply")


@pytest.fixture(scope="module")
def cup():
    return make_vessel("cup", n_vertices=3000, seed=2, texture_size=64)


@pytest.fixture(scope="module")
def amphora():
    return make_vessel("amphora", n_vertices=3000, seed=1, texture_size=64, handles="welded")


def _check_clean(res):
    """No flipped face, no overlapping border: a start the relax stage can take."""
    assert res.distortion.flipped == 0
    assert np.all(signed_areas(res.flat.mesh.faces, res.flat.uv) > 0)
    assert res.boundary_overlap == 0


def test_cup_outer_wall_only(cup):
    res = rollout(cup.mesh)
    parts = cup.face_part[np.unique(res.face_index)]  # (a face the seam cut is there once per piece)
    assert not np.any(parts == PART_INNER)
    assert np.count_nonzero(parts == PART_OUTER) == np.count_nonzero(cup.face_part == PART_OUTER)
    assert res.walls.two_walled and res.side == "outer"
    _check_clean(res)
    # what was trimmed is the rim's thickness, never the painted wall
    assert not np.any(cup.face_part[res.trimmed] == PART_OUTER)


def test_cup_inner_wall_seen_from_inside(cup):
    res = rollout(cup.mesh, side="inner")
    parts = cup.face_part[res.face_index]
    assert not np.any((parts == PART_OUTER) | (parts == PART_BASE))
    # the floor is shown on its own, seen from above (test_base.py): with it, the whole inner wall
    shown = cup.face_part[np.concatenate([res.face_index, res.base.disc_faces])]
    assert np.count_nonzero(shown == PART_INNER) >= 0.99 * np.count_nonzero(cup.face_part == PART_INNER)
    # the inner faces are counter-clockwise seen from the cavity: mirrored u keeps them positive
    _check_clean(res)
    # u = -R theta: to the right of a viewer inside is clockwise seen from above
    for side, sign in (("inner", -1), ("outer", 1)):
        cyl = rollout(cup.mesh, side=side, proxy="cylinder")
        theta = cyl.axis.cylindrical(cyl.flat.mesh.vertices)[2]
        e = cyl.flat.mesh.faces[:, :2]
        dth = (theta[e[:, 1]] - theta[e[:, 0]] + np.pi) % (2 * np.pi) - np.pi
        du = cyl.flat.uv[e[:, 1], 0] - cyl.flat.uv[e[:, 0], 0]
        # (a vertex the seam's cut counts as on its meridian has the meridian's angle there,
        # not its own: its edges to vertices between the two, where the base is cut off, are left out)
        u = cyl.flat.uv[:, 0]
        seam_side = (u <= u.min() + 1e-9 * np.ptp(u)) | (u >= u.max() - 1e-9 * np.ptp(u))
        big = (np.abs(dth) > 1e-3) & ~seam_side[e].any(axis=1)
        assert np.all(sign * du[big] * dth[big] > 0), side


def test_inner_side_needs_an_inner_wall():
    sv = make_vessel("cylinder", n_vertices=1000, seed=1, texture_size=64)
    with pytest.raises(InvalidInputError, match="no inner wall"):
        rollout(sv.mesh, side="inner")


@pytest.mark.parametrize("kwargs,match", [
    ({"side": "both"}, "side"),
    ({"keep_attachments": "yes"}, "keep_attachments"),
])
def test_new_options_are_validated(kwargs, match):
    with pytest.raises(InvalidOptionError, match=match):
        RolloutOptions(**kwargs)


def test_a_dish_face_scanned_alone_is_unrolled_from_above_with_its_orientation_kept():
    """The face of a plate alone, facing up as photographed: read as usual it is turned to
    face down and unrolled from below (its painting mirrored, the load warns); kept as the
    file gives it, its inner side is unrolled from above, not mirrored."""
    import _vessel_meshes as vm

    from potflat.mesh.cleaning import clean_mesh

    V, F, labels, _ = vm.dish()

    def unrolled(keep: bool, side: str):
        mesh, _ = clean_mesh(Mesh(V, F, units="mm"), outward=not keep)
        r = rollout(mesh, side=side, keep_orientation=keep, importance="none")
        corners = r.flat.mesh.vertices[r.flat.mesh.faces]
        normal_z = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])[:, 2]
        return r, normal_z, signed_areas(r.flat.mesh.faces, r.flat.uv)

    r, normal_z, flat = unrolled(False, "outer")
    assert (normal_z < 0).all() and (flat > 0).all()  # from below
    r, normal_z, flat = unrolled(True, "inner")
    assert (normal_z > 0).all() and (flat > 0).all()  # from above
    assert r.walls.face_mask[np.isin(labels, ["well", "broad rim"])].mean() > 0.95


@pytest.mark.parametrize("case", ["plain plate", "inner side", "painted underside", "tall", "no colours"])
def test_an_open_form_plain_outside_points_to_its_inner_side(case):
    """A plate (35 mm high, 243 mm across its profile's widest bin) whose outer side shows no painting in its colours is
    told to unroll its inner side, where a plate's painting usually is; not when its inner
    side is the one unrolled, when the outer side is painted, when the vessel is taller than
    half its width, or when the scan has no colours to look for a painting in."""
    import _vessel_meshes as vm

    from potflat.rollout.notes import rollout_notes

    V, F, labels, _ = vm.plate()
    V = V * np.array([1.0, 1.0, 4.0 if case == "tall" else 1.0])
    rng = np.random.default_rng(0)
    colours = np.clip(rng.normal([225, 215, 195], 1.0, (len(V), 3)), 0, 255).astype(np.uint8)
    if case == "painted underside":
        radius = np.hypot(V[:, 0], V[:, 1])
        colours[(V[:, 2] < 14.0) & (np.abs(np.sin(radius / 3.0)) < 0.3)] = (40, 60, 150)
    mesh = Mesh(V, F, units="mm", vertex_colors=None if case == "no colours" else np.c_[colours, np.full(len(V), 255,
                                                                                                          np.uint8)])
    r = rollout(mesh, side="inner" if case == "inner side" else "outer")
    hint = [n for n in rollout_notes(r) if "open form" in n]
    if case == "plain plate":
        assert hint == ["an open form (35 mm high, 243 mm across: a plate, dish or bowl) with no painting found on "
                        "its outer side; if its inside is painted, unroll it with --side inner"]
    else:
        assert not hint, hint
    assert (r.importance.values is not None) == (case == "painted underside")


def test_handles_are_left_out_and_reported(amphora):
    res = rollout(amphora.mesh)
    att = res.attachments
    assert att.n_faces > 0 and not np.any(att.face_mask[res.face_index])
    handle = amphora.face_part == PART_HANDLE
    assert np.count_nonzero(handle[res.face_index]) < 0.5 * handle.sum()  # only the roots stay
    assert np.count_nonzero(amphora.face_part[res.face_index] == PART_OUTER) >= 0.99 * np.count_nonzero(
        amphora.face_part == PART_OUTER)
    _check_clean(res)
    roots = res.attachment_roots
    assert len(roots) > 0 and roots.max() < len(res.flat.mesh.faces)
    # each root face touches a left-out attachment face in the scan
    touched = np.zeros(len(amphora.mesh.vertices), bool)
    touched[amphora.mesh.faces[att.face_mask].ravel()] = True
    assert touched[amphora.mesh.faces[res.face_index[roots]]].any(axis=1).all()


def test_keep_attachments_keeps_them(amphora):
    res = rollout(amphora.mesh, keep_attachments=True)
    handle = np.flatnonzero(amphora.face_part == PART_HANDLE)
    # kept, cut through (a handle joined at both ends cannot be laid flat: test_disk_cut.py),
    # and what then folds over the wall trimmed
    assert res.disk_cut.handles == 2 and np.all(np.isin(res.disk_cut_faces, handle))
    assert np.all(np.isin(handle, np.concatenate([res.face_index, res.disk_cut_faces, res.trimmed])))
    assert np.isin(handle, res.face_index).any()
    assert len(res.attachment_roots) == 0 and res.attachments_kept


def _rim_cylinder(n_theta=48):
    """An open cylinder (radius 30, height 40) with a flat rim top 4 wide facing up."""
    r = [30.0, 30.0, 30.0, 28.0, 26.0]
    h = [0.0, 20.0, 40.0, 40.0, 40.0]
    V, F, labels, _ = revolve(r, h, n_theta, labels=["wall", "wall", "rim", "rim"])
    return Mesh(V, F), labels


def test_rim_top_is_trimmed_exactly():
    mesh, labels = _rim_cylinder()
    res = rollout(mesh, proxy="cylinder", axis=(0, 0, 0, 0, 0, 1))
    assert set(labels[res.trimmed]) == {"rim"}
    assert set(labels[res.face_index]) == {"wall"}
    assert len(res.trimmed) == np.count_nonzero(labels == "rim")
    # chords of the 48-gon, away from the seam (whose vertices may move onto its meridian)
    u = res.flat.uv[:, 0]
    F = res.flat.mesh.faces
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    e = e[~np.isin(u[e], (u.min(), u.max())).any(axis=1)]
    assert np.sqrt(np.mean(edge_length_error(res.flat.mesh.vertices, res.flat.uv, e) ** 2)) < 1e-3
    _check_clean(res)


@pytest.mark.parametrize("rim_width, proxy", [(0.1, "cylinder"), (4.0, "cylinder"), (0.1, "auto")])
def test_a_trimmed_strip_leaves_the_development_of_the_surface_without_it(monkeypatch, rim_width, proxy):
    """Trimming cuts the strip from the development and develops the rest again on its proxy
    fitted (or chosen) without it, in one unrolling: the development of the surface without
    the strip, and exactly the strip trimmed. (The seam is given: an automatic one goes where
    the least area is, which the strip's own faces move.)"""
    import potflat.rollout.unroll as unroll_module

    r = [30.0, 30.0, 30.0, 30.0 - rim_width / 2, 30.0 - rim_width]
    h = [0.0, 20.0, 40.0, 40.0, 40.0]
    V, F, labels, _ = revolve(r, h, 48, labels=["wall", "wall", "rim", "rim"], jitter=0.3)
    rim = labels == "rim"
    calls = []
    real = unroll_module._unroll
    monkeypatch.setattr(unroll_module, "_unroll", lambda *a, **k: calls.append(1) or real(*a, **k))
    res = rollout(Mesh(V, F), proxy=proxy, axis=(0, 0, 0, 0, 0, 1), seam=50.0)
    assert len(calls) == 1
    assert set(labels[res.trimmed]) == {"rim"} and len(res.trimmed) == np.count_nonzero(rim)
    assert set(labels[res.face_index]) == {"wall"}
    _check_clean(res)
    without = rollout(Mesh(V, F), proxy=proxy, axis=(0, 0, 0, 0, 0, 1), face_mask=~rim, seam=50.0)
    assert len(without.trimmed) == 0 and without.proxy.kind == res.proxy.kind
    assert without.proxy.params == pytest.approx(res.proxy.params, rel=1e-12)
    assert np.array_equal(without.face_index, res.face_index)
    assert np.array_equal(without.flat.mesh.faces, res.flat.mesh.faces)
    assert np.allclose(without.flat.uv, res.flat.uv, rtol=0.0, atol=1e-9 * np.ptp(res.flat.uv))


def _grid(nx: int, ny: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A flat grid of ``nx`` x ``ny`` unit squares, each cut into two triangles: the layout
    (n, 2), the vertex numbers by row and column (ny + 1, nx + 1) and the faces (m, 3)."""
    x, y = np.meshgrid(np.arange(nx + 1.0), np.arange(ny + 1.0))
    uv = np.column_stack([x.ravel(), y.ravel()])
    q = np.arange(len(uv)).reshape(ny + 1, nx + 1)
    a, b, c, d = q[:-1, :-1].ravel(), q[:-1, 1:].ravel(), q[1:, 1:].ravel(), q[1:, :-1].ravel()
    return uv, q, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def test_border_folds_keeps_enclosed_folds_and_untangle_fixes_them():
    # a 6 x 6 vertex grid with one interior vertex pushed across its neighbours
    uv, q, faces = _grid(5, 5)
    area = np.full(len(faces), 0.5)
    folded = uv.copy()
    folded[q[2, 2]] += [1.6, 1.3]
    assert np.any(signed_areas(faces, folded) <= 0)
    assert not border_folds(faces, folded, area).any()  # enclosed: left to untangle
    fixed, n_bad, moved = untangle(faces, folded)
    assert n_bad > 0 and moved >= 1 and np.all(signed_areas(faces, fixed) > 0)
    border = np.unique(edges_and_boundary(faces, 36)[1])
    np.testing.assert_array_equal(fixed[border], folded[border])
    # the same fold on the border is trimmed
    edge = uv.copy()
    edge[q[0, 2]] += [0.0, 1.5]
    drop = border_folds(faces, edge, area)
    assert drop.any() and np.all(signed_areas(faces[~drop], edge) > 0)
    # the caller's edge table (computed once for a face set) gives the same answers
    table = edges_and_boundary(faces, 36)
    again, n_again, moved_again = untangle(faces, folded, table=table)
    np.testing.assert_array_equal(again, fixed)
    assert (n_again, moved_again) == (n_bad, moved)


@pytest.mark.parametrize("seed", range(4))
def test_untangle_against_its_definition_on_a_noisy_development(seed):
    """Patches of noise on a grid, some at its border (a noisy scan's development: the region
    grows in most rounds and widens, through boundary vertices too) untangled as the plain
    definition does it (tests/reference.py), to the last bit: the region's rows and faces kept
    up as it grows are the ones it has."""
    import reference

    from potflat.rollout.border import UNTANGLE_ROUNDS, UNTANGLE_WIDEN

    rng = np.random.default_rng(seed)
    nx, ny = 40, 30
    uv, q, faces = _grid(nx, ny)
    centres = rng.uniform([0, 0], [nx, ny], (4, 2))
    centres[0, 1] = 0.0  # one patch at the border
    near = (np.linalg.norm(uv[:, None] - centres[None], axis=2) < 5).any(axis=1)
    uv[near] += rng.normal(0.0, 0.5 + 0.1 * seed, (near.sum(), 2))
    assert (signed_areas(faces, uv) <= 0).sum() >= 20
    got = untangle(faces, uv)
    want = reference.untangle(faces, uv, UNTANGLE_ROUNDS, UNTANGLE_WIDEN)
    np.testing.assert_array_equal(got[0], want[0])
    assert got[1:] == want[1:] and got[2] < 0.9 * len(uv)  # (the region does not take the whole grid)


def test_crossing_segments_against_brute_force():
    rng = np.random.default_rng(3)
    uv = rng.uniform(0, 10, (60, 2))
    seg = rng.integers(0, 60, (40, 2))
    seg = seg[seg[:, 0] != seg[:, 1]]
    a, b = crossing_segments(uv, seg)
    got = {tuple(sorted(p)) for p in zip(a.tolist(), b.tolist())}

    def orient(p, q, r):
        return np.sign((q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]))

    want = set()
    for i in range(len(seg)):
        for j in range(i + 1, len(seg)):
            if set(seg[i]) & set(seg[j]):
                continue
            p, q, r, s = uv[seg[i, 0]], uv[seg[i, 1]], uv[seg[j, 0]], uv[seg[j, 1]]
            if orient(p, q, r) * orient(p, q, s) < 0 and orient(r, s, p) * orient(r, s, q) < 0:
                want.add((i, j))
    assert got == want and len(want) > 0
    # touching: a copy of a vertex on another segment counts
    uv2 = np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.0], [1.0, 1.0]])
    a, _ = crossing_segments(uv2, np.array([[0, 1], [2, 3]]))
    assert len(a) == 1


def test_stage_writes_profile_and_reports(tmp_path, cup):
    scan = write_ply_colored(cup, tmp_path / "cup.ply")
    out = run_rollout_stage(scan, tmp_path / "out")
    csv, svg = out.paths["profile_csv"], out.paths["profile_svg"]
    assert csv.name == "cup.profile.csv" and svg.name == "cup.profile.svg"
    rows = csv.read_text().splitlines()
    assert rows[0] == "height_mm,outer_radius_mm,inner_radius_mm" and len(rows) > 5
    inner = [r.split(",")[2] for r in rows[1:]]
    assert sum(bool(x) for x in inner) > len(inner) // 2  # the cup's two walls are both profiled
    assert svg.read_text().startswith("<?xml") and "<polygon" in svg.read_text()
    data = json.loads(out.paths["json"].read_text())
    assert data["files"]["profile_csv"] == csv.name and data["files"]["profile_svg"] == svg.name
    assert data["walls"]["side"] == "outer" and data["walls"]["two_walled"]
    assert data["trimmed"]["faces"] > 0 and data["trimmed"]["area_mm2"] > 0
    assert data["attachments"]["faces_left_out"] == 0 and data["boundary_overlap"] == 0
    assert data["profile"]["two_walled"] and data["provenance"]["options"]["side"] == "outer"


@pytest.mark.parametrize("scan", SCANS)
def test_real_scans_roll_out_one_wall_cleanly(real_scans, scan):
    from potflat.io.scan import load_scan

    mesh = load_scan(real_scans / scan).mesh
    res = rollout(mesh)
    assert res.walls.two_walled
    # the inner wall's faces in the image are only those the line between the walls reaches over
    taken = res.face_index[res.walls.labels[res.face_index] != OUTER]
    assert np.all(res.wall_cut.face_mask[taken]) and np.all(res.wall_cut.level[mesh.faces[taken]].max(axis=1) > 0)
    assert res.wall_cut.faces_added < 0.02 * res.walls.n_selected
    _check_clean(res)
    # what was trimmed is a fringe (rim top, base underside, ragged borders)
    assert len(res.trimmed) < 0.05 * res.walls.n_selected


def test_potflat_run_on_a_real_scan_is_fold_free(tmp_path, real_scans):
    from potflat_cli.main import app

    out = tmp_path / "out"
    result = CliRunner().invoke(app, ["run", str(real_scans / "sea-vase.ply"), "-o", str(out), "--preset", "preview",
                                      "--px-per-mm", "1", "--quiet"])
    assert result.exit_code == 0, result.output
    relaxed = json.loads((out / "sea-vase.relaxed.json").read_text())
    assert relaxed["flipped"] == 0 and relaxed["fold_free"]
    rolled = json.loads((out / "sea-vase.rollout.json").read_text())
    assert rolled["attachments"]["faces_left_out"] > 0 and rolled["untangled"]["faces"] > 0
    assert (out / "sea-vase.png").exists() and (out / "sea-vase.profile.svg").exists()
    flat = read_flat_ply(out / "sea-vase.relaxed.ply")
    assert np.all(signed_areas(flat.mesh.faces, flat.uv) > 0)


def test_thick_sherd_unrolls_its_painted_face_only():
    # a thick sherd's back is about as large as its face: it must not be read as inside-out
    sv = make_vessel("sherd", n_vertices=6000, seed=3, texture_size=64, sherd_of="kylix", sherd_thickness=3.0)
    res = rollout(sv.mesh)
    assert not res.walls.normals_inverted
    parts = sv.face_part[res.face_index]
    assert not np.any(parts == PART_INNER)
    # (about 12 % of the face is lost where the wall labels meet the break faces)
    assert np.count_nonzero(parts == PART_OUTER) > 0.8 * np.count_nonzero(sv.face_part == PART_OUTER)
    assert res.seam_method == "gap" and res.seam_vertices == 0
    _check_clean(res)


def test_a_separate_inner_wall_is_kept_but_a_second_vessel_is_left_out():
    """Pieces sharing the vessel's axis stay (an inner wall scanned apart); a second vessel
    beside it is left out, with a note."""
    from potflat_synthetic.vessels import make_vessel

    from potflat.rollout import rollout
    from potflat.types import Mesh

    a = make_vessel("amphora", n_vertices=3000, seed=1, texture_size=64, pose=False)
    inner = Mesh(a.mesh.vertices * [0.95, 0.95, 1.0], a.mesh.faces[:, ::-1])  # same axis, facing it
    V = np.vstack([a.mesh.vertices, inner.vertices])
    F = np.vstack([a.mesh.faces, inner.faces + len(a.mesh.vertices)])
    res = rollout(Mesh(V, F))
    assert res.other_objects_faces == 0
    b = make_vessel("hydria", n_vertices=2000, seed=4, texture_size=64, pose=False)
    V2 = np.vstack([a.mesh.vertices, b.mesh.vertices + [600.0, 0, 0]])
    F2 = np.vstack([a.mesh.faces, b.mesh.faces + len(a.mesh.vertices)])
    res2 = rollout(Mesh(V2, F2))
    # the larger vessel is kept whole, the other left out whole
    assert res2.other_objects_faces in (len(a.mesh.faces), len(b.mesh.faces))
    x = res2.flat.mesh.vertices[:, 0]
    assert x.max() < 300.0 or x.min() > 300.0
    assert abs(res2.axis.direction[2]) > np.cos(np.radians(1.0))
    assert any("separate objects" in n for n in __import__("potflat.rollout.notes").rollout.notes.rollout_notes(res2))


def test_a_sherd_whose_two_faces_are_separate_pieces_keeps_both(real_scans):
    """A sherd cut from the dragon jar's belly (90 degrees, 18 cm), both faces and no breaks:
    two pieces. The inner face's own axis fit leans 8 degrees off the outer's (a small concave
    patch), but its normals lie in the outer's meridian planes (median 0.9 degrees): it is
    the same vessel's inner wall, kept, and ``side="inner"`` unrolls it."""
    from potflat.io.scan import load_scan
    from potflat.rollout import rollout

    mesh = load_scan(real_scans / "dragon-jar.glb").mesh
    V, F = mesh.vertices, mesh.faces
    centre = V[F].mean(axis=1)
    middle = 0.5 * (V.min(axis=0) + V.max(axis=0))
    angle = np.degrees(np.arctan2(centre[:, 2] - middle[2], centre[:, 0] - middle[0])) % 360.0
    height = centre[:, 1] - V[:, 1].min()
    keep = (angle > 20) & (angle < 110) & (height > 0.12) & (height < 0.30)
    sherd = mesh.replace(faces=F[keep], **mesh.face_fields(keep))
    outer = rollout(sherd)
    inner = rollout(sherd, side="inner")
    assert outer.other_objects_faces == 0 and inner.other_objects_faces == 0
    assert len(outer.face_index) + len(inner.face_index) == len(sherd.faces)


def test_a_separate_ground_plate_is_left_out_and_does_not_tilt_the_axis():
    """A flat plate under the foot, not joined to it: its normals run along the axis, so they
    tell nothing of it (a plate lies in every meridian plane): it is not taken for a wall of
    the vessel and stays out of the axis fit."""
    from potflat_synthetic.vessels import make_vessel

    from potflat.rollout import rollout
    from potflat.types import Mesh

    a = make_vessel("amphora", n_vertices=3000, seed=1, texture_size=64, pose=False).mesh
    alone = rollout(Mesh(a.vertices, a.faces))
    lo, hi = a.vertices.min(axis=0), a.vertices.max(axis=0)
    u, v = np.meshgrid(np.linspace(-150.0, 150.0, 30), np.linspace(-150.0, 150.0, 30), indexing="ij")
    plate = np.column_stack([u.ravel(), v.ravel(), np.full(u.size, lo[2] - 2.0)]) + [0.5 * (lo[0] + hi[0]),
                                                                                      0.5 * (lo[1] + hi[1]), 0.0]
    idx = np.arange(900).reshape(30, 30)
    q = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    plate_faces = np.concatenate([np.stack([q[0], q[1], q[2]], 1), np.stack([q[0], q[2], q[3]], 1)])
    both = rollout(Mesh(np.vstack([a.vertices, plate]), np.vstack([a.faces, plate_faces + len(a.vertices)])))
    assert both.other_objects_faces == len(plate_faces)
    np.testing.assert_allclose(both.axis.direction, alone.axis.direction, atol=1e-9)


@pytest.mark.parametrize("kind, handles", [("amphora", True), ("hydria", True), ("bowl", False)])
def test_two_like_vessels_side_by_side_give_the_rollout_of_one(kind, handles):
    """A scan file holding the vessel twice, side by side (a pair scanned together), handles as
    separate pieces, or two walls (the bowl: the other's outer wall must not make this one's
    inner): the other vessel and its pieces are left out of the side's labelling, the
    attachments' measures and the unrolling, so one vessel comes out as it does alone."""
    from potflat_synthetic.vessels import make_vessel

    from potflat.rollout import rollout
    from potflat.types import Mesh

    m = make_vessel(kind, n_vertices=6000, seed=2, texture_size=64, handles=handles, pose=False).mesh
    alone = rollout(m)
    V = np.vstack([m.vertices, m.vertices + [3.0 * np.ptp(m.vertices[:, 0]), 0.0, 0.0]])
    pair = rollout(Mesh(V, np.vstack([m.faces, m.faces + len(m.vertices)])))
    assert alone.other_objects_faces == 0 and pair.other_objects_faces == len(m.faces)
    assert pair.attachments.n_faces == alone.attachments.n_faces and (alone.attachments.n_faces > 0) == handles
    assert len(pair.attachments.components) == len(alone.attachments.components)
    assert pair.attachments.noise == pytest.approx(alone.attachments.noise, rel=0.01)
    assert (pair.walls.n_selected, pair.walls.n_outer, pair.walls.n_inner) == (
        alone.walls.n_selected, alone.walls.n_outer, alone.walls.n_inner)
    assert len(pair.face_index) == len(alone.face_index)
    assert pair.distortion.edge_rms == pytest.approx(alone.distortion.edge_rms, rel=0.01)


def test_border_folds_trims_the_piece_beyond_an_edge_on_band():
    """A development whose second row of faces is edge-on and folded (the surface turning
    under at a foot): trimming that band cuts the first row off the wall, and the cut-off
    row, which lies over the wall, goes with it; nothing of the wall is peeled."""
    nx, ny = 10, 20
    uv, q, faces = _grid(nx, ny)
    row = np.concatenate([np.repeat(np.arange(ny), nx)] * 2)
    area = np.full(len(faces), 0.5)
    uv[q[2]] = uv[q[2]] - [0.0, 1.2]  # the band of row 1 folds: row 2's lower edge dips below row 0's top
    assert np.all(signed_areas(faces[row == 1], uv) <= 0) and np.all(signed_areas(faces[row != 1], uv) > 0)
    drop = border_folds(faces, uv, area)
    np.testing.assert_array_equal(drop, row <= 1)


def test_border_folds_trims_the_teeth_left_along_a_trimmed_strip():
    """A rim-top strip edge-on to the proxy, folded in two places, with one vertex of it
    standing up (a noisy rim): the strip is trimmed, and so are the two faces left standing
    at that vertex as a tooth; nothing of the wall below is."""
    nx, ny = 10, 6
    uv, q, faces = _grid(nx, ny)
    row = np.concatenate([np.repeat(np.arange(ny), nx)] * 2)
    area = np.full(len(faces), 0.5)
    uv[q[-1], 1] = ny - 1 + 0.02  # the top row edge-on
    uv[q[-1, [2, 8]], 1] = ny - 1 - 0.1  # folded
    uv[q[-1, 5], 1] = ny  # a tooth
    tooth = (row == ny - 1) & (signed_areas(faces, uv) > 0.05 * area)
    assert tooth.sum() == 2
    np.testing.assert_array_equal(border_folds(faces, uv, area), row == ny - 1)


@pytest.mark.parametrize("seed", range(6))
def test_border_folds_peeling_in_place_equals_rebuilding_every_pass(seed):
    """Updating the border around the peeled faces gives what rebuilding the kept faces' edge
    table, pieces and overlapping faces at every pass gives (tests/reference.py), on grids
    with a folded band, a ragged rim, a flap over the wall and vertices sharing a 3D place."""
    import reference

    rng = np.random.default_rng(seed)
    nx, ny = 14, 18
    uv, q, faces = _grid(nx, ny)
    uv[q[2]] -= [0.0, 1.2 + 0.3 * seed / 5]  # a folded band near the foot
    uv[q[-1, 1:-1:2], 1] -= rng.uniform(0.8, 2.2, len(q[-1, 1:-1:2]))  # a ragged rim
    uv[q[ny // 2, -3:]] += [-2.5 - seed % 3, 0.4]  # a flap folded back over the wall
    uv += rng.normal(0.0, 0.08, uv.shape)
    area = rng.uniform(0.3, 0.7, len(faces))
    points = np.column_stack([uv, np.zeros(len(uv))])
    points[q[-1, 3]] = points[q[-1, 5]]  # two rim vertices at one 3D place
    for pts in (None, points):
        np.testing.assert_array_equal(border_folds(faces, uv, area, points=pts),
                                      reference.border_folds(faces, uv, area, points=pts))


def test_border_folds_reads_every_pass_off_one_edge_table(monkeypatch):
    """However many passes the trimming takes, the development's edge table is built once
    (shared by the border and the face adjacency; once more for the flipped edge-on faces
    while there are some), not once a pass: a pass updates the border around the peeled
    faces (at 1M vertices 300 passes rebuilt it 452 times; this ragged rim 9 times)."""
    from potflat.mesh import boundary, distortion
    from potflat.mesh._kernels import topology
    from potflat.rollout import walls

    nx, ny = 12, 20
    uv, q, faces = _grid(nx, ny)
    # a ragged rim: every other top vertex pushed down across its neighbours' edge, so the
    # overlapping border is peeled a few faces a pass
    top = q[-1, 1:-1:2]
    uv[top] -= [0.0, 1.6]
    calls = []
    real = topology.edge_table
    for module in (topology, boundary, distortion, walls):
        monkeypatch.setattr(module, "edge_table", lambda *args: calls.append(1) or real(*args))
    drop = border_folds(faces, uv, np.full(len(faces), 0.5))
    assert drop.any() and np.all(signed_areas(faces[~drop], uv) > 0)
    assert len(calls) <= 2


def _two_fans_at_one_place():
    """A fan of four triangles around vertex 0 and one triangle around vertex 6, a copy of
    vertex 0 (same place, as cleaning leaves a non-manifold vertex: one copy per fan)."""
    a = np.radians([0, 45, 90, 135, 180])
    uv = np.concatenate([[[0.0, 0.0]], np.c_[np.cos(a), np.sin(a)], [[0.0, 0.0], [-0.3, -0.5], [0.3, -0.5]]])
    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 5], [6, 7, 8]])
    return faces, uv, np.c_[uv, np.zeros(len(uv))], np.abs(signed_areas(faces, uv))


def test_border_folds_keeps_the_largest_fan_of_a_vertex_split_into_copies():
    faces, uv, points, area = _two_fans_at_one_place()
    assert (signed_areas(faces, uv) > 0).all()
    # the copies count as one pinched vertex: only the smaller fan goes
    np.testing.assert_array_equal(border_folds(faces, uv, area, points=points), [0, 0, 0, 0, 1])
    # taken as two vertices, the fans only touch: the faces at the touching point go from both
    assert border_folds(faces, uv, area)[:4].any()


def test_border_folds_trims_a_flap_lying_over_the_wall_whole():
    # a strip wound a turn and a bit (a spiral: its end lies over its start, no face flipped):
    # the whole crossing region goes, both sheets, not only the faces owning crossing segments
    k, turn = 60, 2 * np.pi + 1.0
    a = np.linspace(0, turn, k + 1)
    r = 1.0 + 0.1 * a / (2 * np.pi)
    uv = np.concatenate([np.c_[r * np.cos(a), r * np.sin(a)], np.c_[(r + 0.3) * np.cos(a), (r + 0.3) * np.sin(a)]])
    i = np.arange(k)
    faces = np.concatenate([np.c_[i, k + 2 + i, i + 1], np.c_[i, k + 1 + i, k + 2 + i]])
    area = signed_areas(faces, uv)
    over = overlapping_faces(faces, uv)
    assert (area > 0).all() and over.any()
    drop = border_folds(faces, uv, area)
    assert drop[over].all() and drop.sum() < 0.4 * len(faces)
    assert not overlapping_faces(faces[~drop], uv).any()
    assert len(crossing_segments(uv, edges_and_boundary(faces[~drop], len(uv))[1])[0]) == 0
