"""Rasterise triangles into a pixel grid: which face covers each pixel centre, and where.

Used by :mod:`potflat_synthetic.vessels` to paint a texture atlas texel by texel, with a gutter:
pixels within ``pad`` pixels outside the triangles take the nearest point of the nearest
triangle, so bilinear sampling at chart borders never reads the background.
"""
from __future__ import annotations

import numpy as np

from potflat._jit import leaf


@leaf
def rasterize_faces(tri, height, width, pad):
    """Face index and barycentric coordinates of every pixel centre, with a gutter.

    Parameters
    ----------
    tri : (m, 3, 2) float64
        Triangle corners in pixel units, ``(column, row)``; pixel ``(i, j)`` has its centre
        at ``(j + 0.5, i + 0.5)``.
    height, width : int
        Size of the pixel grid.
    pad : float
        Gutter width in pixels: a pixel centre outside every triangle but within ``pad``
        of one gets the nearest triangle and the barycentric coordinates of the nearest
        point on it (``0`` = plain rasterisation).

    Returns
    -------
    face : (height, width) int64
        Index of the triangle covering (or nearest to) the pixel centre, ``-1`` for none.
        A centre inside several triangles (on a shared edge) gets the last one (serial
        loop: deterministic).
    bary : (height, width, 3) float64
        Barycentric coordinates of the pixel centre (or its nearest point) in that
        triangle, each in [0, 1].
    dist : (height, width) float64
        Distance in pixels from the centre to that triangle (0 inside), ``inf`` for none.
    """
    face = np.full((height, width), -1, np.int64)
    bary = np.zeros((height, width, 3), np.float64)
    dist = np.full((height, width), np.inf)
    eps = 1e-9
    # pass 1: pixel centres inside a triangle
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
                    bary[i, j, 0] = max(b0, 0.0)
                    bary[i, j, 1] = max(b1, 0.0)
                    bary[i, j, 2] = max(b2, 0.0)
                    dist[i, j] = 0.0
    if pad <= 0.0:
        return face, bary, dist
    # pass 2: the gutter, uncovered centres within pad of a triangle take its nearest point
    for f in range(tri.shape[0]):
        x0, y0 = tri[f, 0, 0], tri[f, 0, 1]
        x1, y1 = tri[f, 1, 0], tri[f, 1, 1]
        x2, y2 = tri[f, 2, 0], tri[f, 2, 1]
        if (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0) == 0.0:
            continue
        jlo = max(int(np.floor(min(x0, x1, x2) - pad - 0.5)), 0)
        jhi = min(int(np.ceil(max(x0, x1, x2) + pad - 0.5)), width - 1)
        ilo = max(int(np.floor(min(y0, y1, y2) - pad - 0.5)), 0)
        ihi = min(int(np.ceil(max(y0, y1, y2) + pad - 0.5)), height - 1)
        for i in range(ilo, ihi + 1):
            py = i + 0.5
            for j in range(jlo, jhi + 1):
                if dist[i, j] == 0.0:
                    continue
                px = j + 0.5
                best = np.inf
                c0 = c1 = c2 = 0.0
                for e in range(3):
                    ax, ay = tri[f, e, 0], tri[f, e, 1]
                    bx, by = tri[f, (e + 1) % 3, 0], tri[f, (e + 1) % 3, 1]
                    dx, dy = bx - ax, by - ay
                    ll = dx * dx + dy * dy
                    t = 0.0 if ll == 0.0 else min(max(((px - ax) * dx + (py - ay) * dy) / ll, 0.0), 1.0)
                    qx, qy = ax + t * dx - px, ay + t * dy - py
                    d = np.sqrt(qx * qx + qy * qy)
                    if d < best:
                        best = d
                        if e == 0:
                            c0, c1, c2 = 1.0 - t, t, 0.0
                        elif e == 1:
                            c0, c1, c2 = 0.0, 1.0 - t, t
                        else:
                            c0, c1, c2 = t, 0.0, 1.0 - t
                if best <= pad and best < dist[i, j]:
                    face[i, j] = f
                    bary[i, j, 0] = c0
                    bary[i, j, 1] = c1
                    bary[i, j, 2] = c2
                    dist[i, j] = best
    return face, bary, dist
