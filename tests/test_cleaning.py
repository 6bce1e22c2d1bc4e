"""Mesh cleaning: welding, junk removal, non-manifold handling, orientation, reports."""
from __future__ import annotations

import json

import numpy as np
import pytest

from potflat.mesh._kernels.topology import edge_table, fan_joins, first_equal_rows, union_find
from potflat.mesh.cleaning import CleaningReport, clean_mesh, weld_vertices
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.types import Mesh


def _cylinder(nu=16, nv=6, r=1.0, h=2.0, shift=(0.0, 0.0, 0.0)):
    """Open cylinder, faces CCW seen from outside."""
    th = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    z = np.linspace(0, h, nv + 1)
    T, Z = np.meshgrid(th, z, indexing="ij")
    V = np.stack([r * np.cos(T), r * np.sin(T), Z], -1).reshape(-1, 3) + shift
    idx = np.arange(len(V)).reshape(nu, nv + 1)
    a, b = idx, np.roll(idx, -1, axis=0)
    F = np.concatenate([np.stack([a[:, :-1], b[:, :-1], b[:, 1:]], -1).reshape(-1, 3),
                        np.stack([a[:, :-1], b[:, 1:], a[:, 1:]], -1).reshape(-1, 3)])
    return V, F


def _radial_outward(mesh, centre=(0.0, 0.0)):
    V, F = mesh.vertices, mesh.faces
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    c = V[F].mean(1)
    return np.einsum("ij,ij->i", n[:, :2], c[:, :2] - np.asarray(centre))


def _pos_texcoords(V, F):
    """Per-corner texture coordinates that are a function of the corner's position."""
    P = V[F]
    return np.stack([P[..., 0] + 0.1 * P[..., 2], P[..., 1] - 0.3 * P[..., 2]], -1)


def _check_alignment(mesh):
    """Texture coordinates and colours still belong to their corners / vertices."""
    np.testing.assert_allclose(mesh.texcoords, _pos_texcoords(mesh.vertices, mesh.faces), atol=1e-12)


# ------------------------------------------------------------------ kernels vs references


def test_edge_table_matches_reference():
    rng = np.random.default_rng(0)
    F = rng.integers(0, 12, (40, 3))
    edge_of, edges, count, halves = edge_table(F, 12)
    ref: dict[tuple[int, int], list[int]] = {}
    for f in range(len(F)):
        for k in range(3):
            a, b = F[f, k], F[f, (k + 1) % 3]
            ref.setdefault((min(a, b), max(a, b)), []).append(3 * f + k)
    keys = sorted(ref)
    assert [tuple(e) for e in edges] == keys
    for e, key in enumerate(keys):
        assert count[e] == len(ref[key])
        assert list(halves[e][:min(2, len(ref[key]))]) == ref[key][:2]
        assert all(edge_of[h] == e for h in ref[key])


def test_edge_table_is_the_same_for_any_thread_count():
    """Each thread buckets its own range of lower endpoints: one thread and two or three (as
    many as Numba has) give the same table, also with ranges of one vertex and no faces."""
    import numba

    from potflat._jit import numba_threads

    rng = np.random.default_rng(1)
    F = rng.integers(0, 300, (3000, 3))
    with numba_threads(1):
        want = edge_table(F, 300)
    for threads in range(2, min(3, numba.config.NUMBA_NUM_THREADS) + 1):
        with numba_threads(threads):
            for got, expected in zip(edge_table(F, 300), want):
                np.testing.assert_array_equal(got, expected)
    with numba_threads(2):  # (two vertices, two ranges of one each; no faces at all)
        assert [len(a) for a in edge_table(np.array([[0, 1, 1]]), 2)] == [3, 2, 2, 2]
        assert [len(a) for a in edge_table(np.zeros((0, 3), np.int64), 0)] == [0, 0, 0, 0]


@pytest.mark.parametrize("seed", range(3))
def test_corner_fans_match_the_numpy_reference(seed):
    """fan_joins: the corner pairs (and so the fan labels) of the former NumPy expressions, on
    meshes with non-manifold edges and faces of both windings."""
    from potflat.mesh.cleaning import _corner_fans, _topology

    rng = np.random.default_rng(seed)
    F = rng.integers(0, 25, (150, 3))
    F = F[(F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])]
    topo = _topology(F, 25)
    h1, h2, same = topo.h1, topo.h2, topo.same
    nxt1, nxt2 = h1 - h1 % 3 + (h1 + 1) % 3, h2 - h2 % 3 + (h2 + 1) % 3
    a = np.concatenate([h1, nxt1])
    b = np.concatenate([np.where(same, h2, nxt2), np.where(same, nxt2, h2)])
    assert same.any() and not same.all() and (topo.count > 2).any()
    assert np.array_equal(fan_joins(h1, h2, same)[0], a) and np.array_equal(fan_joins(h1, h2, same)[1], b)
    label, count = _corner_fans(F, topo)
    want, n_want = union_find(3 * len(F), a, b)
    assert count == n_want and np.array_equal(label, want)


def test_union_find_matches_scipy():
    from scipy import sparse
    from scipy.sparse.csgraph import connected_components

    rng = np.random.default_rng(1)
    a, b = rng.integers(0, 50, 30), rng.integers(0, 50, 30)
    label, count = union_find(50, a, b)
    n_ref, ref = connected_components(sparse.coo_matrix((np.ones(30), (a, b)), shape=(50, 50)), directed=False)
    assert count == n_ref
    # same partition, labels numbered by lowest member
    assert all((label == label[i]).tolist() == (ref == ref[i]).tolist() for i in range(50))
    first = [int(np.flatnonzero(label == k)[0]) for k in range(count)]
    assert first == sorted(first)


@pytest.mark.parametrize("unordered", [False, True])
def test_first_equal_rows_matches_a_dict(unordered):
    # few distinct values: many equal rows, many hash collisions in the probe sequences
    rng = np.random.default_rng(3)
    K = rng.integers(-3, 4, (2000, 3))
    skip = rng.random(2000) < 0.1
    first: dict[tuple, int] = {}
    ref = np.arange(2000)
    for i, row in enumerate(K.tolist()):
        if not skip[i]:
            ref[i] = first.setdefault(tuple(sorted(row)) if unordered else tuple(row), i)
    rep = first_equal_rows(K, unordered, skip)
    np.testing.assert_array_equal(rep, ref)
    assert (rep < np.arange(2000)).any() and (rep[skip] == np.flatnonzero(skip)).all()


def test_propagate_orientation_fixes_random_flips():
    V, F = _cylinder()
    rng = np.random.default_rng(2)
    flipped = rng.random(len(F)) < 0.4
    G = F.copy()
    G[flipped] = G[flipped][:, [0, 2, 1]]
    mesh, report = clean_mesh(Mesh(V, G))
    assert report.orientation_conflicts == 0
    assert report.faces_reoriented == flipped.sum()
    assert (_radial_outward(mesh) > 0).all()


def test_propagate_orientation_counts_conflicts_on_moebius():
    n = 24
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    w = np.array([-0.3, 0.3])
    V = np.array([[(1 + s * np.cos(a / 2)) * np.cos(a), (1 + s * np.cos(a / 2)) * np.sin(a), s * np.sin(a / 2)]
                  for a in t for s in w])
    F = []
    for i in range(n):
        a0, a1 = 2 * i, 2 * i + 1
        j = (i + 1) % n
        b0, b1 = (2 * j, 2 * j + 1) if j else (1, 0)  # the half twist
        F += [[a0, b0, b1], [a0, b1, a1]]
    _, report = clean_mesh(Mesh(V, np.array(F)))
    assert report.orientation_conflicts >= 1
    assert any("non-orientable" in w for w in report.warnings)


# ------------------------------------------------------------------ welding


def test_weld_vertices_exact_keeps_first_and_order():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [-0.0, 1, 0], [1, 1, 0]], float)
    F = np.array([[0, 1, 2], [3, 5, 4]])
    colours = np.arange(24, dtype=np.uint8).reshape(6, 4)
    mesh, merged = weld_vertices(Mesh(V, F, vertex_colors=colours))
    assert merged == 2
    np.testing.assert_array_equal(mesh.vertices, V[[0, 1, 2, 5]])
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [1, 3, 2]])
    np.testing.assert_array_equal(mesh.vertex_colors, colours[[0, 1, 2, 5]])


def test_weld_vertices_tolerance_is_relative_to_diagonal():
    V = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [10 + 1e-6, 0, 0], [0, 10, 1e-6], [10, 10, 0]], float)
    F = np.array([[0, 1, 2], [3, 5, 4]])
    assert weld_vertices(Mesh(V, F))[1] == 0
    mesh, merged = weld_vertices(Mesh(V, F), tolerance=1e-6)  # 1e-6 x 14.1 > 1e-6
    assert merged == 2 and len(mesh.vertices) == 4
    np.testing.assert_array_equal(mesh.faces, [[0, 1, 2], [1, 3, 2]])
    with pytest.raises(InvalidOptionError):
        weld_vertices(Mesh(V, F), tolerance=0.5)


# ------------------------------------------------------------------ removal of junk


def test_degenerate_and_duplicate_faces_removed_and_counted():
    V, F = _cylinder()
    extra_v = np.array([[5, 0, 0], [6, 0, 0], [7, 0, 0]], float)  # collinear
    V2 = np.concatenate([V, extra_v])
    k = len(V)
    bad = np.array([[0, 0, 1], [k, k + 1, k + 2], F[3], F[4][[0, 2, 1]]])
    F2 = np.concatenate([F, bad])
    tc = _pos_texcoords(V2, F2)
    mesh, r = clean_mesh(Mesh(V2, F2, texcoords=tc))
    assert r.degenerate_faces_removed == 2
    assert r.duplicate_faces_removed == 2
    assert r.unreferenced_vertices_removed == 3
    assert len(mesh.faces) == len(F) and len(mesh.vertices) == len(V)
    _check_alignment(mesh)


def test_stray_small_components_removed_substantial_kept():
    V, F = _cylinder()
    Vs, Fs = _cylinder(nu=4, nv=1, r=0.05, h=0.05, shift=(5, 0, 0))  # tiny fragment
    V2, F2 = _cylinder(r=0.9, shift=(0, 0, 10))  # a second, similar vessel
    allV = np.concatenate([V, Vs, V2])
    allF = np.concatenate([F, Fs + len(V), F2 + len(V) + len(Vs)])
    mesh, r = clean_mesh(Mesh(allV, allF, texcoords=_pos_texcoords(allV, allF)))
    assert r.components == 3 and r.components_removed == 1
    assert r.faces_in_removed_components == len(Fs)
    assert 0 < r.removed_area_fraction < 0.01
    assert len(r.kept_component_area_fractions) == 2
    assert r.kept_component_area_fractions[0] == pytest.approx(1 / 1.9, rel=1e-6)
    assert any("2 substantial components" in w for w in r.warnings)
    assert len(mesh.faces) == len(F) + len(F2)
    assert len(mesh.vertices) == len(V) + len(V2)
    _check_alignment(mesh)
    # keep everything on request
    _, r0 = clean_mesh(Mesh(allV, allF), min_component_fraction=0.0)
    assert r0.components_removed == 0
    with pytest.raises(InvalidOptionError):
        clean_mesh(Mesh(allV, allF), min_component_fraction=-0.1)


def test_large_removal_warns():
    V, F = _cylinder()
    pieces = [V]
    faces = [F]
    for i in range(30):  # thirty small fragments, each < 1% of the vessel, 10% in total
        Vs, Fs = _cylinder(nu=4, nv=1, r=0.1, h=0.2, shift=(5 + i, 0, 0))
        faces.append(Fs + sum(len(p) for p in pieces))
        pieces.append(Vs)
    _, r = clean_mesh(Mesh(np.concatenate(pieces), np.concatenate(faces)))
    assert r.components_removed == 30 and r.removed_area_fraction > 0.05
    assert any("lower min_component_fraction" in w for w in r.warnings)


# ------------------------------------------------------------------ non-manifold


def test_bowtie_vertex_split_or_reported():
    V, F = _cylinder()
    # a second cylinder touching the first at one vertex (vertex 0 shared)
    V2, F2 = _cylinder(shift=(2.0, 0, 2.0))  # its bottom vertex at angle 180 lands on our top one
    top = V[6]
    V2[np.argmin(np.linalg.norm(V2 - top, axis=1))] = top  # exactly (sin(pi) is not 0)
    allV = np.concatenate([V, V2])
    allF = np.concatenate([F, F2 + len(V)])
    mesh, r = clean_mesh(Mesh(allV, allF, texcoords=_pos_texcoords(allV, allF)))
    assert r.duplicate_vertices_merged == 1
    assert r.non_manifold_vertices == 1 and r.vertices_added_by_split == 1
    assert len(mesh.vertices) == len(allV)
    assert r.components == 2 and len(r.kept_component_area_fractions) == 2
    _check_alignment(mesh)
    mesh2, r2 = clean_mesh(Mesh(allV, allF), split_nonmanifold=False)
    assert r2.non_manifold_vertices == 1 and r2.vertices_added_by_split == 0
    assert len(mesh2.vertices) == len(allV) - 1
    assert any("left as they are" in w for w in r2.warnings)


def test_non_manifold_edge_fin_is_split_not_deleted():
    V, F = _cylinder()
    # a fin: a big flap on an interior edge of the cylinder, sticking out radially
    a, b = F[0, 1], F[0, 2]
    tip = (V[a] + V[b]) / 2 * 3
    V2 = np.concatenate([V, tip[None]])
    flap = np.array([[b, a, len(V)]])
    mesh, r = clean_mesh(Mesh(V2, np.concatenate([F, flap])), min_component_fraction=0.0)
    assert r.non_manifold_edges == 1
    assert len(mesh.faces) == len(F) + 1  # nothing deleted
    assert r.vertices_added_by_split >= 1


# ------------------------------------------------------------------ orientation, boundary


def test_open_cylinder_inward_is_turned_outward_with_texcoords():
    V, F = _cylinder()
    Fin = F[:, [0, 2, 1]]
    mesh, r = clean_mesh(Mesh(V, Fin, texcoords=_pos_texcoords(V, Fin)))
    assert r.components_reversed_outward == 1 and r.faces_reoriented == len(F)
    assert (_radial_outward(mesh) > 0).all()
    _check_alignment(mesh)
    assert r.boundary_loops == 2 and r.boundary_edges == 2 * 16
    mesh_kept, r_kept = clean_mesh(Mesh(V, Fin), orient=False)
    assert r_kept.faces_reoriented == 0 and (_radial_outward(mesh_kept) < 0).all()


def test_separate_inner_wall_keeps_facing_the_axis():
    """Two walls as separate components (rim not scanned): the file's relative orientation
    is kept (the inner wall faces the axis), and a globally inverted file is turned over."""
    Vo, Fo = _cylinder()
    Vi, Fi = _cylinder(r=0.9)
    Fi = Fi[:, [0, 2, 1]]  # the inner wall's outside (of the material) faces the axis
    V = np.concatenate([Vo, Vi])
    F = np.concatenate([Fo, Fi + len(Vo)])
    for faces, reversed_ in ((F, 0), (F[:, [0, 2, 1]], 2)):
        mesh, r = clean_mesh(Mesh(V, faces, texcoords=_pos_texcoords(V, faces)))
        assert r.components_reversed_outward == reversed_
        radial = _radial_outward(mesh)
        outer = np.linalg.norm(mesh.vertices[mesh.faces].mean(1)[:, :2], axis=1) > 0.95
        assert (radial[outer] > 0).all() and (radial[~outer] < 0).all()
        _check_alignment(mesh)


def test_majority_orientation_of_the_file_is_kept():
    V, F = _cylinder()
    G = F.copy()
    G[:5] = G[:5, [0, 2, 1]]  # a few faces wound the wrong way: those are the ones fixed
    _, r = clean_mesh(Mesh(V, G))
    assert r.faces_reoriented == 5 and r.components_reversed_outward == 0


@pytest.mark.parametrize("table", [1.5, 4.0])
def test_a_cup_standing_on_a_table_keeps_its_outward_orientation(table):
    """A two-walled cup whose foot is joined to a table top around it (no base: the table
    hides it). The table pulls the faces' centroid below the cup, so the faces' flux about
    it comes out negative; closed over its open border the surface encloses the cup's body,
    a positive volume. The file's outward orientation is kept, and an inverted file turned."""
    import _vessel_meshes as vm

    V, F, L, _ = vm.cup(table=table)
    for faces, reversed_ in ((F, 0), (F[:, [0, 2, 1]], 1)):
        mesh, r = clean_mesh(Mesh(V, faces))
        assert r.components_reversed_outward == reversed_ and r.boundary_loops == 1
        radial = _radial_outward(mesh)
        assert (radial[L == "outer"] > 0).all() and (radial[L == "inner"] < 0).all()
        up = np.cross(*(mesh.vertices[mesh.faces[:, k]] - mesh.vertices[mesh.faces[:, 0]] for k in (1, 2)))[:, 2]
        assert (up[L == "table"] > 0).all()


def test_closed_sphere_outward_and_hole_counted():
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=2)
    V, F = sphere.vertices, sphere.faces[:, ::-1]  # all inward
    mesh, r = clean_mesh(Mesh(V, F))
    assert trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).volume > 0
    assert r.boundary_loops == 0 and r.components_reversed_outward == 1
    mesh, r = clean_mesh(Mesh(V, F[~(F == 0).any(axis=1)]))  # the fan around vertex 0 removed
    assert r.boundary_loops == 1 and r.boundary_edges == 5


def test_bowl_and_sherd_outward():
    """Open shapes: a hemisphere bowl and a 60 degree sherd of a cylinder wall."""
    th = np.linspace(0, np.pi / 2, 8)
    ph = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    T, P = np.meshgrid(th, ph, indexing="ij")
    V = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), -np.cos(T)], -1).reshape(-1, 3)
    idx = np.arange(len(V)).reshape(8, 24)
    a, b = idx[:-1], np.roll(idx, -1, axis=1)[:-1]
    c, d = np.roll(idx, -1, axis=1)[1:], idx[1:]
    F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    mesh, _ = clean_mesh(Mesh(V, F), min_component_fraction=0.0)
    W, G = mesh.vertices, mesh.faces
    n = np.cross(W[G[:, 1]] - W[G[:, 0]], W[G[:, 2]] - W[G[:, 0]])
    ok = np.linalg.norm(n, axis=1) > 1e-12
    assert (np.einsum("ij,ij->i", n, W[G].mean(1))[ok] > 0).all()  # away from the sphere centre
    Vc, Fc = _cylinder(nu=64, nv=4)
    sherd = np.all(np.arctan2(Vc[Fc, 1], Vc[Fc, 0]) % (2 * np.pi) < np.pi / 3 + 1e-9, axis=1)
    for faces in (Fc[sherd], Fc[sherd][:, [0, 2, 1]]):
        mesh, _ = clean_mesh(Mesh(Vc, faces))
        assert (_radial_outward(mesh) > 0).all()


def test_a_dish_face_scanned_alone_is_turned_to_its_convex_side_with_a_warning_unless_kept():
    """The face of a plate alone, facing up as scanned: closed by a cap over its rim it encloses
    the air above it, so it is turned to face down, the way its convex side faces, and the
    warning names the way out; ``outward=False`` keeps it as the file gives it."""
    import _vessel_meshes as vm

    V, F, _, _ = vm.dish()

    def up(mesh):  # each face's normal's z (the dish's axis), (m,)
        corner = mesh.vertices[mesh.faces]
        return np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0])[:, 2]

    turned, r = clean_mesh(Mesh(V, F))
    assert r.components_reversed_outward == 1 and (up(turned) < 0).all()
    assert any("--keep-orientation" in w for w in r.warnings)
    kept, r = clean_mesh(Mesh(V, F), outward=False)
    assert r.faces_reoriented == 0 and (up(kept) > 0).all()
    assert not any("--keep-orientation" in w for w in r.warnings)


# ------------------------------------------------------------------ errors and report


def test_all_degenerate_is_an_error():
    V = np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]], float)
    with pytest.raises(InvalidInputError, match="degenerate"):
        clean_mesh(Mesh(V, np.array([[0, 1, 2], [1, 2, 3]])))


def test_too_few_faces_is_an_error():
    V, F = _cylinder()
    with pytest.raises(InvalidInputError, match="at least 4"):
        clean_mesh(Mesh(V, F[:3]))


def test_report_as_dict_is_json():
    V, F = _cylinder()
    _, r = clean_mesh(Mesh(V, F))
    d = r.as_dict()
    assert json.loads(json.dumps(d)) == d
    assert d["output_faces"] == len(F) and d["cleaned"] is True
    assert set(d) == set(CleaningReport.__dataclass_fields__)
