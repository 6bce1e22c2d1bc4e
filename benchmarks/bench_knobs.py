"""The speed knobs of ``potflat run`` at one size, each beside a trimesh load: what each buys
in time and what it costs in accuracy.

One synthetic painted amphora (:func:`bench_scale.make_scan`, default 1M vertices, 8192^2
atlas) goes through ``potflat run`` with the default options and with each knob that trades
accuracy for time (``--supersample 2``: fewer sub-samples per pixel than the automatic choice;
``--maps none``: no distortion maps; ``--preset preview``: the relaxation of a coarse copy
only; all three together). The runs go in turn, round after round (``--rounds``), each round
beside a trimesh load of the same OBJ (the yardstick of ``bench_scale.py``); the table gives
medians. Accuracy is read from each run's ``NAME.bake.json``: the
painted zone's length error (median and 95th percentile, %, the figures the archaeologist
reads), the whole surface's edge-length RMS, and, for the knobs that leave the layout as it
is, how far the painting ``NAME.png`` is from the default's (8-bit levels over the pixels
both cover).

Reproduce (block ``bench_knobs`` of docs/performance.md)::

    python benchmarks/bench_knobs.py --write

Options: ``--vertices`` (default 1e6), ``--rounds`` (default 2), ``--px-per-mm`` (default 4),
``--keep DIR`` (keep the scan and the outputs; the scan is reused by a later run, and by
``bench_scale.py --keep DIR``).
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _docs import command_line, machine, publish  # noqa: E402
from _run import warm_kernels  # noqa: E402
from bench_scale import add_scan_options, child_load, make_scan, run_benchmark  # noqa: E402

BLOCK = "bench_knobs"
#: (name, relax preset, other ``potflat run`` options), the default first (the reference of the
#: image differences).
KNOBS = (
    ("default", "standard", ()),
    ("--supersample 2", "standard", ("--supersample", "2")),
    ("--maps none", "standard", ("--maps", "none")),
    ("--preset preview", "preview", ()),
    ("all three", "preview", ("--supersample", "2", "--maps", "none")),
)
#: Knobs that leave the relaxed layout as the default's (their image is compared pixel by pixel).
SAME_LAYOUT = {"default", "--supersample 2", "--maps none"}


def painting_difference(a: Path, b: Path) -> tuple[float, float] | None:
    """Mean and 99th percentile of ``|a - b|`` (8-bit RGB levels) over the pixels both RGBA
    images cover; None when their sizes differ."""
    from PIL import Image

    x, y = (np.asarray(Image.open(p).convert("RGBA"), dtype=np.int16) for p in (a, b))
    if x.shape != y.shape:
        return None
    both = (x[..., 3] > 0) & (y[..., 3] > 0)
    d = np.abs(x[..., :3] - y[..., :3])[both]
    return float(d.mean()), float(np.percentile(d, 99))


def accuracy(out: Path, name: str) -> dict:
    """The painted zone's length error (%) and the whole surface's edge RMS from ``NAME.bake.json``."""
    bake = json.loads((out / f"{name}.bake.json").read_text())
    zone = bake.get("important_zone") or {}
    return {"zone_median_pct": zone.get("length_error_median_pct"), "zone_p95_pct": zone.get("length_error_p95_pct"),
            "edge_rms": bake["distortion"]["edge_rms"], "supersample": bake.get("supersample"),
            "image": tuple(bake["image_px"])}


def measure(scan: Path, root: Path, *, rounds: int, px_per_mm: float) -> tuple[list[float], dict[str, dict]]:
    """Every knob's runs (in turn, round after round) and the trimesh loads of each round."""
    loads, runs = [], {name: [] for name, _, _ in KNOBS}
    figures: dict[str, dict] = {}
    for rnd in range(rounds):
        loads.append(child_load(scan)["load_s"])
        print(f"round {rnd + 1}: trimesh load {loads[-1]:.1f} s", flush=True)
        for name, preset, extra in KNOBS:
            out = root / name.strip("-").replace(" ", "_")
            res = run_benchmark(scan, out, preset=preset, px_per_mm=px_per_mm, extra=extra)
            runs[name].append(res)
            figures[name] = {**accuracy(out, scan.stem), "png": out / f"{scan.stem}.png"}
            print(f"  {name}: {res['total_wall_s']:.1f} s", flush=True)
    return loads, {name: {"runs": runs[name], **figures[name]} for name, _, _ in KNOBS}


def table(loads: list[float], knobs: dict[str, dict], *, command: str, info: dict, px_per_mm: float) -> str:
    """The block of docs/performance.md: the command, the scan, the table."""
    load = statistics.median(loads)
    lines = [f"`{command}` ({machine()}): {info['vertices']:,} vertices, {info['faces']:,} faces, "
             f"{info['obj_mb']:.0f} MB OBJ, {info['texture']} atlas, {px_per_mm:g} px/mm; medians of "
             f"{len(loads)} rounds; trimesh load {load:.1f} s.", "",
             "| options | whole run s | rollout s | relax s | bake s | run / trimesh | supersample "
             "| zone length error % | edge RMS | painting vs default |",
             "|---|---:|---:|---:|---:|---:|---:|---|---:|---|"]
    default_png = knobs["default"]["png"]
    for name, k in knobs.items():
        med = lambda f: statistics.median(f(r) for r in k["runs"])  # noqa: E731
        stage = {s: med(lambda r, s=s: next(x["wall_s"] for x in r["rows"] if x["stage"] == s))
                 for s in ("rollout", "relax", "bake")}
        total = med(lambda r: r["total_wall_s"])
        diff = painting_difference(default_png, k["png"]) if name in SAME_LAYOUT else None
        zone = ("-" if k["zone_median_pct"] is None
                else f"{k['zone_median_pct']:.2f} / {k['zone_p95_pct']:.2f}")
        lines.append(f"| `{name}` | **{total:.1f}** | {stage['rollout']:.1f} | {stage['relax']:.1f} | "
                     f"{stage['bake']:.1f} | {total / load:.1f} | {k['supersample']} | {zone} | "
                     f"{k['edge_rms']:.4f} | {'-' if diff is None else f'{diff[0]:.2f} / {diff[1]:.0f}'} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vertices", type=float, default=1e6)
    ap.add_argument("--rounds", type=int, default=2)
    add_scan_options(ap)
    args = ap.parse_args(argv)

    warm_kernels()
    with tempfile.TemporaryDirectory(prefix="potflat-knobs-") as tmp:
        root = (args.keep / f"{args.vertices:.3g}") if args.keep else Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        scan, info = make_scan(int(args.vertices), root / "scan", texture_size=args.texture_size)
        loads, knobs = measure(scan, root / "knobs", rounds=args.rounds, px_per_mm=args.px_per_mm)
        command = command_line("bench_knobs.py", argv if argv is not None else sys.argv[1:])
        section = table(loads, knobs, command=command, info=info, px_per_mm=args.px_per_mm)
    publish(BLOCK, section, args.write)


if __name__ == "__main__":
    from potflat_cli._process import command_settings

    with command_settings():  # as the potflat command runs: OpenMP's passive wait, the heap tuning
        main()
