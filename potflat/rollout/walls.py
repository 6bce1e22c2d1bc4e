"""Separate the outer and the inner wall of a vessel scan.

A scanned cup or goblet is often a closed (or two-sided) shell: the outer wall, the rim and
the inner wall (down to the bowl's floor, a kylix's tondo) are one connected surface. A
rollout must take one painted side only. With outward-oriented faces the two sides differ
by the sign of the normal's radial component ``n_r`` (the component along the direction
pointing away from the axis): the outer wall faces away from the axis, the inner wall
towards it, and the rim crest is the fold where ``n_r`` changes sign.

:func:`select_wall` turns that into a clean, spatially coherent split:

1. ``n_r`` per face, smoothed over a few rings of neighbours (noise);
2. faces with a clear sign (``|n_r| >= flat_tolerance``) are seeds; nearly horizontal faces
   (flat base, bowl floor, rim top, ``n_r`` ~ 0) take the side of the nearest seed along the
   surface (multi-source Dijkstra over face adjacency), where a climb over the flat face's
   crest (up for a face facing the mouth, down for one facing the foot) counts
   :data:`_CLIMB_WEIGHT` times its height: a flat part takes the side it reaches without
   crossing its crest, so a level rim top splits midway and a plate's broad rim, sloping
   gently down to the well, goes with the inside;
3. same-side regions are cleaned up: small islands (noise) join the side around them; a
   region facing the axis counts as inner wall only when it meets the outer wall across an
   upward fold (a rim) or lies inside the outer wall's profile (a sherd's inner face); one
   meeting it across a downward fold (the inside of a foot ring, an overhanging lip) or
   lying outside the body (the inner side of a handle) belongs to the outer wall;
4. outer faces facing the mouth at the vessel's lowest heights, in pieces reaching out
   beyond the foot's wall, with what joins them facing up outside the body, are a table or
   the ground the vessel stood on, scanned with it and joined to the foot: no outer
   surface of a vessel faces up there. They are left out;
5. the selection is the connected region of the side asked for with the most wall (area
   times ``|n_r|``), so a flat piece scanned with the vessel (a turntable or ground plane,
   larger than the vessel) is left apart.

:func:`cut_between_walls` then smooths the split into a line through its middle, along
which the rollout cuts the faces across it (a split along whole faces is a staircase a face
deep where the rim is noisy).

Scans whose faces all point inwards (an open surface the loader could not orient) are
detected by the inner side being more than twice as large as the outer one, and read with
flipped normals.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.mesh._kernels.geometry import edge_lengths, face_geometry, radial_parts
from potflat.mesh._kernels.quantiles import grouped_weighted_quantiles
from potflat.mesh.distortion import weighted_percentile
from potflat.mesh.embedding import fan_edges, neighbour_rows
from potflat.mesh.split import snap_to_cut
from potflat.mesh._kernels.topology import edge_table, face_pairs, pair_csr, pair_sums, union_find
from potflat.mesh.tolerances import DEGENERATE, ROUNDING
from potflat.rollout.options import SIDES  # the sides select_wall accepts
from potflat.types import Mesh

#: Label values in :attr:`WallSelection.labels`.
OUTER, INNER = 1, -1

# Cleanup parameters (fractions/cosines, independent of the scan's scale).
_SMOOTH_ITERATIONS = 2
_ISLAND_AREA_FRACTION = 0.002  # same-side regions below this share of the area are noise
_FOLD_COSINE = 0.5  # |mean axial normal| at a region border above this = a rim/foot fold
_CLEANUP_PASSES = 5
_INSIDE_OUT_RATIO = 2.0  # inner/outer area above which a scan is tried with flipped normals
#: A flat face's way to a seed (step 2 above): each unit climbed over its crest costs this many units
#: walked. At 1000 the test plate's broad rim (sloping 2.5 over 25 mm) goes with the inside but for the
#: ring of faces on its crest; at 100 the two rings nearest the crest went with the outer wall.
_CLIMB_WEIGHT = 1000.0
_GROUND_COSINE = 0.9  # axial normal towards the mouth above this: a surface the vessel stands on
_GROUND_HEIGHT = 0.03  # ... within this share of the vessel's height above its lowest face
_FOOT_QUANTILE = 0.95  # the foot's radius: this quantile of the wall's radii at those heights
_GROUND_OUTSIDE = 0.1  # a ground grows above those heights this share of the body's radius outside its profile
#: Rings of vertex neighbours over which the line between the two walls is smoothed before
#: the faces across it are cut along it (:func:`cut_between_walls`): the teeth of a split
#: along whole faces (a noisy rim top, a photogrammetry lip) are about one face deep.
SPLIT_SMOOTH_RINGS = 3


def check_axis(axis_point, axis_direction) -> tuple[np.ndarray, np.ndarray]:
    """Validate an axis and return it as ``(point, unit direction)``.

    Parameters
    ----------
    axis_point : (3,) array_like
        A point on the axis, scan units.
    axis_direction : (3,) array_like
        Direction from the foot to the mouth (normalised here).

    Returns
    -------
    point : (3,) float64
    direction : (3,) float64
        Unit length.
    """
    p = np.asarray(axis_point, dtype=np.float64)
    a = np.asarray(axis_direction, dtype=np.float64)
    if p.shape != (3,) or a.shape != (3,):
        raise InvalidInputError(
            f"axis point and direction must each have 3 coordinates, got shapes {p.shape} and {a.shape}"
        )
    if not (np.isfinite(p).all() and np.isfinite(a).all()):
        raise InvalidInputError("axis point and direction must be finite numbers; give a valid axis")
    norm = float(np.linalg.norm(a))
    if norm <= DEGENERATE:
        raise InvalidInputError("axis direction has zero length; give a non-zero direction (foot to mouth)")
    return p.copy(), a / norm


def check_mesh(mesh: Mesh) -> None:
    """Raise :class:`InvalidInputError` when ``mesh`` cannot be analysed (no faces, NaN)."""
    if not isinstance(mesh, Mesh):
        raise InvalidInputError(f"expected a potflat Mesh, got {type(mesh).__name__}")
    where = f" in {mesh.source}" if mesh.source else ""
    if len(mesh.faces) == 0:
        raise InvalidInputError(f"the mesh{where} has no faces; load a triangle mesh")
    if not np.isfinite(mesh.vertices).all():
        raise InvalidInputError(f"the mesh{where} has non-finite vertex coordinates; clean the scan")
    if mesh.faces.min() < 0 or mesh.faces.max() >= len(mesh.vertices):
        raise InvalidInputError(f"the mesh{where} has face indices outside its vertex list")


def check_graph(graph, mesh: Mesh, shared: bool = False) -> None:
    """Raise :class:`InvalidInputError` unless ``graph`` is None or a :class:`FaceGraph` of
    ``mesh``'s faces (one node per face), keeping its shared edges if ``shared``."""
    if graph is not None and (not isinstance(graph, FaceGraph) or graph.m != len(mesh.faces)
                              or (shared and not graph.keeps_shared)):
        want = "FaceGraph(mesh.faces, shared=True)" if shared else "FaceGraph(mesh.faces)"
        raise InvalidInputError(f"graph must be {want} ({len(mesh.faces)} faces), got {graph!r}")


@dataclass(frozen=True)
class FaceFrame:
    """Per-face geometry relative to the axis (shared by the analysis modules).

    Attributes
    ----------
    area : (m,) float64
        Face areas, scan units squared.
    normal : (m, 3) float64
        Unit face normals (zero for degenerate faces).
    centroid : (m, 3) float64
        Face centroids, scan coordinates.
    height : (m,) float64
        Centroid height along the axis, measured from the axis point.
    radius : (m,) float64
        Centroid distance from the axis.
    n_radial : (m,) float64
        Normal component along the direction pointing away from the axis.
    n_axial : (m,) float64
        Normal component along the axis direction (towards the mouth).
    adjacency : (p, 2) int64
        Pairs of faces sharing a manifold edge (empty when not computed).
    edge_length : (p,) float64
        Length of each shared edge.
    graph : FaceGraph or None
        The same adjacency as a sparse graph.
    wall_area : (m,) float64
        Each face's area times ``|n_radial|``: its share of a wall around the axis (0 for a
        face along the axis: a flat base, a lid's top, a turntable); computed when first read.
    """

    area: np.ndarray
    normal: np.ndarray
    centroid: np.ndarray
    height: np.ndarray
    radius: np.ndarray
    n_radial: np.ndarray
    n_axial: np.ndarray
    adjacency: np.ndarray
    edge_length: np.ndarray
    graph: FaceGraph | None = None

    @cached_property
    def wall_area(self) -> np.ndarray:
        return self.area * np.abs(self.n_radial)


class FaceGraph:
    """Face adjacency (faces sharing an edge used by exactly two faces) of ``faces`` ((m, 3)
    int), as a symmetric sparse graph: :func:`face_adjacency` runs when :attr:`pairs` or
    :attr:`shared` is first read, so a caller may build it once and hand it on to steps that
    need it or not.

    Parameters
    ----------
    faces : (m, 3) int
    table : tuple, optional
        The faces' :attr:`edge_table` when the caller has it (not built a second time).
    shared : bool
        Keep each pair's shared edge (:attr:`shared`; 0.14 GB at 6M faces, so only for a
        caller that reads it).
    """

    def __init__(self, faces: np.ndarray, table: tuple | None = None, *, shared: bool = False) -> None:
        self.m = len(faces)
        self._faces = faces
        self.keeps_shared = shared
        if table is not None:
            self.__dict__["edge_table"] = table

    @cached_property
    def edge_table(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The faces' :func:`potflat.mesh._kernels.topology.edge_table` (``edge_of, edges, count,
        halves``), built on first use and kept: the adjacency reuses it when it is asked for
        first (a graph whose caller never asks keeps no table, half a gigabyte at 6M faces)."""
        F = np.ascontiguousarray(self._faces, dtype=np.int64).reshape(-1, 3)
        return edge_table(F, int(F.max()) + 1 if len(F) else 0)

    @cached_property
    def _adjacency(self) -> tuple[np.ndarray, np.ndarray | None]:
        pairs, shared = face_adjacency(self._faces, return_edges=True, table=self.__dict__.get("edge_table"))
        return pairs, shared if self.keeps_shared else None

    @property
    def pairs(self) -> np.ndarray:
        """Adjacent face pairs (p, 2) int64."""
        return self._adjacency[0]

    @property
    def shared(self) -> np.ndarray:
        """The edge each pair shares (p, 2) int64 (a graph built with ``shared=True``)."""
        if not self.keeps_shared:
            raise ValueError("this FaceGraph was built without its shared edges: build it with shared=True")
        return self._adjacency[1]

    @cached_property
    def _csr(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(indptr, indices, pair of each entry)``, rows sorted (:func:`potflat.mesh._kernels.pair_csr`);
        built on first use (:meth:`matrix` and :attr:`neighbours` need it)."""

        indptr, indices, pair_of = pair_csr(np.ascontiguousarray(self.pairs, dtype=np.int64).reshape(-1, 2), self.m)
        dtype = np.int32 if self.m < 2**31 else np.int64
        return indptr.astype(dtype), indices.astype(dtype), pair_of

    @cached_property
    def neighbours(self) -> tuple[np.ndarray, np.ndarray]:
        """``(indptr, indices)``: the adjacency as CSR (m + 1,) and (2 p,) int64, neighbours sorted."""
        indptr, indices, _ = self._csr
        return indptr.astype(np.int64, copy=False), indices.astype(np.int64, copy=False)

    def matrix(self, weights: np.ndarray) -> sp.csr_matrix:
        """(m, m) CSR matrix with ``weights[pair]`` on both entries of each pair (zeros left
        out): ``weights`` (p,) float64 the same both ways, or (p, 2) float64 the entry from the
        pair's first face to its second, then the one back."""
        indptr, indices, pair_of = self._csr
        weights = np.asarray(weights, np.float64)
        if weights.ndim == 1:
            data = weights[pair_of]
        else:  # an entry runs from the pair's second face back when its column is the first
            back = indices == np.asarray(self.pairs)[pair_of, 0]
            data = weights[pair_of, back.astype(np.int64)]
        A = sp.csr_matrix((data, indices.copy(), indptr.copy()), shape=(self.m, self.m))
        A.eliminate_zeros()  # works in place on the index arrays, hence the copies
        return A

    def neighbour_sum(self, x: np.ndarray) -> np.ndarray:
        """The sum of ``x`` ((m,) float64) over each face's edge neighbours (:meth:`matrix` times
        ``x``, without building the matrix: 0.4 GB at 6M faces)."""
        return pair_sums(np.ascontiguousarray(self.pairs, dtype=np.int64).reshape(-1, 2),
                         np.ascontiguousarray(x, dtype=np.float64))

    def components(self, pair_mask: np.ndarray | None = None) -> np.ndarray:
        """Connected-component label (m,) int64 of every face, over the pairs in ``pair_mask``
        (numbered in order of each component's lowest face, as scipy's connected_components)."""

        a, b = self.pairs[:, 0], self.pairs[:, 1]
        if pair_mask is not None:  # (each column gathered alone: a row gather of the (p, 2) pairs is 5x slower)
            keep = np.asarray(pair_mask, dtype=bool)
            a, b = a[keep], b[keep]
        comp, _ = union_find(self.m, np.ascontiguousarray(a, dtype=np.int64), np.ascontiguousarray(b, dtype=np.int64))
        return comp


def unique_ints(x: np.ndarray, return_counts: bool = False):
    """Sorted unique values of an integer array (and their counts), by sorting.

    ``np.unique`` on large int64 arrays is very slow in the NumPy of this project
    (a hash path: 15 s against 0.1 s for 3M values), so the analysis modules use this.
    """
    srt = np.sort(np.asarray(x).ravel())
    first = np.empty(len(srt), dtype=bool)
    first[:1] = True
    np.not_equal(srt[1:], srt[:-1], out=first[1:])
    u = srt[first]
    if not return_counts:
        return u
    start = np.flatnonzero(first)
    return u, np.diff(np.append(start, len(srt)))


def face_adjacency(faces: np.ndarray, return_edges: bool = False, table: tuple | None = None):
    """Pairs of faces sharing an edge used by exactly two faces.

    From the linear edge table (:func:`potflat.mesh._kernels.edge_table`), in the order and
    form of ``trimesh.graph.face_adjacency`` (which this replaced: 0.3 s against 0.4-1.1 s at 2M faces):
    pairs ordered by their edge's (larger, smaller) endpoint, each pair's lower face first.

    Parameters
    ----------
    faces : (m, 3) int
    return_edges : bool
        Also return each pair's shared edge.
    table : tuple, optional
        The faces' ``edge_table(faces, faces.max() + 1)`` when the caller has it.

    Returns
    -------
    pairs : (p, 2) int64
    edges : (p, 2) int64
        Only with ``return_edges``: endpoints of the shared edge, smaller first.
    """

    F = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    n = int(F.max()) + 1 if len(F) else 0
    _, edges, count, halves = edge_table(F, n) if table is None else table
    pairs, shared = face_pairs(edges, count, halves, n)
    return (pairs, shared) if return_edges else pairs


def cylindrical(points: np.ndarray, axis_point: np.ndarray, axis_direction: np.ndarray):
    """Height along and distance from the axis, and the unit radial direction.

    Parameters
    ----------
    points : (n, 3) float64
    axis_point : (3,) float64
    axis_direction : (3,) float64
        Unit length.

    Returns
    -------
    height : (n,) float64
    radius : (n,) float64
    radial : (n, 3) float64
        Unit vectors pointing away from the axis (zero on the axis).
    """

    direction = np.ascontiguousarray(axis_direction, dtype=np.float64)
    d = np.ascontiguousarray(np.asarray(points, dtype=np.float64) - axis_point).reshape(-1, 3)
    height = d @ direction
    radius, radial = radial_parts(d, height, direction)
    return height, radius, radial


def face_frame(mesh: Mesh, axis_point: np.ndarray, axis_direction: np.ndarray, *,
               adjacency: bool = True, graph: FaceGraph | None = None) -> FaceFrame:
    """Compute :class:`FaceFrame` for a validated mesh and axis (``adjacency=False`` skips
    the face adjacency, which only the wall labelling needs; ``graph``: the mesh's
    :class:`FaceGraph` with its shared edges when the caller has it)."""
    V, F = mesh.vertices, mesh.faces
    # one parallel pass over the faces; the cross products become the unit normals in place
    normal, dbl, _, centroid = face_geometry(np.ascontiguousarray(V, dtype=np.float64),
                                             np.ascontiguousarray(F, dtype=np.int64).reshape(-1, 3))
    ok = dbl > 0
    np.divide(normal, dbl[:, None], out=normal, where=ok[:, None])  # (in place: no gathers of 3m values)
    normal[~ok] = 0.0
    height, radius, radial = cylindrical(centroid, axis_point, axis_direction)
    if adjacency:
        graph = FaceGraph(F, shared=True) if graph is None else graph
        pairs, edges = graph.pairs, graph.shared
        edge_length = edge_lengths(np.ascontiguousarray(V, dtype=np.float64),
                                   np.ascontiguousarray(edges, dtype=np.int64))
    else:
        pairs, edge_length, graph = np.zeros((0, 2), np.int64), np.zeros(0), None
    return FaceFrame(
        area=0.5 * dbl,
        normal=normal,
        centroid=centroid,
        height=height,
        radius=radius,
        n_radial=np.einsum("ij,ij->i", normal, radial),
        n_axial=normal @ axis_direction,
        adjacency=pairs,
        edge_length=edge_length,
        graph=graph,
    )


def largest_component(mesh: Mesh, face_mask: np.ndarray) -> np.ndarray:
    """Keep only the largest (by area) edge-connected region of the masked faces.

    Parameters
    ----------
    mesh : Mesh
    face_mask : (m,) bool

    Returns
    -------
    (m,) bool
        Subset of ``face_mask``.
    """
    mask = np.asarray(face_mask, dtype=bool)
    if mask.shape != (len(mesh.faces),):
        raise InvalidInputError(f"face mask must have one entry per face ({len(mesh.faces)}), got {mask.shape}")
    if not mask.any():
        return mask.copy()
    V, F = mesh.vertices, mesh.faces
    area = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    return _largest_region(mask, FaceGraph(F), area)


def _largest_region(mask: np.ndarray, graph: FaceGraph, area: np.ndarray) -> np.ndarray:
    """The edge-connected region of ``mask`` with the most ``area`` (any per-face weight)."""
    adj = graph.pairs
    comp = graph.components(mask[adj[:, 0]] & mask[adj[:, 1]])
    comp_area = np.bincount(comp[mask], weights=area[mask], minlength=comp.max() + 1)
    # ties broken by the lowest component id, which is deterministic
    return mask & (comp == int(np.argmax(comp_area)))


def _smooth(values: np.ndarray, area: np.ndarray, graph: FaceGraph, iterations: int) -> np.ndarray:
    """Area-weighted average over each face and its edge neighbours in ``graph``, ``iterations`` times."""
    denom = area + graph.neighbour_sum(area)
    denom[denom <= 0] = 1.0
    x = values
    for _ in range(iterations):
        wx = area * x
        x = (wx + graph.neighbour_sum(wx)) / denom
    return x


def binned_median(h: np.ndarray, values: np.ndarray, weights: np.ndarray, edges: np.ndarray,
                  quantiles=(0.5,), extra: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Weighted quantiles of ``values`` in each height bin.

    Parameters
    ----------
    h, values, weights : (s,) float64
        Sample heights, values and non-negative weights.
    edges : (k + 1,) float64
        Increasing bin edges; samples outside are ignored.
    quantiles : sequence of float
        Quantiles in [0, 1].
    extra : (s,) float64, optional
        A second variable whose weighted median per bin is appended as the last row.

    Returns
    -------
    q : (len(quantiles) [+ 1], k) float64
        NaN in bins without weight.
    total : (k,) float64
        Total weight per bin.
    """
    k = len(edges) - 1
    b = np.searchsorted(edges, h, side="right") - 1
    b[h == edges[-1]] = k - 1
    ok = (b >= 0) & (b < k) & (weights > 0)
    rows = [weighted_quantiles(b[ok], values[ok], weights[ok], k, quantiles)]
    if extra is not None:
        rows.append(weighted_quantiles(b[ok], extra[ok], weights[ok], k, (0.5,)))
    total = np.bincount(b[ok], weights=weights[ok], minlength=k)
    return np.vstack(rows), total


def weighted_quantiles(b: np.ndarray, v: np.ndarray, w: np.ndarray, k: int, quantiles) -> np.ndarray:
    """Weighted quantiles of ``v`` per group: in each, the smallest value whose cumulative
    weight reaches the quantile's share of the group's weight
    (:func:`potflat.mesh._kernels.quantiles.grouped_weighted_quantiles`, a selection per
    group, no sort).

    Parameters
    ----------
    b : (s,) int64
        Group of each sample, in ``[0, k)``.
    v, w : (s,) float64
        Values and positive weights.
    k : int
        Number of groups.
    quantiles : sequence of float

    Returns
    -------
    (len(quantiles), k) float64
        NaN for empty groups.
    """
    b = np.ascontiguousarray(b, dtype=np.int64)
    v, w = np.ascontiguousarray(v, dtype=np.float64), np.ascontiguousarray(w, dtype=np.float64)
    # (the kernel reads and writes by these unchecked)
    if v.shape != b.shape or w.shape != b.shape or (len(b) and not (b.min() >= 0 and b.max() < k)):
        raise ValueError(f"weighted_quantiles: one group, value and weight per sample, groups in [0, {k})")
    out = np.empty((len(quantiles), k))
    grouped_weighted_quantiles(b, v, w, np.asarray(quantiles, dtype=np.float64), out)
    return out


@dataclass(frozen=True)
class WallSelection:
    """The faces of one painted side of a vessel scan.

    Attributes
    ----------
    face_mask : (m,) bool
        Faces of the selected wall (its largest connected region, without ``exclude``).
    labels : (m,) int8
        Side of every face: ``1`` outer wall, ``-1`` inner wall.
    side : str
        ``"outer"`` or ``"inner"``.
    n_outer, n_inner : int
        Faces labelled outer / inner over the whole mesh.
    outer_area, inner_area : float
        Their areas, scan units squared.
    n_selected : int
        Faces in ``face_mask``.
    n_dropped : int
        Faces of the chosen side left out: excluded, or not connected to its largest region.
    apart_area : float
        Area of the chosen side's faces, not excluded, apart from its largest region (other
        pieces: a lid, a stand, a fragment scanned with the vessel), scan units squared.
    ground_mask : (m,) bool
        Faces of a table or ground joined to the foot (outer faces facing the mouth at the
        vessel's lowest heights, reaching out beyond the foot), left out of the selection.
    ground_area : float
        Their area, scan units squared.
    rim_faces : (k,) int64
        Selected faces that share an edge with the other wall (the split line).
    two_walled : bool
        True when the scan has an inner wall (at least 1 % of its area).
    normals_inverted : bool
        True when the scan's faces pointed inwards and were read flipped.
    method : str
        How the split was made.
    """

    face_mask: np.ndarray
    labels: np.ndarray
    side: str
    n_outer: int
    n_inner: int
    outer_area: float
    inner_area: float
    n_selected: int
    n_dropped: int
    apart_area: float
    ground_mask: np.ndarray
    ground_area: float
    rim_faces: np.ndarray
    two_walled: bool
    normals_inverted: bool
    method: str

    def summary(self) -> dict:
        """JSON-ready figures for a stage sidecar."""
        return {
            "side": self.side,
            "two_walled": self.two_walled,
            "faces_outer": self.n_outer,
            "faces_inner": self.n_inner,
            "faces_selected": self.n_selected,
            "faces_dropped_disconnected": self.n_dropped,
            "area_apart": self.apart_area,
            "area_ground": self.ground_area,
            "rim_faces": len(self.rim_faces),
            "normals_inverted": self.normals_inverted,
            "method": self.method,
        }


def select_wall(mesh: Mesh, axis_point, axis_direction, *, side: str = "outer",
                exclude=None, others=None, flat_tolerance: float = 0.25, graph: FaceGraph | None = None,
                frame: FaceFrame | None = None, inside_out: bool = True) -> WallSelection:
    """Select the outer or the inner wall of a (possibly two-walled) vessel scan.

    Parameters
    ----------
    mesh : Mesh
        The scan, faces counter-clockwise seen from outside (outward normals) as far as the
        loader could orient them. Open, holed and partial (sherd) meshes are fine.
    axis_point : (3,) array_like
        A point on the vessel's axis, scan units.
    axis_direction : (3,) array_like
        Axis direction from the foot to the mouth.
    side : {"outer", "inner"}
        Painted side to select.
    exclude : (m,) bool, optional
        Faces to leave out of the selection (e.g. ``detect_attachments(...).face_mask``);
        the largest connected region is taken after removing them.
    others : (m,) bool, optional
        Faces of other objects in the scan (whole connected pieces: a second vessel beside
        this one): left out of the selection, of the side counts and areas, and of what the
        labelling decides over the whole vessel (inside-out, the outer wall's profile, its
        largest region).
    flat_tolerance : float
        Faces whose smoothed radial normal component is below this (0-1) are treated as
        horizontal (base, floor, rim top) and take the side of the wall they connect to.
    graph : FaceGraph, optional
        ``FaceGraph(mesh.faces, shared=True)`` when the caller has it (built here otherwise).
    frame : FaceFrame, optional
        ``face_frame(mesh, axis_point, axis_direction)`` (with the adjacency) when the caller
        has it (computed here otherwise).
    inside_out : bool
        Read a scan whose inner side comes out more than twice its outer one with its normals
        flipped (:func:`wall_labels`); False: the faces face as the scanner saw them
        (``RolloutOptions.keep_orientation``).

    Returns
    -------
    WallSelection

    Raises
    ------
    InvalidOptionError
        ``side`` not "outer"/"inner" or ``flat_tolerance`` outside (0, 1).
    InvalidInputError
        Bad mesh or axis, or ``side="inner"`` on a scan without an inner wall.

    Notes
    -----
    The inner wall's faces are counter-clockwise seen from the cavity (their normals point
    towards the axis), so a development seen from outside (``u = R theta``) shows it
    mirrored, every face flipped: unroll the inner side with ``u`` reversed, which is the
    painting as seen from inside the vessel.
    """
    if side not in SIDES:
        raise InvalidOptionError(f"side must be 'outer' or 'inner', got {side!r}")
    if (isinstance(flat_tolerance, bool) or not isinstance(flat_tolerance, (int, float, np.floating))
            or not 0.0 < float(flat_tolerance) < 1.0):
        raise InvalidOptionError(f"flat_tolerance must lie between 0 and 1, got {flat_tolerance!r}")
    check_mesh(mesh)
    p, a = check_axis(axis_point, axis_direction)
    exclude, others = (None if mask is None else np.asarray(mask) for mask in (exclude, others))
    for name, mask in (("exclude", exclude), ("others", others)):
        if mask is not None and (mask.shape != (len(mesh.faces),) or mask.dtype != bool):
            raise InvalidInputError(
                f"{name} must be a boolean mask with one entry per face ({len(mesh.faces)}), got {mask.shape}")
    check_graph(graph, mesh, shared=True)
    fr = face_frame(mesh, p, a, graph=graph) if frame is None else frame
    labels, inverted = wall_labels(fr, flat_tolerance=float(flat_tolerance), others=others, inside_out=inside_out)
    want = OUTER if side == "outer" else INNER
    vessel = np.ones(len(labels), bool) if others is None else ~others
    outer_area = float(fr.area[vessel & (labels == OUTER)].sum())
    inner_area = float(fr.area[vessel & (labels == INNER)].sum())
    two_walled = inner_area >= 0.01 * (outer_area + inner_area)
    chosen = vessel & (labels == want)
    if not chosen.any():
        where = f" {mesh.source}" if mesh.source else ""
        other = "inner" if side == "outer" else "outer"
        facing = "face the axis" if side == "outer" else "face away from the axis"
        raise InvalidInputError(
            f"the scan{where} has no {side} wall (its faces all {facing}); unroll its {other} side "
            f"(--side {other}, side='{other}')")
    ground = _ground(fr, labels, vessel, -1.0 if inverted else 1.0, float(flat_tolerance))
    candidates = chosen & ~ground if exclude is None else chosen & ~ground & ~exclude
    # the region with the most wall (area facing away from or towards the axis), not a flat
    # piece scanned with the vessel (a turntable or ground plane larger than the vessel)
    mask = _largest_region(candidates, fr.graph, fr.wall_area) if candidates.any() else candidates
    adj = fr.adjacency
    cross = labels[adj[:, 0]] != labels[adj[:, 1]]
    touching = np.zeros(len(labels), dtype=bool)
    touching[adj[cross].ravel()] = True
    rim = np.flatnonzero(mask & touching)
    method = "radial normal sign + region growing" if two_walled else "single surface (no inner wall)"
    return WallSelection(
        face_mask=mask,
        labels=labels,
        side=side,
        n_outer=int((vessel & (labels == OUTER)).sum()),
        n_inner=int((vessel & (labels == INNER)).sum()),
        outer_area=outer_area,
        inner_area=inner_area,
        n_selected=int(mask.sum()),
        n_dropped=int(chosen.sum() - mask.sum()),
        apart_area=float(fr.area[candidates & ~mask].sum()),
        ground_mask=ground,
        ground_area=float(fr.area[ground].sum()),
        rim_faces=rim.astype(np.int64),
        two_walled=bool(two_walled),
        normals_inverted=bool(inverted),
        method=method,
    )


@dataclass(frozen=True, eq=False)
class WallCut:
    """The selected wall cut off from the other along a smooth line, the faces across it split.

    Attributes
    ----------
    face_mask : (m,) bool
        Faces with a part on the selected side of the line: the selection's faces less
        those wholly past it, and faces of the other wall reaching over it.
    faces : (k,) int64
        Faces across the line: cut along it (:func:`potflat.mesh.split.split_faces`), their
        parts on the selected side kept.
    level : (n,) float64
        Side of every scan vertex: positive on the selected side, negative on the other;
        the line is where it is 0 (linear along each edge).
    faces_added, faces_dropped : int
        Faces of the other wall with a part on the selected side, and faces of the
        selection wholly on the other.
    """

    face_mask: np.ndarray
    faces: np.ndarray
    level: np.ndarray
    faces_added: int
    faces_dropped: int

    def summary(self) -> dict:
        """JSON-ready figures for a stage sidecar (``walls.line``)."""
        return {"faces_split": int(len(self.faces)), "faces_added": self.faces_added,
                "faces_dropped": self.faces_dropped, "smoothed_rings": SPLIT_SMOOTH_RINGS}

    def levels(self, index: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """The level (k,) float64 of the scan vertices ``index`` ((k,) int64; ``points``, their
        positions, are not needed: the level is given at every scan vertex)."""
        return self.level[index]


def cut_between_walls(faces: np.ndarray, n_vertices: int, walls: WallSelection, *,
                      exclude: np.ndarray | None = None) -> WallCut | None:
    """The line where the selected wall meets the other, smoothed, and the faces across it.

    Each face of the selection counts 1, each face of the other wall -1 (``exclude``d faces
    and the rest nothing); every vertex takes the mean of its faces' counts, then, in the
    band of :data:`SPLIT_SMOOTH_RINGS` rings around the line, the mean over itself and its
    edge neighbours that many times. Its zero level is a curve through the middle of the
    split along whole faces, without its teeth: cut exactly along it, the rim of a
    two-walled scan is a clean edge at any resolution.

    Parameters
    ----------
    faces : (m, 3) int64
    n_vertices : int
    walls : WallSelection
        The selection (:func:`select_wall` of ``faces``).
    exclude : (m,) bool, optional
        Faces of the other wall that are not to be taken over the line (attachments, a
        ground, other objects).

    Returns
    -------
    WallCut or None
        None when the selection does not meet the other wall.

    Raises
    ------
    InvalidInputError
        ``faces`` are not those ``walls`` was selected on.
    """
    F = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(F) != len(walls.labels) or (len(F) and not 0 <= F.min() <= F.max() < n_vertices):
        raise InvalidInputError(f"cut_between_walls needs the faces the walls were selected on "
                                f"({len(walls.labels)}, naming vertices below {n_vertices}), got {len(F)}")
    want = OUTER if walls.side == "outer" else INNER
    count = np.where(walls.labels != want, -1.0, 0.0)
    if exclude is not None:
        count[np.asarray(exclude, dtype=bool)] = 0.0
    count[walls.face_mask] = 1.0
    counted = count != 0.0
    corners = F[counted].ravel()
    total = np.bincount(corners, np.repeat(count[counted], 3), minlength=n_vertices)
    number = np.bincount(corners, minlength=n_vertices)
    level = np.where(number > 0, total / np.maximum(number, 1), -1.0)
    near = np.abs(level) < 1.0
    if not near.any():
        return None
    for _ in range(SPLIT_SMOOTH_RINGS):
        near[F[counted & near[F].any(axis=1)].ravel()] = True
    around = np.flatnonzero(counted & near[F].any(axis=1))
    verts = np.flatnonzero(near)
    rows = neighbour_rows(verts, fan_edges(around, F)[0], n_vertices)
    degree = np.asarray(rows.sum(axis=1)).ravel()
    for _ in range(SPLIT_SMOOTH_RINGS):
        level[verts] = (level[verts] + rows @ level) / (1.0 + degree)
    # the vertices the cut will go through, on it already: the faces kept are those it leaves a part of
    level = snap_to_cut(F[around], level)[0]
    at = level[F[around]]
    face_mask = walls.face_mask.copy()
    face_mask[around] = at.max(axis=1) > 0.0
    across = around[(at.min(axis=1) < 0.0) & (at.max(axis=1) > 0.0)]
    return WallCut(face_mask=face_mask, faces=across.astype(np.int64), level=level,
                   faces_added=int((face_mask & ~walls.face_mask).sum()),
                   faces_dropped=int((walls.face_mask & ~face_mask).sum()))


def wall_labels(fr: FaceFrame, *, flat_tolerance: float = 0.25, others: np.ndarray | None = None,
                inside_out: bool = True) -> tuple[np.ndarray, bool]:
    """Side of every face: ``(labels (m,) int8 (+1 outer, -1 inner), normals_inverted)``.

    See the module docstring for the steps. If the inner side comes out more than twice as
    large as the outer one, the scan is taken to be inside-out and labelled again with
    flipped normals (not without ``inside_out``: the faces face as the scanner saw them).
    ``others`` (m,) bool: faces of other objects (whole connected pieces), labelled like the
    rest but left out of these decisions over the whole vessel.
    """
    area = fr.area if others is None else np.where(others, 0.0, fr.area)
    labels = _label_once(fr, flat_tolerance, sign=1.0, others=others)
    # inside-out: most of the area faces the axis. Not when the two sides are about equal
    # (a thick sherd: its back is as large as its face)
    if inside_out and area[labels == INNER].sum() > _INSIDE_OUT_RATIO * area[labels == OUTER].sum():
        flipped = _label_once(fr, flat_tolerance, sign=-1.0, others=others)
        if area[flipped == OUTER].sum() > area[labels == OUTER].sum():
            return flipped, True
    return labels, False


def _label_once(fr: FaceFrame, flat_tolerance: float, sign: float, others: np.ndarray | None) -> np.ndarray:
    """One labelling with the normals' sign ``sign`` (``others``: as :func:`wall_labels` takes them)."""
    m = len(fr.area)
    adj = fr.adjacency
    s = _smooth(sign * fr.n_radial, fr.area, fr.graph, _SMOOTH_ITERATIONS)
    labels = np.where(s >= 0, OUTER, INNER).astype(np.int8)
    seed = np.abs(s) >= flat_tolerance
    if not seed.any():
        return np.full(m, OUTER, dtype=np.int8)
    flat = ~seed
    if flat.any():
        # nearest seed along the surface (centroid-to-centroid steps, kept strictly positive
        # so the sparse graph keeps every edge). A shortest path's last seed is next to a flat
        # face, so the graph of the steps touching a flat face, from the seeds beside one,
        # gives the same distances as the whole surface's at the cost of the flat part
        touch = flat[adj[:, 0]] | flat[adj[:, 1]]
        step = np.zeros(len(adj))
        step[touch] = np.linalg.norm(fr.centroid[adj[touch, 0]] - fr.centroid[adj[touch, 1]], axis=1)
        step[touch] = np.maximum(step[touch], ROUNDING * max(float(step.max(initial=0.0)), 1e-300))
        sources = np.zeros(m, bool)
        sources[adj[touch].ravel()] = True
        sources &= seed
        # a step from a seed towards a flat face that faces up (towards the mouth) and lies
        # lower, seen from the flat face a climb towards the seed, costs _CLIMB_WEIGHT times the
        # height climbed more (down-facing faces: the other way): a flat part takes the side
        # it reaches without crossing its crest, so a flat rim top splits at its highest line,
        # and a plate's broad rim, sloping down to the well, goes with the inside
        up = np.sign(sign * (fr.n_axial[adj[touch, 0]] + fr.n_axial[adj[touch, 1]]))
        rise = up * (fr.height[adj[touch, 1]] - fr.height[adj[touch, 0]])  # from the first face to the second
        steps = np.stack([step, step], axis=1)
        steps[touch, 0] += _CLIMB_WEIGHT * np.maximum(-rise, 0.0)  # first to second: the second lies lower
        steps[touch, 1] += _CLIMB_WEIGHT * np.maximum(rise, 0.0)
        G = fr.graph.matrix(steps)
        _, _, src = dijkstra(G, directed=True, indices=np.flatnonzero(sources),
                             return_predecessors=True, min_only=True)
        reach = flat & (src >= 0)
        labels[reach] = labels[src[reach]]
        labels[flat & (src < 0)] = OUTER  # flat patches not connected to any wall
    labels = _refine_border(fr, labels, sign * fr.n_radial, s, flat_tolerance)
    return _clean_regions(fr, labels, sign, others)


def _refine_border(fr: FaceFrame, labels: np.ndarray, n_radial: np.ndarray, smoothed: np.ndarray,
                   flat_tolerance: float) -> np.ndarray:
    """Move the split onto the fold: border faces whose own normal clearly faces the other
    way, and whose neighbourhood does not clearly face their side, change side (smoothing
    shifts a sharp crest by a ring or two)."""
    adj = fr.adjacency
    clear = (np.abs(n_radial) >= flat_tolerance) & (
        (np.abs(smoothed) < flat_tolerance) | (np.sign(smoothed) == np.sign(n_radial)))
    own = np.where(n_radial >= 0, OUTER, INNER)
    for _ in range(2 * _SMOOTH_ITERATIONS + 1):
        cross = labels[adj[:, 0]] != labels[adj[:, 1]]
        border = np.zeros(len(labels), dtype=bool)
        border[adj[cross].ravel()] = True
        wrong = border & clear & (own != labels)
        if not wrong.any():
            break
        labels = labels.copy()
        labels[wrong] = own[wrong]
    return labels


def _region_stats(fr: FaceFrame, labels: np.ndarray, sign: float):
    """Components of same-side faces and, per component, its border with the other side."""
    adj = fr.adjacency
    same = labels[adj[:, 0]] == labels[adj[:, 1]]
    comp = fr.graph.components(same)
    nc = int(comp.max()) + 1
    area = np.bincount(comp, weights=fr.area, minlength=nc)
    comp_label = np.zeros(nc, dtype=np.int8)
    comp_label[comp] = labels
    cross = adj[~same]
    length = fr.edge_length[~same]
    nsum = sign * (fr.normal[cross[:, 0]] + fr.normal[cross[:, 1]])
    nn = np.linalg.norm(nsum, axis=1)
    up = np.zeros(len(cross))
    ok = nn > DEGENERATE
    up[ok] = (sign * (fr.n_axial[cross[ok, 0]] + fr.n_axial[cross[ok, 1]])) / nn[ok]
    border = np.zeros(nc)
    border_up = np.zeros(nc)
    border_outer = np.zeros(nc)
    for x, y in ((0, 1), (1, 0)):
        c = comp[cross[:, x]]
        border += np.bincount(c, weights=length, minlength=nc)
        border_up += np.bincount(c, weights=length * up, minlength=nc)
        border_outer += np.bincount(c, weights=length * (labels[cross[:, y]] == OUTER), minlength=nc)
    return comp, comp_label, area, border, border_up, border_outer


def _clean_regions(fr: FaceFrame, labels: np.ndarray, sign: float, others: np.ndarray | None) -> np.ndarray:
    total = float(fr.area.sum() if others is None else fr.area[~others].sum())
    # 1. noise islands join the side around them (an inner strip under a rim stays inner)
    for _ in range(_CLEANUP_PASSES):
        comp, comp_label, area, border, border_up, border_outer = _region_stats(fr, labels, sign)
        up_mean = np.divide(border_up, border, out=np.zeros_like(border), where=border > 0)
        rim_strip = (comp_label == INNER) & (up_mean >= _FOLD_COSINE)
        small = (area < _ISLAND_AREA_FRACTION * total) & (border > 0) & ~rim_strip
        if not small.any():
            break
        majority = np.where(border_outer >= 0.5 * border, OUTER, INNER).astype(np.int8)
        new_label = np.where(small, majority, comp_label)
        if np.array_equal(new_label, comp_label):
            break
        labels = new_label[comp]
    comp, comp_label, area, border, border_up, border_outer = _region_stats(fr, labels, sign)
    up_mean = np.divide(border_up, border, out=np.zeros_like(border), where=border > 0)
    # 2. inward-facing regions: rim fold -> inner; downward fold -> outer; else inside/outside body
    decide = comp_label.copy()
    inner_c = comp_label == INNER
    touches_outer = border_outer > 0
    rim = inner_c & touches_outer & (up_mean >= _FOLD_COSINE)
    foot = inner_c & touches_outer & (up_mean <= -_FOLD_COSINE)
    decide[foot] = OUTER
    undecided = inner_c & ~rim & ~foot
    if undecided.any():  # the profile's medians only for regions the folds leave open (most scans have none)
        outer = labels == OUTER if others is None else (labels == OUTER) & ~others
        decide[undecided & _outside_body(fr, labels, comp, outer)] = OUTER
    labels = decide[comp]
    # 3. outward-facing regions cut off from the main outer wall and bordered mostly by the
    #    inner wall (e.g. a boss on a bowl's floor) belong to the inner wall
    comp, comp_label, area, border, border_up, border_outer = _region_stats(fr, labels, sign)
    outer_c = np.flatnonzero(comp_label == OUTER)
    if len(outer_c) > 1:
        wall = np.bincount(comp, weights=fr.wall_area, minlength=len(area))
        if others is not None:  # (an object's pieces are whole components: none is the vessel's outer wall)
            wall[np.bincount(comp, weights=others, minlength=len(area)) > 0] = -1.0
        main = outer_c[np.argmax(wall[outer_c])]
        enclosed = (comp_label == OUTER) & (border > 0) & (border_outer < 0.5 * border)
        enclosed[main] = False
        comp_label = np.where(enclosed, INNER, comp_label).astype(np.int8)
        labels = comp_label[comp]
    return labels.astype(np.int8)


def _ground(fr: FaceFrame, labels: np.ndarray, vessel: np.ndarray, sign: float, flat_tolerance: float
            ) -> np.ndarray:
    """Faces of a table or ground joined to the foot, (m,) bool.

    Outer faces whose normal (``sign`` times the frame's, or smoothed) faces the mouth, at
    the vessel's lowest heights (below :data:`_GROUND_HEIGHT` of its height above its
    lowest face that does not face up), in connected pieces whose area-weighted median
    radius lies beyond the foot (the :data:`_FOOT_QUANTILE` quantile of the radii of the
    wall at those heights, weighted by its wall area, the faces facing the mouth by their
    own normal left out); with the faces joined to them that face up more than sideways,
    at those heights or :data:`_GROUND_OUTSIDE` of the body's radius outside its profile (a
    ground tilted against the axis rises out of those heights); none unless one piece
    holds at least :data:`_ISLAND_AREA_FRACTION` of the vessel's area. A vessel's own outer
    faces there face down (a base, a foot ring's underside) or away from the axis (the
    foot's wall); the top of a kylix's foot lies within the foot's edge.
    """
    h = fr.height
    facing = sign * fr.n_axial
    # the vessel's lowest face: of those not facing up (a ground tilted against the axis
    # reaches below the foot), and every face up to the band's top
    standing = vessel & (facing < _GROUND_COSINE)
    lo = float(h[standing if standing.any() else vessel].min())
    low = vessel & (h <= lo + _GROUND_HEIGHT * (float(h[vessel].max()) - lo))
    up = low & (labels == OUTER) & (facing >= _GROUND_COSINE)
    wall = low & ~up & (np.abs(fr.n_radial) >= flat_tolerance)
    if not wall.any():
        return np.zeros_like(low)
    foot = weighted_percentile(fr.radius[wall], fr.wall_area[wall], 100.0 * _FOOT_QUANTILE)
    if not np.any(up & (fr.radius > foot)):  # (most scans: nothing faces up beyond the foot)
        return np.zeros_like(low)
    # its own normal, or smoothed over a bumpy ground's facets
    up = low & (labels == OUTER) & (np.maximum(facing, _smooth(facing, fr.area, fr.graph, _SMOOTH_ITERATIONS))
                                    >= _GROUND_COSINE)
    adj = fr.adjacency
    comp = fr.graph.components(up[adj[:, 0]] & up[adj[:, 1]])
    _, piece = np.unique(comp[up], return_inverse=True)
    n = int(piece.max()) + 1
    area = np.bincount(piece, weights=fr.area[up], minlength=n)
    radius = weighted_quantiles(piece, fr.radius[up], fr.area[up], n, (0.5,))[0]
    beyond = radius > foot
    if not np.any(beyond & (area >= _ISLAND_AREA_FRACTION * float(fr.area[vessel].sum()))):
        return np.zeros_like(up)
    out = np.zeros_like(up)  # (with the scraps beside a ground: strips joined at a pinched vertex)
    out[np.flatnonzero(up)[beyond[piece]]] = True
    # with the faces joined to it that face up more than sideways: at those heights (where
    # it meets the foot), and well outside the body at any height (a ground tilted against
    # the axis rises out of those heights)
    outer = vessel & (labels == OUTER)
    reach = low
    found = _profile_offset(fr, outer & ~out)
    if found is not None:
        reach = low | (found[0] > _GROUND_OUTSIDE * found[1])
    grow = out | (outer & reach & (facing > np.abs(fr.n_radial)))
    comp = fr.graph.components(grow[adj[:, 0]] & grow[adj[:, 1]])
    reached = np.zeros(int(comp.max()) + 1, bool)
    reached[comp[out]] = True
    return grow & reached[comp]


def _profile_offset(fr: FaceFrame, outer_faces: np.ndarray) -> tuple[np.ndarray, float] | None:
    """How far each face lies outside the outer wall's profile: ``(offset (m,), largest
    profile radius)``, the offset its radius minus the profile's (the wall-area-weighted
    median radius of ``outer_faces`` in its height bin) at its height; None without a
    profile."""
    if not outer_faces.any():
        return None
    h = fr.height
    lo, hi = float(h.min()), float(h.max())
    k = int(np.clip(np.sqrt(outer_faces.sum()) / 2, 4, 400))
    edges = np.linspace(lo, hi, k + 1) if hi > lo else np.array([lo - 0.5, lo + 0.5])
    weight = fr.wall_area
    (prof,), _ = binned_median(h[outer_faces], fr.radius[outer_faces], weight[outer_faces], edges)
    centres = 0.5 * (edges[:-1] + edges[1:])
    good = np.isfinite(prof)
    if not good.any():
        return None
    return fr.radius - np.interp(h, centres[good], prof[good]), float(prof[good].max())


def _outside_body(fr: FaceFrame, labels: np.ndarray, comp: np.ndarray, outer_faces: np.ndarray) -> np.ndarray:
    """Per component: does it lie outside the outer wall's profile (median radial offset > 0)?"""
    nc = int(comp.max()) + 1
    found = _profile_offset(fr, outer_faces)
    if found is None:
        return np.zeros(nc, dtype=bool)
    # area-weighted median offset per component
    (med,), _ = binned_median(comp.astype(np.float64), found[0], fr.area + 1e-300,
                              np.arange(nc + 1, dtype=np.float64) - 0.5)
    return np.nan_to_num(med, nan=0.0) > 0
