"""Kernels of the coarse-to-fine relaxation: bilinear displacement fields on quadtree grids.

Vertices are sorted by the Morton code of their position in the reference (rollout) domain,
quantised to ``2^QBITS`` steps per side of a bounding square. At grid level ``L`` a vertex
lies in cell ``(q_x >> (QBITS - L), q_y >> (QBITS - L))``, and the vertices of each cell are a
contiguous range of the Morton order, so restriction (the transpose of the bilinear
prolongation) is a gather per grid node over four ranges: race-free and deterministic.
"""
from __future__ import annotations

import numpy as np

from potflat._jit import leaf, parallel, prange

#: Bits of the Morton quantisation per axis.
QBITS = 16


@leaf
def _spread(v):
    """The low 16 bits of ``v`` spread to the even bits (bit ``b`` to bit ``2 b``)."""
    v &= 0xFFFF
    v = (v | (v << 8)) & 0x00FF00FF
    v = (v | (v << 4)) & 0x0F0F0F0F
    v = (v | (v << 2)) & 0x33333333
    return (v | (v << 1)) & 0x55555555


@leaf
def _interleave(cx, cy):
    """Morton code of cell ``(cx, cy)`` (each below ``2^QBITS``): x bits even, y bits odd."""
    return _spread(cx) | (_spread(cy) << 1)


@parallel
def morton_codes(un, out):
    """Morton code of each point of ``un`` (coordinates in ``[0, 1]``), ``QBITS`` per axis.

    Parameters
    ----------
    un : (n, 2) float64
    out : (n,) int64
    """
    top = (1 << QBITS) - 1
    for i in prange(un.shape[0]):
        qx = min(max(int(un[i, 0] * (1 << QBITS)), 0), top)
        qy = min(max(int(un[i, 1] * (1 << QBITS)), 0), top)
        out[i] = _interleave(qx, qy)


@leaf
def _cell_and_frac(u, level):
    top = (1 << QBITS) - 1
    q = min(max(int(u * (1 << QBITS)), 0), top)
    c = q >> (QBITS - level)
    f = u * (1 << level) - c
    return c, min(max(f, 0.0), 1.0)


@parallel
def prolong(un, level, c, out):
    """Bilinear interpolation of node values ``c`` at every vertex.

    Parameters
    ----------
    un : (n, 2) float64
        Reference positions in ``[0, 1]``.
    level : int
        ``2^level`` cells per side.
    c : ((2^level + 1)^2, 2) float64
        Node values, node ``(ix, iy)`` at row ``iy * (2^level + 1) + ix``.
    out : (n, 2) float64
    """
    w = (1 << level) + 1
    for i in prange(un.shape[0]):
        cx, fx = _cell_and_frac(un[i, 0], level)
        cy, fy = _cell_and_frac(un[i, 1], level)
        n00 = np.uint64(cy * w + cx)
        n10 = n00 + np.uint64(1)
        n01 = n00 + np.uint64(w)
        n11 = n01 + np.uint64(1)
        w00 = (1.0 - fx) * (1.0 - fy)
        w10 = fx * (1.0 - fy)
        w01 = (1.0 - fx) * fy
        w11 = fx * fy
        for d in range(2):
            out[i, d] = w00 * c[n00, d] + w10 * c[n10, d] + w01 * c[n01, d] + w11 * c[n11, d]


@parallel
def cell_fractions(un, level, out):
    """Position of every vertex within its cell of ``level``, each coordinate in ``[0, 1]``
    (the bilinear weights of :func:`prolong` and :func:`restrict`).

    Parameters
    ----------
    un : (n, 2) float64
        Reference positions in ``[0, 1]``.
    level : int
    out : (n, 2) float64
    """
    for i in prange(un.shape[0]):
        for d in range(2):
            _, out[i, d] = _cell_and_frac(un[i, d], level)


@parallel
def restrict(frac, level, cell_start, g, corners, out):
    """Transpose of :func:`prolong`: ``out[node] = sum_i w_node(i) g[i]``, column by column.

    Two race-free passes: each cell sums its vertices' weighted values per corner (one read
    of every vertex), then each node adds the corners of its up to four cells.

    Parameters
    ----------
    frac : (n, 2) float64
        Each vertex's position in its cell of ``level`` (:func:`cell_fractions`), rows sorted
        by Morton code.
    level : int
    cell_start : (4^level + 1,) int64
        First vertex of each cell (in Morton order of the cells).
    g : (n, k) float64
    corners : (4^level, 4, k) float64
        Work space (overwritten).
    out : ((2^level + 1)^2, k) float64
    """
    side = 1 << level
    w = side + 1
    k = g.shape[1]
    for code in prange(side * side):
        lo = cell_start[code]
        hi = cell_start[code + 1]
        for c in range(k):
            s00 = 0.0
            s10 = 0.0
            s01 = 0.0
            s11 = 0.0
            for i in range(np.uint64(lo), np.uint64(hi)):
                fx = frac[i, 0]
                fy = frac[i, 1]
                v = g[i, c]
                s00 += (1.0 - fx) * (1.0 - fy) * v
                s10 += fx * (1.0 - fy) * v
                s01 += (1.0 - fx) * fy * v
                s11 += fx * fy * v
            corners[code, 0, c] = s00
            corners[code, 1, c] = s10
            corners[code, 2, c] = s01
            corners[code, 3, c] = s11
    for node in prange(w * w):
        ix = node % w
        iy = node // w
        for c in range(k):
            out[node, c] = 0.0
        for cy in range(iy - 1, iy + 1):
            if cy < 0 or cy >= side:
                continue
            for cx in range(ix - 1, ix + 1):
                if cx < 0 or cx >= side:
                    continue
                corner = (1 if cx == ix - 1 else 0) + (2 if cy == iy - 1 else 0)
                code = _interleave(cx, cy)
                for c in range(k):
                    out[node, c] += corners[code, corner, c]


@parallel
def grid_restrict(fine, level, out):
    """Transpose of :func:`grid_prolong_add`: node values of ``level + 1`` to ``level``.

    Parameters
    ----------
    fine : ((2^(level+1) + 1)^2, k) float64
    level : int
    out : ((2^level + 1)^2, k) float64
    """
    wc = (1 << level) + 1
    wf = (1 << (level + 1)) + 1
    k = fine.shape[1]
    for node in prange(wc * wc):
        ax = node % wc
        ay = node // wc
        for c in range(k):
            out[node, c] = 0.0
        for dy in range(-1, 2):
            fy = 2 * ay + dy
            if fy < 0 or fy >= wf:
                continue
            wy = 1.0 if dy == 0 else 0.5
            for dx in range(-1, 2):
                fx = 2 * ax + dx
                if fx < 0 or fx >= wf:
                    continue
                wxy = wy * (1.0 if dx == 0 else 0.5)
                for c in range(k):
                    out[node, c] += wxy * fine[fy * wf + fx, c]


@parallel
def grid_prolong_add(coarse, level, fine):
    """``fine += `` the bilinear interpolation of ``coarse`` (nodes of ``level``) at the nodes
    of ``level + 1`` (exact: a bilinear field on a cell is bilinear on its four sub-cells).

    Parameters
    ----------
    coarse : ((2^level + 1)^2, k) float64
    level : int
    fine : ((2^(level+1) + 1)^2, k) float64
    """
    wc = (1 << level) + 1
    wf = (1 << (level + 1)) + 1
    k = fine.shape[1]
    for node in prange(wf * wf):
        fx = node % wf
        fy = node // wf
        x0 = fx >> 1
        y0 = fy >> 1
        x1 = x0 + (fx & 1)
        y1 = y0 + (fy & 1)
        for c in range(k):
            fine[node, c] += 0.25 * (coarse[y0 * wc + x0, c] + coarse[y0 * wc + x1, c]
                                     + coarse[y1 * wc + x0, c] + coarse[y1 * wc + x1, c])
