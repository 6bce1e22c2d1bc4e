"""Boundary self-overlap test of a flattening: do two boundary segments cross?

Segments are binned into a uniform grid (cell size about the typical segment length) and
pairs are tested per cell; a pair is reported once, in the cell holding the lower-left
corner of the intersection of the two bounding boxes.
"""
from __future__ import annotations

import math

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
def count_crossings(x, seg, cell, max_pairs):
    """Number of crossing pairs of boundary segments (segments sharing a vertex are skipped).

    Parameters
    ----------
    x : (n, 2) float64
    seg : (b, 2) int64
        Boundary segments as vertex index pairs.
    cell : float
        Grid cell size (positive).
    max_pairs : int
        Stop counting after this many crossings.

    Returns
    -------
    count : int
    first : (2,) int64
        The first crossing pair of segment indices (-1 when none).
    """
    nb = seg.shape[0]
    first = -np.ones(2, np.int64)
    if nb < 2:
        return 0, first
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
    start, items = _bin_segments(x, seg, 0.0, ox, oy, cell, gx, gy)
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
                    if count == 0:
                        first[0] = a
                        first[1] = b
                    count += 1
                    if count >= max_pairs:
                        return count, first
    return count, first


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
def _bin_segments(x, seg, pad, ox, oy, cell, gx, gy):
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


@leaf
def contact_barrier(x, seg, bprev, bnext, dhat, kappa, cell, grad, diag):
    """Barrier between boundary vertices and the boundary segments that come near them.

    For every boundary vertex ``v`` (the first vertex of a segment) and every segment
    ``(a, b)`` not touching ``v`` or its boundary neighbours, at distance ``d < dhat``:
    ``kappa * phi(d / dhat)`` with ``phi(s) = s - 1 - log s`` (zero and flat at ``d = dhat``,
    infinite at contact). Serial over the vertices in order (deterministic); adds the
    gradient and a Hessian diagonal bound in place.

    Parameters
    ----------
    x : (n, 2) float64
    seg : (b, 2) int64
        Boundary segments.
    bprev, bnext : (n,) int32
        Boundary neighbours (-1: none or not unique).
    dhat, kappa : float
        Activation distance and weight.
    cell : float
        Grid cell size of the search (at least ``dhat``).
    grad : (n, 2) float64
    diag : (n,) float64

    Returns
    -------
    float
        The barrier energy (inf at contact).
    """
    nb = seg.shape[0]
    if nb < 3:
        return 0.0
    ox = np.inf
    oy = np.inf
    mx = -np.inf
    my = -np.inf
    for s in range(nb):
        for e in range(2):
            v = seg[s, e]
            ox = min(ox, x[v, 0])
            oy = min(oy, x[v, 1])
            mx = max(mx, x[v, 0])
            my = max(my, x[v, 1])
    ox -= dhat
    oy -= dhat
    gx = int((mx + dhat - ox) / cell) + 1
    gy = int((my + dhat - oy) / cell) + 1
    start, items = _bin_segments(x, seg, dhat, ox, oy, cell, gx, gy)
    total = 0.0
    for t in range(nb):
        v = seg[t, 0]
        px = x[v, 0]
        py = x[v, 1]
        c = int((py - oy) / cell) * gx + int((px - ox) / cell)
        for u in range(start[c], start[c + 1]):
            s = items[u]
            a = seg[s, 0]
            b = seg[s, 1]
            if a == v or b == v or a == bprev[v] or b == bprev[v] or a == bnext[v] or b == bnext[v]:
                continue
            ex = x[b, 0] - x[a, 0]
            ey = x[b, 1] - x[a, 1]
            ee = ex * ex + ey * ey
            w = 0.0
            if ee > 0.0:
                w = min(max(((px - x[a, 0]) * ex + (py - x[a, 1]) * ey) / ee, 0.0), 1.0)
            nx = px - (x[a, 0] + w * ex)
            ny = py - (x[a, 1] + w * ey)
            d = math.sqrt(nx * nx + ny * ny)
            if d >= dhat:
                continue
            if d <= 0.0:
                return np.inf
            r = d / dhat
            total += kappa * (r - 1.0 - math.log(r))
            f = kappa * (1.0 - 1.0 / r) / dhat / d  # dE/dd, per unit of (p - c)
            h = kappa / (d * d)
            grad[v, 0] += f * nx
            grad[v, 1] += f * ny
            grad[a, 0] -= f * (1.0 - w) * nx
            grad[a, 1] -= f * (1.0 - w) * ny
            grad[b, 0] -= f * w * nx
            grad[b, 1] -= f * w * ny
            diag[v] += h
            diag[a] += h * (1.0 - w) * (1.0 - w)
            diag[b] += h * w * w
    return total
