"""Bake stage: measure the baked images (scale, roundness, orientation, coverage, anti-aliasing)."""
from __future__ import annotations

import json
import math

import cv2
import numpy as np
import pytest
from PIL import Image

from potflat.bake import BakeOptions, bake
from potflat.errors import InvalidOptionError
from potflat.files.bake_stage import run_bake_stage
from potflat.io.flat_ply import write_flat_ply
from potflat.types import FlatMesh, Mesh

# ---------------------------------------------------------------------------- fixtures


def grid_mesh(width, height, step, *, z=None):
    """Plane grid ``width x height`` (mm) with isometric uv = (x, y); CCW seen from +z."""
    nu, nv = round(width / step) + 1, round(height / step) + 1
    x, y = np.meshgrid(np.linspace(0, width, nu), np.linspace(0, height, nv))
    V = np.stack([x, y, np.zeros_like(x) if z is None else z(x, y)], -1).reshape(-1, 3)
    a = (np.arange(nv - 1)[:, None] * nu + np.arange(nu - 1)[None, :]).ravel()
    F = np.concatenate([np.stack([a, a + 1, a + nu + 1], 1), np.stack([a, a + nu + 1, a + nu], 1)])
    return V, F, V[:, :2].copy()


def cylinder_band(R=20.0, H=30.0, span=1.5 * np.pi, nu=90, nv=16):
    """Band of a cylinder about +z, unrolled with u = R theta, v = z (theta CCW: outward normals)."""
    th, z = np.meshgrid(np.linspace(0, span, nu), np.linspace(0, H, nv))
    V = np.stack([R * np.cos(th), R * np.sin(th), z], -1).reshape(-1, 3)
    uv = np.stack([R * th, z], -1).reshape(-1, 2)
    a = (np.arange(nv - 1)[:, None] * nu + np.arange(nu - 1)[None, :]).ravel()
    F = np.concatenate([np.stack([a, a + 1, a + nu + 1], 1), np.stack([a, a + nu + 1, a + nu], 1)])
    return V, F, uv


def texcoords_for(uv, F, size_mm, texels_per_mm):
    """Texcoords mapping uv (mm, origin 0) onto an image of ``size_mm`` at ``texels_per_mm``."""
    W, H = (round(s * texels_per_mm) for s in size_mm)
    tc = np.stack([uv[:, 0] * texels_per_mm / W, uv[:, 1] * texels_per_mm / H], -1)
    return tc[F], (H, W)


def draw_texture(path, shape, texels_per_mm, *, circles=(), bars=(), background=(235, 230, 220)):
    """Texture image: filled circles ``(u, v, r_mm, rgb)`` and bars ``(u0, v0, u1, v1, rgb)`` in mm (v up)."""
    H, W = shape
    img = np.zeros((H, W, 3), np.uint8)
    img[:] = background
    s = 16  # cv2 sub-pixel drawing shift
    to_px = lambda u, v: (round(u * texels_per_mm * s), round((H - v * texels_per_mm) * s))
    for u, v, r, rgb in circles:
        cv2.circle(img, to_px(u, v), round(r * texels_per_mm * s), rgb, -1, cv2.LINE_AA, shift=4)
    for u0, v0, u1, v1, rgb in bars:
        p0, p1 = to_px(u0, v1), to_px(u1, v0)
        cv2.rectangle(img, (p0[0] // s, p0[1] // s), (p1[0] // s - 1, p1[1] // s - 1), rgb, -1)
    cv2.imwrite(str(path), img[..., ::-1])
    return img


RED, BLUE, BAR = (200, 20, 20), (20, 40, 210), (10, 10, 10)


@pytest.fixture(scope="module")
def painted_plane(tmp_path_factory):
    """100 x 60 mm plane with a red circle (r 8 mm at (30, 40)), a blue one (r 5 mm at (75, 15))
    and a black 10 mm x 4 mm bar starting at u = 60, v = 40, texture at 10 texels/mm."""
    d = tmp_path_factory.mktemp("plane")
    V, F, uv = grid_mesh(100.0, 60.0, 2.5)
    tc, shape = texcoords_for(uv, F, (100.0, 60.0), 10.0)
    draw_texture(d / "tex.png", shape, 10.0, circles=[(30, 40, 8, RED), (75, 15, 5, BLUE)],
                 bars=[(60, 40, 70, 44, BAR)])
    return FlatMesh(Mesh(V, F, texcoords=tc, texture_path=d / "tex.png"), uv)


def colour_mask(image, rgb, tol=60):
    d = np.abs(image[..., :3].astype(int) - np.array(rgb)).sum(-1)
    return (d < tol) & (image[..., 3] > 128)


def blob(mask):
    """Centre (col, row), axis lengths (major, minor) of the largest blob, by ellipse fit."""
    cs, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    c = max(cs, key=cv2.contourArea)
    (cx, cy), axes, _ = cv2.fitEllipse(c)
    return (cx, cy), (max(axes), min(axes))


# ---------------------------------------------------------------------------- geometry


@pytest.mark.parametrize("ppm", [3.0, 7.5])
def test_circles_round_and_true_scale(painted_plane, ppm):
    res = bake(painted_plane, px_per_mm=ppm, maps=())
    (cx, cy), (major, minor) = blob(colour_mask(res.image, RED))
    assert major / minor < 1.03
    assert abs(0.5 * (major + minor) - 16 * ppm) <= 2.0  # 16 mm diameter
    # the 10 mm bar spans 10 x px/mm columns
    bar = colour_mask(res.image, BAR, tol=90)
    cols = np.flatnonzero(bar.any(axis=0))
    assert abs((cols[-1] - cols[0] + 1) - 10 * ppm) <= 2.0
    # centre where uv says: column (u - origin_u) * s, row (origin_v - v) * s
    s = ppm  # mm units
    assert abs(cx - (30 - res.origin[0]) * s) < 1.5 and abs(cy - (res.origin[1] - 40) * s) < 1.5


def test_upright_and_not_mirrored(painted_plane):
    res = bake(painted_plane, px_per_mm=4, maps=())
    (rx, ry), _ = blob(colour_mask(res.image, RED))  # u 30, v 40
    (bx, by), _ = blob(colour_mask(res.image, BLUE))  # u 75, v 15
    assert ry < by  # larger v -> smaller row (mouth up)
    assert bx > rx  # larger u -> larger column (not mirrored)


def test_coverage_matches_flattened_area_and_holes_transparent(tmp_path):
    V, F, uv = grid_mesh(60.0, 40.0, 2.0)
    centre = (V[F].mean(axis=1)[:, :2] - [30.0, 20.0])
    keep = np.hypot(centre[:, 0], centre[:, 1]) > 8.0  # a hole of about 8 mm radius
    F = F[keep]
    flat = FlatMesh(Mesh(V, F), uv)
    res = bake(flat, px_per_mm=5, maps=())
    e1, e2 = uv[F[:, 1]] - uv[F[:, 0]], uv[F[:, 2]] - uv[F[:, 0]]
    a2 = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    covered = res.painting[..., 3].sum() / 255.0 / 5.0**2
    assert covered == pytest.approx(a2, rel=0.01)
    assert res.figures["covered_area_mm2"] == pytest.approx(a2, rel=0.01)
    hole = res.painting[int((res.origin[1] - 20) * 5), int((30 - res.origin[0]) * 5)]
    assert hole[3] == 0
    assert res.painting[0, :, 3].max() == 0 and res.painting[:, 0, 3].max() == 0  # transparent border
    assert res.painting[20, 20, 3] == 255  # inside


def test_map_values(tmp_path):
    V, F, uv = grid_mesh(20.0, 10.0, 1.0)
    uv = uv * [1.2, 1.0]  # stretch u by 20%: area ratio 1.2, anisotropy 1.2, stress > 0
    res = bake(FlatMesh(Mesh(V, F), uv), px_per_mm=4)
    inside = res.painting[..., 3] == 255
    assert np.allclose(res.maps["area"][inside], math.log(1.2), atol=1e-5)  # natural log, as every area figure
    assert np.allclose(res.maps["anisotropy"][inside], 1.2, atol=1e-5)
    assert np.all(res.maps["stress"][inside] > 0)
    assert np.isnan(res.maps["area"][~(res.painting[..., 3] > 0)]).all()
    assert res.figures["anisotropy"]["p95"] == pytest.approx(1.2, abs=1e-6)
    assert res.figures["area"]["max"] == pytest.approx(math.log(1.2), abs=1e-6)


def test_position_map_traces_back_to_the_scan():
    V, F, uv = cylinder_band(R=20.0, H=30.0)
    res = bake(FlatMesh(Mesh(V, F), uv), px_per_mm=3, maps=(), position_map=True, supersample=1)
    P = res.position
    inside = res.painting[..., 3] == 255
    assert np.isnan(P[res.painting[..., 3] == 0]).all()
    radius = np.hypot(P[..., 0], P[..., 1])[inside]
    assert np.all(np.abs(radius - 20.0) < 0.05)  # on the cylinder (chord sag of 3.0 deg facets < 0.03 mm)
    rows, cols = np.nonzero(inside)
    v = res.origin[1] - (rows + 0.5) / 3.0
    u = res.origin[0] + (cols + 0.5) / 3.0
    assert np.allclose(P[rows, cols, 2], v, atol=1e-4)  # height = v
    theta = np.mod(np.arctan2(P[rows, cols, 1], P[rows, cols, 0]), 2 * np.pi)
    assert np.allclose(theta * 20.0, u, atol=0.02)  # arc length = u


# ---------------------------------------------------------------------------- sampling


def test_antialiasing_matches_box_filter(tmp_path):
    """A 1-texel checker plus a slow gradient baked 12x smaller gives the box-filtered mean, no moire."""
    n = 1200
    yy, xx = np.mgrid[0:n, 0:n]
    checker = ((xx + yy) % 2) * 255.0
    grad = xx / (n - 1) * 120.0
    tex = np.clip(0.5 * checker + grad * 0.5 + 30, 0, 255).astype(np.uint8)
    cv2.imwrite(str(tmp_path / "c.png"), np.repeat(tex[..., None], 3, axis=2))
    V, F, uv = grid_mesh(100.0, 100.0, 10.0)
    tc, _ = texcoords_for(uv, F, (100.0, 100.0), 12.0)
    flat = FlatMesh(Mesh(V, F, texcoords=tc, texture_path=tmp_path / "c.png"), uv)
    ref = cv2.resize(tex, (100, 100), interpolation=cv2.INTER_AREA).astype(float)
    for ss in (0, 1):  # automatic (supersampling + mips) and mips alone
        res = bake(flat, px_per_mm=1.0, maps=(), supersample=ss)
        got = res.image[1:-1, 1:-1, 0].astype(float)  # inner 100 x 100 pixels (1 px pad)
        assert res.figures["mip_levels"] >= 2
        assert np.abs(got - ref)[2:-2, 2:-2].max() < 6.0
        assert np.abs(got - ref).mean() < 2.0


def test_atlas_chart_seam_has_no_gap(tmp_path):
    """Two halves of a plane map to distant atlas charts on a black background: no gap, no bleed."""
    V, F, uv = grid_mesh(40.0, 20.0, 2.0)
    tpm = 8.0
    W = H = 512
    left = V[F].mean(axis=1)[:, 0] < 20.0
    tc = np.empty((len(F), 3, 2))
    # left chart at texel (10, 10) from the top-left, right chart at (250, 300), 3-texel gutters
    for sel, (ox, oy), u0 in ((left, (10, 10), 0.0), (~left, (250, 300), 20.0)):
        pts = uv[F[sel]]
        x = ox + (pts[..., 0] - u0) * tpm
        y = oy + (20.0 - pts[..., 1]) * tpm
        tc[sel] = np.stack([x / W, 1.0 - y / H], -1)
    img = np.zeros((H, W, 3), np.uint8)
    colour = (40, 180, 200)  # BGR on disk
    cv2.rectangle(img, (10 - 3, 10 - 3), (10 + 160 + 3, 10 + 160 + 3), colour, -1)
    cv2.rectangle(img, (250 - 3, 300 - 3), (250 + 160 + 3, 300 + 160 + 3), colour, -1)
    cv2.imwrite(str(tmp_path / "atlas.png"), img)
    flat = FlatMesh(Mesh(V, F, texcoords=tc, texture_path=tmp_path / "atlas.png"), uv)
    for ppm, ss in ((8.0, 0), (3.0, 0), (1.0, 1), (0.5, 1)):  # level 0, then mips up to level 4
        res = bake(flat, px_per_mm=ppm, maps=(), supersample=ss)
        inner = res.image[res.image[..., 3] > 0] if ppm < 3 else res.image[2:-2, 2:-2]
        if ppm >= 3:
            assert (inner[..., 3] == 255).all()
        assert np.abs(inner[..., :3].astype(int) - [200, 180, 40]).max() <= 2


def test_vertex_colours_interpolated():
    V, F, uv = grid_mesh(30.0, 10.0, 10.0)
    colours = np.zeros((len(V), 4), np.uint8)
    colours[:, 3] = 255
    colours[:, 0] = np.where(V[:, 0] < 15, 255, 0)
    colours[:, 2] = np.where(V[:, 0] < 15, 0, 255)
    res = bake(FlatMesh(Mesh(V, F, vertex_colors=colours), uv), px_per_mm=4, maps=())
    row = res.image[res.image.shape[0] // 2]
    assert tuple(row[5, :3]) == (255, 0, 0) and tuple(row[-6, :3]) == (0, 0, 255)
    mid = row[round((15 - res.origin[0]) * 4)]
    assert 64 < mid[0] < 192 and 64 < mid[2] < 192  # blended half way between the columns of vertices


def test_untextured_scan_is_baked_as_its_relief_with_a_legend():
    """A bump 0.3 mm high and a groove 0.2 mm deep on a plane: the untextured scan's image is its
    height in grey (the bump light, the groove dark, the plane between), a legend band below."""
    def z(x, y):
        return (0.3 * np.exp(-((x - 12) ** 2 + (y - 20) ** 2) / 2.0)
                - 0.2 * np.exp(-((x - 28) ** 2) / 0.5) * (np.abs(y - 20) < 10))
    V, F, uv = grid_mesh(40.0, 40.0, 0.25, z=z)
    res = bake(FlatMesh(Mesh(V, F), uv), px_per_mm=4, maps=())
    assert res.figures["painting"] == "relief"
    img = res.painting[..., 0].astype(int)
    at = lambda u, v: img[int((res.origin[1] - v) * 4), int((u - res.origin[0]) * 4)]
    assert at(12, 20) == 255 and at(28, 20) == 0 and 0 < at(5, 35) < 255
    assert len(res.image) > len(res.painting) + 50  # the legend
    lo, hi = res.figures["relief"]["grey_range_mm"]
    assert lo < -0.05 and 0 < hi < 0.3


# ---------------------------------------------------------------------------- rasteriser


def test_rasterizer_matches_reference():
    from scipy.spatial import Delaunay

    from potflat.raster import _kernels as raster

    rng = np.random.default_rng(3)
    pts = rng.uniform(0.3, 29.7, (40, 2))
    F = Delaunay(pts).simplices.astype(np.int64)
    W = H = 30
    ptr, idx = raster.bin_triangles(pts, F, 4.0, (H + 3) // 4)
    face = np.full((H, W), -1, np.int32)
    bary = np.zeros((H, W, 2))
    raster.rasterize_rows(pts, F, ptr, idx, 4, 0, H, W, 1e-9, face, bary)
    for r in range(H):
        for c in range(W):
            p = np.array([c + 0.5, r + 0.5])
            want = -1
            for f, (a, b, d) in enumerate(pts[F]):
                m = np.array([b - a, d - a]).T
                w1, w2 = np.linalg.solve(m, p - a)
                if min(w1, w2, 1 - w1 - w2) >= 0:
                    want = f
                    break
            assert face[r, c] == want
            if want >= 0:
                a, b, d = pts[F[want]]
                w1, w2 = bary[r, c]
                assert np.allclose((1 - w1 - w2) * a + w1 * b + w2 * d, p)


def test_chart_coverage_matches_reference():
    """The atlas' chart coverage marks exactly the texels whose centres lie in some triangle,
    with v up, on a texture that is not square, triangles overlapping, reaching past the
    texture's edges, and one of zero area."""
    from potflat.raster import _kernels as raster

    rng = np.random.default_rng(11)
    h, w = 23, 31
    tc = rng.uniform(-0.1, 1.1, (12, 3, 2))
    tc[1:] = tc[1:, :1] + 0.25 * (tc[1:] - tc[1:, :1])  # mostly small triangles, as in an atlas
    tc[5, 2] = tc[5, 0]  # zero area
    out = np.zeros((h, w), np.uint8)
    raster.cover_texcoords(np.ascontiguousarray(tc), 1e-9, out)
    want = np.zeros((h, w), np.uint8)
    for a, b, d in tc[[i for i in range(len(tc)) if i != 5]] * [w, -h] + [0, h]:  # raster x right, y down
        m = np.array([b - a, d - a]).T
        for r in range(h):
            for c in range(w):
                w1, w2 = np.linalg.solve(m, np.array([c + 0.5, r + 0.5]) - a)
                want[r, c] |= min(w1, w2, 1 - w1 - w2) >= 0
    assert 0 < want.sum() < want.size
    np.testing.assert_array_equal(out, want)


def test_face_values_columns_match_reference():
    """Every column of the per-face fields averaged over each pixel's covered sub-samples as a
    slow loop does it, and as the column alone (the maps' fields share one pass)."""
    from potflat.raster import _kernels as raster

    rng = np.random.default_rng(5)
    n, k, w, m = 3, 4, 5, 7
    face = rng.integers(-1, m, (k * n, w * n)).astype(np.int32)
    face[:n, :n] = -1  # a pixel with no covered sub-sample
    values = rng.normal(size=(m, 3))
    out = np.empty((k, w, 3), np.float32)
    raster.face_values(face, values, n, out)
    for r in range(k):
        for c in range(w):
            hit = face[r * n:(r + 1) * n, c * n:(c + 1) * n].ravel()
            hit = hit[hit >= 0]
            want = values[hit].mean(axis=0) if len(hit) else np.full(3, np.nan)
            np.testing.assert_allclose(out[r, c], want, rtol=1e-6)
    for j in range(3):
        alone = np.empty((k, w, 1), np.float32)
        raster.face_values(face, np.ascontiguousarray(values[:, j:j + 1]), n, alone)
        np.testing.assert_array_equal(alone[..., 0], out[..., j])


def test_strips_threads_and_reruns_give_identical_images(painted_plane, monkeypatch):
    import numba

    import potflat.raster.render as bake_mod

    whole = bake(painted_plane, px_per_mm=4, maps=("stress",))
    monkeypatch.setattr(bake_mod, "STRIP_SAMPLES", 4096)  # many small strips
    stripped = bake(painted_plane, px_per_mm=4, maps=("stress",))
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        serial = bake(painted_plane, px_per_mm=4, maps=("stress",))
    finally:
        numba.set_num_threads(threads)
    assert np.array_equal(whole.image, stripped.image) and np.array_equal(whole.image, serial.image)
    assert np.array_equal(whole.maps["stress"], stripped.maps["stress"], equal_nan=True)


# ---------------------------------------------------------------------------- options


@pytest.mark.parametrize("kwargs, match", [
    ({"px_per_mm": 4, "dpi": 300}, "not both"),
    ({"px_per_mm": -1}, "positive"),
    ({"dpi": 0}, "positive"),
    ({"px_per_mm": float("nan")}, "positive"),
    ({"maps": ("stress", "curl")}, "unknown map"),
    ({"supersample": 9}, "supersample"),
    ({"max_megapixels": -5}, "positive"),
])
def test_bad_options(kwargs, match):
    with pytest.raises(InvalidOptionError, match=match):
        BakeOptions(**kwargs)


def test_options_object_or_keywords_bake_the_same(painted_plane):
    by_keywords = bake(painted_plane, px_per_mm=3, maps=("area",))
    by_options = bake(painted_plane, options=BakeOptions(px_per_mm=3, maps=("area",)))
    assert np.array_equal(by_keywords.image, by_options.image)
    assert np.array_equal(by_keywords.maps["area"], by_options.maps["area"], equal_nan=True)
    with pytest.raises(InvalidOptionError, match="not both"):
        bake(painted_plane, options=BakeOptions(), px_per_mm=3)


def test_refuses_a_surface_reference_of_another_mesh(painted_plane):
    """The 3D side handed to the renderer must be its mesh's (equal arrays count too)."""
    from potflat.errors import InvalidInputError
    from potflat.mesh.distortion import SurfaceReference
    from potflat.raster.render import Renderer

    V, F = painted_plane.mesh.vertices, painted_plane.mesh.faces
    with pytest.raises(InvalidInputError, match="not of the flattening's mesh"):
        Renderer(painted_plane, 1.0, reference=SurfaceReference(V * 2.0, F))
    handed = Renderer(painted_plane, 1.0, reference=SurfaceReference(V.copy(), F.copy()))
    np.testing.assert_array_equal(handed.vertex_length_error, Renderer(painted_plane, 1.0).vertex_length_error)


def test_resolution_from_dpi_and_default():
    assert BakeOptions(dpi=254).resolution == pytest.approx(10.0)
    assert BakeOptions().resolution == 4.0
    assert BakeOptions(maps="area").maps == ("area",)
    assert BakeOptions(maps="none").maps == () and BakeOptions(maps=()).maps == ()


def test_refuses_non_finite_uv(painted_plane):
    from potflat.errors import InvalidInputError

    uv = painted_plane.uv.copy()
    uv[3, 0] = np.nan
    with pytest.raises(InvalidInputError, match="NaN"):
        bake(painted_plane.replace(uv=uv), px_per_mm=2)


def test_refuses_giant_image(painted_plane):
    with pytest.raises(InvalidOptionError, match="--px-per-mm .* or less"):
        bake(painted_plane, px_per_mm=2000)


# ---------------------------------------------------------------------------- stage files


@pytest.fixture(scope="module")
def stage_dir(tmp_path_factory, painted_plane):
    d = tmp_path_factory.mktemp("stage")
    rng = np.random.default_rng(0)
    noisy = painted_plane.replace(uv=painted_plane.uv + rng.normal(0, 0.2, painted_plane.uv.shape))
    write_flat_ply(d / "vase.rollout.ply", noisy)
    write_flat_ply(d / "vase.relaxed.ply", painted_plane)
    return d


def test_stage_writes_files_with_resolution(stage_dir, tmp_path):
    run_bake_stage(stage_dir / "vase.relaxed.ply", tmp_path,
                         BakeOptions(dpi=300, sheet=True, grid=True, tiff=True, position_map=True))
    ppm = 300 / 25.4
    names = {p.name for p in tmp_path.iterdir()}
    assert {"vase.png", "vase.stress.png", "vase.area.png", "vase.anisotropy.png", "vase.overlay.png",
            "vase.scale-layer.png", "vase.scalebar.png", "vase.tif", "vase.position.tif", "vase.sheet.png",
            "vase.bake.json"} <= names
    assert not any(n.endswith(".part") for n in names)
    main = Image.open(tmp_path / "vase.png")
    assert main.mode == "RGBA"
    assert main.info["dpi"] == pytest.approx((300, 300), abs=0.01)
    w, h = main.size
    for key in ("stress", "area", "anisotropy", "overlay"):
        im = Image.open(tmp_path / f"vase.{key}.png")
        assert im.size[0] == w and im.size[1] > h  # same grid, legend band below
        assert im.info["dpi"] == pytest.approx((300, 300), abs=0.01)
    assert Image.open(tmp_path / "vase.scale-layer.png").size == (w, h)
    summary = json.loads((tmp_path / "vase.bake.json").read_text())
    assert summary["image_px"] == [w, h]
    assert summary["px_per_mm"] == pytest.approx(ppm)
    assert summary["image_mm"][0] == pytest.approx(w / ppm)
    for key in ("stress", "area", "anisotropy"):
        assert {"mean", "p95", "max"} <= set(summary[key])
    assert summary["covered_area_mm2"] == pytest.approx(summary["flattened_area_mm2"], rel=0.01)
    assert summary["provenance"]["stage"] == "bake"
    assert any(i["path"].endswith("vase.relaxed.ply") for i in summary["provenance"]["inputs"])
    assert set(summary["files"].values()) <= names
    # the painting and its 16-bit TIFF agree; the position map matches bake()
    import tifffile

    tif = tifffile.imread(tmp_path / "vase.tif")
    png = np.asarray(main)
    assert tif.shape == png.shape and tif.dtype == np.uint16
    assert np.abs(tif.astype(float) / 257.0 - png).max() <= 1.0
    pos = tifffile.imread(tmp_path / "vase.position.tif")
    assert pos.shape == (h, w, 3) and pos.dtype == np.float32
    assert np.isnan(pos[png[..., 3] == 0]).all()
    inside = png[..., 3] == 255
    assert np.allclose(pos[inside][:, :2], bake(_flat(stage_dir), px_per_mm=ppm, maps=(),
                                                 position_map=True).position[inside][:, :2], atol=1e-4)


def _flat(stage_dir):
    from potflat.io.flat_ply import read_flat_ply

    return read_flat_ply(stage_dir / "vase.relaxed.ply")


def test_scalebar_is_a_round_length_at_true_scale(stage_dir, tmp_path):
    out = run_bake_stage(stage_dir / "vase.relaxed.ply", tmp_path, BakeOptions(px_per_mm=5, maps=()))
    bar_mm = out.record["scale_bar_mm"]
    assert bar_mm in (1, 2, 5, 10, 20, 50, 100, 200, 500)
    bar = np.asarray(Image.open(tmp_path / "vase.scalebar.png"))
    dark = (bar[..., :3].sum(-1) < 100)
    row = np.flatnonzero(dark.sum(axis=1) > 0)[0] + 1  # a row through the bar's outline
    cols = np.flatnonzero(dark[row])
    assert abs((cols[-1] - cols[0] + 1) - bar_mm * 5) <= 2


def test_rollout_input_gets_its_own_names(stage_dir, tmp_path):
    out = run_bake_stage(stage_dir / "vase.rollout.ply", tmp_path, BakeOptions(maps=("stress",)))
    assert out.paths["png"].name == "vase.rollout.png"
    assert (tmp_path / "vase.rollout.bake.json").is_file()
    with pytest.raises(InvalidOptionError, match="relaxed"):
        run_bake_stage(stage_dir / "vase.rollout.ply", tmp_path, BakeOptions(sheet=True))


def test_sheet_needs_the_rollout(tmp_path, painted_plane):
    from potflat.errors import InvalidInputError

    write_flat_ply(tmp_path / "lone.relaxed.ply", painted_plane)
    with pytest.raises(InvalidInputError, match="lone.rollout.ply"):
        run_bake_stage(tmp_path / "lone.relaxed.ply", tmp_path, BakeOptions(sheet=True))


def test_missing_texture_is_a_clear_error(tmp_path, painted_plane):
    from potflat.errors import InvalidInputError

    write_flat_ply(tmp_path / "t.relaxed.ply", painted_plane)
    (tmp_path / "t.texture.png").unlink()  # the texture as placed beside the stage file
    with pytest.raises(InvalidInputError, match="texture .* not found"):
        run_bake_stage(tmp_path / "t.relaxed.ply", tmp_path / "out", BakeOptions())


def test_cli(stage_dir, tmp_path):
    from potflat_cli.main import app
    from typer.testing import CliRunner

    runner = CliRunner()
    res = runner.invoke(app, ["bake", str(stage_dir / "vase.relaxed.ply"), "-o", str(tmp_path),
                              "--px-per-mm", "3", "--maps", "stress,area"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "vase.png").is_file() and (tmp_path / "vase.area.png").is_file()
    assert not (tmp_path / "vase.anisotropy.png").exists()
    assert Image.open(tmp_path / "vase.png").info["dpi"] == pytest.approx((76.2, 76.2), abs=0.01)
    bad = runner.invoke(app, ["bake", str(stage_dir / "vase.relaxed.ply"), "-o", str(tmp_path), "--dpi", "-3"])
    assert bad.exit_code == 2
    both = runner.invoke(app, ["bake", str(stage_dir / "vase.relaxed.ply"), "--dpi", "300", "--px-per-mm", "3"])
    assert both.exit_code == 2
    assert "Example" in runner.invoke(app, ["bake", "--help"]).output
    quiet = runner.invoke(app, ["bake", str(stage_dir / "vase.relaxed.ply"), "-o", str(tmp_path / "j"),
                                "--maps", "none", "--json"])
    assert quiet.exit_code == 0, quiet.output
    assert json.loads(quiet.output)["files"]["png"] == "vase.png"
    assert not (tmp_path / "j" / "vase.stress.png").exists()


def test_masked_halving_matches_reference():
    from potflat.raster.render import _halve_masked

    rng = np.random.default_rng(5)
    img = rng.integers(0, 256, (7, 9, 3), dtype=np.uint8)
    valid = rng.random((7, 9)) < 0.6
    out = np.empty((4, 5, 3), np.uint8)
    ok = _halve_masked(img, valid, out)
    for r in range(4):
        for c in range(5):
            blk = (slice(2 * r, 2 * r + 2), slice(2 * c, 2 * c + 2))
            m = valid[blk]
            assert ok[r, c] == m.any()
            if m.any():
                want = img[blk][m].mean(axis=0)
                assert np.abs(out[r, c].astype(float) - want).max() <= 0.5


def test_pull_fill_matches_reference():
    """The texels outside the charts take the next coarser level's bilinear upsampling, the
    coarsest level's the mean of its charts; the texels in the charts keep their values."""
    import cv2

    from potflat.raster.render import _pull_fill

    rng = np.random.default_rng(6)
    for dtype in (np.uint8, np.uint16):
        shapes = [(13, 17), (7, 9), (4, 5)]
        levels = [rng.integers(0, np.iinfo(dtype).max, s + (3,)).astype(dtype) for s in shapes]
        valids = [rng.random(s) < 0.5 for s in shapes]
        want = [lv.copy() for lv in levels]
        want[-1][~valids[-1]] = want[-1][valids[-1]].mean(axis=0).round().astype(dtype)
        for k in (1, 0):
            up = cv2.resize(want[k + 1], shapes[k][::-1], interpolation=cv2.INTER_LINEAR)
            want[k] = np.where(valids[k][..., None], want[k], up)
        _pull_fill(levels, valids)
        for got, ref in zip(levels, want):
            np.testing.assert_array_equal(got, ref)


def test_collapsed_flat_triangle_keeps_the_json_valid(tmp_path):
    V, F, uv = grid_mesh(10.0, 10.0, 5.0)
    uv = uv.copy()
    uv[4] = uv[1]  # the centre vertex onto a neighbour: faces collapse to segments
    write_flat_ply(tmp_path / "c.relaxed.ply", FlatMesh(Mesh(V, F), uv))
    out = run_bake_stage(tmp_path / "c.relaxed.ply", tmp_path, BakeOptions(px_per_mm=2))
    summary = json.loads((tmp_path / "c.bake.json").read_text())
    assert summary["distortion"]["anisotropy_max"] is None  # infinite
    assert out.record["anisotropy"]["max"] >= 1e6
