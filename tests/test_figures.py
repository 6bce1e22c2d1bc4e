"""The painted-figure measure of the benchmarks (``benchmarks/_figures.py``): exact cases."""
from __future__ import annotations

import math

import numpy as np
import pytest

from potflat.rollout import rollout
from potflat_synthetic.vessels import make_vessel

from _bench_meshes import figures


@pytest.fixture(scope="module", params=["cylinder", "cone"])
def developed(request):
    """A developable vessel and its exact development (the rollout, no relaxation)."""
    v = make_vessel(request.param, n_vertices=12000, seed=1)
    return v, rollout(v.mesh, importance="none", seam_at=_seam_between_circles(v))


def _seam_between_circles(v) -> tuple[float, float, float]:
    """A point on the wall midway (in angle) across the widest gap between the painted circles:
    the corners the seam's cut snaps onto its meridian lie away from every circle."""
    angles = np.sort([c.angle % (2 * np.pi) for c in v.features])
    gaps = np.diff(np.append(angles, angles[0] + 2 * np.pi))
    i = int(np.argmax(gaps))
    angle, height = angles[i] + 0.5 * gaps[i], v.features[0].height
    r = float(v.radius_at(np.array([height]))[0])
    return tuple(float(x) for x in v.pose[:3, :3] @ [r * np.cos(angle), r * np.sin(angle), height] + v.pose[:3, 3])


def test_circles_come_out_round_and_true_to_size_on_a_development(developed):
    v, r = developed
    m = figures.measure_figures(r.flat, v.features)
    assert m.measured == len(v.features) >= 8
    for c in m.circles:
        assert c.whole and c.faces > 20
        assert c.coverage == pytest.approx(1.0, abs=0.01)
        assert c.area_ratio == pytest.approx(1.0, abs=2e-3)
        assert c.width_mm == pytest.approx(20.0, abs=0.2) and c.height_mm == pytest.approx(20.0, abs=0.2)
        assert c.anisotropy_p95 < 1.005 and c.elongation < 1.01
    assert m.anisotropy_p95 < 1.005 and m.area_mean_abs_log < 1e-3 and m.flipped == 0


def test_a_known_stretch_is_measured_exactly(developed):
    """u stretched by 1.2 and v squeezed by 0.9 about the centre: every circle 24 x 18 mm,
    area ratio 1.08, anisotropy 4/3, log area ratio log 1.08 everywhere."""
    v, r = developed
    flat = r.flat.replace(uv=r.flat.uv * [1.2, 0.9])
    m = figures.measure_figures(flat, v.features)
    assert m.width_mm[0] == pytest.approx(24.0, abs=0.25) and m.width_mm[1] == pytest.approx(24.0, abs=0.25)
    assert m.height_mm[0] == pytest.approx(18.0, abs=0.2) and m.height_mm[1] == pytest.approx(18.0, abs=0.2)
    assert m.area_ratio == pytest.approx(1.08, rel=2e-3)
    assert m.anisotropy_p95 == pytest.approx(4 / 3, rel=5e-3)
    assert m.area_mean_abs_log == pytest.approx(math.log(1.08), abs=2e-3)


def test_a_cut_or_missing_circle_is_left_out_of_the_aggregates():
    v = make_vessel("cylinder", n_vertices=12000, seed=2)
    c0 = v.features[0]
    # the seam through the first circle's centre: its image falls in two pieces
    probe = rollout(v.mesh, importance="none")
    theta = math.degrees(probe.axis.cylindrical(c0.centre[None])[2][0])
    cut = rollout(v.mesh, importance="none", seam=theta % 360.0)
    m = figures.measure_figures(cut.flat, v.features)
    assert m.circles[0].split and not m.circles[0].whole
    assert m.measured == len(v.features) - 1
    # half of it cut away: not whole (coverage about a half)
    F = v.mesh.faces
    side = (v.mesh.vertices[F].mean(axis=1) - c0.centre) @ np.cross(v.axis_direction, c0.centre - v.axis_point)
    half = rollout(v.mesh, importance="none", face_mask=side < 0)
    c = figures.measure_figures(half.flat, [c0]).circles[0]
    assert 0.4 < c.coverage < 0.6 and not c.whole
    assert figures.measure_figures(half.flat, [c0]).measured == 0


def test_circles_from_a_truth_file_and_bad_circles(tmp_path):
    from potflat_synthetic.vessels import write_truth

    v = make_vessel("cylinder", n_vertices=2000, texture_size=64)
    path = write_truth(v, tmp_path / "cyl.truth.json")
    got = figures.truth_circles(path)
    assert len(got) == len(v.features)
    np.testing.assert_allclose(got[0][0], v.features[0].centre)
    assert got[0][1] == v.features[0].radius
    with pytest.raises(ValueError, match="positive radius"):
        figures.circle_list([(np.zeros(3), 0.0)])
