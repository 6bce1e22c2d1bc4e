"""Coarse spaces of the relaxation's preconditioner: bilinear fields on quadtree grids.

The coarse spaces live in the rollout's 2D domain (the reference layout), so nothing is
interpolated across the seam: its two sides lie far apart there. A level ``L`` moves every
vertex by the bilinear interpolation of displacements at the nodes of a ``2^L x 2^L`` grid
over the layout's bounding square. The solver works on the vertices themselves (every
triangle is protected by the flip-avoiding line search); the levels only shape its steps
(:class:`MultilevelPreconditioner`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from potflat.mesh.distortion import bounds
from potflat.relax._kernels import grid as relax_grid
from potflat.relax._kernels.lbfgs import add_jacobi


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
        lo, hi = bounds(ref)
        side = float((hi - lo).max())
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
        return cls(order=order, un=np.take(un, order, axis=0), codes=codes, levels=tuple(levels))

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

    def fractions(self, level: int) -> np.ndarray:
        """Each (sorted) vertex's position within its cell of ``level``, (n, 2) in ``[0, 1]``."""
        out = np.empty_like(self.un)
        relax_grid.cell_fractions(self.un, level, out)
        return out

    def restrict(self, level: int, cell_start: np.ndarray, g: np.ndarray, *,
                 frac: np.ndarray | None = None, corners: np.ndarray | None = None) -> np.ndarray:
        """Transpose of :meth:`prolong` applied to per-vertex values ``g`` (n, k) -> (nodes, k).

        A caller restricting often keeps ``frac`` (:meth:`fractions` of ``level``) and the
        work space ``corners`` ((4^level, 4, k) float64); None: made here."""
        frac = self.fractions(level) if frac is None else frac
        if corners is None:
            corners = np.empty((1 << (2 * level), 4, g.shape[1]))
        out = np.empty((self.n_nodes(level), g.shape[1]))
        relax_grid.restrict(frac, level, cell_start, np.ascontiguousarray(g), corners, out)
        return out


class MultilevelPreconditioner:
    """Additive multilevel (BPX-like) preconditioner of the spring energy's Hessian.

    ``H0 r = D^-1 r + theta sum_L P_L Dbar_L^-1 P_L^T r`` applied to both coordinates alike:
    ``D`` is the per-vertex Hessian diagonal bound (Jacobi), ``P_L`` the bilinear
    prolongation from the nodes of grid level ``L`` (every level of the hierarchy) and
    ``Dbar_L`` at a node the ``P_L``-weighted mean of ``D`` around it: in 2D a spring
    network's stiffness against a smooth coarse field is about the same at every scale, so
    every level gets the same weight. The levels are nested (a coarse bilinear field is
    bilinear on the finer grid), so one restriction from the vertices to the finest grid and
    one prolongation back carry every level; the rest is arithmetic on the grids.

    Parameters
    ----------
    hier : GridHierarchy
    theta : float
        Weight of the coarse corrections relative to the Jacobi term.
    """

    def __init__(self, hier: GridHierarchy, *, theta: float):
        if not hier.levels:
            raise ValueError("the hierarchy has no grid levels")
        self.hier, self.theta = hier, float(theta)
        self.levels = hier.levels  # consecutive, coarse to fine
        self.finest = self.levels[-1]
        self.cell_start = hier.cell_start(self.finest)
        self.frac = hier.fractions(self.finest)
        self._corners: dict[int, np.ndarray] = {}  # restriction work space per column count
        n = len(hier.un)
        self.weight_sums = self._down(self.restrict(np.ones((n, 1))))
        self.inv_mean: list[np.ndarray] = []

    def restrict(self, g: np.ndarray) -> np.ndarray:
        """Per-vertex values ``g`` (n, k) restricted to the finest level's nodes, (nodes, k).

        Linear: a caller that keeps the restrictions of vectors it combines can combine them
        on the nodes (:meth:`apply` and :meth:`coarse_norm` take them) instead of passing
        over the vertices again."""
        k = g.shape[1]
        if k not in self._corners:
            self._corners[k] = np.empty((1 << (2 * self.finest), 4, k))
        return self.hier.restrict(self.finest, self.cell_start, g, frac=self.frac, corners=self._corners[k])

    def _down(self, finest: np.ndarray) -> list[np.ndarray]:
        """Node values of every level (coarse to fine) from the finest level's by restriction."""
        out = [finest]
        for level in reversed(self.levels[:-1]):
            coarse = np.empty((self.hier.n_nodes(level), finest.shape[1]))
            relax_grid.grid_restrict(out[0], level, coarse)
            out.insert(0, coarse)
        return out

    def refresh(self, diag: np.ndarray) -> None:
        """Take the Hessian diagonal bound ``diag`` (n,) of the current state."""
        self.diag = diag
        sums = self._down(self.restrict(diag.reshape(-1, 1)))
        self.inv_mean = [np.where(s > 0, self.theta * w / np.where(s > 0, s, 1.0), 0.0)
                         for s, w in zip(sums, self.weight_sums)]

    def coarse_norm(self, restricted: np.ndarray) -> float:
        """``r . (H0 - D^-1) r``, the coarse levels' part of ``r . H0 r``, for ``r`` (n, 2)
        given by its restriction ``restricted`` (:meth:`restrict`)."""
        parts = self._down(restricted)
        return float(sum(np.sum(p * p * inv) for p, inv in zip(parts, self.inv_mean)))

    def apply(self, r: np.ndarray, out: np.ndarray, *, restricted: np.ndarray | None = None) -> None:
        """``out = H0 r`` for per-vertex vectors ``r``, ``out`` (n, 2) (distinct arrays);
        ``restricted``: :meth:`restrict` of ``r`` when the caller has it."""

        parts = self._down(self.restrict(r) if restricted is None else restricted)
        z = parts[0] * self.inv_mean[0]
        for i, level in enumerate(self.levels[:-1]):
            finer = parts[i + 1] * self.inv_mean[i + 1]
            relax_grid.grid_prolong_add(z, level, finer)
            z = finer
        self.hier.prolong(self.finest, z, out=out)
        add_jacobi(out.reshape(-1), r.reshape(-1), self.diag)
