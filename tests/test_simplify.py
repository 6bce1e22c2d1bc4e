"""Coarse copies of a rollout (potflat.relax.simplify) and relaxation from or at a coarse copy."""
from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from _bench_meshes import SPRINGS_ONLY, meshes, signed_areas

import potflat.relax.multilevel as relax_module
from potflat.relax import relax
from potflat.relax.parameters import ENERGY
from potflat.relax.simplify import cell_side, grid_simplification, interpolate
from potflat.types import FlatMesh, Mesh


@pytest.fixture(scope="module")
def vessel():
    """Big enough to start from a coarse copy (relax.COARSE.min_vertices)."""
    return meshes.vessel_rollout(30_000, seed=4)


def test_grid_simplification_clusters_and_blocks():
    # two points in each of the cells (0,0) (1,0) (2,0) (0,1) (1,1) of side 1
    uv = np.array([[0.0, 0.0], [0.7, 0.6], [1.2, 0.1], [1.5, 0.9], [2.5, 0.5], [2.2, 0.2],
                   [0.4, 1.5], [0.6, 1.2], [1.3, 1.3], [1.8, 1.7]])
    V = np.c_[uv, np.arange(len(uv)) * 0.1]
    s = grid_simplification(V, uv, 1.0)
    assert len(s.vertices) == 5
    for c in range(5):
        np.testing.assert_allclose(s.uv[c], uv[s.cluster == c].mean(0))
        np.testing.assert_allclose(s.vertices[c], V[s.cluster == c].mean(0))
    cell = [tuple(ij) for ij in np.floor(s.uv).astype(int)]
    tris = {frozenset(cell[v] for v in f) for f in s.faces}
    # the full block at (0,0) gives two triangles; the block at (1,0) has three cells: one
    assert tris == {frozenset({(0, 0), (1, 0), (1, 1)}), frozenset({(0, 0), (1, 1), (0, 1)}),
                    frozenset({(1, 0), (2, 0), (1, 1)})}
    assert np.all(signed_areas(s.uv, s.faces) > 0)


def test_grid_simplification_same_by_counting_and_by_sorting(vessel, monkeypatch):
    import potflat.relax.simplify as simplify

    V, uv = vessel.mesh.vertices, vessel.uv
    side = cell_side(uv, 8.0)
    assert simplify.grid_simplification is grid_simplification
    counted = grid_simplification(V, uv, side)  # the grid has about n / 8 cells: counted
    monkeypatch.setattr(simplify, "DENSE_GRID_CELLS_PER_VERTEX", 0)  # every grid sorted
    by_sort = grid_simplification(V, uv, side)
    for name in ("vertices", "faces", "uv", "cluster"):
        np.testing.assert_array_equal(getattr(counted, name), getattr(by_sort, name))
    assert len(counted.faces) > len(counted.vertices)


def test_cell_side_gives_the_asked_density():
    uv = np.random.default_rng(0).random((40_000, 2)) * [3.0, 1.0]
    s = grid_simplification(np.c_[uv, np.zeros(len(uv))], uv, cell_side(uv, 16.0))
    assert 14 < len(uv) / len(s.vertices) < 18


def test_interpolate_reproduces_affine_maps_exactly(vessel):
    V, uv = vessel.mesh.vertices, vessel.uv
    s = grid_simplification(V, uv, 8.0)
    A, t = np.array([[0.8, -0.3], [0.5, 1.1]]), np.array([3.0, -7.0])
    out, inside = interpolate(s, uv, s.uv @ A.T + t)
    assert 0.9 < inside.mean() < 1.0  # the copy's border is jagged: some vertices lie outside
    np.testing.assert_allclose(out, uv @ A.T + t, atol=1e-9 * np.ptp(uv))  # inside and out
    identity, _ = interpolate(s, uv, s.uv)
    np.testing.assert_array_equal(identity, uv)


def test_interpolate_matches_brute_force_location(vessel):
    V, uv = vessel.mesh.vertices, vessel.uv
    s = grid_simplification(V, uv, 12.0)
    target = s.uv + np.random.default_rng(1).normal(0, 2.0, s.uv.shape)  # any coarse layout
    out, inside = interpolate(s, uv, target)
    P = s.uv[s.faces]  # (mc, 3, 2)
    rng = np.random.default_rng(2)
    checked = 0
    for i in rng.choice(len(uv), 300, replace=False):
        d = P[:, 1:] - P[:, :1]  # (mc, 2, 2)
        det = d[:, 0, 0] * d[:, 1, 1] - d[:, 0, 1] * d[:, 1, 0]
        p = uv[i] - P[:, 0]
        lb = (p[:, 0] * d[:, 1, 1] - p[:, 1] * d[:, 1, 0]) / det
        lc = (d[:, 0, 0] * p[:, 1] - d[:, 0, 1] * p[:, 0]) / det
        bary = np.stack([1 - lb - lc, lb, lc], axis=1)
        inside_faces = np.nonzero(bary.min(1) >= 1e-9)[0]
        if len(inside_faces) != 1:
            continue  # outside the copy or on a shared edge
        f = inside_faces[0]
        assert inside[i]
        np.testing.assert_allclose(out[i], bary[f] @ target[s.faces[f]], atol=1e-9 * np.ptp(uv))
        checked += 1
    assert checked > 200


def test_standard_starts_from_a_coarse_copy(vessel, monkeypatch):
    nested = relax(vessel, preset="standard")
    monkeypatch.setattr(relax_module, "COARSE", dataclasses.replace(relax_module.COARSE, min_vertices=10**9))
    plain = relax(vessel, preset="standard")
    # the area term joins after a first solve without it, on the coarsest mesh solved
    assert [lv.level for lv in nested.levels] == ["coarse, shape first", "coarse", "fine"]
    assert [lv.level for lv in plain.levels] == ["fine, shape first", "fine"]
    assert nested.levels[0].vertices < len(vessel.uv) / 8
    for r in (nested, plain):
        assert r.converged and r.flipped == 0 and r.boundary_overlap == 0
    assert nested.distortion.edge_rms <= plain.distortion.edge_rms + 2e-3
    assert nested.levels[-1].iterations < plain.levels[-1].iterations


def test_only_the_image_s_own_border_holds_the_outline_term(vessel, monkeypatch):
    """A coarse copy that is only the full mesh's start is solved without the outline term
    (its simplified border is not the image's); preview's copy, followed as the result, and
    the full mesh keep it."""
    systems = []
    build = relax_module._spring_system

    def spy(V, *args):
        out = build(V, *args)
        systems.append((len(V), out[0]))
        return out

    monkeypatch.setattr(relax_module, "_spring_system", spy)
    relax(vessel, preset="standard")
    terms = {n: sp.outline_mu for n, sp in systems}
    assert len(terms) == 2 and terms[len(vessel.uv)] == ENERGY.outline_mu > 0
    assert terms[min(terms)] == 0.0
    systems.clear()
    relax(vessel, preset="preview", simplify_mm=6.0)
    assert min(n for n, _ in systems) < len(vessel.uv)
    assert all(sp.outline_mu == ENERGY.outline_mu for _, sp in systems)


def test_preview_follows_a_coarse_copy_and_scales_with_units(vessel):
    r = relax(vessel, preset="preview", simplify_mm=6.0)
    assert relax(vessel, preset="preview", simplify_mm=6.0, **SPRINGS_ONLY).distortion.edge_rms < (
        0.6 * r.distortion_before.edge_rms)
    assert [lv.level for lv in r.levels] == ["coarse, shape first", "coarse", "follow"]
    assert r.levels[0].vertices <= 0.7 * len(vessel.uv)
    assert r.flipped == 0 and r.boundary_overlap == 0 and np.all(signed_areas(r.flat.uv, vessel.mesh.faces) > 0)
    assert any("follows it" in note for note in r.notes)
    again = relax(vessel, preset="preview", simplify_mm=6.0, threads=1)
    np.testing.assert_array_equal(again.flat.uv, r.flat.uv)
    metres = FlatMesh(Mesh(vessel.mesh.vertices / 1000.0, vessel.mesh.faces, units="m"), vessel.uv / 1000.0)
    rm = relax(metres, preset="preview", simplify_mm=6.0)
    assert [lv.vertices for lv in rm.levels] == [lv.vertices for lv in r.levels]
    np.testing.assert_allclose(rm.flat.uv * 1000.0, r.flat.uv, rtol=0, atol=1e-7 * np.ptp(r.flat.uv))


@pytest.mark.parametrize("simplify_mm", [500.0, 1.0])
def test_a_copy_too_coarse_or_too_fine_is_not_followed(vessel, simplify_mm):
    # 500 mm: one cell, nothing to relax; 1 mm: cells smaller than the edges (about 2.6 mm),
    # most fine vertices outside the copy. Both relax the full mesh (from a 16-per-cell copy).
    r = relax(vessel, preset="preview", simplify_mm=simplify_mm)
    assert [lv.level for lv in r.levels] == ["coarse, shape first", "coarse", "fine"] and r.flipped == 0
