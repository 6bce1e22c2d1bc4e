"""Where a scan folds over itself (potflat.rollout.folds): the overlap kernel against a
brute-force reference, and the figures of a known fold."""
from __future__ import annotations

import numpy as np

from potflat.rollout.folds import fold_masks, overlapping_faces, scan_folds


def _reference_overlaps(faces, uv):
    """Every pair of faces sharing no vertex, one's centre strictly inside the other (slow)."""
    out = np.zeros(len(faces), bool)
    centre = uv[faces].mean(axis=1)
    for i, f in enumerate(faces):
        for j, g in enumerate(faces):
            if i == j or set(f) & set(g):
                continue
            a, b, c = uv[g]
            p = centre[i]
            s = [(q[0] - o[0]) * (p[1] - o[1]) - (q[1] - o[1]) * (p[0] - o[0]) for o, q in ((a, b), (b, c), (c, a))]
            if all(x > 0 for x in s) or all(x < 0 for x in s):
                out[i] = out[j] = True
    return out


def _grid(n, m, shift=(0.0, 0.0)):
    u, v = np.meshgrid(np.arange(n, dtype=float), np.arange(m, dtype=float), indexing="ij")
    uv = np.column_stack([u.ravel(), v.ravel()]) + shift
    idx = np.arange(n * m).reshape(n, m)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]), uv


def test_overlapping_faces_match_the_brute_force_reference():
    rng = np.random.default_rng(3)
    F, uv = _grid(7, 6)
    uv = uv + rng.uniform(-0.15, 0.15, uv.shape)
    assert not overlapping_faces(F, uv).any()  # a clean layout: nothing lies over anything
    F2, uv2 = _grid(3, 3, shift=(2.3, 1.4))  # a second sheet over part of it
    faces = np.concatenate([F, F2 + len(uv)])
    layout = np.concatenate([uv, uv2])
    got = overlapping_faces(faces, layout)
    want = _reference_overlaps(faces, layout)
    assert want[len(F):].all() and want.sum() > len(F2)
    np.testing.assert_array_equal(got, want)


def test_a_fold_is_found_measured_and_located():
    """A strip of a flat sheet turned over (its faces face the other way) and lying on its neighbour."""
    F, uv = _grid(12, 5)
    V = np.column_stack([uv, np.zeros(len(uv))])
    raw = uv.copy()
    band = (uv[:, 0] > 4.5) & (uv[:, 0] < 7.5)
    raw[band, 0] = 9.0 - raw[band, 0]  # mirrored about u = 4.5: folded back
    facing, over = fold_masks(F, raw)
    assert facing.sum() == 2 * 2 * 4 and over.any()
    folds = scan_folds(V, F, facing, over, height=uv[:, 1], vessel_height=4.0, angle_deg=uv[:, 0], mm_per_unit=10.0)
    assert folds.area_mm2 == np.sum((facing | over) * 0.5 * 100.0)
    assert folds.regions and folds.regions[0]["band"][1] == 1.0 and folds.regions[0]["height_mm"][1] == 40.0
    assert folds.percent == 100.0 * folds.area_mm2 / (11 * 4 * 100.0)
    assert folds.as_dict()["face_indices"] == folds.faces.tolist()
    clean = scan_folds(V, F, *fold_masks(F, uv), height=uv[:, 1], vessel_height=4.0, angle_deg=uv[:, 0],
                       mm_per_unit=10.0)
    assert clean.area_mm2 == 0.0 and clean.regions == [] and clean.note() is None


def test_smoothing_steps_reach_the_fold_scale():
    """k half steps to the neighbours' mean spread a vertex over sqrt(k / 2) edge lengths:
    about FOLD_MIN_MM, none on a coarse mesh."""
    from potflat.rollout.folds import FOLD_MAX_STEPS, FOLD_MIN_MM, smoothing_steps

    F, uv = _grid(6, 6)
    V = np.column_stack([uv, np.zeros(len(uv))])
    edges = np.array([[0, 1], [1, 2], [0, 6]], dtype=np.int64)  # all 1 unit long
    assert FOLD_MIN_MM == 1.0
    assert smoothing_steps(V, edges, 1.0) == 2
    assert smoothing_steps(V, edges, 0.5) == 8
    assert smoothing_steps(V, edges, 1.5) == 1  # 0.89
    assert smoothing_steps(V, edges, 3.0) == 0  # edges of 3 mm: folds that narrow already show
    assert smoothing_steps(V, edges, 1e-3) == FOLD_MAX_STEPS
    assert smoothing_steps(V, edges[:0], 1.0) == 0


def test_noise_on_an_edge_on_wall_is_not_a_fold_and_a_wide_fold_stays():
    """A wall nearly edge-on to the proxy (its development squeezed to a tenth in v) with noise
    across it turns single faces over; smoothed over FOLD_MIN_MM they are gone, while a strip
    folded back 3 mm wide (6 edges of 0.5 mm) is still found."""
    from potflat.mesh.embedding import fan_edges
    from potflat.rollout.folds import smoothing_steps

    F, uv = _grid(40, 30)
    V = np.column_stack([uv, np.zeros(len(uv))])
    edges = fan_edges(np.arange(len(F)), F)[0]
    steps = smoothing_steps(V, edges, 0.5)
    rng = np.random.default_rng(0)
    noisy = uv * [1.0, 0.1]
    noisy[:, 1] += rng.normal(0.0, 0.05, len(uv))
    facing, over = fold_masks(F, noisy)
    assert facing.sum() > 50  # unsmoothed, the noise is taken for folds
    facing, over = fold_masks(F, noisy, steps=steps)
    assert not facing.any() and not over.any()
    folded = uv.copy()
    band = (uv[:, 0] > 14.5) & (uv[:, 0] < 20.5)
    folded[band, 0] = 29.0 - folded[band, 0]  # mirrored about u = 14.5: folded back
    facing, over = fold_masks(F, folded, steps=steps)
    strip = (uv[F, 0].min(axis=1) >= 15) & (uv[F, 0].max(axis=1) <= 20)
    assert facing[strip].mean() > 0.5 and over.any()
    assert not (facing & (uv[F, 0].max(axis=1) <= 13)).any()


def test_a_noisy_fine_scan_is_not_reported_as_folded(monkeypatch):
    """A 4 cm amphora (20k vertices, edges 0.4 mm) with noise of 0.3 edge lengths along its
    normals: judged on the raw development, its shoulder's noise is 1.5 % of the surface
    "folded" (a warning); smoothed over FOLD_MIN_MM, nothing."""
    import trimesh

    import potflat.rollout.unroll as unroll
    from potflat_synthetic.vessels import make_vessel

    mesh = make_vessel("amphora", n_vertices=20000, seed=1, texture_size=64).mesh
    V = mesh.vertices * 0.1
    F = mesh.faces
    edge = float(np.median(np.linalg.norm(V[F[:, 1]] - V[F[:, 0]], axis=1)))
    normals = trimesh.Trimesh(V, F, process=False).vertex_normals
    noisy = mesh.replace(vertices=V + normals * np.random.default_rng(0).normal(0.0, 0.3 * edge, len(V))[:, None])
    result = unroll.rollout(noisy)
    assert result.folds.smoothing_steps > 0 and len(result.folds.faces) == 0 and result.folds.note() is None
    monkeypatch.setattr(unroll, "smoothing_steps", lambda *args: 0)
    raw = unroll.rollout(noisy).folds
    assert raw.percent > 0.5 and raw.note() is not None


def test_smoothing_around_the_folds_moves_them_as_a_smoothing_of_the_whole_layout():
    """The folded faces' vertices after k smoothing steps within k rings equal those of k
    steps over the whole layout (slow reference: every vertex halfway to the mean of its
    edge neighbours); vertices beyond the region keep their place."""
    from potflat.rollout.folds import _smoothed_around

    rng = np.random.default_rng(5)
    F, uv = _grid(14, 12)
    uv = uv + rng.uniform(-0.45, 0.45, uv.shape)
    folded = np.zeros(len(F), bool)
    folded[[40, 41, 150]] = True
    neighbours = [set() for _ in range(len(uv))]
    for f in F:
        for a in f:
            neighbours[a].update(int(b) for b in f if b != a)
    for steps in (1, 2, 4):
        want = uv.copy()
        for _ in range(steps):
            want = np.array([0.5 * (want[i] + want[sorted(nb)].mean(axis=0)) for i, nb in enumerate(neighbours)])
        got, near = _smoothed_around(F, uv, folded, steps)
        verts = np.unique(F[folded])
        np.testing.assert_allclose(got[verts], want[verts], rtol=0, atol=1e-12)
        moved = np.flatnonzero((got != uv).any(axis=1))
        assert np.isin(verts, moved).all() and len(moved) < len(uv) and np.isin(np.unique(F[near]), moved).any()
        assert not (got != uv)[np.setdiff1d(np.arange(len(uv)), np.unique(F[near]))].any()
