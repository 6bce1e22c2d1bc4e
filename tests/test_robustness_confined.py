"""Nothing leaves or enters where it should not (catalogue in docs/robustness.md).

A stage file, a bake JSON or a manifest never chooses what potflat reads or copies; a folder
under the output folder is potflat's own or refused; embedded and declared data are bounded
before anything is decoded. One small negative test per check, each case in ``tmp_path``.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from potflat_cli.main import app
from test_robustness_hostile import one_line_error
from typer.testing import CliRunner

from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.io.flat_ply import read_flat_ply, write_flat_ply
from potflat.types import FlatMesh, Mesh

runner = CliRunner()


def _png(path: Path, size: int = 8) -> Path:
    from PIL import Image

    path.parent.mkdir(parents=True, exist_ok=True)
    Image.new("RGB", (size, size), (200, 120, 40)).save(path)
    return path


def _stage_file(path: Path, texture: Path | None = None) -> Path:
    """A small textured stage PLY (a fan of three triangles) with its texture beside it."""
    rng = np.random.default_rng(0)
    F = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4]])
    texture = texture or _png(path.parent / "src" / "atlas.png")
    mesh = Mesh(rng.normal(size=(5, 3)), F, texcoords=rng.uniform(size=(3, 3, 2)), texture_path=texture)
    return write_flat_ply(path, FlatMesh(mesh, rng.normal(size=(5, 2))))


def _tube(path: Path, radius: float = 40.0, height: float = 120.0) -> Path:
    """An open cylinder (a plain vessel wall) as an OBJ, in millimetres."""
    t = np.linspace(0, 2 * np.pi, 32, endpoint=False)
    z = np.linspace(0, height, 12)
    lines = [f"v {radius * np.cos(a):.9g} {radius * np.sin(a):.9g} {h:.9g}" for h in z for a in t]
    for i in range(len(z) - 1):
        for j in range(32):
            p, q = i * 32 + j, i * 32 + (j + 1) % 32
            lines += [f"f {p + 1} {q + 1} {q + 33}", f"f {p + 1} {q + 33} {p + 33}"]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    return path


def _name_texture(ply: Path, name: str) -> None:
    """Rewrite the stage file's ``comment TextureFile`` line to ``name``."""
    data = ply.read_bytes()
    head, body = data.split(b"end_header\n", 1)
    lines = [b"comment TextureFile " + name.encode() if line.startswith(b"comment TextureFile") else line
             for line in head.split(b"\n")]
    ply.write_bytes(b"\n".join(lines) + b"end_header\n" + body)


# ---------------------------------------------------------------------------------------
# files named by files


@pytest.mark.parametrize("where", ["relative", "absolute", "link"])
def test_a_stage_file_never_names_a_texture_outside_its_folder(tmp_path, where):
    """``comment TextureFile ../../secret/photo.png``, an absolute path or a link beside the
    stage file leading out: refused on reading, so relax and bake never read or copy it."""
    secret = _png(tmp_path / "secret" / "photo.png")
    ply = _stage_file(tmp_path / "in" / "cone.rollout.ply")
    name = {"relative": "../secret/photo.png", "absolute": str(secret), "link": "photo.png"}[where]
    if where == "link":
        (ply.parent / "photo.png").symlink_to(secret)
    _name_texture(ply, name)
    with pytest.raises(InvalidInputError, match="not a file beside it"):
        read_flat_ply(ply)


def test_relax_never_copies_a_file_that_is_not_an_image(tmp_path):
    """A stage file whose texture beside it is a text file: relax refuses before relaxing and
    copies nothing into its output folder."""
    ply = _stage_file(tmp_path / "in" / "cone.rollout.ply")
    (ply.parent / "notes.txt").write_text("not an image\n")
    _name_texture(ply, "notes.txt")
    out = tmp_path / "out"
    one_line_error(runner.invoke(app, ["relax", str(ply), "-o", str(out)]), "is not an image", "notes.txt")
    assert not out.exists() or not any(out.iterdir())


def test_a_texture_that_does_not_decode_is_never_copied(tmp_path):
    """A PNG whose header is sound and whose pixels are not: the copy beside a stage file is
    refused (only an image that decodes is copied)."""
    good = _png(tmp_path / "src" / "atlas.png", size=64)
    data = good.read_bytes()
    cut = data.index(b"IDAT") + 12
    bad = tmp_path / "src" / "broken.png"
    bad.write_bytes(data[:cut] + b"\0" * 40 + data[-12:])
    with pytest.raises(InvalidInputError, match="does not decode"):
        _stage_file(tmp_path / "out" / "pot.rollout.ply", texture=bad)
    assert not (tmp_path / "out" / "pot.texture.png").exists()


def test_a_bake_json_never_directs_the_mask_importance_elsewhere(tmp_path):
    """A bake JSON beside the mask whose provenance names a flattening in another folder: the
    flattening is looked for beside the JSON only."""
    from potflat.importance import image_mask_importance

    elsewhere = _stage_file(tmp_path / "elsewhere" / "v.relaxed.ply")
    folder = tmp_path / "masks"
    _png(folder / "v.mask.png", size=8)
    (folder / "v.bake.json").write_text(json.dumps({
        "image_px": [8, 8], "origin_uv": [0.0, 0.0], "px_per_unit": 1.0,
        "provenance": {"inputs": [{"path": str(elsewhere)}]}}))
    flat = read_flat_ply(elsewhere)
    with pytest.raises(InvalidInputError, match="not beside it"):
        image_mask_importance(flat, folder / "v.mask.png", folder / "v.bake.json")


# ---------------------------------------------------------------------------------------
# the output folder: written where potflat made it, never read from


@pytest.fixture
def fake_stages(monkeypatch):
    import test_batch_fakes as fakes

    fakes.install(monkeypatch)
    return fakes


def _one_scan_batch(tmp_path: Path, fakes) -> Path:
    fakes.write_scan(tmp_path / "scans" / "cone.obj")
    batch = tmp_path / "batch.yaml"
    batch.write_text("output: OUT/\nscans:\n  - path: scans/cone.obj\n")
    return batch


def test_a_batch_never_writes_through_a_link_under_its_output(tmp_path, fake_stages):
    """``OUT/cone`` a symbolic link to a folder elsewhere: the batch is refused with one line
    before any work; the folder elsewhere (and its manifest) is untouched."""
    batch = _one_scan_batch(tmp_path, fake_stages)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "manifest.json").write_text('{"mine": true}')
    (tmp_path / "OUT").mkdir()
    (tmp_path / "OUT" / "cone").symlink_to(elsewhere)
    one_line_error(runner.invoke(app, ["batch", str(batch), "--workers", "1"]), "OUT/cone", "symbolic link")
    assert sorted(p.name for p in elsewhere.iterdir()) == ["manifest.json"]
    assert (elsewhere / "manifest.json").read_text() == '{"mine": true}'


def test_a_manifest_never_chooses_what_the_batch_reads(tmp_path, fake_stages, monkeypatch):
    """A planted complete manifest listing a file outside the folder as an input: the file is
    never opened (the key comes from the batch file's scan and the files it names)."""
    from potflat.files.batch import manifest as manifest_mod
    from potflat.files.batch.config import load_batch
    from potflat.files.batch.execution import run_batch

    batch = _one_scan_batch(tmp_path, fake_stages)
    assert run_batch(load_batch(batch), workers=1).exit_code == 0
    big = tmp_path / "big.bin"
    big.write_bytes(b"\0" * 1000)
    folder = tmp_path / "OUT" / "cone"
    manifest = json.loads((folder / "manifest.json").read_text())
    manifest["inputs"] = [{"path": str(big), "sha256": "0" * 64}]
    (folder / "manifest.json").write_text(json.dumps(manifest))
    hashed = []
    real = manifest_mod.file_sha256
    monkeypatch.setattr(manifest_mod, "file_sha256", lambda p: hashed.append(Path(p)) or real(p))
    again = run_batch(load_batch(batch), workers=1)
    assert [r.status for r in again.reports] == ["skipped"]
    assert big not in hashed and hashed == [(tmp_path / "scans" / "cone.obj").resolve()]


# ---------------------------------------------------------------------------------------
# files too large for memory


def _sparse(path: Path, size: int, head: bytes = b"") -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        fh.write(head)
        fh.truncate(size)
    return path


@pytest.mark.parametrize("size_mib", [64, 20])  # over the memory; under it, but not twice (20 GB on 24 GB)
def test_a_scan_larger_than_the_memory_is_refused_before_reading(tmp_path, monkeypatch, size_mib):
    """A sparse scan file larger than the memory the process may use (a 20 GB file under an
    8 GB limit, here 64 MiB under 32 MiB), or too large to be read and parsed in it (a 20 GB
    file on a 24 GB machine: killed without a word by the out-of-memory killer; here 20 MiB
    under 32 MiB): one line with both sizes, nothing read."""
    from potflat.io import raw
    from potflat.io.scan import check_scan_file, load_scan

    scan = _sparse(tmp_path / "big.obj", size_mib << 20, b"v 0 0 0\n")
    monkeypatch.setattr(raw, "memory_limit", lambda: 32 << 20)
    monkeypatch.setattr(Path, "read_bytes", lambda self: pytest.fail(f"{self} was read"))
    too_large = rf"big.obj is {size_mib} MiB; reading a scan takes at least 2 times its size, more than the 32 MiB"
    with pytest.raises(InvalidInputError, match=too_large):
        load_scan(scan)
    with pytest.raises(InvalidInputError, match=too_large):  # a run: before its files are looked for in it
        check_scan_file(scan)


def test_the_memory_a_scan_may_use_is_what_the_machine_has_available(monkeypatch):
    """Not the machine's total memory: what other jobs hold is not potflat's to take."""
    import resource

    from potflat.io import raw

    monkeypatch.setattr(resource, "getrlimit", lambda which: (resource.RLIM_INFINITY, resource.RLIM_INFINITY))
    real_read_text = Path.read_text

    def read_text(self, *args, **kwargs):
        if str(self) == "/proc/meminfo":
            return "MemTotal:       24000000 kB\nMemFree:         1000000 kB\nMemAvailable:    5000000 kB\n"
        if str(self).startswith("/sys/fs/cgroup/"):
            raise OSError("no cgroup limit")
        return real_read_text(self, *args, **kwargs)

    monkeypatch.setattr(Path, "read_text", read_text)
    assert raw.memory_limit() == 5000000 * 1024


def test_a_huge_material_library_is_refused_by_its_size(tmp_path):
    """``mtllib`` naming a 32 MiB sparse file: refused by its size, never read whole."""
    from potflat.io.scan import load_scan

    scan = tmp_path / "pot.obj"
    scan.write_text("mtllib pot.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvt 0 0\n"
                    "f 1/1 2/1 3/1\nf 1/1 2/1 4/1\nf 1/1 3/1 4/1\nf 2/1 3/1 4/1\n")
    _sparse(tmp_path / "pot.mtl", 32 << 20, b"newmtl a\nmap_Kd pot.png\n")
    with pytest.raises(InvalidInputError, match="pot.mtl is 32 MiB, too large for a material library"):
        load_scan(scan)


def test_running_out_of_memory_anywhere_is_one_line_naming_the_input(tmp_path, monkeypatch):
    """A MemoryError raised anywhere in a command: one line naming the scan, exit 2."""
    from potflat.files import pipeline

    scan = tmp_path / "pot.obj"
    scan.write_text("v 0 0 0\n")

    def exhausted(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(pipeline, "run_scan", exhausted)
    one_line_error(runner.invoke(app, ["run", str(scan), "-o", str(tmp_path / "out")]), "pot.obj", "out of memory")


# ---------------------------------------------------------------------------------------
# embedded and declared data, bounded before decoding


def _gltf(path: Path, payload: int, declared: int | None = None) -> Path:
    """A .gltf holding one triangle in a buffer of ``payload`` bytes embedded as base64,
    declaring ``declared`` bytes."""
    import base64
    import struct

    tri = struct.pack("<9f", 0, 0, 0, 100, 0, 0, 0, 100, 0) + struct.pack("<3I", 0, 1, 2)
    data = tri + b"\0" * (payload - len(tri))
    doc = {"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
           "buffers": [{"byteLength": declared or len(data),
                        "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                           {"buffer": 0, "byteOffset": 36, "byteLength": 12}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                          "min": [0, 0, 0], "max": [100, 100, 0]},
                         {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"}]}
    path.write_text(json.dumps(doc))
    return path


def test_embedded_gltf_data_over_the_limit_is_refused_before_decoding(tmp_path, monkeypatch):
    """A buffer embedded as base64 over the limit (1 GiB, 5.3 GB to decode; here 2 MiB over
    1 MiB): refused from the JSON, nothing decoded."""
    from potflat.io import gltf
    from potflat.io.scan import load_scan

    monkeypatch.setattr(gltf, "MAX_EMBEDDED_BYTES", 1 << 20)
    monkeypatch.setattr(gltf, "_trimesh_load", lambda *a, **k: pytest.fail("decoded"))
    with pytest.raises(InvalidInputError, match=r"embeds 2 MiB as base64 text .* over the 1 MiB limit"):
        load_scan(_gltf(tmp_path / "pot.gltf", 2 << 20))


def test_a_gltf_buffer_declaring_more_than_its_data_is_refused(tmp_path, monkeypatch):
    """``byteLength`` 1 TiB over a buffer of 1 kB: refused before decoding."""
    from potflat.io import gltf
    from potflat.io.scan import load_scan

    monkeypatch.setattr(gltf, "_trimesh_load", lambda *a, **k: pytest.fail("decoded"))
    with pytest.raises(InvalidInputError, match="buffer 0 declares 1099511627776 bytes but its base64 text holds"):
        load_scan(_gltf(tmp_path / "pot.gltf", 1000, declared=1 << 40))


def test_a_glb_whose_json_chunk_runs_past_the_file_is_refused_as_corrupt(tmp_path):
    """A GLB header declaring a JSON chunk longer than the file (random bytes after the magic
    word): one line saying the file is corrupt, not a size limit."""
    import struct

    from potflat.io.scan import load_scan

    path = tmp_path / "pot.glb"
    path.write_bytes(b"glTF" + struct.pack("<III", 2, 4000, 900_000_000) + b"JSON" + b"\0" * 4000)
    with pytest.raises(InvalidInputError, match=r"pot.glb is not a valid GLB file \(its JSON chunk declares "
                                                r"900000000 bytes, the file holds 4020") as e:
        load_scan(path)
    assert "\n" not in str(e.value)


def test_a_gltf_whose_buffer_file_is_missing_is_refused_naming_it(tmp_path):
    """A .gltf whose buffer is an external ``.bin`` that is not there: the file is named."""
    from potflat.io.scan import load_scan

    doc = json.loads(_gltf(tmp_path / "pot.gltf", 100).read_text())
    doc["buffers"][0]["uri"] = "pot.bin"
    (tmp_path / "pot.gltf").write_text(json.dumps(doc))
    with pytest.raises(InvalidInputError, match="its buffer file pot.bin is not there; put it beside the glTF"):
        load_scan(tmp_path / "pot.gltf")


# ---------------------------------------------------------------------------------------
# a rerun never mixes old and new


def test_an_interrupted_rerun_leaves_the_earlier_outputs_as_they_were(tmp_path, fake_stages):
    """A run, then a rerun with another band interrupted in its bake: the folder holds the
    first run's outputs, byte for byte, and nothing else (no new stage file beside old images)."""
    from potflat.files.pipeline import run_scan

    scan = fake_stages.write_scan(tmp_path / "pot.obj")
    out = tmp_path / "out"
    run_scan(scan, out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    fake_stages.SABOTAGE["pot"] = ("interrupt", "bake")
    with pytest.raises(KeyboardInterrupt):
        run_scan(scan, out, rollout=fake_stages.RolloutOptions(band=(0.3, 0.7)))
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_a_new_stage_run_supersedes_the_outputs_made_from_the_old_one(tmp_path):
    """A new relaxation makes the old images stale: they are removed with the old relaxation
    when it completes; files of other names and the view's masks stay."""
    from potflat.files.names import STAGES_FROM
    from potflat.files.outputs import superseding

    for name in ("pot.rollout.ply", "pot.relaxed.ply", "pot.png", "pot.stress.png", "pot.mask.png", "jug.png"):
        (tmp_path / name).write_text("old")
    with superseding(tmp_path, "pot", STAGES_FROM["relax"]):
        assert not (tmp_path / "pot.png").exists()  # moved aside while the run writes
        (tmp_path / "pot.relaxed.ply").write_text("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["jug.png", "pot.mask.png", "pot.relaxed.ply",
                                                          "pot.rollout.ply"]
    assert (tmp_path / "pot.relaxed.ply").read_text() == "new"


def test_the_earlier_outputs_a_killed_run_moved_aside_come_back(tmp_path):
    """A run killed outright leaves the earlier outputs in the hidden folder: the next run into
    the folder moves them back first, and restores them when it fails in turn."""
    from potflat.files.names import STAGES_FROM
    from potflat.files.outputs import earlier_folder, superseding

    aside = earlier_folder(tmp_path, "pot")
    aside.mkdir()
    (aside / "pot.png").write_text("old painting")
    (tmp_path / "pot.rollout.ply").write_text("killed run's")
    with pytest.raises(RuntimeError):
        with superseding(tmp_path, "pot", STAGES_FROM["rollout"]):
            raise RuntimeError("failed")
    assert (tmp_path / "pot.png").read_text() == "old painting" and not aside.exists()



# ---------------------------------------------------------------------------------------
# the solver never produces a non-finite state


def test_a_rollout_of_pages_on_one_edge_is_refused_before_relaxing():
    """What a non-manifold "book" (pages joined on one edge) unrolls to: separate pages, every
    face flipped. Refused before the relaxation (never a NaN layout, never a RuntimeWarning)."""
    import warnings

    from potflat.errors import FoldedResultError
    from potflat.relax import relax

    quad = np.array([[0, 0, 0], [60, 0, 0], [60, 0, 120], [0, 0, 120]], float)
    V = np.concatenate([quad, quad + [0, 20, 0]])
    F = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    uv = V[:, [0, 2]] * [-1.0, 1.0]  # mirrored: every face flipped
    uv[4:, 0] -= 100.0
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(FoldedResultError, match="mirrored"):
            relax(FlatMesh(Mesh(V, F), uv))


# ---------------------------------------------------------------------------------------
# the image size, checked before anything is written


def test_an_image_too_large_for_the_relaxed_layout_leaves_nothing(tmp_path, monkeypatch):
    """A resolution the rollout's layout takes but the relaxed one (wider: up to 1.6 times the
    rollout's area on real scans, here 9 times) does not: refused before the relax stage
    writes, naming the scan, and the rollout's files go too."""
    import dataclasses

    from potflat.files import relax_stage
    from potflat.files.pipeline import run_scan
    from potflat_synthetic.vessels import make_vessel, write_obj

    scan = write_obj(make_vessel("cylinder", n_vertices=600, seed=1, texture_size=64, pose=False),
                     tmp_path / "pot.obj")
    real = relax_stage.relax

    def wider(flat, **kwargs):
        result = real(flat, **kwargs)
        return dataclasses.replace(result, flat=result.flat.replace(uv=result.flat.uv * 3.0))

    monkeypatch.setattr(relax_stage, "relax", wider)
    with pytest.raises(InvalidOptionError, match=r"pot.obj: 2 px/mm would make a .* over the 2 MP limit"):
        run_scan(scan, tmp_path / "out", relax={"preset": "preview"}, bake={"px_per_mm": 2.0, "max_megapixels": 2.0})
    assert not (tmp_path / "out").exists()


def test_a_scan_given_the_wrong_unit_is_blamed_on_the_unit(tmp_path):
    """A millimetre scan given ``--units m``: the unit is named, not the resolution the user
    never asked for."""
    scan = _tube(tmp_path / "pot.obj")
    line = one_line_error(runner.invoke(app, ["run", str(scan), "-o", str(tmp_path / "out"), "--units", "m"]),
                          "pot.obj", "--units mm")
    assert "px/mm" not in line and "px_per_mm" not in line
    assert not (tmp_path / "out").exists()
