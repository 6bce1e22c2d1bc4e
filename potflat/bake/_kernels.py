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
