"""The local server of ``potflat view``: the page, its assets, the run's files and its API.

It listens on 127.0.0.1 only, on a free port, and answers only requests that carry its random
token (in the URL's ``token=``, the ``X-Potflat-Token`` header, or the cookie the first page
sets) and name it by its own address (``Host``: a page of another site cannot reach it by
rebinding a name to 127.0.0.1). It serves the files of the folder it was given and nothing
outside it (no ``..``, no link that leads out, no hidden files), the page's assets from the
package, and under ``/_potflat/api/NAME/`` the run ``NAME``: its display mesh, image tiles,
the links between the views, the measure and the edits. Edits are written atomically.
"""
from __future__ import annotations

import hmac
import json
import re
import secrets
import threading
import traceback
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, unquote, urlsplit

from potflat.errors import InvalidInputError, InvalidOptionError, PotflatError
from potflat.files.options import options_dict
from potflat.io.atomic import _finite
from potflat.mesh.distortion import painted_zone_distortion
from potflat.view.edits import (
    MAX_MASK_BYTES,
    Edits,
    Rerun,
    command_line,
    edited_options,
    recorded_options,
    save_mask,
    scan_of,
)
from potflat.view.scene import Scene, run_names
from potflat.view.tiles import Layer

#: Where the server's own routes live (a scan cannot be named so: names have no slash).
PREFIX = "/_potflat"
#: The lookups for clicks are built once a page has its display mesh, or after this many seconds.
WARM_AFTER_S = 15.0
#: Largest JSON body accepted.
MAX_JSON_BYTES = 1 << 20
#: Why a scan of a batch is not rerun from the page (the batch's summary, report and manifest
#: describe its outputs).
BATCH_RERUN = ("this scan belongs to a batch (summary.json in the folder given): rerunning it here would leave the "
               "batch's summary and report describing other outputs; run the command shown into another folder, or "
               "change the batch's YAML and run potflat batch again")
#: Content types of the page's assets and the run's files.
TYPES = {".js": "text/javascript; charset=utf-8", ".html": "text/html; charset=utf-8", ".css": "text/css",
         ".json": "application/json", ".png": "image/png", ".svg": "image/svg+xml", ".csv": "text/csv",
         ".tif": "image/tiff", ".pdf": "application/pdf", ".ply": "application/octet-stream"}


class Runs:
    """The runs a server shows: one folder of runs (``NAME.*``) or a batch's output (one folder
    per scan).

    Parameters
    ----------
    root : Path
        The folder given to ``potflat view``.
    """

    def __init__(self, root: Path):
        self.root = Path(root).resolve()
        if not self.root.is_dir():
            raise InvalidInputError(f"{root} is not a folder; give the output folder of potflat run or batch")
        self.folders: dict[str, Path] = {name: self.root for name in run_names(self.root)}
        for sub in sorted(p for p in self.root.iterdir() if p.is_dir() and not p.name.startswith(".")):
            for name in run_names(sub):
                self.folders.setdefault(name, sub)
        if not self.folders:
            raise InvalidInputError(f"{root} holds no finished run (NAME.bake.json beside NAME.relaxed.ply); give the "
                                    "output folder of potflat run or batch")
        self.batch = (self.root / "summary.json").is_file()
        self._scenes: dict[str, Any] = {}
        self._reruns: dict[str, Any] = {}
        self._layers: dict[tuple[str, str], Any] = {}
        self._lock = threading.Lock()
        #: Set when a page has its display mesh: the lookups for clicks are built after it
        #: (building them holds the interpreter, which would slow the page's first render).
        self.opened = threading.Event()

    def scene(self, name: str):
        """The :class:`potflat.view.scene.Scene` of run ``name`` (loaded once)."""

        if name not in self.folders:
            raise KeyError(name)
        with self._lock:
            if name not in self._scenes:
                self._scenes[name] = Scene(self.folders[name], name)
            return self._scenes[name]

    def reload(self, name: str) -> None:
        """Forget run ``name``'s loaded state (after a rerun rewrote its files)."""
        with self._lock:
            self._scenes.pop(name, None)
            for key in [k for k in self._layers if k[0] == name]:
                del self._layers[key]

    def rerun(self, name: str):
        with self._lock:
            return self._reruns.setdefault(name, Rerun())

    def layer(self, name: str, layer: str):
        """The :class:`potflat.view.tiles.Layer` of ``layer`` (``painting`` or a map) of run ``name``."""

        scene = self.scene(name)
        files = layer_files(scene)
        if layer not in files:
            raise KeyError(layer)
        with self._lock:
            key = (name, layer)
            if key not in self._layers:
                self._layers[key] = Layer(files[layer], *layer_size(scene, layer))
            return self._layers[key]


#: The relief's images in the order the page offers them (``raking-``: ``raking-AZ``, one per
#: light azimuth, in the order the bake lists them).
RELIEF_LAYERS = ("relief", "raking-", "curvature", "relief-overlay")


#: The layer of the base's disc (:attr:`potflat.view.scene.Scene.base_image`).
BASE_LAYER = "base"


def layer_files(scene) -> dict[str, Path]:
    """The images of a run by layer name: ``painting``, each distortion map, each of the
    relief's images (``relief``, ``raking-AZ``, ``curvature``, ``relief-overlay``) and the
    base's disc (``base``) that is there."""
    out = {"painting": scene.folder / f"{scene.name}.png"}
    made = scene.bake.get("maps") or {}
    asked = (scene.bake.get("provenance") or {}).get("options", {}).get("maps") or []
    files = scene.bake.get("files") or {}
    relief = [k for kind in RELIEF_LAYERS for k in files if k == kind or (kind == "raking-" and k.startswith(kind))]
    for m in [m for m in asked if m in made] + [m for m in made if m not in asked] + relief:  # in the order asked
        path = scene.folder / f"{scene.name}.{m}.png"
        if path.is_file():
            out[m] = path
    if scene.base_image is not None:
        out[BASE_LAYER] = scene.base_image.path
    return out


def layer_size(scene, layer: str) -> tuple[int, int]:
    """Width and height (pixels) of ``layer``'s image: the bake's grid, or the base disc's own."""
    if layer == BASE_LAYER:
        return scene.base_image.width, scene.base_image.height
    return scene.grid.width, scene.grid.height


def layer_entries(scene) -> list[dict]:
    """The page's layer switch: each layer's ``name``, its ``title`` in the switch, its
    ``label`` (what its colours or greys say) and whether a ``legend`` band is below it."""
    from PIL import Image

    maps = scene.bake.get("maps") or {}
    relief = scene.bake.get("relief") or {}
    entries = []
    for key, path in layer_files(scene).items():
        if key == "painting":
            untextured = scene.bake.get("painting") == "relief"
            title = "relief in grey (no texture)" if untextured else "painting"
            label = (f"height above the surface smoothed at {relief.get('smoothing_mm', 0):.3g} mm, in grey"
                     if untextured else "the scan's texture")
        elif key in maps:
            title, label = f"{key} map", maps[key].get("label", key)
        elif key == "relief":
            title = "relief: height"
            label = f"height above the surface smoothed at {relief.get('smoothing_mm', 0):.3g} mm, mm"
        elif key.startswith("raking-"):
            azimuth = key[len("raking-"):]
            title = f"relief: raking light from {azimuth}°"
            label = (f"raking light at {relief.get('light_elevation_deg', 20):g}° from azimuth {azimuth}° "
                     "(clockwise from the image's up)")
        elif key == "curvature":
            title, label = "relief: curvature", "concavity (MSII-like): dark grooves, light ridges"
        elif key == BASE_LAYER:
            base = scene.base_image
            title = "base, seen along the axis"
            label = ("the base left out of the rollout, seen along the axis"
                     + (f" at {base.px_per_mm:g} px/mm" if base.px_per_mm else "")
                     + ": its own image, not linked to the vessel")
        else:
            title = "painting + relief"
            label = f"painting and relief blended (relief share {relief.get('overlay_blend') or 0:g})"
        try:
            with Image.open(path) as img:
                legend = img.height > layer_size(scene, key)[1]
        except OSError:
            legend = False
        entries.append({"name": key, "title": title, "label": label, "legend": legend,
                        "range": maps.get(key, {}).get("range"), "linked": key != BASE_LAYER,
                        "size": list(layer_size(scene, key))})
    return entries


def scene_json(runs: Runs, name: str) -> dict:
    """What the page needs to start: the image's grid, layers and legends, the display mesh's
    counts, the axis and seam, the figures and the current options."""

    scene = runs.scene(name)
    g = scene.grid
    display = scene.display
    relaxed = json.loads((scene.folder / f"{name}.relaxed.json").read_text(encoding="utf-8")) \
        if (scene.folder / f"{name}.relaxed.json").is_file() else {}
    figures, where = painted_zone_distortion(relaxed) if relaxed else ({}, "whole surface")
    try:
        options = recorded_options(scene.folder, name)
        command = command_line(scan_of(scene.folder, name), scene.folder, name, options)
        rollout = _plain(options["rollout"])
    except InvalidInputError as exc:
        command, rollout = f"(cannot rerun: {exc})", {}
    return {
        "name": name, "folder": str(scene.folder), "width": g.width, "height": g.height, "px_per_mm": g.px_per_mm,
        "mm_per_unit": g.mm_per_unit, "units": scene.flat.mesh.units,
        "layers": layer_entries(scene),
        "mesh": {**display.counts(), "decimated": display.decimated, "full_vertices": len(scene.flat.uv),
                 "full_faces": len(scene.flat.mesh.faces)},
        "axis": scene.rollout.get("axis"), "seam": scene.rollout.get("seam"), "region": scene.rollout.get("region"),
        "painted_zone": scene.flat.importance is not None, "lengths": relaxed.get("lengths"),
        "distortion_where": where, "figures": figures, "rollout": rollout, "command": command,
        "rerun": runs.rerun(name).as_dict(), "batch": runs.batch,
    }


def _plain(options) -> dict:
    return options_dict(options)


class ViewServer(ThreadingHTTPServer):
    """The HTTP server: :class:`Runs` and a token.

    Parameters
    ----------
    runs : Runs
    port : int
        0: a free port.
    """

    daemon_threads = True

    def __init__(self, runs: Runs, port: int = 0):
        self.runs = runs
        self.token = secrets.token_urlsafe(24)
        super().__init__(("127.0.0.1", port), Handler)
        self.port = self.server_address[1]
        self.cookie = f"potflat_view_{self.port}"

    def url(self, name: str | None = None) -> str:
        """The page's address with the token (the run ``name``'s view, or the folder's page)."""
        base = f"http://127.0.0.1:{self.port}"
        path = f"{PREFIX}/view/{name}" if name else "/"
        return f"{base}{path}?token={self.token}"

    def warm(self, names) -> threading.Thread:
        """Load runs in a background thread: what the page asks first, then the whole scan (its
        display copy is ready soon after the first render), then the lookups for clicks."""
        def work():
            for name in names:
                try:
                    self.runs.layer(name, "painting").texture()  # the page's first requests
                    self.runs.scene(name).display
                    self.runs.scene(name).whole()
                    self.runs.opened.wait(timeout=WARM_AFTER_S)
                    self.runs.scene(name).warm()
                except Exception:  # reported when the page asks for it
                    pass
        thread = threading.Thread(target=work, daemon=True, name="potflat-view-warm")
        thread.start()
        return thread


class Handler(BaseHTTPRequestHandler):
    server: ViewServer
    protocol_version = "HTTP/1.1"

    def log_message(self, format: str, *args) -> None:  # quiet: the terminal shows the URL and errors only
        pass

    # ---------------------------------------------------------------- checks
    def _authorised(self, query: dict) -> bool:
        host = self.headers.get("Host", "")
        if host not in (f"127.0.0.1:{self.server.port}", f"localhost:{self.server.port}"):
            return False
        given = [*query.get("token", []), self.headers.get("X-Potflat-Token", "")]
        for part in (self.headers.get("Cookie") or "").split(";"):
            key, _, value = part.strip().partition("=")
            if key == self.server.cookie:
                given.append(value)
        return any(hmac.compare_digest(g.encode(), self.server.token.encode()) for g in given if g)

    def _send(self, status: int, body: bytes, ctype: str, *, cookie: bool = False, cache: bool = False) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("X-Content-Type-Options", "nosniff")
        self.send_header("Cache-Control", "private, max-age=3600" if cache else "no-store")
        if cookie:
            self.send_header("Set-Cookie", f"{self.server.cookie}={self.server.token}; Path=/; HttpOnly; "
                                           "SameSite=Strict")
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, obj: Any, status: int = 200) -> None:
        self._send(status, json.dumps(_finite(obj), allow_nan=False, default=_numpy_scalar).encode(),
                   "application/json")

    def _error(self, status: int, message: str) -> None:
        self._json({"error": message}, status)

    def _body(self, limit: int) -> bytes:
        length = int(self.headers.get("Content-Length") or 0)
        if length > limit:
            raise _Refused(HTTPStatus.REQUEST_ENTITY_TOO_LARGE, f"request body over {limit} bytes")
        return self.rfile.read(length)

    # ---------------------------------------------------------------- dispatch
    def do_HEAD(self) -> None:
        self.do_GET()

    def do_GET(self) -> None:
        self._dispatch("GET")

    def do_POST(self) -> None:
        self._dispatch("POST")

    def do_PUT(self) -> None:
        self._dispatch("PUT")

    def _dispatch(self, method: str) -> None:
        url = urlsplit(self.path)
        query = parse_qs(url.query)
        if not self._authorised(query):
            self._error(HTTPStatus.FORBIDDEN, "missing or wrong token: open the address potflat view printed")
            return
        try:
            path = unquote(url.path, errors="strict")
            if "\x00" in path or "\\" in path:
                raise _Refused(HTTPStatus.BAD_REQUEST, "bad path")
            if path.startswith(PREFIX + "/"):
                self._route(method, path[len(PREFIX):], query, cookie=bool(query.get("token")))
            elif method in ("GET", "HEAD"):
                self._file(path, cookie=bool(query.get("token")))
            else:
                raise _Refused(HTTPStatus.METHOD_NOT_ALLOWED, "method not allowed")
        except _Refused as exc:
            self._error(exc.status, exc.message)
        except KeyError as exc:
            self._error(HTTPStatus.NOT_FOUND, f"no such run or layer: {exc.args[0]}")
        except PotflatError as exc:
            self._error(HTTPStatus.BAD_REQUEST, str(exc))
        except (BrokenPipeError, ConnectionResetError):
            pass
        except Exception as exc:  # one line to the page; the server goes on
            traceback.print_exc()
            self._error(HTTPStatus.INTERNAL_SERVER_ERROR, f"{type(exc).__name__}: {exc}")

    def _file(self, path: str, *, cookie: bool) -> None:
        """A file of the served folder (``/`` is the batch report, or the list of runs)."""
        root = self.server.runs.root
        if path == "/":
            if (root / "index.html").is_file():
                path = "/index.html"
            else:
                self._send(200, _run_list(self.server.runs).encode(), TYPES[".html"], cookie=cookie)
                return
        target = _inside(root, path)
        self._send(200, target.read_bytes(), TYPES.get(target.suffix.lower(), "application/octet-stream"),
                   cookie=cookie)

    def _route(self, method: str, path: str, query: dict, *, cookie: bool) -> None:
        runs = self.server.runs
        parts = path.strip("/").split("/")
        if parts[0] == "static" and method in ("GET", "HEAD"):
            self._static("/".join(parts[1:]))
            return
        if parts[0] == "view" and len(parts) == 2 and method in ("GET", "HEAD"):
            if parts[1] not in runs.folders:
                raise KeyError(parts[1])
            page = resources.files("potflat.view").joinpath("static", "view.html").read_bytes()
            self._send(200, page, TYPES[".html"], cookie=cookie)
            return
        if parts[0] != "api" or len(parts) < 3:
            raise _Refused(HTTPStatus.NOT_FOUND, "not found")
        name, what, rest = parts[1], parts[2], parts[3:]
        if name not in runs.folders:
            raise KeyError(name)
        if method in ("GET", "HEAD"):
            self._get(name, what, rest)
        elif method == "POST":
            self._post(name, what, self._body(MAX_JSON_BYTES))
        elif method == "PUT" and what == "mask":
            if runs.batch:
                raise InvalidOptionError(BATCH_RERUN)
            scene = runs.scene(name)
            saved = save_mask(scene.folder, name, self._body(MAX_MASK_BYTES), (scene.grid.width, scene.grid.height))
            self._json({"saved": saved.name})
        else:
            raise _Refused(HTTPStatus.METHOD_NOT_ALLOWED, "method not allowed")

    def _static(self, rel: str) -> None:
        base = resources.files("potflat.view").joinpath("static")
        parts = [p for p in rel.split("/") if p]
        if not parts or any(p.startswith(".") for p in parts):
            raise _Refused(HTTPStatus.NOT_FOUND, "not found")
        item = base.joinpath(*parts)
        if not item.is_file():
            raise _Refused(HTTPStatus.NOT_FOUND, "not found")
        self._send(200, item.read_bytes(), TYPES.get(Path(parts[-1]).suffix, "application/octet-stream"), cache=True)

    def _get(self, name: str, what: str, rest: list[str]) -> None:
        runs = self.server.runs
        if what == "scene.json":
            self._json(scene_json(runs, name))
        elif what == "mesh.bin":
            self._send(200, runs.scene(name).display.as_bytes(), "application/octet-stream")
            runs.opened.set()
        elif what == "lines" and len(rest) == 1 and rest[0] in ("seam.bin", "edge.bin", "outline.bin"):
            scene = runs.scene(name)
            with scene._lock:
                lines = scene.lines[rest[0][:-4]]
            self._send(200, lines.astype("<f4").tobytes(), "application/octet-stream")
        elif what == "scan.json":
            whole = runs.scene(name).whole()
            self._json({"scan": whole.scan, "message": whole.message,
                        "mesh": None if whole.display is None else whole.display.counts()})
        elif what == "scan.bin":
            whole = runs.scene(name).whole()
            if whole.display is None:
                raise _Refused(HTTPStatus.NOT_FOUND, whole.message)
            self._send(200, whole.display.as_bytes(), "application/octet-stream")
        elif what == "scan-texture.jpg":
            whole = runs.scene(name).whole()
            if whole.texture is None:
                raise _Refused(HTTPStatus.NOT_FOUND, "the scan has no texture")
            self._send(200, whole.texture, "image/jpeg")
        elif what == "dzi" and len(rest) == 1 and rest[0].endswith(".dzi"):
            self._send(200, runs.layer(name, rest[0][:-4]).dzi().encode(), "application/xml")
        elif what == "dzi" and len(rest) == 3 and rest[0].endswith("_files"):
            match = re.fullmatch(r"(\d+)_(\d+)\.png", rest[2])
            if not match or not rest[1].isdigit():
                raise _Refused(HTTPStatus.NOT_FOUND, "no such tile")
            tile = runs.layer(name, rest[0][:-6]).tile(int(rest[1]), int(match[1]), int(match[2]))
            if tile is None:
                raise _Refused(HTTPStatus.NOT_FOUND, "no such tile")
            self._send(200, tile, "image/png")
        elif what == "legend" and len(rest) == 1 and rest[0].endswith(".png"):
            legend = runs.layer(name, rest[0][:-4]).legend()
            if legend is None:
                raise _Refused(HTTPStatus.NOT_FOUND, "no legend")
            self._send(200, legend, "image/png")
        elif what == "texture" and len(rest) == 1 and rest[0].endswith(".jpg"):
            self._send(200, runs.layer(name, rest[0][:-4]).texture(), "image/jpeg")
        elif what == "zone.png":
            self._send(200, zone_mask_png(runs.scene(name)), "image/png")
        elif what == "rerun":
            self._json(runs.rerun(name).as_dict())
        else:
            raise _Refused(HTTPStatus.NOT_FOUND, "not found")

    def _post(self, name: str, what: str, body: bytes) -> None:
        runs = self.server.runs
        try:
            data = json.loads(body or b"{}")
        except ValueError:
            raise _Refused(HTTPStatus.BAD_REQUEST, "the body is not JSON") from None
        if not isinstance(data, dict):
            raise _Refused(HTTPStatus.BAD_REQUEST, "the body must be a JSON object")
        scene = runs.scene(name)
        if what == "pick":
            if "pixel" in data:
                x, y = _numbers(data["pixel"], 2)
                self._json({"hit": scene.pixel_to_surface(x, y)})
            else:
                ray = data.get("ray") or {}
                hint, depth = ray.get("hint"), ray.get("depth")
                near = _numbers(ray.get("near"), 3)
                hit = scene.ray_to_surface(_numbers(ray.get("origin"), 3), _numbers(ray.get("direction"), 3), near,
                                           None if hint is None else _numbers(hint, 2),
                                           None if depth is None else _numbers([depth], 1)[0])
                # a point seen on the vessel that is not in the flattening: where it is, and that it is not in the image
                outside = None if hit is not None or depth is None else {
                    "point": list(near), "point_mm": [c * scene.grid.mm_per_unit for c in near],
                    "angle_deg": scene.angle_deg(near)}
                self._json({"hit": hit, "outside": outside})
        elif what == "measure":
            self._json({"measure": scene.measure(_numbers(data.get("a"), 2), _numbers(data.get("b"), 2))})
        elif what in ("options", "rerun"):
            edits = Edits.from_json(data)
            seam_at = edits.seam_at
            if seam_at is None:
                seam_at = (scene.rollout.get("seam") or {}).get("landmark") or {}
                seam_at = seam_at.get("point") if seam_at.get("kind") == "point" else None
            options = edited_options(scene.folder, name, edits,
                                     seam_deg=(scene.rollout.get("seam") or {}).get("angle_deg"),
                                     landmark_deg=None if seam_at is None else scene.angle_deg(seam_at))
            if what == "options":
                self._json({"rollout": _plain(options["rollout"]),
                            "command": command_line(scan_of(scene.folder, name), scene.folder, name, options)})
            elif runs.batch:
                raise InvalidOptionError(BATCH_RERUN)
            else:
                self._json(runs.rerun(name).start(scene.folder, name, options, lambda: runs.reload(name)))
        elif what == "angle":
            x, y = _numbers(data.get("pixel"), 2)
            hit = scene.pixel_to_surface(x, y)
            self._json({"angle_deg": None if hit is None else hit["angle_deg"],
                        "radius": None if hit is None else scene.radius(hit["point"])})
        else:
            raise _Refused(HTTPStatus.NOT_FOUND, "not found")


class _Refused(Exception):
    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status, self.message = int(status), message


def _numbers(value: Any, n: int) -> tuple[float, ...]:
    import math

    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        raise _Refused(HTTPStatus.BAD_REQUEST, f"expected {n} numbers") from None
    if len(out) != n or not all(math.isfinite(v) for v in out):
        raise _Refused(HTTPStatus.BAD_REQUEST, f"expected {n} finite numbers")
    return out


def _numpy_scalar(obj: Any) -> Any:
    import numpy as np

    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(type(obj).__name__)


def _inside(root: Path, path: str) -> Path:
    """The regular file ``path`` (a URL path) names inside ``root``; refused (403) when it leaves
    ``root`` (``..``, a link out) or names a hidden file, 404 when there is none."""
    parts = [p for p in path.split("/") if p]
    if any(p in ("..", ".") or p.startswith(".") for p in parts):
        raise _Refused(HTTPStatus.FORBIDDEN, "outside the served folder")
    target = root.joinpath(*parts)
    try:
        real = target.resolve(strict=True)
    except (OSError, RuntimeError):
        raise _Refused(HTTPStatus.NOT_FOUND, "not found") from None
    if real != root and root not in real.parents:
        raise _Refused(HTTPStatus.FORBIDDEN, "outside the served folder")
    if not real.is_file():
        raise _Refused(HTTPStatus.NOT_FOUND, "not found")
    return real


def _run_list(runs: Runs) -> str:
    import html

    items = "".join(f'<li><a href="{PREFIX}/view/{html.escape(n)}">{html.escape(n)}</a></li>' for n in runs.folders)
    return (f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>potflat view</title></head>'
            f"<body><h1>potflat view: {html.escape(str(runs.root))}</h1><ul>{items}</ul></body></html>")


def zone_mask_png(scene) -> bytes:
    """The painted zone as a mask over the image (white = painted: faces of the display mesh
    whose corners' mean importance is at least 0.5), PNG; all white without a painted zone."""
    import io

    import numpy as np
    from PIL import Image

    from potflat.raster.render import fill_faces

    g, d = scene.grid, scene.display
    painted = d.importance[d.faces].mean(axis=1) >= 0.5
    mask = fill_faces(d.pixels, d.faces[painted], g.height, g.width)
    buf = io.BytesIO()
    Image.fromarray(mask.astype(np.uint8) * 255).save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def serve(root: Path, *, port: int = 0) -> ViewServer:
    """A :class:`ViewServer` on ``root`` (not yet serving: call ``serve_forever``)."""
    return ViewServer(Runs(root), port)

