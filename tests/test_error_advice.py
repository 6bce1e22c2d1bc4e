"""Every refusal of the rollout and relax stages names an action that works: each test
follows the advice of one message and checks that the run then succeeds (diverging paper
dynamics: ``test_paper_dynamics_that_diverge_stop_with_one_line_and_write_nothing``)."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from potflat_cli.main import app
from typer.testing import CliRunner

from potflat.io.flat_ply import read_flat_ply, write_flat_ply
from potflat.types import Mesh
from potflat_synthetic.vessels import PART_INNER, make_vessel, write_ply_colored

runner = CliRunner()


def _cli(*args):
    return runner.invoke(app, [str(a) for a in args] + ["-q"])


def _refused(result, *words):
    assert result.exit_code == 2, result.output
    line = result.stderr.strip().splitlines()[-1]
    for word in words:
        assert word in line, line
    return line


@pytest.fixture(scope="module")
def amphora_ply(tmp_path_factory):
    vessel = make_vessel("amphora", n_vertices=4000, seed=2, texture_size=256, handles="welded")
    return write_ply_colored(vessel, tmp_path_factory.mktemp("amphora") / "amph.ply")


def test_kept_handles_are_cut_into_a_disk_and_relax(amphora_ply, tmp_path):
    result = _cli("run", amphora_ply, "-o", tmp_path, "--keep-attachments", "--px-per-mm", 1)
    assert result.exit_code == 0, result.output
    cut = json.loads((tmp_path / "amph.rollout.json").read_text())["disk_cut"]
    assert cut["handles"] == 2 and cut["faces"] > 0 and "handle" in cut["reason"]
    assert json.loads((tmp_path / "amph.relaxed.json").read_text())["flipped"] == 0


def test_a_rollout_that_is_not_a_disk_names_fixes_that_exist_and_work(amphora_ply, tmp_path, monkeypatch):
    """A rollout left uncut (as one made before potflat cut such parts) is refused; each fix
    the message names is true of the rollout's JSON, and each one works."""
    from potflat.rollout import unroll
    from potflat.rollout.topology import DiskCut

    with monkeypatch.context() as patch:
        patch.setattr(unroll, "disk_cut", lambda faces, vertices, offset: DiskCut(np.zeros(len(faces), bool), 0, 0, 0))
        line = _refused(_cli("run", amphora_ply, "-o", tmp_path / "kept", "--keep-attachments", "--px-per-mm", 1),
                        "not a disk", "without --keep-attachments", "--band LO HI", "amph.rollout.json",
                        "folded.regions[].band")
        record = json.loads((tmp_path / "kept" / "amph.rollout.json").read_text())
        assert record["attachments"]["kept"] and f"it kept {record['attachments']['faces']} faces" in line
        regions = record["folded"]["regions"]
        lo, hi = regions[0]["band"]
        assert f"{lo:.2f} to {hi:.2f}" in line
        below = min(r["band"][0] for r in regions)
        assert below > 0.2
        result = _cli("run", amphora_ply, "-o", tmp_path / "band", "--keep-attachments", "--band", 0, below - 0.02,
                      "--px-per-mm", 1)
        assert result.exit_code == 0, result.output
        assert _cli("run", amphora_ply, "-o", tmp_path / "left-out", "--px-per-mm", 1).exit_code == 0
    # a rollout from before the cut: made again, it relaxes
    (tmp_path / "kept" / "amph.rollout.json").write_text(json.dumps({k: v for k, v in record.items()
                                                                      if k != "disk_cut"}))
    _refused(_cli("relax", tmp_path / "kept" / "amph.rollout.ply", "-o", tmp_path / "kept"),
             "make the rollout again with potflat rollout")
    assert _cli("run", amphora_ply, "-o", tmp_path / "again", "--keep-attachments", "--px-per-mm", 1).exit_code == 0


def test_the_advice_for_a_rollout_that_is_not_a_disk_names_only_what_the_rollout_did(tmp_path):
    from potflat.files.relax_stage import _not_a_disk_advice

    path = tmp_path / "pot.rollout.json"
    advice = _not_a_disk_advice({"disk_cut": {}, "attachments": {"kept": False, "faces": 300}, "folded": None}, path)
    assert "--keep-attachments" not in advice and "folded.regions" not in advice and "again" not in advice
    assert "--band LO HI" in advice
    advice = _not_a_disk_advice({}, path)  # no record: made by an older potflat, or none beside
    assert "make the rollout again" in advice and "--keep-attachments" not in advice


def test_a_mirrored_rollout_is_refused_and_a_new_rollout_relaxes(amphora_ply, tmp_path):
    assert _cli("rollout", amphora_ply, "-o", tmp_path).exit_code == 0
    ply = tmp_path / "amph.rollout.ply"
    flat = read_flat_ply(ply)
    write_flat_ply(ply, flat.replace(uv=flat.uv * np.array([-1.0, 1.0])))  # seen from the wrong side
    _refused(_cli("relax", ply, "-o", tmp_path), "mirrored", "potflat rollout")
    assert _cli("rollout", amphora_ply, "-o", tmp_path).exit_code == 0
    assert _cli("relax", ply, "-o", tmp_path).exit_code == 0


def test_a_scan_of_one_side_names_the_side_it_has(tmp_path):
    cup = make_vessel("cup", n_vertices=2000, seed=1, texture_size=128)
    keep = cup.face_part == PART_INNER
    used = np.unique(cup.mesh.faces[keep])
    index = np.full(len(cup.mesh.vertices), -1)
    index[used] = np.arange(len(used))
    inside = Mesh(cup.mesh.vertices[used], index[cup.mesh.faces[keep]], units="mm")
    scan = dataclasses.replace(cup, mesh=inside, face_part=cup.face_part[keep], vertex_part=cup.vertex_part[used])
    ply = write_ply_colored(scan, tmp_path / "inside.ply")
    _refused(_cli("rollout", ply, "-o", tmp_path / "a", "--side", "inner"), "no inner wall", "--side outer")
    assert _cli("rollout", ply, "-o", tmp_path / "b", "--side", "outer").exit_code == 0
