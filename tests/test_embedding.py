"""Fold-free starts (potflat.mesh.embedding): local repair of folded clusters, Tutte's
embedding, and the relax stage starting from them when untangling leaves folds."""
from __future__ import annotations

import numpy as np
import pytest

from _bench_meshes import meshes, signed_areas

from potflat.errors import FoldedResultError, NotADiskError
from potflat.mesh._kernels.topology import edge_table, incident_faces, vertex_faces
from potflat.mesh.embedding import (
    boundary_loops,
    fan_edges,
    neighbour_rows,
    repair_folds,
    tutte_embedding,
)
from potflat.relax import relax
from potflat.relax import multilevel


def _interior_vertex(faces, n):
    border = np.zeros(n, bool)
    for loop in boundary_loops(faces, n):
        border[loop] = True
    ring = np.zeros(n, bool)
    ring[faces[border[faces].any(axis=1)].ravel()] = True
    return int(np.flatnonzero(~ring)[len(np.flatnonzero(~ring)) // 2])


@pytest.mark.parametrize("seed", range(3))
def test_fan_edges_and_neighbour_rows_match_the_whole_mesh(seed):
    """Around a few vertices (border ones among them): every mesh edge with an end there, once,
    with the mesh's face count (1 on the boundary); and each vertex's neighbours, weight 1."""
    flat = meshes.vessel_rollout(600, seed=seed)
    F = np.ascontiguousarray(flat.mesh.faces, dtype=np.int64)
    n = len(flat.uv)
    _, all_edges, all_count, _ = edge_table(F, n)
    verts = np.unique(np.random.default_rng(seed).choice(n, 25, replace=False))
    verts = np.union1d(verts, boundary_loops(F, n)[0][:3])
    edges, count = fan_edges(np.unique(incident_faces(verts, *vertex_faces(n, F))), F)
    assert np.all(edges[:, 0] < edges[:, 1]) and len(np.unique(edges, axis=0)) == len(edges)
    assert np.all(np.diff(edges[:, 0] * n + edges[:, 1]) > 0)  # sorted
    mine = np.isin(all_edges, verts).any(axis=1)
    lookup = {tuple(e): c for e, c in zip(edges.tolist(), count, strict=True)}
    assert all(lookup.get(tuple(e)) == c for e, c in zip(all_edges[mine].tolist(), all_count[mine], strict=True))
    dense = np.zeros((n, n))
    dense[all_edges[:, 0], all_edges[:, 1]] = dense[all_edges[:, 1], all_edges[:, 0]] = 1.0
    rows = neighbour_rows(verts, edges, n)
    np.testing.assert_array_equal(rows.toarray(), dense[verts])
    assert np.all(np.diff(rows.indptr) > 0)
    shuffled = np.random.default_rng(seed).permutation(verts)  # (any order of the vertices)
    np.testing.assert_array_equal(neighbour_rows(shuffled, edges, n).toarray(), dense[shuffled])


@pytest.mark.parametrize("seed", range(3))
def test_solve_rows_matches_a_dense_solve(seed):
    """The free vertices of a small layout, in any order, placed by real rows (each the mean of
    its neighbours) and by complex ones (each face similar to its shape in a reference), as
    a dense solve of the same equations places them; the other vertices' rows name none."""
    from potflat.mesh.embedding import _similar_rows, _solve_rows

    rng = np.random.default_rng(seed)
    flat = meshes.vessel_rollout(300, seed=seed)
    F = np.ascontiguousarray(flat.mesh.faces, dtype=np.int64)
    n = len(flat.uv)
    vf_ptr, vf_tri = vertex_faces(n, F)
    free = rng.permutation(np.flatnonzero(rng.random(n) < 0.3))
    uv = flat.uv + rng.normal(scale=0.05, size=flat.uv.shape)
    edges = fan_edges(np.unique(incident_faces(free, vf_ptr, vf_tri)), F)[0]
    for rows in (neighbour_rows(free, edges, n), _similar_rows(free, flat.uv, F, vf_ptr, vf_tri, n)):
        w = rows.toarray()
        w /= w.sum(axis=1, keepdims=True)
        z = uv[:, 0] + 1j * uv[:, 1]
        others = np.setdiff1d(np.arange(n), free)
        want = np.linalg.solve(np.eye(len(free)) - w[:, free], w[:, others] @ z[others])
        got = _solve_rows(uv, free, rows)
        np.testing.assert_allclose(got[:, 0] + 1j * got[:, 1], want, rtol=0, atol=1e-9)


def test_signed_areas_refuses_swapped_or_out_of_range_arguments():
    """The kernel would read outside ``uv``: arguments in the wrong order (a (n, 2) layout
    read as faces), or a face naming a vertex the layout does not have, raise instead."""
    from potflat.mesh.embedding import signed_areas

    uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    np.testing.assert_allclose(signed_areas(faces, uv), [0.5, 0.5])
    with pytest.raises(ValueError, match="got"):
        signed_areas(uv, faces)
    with pytest.raises(ValueError, match="outside the 4 vertices"):
        signed_areas(faces + 1, uv)
    with pytest.raises(ValueError, match="outside the 4 vertices"):
        signed_areas(faces - 1, uv)
    assert len(signed_areas(np.zeros((0, 3), np.int64), uv)) == 0


def test_repair_folds_fixes_an_interior_fold_and_moves_nothing_far_away():
    flat = meshes.vessel_rollout(2000, seed=4)
    F, uv = flat.mesh.faces, flat.uv.copy()
    v = _interior_vertex(F, len(uv))
    nbr = np.unique(F[(F == v).any(axis=1)])
    uv[v] += 3.0 * (uv[nbr].mean(axis=0) - uv[v]) + 4.0 * (uv[nbr].max(axis=0) - uv[nbr].min(axis=0))
    assert (signed_areas(uv, F) <= 0).sum() >= 2
    fixed, repaired, left = repair_folds(F, uv)
    assert left == 0 and repaired >= 2 and np.all(signed_areas(fixed, F) > 0)
    far = np.linalg.norm(flat.uv - flat.uv[v], axis=1) > 20 * np.median(np.ptp(flat.uv[F], axis=1))
    np.testing.assert_array_equal(fixed[far], uv[far])
    assert repair_folds(F, flat.uv)[1:] == (0, 0)  # nothing to do on a clean layout


def test_repair_folds_with_a_reference_carries_its_image_over_exactly():
    """With a fold-free reference layout, a folded cluster at the border (boundary vertices
    included) inside a ring that is a similarity image of the reference is refilled with that
    image: mean value coordinates inside and similar faces along the border reproduce it (to
    rounding), whatever the triangles' shapes; without the reference the border stays folded."""
    flat = meshes.vessel_rollout(2000, seed=4)
    F, ref = flat.mesh.faces, flat.uv
    turn = 1.3 * np.array([[np.cos(0.7), np.sin(0.7)], [-np.sin(0.7), np.cos(0.7)]])
    image = ref @ turn + np.array([5.0, -2.0])
    loop = max(boundary_loops(F, len(ref)), key=len)
    uv = image.copy()
    for v in loop[len(loop) // 3:len(loop) // 3 + 3]:  # boundary vertices pushed in over their neighbours
        nbr = np.unique(F[(F == v).any(axis=1)])
        uv[v] += 4.0 * (image[nbr].mean(axis=0) - image[v])
    assert (signed_areas(uv, F) <= 0).sum() >= 2
    fixed, repaired, left = repair_folds(F, uv, reference=ref)
    assert left == 0 and repaired >= 2
    np.testing.assert_allclose(fixed, image, atol=1e-9 * np.ptp(image))
    assert repair_folds(F, uv)[2] > 0  # boundary vertices fixed without a reference


def test_repair_folds_with_a_reference_reproduces_an_affine_image_inside():
    """Away from the border, mean value coordinates carry any affine image over exactly."""
    flat = meshes.vessel_rollout(2000, seed=4)
    F, ref = flat.mesh.faces, flat.uv
    image = ref @ np.array([[1.3, 0.4], [-0.2, 0.7]]) + np.array([5.0, -2.0])  # shear: not a similarity
    v = _interior_vertex(F, len(ref))
    uv = image.copy()
    nbr = np.unique(F[(F == v).any(axis=1)])
    uv[v] += 3.0 * (image[nbr].mean(axis=0) - image[v]) + 4.0 * (image[nbr].max(axis=0) - image[nbr].min(axis=0))
    assert (signed_areas(uv, F) <= 0).sum() >= 2
    fixed, repaired, left = repair_folds(F, uv, reference=ref)
    assert left == 0 and repaired >= 2
    np.testing.assert_allclose(fixed, image, atol=1e-9 * np.ptp(image))


def test_tutte_embedding_is_fold_free_with_holes_and_several_parts():
    flat = meshes.vessel_rollout(2000, seed=5)
    F = flat.mesh.faces
    c = flat.uv[F].mean(axis=1)
    centre = np.median(c, axis=0)
    hole = np.linalg.norm(c - centre, axis=1) < 0.08 * np.ptp(flat.uv[:, 0])  # a hole in the middle
    part, _ = meshes.cylinder_patch(6, 5)
    both = np.concatenate([F[~hole], part.mesh.faces + len(flat.uv)])
    n = len(flat.uv) + len(part.uv)
    disc = tutte_embedding(both, n)
    assert disc is not None and np.all(signed_areas(disc, both) > 0)
    assert len(boundary_loops(F[~hole], len(flat.uv))) == 2
    tetra = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    assert tutte_embedding(tetra, 4) is None  # a closed surface has no flat layout


def test_relax_starts_fold_free_whatever_the_start(monkeypatch):
    """When untangling leaves folds, the relax stage re-embeds them or starts from Tutte's
    embedding; the relaxed result does not depend on the start (edge RMS and area within 2%)."""
    flat = meshes.vessel_rollout(3000, seed=1)
    clean = relax(flat)
    F, uv = flat.mesh.faces, flat.uv.copy()
    v = _interior_vertex(F, len(uv))
    nbr = np.unique(F[(F == v).any(axis=1)])
    uv[v] += 5.0 * (uv[nbr].max(axis=0) - uv[nbr].min(axis=0))
    monkeypatch.setattr(multilevel, "untangle", lambda sp, x, rounds=200: (x, int((sp.signed_areas(x) <= 0).sum())))
    local = relax(flat.replace(uv=uv))
    assert any("re-embedded" in note for note in local.notes)
    # a fold reaching the border: no local repair, Tutte's disc
    u = uv[:, 0]
    a, b = np.percentile(u, [40, 55])
    strip = (u > a) & (u < b)
    uv[strip, 0] = a + b - u[strip] + 0.3 * (u[strip] - a)
    disc = relax(flat.replace(uv=uv))
    assert any("Tutte" in note for note in disc.notes)
    for r in (local, disc):
        assert r.flipped == 0 and r.boundary_overlap == 0 and np.all(signed_areas(r.flat.uv, F) > 0)
        # (the area term's minimum is flat: Tutte's start ends 1.2% off in edge RMS, 1.1% in area)
        assert r.distortion.edge_rms == pytest.approx(clean.distortion.edge_rms, rel=0.02)
        assert r.distortion.area_mean_abs_log == pytest.approx(clean.distortion.area_mean_abs_log, rel=0.02)
        assert r.distortion.anisotropy_p95 == pytest.approx(clean.distortion.anisotropy_p95, rel=0.02)


def test_a_mesh_that_no_layout_unfolds_is_refused(monkeypatch):
    """(What to do is added by the relax stage's file layer from the rollout's record:
    tests/test_error_advice.py.)"""
    flat = meshes.vessel_rollout(1500, seed=2)
    monkeypatch.setattr(multilevel, "untangle", lambda sp, x, rounds=200: (x, 1))
    with pytest.raises(FoldedResultError, match="mirrored.*--side inner"):
        relax(flat.replace(uv=flat.uv * np.array([-1.0, 1.0])))  # every face flipped: seen from the wrong side
    monkeypatch.setattr("potflat.relax.start.tutte_embedding", lambda faces, n, scale=1.0: None)
    uv = flat.uv.copy()
    u = uv[:, 0]
    a, b = np.percentile(u, [40, 55])
    strip = (u > a) & (u < b)
    uv[strip, 0] = a + b - u[strip] + 0.3 * (u[strip] - a)
    with pytest.raises(NotADiskError, match="not a disk"):
        relax(flat.replace(uv=uv))


def test_a_result_relaxed_from_the_disc_keeps_the_rollouts_orientation(monkeypatch):
    """Mouth up: the layout relaxed from Tutte's disc is turned back to the rollout's
    orientation (the direction from the foot's vertices to the mouth's stays +v)."""
    flat = meshes.vessel_rollout(3000, seed=1)
    clean = relax(flat)
    uv = flat.uv.copy()
    u = uv[:, 0]
    a, b = np.percentile(u, [40, 55])
    strip = (u > a) & (u < b)
    uv[strip, 0] = a + b - u[strip] + 0.3 * (u[strip] - a)
    monkeypatch.setattr(multilevel, "untangle", lambda sp, x, rounds=200: (x, int((sp.signed_areas(x) <= 0).sum())))
    r = relax(flat.replace(uv=uv))
    assert any("Tutte" in note for note in r.notes)
    top = flat.mesh.vertices[:, 2] > np.percentile(flat.mesh.vertices[:, 2], 90)
    bottom = flat.mesh.vertices[:, 2] < np.percentile(flat.mesh.vertices[:, 2], 10)
    up = r.flat.uv[top].mean(axis=0) - r.flat.uv[bottom].mean(axis=0)
    want = clean.flat.uv[top].mean(axis=0) - clean.flat.uv[bottom].mean(axis=0)
    cos = up @ want / np.linalg.norm(up) / np.linalg.norm(want)
    assert cos > 0.999


def test_a_start_whose_border_crosses_itself_relaxes_into_what_it_is():
    """A flat strip laid round past a full turn (no face flipped, its ends overlapping: the
    border crosses itself) relaxes into the flat strip it is, as the rollout's note says."""
    from potflat.types import FlatMesh, Mesh

    nu, nv, length, width = 60, 6, 300.0, 25.0
    u, v = np.meshgrid(np.linspace(0, length, nu), np.linspace(0, width, nv), indexing="ij")
    V = np.column_stack([u.ravel(), v.ravel(), np.zeros(u.size)])
    idx = np.arange(nu * nv).reshape(nu, nv)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    phi = 2.3 * np.pi * V[:, 0] / length
    r = 40.0 + width - V[:, 1]
    start = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
    assert np.all(signed_areas(start, F) > 0)
    result = relax(FlatMesh(Mesh(V, F, units="mm"), start))
    assert result.flipped == 0 and result.boundary_overlap == 0
    assert result.distortion.edge_rms < 0.01
