"""The batch report: ``index.html`` beside ``summary.csv``, one card per scan.

Each card shows the painting's thumbnail and the stress map's, the figures (distortion in the
painted zone, or of the whole surface where the relax stage reports no zone; time; folded
triangles), the status (and the error of a failed scan) and links to every file of the scan's
folder. The cards sort by name, status, distortion, time or folds. The page is one file with
its style, script and thumbnails inside (JPEG data URIs): it needs no network and no server;
the links are relative, so the page works where the batch output folder is.
"""
from __future__ import annotations

import base64
import html
import io
import json
import os
import shlex
from datetime import datetime, timezone
from pathlib import Path
from urllib.parse import quote

from potflat import __version__
from potflat.files.batch.manifest import MANIFEST
from potflat.io.atomic import write_bytes_atomic
from potflat.mesh.distortion import distortion_words, painted_zone_distortion

#: File name of the report in the batch output folder.
REPORT_NAME = "index.html"
#: Longest side of the thumbnails, pixels.
THUMB_PX = 360
#: JPEG quality of the thumbnails.
THUMB_QUALITY = 82

_STYLE = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:1.5rem;background:#f4f2ee;color:#222}
h1{font-size:1.4rem;margin:0 0 .3rem}
.meta{color:#555;margin-bottom:1rem}
.controls{margin-bottom:1rem}
#cards{display:grid;grid-template-columns:repeat(auto-fill,minmax(360px,1fr));gap:1rem}
.card{background:#fff;border-radius:6px;padding:.8rem;box-shadow:0 1px 3px rgba(0,0,0,.15)}
.card h2{font-size:1.05rem;margin:0 0 .4rem;word-break:break-all}
.status{display:inline-block;padding:0 .5em;border-radius:3px;color:#fff;font-size:.85rem}
.done{background:#2e7d32}.skipped{background:#607d8b}.failed{background:#c62828}.interrupted{background:#ef6c00}
.cancelled{background:#8d6e63}
.thumbs{display:flex;gap:.4rem;margin:.5rem 0}
.thumbs figure{margin:0;flex:1;text-align:center;font-size:.75rem;color:#666}
.thumbs img{max-width:100%;max-height:180px;background:repeating-conic-gradient(#eee 0 25%,#fff 0 50%) 0 0/12px 12px}
dl{display:grid;grid-template-columns:auto 1fr;gap:.1rem .6rem;margin:.4rem 0;font-size:.9rem}
dt{color:#666}dd{margin:0}
.error{color:#c62828;font-size:.85rem;word-break:break-word}
details{font-size:.85rem}
details a{display:block;word-break:break-all}
"""

_SCRIPT = """
function sortCards(key){
  const box=document.getElementById('cards');
  const cards=[...box.children];
  const num=k=>(c=>{const v=parseFloat(c.dataset[k]);return isNaN(v)?Infinity:v;});
  const by={name:c=>c.dataset.name,status:c=>c.dataset.rank+c.dataset.name,
            distortion:num('distortion'),time:num('seconds'),flipped:num('flipped')}[key];
  cards.sort((a,b)=>{const x=by(a),y=by(b);
    if(key==='distortion'||key==='time'||key==='flipped'){return (x===Infinity)-(y===Infinity)||y-x;}
    return x<y?-1:x>y?1:0;});
  cards.forEach(c=>box.appendChild(c));
}
document.getElementById('sort').addEventListener('change',e=>sortCards(e.target.value));
// served by 'potflat view' (which answers at data-view): each card links to its scan's view
if(location.protocol!=='file:'){document.querySelectorAll('a.view[data-view]').forEach(a=>
  fetch(a.dataset.view,{method:'HEAD'}).then(r=>{if(r.ok){a.href=a.dataset.view;a.hidden=false;}}).catch(()=>{}));}
"""

_STATUS_RANK = {"failed": "0", "interrupted": "1", "cancelled": "2", "done": "3", "skipped": "4"}


def _thumbnail(path: Path) -> str | None:
    """A JPEG data URI of the image at ``path`` on white, at most :data:`THUMB_PX`; None when unreadable."""
    from PIL import Image

    try:
        with Image.open(path) as img:
            img.draft("RGB", (THUMB_PX, THUMB_PX))
            img = img.convert("RGBA")
            img.thumbnail((THUMB_PX, THUMB_PX), Image.Resampling.LANCZOS)
    except (OSError, ValueError, Image.DecompressionBombError):
        return None
    flat = Image.new("RGB", img.size, (255, 255, 255))
    flat.paste(img, mask=img.getchannel("A"))
    buf = io.BytesIO()
    flat.save(buf, format="JPEG", quality=THUMB_QUALITY, optimize=True)
    return "data:image/jpeg;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _href(target: Path, base: Path) -> str:
    rel = os.path.relpath(target, base)
    return "/".join(quote(part) for part in Path(rel).parts)


def _relax_summary(folder: Path, name: str) -> dict:
    try:
        data = json.loads((folder / f"{name}.relaxed.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}  # a sidecar of another shape says nothing


def _card(report, base: Path) -> str:
    folder = Path(report.output)
    name = report.name
    relax = _relax_summary(folder, name)
    figures, where = painted_zone_distortion(relax) if relax else (dict(report.figures or {}), "whole surface")
    edge = figures.get("edge_rms")
    flipped = figures.get("flipped")
    files = sorted(p for p in folder.iterdir() if p.is_file() and not p.name.endswith(".part")) \
        if folder.is_dir() else []
    thumbs = []
    for label, file in (("painting", folder / f"{name}.png"), ("stress", folder / f"{name}.stress.png")):
        # potflat writes no links: one in an output folder was put there, and the report (often
        # shared) would carry a picture of whatever it points at
        uri = _thumbnail(file) if file.is_file() and not file.is_symlink() else None
        if uri is not None:
            thumbs.append(f'<figure><a href="{_href(file, base)}"><img src="{uri}" alt="{html.escape(label)} of '
                          f'{html.escape(name)}"></a><figcaption>{html.escape(label)}</figcaption></figure>')
    seconds, when = report.seconds, ""
    if report.status == "skipped":  # made by an earlier run: its time is in the manifest
        try:
            seconds, when = float(json.loads((folder / MANIFEST).read_text())["seconds"]), " (earlier run)"
        except (OSError, ValueError, KeyError, TypeError):
            seconds = 0.0
    rows = [("status", f'<span class="status {html.escape(report.status)}">{html.escape(report.status)}</span>'),
            (f"distortion ({where})", html.escape(distortion_words(figures)) if figures else "-"),
            ("time", f"{seconds:.1f} s{when}" if seconds else "-"),
            ("folded triangles", "-" if flipped is None else str(flipped))]
    if (folder / f"{name}.bake.json").is_file():  # the view: a link when served by 'potflat view', else its command
        rows.append(("view", f'<a class="view" hidden data-view="_potflat/view/{quote(name)}">open the view</a> '
                             f'<code>potflat view {html.escape(shlex.quote(str(base)))} {html.escape(shlex.quote(name))}</code>'))
    plate = folder / f"{name}.plate.pdf"
    if plate.is_file():
        rows.append(("plate", f'<a href="{_href(plate, base)}">PDF</a>, '
                              f'<a href="{_href(folder / f"{name}.plate.svg", base)}">SVG</a>'))
    dl = "".join(f"<dt>{k}</dt><dd>{v}</dd>" for k, v in rows)
    error = f'<p class="error">{html.escape(report.error)}</p>' if report.error else ""
    links = "".join(f'<a href="{_href(p, base)}">{html.escape(p.name)}</a>' for p in files)
    attrs = {"name": name.lower(), "status": report.status, "rank": _STATUS_RANK.get(report.status, "9"),
             "distortion": "" if edge is None else f"{edge:.6g}", "seconds": f"{seconds:.3f}",
             "flipped": "" if flipped is None else str(flipped)}
    data = " ".join(f'data-{k}="{html.escape(v)}"' for k, v in attrs.items())
    return (f'<article class="card" {data}><h2>{html.escape(name)}</h2>'
            f'<div class="thumbs">{"".join(thumbs)}</div><dl>{dl}</dl>{error}'
            f'<details><summary>{len(files)} files</summary>{links}</details></article>')


def write_report(summary) -> Path:
    """Write ``index.html`` into the batch output folder, atomically.

    Parameters
    ----------
    summary : BatchSummary
        The batch's outcome (:func:`potflat.files.batch.run_batch`).

    Returns
    -------
    Path
    """

    base = Path(summary.output)
    counts = ", ".join(f"{n} {status}" for status, n in summary.counts.items() if n)
    when = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    cards = "\n".join(_card(r, base) for r in summary.reports)
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width,initial-scale=1">
<title>potflat batch: {html.escape(Path(summary.batch).name)}</title>
<style>{_STYLE}</style></head>
<body>
<h1>potflat batch: {html.escape(Path(summary.batch).name)}</h1>
<p class="meta">{len(summary.reports)} scans: {html.escape(counts)}; {summary.seconds:.1f} s; potflat {__version__};
{when}. Figures: <a href="summary.csv">summary.csv</a>, <a href="summary.json">summary.json</a>.</p>
<p class="controls"><label>Sort by <select id="sort">
<option value="name">name</option><option value="status">status (failed first)</option>
<option value="distortion">distortion (worst first)</option><option value="time">time (longest first)</option>
<option value="flipped">folded triangles (most first)</option></select></label></p>
<main id="cards">
{cards}
</main>
<script>{_SCRIPT}</script>
</body></html>
"""
    return write_bytes_atomic(base / REPORT_NAME, page.encode("utf-8"))
