"""The hostile-input corpus, generated here and run through the real command line.

Every case is made in a temporary folder (nothing is taken from the tests), run as a real
``python -m potflat_cli`` process in its own session under a memory cap (``RLIMIT_AS``,
default 6 GiB of address space: Numba and OpenMP reserve more than they use) and a time
limit, and judged: a bad input must end with exit code 2, **one** ``error:`` line on stderr,
no traceback and nothing written; a case potflat handles must succeed, and some cases check
files afterwards (victims outside the output folder untouched, no ``.part`` left, the output
texture not a link...). It prints a table (Markdown) and exits 1 if any case fails.

    python benchmarks/hostile_corpus.py              # 68 cases, about 8 minutes on 2 shared cores
    python benchmarks/hostile_corpus.py --real ../shared/data/real   # + relax --preset paper on real scans
    python benchmarks/hostile_corpus.py -k yaml      # only the cases whose name contains 'yaml'

The same checks, one small test each, run in the default test suite
(``tests/test_robustness_hostile.py``); this script runs them end to end, as a user would,
with the real stages and processes (signals, locks, workers).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


@dataclass
class Case:
    name: str
    make: Callable[[Path], list]  # folder -> command-line arguments (after 'potflat')
    expect: int = 2  # exit code
    check: Callable[[Path, "Run"], str] | None = None  # "" if fine, else what is wrong
    timeout: float = 120.0
    env: Callable[[Path], dict] | None = None  # folder -> environment variables to set


@dataclass
class Run:
    code: int
    stdout: str
    stderr: str
    seconds: float
    pid: int = 0  # also the session of the process and its workers


def _limits(cap: int) -> Callable[[], None]:
    def apply() -> None:
        os.setsid()
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    return apply


def potflat(args: list, cwd: Path, cap: int, timeout: float, *, stop: tuple | None = None,
            env: dict | None = None) -> Run:
    """Run ``python -m potflat_cli ARGS`` (with the variables ``env`` set); ``stop=(condition,
    signal)`` sends the signal to the process group once ``condition()`` holds (a negative
    signal: to the main process only)."""
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "200", **(env or {})}
    start = time.monotonic()
    proc = subprocess.Popen([sys.executable, "-m", "potflat_cli", *map(str, args)], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_limits(cap))
    if stop is not None:
        condition, sig = stop
        while proc.poll() is None and not condition() and time.monotonic() - start < timeout:
            time.sleep(0.05)
        if proc.poll() is None:
            if sig < 0:
                os.kill(proc.pid, -sig)
            else:
                os.killpg(proc.pid, sig)
    try:
        out, err = proc.communicate(timeout=max(1.0, timeout - (time.monotonic() - start)))
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        return Run(-9, out, err + "\n(timed out)", time.monotonic() - start, proc.pid)
    return Run(proc.returncode, out, err, time.monotonic() - start, proc.pid)


# --------------------------------------------------------------------------------- inputs
def vessel_obj(folder: Path, name: str = "pot", scale: float = 1.0) -> Path:
    """A painted amphora (2000 vertices) as OBJ + MTL + PNG, coordinates times ``scale``."""
    from potflat_synthetic.vessels import make_vessel, write_obj

    path = write_obj(make_vessel("amphora", n_vertices=2000, seed=3, texture_size=64, pose=False),
                     folder / f"{name}.obj")
    if scale != 1.0:
        lines = path.read_text().splitlines()
        for i, line in enumerate(lines):
            if line.startswith("v "):
                lines[i] = "v " + " ".join(f"{float(x) * scale:.9g}" for x in line.split()[1:4])
        path.write_text("\n".join(lines) + "\n")
    return path


def png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def big_png(path: Path, side: int) -> Path:
    """A real ``side`` x ``side`` RGB PNG of one colour (a few MB on disk, side^2 * 3 bytes decoded)."""
    row = b"\0" + bytes([120, 80, 40]) * side
    comp = zlib.compressobj(9)
    data = b"".join(comp.compress(row) for _ in range(side)) + comp.flush()
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", struct.pack(">IIBBBBB", side, side, 8, 2, 0, 0, 0))
                     + png_chunk(b"IDAT", data) + png_chunk(b"IEND", b""))
    return path


def ply(path: Path, header: str, body: bytes = b"") -> Path:
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\n" + header.encode() + b"end_header\n" + body)
    return path


TRI = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\n"
XYZ = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
HOSTILE_PLY = {
    "list-count-minus-1": (TRI + "property list char int vertex_indices\n", XYZ + struct.pack("<b3i", -1, 0, 1, 2)),
    "uint-list-4e9": (TRI + "property list uint int vertex_indices\n", XYZ + struct.pack("<I3i", 4_000_000_000, 0, 1, 2)),
    "vertex-abc": ("element vertex abc\nproperty float x\n", b""),
    "vertex-minus-3": ("element vertex -3\nproperty float x\n", b""),
    "list-without-name": (TRI + "property list uchar int\n", XYZ + struct.pack("<B3i", 3, 0, 1, 2)),
}


def batch_file(folder: Path, body: str, output: str = "out") -> Path:
    path = folder / "batch.yaml"
    path.write_text(f"output: {output}\ndefaults: {{preset: preview, px_per_mm: 1}}\nscans:\n{body}")
    return path


# --------------------------------------------------------------------------------- checks
#: How a line of progress begins (a stage's start and end, the first-run note: stderr is not
#: a terminal here); the error line comes after them.
PROGRESS = "potflat: "


def one_line(run: Run) -> str:
    lines = [line for line in run.stderr.strip().splitlines() if not line.startswith(PROGRESS)]
    if "Traceback" in run.stderr or "╭" in run.stderr:
        return "traceback or box on stderr"
    if len(lines) != 1 or not lines[0].startswith("error: "):
        return f"{len(lines)} lines on stderr"
    return ""


def nothing_in(folder: Path) -> Callable[[Path, Run], str]:
    def check(d: Path, run: Run) -> str:
        out = d / folder
        left = [p.name for p in out.rglob("*")] if out.exists() else []
        return f"wrote {left[:3]}" if left else ""
    return check


def no_parts(folder: str) -> Callable[[Path, Run], str]:
    def check(d: Path, run: Run) -> str:
        parts = [p.name for p in (d / folder).rglob(".*.part")]
        return f".part left: {parts[:3]}" if parts else ""
    return check


def corpus(real: Path | None) -> list[Case]:
    cases: list[Case] = []
    add = cases.append

    # ---- data safety
    def planted_manifest(d: Path) -> list:
        scan = vessel_obj(d / "scans")
        (d / "victim").write_text("precious")
        (d / "victim-abs").write_text("precious")
        out = d / "out" / "pot"
        out.mkdir(parents=True)
        (out / "manifest.json").write_text(json.dumps({"complete": True, "outputs": {
            "../../victim": 8, str(d / "victim-abs"): 8}, "inputs": [{"path": "/dev/zero", "sha256": "0"}]}))
        return ["batch", batch_file(d, f"  - path: {scan.relative_to(d)}\n"), "-w", "1", "-q"]
    add(Case("batch manifest lists ../../victim, /abs/victim, input /dev/zero", planted_manifest, 0,
             lambda d, r: "" if (d / "victim").exists() and (d / "victim-abs").exists() else "a victim was deleted"))

    def glb_cache(d: Path) -> list:
        import trimesh
        from PIL import Image

        t = np.linspace(0, 2 * np.pi, 32, endpoint=False)
        V = np.array([[0.04 * np.cos(a), 0.04 * np.sin(a), h] for h in (0.0, 0.06, 0.12) for a in t])
        F = [[i * 32 + j, i * 32 + (j + 1) % 32, (i + 1) * 32 + (j + 1) % 32] for i in range(2) for j in range(32)]
        F += [[i * 32 + j, (i + 1) * 32 + (j + 1) % 32, (i + 1) * 32 + j] for i in range(2) for j in range(32)]
        uv = np.column_stack([np.tile(t / (2 * np.pi), 3), np.repeat([0.0, 0.5, 1.0], 32)])
        mesh = trimesh.Trimesh(V, F, process=False, visual=trimesh.visual.TextureVisuals(
            uv=uv, image=Image.new("RGB", (16, 16), (200, 30, 40))))
        (d / "pot.glb").write_bytes(mesh.export(file_type="glb"))
        shared = Path(tempfile.gettempdir()) / f"potflat-textures-{os.environ.get('USER', 'root')}"
        shared.mkdir(exist_ok=True)
        for p in list(shared.glob("*.png")) + [shared / "planted.png"]:
            Image.new("RGB", (16, 16), (0, 255, 0)).save(p)
        return ["rollout", d / "pot.glb", "-o", d / "out", "-q"]

    def painting_kept(d: Path, run: Run) -> str:
        from PIL import Image

        tex = d / "out" / "pot.texture.png"
        if not tex.is_file():
            return "no texture beside the rollout"
        return "" if np.asarray(Image.open(tex).convert("RGB"))[0, 0].tolist() == [200, 30, 40] else "planted image used"
    add(Case("GLB texture with planted files in a shared cache", glb_cache, 0, painting_kept))

    def laughs(d: Path) -> list:
        levels = ["  a0: &a0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
        levels += [f"  a{k}: &a{k} [{', '.join([f'*a{k - 1}'] * 9)}]" for k in range(1, 9)]
        vessel_obj(d / "scans")
        (d / "batch.yaml").write_text("x:\n" + "\n".join(levels) + "\noutput: out\ndefaults:\n  maps: *a8\n"
                                      "scans:\n  - path: scans/pot.obj\n")
        return ["batch", d / "batch.yaml"]
    add(Case("YAML billion laughs in a maps: value", laughs, 2, nothing_in(Path("out")), timeout=60))

    def root_glob(d: Path) -> list:
        return ["batch", batch_file(d, "  - path: /**/*.ply\n")]
    add(Case("batch path: /**/*.ply", root_glob, 2, nothing_in(Path("out")), timeout=30))

    def dev_zero(d: Path) -> list:
        return ["batch", batch_file(d, "  - path: /dev/zero\n")]
    add(Case("batch scan path /dev/zero", dev_zero, 2, nothing_in(Path("out")), timeout=30))

    def locked(d: Path) -> list:
        vessel_obj(d / "scans")
        (d / "hold.py").write_text("import sys, time\nfrom potflat.io.atomic import output_lock\n"
                                   "with output_lock(sys.argv[1]):\n    print('locked', flush=True)\n    time.sleep(60)\n")
        holder = subprocess.Popen([sys.executable, d / "hold.py", d / "out"], stdout=subprocess.PIPE, text=True)
        holder.stdout.readline()
        (d / "holder.pid").write_text(str(holder.pid))
        return ["batch", batch_file(d, "  - path: scans/pot.obj\n"), "-w", "1"]

    def release(d: Path, run: Run) -> str:
        os.kill(int((d / "holder.pid").read_text()), signal.SIGTERM)
        return "" if "in use" in run.stderr else "not refused as in use"
    add(Case("a second batch on an output folder in use", locked, 2, release))

    def reserved(d: Path) -> list:
        vessel_obj(d / "scans")
        return ["batch", batch_file(d, "  - path: scans/pot.obj\n    name: summary.json\n")]
    add(Case("batch scan named summary.json", reserved, 2, nothing_in(Path("out"))))
    add(Case("--name ../escaped", lambda d: ["run", vessel_obj(d / "s"), "-o", d / "out", "--name", "../escaped"], 2,
             lambda d, r: "escaped" if (d / "escaped").exists() or (d / "out").exists() else ""))

    def dotdot(d: Path) -> list:
        src = vessel_obj(d / "scans")
        src.rename(d / "scans" / "...obj")
        return ["batch", batch_file(d, "  - path: scans/...obj\n")]
    add(Case("batch scan whose stem is ..", dotdot, 2, lambda d, r: nothing_in(Path("out"))(d, r) or (
        "" if "leading dot" in r.stderr else "not refused for its name")))

    # ---- files named by files
    def stage_file_naming(d: Path, texture: str) -> list:
        (d / "secret").mkdir()
        (d / "secret" / "secret.txt").write_text("the key\n")
        big_png(d / "secret" / "photo.png", 8)
        assert potflat(["rollout", vessel_obj(d / "scans"), "-o", d / "in", "-q"], d, 6 << 30, 120).code == 0
        rollout = d / "in" / "pot.rollout.ply"
        head, body = rollout.read_bytes().split(b"end_header\n", 1)
        lines = [b"comment TextureFile " + texture.encode() if ln.startswith(b"comment TextureFile") else ln
                 for ln in head.split(b"\n")]
        rollout.write_bytes(b"\n".join(lines) + b"end_header\n" + body)
        return ["relax", rollout, "-o", d / "out", "--preset", "preview"]

    def nothing_copied(d: Path, run: Run) -> str:
        copied = [p.name for p in (d / "out").glob("*texture*")] if (d / "out").exists() else []
        return f"copied {copied}" if copied else ""
    for label, texture in (("../secret/photo.png", "../secret/photo.png"), ("an absolute path", "SECRET/photo.png"),
                           ("a text file", "SECRET/secret.txt")):
        add(Case(f"stage file's TextureFile names {label} outside its folder",
                 lambda d, t=texture: stage_file_naming(d, t.replace("SECRET", str(d / "secret"))), 2, nothing_copied))

    def link_under_output(d: Path) -> list:
        (d / "elsewhere").mkdir()
        (d / "elsewhere" / "manifest.json").write_text('{"mine": true}')
        (d / "out").mkdir()
        (d / "out" / "pot").symlink_to(d / "elsewhere")
        return ["batch", batch_file(d, f"  - path: {vessel_obj(d / 'scans').relative_to(d)}\n"), "-w", "1"]
    add(Case("batch output OUT/NAME a symbolic link to a folder elsewhere", link_under_output, 2,
             lambda d, r: "" if sorted(p.name for p in (d / "elsewhere").iterdir()) == ["manifest.json"]
             and (d / "elsewhere" / "manifest.json").read_text() == '{"mine": true}' else "wrote through the link"))

    def manifest_names_a_fifo(d: Path) -> list:
        vessel_obj(d / "scans")
        batch = batch_file(d, "  - path: scans/pot.obj\n")
        assert potflat(["batch", batch, "-w", "1", "-q"], d, 6 << 30, 240).code == 0
        os.mkfifo(d / "endless")  # read: blocks for ever
        manifest = json.loads((d / "out" / "pot" / "manifest.json").read_text())
        manifest["inputs"] = [{"path": str(d / "endless"), "sha256": "0" * 64}]
        (d / "out" / "pot" / "manifest.json").write_text(json.dumps(manifest))
        return ["batch", batch, "-w", "1", "-q"]
    add(Case("planted complete manifest listing a FIFO outside as an input", manifest_names_a_fifo, 0,
             timeout=240))

    # ---- sizes: sparse huge files, huge embedded buffers
    def sparse(path: Path, size: int, head: bytes = b"") -> Path:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb") as fh:
            fh.write(head)
            fh.truncate(size)
        return path
    add(Case("a 20 GB sparse file as the scan", lambda d: ["run", sparse(d / "big.obj", 20 << 30, b"v 0 0 0\n"),
                                                            "-o", d / "out"], 2, nothing_in(Path("out")), timeout=60))

    def sparse_mtl(d: Path) -> list:
        scan = vessel_obj(d)
        (d / "pot.mtl").unlink()
        sparse(d / "pot.mtl", 20 << 30, b"newmtl a\nmap_Kd pot.png\n")
        return ["run", scan, "-o", d / "out"]
    add(Case("mtllib naming a 20 GB sparse file", sparse_mtl, 2, nothing_in(Path("out")), timeout=60))

    def gltf(d: Path, payload: int, declared: int | None = None) -> list:
        import base64

        tri = struct.pack("<9f", 0, 0, 0, 100, 0, 0, 0, 100, 0) + struct.pack("<3I", 0, 1, 2)
        with open(d / "pot.gltf", "w") as fh:  # written in pieces: the text is large
            fh.write('{"asset": {"version": "2.0"}, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}], '
                     '"meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}], '
                     '"bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, '
                     '{"buffer": 0, "byteOffset": 36, "byteLength": 12}], '
                     '"accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", '
                     '"min": [0, 0, 0], "max": [100, 100, 0]}, '
                     '{"bufferView": 1, "componentType": 5125, "count": 3, "type": "SCALAR"}], '
                     f'"buffers": [{{"byteLength": {declared or payload}, '
                     '"uri": "data:application/octet-stream;base64,')
            data = tri + b"\0" * (payload - len(tri))
            piece = 3 << 20  # (a multiple of 3: base64 pieces join)
            for start in range(0, len(data), piece):
                fh.write(base64.b64encode(data[start:start + piece]).decode())
            fh.write('"}]}')
        return ["run", d / "pot.gltf", "-o", d / "out"]
    for payload in (300 << 20, 1 << 30):  # under, and over, the size a glTF file may have
        add(Case(f"glTF embedding a {payload >> 20} MiB buffer as a data: URI", lambda d, n=payload: gltf(d, n), 2,
                 nothing_in(Path("out")), timeout=120))
    add(Case("glTF buffer declaring 1 TiB over 1 kB of data", lambda d: gltf(d, 1000, declared=1 << 40), 2,
             nothing_in(Path("out"))))

    # ---- one line and exit 2
    add(Case("scan in metres without --units", lambda d: ["run", vessel_obj(d, scale=1e-3), "-o", d / "out"], 2,
             lambda d, r: "" if "--units m" in r.stderr else "no unit named"))
    add(Case("scan in micrometres without --units", lambda d: ["run", vessel_obj(d, scale=1e3), "-o", d / "out"], 2,
             lambda d, r: "" if "--units um" in r.stderr else "no unit named"))
    for ppm in ("0.01", "1e-9", "1000"):
        add(Case(f"--px-per-mm {ppm}", lambda d, ppm=ppm: ["run", vessel_obj(d), "-o", d / "out", "--px-per-mm", ppm],
                 2, nothing_in(Path("out"))))

    def big_texture(d: Path) -> list:
        scan = vessel_obj(d)
        big_png(d / "pot.png", 30000)
        return ["run", scan, "-o", d / "out"]
    add(Case("30000 x 30000 PNG texture (2.7 GB decoded)", big_texture, 2, nothing_in(Path("out"))))

    def names(d: Path, encoding: str) -> list:
        plain = vessel_obj(d / "Fund ü")
        scan = plain.with_name("Vase é.obj")
        scan.write_bytes(plain.read_text().replace("mtllib pot.mtl", "mtllib Vase é.mtl").encode(encoding))
        (d / "Fund ü" / "Vase é.mtl").write_bytes(
            plain.with_suffix(".mtl").read_text().replace("pot.png", "Bild ä.png").encode(encoding))
        (d / "Fund ü" / "pot.png").rename(d / "Fund ü" / "Bild ä.png")
        plain.unlink()
        return ["run", scan, "-o", d / "out ü", "--preset", "preview", "--px-per-mm", "1", "-q"]
    add(Case("UTF-8 names with spaces (OBJ, MTL, texture)", lambda d: names(d, "utf-8"), 0))
    add(Case("Latin-1 MTL naming a texture", lambda d: names(d, "latin-1"), 0))

    for key, (header, body) in HOSTILE_PLY.items():
        for command, fname in (("rollout", "pot.ply"), ("relax", "pot.rollout.ply"), ("bake", "pot.relaxed.ply")):
            add(Case(f"PLY {key} ({command})", lambda d, h=header, b=body, c=command, f=fname:
                     [c, ply(d / f, h, b), "-o", d / "out"], 2, nothing_in(Path("out"))))

    def dir_obj(d: Path) -> list:
        (d / "x.obj").mkdir()
        return ["run", d / "x.obj", "-o", d / "out"]
    add(Case("a directory named x.obj as the scan", dir_obj, 2))
    add(Case("a batch file that is a directory", lambda d: ["batch", d], 2))
    add(Case("--workers 0", lambda d: ["batch", batch_file(d, "  - path: x.obj\n"), "--workers", "0"], 2))

    def loop(d: Path) -> list:
        scan = vessel_obj(d)
        (d / "pot.png").unlink()
        os.symlink(d / "pot.png", d / "pot.png")
        return ["run", scan, "-o", d / "out"]
    add(Case("texture that is a symlink loop", loop, 2))

    def null_sidecar(d: Path) -> list:
        assert potflat(["rollout", vessel_obj(d), "-o", d / "out", "-q"], d, 6 << 30, 120).code == 0
        (d / "out" / "pot.rollout.json").write_text("null")
        return ["relax", d / "out" / "pot.rollout.ply", "--preset", "preview", "-q"]
    add(Case("NAME.rollout.json holding null", null_sidecar, 0))

    def newline(d: Path) -> list:
        scan = vessel_obj(d)
        return ["run", scan.rename(d / "po\nt.obj"), "-o", d / "out"]
    add(Case("scan name with a newline", newline, 2, lambda d, r: "" if "control character" in r.stderr else "unclear"))
    add(Case("batch output that cannot be created (/proc)", lambda d: ["batch", batch_file(
        d, f"  - path: {vessel_obj(d / 's').relative_to(d)}\n", output="/proc/potflat-out")], 2))

    def huge(d: Path) -> list:
        (d / "big.obj").write_text("v 1e302 0 0\nv 0 1e302 0\nv 0 0 1e302\nv 1e302 1e302 1e302\n"
                                   "f 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
        return ["run", d / "big.obj", "-o", d / "out"]
    add(Case("coordinates near 1e302", huge, 2, lambda d, r: "" if "overflow" in r.stderr else "overflow not named"))

    # ---- silent wrong results
    def no_vt(d: Path) -> list:
        scan = vessel_obj(d)
        scan.write_text("\n".join(ln for ln in scan.read_text().splitlines() if not ln.startswith("vt ")) + "\n")
        return ["run", scan, "-o", d / "out"]
    add(Case("OBJ faces f v/vt without vt lines", no_vt, 2, nothing_in(Path("out"))))

    # ---- interruption and concurrency
    def batch_of(d: Path, n: int) -> Path:
        body = ""
        for k in range(n):
            vessel_obj(d / "scans", name=f"pot{k}")
            body += f"  - path: scans/pot{k}.obj\n"
        return batch_file(d, body)

    def statuses(expected: set) -> Callable[[Path, Run], str]:
        def check(d: Path, run: Run) -> str:
            try:
                summary = json.loads((d / "out" / "summary.json").read_text())
            except (OSError, ValueError):
                return "no summary"
            got = [s["status"] for s in summary["scans"]]
            if not set(got) <= expected or "cancelled" not in got:
                return f"statuses {got}"
            time.sleep(0.5)
            ps = subprocess.run(["ps", "-o", "pid=,stat=,args=", "-s", str(run.pid)], capture_output=True, text=True)
            alive = [ln for ln in ps.stdout.splitlines() if ln.split()[1][0] != "Z"]  # zombies are dead
            return f"processes alive: {alive[:2]}" if alive else no_parts("out")(d, run)
        return check

    for sig in (signal.SIGINT, signal.SIGTERM):
        add(Case(f"{sig.name} during a batch (4 scans, 2 workers)", lambda d, s=sig: [
            "batch", batch_of(d, 4), "-w", "2", "-q",
            ("stop", lambda: any((d / "out").glob("pot*/pot*.rollout.json")), s)],
            130, statuses({"done", "interrupted", "cancelled"}), timeout=240))

    def orphans(d: Path, run: Run, patience: float = 15.0) -> str:
        deadline = time.monotonic() + patience
        while time.monotonic() < deadline:
            ps = subprocess.run(["ps", "-o", "pid=,stat=", "-s", str(run.pid)], capture_output=True, text=True)
            if not [ln for ln in ps.stdout.splitlines() if ln.split()[1][0] != "Z"]:
                return ""
            time.sleep(0.1)
        return f"processes outlived the killed command by {patience:g} s"
    add(Case("SIGKILL to the batch process alone (workers must end with it)", lambda d: [
        "batch", batch_of(d, 3), "-w", "2", "-q",
        ("stop", lambda: any((d / "out").glob("pot*/pot*.rollout.json")), -signal.SIGKILL)],
        -signal.SIGKILL, orphans, timeout=240))

    def killed_then_rerun(d: Path) -> list:
        scan = vessel_obj(d)
        out = d / "out"
        run = potflat(["run", scan, "-o", out, "--preset", "preview"], d, 6 << 30, 120,
                      stop=(lambda: (out / ".pot.potflat-incomplete").exists(), signal.SIGKILL))
        if run.code != -signal.SIGKILL:
            raise RuntimeError(f"the first run was not killed ({run.code})")
        (out / ".pot.png.x1.part").write_bytes(b"debris")  # as a kill during the bake leaves
        (out / "pot.png").write_bytes(b"half")
        shutil.copy(out / "pot.rollout.json", d / "keep.json")
        return ["run", scan, "-o", out, "--preset", "preview", "-q"]
    add(Case("SIGKILL mid-run, a partial NAME.png, then a rerun", killed_then_rerun, 0, no_parts("out"), timeout=240))

    def sigterm_run(d: Path) -> list:
        return ["run", vessel_obj(d), "-o", d / "out", "--preset", "archival",
                ("stop", lambda: (d / "out" / "pot.rollout.json").exists(), signal.SIGTERM)]
    add(Case("SIGTERM during potflat run", sigterm_run, 130, no_parts("out")))

    def after(seconds: float) -> Callable[[], bool]:
        """A condition that holds ``seconds`` after its first check (made as the process starts)."""
        since: list[float] = []

        def holds() -> bool:
            if not since:
                since.append(time.monotonic())
            return time.monotonic() - since[0] >= seconds
        return holds
    for seconds in (0.1, 0.3, 0.6, 1.0):
        for sig in (signal.SIGINT, signal.SIGTERM):
            add(Case(f"{sig.name} {seconds:g} s after potflat run starts", lambda d, t=seconds, s=sig: [
                "run", vessel_obj(d), "-o", d / "out", "--preset", "preview", ("stop", after(t), s)],
                130, lambda d, r: one_line(r) or no_parts("out")(d, r)))

    def killed_first_run(d: Path) -> list:
        (d / "tmp").mkdir()
        return ["run", vessel_obj(d), "-o", d / "out",
                ("stop", lambda: any((d / "tmp").glob("potflat-warmup-*/warmup.texture.png")), -signal.SIGKILL)]

    def child_ended(d: Path, run: Run) -> str:
        return orphans(d, run, patience=5.0) or (
            "" if not list((d / "tmp").glob("potflat-warmup-*/warmup.texture.png")) else "the child's folder is left")
    add(Case("SIGKILL to a first run (empty kernel cache) while its warm-up child compiles", killed_first_run,
             -signal.SIGKILL, child_ended, timeout=240,
             env=lambda d: {"NUMBA_CACHE_DIR": str(d / "kernel-cache"), "TMPDIR": str(d / "tmp")}))

    # ---- defaults and help
    def default_out(d: Path) -> list:
        vessel_obj(d / "archive")
        return ["run", d / "archive" / "pot.obj", "--preset", "preview", "--px-per-mm", "1", "-q"]

    def defaults_check(d: Path, run: Run) -> str:
        if sorted(p.name for p in (d / "archive").iterdir()) != ["pot.mtl", "pot.obj", "pot.png"]:
            return "wrote into the scan's folder"
        tex = d / "pot" / "pot.texture.png"
        if not tex.is_file() or os.stat(tex).st_nlink != 1:
            return "texture missing or linked"
        bake = json.loads((d / "pot" / "pot.bake.json").read_text())
        return "" if "ln(" in json.dumps(bake) else "area figures not in natural log"
    add(Case("default output ./NAME/, texture copied, one log base", default_out, 0, defaults_check))
    add(Case("--band 0.2,0.8 and --units metre", lambda d: ["rollout", vessel_obj(d, scale=1e-3), "-o", d / "out",
                                                            "--band", "0.2,0.8", "--units", "metre", "-q"], 0))
    add(Case("run --help shows the allowed values", lambda d: ["run", "--help"], 0,
             lambda d, r: "" if "[um|mm|cm|m|in]" in r.stdout and "<bool>" not in r.stdout.split("--help")[0]
             else "choices not shown"))

    if real is not None:
        for scan in sorted(real.glob("*.ply")) + sorted(real.glob("*.stl")):
            def paper(d: Path, scan=scan) -> list:
                assert potflat(["rollout", scan, "-o", d / "out", "-q"], d, 6 << 30, 300).code == 0
                return ["relax", d / "out" / f"{scan.stem}.rollout.ply", "--preset", "paper", "-q"]
            add(Case(f"relax --preset paper on the real {scan.name}", paper, 0, timeout=300))
    return cases


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--memory-gb", type=float, default=6.0, help="address-space cap per process (GiB)")
    parser.add_argument("--real", type=Path, help="folder of real scans: also relax --preset paper on each")
    parser.add_argument("-k", default="", help="run only cases whose name contains this")
    args = parser.parse_args(argv)
    cap = int(args.memory_gb * (1 << 30))
    rows, failed = [], 0
    with tempfile.TemporaryDirectory(prefix="potflat-hostile-") as tmp:
        for i, case in enumerate(c for c in corpus(args.real) if args.k.lower() in c.name.lower()):
            d = Path(tmp) / f"case{i:02d}"
            d.mkdir()
            try:
                argv_ = case.make(d)
                stop = None
                if argv_ and isinstance(argv_[-1], tuple):
                    _, condition, sig = argv_.pop()
                    stop = (condition, sig)
                run = potflat(argv_, d, cap, case.timeout, stop=stop, env=case.env(d) if case.env else None)
                problem = ""
                if run.code != case.expect:
                    problem = f"exit {run.code}, expected {case.expect}"
                elif case.expect == 2:
                    problem = one_line(run)
                if not problem and case.check is not None:
                    problem = case.check(d, run)
            except Exception as exc:  # noqa: BLE001 - a broken case is a failed case
                run, problem = Run(-1, "", "", 0.0), f"case set-up failed: {exc}"
            failed += bool(problem)
            message = (run.stderr.strip().splitlines() or [""])[-1].replace("|", "/")
            rows.append((case.name, run.code, run.seconds, "ok" if not problem else f"FAIL: {problem}",
                         message[:110] + ("..." if len(message) > 110 else "")))
            print(f"{'ok  ' if not problem else 'FAIL'} {case.name} ({run.seconds:.1f} s)", file=sys.stderr, flush=True)
    print("| case | exit | s | verdict | stderr (last line) |\n|---|---|---|---|---|")
    for name, code, seconds, verdict, message in rows:
        print(f"| {name} | {code} | {seconds:.1f} | {verdict} | {message} |")
    print(f"\n{len(rows) - failed} of {len(rows)} cases as expected; memory cap {args.memory_gb:g} GiB per process")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
