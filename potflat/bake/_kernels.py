"""Kernels of the bake's images: the distortion maps' colours over the painting."""
from __future__ import annotations

import numpy as np

from potflat._jit import parallel, prange


@parallel
def heat_rgba(values, lo, hi, lut, coverage, grey, mix, out):
    """Colour-map values into RGBA rows, optionally blended over a greyscale painting.

    Parameters
    ----------
    values : (k, w) float32
        NaN where nothing is covered.
    lo, hi : float
        Values mapped to the first and last colour (clipped beyond).
    lut : (256, 3) uint8
        Colour table.
    coverage : (k, w) float32
        Alpha in [0, 1].
    grey : (k, w) float32
        Painting luminance in [0, 1] (used when ``mix`` < 1).
    mix : float
        Opacity of the heat colour over ``grey`` (1: plain heat map).
    out : (k, w, 4) uint8
    """
    k, w = values.shape
    scale = 255.0 / (hi - lo)
    for r in prange(k):
        for c in range(w):
            v = values[r, c]
            t = 0.0 if np.isnan(v) else min(max((v - lo) * scale, 0.0), 255.0)
            idx = np.uint64(t + 0.5)
            g = grey[r, c] * 255.0 if mix < 1.0 else 0.0
            if np.isnan(g):
                g = 0.0
            for ch in range(3):
                x = mix * lut[idx, ch] + (1.0 - mix) * g
                out[r, c, ch] = int(min(max(x, 0.0), 255.0) + 0.5)
            out[r, c, 3] = int(coverage[r, c] * 255.0 + 0.5)


@parallel
def relief_rows(fields, coverage, lights, gain, curve_hi, curve_span, rgb, grey_lo, grey_scale, blend, painted,
                mm_per_level, zero_level, raking, curvature, overlay, levels):
    """The relief's images of a strip in one pass.

    Parameters
    ----------
    fields : (k, w, 5) float32
        Height (mm), the scan's normal in the smoothed frame (3), concavity; NaN outside.
    coverage : (k, w) float32
        Alpha in [0, 1].
    lights : (a, 3) float64
        Unit light directions in the frame (image right, image up, out).
    gain : float
        Grey per unit of ``normal . light`` (a plane mid grey).
    curve_hi, curve_span : float
        Concavity drawn black, and the span to the one drawn white.
    rgb : (k, w, 3) float32
        The painting in [0, 1] (NaN outside; read when ``painted``).
    grey_lo, grey_scale : float
        Height drawn black and grey per mm in the relief's grey.
    blend : float
        The relief's share of the overlay.
    painted : bool
    mm_per_level : float
    zero_level : int
        The TIFF's scale: level = round(height / mm_per_level) + zero_level.
    raking : (a, k, w, 2) uint8
        Output: grey and alpha per light.
    curvature : (k, w, 2) uint8
        Output: grey and alpha.
    overlay : (k, w, 4) uint8
        Output (when ``painted``): the painting and the relief's grey blended, RGBA.
    levels : (k, w) uint16
        Output: the TIFF's levels, 0 outside.
    """
    k, w = coverage.shape
    for r in prange(k):
        for c in range(w):
            alpha = np.uint8(np.rint(coverage[r, c] * 255.0))
            h = fields[r, c, 0]
            inside = not np.isnan(h)
            nx = fields[r, c, 1]
            ny = fields[r, c, 2]
            nz = fields[r, c, 3]
            length = np.sqrt(nx * nx + ny * ny + nz * nz) if inside else 0.0
            for a in range(lights.shape[0]):
                shade = 0.0
                if length > 0.0:
                    shade = (nx * lights[a, 0] + ny * lights[a, 1] + nz * lights[a, 2]) / length * gain
                raking[a, r, c, 0] = np.uint8(np.rint(min(max(shade, 0.0), 1.0) * 255.0))
                raking[a, r, c, 1] = alpha
            t = (curve_hi - fields[r, c, 4]) / curve_span if inside else 0.0
            curvature[r, c, 0] = np.uint8(np.rint(min(max(t, 0.0), 1.0) * 255.0))
            curvature[r, c, 1] = alpha
            if painted:
                grey = min(max((h - grey_lo) * grey_scale, 0.0), 1.0) if inside else 0.0
                for ch in range(3):
                    x = rgb[r, c, ch]
                    x = 0.0 if np.isnan(x) else min(max(x, 0.0), 1.0)
                    overlay[r, c, ch] = np.uint8(np.rint(min(max((1.0 - blend) * x + blend * grey, 0.0), 1.0) * 255.0))
                overlay[r, c, 3] = alpha
            if inside:
                level = np.rint(h / mm_per_level) + zero_level
                levels[r, c] = np.uint16(min(max(level, 0.0), 65535.0))
            else:
                levels[r, c] = 0
