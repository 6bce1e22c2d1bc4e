"""The figures README.md and docs/guide.md quote are the figures the code gives.

Each test runs what a document describes (the bundled sample through ``potflat run``, the
guide's real-scan example) or reads the defaults it quotes, and checks that the document
says what comes out, at the precision it prints. A failure names the text the document
should have. Timings are not checked here: the benchmarks write them between markers
(``benchmarks/_docs.py``), and the last tests check that those markers are in place.
"""
from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest
from typer.testing import CliRunner

from potflat_cli.main import app

from _bench_meshes import figures

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "samples" / "data" / "amphora.obj"
#: The real scans sit beside the checkout (``../shared/data/real``).
REAL = ROOT.parent / "shared" / "data" / "real"


def read(doc: str) -> str:
    """A document's text with every run of white space made one space (lines wrap anywhere)."""
    return " ".join((ROOT / doc).read_text().split())


def says(doc: str, *texts: str) -> None:
    """Assert that ``doc`` contains each of ``texts`` (white space as in :func:`read`)."""
    body = read(doc)
    missing = [t for t in texts if " ".join(t.split()) not in body]
    assert not missing, f"{doc} should say: " + " | ".join(missing)


def span(lo: float, hi: float, digits: int) -> str:
    return f"{lo:.{digits}f}–{hi:.{digits}f}"


@pytest.fixture(scope="module")
def sample(tmp_path_factory):
    """The guide's plate command on the bundled amphora: its output folder."""
    out = tmp_path_factory.mktemp("sample")
    result = CliRunner().invoke(app, ["run", str(SAMPLE), "-o", str(out), "--plate", "--scale-on-image", "--quiet"])
    assert result.exit_code == 0, result.output
    return out


def test_the_sample_figures_in_the_readme_and_the_guide(sample):
    from potflat import read_flat_ply
    from potflat.mesh.distortion import zone_figures

    relaxed = json.loads((sample / "amphora.relaxed.json").read_text())
    zone = relaxed["important_zone"]
    circles = figures.measure_figures(read_flat_ply(sample / "amphora.relaxed.ply"),
                                      figures.truth_circles(SAMPLE.with_suffix(".truth.json")))
    sizes = f"{span(*circles.width_mm, 1)} x {span(*circles.height_mm, 1)} mm"
    rolled = read_flat_ply(sample / "amphora.rollout.ply")
    before = zone_figures(rolled.mesh.vertices, rolled.uv, rolled.mesh.faces, rolled.importance)["important"]
    proxy = json.loads((sample / "amphora.rollout.json").read_text())["proxy"]["type"]
    assert relaxed["flipped"] == 0
    says("README.md", f"the {proxy} rollout (left) squeezes the painted frieze",
         f"lengths there off by {before.length_error_median_pct:.0f}% in the median",
         f"lengths off by {zone['length_error_median_pct']:.1f}% in the median, "
         f"{zone['length_error_p95_pct']:.1f}% at the 95th percentile",
         f"the frieze's 20 mm circles come out {sizes}", "no folded triangle")
    says("docs/guide.md", f"the frieze's 20 mm circles come out {sizes}", relaxed["lengths"].split(";")[0])


def test_the_plate_profile_and_scale_bar_of_the_sample_in_the_guide(sample):
    bake = json.loads((sample / "amphora.bake.json").read_text())
    plate = bake["plate"]
    (w, h), (pw, ph), (rw, rh) = bake["image_mm"], plate["page_mm"], plate["rollout_mm"]
    rows = len((sample / "amphora.profile.csv").read_text().splitlines()) - 1
    assert plate["profile_rows"] == rows
    says("docs/guide.md",
         f"is {plate['scale_label']}, the largest at which drawing and rollout ({w:.1f} x {h:.1f} mm on the vessel)",
         f"the page is {pw:.1f} x {ph:.1f} mm and the rollout is drawn {rw:.1f} x {rh:.1f} mm",
         f"{plate['profile_step_mm']:.1f} mm on the coarse bundled amphora, {rows} rows",
         f"({bake['scale_on_image']['bar_mm']:.0f} mm on the bundled amphora at {bake['px_per_mm']:g} px/mm")


def test_the_springs_alone_on_the_sample_in_the_guide():
    from potflat import load_scan
    from potflat.relax import relax
    from potflat.rollout import rollout

    flat = rollout(load_scan(SAMPLE).mesh, importance="none").flat
    springs = relax(flat, shape=0.0, rigidity=0.0, area=0.0, importance_contrast=1.0, true_scale=False).flat
    m = figures.measure_figures(springs, figures.truth_circles(SAMPLE.with_suffix(".truth.json")))
    says("docs/guide.md", f"({span(*m.width_mm, 0)} x {span(*m.height_mm, 0)} mm with the springs alone)")


@pytest.mark.skipif(not (REAL / "sea-vase.ply").is_file(), reason=f"no real scans in {REAL}")
def test_the_sea_vase_example_in_the_guide(tmp_path):
    """``potflat run ../shared/data/real/sea-vase.ply -o out --px-per-mm 2``, as the guide shows it."""
    result = CliRunner().invoke(app, ["run", str(REAL / "sea-vase.ply"), "-o", str(tmp_path), "--px-per-mm", "2",
                                      "--quiet"])
    assert result.exit_code == 0, result.output
    roll = json.loads((tmp_path / "sea-vase.rollout.json").read_text())
    relaxed = json.loads((tmp_path / "sea-vase.relaxed.json").read_text())
    bake = json.loads((tmp_path / "sea-vase.bake.json").read_text())
    walls, att, trim, tangle = roll["walls"], roll["attachments"], roll["trimmed"], roll["untangled"]
    (lo, hi), = {tuple(c["height_mm"]) for c in att["components"]}
    proxy = roll["proxy"]["type"]
    (w, h) = bake["image_mm"]
    assert relaxed["flipped"] == 0 and relaxed["boundary_overlap"] == 0
    says("docs/guide.md",
         f"{roll['cleaning']['input_faces'] / 1000:.0f}k faces, no texture",
         f"{w:.1f} x {h:.1f} mm, with the bake's",
         f"| walls | two-walled ({walls['faces_outer']:,} outer, {walls['faces_inner']:,} inner faces",
         f"| attachments | {len(att['components'])} handle, {att['faces']:,} faces, {att['area_mm2']:,.0f} mm², "
         f"{lo:.0f}–{hi:.0f} mm above the foot, left out; {len(att['root_faces'])} root faces |",
         f"| trimmed | {trim['faces']} border faces, {trim['area_mm2']:,.0f} mm²",
         f"| untangled | {tangle['faces']} faces folded by the scan's own creases, {tangle['vertices_moved']} vertices moved |",
         f"| proxy | {proxy} (edge-length RMS {roll['distortion']['edge_rms']:.3f} after untangling) |",
         f"0 flipped faces, no boundary overlap, edge-length RMS {relaxed['distortion']['edge_rms']:.3f} |",
         f"its relief in grey, smoothed at {bake['relief']['smoothing_mm']:.0f} mm as its vertices are "
         f"{bake['relief']['mesh_spacing_mm']:.1f} mm apart")


def test_the_presets_and_defaults_in_the_guide():
    from potflat.bake.options import DEFAULT_PX_PER_MM, BakeOptions
    from potflat.relax.parameters import PRESETS

    def power(x: float) -> str:
        return f"1e{round(math.log10(x))}"

    preview, standard, archival, paper = (PRESETS[k] for k in ("preview", "standard", "archival", "paper"))
    says("docs/guide.md",
         f"({preview.simplify_mm:g} mm at {DEFAULT_PX_PER_MM:g} px/mm; `--simplify-mm`)",
         f"stops early (relative energy change {power(preview.tol)})",
         f"| `standard` (default) | stops at {power(standard.tol)} |",
         f"| `archival` | stops at {power(archival.tol)} |",
         f"(stretch {paper.stretch:g}, k {paper.stiffness:g}, boundary friction)",
         f"`--shape` ({standard.shape:g};", f"`--rigidity` ({standard.rigidity:g};", f"`--area` ({standard.area:g};",
         f"`--max-anisotropy` (`{standard.max_anisotropy}`",
         f"`--importance-contrast` ({standard.importance_contrast:g}, `preview` {preview.importance_contrast:g};",
         f"default {DEFAULT_PX_PER_MM:g} px/mm", f"`--max-megapixels` ({BakeOptions().max_megapixels:g})")


def test_the_relief_defaults_in_the_guide():
    from potflat.bake.options import BakeOptions
    from potflat.bake.relief import RAKING_ELEVATION_DEG
    from potflat.mesh.relief import SMOOTHING_MIN_EDGES

    options = BakeOptions()
    says("docs/guide.md", f"`--relief-mm` (default {options.relief_mm:g} mm)",
         f"raking light at {RAKING_ELEVATION_DEG:g} degrees",
         f"(degrees clockwise from image up; default `{','.join(f'{a:g}' for a in options.relief_light)}`)",
         f"the relief's share (default {options.relief_blend:g})",
         f"raised to {({2.0: 'two', 3.0: 'three', 4.0: 'four'})[SMOOTHING_MIN_EDGES]} edge lengths")


def _docs_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location("_docs", ROOT / "benchmarks" / "_docs.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_every_generated_block_is_marked_once_in_its_document():
    """So a long benchmark run never fails at its last step, and no block is left that no
    benchmark writes."""
    docs = _docs_module()
    for name, doc in docs.BLOCKS.items():
        docs.replace_block(doc.read_text(), name, "x")  # raises when the markers are wrong
    for doc in set(docs.BLOCKS.values()):
        marked = set(re.findall(r"^<!-- begin: (\S+) -->$", doc.read_text(), re.MULTILINE))
        assert marked <= {n for n, d in docs.BLOCKS.items() if d == doc}, f"{doc}: no benchmark writes {marked}"


def test_no_generated_block_holds_a_heading():
    """The headings stay outside the blocks (the hand-written part of each document)."""
    docs = _docs_module()
    for name, doc in docs.BLOCKS.items():
        begin, end = docs.markers(name)
        text = doc.read_text()
        block = text[text.index(begin):text.index(end)]
        assert not re.search(r"^#", block, re.MULTILINE), f"{doc.name}: block {name} holds a heading"


def test_a_block_is_replaced_between_its_markers_only():
    docs = _docs_module()
    text = "# T\n\nhand\n<!-- begin: a -->\nold\n<!-- end: a -->\nafter\n"
    assert docs.replace_block(text, "a", "new\n") == "# T\n\nhand\n<!-- begin: a -->\nnew\n<!-- end: a -->\nafter\n"
    for bad in ("no markers\n", "<!-- end: a -->\n<!-- begin: a -->\n", text + text):
        with pytest.raises(ValueError, match="block 'a'"):
            docs.replace_block(bad, "a", "new")
