"""Relief benchmark: what ``--relief`` adds to a bake of a 1M-vertex scan.

The scan is ``bench_scale.py``'s: a synthetic painted amphora (:func:`potflat_synthetic.vessels.make_vessel`,
multi-chart texture atlas), rolled out and relaxed once (``potflat rollout``, ``potflat relax``;
not timed). Then ``potflat bake NAME.relaxed.ply`` runs without and with ``--relief``,
alternately, each in its own process, ``--repeat`` times; the table gives the medians of the
bake stage's own time (``NAME.bake.json``, ``timings.total``: start-up not counted) and of its
steps, and the ratio of the medians. A first bake of each kind (not counted) compiles and caches
the kernels. Goal: the relief adds at most 50% to the bake.

Reproduce (the table in docs/performance.md, block ``bench_relief``)::

    python benchmarks/bench_relief.py --write

Options: ``--vertices`` (default 1e6), ``--repeat`` (default 3), ``--px-per-mm`` (default 4),
``--texture-size`` (default 8192), ``--keep DIR`` (keep the scan and the outputs; a later run
with the same DIR reuses the scan and its relaxation).
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _docs import command_line, publish  # noqa: E402
from bench_scale import make_scan  # noqa: E402

#: The goal: the relief adds at most this share to a bake.
GOAL_ADDED = 0.5
#: The bake's steps shown (``NAME.bake.json`` timings).
STEPS = ("prepare", "relief", "render", "figures")


def _potflat(*args: str) -> None:
    subprocess.run([sys.executable, "-m", "potflat_cli", *args, "--quiet"], check=True, stdin=subprocess.DEVNULL)


def _bake(relaxed: Path, out: Path, px_per_mm: float, relief: bool) -> dict:
    """One bake in its own process: its ``NAME.bake.json`` timings, the process's CPU seconds
    (user + system, all threads, start-up included) and the files' size (MB)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    _potflat("bake", str(relaxed), "-o", str(out), "--px-per-mm", f"{px_per_mm:g}", *(["--relief"] if relief else []))
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    record = json.loads(next(out.glob("*.bake.json")).read_text())
    size = sum((out / f).stat().st_size for f in record["files"].values()) / 1e6
    return {"timings": {**record["timings"], "cpu": (after.ru_utime - before.ru_utime)
                        + (after.ru_stime - before.ru_stime)},
            "files": len(record["files"]), "mb": size, "relief": record.get("relief"), "image_px": record["image_px"]}


def measure(root: Path, *, vertices: float, repeat: int, px_per_mm: float, texture_size: int) -> dict:
    scan, info = make_scan(int(vertices), root / "scan", texture_size=texture_size)
    relaxed = root / "stages" / f"{scan.stem}.relaxed.ply"
    if not relaxed.is_file():
        print(f"rolling out and relaxing the {info['vertices']:,}-vertex amphora ...", flush=True)
        _potflat("rollout", str(scan), "-o", str(relaxed.parent))
        _potflat("relax", str(relaxed.parent / f"{scan.stem}.rollout.ply"), "-o", str(relaxed.parent))
    runs: dict[bool, list[dict]] = {False: [], True: []}
    for k in range(repeat + 1):  # the first pair compiles and caches the kernels
        for relief in (False, True):
            out = root / f"bake-{'relief' if relief else 'plain'}-{k}"
            result = _bake(relaxed, out, px_per_mm, relief)
            if k:
                runs[relief].append(result)
            print(f"  {'with' if relief else 'without'} relief: {result['timings']['total']:.1f} s, "
                  f"CPU {result['timings']['cpu']:.1f} s", flush=True)
    return {"info": info, "runs": runs}


def _median(runs: list[dict], step: str) -> float:
    return statistics.median(r["timings"].get(step, 0.0) for r in runs)


def table(m: dict, *, command: str, px_per_mm: float, repeat: int) -> str:
    info, runs = m["info"], m["runs"]
    relief = runs[True][0]["relief"]
    w, h = runs[False][0]["image_px"]
    lines = [f"`{command}` ({os.cpu_count()} cores, {platform.machine()}, Python {platform.python_version()}): "
             f"the {info['vertices']:,}-vertex amphora of the scale benchmark, relaxed, baked at {px_per_mm:g} px/mm "
             f"({w} x {h} px), medians of {repeat} bakes of each kind, alternately, each in its own process: "
             f"wall seconds of the bake stage and its steps (its JSON's timings) and CPU seconds of the process "
             f"(user + system, all threads, start-up included).", "",
             "| bake | " + " | ".join(f"{s} s" for s in STEPS) + " | stage s | CPU s | files | MB written |",
             "|---|" + "---:|" * (len(STEPS) + 4)]
    for flag, label in ((False, "default"), (True, "with --relief")):
        cells = [f"{_median(runs[flag], s):.2f}" for s in STEPS]
        lines.append(f"| {label} | " + " | ".join(cells) + f" | **{_median(runs[flag], 'total'):.2f}** | "
                     f"**{_median(runs[flag], 'cpu'):.1f}** | {runs[flag][0]['files']} | "
                     f"{statistics.median(r['mb'] for r in runs[flag]):.0f} |")
    wall, cpu = (_median(runs[True], k) / _median(runs[False], k) - 1.0 for k in ("total", "cpu"))
    lines += ["", f"The relief adds {100 * wall:.0f}% to the bake stage's time and {100 * cpu:.0f}% to its CPU time "
              f"(goal at most {100 * GOAL_ADDED:.0f}%: {'met' if max(wall, cpu) <= GOAL_ADDED else 'NOT met'}); "
              f"smoothing {relief['smoothing_mm']:.3g} mm, mesh spacing {relief['mesh_spacing_mm']:.2f} mm, "
              f"{len(relief['light_azimuth_deg'])} raking lights."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vertices", type=float, default=1e6)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--px-per-mm", type=float, default=4.0)
    ap.add_argument("--texture-size", type=int, default=8192)
    ap.add_argument("--keep", type=Path, help="folder for the scan and outputs (kept)")
    ap.add_argument("--write", action="store_true", help="update the table in docs/performance.md")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="potflat-relief-") as tmp:
        root = args.keep or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        m = measure(root, vertices=args.vertices, repeat=args.repeat, px_per_mm=args.px_per_mm,
                    texture_size=args.texture_size)
    command = command_line("bench_relief.py", argv if argv is not None else sys.argv[1:])
    publish("bench_relief", table(m, command=command, px_per_mm=args.px_per_mm, repeat=args.repeat), args.write)


if __name__ == "__main__":
    main()
