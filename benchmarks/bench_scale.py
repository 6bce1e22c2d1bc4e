"""End-to-end benchmark at scale: synthetic scans of 0.3M, 1M and 3M vertices through
``potflat run``, each beside a trimesh load of the same OBJ.

For each size a painted amphora (:func:`potflat_synthetic.vessels.make_vessel`, random pose,
multi-chart texture atlas) is written as OBJ + MTL + PNG. Then, one after the other in one
run, each in its own child process: ``trimesh.load(obj, process=False)`` (the yardstick: the
time of the load call itself and that process's peak), potflat's loader alone
(``load_scan(obj, clean=False)``, timed alike), and ``python -m potflat_cli run`` exactly as a
user would run it. The benchmark samples the run's resident memory (``VmRSS`` in
``/proc/PID/status``) every 0.1 s and its high-water mark (``VmHWM``), and splits the run into
stages by the appearance of each stage's JSON sidecar (``NAME.rollout.json``,
``NAME.relaxed.json``, ``NAME.bake.json``): per stage the wall time (as the run reports it)
and the peak memory; for the whole run the wall time (start-up included), the CPU time of the
child (user + system, all threads) and its peak (``VmHWM``).
Before the first size, ``potflat run`` on the bundled amphora compiles and caches every kernel
the runs use (:func:`_run.warm_kernels`): the rows measure runs with warm kernels; a first run's
compile time is measured by ``bench_first_run.py``.

Targets: at 1M vertices the whole run at most 2x the trimesh load; at 3M at most 60 s and 3 GB.

Reproduce (block ``bench_scale`` of docs/performance.md)::

    python benchmarks/bench_scale.py --write

Options: ``--vertices`` (sizes, default 0.3e6 1e6 3e6), ``--preset`` (relax preset, default
standard), ``--px-per-mm`` (default 4), ``--texture-size`` (atlas side, default 8192),
``--keep DIR`` (keep the scans and outputs; a later run with the same DIR reuses the scans).
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _docs import command_line, machine, publish  # noqa: E402
from _run import STAGES, run_potflat, warm_kernels  # noqa: E402

#: Targets: the whole run at 1M vertices within this multiple of the trimesh load ...
GOAL_RATIO_1M = 2.0
#: ... and at 3M vertices within these seconds and GB.
GOAL_S_3M, GOAL_GB_3M = 60.0, 3.0
BLOCK = "bench_scale"


def make_scan(n_vertices: int, folder: Path, *, texture_size: int, seed: int = 0) -> tuple[Path, dict]:
    """Write the synthetic amphora into ``folder``; return the OBJ path and its figures. A
    scan this function wrote there before with the same settings (``--keep``) is reused."""
    from potflat_synthetic.vessels import make_vessel, write_obj

    settings = {"n_vertices": n_vertices, "seed": seed, "texture_size": texture_size}
    record = folder / "scan.json"
    if record.is_file() and (folder / "amphora.obj").is_file():
        kept = json.loads(record.read_text())
        if kept.get("settings") == settings:
            return folder / "amphora.obj", kept["info"]
    t = time.perf_counter()
    vessel = make_vessel("amphora", n_vertices=n_vertices, seed=seed, texture_size=texture_size)
    path = write_obj(vessel, folder / "amphora.obj")
    info = {"vertices": len(vessel.mesh.vertices), "faces": len(vessel.mesh.faces),
            "texture": f"{texture_size} x {texture_size}", "obj_mb": path.stat().st_size / 1e6,
            "generate_s": time.perf_counter() - t}
    record.write_text(json.dumps({"settings": settings, "info": info}))
    return path, info


TRIMESH_CHILD = """
import re, sys, time
import trimesh
t = time.perf_counter()
mesh = trimesh.load(sys.argv[1], process=False)
load = time.perf_counter() - t
hwm = int(re.search(r"VmHWM:\\s+(\\d+) kB", open("/proc/self/status").read()).group(1))
print(load, hwm, len(mesh.vertices))
"""


#: potflat's loader alone, as the trimesh child: no cleaning (``potflat run`` cleans too)
POTFLAT_CHILD = TRIMESH_CHILD.replace("import trimesh", "from potflat.io.scan import load_scan").replace(
    "mesh = trimesh.load(sys.argv[1], process=False)", "mesh = load_scan(sys.argv[1], clean=False).mesh")


def child_load(scan: Path, code: str = TRIMESH_CHILD) -> dict:
    """Load ``scan`` in a child process running ``code`` (default: ``trimesh.load(path,
    process=False)``): the seconds of the load call (not the import) and the child's peak
    memory (GB)."""
    out = subprocess.run([sys.executable, "-c", code, str(scan)], capture_output=True, text=True,
                         check=True).stdout.split()
    return {"load_s": float(out[0]), "peak_gb": int(out[1]) / 2**20}


def run_benchmark(scan: Path, out: Path, *, preset: str, px_per_mm: float, extra: tuple[str, ...] = (),
                  interval: float = 0.1) -> dict:
    """Run ``potflat run`` on ``scan`` in a child process (``extra``: more of its options;
    :func:`_run.run_potflat`): per stage its wall time and peak memory, the whole run's wall
    and CPU time and peak, the run's figures. A failed run stops the benchmark."""
    run = run_potflat(scan, out, ("--preset", preset, "--px-per-mm", str(px_per_mm), *extra), interval=interval)
    if run["rc"] != 0:
        raise SystemExit(f"potflat run failed (exit {run['rc']}):\n{run['stderr']}")
    return {"rows": run["stages"], "total_wall_s": run["wall_s"], "run_seconds": run["report"]["seconds"],
            "cpu_s": run["cpu_s"], "peak_gb": run["peak_gb"], "figures": run["report"]["figures"]}


def _image(out: Path, name: str) -> str:
    data = json.loads((out / f"{name}.bake.json").read_text())
    w, h = data["image_px"]
    return f"{w} x {h} px"


def measure(n_vertices: float, root: Path, *, preset: str, px_per_mm: float, texture_size: int) -> dict:
    """Generate one scan, load it with trimesh, run potflat on it; every figure of one row."""
    print(f"generating {n_vertices:.3g}-vertex amphora in {root} ...", flush=True)
    scan, info = make_scan(int(n_vertices), root / "scan", texture_size=texture_size)
    print(f"  {info['vertices']:,} vertices, {info['faces']:,} faces, {info['obj_mb']:.0f} MB, "
          f"{info['generate_s']:.0f} s; trimesh load ...", flush=True)
    yardstick = child_load(scan)
    loader = child_load(scan, POTFLAT_CHILD)
    print(f"  trimesh load {yardstick['load_s']:.1f} s, potflat load {loader['load_s']:.1f} s; potflat run ...",
          flush=True)
    result = run_benchmark(scan, root / "out", preset=preset, px_per_mm=px_per_mm)
    print(f"  potflat run {result['total_wall_s']:.1f} s, peak {result['peak_gb']:.2f} GB", flush=True)
    return {"info": info, "trimesh": yardstick, "loader": loader, "result": result, "image": _image(root / "out", scan.stem)}


def _verdicts(rows: list[dict]) -> list[str]:
    out = []
    for row in rows:
        v, res, tm = row["info"]["vertices"], row["result"], row["trimesh"]
        ratio = res["total_wall_s"] / tm["load_s"]
        if 0.5e6 < v < 2e6:
            out.append(f"{v / 1e6:.1f}M vertices: the whole run takes {ratio:.1f}x the trimesh load "
                       f"(target at most {GOAL_RATIO_1M:g}x): {'met' if ratio <= GOAL_RATIO_1M else 'not met'}.")
        if v >= 2e6:
            fast, small = res["total_wall_s"] <= GOAL_S_3M, res["peak_gb"] <= GOAL_GB_3M
            out.append(f"{v / 1e6:.1f}M vertices: {res['total_wall_s']:.0f} s (target at most {GOAL_S_3M:g} s: "
                       f"{'met' if fast else 'not met'}) and {res['peak_gb']:.2f} GB (target at most "
                       f"{GOAL_GB_3M:g} GB: {'met' if small else 'not met'}).")
    return out


def table(rows: list[dict], *, command: str) -> str:
    """The block of docs/performance.md: the command, the table, the targets."""
    lines = [f"`{command}` ({machine()}):", "",
             "| vertices | faces | OBJ MB | trimesh load s (GB) | potflat load s (GB) | rollout s (GB) | relax s (GB) | bake s (GB) "
             "| whole run s (CPU s) | peak GB | run / trimesh | image |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]
    for row in rows:
        info, res, tm = row["info"], row["result"], row["trimesh"]
        st = {r["stage"]: r for r in res["rows"]}
        cells = [f"{info['vertices']:,}", f"{info['faces']:,}", f"{info['obj_mb']:.0f}",
                 f"{tm['load_s']:.1f} ({tm['peak_gb']:.2f})",
                 f"{row['loader']['load_s']:.1f} ({row['loader']['peak_gb']:.2f})"]
        cells += [f"{st[k]['wall_s']:.1f} ({st[k]['peak_gb']:.2f})" for k in STAGES]
        cells += [f"**{res['total_wall_s']:.1f}** ({res['cpu_s']:.0f})", f"**{res['peak_gb']:.2f}**",
                  f"{res['total_wall_s'] / tm['load_s']:.1f}", row["image"]]
        lines.append("| " + " | ".join(cells) + " |")
    f = rows[-1]["result"]["figures"]
    lines += ["", *_verdicts(rows), (f"Relaxed (largest): edge-length RMS {f.get('edge_rms', float('nan')):.4f}, "
                                     f"{f.get('flipped')} flipped triangles.")]
    return "\n".join(lines) + "\n"


def add_scan_options(ap: argparse.ArgumentParser) -> None:
    """The options of a benchmark on generated scans: resolution, texture size, where to keep
    the files, whether to write its block of docs/performance.md."""
    ap.add_argument("--px-per-mm", type=float, default=4.0)
    ap.add_argument("--texture-size", type=int, default=8192)
    ap.add_argument("--keep", type=Path, help="folder for the scans and outputs (kept)")
    ap.add_argument("--write", action="store_true", help="update the benchmark's block in docs/performance.md")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vertices", type=float, nargs="+", default=[0.3e6, 1e6, 3e6])
    ap.add_argument("--preset", default="standard")
    add_scan_options(ap)
    args = ap.parse_args(argv)

    warm_kernels()
    rows = []
    for n in args.vertices:
        with tempfile.TemporaryDirectory(prefix="potflat-scale-") as tmp:
            root = (args.keep / f"{n:.3g}") if args.keep else Path(tmp)
            root.mkdir(parents=True, exist_ok=True)
            rows.append(measure(n, root, preset=args.preset, px_per_mm=args.px_per_mm,
                                texture_size=args.texture_size))
    command = command_line("bench_scale.py", argv if argv is not None else sys.argv[1:])
    publish(BLOCK, table(rows, command=command), args.write)


if __name__ == "__main__":
    from potflat_cli._process import command_settings

    with command_settings():  # as the potflat command runs: OpenMP's passive wait, the heap tuning
        main()
