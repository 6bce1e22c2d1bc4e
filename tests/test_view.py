"""``potflat view``: the server's safety, the links between the views, the measure, the edits
and the rerun, checked in a real headless Chromium (Debian's, driven by Playwright) on the
amphora sample run once (with ``--relief``) for the whole module."""
from __future__ import annotations

import http.client
import io
import json
import shlex
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "data" / "amphora.obj"
#: Chromium's flags: software WebGL, no network of its own.
CHROMIUM_ARGS = ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--disable-gpu-sandbox",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run",
                 "--disable-dev-shm-usage"]
PX_PER_MM = 4.0
#: The relief's images of a run with ``--relief`` (default lights), in the layer switch's order.
RELIEF = ["relief", "raking-315", "raking-45", "curvature", "relief-overlay"]


def _run_sample(out: Path) -> Path:
    from potflat.files.pipeline import run_scan

    run_scan(SAMPLE, out, relax={"preset": "preview"},
             bake={"px_per_mm": PX_PER_MM, "position_map": True, "relief": True})
    return out


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    return _run_sample(tmp_path_factory.mktemp("view") / "out")


class _Served:
    def __init__(self, folder: Path):
        from potflat.view.server import serve

        self.server = serve(folder)
        self.thread = threading.Thread(target=self.server.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True)
        self.thread.start()
        self.server.runs.scene("amphora").warm()

    @property
    def scene(self):
        return self.server.runs.scene("amphora")

    def close(self):
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture(scope="module")
def served(run_dir):
    s = _Served(run_dir)
    yield s
    s.close()


@pytest.fixture(scope="module")
def browser():
    playwright = pytest.importorskip("playwright.sync_api", reason="pip install playwright (in the test extra)")
    exe = shutil.which("chromium") or shutil.which("chromium-browser")
    if exe is None:
        pytest.skip("no chromium on this machine (.ci/run installs Debian's chromium; apt-get install chromium)")
    with playwright.sync_playwright() as p:
        b = p.chromium.launch(executable_path=exe, args=CHROMIUM_ARGS)
        yield b
        b.close()


def _open(browser, served, errors=None):
    page = browser.new_page(viewport={"width": 1400, "height": 800})
    if errors is not None:
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(served.server.url("amphora"))
    page.wait_for_function("window.potflat && (window.potflat.ready || window.potflat.error)", timeout=60_000)
    assert page.evaluate("potflat.error") is None
    return page


@pytest.fixture(scope="module")
def page(browser, served):
    p = _open(browser, served)
    yield p
    p.close()


def _share_drawn(png: bytes) -> float:
    """Share of a screenshot's pixels that differ from the page's background (59, 59, 59)."""

    from PIL import Image

    a = np.asarray(Image.open(io.BytesIO(png)).convert("RGB")).astype(int)
    return float((np.abs(a - 59).sum(axis=2) > 12).mean())


def _outward(scene, point):
    axis = scene.rollout["axis"]
    d = np.asarray(point) - np.asarray(axis["point"])
    a = np.asarray(axis["direction"])
    d = d - (d @ a) * a
    return d / np.linalg.norm(d)


# ---------------------------------------------------------------------- in the browser
def test_page_loads_without_console_errors_and_both_views_render(browser, served):
    errors: list[str] = []
    page = _open(browser, served, errors)
    try:
        page.wait_for_timeout(300)
        assert errors == []
        assert _share_drawn(page.locator("#vessel").screenshot()) > 0.15   # the vessel, textured
        assert _share_drawn(page.locator("#flat").screenshot()) > 0.3     # the image's tiles
        assert page.evaluate("potflat.firstRenderMs") > 0
        layers = page.evaluate("[...document.querySelectorAll('#layer option')].map(o => o.value)")
        assert layers == ["painting", "stress", "area", "anisotropy", *RELIEF]
        page.select_option("#layer", "stress")
        page.wait_for_function("document.getElementById('legend').complete && "
                               "document.getElementById('legend').naturalWidth > 0")
        assert errors == []
    finally:
        page.close()


def test_the_layer_switch_shows_the_relief_images_with_their_legends(page):
    """Each relief image of a --relief run is a layer: the image shows it, the relief and the
    curvature with the legend band below their PNG, the raking light and the overlay with a
    line saying what they are."""
    from PIL import Image

    def flat_view():
        return np.asarray(Image.open(io.BytesIO(page.locator("#flat").screenshot())).convert("L"), float)

    shown = {}
    for layer in ["painting", *RELIEF]:
        page.select_option("#layer", layer)
        page.wait_for_function(f"potflat.layerShown === {json.dumps(layer)}")
        page.wait_for_timeout(300)
        shown[layer] = flat_view()
        legend = page.evaluate("(() => { const l = document.getElementById('legend'); return l.style.display === 'block' "
                               "? l.src : null; })()")
        label = page.text_content("#layerlabel")
        if layer in ("relief", "curvature"):
            page.wait_for_function("document.getElementById('legend').complete && "
                                   "document.getElementById('legend').naturalWidth > 0")
            assert legend and legend.split("?")[0].endswith(f"/legend/{layer}.png") and label == ""
        elif layer != "painting":
            assert legend is None and label, layer
    assert "raking light" in page.evaluate("potflat.scene.layers.find(l => l.name === 'raking-315').label")
    rows = min(a.shape[0] for a in shown.values())  # (a legend below the image takes some of its height)

    def differ(a, b):
        return np.abs(shown[a][:rows] - shown[b][:rows]).mean()

    for layer in RELIEF:  # each image differs from the painting and from the others
        assert differ(layer, "painting") > 2.0, layer
    assert differ("raking-315", "raking-45") > 1.0
    page.select_option("#layer", "painting")
    page.wait_for_function("potflat.layerShown === 'painting'")


def test_a_relief_layers_tiles_and_legend_are_its_pngs(served, run_dir):
    """The tiles of the relief layer are NAME.relief.png's pixels; its legend is the band below them."""
    from PIL import Image

    g = served.scene.grid
    top = served.server.runs.layer("amphora", "relief").top
    status, body = _get(served, f"/_potflat/api/amphora/dzi/relief_files/{top}/1_1.png")
    assert status == 200
    png = np.asarray(Image.open(run_dir / "amphora.relief.png").convert("RGBA"))
    tile = np.asarray(Image.open(io.BytesIO(body)).convert("RGBA"))
    assert np.array_equal(tile, png[512:1024, 512:1024])
    status, body = _get(served, "/_potflat/api/amphora/legend/curvature.png")
    legend = np.asarray(Image.open(io.BytesIO(body)).convert("RGBA"))
    curvature = np.asarray(Image.open(run_dir / "amphora.curvature.png").convert("RGBA"))
    assert status == 200 and np.array_equal(legend, curvature[g.height:])
    assert _get(served, "/_potflat/api/amphora/legend/raking-45.png")[0] == 404


def test_click_on_the_image_marks_the_position_maps_point_on_the_vessel(page, served, run_dir):
    import tifffile

    scene = served.scene
    position = tifffile.imread(run_dir / "amphora.position.tif")
    page.click("[data-tool=look]")
    for pixel in ([1500.5, 950.5], [2400.5, 700.5]):
        assert np.isfinite(position[int(pixel[1]), int(pixel[0])]).all()
        c = page.evaluate(f"potflat.imageToClient({pixel})")
        page.evaluate("potflat.marker3d = null")
        page.mouse.click(c["x"], c["y"])
        page.wait_for_function("potflat.marker3d !== null")
        marked = np.asarray(page.evaluate("potflat.marker3d"))
        expected = position[int(pixel[1]), int(pixel[0])].astype(float)
        assert np.linalg.norm(marked - expected) * scene.grid.mm_per_unit < 1.0
        readout = page.evaluate("potflat.readout")
        assert readout["length_error_pct"] is not None and readout["anisotropy"] >= 1.0
        assert "local length error" in page.text_content("#readout")


def test_click_on_the_vessel_marks_the_flat_position(page, served):
    scene = served.scene
    page.click("[data-tool=look]")
    for target in ([1700, 900], [1200, 1100]):
        i = int(np.argmin(np.abs(scene.pixels - target).sum(axis=1)))
        point = scene.flat.mesh.vertices[i]
        page.evaluate(f"potflat.lookFrom({point.tolist()}, {_outward(scene, point).tolist()}, 200)")
        s = page.evaluate(f"potflat.project({point.tolist()})")
        page.evaluate("potflat.markerFlat = null")
        page.mouse.click(s["x"], s["y"])
        page.wait_for_function("potflat.markerFlat !== null")
        marked = np.asarray(page.evaluate("potflat.markerFlat"))
        assert np.linalg.norm(marked - scene.pixels[i]) < 2.0


def test_measure_gives_the_image_and_the_vessel_distance(page, served):
    scene = served.scene
    page.click("[data-tool=measure]")
    a, b = [1000.5, 900.5], [1400.5, 950.5]
    page.evaluate("potflat.measurePoints = []; potflat.measure = null")
    for q in (a, b):
        c = page.evaluate(f"potflat.imageToClient({q})")
        page.mouse.click(c["x"], c["y"])
    page.wait_for_function("potflat.measure !== null")
    m = page.evaluate("potflat.measure")
    got = np.asarray(page.evaluate("potflat.measurePoints"))
    assert m["image_mm"] == pytest.approx(np.linalg.norm(got[1] - got[0]) / PX_PER_MM, rel=1e-9)
    assert m["method"] == "geodesic"
    # the surface path is at least the chord and, on this smooth belly, within 3 % of it
    assert m["chord_mm"] <= m["surface_mm"] <= 1.03 * m["chord_mm"]
    direct = scene.measure(tuple(got[0]), tuple(got[1]))
    assert m["surface_mm"] == pytest.approx(direct["surface_mm"], rel=1e-9)
    assert "on the vessel" in page.text_content("#measure")
    # a short length on the smooth belly: the true distance is the chord between the position
    # map's points (the surface bends by much less than 0.5 % over 10 mm there)
    import tifffile

    position = tifffile.imread(served.server.runs.folders["amphora"] / "amphora.position.tif")
    page.evaluate("potflat.measurePoints = []; potflat.measure = null")
    for q in ([1200.5, 900.5], [1240.5, 900.5]):
        c = page.evaluate(f"potflat.imageToClient({q})")
        page.mouse.click(c["x"], c["y"])
        page.wait_for_timeout(400)  # two quick clicks this close would be a double click: a zoom
    page.wait_for_function("potflat.measure !== null")
    m = page.evaluate("potflat.measure")
    got = np.asarray(page.evaluate("potflat.measurePoints"))
    ends = [position[int(y), int(x)].astype(float) for x, y in got]
    true_mm = np.linalg.norm(ends[1] - ends[0]) * scene.grid.mm_per_unit
    assert 8.0 < true_mm < 12.0 and m["surface_mm"] == pytest.approx(true_mm, rel=5e-3)
    page.click("[data-tool=look]")


def test_window_and_overlap_dragged_on_the_image_become_options(page, served):
    scene = served.scene
    row = 0.55 * scene.grid.height
    page.click("[data-tool=window]")
    ends = [page.evaluate(f"potflat.imageToClient({[x, row]})") for x in (0.3 * scene.grid.width, 0.7 * scene.grid.width)]
    page.mouse.move(ends[0]["x"], ends[0]["y"])
    page.mouse.down()
    for t in np.linspace(0, 1, 6):
        page.mouse.move(ends[0]["x"] + t * (ends[1]["x"] - ends[0]["x"]), ends[0]["y"])
    page.mouse.up()
    page.wait_for_function("document.getElementById('command').textContent.includes('--angles')")
    window = page.evaluate("potflat.edits.window")
    expected = [scene.pixel_to_surface(x, row)["angle_deg"] for x in (0.3 * scene.grid.width, 0.7 * scene.grid.width)]
    assert np.allclose(window, expected, atol=0.5)
    assert "--seam " in page.text_content("#command")
    page.click("[data-tool=overlap]")
    x0 = 0.8 * scene.grid.width
    ends = [page.evaluate(f"potflat.imageToClient({[x, row]})") for x in (x0, x0 + 40 * PX_PER_MM)]
    page.mouse.move(ends[0]["x"], ends[0]["y"])
    page.mouse.down()
    page.mouse.move(ends[1]["x"], ends[1]["y"], steps=4)
    page.mouse.up()
    page.wait_for_function("document.getElementById('command').textContent.includes('--overlap')")
    hit = scene.pixel_to_surface(x0, row)
    degrees = 40.0 / (scene.radius(hit["point"]) * scene.grid.mm_per_unit) * 180 / np.pi
    assert page.evaluate("potflat.edits.overlap") == pytest.approx(degrees, abs=0.5)
    assert "--angles" not in page.text_content("#command")
    page.evaluate("potflat.edits = {}; potflat.window = null; potflat.overlap = null")
    page.click("[data-tool=look]")


def test_seam_click_and_painted_mask_rerun_as_the_command_line_does(browser, run_dir, tmp_path):
    """The page's edits and Rerun give the outputs of the command line it shows."""
    from PIL import Image

    from potflat.io.flat_ply import read_flat_ply
    from potflat.view.edits import recorded_options

    folder = tmp_path / "edited"
    shutil.copytree(run_dir, folder)
    served = _Served(folder)
    try:
        page = _open(browser, served)
        scene = served.scene
        # the seam through a point on the back of the vessel (a quarter of the image from the right)
        i = int(np.argmin(np.abs(scene.pixels - [0.8 * scene.grid.width, 0.55 * scene.grid.height]).sum(axis=1)))
        point = scene.flat.mesh.vertices[i]
        page.click("[data-tool=seam]")
        page.evaluate(f"potflat.lookFrom({point.tolist()}, {_outward(scene, point).tolist()}, 200)")
        s = page.evaluate(f"potflat.project({point.tolist()})")
        page.mouse.click(s["x"], s["y"])
        page.wait_for_function("potflat.edits.seam_at !== undefined")
        seam_at = np.asarray(page.evaluate("potflat.edits.seam_at"))
        assert np.linalg.norm(seam_at - point) * scene.grid.mm_per_unit < 2.0
        # paint a stroke across the image
        page.click("[data-tool=paint]")
        page.fill("#brush", "15")
        page.wait_for_function("potflat.zoneLoaded")
        ends = [page.evaluate(f"potflat.imageToClient({[x, 0.7 * scene.grid.height]})") for x in (900, 1500)]
        page.mouse.move(ends[0]["x"], ends[0]["y"])
        page.mouse.down()
        for t in np.linspace(0, 1, 12):
            page.mouse.move(ends[0]["x"] + t * (ends[1]["x"] - ends[0]["x"]), ends[0]["y"])
        page.mouse.up()
        assert page.evaluate("potflat.maskDirty")
        page.wait_for_function("document.getElementById('command').textContent.includes('--importance mask')")
        page.click("#rerun")
        page.wait_for_function("potflat.rerun && ['done', 'failed'].includes(potflat.rerun.state) && potflat.ready",
                               timeout=600_000)
        rerun = page.evaluate("potflat.rerun")
        assert rerun["state"] == "done", rerun["message"]
        page.wait_for_function("potflat.scene.rollout.importance === 'mask'")
        shown = page.text_content("#command")
        page.close()
    finally:
        served.close()
    command = rerun["command"]
    words = shlex.split(command)
    assert words[:2] == ["potflat", "run"] and "--seam-at" in words and "--importance-mask" in words
    # the options used are those the stages' sidecars record, and the page shows their command
    assert shown == command
    recorded = recorded_options(folder, "amphora")["rollout"]
    assert recorded.importance == "mask" and np.allclose(recorded.seam_at, seam_at)
    mask = np.asarray(Image.open(folder / "amphora.mask.png"))
    assert 0 < (mask == 255).mean() < 1
    # the same command line into another folder gives the same outputs
    other = tmp_path / "cli"
    words[words.index("-o") + 1] = str(other)
    run = subprocess.run([sys.executable, "-m", "potflat_cli", *words[1:]], capture_output=True, text=True,
                         timeout=900)
    assert run.returncode == 0, run.stderr
    a, b = read_flat_ply(folder / "amphora.relaxed.ply"), read_flat_ply(other / "amphora.relaxed.ply")
    assert np.array_equal(a.uv, b.uv) and np.array_equal(a.importance, b.importance)
    assert np.array_equal(np.asarray(Image.open(folder / "amphora.png")), np.asarray(Image.open(other / "amphora.png")))
    assert json.loads((folder / "amphora.rollout.json").read_text())["seam"]["method"] == "point"
    # one consistent set: the files of that command, and the mask it reads
    made = {p.name for p in other.iterdir()}
    assert {p.name for p in folder.iterdir()} == made | {"amphora.mask.png", "amphora.mask.bake.json",
                                                         "amphora.mask.relaxed.ply"}


def _with_a_lug(run_dir: Path, folder: Path, scene) -> np.ndarray:
    """A copy of the run in ``folder`` whose scan has a lug the rollout left out: a 30 mm
    square (untextured) 25 mm out from the belly, apart from the body. Its centre."""
    shutil.copytree(run_dir, folder)
    scan = folder / "scan"
    scan.mkdir()
    for part in ("amphora.obj", "amphora.mtl", "amphora.png"):
        shutil.copy(SAMPLE.with_name(part), scan / part)
    i = int(np.argmin(np.abs(scene.pixels - [0.5 * scene.grid.width, 0.5 * scene.grid.height]).sum(axis=1)))
    d = _outward(scene, scene.flat.mesh.vertices[i])
    centre = scene.flat.mesh.vertices[i] + 25.0 * d
    a = np.asarray(scene.rollout["axis"]["direction"])
    u = np.cross(a, d)
    corners = [centre + 15.0 * (su * u + sa * a) for su, sa in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    n = sum(1 for line in (scan / "amphora.obj").read_text().splitlines() if line.startswith("v "))
    with open(scan / "amphora.obj", "a") as f:
        f.writelines("v " + " ".join(repr(float(x)) for x in c) + "\n" for c in corners)
        f.write(f"f {n + 1} {n + 2} {n + 3}\nf {n + 1} {n + 3} {n + 4}\n")
    sidecar = folder / "amphora.rollout.json"
    record = json.loads(sidecar.read_text())
    record["input"] = str(scan / "amphora.obj")
    sidecar.write_text(json.dumps(record))
    return centre


def test_the_vessel_is_the_whole_scan_and_a_part_left_out_is_not_in_the_image(browser, served, run_dir, tmp_path):
    """The vessel is drawn from the whole scan (a lug the rollout left out too); a click on the
    lug says it is not in the image, a click on the belly still marks its flat position."""
    centre = _with_a_lug(run_dir, tmp_path / "lug", served.scene)
    lug = _Served(tmp_path / "lug")
    try:
        page = _open(browser, lug)
        page.wait_for_function("potflat.timings.scan !== undefined || (potflat.scan && !potflat.scan.mesh)",
                               timeout=120_000)
        scan = page.evaluate("potflat.scan.mesh")
        assert scan is not None, page.evaluate("potflat.scan.message")
        assert scan["faces"] == len(served.scene.flat.mesh.faces) + 2 and not scan["decimated"]
        scene = lug.scene
        d = _outward(scene, centre)
        page.evaluate(f"potflat.lookFrom({centre.tolist()}, {d.tolist()}, 200)")
        s = page.evaluate(f"potflat.project({centre.tolist()})")
        page.mouse.click(s["x"], s["y"])
        page.wait_for_function("potflat.readout !== null")
        readout = page.evaluate("potflat.readout")
        assert readout["outside"] and np.linalg.norm(np.asarray(readout["point"]) - centre) < 1.0
        assert page.evaluate("potflat.markerFlat") is None and "not in the image" in page.text_content("#readout")
        # beside the lug, the belly: in the image, at its vertex's flat position
        i = int(np.argmin(np.abs(scene.pixels - [0.3 * scene.grid.width, 0.5 * scene.grid.height]).sum(axis=1)))
        point = scene.flat.mesh.vertices[i]
        page.evaluate(f"potflat.lookFrom({point.tolist()}, {_outward(scene, point).tolist()}, 200)")
        s = page.evaluate(f"potflat.project({point.tolist()})")
        page.mouse.click(s["x"], s["y"])
        page.wait_for_function("potflat.markerFlat !== null")
        assert np.linalg.norm(np.asarray(page.evaluate("potflat.markerFlat")) - scene.pixels[i]) < 2.0
        page.close()
    finally:
        lug.close()


def _with_a_base(run_dir: Path, folder: Path, *, record: bool = True) -> np.ndarray:
    """A copy of the run in ``folder`` with a base's disc as the bake writes it beside the
    painting (``NAME.base.png``, listed under ``base`` in ``NAME.bake.json``; with ``record``,
    ``NAME.base.bake.json`` giving its grid): a 300 x 200 px image, left half red, right half
    blue, a 40 px grey legend band below. Its pixels (RGBA)."""
    from PIL import Image

    shutil.copytree(run_dir, folder)
    disc = np.zeros((240, 300, 4), np.uint8)
    disc[..., 3] = 255
    disc[:200, :150, 0] = 220
    disc[:200, 150:, 2] = 220
    disc[200:, :, :3] = 128
    Image.fromarray(disc).save(folder / "amphora.base.png")
    if record:
        (folder / "amphora.base.bake.json").write_text(json.dumps({"image_px": [300, 200], "px_per_mm": 4.0}))
    bake = json.loads((folder / "amphora.bake.json").read_text())
    bake["base"] = {"what": "the base left out of the rollout, seen along the axis",
                    "files": {"png": "amphora.base.png", "json": "amphora.base.bake.json"}}
    (folder / "amphora.bake.json").write_text(json.dumps(bake))
    return disc


def test_the_base_disc_is_a_layer_on_its_own_grid_not_linked(browser, run_dir, tmp_path):
    """A run with a base's disc offers it in the layer switch: the image shows its pixels on
    its own grid, its legend band below; a click on it marks nothing on the vessel and says
    so; the vessel keeps the painting; back on the painting the views are linked again."""
    from PIL import Image

    disc = _with_a_base(run_dir, tmp_path / "base")
    based = _Served(tmp_path / "base")
    try:
        entry = [e for e in json.loads(_get(based, "/_potflat/api/amphora/scene.json")[1])["layers"]
                 if e["name"] == "base"]
        assert entry and entry[0]["size"] == [300, 200] and not entry[0]["linked"] and entry[0]["legend"]
        status, dzi = _get(based, "/_potflat/api/amphora/dzi/base.dzi")
        assert status == 200 and b'Width="300" Height="200"' in dzi
        top = based.server.runs.layer("amphora", "base").top
        tile = np.asarray(Image.open(io.BytesIO(_get(based, f"/_potflat/api/amphora/dzi/base_files/{top}/0_0.png")[1])))
        assert np.array_equal(tile, disc[:200])
        legend = np.asarray(Image.open(io.BytesIO(_get(based, "/_potflat/api/amphora/legend/base.png")[1])))
        assert np.array_equal(legend, disc[200:])

        errors: list[str] = []
        page = _open(browser, based, errors)
        page.select_option("#layer", "base")
        page.wait_for_function("potflat.layerShown === 'base'")
        page.wait_for_timeout(300)
        shot = np.asarray(Image.open(io.BytesIO(page.locator("#flat").screenshot())).convert("RGB")).astype(int)
        assert ((shot[..., 0] > 180) & (shot[..., 2] < 60)).mean() > 0.05   # the red half
        assert ((shot[..., 2] > 180) & (shot[..., 0] < 60)).mean() > 0.05   # the blue half
        page.evaluate("potflat.marker3d = null")
        c = page.evaluate("potflat.imageToClient([75, 100])")
        page.mouse.click(c["x"], c["y"])
        page.wait_for_function("document.getElementById('readout').textContent.includes('not linked')")
        assert page.evaluate("potflat.marker3d") is None and page.evaluate("potflat.vesselShown") == "painting"
        page.select_option("#layer", "painting")
        page.wait_for_function("potflat.layerShown === 'painting'")
        c = page.evaluate("potflat.imageToClient([1500.5, 950.5])")
        page.mouse.click(c["x"], c["y"])
        page.wait_for_function("potflat.marker3d !== null")
        assert errors == []
        page.close()
    finally:
        based.close()


def test_a_base_listed_without_its_image_or_grid_is_tolerated(run_dir, tmp_path):
    """Without NAME.base.png the run has no base layer; without NAME.base.bake.json the disc
    takes its PNG's size (its band below then counts as image)."""
    from potflat.view.server import layer_entries
    from potflat.view.scene import Scene

    _with_a_base(run_dir, tmp_path / "nogrid", record=False)
    entry = [e for e in layer_entries(Scene(tmp_path / "nogrid", "amphora")) if e["name"] == "base"]
    assert entry and entry[0]["size"] == [300, 240] and not entry[0]["legend"]
    shutil.copytree(tmp_path / "nogrid", tmp_path / "gone")
    (tmp_path / "gone" / "amphora.base.png").unlink()
    names = [e["name"] for e in layer_entries(Scene(tmp_path / "gone", "amphora"))]
    assert "base" not in names and names[0] == "painting"


def test_a_scan_moved_away_leaves_the_unrolled_part_with_one_line(run_dir, tmp_path):
    from potflat.view.scene import Scene

    moved = tmp_path / "moved"
    shutil.copytree(run_dir, moved)
    record = json.loads((moved / "amphora.rollout.json").read_text())
    record["input"] = str(tmp_path / "gone.obj")
    (moved / "amphora.rollout.json").write_text(json.dumps(record))
    whole = Scene(moved, "amphora").whole()
    assert whole.display is None and "gone.obj" in whole.message and "\n" not in whole.message


def test_a_pick_behind_the_surface_seen_is_not_in_the_image(served):
    """The full flattening's hit counts only at the depth where the vessel is seen."""
    scene = served.scene
    i = int(np.argmin(np.abs(scene.pixels - [0.5 * scene.grid.width, 0.5 * scene.grid.height]).sum(axis=1)))
    V = scene.flat.mesh.vertices
    d = _outward(scene, V[i])
    origin = V[i] + 300 * d
    assert scene.ray_to_surface(origin, -d, V[i], depth=300.0) is not None
    assert scene.ray_to_surface(origin, -d, V[i], depth=280.0) is None  # something 20 mm in front of it


def test_the_whole_scan_drawn_whole_keeps_its_faces_and_texture_coordinates():
    from potflat.io.scan import load_scan
    from potflat.view.display import scan_display_mesh

    mesh = load_scan(SAMPLE, clean=False).mesh
    d = scan_display_mesh(mesh, np.ones(len(mesh.vertices), bool), faces=10**6)
    assert not d.decimated and len(d.faces) == len(mesh.faces)
    assert np.array_equal(d.vertices[d.faces], mesh.vertices[mesh.faces].astype(np.float32))
    assert np.array_equal(d.texcoords[d.faces], mesh.texcoords.astype(np.float32))
    assert (d.unrolled == 1).all() and np.allclose(np.linalg.norm(d.normals, axis=1), 1, atol=1e-6)


def test_texture_vertices_are_the_corners_with_one_vertex_and_one_texture_position():
    """The quick grouping (each vertex's first corner, a hash table for the rest) numbers the
    groups of (vertex, texture coordinates) in order of first corner, seams included."""
    from potflat.io.scan import load_scan
    from potflat.view.display import _texture_vertices

    mesh = load_scan(SAMPLE, clean=False).mesh
    fv, uv = mesh.faces.ravel(), mesh.texcoords.reshape(-1, 2) + 0.0
    ids: dict = {}
    expected = [ids.setdefault((int(v), float(a), float(b)), len(ids)) for v, (a, b) in zip(fv, uv)]
    got = _texture_vertices(fv, uv, len(mesh.vertices))
    assert np.array_equal(got, expected)
    assert len(ids) > len(np.unique(fv))  # the sample's texture has seams


def test_a_decimated_scan_keeps_its_texture_seam_apart_and_has_no_cracks():
    """A cylinder textured by angle and height, its texture seam along one line: the decimated
    copy's texture coordinates are those of its vertices' places, on each side of the seam."""
    from potflat.types import Mesh
    from potflat.view.display import scan_display_mesh

    n_t, n_h, R, H = 360, 120, 100.0, 300.0
    t = np.arange(n_t + 1) * 2 * np.pi / n_t  # the last column repeats the first, at u = 1
    z = np.linspace(0, H, n_h)
    V = np.stack([np.tile(R * np.cos(t[:-1]), n_h), np.tile(R * np.sin(t[:-1]), n_h), np.repeat(z, n_t)], axis=1)
    idx = np.arange(n_h)[:, None] * n_t + np.arange(n_t + 1)[None] % n_t
    uv_idx = np.stack(np.meshgrid(t / (2 * np.pi), z / H), axis=-1)
    quads = [(idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1])]
    a, b, c, e = (q.ravel() for q in quads[0])
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, e], 1)])
    ua, ub, uc, ue = (uv_idx[:-1, :-1].reshape(-1, 2), uv_idx[:-1, 1:].reshape(-1, 2), uv_idx[1:, 1:].reshape(-1, 2),
                      uv_idx[1:, :-1].reshape(-1, 2))
    T = np.concatenate([np.stack([ua, ub, uc], 1), np.stack([ua, uc, ue], 1)])
    mesh = Mesh(vertices=V, faces=F, texcoords=T, texture_path=SAMPLE.with_name("amphora.png"))
    d = scan_display_mesh(mesh, np.zeros(len(V), bool), faces=8000)
    assert d.decimated and 4000 < len(d.faces) <= 10000 and (d.unrolled == 0).all()
    P, uv = d.vertices.astype(float), d.texcoords.astype(float)
    theta = np.arctan2(P[:, 1], P[:, 0]) % (2 * np.pi) / (2 * np.pi)
    on_seam = np.minimum(theta, 1 - theta) < 0.02
    # away from the seam, u is the angle; at it, 0 or 1 by the side the faces are on
    assert np.abs(uv[~on_seam, 0] - theta[~on_seam]).max() < 0.01
    assert np.abs(uv[:, 1] - P[:, 2] / H).max() < 0.02
    assert np.ptp(uv[d.faces, 0], axis=1).max() < 0.05  # no face textured across the whole image
    # no cracks: every display edge that is not the cylinder's top or bottom is shared by two faces
    # once the seam's copies (same position) are one
    _, pos = np.unique(d.vertices, axis=0, return_inverse=True)
    E = np.sort(pos.ravel()[d.faces][:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, uses = np.unique(E, axis=0, return_counts=True)
    assert (uses == 1).sum() < 0.05 * len(uses)


def test_level_segments_follow_a_linear_field():
    from potflat.view.display import level_segments

    x, y = np.meshgrid(np.linspace(0, 1, 11), np.linspace(0, 1, 11))
    V = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    idx = np.arange(121).reshape(11, 11)
    a, b, c, e = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, e], 1)])
    seg = level_segments(V, F, V[:, 0] + 0.5 * V[:, 1], 0.73)
    assert len(seg) > 0 and np.allclose(seg[..., 0] + 0.5 * seg[..., 1], 0.73, atol=1e-6)
    crossed = ((V[F, 0] + 0.5 * V[F, 1] >= 0.73).sum(axis=1) % 3) != 0
    assert len(seg) == crossed.sum()


# ---------------------------------------------------------------------- the server's safety
def _get(served, path, *, token=True, host=None, method="GET", body=None):
    conn = http.client.HTTPConnection("127.0.0.1", served.server.port, timeout=30)
    headers = {"Host": host or f"127.0.0.1:{served.server.port}"}
    if token:
        headers["X-Potflat-Token"] = served.server.token
    conn.request(method, path, body=body, headers=headers)
    r = conn.getresponse()
    data = r.read()
    conn.close()
    return r.status, data


def test_requests_without_the_token_are_refused(served):
    assert _get(served, "/_potflat/api/amphora/scene.json")[0] == 200
    assert _get(served, "/_potflat/api/amphora/scene.json", token=False)[0] == 403
    assert _get(served, "/amphora.png", token=False)[0] == 403
    assert _get(served, f"/amphora.png?token={served.server.token[:-2]}", token=False)[0] == 403
    assert _get(served, f"/amphora.png?token={served.server.token}", token=False)[0] == 200


def test_requests_for_another_host_are_refused(served):
    """A page of another site whose name points at 127.0.0.1 (DNS rebinding) is refused."""
    assert _get(served, "/amphora.png", host=f"evil.example:{served.server.port}")[0] == 403


def test_paths_outside_the_folder_are_refused(served, run_dir, tmp_path):
    secret = tmp_path / "secret.txt"
    secret.write_text("not for the page")
    (run_dir / "link-out.txt").symlink_to(secret)
    try:
        assert _get(served, "/amphora.bake.json")[0] == 200
        for path in ("/../secret.txt", "/%2e%2e/%2e%2e/etc/passwd", "/..%2fsecret.txt", "/link-out.txt",
                     "/.potflat.lock", f"/{'%2e%2e/' * 8}etc/passwd"):
            status, body = _get(served, path)
            assert status in (403, 404) and b"not for the page" not in body and b"root:" not in body, path
        assert _get(served, "/link-out.txt")[0] == 403
        assert _get(served, "/%2e%2e/secret.txt")[0] == 403
        assert _get(served, "/_potflat/static/../../server.py")[0] in (403, 404)
    finally:
        (run_dir / "link-out.txt").unlink()


def test_a_mask_of_the_wrong_size_is_refused(served, tmp_path):
    from PIL import Image

    buf = io.BytesIO()
    Image.new("L", (10, 10)).save(buf, format="PNG")
    status, body = _get(served, "/_potflat/api/amphora/mask", method="PUT", body=buf.getvalue())
    assert status == 400 and b"paint it over that image" in body
    assert not (served.scene.folder / "amphora.mask.png").exists()


# ---------------------------------------------------------------------- pieces
def test_picking_on_the_full_mesh_from_a_decimated_display_mesh(served):
    """A ray aimed at a vertex finds that vertex's flat position (the display mesh only says
    where to look), and the display mesh is decimated to about the face count asked."""
    from potflat.view.display import display_mesh

    scene = served.scene
    small = display_mesh(scene.flat, scene.pixels, px_per_unit=scene.grid.px_per_unit, faces=4000)
    assert small.decimated and 2000 < len(small.faces) < 6000 and len(scene.lines["seam"]) > 0
    assert (small.pixels >= -1).all() and (small.pixels[:, 0] <= scene.grid.width + 1).all()
    rng = np.random.default_rng(1)
    V = scene.flat.mesh.vertices
    for i in rng.choice(len(V), 20, replace=False):
        d = _outward(scene, V[i])
        hit = scene.ray_to_surface(V[i] + 300 * d, -d, V[i] + rng.normal(scale=1.0, size=3), hint=scene.pixels[i])
        if hit is None:  # hidden behind another part of the vessel from that side
            continue
        if np.linalg.norm(np.asarray(hit["point"]) - V[i]) < 1e-6:
            assert np.linalg.norm(np.asarray(hit["pixel"]) - scene.pixels[i]) < 1e-6


def test_geodesic_on_a_cylinder_is_the_unrolled_straight_line():
    """On a finely meshed cylinder of radius 100 the distance is that of the development."""
    from potflat.view.geodesic import SurfaceGraph

    n_t, n_h, R, H = 400, 80, 100.0, 200.0
    t = np.linspace(0, 2 * np.pi, n_t, endpoint=False)
    h = np.linspace(0, H, n_h)
    V = np.stack([np.repeat(R * np.cos(t)[None], n_h, 0), np.repeat(R * np.sin(t)[None], n_h, 0),
                  np.repeat(h[:, None], n_t, 1)], axis=2).reshape(-1, 3)
    idx = np.arange(n_h * n_t).reshape(n_h, n_t)
    a, b = idx[:-1], np.roll(idx, -1, axis=1)[:-1]
    c, d = idx[1:], np.roll(idx, -1, axis=1)[1:]
    F = np.concatenate([np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)])
    graph = SurfaceGraph(V, F)
    fa, fb = 1000, 1000 + 40 * 2 * (n_t - 1) + 123
    pa, pb = V[F[fa]].mean(axis=0), V[F[fb]].mean(axis=0)
    length, path, method = graph.distance(pa, fa, pb, fb, F)
    ha, hb = pa[2], pb[2]
    ta, tb = np.arctan2(pa[1], pa[0]), np.arctan2(pb[1], pb[0])
    dt = abs((tb - ta + np.pi) % (2 * np.pi) - np.pi)
    r = R * np.cos(np.pi / n_t)  # the face centres lie on the facets, slightly inside
    assert method == "geodesic"
    assert length == pytest.approx(np.hypot(r * dt, hb - ha), rel=3e-3)
    assert np.allclose(path[0], pa) and np.allclose(path[-1], pb)


def test_window_and_overlap_edits_become_rollout_options(run_dir):
    from potflat.view.edits import Edits, command_line, edited_options, scan_of

    seam = json.loads((run_dir / "amphora.rollout.json").read_text())["seam"]["angle_deg"]
    options = edited_options(run_dir, "amphora", Edits(window=(seam + 30, seam + 200)), seam_deg=seam, landmark_deg=None)
    r = options["rollout"]
    assert r.seam == pytest.approx(seam % 360) and r.angles == pytest.approx((30.0, 200.0))
    options = edited_options(run_dir, "amphora", Edits(overlap=25.0), seam_deg=seam, landmark_deg=None)
    assert options["rollout"].overlap == 25.0 and options["rollout"].angles is None
    line = command_line(scan_of(run_dir, "amphora"), run_dir, "amphora", options)
    assert "--overlap 25.0" in line and "--preset preview" in line and "--position-map" in line
    with pytest.raises(Exception, match="overlap"):
        edited_options(run_dir, "amphora", Edits(overlap=500.0), seam_deg=seam, landmark_deg=None)


def test_the_batch_report_links_each_scan_to_its_view(run_dir, tmp_path):
    from potflat.files.batch.report import write_report

    report = SimpleNamespace(output=str(run_dir), name="amphora", status="done", seconds=1.0, error=None,
                             figures={})
    summary = SimpleNamespace(output=str(tmp_path), counts={"done": 1}, reports=[report], batch="b.yaml", seconds=1.0)
    page = write_report(summary).read_text()
    assert 'data-view="_potflat/view/amphora"' in page and "potflat view" in page


def test_the_batch_report_opens_each_view_when_served(browser, run_dir, tmp_path):
    """Through 'potflat view' on a batch's folder, the report's link opens the scan's view."""
    from potflat.files.batch.report import write_report
    from potflat.view.server import serve

    shutil.copytree(run_dir, tmp_path / "amphora")
    report = SimpleNamespace(output=str(tmp_path / "amphora"), name="amphora", status="done", seconds=1.0,
                             error=None, figures={})
    write_report(SimpleNamespace(output=str(tmp_path), counts={"done": 1}, reports=[report], batch="b.yaml",
                                 seconds=1.0))
    server = serve(tmp_path)
    threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True).start()
    try:
        page = browser.new_page()
        page.goto(server.url())
        link = page.locator("a.view")
        link.wait_for(state="visible")
        link.click()
        page.wait_for_function("window.potflat && (window.potflat.ready || window.potflat.error)", timeout=60_000)
        assert page.evaluate("potflat.error") is None and page.evaluate("potflat.scene.name") == "amphora"
        page.close()
    finally:
        server.shutdown()
        server.server_close()


def test_a_scan_of_a_batch_is_not_rerun_from_the_page(run_dir, tmp_path):
    """In a batch's folder the edits still give the command line, but the rerun and the mask
    are refused with one line (the batch's summary describes the scan's outputs)."""
    folder = tmp_path / "batch"
    shutil.copytree(run_dir, folder / "amphora")
    (folder / "summary.json").write_text("{}")
    batch = _Served(folder)
    try:
        status, body = _get(batch, "/_potflat/api/amphora/options", method="POST", body=b'{"overlap": 20}')
        assert status == 200 and "--overlap 20.0" in json.loads(body)["command"]
        for path, method, body in (("rerun", "POST", b'{"overlap": 20}'), ("mask", "PUT", b"png")):
            status, answer = _get(batch, f"/_potflat/api/amphora/{path}", method=method, body=body)
            assert status == 400 and "belongs to a batch" in json.loads(answer)["error"], path
        assert not (folder / "amphora" / "amphora.mask.png").exists()
        assert json.loads(_get(batch, "/_potflat/api/amphora/rerun")[1])["state"] == "idle"
    finally:
        batch.close()


def test_view_command_prints_the_address_and_stops_on_ctrl_c(run_dir):
    proc = subprocess.Popen([sys.executable, "-m", "potflat_cli", "view", str(run_dir), "--no-browser"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        assert line.startswith("potflat view: http://127.0.0.1:") and "token=" in line
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130 and len(err.strip().splitlines()) == 1 and err.startswith("error: interrupted")


def test_view_command_refuses_a_folder_without_a_run(tmp_path):
    run = subprocess.run([sys.executable, "-m", "potflat_cli", "view", str(tmp_path), "--no-browser"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and run.stderr.startswith("error:") and "holds no finished run" in run.stderr
    assert len(run.stderr.strip().splitlines()) == 1


def test_view_command_refuses_an_unknown_name(run_dir):
    run = subprocess.run([sys.executable, "-m", "potflat_cli", "view", str(run_dir), "nope", "--no-browser"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and "has no run 'nope'" in run.stderr
