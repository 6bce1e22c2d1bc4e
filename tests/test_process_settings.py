"""Process-wide settings: none from importing or calling the library; OpenMP's passive wait and
the heap tuning from the ``potflat`` command (and its batch workers)."""
from __future__ import annotations

import os
import subprocess
import sys

import pytest
from typer.testing import CliRunner

import test_batch_fakes as fakes
from potflat import _heap
from potflat_cli.main import app


def test_importing_the_library_sets_nothing_in_the_environment():
    code = """
import os, pkgutil, importlib, potflat
before = dict(os.environ)
for module in pkgutil.walk_packages(potflat.__path__, "potflat."):
    importlib.import_module(module.name)
import numba
print(sorted(set(os.environ.items()) ^ set(before.items())))
"""
    env = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
    assert out.stdout.strip() == "[]", out.stdout


def _record_stage_settings(monkeypatch) -> list:
    """Fake stages that record the wait policy and the heap opt-in they run with (no warm-up)."""
    import potflat._jit
    from potflat.files import pipeline

    fakes.install(monkeypatch)
    monkeypatch.setattr(potflat._jit, "kernels_cached", lambda: True)
    seen = []
    for stage in ("rollout", "relax", "bake"):
        run = getattr(pipeline, f"run_{stage}_stage")

        def recording(*args, _run=run, **kwargs):
            seen.append((os.environ.get("OMP_WAIT_POLICY"), _heap.heap_tuning_allowed()))
            return _run(*args, **kwargs)

        monkeypatch.setattr(pipeline, f"run_{stage}_stage", recording)
    return seen


def test_the_command_runs_the_stages_waiting_passively_with_the_heap_tuning(tmp_path, monkeypatch):
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    seen = _record_stage_settings(monkeypatch)
    scan = fakes.write_scan(tmp_path / "pot.obj")
    result = CliRunner().invoke(app, ["run", str(scan), "-o", str(tmp_path / "out"), "--quiet"])
    assert result.exit_code == 0, result.output
    assert seen == [("PASSIVE", True)] * 3
    assert "OMP_WAIT_POLICY" not in os.environ and not _heap.heap_tuning_allowed()  # put back


def test_the_users_wait_policy_stands(tmp_path, monkeypatch):
    monkeypatch.setenv("OMP_WAIT_POLICY", "ACTIVE")
    seen = _record_stage_settings(monkeypatch)
    scan = fakes.write_scan(tmp_path / "pot.obj")
    result = CliRunner().invoke(app, ["run", str(scan), "-o", str(tmp_path / "out"), "--quiet"])
    assert result.exit_code == 0, result.output
    assert seen == [("ACTIVE", True)] * 3 and os.environ["OMP_WAIT_POLICY"] == "ACTIVE"


def test_the_settings_are_put_back_when_the_command_fails(tmp_path, monkeypatch):
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    seen = _record_stage_settings(monkeypatch)
    fakes.SABOTAGE["pot"] = ("raise", "relax")
    scan = fakes.write_scan(tmp_path / "pot.obj")
    result = CliRunner().invoke(app, ["run", str(scan), "-o", str(tmp_path / "out"), "--quiet"])
    assert result.exit_code != 0 and len(seen) == 2
    assert "OMP_WAIT_POLICY" not in os.environ and not _heap.heap_tuning_allowed()


@pytest.mark.parametrize("allowed", [True, False])
def test_a_batch_worker_tunes_the_heap_as_its_parent_allowed(monkeypatch, allowed):
    from potflat.files.batch import execution as batch

    seen = []
    monkeypatch.setattr(batch, "run_job", lambda job, key, threads: seen.append(_heap.heap_tuning_allowed()))
    batch._run_job_in_worker(None, "key", 1, allowed)
    assert seen == [allowed] and not _heap.heap_tuning_allowed()
