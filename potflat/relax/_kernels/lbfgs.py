"""Kernels of the L-BFGS solver: fused, in-place passes over flat float64 vectors.

Each pass streams once over its vectors in fixed blocks of :data:`BLOCK` entries and returns
one partial sum per block; the caller adds the partials in block order, so every result
is the same whatever the number of threads. Vectors are flat views of ``(n, 2)`` arrays:
entry ``i`` belongs to vertex (or grid node) ``i >> 1``, whose Jacobi preconditioner is
``1 / max(diag[i >> 1], DIAG_FLOOR)``. Short vectors (fewer than :data:`PARALLEL_BLOCKS`
blocks) are done without threads: starting the thread team would cost more than the pass.
"""
from __future__ import annotations

import numpy as np

from potflat._jit import leaf, parallel, prange

#: Entries per block of the partial sums (also the unit of the dot products' order).
BLOCK = 4096
#: Vectors of fewer blocks than this are done serially.
PARALLEL_BLOCKS = 16
#: Floor of the Hessian diagonal bound in the Jacobi preconditioner.
DIAG_FLOOR = 1e-12


@leaf
def _combine_block(q, c, src, a, y, diag, scale, s, blk):
    acc = 0.0
    lo = blk * BLOCK
    hi = min(q.shape[0], lo + BLOCK)
    precondition = diag.shape[0] > 0
    dotted = s.shape[0] > 0
    for i in range(np.uint64(lo), np.uint64(hi)):
        v = c * src[i] + a * y[i]
        if precondition:
            v *= scale / max(diag[i >> 1], DIAG_FLOOR)
        elif scale != 1.0:
            v *= scale
        q[i] = v
        if dotted:
            acc += s[i] * v
    return acc


@parallel
def combine(q, c, src, a, y, diag, scale, s, out):
    """``q = (c src + a y) * scale * P`` and per-block partials of ``s . q``.

    ``q`` may be the same array as ``src`` or ``y`` (each entry is read before it is written).

    Parameters
    ----------
    q : (N,) float64
        Output.
    c, a, scale : float
    src, y : (N,) float64
    diag : (N // 2,) or (0,) float64
        Hessian diagonal bound per vertex: P = 1 / max(diag, DIAG_FLOOR); empty: P = 1.
    s : (N,) or (0,) float64
        Vector dotted with the new ``q``; empty: no dot product (``out`` gets zeros).
    out : (ceil(N / BLOCK),) float64
        Output: partial sums.
    """
    nb = out.shape[0]
    if nb < PARALLEL_BLOCKS:
        for blk in range(nb):
            out[blk] = _combine_block(q, c, src, a, y, diag, scale, s, blk)
    else:
        for blk in prange(nb):  # (prange's index is unsigned: cast, so the block compiles once)
            out[blk] = _combine_block(q, c, src, a, y, diag, scale, s, np.int64(blk))


@leaf
def _pair_block(q, t, g_new, g_old, diag, s_out, y_out, blk):
    sy = 0.0
    yhy = 0.0
    lo = blk * BLOCK
    hi = min(q.shape[0], lo + BLOCK)
    precondition = diag.shape[0] > 0
    for i in range(np.uint64(lo), np.uint64(hi)):
        sv = t * q[i]
        yv = g_new[i] - g_old[i]
        s_out[i] = sv
        y_out[i] = yv
        sy += sv * yv
        if precondition:
            yhy += yv * yv / max(diag[i >> 1], DIAG_FLOOR)
        else:
            yhy += yv * yv
    return sy, yhy


@parallel
def pair(q, t, g_new, g_old, diag, s_out, y_out, out_sy, out_yhy):
    """Store an L-BFGS pair ``s = t q``, ``y = g_new - g_old``; partials of ``s . y`` and ``y . P y``.

    Parameters
    ----------
    q : (N,) float64
        The search direction of the accepted step ``t``.
    t : float
    g_new, g_old : (N,) float64
        Gradients after and before the step.
    diag : (N // 2,) or (0,) float64
        Hessian diagonal bound at the new point (see :func:`combine`).
    s_out, y_out : (N,) float64
        Output: the pair.
    out_sy, out_yhy : (ceil(N / BLOCK),) float64
        Output: partial sums.
    """
    nb = out_sy.shape[0]
    if nb < PARALLEL_BLOCKS:
        for blk in range(nb):
            out_sy[blk], out_yhy[blk] = _pair_block(q, t, g_new, g_old, diag, s_out, y_out, blk)
    else:
        for blk in prange(nb):  # (prange's index is unsigned: cast, so the block compiles once)
            out_sy[blk], out_yhy[blk] = _pair_block(q, t, g_new, g_old, diag, s_out, y_out, np.int64(blk))


@parallel
def add_jacobi(out, r, diag):
    """``out += r / max(diag, DIAG_FLOOR)`` (the Jacobi term of a preconditioner).

    Parameters
    ----------
    out, r : (N,) float64
    diag : (N // 2,) float64
        Hessian diagonal bound per vertex.
    """
    for i in prange(out.shape[0]):
        out[i] += r[i] / max(diag[i >> 1], DIAG_FLOOR)
