"""potflat batch end to end with the real stages, on small generated vessels.

Two synthetic vessels (about 2,500 vertices, 256 px texture) and one corrupt PLY: the two
finish with all outputs, the corrupt one fails with a one-line message, exit code 1; a
rerun skips the finished ones; a local process pool and a local Dask cluster write the
same files as a serial run.
"""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

from potflat.files.batch.config import load_batch

from potflat.files.batch.execution import run_batch

from potflat.files.batch.manifest import MANIFEST, read_manifest
from potflat_cli.main import app

KINDS = ("amphora", "lekythos")


@pytest.fixture(scope="module")
def collection(tmp_path_factory):
    from potflat_synthetic.vessels import make_vessel, write_obj

    root = tmp_path_factory.mktemp("collection")
    for seed, kind in enumerate(KINDS):
        write_obj(make_vessel(kind, n_vertices=2500, texture_size=256, seed=seed), root / "scans" / f"{kind}.obj")
    good = (root / "scans" / "amphora.obj").read_bytes()
    (root / "scans" / "broken.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99\n"
                                                + good[:200])
    (root / "batch.yaml").write_text(
        "output: results/\n"
        "defaults: {preset: preview, px_per_mm: 1}\n"
        "scans:\n"
        "  - path: scans/*.obj\n"
        "  - path: scans/broken.ply\n"
        "    band: [0.1, 0.9]\n")
    return root


@pytest.fixture(scope="module")
def serial(collection):
    """The batch run once, serially, through the CLI."""
    result = CliRunner().invoke(app, ["batch", str(collection / "batch.yaml"), "--workers", "1", "--json"])
    return result


def images(folder: Path) -> dict:
    """PLY bytes and PNG pixel arrays of a scan folder."""
    out = {p.name: p.read_bytes() for p in folder.glob("*.ply")}
    out.update({p.name: np.asarray(Image.open(p)) for p in folder.glob("*.png")})
    return out


def same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) if isinstance(a[k], np.ndarray)
                                        else a[k] == b[k] for k in a)


def test_two_finish_the_corrupt_one_fails(collection, serial):
    assert serial.exit_code == 1, serial.output
    data = json.loads(serial.stdout)
    rows = {r["name"]: r for r in data["scans"]}
    assert [rows[k]["status"] for k in ("amphora", "lekythos", "broken")] == ["done", "done", "failed"]
    for kind in KINDS:
        folder = collection / "results" / kind
        for suffix in (".rollout.ply", ".rollout.json", ".relaxed.ply", ".relaxed.json", ".png",
                       ".bake.json", ".stress.png"):
            assert (folder / f"{kind}{suffix}").is_file(), suffix
        assert (folder / MANIFEST).is_file()
        assert rows[kind]["flipped"] == 0 and 0 < rows[kind]["edge_rms"] < 0.5
    error = rows["broken"]["error"]
    assert "broken.ply" in error and "\n" not in error and len(error) < 400
    assert "failed  broken: " in serial.stderr
    assert read_manifest(collection / "results" / "broken")["complete"] is False


def test_rerun_skips_finished_and_reruns_on_option_change(collection, serial, tmp_path):
    copy = tmp_path / "c"
    shutil.copytree(collection, copy)
    before = images(copy / "results" / "amphora")
    again = run_batch(load_batch(copy / "batch.yaml"), workers=1)
    assert [r.status for r in again.reports] == ["skipped", "skipped", "failed"]
    (copy / "batch.yaml").write_text((copy / "batch.yaml").read_text().replace(
        "  - path: scans/*.obj\n", "  - path: scans/*.obj\n    maps: [stress]\n"))
    changed = run_batch(load_batch(copy / "batch.yaml"), workers=1)
    assert [r.status for r in changed.reports] == ["done", "done", "failed"], changed.reports
    assert "comment TextureFile amphora.texture.png" in (copy / "results" / "amphora" / "amphora.relaxed.ply"
                                                        ).read_bytes()[:2000].decode("latin-1")
    assert not (copy / "results" / "amphora" / "amphora.area.png").exists()
    after = images(copy / "results" / "amphora")
    assert same({k: v for k, v in before.items() if k in after}, after)  # same inputs, same bytes


def test_spawned_workers_report_errors(tmp_path):
    for name in ("a", "b"):
        (tmp_path / f"{name}.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n0 0\n")
    (tmp_path / "batch.yaml").write_text("output: out\nscans: ['*.ply']\n")
    summary = run_batch(load_batch(tmp_path / "batch.yaml"), workers=2)
    assert [r.status for r in summary.reports] == ["failed", "failed"]
    for report, name in zip(summary.reports, "ab"):
        assert f"{name}.ply" in report.error and "worker process died" not in report.error


@pytest.mark.slow  # each spawned worker compiles the kernels again: about a minute on 2 cores
def test_local_pool_gives_identical_results(collection, serial, tmp_path):
    pooled = run_batch(load_batch(collection / "batch.yaml", output=tmp_path / "pool"), workers=2)
    assert [r.status for r in pooled.reports] == ["done", "done", "failed"]
    for kind in KINDS:
        assert same(images(tmp_path / "pool" / kind), images(collection / "results" / kind))


@pytest.mark.dask
def test_dask_cluster_gives_identical_results(collection, serial, tmp_path):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False, protocol="tcp",
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        result = CliRunner().invoke(app, ["batch", str(collection / "batch.yaml"), "-o", str(tmp_path / "dask"),
                                          "--scheduler", cluster.scheduler_address, "--quiet"])
    assert result.exit_code == 1, result.output
    summary = json.loads((tmp_path / "dask" / "summary.json").read_text())
    assert [r["status"] for r in summary["scans"]] == ["done", "done", "failed"]
    for kind in KINDS:
        assert same(images(tmp_path / "dask" / kind), images(collection / "results" / kind))
    serial_rows = json.loads(serial.stdout)["scans"]
    assert [r["edge_rms"] for r in summary["scans"]] == [r["edge_rms"] for r in serial_rows]
