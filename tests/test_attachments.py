"""Attachment detection (potflat.rollout.attachments): handles flagged, clean vessels untouched."""
from __future__ import annotations

import json

import _vessel_meshes as vm
import numpy as np
import pytest

from potflat.rollout.attachments import detect_attachments
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.types import Mesh


def _posed(V, F, seed=1):
    Vp, p, a = vm.pose(V, seed=seed)
    return Mesh(Vp, F), p, a


@pytest.mark.parametrize("noise", [0.0, 0.15])
def test_handle_tube_is_flagged(noise):
    V, F, is_handle = vm.cylinder_with_handle(noise=noise)
    mesh, p, a = _posed(V, F)
    att = detect_attachments(mesh, p, a)
    recall = att.face_mask[is_handle].mean()
    false_pos = att.face_mask[~is_handle].mean()
    assert recall > 0.95, recall
    assert false_pos < 0.01, false_pos
    assert len(att.components) == 1
    c = att.components[0]
    # the loop spans heights 50 +- 22 plus the tube radius 4 (heights from the foot at 0)
    assert 22 <= c.height_min < 30 and 70 < c.height_max <= 78
    assert c.n_faces == att.n_faces and c.area > 0 and c.max_offset > 20
    json.dumps(att.summary())


def test_handle_root_painting_stays():
    # every body face keeps its place, also the ring where the handle meets the wall
    V, F, is_handle = vm.cylinder_with_handle()
    mesh, p, a = _posed(V, F, seed=3)
    att = detect_attachments(mesh, p, a)
    assert not att.face_mask[~is_handle].any()
    # unflagged handle faces are only those touching the wall (offset of a corner ~ 0)
    missed = is_handle & ~att.face_mask
    assert (np.nanmin(att.vertex_offset[F[missed]], axis=1) <= att.offset_threshold).all()
    # the root ring: unflagged faces next to the handle, all on the handle (it is a separate part)
    roots = att.root_faces(F)
    assert roots.any() and not (roots & att.face_mask).any() and is_handle[roots].all()
    with pytest.raises(InvalidInputError):
        att.root_faces(F[:5])


def test_knob_merged_into_the_wall():
    V, F, bump = vm.cylinder_with_knob()
    mesh, p, a = _posed(V, F, seed=4)
    att = detect_attachments(mesh, p, a)
    low = bump[F].min(axis=1)
    assert att.face_mask[low > 3.0].all()  # clearly off the wall: flagged
    assert not att.face_mask[bump[F].max(axis=1) == 0].any()  # the wall around: kept
    assert (low[att.face_mask] > att.offset_threshold).all()  # the margin rule
    assert len(att.components) == 1 and att.components[0].max_offset > 10


@pytest.mark.parametrize("builder", ["cylinder", "vase", "cup", "sherd"])
def test_clean_vessels_with_noise_have_no_attachments(builder):
    rng = np.random.default_rng(11)
    if builder == "cylinder":
        V, F, is_handle = vm.cylinder_with_handle(noise=0.3)
        F = F[~is_handle]
    elif builder == "vase":
        V, F, _, _ = vm.open_vase()
        V = V + rng.normal(scale=0.2, size=V.shape)
    elif builder == "cup":
        V, F, _, _ = vm.cup(foot_ring=True)  # two walls, foot ring, flat base and floor
        V = V + rng.normal(scale=0.2, size=V.shape)
    else:
        V, F, _ = vm.sherd_shell(theta_span=np.deg2rad(60))
        V = V + rng.normal(scale=0.1, size=V.shape)
    mesh, p, a = _posed(V, F, seed=2)
    att = detect_attachments(mesh, p, a)
    assert att.n_faces == 0 and att.components == ()


def test_holed_body_with_handle():
    V, F, is_handle = vm.cylinder_with_handle()
    zc = V[F][:, :, 2].mean(axis=1)
    ang = np.arctan2(V[F][:, :, 1].mean(axis=1), V[F][:, :, 0].mean(axis=1))
    hole = ~is_handle & (np.abs(ang - 2.0) < 0.5) & (np.abs(zc - 50) < 20)
    mesh, p, a = _posed(V, F[~hole])
    att = detect_attachments(mesh, p, a)
    kept_handle = is_handle[~hole]
    assert att.face_mask[kept_handle].mean() > 0.95
    assert not att.face_mask[~kept_handle].any()


def test_explicit_tolerance_is_used():
    V, F, is_handle = vm.cylinder_with_handle()
    mesh, p, a = _posed(V, F)
    att = detect_attachments(mesh, p, a, tolerance=3.0)
    assert att.tolerance == 3.0
    assert att.face_mask[is_handle].mean() > 0.95 and not att.face_mask[~is_handle].any()


def test_deterministic():
    V, F, _ = vm.cylinder_with_handle(noise=0.1)
    mesh, p, a = _posed(V, F)
    a1 = detect_attachments(mesh, p, a)
    a2 = detect_attachments(mesh, p, a)
    assert np.array_equal(a1.face_mask, a2.face_mask)
    assert np.array_equal(a1.vertex_offset, a2.vertex_offset, equal_nan=True)


@pytest.mark.parametrize("kwargs", [{"tolerance": 0.0}, {"tolerance": -1.0}, {"tolerance": float("nan")},
                                    {"tolerance": "2"}, {"coverage_ratio": 0.0}, {"coverage_ratio": 1.0},
                                    {"coverage_ratio": True}])
def test_bad_options(kwargs):
    V, F, _, _ = vm.open_vase(n_theta=16, n_h=5)
    with pytest.raises(InvalidOptionError):
        detect_attachments(Mesh(V, F), [0, 0, 0], [0, 0, 1], **kwargs)


def test_bad_axis():
    V, F, _, _ = vm.open_vase(n_theta=16, n_h=5)
    with pytest.raises(InvalidInputError):
        detect_attachments(Mesh(V, F), [0, 0, 0], [0, 0, 0])


@pytest.mark.parametrize("others", [np.zeros(5, bool), "all"], ids=["wrong length", "not boolean"])
def test_bad_other_objects_mask(others):
    V, F, _, _ = vm.open_vase(n_theta=16, n_h=5)
    with pytest.raises(InvalidInputError, match="others must be a boolean mask"):
        detect_attachments(Mesh(V, F), [0, 0, 0], [0, 0, 1],
                           others=np.zeros(len(F)) if isinstance(others, str) else others)


def test_synthetic_handles_if_available():
    from potflat_synthetic import vessels as synthetic
    v = synthetic.make_vessel("amphora", n_vertices=8000, texture_size=64, handles=True)
    att = detect_attachments(v.mesh, v.axis_point, v.axis_direction)
    handle = v.face_part == synthetic.PART_HANDLE
    assert att.face_mask[handle].mean() > 0.85
    assert att.face_mask[~handle].mean() < 0.001
    assert len(att.components) == 2


def _slow_coverage(ih, ir, tv, nh, nr, max_bins):
    """angle_coverage by sets: the bins of each target cell and of each cell's own points."""
    def n_bins(ring):
        return int(min(max(np.floor(2 * np.pi * (ring + 0.5)), 6), max_bins))

    def bin_of(t, ring):
        return min(int(t / (2 * np.pi) * n_bins(ring)), n_bins(ring) - 1)

    around, own = {}, {}
    for h, r, t in zip(ih.tolist(), ir.tolist(), tv.tolist()):
        own.setdefault((h, r), set()).add(bin_of(t, r))
        for dh in (-1, 0, 1):
            for dr in (-1, 0, 1):
                if 0 <= h + dh < nh and r + dr >= 0:
                    around.setdefault((h + dh, r + dr), set()).add(bin_of(t, r + dr))
    return ({h * nr + r: len(b) for (h, r), b in around.items()}, {h * nr + r: len(b) for (h, r), b in own.items()})


@pytest.mark.parametrize("seed", [0, 1])
def test_angle_coverage_kernel_matches_sets(seed):
    from potflat.mesh._kernels.grids import angle_coverage

    rng = np.random.default_rng(seed)
    ih = rng.integers(0, 6, 400)
    ir = rng.integers(0, 9, 400)
    tv = rng.uniform(0, 2 * np.pi, 400)
    tv[:5] = np.nextafter(2 * np.pi, 0)  # the last bin
    nh, nr, max_bins = 6, 10, 16  # the outer rings hit the bin limit
    own_cell = ih * nr + ir
    order = np.argsort(own_cell, kind="stable")
    cells, start = np.unique(own_cell[order], return_index=True)
    ptr = np.append(start, len(order)).astype(np.int64)
    around, own = _slow_coverage(ih, ir, tv, nh, nr, max_bins)
    targets = np.array(sorted(around), dtype=np.int64)
    count, own_count = np.empty(len(targets), np.int64), np.empty(len(cells), np.int64)
    ring_bins = np.array([min(max(int(np.floor(2 * np.pi * (r + 0.5))), 6), max_bins) for r in range(nr)], np.int64)
    angle_coverage(cells.astype(np.int64), ptr, tv[order], targets, nh, ring_bins, count, own_count)
    assert count.tolist() == [around[t] for t in targets.tolist()]
    assert own_count.tolist() == [own[c] for c in cells.tolist()]


def test_lower_medians_kernel():
    from potflat.mesh._kernels.quantiles import lower_medians

    rng = np.random.default_rng(2)
    values = rng.normal(size=60)
    values[10:14] = 1.5  # ties
    start = np.array([0, 7, 8, 10, 30], np.int64)
    stop = np.array([7, 8, 10, 30, 60], np.int64)
    out = np.empty(len(start))
    lower_medians(values, start, stop, out)
    expected = [np.sort(values[a:b])[(b - a + 1) // 2 - 1] for a, b in zip(start, stop)]
    assert out.tolist() == expected


def test_segment_distances_match_numpy_reference():
    """The distance to the segment between the two nearest representatives (where it is at
    most ``join`` long) equals NumPy's vector formulas, bit for bit, a zero-length segment and
    points beyond the ends included."""
    from potflat.mesh._kernels.grids import segment_distances

    rng = np.random.default_rng(12)
    reps = rng.normal(size=(30, 2))
    reps[5] = reps[4]  # a zero-length segment
    pts = rng.normal(scale=1.5, size=(400, 2))
    idx = np.stack([rng.integers(0, 30, 400), rng.integers(0, 30, 400)], axis=1)
    idx[:10] = [4, 5]
    nearest = np.linalg.norm(pts - reps[idx[:, 0]], axis=1)
    for join in (0.0, 0.8, np.inf):
        p1, p2 = reps[idx[:, 0]], reps[idx[:, 1]]
        seg = p2 - p1
        L2 = np.einsum("ij,ij->i", seg, seg)
        t = np.clip(np.einsum("ij,ij->i", pts - p1, seg) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
        dseg = np.linalg.norm(pts - (p1 + t[:, None] * seg), axis=1)
        want = np.where(np.sqrt(L2) <= join, np.minimum(nearest, dseg), nearest)
        out = np.empty(len(pts))
        segment_distances(reps, pts, idx, nearest, join, out)
        np.testing.assert_array_equal(out, want)


@pytest.mark.parametrize("scan", ["dragon-jar.glb", "goblet.stl"])
def test_a_finer_triangulation_finds_the_same_attachments(real_scans, scan):
    # the same vessel subdivided (every triangle into 4, twice): its body stays whole, as at
    # the scan's own resolution (cells of a few of the finer edges left parts of these
    # hand-made, out-of-round walls out as attachments)
    from _bench_meshes import load_benchmark

    from potflat.io.scan import load_scan
    from potflat.rollout.axis import estimate_axis

    split_edges = load_benchmark("real_scans").split_edges
    mesh = load_scan(real_scans / scan).mesh
    axis = estimate_axis(mesh)
    native = detect_attachments(mesh, axis.point, axis.direction)
    V, F = mesh.vertices, mesh.faces
    for _ in range(2):
        V, F, _ = split_edges(V, F, None)
    fine = detect_attachments(Mesh(V, F, units=mesh.units), axis.point, axis.direction)
    assert native.n_faces == 0
    assert fine.n_faces == 0, [c.area for c in fine.components]
