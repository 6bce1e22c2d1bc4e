import numpy as np
import pytest

from _revolve import cone, cylinder
from potflat.rollout.proxy import (choose, develop, fit, fit_cone, fit_cylinder, fit_sphere, ortho_proxy,
                           project_ortho)
from potflat.rollout import rollout


def _cone_points(r0, r1, H, n=500, seed=0, span=2.0):
    rng = np.random.default_rng(seed)
    t = rng.uniform(0, 1, n)
    h = H * t
    r = r0 + (r1 - r0) * t
    theta = rng.uniform(0, span, n)
    return h, r, theta


def test_fit_cylinder_and_sphere_exact():
    rng = np.random.default_rng(1)
    h = rng.uniform(0, 50, 200)
    assert np.isclose(fit_cylinder(h, np.full(200, 12.5)).params["radius"], 12.5)
    lat = rng.uniform(-1.2, 1.2, 200)
    p = fit_sphere(7.0 + 20 * np.sin(lat), 20 * np.cos(lat), rng.uniform(0.5, 2, 200)).params
    assert np.isclose(p["centre_height"], 7.0) and np.isclose(p["radius"], 20.0)


@pytest.mark.parametrize("r0,r1", [(40.0, 20.0), (20.0, 40.0)])
def test_fit_cone_exact(r0, r1):
    h, r, theta = _cone_points(r0, r1, 60.0)
    p = fit_cone(h, r, theta).params
    alpha = np.degrees(np.arctan(abs(r1 - r0) / 60.0))
    assert np.isclose(p["half_angle_deg"], alpha)
    assert np.isclose(p["apex_height"], -r0 * 60.0 / (r1 - r0))
    assert p["widens_towards_mouth"] == (r1 > r0)
    assert np.isclose(p["bisector_deg"], np.degrees(0.5 * (theta.min() + theta.max())))


def test_cylinder_development_is_r_theta_h():
    h, r, theta = _cone_points(10.0, 10.0, 30.0)
    uv = develop(fit("cylinder", h, r, theta), h, r, theta)
    np.testing.assert_allclose(uv, np.stack([10 * theta, h], axis=1), atol=1e-12)


@pytest.mark.parametrize("r0,r1", [(40.0, 20.0), (20.0, 40.0)])
def test_cone_development_is_isometric(r0, r1):
    """Distances from the apex and angles at the apex are those of the unrolled cone."""
    h, r, theta = _cone_points(r0, r1, 60.0, span=5.0)
    prox = fit("cone", h, r, theta)
    uv = develop(prox, h, r, theta)
    p = prox.params
    sin_a = np.sin(np.radians(p["half_angle_deg"]))
    apex_h = p["apex_height"]
    slant = np.hypot(h - apex_h, r)  # 3D distance of each point from the apex
    mid = np.radians(p["bisector_deg"])
    apex_uv = np.array([p["reference_radius"] * mid,
                        p["reference_height"] - p["reference_radius"] / p["generator"][1]])
    d = uv - apex_uv
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), slant, rtol=1e-12)
    # angle at the apex between any two points = their angle about the axis times sin(alpha)
    ang = np.arctan2(d[:, 0], np.sign(p["generator"][1]) * d[:, 1])
    np.testing.assert_allclose(ang[1:] - ang[0], (theta[1:] - theta[0]) * sin_a, atol=1e-10)
    # upright: on the bisector v grows with the height, u grows with theta
    assert np.corrcoef(uv[:, 0], theta)[0, 1] > 0.9
    near = np.abs(theta - mid) < 0.3
    assert np.corrcoef(uv[near, 1], h[near])[0, 1] > 0.99


def test_cone_development_tends_to_the_cylinder():
    h, r, theta = _cone_points(10.0, 10.0 + 1e-9, 30.0)
    uv_cone = develop(fit("cone", h, r, theta), h, r, theta)
    uv_cyl = develop(fit("cylinder", h, r, theta), h, r, theta)
    np.testing.assert_allclose(uv_cone, uv_cyl, atol=1e-6)


def test_sphere_development_is_equirectangular():
    rng = np.random.default_rng(3)
    lat, theta = rng.uniform(-1, 1, 100), rng.uniform(0, 6, 100)
    h, r = 5 + 10 * np.sin(lat), 10 * np.cos(lat)
    uv = develop(fit("sphere", h, r, theta), h, r, theta)
    np.testing.assert_allclose(uv, np.stack([10 * theta, 5 + 10 * lat], axis=1), atol=1e-9)


def test_ortho_projection_faces_the_viewer_upright():
    prox = ortho_proxy(np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([2.0, 0, 0]))
    pts = np.array([[5.0, 0, 0], [5.0, 1, 0], [5.0, 0, 1]])
    uv = project_ortho(prox, pts, np.zeros(3))
    # seen from +x with z up, +y is to the right
    np.testing.assert_allclose(uv, [[0, 0], [1, 0], [0, 1]], atol=1e-12)
    top = ortho_proxy(np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))
    np.testing.assert_allclose(top.params["up"], [1, 0, 0])


@pytest.mark.parametrize("make,kind", [(cylinder, "cylinder"), (cone, "cone")])
def test_auto_picks_the_right_proxy(make, kind):
    mesh, *_ = make(seed=4)
    res = rollout(mesh)
    assert res.proxy.kind == kind
    assert set(res.proxy.candidates) == {"cylinder", "cone", "sphere"}
    assert "least unrolling distortion" in res.proxy.reason
    best = min(c["edge_rms"] for c in res.proxy.candidates.values())
    assert res.proxy.candidates[kind]["edge_rms"] <= 1.01 * best + 1e-12


def test_choose_reports_every_candidate():
    mesh, *_ = cone(seed=6, theta_range=(0.0, 2.0))
    res = rollout(mesh, proxy="cylinder")
    fm = res.flat.mesh
    h, r, _ = res.axis.cylindrical(fm.vertices)
    theta = res.flat.uv[:, 0] / res.proxy.params["radius"]  # the cut's unwrapped angles
    prox, uv, summ = choose(fm.vertices, fm.faces, h, r, theta)
    assert prox.kind == "cone" and summ.edge_rms < res.distortion.edge_rms
    assert "cylinder" in prox.reason
