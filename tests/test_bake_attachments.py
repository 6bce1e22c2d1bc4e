"""The bake shows where the rollout left out an attachment (handle roots) as a mask layer."""
import json

import numpy as np
from PIL import Image

from potflat.bake import BakeOptions

from potflat.files.bake_stage import run_bake_stage
from potflat.io.flat_ply import write_flat_ply
from potflat.types import FlatMesh, Mesh


def _plane(tmp_path, root_faces, kept=False):
    xs, ys = np.meshgrid(np.linspace(0, 40, 9), np.linspace(0, 20, 5))
    V = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], 1)
    F = []
    for j in range(4):
        for i in range(8):
            a = j * 9 + i
            F += [[a, a + 1, a + 9], [a + 1, a + 10, a + 9]]
    flat = FlatMesh(Mesh(V, np.array(F)), V[:, :2])
    ply = write_flat_ply(tmp_path / "x.relaxed.ply", flat)
    (tmp_path / "x.rollout.json").write_text(json.dumps({"attachments": {"root_faces": root_faces, "kept": kept}}))
    return ply


def test_attachment_roots_are_masked(tmp_path):
    ply = _plane(tmp_path, [0, 1])  # the bottom-left 5 x 5 mm square
    out = run_bake_stage(ply, tmp_path / "out", BakeOptions(px_per_mm=2, maps=("none",)))
    mask = np.asarray(Image.open(out.paths["attachments"]))
    h, w = mask.shape[:2]
    assert abs(h - 40) <= 2 and abs(w - 80) <= 2  # 20 x 40 mm at 2 px/mm, plus a margin
    marked = mask[..., 3] > 0
    rows, cols = np.nonzero(marked)
    # v up: the bottom of the plane is the last rows; u right: the left columns
    assert rows.min() >= h - 12 and cols.max() <= 12
    assert abs(marked.sum() - 10 * 10) <= 12
    assert out.record["files"]["attachments"] == "x.attachments.png"


def test_no_mask_when_attachments_kept_or_absent(tmp_path):
    ply = _plane(tmp_path, [0, 1], kept=True)
    out = run_bake_stage(ply, tmp_path / "out", BakeOptions(px_per_mm=1, maps=("none",)))
    assert "attachments" not in out.paths
    assert not (tmp_path / "out" / "x.attachments.png").exists()
