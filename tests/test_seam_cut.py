"""The rollout's seam and a window's sides are cut exactly along their meridians: straight
sides at any resolution, the cut faces' pieces carrying what the scan carries."""
import numpy as np
import pytest
from _revolve import cone, cylinder, vase

from potflat.mesh.boundary import edges_and_boundary, outline_turning
from potflat.rollout import seam
from potflat.rollout.unroll import rollout


def _chain_turning(uv: np.ndarray, seg: np.ndarray) -> float:
    """Turning (over 2 pi) of a chain of boundary segments: the absolute exterior angles
    where one of them ends and the next begins."""
    start = {int(a): i for i, (a, _) in enumerate(seg)}
    d = uv[seg[:, 1]] - uv[seg[:, 0]]
    total = 0.0
    for i, (_, b) in enumerate(seg):
        j = start.get(int(b))
        if j is not None:
            total += abs(np.arctan2(d[i, 0] * d[j, 1] - d[i, 1] * d[j, 0], d[i] @ d[j]))
    return total / (2 * np.pi)


def _seam_sides(res) -> list[np.ndarray]:
    """The boundary segments of each side of the seam: both ends have a copy (the same 3D
    position) on the other side; left and right of the development's middle."""
    V, uv = res.flat.mesh.vertices, res.flat.uv
    _, seg, _ = edges_and_boundary(res.flat.mesh.faces, len(uv))
    _, inverse, counts = np.unique(V, axis=0, return_inverse=True, return_counts=True)
    twin = counts[inverse.ravel()] > 1
    cut = seg[twin[seg].all(axis=1)]
    middle = 0.5 * (uv[:, 0].min() + uv[:, 0].max())
    left = uv[cut, 0].mean(axis=1) < middle
    return [cut[left], cut[~left]]


@pytest.mark.parametrize("shape, proxy", [(cylinder, "cylinder"), (cone, "cone"), (vase, "sphere"), (vase, "auto")])
@pytest.mark.parametrize("n_theta, n_t", [(64, 24), (160, 60)])
def test_seam_sides_are_straight_at_any_resolution(shape, proxy, n_theta, n_t):
    mesh, *_ = shape(seed=4, n_theta=n_theta, n_t=n_t, jitter=0.35)
    res = rollout(mesh, proxy=proxy)
    assert res.region.cut and res.cut_vertices > 0 and res.distortion.flipped == 0
    sides = _seam_sides(res)
    for side in sides:
        assert len(side) >= n_t  # (each row of faces crosses the seam once)
        assert _chain_turning(res.flat.uv, side) < 0.05
    # the whole outline: four corners, the seam's sides straight, the foot and rim rows of
    # the scan (straight, or arcs turning by the sector's angle on a cone)
    sector = np.sin(np.radians(res.proxy.params["half_angle_deg"])) if res.proxy.kind == "cone" else 0.0
    assert outline_turning(res.flat.mesh.faces, res.flat.uv) < 1.0 + 2 * sector + 0.1


def test_overlap_repeats_an_exact_strip():
    mesh, *_ = cylinder(seed=2, n_theta=72, n_t=16, jitter=0.35)
    res = rollout(mesh, proxy="cylinder", overlap=40.0)
    R = res.proxy.params["radius"]
    u = res.flat.uv[:, 0] / R
    start = res.region.repeated_from
    assert start is not None and res.region.overlap_deg == 40.0
    # the repeat starts exactly at the seam and ends exactly 40 degrees past it
    rep = res.flat.mesh.faces[start:]
    assert np.isclose(u[rep].min(), 2 * np.pi, rtol=1e-12) and np.isclose(u.max(), 2 * np.pi + np.radians(40), rtol=1e-12)
    assert np.all(u[res.flat.mesh.faces[:start]].max(axis=1) <= 2 * np.pi * (1 + 1e-12))
    assert np.count_nonzero(np.isclose(u, 2 * np.pi + np.radians(40), rtol=1e-12)) >= 17
    # the repeated strip is the cylinder's first 40 degrees again (to the faceting)
    p = res.flat.mesh.vertices[rep]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    assert np.isclose(area, np.radians(40) * 30.0 * 80.0, rtol=1e-2)  # (its sides through vertices near them)


def test_pieces_carry_colours_and_untextured_flags(tmp_path):
    mesh, Rot, shift, local = cylinder(seed=3, n_theta=48, n_t=12, colors=True, jitter=0.35)
    res = rollout(mesh, proxy="cylinder")
    fm = res.flat.mesh
    scan = res.vertex_index >= 0
    np.testing.assert_array_equal(fm.vertex_colors[scan], mesh.vertex_colors[res.vertex_index[scan]])
    # an added vertex's colour lies between its edge's ends' (the scan faces of the faces it
    # belongs to name them, those of a vertex moved onto the cut among them)
    added = np.flatnonzero(~scan)
    assert len(added) == 2 * res.cut_vertices > 0
    for v in added[:10]:
        f = np.flatnonzero((fm.faces == v).any(axis=1))
        ends = mesh.vertex_colors[mesh.faces[res.face_index[f]]].reshape(-1, 4).astype(int)
        assert np.all(fm.vertex_colors[v] >= ends.min(axis=0)) and np.all(fm.vertex_colors[v] <= ends.max(axis=0))
    # flags of untextured faces follow every piece
    tc = np.zeros((len(mesh.faces), 3, 2))
    flags = np.zeros(len(mesh.faces), bool)
    flags[::3] = True
    tex = tmp_path / "t.png"
    import cv2

    cv2.imwrite(str(tex), np.full((8, 8, 3), 128, np.uint8))
    textured = rollout(mesh.replace(texcoords=tc, texture_path=tex, untextured_faces=flags, vertex_colors=None),
                       proxy="cylinder", importance="none")
    np.testing.assert_array_equal(textured.flat.mesh.untextured_faces, flags[textured.face_index])
    assert textured.cut_faces > 0 and flags[textured.face_index[np.bincount(textured.face_index)[
        textured.face_index] > 1]].any()


def test_among_is_isin_for_exact_values(monkeypatch):
    rng = np.random.default_rng(3)
    values = rng.choice(np.linspace(0.0, 1.0, 50), size=(1000, 3))
    values[::7, 1] += 1e-12  # (near a member, not one)
    members = np.unique(rng.choice(np.linspace(0.0, 1.0, 50), 20))
    monkeypatch.setattr(seam, "_AMONG_ROWS", 64)  # (many blocks, the last one short)
    assert np.array_equal(seam._among(values, members), np.isin(values, members))
    assert not seam._among(values, np.zeros(0)).any()
