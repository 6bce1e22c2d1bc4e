"""The shared real scans (``../shared/data/real``) end to end at native size, as a user runs
them (``potflat run`` with the defaults, a low resolution: the images are not what is tested),
each wall of these two-walled scans in turn: an image with no flipped triangle and no boundary
crossing, and the figures the run reports within what a flattening of such a vessel gives.
Each scan and wall runs once for the module, whichever test asks first."""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import pytest
from typer.testing import CliRunner

from potflat_cli.main import app

SCANS = ("dragon-jar.glb", "colonoware-pot.glb", "plastic-vase.ply", "sea-vase.ply", "goblet.stl")
SIDES = ("outer", "inner")
WALLS = [(scan, side) for scan in SCANS for side in SIDES]


@dataclass(frozen=True)
class Run:
    """One ``potflat run``: its exit code, what it printed and its JSON sidecars."""

    exit_code: int
    output: str
    folder: Path
    name: str

    def record(self, stage: str) -> dict:
        return json.loads((self.folder / f"{self.name}.{stage}.json").read_text())


@pytest.fixture(scope="module")
def _runs(tmp_path_factory) -> tuple[dict, object]:
    return {}, tmp_path_factory


@pytest.fixture
def run_scan(real_scans, _runs):
    """``run_scan(file, side)``: the run of ``potflat run`` on that real scan and wall, made on
    first use and shared by the module's tests."""
    done, factory = _runs

    def run(scan: str, side: str) -> Run:
        if (scan, side) not in done:
            folder = factory.mktemp(f"{Path(scan).stem}-{side}")
            result = CliRunner().invoke(app, ["run", str(real_scans / scan), "-o", str(folder), "--side", side,
                                              "--px-per-mm", "1"], env={"COLUMNS": "200"})
            done[scan, side] = Run(result.exit_code, result.output, folder, Path(scan).stem)
        return done[scan, side]

    return run


@pytest.mark.parametrize("scan, side", WALLS)
def test_every_real_scan_gives_a_fold_free_image(run_scan, scan, side):
    r = run_scan(scan, side)
    assert r.exit_code == 0, r.output
    assert (r.folder / f"{r.name}.png").is_file()
    relaxed, bake = r.record("relaxed"), r.record("bake")
    assert relaxed["flipped"] == 0 and relaxed["boundary_overlap"] == 0 and relaxed["fold_free"]
    # the figures a user reads: lengths on the image where the painting is (the whole surface
    # without one), true scale there, the image's size against the surface it shows
    zone = relaxed["important_zone"]
    assert 0 <= zone["length_error_median_pct"] < 25 and zone["length_error_p95_pct"] < 60, relaxed["lengths"]
    assert abs(zone["scale_median"] - 1) < 1e-6 and 0.8 < relaxed["true_scale_factor"] < 1.25
    assert relaxed["distortion"]["edge_rms"] < 0.3 and relaxed["distortion"]["anisotropy_p95"] < 2.0
    width, height = bake["image_mm"]
    assert bake["surface_area_mm2"] <= width * height < 4 * bake["surface_area_mm2"]
    assert "lengths measured on the image" in r.output and "importance (" in r.output


@pytest.mark.parametrize("scan, side", WALLS)
def test_no_real_scan_is_solved_with_its_boundary_wrapped(run_scan, scan, side):
    """A start whose boundary folds over its own triangles at a vertex (angle sum past 2 pi:
    the sea vase's outer wall's rollout at 2 vertices) is unwrapped before the
    solve: left so, the vertex is unguarded, the solve's steps that wrap it further are
    halved by the line search, and the solve stalls before it converges."""
    r = run_scan(scan, side)
    assert r.exit_code == 0, r.output
    notes = r.record("relaxed")["notes"]
    assert not [n for n in notes if "already wrap past 2 pi" in n], notes


@pytest.mark.parametrize("scan, side", WALLS)
def test_no_real_scan_is_warned_of_its_axis_its_mouth_or_of_pieces_apart(run_scan, scan, side):
    """Relief, flutes and a hand-made wall lean the normals out of the meridian planes whatever
    the axis; a fitted axis is not called tilted for that (``tests/test_axis.py`` has the
    threshold against tilted axes). Nor is a wall's own small detached piece called a lid, nor
    a mouth guessed (each scan has an inner wall or an open rim)."""
    r = run_scan(scan, side)
    assert r.exit_code == 0, r.output
    notes = r.record("rollout")["notes"]
    assert not [n for n in notes if "axis looks tilted" in n or "pieces apart" in n or "upside down" in n], notes
    assert "axis looks tilted" not in " ".join(r.output.split())


@pytest.mark.parametrize("scan, side", [("colonoware-pot.glb", "outer"), ("dragon-jar.glb", "inner")])
def test_no_painted_zone_on_the_unpainted_pot_or_the_jars_inside(run_scan, scan, side):
    """The colonoware pot is fired clay (firing clouds, dirt, pinholes, chips) and the dragon
    jar's inside is white glaze in shadow: no painted zone, uniform weights, and the rollout's
    JSON and the run's summary say so in words."""
    r = run_scan(scan, side)
    assert r.exit_code == 0, r.output
    importance = r.record("rollout")["importance"]
    assert importance["uniform"] and importance["method"] == "auto"
    assert importance["reason"].startswith("no painting found") and importance["reason"].find("counts alike") > 0
    assert "importance (auto): no painting found" in " ".join(r.output.split())
    assert r.record("relaxed")["importance"].startswith("none")


def test_the_painted_porcelain_is_found_painted(run_scan):
    """The dragon jar's outer wall is painted nearly all over: found, and so the whole surface
    counts alike."""
    importance = run_scan("dragon-jar.glb", "outer").record("rollout")["importance"]
    assert importance["reason"].startswith("painted all over") and importance["uniform"]


def test_the_seam_runs_between_the_dragon_jar_s_dragons(run_scan):
    """The seam cuts the dragon jar between its two dragons: in the band of their bodies
    (25-55 % of the image's height), the image's left and right edges (1 % of its width)
    are the white ground but for a few clouds. Cut through a dragon's dotted body, 15-35 %
    of an edge is blue; between the dragons, 4-13 %."""
    import numpy as np
    from PIL import Image

    r = run_scan("dragon-jar.glb", "outer")
    assert r.exit_code == 0, r.output
    rgba = np.asarray(Image.open(r.folder / f"{r.name}.png").convert("RGBA")).astype(np.float64)
    inside, grey = rgba[..., 3] > 0, rgba[..., :3] @ [0.299, 0.587, 0.114]
    ground = np.median(grey[inside])
    h, w = inside.shape
    for side in (0, -1):
        edge = [grey[row, np.flatnonzero(inside[row])[::1 if side == 0 else -1][:w // 100]]
                for row in range(int(0.25 * h), int(0.55 * h))]
        assert (np.abs(np.concatenate(edge) - ground) > 30).mean() < 0.14, side
