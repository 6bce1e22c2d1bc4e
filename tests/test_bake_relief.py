"""The relief's images (potflat.bake.relief) and their known answers from
potflat_synthetic.relief: grooves 0.1-0.2 mm deep and 0.5 mm wide and dots on a hydria's
shoulder, with and without scanner noise, whole vessels for the form; the options and files."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import tifffile
from PIL import Image

import reference
from potflat.bake import bake
from potflat.bake.options import BakeOptions
from potflat.errors import InvalidOptionError
from potflat.mesh import relief as R
from potflat.types import FlatMesh, Mesh
from potflat_synthetic.relief import relief_patch, relief_vessel
from test_relief import _plane_mesh

#: Resolution of the known-answer bakes: 0.05 mm pixels, ten across a 0.5 mm groove.
PPM = 20.0
#: Scanner noise of the noisy patch (mm, along the normal per vertex).
NOISE = 0.02


def test_default_smoothing_is_the_bake_default():
    assert BakeOptions().relief_mm == R.SMOOTHING_MM


# ----------------------------------------------------------------------------- known answers


@pytest.fixture(scope="module")
def patches():
    """The hydria's shoulder with grooves (0.2 x 0.5 mm, 0.1 x 0.5 mm) and dots (0.2 and 0.5
    mm high, 0.5 mm across), without and with noise, baked at 20 px/mm."""
    out = {}
    for noise in (0.0, NOISE):
        sc = relief_patch(size_mm=24.0, grooves=((0.2, 0.5), (0.1, 0.5)), dots=((0.2, 0.5), (0.5, 0.5)),
                          noise_mm=noise, seed=7)
        out[noise] = sc, bake(sc.flat, px_per_mm=PPM, maps=(), position_map=True, relief=True)
    return out


def _truth_image(sc, res):
    """The decoration's displacement under each pixel (NaN outside)."""
    P = res.position.reshape(-1, 3)
    inside = np.isfinite(P[:, 0])
    truth = np.full(len(P), np.nan)
    truth[inside] = sc.relief_at(P[inside])
    return truth.reshape(res.position.shape[:2])


def _distance_to(sc, feature, res):
    """Each pixel's distance (mm, along the wall) from a groove's centre line or a dot's centre
    (NaN outside, inf off a groove's span)."""
    P = res.position.reshape(-1, 3)
    d = np.full(len(P), np.nan)
    inside = np.isfinite(P[:, 0])
    d[inside] = sc.distance_on_wall(feature, P[inside])
    return d.reshape(res.position.shape[:2])


@pytest.mark.parametrize("noise", [0.0, NOISE])
def test_grooves_stand_out_five_times_above_the_noise(patches, noise):
    """Every groove 0.2 mm deep and 0.5 mm wide, in the untextured scan's image: its darkening
    at least 5 times the grey levels' spread on the plain wall."""
    sc, res = patches[noise]
    grey = res.painting[..., 0].astype(float)
    truth = _truth_image(sc, res)
    plain = (truth == 0) & (res.painting[..., 3] == 255)
    plain &= cv2.erode(plain.astype(np.uint8), np.ones((21, 21), np.uint8)).astype(bool)  # 0.5 mm clear
    level, spread = np.median(grey[plain]), max(grey[plain].std(), 0.5)
    for groove in (g for g in sc.grooves if (g.depth, g.width) == (0.2, 0.5)):
        centre = (_distance_to(sc, groove, res) < 0.03) & (res.painting[..., 3] == 255)
        contrast = level - np.median(grey[centre])
        assert contrast >= 5 * spread, (groove, contrast, spread)


def test_relief_lies_where_the_decoration_is(patches):
    """Across each groove the deepest pixel, and at each dot the highest, within 0.5 mm of the
    truth (on the surface: the image is at true scale)."""
    sc, res = patches[NOISE]
    height = res.relief_height
    for groove in sc.grooves:
        d = _distance_to(sc, groove, res)
        near = d < 1.5
        rows = np.flatnonzero(near.any(axis=1)) if groove.direction == "meridian" else np.flatnonzero(near.any(axis=0))
        misses = []
        for k in rows[len(rows) // 10: -len(rows) // 10]:  # off the ends of the line
            line = np.where(near[k], height[k], np.inf) if groove.direction == "meridian" else \
                np.where(near[:, k], height[:, k], np.inf)
            j = int(np.argmin(line))
            misses.append(d[k, j] if groove.direction == "meridian" else d[j, k])
        assert np.percentile(misses, 95) < 0.5 and np.median(misses) < 0.1, groove
    for dot in sc.dots:
        dist = _distance_to(sc, dot, res)
        near = np.where(dist < 1.5, height, -np.inf)
        r, c = np.unravel_index(np.argmax(near), near.shape)
        assert dist[r, c] < 0.5, dot


@pytest.mark.parametrize("noise", [0.0, NOISE])
def test_depth_read_off_the_tiff_within_a_fifth(patches, noise, tmp_path):
    """The 16-bit TIFF, read with its scale from the JSON: each groove's depth along its centre
    line and each dot's height at its top within 20% of the truth."""
    from potflat.files.bake_stage import run_bake_stage
    from potflat.io.flat_ply import write_flat_ply

    sc, res = patches[noise]
    ply = write_flat_ply(tmp_path / "patch.relaxed.ply", sc.flat)
    files = run_bake_stage(ply, tmp_path / "out", BakeOptions(px_per_mm=PPM, maps=(), position_map=True,
                                                               relief=True))
    scale = files.record["relief"]["tiff"]
    with tifffile.TiffFile(files.paths["relief_tif"]) as tif:
        levels = tif.asarray()
        described = json.loads(tif.pages[0].description)
    assert levels.dtype == np.uint16 and described["mm_per_level"] == scale["mm_per_level"]
    height = np.where(levels > 0, (levels.astype(float) - scale["zero_level"]) * scale["mm_per_level"], np.nan)
    np.testing.assert_allclose(height, res.relief_height, atol=scale["mm_per_level"], equal_nan=True)
    for groove in sc.grooves:
        centre = _distance_to(sc, groove, res) < 0.03
        assert -np.nanmedian(height[centre]) == pytest.approx(groove.depth, rel=0.2), groove
    for dot in sc.dots:
        top = _distance_to(sc, dot, res) < 0.04
        assert np.nanmedian(height[top]) == pytest.approx(dot.height, rel=0.2), dot


@pytest.mark.parametrize("kind, vertices", [("sphere", 30000), ("hydria", 250000)])
def test_the_vessels_form_leaves_no_gradient(kind, vertices):
    """A whole bulgy hydria (400 mm tall) and a spherical body, scanned with noise, rolled out and
    relaxed: the untextured image against the image of the truth (here: noise only), smoothed
    over 10 mm, varies by at most 5% of the grey range (within 10 mm of the outline, too)."""
    from potflat.relax import relax
    from potflat.rollout import rollout

    sc = relief_vessel(kind, n_vertices=vertices, grooves=(), dots=(), noise_mm=NOISE, seed=3)
    flat = relax(rollout(sc.mesh).flat).flat
    ppm = 2.0
    res = bake(flat, px_per_mm=ppm, maps=(), position_map=True)
    assert res.figures["relief"]["smoothing_mm"] == R.SMOOTHING_MM
    covered = res.painting[..., 3] == 255
    lo, hi = res.figures["relief"]["grey_range_mm"]
    error = np.where(covered, res.painting[..., 0] / 255.0 - (0.0 - lo) / (hi - lo), 0.0)  # the truth: 0 mm
    blur = 10.0 * ppm
    low = cv2.GaussianBlur(error, (0, 0), blur) / np.maximum(cv2.GaussianBlur(covered * 1.0, (0, 0), blur), 1e-9)
    inner = cv2.erode(covered.astype(np.uint8), np.ones((int(2 * blur) + 1,) * 2, np.uint8)).astype(bool)
    p1, p99 = np.percentile(low[inner], [1, 99])
    assert p99 - p1 <= 0.05, (kind, p1, p99)


# ----------------------------------------------------------------------------- images


def _bump_scan(colours=False):
    """A bump 0.4 mm high on a 30 mm square, untextured or painted in vertex colours."""
    V, F, uv = _plane_mesh(20000, 30.0, lambda x, y: 0.4 * np.exp(-((x - 15) ** 2 + (y - 15) ** 2) / 2.0))
    mesh = Mesh(V, F, vertex_colors=np.tile([200, 60, 20, 255], (len(V), 1)).astype(np.uint8) if colours else None)
    return FlatMesh(mesh, uv)


def test_relief_rows_kernel_matches_reference():
    from potflat.bake._kernels import relief_rows

    rng = np.random.default_rng(4)
    k, w = 7, 9
    fields = rng.normal(0, 0.3, (k, w, 5)).astype(np.float32)
    fields[..., 3] += 1.0
    fields[0, :3] = np.nan
    coverage = np.where(np.isnan(fields[..., 0]), 0, rng.uniform(0.2, 1, (k, w))).astype(np.float32)
    rgb = rng.uniform(0, 1, (k, w, 3)).astype(np.float32)
    rgb[0, :3] = np.nan
    lights = np.array([[-0.66, 0.66, 0.34], [0.0, -0.94, 0.34]])
    args = (fields, coverage, lights, 1.46, 0.2, 0.4, rgb, -0.4, 1.25, 0.3, 0.001, 32768)
    raking, curvature = np.empty((2, k, w, 2), np.uint8), np.empty((k, w, 2), np.uint8)
    overlay, levels = np.empty((k, w, 4), np.uint8), np.empty((k, w), np.uint16)
    relief_rows(*args[:10], True, *args[10:], raking, curvature, overlay, levels)
    for got, want in zip((raking, curvature, overlay, levels), reference.relief_rows(*args)):
        np.testing.assert_array_equal(got, want)


def test_raking_light_comes_from_the_azimuth_given():
    res = bake(_bump_scan(), px_per_mm=4, maps=(), relief=True, relief_light=(315, 135))
    at = lambda img, u, v: int(img[int((res.origin[1] - v) * 4), int((u - res.origin[0]) * 4), 0])
    nw, se = res.relief_images["raking-315"], res.relief_images["raking-135"]
    assert nw.shape[2] == 2  # grey and alpha
    assert at(nw, 14, 16) > at(nw, 5, 5) + 40 > at(nw, 16, 14) + 80  # lit from the upper left
    assert at(se, 16, 14) > at(se, 5, 5) + 40 > at(se, 14, 16) + 80
    assert abs(at(nw, 5, 5) - 128) <= 2  # a plane at mid grey


def test_overlay_blends_painting_and_relief():
    flat = _bump_scan(colours=True)
    images = [bake(flat, px_per_mm=4, maps=(), relief=True, relief_blend=b).relief_images["relief-overlay"]
              for b in (0.0, 0.5, 1.0)]
    painting = bake(flat, px_per_mm=4, maps=()).image
    np.testing.assert_array_equal(images[0], painting)
    grey = images[2][..., :3].astype(int)
    assert (grey[..., 0] == grey[..., 2]).all()  # the relief in grey
    np.testing.assert_allclose(images[1][..., :3].astype(int), (painting[..., :3].astype(int) + grey) / 2, atol=1)


def test_painted_scan_keeps_its_painting_without_relief():
    flat = _bump_scan(colours=True)
    res = bake(flat, px_per_mm=4, maps=())
    assert res.figures["relief"] is None and res.relief_images == {} and len(res.image) == len(res.painting)


# ----------------------------------------------------------------------------- options


@pytest.mark.parametrize("fields, message", [
    ({"relief_mm": 0}, "relief_mm must be"),
    ({"relief_mm": float("nan")}, "relief_mm must be"),
    ({"relief_light": ()}, "relief_light must be"),
    ({"relief_light": (315, "north")}, "relief_light must be"),
    ({"relief_light": tuple(range(9))}, "relief_light must be"),
    ({"relief_blend": 1.5}, "relief_blend must be"),
    ({"relief": "yes"}, "relief must be true or false"),
    ({"plate_image": "photo", "relief": True}, "unknown plate_image"),
    ({"plate_image": "relief"}, "add relief"),
])
def test_relief_options_are_checked(fields, message):
    with pytest.raises(InvalidOptionError, match=message):
        BakeOptions(**fields)


def test_relief_light_is_taken_modulo_a_turn():
    assert BakeOptions(relief_light=(-45, 405, 45)).relief_light == (315.0, 45.0)


def test_relief_on_the_command_line(tmp_path):
    from typer.testing import CliRunner

    from potflat.io.flat_ply import write_flat_ply
    from potflat_cli.main import app

    ply = write_flat_ply(tmp_path / "bump.relaxed.ply", _bump_scan())
    result = CliRunner().invoke(app, ["bake", str(ply), "-o", str(tmp_path / "out"), "--relief", "--relief-mm", "3",
                                      "--relief-light", "90,270", "--maps", "none", "--quiet"])
    assert result.exit_code == 0, result.output
    record = json.loads((tmp_path / "out" / "bump.bake.json").read_text())
    assert record["relief"]["smoothing_requested_mm"] == 3.0 and record["relief"]["light_azimuth_deg"] == [90.0, 270.0]
    assert record["provenance"]["options"]["relief_light"] == [90.0, 270.0]
    for name in ("relief.tif", "relief.png", "raking-90.png", "raking-270.png", "curvature.png"):
        assert f"bump.{name}" in record["files"].values(), name
    assert "bump.relief-overlay.png" not in record["files"].values()  # untextured: no painting to blend
    png = Image.open(tmp_path / "out" / "bump.png")
    assert png.size[1] > record["image_px"][1]  # the legend in mm below the relief
    bad = CliRunner().invoke(app, ["bake", str(ply), "-o", str(tmp_path / "bad"), "--relief-blend", "2"])
    assert bad.exit_code == 2 and "relief_blend" in bad.output
