"""The contact barrier between a flattening's boundary vertices and its boundary segments,
and the step bound that keeps a step from running deep into it.

The segments are binned on the grid of :mod:`potflat.mesh._segments` (where crossing
boundary segments are found, :func:`potflat.mesh.boundary.crossing_pairs`).
"""
from __future__ import annotations

import math

import numpy as np

from potflat._jit import leaf
from potflat.mesh._segments import bin_segments
from potflat.relax._kernels.steps import _first_root, _no_root_up_to, triangle_area_polynomial


@leaf
def _near_pairs(x, seg, bprev, bnext, dhat, cell):
    """The (vertex, segment) pairs the contact terms look at: every boundary vertex ``v`` (the
    first vertex of a segment, in the segments' order) with every segment binned within
    ``dhat`` of its grid cell (:func:`~potflat.mesh._segments.bin_segments`, cells of side
    ``cell``) that touches neither ``v`` nor its boundary neighbours. Returns the vertices
    and the segments' indices, (k,) int64 each (count, then fill: the same order)."""
    nb = seg.shape[0]
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
    start, items = bin_segments(x, seg, dhat, ox, oy, cell, gx, gy)
    verts = np.empty(0, np.int64)
    segs = np.empty(0, np.int64)
    for fill in range(2):  # count, then fill
        k = 0
        for t in range(nb):
            v = seg[t, 0]
            c = int((x[v, 1] - oy) / cell) * gx + int((x[v, 0] - ox) / cell)
            for u in range(start[c], start[c + 1]):
                s = items[u]
                a = seg[s, 0]
                b = seg[s, 1]
                if a == v or b == v or a == bprev[v] or b == bprev[v] or a == bnext[v] or b == bnext[v]:
                    continue
                if fill:
                    verts[k] = v
                    segs[k] = s
                k += 1
        if not fill:
            verts = np.empty(k, np.int64)
            segs = np.empty(k, np.int64)
    return verts, segs


@leaf
def contact_barrier(x, seg, bprev, bnext, dhat, kappa, cell, weight, grad, diag):
    """Barrier between boundary vertices and the boundary segments that come near them.

    For every boundary vertex ``v`` (the first vertex of a segment) and every segment
    ``(a, b)`` not touching ``v`` or its boundary neighbours, at distance ``d < dhat``:
    ``kappa w phi(d / dhat)`` with ``phi(s) = s - 1 - log s`` (zero and flat at ``d = dhat``,
    infinite at contact) and ``w`` the mean importance weight of ``v``, ``a`` and ``b``
    (plain surface's contacts as soft as its springs). Serial over the vertices in order
    (deterministic); adds the gradient and a Hessian diagonal bound in place.

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
    weight : (n,) or (0,) float64
        Importance weight of each vertex; empty: every weight is 1.
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
    weighted = weight.shape[0] > 0
    verts, segs = _near_pairs(x, seg, bprev, bnext, dhat, cell)
    total = 0.0
    for p in range(verts.shape[0]):
        v = verts[p]
        a = seg[segs[p], 0]
        b = seg[segs[p], 1]
        px = x[v, 0]
        py = x[v, 1]
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
        kw = kappa * (weight[v] + weight[a] + weight[b]) / 3.0 if weighted else kappa
        total += kw * (r - 1.0 - math.log(r))
        f = kw * (1.0 - 1.0 / r) / dhat / d  # dE/dd, per unit of (p - c)
        h = kw / (d * d)
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


@leaf
def _pair_step(x, d, seg, v, s, dhat, shrink, best):
    """The contact step bound of boundary vertex ``v`` against segment ``s``, or ``best`` when
    it is no lower (the pair is not bounded, or keeps ``1 - shrink`` of its distance up to
    ``best``): see :func:`contact_max_step`."""
    a = seg[s, 0]
    b = seg[s, 1]
    rx = x[v, 0] - x[a, 0]
    ry = x[v, 1] - x[a, 1]
    ex = x[b, 0] - x[a, 0]
    ey = x[b, 1] - x[a, 1]
    ee = ex * ex + ey * ey
    cross = ex * ry - ey * rx  # |ab| times the signed distance of v from the line
    if ee <= 0.0 or not 0.0 < rx * ex + ry * ey < ee or cross * cross >= dhat * dhat * ee:
        return best
    c0, c1, c2 = triangle_area_polynomial(x, d, np.uint32(a), np.uint32(b), np.uint32(v), shrink)
    if cross < 0.0:  # v on the right of a -> b: the area is negative, and must stay so
        c0, c1, c2 = -c0, -c1, -c2
    if _no_root_up_to(c0, c1, c2, best):
        return best
    return min(best, _first_root(c0, c1, c2))


@leaf
def contact_max_step(x, d, seg, bprev, bnext, dhat, cell, cap, shrink):
    """Largest ``t <= cap`` for which no pair of :func:`contact_barrier` whose vertex's foot
    lies inside the segment comes closer to the segment's line along ``x + t d`` than
    ``1 - shrink`` of its distance at ``x``: the contact barrier's counterpart of the faces'
    step bound (:func:`~potflat.relax._kernels.springs.max_step`). The pair's signed
    distance times the segment's length is twice the signed area of the triangle of the
    segment and the vertex, a quadratic in ``t`` (:func:`~potflat.relax._kernels.springs.triangle_area_polynomial`).

    Parameters
    ----------
    x, d : (n, 2) float64
        Positions and direction.
    seg : (b, 2) int64
    bprev, bnext : (n,) int32
    dhat, cell : float
        As in :func:`contact_barrier`: only pairs closer than ``dhat`` are bounded.
    cap : float
        Upper bound of interest.
    shrink : float
        Largest fraction of its distance a pair may lose, in (0, 1].
    """
    if seg.shape[0] < 3:
        return cap
    verts, segs = _near_pairs(x, seg, bprev, bnext, dhat, cell)
    best = cap
    for p in range(verts.shape[0]):
        best = _pair_step(x, d, seg, verts[p], segs[p], dhat, shrink, best)
    return best


@leaf
def contact_pair_steps(x, d, seg, bprev, bnext, dhat, cell, cap, shrink):
    """The pairs of :func:`contact_max_step` whose own bound is below ``cap``: their vertex
    and the segment's two, (k, 3) int64, and the bounds, (k,) float64 (in the pairs' order)."""
    if seg.shape[0] < 3:
        return np.empty((0, 3), np.int64), np.empty(0)
    verts, segs = _near_pairs(x, seg, bprev, bnext, dhat, cell)
    bound = np.empty(verts.shape[0])
    k = 0
    for p in range(verts.shape[0]):
        bound[p] = _pair_step(x, d, seg, verts[p], segs[p], dhat, shrink, cap)
        if bound[p] < cap:
            k += 1
    trio = np.empty((k, 3), np.int64)
    out = np.empty(k)
    k = 0
    for p in range(verts.shape[0]):
        if bound[p] < cap:
            trio[k, 0] = verts[p]
            trio[k, 1] = seg[segs[p], 0]
            trio[k, 2] = seg[segs[p], 1]
            out[k] = bound[p]
            k += 1
    return trio, out
