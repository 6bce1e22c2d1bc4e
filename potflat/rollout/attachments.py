"""Find the parts of a vessel scan that are not on its surface of revolution.

Handles, spouts, lugs and knobs off the axis break the rotational symmetry that a rollout
relies on. :func:`detect_attachments` finds them with two measures taken in the meridian
half-plane (``r`` = distance from the axis, ``h`` = height along it):

* **angular coverage**: the ``(r, h)`` plane is cut into square cells of side
  ``tolerance``. A surface of revolution passes through its cells at every angle around the
  axis (or over the whole angle range of a sherd), an attachment only over the few degrees
  it spans. Each cell counts the angle bins (about ``tolerance`` of arc each) in which the
  scan has vertices within one cell; a vertex is an attachment *core* when its cell's
  coverage is below ``coverage_ratio`` times the best coverage at that height. Measured
  this way, a foot ring, a flat base, a rim, both walls of a cup and every profile shape
  count as revolution surface, and holes or a sherd's limited angle do not matter.
* **offset**: each vertex's distance, in the meridian plane, from the revolution surface
  (the median ``(r, h)`` point of every well-covered cell, joined to its neighbour). Noise
  ``sigma`` is estimated from the offsets of the non-core vertices.

The attachment is every face with all three vertices clearly off the surface
(offset > ``max(3 sigma, 0.25 median edge)``) that is connected to a core face: it grows
from the handle's body to where it meets the wall, and the faces touching the wall stay, so
the painting around a handle root is kept.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from potflat._jit import worker_threads
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.mesh._kernels.grids import angle_coverage, segment_distances
from potflat.mesh._kernels.quantiles import lower_medians
from potflat.mesh.distortion import face_areas, median_edge_length
from potflat.rollout.walls import (
    FaceGraph,
    check_axis,
    check_graph,
    check_mesh,
    cylindrical,
    unique_ints,
)
from potflat.types import Mesh

#: Automatic cell size: at least this many median edge lengths ...
_CELL_EDGES = 2.0
#: ... and at least this many times the noise measured around the revolution surface ...
_CELL_NOISE = 4.0
#: ... and at least this fraction of the scan's size (the square root of its surface area), so
#: that a finer triangulation of the same vessel finds the same attachments: the noise
#: measured in cells of a few edge lengths shrinks with them, and cells narrower than a
#: hand-made vessel's departure from round leave parts of its body uncovered at some angles,
#: taken for attachments (the shared real scans subdivided to 1M vertices: cells of 0.2-0.6%
#: of their size left out up to 16% of a wall; the goblet subdivided needs cells of 1.5% to
#: find what its native size finds, the other scans 1%).
_CELL_SIZE_FRACTION = 0.02
#: An offset above this many noise sigmas is "clearly off" the surface of revolution.
_OFF_SIGMAS = 3.0
#: ... and above this fraction of the median edge length (noise-free scans).
_OFF_EDGE_FRACTION = 0.25
#: Largest number of angle bins per cell ring.
_MAX_ANGLE_BINS = 1 << 16


@dataclass(frozen=True)
class Attachment:
    """One connected attachment (a handle, a spout, a knob...).

    Attributes
    ----------
    n_faces : int
    area : float
        Scan units squared.
    area_mm2 : float
    height_min, height_max : float
        Height range along the axis, scan units, measured from the scan's lowest point (the
        frame of :class:`potflat.rollout.profile.Profile`).
    centroid : (3,) float64
        Area-weighted centre, scan coordinates.
    max_offset : float
        Largest distance of its vertices from the surface of revolution, scan units.
    """

    n_faces: int
    area: float
    area_mm2: float
    height_min: float
    height_max: float
    centroid: np.ndarray
    max_offset: float

    def summary(self, mm_per_unit: float) -> dict:
        """JSON-ready description, lengths in millimetres."""
        return {
            "faces": self.n_faces,
            "area_mm2": self.area_mm2,
            "height_mm": [self.height_min * mm_per_unit, self.height_max * mm_per_unit],
            "centroid": self.centroid.tolist(),
            "max_offset_mm": self.max_offset * mm_per_unit,
        }


@dataclass(frozen=True)
class AttachmentSelection:
    """Faces of a scan that are not on its surface of revolution.

    Attributes
    ----------
    face_mask : (m,) bool
        True for faces of attachments.
    components : tuple of Attachment
        Connected attachments, largest first.
    vertex_offset : (n,) float64
        Distance of each vertex from the surface of revolution in the meridian plane, scan
        units (NaN for vertices used by no face).
    tolerance : float
        Cell size used (scan units).
    coverage_ratio : float
        Core threshold: fraction of the best angular coverage at the same height.
    offset_threshold : float
        Offset above which a vertex is clearly off the surface, scan units.
    noise : float
        Estimated noise (sigma) of the surface around its profile, scan units.
    mm_per_unit : float
    method : str
    """

    face_mask: np.ndarray
    components: tuple
    vertex_offset: np.ndarray
    tolerance: float
    coverage_ratio: float
    offset_threshold: float
    noise: float
    mm_per_unit: float
    method: str

    @property
    def n_faces(self) -> int:
        """Number of attachment faces."""
        return int(self.face_mask.sum())

    def root_faces(self, faces: np.ndarray) -> np.ndarray:
        """Faces not flagged that share a vertex with an attachment: where each one meets the
        wall (its footprint on the rollout, to show as a mask in the bake).

        Parameters
        ----------
        faces : (m, 3) int64
            The faces of the mesh the selection was made on.

        Returns
        -------
        (m,) bool
        """
        faces = np.asarray(faces)
        if faces.shape != (len(self.face_mask), 3):
            raise InvalidInputError("faces must be the (m, 3) faces of the mesh the attachments were detected on")
        on = np.zeros(len(self.vertex_offset), dtype=bool)
        on[faces[self.face_mask].ravel()] = True
        return on[faces].any(axis=1) & ~self.face_mask

    def summary(self) -> dict:
        """JSON-ready figures for a stage sidecar (lengths in millimetres)."""
        s = self.mm_per_unit
        return {
            "faces": self.n_faces,
            "area_mm2": float(sum(c.area_mm2 for c in self.components)),
            "components": [c.summary(s) for c in self.components],
            "tolerance_mm": self.tolerance * s,
            "coverage_ratio": self.coverage_ratio,
            "offset_threshold_mm": self.offset_threshold * s,
            "noise_mm": self.noise * s,
            "method": self.method,
        }


def _check_positive(name: str, value, *, upper: float | None = None) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise InvalidOptionError(f"{name} must be a number, got {value!r}")
    v = float(value)
    if not (math.isfinite(v) and v > 0 and (upper is None or v < upper)):
        rng = f"between 0 and {upper}" if upper is not None else "positive"
        raise InvalidOptionError(f"{name} must be {rng}, got {value!r}")
    return v


def detect_attachments(mesh: Mesh, axis_point, axis_direction, *, tolerance: float | None = None,
                       coverage_ratio: float = 0.3, graph: FaceGraph | None = None,
                       others: np.ndarray | None = None) -> AttachmentSelection:
    """Detect handles, spouts, knobs and other parts off the surface of revolution.

    Parameters
    ----------
    mesh : Mesh
        The scan (open, holed, two-walled and partial meshes are fine).
    axis_point : (3,) array_like
        A point on the axis, scan units.
    axis_direction : (3,) array_like
        Axis direction, foot to mouth.
    tolerance : float, optional
        Cell size in scan units: how far from the surface of revolution a point still counts
        as on it for the coverage measure. Default: the largest of two median edge lengths,
        2% of the square root of the scan's surface area, and four times the measured
        noise of the surface around its profile.
    coverage_ratio : float
        A vertex is an attachment core when its cell is covered over less than this
        fraction (0-1) of the angles covered at the best-covered cell of its height.
    graph : FaceGraph, optional
        ``FaceGraph(mesh.faces)`` when the caller has it (built here when needed).
    others : (m,) bool, optional
        Faces of other objects in the scan (whole connected pieces: a second vessel beside
        this one): neither attachments nor part of the surface's measures (edge length,
        area, noise).

    Returns
    -------
    AttachmentSelection

    Raises
    ------
    InvalidOptionError
        ``tolerance`` not positive or ``coverage_ratio`` outside (0, 1).
    InvalidInputError
        Bad mesh or axis.
    """
    if tolerance is not None:
        tolerance = _check_positive("tolerance", tolerance)
    coverage_ratio = _check_positive("coverage_ratio", coverage_ratio, upper=1.0)
    check_mesh(mesh)
    check_graph(graph, mesh)
    p, a = check_axis(axis_point, axis_direction)
    V, F = mesh.vertices, mesh.faces
    others = None if others is None else np.asarray(others)
    if others is not None and (others.shape != (len(F),) or others.dtype != bool):
        raise InvalidInputError(f"others must be a boolean mask with one entry per face ({len(F)}), got "
                                f"{others.shape}")
    # (the other objects' vertices are in no face of the vessel: no offset, no attachment)
    vessel = F if others is None else F[~others]
    h_all, r_all, _ = cylindrical(V, p, a)
    used = np.flatnonzero(np.bincount(vessel.ravel(), minlength=len(V)))
    h0 = float(h_all[used].min())
    med_edge = median_edge_length(V, vessel)
    area = face_areas(V, F)
    vessel_area = float(area.sum() if others is None else area[~others].sum())

    hv = h_all[used] - h0
    rv = r_all[used]
    tv = _angles(V[used] - p, a)
    if tolerance is None:
        # a first pass at two edge lengths (at least the size fraction) measures the noise
        # around the revolution surface; a noisy scan needs cells of about four sigma so that
        # its surface covers them
        cell = max(_CELL_EDGES * med_edge, _CELL_SIZE_FRACTION * math.sqrt(vessel_area))
        if not cell > 0:
            raise InvalidInputError("the mesh has no extent (all edges of zero length); check the scan")
        _, off1 = _coverage_pass(hv, rv, tv, cell, coverage_ratio)
        fin = np.isfinite(off1)
        noise1 = float(np.median(off1[fin]) / 0.6745) if fin.any() else 0.0
        cell = max(cell, _CELL_NOISE * noise1)
    else:
        cell = float(tolerance)
    core_v, offset_u = _coverage_pass(hv, rv, tv, cell, coverage_ratio)
    body = ~core_v & np.isfinite(offset_u)
    noise = float(np.median(offset_u[body]) / 0.6745) if body.any() else 0.0
    threshold = max(_OFF_SIGMAS * noise, _OFF_EDGE_FRACTION * med_edge)
    offset = np.full(len(V), np.nan)
    offset[used] = np.nan_to_num(offset_u, nan=np.inf)
    core = np.zeros(len(V), dtype=bool)
    core[used] = core_v

    off_f = (offset[F] > threshold).all(axis=1)
    core_f = off_f & core[F].all(axis=1)
    mask = np.zeros(len(F), dtype=bool)
    components: list[Attachment] = []
    if core_f.any():
        graph = FaceGraph(F) if graph is None else graph
        adj = graph.pairs
        comp = graph.components(off_f[adj[:, 0]] & off_f[adj[:, 1]])
        seeded = np.zeros(int(comp.max()) + 1, dtype=bool)
        seeded[comp[core_f]] = True
        cand = off_f & seeded[comp]
        comp_area = np.bincount(comp[cand], weights=area[cand], minlength=len(seeded))
        big = seeded & (comp_area >= cell * cell)  # smaller flagged specks are noise
        mask = off_f & big[comp]
        idx = np.flatnonzero(mask)
        idx = idx[np.argsort(comp[idx], kind="stable")]
        groups = np.split(idx, np.flatnonzero(np.diff(comp[idx])) + 1) if len(idx) else []
        for fm in groups:
            ar = float(area[fm].sum())
            vi = unique_ints(F[fm])
            hc = h_all[vi] - h0
            components.append(Attachment(
                n_faces=len(fm),
                area=ar,
                area_mm2=ar * mesh.mm_per_unit ** 2,
                height_min=float(hc.min()),
                height_max=float(hc.max()),
                centroid=(area[fm] @ V[F[fm]].mean(axis=1)) / ar,
                max_offset=float(np.max(offset[vi])),
            ))
        components.sort(key=lambda c: -c.area)
    offset[used] = offset_u
    return AttachmentSelection(
        face_mask=mask,
        components=tuple(components),
        vertex_offset=offset,
        tolerance=cell,
        coverage_ratio=coverage_ratio,
        offset_threshold=float(threshold),
        noise=noise,
        mm_per_unit=mesh.mm_per_unit,
        method="angular coverage of the meridian plane + offset from the revolution surface",
    )


def _coverage_pass(hv: np.ndarray, rv: np.ndarray, tv: np.ndarray, cell: float,
                   coverage_ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """Attachment cores and offsets from the revolution surface at one cell size.

    Parameters
    ----------
    hv, rv, tv : (s,) float64
        Height (>= 0), radius and angle of the vertices.
    cell : float
        Cell side in the meridian plane (and arc width of an angle bin).
    coverage_ratio : float

    Returns
    -------
    core : (s,) bool
        Vertices whose cell is covered over few angles compared with the best cell of its row.
    offset : (s,) float64
        Distance from the revolution surface in the meridian plane (NaN when none found).
    """

    ih = np.floor(hv / cell).astype(np.int64)
    ir = np.floor(rv / cell).astype(np.int64)
    nh = int(ih.max()) + 1
    nr = int(ir.max()) + 2

    # angle bins of each ring, about one cell of arc wide at the ring's mid radius
    ring_bins = np.clip(np.floor(2 * np.pi * (np.arange(nr) + 0.5)), 6, _MAX_ANGLE_BINS).astype(np.int64)

    # the vertices grouped by cell; the cells within one row and ring of them
    own_cell = ih * nr + ir
    order = np.argsort(own_cell)
    grouped = own_cell[order]
    first = np.empty(len(grouped), dtype=bool)
    first[:1] = True
    np.not_equal(grouped[1:], grouped[:-1], out=first[1:])
    ocells = grouped[first]
    ptr = np.append(np.flatnonzero(first), len(grouped))
    cell_of = np.empty(len(own_cell), dtype=np.int64)  # index in ocells of each vertex's cell
    cell_of[order] = np.repeat(np.arange(len(ocells)), np.diff(ptr))
    th = (ocells // nr)[:, None] + np.repeat([-1, 0, 1], 3)
    tr = (ocells % nr)[:, None] + np.tile([-1, 0, 1], 3)
    ok = (th >= 0) & (th < nh) & (tr >= 0)
    cells = unique_ints(th[ok] * nr + tr[ok])
    counts = np.empty(len(cells), dtype=np.int64)
    ocounts = np.empty(len(ocells), dtype=np.int64)
    angle_coverage(ocells, ptr, np.ascontiguousarray(tv[order], dtype=np.float64), cells, nh, ring_bins,
                   counts, ocounts)
    frac = counts / ring_bins[cells % nr]
    row_ref = np.zeros(nh)
    np.maximum.at(row_ref, cells // nr, frac)
    frac_v = frac[np.searchsorted(cells, ocells)][cell_of]
    core = frac_v < coverage_ratio * row_ref[ih]

    # revolution surface: median (r, h) of the vertices of each cell that the scan itself
    # covers over many angles (a handle's few vertices in a wall cell do not move the median)
    good = ocounts / ring_bins[ocells % nr] >= coverage_ratio * row_ref[ocells // nr]
    offset = np.full(len(hv), np.nan)
    if not good.any():
        return core, offset
    # (the lower median of each cell's vertices, grouped by cell in `order`)
    cells_good = np.flatnonzero(good)
    reps = []
    for values in (rv, hv):
        reps.append(np.empty(len(cells_good)))
        lower_medians(np.ascontiguousarray(values[order], dtype=np.float64), ptr[cells_good], ptr[cells_good + 1],
                      reps[-1])
    reps = np.column_stack(reps)
    offset = _distance_to_curve(reps, np.column_stack([rv, hv]), 2.5 * cell)
    return core, offset


def _angles(d: np.ndarray, a: np.ndarray) -> np.ndarray:
    """Angle in [0, 2 pi) of each offset ``d`` ((n, 3)) about the unit axis ``a``."""
    ref = np.eye(3)[int(np.argmin(np.abs(a)))]
    e1 = np.cross(a, ref)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    t = np.arctan2(d @ e2, d @ e1)
    return np.mod(t, 2 * np.pi)


def _distance_to_curve(reps: np.ndarray, pts: np.ndarray, join: float) -> np.ndarray:
    """Distance of each point to the curve through ``reps`` ((q, 2)), approximated by the
    segment to its two nearest representatives when they are closer than ``join``."""
    if len(reps) == 0:
        return np.full(len(pts), np.nan)

    tree = cKDTree(reps)
    if len(reps) == 1:
        d, _ = tree.query(pts, k=1, workers=worker_threads())
        return d
    d, idx = tree.query(pts, k=2, workers=worker_threads())  # the same answer from any number of threads
    out = np.empty(len(pts))
    segment_distances(np.ascontiguousarray(reps, dtype=np.float64), np.ascontiguousarray(pts, dtype=np.float64),
                      np.ascontiguousarray(idx, dtype=np.int64), np.ascontiguousarray(d[:, 0]), float(join), out)
    return out
