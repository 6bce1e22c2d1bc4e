"""The relief's images, strip by strip on the painting's pixel grid: the height above the
smoothed scan coloured with a legend and as 16-bit levels for a TIFF, raking light from the
azimuths the user sets, the multi-scale concavity (in the spirit of GigaMesh's MSII view), and
the painting and the relief blended. The per-vertex relief is the renderer's
(:attr:`potflat.raster.render.Renderer.relief`, :mod:`potflat.mesh.relief`)."""
from __future__ import annotations

import json
import math

import numpy as np

from potflat.bake import annotate
from potflat.bake._kernels import relief_rows
from potflat.raster.render import RELIEF_GREY_PERCENTILES, RELIEF_MIN_RANGE_MM, Renderer

#: Elevation of the raking light above the smoothed surface, degrees.
RAKING_ELEVATION_DEG = 20.0
#: Percentiles (area-weighted) of the heights, and of the concavity, whose larger magnitude
#: ends the colour scale of ``NAME.relief.png`` and of ``NAME.curvature.png``.
SCALE_PERCENTILES = (1.0, 99.0)
#: Narrowest half range of the concavity's scale (a plane's rounding is not detail).
MIN_CONCAVITY = 0.005
#: The 16-bit level of a height of 0 in ``NAME.relief.tif``; level 0 is no surface.
TIFF_ZERO_LEVEL = 32768


def raking_key(azimuth: float) -> str:
    """The image key (and file infix) of the raking light from ``azimuth`` degrees: ``raking-315``."""
    return f"raking-{azimuth:g}"


def grey_alpha(rgba: np.ndarray) -> np.ndarray:
    """RGBA rows (k, w, 4) uint8 as grey and alpha (k, w, 2) uint8 (luminance of the colours)."""
    out = np.empty(rgba.shape[:2] + (2,), np.uint8)
    out[..., 0] = np.rint(rgba[..., :3] @ np.array([0.299, 0.587, 0.114], np.float32))
    out[..., 1] = rgba[..., 3]
    return out


class ReliefImages:
    """How the relief's images of one bake are drawn.

    Parameters
    ----------
    renderer : Renderer
    lights : tuple of float
        Raking-light azimuths, degrees clockwise from image up.
    blend : float
        Share of the relief in the overlay with the painting.

    Attributes
    ----------
    keys : tuple of str
        The images, in order: ``relief`` (coloured height), one ``raking-AZ`` per azimuth,
        ``curvature`` and, when the scan has a painting, ``relief-overlay``.
    channels : dict of str to int
        4 (RGBA) or 2 (grey and alpha) per image.
    legends : dict of str to (b, w, c) uint8
        The legend band below ``relief`` and ``curvature``.
    mm_per_level : float
        The TIFF's height step: height (mm) = (level - :data:`TIFF_ZERO_LEVEL`) * mm_per_level.
    """

    def __init__(self, renderer: Renderer, *, lights: tuple, blend: float):
        r = self.renderer = renderer
        rel = r.relief
        self.lights = tuple(lights)
        self.blend = float(blend)
        self.painted = not r.paints_relief
        p_lo, p_hi = rel.height_percentiles(SCALE_PERCENTILES)
        half = max(abs(p_lo), abs(p_hi), 0.5 * RELIEF_MIN_RANGE_MM)
        what = f"surface smoothed at {rel.smoothing_mm:.3g} mm"
        self.height_scale = annotate.MapScale("relief", -half, half, "RdBu_r", f"height above the {what}, mm",
                                              extend="both")
        c_lo, c_hi = rel.concavity_percentiles(SCALE_PERCENTILES)
        c_half = max(abs(c_lo), abs(c_hi), MIN_CONCAVITY)
        radii = f"{rel.radii_mm[0]:.2g}-{rel.radii_mm[-1]:.2g}" if len(rel.radii_mm) > 1 else f"{rel.radii_mm[0]:.2g}"
        self.concavity_scale = annotate.MapScale(
            "curvature", -c_half, c_half, "gray_r",
            f"concavity (MSII-like) over {radii} mm: dark grooves, light ridges", extend="both")
        g = r.grid
        self.legends = {"relief": annotate.legend_band(self.height_scale, g.width),
                        "curvature": grey_alpha(annotate.legend_band(self.concavity_scale, g.width))}
        self.keys = ("relief", *(raking_key(a) for a in self.lights), "curvature") + (
            ("relief-overlay",) if self.painted else ())
        self.channels = {k: 2 if k == "curvature" or k.startswith("raking-") else 4 for k in self.keys}
        el = math.radians(RAKING_ELEVATION_DEG)
        self._lights = np.array([[math.sin(math.radians(a)) * math.cos(el), math.cos(math.radians(a)) * math.cos(el),
                                  math.sin(el)] for a in self.lights])
        used = np.zeros(len(rel.height_mm), bool)
        used[r.faces.ravel()] = True
        self.max_abs_mm = max(float(np.abs(rel.height_mm[used]).max()), 1e-9)
        self.mm_per_level = self.max_abs_mm / (TIFF_ZERO_LEVEL - 1)

    def rows(self, r0: int, r1: int, rgb: np.ndarray, coverage: np.ndarray) -> dict[str, np.ndarray]:
        """Rows ``r0:r1`` of every image of :attr:`keys` and, as ``"levels"``, of
        ``NAME.relief.tif`` (the height as 16-bit levels, 0 where no surface is); ``rgb`` (k,
        w, 3) and ``coverage`` (k, w) are the strip's painting and covered fraction."""
        r = self.renderer
        fields = r.relief_fields(r0, r1)
        k, w = coverage.shape
        raking = np.empty((len(self.lights), k, w, 2), np.uint8)
        curvature = np.empty((k, w, 2), np.uint8)
        overlay = np.empty((k, w, 4) if self.painted else (0, 0, 4), np.uint8)
        levels = np.empty((k, w), np.uint16)
        lo, hi = r.relief_grey_range
        sc = self.concavity_scale
        relief_rows(fields, np.ascontiguousarray(coverage, np.float32), self._lights,
                    0.5 / math.sin(math.radians(RAKING_ELEVATION_DEG)), sc.hi, sc.hi - sc.lo,
                    np.ascontiguousarray(rgb, np.float32), lo, 1.0 / (hi - lo), self.blend, self.painted,
                    self.mm_per_level, TIFF_ZERO_LEVEL, raking, curvature, overlay, levels)
        out = {"relief": annotate.colorize(fields[..., 0], self.height_scale, coverage), "curvature": curvature,
               "levels": levels, **{raking_key(a): raking[j] for j, a in enumerate(self.lights)}}
        if self.painted:
            out["relief-overlay"] = overlay
        return out

    def tiff_description(self) -> str:
        """What ``NAME.relief.tif`` holds and its scale, as JSON text for its description tag."""
        return json.dumps({"quantity": "height above the " + self.height_scale.label.split("above the ", 1)[1],
                           "height_mm": f"(level - {TIFF_ZERO_LEVEL}) * {self.mm_per_level!r}",
                           "mm_per_level": self.mm_per_level, "zero_level": TIFF_ZERO_LEVEL, "no_surface_level": 0,
                           "px_per_mm": self.renderer.grid.px_per_mm})

    def figures(self) -> dict:
        """The relief's settings and figures for ``NAME.bake.json``."""
        return relief_figures(self.renderer) | {
            "colour_range_mm": [self.height_scale.lo, self.height_scale.hi],
            "light_azimuth_deg": list(self.lights),
            "light_elevation_deg": RAKING_ELEVATION_DEG,
            "concavity_range": [self.concavity_scale.lo, self.concavity_scale.hi],
            "overlay_blend": self.blend if self.painted else None,
            "tiff": {"zero_level": TIFF_ZERO_LEVEL, "mm_per_level": self.mm_per_level, "no_surface_level": 0,
                     "height_mm": f"(level - {TIFF_ZERO_LEVEL}) * mm_per_level"},
        }


def relief_figures(r: Renderer) -> dict:
    """The relief's settings and height figures (``r``'s relief, made on first use)."""
    rel = r.relief
    p = rel.height_percentiles((0.0, 1.0, 50.0, 99.0, 100.0))
    return {
        "smoothing_mm": rel.smoothing_mm,
        "smoothing_requested_mm": rel.requested_mm,
        "method": ("height above the scan smoothed by robust local quadric fits over the flat layout "
                   f"(Gaussian sigma {rel.smoothing_mm:.3g} mm), along the smoothed surface's normal"),
        "mesh_spacing_mm": rel.spacing_mm,
        "height_mm": {"min": p[0], "p1": p[1], "median": p[2], "p99": p[3], "max": p[4]},
        "grey_range_mm": list(r.relief_grey_range),
        "grey_percentiles": list(RELIEF_GREY_PERCENTILES),
        "concavity_radii_mm": list(rel.radii_mm),
    }
