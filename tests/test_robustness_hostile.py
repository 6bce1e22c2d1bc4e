"""Hostile inputs and first contact (catalogue in docs/robustness.md).

One small negative test per check, each case generated in ``tmp_path``: data safety (a batch
confined to its output folder, a private texture cache, bounded YAML, confined globs, the
output-folder lock, unsafe names), one clear line and exit 2 instead of tracebacks, no
silent wrong results, clean interruptions and the defaults a user expects. The batch and
pipeline cases run against the fake stages of ``test_batch_fakes`` (fast); the loader and
stage-file cases against the real readers.
"""
from __future__ import annotations

import json
import os
import signal
import struct
import subprocess
import sys
import time
import zlib
from pathlib import Path

import numpy as np
import pytest
import test_batch_fakes as fakes
from potflat_cli._stage import PROGRESS
from potflat_cli.main import app
from typer.testing import CliRunner

from potflat.errors import FoldedResultError, InvalidInputError
from potflat.files.batch.config import BatchFileError, load_batch
from potflat.files.batch.execution import run_batch
from potflat.files.batch.manifest import MANIFEST, read_manifest

runner = CliRunner()


def cli(*args):
    return runner.invoke(app, [str(a) for a in args])


COMPILING = "potflat: first run: compiling"


def one_line_error(result, *words: str) -> str:
    """Exit 2, exactly one ``error:`` line on stderr with ``words``, no traceback, no box."""
    assert result.exit_code == 2, (result.exit_code, result.output)
    assert "Traceback" not in result.output and "╭" not in result.output, result.output
    # lines of progress (a run whose kernels are not cached yet says so first; in a log each
    # stage says when it starts and ends) come before it
    lines = [line for line in result.stderr.strip().splitlines() if not line.startswith(PROGRESS)]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for word in words:
        assert word.lower() in lines[0].lower(), (word, lines[0])
    return lines[0]


@pytest.fixture
def fake_stages(monkeypatch):
    fakes.install(monkeypatch)


def _batch(tmp_path: Path, body: str, n: int = 2) -> Path:
    for k in range(n):
        fakes.write_scan(tmp_path / "scans" / f"pot-{k}.obj", k)
    path = tmp_path / "batch.yaml"
    path.write_text(f"output: results/\nscans:\n{body}")
    return path


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def _png_header_only(path: Path, width: int, height: int) -> Path:
    """A PNG whose header declares ``width`` x ``height`` RGB pixels (nothing is decoded)."""
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
                     + _png_chunk(b"IDAT", zlib.compress(b"\0" * 100)) + _png_chunk(b"IEND", b""))
    return path


def _tube_obj(path: Path, radius: float = 40.0, height: float = 120.0, scale: float = 1.0, extra: str = "") -> Path:
    """An open cylinder (a plain vessel wall), coordinates multiplied by ``scale``."""
    t = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    z = np.linspace(0, height, 12)
    V = np.array([[radius * np.cos(a), radius * np.sin(a), h] for h in z for a in t]) * scale
    lines = [f"v {x:.9g} {y:.9g} {w:.9g}" for x, y, w in V]
    for i in range(len(z) - 1):
        for j in range(32):
            p, q = i * 32 + j, i * 32 + (j + 1) % 32
            lines += [f"f {p + 1} {q + 1} {q + 33}", f"f {p + 1} {q + 33} {p + 33}"]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(extra + "\n".join(lines) + "\n")
    return path


# ---------------------------------------------------------------------------------------
# data safety


def test_a_manifest_never_directs_a_batch_outside_its_folder(tmp_path, fake_stages):
    """A planted manifest listing ../../victim and /abs/victim: nothing outside is deleted."""
    batch = _batch(tmp_path, "  - path: scans/*.obj\n")
    assert run_batch(load_batch(batch), workers=1).exit_code == 0
    victims = [tmp_path / "victim-rel", tmp_path / "victim-abs"]
    for v in victims:
        v.write_text("precious")
    folder = tmp_path / "results" / "pot-0"
    manifest = read_manifest(folder)
    manifest["outputs"].update({"../../victim-rel": 8, str(victims[1]): 8, "../pot-1/pot-1.png": 1})
    (folder / MANIFEST).write_text(json.dumps(manifest))
    assert [r.status for r in run_batch(load_batch(batch), workers=1, force=True).reports] == ["done", "done"]
    assert all(v.read_text() == "precious" for v in victims)
    assert (tmp_path / "results" / "pot-1" / "pot-1.png").is_file()


def test_the_texture_cache_is_private_and_never_trusted(tmp_path):
    """An embedded GLB texture is extracted into a new 0700 folder of this process, never into
    a shared folder where a planted file (or symlink) could replace the painting."""
    import tempfile

    import trimesh
    from PIL import Image

    from potflat.io import scan as scan_io

    painting = Image.new("RGB", (16, 16), (200, 30, 40))
    t = np.linspace(0, 2 * np.pi, 24, endpoint=False)
    V = np.array([[40 * np.cos(a), 40 * np.sin(a), h] for h in (0.0, 60.0, 120.0) for a in t])
    F = [[i * 24 + j, i * 24 + (j + 1) % 24, (i + 1) * 24 + (j + 1) % 24] for i in range(2) for j in range(24)]
    F += [[i * 24 + j, (i + 1) * 24 + (j + 1) % 24, (i + 1) * 24 + j] for i in range(2) for j in range(24)]
    uv = np.column_stack([np.tile(t / (2 * np.pi), 3), np.repeat([0.0, 0.5, 1.0], 24)])
    mesh = trimesh.Trimesh(V / 1000.0, F, process=False,
                           visual=trimesh.visual.TextureVisuals(uv=uv, image=painting))
    glb = tmp_path / "pot.glb"
    glb.write_bytes(mesh.export(file_type="glb"))
    # plant files in a shared cache folder, where an attacker could
    shared = Path(tempfile.gettempdir()) / f"potflat-textures-{os.environ.get('USER', 'root')}"
    shared.mkdir(exist_ok=True)
    for name in [p.name for p in shared.glob("*.png")] + ["planted.png"]:
        Image.new("RGB", (16, 16), (0, 255, 0)).save(shared / name)
    loaded = scan_io.load_scan(glb)
    tex = loaded.mesh.texture_path
    assert shared not in tex.parents
    assert (tex.parent.stat().st_mode & 0o777) == 0o700
    assert np.asarray(Image.open(tex).convert("RGB"))[0, 0].tolist() == [200, 30, 40]


def test_yaml_alias_bomb_in_an_option_value_is_refused(tmp_path, fake_stages):
    levels = ["a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    levels += [f"a{k}: &a{k} [{', '.join([f'*a{k - 1}'] * 9)}]" for k in range(1, 9)]
    batch = _batch(tmp_path, "  - path: scans/pot-0.obj\n", n=1)
    text = batch.read_text().replace("scans:\n", "defaults:\n  maps: *a8\nscans:\n")
    batch.write_text("x-aliases:\n" + "\n".join("  " + lv for lv in levels) + "\n" + text)
    start = time.monotonic()
    with pytest.raises(BatchFileError, match="expands to more than"):
        load_batch(batch)
    assert time.monotonic() - start < 5


def test_yaml_nested_too_deeply_or_too_long_is_one_problem(tmp_path, fake_stages):
    path = tmp_path / "deep.yaml"
    path.write_text("output: o\nscans: " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(BatchFileError, match="nested too deeply"):
        load_batch(path)
    path.write_text("output: o\nscans:\n  - path: " + "x" * 5000 + ".obj\n")
    with pytest.raises(BatchFileError, match="5004 characters"):
        load_batch(path)


@pytest.mark.parametrize("pattern", ["/**/*.ply", "../*.obj", "scans/*/../../../*.obj"])
def test_a_pattern_outside_the_batch_folder_is_refused(tmp_path, fake_stages, pattern):
    (tmp_path / "inner").mkdir()
    batch = _batch(tmp_path / "inner", f"  - path: '{pattern}'\n")
    with pytest.raises(BatchFileError, match="outside the batch file's folder"):
        load_batch(batch)


def test_a_second_batch_on_the_same_output_folder_is_refused(tmp_path, fake_stages):
    from potflat.io.atomic import output_lock

    batch = _batch(tmp_path, "  - path: scans/*.obj\n")
    with output_lock(tmp_path / "results"):
        one_line_error(cli("batch", batch, "-w", 1), "results", "in use")
    assert cli("batch", batch, "-w", 1).exit_code == 0
    assert not (tmp_path / "results" / ".potflat.lock").exists()


@pytest.mark.parametrize("entry,words", [
    ("  - path: scans/pot-0.obj\n    name: summary.json\n", ("summary.json", "reserved")),
    ("  - path: scans/pot-0.obj\n    name: ../escaped\n", ("../escaped", "plain file name")),
    ("  - path: scans/...obj\n", ("..", "leading dot")),
    ("  - path: scans/new*.obj\n", ("control character",)),
])
def test_unsafe_scan_names_are_refused_when_the_batch_is_checked(tmp_path, fake_stages, entry, words):
    fakes.write_scan(tmp_path / "scans" / "...obj")
    fakes.write_scan(tmp_path / "scans" / "new\nline.obj")
    batch = _batch(tmp_path, entry)
    with pytest.raises(BatchFileError) as err:
        load_batch(batch)
    assert all(w in str(err.value) for w in words), str(err.value)
    assert not (tmp_path / "results").exists()


@pytest.mark.parametrize("name,words", [("../escaped", ("plain file name",)), ("a\nb", ("control character",)),
                                        ("summary.csv", ("reserved",))])
def test_unsafe_name_option_is_exit_2(tmp_path, fake_stages, name, words):
    scan = fakes.write_scan(tmp_path / "pot.obj")
    one_line_error(cli("run", scan, "-o", tmp_path / "out", "--name", name), *words)
    assert not (tmp_path / "out").exists() and not (tmp_path / "escaped").exists()


# ---------------------------------------------------------------------------------------
# one line and exit 2 instead of a traceback


@pytest.mark.parametrize("units,likely", [(1e-3, "metres: add --units m"), (1e3, "micrometres: add --units um")])
def test_a_scan_in_another_unit_is_refused_with_the_likely_unit(tmp_path, units, likely):
    scan = _tube_obj(tmp_path / "vase.obj", scale=units)
    one_line_error(cli("run", scan, "-o", tmp_path / "out"), "vase.obj", likely)
    assert not (tmp_path / "out").exists()
    # declared, it runs (the rollout alone is enough to show it)
    assert cli("rollout", scan, "-o", tmp_path / "out", "--units", "m" if units < 1 else "um", "-q").exit_code == 0


@pytest.mark.parametrize("px_per_mm,words", [("0.01", ("or more",)), ("1e-9", ("or more",)),
                                             ("1000", ("megapixels", "or less"))])
def test_image_size_is_checked_before_any_file_is_written(tmp_path, px_per_mm, words):
    scan = _tube_obj(tmp_path / "vase.obj")
    out = tmp_path / "out"
    one_line_error(cli("run", scan, "-o", out, "--px-per-mm", px_per_mm), "vase.obj", "--px-per-mm", *words)
    assert not out.exists() or not any(out.iterdir())


def test_a_tiny_image_draws_its_scale_bar_without_crashing():
    from potflat.bake.annotate import ScaleLayer

    layer = ScaleLayer(20, 12, 0.05)
    assert layer.rows(0, 12).shape == (12, 20, 4) and layer.bar_image().ndim == 3


def test_a_texture_over_the_memory_budget_is_refused_with_its_size(tmp_path):
    from potflat.io.images import read_texture
    from potflat.io.scan import load_scan

    scan = _tube_obj(tmp_path / "pot.obj", extra="mtllib pot.mtl\nvt 0 0\nvt 1 0\nvt 1 1\nusemtl m\n")
    text = scan.read_text().splitlines()
    scan.write_text("\n".join(ln if not ln.startswith("f ") else
                              "f " + " ".join(f"{v}/{k + 1}" for k, v in enumerate(ln.split()[1:]))
                              for ln in text) + "\n")
    (tmp_path / "pot.mtl").write_text("newmtl m\nmap_Kd big.png\n")
    _png_header_only(tmp_path / "big.png", 30000, 30000)
    with pytest.raises(InvalidInputError, match=r"30000 x 30000 pixels \(2\.5 GiB decoded\).*downsample"):
        load_scan(scan)
    with pytest.raises(InvalidInputError, match="30000 x 30000"):
        read_texture(tmp_path / "big.png")


def test_utf8_and_latin1_names_in_obj_mtl_and_stage_files(tmp_path):
    from PIL import Image

    from potflat.io.flat_ply import read_flat_ply, write_flat_ply
    from potflat.io.scan import load_scan
    from potflat.types import FlatMesh

    folder = tmp_path / "Fund ü"
    scan = _tube_obj(folder / "Vase é.obj", extra="mtllib Vase é.mtl\nvt 0 0\nvt 1 0\nvt 1 1\nusemtl m\n")
    scan.write_text("\n".join(ln if not ln.startswith("f ") else
                              "f " + " ".join(f"{v}/{k + 1}" for k, v in enumerate(ln.split()[1:]))
                              for ln in scan.read_text().splitlines()) + "\n")
    Image.new("RGB", (8, 8), (9, 9, 9)).save(folder / "Bild ä.png")
    for encoding in ("utf-8", "latin-1"):
        (folder / "Vase é.mtl").write_bytes("newmtl m\nmap_Kd Bild ä.png\n".encode(encoding))
        mesh = load_scan(scan).mesh
        assert mesh.texture_path.name == "Bild ä.png", encoding
    flat = FlatMesh(mesh, mesh.vertices[:, :2].copy())
    back = read_flat_ply(write_flat_ply(tmp_path / "out" / "Vase é.rollout.ply", flat))
    assert back.mesh.texture_path.name == "Vase é.texture.png" and back.mesh.texture_path.is_file()


HOSTILE_PLY = {
    "list count -1": ("element vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\n"
                      "property list char int vertex_indices\n", struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
                      + struct.pack("<b3i", -1, 0, 1, 2), "negative length"),
    "uint list of 4e9": ("element vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\n"
                         "property list uint int vertex_indices\n", struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
                         + struct.pack("<I3i", 4_000_000_000, 0, 1, 2), "truncated"),
    "element vertex abc": ("element vertex abc\nproperty float x\n", b"", "malformed PLY header"),
    "element vertex -3": ("element vertex -3\nproperty float x\n", b"", "negative element count"),
    "list without a name": ("element vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\n"
                            "property list uchar int\n", struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
                            + struct.pack("<B3i", 3, 0, 1, 2), "malformed PLY header"),
}


@pytest.mark.parametrize("case", list(HOSTILE_PLY))
@pytest.mark.parametrize("command", ["rollout", "relax", "bake"])
def test_hostile_ply_headers_are_one_line_in_every_reader(tmp_path, case, command):
    header, body, words = HOSTILE_PLY[case]
    name = {"rollout": "pot.ply", "relax": "pot.rollout.ply", "bake": "pot.relaxed.ply"}[command]
    path = tmp_path / name
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\n" + header.encode() + b"end_header\n" + body)
    one_line_error(cli(command, path, "-o", tmp_path / "out"), name)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("args,words", [
    (lambda d: ["run", d / "x.obj", "-o", d / "o"], ("x.obj", "directory")),
    (lambda d: ["batch", d / "x.obj"], ("x.obj", "directory")),
    (lambda d: ["batch", d / "b.yaml", "--workers", "0"], ("--workers",)),
    (lambda d: ["run", "/dev/zero", "-o", d / "o"], ("/dev/zero", "not a regular file")),
    (lambda d: ["relax", "/dev/zero", "-o", d / "o"], ("/dev/zero",)),
])
def test_usage_errors_are_one_line_not_a_box(tmp_path, args, words):
    (tmp_path / "x.obj").mkdir()
    (tmp_path / "b.yaml").write_text("output: o\nscans: [x.obj]\n")
    one_line_error(cli(*args(tmp_path)), *words)


def test_a_texture_symlink_loop_is_one_line(tmp_path):
    scan = _tube_obj(tmp_path / "pot.obj", extra="mtllib pot.mtl\nvt 0 0\nvt 1 0\nvt 1 1\nusemtl m\n")
    scan.write_text("\n".join(ln if not ln.startswith("f ") else
                              "f " + " ".join(f"{v}/{k + 1}" for k, v in enumerate(ln.split()[1:]))
                              for ln in scan.read_text().splitlines()) + "\n")
    (tmp_path / "pot.mtl").write_text("newmtl m\nmap_Kd loop.png\n")
    os.symlink(tmp_path / "loop.png", tmp_path / "loop.png")
    one_line_error(cli("rollout", scan, "-o", tmp_path / "out"), "loop.png", "--no-texture")


@pytest.mark.parametrize("sidecar", ["null", "[1, 2]", '{"attachments": null}', '{"attachments": {"root_faces": "x"}}'])
def test_a_sidecar_of_the_wrong_type_does_not_break_the_next_stage(tmp_path, sidecar):
    from potflat.bake import BakeOptions
    from potflat.files.bake_stage import run_bake_stage
    from potflat.files.relax_stage import run_relax_stage
    from potflat.io.flat_ply import write_flat_ply
    from potflat.relax import RelaxOptions
    from potflat.types import FlatMesh, Mesh

    x, y = np.meshgrid(np.linspace(0, 40, 6), np.linspace(0, 30, 5))
    V = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    F = np.array([[r * 6 + c, r * 6 + c + 1, r * 6 + c + 7] for r in range(4) for c in range(5)]
                 + [[r * 6 + c, r * 6 + c + 7, r * 6 + c + 6] for r in range(4) for c in range(5)])
    write_flat_ply(tmp_path / "pot.rollout.ply", FlatMesh(Mesh(V, F), V[:, :2].copy()))
    (tmp_path / "pot.rollout.json").write_text(sidecar)
    run_relax_stage(tmp_path / "pot.rollout.ply", tmp_path, RelaxOptions(preset="preview"))
    out = run_bake_stage(tmp_path / "pot.relaxed.ply", tmp_path, BakeOptions(px_per_mm=1, maps=()))
    assert out.paths["png"].is_file()


def test_a_batch_output_that_cannot_be_written_is_one_line(tmp_path, fake_stages):
    batch = _batch(tmp_path, "  - path: scans/*.obj\n")
    (tmp_path / "notes.txt").write_text("x")
    one_line_error(cli("batch", batch, "-o", tmp_path / "notes.txt" / "out"), "notes.txt")


def test_overflowing_coordinates_are_named(tmp_path):
    path = tmp_path / "big.obj"
    path.write_text("v 1e302 0 0\nv 0 1e302 0\nv 0 0 1e302\nv 1e302 1e302 1e302\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    one_line_error(cli("run", path, "-o", tmp_path / "o"), "big.obj", "1e+302", "overflow")


def test_paper_dynamics_that_diverge_stop_with_one_line_and_write_nothing(tmp_path, monkeypatch):
    from potflat.files.relax_stage import run_relax_stage
    from potflat.io.flat_ply import write_flat_ply
    from potflat.relax import energy as relax_mod
    from potflat.relax import options as relax_options
    from potflat.types import FlatMesh, Mesh

    x, y = np.meshgrid(np.linspace(0, 40, 8), np.linspace(0, 30, 7))
    V = np.column_stack([x.ravel(), y.ravel(), 0.1 * np.sin(x.ravel())])
    F = np.array([[r * 8 + c, r * 8 + c + 1, r * 8 + c + 9] for r in range(6) for c in range(7)]
                 + [[r * 8 + c, r * 8 + c + 9, r * 8 + c + 8] for r in range(6) for c in range(7)])
    write_flat_ply(tmp_path / "pot.rollout.ply", FlatMesh(Mesh(V, F), V[:, :2].copy()))
    monkeypatch.setattr(relax_mod.SpringSystem, "laplacian_bound", lambda self: 1e-4)  # a step 100x too long
    with pytest.raises(FoldedResultError, match="diverged.*--preset standard"):
        run_relax_stage(tmp_path / "pot.rollout.ply", tmp_path / "out", relax_options.RelaxOptions(preset="paper"))
    assert not (tmp_path / "out").exists()
    # the advice works
    out = run_relax_stage(tmp_path / "pot.rollout.ply", tmp_path / "out", relax_options.RelaxOptions(preset="standard"))
    assert out.record["fold_free"]


def test_the_paper_step_bounds_the_largest_eigenvalue():
    """dt = 1.9 / sqrt(bound) is stable when bound >= the spring Laplacian's largest
    eigenvalue; the earlier power-iteration estimate came from below (diverged on real scans)."""
    from potflat.relax import energy as relax_mod
    from potflat.relax import parameters as relax_parameters
    from potflat.types import FlatMesh, Mesh

    rng = np.random.default_rng(1)
    x, y = np.meshgrid(np.linspace(0, 10, 7), np.linspace(0, 8, 6))
    V = np.column_stack([x.ravel() + rng.normal(0, 0.2, x.size), y.ravel(), np.zeros(x.size)])
    F = np.array([[r * 7 + c, r * 7 + c + 1, r * 7 + c + 8] for r in range(5) for c in range(6)]
                 + [[r * 7 + c, r * 7 + c + 8, r * 7 + c + 7] for r in range(5) for c in range(6)])
    flat = FlatMesh(Mesh(V, F), V[:, :2].copy())
    for weighting in ("uniform", "relative"):
        sp = relax_mod.SpringSystem(flat.mesh.vertices, F, len(V), k=0.5, relative=weighting == "relative")
        n = sp.n
        L = np.zeros((n, n))
        for i in range(n):
            for p in range(sp.ptr[i], sp.ptr[i + 1]):
                j = sp.nbr[p]
                c = sp.k / max(sp.rst[p], relax_parameters.ENERGY.length_floor) ** 2 if sp.relative else sp.k
                L[i, i] += c
                L[i, j] -= c
        assert sp.laplacian_bound() >= np.linalg.eigvalsh(L).max() * (1 - 1e-12)


# ---------------------------------------------------------------------------------------
# silent wrong results


def test_obj_faces_naming_missing_texture_coordinates_are_refused(tmp_path):
    scan = _tube_obj(tmp_path / "pot.obj")
    scan.write_text("\n".join(ln if not ln.startswith("f ") else "f " + " ".join(f"{v}/{v}" for v in ln.split()[1:])
                              for ln in scan.read_text().splitlines()) + "\n")
    one_line_error(cli("rollout", scan, "-o", tmp_path / "out"), "pot.obj", "no 'vt' lines", "--no-texture")
    assert cli("rollout", scan, "-o", tmp_path / "out", "--no-texture", "-q").exit_code == 0


# ---------------------------------------------------------------------------------------
# interruption and concurrency


def test_an_interrupted_batch_records_cancelled_and_interrupted_scans(tmp_path, fake_stages):
    from potflat.files.batch.execution import _unfinished

    batch = load_batch(_batch(tmp_path, "  - path: scans/*.obj\n"))
    started = time.time()
    first, second = batch.jobs
    first.out_dir.mkdir(parents=True)
    (first.out_dir / MANIFEST).write_text(json.dumps({"complete": False, "name": first.name}))
    assert _unfinished(first, started).status == "interrupted"
    assert _unfinished(second, started).status == "cancelled"


def test_stopping_the_pool_ends_its_workers_and_cancels_the_queue():
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing.connection import wait

    from potflat.files.batch.execution import START_METHOD, _stop_workers, _worker_start

    pool = ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context(START_METHOD),
                               initializer=_worker_start, initargs=(os.getpid(),))
    running = pool.submit(time.sleep, 60)
    queued = [pool.submit(time.sleep, 60) for _ in range(3)]
    while not running.running():
        time.sleep(0.05)
    processes = list(pool._processes.values())
    start = time.monotonic()
    _stop_workers(pool)
    assert time.monotonic() - start < 30
    # ended: each sentinel is ready (is_alive can read True for a moment while the executor's
    # own thread reaps the process)
    assert processes and len(wait([p.sentinel for p in processes], timeout=0)) == len(processes)
    time.sleep(0.5)  # the executor's own thread marks what was left
    finished = [f for f in queued if f.done() and not f.cancelled() and f.exception(timeout=0) is None]
    assert not finished  # no queued scan ran after the stop


def test_potflats_own_partial_painting_does_not_block_the_rerun(tmp_path, fake_stages):
    """Killed between NAME.png and NAME.bake.json: the marker says the PNG is potflat's."""
    from potflat.files.pipeline import partial_marker, run_scan

    scan = fakes.write_scan(tmp_path / "pot.obj")
    out = tmp_path / "out"
    fakes.SABOTAGE["pot"] = ("interrupt", "bake")
    with pytest.raises(KeyboardInterrupt):
        run_scan(scan, out)
    (out / "pot.png").write_bytes(b"half")  # as a kill after the painting leaves it, with the marker
    partial_marker(out, "pot").write_text("{}")
    (out / ".pot.png.abc123.part").write_bytes(b"debris")
    fakes.SABOTAGE.clear()
    run_scan(scan, out)
    assert (out / "pot.bake.json").is_file()
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == []


def test_batch_force_redoes_a_scan_interrupted_in_its_bake(tmp_path, fake_stages):
    from potflat.files.pipeline import partial_marker

    batch = _batch(tmp_path, "  - path: scans/pot-0.obj\n", n=1)
    fakes.SABOTAGE["pot-0"] = ("interrupt", "bake")
    with pytest.raises(KeyboardInterrupt):
        run_batch(load_batch(batch), workers=1)
    folder = tmp_path / "results" / "pot-0"
    (folder / "pot-0.png").write_bytes(b"half")  # as a kill during the bake leaves it, with the marker
    partial_marker(folder, "pot-0").write_text("{}")
    fakes.SABOTAGE.clear()
    for force in (False, True):
        assert [r.status for r in run_batch(load_batch(batch), workers=1, force=force).reports] == ["done"]
        assert read_manifest(folder)["complete"] is True


def _exit_code_of_stopped(command) -> int:
    """Run ``command`` (a :func:`user_errors` command that records a stop signal) and return
    the exit code it ends with; the recorded signals are cleared afterwards."""
    import typer
    from potflat_cli._errors import STOP

    try:
        with pytest.raises(typer.Exit) as exit_:
            command()
    finally:
        STOP.clear()
    return exit_.value.exit_code


def test_an_interrupt_python_swallowed_still_stops_with_130(capsys):
    """A KeyboardInterrupt raised inside a finaliser is only printed by Python; the signal is
    remembered and the command still ends as interrupted."""
    from potflat_cli._errors import STOP, user_errors

    @user_errors
    def command():
        STOP.append(signal.SIGTERM)  # the handler ran, its KeyboardInterrupt was lost

    assert _exit_code_of_stopped(command) == 130 and "interrupted" in capsys.readouterr().err


def test_an_interrupt_inside_a_finaliser_prints_no_traceback(capsys, monkeypatch):
    """The handler's KeyboardInterrupt raised inside a weakref callback or a finaliser is
    "unraisable": Python printed "Exception ignored in ... Traceback" (1 SIGTERM in 40 at a
    random moment); the command's one line says it all. So is a finaliser's error once
    stopping (whatever the interrupt broke). Before a stop, unraisable errors are printed."""
    from potflat_cli._errors import STOP
    from potflat_cli.main import _quiet_unraisable

    class Finalised:
        def __init__(self, error):
            self.error = error

        def __del__(self):
            raise self.error

    monkeypatch.setattr(sys, "unraisablehook", _quiet_unraisable)
    STOP.append(signal.SIGTERM)
    try:
        Finalised(KeyboardInterrupt())
        Finalised(AttributeError("'ValueRef' object has no attribute '_as_parameter_'"))
    finally:
        STOP.clear()
    assert capsys.readouterr().err == ""
    Finalised(ValueError("a real error"))
    assert "a real error" in capsys.readouterr().err


def test_an_interrupt_that_broke_a_numba_call_stops_with_130_not_a_traceback(capsys):
    """A signal handled while a Numba dispatcher calls back into Python makes the call raise
    SystemError ("returned a result with an exception set"); after a stop signal, any error
    is the interrupt's."""
    from potflat_cli._errors import STOP, user_errors

    @user_errors
    def command():
        STOP.append(signal.SIGTERM)
        raise SystemError("CPUDispatcher(<function build_csr>) returned a result with an exception set")

    assert _exit_code_of_stopped(command) == 130 and "interrupted" in capsys.readouterr().err

    @user_errors
    def broken():  # without a stop signal the error is a bug, and is not hidden
        raise SystemError("a bug")

    with pytest.raises(SystemError):
        broken()


def test_python_m_ends_an_interrupt_that_left_an_exec_with_130(tmp_path):
    """Under ``python -m``, a KeyboardInterrupt that left an ``exec`` of a string (where a
    dataclass or a Numba wrapper is made) made CPython end the process by SIGINT (-2), not
    with the exit code 130. The rollout is replaced (``sitecustomize``) by one that is
    interrupted inside an ``exec``."""
    (tmp_path / "sitecustomize.py").write_text(
        "import potflat.files.rollout_stage\n"
        "def _interrupted(*args, **kwargs):\n"
        "    exec('import os, signal\\nos.kill(os.getpid(), signal.SIGTERM)\\nfor _ in range(10 ** 7): pass')\n"
        "potflat.files.rollout_stage.run_rollout_stage = _interrupted\n")
    scan = _tube_obj(tmp_path / "vase.obj")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, "-m", "potflat_cli", "rollout", str(scan), "-o", str(tmp_path / "out")],
                       capture_output=True, text=True, env=env, timeout=120)
    assert r.returncode == 130 and "error: interrupted" in r.stderr and "Traceback" not in r.stderr, (r.returncode,
                                                                                                     r.stderr[-1000:])


def test_an_interrupt_inside_numba_s_compiler_is_raised_once_it_returns():
    """Ctrl-C or SIGTERM landing while Numba compiles a kernel (or loads it from its cache) is
    raised once the compiler has returned: raised inside it, it can leave a kernel half-linked,
    and a kernel loaded later crashes the process (segmentation fault). The signal is sent
    from the typing of a call, inside the compiler."""
    import numba
    from numba.extending import overload

    from potflat._interrupts import raise_interrupt

    def marker():
        return 1

    @overload(marker)
    def _typed_marker():
        os.kill(os.getpid(), signal.SIGTERM)
        sum(range(10_000))  # bytecodes where the handler runs, inside the compiler
        return lambda: 1

    @numba.njit
    def kernel():
        return marker()

    previous = signal.signal(signal.SIGTERM, raise_interrupt)
    compiled = []
    try:
        with pytest.raises(KeyboardInterrupt):
            compiled.append(kernel())
            time.sleep(10)  # the deferred interrupt ends this at once
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert compiled == [1]
    assert signal.getsignal(signal.SIGALRM) is signal.SIG_DFL


def test_a_finished_command_ignores_stop_signals_while_python_shuts_down():
    """Once the command's exit code is decided, Ctrl-C and SIGTERM are ignored: Python's shutdown
    (tenths of a second with Numba loaded) puts the default handlers back, which would let a
    late SIGTERM kill a finished run (exit -15)."""
    script = ("import signal, sys\n"
              "sys.argv = ['potflat', '--version']\n"
              "from potflat_cli.main import app\n"
              "try:\n"
              "    app()\n"
              "except SystemExit as end:\n"
              "    print(end.code, *(signal.getsignal(s) is signal.SIG_IGN for s in (signal.SIGINT, signal.SIGTERM)))\n")
    r = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert r.stdout.split()[-3:] == ["0", "True", "True"], (r.stdout, r.stderr)


def test_sigterm_ends_a_run_like_ctrl_c(tmp_path):
    """SIGTERM mid-run: exit 130, the interrupt message, no .part temporaries left."""
    scan = _tube_obj(tmp_path / "vase.obj", radius=60, height=200)
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "potflat_cli", "run", str(scan), "-o", str(out), "--preset",
                             "archival"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
    deadline = time.monotonic() + 120
    while not (out / "vase.rollout.json").exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode in (0, 130), err  # 0 only if it finished before the signal
    if proc.returncode == 130:
        assert "interrupted" in err and "Traceback" not in err
    assert not list(out.glob(".*.part")) and not (out / ".potflat.lock").exists()


# ---------------------------------------------------------------------------------------
# defaults and help


def test_help_shows_the_allowed_values():
    text = " ".join(runner.invoke(app, ["run", "--help"], env={"COLUMNS": "240"}).stdout.split())
    for shown in ("[um|mm|cm|m|in]", "[outer|inner]", "--proxy NAME", "One of: auto, cylinder, cone, sphere, ortho",
                  "--preset NAME", "One of: preview, standard, archival, paper", "--band LO HI"):
        assert shown in text, shown
    assert "<bool>" not in text.replace("--help <bool>", "") and "--proxy <str>" not in text
    batch_help = " ".join(cli("batch", "--help").stdout.split())
    assert "the input's folder" not in batch_help and "'output:'" in batch_help


def test_band_with_a_comma_and_unit_names(tmp_path, fake_stages):
    from potflat_cli.main import split_pairs

    pairs = ("--band", "--angles")
    assert split_pairs(["x", "--band", "0.2,0.8"], pairs) == ["x", "--band", "0.2", "0.8"]
    assert split_pairs(["--band=0.2,0.8", "--angles", "-60", "60"], pairs) == ["--band", "0.2", "0.8", "--angles",
                                                                              "-60", "60"]
    scan = fakes.write_scan(tmp_path / "vase.obj")
    assert cli("run", scan, "-o", tmp_path / "out", "--band", "0.2,0.8", "-q").exit_code == 0
    rollout = json.loads((tmp_path / "out" / "vase.rollout.json").read_text())
    assert rollout["provenance"]["options"]["band"] == [0.2, 0.8]
    from potflat.types import canonical_units

    assert [canonical_units(u) for u in ("meter", "Metres", "millimetre", "µm", "inch")] == ["m", "m", "mm", "um", "in"]


def test_one_log_base_and_figures_in_words():
    from potflat.mesh.distortion import distortion_words, percent_from_log

    assert percent_from_log(0.1604) == pytest.approx(17.4, abs=0.05)  # the natural log, as every area figure
    assert distortion_words({"edge_rms": 0.14, "area_mean_abs_log": 0.1604, "flipped": 0}) == \
        "length error 14.0 % RMS, area error 17.4 % mean, 0 folded triangles"


def test_large_trims_and_poor_axis_fits_are_warned_with_the_option():
    from types import SimpleNamespace

    from potflat.rollout.notes import rollout_notes as _notes
    from potflat.types import FlatMesh, Mesh

    V = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0]], float)
    flat = FlatMesh(Mesh(V, np.array([[0, 1, 2]])), V[:, :2].copy())
    result = SimpleNamespace(landmark_notes=(), region=SimpleNamespace(repeated_from=None),
                             distortion=SimpleNamespace(flipped=0), boundary_overlap=0, folds=None,
                             other_objects_faces=0, disk_cut_faces=np.zeros(0, np.int64),
                             walls=SimpleNamespace(side="outer", outer_area=50.0, inner_area=0.0, apart_area=0.0,
                                                   ground_area=0.0),
                             trimmed_area=20.0, flat=flat, proxy=SimpleNamespace(kind="cylinder"), profile=None,
                             importance=None,
                             axis=SimpleNamespace(misfit_angle_deg=3.2, direction=np.array([0.0, 1.0, 0.0]),
                                                  mouth_guessed=False))
    notes = " ".join(_notes(result))
    assert "upside down" not in notes
    assert "29 % of the surface was trimmed" in notes and "--band" in notes
    assert "tilted or off-centre" in notes and "lean 3.2 deg RMS" in notes and "--axis" in notes
    assert "faces along the axis" not in notes  # the triangle faces across the axis (y)
    result.axis.direction = np.array([0.0, 0.0, 1.0])  # now the triangle faces along it: a flange
    assert "100 % of the unrolled surface faces along the axis" in " ".join(_notes(result))
    result.axis.mouth_guessed = True  # only the wider end told the mouth
    assert "the image may be upside down" in " ".join(_notes(result)) and "--flip" in " ".join(_notes(result))


def test_a_foot_unrolled_into_a_flange_is_warned_with_the_option():
    from potflat_synthetic.vessels import make_vessel

    from potflat.rollout import rollout
    from potflat.rollout.notes import rollout_notes as _notes

    kylix = rollout(make_vessel("kylix", n_vertices=4000, seed=1).mesh, importance="none")
    assert any("faces along the axis" in note and "--band" in note for note in _notes(kylix))
    hydria = rollout(make_vessel("hydria", n_vertices=4000, seed=1).mesh, importance="none")
    assert not any("faces along the axis" in note for note in _notes(hydria))


def test_a_lid_scanned_with_the_vessel_is_left_out_with_a_note():
    """A lid (or a stand) scanned with the vessel is a piece apart from its wall: left out of
    the image, and the rollout says how much and what to do."""
    import trimesh
    from potflat_synthetic.vessels import make_vessel

    from potflat.rollout import rollout
    from potflat.rollout.notes import rollout_notes as _notes
    from potflat.types import Mesh

    jar = make_vessel("hydria", n_vertices=4000, seed=1, pose=False).mesh
    top = jar.vertices[:, 2].max()
    dome = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    lid = dome.vertices * [110.0, 110.0, 48.0] + [*jar.vertices[:, :2].mean(axis=0), top + 24.0]
    with_lid = Mesh(np.vstack([jar.vertices, lid]), np.vstack([jar.faces, dome.faces + len(jar.vertices)]))
    result = rollout(with_lid, importance="none")
    apart = [n for n in _notes(result) if "pieces apart from the vessel's wall" in n]
    assert len(apart) == 1 and "split the file" in apart[0], _notes(result)
    lid_area = trimesh.Trimesh(lid, dome.faces, process=False).area
    assert 0.05 * result.walls.outer_area < result.walls.apart_area <= lid_area  # (its faces facing away from the axis)
    assert not any("pieces apart" in n for n in _notes(rollout(jar, importance="none")))


def test_a_turntable_scanned_under_the_vessel_is_left_apart_not_unrolled():
    """A turntable or ground plane scanned with the vessel, larger than it: a flat piece facing
    along the axis that holds most of the scan's area. Its edge, the longest open boundary
    around the axis, is no rim (its faces face along the axis), so the jar stays mouth up.
    The vessel's wall is unrolled and the plane, facing up under the foot, is left out as
    the ground the vessel stood on, with a note."""
    from potflat_synthetic.vessels import make_vessel

    from potflat.rollout import rollout
    from potflat.rollout.notes import rollout_notes as _notes
    from potflat.types import Mesh

    jar = make_vessel("hydria", n_vertices=4000, seed=1, pose=False).mesh
    lo, hi = jar.vertices.min(axis=0), jar.vertices.max(axis=0)
    k = 30
    side = np.linspace(-1.5, 1.5, k + 1) * (hi - lo).max()
    X, Y = np.meshgrid(side, side)
    plane = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, lo[2] - 1.0)]) + [*(0.5 * (lo + hi))[:2], 0.0]
    ids = np.arange((k + 1) ** 2).reshape(k + 1, k + 1)
    quads = np.column_stack([ids[:-1, :-1].ravel(), ids[:-1, 1:].ravel(), ids[1:, 1:].ravel(), ids[1:, :-1].ravel()])
    grid = np.vstack([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]) + len(jar.vertices)
    scan = Mesh(np.vstack([jar.vertices, plane]), np.vstack([jar.faces, grid]))
    result = rollout(scan, importance="none")
    assert result.axis.direction[2] > 0.999  # mouth up, as without the plane (its edge is no rim)
    # the plane: most of the outer area, found facing up under the foot (a ground)
    assert result.walls.ground_area > result.walls.outer_area / 2
    assert result.flat.mesh.vertices[:, 2].min() >= lo[2]  # none of its vertices unrolled
    assert result.distortion.flipped == 0
    ground = [n for n in _notes(result) if "flat piece around the foot facing up" in n]
    assert len(ground) == 1 and "table or the ground" in ground[0], _notes(result)


def test_a_table_joined_to_the_foot_is_left_out_with_a_note():
    """A cup scanned standing on a table, as a photogrammetry scan that kept the ground: the
    table's top is joined to the foot and holds most of the area. The cleaned scan keeps its
    outward faces, the cup's outer wall is unrolled without the table, and the run says so."""
    import _vessel_meshes as vm

    from potflat.mesh.cleaning import clean_mesh
    from potflat.rollout import rollout
    from potflat.rollout.notes import rollout_notes as _notes
    from potflat.types import Mesh

    V, F, L, _ = vm.cup(table=3.0)
    scan, report = clean_mesh(Mesh(V, F))
    assert report.components_reversed_outward == 0
    result = rollout(scan, importance="none")
    kept = np.unique(result.face_index)
    assert not np.isin(L[kept], ["table", "inner", "floor"]).any()
    assert np.isin(L[kept], ["outer"]).sum() == (L == "outer").sum()
    assert result.distortion.flipped == 0
    table = [n for n in _notes(result) if "flat piece around the foot facing up" in n]
    assert len(table) == 1 and "table or the ground" in table[0], _notes(result)


def test_compile_note_on_a_first_run(tmp_path, monkeypatch):
    import hashlib
    import pickle

    import numba
    from potflat_cli._stage import with_compile_note

    import potflat.relax._kernels.springs

    def write_index(version: str, source: bytes) -> None:
        with open(index, "wb") as f:  # how Numba writes an index: its version, then (stamp, overloads)
            pickle.dump(version, f)
            pickle.dump((hashlib.sha256(source).digest(), {}), f)

    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "empty"))
    assert "first run: compiling" in with_compile_note("rolling out")
    (tmp_path / "full" / "x").mkdir(parents=True)
    index = tmp_path / "full" / "x" / "springs.f-1.py311.nbi"
    with open(potflat.relax._kernels.springs.__file__, "rb") as f:
        source = f.read()
    write_index(numba.__version__, source)
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "full"))
    assert with_compile_note("rolling out") == "rolling out"
    write_index(numba.__version__, source + b"#")  # of another source (an upgrade of potflat since)
    assert "first run: compiling" in with_compile_note("rolling out")
    write_index("0.0.0", source)  # written by another version of Numba
    assert "first run: compiling" in with_compile_note("rolling out")


def test_compile_note_is_a_plain_line_when_stderr_is_not_a_terminal(tmp_path, monkeypatch):
    import io

    import numba
    from potflat_cli._stage import say_compiling
    from rich.console import Console

    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "empty"))
    log = io.StringIO()
    say_compiling(Console(file=log, force_terminal=False, width=40))  # one line however narrow the log
    assert "first run: compiling" in log.getvalue() and log.getvalue().count("\n") == 1
    (tmp_path / "full" / "x").mkdir(parents=True)
    (tmp_path / "full" / "x" / "springs.f-1.py311.nbi").write_bytes(b"")
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "full"))
    log = io.StringIO()
    say_compiling(Console(file=log, force_terminal=False))
    assert log.getvalue() == ""


def test_the_main_command_compiles_each_kernel_for_one_argument_type(tmp_path):
    """A second type specialisation of a kernel is a second compile on a first run: an
    omitted default argument in one call and not in another, or read-only rows for the PNG
    filter, each cost seconds. Specialisations to constants passed between
    kernels (Numba's literal types) are left aside."""
    sample = Path(__file__).resolve().parents[1] / "samples" / "data" / "amphora.obj"
    code = f"""
import sys, numba
from numba.core import types
from potflat_cli._stage import PROGRESS
from potflat_cli.main import app
sys.argv = ["potflat", "run", {str(sample)!r}, "-o", {str(tmp_path / "out")!r}]
try:
    app()
except SystemExit as stop:
    assert not stop.code, stop.code
twice = []
for name, module in list(sys.modules.items()):
    if not name.startswith("potflat"):
        continue
    for kname, kernel in vars(module).items():
        if isinstance(kernel, numba.core.registry.CPUDispatcher) and kernel.__module__ == name:
            plain = [s for s in kernel.signatures if not any(isinstance(a, types.Literal) for a in s)]
            if len(plain) > 1:
                twice.append(f"{{name}}.{{kname}}: {{plain}}")
print("KERNELS OF MORE THAN ONE TYPE:", twice)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert "KERNELS OF MORE THAN ONE TYPE: []" in out, out[-2000:]


def test_a_refused_run_does_not_announce_compiling_first(tmp_path, fake_stages, monkeypatch):
    import numba

    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "empty"))  # a first run
    scan = fakes.write_scan(tmp_path / "pot.obj")
    result = cli("run", scan, "-o", tmp_path / "out", "--name", "../escaped")
    assert result.exit_code == 2 and "compiling" not in result.stderr, result.stderr
    ok = cli("run", scan, "-o", tmp_path / "out")  # a run that starts says it
    assert ok.exit_code == 0 and COMPILING in ok.stderr, ok.stderr


def test_the_output_texture_is_a_copy_never_a_link(tmp_path):
    from PIL import Image

    from potflat.io.flat_ply import write_flat_ply
    from potflat.types import FlatMesh, Mesh

    (tmp_path / "scan").mkdir()
    texture = tmp_path / "scan" / "pot.png"
    Image.new("RGB", (4, 4), (1, 2, 3)).save(texture)
    V = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0]], float)
    mesh = Mesh(V, np.array([[0, 1, 2]]), texcoords=np.zeros((1, 3, 2)), texture_path=texture)
    write_flat_ply(tmp_path / "out" / "pot.rollout.ply", FlatMesh(mesh, V[:, :2].copy()))
    placed = tmp_path / "out" / "pot.texture.png"
    assert placed.read_bytes() == texture.read_bytes()
    assert not os.path.samefile(placed, texture) and os.stat(texture).st_nlink == 1
