"""Kernels of the relaxation's coarse copies: the fine layout following a coarse one.

Arrays in, arrays out, no I/O.
"""
from __future__ import annotations

import numpy as np

from potflat._jit import leaf, parallel, prange


@leaf
def _barycentric(p0, p1, uv, faces, f):
    """Barycentric coordinates of ``(p0, p1)`` in face ``f`` of ``uv`` (nan for a degenerate face)."""
    a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
    x0, y0 = uv[a, 0], uv[a, 1]
    ux, uy = uv[b, 0] - x0, uv[b, 1] - y0
    wx, wy = uv[c, 0] - x0, uv[c, 1] - y0
    det = ux * wy - uy * wx
    if det == 0.0:
        return np.nan, np.nan, np.nan
    px, py = p0 - x0, p1 - y0
    lb = (px * wy - py * wx) / det
    lc = (ux * py - uy * px) / det
    return 1.0 - lb - lc, lb, lc


@leaf
def _scan_fan(p0, p1, v, uv, faces, vf_ptr, vf_tri, best, best_min, b0, b1, b2):
    """Update the best face so far (largest smallest barycentric coordinate) over the faces of ``v``."""
    for k in range(vf_ptr[v], vf_ptr[v + 1]):
        f = vf_tri[k]
        l0, l1, l2 = _barycentric(p0, p1, uv, faces, f)
        m = min(l0, min(l1, l2))
        if m > best_min:  # nan never wins; ties keep the first face met
            best, best_min, b0, b1, b2 = f, m, l0, l1, l2
    return best, best_min, b0, b1, b2


@parallel
def interpolate(points, cluster, uv_from, uv_to, faces, vf_ptr, vf_tri, out, inside):
    """Move every point with the piecewise-linear map of a coarse mesh from ``uv_from`` to ``uv_to``.

    Each point moves with the map of the face it lies deepest in (largest smallest
    barycentric coordinate; the first such face in CSR order) among the faces around its
    cluster's coarse vertex, or, when it lies in none of those, around that vertex's
    neighbours too. A point inside none of them (outside the copy's jagged border) moves with
    the linear map of the face it is least outside of.

    Parameters
    ----------
    points : (n, 2) float64
        Fine positions in the coarse mesh's ``uv_from`` frame.
    cluster : (n,) int64
        Coarse vertex of each point (a vertex near it).
    uv_from, uv_to : (nc, 2) float64
        Coarse layouts before and after.
    faces : (mc, 3) int64
    vf_ptr : (nc + 1,) int64
    vf_tri : (3 mc,) int32
        Incident faces of each coarse vertex (CSR).
    out : (n, 2) float64
        The moved points.
    inside : (n,) bool
        Whether each point lies in a face of the copy.
    """
    for i in prange(points.shape[0]):
        p0, p1 = points[i, 0], points[i, 1]
        c = cluster[i]
        best, best_min, b0, b1, b2 = _scan_fan(p0, p1, c, uv_from, faces, vf_ptr, vf_tri, np.int64(-1), -np.inf, 0.0,
                                               0.0, 0.0)  # (np.int64: a literal -1 would be a second compile)
        if not best_min >= -1e-12:  # not inside a face of c: try the faces of c's neighbours
            for k in range(vf_ptr[c], vf_ptr[c + 1]):
                for corner in range(3):
                    v = faces[vf_tri[k], corner]
                    if v != c:
                        best, best_min, b0, b1, b2 = _scan_fan(p0, p1, v, uv_from, faces, vf_ptr, vf_tri,
                                                               best, best_min, b0, b1, b2)
        inside[i] = best_min >= -1e-12
        if best < 0:  # only degenerate faces around: move with the cluster's vertex
            out[i, 0] = p0 + uv_to[c, 0] - uv_from[c, 0]
            out[i, 1] = p1 + uv_to[c, 1] - uv_from[c, 1]
            continue
        a, b, d = faces[best, 0], faces[best, 1], faces[best, 2]
        out[i, 0] = p0 + b0 * (uv_to[a, 0] - uv_from[a, 0]) + b1 * (uv_to[b, 0] - uv_from[b, 0]) + b2 * (
            uv_to[d, 0] - uv_from[d, 0])
        out[i, 1] = p1 + b0 * (uv_to[a, 1] - uv_from[a, 1]) + b1 * (uv_to[b, 1] - uv_from[b, 1]) + b2 * (
            uv_to[d, 1] - uv_from[d, 1])
