"""Uniform grid kernels over a flattening's faces and points: which face centres lie inside
which faces, how much of a ring of angles is covered, nearest segments.

Arrays in, arrays out, no I/O; deterministic for any thread count.
"""
from __future__ import annotations


import numpy as np

from potflat._jit import leaf, parallel, prange


@leaf
def _strictly_inside(px, py, ax, ay, bx, by, cx, cy):
    """Whether (px, py) lies strictly inside the triangle a b c, either orientation."""
    s1 = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
    s2 = (cx - bx) * (py - by) - (cy - by) * (px - bx)
    s3 = (ax - cx) * (py - cy) - (ay - cy) * (px - cx)
    return (s1 > 0.0 and s2 > 0.0 and s3 > 0.0) or (s1 < 0.0 and s2 < 0.0 and s3 < 0.0)


@leaf
def _cell_range(lo, hi, origin, cell, cells):
    """First and last grid cell (clamped to ``0 .. cells - 1``) of the interval [lo, hi]."""
    a = int((lo - origin) / cell)
    b = int((hi - origin) / cell)
    return min(max(a, 0), cells - 1), min(max(b, 0), cells - 1)


@leaf
def _box_cells(faces, uv, t, ox, oy, cell, gx, gy):
    """The grid cells ``x0..x1`` by ``y0..y1`` of the bounding box of face ``t``."""
    a, b, c = np.uint64(faces[t, 0]), np.uint64(faces[t, 1]), np.uint64(faces[t, 2])
    x0, x1 = _cell_range(min(uv[a, 0], uv[b, 0], uv[c, 0]), max(uv[a, 0], uv[b, 0], uv[c, 0]), ox, cell, gx)
    y0, y1 = _cell_range(min(uv[a, 1], uv[b, 1], uv[c, 1]), max(uv[a, 1], uv[b, 1], uv[c, 1]), oy, cell, gy)
    return x0, x1, y0, y1


@leaf
def centre_grid(faces, uv, ox, oy, cell, gx, gy):
    """The faces binned by the grid cell of their centre, as a CSR table (counting sort):
    cell ``c`` (``cx * gy + cy``) holds ``items[start[c]:start[c + 1]]``, in face order, whose
    centres are ``centres[start[c]:start[c + 1]]``; and the number of cells under the faces'
    bounding boxes in all (the work of :func:`centres_inside`).

    faces (m, 3) int64, uv (n, 2) float64, a grid of ``gx`` x ``gy`` square cells of side
    ``cell`` from (``ox``, ``oy``). Returns start (gx * gy + 1,) int64, items (m,) int64, centres
    (m, 2) float64, covered int.
    """
    m = faces.shape[0]
    where = np.empty(m, np.int64)
    centre = np.empty((m, 2), np.float64)
    covered = 0
    for t in range(m):
        a, b, c = np.uint64(faces[t, 0]), np.uint64(faces[t, 1]), np.uint64(faces[t, 2])
        px = (uv[a, 0] + uv[b, 0] + uv[c, 0]) / 3.0
        py = (uv[a, 1] + uv[b, 1] + uv[c, 1]) / 3.0
        centre[t, 0] = px
        centre[t, 1] = py
        where[t] = _cell_range(px, px, ox, cell, gx)[0] * gy + _cell_range(py, py, oy, cell, gy)[0]
        x0, x1, y0, y1 = _box_cells(faces, uv, t, ox, oy, cell, gx, gy)
        covered += (x1 - x0 + 1) * (y1 - y0 + 1)
    start = np.zeros(gx * gy + 1, np.int64)
    for t in range(m):
        start[np.uint64(where[t] + 1)] += 1
    for k in range(1, start.shape[0]):
        start[k] += start[k - 1]
    fill = start[:-1].copy()
    items = np.empty(m, np.int64)
    centres = np.empty((m, 2), np.float64)
    for t in range(m):
        k = np.uint64(where[t])
        q = np.uint64(fill[k])
        items[q] = t
        centres[q, 0] = centre[t, 0]
        centres[q, 1] = centre[t, 1]
        fill[k] = q + np.uint64(1)
    return start, items, centres, covered


@parallel
def centres_inside(faces, uv, ox, oy, cell, gx, gy, start, items, centres, first, counts, pairs):
    """Faces whose centre lies strictly inside each face, sharing no vertex with it, through
    the grid of :func:`centre_grid`: per face the number of such faces (``first`` empty), or
    their indices written to ``pairs[first[j]:first[j] + counts[j]]`` (the faces counted
    none skipped).

    faces (m, 3) int64, uv (n, 2) float64, start/items/centres the grid's, first (m,) int64 or
    (0,), counts (m,) int64 (out when counting), pairs (k,) int64 out.
    """
    fill = first.shape[0] > 0
    for j in prange(faces.shape[0]):
        if fill and counts[j] == 0:
            continue
        b0, b1, b2 = np.uint64(faces[j, 0]), np.uint64(faces[j, 1]), np.uint64(faces[j, 2])
        x0, x1, y0, y1 = _box_cells(faces, uv, np.int64(j), ox, oy, cell, gx, gy)  # (one compile: j is unsigned)
        n_in = 0
        for cx in range(x0, x1 + 1):
            for cy in range(y0, y1 + 1):
                k = np.uint64(cx * gy + cy)
                for q in range(np.uint64(start[k]), np.uint64(start[k + 1])):
                    # the grid's centres in order first; the faces' corners only for a centre inside
                    if not _strictly_inside(centres[q, 0], centres[q, 1], uv[b0, 0], uv[b0, 1], uv[b1, 0],
                                            uv[b1, 1], uv[b2, 0], uv[b2, 1]):
                        continue
                    i = items[q]
                    if i == j:
                        continue
                    iu = np.uint64(i)
                    a0, a1, a2 = np.uint64(faces[iu, 0]), np.uint64(faces[iu, 1]), np.uint64(faces[iu, 2])
                    if (b0 == a0 or b0 == a1 or b0 == a2 or b1 == a0 or b1 == a1 or b1 == a2
                            or b2 == a0 or b2 == a1 or b2 == a2):
                        continue
                    if fill:
                        pairs[first[j] + n_in] = i
                    n_in += 1
        if not fill:
            counts[j] = n_in


@leaf
def _mark_bins(stamp, mark, tv, lo, hi, nbins):
    """Stamp with ``mark`` the angle bins (of ``nbins``) of the points ``lo:hi``; the number
    of bins newly stamped."""
    new = 0
    for k in range(np.uint64(lo), np.uint64(hi)):
        b = np.uint64(min(np.int64(tv[k] / (2.0 * np.pi) * nbins), nbins - 1))
        if stamp[b] != mark:
            stamp[b] = mark
            new += 1
    return new


@leaf
def angle_coverage(cells, ptr, tv, targets, nh, ring_bins, target_count, own_count):
    """Angle bins covered by the points of each meridian-plane cell and of its 3 x 3 cells.

    Cells are numbered ``row * nr + ring`` (row in ``[0, nh)``, ring in ``[0, nr)``); a point
    at angle ``t`` lies in bin ``floor(t / (2 pi) * bins)`` of a ring of ``bins`` angle bins
    (the last bin at most).

    Parameters
    ----------
    cells : (u,) int64
        The cells holding points, ascending.
    ptr : (u + 1,) int64
        Cell ``cells[i]`` holds the points ``ptr[i]:ptr[i + 1]`` of ``tv``.
    tv : (s,) float64
        Angle in ``[0, 2 pi)`` of each point, grouped by cell.
    targets : (t,) int64
        Cells to measure, ascending, each within one row and one ring of a cell in ``cells``.
    nh : int
        Rows.
    ring_bins : (nr,) int64
        Angle bins of each ring (every ring in ``cells`` below ``nr - 1``).
    target_count : (t,) int64
        Output: the bins of each target's ring holding a point of its 3 x 3 cells.
    own_count : (u,) int64
        Output: the bins of each cell's ring holding one of its own points.
    """
    u = cells.shape[0]
    nr = ring_bins.shape[0]
    stamp = np.zeros(ring_bins.max(), np.int64)  # bin b was counted for the target stamped in it
    mark = 0
    for i in range(targets.shape[0]):
        row = targets[i] // nr
        ring = targets[i] % nr
        nbins = ring_bins[ring]
        mark += 1
        count = 0
        for dh in range(-1, 2):
            sh = row - dh
            if sh < 0 or sh >= nh:
                continue
            for dr in range(-1, 2):
                sr = ring - dr
                if sr < 0 or sr >= nr:
                    continue
                key = sh * nr + sr
                lo = 0  # binary search of the source cell
                hi = u
                while lo < hi:
                    mid = (lo + hi) >> 1
                    if cells[mid] < key:
                        lo = mid + 1
                    else:
                        hi = mid
                if lo < u and cells[lo] == key:
                    count += _mark_bins(stamp, mark, tv, ptr[lo], ptr[lo + 1], nbins)
        target_count[i] = count
    for j in range(u):
        mark += 1
        own_count[j] = _mark_bins(stamp, mark, tv, ptr[j], ptr[j + 1], ring_bins[cells[j] % nr])


@parallel
def segment_distances(reps, pts, idx, nearest, join, out):
    """Distance of each point to the segment between its two nearest representatives, where
    that segment is at most ``join`` long, else to the nearest one (the formulas, and their
    order, of NumPy's vector form).

    Parameters
    ----------
    reps : (q, 2) float64
        The representatives (points of a curve).
    pts : (k, 2) float64
    idx : (k, 2) int64
        Each point's two nearest representatives (a k-d tree's answer).
    nearest : (k,) float64
        The distance to the first of them.
    join : float
    out : (k,) float64
        Output: ``min(nearest, segment distance)`` where the segment is at most ``join`` long,
        else ``nearest``.
    """
    for i in prange(pts.shape[0]):
        a = np.uint64(idx[i, 0])
        b = np.uint64(idx[i, 1])
        p1x = reps[a, 0]
        p1y = reps[a, 1]
        sx = reps[b, 0] - p1x
        sy = reps[b, 1] - p1y
        L2 = sx * sx + sy * sy
        t = ((pts[i, 0] - p1x) * sx + (pts[i, 1] - p1y) * sy) / (L2 if L2 > 0.0 else 1.0)
        t = min(max(t, 0.0), 1.0)
        dx = pts[i, 0] - (p1x + t * sx)
        dy = pts[i, 1] - (p1y + t * sy)
        d = nearest[i]
        out[i] = min(d, np.sqrt(dx * dx + dy * dy)) if np.sqrt(L2) <= join else d
