"""Kernel of :mod:`potflat.mesh.split`: triangles cut into pieces along a level set.

Arrays in, arrays out, no I/O; serial and in order (deterministic).
"""
from __future__ import annotations

import numpy as np

from potflat._jit import leaf


@leaf
def split_pieces(faces, level, cut, points, added, out_faces, out_parent, out_side, out_weights):
    """Cut each face at the added vertices of its cut edges.

    A face with no cut edge stays one piece; with one (the opposite corner lies on the
    cut), two pieces through that corner; with two, the triangle at the corner they share
    and the rest, a quadrilateral, split along its shorter diagonal. Pieces keep their
    face's orientation.

    Parameters
    ----------
    faces : (k, 3) int64
        Faces (indices into ``level`` and ``points``).
    level : (n,) float64
        The level of every vertex (0 on the cut).
    cut : (k, 3) int64
        Added vertex on the face's edge from corner ``c`` to corner ``c + 1`` (``n + j`` for
        the ``j``-th added vertex), -1 where the edge is not cut.
    points : (n, 3) float64
        Positions of the vertices.
    added : (j, 3) float64
        Positions of the added vertices.
    out_faces : (3 k, 3) int64
    out_parent : (3 k,) int64
    out_side : (3 k,) int8
    out_weights : (3 k, 3, 3) float64
        Outputs: pieces, their face, the sign of the level on them (0 when every corner is
        on the cut) and each piece corner's weights of its face's corners.

    Returns
    -------
    int
        Number of pieces written; -1 when a face has three cut edges (a level that is not
        linear on it).
    """
    p = 0
    w = np.zeros((5, 3))  # weights of the corners 0, 1, 2 and of two added vertices
    vid = np.zeros(5, np.int64)
    for f in range(faces.shape[0]):
        n_cut = 0
        for c in range(3):
            if cut[f, c] >= 0:
                n_cut += 1
        if n_cut == 3:
            return -1
        # rotate so that corner 0 is the one the cut edges share (two), or the one whose
        # outgoing edge is cut (one)
        r = 0
        if n_cut == 2:
            while not (cut[f, r] >= 0 and cut[f, (r + 2) % 3] >= 0):
                r += 1
        elif n_cut == 1:
            while cut[f, r] < 0:
                r += 1
        w[:, :] = 0.0
        for c in range(3):
            vid[c] = faces[f, (r + c) % 3]
            w[c, (r + c) % 3] = 1.0
        s0 = level[vid[0]]
        if n_cut == 0:
            side = 0
            for c in range(3):
                if level[vid[c]] > 0.0:
                    side = 1
                elif level[vid[c]] < 0.0:
                    side = -1
            _emit(out_faces, out_parent, out_side, out_weights, p, f, side, vid, w, 0, 1, 2)
            p += 1
            continue
        # the added vertex on edge 0 -> 1, at t = l0 / (l0 - l1) from corner 0
        t = s0 / (s0 - level[vid[1]])
        vid[3] = cut[f, r]
        w[3] = (1.0 - t) * w[0] + t * w[1]
        if n_cut == 1:
            _emit(out_faces, out_parent, out_side, out_weights, p, f, _sign(s0), vid, w, 0, 3, 2)
            _emit(out_faces, out_parent, out_side, out_weights, p + 1, f, _sign(level[vid[1]]), vid, w, 3, 1, 2)
            p += 2
            continue
        # the added vertex on edge 2 -> 0
        l2 = level[vid[2]]
        t = l2 / (l2 - s0)
        vid[4] = cut[f, (r + 2) % 3]
        w[4] = (1.0 - t) * w[2] + t * w[0]
        _emit(out_faces, out_parent, out_side, out_weights, p, f, _sign(s0), vid, w, 0, 3, 4)
        other = _sign(level[vid[1]])
        if _dist2(points, added, vid[3], vid[2]) <= _dist2(points, added, vid[1], vid[4]):
            _emit(out_faces, out_parent, out_side, out_weights, p + 1, f, other, vid, w, 3, 1, 2)
            _emit(out_faces, out_parent, out_side, out_weights, p + 2, f, other, vid, w, 3, 2, 4)
        else:
            _emit(out_faces, out_parent, out_side, out_weights, p + 1, f, other, vid, w, 3, 1, 4)
            _emit(out_faces, out_parent, out_side, out_weights, p + 2, f, other, vid, w, 1, 2, 4)
        p += 3
    return p


@leaf
def _sign(x):
    return 1 if x > 0.0 else (-1 if x < 0.0 else 0)


@leaf
def _dist2(points, added, a, b):
    n = points.shape[0]
    s = 0.0
    for d in range(3):
        e = (points[a, d] if a < n else added[a - n, d]) - (points[b, d] if b < n else added[b - n, d])
        s += e * e
    return s


@leaf
def _emit(out_faces, out_parent, out_side, out_weights, p, f, side, vid, w, i, j, k):
    out_faces[p, 0] = vid[i]
    out_faces[p, 1] = vid[j]
    out_faces[p, 2] = vid[k]
    out_parent[p] = f
    out_side[p] = side
    out_weights[p, 0] = w[i]
    out_weights[p, 1] = w[j]
    out_weights[p, 2] = w[k]
