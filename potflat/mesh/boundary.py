"""Boundary checks of a flattening: which boundary segments cross or touch each other.

One implementation for every stage: the rollout trims the faces of a border that overlaps
itself and reports the count, the relax stage refuses a result whose border does
(:mod:`potflat.mesh._segments` holds the Numba kernels).
"""
from __future__ import annotations

import numpy as np

from potflat.mesh import _segments
from potflat.mesh._kernels.topology import edge_table
from potflat.mesh.tolerances import DEGENERATE

#: Finest grid of the search: the cell is at least the layout's extent over this.
GRID_CELLS = 2048


def _coerced(uv, seg) -> tuple[np.ndarray, np.ndarray]:
    uv = np.ascontiguousarray(uv, dtype=np.float64)
    seg = np.ascontiguousarray(seg, dtype=np.int64).reshape(-1, 2)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must be (n, 2), got {uv.shape}")
    if len(seg) and (seg.min() < 0 or seg.max() >= len(uv)):
        raise ValueError("segments name vertices outside uv")
    return uv, seg


def _cell(uv: np.ndarray, seg: np.ndarray) -> float:
    """Grid cell of the search: twice the mean segment length, at least the extent over
    :data:`GRID_CELLS`."""
    lens = np.linalg.norm(uv[seg[:, 0]] - uv[seg[:, 1]], axis=1)
    extent = float(np.ptp(uv[seg.ravel()], axis=0).max()) or 1.0
    return max(2.0 * float(np.mean(lens)), extent / GRID_CELLS, DEGENERATE)  # a layout collapsed to a point


def crossing_pairs(uv: np.ndarray, seg: np.ndarray, *, max_pairs: int | None = None) -> np.ndarray:
    """Pairs of segments that cross or touch (segments sharing a vertex are not compared).

    Parameters
    ----------
    uv : (n, 2) float64
    seg : (b, 2) int64
        Segments as vertex index pairs (typically the boundary of a flattening).
    max_pairs : int, optional
        Stop after this many pairs (default: all).

    Returns
    -------
    (k, 2) int64
        Indices into ``seg`` of each crossing pair.
    """

    uv, seg = _coerced(uv, seg)
    if len(seg) < 2:
        return np.zeros((0, 2), np.int64)
    limit = np.iinfo(np.int64).max if max_pairs is None else int(max_pairs)
    return _segments.crossing_pairs(uv, seg, _cell(uv, seg), limit)


def edges_and_boundary(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The undirected edges of a triangle mesh and its boundary segments (edges of one face).

    Parameters
    ----------
    faces : (m, 3) int64
    n : int
        Number of vertices.

    Returns
    -------
    edges : (e, 2) int64
        Endpoints (smaller first), sorted lexicographically.
    segments : (b, 2) int64
        Boundary edges as vertex pairs in their face's order, in the order of ``edges``.
    owner : (b,) int64
        The face of each segment.
    """

    F = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    _, edges, count, halves = edge_table(F, int(n))
    half = halves[count == 1, 0]
    owner, k = half // 3, half % 3
    return edges, np.stack([F[owner, k], F[owner, (k + 1) % 3]], axis=1), owner


def outline_turning(faces: np.ndarray, uv: np.ndarray, *, segments: np.ndarray | None = None) -> float:
    """Total turning of a flattening's outline: the sum of the absolute exterior angles at
    every boundary vertex, over all boundary loops (the outline and the holes), over 2 pi.

    A convex outline without holes turns once (1.0); every tooth of a saw-toothed edge adds
    about twice its angle, so the figure measures how ragged the outline is.

    Parameters
    ----------
    faces : (m, 3) int64
    uv : (n, 2) float64
    segments : (b, 2) int64, optional
        The boundary segments (``edges_and_boundary(faces, n)[1]``) when the caller has them.

    Returns
    -------
    float
    """
    uv = np.ascontiguousarray(uv, dtype=np.float64)
    if segments is None:
        segments = edges_and_boundary(faces, len(uv))[1]
    seg = np.ascontiguousarray(segments, dtype=np.int64).reshape(-1, 2)
    if len(seg) == 0:
        return 0.0
    # each segment is followed by one that starts where it ends (the k-th arriving at a
    # vertex by the k-th leaving it, where the boundary touches itself)
    into = np.argsort(seg[:, 1], kind="stable")
    out_of = np.argsort(seg[:, 0], kind="stable")
    if not np.array_equal(seg[into, 1], seg[out_of, 0]):
        raise ValueError("the boundary segments do not form closed loops")
    d = uv[seg[:, 1]] - uv[seg[:, 0]]
    d1, d2 = d[into], d[out_of]
    angle = np.arctan2(d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0], (d1 * d2).sum(axis=1))
    return float(np.abs(angle).sum() / (2.0 * np.pi))


def surface_turning(vertices: np.ndarray, faces: np.ndarray, *, segments: np.ndarray | None = None) -> float:
    """Total turning of a mesh's boundary on the surface itself: at every boundary vertex,
    ``pi`` (once per pass of the boundary through it) less the sum of its faces' 3D corner
    angles there (the boundary's geodesic turning), absolute, summed over 2 pi.

    It is :func:`outline_turning` of a flattening that keeps every triangle's shape, so a
    layout's outline turning set against it tells what the layout adds to (or takes from) the
    raggedness of the scan's own boundary.

    Parameters
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int64
    segments : (b, 2) int64, optional
        The boundary segments (``edges_and_boundary(faces, n)[1]``) when the caller has them.

    Returns
    -------
    float
    """
    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    if segments is None:
        segments = edges_and_boundary(F, len(V))[1]
    seg = np.ascontiguousarray(segments, dtype=np.int64).reshape(-1, 2)
    if len(seg) == 0:
        return 0.0
    passes = np.bincount(seg[:, 0], minlength=len(V))
    total = corner_angle_sums(V, F, passes > 0)
    ends = np.flatnonzero(passes)
    return float(np.abs(np.pi * passes[ends] - total[ends]).sum() / (2.0 * np.pi))


def corner_angle_sums(vertices: np.ndarray, faces: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The sum of the faces' corner angles at each vertex ``at`` selects (its fan's total angle;
    in 3D, 2 pi less its angle defect inside the mesh).

    Parameters
    ----------
    vertices : (n, 2) or (n, 3) float64
    faces : (m, 3) int64
    at : (n,) bool
        The vertices wanted (only their faces are visited).

    Returns
    -------
    (n,) float64
        0 at the vertices not wanted.
    """
    V = np.asarray(vertices, dtype=np.float64)
    near = faces[at[faces].any(axis=1)]
    P = V[near]
    total = np.zeros(len(V))
    for c in range(3):
        a, b = P[:, (c + 1) % 3] - P[:, c], P[:, (c + 2) % 3] - P[:, c]
        sine = (np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]) if V.shape[1] == 2
                else np.linalg.norm(np.cross(a, b), axis=1))
        total += np.bincount(near[:, c], np.arctan2(sine, (a * b).sum(axis=1)), minlength=len(V))
    return np.where(at, total, 0.0)


def turning_words(turning: dict) -> str:
    """One line on how ragged the relaxed outline is beside the rollout's, from the relaxed
    JSON's ``outline_turning`` (:func:`outline_turning` of each)."""
    ratio = turning.get("ratio")
    surface = turning.get("surface")
    return (f"outline: turns {turning['relaxed']:.2f} times round (the rollout's {turning['rollout']:.2f}"
            + (f", {ratio:.2f}x" if ratio is not None else "")
            + (f"; the scan's boundary on the surface {surface:.2f}" if surface is not None else "")
            + "; 1 is a convex outline without holes)")
