"""One finished run as the page sees it, and the links between its two views.

The flat image's pixel grid is the bake's (``NAME.bake.json``: ``origin_uv``, ``px_per_unit``,
``image_px``); pixel ``(column, row)`` covers ``[column, column + 1) x [row, row + 1)``, so a
pixel's centre is at ``+ 0.5``. A point on the image goes to the vessel through the bake's
position map (``NAME.position.tif``; rendered in memory by the bake's renderer when the run
was baked without ``--position-map``); a point on the vessel (a ray from the page's camera,
hitting its display mesh) is cast again on the full mesh and reaches the image through the
hit face's barycentric coordinates. Distances on the vessel are shortest paths through the
surface (:mod:`potflat.view.geodesic`).
"""
from __future__ import annotations

import json
import math
import threading
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from potflat.errors import InvalidInputError, PotflatError
from potflat.io.flat_ply import read_flat_ply
from potflat.mesh.distortion import ZONE_THRESHOLD, face_distortion, length_error
from potflat.raster.render import Renderer
from potflat.rollout.axis import cylindrical
from potflat.types import FlatMesh
from potflat.view.display import ScanDisplay, boundary_segments, display_mesh, level_segments, rows_in, scan_display_mesh
from potflat.view.geodesic import SurfaceGraph
from potflat.view.tiles import texture_jpeg

#: Candidate faces tested for a pick: the nearest by centroid to the display mesh's hit.
PICK_CANDIDATES = 256
#: Candidate faces tested to locate a point of the image.
LOCATE_CANDIDATES = 16
#: How the face lookups are built: unbalanced, not compacted (at 6M faces three times faster
#: to build than the default, as fast to query).
TREE = {"balanced_tree": False, "compact_nodes": False}
#: A pick's hit on the full flattening is the point seen on the vessel when it is at most this
#: many display cells (of the two display meshes, added) farther or nearer along the ray.
PICK_CELLS = 2.0


@dataclass(frozen=True)
class WholeScan:
    """The whole scan as the page draws it, or why it cannot.

    Attributes
    ----------
    display : ScanDisplay or None
        None when the scan cannot be read (``message`` says why).
    texture : bytes or None
        The scan's texture as JPEG (:func:`potflat.view.tiles.texture_jpeg`).
    scan : str
        The scan file the rollout read.
    message : str
        Empty, or one line: why only the flattened part is drawn.
    """

    display: ScanDisplay | None
    texture: bytes | None
    scan: str
    message: str


@dataclass(frozen=True)
class BaseImage:
    """The base's disc the bake writes beside the painting when the rollout left the base out:
    an orthographic view along the axis, on its own pixel grid (not linked to the vessel).

    Attributes
    ----------
    path : Path
        ``NAME.base.png``.
    width, height : int
        The disc image's size, pixels (rows below it: its legend band, if any).
    px_per_mm : float or None
        Its resolution (None when ``NAME.base.bake.json`` cannot be read).
    """

    path: Path
    width: int
    height: int
    px_per_mm: float | None


@dataclass(frozen=True)
class Grid:
    """The bake's pixel grid.

    Attributes
    ----------
    origin : (2,) float64
        Flat coordinates of the image's top-left corner.
    px_per_unit : float
        Pixels per scan unit.
    width, height : int
        Image size, pixels.
    px_per_mm : float
    mm_per_unit : float
    """

    origin: np.ndarray
    px_per_unit: float
    width: int
    height: int
    px_per_mm: float
    mm_per_unit: float

    def pixels(self, uv: np.ndarray) -> np.ndarray:
        """Pixel positions (column, row) of flat points ``uv`` (k, 2)."""
        out = np.empty_like(np.asarray(uv, np.float64))
        out[:, 0] = (uv[:, 0] - self.origin[0]) * self.px_per_unit
        out[:, 1] = (self.origin[1] - uv[:, 1]) * self.px_per_unit
        return out


def run_names(folder: Path) -> list[str]:
    """Names of the finished runs in ``folder`` (``NAME.bake.json`` beside ``NAME.relaxed.ply``), sorted."""
    return sorted(p.name[: -len(".bake.json")] for p in folder.glob("*.bake.json")
                  if (folder / p.name.replace(".bake.json", ".relaxed.ply")).is_file())


def _read_json(path: Path) -> dict:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InvalidInputError(f"cannot read {path}: {getattr(exc, 'strerror', None) or exc}; run potflat on the "
                                "scan again") from None
    if not isinstance(data, dict):
        raise InvalidInputError(f"{path} is not a potflat sidecar; run potflat on the scan again")
    return data


class Scene:
    """A finished run ``NAME`` in ``folder``: its flattening, image grid and the links.

    Parameters
    ----------
    folder : Path
        The run's output folder.
    name : str
        ``NAME`` of ``NAME.relaxed.ply``, ``NAME.bake.json``, ``NAME.png``.
    """

    def __init__(self, folder: Path, name: str):
        self.folder, self.name = Path(folder), name
        self.bake = _read_json(self.folder / f"{name}.bake.json")
        rollout_json = self.folder / f"{name}.rollout.json"
        self.rollout = _read_json(rollout_json) if rollout_json.is_file() else {}
        self.relaxed = self.folder / f"{name}.relaxed.ply"
        self.flat: FlatMesh = read_flat_ply(self.relaxed)
        try:
            width, height = (int(v) for v in self.bake["image_px"])
            self.grid = Grid(origin=np.asarray(self.bake["origin_uv"], np.float64),
                             px_per_unit=float(self.bake["px_per_unit"]), width=width, height=height,
                             px_per_mm=float(self.bake["px_per_mm"]), mm_per_unit=self.flat.mesh.mm_per_unit)
        except (KeyError, TypeError, ValueError):
            raise InvalidInputError(f"{self.folder / f'{name}.bake.json'} lacks the image grid; bake the run again "
                                    "with potflat") from None
        self.pixels = self.grid.pixels(self.flat.uv)
        self._lock = threading.Lock()
        self._whole_lock = threading.Lock()
        self._whole: WholeScan | None = None

    @cached_property
    def base_image(self) -> BaseImage | None:
        """The base's disc (``NAME.base.png``, written when the rollout left the base out), or
        None when the run has none. Its size is its own grid's (``NAME.base.bake.json``), else
        the PNG's."""
        entry = self.bake.get("base")
        listed = entry.get("files") if isinstance(entry, dict) else None
        png = listed.get("png") if isinstance(listed, dict) else None
        if not (isinstance(png, str) and png.startswith(f"{self.name}.base") and Path(png).name == png):
            png = f"{self.name}.base.png"
        path = self.folder / png
        if not path.is_file():
            return None
        try:
            record = json.loads((self.folder / f"{self.name}.base.bake.json").read_text(encoding="utf-8"))
            width, height = (int(v) for v in record["image_px"])
            px_per_mm = float(record["px_per_mm"])
        except (OSError, ValueError, TypeError, KeyError):
            from PIL import Image

            try:
                with Image.open(path) as img:
                    width, height = img.size
            except OSError:
                return None
            px_per_mm = None
        return BaseImage(path=path, width=width, height=height, px_per_mm=px_per_mm)

    # ---------------------------------------------------------------- lazily built parts
    @property
    def display(self):
        """The :class:`potflat.view.display.DisplayMesh` the page draws (made once)."""
        with self._lock:
            return self._display

    @cached_property
    def _display(self):
        return display_mesh(self.flat, self.pixels, px_per_unit=self.grid.px_per_unit)

    @cached_property
    def lines(self) -> dict[str, np.ndarray]:
        """The lines drawn on the vessel, each (s, 2, 3) float32: ``seam`` (the cut), ``edge``
        (the rest of the flattening's boundary: the image's edge) and ``outline`` (the painted
        zone's: where the importance crosses :data:`potflat.mesh.distortion.ZONE_THRESHOLD`;
        none without a painted zone)."""
        V, F = self.flat.mesh.vertices, self.flat.mesh.faces
        seam, edge = boundary_segments(V, F)
        outline = (np.zeros((0, 2, 3), np.float32) if self.flat.importance is None
                   else level_segments(V, F, self.flat.importance, ZONE_THRESHOLD))
        return {"seam": seam, "edge": edge, "outline": outline}

    def whole(self) -> WholeScan:
        """The whole scan (the file the rollout read, as loaded) for the page: made once, by the
        first caller, under its own lock (the links' lookups stay free meanwhile)."""
        with self._whole_lock:
            if self._whole is None:
                self._whole = self._load_whole()
            return self._whole

    def _load_whole(self) -> WholeScan:
        from potflat.io.scan import load_scan

        given = self.rollout.get("input")
        if not given:
            return WholeScan(None, None, "", f"{self.name}.rollout.json does not name its scan")
        scan = Path(given)
        options = (self.rollout.get("provenance") or {}).get("options") or {}
        try:  # as the rollout loaded it, without the cleaning (stray pieces are part of the scan too)
            mesh = load_scan(scan, units=options.get("units"), texture="use" if options.get("texture", True) else "ignore",
                             clean=False).mesh
            display = scan_display_mesh(mesh, rows_in(mesh.vertices, self.flat.mesh.vertices))
            texture = texture_jpeg(mesh.texture_path) if display.texcoords is not None else None
        except PotflatError as exc:
            return WholeScan(None, None, str(scan), str(exc).splitlines()[0])
        return WholeScan(display, texture, str(scan), "")

    @property
    def pick_tolerance(self) -> float:
        """How far along a pick's ray (scan units) its hit on the full flattening may be from
        the point seen on the vessel (:data:`PICK_CELLS` display cells)."""
        whole = self._whole
        spacing = self._display.spacing + (whole.display.spacing if whole is not None and whole.display else 0.0)
        V = self.flat.mesh.vertices
        return PICK_CELLS * spacing + 1e-6 * float(np.ptp(V, axis=0).max())

    @cached_property
    def _face_figures(self) -> tuple[np.ndarray, np.ndarray]:
        """Each face's largest length error (:func:`potflat.mesh.distortion.length_error`) and anisotropy."""

        fd = face_distortion(self.flat.mesh.vertices, self.flat.uv, self.flat.mesh.faces)
        return length_error(fd), fd.anisotropy

    @cached_property
    def position(self) -> np.ndarray:
        """The 3D point under each pixel (h, w, 3) float32, NaN off the surface: the bake's
        ``NAME.position.tif``, or rendered in memory by the bake's renderer."""
        path = self.folder / f"{self.name}.position.tif"
        shape = (self.grid.height, self.grid.width, 3)
        if path.is_file():
            import tifffile

            try:
                data = tifffile.memmap(path, mode="r")
            except (OSError, ValueError):
                data = tifffile.imread(path)
            if data.shape != shape:
                raise InvalidInputError(f"{path} is {data.shape[1]} x {data.shape[0]} px but {self.name}.png is "
                                        f"{shape[1]} x {shape[0]}; bake the run again")
            return data

        options = self.bake.get("provenance", {}).get("options", {})
        r = Renderer(self.flat, self.grid.px_per_mm, supersample=int(options.get("supersample") or 0),
                     max_megapixels=float(options.get("max_megapixels") or 1000.0), distortion_maps=False)
        if (r.grid.width, r.grid.height) != (self.grid.width, self.grid.height):
            raise InvalidInputError(f"{self.name}.bake.json does not match {self.name}.relaxed.ply; bake the run "
                                    "again (with --position-map)")
        out = np.empty(shape, np.float32)
        for r0, r1 in r.strips():
            out[r0:r1] = r.position(r0, r1)
        return out

    @cached_property
    def _flat_tree(self):
        from scipy.spatial import cKDTree

        F = self.flat.mesh.faces
        return cKDTree(self.pixels[F].mean(axis=1), **TREE)

    @cached_property
    def _surface_tree(self):
        from scipy.spatial import cKDTree

        V, F = self.flat.mesh.vertices, self.flat.mesh.faces
        return cKDTree(V[F].mean(axis=1), **TREE)

    @cached_property
    def geodesics(self):
        """The :class:`potflat.view.geodesic.SurfaceGraph` of the scan's surface."""

        return SurfaceGraph(self.flat.mesh.vertices, self.flat.mesh.faces)

    def warm(self) -> None:
        """Build the lookups a first click needs (in a background thread after the page opened)."""
        for part in ("_display", "lines", "position", "_flat_tree", "_surface_tree", "_face_figures"):
            with self._lock:
                getattr(self, part)
        self.whole()
        with self._lock:
            self.geodesics  # noqa: B018 - the measure's (made on first use)

    # ---------------------------------------------------------------- the links
    def locate_pixel(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The faces under image points and their barycentric coordinates.

        Parameters
        ----------
        xy : (k, 2) float64
            Image positions (column, row).

        Returns
        -------
        face : (k,) int64
            The face containing each point, -1 where none does (off the surface).
        bary : (k, 3) float64
        point : (k, 3) float64
            The surface point (scan coordinates), NaN off the surface.
        """
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        F = self.flat.mesh.faces
        with self._lock:
            tree = self._flat_tree
        k = min(LOCATE_CANDIDATES, len(F))
        _, cand = tree.query(xy, k=k)
        cand = np.asarray(cand, np.int64).reshape(len(xy), k)
        face = np.full(len(xy), -1, np.int64)
        bary = np.full((len(xy), 3), np.nan)
        for j in range(k):
            P = self.pixels[F[cand[:, j]]]
            lam = _barycentric_2d(xy, P)
            ok = (face < 0) & (lam.min(axis=1) >= -1e-9)
            face[ok], bary[ok] = cand[ok, j], lam[ok]
        point = np.full((len(xy), 3), np.nan)
        on = face >= 0
        point[on] = np.einsum("ij,ijk->ik", bary[on], self.flat.mesh.vertices[F[face[on]]])
        return face, bary, point

    def pixel_to_surface(self, x: float, y: float) -> dict | None:
        """The vessel's point under image point ``(x, y)`` (pixels): the position map's value at
        that pixel, with the readout; None off the surface or outside the image."""
        if not (math.isfinite(x) and math.isfinite(y) and 0 <= x < self.grid.width and 0 <= y < self.grid.height):
            return None
        with self._lock:
            position = self.position
        point = np.asarray(position[int(y), int(x)], np.float64)
        if not np.isfinite(point).all():
            return None
        face, bary, _ = self.locate_pixel(np.array([[math.floor(x) + 0.5, math.floor(y) + 0.5]]))
        return self.readout(int(face[0]), point, np.array([x, y]))

    def ray_to_surface(self, origin, direction, near, hint=None, depth=None) -> dict | None:
        """Cast a ray on the full mesh near ``near`` (where it hit the display mesh).

        Parameters
        ----------
        origin, direction : (3,) float
            The ray (scan coordinates).
        near : (3,) float
            The display mesh's hit point.
        hint : (2,) float, optional
            The display mesh's flat position there (pixels): of two hits at the same depth (the
            seam's two sides), the one nearer to it.
        depth : float, optional
            Distance along the ray (scan units) to the surface seen on the vessel (the whole scan's display
            mesh): a hit farther or nearer than :attr:`pick_tolerance` is another part of the
            vessel than the one seen there (seen: a part left out of the flattening).

        Returns
        -------
        dict or None
            The readout of the hit (:meth:`readout`), None when the ray misses the candidates
            or the surface seen is not in the flattening.
        """
        o = np.asarray(origin, np.float64).reshape(3)
        d = np.asarray(direction, np.float64).reshape(3)
        d = d / max(np.linalg.norm(d), 1e-300)
        V, F = self.flat.mesh.vertices, self.flat.mesh.faces
        with self._lock:
            tree = self._surface_tree
        k = min(PICK_CANDIDATES, len(F))
        _, cand = tree.query(np.asarray(near, np.float64).reshape(1, 3), k=k)
        cand = np.asarray(cand, np.int64).reshape(-1)
        t, lam = _ray_triangles(o, d, V[F[cand]])
        hit = np.isfinite(t)
        if not hit.any():
            return None
        t_min = t[hit].min()
        if depth is not None and abs(t_min - float(depth)) > self.pick_tolerance:
            return None
        near_hits = np.flatnonzero(hit & (t <= t_min + 1e-9 * max(1.0, abs(t_min))))
        best = near_hits[0]
        pix = np.einsum("ij,ijk->ik", lam[near_hits], self.pixels[F[cand[near_hits]]])
        if hint is not None and len(near_hits) > 1:
            best = near_hits[int(np.argmin(np.linalg.norm(pix - np.asarray(hint, np.float64), axis=1)))]
        face = int(cand[best])
        point = lam[best] @ V[F[face]]
        return self.readout(face, point, lam[best] @ self.pixels[F[face]])

    def readout(self, face: int, point: np.ndarray, pixel: np.ndarray) -> dict:
        """What the page shows of a point: where it is on the image and on the vessel (mm), the
        local length error and anisotropy (of its face), the angle about the axis."""
        mm = self.grid.mm_per_unit
        out = {"pixel": [float(pixel[0]), float(pixel[1])],
               "image_mm": [float(pixel[0]) / self.grid.px_per_mm, float(pixel[1]) / self.grid.px_per_mm],
               "point": [float(c) for c in point], "point_mm": [float(c) * mm for c in point], "face": face,
               "length_error_pct": None, "anisotropy": None, "painted": None, "angle_deg": self.angle_deg(point)}
        if face >= 0:
            with self._lock:
                error, anisotropy = self._face_figures
            out["length_error_pct"] = 100.0 * float(error[face])
            out["anisotropy"] = float(anisotropy[face])
            if self.flat.importance is not None:
                out["painted"] = bool(self.flat.importance[self.flat.mesh.faces[face]].mean() >= 0.5)
        return out

    def angle_deg(self, point: np.ndarray) -> float | None:
        """Angle of ``point`` about the rollout's axis from its reference direction, degrees in
        ``[0, 360)`` (None without ``NAME.rollout.json``)."""
        about = self._about_axis(point)
        return None if about is None else float(np.degrees(about[1]))

    def radius(self, point: np.ndarray) -> float | None:
        """Distance of ``point`` from the rollout's axis, scan units (None without the axis)."""
        about = self._about_axis(point)
        return None if about is None else about[0]

    def _about_axis(self, point: np.ndarray) -> tuple[float, float] | None:
        """Radius and angle (radians) of ``point`` about the rollout's axis."""

        axis = self.rollout.get("axis") or {}
        try:
            _, r, theta = cylindrical(np.asarray(point, np.float64).reshape(1, 3), np.asarray(axis["point"]),
                                      np.asarray(axis["direction"]), np.asarray(axis["reference_direction"]))
        except (KeyError, TypeError, ValueError):
            return None
        return float(r[0]), float(theta[0])

    def measure(self, a: tuple[float, float], b: tuple[float, float]) -> dict | None:
        """Two points of the image: their distance on the image and on the vessel, mm.

        Returns
        -------
        dict or None
            ``image_mm``, ``surface_mm`` (the shortest path through the surface), ``chord_mm``
            (the straight line in 3D), ``error_pct`` (how far the image's length is off),
            ``path`` (the surface path, scan coordinates), ``method``; None when a point is off
            the surface.
        """
        ends = [self.pixel_to_surface(*p) for p in (a, b)]
        if any(e is None or e["face"] < 0 for e in ends):
            return None
        mm = self.grid.mm_per_unit
        pa, pb = (np.asarray(e["point"]) for e in ends)
        with self._lock:
            graph = self.geodesics
        length, path, method = graph.distance(pa, ends[0]["face"], pb, ends[1]["face"],
                                              self.flat.mesh.faces)
        image_mm = float(math.dist(a, b)) / self.grid.px_per_mm
        surface_mm = length * mm
        return {"a": ends[0], "b": ends[1], "image_mm": image_mm, "surface_mm": surface_mm,
                "chord_mm": float(np.linalg.norm(pa - pb)) * mm,
                "error_pct": 100.0 * (image_mm / surface_mm - 1.0) if surface_mm > 0 else None,
                "path": np.asarray(path, np.float64).tolist(), "method": method}


def _barycentric_2d(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (k, 3) of points ``p`` (k, 2) in triangles ``tri`` (k, 3, 2)."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    v0, v1, v2 = b - a, c - a, p - a
    den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
    den = np.where(np.abs(den) > 0, den, np.nan)
    s = (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / den
    t = (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / den
    return np.stack([1.0 - s - t, s, t], axis=1)


def _ray_triangles(o: np.ndarray, d: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Möller-Trumbore: distance along the ray (inf where it misses) and barycentric
    coordinates of the hit on each triangle ``tri`` (k, 3, 3); both sides count."""
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    e1, e2 = b - a, c - a
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-300
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = o - a
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ d) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    eps = 1e-9
    hit = ok & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps) & (t > 0)
    lam = np.stack([1.0 - u - v, u, v], axis=1)
    return np.where(hit, t, np.inf), lam
