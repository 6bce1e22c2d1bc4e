"""Coarse copies of a rollout for the relaxation: grid clusters of its start layout.

The start layout is cut into square cells of a given side; the fine vertices of each
occupied cell make one coarse vertex, at their mean 3D position and their mean layout
position. Coarse triangles join the cells of every 2 x 2 block of the grid: two triangles
where all four cells are occupied, one where three are. Such a mesh is near-regular (the
relaxation converges in few iterations on it), nearly always fold-free in the start (each
coarse vertex lies in its own cell; a triangle flips only when its vertices sit at extreme
corners of their cells, which the relaxation's untangling fixes), and its springs measure
the surface at the cell scale. The fine vertices then follow the coarse layout's
piecewise-linear map (:func:`interpolate`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from potflat.mesh.distortion import bounds
from potflat.relax._kernels.simplify import interpolate as kernel
from potflat.mesh._kernels.topology import vertex_faces

#: A grid of at most this many cells per fine vertex is indexed directly (counting, no sort:
#: at 3M vertices 0.33 against 1.1 s; the default side gives about 1/8), a finer one (a tiny
#: ``simplify_mm``) by sorting its occupied cells' keys: its per-cell arrays would outgrow
#: the vertices'.
DENSE_GRID_CELLS_PER_VERTEX = 1


@dataclass(frozen=True)
class Simplification:
    """A coarse copy of a rollout and how its vertices relate to the full one.

    Attributes
    ----------
    vertices : (nc, 3) float64
        Coarse 3D positions (means of the cells' fine vertices).
    faces : (mc, 3) int64
        Counter-clockwise in the start layout.
    uv : (nc, 2) float64
        Coarse start layout (means of the cells' fine start positions).
    cluster : (n,) int64
        Coarse vertex (cell) of each fine vertex.
    """

    vertices: np.ndarray
    faces: np.ndarray
    uv: np.ndarray
    cluster: np.ndarray


def cell_side(uv: np.ndarray, vertices_per_cell: float) -> float:
    """Cell side giving about ``vertices_per_cell`` fine vertices per cell, from the layout's
    mean vertex density over its bounding box (occupied cells hold more when the layout
    fills its box only partly)."""
    lo, hi = bounds(uv)
    area = float(np.prod(np.maximum(hi - lo, 1e-300)))
    return math.sqrt(vertices_per_cell * area / max(len(uv), 1))


def grid_simplification(vertices: np.ndarray, uv: np.ndarray, side: float) -> Simplification:
    """Cluster the vertices by square cells of ``side`` in the start layout ``uv``.

    Parameters
    ----------
    vertices : (n, 3) float64
    uv : (n, 2) float64
        Start layout (fold-free).
    side : float
        Cell side in layout units (> 0).

    Returns
    -------
    Simplification
    """
    lo = bounds(uv)[0]
    ij = np.floor((uv - lo) / side).astype(np.int64) + 1  # a free row and column on every side
    nx, ny = int(ij[:, 0].max()) + 2, int(ij[:, 1].max()) + 2
    key = ij[:, 1] * nx + ij[:, 0]
    # the occupied cells in key order, each vertex's cell among them, and the coarse vertex of
    # a cell key (-1 when empty)
    dense = nx * ny <= DENSE_GRID_CELLS_PER_VERTEX * len(key)
    if dense:  # counted over the grid's cells (about n / 8 of them at the default side)
        per_cell = np.bincount(key, minlength=nx * ny)
        cells = np.flatnonzero(per_cell)
        count = per_cell[cells].astype(np.float64)
        del per_cell
        coarse_of = np.full(nx * ny, -1, np.int64)
        coarse_of[cells] = np.arange(len(cells))
        cluster = coarse_of[key]

        def index(k: np.ndarray) -> np.ndarray:
            return coarse_of[k]
    else:
        cells, cluster = np.unique(key, return_inverse=True)
        count = np.bincount(cluster, minlength=len(cells)).astype(np.float64)

        def index(k: np.ndarray) -> np.ndarray:
            p = np.minimum(np.searchsorted(cells, k), len(cells) - 1)
            return np.where(cells[p] == k, p, -1)
    nc = len(cells)

    def mean(a: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(np.stack([np.bincount(cluster, a[:, j], minlength=nc) for j in range(a.shape[1])],
                                             axis=1) / count[:, None])

    # every 2 x 2 block with an occupied cell, named by its lower-left cell (in key order)
    if dense:
        in_block = np.zeros(nx * ny, bool)
        for shift in (0, 1, nx, nx + 1):
            in_block[cells - shift] = True
        block = np.flatnonzero(in_block)
        del in_block
    else:
        block = np.unique(np.concatenate([cells, cells - 1, cells - nx, cells - nx - 1]))
    a, b, c, d = index(block), index(block + 1), index(block + nx), index(block + nx + 1)  # ll, lr, ul, ur
    full = (a >= 0) & (b >= 0) & (c >= 0) & (d >= 0)
    faces = [np.stack([a, b, d], axis=1)[full], np.stack([a, d, c], axis=1)[full]]
    for tri, missing in (((a, b, d), c), ((a, b, c), d), ((a, d, c), b), ((b, d, c), a)):
        three = (missing < 0) & (tri[0] >= 0) & (tri[1] >= 0) & (tri[2] >= 0)
        faces.append(np.stack(tri, axis=1)[three])
    return Simplification(vertices=mean(np.asarray(vertices, dtype=np.float64)),
                          faces=np.ascontiguousarray(np.concatenate(faces), dtype=np.int64),
                          uv=mean(np.asarray(uv, dtype=np.float64)), cluster=cluster.astype(np.int64))


def interpolate(s: Simplification, uv: np.ndarray, uv_coarse: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fine layout from the relaxed coarse one.

    Parameters
    ----------
    s : Simplification
    uv : (n, 2) float64
        The fine start layout.
    uv_coarse : (nc, 2) float64
        The coarse layout the fine one is to follow (from ``s.uv``).

    Returns
    -------
    moved : (n, 2) float64
        ``uv`` moved by the piecewise-linear map from ``s.uv`` to ``uv_coarse`` (vertices
        outside the copy: see :func:`potflat.relax._kernels.simplify.interpolate`).
    inside : (n,) bool
        Which fine vertices lie inside the copy.
    """

    vf_ptr, vf_tri = vertex_faces(len(s.uv), s.faces)
    out = np.empty((len(uv), 2))
    inside = np.empty(len(uv), bool)
    kernel(np.ascontiguousarray(uv, dtype=np.float64), s.cluster, np.ascontiguousarray(s.uv),
           np.ascontiguousarray(uv_coarse, dtype=np.float64), s.faces, vf_ptr, vf_tri, out, inside)
    return out, inside
