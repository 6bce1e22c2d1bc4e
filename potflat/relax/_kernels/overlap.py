"""The contact barrier between a flattening's boundary vertices and its boundary segments.

The segments are binned on the grid of :mod:`potflat.mesh._segments` (where crossing
boundary segments are found, :func:`potflat.mesh.boundary.crossing_pairs`).
"""
from __future__ import annotations

import math

import numpy as np

from potflat._jit import leaf
from potflat.mesh._segments import bin_segments


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
    start, items = bin_segments(x, seg, dhat, ox, oy, cell, gx, gy)
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
