import json

import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.csgraph
import trimesh
from _revolve import cone, cylinder, vase

from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.files.rollout_stage import run_rollout_stage
from potflat.io.flat_ply import read_flat_ply
from potflat.mesh.distortion import edge_length_error, face_distortion
from potflat.mesh.split import CUT_SNAP
from potflat.rollout.axis import _boundary_loops
from potflat.rollout.seam import cut_open
from potflat.rollout.unroll import RolloutOptions, rollout

#: The shared real scans (CI has ../shared beside the repository).


def _local(res, Rot, shift):
    """Local (unposed) coordinates of the output vertices, seen along the fitted axis.

    Returns theta (counter-clockwise about the fitted axis), height along it, radius; an
    open tube may be oriented either way, so local z and theta change sign with it.
    """
    p = (res.flat.mesh.vertices - shift) @ Rot
    s = np.sign(res.axis.direction @ Rot[:, 2])
    return s * np.arctan2(p[:, 1], p[:, 0]), s * p[:, 2], np.hypot(p[:, 0], p[:, 1])


def _local_angle(res, Rot, angle_deg):
    """Local angle (degrees, about local +z) of a direction given in degrees from the axis' reference."""
    a = np.radians(angle_deg)
    w = np.cos(a) * res.axis.reference + np.sin(a) * np.cross(res.axis.direction, res.axis.reference)
    loc = Rot.T @ w
    return np.degrees(np.arctan2(loc[1], loc[0])) % 360


def _euler(faces):
    e = np.unique(np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1), axis=0)
    return len(np.unique(faces)) - len(e) + len(faces)


def _areas(V, F):
    return 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)


def _wrap(x):
    return (x + np.pi) % (2 * np.pi) - np.pi


def _on_seam(res):
    """Output vertices on the seam's two sides (their development's angle is 0 or one turn)."""
    theta = res.flat.uv[:, 0] / res.proxy.params["radius"]
    return (np.abs(theta) < 1e-12) | (np.abs(theta - 2 * np.pi) < 1e-12)


def _edges(F):
    return np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)


def _edge_rms_off_seam(res):
    """The rollout's edge-length RMS over the edges not touching the seam (whose vertices may
    have moved onto its meridian by up to CUT_SNAP of an edge)."""
    e = _edges(res.flat.mesh.faces)
    e = e[~_on_seam(res)[e].any(axis=1)]
    return np.sqrt(np.mean(edge_length_error(res.flat.mesh.vertices, res.flat.uv, e) ** 2))


def test_posed_cylinder_unrolls_exactly():
    R0 = 30.0
    mesh, Rot, shift, _ = cylinder(R=R0, seed=7)
    res = rollout(mesh, proxy="cylinder")
    th, z, _ = _local(res, Rot, shift)
    uv = res.flat.uv
    assert np.isclose(res.proxy.params["radius"], R0, rtol=1e-12)
    # the flat point of every vertex is (R theta, h): v is the height, u / R the angle; the
    # seam is cut exactly along its meridian: its vertices lie on it (added on the edges
    # crossing it, or moved onto it by at most CUT_SNAP of an edge)
    np.testing.assert_allclose(uv[:, 1], z - z.min(), atol=1e-9)
    seam = _on_seam(res)
    assert seam.sum() >= 2 * 25  # (25 rows of vertices, each side)
    offset = _wrap(uv[:, 0] / R0 - th)
    ref = offset[np.flatnonzero(~seam)[0]]
    np.testing.assert_allclose(_wrap(offset[~seam] - ref), 0, atol=1e-10)
    step = 2 * np.pi / 64
    assert np.abs(_wrap(offset[seam] - ref)).max() < 1.5 * CUT_SNAP * step
    # the only distortion left is the faceting (chord vs arc), predicted edge by edge where
    # no end was moved onto the seam
    F = res.flat.mesh.faces
    e = _edges(F)
    dth = _wrap(th[e[:, 1]] - th[e[:, 0]])
    dz = z[e[:, 1]] - z[e[:, 0]]
    length = np.linalg.norm(res.flat.mesh.vertices[e[:, 1]] - res.flat.mesh.vertices[e[:, 0]], axis=1)
    predicted = np.hypot(R0 * dth, dz) / length - 1
    actual = np.linalg.norm(uv[e[:, 1]] - uv[e[:, 0]], axis=1) / length - 1
    exact = ~(seam[e[:, 0]] | seam[e[:, 1]])
    np.testing.assert_allclose(actual[exact], predicted[exact], atol=1e-9)
    d = res.distortion
    assert d.edge_rms < 0.02 and d.flipped == 0  # (the moves onto the seam)
    assert abs(d.scale - 1) < np.max(predicted) + 1e-3  # flat area = 3D area up to faceting


def test_cylinder_distortion_is_only_faceting():
    """Halving the angular step divides the rollout's edge error by about 4 (chord vs arc)
    away from the seam (where vertices may move onto its meridian by CUT_SNAP of an edge)."""
    coarse = rollout(cylinder(seed=1, n_theta=48, n_t=12)[0], proxy="cylinder")
    fine = rollout(cylinder(seed=1, n_theta=96, n_t=12)[0], proxy="cylinder")
    assert 3.0 < _edge_rms_off_seam(coarse) / _edge_rms_off_seam(fine) < 5.0
    assert fine.distortion.area_max_abs_log < 1e-3 and fine.distortion.flipped == 0


@pytest.mark.parametrize("r0,r1", [(40.0, 20.0), (20.0, 45.0)])
def test_posed_cone_unrolls_exactly(r0, r1):
    H = 60.0
    mesh, Rot, shift, local = cone(r0, r1, H, seed=8, cap=False)
    res = rollout(mesh, proxy="cone")
    p = res.proxy.params
    # every scan vertex keeps its exact distance from the apex, and the angle at the apex is
    # the angle about the axis times sin(alpha): the isometric development (the vertices
    # added on the seam lie on chords, inside the cone; the seam's own vertices are moved
    # onto its meridian by at most CUT_SNAP of an edge)
    apex_local = np.array([0, 0, -r0 * H / (r1 - r0)])
    th, z, _ = _local(res, Rot, shift)
    scan = res.vertex_index >= 0
    slant = np.linalg.norm(local[res.vertex_index[scan]] - apex_local, axis=1)
    mid = np.radians(p["bisector_deg"])
    apex_uv = np.array([p["reference_radius"] * mid, p["reference_height"] - p["reference_radius"] / p["generator"][1]])
    d = res.flat.uv - apex_uv
    np.testing.assert_allclose(np.linalg.norm(d[scan], axis=1), slant, rtol=1e-9)
    sin_a = abs(r1 - r0) / np.hypot(r1 - r0, H)
    assert np.isclose(np.sin(np.radians(p["half_angle_deg"])), sin_a, rtol=1e-9)
    ang = np.arctan2(d[:, 0], np.sign(p["generator"][1]) * d[:, 1])
    offset = _wrap(ang / sin_a - th)
    # the seam's sides are the two rays from the apex at the ends of the sector
    side = np.abs(np.abs(ang / sin_a) - np.pi) < 1e-9
    assert side.sum() >= 2 * 25
    np.testing.assert_allclose(_wrap(offset[~side] - offset[~side][0]), 0, atol=1e-9)
    assert res.distortion.flipped == 0 and res.distortion.edge_rms < 0.02


def test_no_face_is_lost_and_the_mesh_becomes_a_disk():
    mesh, *_ = vase(seed=2)
    res = rollout(mesh)
    fm = res.flat.mesh
    assert len(fm.faces) == res.region.faces
    np.testing.assert_array_equal(np.unique(res.face_index), np.arange(len(mesh.faces)))
    # the scan vertices the cut moved onto the meridian are gone from the output (an added
    # vertex on one of their edges took their place)
    moved = np.setdiff1d(np.arange(len(mesh.vertices)), res.vertex_index)
    assert len(moved) > 0
    # faces not cut are the same triangles with the same 3D corners; the pieces of a cut face
    # cover it exactly, and their new corners lie on its edges
    pieces = np.bincount(res.face_index) > 1
    reshaped = np.isin(mesh.faces, moved).any(axis=1)
    assert res.cut_faces == np.count_nonzero(pieces | reshaped) > pieces.sum() > 0
    whole = ~(pieces | reshaped)[res.face_index]
    np.testing.assert_array_equal(fm.vertices[fm.faces[whole]], mesh.vertices[mesh.faces[res.face_index[whole]]])
    exact = pieces & ~reshaped
    np.testing.assert_allclose(np.bincount(res.face_index, _areas(fm.vertices, fm.faces))[exact],
                               _areas(mesh.vertices, mesh.faces)[exact], rtol=1e-12)
    # the surface changes only where a vertex moved, by a small fraction of its faces
    np.testing.assert_allclose(_areas(fm.vertices, fm.faces).sum(), _areas(mesh.vertices, mesh.faces).sum(), rtol=1e-3)
    # the cut: one copy per seam vertex (at least one per row of the grid's 24 rows), the
    # added ones among them; a disk with one boundary
    assert 25 <= res.seam_vertices <= 50 and res.split_vertices == 0 and res.region.cut
    assert res.cut_vertices > 0 and np.count_nonzero(res.vertex_index < 0) == 2 * res.cut_vertices
    assert len(fm.vertices) == len(mesh.vertices) - len(moved) + res.seam_vertices + res.cut_vertices
    assert _euler(fm.faces) == 1
    assert len(_boundary_loops(fm)) == 1
    # the seam's vertices lie on its meridian on the surface too, and the two copies of each
    # are one turn apart: on the cone's development (a sector of angle 2 pi sin(half angle)),
    # at the same slant distance from the apex, the chord between the sector's two sides
    _, first, counts = np.unique(fm.vertices, axis=0, return_index=True, return_counts=True)
    twins = first[counts == 2]
    assert len(twins) == res.seam_vertices and res.proxy.kind == "cone"
    _, _, theta = res.axis.cylindrical(fm.vertices[twins])
    np.testing.assert_allclose(_wrap(theta - np.radians(res.seam_angle)), 0.0, atol=1e-9)
    half = np.radians(res.proxy.params["half_angle_deg"])
    x = fm.vertices[twins] - res.axis.point
    height = x @ res.axis.direction
    radius = np.linalg.norm(x - height[:, None] * res.axis.direction, axis=1)
    slant = (height - res.proxy.params["apex_height"]) * np.cos(half) + radius * np.sin(half)
    copies = np.array([np.flatnonzero((fm.vertices == fm.vertices[t]).all(axis=1)) for t in twins])
    apart = np.linalg.norm(res.flat.uv[copies[:, 0]] - res.flat.uv[copies[:, 1]], axis=1)
    np.testing.assert_allclose(apart, 2 * slant * np.sin(np.pi * np.sin(half)), rtol=1e-12)


def test_upright_and_not_mirrored():
    mesh, Rot, shift, local = vase(seed=3, cap=True)  # closed foot: mouth known to be +z local
    res = rollout(mesh, band=(0.03, 1.0), proxy="cylinder")
    th, z, _ = _local(res, Rot, shift)
    uv = res.flat.uv
    assert res.axis.direction @ Rot[:, 2] > 0.999
    assert np.corrcoef(uv[:, 1], z)[0, 1] > 0.999  # higher on the vessel = higher in the image
    F = res.flat.mesh.faces
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    dth = _wrap(th[e[:, 1]] - th[e[:, 0]])
    du = uv[e[:, 1], 0] - uv[e[:, 0], 0]
    # (edges to a vertex moved onto the seam's meridian, by at most CUT_SNAP of an edge, aside)
    big = (np.abs(dth) > 1e-3) & ~_on_seam(res)[e].any(axis=1)
    assert np.all(np.sign(du[big]) == np.sign(dth[big]))  # larger angle (CCW) = further right
    fd = face_distortion(res.flat.mesh.vertices, uv, F)
    assert np.all(fd.area_2d > 0)
    assert res.distortion.flipped == 0


def test_band_and_angles_cut_exactly():
    mesh, Rot, shift, local = cylinder(seed=5, n_theta=72)
    low, high = 0.27, 0.52  # (between the grid's rows of vertices)
    res = rollout(mesh, band=(low, high), angles=(-40.0, 70.0), seam=200.0, proxy="cylinder")
    c = local[mesh.faces].mean(axis=1)
    s = np.sign(res.axis.direction @ Rot[:, 2])
    to_seam = _local_angle(res, Rot, 200.0)
    rel = (s * (np.degrees(np.arctan2(c[:, 1], c[:, 0])) - to_seam) + 40.0) % 360.0 - 40.0
    corner = s * (np.degrees(np.arctan2(local[mesh.faces][..., 1], local[mesh.faces][..., 0])) - to_seam)
    corner = rel[:, None] + (corner - rel[:, None] + 180.0) % 360.0 - 180.0
    height = local[:, 2] / 80.0 if s > 0 else 1 - local[:, 2] / 80.0
    frac = height[mesh.faces]
    # the band and the angles by the faces' spans: cut along the band's planes and the window's sides
    meets = np.any([(corner.max(axis=1) + k > -40.0) & (corner.min(axis=1) + k < 70.0) for k in (-360, 0, 360)], axis=0)
    reach = (frac.max(axis=1) > low) & (frac.min(axis=1) < high) & meets
    centred = (frac.mean(axis=1) >= low) & (frac.mean(axis=1) <= high) & meets
    got = np.zeros(len(mesh.faces), bool)
    got[res.face_index] = True
    assert np.all(reach[got]) and np.all(got[centred]) and got.sum() > centred.sum()
    # every vertex within the band but for those the cut goes through (within CUT_SNAP of an
    # edge crossing a plane); the vertices it adds lie on the planes
    at = res.flat.mesh.vertices - shift
    flat_height = (at @ Rot[:, 2]) / 80.0
    flat_height = flat_height if s > 0 else 1 - flat_height
    rise = np.abs(np.diff(height[mesh.faces][:, [0, 1, 2, 0]], axis=1)).max()
    assert flat_height.min() >= low - CUT_SNAP * rise and flat_height.max() <= high + CUT_SNAP * rise
    for plane in (low, high):
        assert np.count_nonzero(np.abs(flat_height - plane) < 1e-9) >= 10
    assert res.cut_faces > 0 and not res.region.cut and res.seam_vertices == 0
    lo, hi = res.region.theta_range_deg
    assert np.isclose(lo, -40.0, atol=1e-9) and np.isclose(hi, 70.0, atol=1e-9)
    assert res.region.angles_deg == (-40.0, 70.0) and res.seam_method == "user"
    assert np.isclose(res.seam_angle, 200.0)
    # u = R * angle from the seam: the requested range maps to [-40, 70] degrees of arc, the
    # sides straight
    u = res.flat.uv[:, 0] / res.proxy.params["radius"]
    assert np.isclose(np.degrees(u.min()), -40.0, atol=1e-9) and np.isclose(np.degrees(u.max()), 70.0, atol=1e-9)
    for side in (u.min(), u.max()):
        assert np.count_nonzero(u == side) >= 8  # (8 rows of vertices in the band, each side)


def test_sherd_is_not_cut():
    mesh, *_ = vase(seed=4, theta_range=(0.5, 2.5))
    res = rollout(mesh)
    assert res.seam_method == "gap" and not res.region.cut and res.seam_vertices == 0
    assert len(res.flat.mesh.vertices) == len(mesh.vertices)
    assert _euler(res.flat.mesh.faces) == 1 and res.distortion.flipped == 0
    span = res.region.theta_range_deg[1] - res.region.theta_range_deg[0]
    assert np.isclose(span, np.degrees(2.0), atol=1.0)


def test_user_seam_across_a_sherd_does_not_cut_it():
    mesh, Rot, _, _ = cylinder(seed=4, theta_range=(0.5, 2.5))
    first = rollout(mesh)
    mid = (first.seam_angle + 180.0) % 360.0  # through the middle of the sherd
    res = rollout(mesh, seam=mid)
    assert res.seam_vertices == 0 and _euler(res.flat.mesh.faces) == 1
    lo, hi = res.region.theta_range_deg
    assert lo < 0 < hi  # angles measured from the seam, on both sides of it


def test_holes_stay_holes():
    holes = [(1.0, 1.6, 0.3, 0.6), (4.0, 4.3, 0.1, 0.9)]
    mesh, Rot, _, _ = cylinder(seed=6, holes=holes)
    res = rollout(mesh)
    assert len(np.unique(res.face_index)) == len(mesh.faces)
    assert res.distortion.flipped == 0 and res.proxy.kind == "cylinder"
    # the automatic seam runs through the long hole (least to cut): one hole is left inside
    assert 4.0 < np.radians(_local_angle(res, Rot, res.seam_angle)) < 4.3
    assert _euler(res.flat.mesh.faces) == 0
    # a seam away from both holes keeps both as holes
    turn = np.degrees(2.8) - _local_angle(res, Rot, res.seam_angle)  # to local angle 2.8 rad
    kept = rollout(mesh, seam=(res.seam_angle + np.sign(res.axis.direction @ Rot[:, 2]) * turn) % 360)
    assert np.isclose(np.radians(_local_angle(kept, Rot, kept.seam_angle)), 2.8)
    assert _euler(kept.flat.mesh.faces) == 1 - len(holes)
    assert len(_boundary_loops(kept.flat.mesh)) == 1 + len(holes)


def test_seam_goes_where_the_painting_is_plain():
    mesh, Rot, shift, local = cylinder(seed=9, n_theta=90)
    th = np.arctan2(local[:, 1], local[:, 0]) % (2 * np.pi)
    rng = np.random.default_rng(0)
    colors = rng.integers(0, 255, (len(th), 3))
    plain = (th > np.radians(100)) & (th < np.radians(150))
    colors[plain] = 128
    res = rollout(mesh.replace(vertex_colors=colors))
    assert res.seam_method == "colours"
    assert 105 < _local_angle(res, Rot, res.seam_angle) < 145


def test_seam_from_the_texture(tmp_path):
    import cv2

    mesh, Rot, shift, local = cylinder(seed=9, n_theta=90)
    th = np.arctan2(local[:, 1], local[:, 0]) % (2 * np.pi)
    tc = np.stack([th / (2 * np.pi), local[:, 2] / 80.0], axis=1)[mesh.faces]
    # seam faces (spanning 0/2pi) get consistent texture u
    tc[..., 0] = np.where(tc[..., 0].max(axis=1, keepdims=True) - tc[..., 0] > 0.5, tc[..., 0] + 1, tc[..., 0]) % 1.0
    img = np.random.default_rng(1).integers(0, 255, (256, 1024, 3), dtype=np.uint8)
    img[:, int(1024 * 200 / 360):int(1024 * 250 / 360)] = 90
    tex = tmp_path / "atlas.png"
    cv2.imwrite(str(tex), img)
    res = rollout(mesh.replace(texcoords=tc, texture_path=tex))
    assert res.seam_method == "texture"
    assert 203 < _local_angle(res, Rot, res.seam_angle) < 247
    # faces not cut keep their texture coordinates; a piece's corner has its face's texture
    # map at the corner's place (barycentric coordinates in the face)
    fm = res.flat.mesh
    cut = np.bincount(res.face_index)[res.face_index] > 1
    np.testing.assert_array_equal(fm.texcoords[~cut], tc[res.face_index[~cut]])
    tri = mesh.vertices[mesh.faces[res.face_index[cut]]]
    p = fm.vertices[fm.faces[cut]]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    d = p - tri[:, None, 0]
    g = np.stack([np.einsum("ij,ij->i", e1, e1), np.einsum("ij,ij->i", e1, e2), np.einsum("ij,ij->i", e2, e2)], axis=1)
    r1, r2 = np.einsum("ikj,ij->ik", d, e1), np.einsum("ikj,ij->ik", d, e2)
    det = g[:, 0] * g[:, 2] - g[:, 1] ** 2
    b1 = (g[:, 2, None] * r1 - g[:, 1, None] * r2) / det[:, None]
    b2 = (g[:, 0, None] * r2 - g[:, 1, None] * r1) / det[:, None]
    t = tc[res.face_index[cut]]
    want = t[:, None, 0] + b1[..., None] * (t[:, None, 1] - t[:, None, 0]) + b2[..., None] * (t[:, None, 2] - t[:, None, 0])
    np.testing.assert_allclose(fm.texcoords[cut], want, atol=1e-12)


def test_ortho_cutout_is_seen_face_on():
    mesh, Rot, shift, local = cylinder(seed=2)
    res = rollout(mesh, proxy="ortho", angles=(-30.0, 30.0), band=(0.2, 0.8), seam=90.0)
    assert res.proxy.kind == "ortho" and res.seam_vertices == 0
    assert res.distortion.flipped == 0 and res.distortion.scale < 1.0
    other = np.cross(res.axis.direction, res.axis.reference)
    centre = np.cos(np.pi / 2) * res.axis.reference + np.sin(np.pi / 2) * other
    assert np.asarray(res.proxy.params["view"]) @ centre > 0.99
    custom = rollout(mesh, proxy="ortho", angles=(-30.0, 30.0), seam=90.0, view=tuple(2 * centre))
    np.testing.assert_allclose(custom.proxy.params["view"], centre, atol=1e-12)


def test_manual_axis_option():
    mesh, Rot, shift, _ = cone(seed=1)
    res = rollout(mesh, axis=(*shift, *(-Rot[:, 2])), flip=True)
    assert res.axis.method == "manual"
    np.testing.assert_allclose(res.axis.direction, Rot[:, 2], atol=1e-12)
    assert res.proxy.kind == "cone" and res.distortion.edge_rms < 0.02


def test_rollout_is_deterministic():
    mesh, *_ = vase(seed=11)
    a, b = rollout(mesh), rollout(mesh)
    assert np.array_equal(a.flat.uv, b.flat.uv) and np.array_equal(a.flat.mesh.faces, b.flat.mesh.faces)


def test_cut_open_splits_only_disagreeing_corners():
    # two triangles sharing edge (1, 2); vertex 1 seen one turn apart by the two faces
    faces = np.array([[0, 1, 2], [2, 1, 3]])
    theta = np.array([[0.1, 0.2, 0.15], [0.15, 0.2 + 2 * np.pi, 0.3]])
    new_faces, vidx, th, seam, split = cut_open(faces, theta)
    assert seam == 1 and split == 0 and len(vidx) == 5
    np.testing.assert_array_equal(vidx, [0, 1, 1, 2, 3])
    assert new_faces[0, 1] != new_faces[1, 1] and new_faces[0, 2] == new_faces[1, 0]
    # a bow-tie vertex (two fans touching at vertex 0) becomes one vertex per fan
    bow = np.array([[0, 1, 2], [0, 3, 4]])
    _, vidx, _, seam, split = cut_open(bow, np.zeros((2, 3)))
    assert seam == 0 and split == 1 and len(vidx) == 6


def _cut_open_by_sorting(faces, corner_theta):
    """cut_open as it was before the edge table's counting sort: half-edges sorted by
    (lower vertex, higher vertex, turn at the lower vertex, id) with NumPy (the reference)."""
    m = len(faces)
    corner_v, th = faces.ravel(), corner_theta.ravel()
    nxt = faces[:, [1, 2, 0]].ravel()
    swap = corner_v > nxt
    n = int(corner_v.max()) + 1
    lower = np.arange(3 * m)
    lower[swap] = lower[swap] - lower[swap] % 3 + (lower[swap] + 1) % 3
    turn = np.clip(np.floor(th[lower] / (2 * np.pi) + 0.5), -4, 3).astype(np.int64) + 4
    key = (np.minimum(corner_v, nxt) * n + np.maximum(corner_v, nxt)) * 8 + turn
    order = np.argsort(key, kind="stable")
    key = key[order] // 8
    pair = np.flatnonzero(key[1:] == key[:-1])
    h1, h2 = order[pair], order[pair + 1]

    def ends(h):
        nh = h - h % 3 + (h + 1) % 3
        return np.where(swap[h], nh, h), np.where(swap[h], h, nh)

    (lo1, hi1), (lo2, hi2) = ends(h1), ends(h2)
    a, b = np.concatenate([lo1, hi1]), np.concatenate([lo2, hi2])
    ok = np.abs(th[a] - th[b]) < np.pi
    graph = scipy.sparse.coo_matrix((np.ones(int(ok.sum())), (a[ok], b[ok])), shape=(3 * m, 3 * m))
    n_comp, labels = scipy.sparse.csgraph.connected_components(graph, directed=False)
    by_label = np.argsort(labels, kind="stable")
    first = by_label[np.searchsorted(labels[by_label], np.arange(n_comp))]
    vertex_of = corner_v[first]
    perm = np.lexsort((first, vertex_of))
    rank = np.empty(n_comp, np.int64)
    rank[perm] = np.arange(n_comp)
    vertex_index, theta = vertex_of[perm], th[first][perm]
    base = np.count_nonzero(np.bincount(corner_v))
    turns = np.floor(theta / (2 * np.pi) + 0.5).astype(np.int64)
    o = np.lexsort((turns, vertex_index))
    seam = 1 + np.count_nonzero((np.diff(vertex_index[o]) != 0) | (np.diff(turns[o]) != 0)) - base
    return rank[labels].reshape(m, 3), vertex_index, theta, int(seam), int(n_comp - base - seam)


@pytest.mark.parametrize("seed", range(6))
def test_cut_open_matches_the_sorting_reference(seed):
    """Random meshes with non-manifold edges, repeated faces (an overlap past 360 degrees)
    and angles a turn or more apart: the same outputs, bit for bit, as the sorting version."""
    rng = np.random.default_rng(seed)
    faces = rng.integers(0, 30, size=(200, 3))
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    faces = np.concatenate([faces, faces[:40]])  # listed twice, one turn on
    theta = rng.uniform(-0.5, 1.0, size=faces.shape) * (2 * np.pi if seed % 2 else 0.3)
    theta[-40:] += 2 * np.pi
    got, want = cut_open(faces, theta), _cut_open_by_sorting(faces, theta)
    assert got[3] + got[4] > 0  # cuts and splits happened
    for g, w in zip(got, want):
        assert np.asarray(g).dtype == np.asarray(w).dtype and np.array_equal(g, w)


def _lattice_texels(tc, faces, img, steps):
    """Slow reference: the grey levels at each face's barycentric lattice points, (k, m)."""
    pts = [(a, b, steps - a - b) for a in range(steps + 1) for b in range(steps + 1 - a)]
    out = np.empty((len(faces), len(pts)), dtype=np.int64)
    h, w = img.shape
    for i, f in enumerate(faces):
        for j, (a, b, c) in enumerate(pts):
            u, v = (a * tc[f, 0] + b * tc[f, 1] + c * tc[f, 2]) / steps
            out[i, j] = img[min(int((1.0 - v % 1.0) * h), h - 1), min(int((u % 1.0) * w), w - 1)]
    return out


@pytest.mark.parametrize("shape,steps", [((64, 48), 4), ((7, 5), 1), ((1, 1), 3)])
def test_texel_histogram_and_far_share_match_a_slow_reference(shape, steps):
    """The seam's samples per face (lattice points, coordinates wrapped, also outside [0, 1]):
    the weighted histogram of each group of faces and the share far from each face's level,
    against a Python loop."""
    from potflat.mesh._kernels.geometry import texel_far_share, texel_histogram

    rng = np.random.default_rng(len(shape) + shape[0])
    img = rng.integers(0, 256, size=shape, dtype=np.uint8)
    tc = rng.uniform(-2.0, 3.0, size=(300, 3, 2))
    tc[:30] = np.round(tc[:30])  # corners exactly on a texel border, v = 0 and 1 included
    faces = rng.permutation(300)[:200]
    weights = rng.uniform(0.5, 2.0, size=200)
    group = rng.integers(0, 3, size=200)
    want = _lattice_texels(tc, faces, img, steps)
    hist = np.zeros((4, 256))  # (the last group has no face)
    for i in range(len(faces)):
        for g in want[i]:
            hist[group[i], g] += weights[i] / want.shape[1]
    np.testing.assert_allclose(texel_histogram(tc, faces, img, weights, steps, group, 4), hist, rtol=1e-12)
    for level, contrast in ((128, 30), (0, 0), (255, 254)):
        share = texel_far_share(tc, faces, img, np.full(len(faces), level), contrast, steps)
        assert share.tobytes() == (np.abs(want - level) > contrast).mean(axis=1).tobytes()
    levels = rng.integers(0, 256, size=len(faces))
    share = texel_far_share(tc, faces, img, levels, 30, steps)
    assert share.tobytes() == (np.abs(want - levels[:, None]) > 30).mean(axis=1).tobytes()
    assert shape == (1, 1) or 0.2 < texel_far_share(tc, faces, img, np.full(len(faces), 128), 30, steps).mean() < 0.9


def test_the_ground_is_the_grey_with_the_most_area_near_it_in_each_band():
    """A light ground spread over many levels by the shading outweighs a dark paint of less
    area on a few; a band without samples takes the whole region's ground."""
    from potflat.rollout.seam import INK_CONTRAST, _ground_levels, _height_bands

    hist = np.zeros((3, 256))
    hist[0, 150:190] = 1.0  # 40 area over 40 levels ...
    hist[0, 20:24] = 7.5  # ... against 30 on 4: the peak is the paint's, the ground the clay's
    hist[1, 20:24] = 7.5  # a band of glaze alone
    levels = _ground_levels(hist)
    assert 150 <= levels[0] < 190 and abs(levels[1] - 21.5) <= INK_CONTRAST
    assert levels[2] == _ground_levels(hist[:2].sum(axis=0, keepdims=True))[0]  # empty: the whole region's
    bands = _height_bands(np.array([5.0, 5.5, 7.0, 9.0]))
    assert bands[0] == 0 and bands[-1] == 31 and np.all(np.diff(bands) >= 0)
    assert not _height_bands(np.full(4, 3.0)).any()  # no height: one band


@pytest.mark.parametrize("half, buckets", [(np.radians(2.5), 1024), (1.2, 8), (1e-4, 64)])
def test_angular_window_sums_match_a_slow_reference(half, buckets):
    """The seam's window sums: every angle within half of a centre, circularly (across 0
    and 2 pi), whatever the buckets that speed it up."""
    from potflat.mesh._kernels.geometry import angular_window_sums

    rng = np.random.default_rng(buckets)
    theta = rng.uniform(0.0, 2 * np.pi, 2000)
    theta[:20] = [0.0, 2 * np.pi - 1e-12] * 10
    weight = rng.uniform(0.0, 1.0, 2000)
    centres = np.concatenate([rng.uniform(0.0, 2 * np.pi, 300), theta[:40], [0.0, np.pi]])
    want = [weight[np.abs((theta - c + np.pi) % (2 * np.pi) - np.pi) <= half].sum() for c in centres]
    np.testing.assert_allclose(angular_window_sums(theta, weight, centres, half, buckets), want, rtol=1e-12, atol=1e-12)


def test_the_least_painted_window_moves_with_the_angles_origin():
    """The seam's window is chosen at the faces' own angles: counting the angles from another
    origin (another pose) moves the choice by exactly that much, and a plain sector wider
    than the window gets the seam in its middle."""
    from potflat.rollout.seam import _least_window

    rng = np.random.default_rng(5)
    theta = rng.uniform(0.0, 2 * np.pi, 20000)
    weight = rng.uniform(0.5, 1.5, 20000)
    plain = np.abs((theta - 4.0 + np.pi) % (2 * np.pi) - np.pi) < np.radians(6.0)
    weight[plain] = 0.0
    angle = _least_window(theta, weight)
    assert abs(angle - 4.0) < np.radians(0.1)
    for shift in (0.3, 2.9, 5.5):
        moved = _least_window((theta + shift) % (2 * np.pi), weight)
        assert abs((moved - angle - shift + np.pi) % (2 * np.pi) - np.pi) < 1e-9
    noisy = rng.uniform(0.5, 1.5, 20000)  # no plain sector: one least window among many near it
    angle = _least_window(theta, noisy)
    for shift in (0.3, 2.9, 5.5):
        moved = _least_window((theta + shift) % (2 * np.pi), noisy)
        assert abs((moved - angle - shift + np.pi) % (2 * np.pi) - np.pi) < 1e-9


@pytest.mark.parametrize("vertices_deg, angle_deg, want_deg", [
    ([0.0, 10.0, 20.0], 10.2, 10.7),  # near a vertex: to the window's end, the farthest from it
    ([9.9, 10.1, 10.3, 13.0], 10.2, 10.7),  # the wide gap beyond the close vertices
    ([359.8, 0.1, 5.0], 0.0, 0.5),  # across 0
    ([100.0], 0.0, 359.5),  # no vertex near: anywhere in the window, room on both sides
])
def test_the_seam_keeps_away_from_vertices_within_its_window(vertices_deg, angle_deg, want_deg):
    """A seam through a vertex puts it on the cut or not by the last bits of its angle (a
    pose's rounding): the seam moves, by at most SEAM_SNAP_DEG, to where its nearest vertex
    angle is farthest."""
    from potflat.rollout.seam import SEAM_SNAP_DEG, _snap_to_gap

    assert SEAM_SNAP_DEG == 0.5
    got = _snap_to_gap(np.radians(vertices_deg), np.radians(angle_deg), np.radians(SEAM_SNAP_DEG))
    assert np.degrees(got) == pytest.approx(want_deg, abs=1e-9)


def test_the_seam_goes_between_black_figures_not_through_one(tmp_path):
    """Black-figure painting: two solid figures wider than the plain gaps between columns of
    thin lines. The figures' insides are as even as the plain ground, and the lines blur
    into an even grey in a reduced texture: only the share of samples that are painted, at
    the texture's detail, puts the seam in a plain gap."""
    import cv2

    mesh, Rot, shift, local = cylinder(seed=9, n_theta=180)
    th = np.arctan2(local[:, 1], local[:, 0]) % (2 * np.pi)
    tc = np.stack([th / (2 * np.pi), local[:, 2] / 80.0], axis=1)[mesh.faces]
    tc[..., 0] = np.where(tc[..., 0].max(axis=1, keepdims=True) - tc[..., 0] > 0.5, tc[..., 0] + 1, tc[..., 0]) % 1.0
    img = np.full((256, 1440, 3), 170, dtype=np.uint8)  # the clay ground, 4 px per degree
    for lo in (20, 200):  # the figures, 60 degrees each
        img[40:216, 4 * lo:4 * (lo + 60)] = 25
    for lo in (110, 160, 290, 330):  # ornament columns, 16 degrees of thin lines
        img[:, 4 * lo:4 * (lo + 16):8] = 25
    tex = tmp_path / "black_figure.png"
    cv2.imwrite(str(tex), img)
    res = rollout(mesh.replace(texcoords=tc, texture_path=tex))
    angle = _local_angle(res, Rot, res.seam_angle)
    assert res.seam_method == "texture"
    assert not any(lo - 2 < angle < lo + 62 for lo in (20, 200)), angle
    assert any(lo + 2 < angle < hi - 2 for lo, hi in ((80, 110), (126, 160), (176, 200), (260, 290), (306, 330))), angle


def test_the_seam_goes_between_black_figures_on_a_belt_of_a_glazed_vessel(tmp_path):
    """Black figures on a terracotta belt, black glaze above and below it (a black-figure
    frieze): the figures are as dark as the glaze that covers most of the vessel, yet they
    are painting on the belt's ground, so the seam goes through the terracotta between two
    figures, not through one."""
    import cv2

    mesh, Rot, shift, local = cylinder(seed=9, n_theta=180)
    th = np.arctan2(local[:, 1], local[:, 0]) % (2 * np.pi)
    tc = np.stack([th / (2 * np.pi), local[:, 2] / 80.0], axis=1)[mesh.faces]
    tc[..., 0] = np.where(tc[..., 0].max(axis=1, keepdims=True) - tc[..., 0] > 0.5, tc[..., 0] + 1, tc[..., 0]) % 1.0
    img = np.full((256, 1440, 3), 25, dtype=np.uint8)  # the glaze, 4 px per degree
    img[96:160] = 120  # the belt's terracotta, 30 to 50 mm up
    for k, lo in enumerate(range(0, 360, 45)):  # figures of 25 degrees, black and cream in turn
        img[104:152, 4 * lo:4 * (lo + 25)] = 25 if k % 2 == 0 else 215
    tex = tmp_path / "belt.png"
    cv2.imwrite(str(tex), img)
    res = rollout(mesh.replace(texcoords=tc, texture_path=tex))
    angle = _local_angle(res, Rot, res.seam_angle)
    assert res.seam_method == "texture"
    assert any(lo + 25 + 2 < angle < lo + 45 - 2 for lo in range(0, 360, 45)), angle


@pytest.mark.parametrize("kwargs,match", [
    ({"units": "furlong"}, "units"),
    ({"proxy": "cyl"}, "proxy"),
    ({"axis": (0, 0, 0, 1)}, "6 finite"),
    ({"axis": (0, 0, 0, 0, 0, 0)}, "zero"),
    ({"axis": (0, 0, 0, 0, 0, float("nan"))}, "6 finite"),
    ({"seam": float("inf")}, "seam"),
    ({"seam": "north"}, "seam"),
    ({"band": (0.6, 0.2)}, "band"),
    ({"band": (-0.1, 0.5)}, "band"),
    ({"band": (0.1,)}, "band"),
    ({"angles": (60, -60)}, "angles"),
    ({"angles": (0, 400)}, "angles"),
    ({"view": (0, 0, 0), "proxy": "ortho"}, "zero"),
    ({"view": (1, 0, 0)}, "ortho"),
    ({"view": (1, 0), "proxy": "ortho"}, "view"),
])
def test_options_are_validated(kwargs, match):
    with pytest.raises(InvalidOptionError, match=match):
        RolloutOptions(**kwargs)


def test_options_or_keywords_not_both_and_empty_region():
    mesh, *_ = cylinder()
    with pytest.raises(InvalidOptionError, match="not both"):
        rollout(mesh, options=RolloutOptions(), proxy="cone")
    with pytest.raises(InvalidOptionError, match="select no faces"):
        rollout(mesh, angles=(0.0, 1e-6), band=(0.0, 1e-6))


def test_options_as_dict_round_trip():
    opts = RolloutOptions(proxy="cone", axis=(0, 0, 0, 0, 0, 1), band=(0.1, 0.9), seam=10)
    d = opts.as_dict()
    assert d["axis"] == [0, 0, 0, 0, 0, 1] and d["band"] == [0.1, 0.9] and d["seam"] == 10.0
    assert RolloutOptions(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}) == opts


def test_run_rollout_stage_writes_ply_and_json(tmp_path):
    mesh, *_ = vase(seed=1, colors=True)
    scan = tmp_path / "pot.ply"
    trimesh.Trimesh(mesh.vertices, mesh.faces, vertex_colors=mesh.vertex_colors, process=False).export(scan)
    out = run_rollout_stage(scan, tmp_path / "out", RolloutOptions(band=(0.1, 0.9)))
    ply, js = out.paths["ply"], out.paths["json"]
    assert ply == tmp_path / "out" / "pot.rollout.ply" and js.name == "pot.rollout.json"
    data = json.loads(js.read_text())
    assert data == json.loads(json.dumps(out.record))
    for key in ("axis", "proxy", "seam", "region", "units", "counts", "cleaning", "distortion", "provenance"):
        assert key in data
    assert np.isclose(np.linalg.norm(data["axis"]["direction"]), 1.0)
    assert data["region"]["band"] == [0.1, 0.9] and data["units"] == "mm"
    assert data["provenance"]["options"]["band"] == [0.1, 0.9]
    flat = read_flat_ply(ply)
    assert len(flat.mesh.faces) == data["counts"]["faces"]
    assert len(flat.mesh.vertices) == data["counts"]["vertices"]
    assert flat.mesh.vertex_colors is not None
    d = face_distortion(flat.mesh.vertices, flat.uv, flat.mesh.faces)
    assert np.count_nonzero(d.area_2d <= 0) == data["distortion"]["flipped"]
    assert not list((tmp_path / "out").glob("*.part"))


def test_run_rollout_stage_refuses_to_overwrite_its_input(tmp_path):
    mesh, *_ = cylinder()
    scan = tmp_path / "pot.rollout.ply"
    trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).export(scan)
    before = scan.read_bytes()
    with pytest.raises(InvalidOptionError, match="overwrite the input"):
        run_rollout_stage(scan, tmp_path, name="pot")
    assert scan.read_bytes() == before
    with pytest.raises(InvalidOptionError, match="plain file name"):
        run_rollout_stage(scan, tmp_path, name="a/b")


def test_real_goblet_band_rolls_out(tmp_path, real_scans):
    out = run_rollout_stage(real_scans / "goblet.stl", tmp_path)
    s = out.record
    # the goblet is a closed shell: its outer wall is unrolled, less the foot's underside (which
    # faces along the axis: a disc of its own) and any border faces that fold over, cut off the
    # inner wall along a smoothed line (which takes some faces over from each side)
    assert s["walls"]["two_walled"] and s["walls"]["faces_inner"] > 0
    assert s["base"]["left_out"] and s["base"]["faces_in_disc"] > 0 and s["base"]["faces_in_neither"] == 0
    line = s["walls"]["line"]
    assert line["faces_split"] > 0
    assert (s["counts"]["input_faces_unrolled"] + s["trimmed"]["faces"] + s["base"]["faces_in_disc"]
            == s["walls"]["faces_selected"] + line["faces_added"] - line["faces_dropped"])
    assert s["trimmed"]["faces"] < 0.02 * s["counts"]["faces"]
    assert s["distortion"]["flipped"] == 0 and s["boundary_overlap"] == 0
    assert s["axis"]["direction"][2] > 0.999


def test_synthetic_samples_from_the_generator():
    from potflat_synthetic import vessels as synthetic
    for kind in ("cylinder", "cone", "sherd"):
        sv = synthetic.make_vessel(kind, n_vertices=2000, seed=3, texture_size=64)
        res = rollout(sv.mesh)
        cos = abs(res.axis.direction @ sv.axis_direction) / np.linalg.norm(sv.axis_direction)
        assert np.degrees(np.arccos(min(cos, 1.0))) < 0.05, kind
        assert res.distortion.flipped == 0, kind
        assert len(np.unique(res.face_index)) == len(sv.mesh.faces)
        if kind != "sherd":
            assert res.proxy.kind == kind and res.distortion.edge_rms < 0.02
        else:
            assert res.seam_method == "gap" and res.seam_vertices == 0


def test_face_mask_restricts_the_region():
    mesh, *_ = vase(seed=1)
    centroid = mesh.vertices[mesh.faces].mean(axis=1)
    mask = centroid[:, 0] > np.median(centroid[:, 0])  # one side of the vessel
    res = rollout(mesh, face_mask=mask, band=(0.2, 0.8))
    assert np.all(mask[res.face_index])
    full = rollout(mesh, band=(0.2, 0.8))
    np.testing.assert_array_equal(np.unique(res.face_index), np.unique(full.face_index[mask[full.face_index]]))
    with pytest.raises(InvalidInputError, match="face_mask"):
        rollout(mesh, face_mask=np.ones(3, bool))


def test_two_open_ends_say_flip_may_be_needed():
    mesh, *_ = cylinder(seed=1)
    assert "use flip" in rollout(mesh).axis.orientation


def test_units_declared_by_the_file_are_kept_unless_given(tmp_path):
    mesh, *_ = vase(seed=1)
    scan = tmp_path / "pot.ply"
    lines = ["ply", "format ascii 1.0", "comment units cm", f"element vertex {len(mesh.vertices)}",
             "property double x", "property double y", "property double z",
             f"element face {len(mesh.faces)}", "property list uchar int vertex_indices", "end_header"]
    lines += [" ".join(map(repr, v)) for v in mesh.vertices.tolist()]
    lines += ["3 " + " ".join(map(str, f)) for f in mesh.faces.tolist()]
    scan.write_text("\n".join(lines) + "\n")
    assert run_rollout_stage(scan, tmp_path / "a").record["units"] == "cm"
    out = run_rollout_stage(scan, tmp_path / "b", RolloutOptions(units="mm"))
    assert out.record["units"] == "mm" and out.record["mm_per_unit"] == 1.0
    assert read_flat_ply(out.paths["ply"]).mesh.units == "mm"


def test_corner_angles_match_numpy_reference():
    """Each corner's angle unwrapped to within pi of its face's, as the NumPy formula gives it
    (Python's float modulo), at the wrap points too."""
    from potflat.rollout.seam import _corner_angles

    rng = np.random.default_rng(4)
    theta_v = rng.random(60) * 2 * np.pi
    theta_v[:6] = [0.0, np.pi, -np.pi, 2 * np.pi, 3 * np.pi, 1e-300]
    F = rng.integers(0, 60, (90, 3))
    idx = np.sort(rng.choice(90, 70, replace=False))
    centre = rng.random(70) * 8 - 2
    centre[:3] = [np.pi, 0.0, -np.pi]
    for shift in (0.0, 1.5, -7.0):
        x = theta_v[F[idx]] - shift - centre[:, None]
        want = centre[:, None] + ((x + np.pi) % (2 * np.pi) - np.pi)
        np.testing.assert_array_equal(_corner_angles(theta_v, F, idx, centre, shift), want)
