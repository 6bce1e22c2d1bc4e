"""Synthetic vessel generator: geometry, topology, pose, atlas, writers, issue-7 kinds."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from potflat.errors import InvalidOptionError
from potflat_synthetic.spec import (
    ATLAS_BACKGROUND, BLACK, CIRCLE_RADIUS, CREAM, PAINTINGS, PART_HANDLE, PART_INNER, PART_OUTER,
    SHADING_RANGE, TERRACOTTA,
)
from potflat_synthetic.vessels import make_vessel, write_obj, write_ply_colored

SMALL = dict(n_vertices=3000, texture_size=256)


# --------------------------------------------------------------------------- helpers


def _edges(F):
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    u, c = np.unique(e, axis=0, return_counts=True)
    return u, c


def _boundary_loops(F, n):
    u, c = _edges(F)
    b = u[c == 1]
    if len(b) == 0:
        return 0
    g = coo_matrix((np.ones(len(b)), (b[:, 0], b[:, 1])), shape=(n, n))
    k, lab = connected_components(g, directed=False)
    return len(np.unique(lab[np.unique(b)]))


def _components(F, n):
    rows = np.repeat(np.arange(len(F)), 3)
    inc = coo_matrix((np.ones(3 * len(F)), (rows, F.ravel())), shape=(len(F), n)).tocsr()
    return connected_components(inc @ inc.T, directed=False)[0]


def _axis_coords(v, P):
    d = v.axis_direction
    q = P - v.axis_point
    h = q @ d
    r = np.linalg.norm(q - h[:, None] * d, axis=1)
    return h, r


def _face_normals(V, F):
    return np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])


@pytest.fixture(scope="module")
def amphora():
    return make_vessel("amphora", seed=3, **SMALL)


# --------------------------------------------------------------------------- geometry


@pytest.mark.parametrize("kind", ["amphora", "lekythos", "aryballos", "kylix", "cone"])
def test_vertices_lie_on_the_profile(kind):
    v = make_vessel(kind, seed=1, **SMALL)
    P = v.mesh.vertices[v.vertex_part == PART_OUTER]
    h, r = _axis_coords(v, P)
    assert len(P) > 1000
    np.testing.assert_allclose(r, v.radius_at(h), atol=1e-9 * 500)
    assert np.all(np.diff(v.profile[:, 0]) > 0)
    assert 80 <= v.profile[-1, 0] - v.profile[0, 0] <= 450


def test_pose_is_random_and_recorded(amphora):
    d = amphora.axis_direction
    assert abs(np.linalg.norm(d) - 1) < 1e-12
    assert np.max(np.abs(d)) < math.cos(math.radians(15))
    R = amphora.pose[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) > 0
    np.testing.assert_allclose(R[:, 2], d)
    np.testing.assert_allclose(amphora.pose[:3, 3], amphora.axis_point)
    # the mouth is at the top: heights of the vertices run from 0 to the profile's top
    h, _ = _axis_coords(amphora, amphora.mesh.vertices)
    assert h.min() > -1e-6 and abs(h.max() - amphora.profile[-1, 0]) < 1e-6
    flat = make_vessel("amphora", seed=3, pose=False, **SMALL)
    np.testing.assert_allclose(flat.axis_direction, [0, 0, 1])
    np.testing.assert_allclose(flat.mesh.vertices @ R.T + amphora.axis_point, amphora.mesh.vertices,
                               atol=1e-9)


@pytest.mark.parametrize("kind,base,loops", [("amphora", False, 2), ("hydria", True, 1),
                                             ("cylinder", False, 2), ("cup", None, 0)])
def test_one_manifold_piece_without_seam(kind, base, loops):
    v = make_vessel(kind, base=base, **SMALL)
    V, F = v.mesh.vertices, v.mesh.faces
    _, cnt = _edges(F)
    assert cnt.max() == 2
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    assert len(np.unique(directed, axis=0)) == len(directed)  # consistently oriented
    assert _components(F, len(V)) == 1
    assert _boundary_loops(F, len(V)) == loops
    assert len(np.unique(V.round(6), axis=0)) == len(V)  # no duplicated (seam) vertices
    # faces point outwards: outer-wall normals have a positive radial component
    n = _face_normals(V, F)
    c = V[F].mean(axis=1) - v.axis_point
    radial = c - (c @ v.axis_direction)[:, None] * v.axis_direction
    outer = v.face_part == PART_OUTER
    assert np.all(np.einsum("ij,ij->i", n[outer], radial[outer]) > 0)


def test_triangles_are_irregular(amphora):
    V, F = amphora.mesh.vertices, amphora.mesh.faces
    u, _ = _edges(F)
    length = np.linalg.norm(V[u[:, 0]] - V[u[:, 1]], axis=1)
    assert length.std() / length.mean() > 0.15
    valence = np.bincount(u.ravel())
    assert len(np.unique(valence)) >= 4
    n_target = SMALL["n_vertices"]
    assert 0.8 * n_target < len(V) < 1.25 * n_target


def test_cylinder_and_cone_are_developable_known_answers():
    cyl = make_vessel("cylinder", **SMALL)
    np.testing.assert_allclose(cyl.profile[:, 1], 100.0)
    assert cyl.profile[-1, 0] == pytest.approx(200.0)
    cone = make_vessel("cone", **SMALL)
    np.testing.assert_allclose(cone.profile[:, 1], 60.0 + 0.3 * cone.profile[:, 0], atol=1e-9)
    h, r = _axis_coords(cone, cone.mesh.vertices)
    np.testing.assert_allclose(r, 60.0 + 0.3 * h, atol=1e-9)
    # area of the mesh against the exact lateral area of the frustum (chords: slightly less)
    V, F = cone.mesh.vertices, cone.mesh.faces
    area = 0.5 * np.linalg.norm(_face_normals(V, F), axis=1).sum()
    exact = math.pi * (60 + 120) * math.hypot(200, 60)
    assert 0.99 * exact < area < exact


def test_painted_circles_are_on_the_surface_and_painted(amphora):
    assert len(amphora.features) >= 3
    for c in amphora.features:
        h, r = _axis_coords(amphora, c.centre[None])
        assert r[0] == pytest.approx(amphora.radius_at(h)[0], abs=1e-9)
        assert h[0] == pytest.approx(c.height)
        assert c.radius == 10.0
    col = amphora.vertex_colors()
    V = amphora.mesh.vertices
    R, t = amphora.pose[:3, :3], amphora.pose[:3, 3]
    for c in amphora.features:
        d = np.linalg.norm(V - c.centre, axis=1)
        assert np.all(col[d < c.radius] == c.colour)
        # along the parallel through the centre: inside up to the radius, background beyond
        r = float(amphora.radius_at(c.height))
        arc = np.array([-10.5, -9.5, 0.0, 9.5, 10.5])
        th = c.angle + arc / r
        P = np.stack([r * np.cos(th), r * np.sin(th), np.full(5, c.height)], axis=1) @ R.T + t
        got = amphora.paint(P)
        np.testing.assert_array_equal(got, [TERRACOTTA, c.colour, c.colour, c.colour, TERRACOTTA])


# --------------------------------------------------------------------------- atlas


def _sample_nearest(tex, uv):
    S = tex.shape[0]
    j = np.clip(np.floor(uv[:, 0] * S).astype(int), 0, S - 1)
    i = np.clip(np.floor((1 - uv[:, 1]) * S).astype(int), 0, S - 1)
    return tex[i, j], i, j


@pytest.mark.parametrize("kind,kw", [("amphora", {}), ("cup", {}), ("hydria", {"handles": True})])
def test_atlas_texels_show_the_painting(kind, kw):
    v = make_vessel(kind, seed=2, n_vertices=4000, texture_size=512, **kw)
    tex, tc, V, F = v.texture, v.mesh.texcoords, v.mesh.vertices, v.mesh.faces
    S = tex.shape[0]
    body = v.face_part != PART_HANDLE
    # the texel whose centre is nearest each face's texture centroid
    cen = tc.mean(axis=1)
    j = np.floor(cen[:, 0] * S).astype(int)
    i = np.floor((1 - cen[:, 1]) * S).astype(int)
    p = np.stack([(j + 0.5) / S, 1 - (i + 0.5) / S], axis=1)
    a, b, c = tc[:, 0], tc[:, 1], tc[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    l1 = ((p[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (p[:, 1] - a[:, 1])) / det
    l2 = ((b[:, 0] - a[:, 0]) * (p[:, 1] - a[:, 1]) - (p[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])) / det
    bary = np.stack([1 - l1 - l2, l1, l2], axis=1)
    inside = np.all(bary > 1e-6, axis=1)
    assert inside.sum() > 0.3 * len(F)
    sel = inside & body
    P = np.einsum("nk,nkd->nd", bary[sel], V[F[sel]])
    expected = v.paint(P)
    got = tex[i[sel], j[sel]]
    assert np.mean(np.any(got != expected, axis=1)) < 1e-3
    colours = {tuple(x) for x in np.unique(got, axis=0)}
    assert {TERRACOTTA, BLACK, CREAM} <= colours
    if kw.get("handles"):
        assert np.all(tex[i[inside & ~body], j[inside & ~body]] == BLACK)


def test_atlas_has_several_charts_and_gutters(amphora):
    tex, tc = amphora.texture, amphora.mesh.texcoords
    assert amphora.face_chart.max() + 1 >= 6
    # bilinear footprint of every face corner (chart borders included) avoids the background
    S = tex.shape[0]
    uv = tc.reshape(-1, 2)
    x = uv[:, 0] * S - 0.5
    y = (1 - uv[:, 1]) * S - 0.5
    for dj in (0, 1):
        for di in (0, 1):
            j = np.clip(np.floor(x).astype(int) + dj, 0, S - 1)
            i = np.clip(np.floor(y).astype(int) + di, 0, S - 1)
            assert not np.any(np.all(tex[i, j] == ATLAS_BACKGROUND, axis=1))
    assert np.any(np.all(tex == ATLAS_BACKGROUND, axis=2))  # the background exists


# --------------------------------------------------------------------------- writers


def _parse_obj(path):
    v, vt, f = [], [], []
    mtllib = None
    for line in path.read_text().splitlines():
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        if parts[0] == "v":
            v.append([float(x) for x in parts[1:4]])
        elif parts[0] == "vt":
            vt.append([float(x) for x in parts[1:3]])
        elif parts[0] == "f":
            f.append([[int(i) for i in c.split("/")] for c in parts[1:]])
        elif parts[0] == "mtllib":
            mtllib = parts[1]
    return np.array(v), np.array(vt), np.array(f) - 1, mtllib


def test_obj_round_trip(tmp_path, amphora):
    import cv2

    path = write_obj(amphora, tmp_path / "a.obj")
    V, VT, FF, mtllib = _parse_obj(path)
    mesh = amphora.mesh
    assert len(V) == len(mesh.vertices) == len(np.unique(V, axis=0))
    np.testing.assert_allclose(V, mesh.vertices, atol=1e-4)
    np.testing.assert_array_equal(FF[:, :, 0], mesh.faces)
    np.testing.assert_allclose(VT[FF[:, :, 1]], mesh.texcoords, atol=1e-6)
    # vertices on chart borders carry several texture coordinates
    pairs = np.unique(FF.reshape(-1, 2), axis=0)
    per_vertex = np.bincount(pairs[:, 0], minlength=len(V))
    assert len(VT) > len(V) and per_vertex.max() >= 2 and np.all(per_vertex >= 1)
    mtl = (tmp_path / mtllib).read_text()
    assert "map_Kd a.png" in mtl
    png = cv2.imread(str(tmp_path / "a.png"))[:, :, ::-1]
    np.testing.assert_array_equal(png, amphora.texture)


def test_ply_colored_round_trip(tmp_path, amphora):
    path = write_ply_colored(amphora, tmp_path / "a.ply")
    data = path.read_bytes()
    head, body = data.split(b"end_header\n", 1)
    assert b"comment units mm" in head
    n, m = len(amphora.mesh.vertices), len(amphora.mesh.faces)
    vdt = np.dtype([("x", "<f8"), ("y", "<f8"), ("z", "<f8"), ("r", "u1"), ("g", "u1"), ("b", "u1")])
    fdt = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    vert = np.frombuffer(body, vdt, n)
    face = np.frombuffer(body, fdt, m, offset=n * vdt.itemsize)
    assert len(body) == n * vdt.itemsize + m * fdt.itemsize
    np.testing.assert_array_equal(np.stack([vert["x"], vert["y"], vert["z"]], 1), amphora.mesh.vertices)
    np.testing.assert_array_equal(np.stack([vert["r"], vert["g"], vert["b"]], 1), amphora.vertex_colors())
    np.testing.assert_array_equal(face["i"], amphora.mesh.faces)


def test_deterministic_bytes(tmp_path):
    a = write_obj(make_vessel("lekythos", seed=5, **SMALL), tmp_path / "a" / "v.obj")
    b = write_obj(make_vessel("lekythos", seed=5, **SMALL), tmp_path / "b" / "v.obj")
    c = write_obj(make_vessel("lekythos", seed=6, **SMALL), tmp_path / "c" / "v.obj")
    for suffix in (".obj", ".png", ".mtl"):
        assert a.with_suffix(suffix).read_bytes() == b.with_suffix(suffix).read_bytes()
    assert a.read_bytes() != c.read_bytes()


# --------------------------------------------------------------------------- real-vessel kinds


def test_cup_has_two_walls_a_thickness_and_a_tondo():
    v = make_vessel("cup", thickness=4.0, **SMALL)
    V, F = v.mesh.vertices, v.mesh.faces
    assert _boundary_loops(F, len(V)) == 0
    n = _face_normals(V, F)
    vol = np.einsum("ij,ij->i", V[F[:, 0]] - v.axis_point, n).sum() / 6
    assert vol > 0  # closed shell, outward normals
    # inner wall vertices are exactly one thickness from the outer profile (section plane)
    h, r = _axis_coords(v, V[v.vertex_part == PART_INNER])
    prof = v.profile
    seg_a, seg_b = prof[:-1][:, ::-1], prof[1:][:, ::-1]  # (r, h)
    q = np.stack([r, h], axis=1)[:, None, :]
    ab = seg_b - seg_a
    t = np.clip(np.einsum("nkj,kj->nk", q - seg_a, ab) / np.einsum("kj,kj->k", ab, ab), 0, 1)
    dist = np.linalg.norm(seg_a + t[..., None] * ab - q, axis=2).min(axis=1)
    wall = h > 10.0  # above the floor
    np.testing.assert_allclose(dist[wall], 4.0, atol=0.05)
    inner = [c for c in v.features if c.side == "inner"]
    assert len(inner) == 1
    assert np.all(v.paint(inner[0].centre[None]) == BLACK)


def test_handles_are_extra_tubes_sunk_into_the_wall():
    v = make_vessel("amphora", handles=True, **SMALL)
    V, F = v.mesh.vertices, v.mesh.faces
    assert _components(F, len(V)) == 3
    assert _boundary_loops(F, len(V)) == 2 + 4
    hv = np.unique(F[v.face_part == PART_HANDLE])
    u, c = _edges(F)
    bnd = np.intersect1d(np.unique(u[c == 1]), hv)
    h, r = _axis_coords(v, V[bnd])
    depth = v.radius_at(h) - r
    assert np.all(depth > 0) and np.all(depth < 10)
    h, r = _axis_coords(v, V[hv])
    assert np.max(r - v.radius_at(h)) > 20  # the loops stand off the wall


def test_welded_handles_make_one_surface_of_higher_genus():
    v = make_vessel("amphora", handles="welded", n_vertices=6000, texture_size=256)
    V, F = v.mesh.vertices, v.mesh.faces
    u, cnt = _edges(F)
    assert cnt.max() == 2
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    assert len(np.unique(directed, axis=0)) == len(directed)
    assert _components(F, len(V)) == 1
    assert _boundary_loops(F, len(V)) == 2  # mouth and foot only: the roots are closed
    chi = len(V) - len(u) + len(F)
    assert chi == 0 - 2 * 2  # an open band (0) with two handles, each adding a genus
    h, r = _axis_coords(v, V[np.unique(F[v.face_part == PART_HANDLE])])
    assert np.max(r - v.radius_at(h)) > 20
    # the wall is cut only just around each root: wall vertices remain close to it
    body = np.unique(F[v.face_part != PART_HANDLE])
    hb, rb = _axis_coords(v, V[body])
    assert np.all(np.abs(rb - v.radius_at(hb)) < 1e-6)


def test_holes_are_interior_boundaries_clear_of_circles():
    v = make_vessel("hydria", holes=3, seed=4, **SMALL)
    V, F = v.mesh.vertices, v.mesh.faces
    assert len(v.holes) == 3
    assert _components(F, len(V)) == 1
    assert _boundary_loops(F, len(V)) == 2 + 3
    cen = V[F].mean(axis=1)
    for hole in v.holes:
        assert np.linalg.norm(cen - hole.centre, axis=1).min() > hole.radius
        for c in v.features:
            assert np.linalg.norm(hole.centre - c.centre) > hole.radius + c.radius


def test_sherd_is_one_patch_of_the_requested_width():
    v = make_vessel("sherd", sherd_of="hydria", sherd_span=80.0, n_vertices=3000, texture_size=256)
    V, F = v.mesh.vertices, v.mesh.faces
    assert _components(F, len(V)) == 1 and _boundary_loops(F, len(V)) == 1
    assert 0.7 * 3000 < len(V) < 1.4 * 3000
    Q = v.to_canonical(V)
    ang = np.unwrap(np.sort(np.arctan2(Q[:, 1], Q[:, 0])))
    gaps = np.diff(np.sort(np.arctan2(Q[:, 1], Q[:, 0])))
    width = 2 * math.pi - gaps.max() if gaps.max() > math.pi else ang.max() - ang.min()
    assert math.radians(65) < width < math.radians(95)
    h, r = _axis_coords(v, V)
    np.testing.assert_allclose(r, v.radius_at(h), atol=1e-6)
    assert len(v.features) >= 1
    for c in v.features:  # kept circles are whole: surface all around them
        d = np.linalg.norm(V - c.centre, axis=1)
        assert np.sum(d < c.radius) > 5


def test_thick_sherd_is_a_closed_fragment_with_a_plain_back():
    from potflat_synthetic.spec import CLAY, PART_BREAK

    v = make_vessel("sherd", sherd_thickness=6.0, holes=1, seed=1, n_vertices=3000, texture_size=256)
    V, F = v.mesh.vertices, v.mesh.faces
    assert _boundary_loops(F, len(V)) == 0 and _components(F, len(V)) == 1
    n = _face_normals(V, F)
    vol = np.einsum("ij,ij->i", V[F[:, 0]] - V.mean(axis=0), n).sum() / 6
    outer_area = 0.5 * np.linalg.norm(n[v.face_part == PART_OUTER], axis=1).sum()
    assert vol == pytest.approx(6.0 * outer_area, rel=0.1)  # slab of 6 mm over the painted face
    assert np.any(v.face_part == PART_BREAK)
    col = v.vertex_colors()
    assert np.all(col[v.vertex_part == PART_INNER] == CLAY)
    assert not np.all(col[v.vertex_part == PART_OUTER] == CLAY)
    h, r = _axis_coords(v, V[v.vertex_part == PART_OUTER])
    np.testing.assert_allclose(r, v.radius_at(h), atol=1e-6)


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize("kind,kw", [
    ("vase", {}),
    ("amphora", {"n_vertices": 10}),
    ("amphora", {"n_vertices": 2.5}),
    ("amphora", {"texture_size": 16}),
    ("amphora", {"holes": -1}),
    ("amphora", {"seed": -1}),
    ("amphora", {"thickness": 0.0}),
    ("amphora", {"walls": 2}),
    ("amphora", {"walls": 3}),
    ("cylinder", {"handles": True}),
    ("amphora", {"pose": "yes"}),
    ("amphora", {"handles": 1}),
    ("amphora", {"handles": "glued"}),
    ("amphora", {"handles": "welded", "n_vertices": 600}),
    ("amphora", {"base": "no"}),
    ("sherd", {"sherd_of": "vase"}),
    ("sherd", {"sherd_span": 5.0}),
    ("sherd", {"handles": True}),
    ("sherd", {"sherd_thickness": 0.5}),
    ("amphora", {"sherd_thickness": 5.0}),
    ("amphora", {"painting": "metope"}),
    ("amphora", {"shading": 1}),
])
def test_invalid_options(kind, kw):
    with pytest.raises(InvalidOptionError):
        make_vessel(kind, **kw)


def test_write_obj_needs_obj_suffix(tmp_path, amphora):
    with pytest.raises(InvalidOptionError):
        write_obj(amphora, tmp_path / "a.ply")


# --------------------------------------------------------------------------- raster kernel


def _reference_raster(tri, h, w, pad):
    """Slow reference: every pixel against every triangle."""
    face = np.full((h, w), -1)
    bary = np.zeros((h, w, 3))
    dist = np.full((h, w), np.inf)
    for i in range(h):
        for j in range(w):
            p = np.array([j + 0.5, i + 0.5])
            for f, t in enumerate(tri):
                m = np.array([t[1] - t[0], t[2] - t[0]]).T
                l1, l2 = np.linalg.solve(m, p - t[0])
                b = np.array([1 - l1 - l2, l1, l2])
                if np.all(b >= -1e-9):
                    face[i, j], bary[i, j], dist[i, j] = f, np.clip(b, 0, None), 0.0
                    continue
                if dist[i, j] == 0.0:
                    continue
                best, bb = np.inf, None
                for e in range(3):
                    a, c = t[e], t[(e + 1) % 3]
                    s = np.clip((p - a) @ (c - a) / ((c - a) @ (c - a)), 0, 1)
                    d = np.linalg.norm(a + s * (c - a) - p)
                    if d < best:
                        best, bb = d, np.zeros(3)
                        bb[e], bb[(e + 1) % 3] = 1 - s, s
                if best <= pad and best < dist[i, j]:
                    face[i, j], bary[i, j], dist[i, j] = f, bb, best
    return face, bary, dist


def test_raster_kernel_matches_reference():
    from potflat_synthetic._kernels import rasterize_faces

    rng = np.random.default_rng(0)
    tri = rng.uniform(2, 22, (6, 3, 2))
    for pad in (0.0, 2.5):
        face, bary, dist = rasterize_faces(tri, 20, 24, pad)
        rf, rb, rd = _reference_raster(tri, 20, 24, pad)
        np.testing.assert_array_equal(face, rf)
        np.testing.assert_allclose(bary, rb, atol=1e-9)
        np.testing.assert_allclose(dist, rd, atol=1e-9)
        assert np.any(face >= 0) and np.any(face < 0)
    # barycentric coordinates reproduce the pixel centre inside the triangles
    inside = dist == 0
    ii, jj = np.nonzero(inside)
    pts = np.einsum("nk,nkd->nd", bary[ii, jj], tri[face[ii, jj]])
    np.testing.assert_allclose(pts, np.stack([jj + 0.5, ii + 0.5], axis=1), atol=1e-9)


def test_generate_script_writes_obj_and_truth(tmp_path):
    import importlib.util
    import json
    from pathlib import Path

    script = Path(__file__).resolve().parents[1] / "samples" / "generate.py"
    spec = importlib.util.spec_from_file_location("generate", script)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main(["--kind", "cone", "--vertices", "2000", "--texture-size", "128", "--ply",
                     "-o", str(tmp_path)]) == 0
    for suffix in (".obj", ".mtl", ".png", ".ply", ".truth.json"):
        assert (tmp_path / f"cone{suffix}").stat().st_size > 0
    truth = json.loads((tmp_path / "cone.truth.json").read_text())
    v = make_vessel("cone", n_vertices=2000, texture_size=128)
    np.testing.assert_allclose(truth["axis_direction"], v.axis_direction)
    np.testing.assert_allclose(np.interp(truth["profile"]["height"], v.profile[:, 0], v.profile[:, 1]),
                               truth["profile"]["radius"], atol=1e-5)
    assert len(truth["circles"]) == len(v.features)
    assert mod.main(["--kind", "cone", "--vertices", "10", "-o", str(tmp_path)]) == 2


# --------------------------------------------------------------------------- paintings, shading


def _wall_points(v, step=0.5):
    """World points on the outer wall every ``step`` mm of height and of arc length about the
    axis (between 2 mm above the foot and 2 mm below the mouth, off whole millimetres), and their
    (height, angle)."""
    h0, h1 = v.profile[0, 0] + 2.0 + step / 7, v.profile[-1, 0] - 2.0
    pts, hs, ths = [], [], []
    for h in np.arange(h0, h1, step):
        r = float(v.radius_at(h))
        th = np.arange(0.0, 2 * math.pi, step / r)
        pts.append(np.stack([r * np.cos(th), r * np.sin(th), np.full(len(th), h)], axis=1))
        hs.append(np.full(len(th), h))
        ths.append(th)
    P = np.concatenate(pts)
    return P @ v.pose[:3, :3].T + v.pose[:3, 3], np.concatenate(hs), np.concatenate(ths)


def test_default_painting_reproduces_the_bundled_sample():
    """The bundled cone was generated before paintings existed: same texture, same options."""
    import json
    from pathlib import Path

    import cv2

    data = Path(__file__).resolve().parents[1] / "samples" / "data"
    truth = json.loads((data / "cone.truth.json").read_text())
    opts = {k: val for k, val in truth["options"].items() if val is not None}
    v = make_vessel(opts.pop("kind"), **opts)
    np.testing.assert_array_equal(v.texture, cv2.imread(str(data / "cone.png"))[:, :, ::-1])
    assert v.options == truth["options"]
    assert v.painting.kind == "frieze" and v.painting.zone is None


def test_painting_and_shading_leave_the_mesh_alone():
    ref = make_vessel("hydria", seed=4, handles=True, **SMALL)
    for painting in PAINTINGS:
        v = make_vessel("hydria", seed=4, handles=True, painting=painting, shading=True, **SMALL)
        np.testing.assert_array_equal(v.mesh.vertices, ref.mesh.vertices)
        np.testing.assert_array_equal(v.mesh.faces, ref.mesh.faces)
        np.testing.assert_array_equal(v.mesh.texcoords, ref.mesh.texcoords)
        assert v.options["painting" if painting != "frieze" else "shading"] == (
            painting if painting != "frieze" else True)


@pytest.mark.parametrize("kind,kw", [("hydria", {"handles": True}), ("aryballos", {}), ("cone", {}),
                                     ("lekythos", {"handles": "welded"})])
@pytest.mark.parametrize("painting", ["belt", "panel"])
def test_belt_and_panel_are_painted_in_their_zone_only(kind, kw, painting):
    v = make_vessel(kind, seed=1, painting=painting, **SMALL, **kw)
    P, h, th = _wall_points(v, step=0.8)
    col = v.paint(P)
    zone = v.painted_zone(P)
    black = np.all(col == BLACK, axis=1)
    assert 0.02 < zone.mean() < 0.6
    assert np.all(black[~zone])  # glaze everywhere else
    assert np.mean(np.all(col[zone] == TERRACOTTA, axis=1)) > 0.3
    z_lo, z_hi, centre, half = v.painting.zone
    belt = (h >= z_lo) & (h <= z_hi)  # canonical heights: along the axis from the foot
    if painting == "belt":
        assert centre is None
        np.testing.assert_array_equal(zone, belt)
    else:
        assert 100 <= math.degrees(2 * half) <= 140
        around = np.abs((th - centre + math.pi) % (2 * math.pi) - math.pi) <= half
        np.testing.assert_array_equal(zone, belt & around)
        # the rest of the frieze (the circles' height) is glaze
        zf = v.features[0].height
        assert np.all(black[(np.abs(h - zf) < 2.0) & ~around])
    # the faces of the zone are outer-wall faces whose centroids are in it
    zf_ = v.zone_faces()
    assert zf_.any() and np.all(v.face_part[zf_] == PART_OUTER)


@pytest.mark.parametrize("kind,kw", [("hydria", {"handles": True}), ("aryballos", {}), ("alabastron", {}),
                                     ("cup", {})])
@pytest.mark.parametrize("painting", PAINTINGS)
def test_feature_circles_lie_inside_the_painted_zone(kind, kw, painting):
    v = make_vessel(kind, seed=2, painting=painting, **SMALL, **kw)
    outer = [c for c in v.features if c.side == "outer"]
    assert len(outer) >= (2 if painting == "panel" else 3)
    from scipy.spatial import cKDTree

    P, _, _ = _wall_points(v, step=0.8)
    col = v.paint(P)
    zone = v.painted_zone(P)
    tree = cKDTree(P)
    for c in outer:
        assert c.radius == CIRCLE_RADIUS
        disc = tree.query_ball_point(c.centre, c.radius)
        assert len(disc) > 100
        assert np.all(col[disc] == c.colour)  # whole, not covered by glaze or another circle
        assert np.all(zone[tree.query_ball_point(c.centre, c.radius + 2.0)])  # a margin inside the zone
    if painting == "panel":  # one group: within the panel's width
        ang = np.array([c.angle for c in outer])
        spread = np.abs((ang - v.painting.zone[2] + math.pi) % (2 * math.pi) - math.pi)
        assert np.all(spread < math.radians(70))


@pytest.mark.parametrize("kind", ["aryballos", "alabastron"])
def test_allover_painting_leaves_no_large_plain_area(kind):
    from scipy.spatial import cKDTree

    v = make_vessel(kind, seed=0, painting="allover", **SMALL)
    P, _, _ = _wall_points(v, step=0.5)
    col = v.paint(P)
    plain = np.all(col == TERRACOTTA, axis=1)
    assert 0.2 < plain.mean() < 0.9
    dist, _ = cKDTree(P[~plain]).query(P[plain])
    assert dist.max() < 8.0  # every plain point is within 8 mm of a line or a figure
    assert np.all(v.painted_zone(P))
    circles = np.array([c.centre for c in v.features])
    assert len(circles) >= 10
    gaps = np.linalg.norm(circles[:, None] - circles[None], axis=2) + np.eye(len(circles)) * 1e9
    assert gaps.min() > 2 * CIRCLE_RADIUS  # the circles do not touch


def test_shading_is_a_smooth_gradient_with_mild_noise():
    plain_v = make_vessel("hydria", seed=3, **SMALL)
    lit_v = make_vessel("hydria", seed=3, shading=True, **SMALL)
    np.testing.assert_array_equal(lit_v.paint(lit_v.mesh.vertices), plain_v.paint(plain_v.mesh.vertices))
    base, lit = plain_v.texture.astype(float), lit_v.texture.astype(float)
    covered = np.any(plain_v.texture != ATLAS_BACKGROUND, axis=2)
    np.testing.assert_array_equal(lit[~covered], base[~covered])
    bright = covered & (base.min(axis=2) >= 50)
    ratio = lit[bright] / base[bright]
    lo, hi = SHADING_RANGE
    q = np.percentile(ratio, [0.5, 99.5])
    assert lo - 0.06 < q[0] < lo + 0.1 and hi - 0.1 < q[1] < hi + 0.06  # the whole range, about
    # noise: neighbouring texels of the same plain colour differ by a few grey levels
    same = bright[:, 1:] & bright[:, :-1] & np.all(plain_v.texture[:, 1:] == plain_v.texture[:, :-1], axis=2)
    step = (lit[:, 1:] - lit[:, :-1])[same]
    assert 1.5 < step.std() < 5.0
    # the vertex colours are lit as well (the same lighting), the painting stays unlit
    vc = lit_v.vertex_colors().astype(float)
    vb = plain_v.vertex_colors().astype(float)
    ok = vb.min(axis=1) >= 50
    r = vc[ok].sum(axis=1) / vb[ok].sum(axis=1)
    assert lo - 0.03 < r.min() and r.max() < hi + 0.03 and np.ptp(r) > 0.3
