"""potflat_cli._warmup: the child process that compiles the relax kernels on a first run, and
the bake kernels compiled in the run first."""
from __future__ import annotations

import json
import os
import sys
import time

import numpy as np
import pytest

import potflat._jit
from potflat.mesh.embedding import signed_areas
from potflat.relax.parameters import COARSE
from potflat_cli import _warmup as warmup


def test_the_vessel_is_a_fold_free_painted_start_with_coarse_copies(tmp_path):
    flat = warmup.vessel(tmp_path)
    assert len(flat.uv) >= COARSE.min_vertices  # so the coarse copies' kernels compile too
    assert (signed_areas(flat.mesh.faces, flat.uv) > 0).all()
    normals = np.cross(*(flat.mesh.vertices[flat.mesh.faces[:, k]] - flat.mesh.vertices[flat.mesh.faces[:, 0]]
                         for k in (1, 2)))
    centres = flat.mesh.vertices[flat.mesh.faces].mean(axis=1)
    assert (np.einsum("ij,ij->i", normals[:, :2], centres[:, :2]) > 0).all()  # facing outwards
    assert 0 < flat.importance.mean() < 1  # a painted zone: the relax stage's zone path
    assert flat.mesh.texture_path.parent == tmp_path and flat.mesh.texture_path.is_file()


@pytest.mark.parametrize("stamp, version, cached", [
    ("source", "numba", True), ("time", "numba", True), ("other", "numba", False), ("source", "0.1", False)],
    ids=["hash of the source", "time and size", "another source", "another Numba"])
def test_kernels_count_as_cached_when_an_index_is_of_this_source_and_numba(tmp_path, monkeypatch, stamp, version,
                                                                          cached):
    """A spring kernel's cache index counts when its stamp is the source's (as Numba stamps it:
    the source's SHA-256, or its time and size), whatever the files' times, and this Numba wrote it."""
    import hashlib
    import pickle
    from pathlib import Path

    import numba

    source = Path(potflat._jit.__file__).parent / "relax" / "_kernels" / "springs.py"
    stamps = {"source": hashlib.sha256(source.read_bytes()).digest(),
              "time": (source.stat().st_mtime, source.stat().st_size), "other": hashlib.sha256(b"x").digest()}
    (tmp_path / "k").mkdir()
    index = tmp_path / "k" / "springs.energy_gradient-1.py311.nbi"
    index.write_bytes(pickle.dumps(numba.__version__ if version == "numba" else version)
                      + pickle.dumps((stamps[stamp], {})))
    os.utime(index, (0, 0))  # (older than the source: the index's own time does not matter)
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path))
    assert potflat._jit.kernels_cached() is cached
    index.unlink()
    assert potflat._jit.kernels_cached() is False


def test_warm_relaxes_like_a_run(tmp_path):
    warmup.warm(tmp_path, "relax")
    relaxed = json.loads((tmp_path / "warmup.relaxed.json").read_text())
    assert relaxed["fold_free"] and relaxed["important_zone"]["area_fraction"] < 1
    assert any("coarse copy" in note for note in relaxed["notes"])
    assert not (tmp_path / "warmup.png").exists()


def test_warm_bakes_like_a_run(tmp_path):
    warmup.warm(tmp_path, "bake")
    baked = json.loads((tmp_path / "warmup.rollout.bake.json").read_text())
    assert baked["painting"] == "texture" and (tmp_path / "warmup.rollout.png").is_file()
    assert not (tmp_path / "warmup.relaxed.json").exists()


def test_bake_here_leaves_nothing_behind_and_never_fails_the_run(tmp_path, monkeypatch):
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    warmup.bake_here()
    assert not list(tmp_path.iterdir())

    def broken(folder, stage):
        (folder / "half-written").write_text("x")
        raise RuntimeError("no bake")

    monkeypatch.setattr(warmup, "warm", broken)
    warmup.bake_here()  # no exception
    assert not list(tmp_path.iterdir())


def test_no_child_when_the_kernels_are_cached(monkeypatch):
    monkeypatch.setattr(potflat._jit, "kernels_cached", lambda: True)
    assert warmup.start() is None


@pytest.mark.parametrize("patience_s", [warmup.STOP_TIMEOUT_S, 0.0])  # 0: killed at once, mid-work
def test_a_stopped_child_leaves_nothing_behind(tmp_path, monkeypatch, patience_s):
    import tempfile

    monkeypatch.setattr(potflat._jit, "kernels_cached", lambda: False)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # the child's temporary folder goes here
    monkeypatch.setattr(warmup, "STOP_TIMEOUT_S", patience_s)
    child = warmup.start()
    assert child is not None
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob("potflat-warmup-*/warmup.texture.png")):  # at work in its folder
        assert child.process.poll() is None, "the child ended before it made its folder"
        if time.monotonic() > deadline:
            pytest.fail("the child made no folder in 120 s")
        time.sleep(0.05)
    child.stop()
    child.stop()  # again: nothing to do
    assert child.process.returncode is not None
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("fails", [False, True])
def test_a_first_run_starts_the_child_and_ends_it_with_the_run(tmp_path, monkeypatch, fails):
    import test_batch_fakes as fakes
    from typer.testing import CliRunner

    from potflat_cli.main import app

    fakes.install(monkeypatch)
    started = []
    real_start = warmup.start

    def start():
        started.append(real_start())
        return started[-1]

    monkeypatch.setattr(potflat._jit, "kernels_cached", lambda: False)
    monkeypatch.setattr(warmup, "start", start)
    scan = fakes.write_scan(tmp_path / "pot.obj")
    if fails:
        fakes.SABOTAGE["pot"] = ("raise", "relax")
    result = CliRunner().invoke(app, ["run", str(scan), "-o", str(tmp_path / "out")])
    assert (result.exit_code != 0) == fails, result.output
    assert len(started) == 1 and started[0] is not None
    assert started[0].process.returncode is not None  # ended (stopped, or done) when the command returned


@pytest.mark.parametrize("refused_at", [None, "rollout"])
def test_the_run_compiles_the_bake_kernels_only_after_its_rollout(tmp_path, monkeypatch, refused_at):
    """A scan the rollout refuses gets its one line at once, not after the bake kernels compile."""
    import test_batch_fakes as fakes
    from typer.testing import CliRunner

    from potflat_cli.main import app

    fakes.install(monkeypatch)
    baked = []
    monkeypatch.setattr(potflat._jit, "kernels_cached", lambda: False)
    monkeypatch.setattr(warmup, "bake_here", lambda: baked.append(True))
    scan = fakes.write_scan(tmp_path / "pot.obj")
    if refused_at:
        fakes.SABOTAGE["pot"] = ("raise", refused_at)
    result = CliRunner().invoke(app, ["run", str(scan), "-o", str(tmp_path / "out")])
    assert (result.exit_code != 0) == bool(refused_at), result.output
    assert baked == ([] if refused_at else [True])


#: A run in a fresh process (``sys.argv[1]``: the temporary folder) that starts the child on a
#: cold kernel cache, prints the child's process id and waits to be killed.
PARENT = """
import sys, tempfile, time
import potflat._jit
from potflat_cli import _warmup
potflat._jit.kernels_cached = lambda: False
tempfile.tempdir = sys.argv[1]
child = _warmup.start()
print(child.process.pid, flush=True)
time.sleep(600)
"""


def _gone(pid: int) -> bool:
    """Whether process ``pid`` has ended (and been reaped, or is a zombie)."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] == "Z"
    except FileNotFoundError:
        return True


def _wait_at_work(folder, pid: int) -> None:
    deadline = time.monotonic() + 120
    while not list(folder.glob("potflat-warmup-*/warmup.texture.png")):  # compiling in its folder
        assert not _gone(pid), "the child ended before it made its folder"
        if time.monotonic() > deadline:
            pytest.fail("the child made no folder in 120 s")
        time.sleep(0.05)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
@pytest.mark.parametrize("how", ["parent killed", "pipe closed"])
def test_the_child_dies_with_the_run(tmp_path, how):
    """The run killed outright (SIGKILL: no stop(), no finaliser) ends its child within 2 s,
    by the death signal and by the pipe; the pipe alone (its end closed while the run lives)
    ends it too. Either way the child removes its folder."""
    import signal
    import subprocess

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cold-cache")}  # compiling: a minute of work
    temp = tmp_path / "temp"
    temp.mkdir()
    script = PARENT if how == "parent killed" else PARENT.replace(
        "time.sleep(600)", "import os; time.sleep(float(sys.stdin.readline())); os.close(child.pipe); time.sleep(600)")
    parent = subprocess.Popen([sys.executable, "-c", script, str(temp)], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              text=True, env=env)
    try:
        pid = int(parent.stdout.readline())
        _wait_at_work(temp, pid)
        if how == "parent killed":
            parent.send_signal(signal.SIGKILL)
            parent.wait()
        else:
            parent.stdin.write("0\n")
            parent.stdin.flush()
        deadline = time.monotonic() + 2.0
        while not _gone(pid) and time.monotonic() < deadline:
            time.sleep(0.02)
        alive = not _gone(pid)
        if alive:
            os.kill(pid, signal.SIGKILL)
        assert not alive, f"the child outlived the {how} by 2 s"
        if how == "pipe closed":
            assert parent.poll() is None  # the run lives: the pipe ended the child, not a death signal
        deadline = time.monotonic() + 2.0
        while list(temp.iterdir()) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not list(temp.iterdir())
    finally:
        parent.kill()
        parent.wait()


@pytest.mark.parametrize("cached", [False, True])
def test_the_warmup_command_runs_the_stages_in_a_folder_it_removes(tmp_path, monkeypatch, cached):
    """``potflat warmup``: the three stages on a generated vessel large enough for the coarse
    copies, in a temporary folder removed afterwards, the child started on a cold cache and
    ended with the command; it says what it did."""
    import tempfile

    from potflat.files import pipeline
    from potflat_cli._stage import PROGRESS
    from typer.testing import CliRunner

    from potflat.io.scan import load_scan
    from potflat.relax.parameters import COARSE
    from potflat_cli.main import app

    monkeypatch.setattr(potflat._jit, "kernels_cached", lambda: cached)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    scans, started = [], []
    real_start = warmup.start

    def run_scan(scan, out, progress=None, **kwargs):  # the stages' work: tested with run_scan
        mesh = load_scan(scan).mesh
        scans.append((len(mesh.vertices), mesh.texture_path is not None, kwargs))
        for stage in ("rollout", "relax", "bake"):
            progress(stage)
        out.mkdir(parents=True)
        (out / "warmup.png").write_bytes(b"painting")

    def start():
        started.append(real_start())
        return started[-1]

    monkeypatch.setattr(pipeline, "run_scan", run_scan)
    monkeypatch.setattr(warmup, "start", start)
    result = CliRunner().invoke(app, ["warmup"])
    assert result.exit_code == 0, result.output
    assert len(scans) == 1 and scans[0][0] >= COARSE.min_vertices and scans[0][1:] == (True, {})  # default options
    assert (started[0] is None) == cached and (cached or started[0].process.returncode is not None)
    assert f"{PROGRESS}kernels compiled and cached in" in result.stderr
    assert not list(tmp_path.iterdir())  # the vessel, its outputs and the child's folder removed
