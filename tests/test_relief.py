"""The relief of a scan per vertex (potflat.mesh.relief): its kernels against slow references,
the vessel's form taken out, detail kept, the checks of its input."""
from __future__ import annotations

import numpy as np
import pytest

import reference
from potflat._jit import numba_threads
from potflat.errors import InvalidOptionError
from potflat.mesh import relief as R
from potflat.mesh._kernels import relief as K
from potflat.mesh._kernels.geometry import vertex_normal_sums


def _plane_mesh(n, size, z, seed=0):
    """``n`` random points over a ``size`` mm square, Delaunay faces counter-clockwise, lifted
    to ``z(x, y)``; the layout is the square."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    uv = rng.uniform(0.0, size, (n, 2))
    F = Delaunay(uv).simplices.astype(np.int64)
    e1, e2 = uv[F[:, 1]] - uv[F[:, 0]], uv[F[:, 2]] - uv[F[:, 0]]
    back = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    F[back] = F[back][:, ::-1]
    return np.column_stack([uv, z(uv[:, 0], uv[:, 1])]), F, uv


# ----------------------------------------------------------------------------- kernels


def test_relief_kernels_match_reference():
    """The fits from cell moments, their blend and the volume invariants equal direct solves,
    loops and all pairs on a tiny wavy sheet."""
    V, F, uv = _plane_mesh(300, 12.0, lambda x, y: 0.3 * np.sin(x) * np.cos(0.7 * y) + 0.02 * x * x)
    used = np.ones(len(V), bool)
    sums, area = vertex_normal_sums(V, F)
    sigma, cell, step, reach, ridge = 2.0, 1.0, 2, 5, R.QUADRIC_RIDGE
    origin, nx, ny = R._grid(uv, used, cell)
    order, ptr = R._sorted_by_cell(uv, used, origin, cell, nx, ny)
    mx, my = -(-nx // step), -(-ny // step)
    M = np.empty((nx * ny, K.MOMENTS))
    N = np.empty((nx * ny, K.TERMS, 3))
    coef = np.zeros((mx * my, K.TERMS, 3))
    ok = np.zeros(mx * my, bool)
    K.cell_moments(uv, V, area, order, ptr, float(origin[0]), float(origin[1]), cell, nx, sigma, M, N)
    K.fit_quadrics(M, N, nx, ny, cell, sigma, step, reach, np.ones(mx * my, bool), ridge, coef, ok)
    cells = np.floor((uv - origin) / cell)
    centres = origin + (np.minimum(cells, [nx - 1, ny - 1]) + 0.5) * cell
    nodes = np.stack(np.meshgrid(origin[0] + (np.arange(mx) * step + 0.5) * cell,
                                 origin[1] + (np.arange(my) * step + 0.5) * cell), axis=-1)
    want = np.stack([reference.relief_fit(uv, V, area, centres, node, sigma, reach * cell, ridge)
                     for node in nodes.reshape(-1, 2)])
    assert ok.all() and np.isfinite(want).all()
    np.testing.assert_allclose(coef, want, rtol=1e-9, atol=1e-9)

    height, frame = np.empty(len(V)), np.empty((len(V), 3))
    node_origin = origin + 0.5 * cell
    K.blend_quadrics(uv, V, sums, float(node_origin[0]), float(node_origin[1]), step * cell, mx, my, sigma, coef,
                     ok, height, frame)
    ref_height, ref_frame = reference.relief_blend(uv, V, sums, nodes, coef.reshape(my, mx, 6, 3), sigma)
    np.testing.assert_allclose(height, ref_height, atol=1e-12)
    np.testing.assert_allclose(frame, ref_frame, atol=1e-12)
    scalar = np.empty(len(V))
    z_fits = np.ascontiguousarray(coef[..., 2:])
    K.blend_scalar(uv, float(node_origin[0]), float(node_origin[1]), step * cell, mx, my, sigma, z_fits, ok, scalar)
    np.testing.assert_allclose(scalar, reference.relief_blend_scalar(uv, nodes, z_fits.reshape(my, mx, 6), sigma),
                               atol=1e-12)
    radii = np.array([0.6, 1.0, 1.6])
    origin2, nx2, ny2 = R._grid(uv, used, 1.6)
    order2, ptr2 = R._sorted_by_cell(uv, used, origin2, 1.6, nx2, ny2)
    out = np.empty(len(V))
    K.volume_invariants(uv, V[:, 2], area, order2, ptr2, float(origin2[0]), float(origin2[1]), 1.6, nx2, ny2,
                        radii, out)
    np.testing.assert_allclose(out, reference.volume_invariant(uv, V[:, 2], area, radii), atol=1e-12)


def test_relief_does_not_depend_on_the_thread_count():
    rng = np.random.default_rng(5)
    V, F, uv = _plane_mesh(20000, 30.0, lambda x, y: 0.02 * x * y / 30 + rng.normal(0, 0.02, len(x)))
    runs = []
    for threads in (1, None):
        with numba_threads(threads):
            rel = R.surface_relief(V, F, uv, smoothing_mm=3.0)
        runs.append(rel.columns.copy())
    np.testing.assert_array_equal(runs[0], runs[1])


# ----------------------------------------------------------------------------- the form taken out


@pytest.mark.parametrize("surface", ["sphere", "paraboloid", "saddle"])
def test_a_smooth_form_leaves_no_relief(surface):
    """A sphere of radius 40 mm, a paraboloid and a saddle: heights within a micrometre or so,
    the scan's normals along the smoothed surface's."""
    if surface == "sphere":
        V, F, uv = _plane_mesh(8000, 40.0, lambda x, y: np.zeros_like(x))
        lon, lat = (uv[:, 0] - 20) / 40.0, (uv[:, 1] - 20) / 40.0
        V = 40.0 * np.column_stack([np.cos(lat) * np.sin(lon), np.sin(lat), np.cos(lat) * np.cos(lon)])
    else:
        k = 1.0 if surface == "paraboloid" else -1.0
        V, F, uv = _plane_mesh(8000, 40.0, lambda x, y: 0.01 * (x - 20) ** 2 + k * 0.015 * (y - 20) ** 2)
    rel = R.surface_relief(V, F, uv, smoothing_mm=3.0)
    assert np.abs(rel.height_mm).max() < 2e-3
    inner = (np.abs(uv - 20.0) < 18.0).all(axis=1)  # (the random hull's slivers have no normal worth the name)
    assert rel.frame_normal[inner, 2].min() > 0.999
    assert np.abs(rel.concavity).max() < 1e-3


def test_a_bump_keeps_its_height_and_a_groove_its_depth():
    def z(x, y):
        return 0.3 * np.exp(-((x - 12) ** 2 + (y - 20) ** 2) / 0.5) - 0.2 * np.exp(-((x - 28) ** 2) / 0.1)
    V, F, uv = _plane_mesh(40000, 40.0, z)
    rel = R.surface_relief(V, F, uv, smoothing_mm=4.0)
    peak = rel.height_mm[np.argmin(np.hypot(uv[:, 0] - 12, uv[:, 1] - 20))]
    groove = np.median(rel.height_mm[(np.abs(uv[:, 0] - 28) < 0.05) & (np.abs(uv[:, 1] - 20) < 10)])
    assert peak == pytest.approx(0.3, rel=0.1) and groove == pytest.approx(-0.2, rel=0.1)
    plain = (np.abs(uv[:, 0] - 12) > 5) & (np.abs(uv[:, 0] - 28) > 3)
    assert np.abs(rel.height_mm[plain]).max() < 0.01
    at = lambda u, v: rel.concavity[np.argmin(np.hypot(uv[:, 0] - u, uv[:, 1] - v))]
    assert at(12, 20) < -0.05 and at(28, 20) > 0.05 and abs(at(5, 5)) < 0.01  # convex, concave, plane


def test_the_smoothing_is_raised_on_a_coarse_mesh():
    V, F, uv = _plane_mesh(400, 100.0, lambda x, y: np.zeros_like(x))
    rel = R.surface_relief(V, F, uv, smoothing_mm=2.0)
    assert rel.requested_mm == 2.0
    assert rel.smoothing_mm == pytest.approx(R.SMOOTHING_MIN_EDGES * rel.spacing_mm) and rel.smoothing_mm > 10


def test_relief_refuses_a_smoothing_that_is_not_a_length():
    V, F, uv = _plane_mesh(100, 10.0, lambda x, y: np.zeros_like(x))
    with pytest.raises(InvalidOptionError, match="positive number of mm"):
        R.surface_relief(V, F, uv, smoothing_mm=0.0)


def test_the_smoothing_is_raised_to_fit_a_huge_layout():
    """Two fine pieces 100 m apart: cells of half the smoothing asked for would not fit in memory."""
    V, F, uv = _plane_mesh(400, 10.0, lambda x, y: np.zeros_like(x))
    far = np.array([1e5, 1e5])
    rel = R.surface_relief(np.vstack([V, V + [*far, 0.0]]), np.vstack([F, F + len(V)]), np.vstack([uv, uv + far]),
                           smoothing_mm=1.0)
    assert (1e5 / rel.smoothing_mm * R.FIT_CELLS_PER_SIGMA) ** 2 <= R.MAX_CELLS
    assert rel.smoothing_mm < 1.05 * 1e5 * R.FIT_CELLS_PER_SIGMA / R.MAX_CELLS ** 0.5


def test_relief_refuses_faces_out_of_range():
    V, F, uv = _plane_mesh(100, 10.0, lambda x, y: np.zeros_like(x))
    with pytest.raises(ValueError, match="out of range"):
        R.surface_relief(V, F + 1, uv, smoothing_mm=2.0)
