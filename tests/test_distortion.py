import warnings

import numpy as np
import pytest

from potflat.mesh.distortion import (
    SurfaceReference,
    edge_length_error,
    face_distortion,
    summarize,
    unique_edges,
    vertex_length_error,
    vertex_stress,
)


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


def _face_distortion_reference(V, uv, F):
    """The numpy formulation the kernels replaced (per face, vectorised)."""
    area_3d = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    valid = area_3d > 1e-12 * max(area_3d.mean(), np.finfo(float).tiny)
    d1, d2 = V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]
    len1 = np.linalg.norm(d1, axis=1)
    len1s = np.where(valid & (len1 > 0), len1, 1.0)
    q2x = np.einsum("ij,ij->i", d2, d1 / len1s[:, None])
    q2y = np.where(valid, 2.0 * area_3d / len1s, 1.0)
    w1, w2 = uv[F[:, 1]] - uv[F[:, 0]], uv[F[:, 2]] - uv[F[:, 0]]
    area_2d = 0.5 * (w1[:, 0] * w2[:, 1] - w1[:, 1] * w2[:, 0])
    inv11, inv12, inv22 = 1.0 / len1s, -q2x / (len1s * q2y), 1.0 / q2y
    a, c = w1[:, 0] * inv11, w1[:, 1] * inv11
    b, d = w1[:, 0] * inv12 + w2[:, 0] * inv22, w1[:, 1] * inv12 + w2[:, 1] * inv22
    q, r = np.hypot(0.5 * (a + d), 0.5 * (c - b)), np.hypot(0.5 * (a - d), 0.5 * (c + b))
    return area_3d, area_2d, (q + r) * valid, (q - r) * valid, valid


def test_face_kernels_match_numpy_reference():
    rng = np.random.default_rng(3)
    V, F = _grid(7, 6)
    V = V + rng.normal(scale=0.2, size=V.shape)
    V[F[4, 1]] = V[F[4, 0]]  # a degenerate face
    uv = V[:, :2] * [1.3, 0.7] + rng.normal(scale=0.1, size=(len(V), 2))
    uv[F[9, 2]] = uv[F[9, 1]]  # a collapsed flat face
    fd = face_distortion(V, uv, F)
    for got, want in zip((fd.area_3d, fd.area_2d, fd.sigma_max, fd.sigma_min, fd.valid),
                         _face_distortion_reference(V, uv, F)):
        np.testing.assert_array_equal(got, want)
    assert not fd.valid[4] and fd.area_2d[9] == 0


def test_edge_kernels_and_shared_reference_match_numpy():
    rng = np.random.default_rng(4)
    V, F = _grid(6, 5)
    V = V + rng.normal(scale=0.2, size=V.shape)
    uv = V[:, :2] * [1.2, 0.9]
    edges = unique_edges(F)
    l3 = np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1)
    l2 = np.linalg.norm(uv[edges[:, 0]] - uv[edges[:, 1]], axis=1)
    np.testing.assert_array_equal(edge_length_error(V, uv, edges), (l2 - l3) / l3)
    reference = SurfaceReference(V, F)
    for flat in (uv, uv * 0.5, uv[:, ::-1].copy()):  # one reference, several flattenings
        assert reference.summarize(flat) == summarize(V, flat, F)
        np.testing.assert_array_equal(reference.vertex_stress(flat, 2.0), vertex_stress(V, flat, F, 2.0))
        np.testing.assert_array_equal(reference.vertex_length_error(flat), vertex_length_error(V, flat, F))
    ref_stress = np.zeros(len(V))
    num, den = np.zeros(len(V)), np.zeros(len(V))
    for (i, j), a, b in zip(edges, l3, l2):
        for v in (i, j):
            num[v] += (b - a) ** 2
            den[v] += a
    ref_stress = np.sqrt(num / den)
    np.testing.assert_allclose(vertex_stress(V, uv, F), ref_stress, rtol=1e-12)


def test_weighted_percentiles_match_a_slow_reference():
    """Integer weights: the weighted percentile is the plain one of the values repeated
    by their weights (the smallest value whose cumulative share reaches q); several from
    one sort equal one at a time."""
    from potflat.mesh.distortion import weighted_percentile, weighted_percentiles

    rng = np.random.default_rng(3)
    for _ in range(30):
        values = rng.integers(0, 20, int(rng.integers(1, 40))).astype(float)
        weights = rng.integers(0, 4, len(values)).astype(float)
        qs = (0.0, 12.5, 50.0, 95.0, 100.0)
        if not weights.any():
            assert all(np.isnan(weighted_percentiles(values, weights, qs)))
            continue
        repeated = np.repeat(values, weights.astype(int))
        want = [float(np.percentile(repeated, q, method="inverted_cdf")) for q in qs]
        assert weighted_percentiles(values, weights, qs) == want
        assert [weighted_percentile(values, weights, q) for q in qs] == want


def _sorted_weighted_percentiles(values, weights, qs):
    """Slow reference: sort the values of positive weight, the first whose cumulative weight
    reaches q % of the total (the last when none does)."""
    keep = weights > 0
    kept = values[keep]
    order = np.argsort(kept, kind="stable")
    cum = np.cumsum(weights[keep][order])
    return [float(kept[order[min(np.searchsorted(cum, q / 100.0 * cum[-1]), len(kept) - 1)]]) for q in qs]


@pytest.mark.parametrize("case", ["spread", "narrow", "ties", "special", "boundary"])
def test_weighted_percentiles_select_as_a_sort_would(case):
    """Radix selection against a full sort on many values (several histogram passes): values
    spread over decades, all within a few units in the last place (every pass down to the last
    bits), with many equal values, with -0.0, 0.0, infinities and NaN (sorted last), and with
    the median's threshold met exactly by the lower half (the answer is the lower value).
    Integer weights sum exactly in any order, so the answers must be equal."""
    from potflat.mesh.distortion import weighted_percentiles

    rng = np.random.default_rng(11)
    n = 50_000
    if case == "spread":
        values = rng.lognormal(0.0, 4.0, n) * rng.choice([-1.0, 1.0], n)
    elif case == "narrow":
        values = 1.0 + rng.integers(0, 3000, n) * np.finfo(float).eps
    elif case == "ties":
        values = rng.integers(0, 7, n).astype(float) / 3.0
    elif case == "boundary":
        values = np.repeat([1.0, 2.0, 4.0, 8.0], n // 4)
    else:
        values = rng.normal(size=n)
        values[rng.integers(0, n, 3000)] = rng.choice([-0.0, 0.0, np.inf, -np.inf, np.nan], 3000)
    weights = np.ones(n) if case == "boundary" else rng.integers(0, 5, n).astype(float)
    qs = (0.0, 0.01, 25.0, 50.0, 95.0, 99.99, 100.0)
    got = weighted_percentiles(values, weights, qs)
    want = _sorted_weighted_percentiles(values, weights, qs)
    assert np.array_equal(got, want, equal_nan=True)


def test_weighted_percentiles_refuse_weights_of_another_length():
    from potflat.mesh.distortion import weighted_percentiles

    with pytest.raises(ValueError, match="differ in length"):
        weighted_percentiles(np.arange(5.0), np.ones(4), (50.0,))


def test_a_part_of_the_faces_is_summarized_as_a_mesh_of_those_faces():
    """``summarize_part`` takes a reference's arrays: the same figures, bit for bit, as a new
    reference of the part's faces, also for a part with a face degenerate by its own mean
    area only (the fallback), the empty part and the whole mesh."""
    from potflat.mesh.distortion import zone_figures

    rng = np.random.default_rng(8)
    V, F = _grid(9, 7)
    V = V + rng.normal(scale=0.2, size=V.shape)
    V[-1] = V[-2] + 1e-13  # a sliver: degenerate by the mean area of all faces, not by its own
    uv = V[:, :2] * [1.1, 0.8] + rng.normal(scale=0.05, size=(len(V), 2))
    reference = SurfaceReference(V, F)
    sliver = np.flatnonzero((F == len(V) - 1).any(axis=1))
    parts = [rng.random(len(F)) < share for share in (0.1, 0.5, 0.9)]
    parts += [np.zeros(len(F), bool), np.ones(len(F), bool), np.isin(np.arange(len(F)), sliver)]
    for part in parts:
        assert reference.summarize_part(uv, part) == summarize(V, uv, F[part]), part.sum()
    importance = (V[:, 0] > 3).astype(float)
    with_reference = zone_figures(V, uv, F, importance, reference=reference)
    assert with_reference == zone_figures(V, uv, F, importance)
    for key, sel in (("important", importance[F].mean(axis=1) >= 0.5), ("rest", importance[F].mean(axis=1) < 0.5)):
        assert with_reference[key].distortion == summarize(V, uv, F[sel])


def test_summary_figures_match_numpy_reference():
    """The valid faces' figures taken in one kernel pass give the figures of the NumPy
    formulas, bit for bit: flipped, collapsed (sigma_min 0: anisotropy inf, or NaN for 0 / 0)
    and zero-area faces among degenerate ones."""
    from potflat.mesh.distortion import FaceDistortion, _summary

    rng = np.random.default_rng(5)
    m = 500
    for case in range(4):
        area_3d = rng.random(m) + 0.1
        area_2d = area_3d * rng.lognormal(0.0, 0.3, m) * np.where(rng.random(m) < 0.05, -1.0, 1.0)
        sigma_max = rng.random(m) + 1.0
        sigma_min = rng.random(m) * np.sign(area_2d)
        valid = rng.random(m) > 0.1
        area_2d[rng.random(m) < 0.05] = 0.0
        if case >= 2:  # a collapsed face: infinite anisotropy (case 3: also 0 / 0)
            sigma_min[np.flatnonzero(valid)[:2]] = 0.0
            if case == 3:
                sigma_max[np.flatnonzero(valid)[1]] = 0.0
        if case == 1:
            valid[:] = False
        fd = FaceDistortion(area_3d, area_2d, sigma_max, sigma_min, valid)
        err = rng.normal(size=40)
        got = _summary(fd, err)
        v = valid
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a collapsed face is measured without a warning
            w, la, an = area_3d[v], np.abs(fd.log_area_ratio[v]), fd.anisotropy[v]
        if case == 3:
            assert np.isnan(an[1]) and np.isinf(an[0])
        if not v.any():
            la = an = w = np.ones(1)
        finite = np.isfinite(an).all()
        want = (float(np.sqrt(np.mean(err**2))), float(np.max(np.abs(err))), float(np.average(la, weights=w)),
                float(np.percentile(la, 95)), float(np.max(la)),
                float(np.average(an, weights=w)) if finite else float("inf"),
                float(np.percentile(an, 95, method="linear" if finite else "higher")), float(np.max(an)),
                float(area_2d[v].sum() / area_3d[v].sum()) if v.any() else 0.0,
                int(np.count_nonzero(v & (area_2d <= 0))), int(np.count_nonzero(~v)))
        np.testing.assert_array_equal(np.array(tuple(got.as_dict().values()), float), np.array(want, float))


def test_important_faces_match_numpy_reference():
    """A face is in the zone when its corners' mean importance reaches the threshold, as the
    NumPy mean gives it (corner values in quarters: means at the threshold exactly)."""
    from potflat.mesh.distortion import ZONE_THRESHOLD, important_faces

    rng = np.random.default_rng(9)
    F = rng.integers(0, 40, (300, 3))
    for values in (rng.random(40), np.round(rng.random(40) * 4) / 4, np.full(40, ZONE_THRESHOLD)):
        want = values[F].mean(axis=1) >= ZONE_THRESHOLD
        np.testing.assert_array_equal(important_faces(F, values), want)
    assert important_faces(F, None).all()
