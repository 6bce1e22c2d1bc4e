"""Bake benchmark: time and peak memory of ``run_bake_stage`` on a large textured frieze.

Wall time depends on what else runs on the machine; CPU time (user + system, all
threads) is the steadier figure. The frieze is a band of a vessel (radius 160 mm, 300 mm high, the whole circumference:
1005 x 300 mm) triangulated on a jittered lattice with random diagonals, textured from
an 8192 x 8192 atlas holding the band in eight charts (13.6 texels/mm). The bake runs in a fresh child
process so its peak resident memory (``ru_maxrss``) is measured alone.

Two sets of outputs, each baked in its own child process from the same frieze: ``maps`` (the
painting, the three distortion maps, the overlay and the scale layer: what ``potflat run``
writes) and ``archive`` (the painting, a 16-bit TIFF and the position map, no maps).

Reproduce (block ``bench_bake`` of docs/performance.md)::

    python benchmarks/bench_bake.py --write
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _docs import command_line, machine, publish  # noqa: E402

RADIUS_MM, HEIGHT_MM, ATLAS = 160.0, 300.0, 8192
#: The sets of outputs: name -> ``BakeOptions`` keywords besides the resolution.
OUTPUTS = {
    "maps": {"maps": ["stress", "area", "anisotropy"]},
    "archive": {"maps": [], "position_map": True, "tiff": True},
}


def make_frieze(n_vertices: float, out: Path, *, seed: int = 0) -> Path:
    """Write ``frieze.relaxed.ply`` (and its atlas) into ``out`` and return the PLY path."""
    import cv2

    from potflat.io.flat_ply import write_flat_ply
    from potflat.types import FlatMesh, Mesh

    rng = np.random.default_rng(seed)
    circ = 2 * np.pi * RADIUS_MM
    nv = int(np.sqrt(n_vertices * HEIGHT_MM / circ))
    nu = int(n_vertices / nv)
    u, v = np.meshgrid(np.linspace(0, circ, nu), np.linspace(0, HEIGHT_MM, nv))
    du, dv = circ / (nu - 1), HEIGHT_MM / (nv - 1)
    u[:, 1:-1] += rng.uniform(-0.3, 0.3, u[:, 1:-1].shape) * du
    v[1:-1, :] += rng.uniform(-0.3, 0.3, v[1:-1, :].shape) * dv
    theta = u / RADIUS_MM
    X = np.stack([RADIUS_MM * np.cos(theta), RADIUS_MM * np.sin(theta), v], -1).reshape(-1, 3)
    uv = np.stack([u, v], -1).reshape(-1, 2)
    idx = np.arange(nu * nv).reshape(nv, nu)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    flip = rng.random(len(a)) < 0.5
    f1 = np.where(flip[:, None], np.stack([a, b, d], 1), np.stack([a, b, c], 1))
    f2 = np.where(flip[:, None], np.stack([a, d, c], 1), np.stack([b, d, c], 1))
    F = np.concatenate([f1, f2]).astype(np.int64)
    # atlas: eight charts (eighths of the circumference) in 4 columns x 2 rows, 8-texel gutters
    charts, cols = 8, 4
    cell_w, cell_h = ATLAS // cols, ATLAS // (charts // cols)
    part = np.minimum((uv[F].mean(axis=1)[:, 0] / circ * charts).astype(int), charts - 1)
    tpm = min((cell_w - 16) / (circ / charts), (cell_h - 16) / HEIGHT_MM)
    pts = uv[F]
    x = (part % cols)[:, None] * cell_w + 8 + (pts[..., 0] - part[:, None] * circ / charts) * tpm
    y = (part // cols)[:, None] * cell_h + 8 + (HEIGHT_MM - pts[..., 1]) * tpm
    tc = np.stack([x / ATLAS, 1.0 - y / ATLAS], axis=-1)
    img = rng.integers(150, 230, (ATLAS // 8, ATLAS // 8, 3), dtype=np.uint8)
    img = cv2.resize(img, (ATLAS, ATLAS), interpolation=cv2.INTER_CUBIC)
    for _ in range(400):
        cv2.circle(img, (int(rng.integers(0, ATLAS)), int(rng.integers(0, ATLAS))), int(rng.integers(10, 120)),
                   tuple(int(t) for t in rng.integers(0, 255, 3)), -1, cv2.LINE_AA)
    out.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out / "frieze_atlas.png"), img)
    flat = FlatMesh(Mesh(X, F, texcoords=tc, texture_path=out / "frieze_atlas.png", units="mm"), uv)
    return write_flat_ply(out / "frieze.relaxed.ply", flat)


def _child(ply: str, out: str, options: str) -> None:
    from potflat.bake import BakeOptions
    from potflat.files.bake_stage import run_bake_stage

    t = time.perf_counter()
    res = run_bake_stage(ply, out, BakeOptions(**json.loads(options)))
    seconds = time.perf_counter() - t
    usage = resource.getrusage(resource.RUSAGE_SELF)
    s = res.record
    print(json.dumps({"seconds": seconds, "cpu_seconds": usage.ru_utime + usage.ru_stime,
                      "peak_mb": usage.ru_maxrss / 1024, "image_px": s["image_px"],
                      "supersample": s["supersample"], "mip_levels": s["mip_levels"],
                      "files_mb": sum(p.stat().st_size for p in res.paths.values()) / 1e6,
                      "files": sorted(res.record["files"].values())}))


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--vertices", type=float, default=2.5e6)
    ap.add_argument("--px-per-mm", type=float, default=20.0)
    ap.add_argument("--outputs", default=",".join(OUTPUTS), help=f"comma-separated, of {', '.join(OUTPUTS)}")
    ap.add_argument("--workdir", type=Path, default=None, help="keep the frieze and outputs here")
    ap.add_argument("--write", action="store_true", help="rewrite block bench_bake of docs/performance.md")
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        _child(*args.child)
        return
    unknown = sorted(set(args.outputs.split(",")) - set(OUTPUTS))
    if unknown:
        raise SystemExit(f"--outputs: unknown {', '.join(unknown)}; choose from {', '.join(OUTPUTS)}")
    work = args.workdir or Path(tempfile.mkdtemp(prefix="potflat-bench-bake-"))
    ply = work / "frieze.relaxed.ply"
    t = time.perf_counter()
    if not ply.exists():
        make_frieze(args.vertices, work)
    build = time.perf_counter() - t
    from potflat.io.flat_ply import read_flat_ply

    flat = read_flat_ply(ply)
    print(f"frieze {len(flat.mesh.vertices) / 1e6:.2f}M vertices, {len(flat.mesh.faces) / 1e6:.2f}M faces "
          f"(built in {build:.0f} s), atlas {ATLAS}^2", flush=True)
    lines = [f"`{command_line('bench_bake.py', argv if argv is not None else sys.argv[1:])}` ({machine()}): "
             f"{len(flat.mesh.vertices) / 1e6:.2f}M vertices, {len(flat.mesh.faces) / 1e6:.2f}M faces, "
             f"{ATLAS} x {ATLAS} atlas.", "",
             "| outputs | files | px/mm | image | supersample | wall time | CPU time | peak memory | written |",
             "|---|---|---:|---|---:|---:|---:|---:|---:|"]
    for name in args.outputs.split(","):
        options = {"px_per_mm": args.px_per_mm, **OUTPUTS[name]}
        proc = subprocess.run([sys.executable, __file__, "--child", str(ply), str(work / name), json.dumps(options)],
                              check=True, capture_output=True, text=True, env={**os.environ})
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        w, h = r["image_px"]
        files = ", ".join(f.split(".", 1)[1] for f in r["files"])
        lines.append(f"| {name} | {files} | {args.px_per_mm:g} | {w} x {h} ({w * h / 1e6:.0f} MP) | {r['supersample']} | "
                     f"{r['seconds']:.0f} s | {r['cpu_seconds']:.0f} s | {r['peak_mb'] / 1024:.2f} GB | "
                     f"{r['files_mb']:.0f} MB |")
        print(lines[-1], flush=True)
    publish("bench_bake", "\n".join(lines) + "\n", args.write)


if __name__ == "__main__":
    from potflat_cli._process import command_settings

    with command_settings():  # as the potflat command runs: OpenMP's passive wait, the heap tuning
        main()
