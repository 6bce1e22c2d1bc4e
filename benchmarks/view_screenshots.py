"""The guide's screenshots of ``potflat view``: the bundled amphora and the dragon jar (a real
photogrammetry scan), each with a measure across the painting and the readout of a point.

The real scans are in ``../shared/data/real`` beside the repository. For each scan, ``potflat
run SCAN -o OUT --position-map`` (kept with ``--keep DIR``), then ``potflat view OUT
--no-browser`` and a headless Chromium (Debian's, software WebGL) at 1400 x 760: the whole
scan drawn, two clicks of the measure on the image and a click between them; the page is
saved as ``docs/img/view-NAME.png``.

Reproduce (the figures in docs/guide.md, section "Looking at a run")::

    python benchmarks/view_screenshots.py
"""
from __future__ import annotations

import argparse
import shutil
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_view import CHROMIUM_ARGS  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: Each scan, its name in docs/img, and where on its image (fractions of width and height) the
#: measure starts and ends and the point is clicked.
SHOTS = [
    (ROOT / "samples" / "data" / "amphora.obj", "amphora", ((0.36, 0.49), (0.63, 0.49), (0.50, 0.49))),
    (ROOT.parent / "shared" / "data" / "real" / "dragon-jar.glb", "dragon-jar",
     ((0.30, 0.46), (0.52, 0.46), (0.42, 0.50))),
]


def shoot(browser, scan: Path, out: Path, picks, png: Path) -> None:
    """Run ``scan`` into ``out`` (unless there) and save the page with its measure as ``png``."""
    name = scan.stem
    if not (out / f"{name}.bake.json").is_file():
        subprocess.run([sys.executable, "-m", "potflat_cli", "run", str(scan), "-o", str(out), "--position-map", "-q"],
                       check=True)
    proc = subprocess.Popen([sys.executable, "-m", "potflat_cli", "view", str(out), "--no-browser"],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        url = proc.stdout.readline().split()[2]
        page = browser.new_page(viewport={"width": 1400, "height": 760})
        page.goto(url)
        page.wait_for_function("window.potflat && (window.potflat.ready || window.potflat.error)", timeout=300_000)
        if page.evaluate("potflat.error"):
            raise RuntimeError(page.evaluate("potflat.error"))
        page.wait_for_function("potflat.timings.scan || (potflat.scan && !potflat.scan.mesh)", timeout=300_000)
        w, h = page.evaluate("[potflat.scene.width, potflat.scene.height]")
        a, b, c = ([fx * w, fy * h] for fx, fy in picks)
        page.evaluate(f"(async () => {{ potflat.setTool('measure'); await potflat.flatClick({a}); "
                      f"await potflat.flatClick({b}); potflat.setTool('look'); await potflat.flatClick({c}); }})()")
        page.wait_for_function("potflat.measure !== null && potflat.marker3d !== null")
        page.wait_for_timeout(500)
        page.screenshot(path=str(png))
        page.close()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=60)


def main(argv: list[str] | None = None) -> None:
    from playwright.sync_api import sync_playwright

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--keep", type=Path, default=None, help="keep the runs in this folder")
    args = parser.parse_args(argv)
    work = args.keep or Path(tempfile.mkdtemp(prefix="view-shots-"))
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=shutil.which("chromium"), args=CHROMIUM_ARGS)
        for scan, name, picks in SHOTS:
            png = ROOT / "docs" / "img" / f"view-{name}.png"
            shoot(browser, scan, work / name, picks, png)
            print(f"wrote {png}", flush=True)
        browser.close()
    if args.keep is None:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
