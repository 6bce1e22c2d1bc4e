"""potflat.mesh.split: triangles cut exactly along a plane."""
import numpy as np
import pytest
import trimesh
from reference import clip_faces, polygon_area

from potflat.mesh.split import CUT_SNAP, cut_moves, plane_levels, plane_weights, split_faces


def _grid(rng, n=7, jitter=0.3):
    """A jittered, bumpy grid of (n - 1)^2 quads with random diagonals: shared edges."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    p = np.stack([i + rng.uniform(-jitter, jitter, i.shape), j + rng.uniform(-jitter, jitter, i.shape),
                  rng.normal(0, 0.3, i.shape)], axis=-1).reshape(-1, 3)
    idx = np.arange(n * n).reshape(n, n)
    faces = []
    for a in range(n - 1):
        for b in range(n - 1):
            q = idx[a, b], idx[a + 1, b], idx[a + 1, b + 1], idx[a, b + 1]
            faces += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] if rng.random() < 0.5 else [[q[0], q[1], q[3]],
                                                                                        [q[1], q[2], q[3]]]
    return p, np.array(faces)


def _areas(p):
    return 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=-1)


def _grid_and_plane(rng):
    """A grid (:func:`_grid`) and the levels of a random plane through its middle."""
    points, faces = _grid(rng)
    normal = rng.normal(size=3)
    normal /= np.linalg.norm(normal)
    return points, faces, plane_levels(points, points.mean(axis=0) + rng.normal(0, 0.5, 3), normal)


def _positions(split, points):
    return np.concatenate([points, split.added(points)])


@pytest.mark.parametrize("seed", range(6))
def test_cut_moves_matches_a_slow_reference_and_puts_each_vertex_on_the_cut(seed):
    rng = np.random.default_rng(seed)
    points, faces, level = _grid_and_plane(rng)
    level[rng.choice(len(level), 4, replace=False)] = 0.0  # on the cut already: not moved
    vertices, towards, t = cut_moves(faces, level)
    # the slow reference: every crossing edge seen from each end, the nearest kept
    best = {}
    for f in faces:
        for a, b in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            for v, w in ((a, b), (b, a)):
                if level[v] * level[w] < 0:
                    frac = level[v] / (level[v] - level[w])
                    if frac < CUT_SNAP and (frac, w) < best.get(v, (np.inf, -1)):
                        best[v] = (frac, w)
    assert len(vertices) > 0 and vertices.tolist() == sorted(best)
    assert towards.tolist() == [best[v][1] for v in sorted(best)]
    np.testing.assert_allclose(t, [best[v][0] for v in sorted(best)], rtol=1e-12)
    np.testing.assert_allclose((1 - t) * level[vertices] + t * level[towards], 0.0, atol=1e-15)
    assert np.all((t > 0) & (t < CUT_SNAP)) and not np.isin(vertices, np.flatnonzero(level == 0.0)).any()


def test_plane_weights_are_barycentric_coordinates_of_the_projection():
    tri = np.array([[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 0.0]]] * 4)
    points = np.array([[0.5, 0.25, 0.0],   # inside
                       [0.5, 0.25, 3.0],   # above it: its projection's
                       [-1.0, 0.5, -2.0],  # outside: negative weights, the map extended
                       [2.0, 0.0, 0.0]])   # a corner
    w = plane_weights(tri, points)
    np.testing.assert_allclose(w, [[0.5, 0.25, 0.25], [0.5, 0.25, 0.25], [1.0, -0.5, 0.5], [0.0, 1.0, 0.0]],
                               atol=1e-15)
    # a degenerate triangle gives its first corner
    flat = np.array([[[0.0, 0.0, 0.0], [1.0, 1.0, 1.0], [2.0, 2.0, 2.0]]])
    np.testing.assert_array_equal(plane_weights(flat, np.array([[5.0, 0.0, 0.0]])), [[1.0, 0.0, 0.0]])


@pytest.mark.parametrize("seed", range(12))
def test_split_faces_matches_a_slow_reference(seed):
    rng = np.random.default_rng(seed)
    points, faces, level = _grid_and_plane(rng)
    if seed % 3 == 0:  # vertices on the plane, and near it
        level[rng.choice(len(level), 6, replace=False)] = 0.0
        level[rng.choice(len(level), 6, replace=False)] *= 1e-3
    snap = (0.0, CUT_SNAP, 0.2)[seed % 3]
    split = split_faces(points, faces, level, snap=snap)
    polygons, added, on_cut = clip_faces(points, faces, level, snap)
    assert split.on_cut.tolist() == on_cut
    assert {tuple(e): t for e, t in zip(split.edges.tolist(), split.t)} == pytest.approx(added, abs=1e-15)
    assert np.all((split.t >= snap) & (split.t <= 1 - snap))
    x = _positions(split, points)
    tri = x[split.faces]
    area = _areas(tri)
    # each face's part on each side: the same area, the same corners; pieces keep the face's orientation
    for f, parts in enumerate(polygons):
        for side in (1, -1):
            mine = (split.parent == f) & (split.side == side)
            assert np.isclose(area[mine].sum(), polygon_area(parts[side]) if side in parts else 0.0, atol=1e-12)
            if side in parts:
                got = {tuple(np.round(q, 9)) for q in tri[mine].reshape(-1, 3)}
                assert got == {tuple(np.round(q, 9)) for q in parts[side]}
    face_n = np.cross(points[faces[:, 1]] - points[faces[:, 0]], points[faces[:, 2]] - points[faces[:, 0]])
    piece_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.einsum("ij,ij->i", piece_n, face_n[split.parent]) > 0)
    # the pieces of a face follow each other, in the order of the faces
    assert np.all(np.diff(split.parent) >= 0) and set(split.parent.tolist()) == set(range(len(faces)))


def test_corner_weights_carry_per_corner_values():
    """A per-corner value linear in the position (texture coordinates of a planar map) comes
    out at each piece corner as at its position; a per-vertex value along the added edges."""
    rng = np.random.default_rng(3)
    points, faces = _grid(rng)
    split = split_faces(points, faces, plane_levels(points, [2.9, 3.1, 0.0], [0.6, 0.8, 0.0]))
    assert len(split.edges) > 5
    A = rng.normal(size=(3, 2))
    got = split.corners((points @ A)[faces])
    np.testing.assert_allclose(got, _positions(split, points)[split.faces] @ A, atol=1e-12)
    colours = rng.uniform(0, 255, (len(points), 4))
    t = split.t[:, None]
    np.testing.assert_allclose(split.added(colours), (1 - t) * colours[split.edges[:, 0]] + t * colours[split.edges[:, 1]])


def test_a_closed_surface_stays_closed():
    sphere = trimesh.creation.icosphere(subdivisions=3)
    points, faces = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    split = split_faces(points, faces, plane_levels(points, [0.0, 0.0, 0.137], [0.1, 0.2, 0.97] / np.linalg.norm(
        [0.1, 0.2, 0.97])))
    x = _positions(split, points)
    cut = trimesh.Trimesh(x, split.faces, process=False)
    assert cut.is_watertight and cut.is_winding_consistent
    assert cut.euler_number == sphere.euler_number == 2
    assert np.isclose(cut.area, sphere.area, rtol=1e-12)
    # the added vertices lie on the plane
    n = np.array([0.1, 0.2, 0.97]) / np.linalg.norm([0.1, 0.2, 0.97])
    assert np.abs(plane_levels(split.added(points), [0.0, 0.0, 0.137], n)).max() < 1e-15


def test_faces_away_from_the_cut_are_one_piece_each():
    rng = np.random.default_rng(0)
    points, faces = _grid(rng)
    split = split_faces(points, faces, points[:, 0] + 100.0)
    np.testing.assert_array_equal(split.faces, faces)
    np.testing.assert_array_equal(split.side, 1)
    np.testing.assert_array_equal(split.weights, np.broadcast_to(np.eye(3), (len(faces), 3, 3)))
    assert split.edges.shape == (0, 2) and split.on_cut.size == 0


@pytest.mark.parametrize("bad, match", [
    (dict(level=np.zeros(3)), "one value per point"),
    (dict(faces=np.array([[0, 1, 99]])), "outside points"),
    (dict(level=np.full(49, np.nan)), "finite"),
    (dict(snap=0.5), "snap"),
])
def test_bad_input_is_refused(bad, match):
    points, faces = _grid(np.random.default_rng(0))
    args = dict(points=points, faces=faces, level=points[:, 0] - 3.1)
    with pytest.raises(ValueError, match=match):
        split_faces(**{**args, **bad})
