"""Faults: a run killed with SIGKILL during relax, during bake and during a batch.

Each run is a real ``python -m potflat_cli`` process in its own session, killed (with any
worker processes: the whole process group) when the files show that a stage is under way.
Afterwards every file under its final name must be complete (PLY via read_flat_ply, PNG via
Pillow, JSON via json), the only debris are hidden ``.NAME.*.part`` temporaries that no
output glob picks up and no later run counts, the input scan is unchanged, and a rerun
completes. Catalogue: docs/robustness.md.
"""
from __future__ import annotations

import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from PIL import Image
from potflat_cli._stage import PROGRESS

from potflat.io.flat_ply import read_flat_ply
from potflat_synthetic.vessels import make_vessel, write_obj

TIMEOUT = 240.0


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _start(*args) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "potflat_cli", *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, start_new_session=True)


def _kill_when(proc: subprocess.Popen, ready, what: str) -> None:
    """Poll every 5 ms until ``ready()``; then SIGKILL the process group."""
    deadline = time.monotonic() + TIMEOUT
    while not ready():
        if proc.poll() is not None:
            _, err = proc.communicate()
            pytest.fail(f"the run ended (exit {proc.returncode}) before {what}: {err.decode()[-2000:]}")
        if time.monotonic() > deadline:
            os.killpg(proc.pid, signal.SIGKILL)
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.005)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL


def _run(*args) -> subprocess.CompletedProcess:
    r = subprocess.run([sys.executable, "-m", "potflat_cli", *map(str, args)], check=False, capture_output=True, text=True,
                       timeout=TIMEOUT)
    assert r.returncode == 0, r.stderr[-3000:]
    return r


def _parts(folder: Path) -> list[Path]:
    return sorted(p for p in folder.rglob("*") if p.name.endswith(".part"))


def _check_outputs(folder: Path) -> dict[str, int]:
    """Every file under its final name parses; debris is hidden ``*.part`` only. Returns counts."""
    counts = {"ply": 0, "png": 0, "json": 0}
    for p in sorted(folder.rglob("*")):
        if p.is_dir():
            continue
        if p.name.endswith(".part"):
            assert p.name.startswith("."), f"visible temporary {p}"
            continue
        if p.suffix == ".ply":
            flat = read_flat_ply(p)
            assert len(flat.mesh.faces) > 0
            counts["ply"] += 1
        elif p.suffix == ".png":
            with Image.open(p) as im:
                im.load()
            counts["png"] += 1
        elif p.suffix == ".json":
            json.loads(p.read_text())
            counts["json"] += 1
    return counts


@pytest.fixture(scope="module")
def scan(tmp_path_factory):
    d = tmp_path_factory.mktemp("scan")
    path = write_obj(make_vessel("lekythos", n_vertices=3000, seed=5, texture_size=128), d / "pot.obj")
    return path


def _inputs(scan: Path) -> dict[str, str]:
    return {p.name: _sha(p) for p in scan.parent.iterdir() if p.is_file() and p.stem == "pot"}


def test_killed_during_relax_then_during_bake_then_rerun(scan, tmp_path):
    before = _inputs(scan)
    out = tmp_path / "out"

    # 1. killed during relax: the rollout is complete, the relaxation not yet written
    proc = _start("run", scan, "-o", out, "--preset", "standard", "--px-per-mm", "2", "-q")
    _kill_when(proc, lambda: (out / "pot.rollout.json").exists(), "the relax stage")
    assert not (out / "pot.relaxed.json").exists(), "killed too late: relax had finished"
    counts = _check_outputs(out)
    assert counts["ply"] >= 1 and counts["json"] >= 1
    assert _inputs(scan) == before

    # 2. rerun, killed during bake while a PNG is being streamed into its temporary file
    proc = _start("run", scan, "-o", out, "--preset", "preview", "--px-per-mm", "6", "-q")
    _kill_when(proc, lambda: (out / "pot.relaxed.json").exists() and any(".png." in p.name for p in _parts(out)),
               "the bake stage writing a PNG")
    assert not (out / "pot.bake.json").exists()
    debris = _parts(out)
    assert debris, "the kill should have left the PNG being written as a temporary"
    _check_outputs(out)
    assert _inputs(scan) == before

    # 3. rerun completes; the debris is never taken for output
    _run("run", scan, "-o", out, "--preset", "preview", "--px-per-mm", "2", "-q")
    counts = _check_outputs(out)
    assert counts["ply"] == 2 and counts["json"] == 3 and counts["png"] >= 4
    bake = json.loads((out / "pot.bake.json").read_text())
    assert not any(name.endswith(".part") for name in bake["files"].values())
    assert all((out / name).is_file() for name in bake["files"].values())
    assert _inputs(scan) == before


def test_batch_killed_mid_scan_then_resumed(scan, tmp_path):
    import shutil

    other = tmp_path / "copy" / "pot.obj"  # a second scan (a copy: same files, another folder)
    other.parent.mkdir()
    for p in scan.parent.glob("pot.*"):
        shutil.copy(p, other.parent / p.name)
    before = _inputs(scan), _inputs(other)
    batch = tmp_path / "batch.yaml"
    batch.write_text(f"output: out\ndefaults:\n  preset: preview\n  px_per_mm: 4\nscans:\n"
                     f"  - path: {scan}\n    name: a\n  - path: {other}\n    name: b\n")
    out = tmp_path / "out"
    proc = _start("batch", batch, "--workers", "1", "-q")
    # killed (with its worker processes) while scan a is being baked
    _kill_when(proc, lambda: (out / "a" / "a.relaxed.json").exists() and bool(_parts(out / "a")), "a's bake")
    assert json.loads((out / "a" / "manifest.json").read_text())["complete"] is False  # partial marker only
    _check_outputs(out)
    assert (_inputs(scan), _inputs(other)) == before

    # the rerun does not take the killed scan as complete, and finishes both
    r = _run("batch", batch, "--workers", "1", "--json")
    summary = json.loads(r.stdout)
    status = {row["name"]: row["status"] for row in summary["scans"]}
    assert status == {"a": "done", "b": "done"}, summary
    _check_outputs(out)
    for name in ("a", "b"):
        manifest = json.loads((out / name / "manifest.json").read_text())
        assert not any(rel.endswith(".part") for rel in manifest["outputs"])
        for rel, size in manifest["outputs"].items():
            assert (out / name / rel).stat().st_size == size
    assert (_inputs(scan), _inputs(other)) == before


def test_disk_full_is_one_line_and_leaves_nothing_half_written(scan, tmp_path):
    """Writes fail as on a full disk (RLIMIT_FSIZE: every write beyond 100 kB fails with
    EFBIG): one line naming the file, exit 2, no output under its final name; then a rerun
    with room completes."""
    import resource

    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (100_000, 100_000))

    before = _inputs(scan)
    # a first run fills Numba's cache (a cache file that cannot be written fails the run too,
    # with the same one line but without a file name: Numba does not say which)
    _run("run", scan, "-o", tmp_path / "warm", "--preset", "preview", "--px-per-mm", "2", "-q")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "potflat_cli", "run", str(scan), "-o", str(out), "--preset", "preview",
                        "--px-per-mm", "2"], check=False, capture_output=True, text=True, timeout=TIMEOUT,
                       preexec_fn=limit)
    lines = [line for line in r.stderr.strip().splitlines() if not line.startswith(PROGRESS)]  # (stages started)
    assert r.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), r.stderr[-3000:]
    assert "pot.rollout.ply" in lines[0] and "disk space" in lines[0]
    assert not out.exists() or not list(out.iterdir())  # the stage that failed leaves nothing
    assert not _parts(out)
    _run("run", scan, "-o", out, "--preset", "preview", "--px-per-mm", "2", "-q")
    assert _check_outputs(out)["png"] >= 4
    assert _inputs(scan) == before
