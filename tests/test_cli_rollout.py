import json

import pytest
import trimesh
from _revolve import vase
from potflat_cli.main import app
from typer.testing import CliRunner

runner = CliRunner()


@pytest.fixture
def scan(tmp_path):
    mesh, *_ = vase(seed=2, cap=True)
    path = tmp_path / "pot.ply"
    trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).export(path)
    return path


def test_rollout_writes_both_files_and_a_summary(scan, tmp_path):
    out = tmp_path / "new" / "dir"
    result = runner.invoke(app, ["rollout", str(scan), "-o", str(out), "--band", "0.05", "1",
                                 "--proxy", "cone"])
    assert result.exit_code == 0, result.output
    assert (out / "pot.rollout.ply").is_file() and (out / "pot.rollout.json").is_file()
    for word in ("axis", "residual", "proxy cone", "seam", "distortion", "flipped"):
        assert word in result.output
    data = json.loads((out / "pot.rollout.json").read_text())
    assert data["proxy"]["type"] == "cone" and data["region"]["band"] == [0.05, 1.0]


def test_rollout_options_reach_the_stage(tmp_path):
    mesh, *_ = vase(seed=2, pose=False)  # axis along +z through the origin
    scan = tmp_path / "pot.ply"
    trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).export(scan)
    result = runner.invoke(app, ["rollout", str(scan), "-o", str(tmp_path), "--angles", "-60", "60",
                                 "--seam", "45", "--band", "0.2", "0.8", "--axis", "0,0,0,0,0,1",
                                 "--flip", "--units", "cm", "--name", "frieze", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["units"] == "cm" and data["seam"]["angle_deg"] == 45.0
    assert data["region"]["angles_deg"] == [-60.0, 60.0]
    assert data["axis"]["method"] == "manual" and data["axis"]["direction"] == [0.0, 0.0, -1.0]
    assert (tmp_path / "frieze.rollout.json").is_file()


def test_ortho_with_view(scan, tmp_path):
    result = runner.invoke(app, ["rollout", str(scan), "-o", str(tmp_path), "--proxy", "ortho",
                                 "--angles", "-20", "20", "--view", "1,0,0", "-q"])
    assert result.exit_code == 0, result.output
    assert result.output == ""
    data = json.loads((tmp_path / "pot.rollout.json").read_text())
    assert data["proxy"]["params"]["view"] == [1.0, 0.0, 0.0]


@pytest.mark.parametrize("args,words", [
    (["--band", "0.8", "0.2"], "band"),
    (["--axis", "1,2,3"], "axis"),
    (["--axis", "a,b,c,d,e,f"], "axis"),
    (["--proxy", "cyl"], "proxy"),
    (["--view", "1,0,0"], "ortho"),
    (["--angles", "0", "400"], "angles"),
    (["--units", "furlong"], "units"),
])
def test_bad_options_exit_2_with_one_line(scan, tmp_path, args, words):
    result = runner.invoke(app, ["rollout", str(scan), "-o", str(tmp_path), *args])
    assert result.exit_code == 2
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and words in lines[0]
    assert not (tmp_path / "pot.rollout.ply").exists()


def test_no_symmetry_is_a_clear_error(tmp_path):
    box = trimesh.creation.box((30, 50, 70)).subdivide().subdivide().subdivide()
    path = tmp_path / "box.stl"
    box.export(path)
    result = runner.invoke(app, ["rollout", str(path), "-o", str(tmp_path)])
    assert result.exit_code == 2
    errors = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(errors) == 1 and "--axis px,py,pz,dx,dy,dz" in errors[0], result.output


def test_output_may_not_overwrite_the_input(tmp_path):
    mesh, *_ = vase(seed=2)
    path = tmp_path / "pot.rollout.ply"
    trimesh.Trimesh(mesh.vertices, mesh.faces, process=False).export(path)
    result = runner.invoke(app, ["rollout", str(path), "-o", str(tmp_path), "--name", "pot"])
    assert result.exit_code == 2 and "overwrite the input" in result.output


def test_help_shows_an_example():
    result = runner.invoke(app, ["rollout", "--help"])
    assert result.exit_code == 0
    assert "Example:" in result.output and "potflat rollout" in result.output


def test_side_and_keep_attachments_reach_the_stage(tmp_path):
    from potflat_synthetic.vessels import make_vessel, write_ply_colored

    scan = write_ply_colored(make_vessel("cup", n_vertices=2000, seed=1, texture_size=64), tmp_path / "cup.ply")
    result = runner.invoke(app, ["rollout", str(scan), "-o", str(tmp_path), "--side", "inner",
                                 "--keep-attachments", "--json"])
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["walls"]["side"] == "inner" and data["attachments"]["kept"] is True
    assert data["distortion"]["flipped"] == 0 and (tmp_path / "cup.profile.svg").is_file()
    result = runner.invoke(app, ["rollout", str(scan), "-o", str(tmp_path), "--side", "both"])
    assert result.exit_code == 2 and "side" in result.output
