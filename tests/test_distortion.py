import numpy as np

from potflat.mesh.distortion import face_distortion, summarize, vertex_stress


def _grid(nx=4, ny=3):
    xs, ys = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float))
    V = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1)
    F = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a = j * nx + i
            F += [[a, a + 1, a + nx], [a + 1, a + nx + 1, a + nx]]
    return V, np.array(F)


def test_isometry_has_no_distortion():
    V, F = _grid()
    rot = np.array([[0.6, -0.8], [0.8, 0.6]])
    s = summarize(V, V[:, :2] @ rot.T + 5.0, F)
    assert s.edge_rms < 1e-12 and s.flipped == 0
    assert abs(s.anisotropy_max - 1) < 1e-12 and abs(s.scale - 1) < 1e-12


def test_stretch_and_mirror_are_measured():
    V, F = _grid()
    s = summarize(V, V[:, :2] * [3.0, 1.0], F)
    assert np.isclose(s.anisotropy_max, 3.0) and np.isclose(s.area_mean_abs_log, np.log(3.0))
    mirrored = summarize(V, V[:, :2] * [-1.0, 1.0], F)
    assert mirrored.flipped == len(F)


def test_singular_values_match_svd_reference():
    rng = np.random.default_rng(1)
    V = rng.normal(size=(3, 3))
    uv = rng.normal(size=(3, 2))
    F = np.array([[0, 1, 2]])
    fd = face_distortion(V, uv, F)
    # reference: least-squares Jacobian in an orthonormal frame of the triangle
    e1 = (V[1] - V[0]) / np.linalg.norm(V[1] - V[0])
    n = np.cross(V[1] - V[0], V[2] - V[0]); n /= np.linalg.norm(n)
    e2 = np.cross(n, e1)
    Q = np.array([[(V[k] - V[0]) @ e1, (V[k] - V[0]) @ e2] for k in (1, 2)]).T
    W = np.array([uv[1] - uv[0], uv[2] - uv[0]]).T
    s = np.linalg.svd(W @ np.linalg.inv(Q), compute_uv=False)
    np.testing.assert_allclose([fd.sigma_max[0], abs(fd.sigma_min[0])], s, rtol=1e-10)
    assert np.sign(fd.sigma_min[0]) == np.sign(np.linalg.det(W @ np.linalg.inv(Q)))


def test_stress_is_unit_independent():
    V, F = _grid()
    uv = V[:, :2] * [1.1, 0.9]
    in_mm = vertex_stress(V, uv, F, mm_per_unit=1.0)
    in_m = vertex_stress(V / 1000, uv / 1000, F, mm_per_unit=1000.0)
    np.testing.assert_allclose(in_mm, in_m, rtol=1e-12)
    assert vertex_stress(V, V[:, :2], F).max() == 0
