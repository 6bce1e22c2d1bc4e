"""End-to-end benchmark at scale: a 3M-vertex synthetic scan through ``potflat run``.

A painted amphora (:func:`potflat_synthetic.vessels.make_vessel`, random pose, multi-chart texture
atlas) is written as OBJ + MTL + PNG, then ``python -m potflat_cli run`` processes it in one
child process, exactly as a user would run it. The benchmark samples the child's resident
memory (``VmRSS`` in ``/proc/PID/status``) every 0.1 s and its high-water mark
(``VmHWM``), and splits the run into stages by the appearance of each stage's JSON
sidecar (``NAME.rollout.json``, ``NAME.relaxed.json``, ``NAME.bake.json``): per stage the
wall time and the peak memory; for the whole run the wall time, the CPU time of the child
(user + system, all threads) and its peak (``VmHWM``). Goal (issue 6): at most 4 GB.
``ru_maxrss`` of the child is printed too but not judged: Linux carries the parent's
resident set at fork (here the generated scan) into it, so it overstates potflat's peak.

Reproduce (the table in docs/performance.md, section "End to end at scale")::

    python benchmarks/bench_scale.py --vertices 3e6 --write

Options: ``--preset`` (relax preset, default standard), ``--px-per-mm`` (default 4),
``--texture-size`` (atlas side, default 8192), ``--keep DIR`` (keep the scan and outputs).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import re
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

GOAL_GB = 4.0
STAGES = ("rollout", "relax", "bake")
SIDE = {"rollout": ".rollout.json", "relax": ".relaxed.json", "bake": ".bake.json"}
SECTION = "## End to end at scale"


def make_scan(n_vertices: int, folder: Path, *, texture_size: int, seed: int = 0) -> tuple[Path, dict]:
    """Write the synthetic amphora into ``folder``; return the OBJ path and its figures."""
    from potflat_synthetic.vessels import make_vessel, write_obj

    t = time.perf_counter()
    vessel = make_vessel("amphora", n_vertices=n_vertices, seed=seed, texture_size=texture_size)
    path = write_obj(vessel, folder / "amphora.obj")
    info = {"vertices": len(vessel.mesh.vertices), "faces": len(vessel.mesh.faces),
            "texture": f"{texture_size} x {texture_size}", "obj_mb": path.stat().st_size / 1e6,
            "generate_s": time.perf_counter() - t}
    return path, info


def _status_kb(pid: int) -> dict[str, int]:
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return {}
    return {k: int(v) for k, v in re.findall(r"^(VmRSS|VmHWM):\s+(\d+) kB", text, re.MULTILINE)}


def run_benchmark(scan: Path, out: Path, *, preset: str, px_per_mm: float, interval: float = 0.1) -> dict:
    """Run ``potflat run`` on ``scan`` in a child process; sample its memory; split by stage."""
    cmd = [sys.executable, "-m", "potflat_cli", "run", str(scan), "-o", str(out), "--preset", preset,
           "--px-per-mm", str(px_per_mm), "--json"]
    samples: list[tuple[float, int]] = []
    marks: dict[str, float] = {}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    hwm = [0]

    def sample() -> None:
        while proc.poll() is None:
            now = time.perf_counter() - start
            st = _status_kb(proc.pid)
            if "VmRSS" in st:
                samples.append((now, st["VmRSS"]))
                hwm[0] = max(hwm[0], st.get("VmHWM", 0))
            for stage in STAGES:
                if stage not in marks and (out / f"{scan.stem}{SIDE[stage]}").exists():
                    marks[stage] = now
            time.sleep(interval)

    thread = threading.Thread(target=sample, daemon=True)
    thread.start()
    stdout, stderr = proc.communicate()
    total = time.perf_counter() - start
    thread.join()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise SystemExit(f"potflat run failed (exit {proc.returncode}):\n{stderr[-3000:]}")
    report = json.loads(stdout)
    rows, t0 = [], 0.0
    for stage in STAGES:
        t1 = marks.get(stage, total)
        window = [kb for t, kb in samples if t0 <= t <= t1 + interval]
        rows.append({"stage": stage, "wall_s": report["seconds"].get(stage, t1 - t0),
                     "peak_gb": max(window, default=0) / 2**20})
        t0 = t1
    return {
        "rows": rows,
        "total_wall_s": total,
        "run_seconds": report["seconds"],
        "cpu_s": (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime),
        # the child's own high-water mark; RUSAGE_CHILDREN's ru_maxrss is not used for the
        # verdict: Linux carries the parent's resident set at fork into the child's maxrss
        # (here the generated scan held by this process), so it overstates potflat's peak
        "peak_gb": hwm[0] / 2**20,
        "hwm_gb": hwm[0] / 2**20, "maxrss_gb": after.ru_maxrss / 2**20,
        "figures": report["figures"],
    }


def _image(out: Path, name: str) -> str:
    data = json.loads((out / f"{name}.bake.json").read_text())
    w, h = data["image_px"]
    return f"{w} x {h} px ({data['image_mm'][0]:.0f} x {data['image_mm'][1]:.0f} mm)"


def table(info: dict, result: dict, image: str, *, command: str, preset: str, px_per_mm: float) -> str:
    """The Markdown section (heading, setup line, table, verdict)."""
    setup = (f"`{command}` "
             f"({time.strftime('%Y-%m-%d')}, {os.cpu_count()} cores, {platform.machine()}, Python "
             f"{platform.python_version()}): a synthetic painted amphora, {info['vertices']:,} vertices, "
             f"{info['faces']:,} faces, {info['texture']} texture atlas, OBJ {info['obj_mb']:.0f} MB "
             f"(generated in {info['generate_s']:.0f} s, not counted), through `potflat run --preset {preset} "
             f"--px-per-mm {px_per_mm:g}` in one process: painting {image}. Memory is the resident set sampled "
             "every 0.1 s (stage peaks) and the process's high-water mark (total); the machine is shared, "
             "so treat times as +-30%.")
    lines = [SECTION, "", setup, "", "| stage | wall s | peak memory GB |", "|---|---:|---:|"]
    for r in result["rows"]:
        lines.append(f"| {r['stage']} | {r['wall_s']:.1f} | {r['peak_gb']:.2f} |")
    lines.append(f"| **whole run** (incl. start-up) | **{result['total_wall_s']:.1f}** "
                 f"(CPU {result['cpu_s']:.0f}) | **{result['peak_gb']:.2f}** |")
    f = result["figures"]
    verdict = "within" if result["peak_gb"] <= GOAL_GB else "OVER"
    lines += ["", (f"Peak {result['peak_gb']:.2f} GB (VmHWM {result['hwm_gb']:.2f}, ru_maxrss "
                   f"{result['maxrss_gb']:.2f}, which counts this benchmark's own memory at fork; "
                   f"GB = 2^30 bytes): {verdict} the {GOAL_GB:g} GB goal. Relaxed: edge-length "
                   f"RMS {f.get('edge_rms', float('nan')):.4f}, {f.get('flipped')} flipped triangles."), ""]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vertices", type=float, default=3e6)
    ap.add_argument("--preset", default="standard")
    ap.add_argument("--px-per-mm", type=float, default=4.0)
    ap.add_argument("--texture-size", type=int, default=8192)
    ap.add_argument("--keep", type=Path, help="folder for the scan and outputs (kept)")
    ap.add_argument("--write", action="store_true", help="update the section in docs/performance.md")
    args = ap.parse_args(argv)

    with tempfile.TemporaryDirectory(prefix="potflat-scale-") as tmp:
        root = args.keep or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        print(f"generating {args.vertices:.3g}-vertex amphora in {root} ...", flush=True)
        scan, info = make_scan(int(args.vertices), root / "scan", texture_size=args.texture_size)
        print(f"  {info['vertices']:,} vertices, {info['faces']:,} faces, {info['obj_mb']:.0f} MB, "
              f"{info['generate_s']:.0f} s; running potflat run ...", flush=True)
        result = run_benchmark(scan, root / "out", preset=args.preset, px_per_mm=args.px_per_mm)
        given = list(argv if argv is not None else sys.argv[1:])
        if "--keep" in given:  # where the files went is not part of the benchmark
            del given[given.index("--keep"):given.index("--keep") + 2]
        command = "python benchmarks/bench_scale.py " + " ".join(a for a in given if not a.startswith("--keep="))
        section = table(info, result, _image(root / "out", scan.stem), command=command.strip(),
                        preset=args.preset, px_per_mm=args.px_per_mm)
    print(section)
    if args.write:
        sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
        from benchmarks._docs import PERFORMANCE_MD, write_section

        write_section(section)
        print(f"updated {PERFORMANCE_MD}")


if __name__ == "__main__":
    main()
