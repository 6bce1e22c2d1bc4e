"""Coarse-to-fine spaces for the relaxation: bilinear displacement fields on quadtree grids.

The coarse spaces live in the rollout's 2D domain (the reference layout), so nothing is
interpolated across the seam: its two sides lie far apart there. A level ``L`` moves every
vertex by the bilinear interpolation of displacements at the nodes of a ``2^L x 2^L`` grid
over the layout's bounding square; the fine mesh's own springs and triangles are evaluated
at every level, so the flip-avoiding line search protects every triangle at every level.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from potflat._kernels import relax_grid


@dataclass(frozen=True)
class GridHierarchy:
    """Morton order of the vertices and the grid levels over the reference layout.

    Attributes
    ----------
    order : (n,) int64
        Vertex permutation: row ``r`` of the sorted arrays is vertex ``order[r]``.
    un : (n, 2) float64
        Reference positions, sorted, scaled into the unit square.
    codes : (n,) int64
        Sorted Morton codes of ``un``.
    levels : tuple of int
        Grid levels (``2^L`` cells per side), coarse to fine.
    """

    order: np.ndarray
    un: np.ndarray
    codes: np.ndarray
    levels: tuple

    @classmethod
    def build(cls, ref: np.ndarray, *, min_vertices_per_cell: float, coarsest: int = 2) -> GridHierarchy:
        """Sort the vertices along a Morton curve of ``ref`` and choose the levels.

        Parameters
        ----------
        ref : (n, 2) float64
            Reference layout.
        min_vertices_per_cell : float
            The finest level keeps at least this many vertices per occupied cell on average.
        coarsest : int
            Level of the coarsest grid.
        """
        lo = ref.min(axis=0)
        side = float((ref.max(axis=0) - lo).max())
        side = side if side > 0 else 1.0
        un = np.ascontiguousarray((ref - lo) / side)
        codes = np.empty(len(ref), np.int64)
        relax_grid.morton_codes(un, codes)
        order = np.argsort(codes, kind="stable")
        codes = codes[order]
        levels = []
        for level in range(coarsest, relax_grid.QBITS + 1):
            cells = codes >> (2 * (relax_grid.QBITS - level))
            occupied = 1 + int(np.count_nonzero(np.diff(cells)))
            if len(ref) / occupied < min_vertices_per_cell:
                break
            levels.append(level)
        return cls(order=order, un=np.ascontiguousarray(un[order]), codes=codes, levels=tuple(levels))

    def cell_start(self, level: int) -> np.ndarray:
        """First sorted vertex of every cell of ``level`` (Morton order), shape (4^level + 1,)."""
        cells = self.codes >> (2 * (relax_grid.QBITS - level))
        return np.searchsorted(cells, np.arange((1 << (2 * level)) + 1), side="left").astype(np.int64)

    @staticmethod
    def n_nodes(level: int) -> int:
        """Number of grid nodes of ``level``."""
        return ((1 << level) + 1) ** 2

    def prolong(self, level: int, c: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Displacement of every (sorted) vertex from node values ``c`` ((nodes, 2)) -> (n, 2),
        written into ``out`` when given."""
        if out is None:
            out = np.empty((len(self.un), 2))
        relax_grid.prolong(self.un, level, np.ascontiguousarray(c), out)
        return out

    def restrict(self, level: int, cell_start: np.ndarray, g: np.ndarray) -> np.ndarray:
        """Transpose of :meth:`prolong` applied to per-vertex values ``g`` (n, 2) -> (nodes, 2)."""
        out = np.empty((self.n_nodes(level), 2))
        relax_grid.restrict(self.un, level, cell_start, np.ascontiguousarray(g), out)
        return out
