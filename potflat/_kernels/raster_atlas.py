"""Rasterise triangles into a pixel grid: which face covers each pixel centre, and where.

Used by :mod:`potflat.synthetic` to paint a texture atlas texel by texel.
"""
from __future__ import annotations

import numpy as np

from potflat._kernels._jit import leaf


@leaf
def rasterize_faces(tri, height, width):
    """Face index and barycentric coordinates of every covered pixel centre.

    Parameters
    ----------
    tri : (m, 3, 2) float64
        Triangle corners in pixel units, ``(column, row)``; pixel ``(i, j)`` has its centre
        at ``(j + 0.5, i + 0.5)``.
    height, width : int
        Size of the pixel grid.

    Returns
    -------
    face : (height, width) int64
        Index of the triangle covering the pixel centre, ``-1`` where none does. Where
        triangles share an edge the later one wins (serial loop: deterministic).
    bary : (height, width, 3) float64
        Barycentric coordinates of the pixel centre in that triangle.
    """
    face = np.full((height, width), -1, np.int64)
    bary = np.zeros((height, width, 3), np.float64)
    eps = 1e-9
    for f in range(tri.shape[0]):
        x0, y0 = tri[f, 0, 0], tri[f, 0, 1]
        x1, y1 = tri[f, 1, 0], tri[f, 1, 1]
        x2, y2 = tri[f, 2, 0], tri[f, 2, 1]
        det = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if det == 0.0:
            continue
        jlo = max(int(np.floor(min(x0, x1, x2) - 0.5)), 0)
        jhi = min(int(np.ceil(max(x0, x1, x2) - 0.5)), width - 1)
        ilo = max(int(np.floor(min(y0, y1, y2) - 0.5)), 0)
        ihi = min(int(np.ceil(max(y0, y1, y2) - 0.5)), height - 1)
        for i in range(ilo, ihi + 1):
            py = i + 0.5
            for j in range(jlo, jhi + 1):
                px = j + 0.5
                b1 = ((px - x0) * (y2 - y0) - (x2 - x0) * (py - y0)) / det
                b2 = ((x1 - x0) * (py - y0) - (px - x0) * (y1 - y0)) / det
                b0 = 1.0 - b1 - b2
                if b0 >= -eps and b1 >= -eps and b2 >= -eps:
                    face[i, j] = f
                    bary[i, j, 0] = b0
                    bary[i, j, 1] = b1
                    bary[i, j, 2] = b2
    return face, bary
