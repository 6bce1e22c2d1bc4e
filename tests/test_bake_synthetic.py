"""Bake a rolled-out synthetic painted cylinder (multi-chart atlas) and measure its circles."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

synthetic = pytest.importorskip("potflat.synthetic")


def test_painted_circles_of_a_rolled_out_cylinder(tmp_path):
    from potflat.bake import run_bake_stage, BakeOptions
    from potflat.io.stage import read_flat_ply
    from potflat.rollout import run_rollout_stage

    vessel = synthetic.make_vessel("cylinder", n_vertices=3000, texture_size=1024, seed=1)
    out = run_rollout_stage(synthetic.write_obj(vessel, tmp_path / "cyl.obj"), tmp_path)
    ppm = 3.0
    baked = run_bake_stage(out.paths["ply"], tmp_path, BakeOptions(px_per_mm=ppm, maps=()))
    img = cv2.cvtColor(cv2.imread(str(baked.paths["png"]), cv2.IMREAD_UNCHANGED), cv2.COLOR_BGRA2RGBA)
    cream = np.array(synthetic.CREAM)
    mask = (np.abs(img[..., :3].astype(int) - cream).sum(-1) < 60) & (img[..., 3] == 255)
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    want = 2 * synthetic.CIRCLE_RADIUS * ppm
    full = [c for c in contours if cv2.contourArea(c) > 0.8 * np.pi * (want / 2) ** 2]
    assert len(full) >= 4  # the cream circles not cut by the seam
    flat = read_flat_ply(out.paths["ply"])
    edge_rms = baked.summary["distortion"]["edge_rms"]
    for c in full:
        _, axes, _ = cv2.fitEllipse(c)
        assert max(axes) / min(axes) < 1.03 + 2 * edge_rms  # round within the flattening's own error
        assert abs(np.mean(axes) - want) <= 2.0  # 20 mm across at true scale
    # the covered area matches the flattened area
    assert baked.summary["covered_area_mm2"] == pytest.approx(baked.summary["flattened_area_mm2"], rel=0.01)
    assert flat.mesh.texture_path is not None and baked.summary["painting"] == "texture"
