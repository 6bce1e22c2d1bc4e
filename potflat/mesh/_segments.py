"""Boundary segments of a flattening: do two of them cross? (Numba kernels.)

Segments are binned into a uniform grid (cell size about the typical segment length) and
pairs are tested per cell; a pair is reported once, in the cell holding the lower-left
corner of the intersection of the two bounding boxes. The grid binning is shared with the
relax stage's contact barrier (:mod:`potflat.relax._kernels.overlap`).
"""
from __future__ import annotations

import numpy as np

from potflat._jit import leaf


@leaf
def _orient(ax, ay, bx, by, cx, cy):
    v = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax)
    if v > 0.0:
        return 1
    if v < 0.0:
        return -1
    return 0


@leaf
def _on_segment(ax, ay, bx, by, px, py):
    return min(ax, bx) <= px <= max(ax, bx) and min(ay, by) <= py <= max(ay, by)


@leaf
def _segments_cross(p, q, r, s):
    o1 = _orient(p[0], p[1], q[0], q[1], r[0], r[1])
    o2 = _orient(p[0], p[1], q[0], q[1], s[0], s[1])
    o3 = _orient(r[0], r[1], s[0], s[1], p[0], p[1])
    o4 = _orient(r[0], r[1], s[0], s[1], q[0], q[1])
    if o1 * o2 < 0 and o3 * o4 < 0:
        return True
    if o1 == 0 and _on_segment(p[0], p[1], q[0], q[1], r[0], r[1]):
        return True
    if o2 == 0 and _on_segment(p[0], p[1], q[0], q[1], s[0], s[1]):
        return True
    if o3 == 0 and _on_segment(r[0], r[1], s[0], s[1], p[0], p[1]):
        return True
    return bool(o4 == 0 and _on_segment(r[0], r[1], s[0], s[1], q[0], q[1]))


@leaf
def crossing_pairs(x, seg, cell, max_pairs):
    """Crossing pairs of boundary segments, in the grid's order (segments sharing a vertex
    are skipped; segments that touch count).

    Parameters
    ----------
    x : (n, 2) float64
    seg : (b, 2) int64
        Boundary segments as vertex index pairs.
    cell : float
        Grid cell size (positive).
    max_pairs : int
        Stop after this many crossings.

    Returns
    -------
    (k, 2) int64
        Segment index pairs ``a < b`` in ``seg``'s order of binning, ``k <= max_pairs``.
    """
    nb = seg.shape[0]
    pairs = np.empty((min(max(max_pairs, 0), 64), 2), np.int64)
    if nb < 2 or max_pairs < 1:
        return pairs[:0]
    lo = np.empty((nb, 2))
    hi = np.empty((nb, 2))
    for s in range(nb):
        for d in range(2):
            a = x[seg[s, 0], d]
            b = x[seg[s, 1], d]
            lo[s, d] = min(a, b)
            hi[s, d] = max(a, b)
    ox = lo[:, 0].min()
    oy = lo[:, 1].min()
    gx = int((hi[:, 0].max() - ox) / cell) + 1
    gy = int((hi[:, 1].max() - oy) / cell) + 1
    start, items = bin_segments(x, seg, 0.0, ox, oy, cell, gx, gy)
    count = 0
    for c in range(gx * gy):
        cx = c % gx
        cy = c // gx
        for u in range(start[c], start[c + 1]):
            a = items[u]
            for w in range(u + 1, start[c + 1]):
                b = items[w]
                if (seg[a, 0] == seg[b, 0] or seg[a, 0] == seg[b, 1]
                        or seg[a, 1] == seg[b, 0] or seg[a, 1] == seg[b, 1]):
                    continue
                # report the pair only in the cell of the boxes' common lower-left corner
                bx = max(lo[a, 0], lo[b, 0])
                by = max(lo[a, 1], lo[b, 1])
                if bx > min(hi[a, 0], hi[b, 0]) or by > min(hi[a, 1], hi[b, 1]):
                    continue
                if int((bx - ox) / cell) != cx or int((by - oy) / cell) != cy:
                    continue
                if _segments_cross(x[seg[a, 0]], x[seg[a, 1]], x[seg[b, 0]], x[seg[b, 1]]):
                    if count == len(pairs):  # grow: a ragged border may cross itself often
                        grown = np.empty((min(2 * count, max_pairs), 2), np.int64)
                        for r in range(count):  # (a slice assignment costs seconds of compiling)
                            grown[r, 0] = pairs[r, 0]
                            grown[r, 1] = pairs[r, 1]
                        pairs = grown
                    pairs[count, 0] = a
                    pairs[count, 1] = b
                    count += 1
                    if count >= max_pairs:
                        return pairs[:count]
    return pairs[:count]


@leaf
def _padded_cells(x, seg, s, pad, ox, oy, cell, gx, gy):
    """Grid cell range of segment ``s``'s bounding box grown by ``pad``."""
    ax = x[seg[s, 0], 0]
    ay = x[seg[s, 0], 1]
    bx = x[seg[s, 1], 0]
    by = x[seg[s, 1], 1]
    x0 = max(int((min(ax, bx) - pad - ox) / cell), 0)
    x1 = min(int((max(ax, bx) + pad - ox) / cell), gx - 1)
    y0 = max(int((min(ay, by) - pad - oy) / cell), 0)
    y1 = min(int((max(ay, by) + pad - oy) / cell), gy - 1)
    return x0, x1, y0, y1


@leaf
def bin_segments(x, seg, pad, ox, oy, cell, gx, gy):
    """Segments per cell of a ``gx`` by ``gy`` grid (origin ``ox, oy``), each segment in every
    cell its bounding box grown by ``pad`` overlaps: CSR ``start`` (gx gy + 1,), ``items``."""
    cnt = np.zeros(gx * gy + 1, np.int64)
    for s in range(seg.shape[0]):
        x0, x1, y0, y1 = _padded_cells(x, seg, s, pad, ox, oy, cell, gx, gy)
        for cy in range(y0, y1 + 1):
            for cx in range(x0, x1 + 1):
                cnt[cy * gx + cx + 1] += 1
    start = np.cumsum(cnt)
    fill = start[:-1].copy()
    items = np.empty(start[-1], np.int64)
    for s in range(seg.shape[0]):
        x0, x1, y0, y1 = _padded_cells(x, seg, s, pad, ox, oy, cell, gx, gy)
        for cy in range(y0, y1 + 1):
            for cx in range(x0, x1 + 1):
                items[fill[cy * gx + cx]] = s
                fill[cy * gx + cx] += 1
    return start, items
