"""Bad-input corpus through the CLI (catalogue in docs/robustness.md).

Every case is generated here in ``tmp_path``. A bad input must give exit code 2 and exactly
one line on stderr, ``error: ...``, naming the file and saying what to do; no traceback,
nothing on stdout, and no file in the output folder. Inputs that potflat handles (a
non-manifold fan, a non-symmetric shape with a given axis) must work. The commands run
in-process (``CliRunner``: no per-case interpreter start); one case also runs as a real
``python -m potflat_cli`` process.
"""
from __future__ import annotations

import hashlib
import json
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest
from potflat_cli._stage import PROGRESS
from potflat_cli.main import app
from typer.testing import CliRunner

from potflat.io.flat_ply import read_flat_ply
from potflat_synthetic.vessels import make_vessel, write_obj, write_ply_colored

runner = CliRunner()


# ---------------------------------------------------------------------------------------
# helpers


def _sha(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _plain_obj(path: Path, V, F) -> Path:
    path.write_text("".join(f"v {a:.6f} {b:.6f} {c:.6f}\n" for a, b, c in V)
                    + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F))
    return path


def _tube(a: float, b: float, height: float, n_theta: int = 64, n_h: int = 24):
    """Open elliptic tube about +z (semi-axes a, b), faces CCW seen from outside."""
    t = np.linspace(0, 2 * np.pi, n_theta, endpoint=False)
    z = np.linspace(0, height, n_h)
    V = np.array([[a * np.cos(ti), b * np.sin(ti), zi] for zi in z for ti in t])
    F = []
    for i in range(n_h - 1):
        for j in range(n_theta):
            p, q = i * n_theta + j, i * n_theta + (j + 1) % n_theta
            F += [[p, q, q + n_theta], [p, q + n_theta, p + n_theta]]
    return V, np.array(F)


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def _invoke(args):
    return runner.invoke(app, [str(a) for a in args])


def _assert_clean_error(result, out_dir: Path | None, *words: str) -> str:
    """Exit 2, one ``error:`` line on stderr containing ``words``, no traceback, no output files."""
    assert result.exception is None or isinstance(result.exception, SystemExit), repr(result.exception)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output and "Error ─" not in result.output, result.output
    assert result.stdout == ""
    # (lines of progress come before: the first-run notice when this file runs alone, with the test
    # session's empty kernel cache, and each stage's start in a log)
    lines = [line for line in result.stderr.strip().splitlines() if not line.startswith(PROGRESS)]
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for word in words:
        assert word.lower() in lines[0].lower(), (word, lines[0])
    if out_dir is not None:
        assert not out_dir.exists() or not any(out_dir.iterdir()), sorted(out_dir.iterdir())
    return lines[0]


@pytest.fixture(scope="module")
def vessel():
    return make_vessel("amphora", n_vertices=2000, seed=3, texture_size=64, pose=False)


@pytest.fixture
def scan(tmp_path, vessel):
    """A good textured OBJ (+ MTL + PNG) in its own folder."""
    return write_obj(vessel, tmp_path / "scan" / "pot.obj")


# ---------------------------------------------------------------------------------------
# broken mesh files: one line naming the file and the fix


def _empty(d, v):
    (d / "empty.obj").write_bytes(b"")
    return d / "empty.obj", ("empty.obj", "empty", "export")


def _truncated_ply(d, v):
    data = write_ply_colored(v, d / "full.ply").read_bytes()
    (d / "cut.ply").write_bytes(data[: int(len(data) * 0.6)])
    return d / "cut.ply", ("cut.ply", "truncated", "again")


def _missing_vertices(d, v):
    p = d / "missing.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\nf 1 2 9\n")
    return p, ("missing.obj", "vertex", "export")


def _nan(d, v):
    p = d / "nan.obj"
    p.write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 3\nf 2 4 3\n")
    return p, ("nan.obj", "nan", "repair")


def _inf(d, v):
    V = v.mesh.vertices.copy()
    V[7] = [np.inf, 0, -np.inf]
    return _plain_obj(d / "inf.obj", V, v.mesh.faces), ("inf.obj", "infinite", "repair")


def _single_triangle(d, v):
    p = d / "one.obj"
    p.write_text("v 0 0 0\nv 10 0 0\nv 0 10 0\nf 1 2 3\n")
    return p, ("one.obj", "faces", "whole scan")


def _all_degenerate(d, v):
    p = d / "flat.obj"  # every face has three collinear corners
    p.write_text("".join(f"v {i} {2 * i} {3 * i}\n" for i in range(12))
                 + "".join(f"f {i + 1} {i + 2} {i + 3}\n" for i in range(10)))
    return p, ("flat.obj", "degenerate", "real surface")


def _not_a_mesh(d, v):
    p = d / "points.ply"  # a point cloud
    V = v.mesh.vertices[:50]
    p.write_text("ply\nformat ascii 1.0\nelement vertex 50\nproperty float x\nproperty float y\n"
                 "property float z\nend_header\n" + "".join(f"{a} {b} {c}\n" for a, b, c in V))
    return p, ("points.ply", "faces", "mesh")


@pytest.mark.parametrize("make", [_empty, _truncated_ply, _missing_vertices, _nan, _inf, _single_triangle,
                                  _all_degenerate, _not_a_mesh], ids=lambda f: f.__name__.strip("_"))
def test_broken_scan_is_one_clear_line(tmp_path, vessel, make):
    d = tmp_path / "in"
    d.mkdir()
    path, words = make(d, vessel)
    before = _sha(path)
    out = tmp_path / "out"
    _assert_clean_error(_invoke(["rollout", path, "-o", out]), out, *words)
    assert _sha(path) == before


def test_broken_scan_in_a_real_process(tmp_path):
    """The same through the installed entry point: no rich traceback, exit 2."""
    p = tmp_path / "missing.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 7\n")
    out = tmp_path / "out"
    r = subprocess.run([sys.executable, "-m", "potflat_cli", "run", str(p), "-o", str(out)],
                       check=False, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and r.stdout == ""
    lines = [line for line in r.stderr.strip().splitlines() if not line.startswith(PROGRESS)]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "missing.obj" in lines[0], r.stderr
    assert not out.exists()


# ---------------------------------------------------------------------------------------
# shapes


def test_nonmanifold_fans_are_split_off_and_the_vessel_kept(tmp_path, vessel):
    """Decided by running it: small fans hanging on one vertex and a fin on an edge are split
    off as stray components and removed (the report says so); the vessel unrolls whole."""
    V, F = vessel.mesh.vertices, vessel.mesh.faces
    i0, p = F[0, 0], V[F[0, 0]]
    n = len(V)
    V2 = np.vstack([V, p + [5, 0, 0], p + [5, 5, 0], p + [0, 5, 5]])
    F2 = np.vstack([F, [[i0, n, n + 1], [i0, n + 1, n + 2]], [[F[5, 0], F[5, 1], n + 2]]])
    path = _plain_obj(tmp_path / "fans.obj", V2, F2)
    out = tmp_path / "out"
    result = _invoke(["rollout", path, "-o", out, "-q"])
    assert result.exit_code == 0, result.output
    data = json.loads((out / "fans.rollout.json").read_text())
    cleaning = data["cleaning"]
    assert cleaning["components_removed"] + cleaning["non_manifold_vertices"] + cleaning["non_manifold_edges"] > 0
    flat = read_flat_ply(out / "fans.rollout.ply")
    # the vessel, not the fans (the faces the seam cut are counted once)
    assert len(F) - 1 <= data["counts"]["input_faces_unrolled"] <= len(F) + 1
    assert np.isfinite(flat.uv).all()
    assert np.isfinite(flat.uv).all()


def test_two_vessels_in_one_file_are_not_mixed(tmp_path, vessel):
    """Two separate upright surfaces of revolution side by side: a clear error, or one of
    them (the largest) unrolled about its own axis with a warning in the report; never an
    axis fitted through both."""
    other = make_vessel("hydria", n_vertices=2000, seed=4, texture_size=64, pose=False)
    V, F = vessel.mesh.vertices, vessel.mesh.faces
    shift = np.ptp(V[:, 0]) * 1.5 + 100.0
    V2 = np.vstack([V, other.mesh.vertices + [shift, 0, 0]])
    F2 = np.vstack([F, other.mesh.faces + len(V)])
    path = _plain_obj(tmp_path / "two.obj", V2, F2)
    out = tmp_path / "out"
    result = _invoke(["rollout", path, "-o", out, "-q"])
    if result.exit_code == 2:
        _assert_clean_error(result, out, "two.obj")
        return
    assert result.exit_code == 0, result.output
    data = json.loads((out / "two.rollout.json").read_text())
    assert data["cleaning"]["warnings"], "one vessel dropped without a warning"
    assert abs(data["axis"]["direction"][2]) > np.cos(np.radians(5)), data["axis"]  # both axes are +z
    x = read_flat_ply(out / "two.rollout.ply").mesh.vertices[:, 0]
    assert (x.max() < shift / 2) or (x.min() > shift / 2)  # one vessel only
    assert data["counts"]["faces"] >= 0.95 * min(len(F), len(other.mesh.faces))  # all of it


def test_no_rotational_symmetry_is_refused_with_the_residual(tmp_path):
    V, F = _tube(60.0, 32.0, 150.0)
    path = _plain_obj(tmp_path / "ellipse.obj", V, F)
    out = tmp_path / "out"
    line = _assert_clean_error(_invoke(["rollout", path, "-o", out]), out,
                               "ellipse.obj", "not rotationally symmetric", "--axis")
    assert "%" in line and "deg" in line  # the residuals behind the refusal
    # with the user's axis it unrolls
    result = _invoke(["rollout", path, "-o", out, "--axis", "0,0,0,0,0,1", "--proxy", "cylinder", "-q"])
    assert result.exit_code == 0, result.output
    flat = read_flat_ply(out / "ellipse.rollout.ply")
    counts = json.loads((out / "ellipse.rollout.json").read_text())["counts"]
    assert counts["input_faces_unrolled"] == len(F) and np.isfinite(flat.uv).all()


def test_a_box_with_an_axis_unrolls_without_a_traceback(tmp_path):
    """A closed box with a given axis (its lids are crossed by the axis): the rollout
    finishes with a strict-JSON sidecar, or refuses in one line."""
    import trimesh

    box = trimesh.creation.box((100, 60, 30)).subdivide().subdivide()
    path = _plain_obj(tmp_path / "box.obj", box.vertices, box.faces)
    out = tmp_path / "out"
    result = _invoke(["rollout", path, "-o", out, "--axis", "0,0,0,0,0,1", "-q"])
    if result.exit_code == 2:
        _assert_clean_error(result, out, "box.obj")
        return
    assert result.exit_code == 0, result.output
    text = (out / "box.rollout.json").read_text()
    json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard JSON constant {c}"))
    assert np.isfinite(read_flat_ply(out / "box.rollout.ply").uv).all()


def test_infinite_figures_are_written_as_null(tmp_path):
    """A flattening with a face collapsed to a segment has infinite anisotropy: the JSON
    sidecar stays strict JSON (null), instead of a traceback after the PLY was written."""
    from potflat.mesh.distortion import summarize
    from potflat.io.atomic import write_json_atomic

    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    uv = np.array([[0, 0], [1, 0], [2, 0], [1, 1]], float)  # face 0 collapses to a segment
    s = summarize(V, uv, np.array([[0, 1, 2], [1, 3, 2]])).as_dict()
    assert s["anisotropy_max"] == np.inf and s["anisotropy_p95"] == np.inf  # not NaN
    path = write_json_atomic(tmp_path / "x.json", {"distortion": s, "h": [np.float32("nan"), 1.0]})
    back = json.loads(path.read_text(), parse_constant=lambda c: pytest.fail(c))
    assert back["distortion"]["anisotropy_max"] is None and back["h"] == [None, 1.0]
    assert back["distortion"]["edge_rms"] == s["edge_rms"]


# ---------------------------------------------------------------------------------------
# textures


def _texture_missing(png: Path):
    png.unlink()
    return ("pot.obj", "pot.png", "not found", "--no-texture")


def _texture_corrupt(png: Path):
    png.write_bytes(png.read_bytes()[:40] + b"\0garbage" * 8)
    return ("pot.obj", "pot.png", "not a readable image", "--no-texture")


def _texture_bomb(png: Path):
    """A valid PNG header declaring 100000 x 100000 RGB pixels (30 GB decoded)."""
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", struct.pack(">IIBBBBB", 100000, 100000, 8, 2, 0, 0, 0))
                    + _png_chunk(b"IDAT", zlib.compress(b"\0" * 1000)) + _png_chunk(b"IEND", b""))
    return ("pot.obj", "pot.png", "100000 x 100000", "--no-texture")


@pytest.mark.parametrize("spoil", [_texture_missing, _texture_corrupt, _texture_bomb],
                         ids=lambda f: f.__name__[len("_texture_"):])
def test_bad_texture_is_one_clear_line_and_no_texture_works(tmp_path, scan, spoil):
    words = spoil(scan.with_suffix(".png"))
    out = tmp_path / "out"
    _assert_clean_error(_invoke(["rollout", scan, "-o", out]), out, *words)
    # the fix the message names works
    result = _invoke(["rollout", scan, "-o", out, "--no-texture", "-q"])
    assert result.exit_code == 0, result.output
    assert read_flat_ply(out / "pot.rollout.ply").mesh.texture_path is None


# ---------------------------------------------------------------------------------------
# batch files


@pytest.mark.parametrize("text,words", [
    ("output: out\ndefaults:\n  px_per_mmm: 2\nscans:\n  - path: pot.obj\n", ("batch.yaml:3", "px_per_mmm", "px_per_mm")),
    ("output: out\nscans:\n  - path: pot.obj\n    colour: red\n", ("batch.yaml:4", "colour", "valid keys")),
    ("output: out\ndefaults:\n  px_per_mm: two\nscans:\n  - path: pot.obj\n", ("batch.yaml:3", "px_per_mm", "number")),
    ("output: out\nscans:\n  - path: pot.obj\n    band: 0.5\n", ("batch.yaml:4", "band", "list of 2")),
    ("output: out\nscans:\n  - path: pot.obj\n    max_iter: 1.5\n", ("batch.yaml:4", "max_iter", "whole number")),
    ("output: out\nscans:\n  - path: nothere.obj\n", ("batch.yaml:3", "nothere.obj", "does not exist")),
    ("output: out\nscans:\n  - path: nowhere/*.obj\n", ("batch.yaml:3", "nowhere/*.obj", "matches no file")),
    ("output: out\nscans: [\n", ("batch.yaml", "yaml")),
    ("", ("batch.yaml", "empty")),
], ids=["unknown-default", "unknown-key", "wrong-type", "band-scalar", "int-float", "missing-path",
        "empty-glob", "bad-yaml", "empty-file"])
def test_bad_batch_file_is_one_clear_line(tmp_path, scan, text, words):
    batch = scan.parent / "batch.yaml"
    batch.write_text(text)
    _assert_clean_error(_invoke(["batch", batch]), scan.parent / "out", *words)


def test_several_batch_problems_one_line_each_nothing_run(tmp_path, scan):
    batch = scan.parent / "batch.yaml"
    batch.write_text("output: out\ndefaults:\n  preset: quick\nscans:\n  - path: pot.obj\n    colour: red\n"
                     "  - path: gone.obj\n")
    result = _invoke(["batch", batch])
    assert result.exit_code == 2 and result.stdout == "" and "Traceback" not in result.output
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 3 and all(ln.startswith("error: ") and "batch.yaml:" in ln for ln in lines), lines
    assert not (scan.parent / "out").exists()


# ---------------------------------------------------------------------------------------
# output folders


@pytest.mark.parametrize("command", ["rollout", "run"])
def test_output_folder_under_a_regular_file(tmp_path, scan, command):
    """Tests run as root, so chmod cannot make a folder unwritable: a folder below a regular
    file cannot be created by anyone."""
    blocker = tmp_path / "notes.txt"
    blocker.write_text("not a folder")
    out = blocker / "sub"
    args = [command, scan, "-o", out] + (["--preset", "preview", "--px-per-mm", "1"] if command == "run" else [])
    _assert_clean_error(_invoke(args), None, str(out), "folder")
    assert blocker.read_text() == "not a folder"
    assert sorted(p.name for p in scan.parent.iterdir()) == ["pot.mtl", "pot.obj", "pot.png"]


def test_output_folder_in_proc_is_refused(tmp_path, scan):
    _assert_clean_error(_invoke(["rollout", scan, "-o", "/proc/potflat-out"]), None, "/proc/potflat-out")


# ---------------------------------------------------------------------------------------
# an input that is also an output


def test_rollout_onto_its_own_input_is_refused(tmp_path, vessel):
    scan = write_ply_colored(vessel, tmp_path / "pot.rollout.ply")
    before = _sha(scan)
    _assert_clean_error(_invoke(["rollout", scan, "-o", tmp_path, "--name", "pot"]), None, "pot.rollout.ply",
                        "overwrite", "--name")
    assert _sha(scan) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pot.rollout.ply"]


def test_run_into_the_scan_folder_never_overwrites_the_texture(tmp_path, scan):
    """pot.obj with texture pot.png, outputs beside it: bake's pot.png would replace the
    texture. Refused before any stage runs; inputs unchanged."""
    inputs = {p.name: _sha(p) for p in scan.parent.iterdir()}
    result = _invoke(["run", scan, "-o", scan.parent, "--preset", "preview", "--px-per-mm", "1"])
    _assert_clean_error(result, None, "pot.png", "overwritten", "-o")
    assert {p: _sha(scan.parent / p) for p in inputs} == inputs
    assert sorted(p.name for p in scan.parent.iterdir()) == sorted(inputs)  # nothing written
    assert not list(scan.parent.glob("*.part")) and not list(scan.parent.glob(".*.part"))
    # with an output folder it works, and a rerun works too (the texture is not taken for output)
    out = tmp_path / "out"
    for _ in range(2):
        result = _invoke(["run", scan, "-o", out, "--preset", "preview", "--px-per-mm", "1", "-q"])
        assert result.exit_code == 0, result.output
    assert {p: _sha(scan.parent / p) for p in inputs} == inputs
    texture = read_flat_ply(out / "pot.relaxed.ply").mesh.texture_path
    assert _sha(texture) == inputs["pot.png"] and texture != out / "pot.png"


def test_relax_and_bake_never_write_over_their_input(tmp_path, scan):
    out = tmp_path / "out"
    assert _invoke(["rollout", scan, "-o", out, "-q"]).exit_code == 0
    rollout = out / "pot.rollout.ply"
    # a relaxed file given back to relax, and to bake, in its own folder
    assert _invoke(["relax", rollout, "--preset", "preview"]).exit_code == 0
    relaxed = out / "pot.relaxed.ply"
    before = {p.name: _sha(p) for p in out.iterdir()}
    assert _invoke(["relax", relaxed, "--preset", "preview"]).exit_code == 0
    result = _invoke(["bake", relaxed, "--px-per-mm", "1", "--name", "pot.texture", "-q"])
    _assert_clean_error(result, None, "pot.texture.png", "overwritten")
    after = {p.name: _sha(p) for p in out.iterdir() if p.name in before}
    assert after == before
    # relax and bake into a folder below a regular file
    blocker = tmp_path / "notes.txt"
    blocker.write_text("x")
    for args in (["relax", rollout, "-o", blocker / "sub", "--preset", "preview"],
                 ["bake", relaxed, "-o", blocker / "sub", "--px-per-mm", "1"]):
        _assert_clean_error(_invoke(args), None, "notes.txt")


def test_missing_texture_at_relax_time_is_one_clear_line_before_relaxing(tmp_path, scan, monkeypatch):
    """A rollout file copied without its texture: refused on reading, not after the solve."""
    import potflat.files.relax_stage as relax_stage

    out = tmp_path / "out"
    assert _invoke(["rollout", scan, "-o", out, "-q"]).exit_code == 0
    (out / "pot.texture.png").unlink()

    def no_solve(*args, **kwargs):
        raise AssertionError("relaxed before the texture was checked")

    monkeypatch.setattr(relax_stage, "relax", no_solve)
    relaxed = tmp_path / "relaxed"
    _assert_clean_error(_invoke(["relax", out / "pot.rollout.ply", "-o", relaxed]), relaxed,
                        "pot.texture.png", "not found", "beside")


@pytest.mark.parametrize("command,name", [("relax", "pot.rollout.ply"), ("bake", "pot.relaxed.ply")])
def test_truncated_or_foreign_stage_file_is_one_clear_line(tmp_path, command, name):
    """A stage file cut short (a copy interrupted) or an ascii PLY from another tool."""
    from potflat.io.flat_ply import write_flat_ply
    from potflat.types import FlatMesh, Mesh

    V = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [10, 10, 0]], float)
    flat = FlatMesh(Mesh(V, np.array([[0, 1, 2], [1, 3, 2]])), V[:, :2])
    data = write_flat_ply(tmp_path / name, flat).read_bytes()
    (tmp_path / name).write_bytes(data[: len(data) - 20])
    out = tmp_path / "out"
    _assert_clean_error(_invoke([command, tmp_path / name, "-o", out]), out, name, "truncated", "again")
    (tmp_path / name).write_text("ply\nformat ascii 1.0\nelement vertex 0\nend_header\n")
    _assert_clean_error(_invoke([command, tmp_path / name, "-o", out]), out, name, "ascii", "potflat")


@pytest.mark.parametrize("value,words", [("1000", ("1000 px/mm", "megapixels", "or less")),
                                         ("0", ("px_per_mm", "positive")), ("nan", ("px_per_mm", "positive"))])
def test_absurd_resolution_is_refused_before_rendering(tmp_path, value, words):
    from potflat.io.flat_ply import write_flat_ply
    from potflat.types import FlatMesh, Mesh

    V = np.array([[0, 0, 0], [600, 0, 0], [0, 500, 0], [600, 500, 0]], float)  # 600 x 500 mm
    path = write_flat_ply(tmp_path / "pot.relaxed.ply", FlatMesh(Mesh(V, np.array([[0, 1, 2], [1, 3, 2]])), V[:, :2]))
    out = tmp_path / "out"
    _assert_clean_error(_invoke(["bake", path, "-o", out, "--px-per-mm", value]), out, *words)


@pytest.mark.parametrize("spoil,words", [
    (lambda p: p.unlink(), ("pot.texture.png", "not found")),
    (lambda p: p.write_bytes(b"garbage"), ("pot.texture.png", "cannot decode")),
    (lambda p: _texture_bomb(p), ("pot.texture.png", "100000 x 100000", "downsample")),
], ids=["missing", "corrupt", "bomb"])
def test_bad_texture_at_bake_time_is_one_clear_line(tmp_path, spoil, words):
    """The texture beside a stage file lost, damaged or replaced by a decompression bomb
    between rollout and bake."""
    from PIL import Image

    from potflat.io.flat_ply import write_flat_ply
    from potflat.types import FlatMesh, Mesh

    src = tmp_path / "src" / "pot.png"
    src.parent.mkdir()
    Image.new("RGB", (8, 8), (200, 100, 50)).save(src)
    V = np.array([[0, 0, 0], [60, 0, 0], [0, 50, 0], [60, 50, 0]], float)
    F = np.array([[0, 1, 2], [1, 3, 2]])
    tc = (V[:, :2] / [60, 50])[F]
    mesh = Mesh(V, F, texcoords=tc, texture_path=src)
    path = write_flat_ply(tmp_path / "stage" / "pot.relaxed.ply", FlatMesh(mesh, V[:, :2]))
    texture = path.parent / "pot.texture.png"
    texture.unlink()  # a hard link to src: replace, never write through it
    texture.write_bytes(src.read_bytes())
    spoil(texture)
    out = tmp_path / "out"
    _assert_clean_error(_invoke(["bake", path, "-o", out, "--px-per-mm", "1"]), out, *words)


def test_two_scans_with_the_same_texture_name_into_one_folder(tmp_path):
    """Photogrammetry exports often call every texture 'texture.png': two scans rolled out into
    one folder each keep their own (was: the second failed or silently used the first's)."""
    from PIL import Image

    from potflat.io.flat_ply import read_flat_ply, write_flat_ply
    from potflat.types import FlatMesh, Mesh

    V = np.array([[0, 0, 0], [60, 0, 0], [0, 50, 0], [60, 50, 0]], float)
    F = np.array([[0, 1, 2], [1, 3, 2]])
    out = tmp_path / "out"
    for name, colour in (("a", (255, 0, 0)), ("b", (0, 0, 255))):  # same size, different content
        tex = tmp_path / name / "texture.png"
        tex.parent.mkdir()
        Image.new("RGB", (8, 8), colour).save(tex)
        mesh = Mesh(V, F, texcoords=(V[:, :2] / [60, 50])[F], texture_path=tex)
        write_flat_ply(out / f"{name}.rollout.ply", FlatMesh(mesh, V[:, :2]))
    for name, colour in (("a", (255, 0, 0)), ("b", (0, 0, 255))):
        with Image.open(read_flat_ply(out / f"{name}.rollout.ply").mesh.texture_path) as im:
            assert im.getpixel((0, 0)) == colour
