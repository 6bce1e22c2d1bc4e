"""The batch report index.html (potflat.files.batch.report): cards, links, thumbnails, sorting, in a real browser."""
from __future__ import annotations

import base64
import functools
import html
import io
import json
import re
import shutil
import subprocess
import threading
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import unquote

import pytest
from PIL import Image

from potflat.files.batch.config import load_batch

from potflat.files.batch.execution import run_batch
from potflat.mesh.distortion import painted_zone_distortion
from potflat.files.batch.report import REPORT_NAME

#: Browsers tried, in order (Debian's package is chromium; .ci/run installs it when missing).
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome")


@pytest.fixture(scope="module")
def batch_out(tmp_path_factory):
    """Two small vessels (one with the plate) and a broken file, run as a batch."""
    from potflat_synthetic.vessels import make_vessel, write_obj

    root = tmp_path_factory.mktemp("report")
    write_obj(make_vessel("cup", n_vertices=1200, texture_size=128, seed=3), root / "scans" / "cup.obj")
    write_obj(make_vessel("amphora", n_vertices=1200, texture_size=128, seed=1), root / "scans" / "amph ora.obj")
    (root / "scans" / "broken.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99\n")
    (root / "batch.yaml").write_text(
        "output: results/\n"
        "defaults: {preset: preview, px_per_mm: 1}\n"
        "scans:\n"
        "  - path: scans/cup.obj\n"
        "    plate: true\n"
        "  - path: scans/amph ora.obj\n"
        "  - path: scans/broken.ply\n")
    summary = run_batch(load_batch(root / "batch.yaml"), workers=1)
    assert summary.counts["done"] == 2 and summary.counts["failed"] == 1
    return root / "results"


def _cards(page: str) -> list[str]:
    return re.findall(r'<article class="card".*?</article>', page, re.S)


def test_report_has_a_card_per_scan_with_figures_status_and_files(batch_out):
    page = (batch_out / REPORT_NAME).read_text()
    cards = _cards(page)
    assert len(cards) == 3
    by_name = {html.unescape(re.search(r"<h2>(.*?)</h2>", c)[1]): c for c in cards}
    assert set(by_name) == {"cup", "amph ora", "broken"}
    cup = by_name["cup"]
    assert 'data-status="done"' in cup and "lengths off by" in cup and "folded triangles" in cup
    assert "cup.plate.pdf" in cup and "cup.stress.png" in cup and "cup.relaxed.json" in cup
    assert cup.count("<img ") == 2  # painting and stress map
    broken = by_name["broken"]
    assert 'data-status="failed"' in broken and 'class="error"' in broken and "error.log" in broken
    # figures agree with the relax stage's JSON
    relaxed = json.loads((batch_out / "cup" / "cup.relaxed.json").read_text())
    edge = float(re.search(r'data-distortion="([^"]+)"', cup)[1])
    assert edge == pytest.approx(painted_zone_distortion(relaxed)[0]["edge_rms"], rel=1e-5)
    assert "summary.csv" in page and "http" not in re.sub(r'"data:[^"]*"', "", page).replace(
        'name="viewport"', "")  # no network


def test_report_links_resolve_and_thumbnails_decode(batch_out):
    page = (batch_out / REPORT_NAME).read_text()
    hrefs = [html.unescape(h) for h in re.findall(r'href="([^"]+)"', page)]
    assert len(hrefs) > 20
    for href in hrefs:
        assert (batch_out / unquote(href)).is_file(), href
    srcs = re.findall(r'src="([^"]+)"', page)
    assert len(srcs) == 4
    for src in srcs:
        assert src.startswith("data:image/jpeg;base64,")
        img = Image.open(io.BytesIO(base64.b64decode(src.split(",", 1)[1])))
        assert max(img.size) <= 360 and min(img.size) > 10


def test_report_shows_no_thumbnail_of_a_planted_link(batch_out, tmp_path):
    from types import SimpleNamespace

    from potflat.files.batch.report import _card

    folder = tmp_path / "cup"
    shutil.copytree(batch_out / "cup", folder)
    Image.new("RGB", (40, 30), (200, 0, 0)).save(tmp_path / "private.png")
    (folder / "cup.png").unlink()
    (folder / "cup.png").symlink_to(tmp_path / "private.png")
    report = SimpleNamespace(output=str(folder), name="cup", figures={}, status="done", seconds=1.0, error=None)
    card = _card(report, tmp_path)
    assert card.count("<img ") == 1 and 'alt="stress of cup"' in card  # the stress map only


def _browser() -> str | None:
    return next((path for name in BROWSERS if (path := shutil.which(name))), None)


HARNESS = """<!DOCTYPE html><html><body><script>
const f = document.createElement('iframe'); f.src = 'index.html'; f.style.width = '1200px';
f.onload = async () => {
  const d = f.contentDocument;
  const imgs = [...d.images];
  const badImages = imgs.filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.alt);
  const links = [...d.querySelectorAll('a[href]')].map(a => a.href);
  const badLinks = [];
  for (const h of links) { const r = await fetch(h, {method: 'HEAD'}); if (!r.ok) badLinks.push(h + ' ' + r.status); }
  const order = key => { const s = d.getElementById('sort'); s.value = key; s.dispatchEvent(new Event('change'));
                         return [...d.querySelectorAll('.card')].map(c => c.querySelector('h2').textContent); };
  const result = {images: imgs.length, badImages, links: links.length, badLinks,
                  byName: order('name'), byStatus: order('status'), byDistortion: order('distortion'),
                  distortions: [...d.querySelectorAll('.card')].map(c => c.dataset.distortion)};
  const out = document.createElement('pre'); out.id = 'result'; out.textContent = JSON.stringify(result);
  document.body.appendChild(out);
};
document.body.appendChild(f);
</script></body></html>
"""


def test_report_in_a_headless_browser(batch_out, tmp_path):
    """Chromium loads the report over HTTP: every image loads, every link answers 200, sorting works."""
    browser = _browser()
    if browser is None:
        pytest.skip("no Chromium/Chrome on this machine (.ci/run installs Debian's chromium; "
                    "apt-get install chromium)")
    served = tmp_path / "served"
    shutil.copytree(batch_out, served)
    (served / "__check.html").write_text(HARNESS)
    handler = functools.partial(_QuietHandler, directory=str(served))
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        url = f"http://127.0.0.1:{server.server_address[1]}/__check.html"
        run = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                              f"--user-data-dir={tmp_path / 'profile'}", "--virtual-time-budget=20000",
                              "--dump-dom", url], capture_output=True, text=True, timeout=180)
    finally:
        server.shutdown()
        server.server_close()
    found = re.search(r'<pre id="result">(.*?)</pre>', run.stdout, re.S)
    assert found, f"the page did not finish: {run.stderr[-2000:]}"
    result = json.loads(html.unescape(found[1]))
    assert result["images"] == 4 and result["badImages"] == []
    assert result["links"] > 20 and result["badLinks"] == []
    assert result["byName"] == ["amph ora", "broken", "cup"]
    assert result["byStatus"][0] == "broken"
    worst = [float(x) for x in result["distortions"] if x]
    assert worst == sorted(worst, reverse=True) and result["byDistortion"][-1] == "broken"


class _QuietHandler(SimpleHTTPRequestHandler):
    def log_message(self, *args):  # keep the test output clean
        pass
