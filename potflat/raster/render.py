"""A flattening drawn in a true-scale pixel grid: its painting and per-pixel fields.

For every output pixel the flat triangle under it is found (a binned, parallel
rasteriser, :mod:`potflat.raster._kernels`), the per-corner texture coordinates are
interpolated barycentrically and the texture is sampled bilinearly. Anti-aliasing:
each pixel averages ``n x n`` sub-samples (``supersample``; also anti-aliases the
outline, alpha = covered fraction) and, where the texture is still finer than a
sub-sample, a mip level chosen per triangle from its texture-coordinate Jacobian
(trilinear). Sampling per face through its own texture coordinates keeps atlas chart
borders seamless. Vertex-coloured scans bake their colours; untextured scans bake their
relief (:mod:`potflat.mesh.relief`: the height above the surface smoothed, in grey, the
range of most heights spread over the grey levels), and so do the faces of a textured scan
that have no texture coordinates (:attr:`potflat.types.Mesh.untextured_faces`): they never
read the texture, and the texture's mip levels are made from the other faces' charts only.

The pixel grid: ``px_per_mm`` pixels per millimetre, row 0 at the largest ``v`` (the
mouth up), column 0 at the smallest ``u`` (not mirrored); :attr:`Grid.origin` is
the ``uv`` of the top-left pixel corner. Images are rendered in horizontal strips,
so large outputs (hundreds of megapixels) are streamed to disk with a bounded memory
footprint: :class:`Renderer` gives every layer of a strip of rows, which the bake composes
(:mod:`potflat.bake.compose`) and its file stage writes as it goes.
"""
from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.io.images import read_ahead, read_texture
from potflat.mesh import distortion
from potflat.mesh.relief import SMOOTHING_MM, SurfaceRelief, surface_relief
from potflat.mesh.tolerances import DEGENERATE, ROUNDING
from potflat.raster import _kernels as raster
from potflat.raster._kernels import copy_where, halve_masked
from potflat.types import FlatMesh

#: Transparent border around the mesh, in pixels.
PAD_PX = 1
#: Fewest pixels along the painting's longer side: smaller images show nothing (and leave no
#: room for a scale bar); a resolution that small is a mistyped one, or a scan in metres.
MIN_PAINTING_PX = 16
#: Image rows per raster block (the unit of parallel work).
BLOCK_ROWS = 4
#: Sub-samples rendered per strip (bounds the strip buffers to ~100 MB).
STRIP_SAMPLES = 1 << 21
#: Largest automatic supersampling factor (mip levels take over beyond it).
MAX_AUTO_SUPERSAMPLE = 4
#: Automatic supersampling stays below this many sub-samples in the whole image.
AUTO_SUPERSAMPLE_BUDGET = 64e6
#: Percentiles (area-weighted, of the relief's heights) that end the grey range of the relief
#: image: the one further from the median height (the plain surface, mid grey) is black or white.
RELIEF_GREY_PERCENTILES = (1.0, 99.0)
#: Narrowest height range (mm) the grey range is spread over: a smooth scan's rounding is not relief.
RELIEF_MIN_RANGE_MM = 0.01


# --------------------------------------------------------------------------------------
# per-mesh fields


def _chart_mask(texcoords: np.ndarray, height: int, width: int) -> np.ndarray:
    """Texels covered by the texture-space triangles, grown by one texel. Shape (height, width) bool.

    Parameters
    ----------
    texcoords : (m, 3, 2) float64
        OBJ convention (v up).
    height, width : int
        Texture size.
    """

    mask = np.zeros((height, width), np.uint8)
    raster.cover_texcoords(np.ascontiguousarray(texcoords, dtype=np.float64).reshape(-1, 3, 2), ROUNDING, mask)
    import cv2  # here, not at the top: importing cv2 sets LD_LIBRARY_PATH in the environment

    return cv2.dilate(mask, np.ones((3, 3), np.uint8)).view(bool)  # (0 and 1: valid as bool, no copy)


def _halve_masked(img: np.ndarray, valid: np.ndarray, out: np.ndarray) -> np.ndarray:
    """2 x 2 box average over the valid texels only, written into ``out``.

    img : (H, W, C) uint8/uint16, valid : (H, W) bool, out : ((H+1)//2, (W+1)//2, C) same dtype,
    C-contiguous; returns the validity of ``out`` (any valid texel in the block).
    """

    h, w = out.shape[:2]
    out_valid = np.empty((h, w), bool)
    halve_masked(img, np.ascontiguousarray(valid), out, out_valid)
    return out_valid


def _pull_fill(levels: list, valids: list) -> None:
    """Fill each level's texels outside the charts from the next coarser level (in place)."""

    import cv2  # here, not at the top: importing cv2 sets LD_LIBRARY_PATH in the environment

    last, ok = levels[-1], valids[-1]
    if ok.any() and not ok.all():
        last[~ok] = last[ok].mean(axis=0).round().astype(last.dtype)
    for k in range(len(levels) - 2, -1, -1):
        hole = ~valids[k]
        if hole.any():
            up = cv2.resize(levels[k + 1], levels[k].shape[1::-1], interpolation=cv2.INTER_LINEAR)
            copy_where(levels[k], np.ascontiguousarray(up.reshape(levels[k].shape)), hole)


@dataclass(frozen=True)
class Grid:
    """Pixel grid of a flattening."""

    px_per_mm: float
    scale: float  # pixels per scan unit
    origin: np.ndarray  # uv of the top-left pixel corner
    width: int
    height: int


def make_grid(flat: FlatMesh, px_per_mm: float, max_megapixels: float) -> Grid:
    used = np.zeros(len(flat.uv), bool)
    used[flat.mesh.faces.ravel()] = True
    if not used.any():
        raise InvalidInputError(f"{flat.mesh.source or 'the mesh'} has no faces to bake; check the stage file")
    uv = flat.uv[used]
    if not np.isfinite(uv).all():
        raise InvalidInputError(f"{flat.mesh.source or 'the flattening'} has NaN or infinite uv; flatten it again")
    lo, hi = distortion.bounds(uv)
    scale = px_per_mm * flat.mesh.mm_per_unit
    width, height = image_size((hi - lo) * flat.mesh.mm_per_unit, px_per_mm, max_megapixels)
    origin = np.array([lo[0] - PAD_PX / scale, hi[1] + PAD_PX / scale])
    return Grid(px_per_mm, scale, origin, width, height)


def image_size(extent_mm, px_per_mm: float, max_megapixels: float) -> tuple[int, int]:
    """Width and height in pixels of the image of a painting ``extent_mm`` (width, height) wide.

    Raises
    ------
    InvalidOptionError
        When the image would exceed ``max_megapixels`` or the painting would be under
        :data:`MIN_PAINTING_PX` pixels long; the message gives a resolution that works.
    """
    w_mm, h_mm = (float(e) for e in extent_mm)
    width = math.ceil(w_mm * px_per_mm) + 2 * PAD_PX
    height = math.ceil(h_mm * px_per_mm) + 2 * PAD_PX
    if width * height > max_megapixels * 1e6:
        suggest = px_per_mm * math.sqrt(max_megapixels * 1e6 / (width * height)) * 0.99
        raise InvalidOptionError(
            f"{px_per_mm:g} px/mm would make a {width} x {height} image ({width * height / 1e6:.0f} megapixels, "
            f"over the {max_megapixels:g} MP limit, --max-megapixels); use --px-per-mm {suggest:.3g} or less")
    longest = max(w_mm, h_mm)
    if longest * px_per_mm < MIN_PAINTING_PX:
        raise InvalidOptionError(
            f"{px_per_mm:g} px/mm would make the {w_mm:.3g} x {h_mm:.3g} mm painting a {width} x {height} pixel "
            f"image; use --px-per-mm {MIN_PAINTING_PX / max(longest, 1e-300):.3g} or more")
    return width, height


class Renderer:
    """Rasterises a flattening strip by strip and produces every bake layer.

    The strip API: :attr:`grid` (the pixel grid), :meth:`strips` (row ranges ``r0, r1``),
    and per strip :meth:`coverage`, :meth:`painting` (with :meth:`untextured_share`),
    :meth:`scalar` (a distortion map or a per-face field put in :attr:`face_values`),
    :meth:`zone_outline` and :meth:`position`;
    :func:`image_figures` sums them up. Every layer of one strip has ``r1 - r0`` rows of
    ``grid.width`` pixels.

    Parameters
    ----------
    flat : FlatMesh
    px_per_mm : float
    supersample : int
        Sub-samples per pixel side; 0: from the texture's resolution.
    max_megapixels : float
    distortion_maps : bool
        False: the painting only (no distortion maps, no :attr:`summary` or :attr:`zone`).
    summary : DistortionSummary, optional
        ``flat``'s whole-surface figures when the caller has them (``potflat run``: the relax
        stage's, of the same flattening); computed when not given.
    zone : ZoneSummary, optional
        ``flat``'s painted-zone figures (:func:`potflat.mesh.distortion.zone_summary`) when the
        caller has them (the relax stage's); computed when not given.
    reference : SurfaceReference, optional
        The 3D side of ``flat``'s figures (:class:`potflat.mesh.distortion.SurfaceReference` of
        its mesh's vertices and faces) when the caller has it (the relax stage's); built when
        not given.
    relief_mm : float
        Scale (mm) of the smoothed surface the relief is measured against (:attr:`relief`).
    """

    def __init__(self, flat: FlatMesh, px_per_mm: float, *, supersample: int = 0, max_megapixels: float = 1000.0,
                 distortion_maps: bool = True, summary: distortion.DistortionSummary | None = None,
                 zone: distortion.ZoneSummary | None = None,
                 reference: distortion.SurfaceReference | None = None, relief_mm: float = SMOOTHING_MM):
        self.flat = flat
        self.relief_mm = relief_mm
        mesh = flat.mesh
        self.faces = mesh.faces
        self.grid = make_grid(flat, px_per_mm, max_megapixels)
        g = self.grid
        untextured = mesh.untextured_faces
        textured = mesh.texcoords is not None and mesh.texture_path is not None and (untextured is None
                                                                                     or not untextured.all())
        # the texture is decoded on a second core while the distortion maps are computed
        with read_ahead(mesh.texture_path if textured else None, rgb=True):
            if distortion_maps:
                if reference is None:
                    reference = distortion.SurfaceReference(mesh.vertices, self.faces)  # the 3D side once
                elif not reference.describes(mesh.vertices, self.faces):
                    raise InvalidInputError("the surface reference handed to the bake is not of the flattening's "
                                            "mesh; hand the relax stage's for its own result, or none")
                # the map's per-face and per-edge figures once, for the summaries and the maps
                fd = reference.face_distortion(flat.uv)
                edge_error = reference.edge_length_error(flat.uv)
                self.summary = summary if summary is not None else reference.summarize(
                    flat.uv, fd=fd, edge_error=edge_error)
                self.zone = zone if zone is not None else distortion.zone_summary(
                    mesh.vertices, flat.uv, self.faces, flat.importance, reference=reference, fd=fd,
                    edge_error=edge_error)
                self.area_3d, self.area_2d, self.valid = fd.area_3d, fd.area_2d, fd.valid
                self.face_values = {"area": fd.log_area_ratio, "anisotropy": np.minimum(fd.anisotropy, 1e6)}
                self.vertex_stress = flat.stress if flat.stress is not None else reference.vertex_stress(
                    flat.uv, mesh.mm_per_unit)
                # the stress map shows it in words people read: % length error around each point
                self.vertex_length_error = reference.vertex_length_error(flat.uv, edge_error=edge_error)
                del reference, fd, edge_error
            self.texture = read_texture(mesh.texture_path) if textured else None
        pix = np.empty_like(flat.uv)
        pix[:, 0] = (flat.uv[:, 0] - g.origin[0]) * g.scale
        pix[:, 1] = (g.origin[1] - flat.uv[:, 1]) * g.scale
        self.texels_per_pixel = None
        self.texels_per_pixel_median = None
        if self.texture is not None:
            self.texels_per_pixel = self._texel_ratio(pix)
            self.texels_per_pixel_median = float(np.median(
                self.texels_per_pixel if untextured is None else self.texels_per_pixel[~untextured]))
        #: whether some faces of a textured painting are drawn as relief (untextured faces)
        self.has_untextured = self.texture is not None and untextured is not None
        # the kernel's flag of those faces: always an array (all False without them)
        self._untextured = untextured if self.has_untextured else np.zeros(len(self.faces), bool)
        n = supersample
        if n == 0:
            ratio = self.texels_per_pixel_median if self.texels_per_pixel_median is not None else 1.0
            n = int(np.clip(math.ceil(ratio - 0.01), 2, MAX_AUTO_SUPERSAMPLE))
            while n > 1 and g.width * g.height * n * n > AUTO_SUPERSAMPLE_BUDGET:
                n -= 1
        self.n = n
        self.mip_levels = 0
        self.lod = None
        if self.texture is not None:
            self._build_mips()
        self._pix = np.ascontiguousarray(pix * n)
        self._block = BLOCK_ROWS * n
        nblocks = (g.height * n + self._block - 1) // self._block
        self._ptr, self._idx = raster.bin_triangles(self._pix, self.faces, float(self._block), nblocks)
        self._raster_mod = raster
        self._cache = None
        self._face_cache = self._vertex_cache = None  # the strip's fields (_face_fields, _vertex_fields)
        self._face_columns = None  # face_values stacked (m, d), with their names
        self._vertex_paint = None  # per-vertex colours of a vertex-coloured painting, made on first use
        self._relief_cache = None  # the strip's relief fields (relief_fields)

    # -- setup ---------------------------------------------------------------------
    def _texel_ratio(self, pix: np.ndarray) -> np.ndarray:
        """Texels per output pixel (largest singular value of the pixel-to-texel map) per face."""

        H0, W0 = self.texture.shape[:2]
        out = np.empty(len(self.faces))
        raster.texel_ratio(pix, self.faces, self.flat.mesh.texcoords, H0, W0, DEGENERATE, out)
        return out

    def _build_mips(self) -> None:
        """Mip levels down to the coarsest level any face needs.

        Each level averages the texels of the level above that lie in an atlas chart
        (the texture-space footprint of the textured triangles, grown by one texel), and the texels
        outside every chart are then filled from the coarser levels (push-pull), so a
        coarse tap at a chart border never mixes in the atlas background: no seams.
        """
        lod = np.log2(np.maximum(self.texels_per_pixel / self.n, 1.0))
        top = math.ceil(min(np.max(lod), math.log2(max(min(self.texture.shape[:2]), 1))))
        shapes = [self.texture.shape[:2]]
        for _ in range(top):
            shapes.append(((shapes[-1][0] + 1) // 2, (shapes[-1][1] + 1) // 2))
        channels = self.texture.shape[2]
        sizes = [h * w * channels for h, w in shapes[1:]]
        # the levels are made in place in one buffer, the kernel's (no copy of them at the peak)
        mips = np.empty(max(1, sum(sizes)), self.texture.dtype)
        starts = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        levels = [mips[a:a + n].reshape(h, w, channels) for a, n, (h, w) in zip(starts, sizes, shapes[1:])]
        if top > 0:
            tc = self.flat.mesh.texcoords
            cur, valid = self.texture, _chart_mask(tc[~self._untextured] if self.has_untextured else tc,
                                                   *self.texture.shape[:2])
            valids = []
            for level in levels:
                valid = _halve_masked(cur, valid, level)
                cur = level
                valids.append(valid)
            _pull_fill(levels, valids)
        self.mip_levels = top
        self._mip_shapes = np.array(shapes, np.int64).reshape(-1, 2)
        self._mip_offsets = np.concatenate([[0], starts[:-1]]).astype(np.int64)
        self._mips = mips
        self.lod = np.ascontiguousarray(lod)

    # -- strips --------------------------------------------------------------------
    def strips(self) -> Iterator[tuple[int, int]]:
        """Pixel row ranges ``(r0, r1)`` covering the image, each a whole number of blocks."""
        g = self.grid
        rows = max(BLOCK_ROWS, (STRIP_SAMPLES // max(1, g.width * self.n * self.n)) // BLOCK_ROWS * BLOCK_ROWS)
        for r0 in range(0, g.height, rows):
            yield r0, min(g.height, r0 + rows)

    def _raster(self, r0: int, r1: int):
        if self._cache is not None and self._cache[0] == (r0, r1):
            return self._cache[1]
        n, g = self.n, self.grid
        face = np.full(((r1 - r0) * n, g.width * n), -1, np.int32)
        bary = np.empty(face.shape + (2,), np.float64)  # read only where a face is
        self._raster_mod.rasterize_rows(self._pix, self.faces, self._ptr, self._idx, self._block, r0 * n,
                                        face.shape[0], face.shape[1], ROUNDING, face, bary)
        self._cache = ((r0, r1), (face, bary))
        return face, bary

    def coverage(self, r0: int, r1: int) -> np.ndarray:
        """Covered fraction of each pixel. Shape (k, w) float32."""
        face, _ = self._raster(r0, r1)
        out = np.empty((r1 - r0, self.grid.width), np.float32)
        self._raster_mod.coverage(face, self.n, out)
        return out

    def _vertex_field(self, values: np.ndarray, r0: int, r1: int) -> np.ndarray:
        face, bary = self._raster(r0, r1)
        attr = np.ascontiguousarray(values.reshape(len(values), -1), dtype=np.float64)
        out = np.empty((r1 - r0, self.grid.width, attr.shape[1]), np.float32)
        self._raster_mod.interpolate_vertex_attr(face, bary, self.faces, attr, self.n, out)
        return out

    def painting(self, r0: int, r1: int, *, relief_on_untextured: bool = True) -> np.ndarray:
        """RGB in [0, 1] (NaN outside). Shape (k, w, 3) float32.

        ``relief_on_untextured``: the sub-samples on untextured faces of a textured painting
        are relief in grey (True: the painting's pixels), or are left out (False: a pixel is the
        mean of its textured sub-samples, NaN where it has none; the colour evidence alone,
        with :meth:`untextured_share` to leave those pixels uncovered).
        """
        face, bary = self._raster(r0, r1)
        mesh = self.flat.mesh
        if self.texture is not None:
            out = np.empty((r1 - r0, self.grid.width, 3), np.float32)
            self._raster_mod.sample_texture(face, bary, mesh.texcoords, self._untextured, self.lod,
                                            self.texture.reshape(-1), self._mips, self._mip_offsets,
                                            self._mip_shapes, self.n, out)
            out /= np.float32(np.iinfo(self.texture.dtype).max)
            if self.has_untextured and relief_on_untextured:
                share = self.untextured_share(r0, r1)
                mixed = share > 0.0  # (NaN outside: False)
                if mixed.any():
                    s = share[mixed][:, None]
                    out[mixed] = np.nan_to_num(out[mixed]) * (1.0 - s) + self.relief_grey(r0, r1)[mixed][:, None] * s
            return out
        if mesh.vertex_colors is not None:
            if self._vertex_paint is None:
                self._vertex_paint = mesh.vertex_colors[:, :3] / 255.0
            return self._vertex_field(self._vertex_paint, r0, r1)
        return np.repeat(self.relief_grey(r0, r1)[..., None], 3, axis=-1)

    @property
    def paints_relief(self) -> bool:
        """Whether :meth:`painting` is the relief in grey (an untextured scan without colours)."""
        return self.texture is None and self.flat.mesh.vertex_colors is None

    @cached_property
    def relief(self) -> SurfaceRelief:
        """The scan's relief against itself smoothed at :attr:`relief_mm`, per vertex (made on first use)."""
        mesh = self.flat.mesh
        return surface_relief(mesh.vertices, self.faces, self.flat.uv, smoothing_mm=self.relief_mm,
                              mm_per_unit=mesh.mm_per_unit)

    @cached_property
    def relief_grey_range(self) -> tuple[float, float]:
        """The heights (mm) drawn black and white in :meth:`relief_grey`: the median height
        (mid grey) less and plus the larger of its distances to the
        :data:`RELIEF_GREY_PERCENTILES` of the heights, at least :data:`RELIEF_MIN_RANGE_MM` apart."""
        lo, mid, hi = self.relief.height_percentiles((RELIEF_GREY_PERCENTILES[0], 50.0, RELIEF_GREY_PERCENTILES[1]))
        half = max(mid - lo, hi - mid, 0.5 * RELIEF_MIN_RANGE_MM)
        return mid - half, mid + half

    def relief_fields(self, r0: int, r1: int) -> np.ndarray:
        """The relief's per-vertex fields of the strip (:attr:`potflat.mesh.relief.SurfaceRelief.columns`:
        height in mm, the normal in the smoothed surface's frame, concavity), NaN outside. Shape
        (k, w, 5) float32, from one pass over the strip's sub-samples (kept for its other layers)."""
        if self._relief_cache is None or self._relief_cache[0] != (r0, r1):
            self._relief_cache = (r0, r1), self._vertex_field(self.relief.columns, r0, r1)
        return self._relief_cache[1]

    def relief_grey(self, r0: int, r1: int) -> np.ndarray:
        """The relief's height in grey: :attr:`relief_grey_range` spread over [0, 1] (clipped
        beyond; NaN outside). Shape (k, w) float32."""
        lo, hi = self.relief_grey_range
        grey = (self.relief_fields(r0, r1)[..., 0] - np.float32(lo)) * np.float32(1.0 / (hi - lo))
        return np.clip(grey, 0.0, 1.0, out=grey)

    def untextured_share(self, r0: int, r1: int) -> np.ndarray:
        """Share of each pixel's covered sub-samples that lie on untextured faces of a textured
        painting (0 everywhere without such faces, :attr:`has_untextured`; NaN outside).
        Shape (k, w) float32."""
        return self._face_field(self._untextured_value, r0, r1)[..., 0]

    def _face_field(self, values: np.ndarray, r0: int, r1: int) -> np.ndarray:
        """Per-face ``values`` ((m, d) float64) averaged per pixel. Shape (k, w, d) float32."""
        face, _ = self._raster(r0, r1)
        out = np.empty((r1 - r0, self.grid.width, values.shape[1]), np.float32)
        self._raster_mod.face_values(face, values, self.n, out)
        return out

    @cached_property
    def _untextured_value(self) -> np.ndarray:
        """The untextured-face flag as a face value (m, 1) float64 (0 or 1), made on first use."""
        return self._untextured.astype(np.float64)[:, None]

    def _face_fields(self, r0: int, r1: int) -> dict[str, np.ndarray]:
        """Every :attr:`face_values` field of the strip by name, (k, w) float32 each, from one
        pass over its sub-samples (kept for the strip's other layers)."""
        names = tuple(self.face_values)
        if self._face_cache is not None and self._face_cache[0] == (r0, r1, names):
            return self._face_cache[1]
        if self._face_columns is None or self._face_columns[0] != names:  # a field added since: stacked again
            self._face_columns = names, np.ascontiguousarray(
                np.stack([self.face_values[k] for k in names], axis=1), dtype=np.float64)
        both = self._face_field(self._face_columns[1], r0, r1)
        found = {k: np.ascontiguousarray(both[..., j]) for j, k in enumerate(names)}
        self._face_cache = (r0, r1, names), found
        return found

    def _vertex_fields(self, r0: int, r1: int) -> tuple[np.ndarray, np.ndarray | None]:
        """The stress map's values and the importance (None without) of the strip, (k, w)
        float32 each, from one pass over its sub-samples (kept for the strip's other layers)."""
        if self._vertex_cache is not None and self._vertex_cache[0] == (r0, r1):
            return self._vertex_cache[1]
        both = self._vertex_field(self._vertex_columns, r0, r1)
        found = (np.ascontiguousarray(both[..., 0]),
                 np.ascontiguousarray(both[..., 1]) if self.flat.importance is not None else None)
        self._vertex_cache = (r0, r1), found
        return found

    @cached_property
    def _vertex_columns(self) -> np.ndarray:
        """The stress map's values and the importance (when there is one) as columns (n, 1 or 2)
        float64, stacked once for every strip."""
        importance = self.flat.importance
        return np.stack([self.vertex_length_error] + ([importance] if importance is not None else []), axis=1)

    def scalar(self, name: str, r0: int, r1: int) -> np.ndarray:
        """A distortion map's values (NaN outside). Shape (k, w) float32."""
        return self._vertex_fields(r0, r1)[0] if name == "stress" else self._face_fields(r0, r1)[name]

    def zone_outline(self, r0: int, r1: int) -> np.ndarray | None:
        """Pixels on the outline of the important zone (importance crossing
        :data:`potflat.mesh.distortion.ZONE_THRESHOLD`), shape (k, w) bool; None without importance."""
        if self.flat.importance is None:
            return None
        return outline_pixels(self._vertex_fields(r0, r1)[1], distortion.ZONE_THRESHOLD)

    def position(self, r0: int, r1: int) -> np.ndarray:
        """3D point under each pixel, scan units (NaN outside). Shape (k, w, 3) float32."""
        return self._vertex_field(self.flat.mesh.vertices, r0, r1)


# --------------------------------------------------------------------------------------
# figures


# --------------------------------------------------------------------------------------
# library entry point


def paint(flat: FlatMesh, px_per_mm: float, *, supersample: int = 2,
          leave_out_untextured: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The painting of a flattening alone (no distortion maps or figures), in memory.

    Parameters
    ----------
    flat : FlatMesh
    px_per_mm : float
    supersample : int
        Sub-samples per pixel side (1-8).
    leave_out_untextured : bool
        False: untextured faces of a textured scan are drawn as relief in grey, as :func:`bake`
        draws them. True: they count as not covered (alpha 0 for their share of a pixel, whose
        colour is then its textured part's alone): the colour evidence of the painting only.

    Returns
    -------
    image : (h, w, 4) uint8
        RGBA, alpha the covered fraction; the pixel grid of :func:`bake`.
    origin : (2,) float64
        ``(u, v)`` of the top-left pixel corner (:attr:`BakeResult.origin`).
    """
    r = Renderer(flat, px_per_mm, supersample=supersample, distortion_maps=False)
    g = r.grid
    leave_out = leave_out_untextured and r.has_untextured
    image = np.zeros((g.height, g.width, 4), np.uint8)
    for r0, r1 in r.strips():
        coverage = r.coverage(r0, r1)
        if leave_out:
            coverage *= 1.0 - np.nan_to_num(r.untextured_share(r0, r1), nan=0.0)
        image[r0:r1] = rgba8(r.painting(r0, r1, relief_on_untextured=not leave_out), coverage)
    return image, g.origin.copy()


def fill_faces(pixels: np.ndarray, faces: np.ndarray, height: int, width: int) -> np.ndarray:
    """The pixels whose centre lies in one of ``faces``: a mask of whole faces, without
    anti-aliasing (for a painting and its fields, :class:`Renderer`).

    Parameters
    ----------
    pixels : (n, 2) float
        Flat positions in pixels (column, row; ``(0, 0)`` the top-left corner of the image).
    faces : (k, 3) int64
        The faces to fill.
    height, width : int
        Image size.

    Returns
    -------
    (height, width) bool
    """
    import cv2  # here, not at the top: importing cv2 sets LD_LIBRARY_PATH in the environment

    mask = np.zeros((height, width), np.uint8)
    if len(faces):
        # pixel centres at integer positions for OpenCV, with 4 fractional bits
        corners = np.round((np.asarray(pixels, np.float64)[faces] - 0.5) * 16).astype(np.int32)
        cv2.fillPoly(mask, list(corners), 1, lineType=cv2.LINE_8, shift=4)
    return mask.astype(bool)


def rgba8(rgb: np.ndarray, coverage: np.ndarray) -> np.ndarray:
    """(k, w, 3) float in [0, 1] (NaN outside) and coverage -> (k, w, 4) uint8."""
    out = np.empty(rgb.shape[:2] + (4,), np.uint8)
    out[..., :3] = np.rint(np.clip(np.nan_to_num(rgb, nan=0.0), 0.0, 1.0) * 255.0)
    out[..., 3] = np.rint(coverage * 255.0)
    return out


# --------------------------------------------------------------------------------------
# marks and the scale bar drawn into the painting (used strip by strip by the file stage)


def outline_pixels(field: np.ndarray, threshold: float) -> np.ndarray:
    """Pixels (k, w) bool on the outline of where ``field`` (k, w, NaN outside) is at least ``threshold``."""
    import cv2  # here, not at the top: importing cv2 sets LD_LIBRARY_PATH in the environment

    inside = (np.nan_to_num(field, nan=0.0) >= threshold).astype(np.uint8)
    ring = np.ones((3, 3), np.uint8)
    edge = cv2.dilate(inside, ring, borderType=cv2.BORDER_REPLICATE) & ~cv2.erode(
        inside, ring, borderType=cv2.BORDER_REPLICATE)
    return edge.astype(bool) & np.isfinite(field)
