"""Step bounds of the fold-free solver: the longest step along a direction that keeps every
face above a share of its area, and every guarded boundary vertex's angle sum below 2 pi.

Arrays in, arrays out, no I/O; deterministic for any thread count.
"""
from __future__ import annotations

import heapq
import math

import numpy as np

from potflat._jit import leaf, parallel, prange

from potflat.relax._kernels.springs import BLOCK


@leaf
def _area_polynomial(x, d, faces, f, shrink):
    """Coefficients ``(c0, c1, c2)`` of face ``f``'s signed area (doubled) along ``x + t d``
    minus ``1 - shrink`` of its area at ``x``: ``c0 + c1 t + c2 t^2``."""
    # (uint32 corners: one compiled type for the faces' int32 and the contact bound's int64,
    # and no negative-index wraparound at each read)
    return triangle_area_polynomial(x, d, np.uint32(faces[f, 0]), np.uint32(faces[f, 1]), np.uint32(faces[f, 2]),
                                    shrink)


@leaf
def triangle_area_polynomial(x, d, a0, a1, a2, shrink):
    """:func:`_area_polynomial` of the triangle of vertices ``a0, a1, a2`` (any three; the
    contact step bound's vertex and segment too)."""
    e1x = x[a1, 0] - x[a0, 0]
    e1y = x[a1, 1] - x[a0, 1]
    e2x = x[a2, 0] - x[a0, 0]
    e2y = x[a2, 1] - x[a0, 1]
    f1x = d[a1, 0] - d[a0, 0]
    f1y = d[a1, 1] - d[a0, 1]
    f2x = d[a2, 0] - d[a0, 0]
    f2y = d[a2, 1] - d[a0, 1]
    c0 = (e1x * e2y - e1y * e2x) * shrink
    c1 = e1x * f2y - e1y * f2x + f1x * e2y - f1y * e2x
    c2 = f1x * f2y - f1y * f2x
    return c0, c1, c2


@leaf
def _no_root_up_to(c0, c1, c2, t):
    """True when ``c0 + c1 s + c2 s^2`` stays positive for every ``s`` in ``[0, t]``: positive
    at both ends and no convex dip below zero in between (branch-free, without a division
    or a square root)."""
    return (c0 > 0.0) & (c0 + t * (c1 + t * c2) > 0.0) & (
        (c2 <= 0.0) | (c1 >= 0.0) | (-c1 >= 2.0 * c2 * t) | (4.0 * c0 * c2 > c1 * c1))


@parallel
def max_step(x, d, faces, cap, shrink, out, limiting):
    """Per block of faces, the largest ``t <= cap`` for which ``x + t d`` keeps every face's
    signed area above ``1 - shrink`` times its area at ``x`` (``shrink = 1``: positive;
    the smallest positive root of a quadratic in ``t``).

    A face whose area polynomial has no root in ``[0, best]`` is skipped (most faces); only
    the others solve their quadratic.

    Parameters
    ----------
    x, d : (n, 2) float64
    faces : (m, 3) int32 or int64
    cap : float
        Upper bound of interest (``inf``: none).
    shrink : float
        Largest fraction of its area a face may lose, in (0, 1].
    out : (ceil(m / BLOCK),) float64
        Output: minimum over each block (``cap`` when no face shrinks that far before it).
    limiting : (m,) or (0,) bool
        Output unless empty: the faces whose own bound is below ``cap``.
    """
    m = faces.shape[0]
    nb = out.shape[0]
    flag = limiting.shape[0] > 0
    for b in prange(nb):
        best = cap
        for f in range(np.uint64(b * BLOCK), np.uint64(min(m, (b + 1) * BLOCK))):
            c0, c1, c2 = _area_polynomial(x, d, faces, f, shrink)
            if flag:
                limiting[f] = not _no_root_up_to(c0, c1, c2, cap)
            if not _no_root_up_to(c0, c1, c2, best):
                best = min(best, _first_root(c0, c1, c2))
        out[b] = best


@leaf
def _face_bound(x, d, faces, f, cap, shrink):
    """Face ``f``'s own bound of :func:`max_step`: the largest ``t <= cap``."""
    c0, c1, c2 = _area_polynomial(x, d, faces, f, shrink)
    return cap if _no_root_up_to(c0, c1, c2, cap) else min(cap, _first_root(c0, c1, c2))


@leaf
def max_step_of(x, d, faces, face_list, cap, shrink):
    """:func:`max_step` over the listed faces only (repeats allowed): the largest ``t <= cap``.

    Parameters
    ----------
    x, d : (n, 2) float64
    faces : (m, 3) int32 or int64
    face_list : (k,) int64
    cap, shrink : float
    """
    best = cap
    for p in range(face_list.shape[0]):
        best = _face_bound(x, d, faces, np.uint64(face_list[p]), best, shrink)
    return best


@parallel
def face_steps(x, d, faces, face_list, cap, shrink, out):
    """:func:`max_step_of` per listed face, into ``out`` (k,) float64: each face's own bound."""
    for p in prange(face_list.shape[0]):
        out[p] = _face_bound(x, d, faces, np.uint64(face_list[p]), cap, shrink)


@leaf
def _first_root(c0, c1, c2):
    """Smallest positive root of ``c0 + c1 t + c2 t^2`` (inf if none); 0 if ``c0 <= 0``."""
    if c0 <= 0.0:
        return 0.0
    scale = abs(c0) + abs(c1) + abs(c2)
    if abs(c2) <= 1e-14 * scale:
        if c1 < 0.0:
            return -c0 / c1
        return np.inf
    disc = c1 * c1 - 4.0 * c2 * c0
    if disc < 0.0:
        return np.inf
    sq = math.sqrt(disc)
    q = -0.5 * (c1 + sq) if c1 >= 0.0 else -0.5 * (c1 - sq)
    best = np.inf
    if q != 0.0:
        r1 = q / c2
        r2 = c0 / q
        if r1 > 0.0:
            best = r1
        if 0.0 < r2 < best:
            best = r2
    return best


@leaf
def _angle_step(x, d, b, nx, pv):
    """The largest ``t`` before boundary vertex ``b``'s angle sum at ``x + t d`` reaches
    ``2 pi`` (inf: never), with ``nx`` and ``pv`` its boundary neighbours.

    With ``u = x_nxt - x_b`` and ``w = x_prv - x_b`` the angle sum is a multiple of ``2 pi``
    exactly where ``cross(u, w) = 0`` (a quadratic in ``t``) and ``dot(u, w) > 0``; starting
    below ``2 pi`` with no face flipping, the first such ``t`` is where it reaches ``2 pi``.
    """
    ux = x[nx, 0] - x[b, 0]
    uy = x[nx, 1] - x[b, 1]
    wx = x[pv, 0] - x[b, 0]
    wy = x[pv, 1] - x[b, 1]
    dux = d[nx, 0] - d[b, 0]
    duy = d[nx, 1] - d[b, 1]
    dwx = d[pv, 0] - d[b, 0]
    dwy = d[pv, 1] - d[b, 1]
    c0 = ux * wy - uy * wx
    c1 = ux * dwy - uy * dwx + dux * wy - duy * wx
    c2 = dux * dwy - duy * dwx
    e0 = ux * wx + uy * wy
    e1 = ux * dwx + uy * dwy + dux * wx + duy * wy
    e2 = dux * dwx + duy * dwy
    r1, r2 = _positive_roots(c0, c1, c2)
    if e0 + r1 * (e1 + r1 * e2) > 0.0:
        return r1
    if e0 + r2 * (e1 + r2 * e2) > 0.0:
        return r2
    return np.inf


@parallel
def boundary_max_step(x, d, verts, bprev, bnext, out):
    """Per block of guarded boundary vertices, the largest ``t`` before the vertex's angle
    sum at ``x + t d`` reaches ``2 pi`` (:func:`_angle_step`).

    Parameters
    ----------
    x, d : (n, 2) float64
    verts : (b,) int64
        Guarded boundary vertices (angle sum below ``2 pi`` at ``x``).
    bprev, bnext : (n,) int32
    out : (ceil(b / BLOCK),) float64
        Output: minimum over each block (inf when no angle sum reaches ``2 pi``).
    """
    nv = verts.shape[0]
    for blk in prange(out.shape[0]):
        best = np.inf
        for s in range(blk * BLOCK, min(nv, (blk + 1) * BLOCK)):
            b = verts[s]
            best = min(best, _angle_step(x, d, b, bnext[b], bprev[b]))
        out[blk] = best


@parallel
def boundary_vertex_steps(x, d, verts, bprev, bnext, out):
    """:func:`boundary_max_step` per vertex: ``out`` (b,) float64, each guarded boundary
    vertex's own bound (:func:`_angle_step`)."""
    for s in prange(verts.shape[0]):
        b = verts[s]
        out[s] = _angle_step(x, d, b, bnext[b], bprev[b])


@leaf
def _positive_roots(c0, c1, c2):
    """The non-negative roots of ``c0 + c1 t + c2 t^2`` in increasing order (inf for missing ones)."""
    scale = abs(c0) + abs(c1) + abs(c2)
    if scale == 0.0:
        return np.inf, np.inf
    if abs(c2) <= 1e-14 * scale:
        if c1 != 0.0 and -c0 / c1 >= 0.0:
            return -c0 / c1, np.inf
        return np.inf, np.inf
    disc = c1 * c1 - 4.0 * c2 * c0
    if disc < 0.0:
        return np.inf, np.inf
    sq = math.sqrt(disc)
    q = -0.5 * (c1 + sq) if c1 >= 0.0 else -0.5 * (c1 - sq)
    r1 = q / c2
    r2 = c0 / q if q != 0.0 else r1
    lo = min(r1, r2)
    hi = max(r1, r2)
    if lo < 0.0:
        lo = np.inf
    if hi < 0.0:
        hi = np.inf
    if lo > hi:
        lo, hi = hi, lo
    return lo, hi


@parallel
def vertex_max_steps(x, d, faces, vf_ptr, vf_tri, floors, verts, out):
    """For each listed vertex, the largest ``t <= 1`` for which ``x + t d`` keeps every face
    around it above its floor (all vertices moving along ``d`` together); 0 for a vertex with
    a face at or below its floor that ``d`` does not grow.

    Parameters
    ----------
    x, d : (n, 2) float64
    faces : (m, 3) int32
    vf_ptr, vf_tri
        Incident faces of each vertex (CSR).
    floors : (m,) float64
        Each face's least signed area, doubled.
    verts : (k,) int64
    out : (k,) float64
    """
    for k in prange(verts.shape[0]):
        i = verts[k]
        best = 1.0
        for p in range(vf_ptr[i], vf_ptr[i + 1]):
            c0, c1, c2 = _area_polynomial(x, d, faces, vf_tri[p], 1.0)
            c0 -= floors[vf_tri[p]]
            if c0 <= 0.0:
                if c1 < 0.0 or (c1 == 0.0 and c2 < 0.0):
                    best = 0.0
                continue
            if not _no_root_up_to(c0, c1, c2, best):
                best = min(best, _first_root(c0, c1, c2))
        out[k] = best


@leaf
def ease_scales(x, d, ptr, nbr, sources, values, t, width, max_visit, scale):
    """Lower a direction's per-vertex scales around the vertices that hold its step.

    Each source vertex's scale becomes at most its value, and every vertex's at most a
    source's value plus the length of a path to it in ``x`` over ``width * t`` times the
    larger ``|d|`` of each edge's two ends (Dijkstra's search over the neighbour lists): the
    scaled direction's moves differ between neighbours by at most ``1 / width`` of their
    distance more than ``d``'s over a step of ``t``.

    Parameters
    ----------
    x, d : (n, 2) float64
        Positions and direction.
    ptr, nbr : (n + 1,) and (e,) int64
        Neighbours of each vertex (CSR).
    sources : (k,) int64
    values : (k,) float64
        The sources' scales, in [0, 1).
    t, width : float
        The step aimed at, and the ramp's width in steps.
    max_visit : int
        The search stops after lowering this many vertices.
    scale : (n,) float64
        In/out: each vertex's scale (1: unchanged).

    Returns
    -------
    (j,) int64
        The vertices whose scale went from 1 to below it, in order (``j > max_visit``: stopped).
    """
    heap = [(0.0, np.int64(0))]
    heap.pop()
    lowered = [np.int64(0)]
    lowered.pop()
    for p in range(sources.shape[0]):
        v = np.int64(sources[p])
        if values[p] < scale[v]:
            if scale[v] == 1.0:
                lowered.append(v)
            scale[v] = values[p]
            heapq.heappush(heap, (values[p], v))
    while heap and len(lowered) <= max_visit:
        s, u = heapq.heappop(heap)
        if s > scale[u]:
            continue
        du = math.hypot(d[u, 0], d[u, 1])
        for q in range(ptr[u], ptr[u + 1]):
            v = np.int64(nbr[q])
            reach = width * t * max(du, math.hypot(d[v, 0], d[v, 1]))
            if reach <= 0.0:
                continue
            sv = s + math.hypot(x[v, 0] - x[u, 0], x[v, 1] - x[u, 1]) / reach
            if sv < scale[v]:
                if scale[v] == 1.0:
                    lowered.append(v)
                scale[v] = sv
                heapq.heappush(heap, (sv, v))
    out = np.empty(len(lowered), np.int64)
    for p in range(len(lowered)):
        out[p] = lowered[p]
    return out
