"""Distortion measures of a flattening, shared by rollout, relax and bake.

All measures compare each flattened triangle or edge with the same one on the 3D scan:

* **edge-length RMS**: ``sqrt(mean(((l_2d - l_3d) / l_3d)^2))`` over the mesh edges
  (dimensionless; 0 for an isometric flattening).
* **area distortion** per face: ``log(A_2d / A_3d)``; summarised as the area-weighted mean
  of its absolute value.
* **anisotropy** per face: ``sigma_1 / sigma_2``, the ratio of the singular values of the
  linear map from the 3D triangle to the flat one (1 = no shear or one-sided stretch).
* **flipped**: faces whose flat signed area is not positive (folded or mirrored).
* **stress** per vertex: the paper's Eq. 3, ``sqrt(sum_j (|x_i - x_j| - r_ij)^2 / sum_j r_ij)``
  over the vertex's mesh edges, evaluated in millimetres (so its unit is sqrt(mm) and it does
  not depend on the scan's unit).

Faces whose 3D area is (numerically) zero carry no distortion and are excluded.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from functools import cached_property

import numpy as np

from potflat.mesh._kernels.geometry import edge_lengths, face_frames, faces_reaching, flat_face_maps, triangle_areas, valid_face_figures

from potflat.mesh._kernels.quantiles import select_weighted_quantiles

from potflat.mesh._kernels.topology import mark_face_edges
from potflat.mesh.tolerances import ROUNDING
from potflat.mesh._kernels.topology import edge_table
from potflat.types import FlatMesh

#: Relative 3D area below which a face counts as degenerate (fraction of the mean face area).
DEGENERATE_AREA_FRACTION = 1e-12
#: Faces (or edges) per block of the per-face and per-edge figures: bounds their
#: temporaries on big meshes (the figures do not depend on it).
BLOCK = 1 << 18


@dataclass(frozen=True)
class FaceDistortion:
    """Per-face distortion of a flattening.

    Attributes
    ----------
    area_3d : (m,) float64
        Triangle area on the scan, scan units squared.
    area_2d : (m,) float64
        Signed flattened area (negative when flipped).
    sigma_max, sigma_min : (m,) float64
        Singular values of the 3D-to-flat linear map (``sigma_min`` is signed: negative when flipped).
    valid : (m,) bool
        Non-degenerate faces (positive 3D area).
    """

    area_3d: np.ndarray
    area_2d: np.ndarray
    sigma_max: np.ndarray
    sigma_min: np.ndarray
    valid: np.ndarray

    @property
    def log_area_ratio(self) -> np.ndarray:
        """``log(|A_2d| / A_3d)`` per face, 0 for degenerate faces. Shape (m,)."""
        out = np.zeros_like(self.area_3d)
        v = self.valid & (self.area_2d != 0)
        out[v] = np.log(np.abs(self.area_2d[v]) / self.area_3d[v])
        return out

    @property
    def anisotropy(self) -> np.ndarray:
        """``sigma_max / |sigma_min|`` per face (inf for faces collapsed to a segment, NaN to a
        point, 1 for degenerate ones). Shape (m,)."""
        out = np.ones_like(self.area_3d)
        v = self.valid
        with np.errstate(divide="ignore", invalid="ignore"):  # (a collapsed face is not an error)
            out[v] = self.sigma_max[v] / np.abs(self.sigma_min[v])
        return out


@dataclass(frozen=True)
class DistortionSummary:
    """Scalar distortion figures of a flattening (all dimensionless)."""

    edge_rms: float
    edge_max: float
    area_mean_abs_log: float
    area_p95_abs_log: float
    area_max_abs_log: float
    anisotropy_mean: float
    anisotropy_p95: float
    anisotropy_max: float
    scale: float
    flipped: int
    degenerate: int

    def as_dict(self) -> dict:
        """The figures as a plain JSON-ready dict."""
        return asdict(self)


def percent_from_log(mean_abs_log: float) -> float:
    """A mean ``|ln(ratio)|`` as the percentage change it stands for (0.1604 -> 17.4 %).

    Every area figure potflat reports is a natural log of the area ratio flat / 3D.
    """
    return 100.0 * math.expm1(mean_abs_log)


def face_distortion(vertices: np.ndarray, uv: np.ndarray, faces: np.ndarray) -> FaceDistortion:
    """Per-face distortion of the map from ``vertices`` to ``uv``.

    Parameters
    ----------
    vertices : (n, 3) float64
        3D positions.
    uv : (n, 2) float64
        Flattened positions, same units.
    faces : (m, 3) int64
        Triangles, counter-clockwise seen from outside.

    Returns
    -------
    FaceDistortion
    """
    return SurfaceReference(vertices, faces).face_distortion(uv)


class SurfaceReference:
    """The 3D side of the distortion figures of one triangle set, computed once and reused
    for every flattening of it (the proxy candidates of a rollout, before and after relax).

    Parameters
    ----------
    vertices : (n, 3) float64
        3D positions.
    faces : (m, 3) int64
        Triangles, counter-clockwise seen from outside.
    edges : (e, 2) int64, optional
        :func:`unique_edges` of ``faces`` when the caller has them (the first array of
        :func:`potflat.mesh.boundary.edges_and_boundary` is the same); found when first needed.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, *, edges: np.ndarray | None = None):
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64)
        F = np.ascontiguousarray(faces, dtype=np.int64)
        self.faces = F if F.ndim == 2 and F.shape[1] == 3 else F.reshape(-1, 3)  # (the caller's array: describes)
        if edges is not None:  # (the cached property's value)
            self.__dict__["edges"] = np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2)

    def describes(self, vertices: np.ndarray, faces: np.ndarray) -> bool:
        """Whether this is the reference of ``vertices`` (n, 3) and ``faces`` (m, 3): the same
        arrays (the usual case, checked first) or equal ones."""
        return all(mine is theirs or (mine.shape == np.shape(theirs) and np.array_equal(mine, theirs))
                   for mine, theirs in ((self.vertices, vertices), (self.faces, faces)))

    @cached_property
    def area_3d(self) -> np.ndarray:
        """3D face areas. Shape (m,) float64."""
        return face_areas(self.vertices, self.faces)

    @cached_property
    def valid(self) -> np.ndarray:
        """Non-degenerate faces (:func:`_nondegenerate`). Shape (m,) bool."""
        return _nondegenerate(self.area_3d)

    @cached_property
    def edges(self) -> np.ndarray:
        """The undirected mesh edges (:func:`unique_edges`). Shape (e, 2) int64."""
        return unique_edges(self.faces)

    @cached_property
    def edge_length_3d(self) -> np.ndarray:
        """3D length of each of :attr:`edges`. Shape (e,) float64."""

        return edge_lengths(self.vertices, self.edges)

    @cached_property
    def _frames(self) -> np.ndarray:
        return face_frames(self.vertices, self.faces, self.area_3d, self.valid)

    def _flat_lengths(self, uv: np.ndarray) -> np.ndarray:
        return edge_lengths(np.ascontiguousarray(uv, dtype=np.float64), self.edges)

    def face_distortion(self, uv: np.ndarray) -> FaceDistortion:
        """Per-face distortion of the map to ``uv`` ((n, 2) float64)."""

        area_2d, sigma_max, sigma_min = flat_face_maps(np.ascontiguousarray(uv, dtype=np.float64),
                                                       self.faces, self._frames)
        return FaceDistortion(self.area_3d, area_2d, sigma_max, sigma_min, self.valid)

    def edge_length_error(self, uv: np.ndarray) -> np.ndarray:
        """Relative edge-length error per edge of :attr:`edges` (as :func:`edge_length_error`). Shape (e,)."""
        return _relative_error(self._flat_lengths(uv), self.edge_length_3d)

    def vertex_stress(self, uv: np.ndarray, mm_per_unit: float = 1.0) -> np.ndarray:
        """:func:`vertex_stress` of the map to ``uv``. Shape (n,) float64."""
        r = self.edge_length_3d * mm_per_unit
        l = self._flat_lengths(uv) * mm_per_unit
        return _vertex_root_ratio(self.edges, (l - r) ** 2, r, len(self.vertices))

    def vertex_length_error(self, uv: np.ndarray, *, edge_error: np.ndarray | None = None) -> np.ndarray:
        """:func:`vertex_length_error` of the map to ``uv`` (``edge_error``: its
        :meth:`edge_length_error` when the caller has it). Shape (n,) float64."""
        if not len(self.edges):
            return np.zeros(len(self.vertices))
        err = edge_error if edge_error is not None else self.edge_length_error(uv)
        return 100.0 * _vertex_root_ratio(self.edges, err ** 2, np.ones(len(self.edges)), len(self.vertices))

    def summarize(self, uv: np.ndarray, *, fd: FaceDistortion | None = None,
                  edge_error: np.ndarray | None = None) -> DistortionSummary:
        """Scalar distortion figures of the map to ``uv`` ((n, 2) float64; see module docs);
        ``fd``, ``edge_error``: its :meth:`face_distortion` and :meth:`edge_length_error` when
        the caller has them."""
        if not len(self.faces):
            edge_error = np.zeros(1)
        return _summary(fd if fd is not None else self.face_distortion(uv),
                        edge_error if edge_error is not None else self.edge_length_error(uv))

    @cached_property
    def _edge_first(self) -> np.ndarray:
        """Where each vertex's edges start in :attr:`edges` as their smaller endpoint. Shape (n + 1,) int64."""
        first = np.zeros(len(self.vertices) + 1, np.int64)
        np.cumsum(np.bincount(self.edges[:, 0], minlength=len(self.vertices)), out=first[1:])
        return first

    def summarize_part(self, uv: np.ndarray, part: np.ndarray, *, fd: FaceDistortion | None = None,
                       edge_error: np.ndarray | None = None) -> DistortionSummary:
        """The figures of the faces ``part`` alone: ``summarize(vertices, uv, faces[part])``,
        taken from this reference's per-face and per-edge arrays instead of a new reference.

        Parameters
        ----------
        uv : (n, 2) float64
        part : (m,) bool
        fd, edge_error : optional
            :meth:`face_distortion` and :meth:`edge_length_error` of ``uv`` when the caller has them.
        """

        part = np.asarray(part, bool)
        area = self.area_3d[part]
        valid = _nondegenerate(area)  # (by the part's own mean area, as a reference of its faces has it)
        if not part.any() or not np.array_equal(valid, self.valid[part]):
            # (a face degenerate by one of the two mean areas only: its frame differs)
            return summarize(self.vertices, uv, self.faces[part])
        fd = fd if fd is not None else self.face_distortion(uv)
        err = edge_error if edge_error is not None else self.edge_length_error(uv)
        on_part = np.zeros(len(self.edges), bool)
        mark_face_edges(self.faces, part, self.edges, self._edge_first, on_part)
        return _summary(FaceDistortion(area, fd.area_2d[part], fd.sigma_max[part], fd.sigma_min[part], valid),
                        err[on_part])


def _nondegenerate(area_3d: np.ndarray) -> np.ndarray:
    """Faces whose 3D area is above :data:`DEGENERATE_AREA_FRACTION` of the mean. Shape (m,) bool."""
    mean_area = area_3d.mean() if len(area_3d) else 0.0
    return area_3d > DEGENERATE_AREA_FRACTION * max(mean_area, np.finfo(float).tiny)


def _summary(fd: FaceDistortion, err: np.ndarray) -> DistortionSummary:
    """:class:`DistortionSummary` of per-face figures ``fd`` and relative edge-length errors ``err`` ((e,))."""

    m = len(fd.area_3d)
    w, area_2d, ratio, an = (np.empty(m) for _ in range(4))
    count, flipped = valid_face_figures(fd.area_3d, fd.area_2d, fd.sigma_max, fd.sigma_min, fd.valid,
                                        w, area_2d, ratio, an)
    w, area_2d, an = w[:count], area_2d[:count], an[:count]
    la = np.abs(np.log(ratio[:count]))  # (NumPy's log: the figures of FaceDistortion.log_area_ratio, bit for bit)
    total3 = w.sum()
    if not count:
        la = an = w = np.ones(1)
    return DistortionSummary(
        edge_rms=float(np.sqrt(np.mean(err**2))),
        edge_max=float(np.max(np.abs(err))),
        area_mean_abs_log=float(np.average(la, weights=w)),
        area_p95_abs_log=float(np.percentile(la, 95)),
        area_max_abs_log=float(np.max(la)),
        anisotropy_mean=float(np.average(an, weights=w)) if np.isfinite(an).all() else float("inf"),
        # no interpolation across infinite values (inf - inf is NaN): collapsed faces give inf
        anisotropy_p95=float(np.percentile(an, 95, method="linear" if np.isfinite(an).all() else "higher")),
        anisotropy_max=float(np.max(an)),
        scale=float(area_2d.sum() / total3) if total3 > 0 else 0.0,
        flipped=int(flipped),
        degenerate=m - int(count),
    )


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """3D area of each face (a parallel kernel, no temporaries). Shape (m,) float64."""

    return triangle_areas(np.ascontiguousarray(vertices, dtype=np.float64),
                          np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3))


def row_blocks(m: int, size: int | None = None) -> list[slice]:
    """Slices of ``size`` rows (default :data:`BLOCK`) covering ``range(m)``, to bound the
    temporaries of per-row work."""
    size = size or BLOCK
    return [slice(a, min(a + size, m)) for a in range(0, m, size)]


def bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest value of each column of ``points``.

    Parameters
    ----------
    points : (k, d) float64

    Returns
    -------
    lo, hi : (d,) float64

    Notes
    -----
    Column by column: NumPy reduces a C-ordered (k, d) array along its first axis 4-8x slower
    than each (strided) column by itself (3M x 3: 0.11 against 0.028 s for the minimum).
    """
    cols = range(points.shape[1])
    return np.array([points[:, j].min() for j in cols]), np.array([points[:, j].max() for j in cols])


def median_edge_length(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Median length of the faces' edges, each edge once per face (3 m lengths; the parallel
    :func:`potflat.mesh._kernels.edge_lengths` in blocks of :data:`BLOCK` faces).

    Parameters
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int64
        At least one face.

    Returns
    -------
    float
    """

    V = np.ascontiguousarray(vertices, dtype=np.float64)
    F = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    length = np.empty(F.shape)
    for s in row_blocks(len(F)):
        f = F[s]
        length[s] = edge_lengths(V, np.stack((f, f[:, [1, 2, 0]]), axis=2).reshape(-1, 2)).reshape(-1, 3)
    return float(np.median(length, overwrite_input=True))  # (ours: partitioned in place, no copy)


def _edge_vectors(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``p1 - p0`` and ``p2 - p0`` of each face ((k, d) float64 each)."""
    p0 = points[faces[:, 0]]
    return points[faces[:, 1]] - p0, points[faces[:, 2]] - p0


def unique_edges(faces: np.ndarray) -> np.ndarray:
    """Undirected edges of ``faces``, each once (``i <= j``), sorted. Shape (e, 2) int64
    (the edge table's, :func:`potflat.mesh._kernels.topology.edge_table`)."""
    faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    n = int(faces.max()) + 1 if len(faces) else 0
    return edge_table(faces, n)[1]


def edge_length_error(vertices: np.ndarray, uv: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Relative edge-length error ``(l_2d - l_3d) / l_3d`` per edge (0 for zero-length edges). Shape (e,)."""

    edges = np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2)
    return _relative_error(edge_lengths(np.ascontiguousarray(uv, dtype=np.float64), edges),
                           edge_lengths(np.ascontiguousarray(vertices, dtype=np.float64), edges))


def _relative_error(l2: np.ndarray, l3: np.ndarray) -> np.ndarray:
    """``(l2 - l3) / l3`` where ``l3 > 0``, else 0. Shape like ``l3``."""
    ok = l3 > 0
    out = np.subtract(l2, l3)
    np.divide(out, l3, out=out, where=ok)
    out[~ok] = 0.0
    return out


def vertex_stress(vertices: np.ndarray, uv: np.ndarray, faces: np.ndarray, mm_per_unit: float = 1.0) -> np.ndarray:
    """The paper's per-vertex residual stress (Eq. 3) over mesh edges, in sqrt(mm).

    Parameters
    ----------
    vertices : (n, 3) float64
    uv : (n, 2) float64
    faces : (m, 3) int64
    mm_per_unit : float
        Millimetres per unit of ``vertices`` and ``uv``.

    Returns
    -------
    (n,) float64
        0 for isolated vertices.
    """
    return SurfaceReference(vertices, faces).vertex_stress(uv, mm_per_unit)


def _vertex_root_ratio(edges: np.ndarray, num: np.ndarray, den: np.ndarray, n: int) -> np.ndarray:
    """``sqrt(sum num / sum den)`` over each vertex's edges ((e,) values per edge), 0 where a
    vertex has no edge weight. Shape (n,) float64."""
    top = np.bincount(edges[:, 0], num, n) + np.bincount(edges[:, 1], num, n)
    bottom = np.bincount(edges[:, 0], den, n) + np.bincount(edges[:, 1], den, n)
    out = np.zeros(n)
    ok = bottom > 0
    out[ok] = np.sqrt(top[ok] / bottom[ok])
    return out


def vertex_length_error(vertices: np.ndarray, uv: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """How far the lengths around each vertex are off, in percent: the RMS of the relative
    length error ``(l_2d - l_3d) / l_3d`` over the vertex's mesh edges (what the stress map
    shows; the paper's Eq. 3 stays :func:`vertex_stress`).

    Parameters
    ----------
    vertices : (n, 3) float64
    uv : (n, 2) float64
    faces : (m, 3) int64

    Returns
    -------
    (n,) float64
        0 for isolated vertices.
    """
    return SurfaceReference(vertices, faces).vertex_length_error(uv)


def summarize(vertices: np.ndarray, uv: np.ndarray, faces: np.ndarray, *,
              edges: np.ndarray | None = None) -> DistortionSummary:
    """Scalar distortion figures of the map from ``vertices`` to ``uv`` (see module docs); to
    compare several flattenings of one mesh, build one :class:`SurfaceReference`. ``edges``:
    :func:`unique_edges` of ``faces`` when the caller has them."""
    return SurfaceReference(vertices, faces, edges=edges).summarize(uv)


def summarize_flat(flat: FlatMesh) -> DistortionSummary:
    """:func:`summarize` for a :class:`FlatMesh`."""
    return summarize(flat.mesh.vertices, flat.uv, flat.mesh.faces)


#: A face belongs to the important zone when the mean importance of its corners reaches this.
ZONE_THRESHOLD = 0.5


def important_faces(faces: np.ndarray, importance: np.ndarray | None) -> np.ndarray:
    """Faces of the important zone (mean corner importance >= :data:`ZONE_THRESHOLD`).

    Parameters
    ----------
    faces : (m, 3) int64
    importance : (n,) float64 in [0, 1] or None
        None: the whole surface is the zone.

    Returns
    -------
    (m,) bool
    """

    if importance is None:
        return np.ones(len(faces), bool)
    out = np.empty(len(faces), bool)
    faces_reaching(np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3),
                   np.ascontiguousarray(importance, dtype=np.float64), ZONE_THRESHOLD, out)
    return out


def weighted_percentile(values: np.ndarray, weights: np.ndarray, q: float) -> float:
    """The ``q``-th percentile (0-100) of ``values`` where each counts with its weight (the
    smallest value at or above ``q`` % of the total weight). NaN for no positive weight."""
    return weighted_percentiles(values, weights, (q,))[0]


def weighted_percentiles(values: np.ndarray, weights: np.ndarray, qs) -> list[float]:
    """:func:`weighted_percentile` for each of ``qs``, by selection, not a sort of all values
    (:func:`potflat.mesh._kernels.select_weighted_quantiles`; 6M values: 0.07 s a percentile,
    0.073 s two, against 0.7 s for a sort). Ties and NaN as a sort orders them (NaN last);
    the total weight is summed in index order."""

    values = np.ascontiguousarray(values, dtype=np.float64).ravel()
    weights = np.ascontiguousarray(weights, dtype=np.float64).ravel()
    if values.shape != weights.shape:
        raise ValueError(f"values and weights differ in length ({len(values)} and {len(weights)})")
    if not (weights > 0).any():
        return [float("nan")] * len(qs)
    out = np.empty(len(qs))
    select_weighted_quantiles(values, weights, np.asarray(qs, dtype=np.float64) / 100.0, out)
    return [float(x) for x in out]


def length_scale(fd: FaceDistortion) -> np.ndarray:
    """Linear scale of each face, ``sqrt(|A_2d| / A_3d)`` (1 for degenerate faces). Shape (m,)."""
    out = np.ones_like(fd.area_3d)
    v = fd.valid
    out[v] = np.sqrt(np.abs(fd.area_2d[v]) / fd.area_3d[v])
    return out


def length_error(fd: FaceDistortion) -> np.ndarray:
    """Largest relative error of a length through each face: ``max(sigma_max - 1, 1 - sigma_min)``
    (0.05: some length there is 5% too long or too short; flipped faces count > 1). Shape (m,)."""
    return np.where(fd.valid, np.maximum(fd.sigma_max - 1.0, 1.0 - fd.sigma_min), 0.0)


@dataclass(frozen=True)
class ZoneFigures:
    """How true the image is in one zone of the surface (the important zone or the rest).

    Attributes
    ----------
    area_fraction : float
        Share of the surface's 3D area in the zone.
    faces : int
    scale_median : float
        Area-weighted median of the faces' linear scale (1: true scale).
    length_error_median_pct, length_error_p95_pct : float
        Area-weighted median and 95th percentile of the largest length error through a face,
        in percent (:func:`length_error`).
    distortion : DistortionSummary or None
        The usual figures over the zone's faces (None for an empty zone).
    """

    area_fraction: float
    faces: int
    scale_median: float
    length_error_median_pct: float
    length_error_p95_pct: float
    distortion: DistortionSummary | None

    def as_dict(self) -> dict:
        """JSON-ready dict (the distortion nested)."""
        out = asdict(self)
        out["distortion"] = self.distortion.as_dict() if self.distortion is not None else None
        return out


def zone_figures(vertices: np.ndarray, uv: np.ndarray, faces: np.ndarray, importance: np.ndarray | None, *,
                 reference: SurfaceReference | None = None, fd: FaceDistortion | None = None,
                 edge_error: np.ndarray | None = None) -> dict[str, ZoneFigures]:
    """:class:`ZoneFigures` of the important zone (``"important"``) and of the rest (``"rest"``).

    Parameters
    ----------
    vertices : (n, 3) float64
    uv : (n, 2) float64
    faces : (m, 3) int64
    importance : (n,) float64 or None
        None: the whole surface is the important zone and the rest is empty.
    reference : SurfaceReference, optional
        The 3D side of ``vertices`` and ``faces`` when the caller has it already.
    fd, edge_error : optional
        ``reference``'s :meth:`~SurfaceReference.face_distortion` and
        :meth:`~SurfaceReference.edge_length_error` of ``uv`` when the caller has them.
    """
    reference = reference if reference is not None else SurfaceReference(vertices, faces)
    fd = fd if fd is not None else reference.face_distortion(uv)
    if edge_error is None and len(faces):
        edge_error = reference.edge_length_error(uv)
    zone = important_faces(faces, importance)
    scale, err = length_scale(fd), length_error(fd)
    total = float(fd.area_3d[fd.valid].sum()) or 1.0
    out = {}
    for key, sel in (("important", zone), ("rest", ~zone)):
        w = np.where(sel & fd.valid, fd.area_3d, 0.0)
        if not sel.any() or w.sum() <= 0:
            out[key] = ZoneFigures(0.0, int(sel.sum()), float("nan"), float("nan"), float("nan"), None)
            continue
        err_median, err_p95 = weighted_percentiles(err, w, (50.0, 95.0))
        out[key] = ZoneFigures(
            area_fraction=float(w.sum()) / total,
            faces=int(sel.sum()),
            scale_median=weighted_percentile(scale, w, 50.0),
            length_error_median_pct=100.0 * err_median,
            length_error_p95_pct=100.0 * err_p95,
            distortion=reference.summarize_part(uv, sel, fd=fd, edge_error=edge_error),
        )
    return out


def true_scale_factor(vertices: np.ndarray, uv: np.ndarray, faces: np.ndarray, importance: np.ndarray | None, *,
                      reference: SurfaceReference | None = None) -> float:
    """The uniform factor that brings the area-weighted median linear scale of the important
    zone (the whole surface when ``importance`` is None) to 1; 1 when it is undefined.

    Parameters
    ----------
    vertices : (n, 3) float64
    uv : (n, 2) float64
    faces : (m, 3) int64
    importance : (n,) float64 or None
    reference : SurfaceReference or None
        The 3D side of ``vertices`` and ``faces`` when the caller has it already.
    """
    fd = (reference or SurfaceReference(vertices, faces)).face_distortion(uv)
    zone = important_faces(faces, importance) & fd.valid
    if not zone.any():
        zone = fd.valid
    median = weighted_percentile(length_scale(fd), np.where(zone, fd.area_3d, 0.0), 50.0)
    return 1.0 / median if np.isfinite(median) and median > 0 else 1.0


@dataclass(frozen=True)
class ZoneSummary:
    """How true a flattening is inside the important (painted) zone and outside it.

    Attributes
    ----------
    important_zone : ZoneFigures
        The important zone (the whole surface without an importance).
    rest : ZoneFigures
        The rest of the surface (empty without an importance).
    lengths : str
        One sentence on how far lengths read off the image are off where the painting is.
    """

    important_zone: ZoneFigures
    rest: ZoneFigures
    lengths: str

    def as_dict(self) -> dict:
        """JSON-ready dict: ``important_zone`` (:data:`PAINTED_ZONE_KEY`), ``rest`` (NaN as
        null) and ``lengths``."""
        return {PAINTED_ZONE_KEY: _json_safe(self.important_zone.as_dict()), "rest": _json_safe(self.rest.as_dict()),
                "lengths": self.lengths}


def zone_summary(vertices: np.ndarray, uv: np.ndarray, faces: np.ndarray, importance: np.ndarray | None, *,
                 reference: SurfaceReference | None = None, fd: FaceDistortion | None = None,
                 edge_error: np.ndarray | None = None) -> ZoneSummary:
    """How true the flattening is inside the important zone and outside it.

    Parameters
    ----------
    vertices : (n, 3) float64
    uv : (n, 2) float64
    faces : (m, 3) int64
    importance : (n,) float64 or None
    reference : SurfaceReference, optional
        The 3D side of ``vertices`` and ``faces`` when the caller has it already.
    fd, edge_error : optional
        As for :func:`zone_figures`.
    """
    zones = zone_figures(vertices, uv, faces, importance, reference=reference, fd=fd, edge_error=edge_error)
    imp = zones["important"]
    where = "in the painted zone" if importance is not None else "on the surface"
    words = (f"lengths measured on the image {where} are off by {imp.length_error_median_pct:.1f}% "
             f"(median) and by at most {imp.length_error_p95_pct:.1f}% over 95% of it; "
             f"median scale {imp.scale_median:.3f}")
    return ZoneSummary(important_zone=imp, rest=zones["rest"], lengths=words)


def _json_safe(node):
    """NaN and infinity as None (JSON has neither), recursively."""
    if isinstance(node, dict):
        return {k: _json_safe(v) for k, v in node.items()}
    if isinstance(node, float) and not math.isfinite(node):
        return None
    return node


#: Key of the relax stage's JSON holding the figures of the painted (important) zone
#: (:func:`zone_summary`).
PAINTED_ZONE_KEY = "important_zone"


def painted_zone_distortion(relax_summary: dict) -> tuple[dict, str]:
    """The distortion figures to quote, and where they were measured.

    The relax stage's figures of the painted (important) zone (:data:`PAINTED_ZONE_KEY`: its
    ``distortion`` with its ``length_error_median_pct`` and ``length_error_p95_pct``) when it
    reports them, else those of the whole surface (``distortion``). A zone covering the whole
    surface (no importance) is reported as the whole surface.

    Parameters
    ----------
    relax_summary : dict
        Content of ``NAME.relaxed.json``.

    Returns
    -------
    figures : dict
        ``edge_rms``, ``area_mean_abs_log``, ``flipped``... and, from the zone,
        ``length_error_median_pct``, ``length_error_p95_pct`` (may be empty).
    where : str
        ``"painted zone"`` or ``"whole surface"``.
    """
    zone = relax_summary.get(PAINTED_ZONE_KEY)
    if isinstance(zone, dict) and isinstance(zone.get("distortion"), dict):
        figures = {**zone["distortion"], **{k: zone.get(k) for k in ("length_error_median_pct",
                                                                      "length_error_p95_pct", "area_fraction")}}
        whole = (zone.get("area_fraction") or 0.0) >= 1.0 - ROUNDING
        return figures, "whole surface" if whole else "painted zone"
    return relax_summary.get("distortion") or {}, "whole surface"


def distortion_words(figures: dict) -> str:
    """Distortion figures as a reader quotes them (% length and area error, folded triangles)."""
    def pct(x: float) -> str:
        return f"{x:.1f}" if abs(x) >= 1 else f"{x:.2g}"

    parts = []
    if figures.get("length_error_median_pct") is not None and figures.get("length_error_p95_pct") is not None:
        parts.append(f"lengths off by {pct(figures['length_error_median_pct'])} % (median), at most "
                     f"{pct(figures['length_error_p95_pct'])} % over 95 % of it")
    elif figures.get("edge_rms") is not None:
        parts.append(f"length error {pct(100 * figures['edge_rms'])} % RMS")
    if figures.get("area_mean_abs_log") is not None:
        parts.append(f"area error {pct(percent_from_log(figures['area_mean_abs_log']))} % mean")
    if figures.get("flipped") is not None:
        parts.append(f"{figures['flipped']} folded triangles")
    return ", ".join(parts) or "not measured"
