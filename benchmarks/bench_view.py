"""``potflat view``: open to first render and pick accuracy, on the bundled amphora and on a
3M-vertex synthetic amphora.

For each scan, ``potflat run --position-map`` makes the run once (kept with ``--keep DIR``).
Then, ``--repeat`` times: ``python -m potflat_cli view OUT --no-browser`` starts in a child
process (Python's start-up, reading the run, the display mesh: everything a user waits for),
a headless Chromium (Debian's, software WebGL) opens the address it prints, and the time from
the command's start to the page's first render of both views is taken (the page's own share,
from its navigation, is given apart), and to the whole scan drawn with its own texture (the
server reads the scan file after the first render and sends its display mesh). On the last
page opened: the accuracy of the links
(``--picks`` points each way): image to vessel (the page's marked point against the bake's
position map at that pixel, mm) and vessel to image (a ray through a vertex's screen position,
from outside at ``--distance`` mm, against that vertex's flat position, pixels), and the
median time of a frame while the vessel turns (software rendering on the CPU: a laptop's GPU
draws far faster).

Goals: open to first render at most 3 s for the sample and 10 s at 3M vertices; picks within
1 mm (image to vessel) and 2 px at 4 px/mm (vessel to image) at 3M vertices.

Reproduce (the table in docs/performance.md, section "Looking at a run")::

    python benchmarks/bench_view.py --write
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _docs import command_line, publish  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "samples" / "data" / "amphora.obj"
GOALS_S = {"sample": 3.0, "large": 10.0}
CHROMIUM_ARGS = ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-gpu-sandbox",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run",
                 "--disable-dev-shm-usage"]


def make_run(scan: Path, out: Path, px_per_mm: float) -> float:
    """``potflat run SCAN -o OUT --position-map`` unless OUT holds it; the seconds it took."""
    if (out / "amphora.bake.json").is_file() and (out / "amphora.position.tif").is_file():
        return float("nan")
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "potflat_cli", "run", str(scan), "-o", str(out), "--position-map",
                    "--px-per-mm", str(px_per_mm), "-q"], check=True)
    return time.perf_counter() - t


def open_once(browser, out: Path) -> tuple[float, float, float, object, subprocess.Popen]:
    """Start ``potflat view`` and open its page: seconds to first render (from the command's
    start, and the page's own share), to the whole scan drawn (from the command's start), and
    the open page with its server process."""
    t = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "potflat_cli", "view", str(out), "--no-browser"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    url = proc.stdout.readline().split()[2]
    page = browser.new_page(viewport={"width": 1400, "height": 800})
    page.goto(url)
    page.wait_for_function("window.potflat && (window.potflat.ready || window.potflat.error)", timeout=300_000)
    total = time.perf_counter() - t
    if page.evaluate("potflat.error"):
        raise RuntimeError(page.evaluate("potflat.error"))
    page.wait_for_function("potflat.timings.scan || (potflat.scan && !potflat.scan.mesh)", timeout=600_000)
    if not page.evaluate("potflat.scan.mesh"):
        raise RuntimeError(page.evaluate("potflat.scan.message"))
    whole = time.perf_counter() - t
    return total, page.evaluate("potflat.firstRenderMs") / 1000.0, whole, page, proc


def stop(page, proc) -> None:
    page.close()
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=60)


def accuracy(page, out: Path, picks: int, distance_mm: float, seed: int = 0) -> dict:
    """The links' errors: image to vessel (mm) and vessel to image (px), medians and maxima."""
    import tifffile

    from potflat.view.scene import Scene

    scene = Scene(out, "amphora")
    position = tifffile.imread(out / "amphora.position.tif")
    rng = np.random.default_rng(seed)
    mm = scene.grid.mm_per_unit
    to_3d, to_flat = [], []
    while len(to_3d) < picks:
        x, y = rng.uniform(0, scene.grid.width), rng.uniform(0, scene.grid.height)
        p = position[int(y), int(x)].astype(float)
        if not np.isfinite(p).all():
            continue
        hit = page.evaluate(f"potflat.flatClick([{x}, {y}]).then(() => potflat.marker3d)")
        to_3d.append(float(np.linalg.norm(np.asarray(hit) - p) * mm))
    axis = scene.rollout["axis"]
    a, c = np.asarray(axis["direction"]), np.asarray(axis["point"])
    V = scene.flat.mesh.vertices
    tries = 0
    while len(to_flat) < picks and tries < 20 * picks:
        tries += 1
        i = int(rng.integers(len(V)))
        d = V[i] - c
        d = d - (d @ a) * a
        d /= np.linalg.norm(d)
        page.evaluate(f"potflat.lookFrom({V[i].tolist()}, {d.tolist()}, {distance_mm / mm})")
        s = page.evaluate(f"potflat.project({V[i].tolist()})")
        hit = page.evaluate(f"potflat.vesselClick({s['x']}, {s['y']})")
        if hit is None or hit.get("outside") or np.linalg.norm(np.asarray(hit["point"]) - V[i]) * mm > 1.0:
            continue  # hidden from outside there (the foot, a fold of the scan)
        to_flat.append(float(np.linalg.norm(np.asarray(hit["pixel"]) - scene.pixels[i])))
    return {"to_3d_mm": (statistics.median(to_3d), max(to_3d)),
            "to_flat_px": (statistics.median(to_flat), max(to_flat)) if to_flat else (float("nan"),) * 2,
            "n": (len(to_3d), len(to_flat)), "faces": len(scene.flat.mesh.faces), "vertices": len(V),
            "display_faces": len(scene.display.faces), "image_px": (scene.grid.width, scene.grid.height),
            "px_per_mm": scene.grid.px_per_mm}


def main(argv: list[str] | None = None) -> None:
    from playwright.sync_api import sync_playwright

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--vertices", type=float, default=3e6, help="vertices of the large scan (0: none)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--picks", type=int, default=40)
    parser.add_argument("--distance", type=float, default=600.0, help="camera distance for the picks, mm")
    parser.add_argument("--px-per-mm", type=float, default=4.0)
    parser.add_argument("--texture-size", type=int, default=4096)
    parser.add_argument("--keep", type=Path, default=None)
    parser.add_argument("--write", action="store_true")
    args = parser.parse_args(argv)
    work = args.keep or Path(tempfile.mkdtemp(prefix="bench-view-"))
    work.mkdir(parents=True, exist_ok=True)
    from bench_scale import make_scan

    scans = [("sample", SAMPLE, work / "sample")]
    if args.vertices:
        large = work / f"scan-{int(args.vertices)}"
        large.mkdir(exist_ok=True)
        scans.append(("large", make_scan(int(args.vertices), large, texture_size=args.texture_size)[0], work / "large"))
    rows = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=shutil.which("chromium"), args=CHROMIUM_ARGS)
        for kind, scan, out in scans:
            run_s = make_run(scan, out, args.px_per_mm)
            opens, pages = [], []
            for _ in range(args.repeat):
                total, own, whole, page, proc = open_once(browser, out)
                opens.append((total, own, whole))
                if _ < args.repeat - 1:
                    stop(page, proc)
            acc = accuracy(page, out, args.picks, args.distance)
            frame_ms = page.evaluate("potflat.frameTimes(24)")
            phases = page.evaluate("potflat.timings")  # ms from the page's start: module, scene, mesh, ...
            scan_faces = page.evaluate("potflat.scan.mesh.faces")
            stop(page, proc)
            rows.append({"kind": kind, "run_s": run_s, "open_s": statistics.median(o[0] for o in opens),
                         "page_s": statistics.median(o[1] for o in opens), "whole_s": statistics.median(o[2] for o in opens),
                         "frame_ms": frame_ms, "page_phases_ms": phases, "scan_faces": scan_faces, **acc})
            print(json.dumps(rows[-1]), flush=True)
        browser.close()
    if args.keep is None:
        shutil.rmtree(work, ignore_errors=True)
    load = os.getloadavg()[0]
    lines = [f"`potflat view` on a finished run: from the command's start to the page's first render of both views "
             f"(median of {args.repeat}; the page's own share from its navigation) and to the whole scan drawn with "
             "its own texture, on this machine's 2 cores with Debian's Chromium rendering WebGL in software (load "
             f"average {load:.1f} at the end: other jobs shared the cores); the links' accuracy over "
             f"{args.picks} random points each way (vessel to image: a ray through a vertex seen from outside at "
             f"{args.distance:g} mm); a frame's time while the vessel turns (software rendering).", "",
             "| scan | vertices | faces drawn: unrolled / scan | image px | open to first render | page's share | goal "
             "| whole scan drawn | image -> vessel, mm (median / max) | vessel -> image, px (median / max) | frame |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {'bundled amphora' if r['kind'] == 'sample' else 'synthetic amphora'} | {r['vertices']:,} | "
                     f"{r['display_faces']:,} / {r['scan_faces']:,} | {r['image_px'][0]} x {r['image_px'][1]} | "
                     f"{r['open_s']:.2f} s | {r['page_s']:.2f} s | {GOALS_S[r['kind']]:g} s | {r['whole_s']:.1f} s | "
                     f"{r['to_3d_mm'][0]:.3f} / {r['to_3d_mm'][1]:.3f} | "
                     f"{r['to_flat_px'][0]:.3f} / {r['to_flat_px'][1]:.3f} | {r['frame_ms']:.0f} ms |")
    lines += ["", f"Reproduce: `{command_line('bench_view.py', sys.argv[1:] if argv is None else argv)}`", ""]
    publish("bench_view", "\n".join(lines), args.write)


if __name__ == "__main__":
    main()
