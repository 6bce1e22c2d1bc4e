"""First contact: the help and the messages in the command line's words, naming the file
and the fix (catalogue in docs/robustness.md). One small test per check."""
from __future__ import annotations

import re

import pytest
import test_batch_fakes as fakes
from potflat_cli._stage import PROGRESS
from potflat_cli.main import app
from typer.testing import CliRunner

from potflat.files.batch.config import BatchFileError, load_batch

runner = CliRunner()
COMMANDS = ("rollout", "relax", "bake", "run", "batch", "plate", "view", "warmup")


def _help(command: str) -> str:
    result = runner.invoke(app, [command, "--help"], env={"COLUMNS": "300"})
    assert result.exit_code == 0, result.output
    return result.stdout


@pytest.mark.parametrize("command", COMMANDS)
def test_help_is_in_the_command_lines_words(command):
    """No Python in the help: no ``None``, field or constant names, module paths, quoted
    Python literals, ``<bool>`` after a flag or ``{scan}`` in the usage line."""
    text = _help(command)
    usage = next(line for line in text.splitlines() if "Usage:" in line)
    assert "{" not in usage and re.search(r"\[OPTIONS\]( \[?[A-Z_]+\]?)*\s*$", usage), usage
    assert "<bool>" not in text
    for python in ("None", "MAP_NAMES", "'seam_at'", "'importance_mask'", "texture='", "=\"", "'\"auto\"'",
                   "False", "True"):
        assert python not in text, (python, command)
    assert not re.search(r"potflat\.[a-z]", text), command  # a module path


def test_plate_help_gives_the_output_folder_it_uses():
    """The plate writes beside its input (``potflat plate out/x.relaxed.ply``), not ./NAME/."""
    text = _help("plate")
    assert "./NAME/" not in text and "the folder of the input file" in text


def test_every_option_with_a_default_shows_it_once():
    """``--maps`` shows its default; ``--dpi`` (derived from --px-per-mm) shows none."""
    text = " ".join(_help("run").split())
    maps = text[text.index("--maps"):text.index("--sheet")]
    assert "[default: stress,area,anisotropy]" in maps
    dpi = text[text.index("--dpi"):text.index("--maps")]
    assert "default: auto" not in dpi and "[default:" not in dpi


def test_the_run_summary_speaks_words_not_field_names(tmp_path, monkeypatch):
    fakes.install(monkeypatch)
    scan = fakes.write_scan(tmp_path / "pot.obj")
    result = runner.invoke(app, ["run", str(scan), "-o", str(tmp_path / "out")], env={"COLUMNS": "300"})
    assert result.exit_code == 0, result.output
    for key in ("edge_rms", "area_mean_abs_log", "anisotropy_p95", "natural log"):
        assert key not in result.stdout, key
    assert "length error" in result.stdout and "area error" in result.stdout


def test_a_missing_texture_is_told_in_the_command_lines_words(tmp_path):
    from potflat.errors import InvalidInputError
    from potflat.io.scan import load_scan

    scan = tmp_path / "pot.obj"
    scan.write_text("mtllib pot.mtl\nusemtl m\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvt 0 0\n"
                    "f 1/1 2/1 3/1\nf 1/1 2/1 4/1\nf 1/1 3/1 4/1\nf 2/1 3/1 4/1\n")
    (tmp_path / "pot.mtl").write_text("newmtl m\nmap_Kd gone.png\n")
    with pytest.raises(InvalidInputError) as error:
        load_scan(scan)
    assert "--no-texture" in str(error.value) and "texture=" not in str(error.value)


def _batch_problems(tmp_path, text: str) -> list[str]:
    (tmp_path / "pot.obj").write_text("v 0 0 0\n")
    (tmp_path / "b.yaml").write_text(text)
    with pytest.raises(BatchFileError) as error:
        load_batch(tmp_path / "b.yaml")
    return [p.split("b.yaml:", 1)[1] for p in error.value.problems]


def test_a_batch_error_names_the_line_of_the_option_at_fault(tmp_path):
    """A default on line 3 whose message calls it by its words ("importance band"), the scan
    entry on line 5: line 3."""
    problems = _batch_problems(tmp_path, "output: out\ndefaults:\n  importance_band: [0.6, 0.2]\nscans:\n"
                                         "  - path: pot.obj\n")
    assert len(problems) == 1 and problems[0].startswith("3:"), problems


def test_batch_errors_are_listed_in_line_order(tmp_path):
    problems = _batch_problems(tmp_path, "output: out\ndefaults:\n  px_per_mm: two\nscans:\n  - path: gone.obj\n"
                                         "extra: 1\n")
    assert [int(p.split(":")[0]) for p in problems] == [3, 5, 6], problems


def test_a_scan_listed_many_times_is_one_line_without_a_pattern_hint(tmp_path):
    """10,000 entries of one scan (no pattern): one line, not 9,999 saying "narrow the pattern"."""
    problems = _batch_problems(tmp_path, "output: out\nscans:\n" + "  - path: pot.obj\n" * 10_000)
    assert len(problems) == 1 and "narrow the pattern" not in problems[0] and "9994 more" in problems[0]


# ---------------------------------------------------------------------------------------
# outputs: shapes that are no vessel are refused


def test_a_tetrahedron_is_no_vessel(tmp_path):
    """Four faces, one point at each height: no radius anywhere, so no axis to unroll about."""
    from potflat.errors import AxisNotFoundError
    from potflat.io.scan import load_scan
    from potflat.rollout import rollout

    scan = tmp_path / "tet.obj"
    scan.write_text("v 0 0 0\nv 100 0 0\nv 0 100 0\nv 0 0 100\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    with pytest.raises(AxisNotFoundError, match="tet.obj is no vessel to unroll"):
        rollout(load_scan(scan).mesh)


def test_a_flat_disc_is_no_vessel(tmp_path):
    """A flat disc (every face facing along the axis found): refused in one line naming the
    file, before any output is written."""
    import math

    ring = [f"v {40 * math.cos(2 * math.pi * k / 32):.6f} {40 * math.sin(2 * math.pi * k / 32):.6f} 0" for k in range(32)]
    scan = tmp_path / "disc.obj"
    scan.write_text("\n".join(ring + ["v 0 0 0"] + [f"f 33 {k + 1} {(k + 1) % 32 + 1}" for k in range(32)]) + "\n")
    out = tmp_path / "out"
    result = runner.invoke(app, ["run", str(scan), "-o", str(out)], env={"COLUMNS": "300"})
    assert result.exit_code == 2, result.output
    error = [line for line in result.stderr.splitlines() if line.startswith("error:")]
    assert len(error) == 1 and "disc.obj: no part of it faces away from the axis found" in error[0], result.stderr
    assert "--axis px,py,pz,dx,dy,dz" in error[0] and "Traceback" not in result.stderr
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("nodes,roots,words", [
    ([{"mesh": 0, "children": [0]}], [0], "node 0 is its own child"),
    ([{"children": [1]}, {"mesh": 0, "children": [0]}], [0], "among its own descendants"),
    ([{"mesh": 0}, {"children": [0]}, {"children": [0]}], [1, 2], "two parents"),
    ([{"children": [1]}, {"mesh": 0}], [0, 1], "drawn twice"),
])
def test_a_gltf_whose_nodes_are_no_tree_is_refused(tmp_path, nodes, roots, words):
    import base64
    import json
    import struct

    from potflat.errors import InvalidInputError
    from potflat.io.scan import load_scan

    data = struct.pack("<9f", 0, 0, 0, 0.1, 0, 0, 0, 0.1, 0) + struct.pack("<3I", 0, 1, 2)
    doc = {"asset": {"version": "2.0"}, "scenes": [{"nodes": roots}], "nodes": nodes,
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
           "buffers": [{"byteLength": len(data),
                        "uri": "data:application/octet-stream;base64," + base64.b64encode(data).decode()}],
           "bufferViews": [{"buffer": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 12}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                          "min": [0, 0, 0], "max": [0.1, 0.1, 0]},
                         {"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"}]}
    (tmp_path / "pot.gltf").write_text(json.dumps(doc))
    with pytest.raises(InvalidInputError, match=words):
        load_scan(tmp_path / "pot.gltf")


def test_a_side_the_scan_barely_shows_is_noted(tmp_path):
    """A tube whose wall folds over its rim into a short inner band (as the sea vase's inside
    is a piece of its neck): ``--side inner`` unrolls the band, with a note saying how little of
    the scan it is and the other side's option."""
    import numpy as np

    from potflat.io.scan import load_scan
    from potflat.rollout import rollout
    from potflat.rollout.notes import rollout_notes

    t = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    rings = [(40.0, z) for z in np.linspace(0, 120, 13)] + [(39.0, 120.0)] + [(38.0, z) for z in (118.0, 114.0, 110.0)]
    V = np.array([[r * np.cos(a), r * np.sin(a), z] for r, z in rings for a in t])
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in V]
    for i in range(len(rings) - 1):
        for j in range(48):
            p, q = i * 48 + j, i * 48 + (j + 1) % 48
            lines += [f"f {p + 1} {q + 1} {q + 49}", f"f {p + 1} {q + 49} {p + 49}"]
    scan = tmp_path / "tube.obj"
    scan.write_text("\n".join(lines) + "\n")
    mesh = load_scan(scan).mesh
    notes = " ".join(rollout_notes(rollout(mesh, side="inner")))
    assert "inner wall unrolled here is only" in notes and "--side outer" in notes, notes
    assert "wall unrolled here" not in " ".join(rollout_notes(rollout(mesh, side="outer")))


# ---------------------------------------------------------------------------------------
# every run honest from the first second


#: ``potflat run`` in a fresh process, sent the signal ``sys.argv[2]`` by a timer once the
#: process has used ``sys.argv[1]`` seconds of CPU time after the command's first instruction
#: (an outside kill cannot land as precisely, nor can a wall-clock timer on a busy machine;
#: before that instruction the Python interpreter is still starting; importing the package up
#: to its first line takes about 1.5 ms of CPU).
EARLY_INTERRUPT = """
import os, signal, sys
seconds, sig = float(sys.argv[1]), getattr(signal, sys.argv[2])
sys.argv = ["potflat", "run", sys.argv[3], "-o", sys.argv[4], "--preset", "preview"]
signal.signal(signal.SIGPROF, lambda *a: os.kill(os.getpid(), sig))
signal.setitimer(signal.ITIMER_PROF, seconds)
from potflat_cli.main import app
app()
"""


@pytest.mark.parametrize("seconds, signal_name", [(0.005, "SIGINT"), (0.01, "SIGINT"), (0.02, "SIGINT"),
                                                  (0.1, "SIGINT"), (0.3, "SIGINT"), (0.6, "SIGINT"),
                                                  (1.0, "SIGINT"), (0.005, "SIGTERM"), (0.3, "SIGTERM")])
def test_an_interrupt_in_the_first_moments_is_one_line_and_130(tmp_path, seconds, signal_name):
    """Ctrl-C or SIGTERM from the command's first instruction to its first stage (while it
    imports itself, builds its options, loads or compiles its first kernels): one line, exit
    130, no output half-written."""
    import subprocess
    import sys
    from pathlib import Path

    scan = Path(__file__).resolve().parents[1] / "samples" / "data" / "cone.obj"
    out = tmp_path / "out"
    result = subprocess.run([sys.executable, "-c", EARLY_INTERRUPT, str(seconds), signal_name, str(scan), str(out)],
                            capture_output=True, text=True, timeout=120)
    lines = [line for line in result.stderr.strip().splitlines() if not line.startswith(PROGRESS)]
    assert result.returncode == 130 and len(lines) == 1 and lines[0].startswith("error: interrupted"), result.stderr
    left = sorted(p.name for p in out.rglob("*")) if out.exists() else []
    assert not [name for name in left if name.endswith(".part") or name == ".potflat.lock"], left


def test_a_log_gets_a_line_when_each_stage_starts_and_ends(tmp_path, monkeypatch):
    """stderr not a terminal (a log, a pipe; here the test's capture): a plain line per stage
    start and end, with seconds, between the first-run note and the summary (nothing was
    written there for minutes before); a failing stage gets no end line, the error follows."""
    import io

    from rich.console import Console

    from potflat_cli._stage import StageLog

    fakes.install(monkeypatch)
    scan = fakes.write_scan(tmp_path / "pot.obj")
    result = CliRunner().invoke(app, ["run", str(scan), "-o", str(tmp_path / "out")])
    assert result.exit_code == 0, result.output
    progress = [line for line in result.stderr.splitlines() if line.startswith(PROGRESS) and "first run" not in line]
    assert [re.sub(r"[0-9.]+ s$", "N s", line) for line in progress] == [
        f"{PROGRESS}pot.obj: {stage}{end}" for stage in ("rollout", "relax", "bake") for end in (" ...", ": done in N s")]
    fakes.SABOTAGE["pot"] = ("interrupt", "relax")
    failed = CliRunner().invoke(app, ["run", str(scan), "-o", str(tmp_path / "again")])
    lines = failed.stderr.strip().splitlines()
    assert failed.exit_code == 130 and f"{PROGRESS}pot.obj: relax ..." in lines and lines[-1].startswith("error: ")
    assert not any("relax: done" in line for line in lines), lines
    terminal = io.StringIO()
    log = StageLog(Console(file=terminal, force_terminal=True))
    log.start("pot.obj: rollout")
    log.end()
    assert terminal.getvalue() == ""  # a terminal has the live status line instead


#: Compiles, in a fresh process on an empty kernel cache, the kernels that share a helper
#: between a serial and a parallel loop (``prange``'s index is unsigned) or call it with a
#: constant, and prints the helpers compiled for more than one type.
ONE_COMPILE_PER_HELPER = """
import numpy as np
from potflat.mesh._kernels import grids
from potflat.relax._kernels import lbfgs, simplify

q, none = np.ones(8), np.zeros(0)
lbfgs.combine(q, 1.0, q.copy(), 0.5, q.copy(), none, 1.0, none, np.zeros(1))
lbfgs.pair(q, 0.5, q.copy(), q * 0.0, none, np.zeros(8), np.zeros(8), np.zeros(1), np.zeros(1))
faces, uv = np.array([[0, 1, 2]], np.int64), np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
start, items, centres, covered = grids.centre_grid(faces, uv, 0.0, 0.0, 1.0, 2, 2)
grids.centres_inside(faces, uv, 0.0, 0.0, 1.0, 2, 2, start, items, centres, np.zeros(0, np.int64),
                     np.zeros(1, np.int64), np.zeros(0, np.int64))
simplify.interpolate(np.array([[0.2, 0.2]]), np.zeros(1, np.int64), uv, uv.copy(), faces,
                     np.array([0, 1, 2, 3], np.int64), np.zeros(3, np.int32), np.zeros((1, 2)), np.zeros(1, bool))
print("MORE THAN ONE TYPE:", [f"{m.__name__}.{k}: {d.signatures}" for m in (grids, lbfgs, simplify)
                              for k, d in vars(m).items() if len(getattr(d, "signatures", ())) > 1])
"""


def test_a_helper_kernel_compiles_once_for_its_callers(tmp_path):
    """A helper called from a serial loop (``range``: int64) and a ``prange`` loop (uint64), or
    with the constant -1 as well as a variable (a literal type), compiled twice on a first run:
    three of the relax stage's helpers and one of the grids'. The index is cast at the call."""
    import os
    import subprocess
    import sys

    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "empty-cache")}
    out = subprocess.run([sys.executable, "-c", ONE_COMPILE_PER_HELPER], capture_output=True, text=True, env=env,
                         timeout=600)
    assert "MORE THAN ONE TYPE: []" in out.stdout, out.stdout[-3000:] + out.stderr[-3000:]
