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
