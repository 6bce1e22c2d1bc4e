"""Kernels of the coarse-to-fine relaxation: bilinear displacement fields on quadtree grids.

Vertices are sorted by the Morton code of their position in the reference (rollout) domain,
quantised to ``2^QBITS`` steps per side of a bounding square. At grid level ``L`` a vertex
lies in cell ``(q_x >> (QBITS - L), q_y >> (QBITS - L))``, and the vertices of each cell are a
contiguous range of the Morton order, so restriction (the transpose of the bilinear
prolongation) is a gather per grid node over four ranges: race-free and deterministic.
"""
from __future__ import annotations

from potflat._kernels._jit import leaf, parallel, prange

#: Bits of the Morton quantisation per axis.
QBITS = 16


@leaf
def _interleave(cx, cy, bits):
    code = 0
    for b in range(bits):
        code |= ((cx >> b) & 1) << (2 * b)
        code |= ((cy >> b) & 1) << (2 * b + 1)
    return code


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
        out[i] = _interleave(qx, qy, QBITS)


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
        n00 = cy * w + cx
        n10 = n00 + 1
        n01 = n00 + w
        n11 = n01 + 1
        w00 = (1.0 - fx) * (1.0 - fy)
        w10 = fx * (1.0 - fy)
        w01 = (1.0 - fx) * fy
        w11 = fx * fy
        for d in range(2):
            out[i, d] = w00 * c[n00, d] + w10 * c[n10, d] + w01 * c[n01, d] + w11 * c[n11, d]


@parallel
def restrict(un, level, cell_start, g, out):
    """Transpose of :func:`prolong`: ``out[node] = sum_i w_node(i) g[i]``.

    Parameters
    ----------
    un : (n, 2) float64
        Reference positions, rows sorted by Morton code.
    level : int
    cell_start : (4^level + 1,) int64
        First vertex of each cell (in Morton order of the cells).
    g : (n, 2) float64
    out : ((2^level + 1)^2, 2) float64
    """
    side = 1 << level
    w = side + 1
    for node in prange(w * w):
        ix = node % w
        iy = node // w
        ax = 0.0
        ay = 0.0
        for cy in range(iy - 1, iy + 1):
            if cy < 0 or cy >= side:
                continue
            for cx in range(ix - 1, ix + 1):
                if cx < 0 or cx >= side:
                    continue
                code = _interleave(cx, cy, level)
                for i in range(cell_start[code], cell_start[code + 1]):
                    _, fx = _cell_and_frac(un[i, 0], level)
                    _, fy = _cell_and_frac(un[i, 1], level)
                    wx = fx if cx == ix - 1 else 1.0 - fx
                    wy = fy if cy == iy - 1 else 1.0 - fy
                    ax += wx * wy * g[i, 0]
                    ay += wx * wy * g[i, 1]
        out[node, 0] = ax
        out[node, 1] = ay
