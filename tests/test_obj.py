"""OBJ export of the flattened surface (potflat.io.obj, bake --obj): loads in trimesh, re-baked texture."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from PIL import Image

from potflat.errors import InvalidOptionError
from potflat.io.obj import write_textured_obj


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    from potflat.files.pipeline import run_scan
    from potflat_synthetic.vessels import make_vessel, write_obj

    root = tmp_path_factory.mktemp("obj")
    write_obj(make_vessel("cylinder", n_vertices=1500, texture_size=256, seed=2), root / "scan" / "pot.obj")
    return run_scan(root / "scan" / "pot.obj", root / "out", relax={"preset": "preview"},
                    bake={"px_per_mm": 3, "obj": True, "maps": ()})


def _sample(img: np.ndarray, tc: np.ndarray) -> np.ndarray:
    """Bilinear colour at (k, 2) OBJ texture coordinates (v up), as a viewer samples. Shape (k, 3) float."""
    import cv2

    h, w = img.shape[:2]
    x = (tc[:, 0] * w - 0.5).astype(np.float32)[None]
    y = ((1.0 - tc[:, 1]) * h - 0.5).astype(np.float32)[None]
    return cv2.remap(np.ascontiguousarray(img[..., :3]), x, y, cv2.INTER_LINEAR,
                     borderMode=cv2.BORDER_REPLICATE)[0].astype(float)


def test_flat_obj_loads_with_its_texture(baked):
    from potflat.io.flat_ply import read_flat_ply

    out = baked.out_dir
    paths = baked.bake.paths
    assert paths["obj"] == out / "pot.flat.obj" and paths["mtl"] == out / "pot.flat.mtl"
    flat = read_flat_ply(out / "pot.relaxed.ply")
    mesh = trimesh.load(paths["obj"], process=False)
    assert isinstance(mesh, trimesh.Trimesh) and mesh.visual.kind == "texture"
    np.testing.assert_allclose(mesh.vertices, flat.mesh.vertices, rtol=1e-8, atol=1e-6)
    np.testing.assert_array_equal(mesh.faces, flat.mesh.faces)
    painting = Image.open(out / "pot.png")
    assert mesh.visual.material.image.size == painting.size
    # the texture coordinates are the flat layout: the same affine map of uv for every vertex
    uv = mesh.visual.uv
    scale = np.ptp(uv, axis=0) / np.ptp(flat.uv, axis=0)
    assert scale[0] * painting.size[0] == pytest.approx(scale[1] * painting.size[1], rel=1e-6)  # no shear, square px
    assert scale[0] * painting.size[0] == pytest.approx(3.0, rel=1e-6)  # 3 px per mm


def test_flat_obj_shows_the_scan_texture(baked):
    """At every face centre the re-baked texture shows the colour of the scan's own texture there."""
    from potflat.io.flat_ply import read_flat_ply

    out = baked.out_dir
    flat = read_flat_ply(out / "pot.relaxed.ply")
    original = np.asarray(Image.open(flat.mesh.texture_path).convert("RGB"))
    rebaked = np.asarray(Image.open(out / "pot.png").convert("RGBA"))
    mesh = trimesh.load(out / "pot.flat.obj", process=False)
    centre_old = flat.mesh.texcoords.mean(axis=1)
    centre_new = mesh.visual.uv[mesh.faces].mean(axis=1)
    diff = np.abs(_sample(original, centre_old) - _sample(rebaked, centre_new)).max(axis=1)
    assert np.median(diff) < 6 and np.mean(diff < 40) > 0.95


def test_obj_writer_checks_its_input(tmp_path):
    V = np.eye(3)
    F = np.array([[0, 1, 2]])
    with pytest.raises(InvalidOptionError, match=r"\.obj"):
        write_textured_obj(tmp_path / "a.ply", V, F, V[:, :2], F, "t.png")
    with pytest.raises(InvalidOptionError, match="one index per face corner"):
        write_textured_obj(tmp_path / "a.obj", V, F, V[:, :2], F[:, :2], "t.png")
    path = write_textured_obj(tmp_path / "a.obj", V, F, V[:, :2], F, "t.png", header="test")
    assert path.read_text().splitlines()[:3] == ["# test", "mtllib a.mtl", "usemtl painted"]
    assert "map_Kd t.png" in (tmp_path / "a.mtl").read_text()
