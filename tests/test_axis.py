from pathlib import Path

import numpy as np
import pytest
import trimesh

from _revolve import cone, cylinder, revolve, vase
from potflat.rollout.axis import (AxisFit, axis_residuals, cylindrical, estimate_axis, manual_axis, orient,
                          reference_direction)
from potflat.errors import AxisNotFoundError, InvalidInputError, InvalidOptionError
from potflat.types import Mesh

def _angle_deg(a, b):
    return np.degrees(np.arccos(np.clip(abs(a @ b) / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


def _line_distance(point, fit: AxisFit):
    d = point - fit.point
    return np.linalg.norm(d - (d @ fit.direction) * fit.direction)


@pytest.mark.parametrize("make", [cylinder, cone, vase])
@pytest.mark.parametrize("kw", [{}, {"theta_range": (0.3, 1.8)},
                                {"holes": [(1.0, 1.6, 0.3, 0.6), (4.0, 4.3, 0.1, 0.9)]}],
                         ids=["full", "sherd", "holed"])
def test_axis_recovered_on_posed_surfaces(make, kw):
    mesh, R, shift, _ = make(seed=3, **kw)
    fit = estimate_axis(mesh)
    assert _angle_deg(fit.direction, R[:, 2]) < 0.2
    assert _line_distance(shift, fit) < 0.01 * 30
    assert fit.method in ("normals", "normals+profile")
    assert np.isclose(np.linalg.norm(fit.direction), 1.0)
    # heights run from the foot (0) to the mouth (height)
    h, r, theta = fit.cylindrical(mesh.vertices)
    assert abs(h.min()) < 1e-9 and np.isclose(h.max(), fit.height)
    assert fit.median_angle_deg < 3 and fit.profile_deviation < 0.01


def test_axis_sign_points_to_the_open_mouth():
    mesh, R, _, _ = vase(seed=1, cap=True)  # closed foot, open mouth (narrower than the foot)
    fit = estimate_axis(mesh)
    assert fit.direction @ R[:, 2] > 0.999
    assert "rim" in fit.orientation
    flipped = estimate_axis(mesh, flip=True)
    np.testing.assert_allclose(flipped.direction, -fit.direction)
    assert "flipped" in flipped.orientation


def test_axis_sign_from_the_inner_wall():
    # a cup: outer wall, lip, inner wall (facing the axis), closed outer foot; the mouth is
    # where the inner wall is, although both ends are the same width
    m_out, *_ = revolve(lambda s: np.full_like(s, 30.0), lambda s: 60 * s, pose=False, seed=0, cap=True)
    m_in, *_ = revolve(lambda s: np.full_like(s, 27.0), lambda s: 15 + 45 * s, pose=False, seed=1)
    inner_faces = m_in.faces[:, ::-1] + len(m_out.vertices)
    V = np.vstack([m_out.vertices, m_in.vertices])
    F = np.vstack([m_out.faces, inner_faces])
    cup = Mesh(V, F)
    d, reason, guessed = orient(cup, np.zeros(3), np.array([0, 0, -1.0]))
    assert d[2] > 0 and "inner wall" in reason and not guessed


def test_a_jar_scanned_without_its_interior_is_not_turned_over_by_its_foot_ring():
    """A cup with a foot ring whose inside was not scanned (its outer wall, base and foot ring
    only, the mouth open): the foot ring's inside faces the axis at the foot's end, but its
    base closes it across, so it is no mouth. The open rim decides. With a lid over the
    mouth (no open rim) the wider end is taken and said to be a guess."""
    import _vessel_meshes as vm

    V, F, L, _ = vm.cup(foot_ring=True)
    outside = np.isin(L, ["base", "ring", "outer"])
    jar = Mesh(V, F[outside])
    d, reason, guessed = orient(jar, np.zeros(3), np.array([0, 0, -1.0]))
    assert d[2] > 0 and "open rim" in reason and not guessed
    top = V[:, 2] >= V[F[outside]][:, :, 2].max() - 1e-9
    rim = np.flatnonzero(top & np.isin(np.arange(len(V)), F[outside]))
    rim = rim[np.argsort(np.arctan2(V[rim, 1], V[rim, 0]))]
    lid = np.column_stack([np.roll(rim, -1), rim, np.full(len(rim), len(V))])  # (counter-clockwise seen from above)
    closed = Mesh(np.vstack([V, [[0.0, 0.0, V[rim, 2].mean()]]]), np.vstack([F[outside], lid]))
    d, reason, guessed = orient(closed, np.zeros(3), np.array([0, 0, -1.0]))
    assert d[2] > 0 and "wider end" in reason and guessed


def test_a_dish_face_scanned_alone_is_not_turned_over_by_its_well():
    """The face of a plate alone, facing up as photographed lying on a table: its well faces
    the axis at the floor's end, but the floor closes it across, so it is no mouth. The open
    rim decides."""
    import _vessel_meshes as vm

    V, F, _, _ = vm.dish()
    d, reason, guessed = orient(Mesh(V, F), np.zeros(3), np.array([0, 0, -1.0]))
    assert d[2] > 0 and "open rim" in reason and not guessed


def test_wider_end_tie_break_for_a_closed_shape():
    mesh = trimesh.creation.cone(radius=20, height=50, sections=48)  # closed: base disk + apex
    d, reason, guessed = orient(Mesh(mesh.vertices, mesh.faces), np.zeros(3), np.array([0, 0, 1.0]))
    assert d[2] < 0 and "wider end" in reason and guessed


def test_a_mouth_taken_at_the_wider_end_is_flagged_as_a_guess_unless_flipped():
    """A closed cone without a cavity: only the wider end tells the mouth, a guess the fit says
    it is (and the rollout warns of); a flip on request is the user's answer to it. An open
    vessel's mouth is found at its rim, not guessed."""
    solid = trimesh.creation.cone(radius=20, height=50, sections=48).subdivide().subdivide()
    closed = Mesh(solid.vertices, solid.faces)
    fit = estimate_axis(closed)
    assert fit.mouth_guessed and fit.as_dict()["mouth_guessed"] is True and "wider end" in fit.orientation
    assert not estimate_axis(closed, flip=True).mouth_guessed
    open_cone, *_ = cone(cap=True)
    assert not estimate_axis(open_cone).mouth_guessed


def test_box_has_no_axis():
    box = trimesh.creation.box((30, 50, 70)).subdivide().subdivide().subdivide()
    with pytest.raises(AxisNotFoundError, match=r"give --axis px,py,pz,dx,dy,dz") as exc:
        estimate_axis(Mesh(box.vertices, box.faces, source=Path("box.ply")))
    msg = str(exc.value)
    assert "\n" not in msg and "box.ply" in msg and "%" in msg and "deg" in msg


def test_random_blob_has_no_axis():
    rng = np.random.default_rng(2)
    s = trimesh.creation.icosphere(3, radius=20)
    v = s.vertices * rng.uniform(0.5, 1.5, 3)
    v = v * (1 + 0.2 * np.sin(v @ rng.normal(size=3) / 10))[:, None]
    with pytest.raises(AxisNotFoundError):
        estimate_axis(Mesh(v, s.faces))


def test_sphere_axis_is_reported_as_undetermined():
    s = trimesh.creation.icosphere(3, radius=20)
    fit = estimate_axis(Mesh(s.vertices + [5, 7, 9], s.faces))
    assert fit.method == "pca" and "undetermined" in fit.note
    assert _line_distance(np.array([5.0, 7, 9]), fit) < 1e-6


def test_sphere_with_an_opening_takes_the_axis_through_it():
    s = trimesh.creation.icosphere(3, radius=20)
    c = s.triangles_center
    keep = c @ np.array([0.6, 0.0, 0.8]) < 15.0
    fit = estimate_axis(Mesh(s.vertices, s.faces[keep]))
    assert fit.method == "centre+opening"
    assert _angle_deg(fit.direction, np.array([0.6, 0.0, 0.8])) < 1.0
    assert fit.direction @ np.array([0.6, 0.0, 0.8]) > 0


def test_manual_axis_and_its_residuals():
    mesh, R, shift, _ = cylinder(seed=2)
    fit = manual_axis(mesh, shift + 5 * R[:, 2], 3 * R[:, 2])
    assert fit.method == "manual"
    np.testing.assert_allclose(fit.direction, R[:, 2], atol=1e-12)
    assert _line_distance(shift, fit) < 1e-9
    assert fit.profile_deviation < 1e-12
    tilted = axis_residuals(mesh, shift, R[:, 2] + 0.05 * R[:, 0])
    assert tilted[0] > fit.rms_angle_deg and tilted[3] > fit.misfit_angle_deg and tilted[4] > 0.005
    assert manual_axis(mesh, shift, R[:, 2], flip=True).direction @ R[:, 2] < 0


def test_manual_axis_validation():
    mesh, *_ = cylinder()
    with pytest.raises(InvalidOptionError, match="zero"):
        manual_axis(mesh, [0, 0, 0], [0, 0, 0])
    with pytest.raises(InvalidOptionError, match="6 finite"):
        manual_axis(mesh, [0, 0, np.nan], [0, 0, 1])


def test_empty_and_nan_meshes_are_rejected():
    with pytest.raises(InvalidInputError, match="no faces"):
        estimate_axis(Mesh(np.zeros((3, 3)), np.zeros((0, 3), int)))
    with pytest.raises(InvalidInputError, match="NaN"):
        estimate_axis(Mesh(np.array([[0, 0, 0], [1, 0, 0], [np.nan, 1, 0]]), [[0, 1, 2]]))


def test_reference_direction_and_cylindrical_coordinates():
    rng = np.random.default_rng(0)
    for _ in range(5):
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        e = reference_direction(d)
        assert abs(e @ d) < 1e-12 and np.isclose(np.linalg.norm(e), 1)
    # theta counter-clockwise about +z from +x
    h, r, th = cylindrical(np.array([[1.0, 0, 2], [0, 1, 3], [-1, 0, 0]]), np.zeros(3),
                           np.array([0, 0, 1.0]), np.array([1.0, 0, 0]))
    np.testing.assert_allclose(h, [2, 3, 0])
    np.testing.assert_allclose(r, 1)
    np.testing.assert_allclose(th, [0, np.pi / 2, np.pi])


def test_deterministic():
    mesh, *_ = vase(seed=5)
    a, b = estimate_axis(mesh), estimate_axis(mesh)
    assert np.array_equal(a.point, b.point) and np.array_equal(a.direction, b.direction)


def test_real_goblet_axis(real_scans):
    from potflat.io.scan import load_scan

    mesh = load_scan(real_scans / "goblet.stl").mesh  # designed exact surface of revolution, upright in +z
    fit = estimate_axis(mesh)
    assert fit.direction[2] > np.cos(np.radians(0.5))  # mouth (cup, inner wall) up
    assert fit.median_angle_deg < 1.0 and fit.profile_deviation < 0.03


@pytest.mark.parametrize("name", ["plastic-vase.ply", "sea-vase.ply"])
def test_real_scanned_vases_axis(real_scans, name):
    from potflat.io.scan import load_scan

    mesh = load_scan(real_scans / name).mesh  # both stand roughly upright along +z in their files
    fit = estimate_axis(mesh)
    assert abs(fit.direction[2]) > np.cos(np.radians(3.0))
    assert fit.median_angle_deg < 10 and fit.profile_deviation < 0.05


def test_normal_lines_match_the_bincount_reference():
    """The vertex sums of the serial kernel: the same bits as NumPy's cross products and
    bincounts (a vertex without faces and a degenerate face included)."""
    from potflat.rollout.axis import normal_lines

    mesh, *_ = vase(seed=3)
    rng = np.random.default_rng(4)
    V = np.concatenate([mesh.vertices, [[1e3, 0.0, 0.0]]])  # unused: left out
    F = mesh.faces[rng.permutation(len(mesh.faces))]
    F = np.concatenate([F, [[0, 0, 1]]])  # no area
    cross = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    acc = np.stack([np.bincount(F.ravel(), np.repeat(cross[:, k], 3), len(V)) for k in range(3)], axis=1)
    area = np.bincount(F.ravel(), np.repeat(np.linalg.norm(cross, axis=1) / 6.0, 3), len(V))
    norm = np.linalg.norm(acc, axis=1)
    ok = (norm > 0) & (area > 0)
    want = (V[ok], acc[ok] / norm[ok, None], area[ok])
    got = normal_lines(Mesh(V, F))
    assert not ok[-1] and ok.sum() == len(mesh.vertices)
    assert all(g.dtype == w.dtype and g.tobytes() == w.tobytes() for g, w in zip(got, want))


@pytest.mark.parametrize("seed", range(3))
def test_profile_deviation_matches_the_sorting_reference(seed):
    """Slice medians by grouping and partitioning: the same figure, bit for bit, as a full
    lexsort (empty slices, a one-point slice and ties of radii included)."""
    from potflat.rollout.axis import _profile_deviation

    rng = np.random.default_rng(seed)
    h = np.concatenate([rng.uniform(0, 40, 3000), rng.uniform(60, 100, 3000), [50.0]])
    r = np.round(20 + 0.1 * h + rng.normal(0, 0.5, len(h)), 1)  # many equal radii
    t = rng.uniform(0, 2 * np.pi, len(h))
    points = np.column_stack([r * np.cos(t), r * np.sin(t), h])
    point, direction = np.array([0.1, -0.2, 0.0]), np.array([0.0, 0.01, 1.0]) / np.hypot(0.01, 1.0)
    hh = (points - point) @ direction
    rr = np.linalg.norm(points - point - hh[:, None] * direction, axis=1)
    idx = np.clip(((hh - hh.min()) / (hh.max() - hh.min()) * 32).astype(np.int64), 0, 31)
    order = np.lexsort((rr, idx))
    starts = np.searchsorted(idx[order], np.arange(32))
    ends = np.searchsorted(idx[order], np.arange(32), side="right")
    have = ends > starts
    med = rr[order][(starts + ends - 1)[have] // 2]
    mean_h = np.bincount(idx, hh, 32)[have] / np.bincount(idx, minlength=32)[have]
    want = float(np.median(np.abs(rr - np.interp(hh, mean_h, med))) / float(np.median(rr)))
    assert not have.all() and want > 0
    assert _profile_deviation(points, point, direction) == want


@pytest.mark.parametrize("share", [0.02, 0.1])
def test_misfit_angle_of_an_off_centre_axis_on_a_cylinder(share):
    """An axis off a cylinder's centre by a share s of its radius: a normal at angle theta from
    the offset leans -s sin(theta) / sqrt(1 - 2 s cos(theta) + s^2) out of its meridian plane,
    whose part turning once around is -s sin(theta) to first order: s / sqrt(2) RMS."""
    mesh, R, shift, _ = cylinder(R=30.0, seed=4, n_theta=180, jitter=0.0)
    exact = manual_axis(mesh, shift, R[:, 2])
    assert exact.misfit_angle_deg < 0.05  # (the faceting's random diagonals lean vertex normals a little)
    off = manual_axis(mesh, shift + share * 30.0 * R[:, 0], R[:, 2])
    expected = np.degrees(np.arcsin(share / np.sqrt(2)))
    assert off.misfit_angle_deg == pytest.approx(expected, abs=0.01)


def test_misfit_angle_tells_a_tilted_axis_from_relief(real_scans):
    """The shared real scans' relief, flutes and uneven hand-made wall lean their normals out of
    the meridian planes whatever the axis (``rms_angle_deg`` up to 14 deg on the fluted vase):
    their fitted axes stay under the warning's threshold, and the same axes tilted by 2
    degrees go over it."""
    from potflat.io.scan import load_scan
    from potflat.rollout.notes import WARN_AXIS_MISFIT_DEG

    assert f"Above {WARN_AXIS_MISFIT_DEG:g} the rollout warns" in (Path(__file__).parents[1] / "docs" /
                                                                  "formats.md").read_text()
    fluted = 0.0
    for name in ("dragon-jar.glb", "colonoware-pot.glb", "plastic-vase.ply", "sea-vase.ply", "goblet.stl"):
        mesh = load_scan(real_scans / name, units=None if name.endswith(".glb") else "mm").mesh
        fit = estimate_axis(mesh)
        assert fit.misfit_angle_deg < WARN_AXIS_MISFIT_DEG, (name, fit)
        fluted = max(fluted, fit.rms_angle_deg)
        tilt = np.radians(2.0)
        tilted = manual_axis(mesh, fit.point, np.cos(tilt) * fit.direction + np.sin(tilt) * fit.reference)
        assert tilted.misfit_angle_deg > WARN_AXIS_MISFIT_DEG, (name, tilted)
    assert fluted > 10.0


def test_misfit_angle_leaves_out_slices_that_do_not_determine_it():
    """A height slice whose points all lie at one angle around the axis (a narrow strip of
    a sherd) cannot tell a lean to one side from one all round: it adds nothing (its normal
    equations are singular), without an error or a warning."""
    import warnings

    from potflat.rollout.axis import _once_around

    k = 32 * 20  # (20 points in each of the 32 slices)
    radial = np.tile([1.0, 0.0, 0.0], (k, 1))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert _once_around(np.full(k, 0.1), np.linspace(0.0, 1.0, k), radial, np.ones(k),
                            np.array([0.0, 0.0, 1.0])) == 0.0
