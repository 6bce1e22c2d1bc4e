"""The archaeological plate (potflat.files.plate), the scale bar on the image and the profile step."""
from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from potflat import __version__
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.bake.options import parse_scale
from potflat.files.plate import PREVIEW_DPI, make_plate, scale_label
from potflat.mesh.distortion import PAINTED_ZONE_KEY, distortion_words, painted_zone_distortion
from potflat_cli.main import app

PT_PER_MM = 72 / 25.4


@pytest.fixture(scope="module")
def cup_run(tmp_path_factory):
    """A small two-walled cup run through every stage, with the plate at 1:2 and the bar on the image."""
    from potflat.files.pipeline import run_scan
    from potflat_synthetic.vessels import make_vessel, write_obj

    root = tmp_path_factory.mktemp("plate")
    write_obj(make_vessel("cup", n_vertices=1500, texture_size=128, seed=3), root / "scans" / "cup.obj")
    result = run_scan(root / "scans" / "cup.obj", root / "out", relax={"preset": "preview"},
                      bake={"px_per_mm": 2, "plate": True, "plate_scale": "1:2", "scale_on_image": True,
                            "maps": ("stress",)})
    return result


def _svg_size_mm(path):
    root = ET.parse(path).getroot()
    return tuple(float(root.get(k).removesuffix("pt")) / PT_PER_MM for k in ("width", "height"))


def test_plate_pages_are_at_print_size(cup_run):
    out, bake = cup_run.out_dir, cup_run.bake.record
    page = bake["plate"]["page_mm"]
    assert _svg_size_mm(out / "cup.plate.svg") == pytest.approx(page, abs=0.01)
    media = re.search(rb"/MediaBox \[ 0 0 ([\d.]+) ([\d.]+) \]", (out / "cup.plate.pdf").read_bytes())
    assert (float(media[1]) / PT_PER_MM, float(media[2]) / PT_PER_MM) == pytest.approx(page, abs=0.01)
    png = Image.open(out / "cup.plate.png")
    assert png.size == pytest.approx([p / 25.4 * PREVIEW_DPI for p in page], abs=1.5)


def test_plate_rollout_is_at_the_stated_scale(cup_run):
    """The embedded rollout is NAME.png, unresampled, drawn at half its true size (1:2)."""
    out, bake = cup_run.out_dir, cup_run.bake.record
    w_px, h_px = Image.open(out / "cup.png").size
    ns = {"svg": "http://www.w3.org/2000/svg"}
    images = ET.parse(out / "cup.plate.svg").getroot().findall(".//svg:image", ns)
    assert len(images) == 2  # outside view and rollout
    roll = [im for im in images if (int(im.get("width")), int(im.get("height"))) == (w_px, h_px)]
    assert len(roll) == 1, "the rollout is embedded with its own pixels"
    k = float(re.match(r"matrix\(([\d.]+) ", roll[0].get("transform"))[1])  # pt per pixel
    mm_per_px_on_paper = k / PT_PER_MM
    assert mm_per_px_on_paper == pytest.approx(0.5 / bake["px_per_mm"], rel=1e-3)


def test_plate_svg_text_caption_and_vector_profile(cup_run):
    svg = (cup_run.out_dir / "cup.plate.svg").read_text()
    texts = " ".join(re.findall(r"<text[^>]*>([^<]*)</text>", svg))
    for words in ("cup", "computed from a 3D scan", f"potflat {__version__}", "proxy", "preset preview",
                  "Distortion in the whole surface", "lengths off by", "Scale 1:2", "10 cm"):
        assert words in texts, words
    assert "data:image/png;base64," in svg
    assert len(re.findall(r"<path ", svg)) >= 6  # section, outer lines, axis, scale bar blocks
    summary = cup_run.bake.record
    assert summary["files"]["plate_svg"] == "cup.plate.svg"
    assert summary["plate"]["scale_label"] == "1:2"


def test_plate_is_reproducible_with_source_date_epoch(cup_run, tmp_path, monkeypatch):
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "0")
    relaxed = cup_run.out_dir / "cup.relaxed.ply"
    a = make_plate(relaxed, cup_run.out_dir, scale="1:2", name="cup")
    first = a.paths["svg"].read_bytes()
    b = make_plate(relaxed, cup_run.out_dir, scale="1:2", name="cup")
    assert b.paths["svg"].read_bytes() == first
    assert "1970-01-01" in first.decode()


def test_plate_auto_scale_fits_a4(cup_run):
    plate = make_plate(cup_run.out_dir / "cup.relaxed.ply", cup_run.out_dir, name="cup")
    w, h = plate.record["page_mm"]
    assert plate.record["scale"] in (1.0, 0.5, 1 / 3, 0.25, 0.2, 0.1, 0.05, 0.02)
    assert w <= 210 and h <= 297 and plate.record["paper"] == "A4"  # the whole page, caption included
    assert plate.record["scale"] <= 0.5  # the cup's rollout is wider than 180 mm at 1:1


def test_a_plate_larger_than_a4_says_so_and_names_the_scales_that_fit(cup_run):
    """At 1:1 the cup's page is larger than A3: the command says so, with the largest scale that
    fits A4 and A3, and the record keeps the paper and those scales."""
    res = CliRunner().invoke(app, ["plate", str(cup_run.out_dir / "cup.relaxed.ply"), "--scale", "1:1"],
                             env={"COLUMNS": "300"})
    assert res.exit_code == 0, res.output
    record = json.loads((cup_run.out_dir / "cup.bake.json").read_text())["plate"]  # (the run's, at 1:2)
    plate = make_plate(cup_run.out_dir / "cup.relaxed.ply", cup_run.out_dir, scale="1:1", name="cup").record
    a4, a3 = plate["largest_scale_on"]["A4"], plate["largest_scale_on"]["A3"]
    assert plate["paper"] is None and a4 and a3 and record["paper"] in ("A4", "A3", None)
    assert f"larger than A3: {a4} fits A4, {a3} fits A3" in " ".join(res.stdout.split())


def test_plate_cli_and_its_errors(cup_run, tmp_path):
    runner = CliRunner()
    res = runner.invoke(app, ["plate", str(cup_run.out_dir / "cup.relaxed.ply"), "--scale", "1:3", "--json"])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["scale_label"] == "1:3"
    res = runner.invoke(app, ["plate", str(cup_run.out_dir / "cup.rollout.ply")])
    assert res.exit_code == 2 and "NAME.relaxed.ply" in res.stderr
    res = runner.invoke(app, ["plate", str(cup_run.out_dir / "cup.relaxed.ply"), "--scale", "1:0"])
    assert res.exit_code == 2 and "not a scale" in res.stderr
    # the bake outputs are looked for in -o
    res = runner.invoke(app, ["plate", str(cup_run.out_dir / "cup.relaxed.ply"), "-o", str(tmp_path)])
    assert res.exit_code == 2 and "bake it first" in res.stderr
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("value, expected", [("1:2", 0.5), ("1/5", 0.2), (0.25, 0.25), ("2:1", 2.0),
                                             (None, None), ("auto", None)])
def test_parse_scale(value, expected):
    assert parse_scale(value) == expected


@pytest.mark.parametrize("value", ["1:0", "half", "-1:2", "0", "nan", 65])
def test_parse_scale_rejects(value):
    with pytest.raises(InvalidOptionError):
        parse_scale(value)


def test_scale_label():
    assert [scale_label(s) for s in (1.0, 0.5, 0.2, 0.4, 2.0)] == ["1:1", "1:2", "1:5", "1:2.5", "2:1"]


def test_painted_zone_figures_are_preferred():
    whole = {"edge_rms": 0.2, "flipped": 0}
    assert painted_zone_distortion({"distortion": whole}) == (whole, "whole surface")
    zone = {"area_fraction": 0.3, "length_error_median_pct": 1.5, "length_error_p95_pct": 4.0,
            "distortion": {"edge_rms": 0.05, "flipped": 0}}
    figures, where = painted_zone_distortion({"distortion": whole, PAINTED_ZONE_KEY: zone})
    assert where == "painted zone" and figures["edge_rms"] == 0.05
    assert distortion_words(figures).startswith("lengths off by 1.5 % (median), at most 4.0 % over 95 %")
    everywhere = {**zone, "area_fraction": 1.0}
    assert painted_zone_distortion({"distortion": whole, PAINTED_ZONE_KEY: everywhere})[1] == "whole surface"
    assert distortion_words(whole) == "length error 20.0 % RMS, 0 folded triangles"


def test_scale_on_image_covers_no_painting(cup_run, tmp_path):
    """NAME.png with the bar differs from the plain bake only where the painting is transparent."""
    from potflat.bake import BakeOptions
    from potflat.files.bake_stage import run_bake_stage

    run_bake_stage(cup_run.out_dir / "cup.relaxed.ply", tmp_path, BakeOptions(px_per_mm=2, maps=()))
    plain = np.asarray(Image.open(tmp_path / "cup.png"))
    barred = np.asarray(Image.open(cup_run.out_dir / "cup.png"))
    assert barred.shape == plain.shape  # a free place was found: no band
    changed = np.any(barred != plain, axis=2)
    assert changed.sum() > 500  # the bar and its labels are there
    assert (plain[changed, 3] == 0).all()
    info = cup_run.bake.record["scale_on_image"]
    assert info["band_below_px"] == 0


def test_scale_on_image_adds_a_band_when_the_painting_fills_the_image(tmp_path):
    from potflat.bake import BakeOptions
    from potflat.files.bake_stage import run_bake_stage
    from potflat.io.flat_ply import write_flat_ply
    from potflat.types import FlatMesh, Mesh

    xs, ys = np.meshgrid(np.linspace(0, 60, 13), np.linspace(0, 30, 7))
    V = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    q = (np.arange(6)[:, None] * 13 + np.arange(12)[None, :]).ravel()
    F = np.concatenate([np.stack([q, q + 1, q + 14], 1), np.stack([q, q + 14, q + 13], 1)])
    colours = np.full((len(V), 4), 200, np.uint8)
    write_flat_ply(tmp_path / "flat.relaxed.ply", FlatMesh(Mesh(V, F, vertex_colors=colours), V[:, :2]))
    out = run_bake_stage(tmp_path / "flat.relaxed.ply", tmp_path / "o", BakeOptions(px_per_mm=4, maps=(),
                                                                                    scale_on_image=True))
    band = out.record["scale_on_image"]["band_below_px"]
    w, h = out.record["image_px"]
    img = np.asarray(Image.open(out.paths["png"]))
    assert band > 0 and img.shape[:2] == (h + band, w)
    assert (img[h:, :, 3] > 0).any()  # the bar is in the band
    plain = run_bake_stage(tmp_path / "flat.relaxed.ply", tmp_path / "p", BakeOptions(px_per_mm=4, maps=()))
    assert np.array_equal(np.asarray(Image.open(plain.paths["png"])), img[:h])


def test_profile_step_follows_the_edges_or_the_option(cup_run, tmp_path):
    from potflat.rollout.profile import read_profile_csv
    from potflat.rollout import RolloutOptions
    from potflat.files.rollout_stage import run_rollout_stage

    summary = cup_run.rollout.record["profile"]
    csv = cup_run.out_dir / "cup.profile.csv"
    prof = read_profile_csv(csv, summary)
    assert np.median(np.diff(prof.heights)) == pytest.approx(summary["bin_mm"], rel=1e-3)
    assert prof.two_walled and np.isfinite(prof.floor_height)
    fine = run_rollout_stage(cup_run.scan, tmp_path, RolloutOptions(profile_mm=1.0))
    assert fine.record["profile"]["bin_mm"] == pytest.approx(1.0, rel=0.05)
    assert fine.record["profile"]["bins"] > 3 * summary["bins"]
    with pytest.raises(InvalidOptionError):
        RolloutOptions(profile_mm=0)
    (tmp_path / "bad.csv").write_text("a,b\n")
    with pytest.raises(InvalidInputError):
        read_profile_csv(tmp_path / "bad.csv", {})


def test_plate_shows_the_relief_beside_the_painting(cup_run, tmp_path):
    """plate_image both: the painting and, below it, the relief in raking light from the first
    azimuth, each at the plate's scale; relief alone: only the raking light."""
    from potflat.bake.options import BakeOptions
    from potflat.files.bake_stage import run_bake_stage

    relaxed = cup_run.out_dir / "cup.relaxed.ply"
    files = run_bake_stage(relaxed, tmp_path, BakeOptions(px_per_mm=2, maps=(), relief=True, relief_light=(45, 315),
                                                          plate=True, plate_scale="1:2", plate_image="both"))
    plate = files.record["plate"]
    assert plate["rollout_images"] == ["painting", "relief in raking light from 45 degrees"]
    ns = {"svg": "http://www.w3.org/2000/svg"}
    images = ET.parse(tmp_path / "cup.plate.svg").getroot().findall(".//svg:image", ns)
    w_px, h_px = Image.open(tmp_path / "cup.png").size
    assert len(images) == 3  # outside view, painting, relief
    assert sum((int(im.get("width")), int(im.get("height"))) == (w_px, h_px) for im in images) == 2
    alone = make_plate(relaxed, tmp_path, scale="1:2", name="cup", image="relief")
    assert alone.record["rollout_images"] == ["relief in raking light from 45 degrees"]
    assert alone.record["page_mm"][1] < plate["page_mm"][1]


def test_plate_of_the_relief_needs_a_bake_with_relief(cup_run):
    with pytest.raises(InvalidInputError, match="bake it with --relief first"):
        make_plate(cup_run.out_dir / "cup.relaxed.ply", cup_run.out_dir, name="cup", image="relief")
