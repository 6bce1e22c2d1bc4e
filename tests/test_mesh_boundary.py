"""potflat.mesh.boundary: edges, boundary segments and their crossings."""
from collections import Counter

import numpy as np
import pytest

from potflat.mesh.boundary import (
    corner_angle_sums,
    crossing_pairs,
    edges_and_boundary,
    outline_turning,
    surface_turning,
)


def test_edges_and_boundary_match_a_slow_reference():
    rng = np.random.default_rng(0)
    for _ in range(50):
        n = int(rng.integers(3, 30))
        F = rng.integers(0, n, (int(rng.integers(1, 40)), 3))
        F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
        halves = [(int(f[j]), int(f[(j + 1) % 3]), i) for i, f in enumerate(F) for j in range(3)]
        uses = Counter((min(a, b), max(a, b)) for a, b, _ in halves)
        edges, seg, owner = edges_and_boundary(F, n)
        assert edges.tolist() == sorted(map(list, uses))
        want = sorted((min(a, b), max(a, b), a, b, f) for a, b, f in halves if uses[(min(a, b), max(a, b))] == 1)
        assert [[a, b] for _, _, a, b, _ in want] == seg.tolist()
        assert [f for *_, f in want] == owner.tolist()


def test_a_closed_surface_has_no_boundary():
    tetra = np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]])
    edges, seg, owner = edges_and_boundary(tetra, 4)
    assert len(edges) == 6 and seg.shape == (0, 2) and owner.shape == (0,)


def test_crossing_pairs_lists_every_pair_of_a_grid_and_stops_at_the_cap():
    """12 horizontal and 12 vertical segments cross 144 times (past the kernel's first buffer)."""
    t = np.arange(12, dtype=float)
    x = np.concatenate([np.column_stack([np.full(12, -1.0), t]), np.column_stack([np.full(12, 12.0), t]),
                        np.column_stack([t, np.full(12, -1.0)]), np.column_stack([t, np.full(12, 12.0)])])
    seg = np.array([[i, 12 + i] for i in range(12)] + [[24 + i, 36 + i] for i in range(12)])
    got = {tuple(sorted(p)) for p in crossing_pairs(x, seg).tolist()}
    assert got == {(i, j) for i in range(12) for j in range(12, 24)}
    assert len(crossing_pairs(x, seg, max_pairs=100)) == 100


def _squares(k: int, leave_out=()):
    """A k x k grid of unit squares (two triangles each, counter-clockwise) without the
    squares ``leave_out`` ((i, j) pairs): faces (m, 3) and uv ((k + 1)^2, 2)."""
    ij = np.stack(np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij"), -1).reshape(-1, 2)
    at = lambda i, j: i * (k + 1) + j  # noqa: E731
    F = [f for i in range(k) for j in range(k) if (i, j) not in leave_out
         for f in ([at(i, j), at(i + 1, j), at(i + 1, j + 1)], [at(i, j), at(i + 1, j + 1), at(i, j + 1)])]
    return np.array(F), ij.astype(float)


@pytest.mark.parametrize("leave_out, turns", [((), 1.0), (((1, 0),), 2.0), (((1, 1),), 2.0)])
def test_outline_turning_of_a_square_a_notch_and_a_hole(leave_out, turns):
    # a convex outline turns once; a square notch adds four right angles; a hole turns once more
    F, uv = _squares(3, leave_out)
    assert np.isclose(outline_turning(F, uv), turns, rtol=1e-12)


def test_outline_turning_counts_every_tooth():
    # a side of two teeth, tips moved out by half an edge (sides at a = atan(1/2) to it):
    # 2 a at each tip and at the base between them, a less at the two corners
    F, uv = _squares(4)
    uv[(uv[:, 1] == 0) & (uv[:, 0] % 2 == 1), 1] = -0.5
    assert np.isclose(outline_turning(F, uv), 1.0 + 4 * np.arctan(0.5) / (2 * np.pi), rtol=1e-12)


def test_outline_turning_refuses_segments_that_do_not_close():
    F, uv = _squares(2)
    seg = edges_and_boundary(F, len(uv))[1]
    with pytest.raises(ValueError, match="closed loops"):
        outline_turning(F, uv, segments=seg[1:])


@pytest.mark.parametrize("leave_out, turns", [((), 1.0), (((1, 0),), 2.0), (((1, 1),), 2.0)])
def test_surface_turning_of_a_flat_sheet_is_its_outline_turning(leave_out, turns):
    F, uv = _squares(3, leave_out)
    rot = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0]
    V = np.c_[uv, np.zeros(len(uv))] @ rot.T
    assert np.isclose(surface_turning(V, F), turns, rtol=1e-12)


def test_surface_turning_of_a_sheet_bent_round_a_cylinder():
    # its sides (generators) and ends (circles) are geodesics: four right-angled corners only
    F, uv = _squares(8)
    angle, z = uv[:, 0] * (np.pi / 8), uv[:, 1]
    V = np.c_[np.cos(angle), np.sin(angle), z]
    assert np.isclose(surface_turning(V, F), 1.0, rtol=1e-12)
    # a tooth pulled out of an end (tip half an edge along the axis) adds its turns
    tip = (uv[:, 1] == 0) & (uv[:, 0] == 4)
    V[tip, 2] = -0.5
    assert surface_turning(V, F) > 1.0 + 3 * np.arctan(0.5) / (2 * np.pi)


def test_corner_angle_sums_of_a_flat_fan_a_pyramid_s_apex_and_a_square():
    ring = np.c_[np.cos(np.arange(6) * np.pi / 3), np.sin(np.arange(6) * np.pi / 3), np.zeros(6)]
    fan = np.array([[6, i, (i + 1) % 6] for i in range(6)])
    apex = np.r_[ring, [[0.0, 0.0, 0.0]]]
    at = np.zeros(7, bool)
    at[[0, 6]] = True
    sums = corner_angle_sums(apex, fan, at)
    np.testing.assert_allclose(sums, [2 * np.pi / 3, 0, 0, 0, 0, 0, 2 * np.pi], rtol=1e-12)
    # four equilateral triangles round the apex of a square pyramid: 4 x 60 degrees
    base = np.array([[1.0, 0, 0], [0, 1.0, 0], [-1.0, 0, 0], [0, -1.0, 0], [0, 0, 1.0]])
    pyramid = np.array([[4, i, (i + 1) % 4] for i in range(4)])
    np.testing.assert_allclose(corner_angle_sums(base, pyramid, np.arange(5) == 4)[4], 4 * np.pi / 3, rtol=1e-12)
    # flat (n, 2) positions: a square's corner
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    np.testing.assert_allclose(corner_angle_sums(square, np.array([[0, 1, 2], [0, 2, 3]]), np.ones(4, bool)),
                               np.pi / 2, rtol=1e-12)
