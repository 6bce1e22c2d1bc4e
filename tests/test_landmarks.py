"""Seams and windows measured from landmarks (potflat.rollout.landmarks), and the overlap past 360 degrees."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.csgraph
from _vessel_meshes import cylinder_with_handle

from potflat.errors import InvalidOptionError
from potflat.files.rollout_stage import rollout_record as rollout_summary
from potflat.rollout.unroll import RolloutOptions, rollout
from potflat.types import Mesh

#: Azimuth (degrees, about +z from +x) of the painted sector of the test vessel.
PAINTED_AT = 120.0


def _azimuth(p):
    return np.degrees(np.arctan2(p[..., 1], p[..., 0])) % 360.0


def _circ(a, b):
    """Circular difference of angles in degrees, in [-180, 180)."""
    return (np.asarray(a) - b + 180.0) % 360.0 - 180.0


@pytest.fixture(scope="module")
def vessel():
    """Open cylinder (R 40, H 100, axis z) with a handle at azimuth 0 and dark spots painted in a
    60 degree sector around PAINTED_AT (vertex colours)."""
    V, F, _ = cylinder_with_handle(n_theta=90, n_h=26)
    az = _azimuth(V)
    lum = np.full(len(V), 200, np.uint8)
    spots = (np.abs(_circ(az, PAINTED_AT)) < 30) & ((np.round(V[:, 2] / 4) + np.round(az / 4)) % 2 == 0)
    lum[spots] = 20
    colours = np.repeat(lum[:, None], 3, axis=1)
    return Mesh(V, F, vertex_colors=colours)


def _seam_azimuths(res):
    """Azimuths of the vertices the cut duplicated (a copy at the same place)."""
    V = res.flat.mesh.vertices
    _, inverse, counts = np.unique(V, axis=0, return_inverse=True, return_counts=True)
    return _azimuth(V[counts[inverse.ravel()] > 1])


def test_seam_at_a_point(vessel):
    point = np.array([40 * np.cos(np.radians(250)), 40 * np.sin(np.radians(250)), 30.0])
    res = rollout(vessel, proxy="cylinder", seam_at=tuple(point))
    assert res.seam_method == "point" and res.landmark.kind == "point"
    assert np.abs(_circ(_seam_azimuths(res), 250.0)).max() < 5.0  # within a face of the point
    later = rollout(vessel, proxy="cylinder", seam_at=tuple(point), seam=30.0)
    assert later.seam_method == "user"
    assert abs(_circ(later.seam_angle - res.seam_angle, 30.0)) < 1e-9  # --seam measured from the point
    summary = rollout_summary(res)
    assert summary["seam"]["landmark"]["kind"] == "point"
    assert summary["seam"]["landmark"]["point"] == pytest.approx(point.tolist())


def test_seam_at_far_from_the_surface_is_refused(vessel):
    with pytest.raises(InvalidOptionError, match="from the scan's surface"):
        rollout(vessel, proxy="cylinder", seam_at=(500.0, 0.0, 0.0))


def test_seam_through_the_largest_handle(vessel):
    res = rollout(vessel, proxy="cylinder", landmark="handle")
    assert res.seam_method == "handle" and res.landmark.kind == "handle"
    assert np.abs(_circ(_seam_azimuths(res), 0.0)).max() < 5.0


def test_seam_opposite_the_painted_zone(vessel):
    res = rollout(vessel, proxy="cylinder", landmark="painted")
    assert res.landmark.kind == "painted zone"
    assert np.abs(_circ(_seam_azimuths(res), PAINTED_AT + 180.0)).max() < 8.0
    # the painting is in the middle of the rollout
    V, u = res.flat.mesh.vertices, res.flat.uv[:, 0]
    mid = 0.5 * (u.min() + u.max())
    assert abs(_circ(_azimuth(V[np.argmin(np.abs(u - mid))]), PAINTED_AT)) < 8.0


def test_angles_alone_centre_the_window_on_the_painting_and_keep_the_automatic_seam(vessel):
    auto = rollout(vessel, proxy="cylinder")
    res = rollout(vessel, proxy="cylinder", angles=(-40.0, 40.0))
    assert res.seam_method == auto.seam_method != "user"
    assert res.seam_angle == pytest.approx(auto.seam_angle)
    az = _azimuth(res.flat.mesh.vertices)
    assert np.abs(_circ(az, PAINTED_AT)).max() < 45.0
    assert abs(np.mean(_circ(az, PAINTED_AT))) < 5.0
    assert res.landmark.kind == "painted zone"


def test_unpainted_scan_says_it_has_no_painted_zone(vessel):
    plain = vessel.replace(vertex_colors=None)
    res = rollout(plain, proxy="cylinder", landmark="painted")
    assert any("no texture or vertex colours" in n for n in rollout_summary(res)["notes"])


def test_angles_with_seam_still_count_from_the_seam(vessel):
    res = rollout(vessel, proxy="cylinder", seam=90.0, angles=(0.0, 60.0))
    assert res.seam_method == "user" and res.landmark is None
    assert res.theta_origin == pytest.approx(90.0)
    assert res.region.theta_range_deg[0] >= -6 and res.region.theta_range_deg[1] <= 66


def test_overlap_repeats_the_start_past_360(vessel):
    base = rollout(vessel, proxy="cylinder")
    res = rollout(vessel, proxy="cylinder", overlap=45.0)
    n, start = len(res.flat.mesh.faces), res.region.repeated_from
    assert start == len(base.flat.mesh.faces)
    assert res.region.theta_range_deg[1] == pytest.approx(base.region.theta_range_deg[1] + 45.0, abs=6.0)
    # the repeats are the faces of the first 45 degrees, once more, attached: one piece, no crack
    assert set(res.face_index[start:]) <= set(res.face_index[:start])
    F = res.flat.mesh.faces
    adj = scipy.sparse.coo_matrix((np.ones(3 * n), (F.ravel(), np.roll(F, 1, axis=1).ravel())),
                                  shape=(len(res.flat.uv),) * 2)
    assert scipy.sparse.csgraph.connected_components(adj, directed=False)[0] == 1
    assert res.distortion.flipped == 0
    u = res.flat.uv[:, 0]
    assert (u.max() - u.min()) == pytest.approx(2 * np.pi * 40 * (1 + 45 / 360), rel=0.03)


def test_overlap_is_marked_in_the_baked_image(vessel, tmp_path):
    from PIL import Image

    from potflat.bake.marks import REPEAT_COLOUR
    from potflat.bake.options import BakeOptions
    from potflat.files.bake_stage import run_bake_stage
    from potflat.io.atomic import write_json_atomic
    from potflat.io.flat_ply import write_flat_ply

    res = rollout(vessel, proxy="cylinder", overlap=45.0)
    write_flat_ply(tmp_path / "v.rollout.ply", res.flat)
    write_json_atomic(tmp_path / "v.rollout.json", rollout_summary(res))
    out = run_bake_stage(tmp_path / "v.rollout.ply", tmp_path, BakeOptions(px_per_mm=2, maps=()))
    assert out.record["overlap"]["repeated_faces"] == len(res.flat.mesh.faces) - res.region.repeated_from
    img = np.asarray(Image.open(out.paths["png"]))
    marked = np.all(img == REPEAT_COLOUR, axis=2)
    rows, cols = np.nonzero(marked)
    assert len(rows) > 50
    # at the 360 degree line: 2 pi R = 251 mm from the left edge, 2 px per mm
    assert np.median(cols) == pytest.approx(2 * 2 * np.pi * 40, abs=8)
    assert 0.3 < len(np.unique(rows)) / img.shape[0] < 0.7  # dashed


@pytest.mark.parametrize("kwargs, match", [
    ({"landmark": "spout"}, "unknown"),
    ({"landmark": "handle", "seam_at": (0, 0, 0)}, "not both"),
    ({"seam_at": (0, 0)}, "seam_at"),
    ({"overlap": 200}, "0 to 180"),
    ({"overlap": -1}, "0 to 180"),
    ({"overlap": 10, "angles": (0, 90)}, "drop --angles"),
])
def test_landmark_options_are_validated(kwargs, match):
    with pytest.raises(InvalidOptionError, match=match):
        RolloutOptions(**kwargs)
