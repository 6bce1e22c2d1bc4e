"""Outer/inner wall separation (potflat.rollout.walls) on analytic shells with construction labels."""
from __future__ import annotations

import json

import _vessel_meshes as vm
import numpy as np
import pytest

from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.types import Mesh
from potflat.mesh.distortion import face_areas
from potflat.mesh.split import split_faces
from potflat.rollout.walls import (
    INNER,
    OUTER,
    FaceGraph,
    check_axis,
    cut_between_walls,
    largest_component,
    select_wall,
)


def _posed(V, F, seed=1, units="mm"):
    Vp, p, a = vm.pose(V, seed=seed)
    return Mesh(Vp, F, units=units), p, a


def _assert_clean_split(outer, inner, L, outer_parts, inner_parts):
    is_out = np.isin(L, outer_parts)
    is_in = np.isin(L, inner_parts)
    # the outer selection holds every outer face and no inner face, and vice versa
    assert outer.face_mask[is_out].all()
    assert not outer.face_mask[is_in].any()
    assert inner.face_mask[is_in].all()
    assert not inner.face_mask[is_out].any()
    # the two walls never share a face
    assert not (outer.face_mask & inner.face_mask).any()


@pytest.mark.parametrize("foot_ring", [False, True])
def test_cup_walls_match_construction(foot_ring):
    V, F, L, _ = vm.cup(foot_ring=foot_ring)
    mesh, p, a = _posed(V, F)
    outer = select_wall(mesh, p, a)
    inner = select_wall(mesh, p, a, side="inner")
    _assert_clean_split(outer, inner, L, ["base", "ring", "outer"], ["inner", "floor"])
    # the rim is split exactly once, at its crest: every rim face on one side, about half each
    rim = L == "rim"
    assert (outer.face_mask[rim] ^ inner.face_mask[rim]).all()
    assert abs(outer.face_mask[rim].mean() - 0.5) < 0.1
    assert outer.two_walled and inner.two_walled
    assert len(outer.rim_faces) > 0 and np.isin(L[outer.rim_faces], ["rim"]).all()
    assert outer.n_outer + outer.n_inner == len(F)
    assert not outer.normals_inverted


def test_cup_walls_with_noise():
    V, F, L, _ = vm.cup(foot_ring=True, n_theta=96)
    V = V + np.random.default_rng(5).normal(scale=0.3, size=V.shape)  # 10 % of the wall thickness
    mesh, p, a = _posed(V, F, seed=2)
    outer = select_wall(mesh, p, a)
    inner = select_wall(mesh, p, a, side="inner")
    _assert_clean_split(outer, inner, L, ["base", "ring", "outer"], ["inner", "floor"])


def _rim_variation(points):
    """How far the cup's rim line (points (k, 3) in its own frame) goes up and down its rounded
    rim as it goes round: the total variation of the angle across the rim, in turns."""
    across = np.arctan2(points[:, 2] - 60.0, np.hypot(points[:, 0], points[:, 1]) - 38.5)
    ordered = across[np.argsort(np.arctan2(points[:, 1], points[:, 0]))]
    return np.abs(np.diff(np.append(ordered, ordered[0]))).sum() / (2.0 * np.pi)


@pytest.mark.parametrize("seed", [5, 6])
def test_the_walls_are_cut_apart_along_a_smooth_line(seed):
    V, F, L, _ = vm.cup(foot_ring=True, n_theta=96)
    mesh, p, a = _posed(V + np.random.default_rng(seed).normal(scale=0.3, size=V.shape), F, seed=2)
    outer = select_wall(mesh, p, a)
    cut = cut_between_walls(mesh.faces, len(V), outer)
    # the split along whole faces is a staircase up and down the noisy rim; the line through
    # its middle goes round it once, near its crest
    stairs = np.intersect1d(np.unique(F[outer.face_mask]), np.unique(F[outer.labels == INNER]))
    line = np.concatenate([split_faces(V, F[cut.faces], cut.level).added(V), V[cut.level == 0.0]])
    assert _rim_variation(line) < 0.3 * _rim_variation(V[stairs])
    # only rim faces change sides or are cut; the rest keep their wall's whole level
    changed = cut.face_mask != outer.face_mask
    assert np.all(L[cut.faces] == "rim") and np.all(L[changed] == "rim")
    assert cut.faces_added == int((cut.face_mask & ~outer.face_mask).sum()) > 0
    assert cut.faces_dropped == int((outer.face_mask & ~cut.face_mask).sum())
    far = ~np.isin(L, ["rim", "outer", "inner"])
    assert np.all(np.abs(cut.level[F[far]]) == 1.0)
    assert np.all(cut.level[F[cut.face_mask]].max(axis=1) > 0.0)


def test_walls_split_along_a_clean_ring_or_one_wall_are_not_cut():
    mesh, p, a = _posed(*vm.cup(foot_ring=True, n_theta=96)[:2])
    outer = select_wall(mesh, p, a)
    cut = cut_between_walls(mesh.faces, len(mesh.vertices), outer)
    assert len(cut.faces) == 0 and np.array_equal(cut.face_mask, outer.face_mask)
    mesh, p, a = _posed(*vm.open_vase()[:2])
    assert cut_between_walls(mesh.faces, len(mesh.vertices), select_wall(mesh, p, a)) is None


def test_cutting_between_walls_needs_the_faces_they_were_selected_on():
    mesh, p, a = _posed(*vm.cup()[:2])
    outer = select_wall(mesh, p, a)
    with pytest.raises(InvalidInputError, match="the faces the walls were selected on"):
        cut_between_walls(mesh.faces[:-1], len(mesh.vertices), outer)


def test_kylix_tondo_is_inner():
    # shallow bowl on a stem: the whole interior incl. the tondo floor is the inner wall
    rs = [0, 20, 20.5, 4, 4, 30, 62, 64, 63, 61, 30, 0]
    hs = [0, 0, 1, 8, 30, 34, 45, 46.5, 47.5, 46.5, 37, 36]
    crest = 8  # index of the rim crest point (63, 47.5)
    r, h, lab = [], [], []
    for i in range(len(rs) - 1):
        r += list(np.linspace(rs[i], rs[i + 1], 6, endpoint=False))
        h += list(np.linspace(hs[i], hs[i + 1], 6, endpoint=False))
        lab += ["outer" if i < crest else "inner"] * 6
    r.append(0.0)
    h.append(36.0)
    V, F, L, _ = vm.revolve(r, h, 72, labels=lab + [None])
    mesh, p, a = _posed(V, F, seed=3)
    outer = select_wall(mesh, p, a)
    inner = select_wall(mesh, p, a, side="inner")
    _assert_clean_split(outer, inner, L, ["outer"], ["inner"])


@pytest.mark.parametrize("table", [1.5, 4.0])
def test_a_table_joined_to_the_foot_is_left_out(table):
    """A cup scanned standing on a table, the table's top joined to the foot: the table faces
    up beyond the foot at the lowest heights and is left out; both walls split as without it."""
    V, F, L, _ = vm.cup(table=table)
    mesh, p, a = _posed(V, F)
    outer = select_wall(mesh, p, a)
    inner = select_wall(mesh, p, a, side="inner")
    assert np.array_equal(outer.ground_mask, L == "table")
    assert np.isclose(outer.ground_area, face_areas(mesh.vertices, mesh.faces)[L == "table"].sum())
    _assert_clean_split(outer, inner, L, ["outer"], ["inner", "floor"])
    assert not outer.face_mask[L == "table"].any()
    assert outer.summary()["area_ground"] == outer.ground_area


def test_a_table_tilted_against_the_axis_is_left_out_where_it_rises():
    """The table tilted by 2 degrees (away from the foot it stays joined to): one side rises
    out of the lowest heights (5.6 mm at its 160 mm radius, against 1.8 mm), the other
    sinks as far below the foot. All of it is left out: the heights are measured from the
    cup's lowest face that does not face up, and the ground grows well outside the cup's
    profile at any height."""
    V, F, L, _ = vm.cup(table=4.0)
    V = V.copy()
    on_table = np.zeros(len(V), bool)
    on_table[F[L == "table"].ravel()] = True
    on_table &= np.hypot(V[:, 0], V[:, 1]) > 30.0 + 1e-9  # (the ring it shares with the foot stays)
    r = np.hypot(V[on_table, 0], V[on_table, 1])
    V[on_table, 2] += np.tan(np.radians(2.0)) * V[on_table, 0] * (r - 30.0) / (r.max() - 30.0)
    assert V[on_table, 2].max() > 0.05 * 60.0  # (out of the lowest 3 % of the height, and as far below)
    mesh, p, a = _posed(V, F)
    outer = select_wall(mesh, p, a)
    assert np.array_equal(outer.ground_mask, L == "table")
    assert not outer.face_mask[L == "table"].any() and outer.face_mask[L == "outer"].all()


def test_the_top_of_a_thin_foot_is_not_taken_for_a_table():
    """A stemmed cup on a thin disc foot: the foot's top faces up at the lowest heights but
    lies within the foot's edge, so it stays with the outer wall."""
    rs = [0, 30, 30, 6, 6, 40, 41.5, 41, 38, 0]
    hs = [0, 0, 1, 1.2, 20, 58, 60, 61.5, 58, 24]
    r, h, lab = [], [], []
    for i in range(len(rs) - 1):
        r += list(np.linspace(rs[i], rs[i + 1], 6, endpoint=False))
        h += list(np.linspace(hs[i], hs[i + 1], 6, endpoint=False))
        lab += ["foot top" if i == 2 else "outer" if i < 7 else "inner"] * 6
    r.append(0.0)
    h.append(24.0)
    V, F, L, _ = vm.revolve(r, h, 72, labels=lab + [None])
    mesh, p, a = _posed(V, F, seed=4)
    outer = select_wall(mesh, p, a)
    assert not outer.ground_mask.any() and outer.ground_area == 0.0
    assert outer.face_mask[L == "foot top"].all()


def test_single_walled_vessel_is_all_outer():
    V, F, _, _ = vm.open_vase()
    mesh, p, a = _posed(V, F)
    w = select_wall(mesh, p, a)
    assert w.face_mask.all() and (w.labels == OUTER).all()
    assert not w.two_walled and w.n_inner == 0 and len(w.rim_faces) == 0
    json.dumps(w.summary())


def test_inside_out_single_surface_is_read_flipped():
    V, F, _, _ = vm.open_vase()
    mesh, p, a = _posed(V, F[:, ::-1])
    w = select_wall(mesh, p, a)
    assert w.normals_inverted and w.face_mask.all()


def test_a_sheet_facing_the_axis_is_read_inside_out_unless_its_orientation_is_kept():
    """The face of a dish alone, facing up as scanned: most of it faces the axis, which reads
    as an open surface facing inwards; with ``inside_out=False`` (``keep_orientation``) its
    well and broad rim are the inner side they are."""
    V, F, labels, _ = vm.dish()
    mesh, p, a = _posed(V, F)
    assert select_wall(mesh, p, a).normals_inverted
    inner = select_wall(mesh, p, a, side="inner", inside_out=False)
    assert not inner.normals_inverted
    assert inner.face_mask[np.isin(labels, ["well", "broad rim"])].mean() > 0.95


def test_inner_wall_requested_on_single_surface_raises():
    V, F, _, _ = vm.open_vase()
    mesh, p, a = _posed(V, F)
    with pytest.raises(InvalidInputError, match="no inner wall"):
        select_wall(mesh, p, a, side="inner")


def test_sherd_shell_walls():
    V, F, L = vm.sherd_shell(theta_span=np.deg2rad(70))
    mesh, p, a = _posed(V, F, seed=4)
    outer = select_wall(mesh, p, a)
    inner = select_wall(mesh, p, a, side="inner")
    _assert_clean_split(outer, inner, L, ["outer"], ["inner"])


@pytest.mark.parametrize("span_deg", [60, 120])
def test_open_sherd_patch_is_outer(span_deg):
    h = np.linspace(10, 70, 31)
    V, F, _, _ = vm.revolve(vm.vase_radius(h), h, 40, theta1=np.deg2rad(span_deg))
    mesh, p, a = _posed(V, F)
    w = select_wall(mesh, p, a)
    assert w.face_mask.all()


def test_holed_cup():
    V, F, L, T = vm.cup()
    tri_h = V[F][:, :, 2].mean(axis=1)
    hole = (np.abs(T - 1.0) < 0.3) & (np.abs(tri_h - 30) < 8)  # a hole through the outer wall
    mesh, p, a = _posed(V, F[~hole])
    outer = select_wall(mesh, p, a)
    inner = select_wall(mesh, p, a, side="inner")
    _assert_clean_split(outer, inner, L[~hole], ["base", "outer"], ["inner", "floor"])


def test_handle_inner_side_belongs_to_outer():
    V, F, is_handle = vm.cylinder_with_handle()
    mesh, p, a = _posed(V, F)
    w = select_wall(mesh, p, a)
    assert (w.labels[is_handle] == OUTER).all()  # the side of the handle facing the body too
    # the handle is a separate component: the selection is the body
    assert w.face_mask[~is_handle].all() and w.n_dropped == is_handle.sum()


def test_exclude_attachments():
    from potflat.rollout.attachments import detect_attachments

    # a knob pushed out of the wall is part of the same surface: only the exclusion removes it
    V, F, _ = vm.cylinder_with_knob()
    mesh, p, a = _posed(V, F)
    att = detect_attachments(mesh, p, a)
    assert att.n_faces > 0
    assert select_wall(mesh, p, a).face_mask.all()
    w = select_wall(mesh, p, a, exclude=att.face_mask)
    assert np.array_equal(w.face_mask, ~att.face_mask)  # the rest stays one connected region
    assert w.n_dropped == att.n_faces
    with pytest.raises(InvalidInputError):
        select_wall(mesh, p, a, exclude=np.zeros(5, bool))
    with pytest.raises(InvalidInputError):
        select_wall(mesh, p, a, exclude=np.zeros(len(F)))  # not boolean
    with pytest.raises(InvalidInputError, match="others must be"):
        select_wall(mesh, p, a, others=np.zeros(5, bool))
    with pytest.raises(InvalidInputError, match="others must be"):
        select_wall(mesh, p, a, others=np.zeros(len(F)))  # not boolean


def test_deterministic():
    V, F, _, _ = vm.cup(foot_ring=True)
    mesh, p, a = _posed(V, F)
    w1 = select_wall(mesh, p, a, side="inner")
    w2 = select_wall(mesh, p, a, side="inner")
    assert np.array_equal(w1.labels, w2.labels) and np.array_equal(w1.face_mask, w2.face_mask)


@pytest.mark.parametrize("tolerance", [0.3, 0.7])
def test_flat_faces_take_the_side_of_the_nearest_seed(monkeypatch, tolerance):
    """Faces whose smoothed radial normal is under the tolerance take the side of the nearest
    clear face along the surface, a climb towards it over the flat face's crest (up for a
    face facing the mouth, down for one facing the foot) counting ``_CLIMB_WEIGHT`` times:
    the same as a Dijkstra over the whole face graph from every clear face (the labelling
    searches only the steps touching a flat face)."""
    import scipy.sparse as sps
    from scipy.sparse.csgraph import dijkstra

    from potflat.rollout import walls

    V, F, _, _ = vm.cup(foot_ring=True, n_theta=48)
    V = V + np.random.default_rng(3).normal(scale=0.3, size=V.shape)
    mesh, p, a = _posed(V, F, seed=4)
    fr = walls.face_frame(mesh, p, a)
    monkeypatch.setattr(walls, "_refine_border", lambda fr, labels, *rest: labels)
    monkeypatch.setattr(walls, "_clean_regions", lambda fr, labels, sign, others: labels)
    got = walls._label_once(fr, tolerance, 1.0, None)
    s = walls._smooth(fr.n_radial, fr.area, fr.graph, walls._SMOOTH_ITERATIONS)
    seed = np.abs(s) >= tolerance
    assert 0.05 < 1 - seed.mean() < 0.95
    # every step both ways: from face i to face j costs the distance plus the climb from j to i
    i, j = np.concatenate([fr.adjacency, fr.adjacency[:, ::-1]]).T
    facing = np.sign(fr.n_axial[i] + fr.n_axial[j])
    cost = (np.linalg.norm(fr.centroid[i] - fr.centroid[j], axis=1)
            + walls._CLIMB_WEIGHT * np.maximum(facing * (fr.height[i] - fr.height[j]), 0.0))
    graph = sps.csr_matrix((cost, (i, j)), shape=(len(F), len(F)))
    _, _, nearest = dijkstra(graph, directed=True, indices=np.flatnonzero(seed), return_predecessors=True,
                             min_only=True)
    flat = ~seed & (nearest >= 0)
    assert flat.sum() > 50
    assert np.array_equal(got[flat], np.where(s >= 0, OUTER, INNER)[nearest[flat]])


def test_face_graph_matrix_takes_a_weight_each_way():
    from potflat.rollout.walls import FaceGraph

    V, F, _, _ = vm.cup(n_theta=12)
    graph = FaceGraph(F)
    pairs = graph.pairs
    w = np.random.default_rng(0).uniform(1.0, 2.0, size=(len(pairs), 2))
    M = graph.matrix(w).toarray()
    assert np.array_equal(M[pairs[:, 0], pairs[:, 1]], w[:, 0])
    assert np.array_equal(M[pairs[:, 1], pairs[:, 0]], w[:, 1])
    assert np.count_nonzero(M) == 2 * len(pairs)
    assert np.array_equal(graph.matrix(w[:, 0]).toarray(), graph.matrix(np.stack([w[:, 0]] * 2, 1)).toarray())


@pytest.mark.parametrize("side", ["inner", "outer"])
def test_a_plate_s_broad_rim_goes_with_its_inside(side):
    """A plate's broad rim, sloping gently down to the well, is nearly flat (its radial normal
    under the tolerance), and nearer the outer wall at the rim's edge than the well over its
    outer half: it still goes with the inside, the side it reaches without crossing its crest,
    and the outer wall keeps none of it."""
    V, F, labels, _ = vm.plate()
    mesh, p, a = _posed(V, F)
    w = select_wall(mesh, p, a, side=side)
    radius = np.linalg.norm((V[F].mean(axis=1))[:, :2], axis=1)  # (the canonical frame: axis = z)
    broad = (labels == "broad rim") & (radius < 118.0)  # (the ring at the crest, radius 120, may go either way)
    assert broad.sum() > 500
    assert (w.face_mask[broad].all() if side == "inner" else not w.face_mask[broad].any())
    underside = labels == "underside"
    assert (not w.face_mask[underside].any()) if side == "inner" else w.face_mask[underside].mean() > 0.9


def test_a_level_rim_top_still_splits_at_its_middle():
    """A level rim top, its crest all along it, splits midway between the two walls."""
    V, F, labels, _ = vm.plate(broad_rim_drop=0.0)
    mesh, p, a = _posed(V, F)
    w = select_wall(mesh, p, a, side="inner")
    broad = labels == "broad rim"
    radius = np.linalg.norm((V[F].mean(axis=1))[:, :2], axis=1)  # (the canonical frame: axis = z)
    inner_share = w.face_mask[broad].mean()
    assert 0.3 < inner_share < 0.7
    assert radius[broad & w.face_mask].max() < radius[broad & ~w.face_mask].min() + 2.0


def test_largest_component():
    V, F, is_handle = vm.cylinder_with_handle()
    mesh = Mesh(V, F)
    keep = largest_component(mesh, np.ones(len(F), bool))
    assert np.array_equal(keep, ~is_handle)
    assert not largest_component(mesh, np.zeros(len(F), bool)).any()
    with pytest.raises(InvalidInputError):
        largest_component(mesh, np.ones(3, bool))


def test_check_axis_normalises():
    p, a = check_axis([1, 2, 3], [0, 0, 5])
    assert np.allclose(a, [0, 0, 1]) and np.allclose(p, [1, 2, 3])


@pytest.mark.parametrize("axis_point, axis_direction", [
    ([0, 0, 0], [0, 0, 0]),          # zero length
    ([0, 0, 0], [0, 0, 1e-15]),      # numerically zero
    ([0, 0, np.nan], [0, 0, 1]),     # not finite
    ([0, 0], [0, 0, 1]),             # wrong shape
    ([0, 0, 0], [0, np.inf, 1]),
])
def test_bad_axis(axis_point, axis_direction):
    V, F, _, _ = vm.open_vase(n_theta=16, n_h=5)
    with pytest.raises(InvalidInputError):
        select_wall(Mesh(V, F), axis_point, axis_direction)


@pytest.mark.parametrize("kwargs", [{"side": "top"}, {"side": "Outer"}, {"side": None},
                                    {"flat_tolerance": 0.0}, {"flat_tolerance": 1.0},
                                    {"flat_tolerance": "0.2"}])
def test_bad_options(kwargs):
    V, F, _, _ = vm.open_vase(n_theta=16, n_h=5)
    with pytest.raises(InvalidOptionError):
        select_wall(Mesh(V, F), [0, 0, 0], [0, 0, 1], **kwargs)


def test_bad_mesh():
    with pytest.raises(InvalidInputError):
        select_wall("not a mesh", [0, 0, 0], [0, 0, 1])
    with pytest.raises(InvalidInputError, match="no faces"):
        select_wall(Mesh(np.zeros((3, 3)), np.zeros((0, 3), np.int64)), [0, 0, 0], [0, 0, 1])
    with pytest.raises(InvalidInputError, match="non-finite"):
        select_wall(Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]]), [[0, 1, 2]]), [0, 0, 0], [0, 0, 1])


def test_synthetic_vessels_if_available():
    from potflat_synthetic import vessels as synthetic
    v = synthetic.make_vessel("cup", n_vertices=6000, texture_size=64)
    outer = select_wall(v.mesh, v.axis_point, v.axis_direction)
    inner = select_wall(v.mesh, v.axis_point, v.axis_direction, side="inner")
    part = v.face_part
    _assert_clean_split(outer, inner, part, [synthetic.PART_OUTER, synthetic.PART_BASE], [synthetic.PART_INNER])
    assert set(np.unique(outer.labels)) == {OUTER, INNER}


def _face_adjacency_reference(F):
    """Slow reference: faces on each undirected edge used by exactly two faces, the pairs
    ordered by (larger, smaller) endpoint of the edge, lower face first."""
    on_edge = {}
    for f, tri in enumerate(F):
        for k in range(3):
            a, b = int(tri[k]), int(tri[(k + 1) % 3])
            on_edge.setdefault((min(a, b), max(a, b)), []).append(f)
    rows = sorted((e[1], e[0], min(fs), max(fs)) for e, fs in on_edge.items() if len(fs) == 2 and fs[0] != fs[1])
    pairs = np.array([[r[2], r[3]] for r in rows], np.int64).reshape(-1, 2)
    edges = np.array([[r[1], r[0]] for r in rows], np.int64).reshape(-1, 2)
    return pairs, edges


def test_face_adjacency_matches_reference_and_trimesh():
    import trimesh

    from potflat.rollout.walls import face_adjacency

    rng = np.random.default_rng(3)
    meshes = [np.asarray(vm.cup(n_theta=16)[1], np.int64)]
    # random small meshes with non-manifold edges (three faces) and degenerate faces
    for _ in range(20):
        meshes.append(rng.integers(0, 9, size=(rng.integers(1, 30), 3)).astype(np.int64))
    meshes.append(np.array([[0, 1, 2], [2, 1, 3], [1, 0, 4], [0, 0, 1]], np.int64))
    for F in meshes:
        pairs, edges = face_adjacency(F, return_edges=True)
        ref_pairs, ref_edges = _face_adjacency_reference(F)
        np.testing.assert_array_equal(pairs, ref_pairs)
        np.testing.assert_array_equal(edges, ref_edges)
        np.testing.assert_array_equal(face_adjacency(F), ref_pairs)
        np.testing.assert_array_equal(pairs, np.asarray(trimesh.graph.face_adjacency(faces=F), np.int64).reshape(-1, 2))


def test_face_graph_components_match_scipy():
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(5)
    F = np.asarray(vm.cup(n_theta=16)[1], np.int64)
    graph = FaceGraph(F)
    for mask in (None, rng.random(len(graph.pairs)) < 0.5, np.zeros(len(graph.pairs), bool)):
        pairs = graph.pairs if mask is None else graph.pairs[mask]
        A = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(F), len(F)))
        _, ref = connected_components(A, directed=False)
        comp = graph.components(mask)
        assert comp.dtype == np.int64
        np.testing.assert_array_equal(comp, ref)


class _GivenPairs(FaceGraph):
    """A face graph of given pairs (any multigraph), for testing :meth:`FaceGraph.matrix` and
    :meth:`FaceGraph.neighbour_sum`."""

    def __init__(self, m, pairs):
        self.m = m
        self._given = pairs

    @property
    def pairs(self):
        return self._given


@pytest.mark.parametrize("seed", range(3))
def test_face_graph_matrix_matches_the_sorting_reference(seed):
    """The CSR of pair_csr: the indices, row pointers and data of the former stable argsort of
    ``i * m + j`` (repeated pairs and a face without neighbours included)."""
    import scipy.sparse as sp

    rng = np.random.default_rng(seed)
    m = 60
    pairs = rng.integers(0, m - 1, size=(150, 2))  # node m - 1 has no neighbour
    pairs = np.concatenate([pairs, pairs[:20], pairs[:10, ::-1]])
    weights = rng.random(len(pairs))
    weights[::7] = 0.0  # eliminated
    i = np.concatenate([pairs[:, 0], pairs[:, 1]])
    j = np.concatenate([pairs[:, 1], pairs[:, 0]])
    order = np.argsort(i * m + j, kind="stable")
    indptr = np.concatenate([[0], np.cumsum(np.bincount(i, minlength=m))]).astype(np.int32)
    ref = sp.csr_matrix((np.concatenate([weights, weights])[order], j[order].astype(np.int32), indptr), shape=(m, m))
    ref.eliminate_zeros()
    got = _GivenPairs(m, pairs).matrix(weights)
    for a, b in ((got.indptr, ref.indptr), (got.indices, ref.indices), (got.data, ref.data)):
        assert a.dtype == b.dtype and np.array_equal(a, b)


@pytest.mark.parametrize("seed", range(3))
def test_face_graph_neighbour_sum_is_the_adjacency_times_x(seed):
    """Each pair adds its other end's value to both ends (repeated pairs count each time, a
    face without neighbours gets 0): the dense adjacency matrix times x."""
    rng = np.random.default_rng(seed)
    m = 40
    pairs = rng.integers(0, m - 1, size=(90, 2))
    pairs = np.concatenate([pairs, pairs[:10]])
    x = rng.normal(size=m)
    dense = np.zeros((m, m))
    for a, b in pairs:
        dense[a, b] += 1.0
        dense[b, a] += 1.0
    got = _GivenPairs(m, pairs).neighbour_sum(x)
    assert np.allclose(got, dense @ x, rtol=1e-13, atol=1e-13) and got[m - 1] == 0.0


def test_select_wall_takes_the_callers_face_graph():
    V, F, _, _ = vm.cup(n_theta=16)
    mesh, p, a = _posed(V, F)
    own = select_wall(mesh, p, a, side="inner")
    given = select_wall(mesh, p, a, side="inner", graph=FaceGraph(mesh.faces, shared=True))
    assert own.two_walled and np.array_equal(own.labels, given.labels)
    assert np.array_equal(own.face_mask, given.face_mask)
    for wrong in (FaceGraph(mesh.faces[:-1], shared=True), FaceGraph(mesh.faces), mesh.faces):
        with pytest.raises(InvalidInputError, match="FaceGraph"):
            select_wall(mesh, p, a, graph=wrong)


def test_face_graph_finds_the_adjacency_once_on_first_use(monkeypatch):
    from potflat.rollout import walls

    calls = []
    real = walls.face_adjacency
    monkeypatch.setattr(walls, "face_adjacency", lambda *a, **k: calls.append(1) or real(*a, **k))
    F = np.asarray(vm.cup(n_theta=16)[1], np.int64)
    graph = walls.FaceGraph(F, shared=True)
    assert not calls and graph.m == len(F)
    pairs, shared = real(F, return_edges=True)
    assert np.array_equal(graph.pairs, pairs) and np.array_equal(graph.shared, shared)
    graph.components()
    assert len(calls) == 1


def test_face_graph_keeps_shared_edges_only_when_asked():
    F = np.asarray(vm.cup(n_theta=16)[1], np.int64)
    graph = FaceGraph(F)
    assert len(graph.pairs)
    with pytest.raises(ValueError, match="shared=True"):
        _ = graph.shared


def test_cylindrical_matches_numpy_reference():
    from potflat.rollout.walls import cylindrical

    rng = np.random.default_rng(9)
    points = rng.normal(size=(200, 3)) * 50.0
    p = np.array([1.0, -2.0, 3.0])
    a = np.array([0.3, -0.4, 0.866])
    a /= np.linalg.norm(a)
    points[0] = p  # on the axis: radius 0, radial 0
    d = points - p
    h_ref = d @ a
    perp = d - h_ref[:, None] * a
    r_ref = np.linalg.norm(perp, axis=1)
    height, radius, radial = cylindrical(points, p, a)
    np.testing.assert_array_equal(height, h_ref)
    np.testing.assert_array_equal(radius, r_ref)
    ok = r_ref > 0
    np.testing.assert_array_equal(radial[ok], perp[ok] / r_ref[ok, None])
    assert radius[0] == 0 and (radial[0] == 0).all()


def test_weighted_quantiles_per_group_select_as_a_sort_of_each_group_would():
    """Each group's quantiles are its own (a full sort of the group's values of positive weight,
    the first whose cumulative weight reaches the share; integer weights sum exactly), for
    groups of one entry, of many thousands (several radix passes), with ties, and NaN for a
    group that is empty or whose entries all weigh nothing; the entries in any order."""
    from potflat.rollout.walls import weighted_quantiles

    rng = np.random.default_rng(5)
    sizes = [1, 3, 0, 40, 9000, 7, 0, 300]
    b = np.repeat(np.arange(len(sizes)), sizes)
    v = rng.integers(0, 50, len(b)) / 7.0
    w = rng.integers(0, 4, len(b)).astype(float)
    w[b == 1] = 0.0  # (a group whose entries all weigh nothing)
    w[np.flatnonzero(b == 0)] = 2.0
    shuffle = rng.permutation(len(b))
    b, v, w = b[shuffle], v[shuffle], w[shuffle]
    qs = (0.0, 0.25, 0.5, 0.9, 1.0)
    got = weighted_quantiles(b, v, w, len(sizes) + 1, qs)
    assert got.shape == (len(qs), len(sizes) + 1)
    for g in range(len(sizes) + 1):
        keep = (b == g) & (w > 0)
        if not keep.any():
            assert np.isnan(got[:, g]).all()
            continue
        order = np.argsort(v[keep], kind="stable")
        cum = np.cumsum(w[keep][order])
        want = [v[keep][order][min(np.searchsorted(cum, q * cum[-1]), keep.sum() - 1)] for q in qs]
        np.testing.assert_array_equal(got[:, g], want)


@pytest.mark.parametrize("case", ["group out of range", "negative group", "lengths differ"])
def test_weighted_quantiles_refuse_groups_outside_or_samples_of_other_lengths(case):
    from potflat.rollout.walls import weighted_quantiles

    b, v, w = np.array([0, 1, 2]), np.ones(3), np.ones(3)
    if case == "group out of range":
        b = np.array([0, 1, 3])
    elif case == "negative group":
        b = np.array([0, -1, 2])
    else:
        w = np.ones(2)
    with pytest.raises(ValueError, match="groups in"):
        weighted_quantiles(b, v, w, 3, (0.5,))
