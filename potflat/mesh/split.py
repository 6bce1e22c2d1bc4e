"""Faces cut exactly along a plane, as GigaMesh cuts a mesh at its prime meridian.

:func:`split_faces` cuts triangles along the zero set of a per-vertex level that is linear
along edges (a plane's signed distance, :func:`plane_levels`): a vertex is added where an
edge crosses the cut, shared by the faces of that edge, and each face becomes the pieces
on either side. What a mesh carries follows the pieces (:class:`FaceSplit`): added
vertices interpolate per-vertex values along their edge, piece corners interpolate
per-corner values (texture coordinates) within their face, per-face values (untextured
flags) are inherited.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from potflat.mesh._kernels.split import split_pieces
from potflat.mesh.tolerances import DEGENERATE

#: A vertex closer to the cut than this fraction of a crossing edge (measured by the level's
#: change along it) counts as on the cut: no piece is a sliver thinner than that.
CUT_SNAP = 0.2


@dataclass(frozen=True, eq=False)
class FaceSplit:
    """Faces cut into pieces along a level set (:func:`split_faces`).

    Attributes
    ----------
    faces : (k, 3) int64
        The pieces, oriented like their face. Index ``i < n`` is vertex ``i`` of the input,
        ``n + j`` the ``j``-th added vertex.
    parent : (k,) int64
        The face (a row of the faces given) each piece is part of; a face's pieces follow
        each other, in the order of the faces (a face not cut is one piece).
    side : (k,) int8
        Sign of the level on each piece: +1, -1, or 0 when all its corners are on the cut.
    weights : (k, 3, 3) float64
        Each piece corner as weights of its face's three corners (each row sums to 1): a
        per-corner value of a piece is ``weights @ values`` of its face (:meth:`corners`).
    edges : (j, 2) int64
        The edge each added vertex lies on (the smaller index first).
    t : (j,) float64
        Where on it: ``(1 - t) x[a] + t x[b]`` for ``edges[j] = (a, b)``, ``0 < t < 1``.
    on_cut : (s,) int64
        Vertices of the faces given that lie on the cut: level 0, or closer to it than
        :data:`CUT_SNAP` of a crossing edge (the cut goes through
        them, so no piece is a sliver). Sorted.
    n : int
        Number of vertices of the input.
    """

    faces: np.ndarray
    parent: np.ndarray
    side: np.ndarray
    weights: np.ndarray
    edges: np.ndarray
    t: np.ndarray
    on_cut: np.ndarray
    n: int

    def added(self, values: np.ndarray) -> np.ndarray:
        """A per-vertex value at the added vertices, interpolated along their edges.

        Parameters
        ----------
        values : (n, ...) float64
            The value at the input's vertices (positions, colours as floats, levels).

        Returns
        -------
        (j, ...) float64
        """
        values = np.asarray(values, dtype=np.float64)
        t = self.t.reshape((-1,) + (1,) * (values.ndim - 1))
        a, b = values[self.edges[:, 0]], values[self.edges[:, 1]]
        return a + t * (b - a)

    def corners(self, corner_values: np.ndarray) -> np.ndarray:
        """A per-corner value of the faces given (texture coordinates), at the pieces' corners.

        Parameters
        ----------
        corner_values : (m, 3, d) float64
            The value at each corner of the faces given.

        Returns
        -------
        (k, 3, d) float64
        """
        return self.weights @ np.asarray(corner_values, dtype=np.float64)[self.parent]


def plane_levels(points: np.ndarray, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Signed distance of ``points`` (k, 3) to the plane through ``point`` with unit ``normal``: (k,) float64."""
    return (np.asarray(points, dtype=np.float64) - np.asarray(point, dtype=np.float64)) @ np.asarray(normal, float)


def snap_to_cut(faces: np.ndarray, level: np.ndarray, *, snap: float = CUT_SNAP) -> tuple[np.ndarray, np.ndarray]:
    """The vertices of ``faces`` ((m, 3) int64) that :func:`split_faces` puts on the cut of
    ``level`` ((n,) float64): level 0, or closer to the cut than ``snap`` times the level's
    change along a crossing edge of those faces.

    Returns
    -------
    level : (n,) float64
        A copy, 0 at those vertices (snapping it again puts no other vertex on the cut).
    on_cut : (s,) int64
        Those vertices, sorted.
    """
    level = np.array(level, dtype=np.float64)
    tail, head = faces, np.roll(faces, -1, axis=1)  # corner c's outgoing edge
    lt, lh = level[tail], level[head]
    crossing = lt * lh < 0
    frac = np.divide(lt, lt - lh, out=np.ones_like(lt), where=crossing)
    near = np.zeros(len(level), bool)
    near[tail[crossing & (frac < snap)]] = True
    near[head[crossing & (frac > 1.0 - snap)]] = True
    near[faces[level[faces] == 0.0]] = True
    on_cut = np.flatnonzero(near)
    level[on_cut] = 0.0
    return level, on_cut


def cut_moves(faces: np.ndarray, level: np.ndarray, *, snap: float = CUT_SNAP
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where to move the vertices :func:`snap_to_cut` would put on the cut so that they lie on it.

    Snapping keeps a vertex where it is, so the cut through it leaves the level's zero set
    by up to ``snap`` of an edge: a cut along a plane zigzags about it. Moving each such
    vertex along its nearest crossing edge to where the level is 0 keeps the cut exact and
    still leaves no sliver (every crossing of a moved vertex's edges was at least ``snap``
    of the edge from the vertex's new place or is gone).

    Parameters
    ----------
    faces : (m, 3) int64
    level : (n,) float64
        Linear along edges (a plane's signed distance).
    snap : float
        As for :func:`snap_to_cut`.

    Returns
    -------
    vertices : (s,) int64
        The vertices to move (sorted; those at level 0 are on the cut already).
    towards : (s,) int64
        The other end of each one's nearest crossing edge (the lower index among equals).
    t : (s,) float64
        Where on that edge the level is 0: ``(1 - t) x[vertex] + t x[towards]``, ``0 < t < snap``.
    """
    level = np.asarray(level, dtype=np.float64)
    tail, head = faces.ravel(), np.roll(faces, -1, axis=1).ravel()
    lt, lh = level[tail], level[head]
    crossing = lt * lh < 0
    tail, head, lt, lh = tail[crossing], head[crossing], lt[crossing], lh[crossing]
    frac = lt / (lt - lh)
    near_tail, near_head = frac < snap, frac > 1.0 - snap
    vertex = np.concatenate([tail[near_tail], head[near_head]])
    towards = np.concatenate([head[near_tail], tail[near_head]])
    t = np.concatenate([frac[near_tail], 1.0 - frac[near_head]])
    order = np.lexsort((towards, t, vertex))  # per vertex: the nearest crossing first
    vertex, towards, t = vertex[order], towards[order], t[order]
    first = np.ones(len(vertex), bool)
    first[1:] = vertex[1:] != vertex[:-1]
    return vertex[first], towards[first], t[first]


def plane_weights(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Each point as weights of its triangle's corners: the barycentric coordinates of its
    projection onto the triangle's plane (negative outside the triangle: the triangle's
    linear map extended). A degenerate triangle gives its first corner.

    Parameters
    ----------
    triangles : (k, 3, 3) float64
        Corners.
    points : (k, 3) float64

    Returns
    -------
    (k, 3) float64
        Rows summing to 1.
    """
    p0 = triangles[:, 0]
    e1, e2, d = triangles[:, 1] - p0, triangles[:, 2] - p0, np.asarray(points, dtype=np.float64) - p0
    g11, g12, g22 = (e1 * e1).sum(axis=1), (e1 * e2).sum(axis=1), (e2 * e2).sum(axis=1)
    r1, r2 = (e1 * d).sum(axis=1), (e2 * d).sum(axis=1)
    det = g11 * g22 - g12 * g12
    ok = det > DEGENERATE * g11 * g22
    safe = np.where(ok, det, 1.0)
    b = np.where(ok, (g22 * r1 - g12 * r2) / safe, 0.0)
    c = np.where(ok, (g11 * r2 - g12 * r1) / safe, 0.0)
    return np.stack([1.0 - b - c, b, c], axis=1)


def split_faces(points: np.ndarray, faces: np.ndarray, level: np.ndarray, *, snap: float = CUT_SNAP) -> FaceSplit:
    """Cut triangles along the zero set of a level that is linear along edges.

    Each edge whose ends have levels of opposite signs gets a vertex where the linear
    interpolation of the level is 0 (on the plane, for a plane's signed distance), one per
    edge whatever the number of faces on it. A vertex closer to the cut than ``snap`` times
    the level's change along a crossing edge counts as on it (the edge is not cut there),
    so every added vertex lies at least that fraction of its edge from both ends. A face is
    then one piece (no cut edge), two (one cut edge: the cut runs through the opposite
    corner) or three (two cut edges; the quadrilateral split along its shorter diagonal).

    Faces sharing a cut edge must be cut together: give them all, or the mesh gets a crack.

    Parameters
    ----------
    points : (n, 3) float64
        Vertex positions.
    faces : (m, 3) int64
        The faces to cut.
    level : (n,) float64
        The level of every vertex, e.g. :func:`plane_levels`.
    snap : float
        See above; 0 cuts every crossing edge however close to a vertex.

    Returns
    -------
    FaceSplit

    Raises
    ------
    ValueError
        When the arrays do not fit together, a value is not finite, or ``snap`` is not in
        ``[0, 0.5)``.
    """
    points = np.ascontiguousarray(points, dtype=np.float64)
    faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    level = np.asarray(level, dtype=np.float64)
    n = len(points)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be (n, 3), got {points.shape}")
    if level.shape != (n,):
        raise ValueError(f"level must have one value per point, shape ({n},), got {level.shape}")
    if len(faces) and (faces.min() < 0 or faces.max() >= n):
        raise ValueError("faces name vertices outside points")
    if not (np.isfinite(level).all() and np.isfinite(points).all()):
        raise ValueError("points and level must be finite")
    if not 0.0 <= snap < 0.5:
        raise ValueError(f"snap must be in [0, 0.5), got {snap}")
    level, on_cut = snap_to_cut(faces, level, snap=snap)
    tail, head = faces, np.roll(faces, -1, axis=1)  # corner c's outgoing edge
    lt, lh = level[tail], level[head]
    crossing = lt * lh < 0
    a, b = np.minimum(tail, head)[crossing], np.maximum(tail, head)[crossing]
    keys, which = np.unique(a * np.int64(n) + b, return_inverse=True)
    edges = np.stack([keys // n, keys % n], axis=1)
    la, lb = level[edges[:, 0]], level[edges[:, 1]]
    t = la / (la - lb)
    pa, pb = points[edges[:, 0]], points[edges[:, 1]]
    added = pa + t[:, None] * (pb - pa)
    cut = np.full(faces.shape, -1, np.int64)
    cut[crossing] = n + which.ravel()
    k = 3 * len(faces)
    out_faces, out_parent = np.empty((k, 3), np.int64), np.empty(k, np.int64)
    out_side, out_weights = np.empty(k, np.int8), np.empty((k, 3, 3))
    count = split_pieces(faces, level, cut, points, added, out_faces, out_parent, out_side, out_weights)
    if count < 0:
        raise ValueError("a face has three edges crossing the cut: the level is not linear along its edges")
    return FaceSplit(faces=out_faces[:count], parent=out_parent[:count], side=out_side[:count],
                     weights=out_weights[:count], edges=edges, t=t, on_cut=on_cut, n=n)
