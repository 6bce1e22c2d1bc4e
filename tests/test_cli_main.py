"""The potflat CLI as a whole: version, help with examples, run, conventions."""
from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import pytest
from typer.testing import CliRunner

import test_batch_fakes as fakes
from potflat_cli._stage import PROGRESS
from potflat_cli.main import app

COMMANDS = ("rollout", "relax", "bake", "run", "batch")


def cli(*args):
    # a wide terminal, so that help tables do not cut long option names ("--importance-angl…")
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "200"})


@pytest.fixture
def fake_stages(monkeypatch):
    fakes.install(monkeypatch)


def test_version():
    from potflat import __version__

    result = cli("--version")
    assert result.exit_code == 0 and result.stdout.strip() == f"potflat {__version__}"


def test_help_lists_every_command_and_exit_codes():
    result = cli("--help")
    assert result.exit_code == 0
    for command in COMMANDS:
        assert command in result.stdout
    assert "Exit codes" in result.stdout


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_help_has_an_example(command):
    result = cli(command, "--help")
    assert result.exit_code == 0, result.output
    assert "Example" in result.stdout and f"potflat {command}" in result.stdout


def test_cli_startup_imports_no_numerics():
    code = "import sys, potflat_cli.main; print(sorted({'numba', 'scipy', 'trimesh'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize("command", COMMANDS)
def test_help_imports_no_numerics(command):
    """``--help`` shows the allowed values of the name options from light modules only."""
    code = (f"import sys\nfrom potflat_cli.main import app\ntry:\n    app(prog_name='potflat', args=['{command}', '--help'])\n"
            "except SystemExit:\n    pass\nprint(sorted({'numba', 'scipy', 'trimesh', 'cv2'} & set(sys.modules)), file=sys.stderr)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stderr.strip().splitlines()[-1] == "[]"


def test_run_help_lists_every_stage_option(fake_stages):
    result = cli("run", "--help")
    assert result.exit_code == 0, result.output
    text = " ".join(result.stdout.split())
    for cls in (fakes.RolloutOptions, fakes.RelaxOptions, fakes.BakeOptions):
        for field in dataclasses.fields(cls):
            assert "--" + field.name.replace("_", "-") in text
    assert "Rollout options" in text and "Bake options" in text


def test_run_help_with_the_real_stages():
    from potflat.files.options import STAGE_OPTIONS

    text = " ".join(cli("run", "--help").stdout.split())
    for cls in STAGE_OPTIONS.values():
        for field in dataclasses.fields(cls):
            assert "--" + field.name.replace("_", "-") in text


def test_run_writes_everything_and_json(tmp_path, fake_stages):
    scan = fakes.write_scan(tmp_path / "vase.obj")
    result = cli("run", scan, "-o", tmp_path / "out", "--band", 0.1, 0.9, "--preset", "preview",
                 "--px-per-mm", 2, "--maps", "stress,area", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.stdout)
    assert data["name"] == "vase" and data["figures"]["flipped"] == 0
    written = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert "vase.png" in written and "vase.area.png" in written and "vase.anisotropy.png" not in written
    rollout = json.loads((tmp_path / "out" / "vase.rollout.json").read_text())
    assert rollout["provenance"]["options"]["band"] == [0.1, 0.9]


def test_run_summary_says_how_ragged_the_outline_is(tmp_path, fake_stages):
    scan = fakes.write_scan(tmp_path / "vase.obj")
    result = cli("run", scan, "-o", tmp_path / "out")
    assert result.exit_code == 0, result.output
    assert "outline: turns 1.60 times round (the rollout's 1.50, 1.07x" in " ".join(result.stdout.split())


def test_run_default_output_is_name_in_the_current_folder(tmp_path, fake_stages, monkeypatch):
    """Never the scan's folder (often an archive or read-only) unless asked: ./NAME/."""
    scan = fakes.write_scan(tmp_path / "archive" / "vase.obj")
    monkeypatch.chdir(tmp_path)
    result = cli("run", scan, "--quiet")
    assert result.exit_code == 0 and result.stdout == ""
    assert (tmp_path / "vase" / "vase.png").is_file()
    assert sorted(p.name for p in scan.parent.iterdir()) == ["vase.obj"]


@pytest.mark.parametrize("args, message", [
    (["--px-per-mm", "-1"], "px_per_mm must be positive"),
    (["--band", "0.6", "0.2"], "band must be two fractions"),
    (["--maps", "stress,colour"], "unknown map 'colour'"),
])
def test_run_bad_option_exit_2_on_stderr(tmp_path, fake_stages, args, message):
    scan = fakes.write_scan(tmp_path / "vase.obj")
    result = cli("run", scan, "-o", tmp_path / "out", *args)
    assert result.exit_code == 2
    assert message in result.stderr and result.stdout == ""
    assert not (tmp_path / "out").exists()


def test_run_bad_choice_and_missing_scan_exit_2(tmp_path, fake_stages):
    scan = fakes.write_scan(tmp_path / "vase.obj")
    assert cli("run", scan, "--proxy", "cube").exit_code == 2
    result = cli("run", tmp_path / "nothere.obj")
    assert result.exit_code == 2 and "nothere.obj" in result.stderr


def test_run_corrupt_scan_one_line_error(tmp_path, fake_stages):
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nforma")
    result = cli("run", bad, "-o", tmp_path / "out")
    assert result.exit_code == 2
    lines = [line for line in result.stderr.strip().splitlines() if not line.startswith(PROGRESS)]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "bad.ply" in lines[0]


@pytest.mark.parametrize("stage", ["rollout", "relax", "bake"])
def test_stage_commands_use_the_shared_option_names(stage):
    """Every options field is --field-name on its stage command, with -o/--output and --name."""
    from potflat.files.options import STAGE_OPTIONS

    cls = STAGE_OPTIONS[stage]
    text = " ".join(cli(stage, "--help").stdout.split())
    missing = [f"--{f.name.replace('_', '-')}" for f in dataclasses.fields(cls)
               if f"--{f.name.replace('_', '-')}" not in text]
    missing += [flag for flag in ("--output", "-o", "--name", "--quiet", "--json") if f" {flag} " not in text]
    assert not missing, f"potflat {stage} lacks {', '.join(missing)}"
