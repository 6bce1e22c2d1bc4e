"""Kernels of the file formats: PNG row filtering (the streaming PNG encoder in
:mod:`potflat.io.images`) and the float32 precision of stage PLYs."""
from __future__ import annotations

import numpy as np

from potflat._jit import leaf, parallel, prange


@leaf
def float32_exact(values):
    """Whether every value is a float32 value (survives a round trip through float32, as the
    texture coordinates a stage PLY stores do; NaN does not).

    Parameters
    ----------
    values : (k,) float64

    Returns
    -------
    bool
    """
    for i in range(values.shape[0]):
        v = values[i]
        if np.float64(np.float32(v)) != v:
            return False
    return True


@parallel
def paeth_filter(raw, prev, bpp, out):
    """PNG filter type 4 (Paeth) of a block of rows.

    Parameters
    ----------
    raw : (k, b) uint8
        Raw row bytes.
    prev : (b,) uint8
        The row above the first one (zeros for the first row of the image).
    bpp : int
        Bytes per pixel.
    out : (k, b + 1) uint8
        Output: the filter byte (4) and the filtered bytes of each row.
    """
    k, b = raw.shape
    for r in prange(k):
        out[r, 0] = 4
        for x in range(b):
            a = int(raw[r, x - bpp]) if x >= bpp else 0
            up = int(raw[r - 1, x]) if r > 0 else int(prev[x])
            c = 0
            if x >= bpp:
                c = int(raw[r - 1, x - bpp]) if r > 0 else int(prev[x - bpp])
            p = a + up - c
            pa = abs(p - a)
            pb = abs(p - up)
            pc = abs(p - c)
            if pa <= pb and pa <= pc:
                pred = a
            elif pb <= pc:
                pred = up
            else:
                pred = c
            out[r, x + 1] = (int(raw[r, x]) - pred) & 0xFF
