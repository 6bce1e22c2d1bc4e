"""Bake a synthetic painted cylinder with a photogrammetry-like multi-chart atlas (UV seams
inside the surface), developed exactly, and measure its painted circles."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from potflat.types import FlatMesh
from potflat_synthetic import spec
from potflat_synthetic import vessels as synthetic


@pytest.fixture(scope="module")
def developed_cylinder(tmp_path_factory):
    """The exact development u = R theta, v = height; faces across theta = +-pi are dropped (the cut)."""
    d = tmp_path_factory.mktemp("cyl")
    vessel = synthetic.make_vessel("cylinder", n_vertices=3000, texture_size=512, seed=1)
    cv2.imwrite(str(d / "atlas.png"), vessel.texture[..., ::-1])
    P = vessel.to_canonical(vessel.mesh.vertices)
    theta = np.arctan2(P[:, 1], P[:, 0])
    uv = np.stack([vessel.radius_at(P[:, 2]) * theta, P[:, 2]], axis=1)
    F = vessel.mesh.faces
    keep = np.ptp(theta[F], axis=1) < np.pi
    mesh = vessel.mesh.replace(faces=F[keep], texcoords=vessel.mesh.texcoords[keep], texture_path=d / "atlas.png")
    return FlatMesh(mesh, uv), vessel


def test_painted_circles_round_and_true_scale(developed_cylinder):
    from potflat.bake import bake

    flat, vessel = developed_cylinder
    ppm = 3.0
    res = bake(flat, px_per_mm=ppm, maps=())
    img = res.image
    want = 2 * spec.CIRCLE_RADIUS * ppm
    found = 0
    for feature in vessel.features:
        x, y, h = vessel.to_canonical(feature.centre)[0]
        theta = np.arctan2(y, x)
        if abs(theta) > np.pi - 0.2:
            continue  # cut by the seam
        col = int((vessel.radius_at(h) * theta - res.origin[0]) * ppm)
        row = int((res.origin[1] - h) * ppm)
        # half-way between the circle's colour and the ground it is painted on: unbiased by blur
        rgb = img[..., :3].astype(int)
        mask = ((np.abs(rgb - np.array(feature.colour)).sum(-1) < np.abs(rgb - np.array(spec.TERRACOTTA)).sum(-1))
                & (img[..., 3] == 255))
        _, labels = cv2.connectedComponents(mask.astype(np.uint8))
        assert labels[row, col] > 0  # the circle is where the development puts it
        blob = (labels == labels[row, col]).astype(np.uint8)
        contour = max(cv2.findContours(blob, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)[0], key=cv2.contourArea)
        _, axes, _ = cv2.fitEllipse(contour)
        assert max(axes) / min(axes) < 1.03
        assert abs(np.mean(axes) - want) <= 2.0  # 20 mm across at true scale
        found += 1
    assert found >= 8


def test_atlas_charts_leave_no_gap(developed_cylinder):
    """Every pixel inside the developed surface is opaque, across the atlas' chart borders."""
    from potflat.bake import bake

    flat, vessel = developed_cylinder
    assert len(np.unique(vessel.face_chart)) > 1
    res = bake(flat, px_per_mm=2.0, maps=())
    alpha = res.image[..., 3]
    inside = cv2.erode((alpha > 0).astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    assert inside.sum() > 0.8 * (alpha > 0).sum()
    assert (alpha[inside] == 255).all()
    # no atlas background (grey) leaks in at chart borders
    grey = np.abs(res.image[..., :3].astype(int) - np.array(spec.ATLAS_BACKGROUND)).sum(-1) < 12
    assert not (grey & inside).any()
    assert res.figures["covered_area_mm2"] == pytest.approx(res.figures["flattened_area_mm2"], rel=0.01)
