"""potflat batch against fake stages: isolation, summaries, resume, pools, Dask, validation."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

import test_batch_fakes as fakes
from potflat.files.batch import execution as batch_execution
from potflat.files.batch import manifest as batch_mod
from potflat.files.batch.config import BatchFileError, load_batch
from potflat.files.batch.execution import run_batch
from potflat.files.batch.manifest import MANIFEST, read_manifest
from potflat.files.pipeline import ZONE_FIGURES
from potflat_cli.main import app


@pytest.fixture
def fake_stages(monkeypatch):
    fakes.install(monkeypatch)


@pytest.fixture
def three(tmp_path, fake_stages):
    """A batch of three scans (a glob and a file), one of them corrupt."""
    scans = tmp_path / "scans"
    fakes.write_scan(scans / "amphora-1.obj", 1)
    fakes.write_scan(scans / "amphora-2.obj", 2)
    (scans / "hydria.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement ver")
    path = tmp_path / "batch.yaml"
    path.write_text("output: results/\n"
                    "defaults: {proxy: auto, px_per_mm: 1, preset: preview}\n"
                    "scans:\n"
                    "  - path: scans/amphora-*.obj\n"
                    "    band: [0.2, 0.6]\n"
                    "  - path: scans/hydria.ply\n")
    return path


def cli(*args):
    result = CliRunner().invoke(app, [str(a) for a in args])
    return result


def outputs(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.suffix in (".ply", ".png")}


def test_batch_isolates_the_corrupt_scan(three):
    result = cli("batch", three, "--workers", 1)
    assert result.exit_code == 1, result.output
    res = three.parent / "results"
    for name in ("amphora-1", "amphora-2"):
        folder = res / name
        assert f"{name}.png" in outputs(folder)
        assert (folder / MANIFEST).is_file()
        assert len(outputs(folder)) == 2 + 1 + 3  # two PLYs, the PNG, three maps
    assert read_manifest(res / "hydria")["complete"] is False  # the partial marker, never complete
    assert "not a readable mesh" in result.stderr and "hydria" in result.stderr
    summary = json.loads((res / "summary.json").read_text())
    rows = {r["name"]: r for r in summary["scans"]}
    assert [r["status"] for r in summary["scans"]] == ["done", "done", "failed"]
    assert rows["hydria"]["error"].count("\n") == 0 and "hydria.ply" in rows["hydria"]["error"]
    assert rows["amphora-1"]["flipped"] == 0 and rows["amphora-1"]["edge_rms"] > 0
    relaxed = json.loads((res / "amphora-1" / "amphora-1.relaxed.json").read_text())
    for column, (key, figure) in ZONE_FIGURES.items():  # the painted zone's figures and the plain surface's
        assert rows["amphora-1"][column] == relaxed[key][figure]
    assert 0 < rows["amphora-1"]["painted_area_fraction"] <= 1
    assert rows["amphora-1"]["painted_length_error_p95_pct"] >= rows["amphora-1"]["painted_length_error_median_pct"]
    assert summary["counts"] == {"done": 2, "skipped": 0, "failed": 1, "interrupted": 0, "cancelled": 0}
    with open(res / "summary.csv", newline="") as fh:
        table = list(csv.DictReader(fh))
    assert [r["status"] for r in table] == ["done", "done", "failed"]
    assert float(table[0]["painted_length_error_median_pct"]) == rows["amphora-1"]["painted_length_error_median_pct"]
    assert "hydria" in result.stdout and "failed" in result.stdout  # the rich table
    assert f"{rows['amphora-1']['painted_length_error_median_pct']:.1f} / 2.5" in result.stdout


def test_manifest_records_key_options_and_outputs(three):
    batch = load_batch(three)
    run_batch(batch, workers=1)
    job = batch.jobs[0]
    manifest = json.loads((job.out_dir / MANIFEST).read_text())
    assert manifest["key"] == batch_mod.job_key(job)
    assert manifest["options"]["rollout"]["band"] == [0.2, 0.6]
    assert manifest["options"]["bake"]["px_per_mm"] == 1.0
    assert set(manifest["outputs"]) == set(outputs(job.out_dir)) | {
        "amphora-1.rollout.json", "amphora-1.relaxed.json", "amphora-1.bake.json"}


def test_rerun_skips_finished_and_redoes_changed(three):
    first = run_batch(load_batch(three), workers=1)
    res = three.parent / "results"
    before = {p: p.stat().st_mtime_ns for p in res.rglob("*.png")}
    second = run_batch(load_batch(three), workers=1)
    assert [r.status for r in second.reports] == ["skipped", "skipped", "failed"]
    assert second.reports[0].figures == first.reports[0].figures
    assert {p: p.stat().st_mtime_ns for p in res.rglob("*.png")} == before
    # an option change reruns the scans it applies to
    three.write_text(three.read_text().replace("band: [0.2, 0.6]", "band: [0.2, 0.7]"))
    third = run_batch(load_batch(three), workers=1)
    assert [r.status for r in third.reports] == ["done", "done", "failed"]
    # a changed scan reruns only that scan
    fakes.write_scan(three.parent / "scans" / "amphora-2.obj", 22)
    fourth = run_batch(load_batch(three), workers=1)
    assert [r.status for r in fourth.reports] == ["skipped", "done", "failed"]


def test_force_redoes_all(three):
    run_batch(load_batch(three), workers=1)
    result = cli("batch", three, "--workers", 1, "--force", "--json")
    assert result.exit_code == 1
    summary = json.loads(result.stdout)
    assert [r["status"] for r in summary["scans"]] == ["done", "done", "failed"]


def test_incomplete_outputs_or_changed_texture_rerun(three):
    texture = three.parent / "scans" / "amphora-2.png"  # read by the fake rollout, named by the scan's MTL
    texture.write_bytes(b"texture v1")
    (three.parent / "scans" / "amphora-2.mtl").write_text("newmtl painted\nmap_Kd amphora-2.png\n")
    with open(three.parent / "scans" / "amphora-2.obj", "a") as fh:
        fh.write("mtllib amphora-2.mtl\n")
    run_batch(load_batch(three), workers=1)
    res = three.parent / "results"
    (res / "amphora-1" / "amphora-1.area.png").unlink()
    report = run_batch(load_batch(three), workers=1)
    assert [r.status for r in report.reports] == ["done", "skipped", "failed"]
    assert (res / "amphora-1" / "amphora-1.area.png").is_file()
    assert [r.status for r in run_batch(load_batch(three), workers=1).reports][:2] == ["skipped"] * 2
    texture.write_bytes(b"texture v2")
    assert [r.status for r in run_batch(load_batch(three), workers=1).reports][:2] == ["skipped", "done"]


def test_failed_redo_removes_old_manifest_and_stale_outputs(three):
    run_batch(load_batch(three), workers=1)
    folder = three.parent / "results" / "amphora-1"
    three.write_text(three.read_text().replace("preset: preview}", "preset: preview, maps: [stress]}"))
    run_batch(load_batch(three), workers=1)
    assert not (folder / "amphora-1.area.png").exists()  # no longer asked for
    assert (folder / "amphora-1.stress.png").is_file()
    fakes.SABOTAGE["amphora-1"] = ("raise", "bake")
    report = run_batch(load_batch(three), workers=1, force=True)
    assert report.reports[0].status == "failed"
    assert report.reports[0].error == "RuntimeError: bake exploded second line"
    assert read_manifest(folder)["complete"] is False
    assert "Traceback" in (folder / "error.log").read_text()


def test_json_output_is_the_only_stdout(three):
    result = cli("batch", three, "-w", 1, "--json")
    data = json.loads(result.stdout)
    assert data["counts"]["failed"] == 1 and len(data["scans"]) == 3
    assert data == json.loads((three.parent / "results" / "summary.json").read_text())


def test_quiet_prints_only_failures(three):
    result = cli("batch", three, "-w", 1, "--quiet")
    assert result.exit_code == 1
    assert result.stdout == ""
    assert result.stderr.strip().startswith("failed") and "hydria" in result.stderr
    assert "amphora" not in result.stderr


def test_all_good_exits_zero_and_output_override(three, tmp_path):
    three.write_text(three.read_text().replace("  - path: scans/hydria.ply\n", ""))
    other = tmp_path / "elsewhere"
    result = cli("batch", three, "-w", 1, "-o", other)
    assert result.exit_code == 0, result.output
    assert (other / "amphora-2" / "amphora-2.png").is_file() and (other / "summary.csv").is_file()


def test_local_pool_matches_serial_and_survives_a_dying_worker(three, monkeypatch, tmp_path):
    monkeypatch.setattr(batch_execution, "START_METHOD", "fork")  # the fakes live in this process only
    serial = run_batch(load_batch(three, output=tmp_path / "serial"), workers=1)
    fakes.SABOTAGE["amphora-2"] = ("exit", "relax")
    pooled = run_batch(load_batch(three, output=tmp_path / "pool"), workers=2)
    assert [r.status for r in pooled.reports] == ["done", "failed", "failed"]
    assert "worker process died" in pooled.reports[1].error
    assert "not a readable mesh" in pooled.reports[2].error
    assert outputs(tmp_path / "pool" / "amphora-1") == outputs(tmp_path / "serial" / "amphora-1")
    assert serial.reports[0].figures == pooled.reports[0].figures


@pytest.mark.dask
def test_dask_local_cluster_gives_identical_results(three, tmp_path):
    distributed = pytest.importorskip("distributed")
    serial = run_batch(load_batch(three, output=tmp_path / "serial"), workers=1)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  protocol="tcp", host="127.0.0.1", dashboard_address=None) as cluster:
        result = cli("batch", three, "--scheduler", cluster.scheduler_address, "-o", tmp_path / "dask",
                     "--json")
    assert result.exit_code == 1, result.output
    data = json.loads(result.stdout)
    assert [r["status"] for r in data["scans"]] == ["done", "done", "failed"]
    for name in ("amphora-1", "amphora-2"):
        assert outputs(tmp_path / "dask" / name) == outputs(tmp_path / "serial" / name)
    assert [r["edge_rms"] for r in data["scans"]] == [r.figures.get("edge_rms") for r in serial.reports]


@pytest.mark.dask
def test_unreachable_scheduler_is_a_usage_error(three, monkeypatch):
    pytest.importorskip("distributed")
    monkeypatch.setattr(batch_execution, "CONNECT_TIMEOUT", "2s")
    result = cli("batch", three, "--scheduler", "tcp://127.0.0.1:1")
    assert result.exit_code == 2
    assert "cannot connect to the Dask scheduler" in result.stderr
    assert not (three.parent / "results").exists()


# ------------------------------------------------------------------ validation (exit code 2)
BAD = {
    "unknown top-level key": ("output: r/\noutptu: x\nscans: [a.obj]\n", 2, "did you mean 'output'"),
    "option at top level": ("output: r/\nproxy: cone\nscans: [a.obj]\n", 2, "under 'defaults:'"),
    "unknown option in defaults": ("output: r/\ndefaults:\n  px_per_m: 4\nscans: [a.obj]\n", 3,
                                   "did you mean 'px_per_mm'"),
    "unknown option in a scan": ("output: r/\nscans:\n  - path: a.obj\n    bnad: [0, 1]\n", 4,
                                 "did you mean 'band'"),
    "wrong type": ("output: r/\ndefaults: {px_per_mm: four}\nscans: [a.obj]\n", 2,
                   "'px_per_mm' must be a number, got 'four'"),
    "wrong type in a scan": ("output: r/\nscans:\n  - path: a.obj\n    band: 0.5\n", 4,
                             "'band' must be a list of 2 numbers"),
    "bad choice": ("output: r/\ndefaults: {proxy: cnoe}\nscans: [a.obj]\n", 2, "did you mean cone"),
    "missing file": ("output: r/\nscans:\n  - path: a.obj\n  - path: nothere.obj\n", 4,
                     "nothere.obj does not exist"),
    "glob matching nothing": ("output: r/\nscans:\n  - path: 'x-*.obj'\n", 3, "matches no file"),
    "bad value": ("output: r/\ndefaults: {px_per_mm: 4}\nscans:\n  - path: a.obj\n"
                  "    band: [0.6, 0.2]\n", 5, "band must be two fractions"),
    "bad value in defaults": ("output: r/\ndefaults:\n  max_iter: 0\nscans: [a.obj]\n", 3,
                              "max_iter must be at least 1"),
    "not a mapping": ("- a.obj\n- b.obj\n", 1, "must be a mapping"),
    "empty file": ("", 1, "got an empty file"),
    "bad YAML syntax": ("output: r/\nscans:\n  - path: a.obj\n   band: [0.2\n", 4, "invalid YAML"),
    "duplicate key": ("output: r/\noutput: s/\nscans: [a.obj]\n", 2, "given twice"),
    "missing output": ("scans: [a.obj]\n", 1, "missing 'output:'"),
    "missing scans": ("output: r/\n", 1, "missing 'scans:'"),
    "scans not a list": ("output: r/\nscans: {path: a.obj}\n", 2, "non-empty list"),
    "scan without path": ("output: r/\nscans:\n  - band: [0, 1]\n", 3, "without 'path:'"),
    "defaults not a mapping": ("output: r/\ndefaults: [1, 2]\nscans: [a.obj]\n", 2, "must be a mapping"),
    "same scan twice": ("output: r/\nscans:\n  - a.obj\n  - '*.obj'\n", 4,
                        "listed on line 3, is listed again on line 4"),
    "same output name": ("output: r/\nscans:\n  - a.obj\n  - sub/a.obj\n", 4, "would both write"),
    "not a scan format": ("output: r/\nscans:\n  - notes.txt\n", 3, "not a scan format"),
    "glob matching no scan": ("output: r/\nscans:\n  - '*.txt'\n", 3, "matches 1 files but no scan"),
    "same name but for case": ("output: r/\nscans:\n  - a.obj\n  - path: b.obj\n    name: A\n", 4,
                               "would both write"),
    "name with a glob": ("output: r/\nscans:\n  - path: '*.obj'\n    name: x\n", 4, "matches 2"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_batch_file_exit_2_with_line(case, tmp_path, fake_stages):
    text, line, message = BAD[case]
    fakes.write_scan(tmp_path / "a.obj")
    fakes.write_scan(tmp_path / "b.obj")
    fakes.write_scan(tmp_path / "sub" / "a.obj")
    (tmp_path / "notes.txt").write_text("not a scan")
    path = tmp_path / "batch.yaml"
    path.write_text(text)
    result = cli("batch", path)
    assert result.exit_code == 2, result.output
    assert result.stdout == ""
    assert f"batch.yaml:{line}: " in result.stderr, result.stderr
    assert message in result.stderr, result.stderr
    assert not (tmp_path / "r").exists()  # nothing ran


def test_every_problem_is_reported_at_once(tmp_path, fake_stages):
    path = tmp_path / "b.yaml"
    path.write_text("output: r/\ndefaults: {px_per_mm: x, proxi: cone}\nscans:\n  - gone.obj\n")
    with pytest.raises(BatchFileError) as info:
        load_batch(path)
    assert len(info.value.problems) == 3
    assert all(p.startswith(f"{path}:") and "\n" not in p for p in info.value.problems)


def test_shorthand_entries_names_and_output_relative_to_file(tmp_path, fake_stages):
    fakes.write_scan(tmp_path / "d" / "a.obj")
    fakes.write_scan(tmp_path / "d" / "sub" / "a.obj")
    path = tmp_path / "d" / "batch.yaml"
    path.write_text("output: out\nscans:\n  - a.obj\n  - path: sub/a.obj\n    name: a2\n"
                    "    relax: ignored\n" .replace("    relax: ignored\n", "    tol: 1e-3\n"))
    batch = load_batch(path)
    assert batch.output == (tmp_path / "d" / "out").resolve()
    assert [j.name for j in batch.jobs] == ["a", "a2"]
    assert batch.jobs[1].options.relax.tol == 1e-3 and batch.jobs[0].options.relax.tol == 1e-6
    assert batch.jobs[1].out_dir == batch.output / "a2"


def test_glob_skips_the_output_folder(tmp_path, fake_stages):
    fakes.write_scan(tmp_path / "a.obj")
    fakes.write_scan(tmp_path / "res" / "a" / "old.obj")
    path = tmp_path / "batch.yaml"
    path.write_text("output: res\nscans: ['**/*.obj']\n")
    assert [j.scan.name for j in load_batch(path).jobs] == ["a.obj"]


def test_one_line_strips_newlines_and_colour_codes():
    from potflat.files.batch.execution import one_line
    from potflat.errors import InvalidInputError

    assert one_line(RuntimeError("\x1b[1mIllegal IR\x1b[0m\n  at x")) == "RuntimeError: Illegal IR at x"
    assert one_line(InvalidInputError("a.ply: truncated; re-export")) == "a.ply: truncated; re-export"
    assert one_line(KeyError()) == "KeyError"
    assert len(one_line(ValueError("x" * 1000))) == 400


def test_sample_batch_file_is_valid():
    sample = Path(__file__).resolve().parents[1] / "samples" / "batch.yaml"
    batch = load_batch(sample)
    assert [job.name for job in batch.jobs] == ["amphora", "cone"]
    assert batch.jobs[0].options.rollout.band == (0.05, 0.95)
    assert batch.jobs[1].options.rollout.proxy == "cone"
    assert batch.jobs[1].options.bake.maps == ("stress", "area")
    assert batch.output == sample.parent.parent / "out" / "batch"


def test_interrupt_keeps_finished_scans_and_writes_the_summary(three):
    fakes.SABOTAGE["amphora-2"] = ("interrupt", "bake")
    result = cli("batch", three, "-w", 1)
    assert result.exit_code == 130
    assert "interrupted" in result.stderr
    res = three.parent / "results"
    assert (res / "amphora-1" / MANIFEST).is_file()
    assert (read_manifest(res / "amphora-2") or {}).get("complete") is not True
    assert not [p for p in res.rglob("*") if p.name.endswith(".part")]
    summary = json.loads((res / "summary.json").read_text())
    assert [r["status"] for r in summary["scans"]] == ["done", "interrupted", "cancelled"]
    fakes.SABOTAGE.clear()
    again = run_batch(load_batch(three), workers=1)
    assert [r.status for r in again.reports] == ["skipped", "done", "failed"]


def test_scheduler_without_dask_says_what_to_install(three, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    result = cli("batch", three, "--scheduler", "tcp://127.0.0.1:8786")
    assert result.exit_code == 2
    assert "pip install 'dask[distributed]'" in result.stderr
    assert not (three.parent / "results").exists()  # nothing ran, no summary


def test_scan_vanishing_after_validation_fails_only_that_scan(three):
    batch = load_batch(three)
    (three.parent / "scans" / "amphora-1.obj").unlink()
    summary = run_batch(batch, workers=1)
    assert [r.status for r in summary.reports] == ["failed", "done", "failed"]
    assert "amphora-1.obj: cannot read" in summary.reports[0].error
