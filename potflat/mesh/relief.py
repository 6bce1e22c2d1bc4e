"""The relief of a scan on its flat layout: how far each point of the surface lies above or
below the same surface smoothed, with the vessel's form taken out.

The smoothed surface is a local quadric fit over the flat coordinates: around each node of a
grid ``sigma`` apart laid over the layout, the 3D positions of the vertices within ``2.5
sigma`` are fitted by a quadric in the flat coordinates, each vertex weighted by its area and a
Gaussian of standard deviation ``sigma`` (:func:`potflat.mesh._kernels.relief.fit_quadrics`,
from the moments of the vertices of cells ``sigma / 2`` wide, so a fit costs the same however
dense the mesh); at each vertex the fits of its four nearest nodes are evaluated and blended
bilinearly.
A quadric reproduces the vessel's curvature exactly, so the form leaves no offset in the
relief (a mean would sink into a curved wall by about ``H sigma^2``, 0.1-0.2 mm at 4 mm on a
vessel's shoulder), and every vertex is visited by a fixed number of nodes: linear time, no
solve of a system of the whole mesh. The fit is repeated with robust weights
(:data:`ROBUST_REFITS`), so grooves and bosses do not pull the smoothed surface. The flat layout is nearly isometric, so ``sigma`` is a
length on the surface too.

From the fit, for every vertex: its **height** above the smoothed surface along the surface's
normal (mm); the scan's normal in the smoothed surface's frame (image right, image up, out),
which raking light is computed from; and a **multi-scale volume invariant** in the spirit of
MSII (Mara et al.): the share of a ball about the vertex below the height field, minus one
half, averaged over a few radii (:func:`potflat.mesh._kernels.relief.volume_invariants`):
positive in grooves and pits, negative on ridges and bosses, 0 on a plane.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from potflat.errors import InvalidOptionError
from potflat.mesh._kernels.geometry import triangle_areas, vertex_normal_sums
from potflat.mesh._kernels.relief import (
    MOMENTS,
    TERMS,
    blend_quadrics,
    blend_scalar,
    cell_moments,
    fit_quadrics,
    volume_invariants,
)
from potflat.mesh.distortion import weighted_percentiles

#: Default scale (mm) of the smoothed surface: grooves, stamps and relief decoration are
#: narrower, a vessel's form is wider (the bake's default, ``BakeOptions.relief_mm``).
SMOOTHING_MM = 4.0
#: Smallest smoothing scale, in edge lengths of the mesh: a fit needs vertices enough in its
#: reach, else the relief is the mesh's own facets (a 18k-vertex vase 45 cm tall, edges 4.7 mm:
#: noise at 4 mm, its rim, throwing rings and a mould seam at 14 mm). A smaller scale asked for
#: is raised to it (:attr:`SurfaceRelief.smoothing_mm` and ``requested_mm`` say so).
SMOOTHING_MIN_EDGES = 3.0
#: Vertices of the cells within this many sigma of a node take part in its fit; the cells are
#: ``1 / FIT_CELLS_PER_SIGMA`` sigma wide (the fit's Gaussian is taken per cell), the nodes sigma apart.
FIT_REACH_SIGMA = 2.5
FIT_CELLS_PER_SIGMA = 2
#: Weight that holds a fit's quadratic terms towards zero, relative to its total weight (the
#: quadratic terms' own weight is about 3 times the total in the middle of the surface).
QUADRIC_RIDGE = 1e-3
#: Robust refits of the smoothed surface: each weights every vertex by Huber's function of its
#: height (over :data:`HUBER_K` times the heights' robust spread, 1.4826 times their median
#: absolute deviation, at least :data:`ROBUST_SPREAD_MM`), so the decoration does not pull the
#: smoothed surface towards it (a groove field would raise the plain surface beside it).
#: Measured on the hydria patch of ``potflat_synthetic.relief``: grooves 15% too shallow by a
#: plain fit, 3.4% after one refit, 0.9% after two; the plain wall between them within
#: -0.005..0.048 mm, then -0.004..0.004 mm.
ROBUST_REFITS = 2
HUBER_K = 1.345
ROBUST_SPREAD_MM = 0.005
#: Largest ball radius of the volume invariant, as a share of the smoothing scale, and how
#: many radii (each 2^(-2/3) of the one before).
INVARIANT_LARGEST = 0.25
INVARIANT_RADII = 4
#: Smallest ball radius, in edge lengths of the mesh (a smaller ball holds no neighbour).
INVARIANT_SMALLEST_EDGES = 1.2
#: Most vertices the largest ball holds on average (bounds the invariant's cost on a dense
#: mesh: its radius shrinks to hold no more).
INVARIANT_MOST_VERTICES = 200
#: Most grid cells the fit may use (bounds its memory: about 300 bytes a cell); on a layout
#: too large for them at the scale asked for, the scale is raised to fit.
MAX_CELLS = 4_000_000


@dataclass(frozen=True, eq=False)
class SurfaceRelief:
    """The relief of a scan, per vertex.

    Attributes
    ----------
    height_mm : (n,) float64
        Height above the smoothed surface along its outward normal, mm (0 for vertices of no
        face).
    frame_normal : (n, 3) float64
        The scan's unit vertex normal in the smoothed surface's frame: along image right,
        image up and out of the surface.
    concavity : (n,) float64
        Volume invariant minus its value on a plane, mean over :attr:`radii_mm`: from -1/2
        (peak) through 0 (plane) to +1/2 (pit).
    vertex_area_mm2 : (n,) float64
        Each vertex's share of the surface (a third of its faces' areas).
    smoothing_mm : float
        The smoothed surface's scale (Gaussian sigma of the fit): the one asked for, or
        :data:`SMOOTHING_MIN_EDGES` edge lengths when that is larger (or the smallest whose
        grid fits :data:`MAX_CELLS` cells, on a huge layout).
    requested_mm : float
        The scale asked for.
    radii_mm : tuple of float
        The ball radii of :attr:`concavity`, ascending.
    spacing_mm : float
        The mesh's typical edge length (of an equilateral triangle of the median face area).
    """

    height_mm: np.ndarray
    frame_normal: np.ndarray
    concavity: np.ndarray
    vertex_area_mm2: np.ndarray
    smoothing_mm: float
    requested_mm: float
    radii_mm: tuple
    spacing_mm: float

    @cached_property
    def columns(self) -> np.ndarray:
        """Height, frame normal and concavity as columns (n, 5) float64, for interpolation."""
        return np.ascontiguousarray(np.column_stack([self.height_mm, self.frame_normal, self.concavity]))

    def height_percentiles(self, qs) -> list[float]:
        """Area-weighted percentiles (0-100) of the height, mm."""
        return weighted_percentiles(self.height_mm, self.vertex_area_mm2, qs)

    def concavity_percentiles(self, qs) -> list[float]:
        """Area-weighted percentiles (0-100) of the concavity."""
        return weighted_percentiles(self.concavity, self.vertex_area_mm2, qs)


def _robust_weights(height: np.ndarray, area: np.ndarray, used: np.ndarray) -> np.ndarray:
    """Each vertex's area times Huber's weight of its height (:data:`HUBER_K` robust spreads)."""
    centre = weighted_percentiles(height[used], area[used], (50.0,))[0]
    spread = 1.4826 * weighted_percentiles(np.abs(height[used] - centre), area[used], (50.0,))[0]
    limit = HUBER_K * max(spread, ROBUST_SPREAD_MM)
    return area * np.minimum(1.0, limit / np.maximum(np.abs(height - centre), limit))


def _sorted_by_cell(xy: np.ndarray, used: np.ndarray, origin: np.ndarray, cell: float, nx: int, ny: int):
    """The used points' indices sorted by grid cell (stable) and each cell's start: ``order``
    (k,) int64, ``ptr`` (nx ny + 1,) int64."""
    ix = np.clip(((xy[used, 0] - origin[0]) / cell).astype(np.int64), 0, nx - 1)
    iy = np.clip(((xy[used, 1] - origin[1]) / cell).astype(np.int64), 0, ny - 1)
    key = iy * nx + ix
    order = np.flatnonzero(used)[np.argsort(key, kind="stable")]
    ptr = np.zeros(nx * ny + 1, np.int64)
    np.cumsum(np.bincount(key, minlength=nx * ny), out=ptr[1:])
    return np.ascontiguousarray(order, dtype=np.int64), ptr


def _grid(xy: np.ndarray, used: np.ndarray, cell: float):
    lo = xy[used].min(axis=0)
    hi = xy[used].max(axis=0)
    nx, ny = (int(k) + 1 for k in np.floor((hi - lo) / cell))
    return lo, nx, ny


def invariant_radii(smoothing_mm: float, spacing_mm: float, vertices_per_mm2: float) -> tuple:
    """The ball radii of the volume invariant (mm, ascending): from
    :data:`INVARIANT_LARGEST` of the smoothing scale (or less on a mesh so dense that the ball
    would hold over :data:`INVARIANT_MOST_VERTICES` vertices) down by 2^(-2/3) a step, none
    under :data:`INVARIANT_SMALLEST_EDGES` edge lengths (the largest is raised to that when it
    is under it)."""
    floor = INVARIANT_SMALLEST_EDGES * spacing_mm
    largest = min(INVARIANT_LARGEST * smoothing_mm, math.sqrt(INVARIANT_MOST_VERTICES / (math.pi * vertices_per_mm2)))
    largest = max(largest, floor)
    radii = [largest * 2.0 ** (-2.0 * k / 3.0) for k in range(INVARIANT_RADII)]
    return tuple(sorted(r for r in radii if r >= floor * (1 - 1e-9)))


def surface_relief(vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray, *, smoothing_mm: float,
                   mm_per_unit: float = 1.0) -> SurfaceRelief:
    """The relief of a surface against itself smoothed at ``smoothing_mm``.

    Parameters
    ----------
    vertices : (n, 3) float64
        3D positions, scan units.
    faces : (m, 3) int64
    uv : (n, 2) float64
        The flat layout (scan units; u right, v up, seen from outside), nearly isometric.
    smoothing_mm : float
        Scale of the smoothed surface (Gaussian sigma of the local fits), mm: detail narrower
        than about this is relief, wider shapes are form (raised to :data:`SMOOTHING_MIN_EDGES`
        edge lengths on a coarse mesh).
    mm_per_unit : float
        Millimetres per scan unit.

    Returns
    -------
    SurfaceRelief

    Raises
    ------
    InvalidOptionError
        ``smoothing_mm`` not a positive number.
    ValueError
        Arrays of the wrong shape, non-finite coordinates or face indices out of range.
    """
    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.ascontiguousarray(faces, dtype=np.int64)
    UV = np.ascontiguousarray(uv, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or UV.shape != (len(V), 2):
        raise ValueError("surface_relief needs vertices (n, 3), faces (m, 3) and uv (n, 2)")
    if len(F) and (F.min() < 0 or F.max() >= len(V)):
        raise ValueError("face indices out of range")
    if not (math.isfinite(smoothing_mm) and smoothing_mm > 0):
        raise InvalidOptionError(f"relief smoothing must be a positive number of mm, got {smoothing_mm!r}")
    if not (math.isfinite(mm_per_unit) and mm_per_unit > 0):
        raise ValueError(f"mm_per_unit must be positive, got {mm_per_unit!r}")
    used = np.zeros(len(V), bool)
    used[F.ravel()] = True
    if not used.any():
        raise ValueError("the mesh has no faces")
    if not (np.isfinite(V[used]).all() and np.isfinite(UV[used]).all()):
        raise ValueError("vertices or uv are not finite")
    P = V * mm_per_unit
    xy = UV * mm_per_unit
    sums, area = vertex_normal_sums(P, F)
    spacing = float(math.sqrt(4.0 * np.median(triangle_areas(P, F)) / math.sqrt(3.0))) if len(F) else 0.0

    extent = np.ptp(xy[used], axis=0) + spacing
    least = math.sqrt(float(extent[0] * extent[1]) / MAX_CELLS) * FIT_CELLS_PER_SIGMA * 1.01
    sigma = max(float(smoothing_mm), SMOOTHING_MIN_EDGES * spacing, least)
    cell = sigma / FIT_CELLS_PER_SIGMA
    origin, nx, ny = _grid(xy, used, cell)
    mx, my = -(-nx // FIT_CELLS_PER_SIGMA), -(-ny // FIT_CELLS_PER_SIGMA)
    order, ptr = _sorted_by_cell(xy, used, origin, cell, nx, ny)
    # the nodes: at the centres of every FIT_CELLS_PER_SIGMA-th cell, sigma apart; a vertex
    # blends the four around it, so those of every node square holding a vertex are needed
    node_origin = origin + 0.5 * cell
    node_step = FIT_CELLS_PER_SIGMA * cell
    at = np.clip(np.floor((xy[used] - node_origin) / node_step).astype(np.int64), 0, [mx - 1, my - 1])
    held = np.zeros((my, mx), np.uint8)
    held[at[:, 1], at[:, 0]] = 1
    need = np.zeros((my + 1, mx + 1), np.uint8)
    need[:my, :mx] |= held
    need[1:, :mx] |= held
    need[:my, 1:] |= held
    need[1:, 1:] |= held
    need = np.ascontiguousarray(need[:my, :mx]).astype(bool).ravel()
    M = np.empty((nx * ny, MOMENTS))
    N = np.empty((nx * ny, TERMS, 3))
    coef = np.zeros((mx * my, TERMS, 3))
    ok = np.zeros(mx * my, bool)
    reach = math.ceil(FIT_REACH_SIGMA * FIT_CELLS_PER_SIGMA)
    height = np.empty(len(V))
    frame = np.empty((len(V), 3))
    grid = (float(origin[0]), float(origin[1]), cell, nx)
    nodes = (float(node_origin[0]), float(node_origin[1]), node_step, mx, my, sigma)
    weight = area
    for refit in range(ROBUST_REFITS + 1):
        if refit:
            weight = _robust_weights(height, area, used)
        cell_moments(xy, P, weight, order, ptr, *grid, sigma, M, N)
        fit_quadrics(M, N, nx, ny, cell, sigma, FIT_CELLS_PER_SIGMA, reach, need, QUADRIC_RIDGE, coef, ok)
        blend_quadrics(xy, P, sums, *nodes, coef, ok, height, frame)
        height[~used | ~np.isfinite(height)] = 0.0
    # the fit's own bias (the form's terms beyond a quadric) taken out: the heights less their
    # smoothed selves, fitted alike (twicing)
    weight = _robust_weights(height, area, used)
    N, coef = np.empty((nx * ny, TERMS, 1)), np.zeros((mx * my, TERMS, 1))
    cell_moments(xy, np.ascontiguousarray(height[:, None]), weight, order, ptr, *grid, sigma, M, N)
    fit_quadrics(M, N, nx, ny, cell, sigma, FIT_CELLS_PER_SIGMA, reach, need, QUADRIC_RIDGE, coef, ok)
    bias = np.empty(len(V))
    blend_scalar(xy, *nodes, coef, ok, bias)
    height -= np.nan_to_num(bias, nan=0.0)
    height[~used] = 0.0
    del M, N, coef, ok, weight, bias
    if np.dot(frame[used, 2], area[used]) < 0:  # faces wound against the layout: the normals point in
        frame = -frame

    radii = invariant_radii(sigma, spacing, used.sum() / max(float(area.sum()), 1e-300))
    cell = max(radii[-1], math.sqrt(float(np.prod(np.ptp(xy[used], axis=0))) / (4.0 * used.sum())))
    origin, nx, ny = _grid(xy, used, cell)
    order, ptr = _sorted_by_cell(xy, used, origin, cell, nx, ny)
    concavity = np.empty(len(V))
    volume_invariants(xy, height, area, order, ptr, float(origin[0]), float(origin[1]), cell, nx, ny,
                      np.asarray(radii, np.float64), concavity)
    concavity[~used] = 0.0
    return SurfaceRelief(height_mm=height, frame_normal=frame, concavity=concavity, vertex_area_mm2=area,
                         smoothing_mm=sigma, requested_mm=float(smoothing_mm), radii_mm=radii, spacing_mm=spacing)
