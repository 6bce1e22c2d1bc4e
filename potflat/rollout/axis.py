"""The rotation axis of a vessel scan, found from its surface normals.

On a surface of revolution every normal line meets the axis. The axis is therefore the
line closest to all normal lines of the scan (Pottmann and Randrup's line-complex fit, in
Pluecker coordinates, area-weighted), refined robustly by iteratively reweighted least
squares (Huber weights on the angle between each normal and the meridian plane through its
face), and optionally polished by making the radius constant within height slices (profile
consistency). PCA of the surface is only a fallback.

Quality figures (reported, never hidden):

* ``rms_angle_deg`` / ``median_angle_deg``: area-weighted RMS / median angle between each
  vertex normal and the plane that contains the axis and the vertex (0 for an exact
  surface of revolution whatever the scan's size; the faceting of a coarse mesh alone gives
  about 1 degree, noisy or fluted scans up to about 10);
* ``misfit_angle_deg``: the part of that angle, on the outer wall, that leans to one side
  and turns once around the axis within each height slice (its first harmonic in the
  angle around the axis), area-weighted RMS: what a tilted or off-centre axis leaves (an
  axis off a cylinder's centre by a share s of its radius: s / sqrt(2) radians), and what
  relief, flutes or an irregular hand-made wall, which raise ``rms_angle_deg``, do not; the
  rollout warns above :data:`potflat.rollout.notes.WARN_AXIS_MISFIT_DEG`;
* ``rms_distance``: area-weighted RMS distance between each vertex normal line and the axis,
  in scan units, over the vertices whose normal is at least 10 degrees away from the axis
  direction (the distance is undefined for normals parallel to the axis);
* ``profile_deviation``: median of ``|r - profile(h)|`` over the outer wall's vertices
  (normals facing away from the axis), relative to their median radius; the profile
  interpolates the height slices' median radii. It decides whether the scan has an axis at all: a box
  gives about 0.1, scanned vessels (even fluted ones) 0.01-0.02; above
  :data:`MAX_PROFILE_DEVIATION` (or a median angle above :data:`MAX_MEDIAN_ANGLE_DEG`)
  :class:`~potflat.errors.AxisNotFoundError` is raised.

The lines used are vertex normal lines (area-weighted mean of the adjacent face normals,
through the vertex): on an exactly sampled surface of revolution they meet the axis far
more closely than face normals through face centroids, which the faceting tilts.

Orientation (foot to mouth), the first rule that applies:

1. an inner wall (normals facing the axis, as inside a cup, a two-walled scan or a scanned
   inner neck) shows from the mouth down: the mouth is the end (last 10 % of the height)
   where a larger share of the area faces the axis, by at least 5 points (a two-sided
   sherd has its inner face at both ends and goes to the next rules). An end whose inside
   is closed across by a surface facing along the axis counts as having none: facing out
   (a foot ring's inside over its base, a neck shut by a lid), so a jar scanned without its
   interior is not turned over by its foot ring, or facing in (the floor of a dish or plate
   whose face alone was scanned, its well reaching the floor's end), so such a dish is not
   turned over by its well;
2. an open rim (a boundary loop that winds once around the axis, along faces that face
   sideways, not a turntable's edge): the mouth is the end
   nearer to the longest one (an open vessel's only rim, or the larger of two: a scan
   open at both ends with a narrow neck and a wide open foot comes out upside down, and
   says so);
3. otherwise (a closed scan without cavity, a sherd) the wider end (larger mean radius over
   the last 10 % of the height at each end).

``flip`` reverses the result. The rule used is reported in :attr:`AxisFit.orientation`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.sparse
import scipy.sparse.csgraph

from potflat.errors import AxisNotFoundError, InvalidInputError, InvalidOptionError
from potflat.mesh._kernels.geometry import vertex_normal_sums
from potflat.mesh.distortion import weighted_percentile
from potflat.mesh.tolerances import DEGENERATE
from potflat.types import Mesh

#: Largest relative profile deviation (median |r - slice median r| / median r) of a vessel.
MAX_PROFILE_DEVIATION = 0.05
#: Largest median normal-to-meridian angle (degrees) of a vessel: fluted scans reach ~9, scans
#: with noise comparable to their edge length ~30 (the profile test is the main one).
MAX_MEDIAN_ANGLE_DEG = 35.0
#: Evidence of an axis: the scan's points in :data:`SUPPORT_SLICES` equal height slices, at
#: least this many in a typical (median) occupied slice. Fewer (a tetrahedron: one point per
#: slice) show no radius at any height, and so no rotation, whatever the fit says.
MIN_POINTS_PER_SLICE = 3
SUPPORT_SLICES = 8
#: Vertices used at most by the fits (an area-proportional, seeded subsample beyond this).
MAX_FIT_POINTS = 100_000
#: Vertices used at most by the profile polish (area-proportional, seeded subsample).
MAX_PROFILE_POINTS = 20_000
#: Huber constant (in robust standard deviations) of the IRLS refinement.
HUBER_K = 1.345
#: The axis is undetermined (a sphere: every normal passes through its centre) when the
#: second-best axis direction fits almost perfectly too (mean squared sine-distance of the
#: normal lines below this, in units of the scan's RMS size), or when all three directions
#: fit equally (eigenvalues within this relative spread).
DEGENERATE_ABS = 1e-4
DEGENERATE_SPREAD = 0.1


@dataclass(frozen=True)
class AxisFitTolerances:
    """The axis fits' numerical settings, in one place.

    Attributes
    ----------
    pinv_rcond : float
        Relative cut-off of the pseudo-inverse in the line-complex fit.
    scale_floor : float
        Smallest robust scale of the residuals (IRLS and the profile polish's Huber scale).
    converged : float
        The IRLS stops when the axis moves less than this (direction plus offset, scan units
        relative to the scan's size).
    polish_x_scale : float
        Typical size of the profile polish's four parameters (tilt and shift, radians and
        scan-size units).
    polish_diff_step : float
        Relative finite-difference step of the profile polish.
    polish_max_evaluations : int
    """

    pinv_rcond: float = 1e-10
    scale_floor: float = 1e-9
    converged: float = 1e-12
    polish_x_scale: float = 1e-3
    polish_diff_step: float = 1e-7
    polish_max_evaluations: int = 200


AXIS_FIT = AxisFitTolerances()
#: The mouth is the end where the inner wall (area facing the axis) is reached: the fraction
#: of the area facing the axis within INNER_WALL_END of the height at each end must differ
#: by at least INNER_WALL_FRACTION.
INNER_WALL_END = 0.1
INNER_WALL_FRACTION = 0.05
#: An end's inside is closed (a foot ring's by its base, a neck's by a lid, a dish's well by
#: its floor) when the area there facing along the axis within the inside's median radius is
#: at least this fraction of the disc that radius spans.
INNER_WALL_CAP = 0.5
#: An open boundary loop is a rim when the faces along it face sideways (mean |n_r|, by
#: edge length) at least this much; a flat piece's edge (a turntable) faces along the axis.
RIM_WALL = 0.25


@dataclass(frozen=True, eq=False)
class AxisFit:
    """A rotation axis with its fit quality.

    Attributes
    ----------
    point : (3,) float64
        The point of the axis at the foot: the lowest height of the mesh, so heights
        ``(x - point) . direction`` run from 0 (foot) to :attr:`height` (mouth).
    direction : (3,) float64
        Unit direction, from the foot to the mouth.
    reference : (3,) float64
        Unit vector perpendicular to ``direction`` from which angles are measured
        (counter-clockwise about ``direction``); a fixed function of ``direction``.
    height : float
        Axial extent of the mesh, scan units.
    method : str
        ``"normals"``, ``"normals+profile"``, ``"pca"``, ``"centre+opening"`` or ``"manual"``.
    orientation : str
        How the foot-to-mouth sign was chosen.
    rms_angle_deg, median_angle_deg : float
        Area-weighted RMS and median angle between normals and meridian planes, degrees.
    rms_distance : float
        Area-weighted RMS distance of normal lines to the axis, scan units.
    misfit_angle_deg : float
        Area-weighted RMS of the outer wall's normal-to-meridian angle that turns once around
        the axis within height slices (a tilted or off-centre axis), degrees.
    profile_deviation : float
        Median of ``|r - profile(h)|`` over the outer wall's vertices, divided by their
        median radius (0 for a surface of revolution; a box gives about 0.1).
    note : str
        Warning about the fit (e.g. undetermined axis), empty when none.
    mouth_guessed : bool
        The mouth was taken to be the wider end (rule 3 of the module: no inner wall or
        open rim told the ends apart), not flipped on request: the image may be upside down.
    """

    point: np.ndarray
    direction: np.ndarray
    reference: np.ndarray
    height: float
    method: str
    orientation: str
    rms_angle_deg: float
    median_angle_deg: float
    rms_distance: float
    misfit_angle_deg: float
    profile_deviation: float
    note: str = ""
    mouth_guessed: bool = False

    def cylindrical(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Height, radius and angle of ``points`` about the axis.

        Parameters
        ----------
        points : (k, 3) float64

        Returns
        -------
        h, r, theta : (k,) float64
            Height above the foot, distance to the axis, and angle in ``[0, 2 pi)``
            counter-clockwise about :attr:`direction` from :attr:`reference`.
        """
        return cylindrical(points, self.point, self.direction, self.reference)

    def as_dict(self) -> dict:
        """JSON-ready description (see ``docs/formats.md``)."""
        return {
            "point": [float(x) for x in self.point],
            "direction": [float(x) for x in self.direction],
            "reference_direction": [float(x) for x in self.reference],
            "height": float(self.height),
            "method": self.method,
            "orientation": self.orientation,
            "mouth_guessed": bool(self.mouth_guessed),
            "rms_angle_deg": float(self.rms_angle_deg),
            "median_angle_deg": float(self.median_angle_deg),
            "rms_distance": float(self.rms_distance),
            "misfit_angle_deg": float(self.misfit_angle_deg),
            "profile_deviation": float(self.profile_deviation),
            "note": self.note,
        }


def reference_direction(direction: np.ndarray) -> np.ndarray:
    """The unit vector perpendicular to ``direction`` from which angles are measured.

    It is the world axis (x, then y, then z on ties) least aligned with ``direction``,
    made perpendicular to it. Shape (3,).
    """
    d = np.asarray(direction, float)
    w = np.zeros(3)
    w[int(np.argmin(np.abs(d)))] = 1.0
    e = w - (w @ d) * d
    return e / np.linalg.norm(e)


def cylindrical(points, point, direction, reference) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Height, radius and angle ``[0, 2 pi)`` of ``points`` (k, 3) about an axis (see :meth:`AxisFit.cylindrical`)."""
    d = np.asarray(points, float) - point
    h = d @ direction
    radial = d - h[:, None] * direction
    r = np.linalg.norm(radial, axis=1)
    other = np.cross(direction, reference)
    theta = np.arctan2(radial @ other, radial @ reference) % (2.0 * np.pi)
    return h, r, theta


def normal_lines(mesh: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertex normal lines of ``mesh``: points (k, 3), unit normals (k, 3), areas (k,).

    Normals are area-weighted means of the adjacent face normals; the weight of a vertex is
    a third of the area of its faces. Vertices without area are left out. On a surface of
    revolution sampled exactly, these lines meet the axis far more closely than face normals
    through face centroids (which are tilted by the faceting).
    """

    V = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    acc, area = vertex_normal_sums(V, np.ascontiguousarray(mesh.faces, dtype=np.int64).reshape(-1, 3))
    norm = np.linalg.norm(acc, axis=1)
    ok = (norm > 0) & (area > 0)
    if ok.all():  # (the usual case: no row gathers)
        return V, acc / norm[:, None], area
    keep = np.flatnonzero(ok)
    return np.take(V, keep, axis=0), np.take(acc, keep, axis=0) / norm[keep, None], area[keep]


def _check_mesh(mesh: Mesh) -> None:
    if len(mesh.faces) == 0:
        raise InvalidInputError(f"{mesh.source or 'mesh'} has no faces; give a triangle mesh of the vessel")
    if not np.isfinite(mesh.vertices).all():
        raise InvalidInputError(f"{mesh.source or 'mesh'} has NaN or infinite vertex positions; clean the scan first")


def _sample(areas: np.ndarray, limit: int) -> np.ndarray:
    """Indices of at most ``limit`` items with positive area; area-proportional and seeded beyond it."""
    ok = np.flatnonzero(areas > 0)
    if len(ok) <= limit:
        return ok
    rng = np.random.default_rng(0)
    return np.sort(rng.choice(ok, size=limit, replace=False, p=areas[ok] / areas[ok].sum()))


def _line_complex_fit(c: np.ndarray, n: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weighted line closest to all normal lines (c_i, n_i), in Pluecker coordinates.

    Minimises ``sum w_i (a . (c_i x n_i) + n_i . m)^2`` over unit ``a`` and moment ``m``.
    Returns the direction ``a`` (3,), a point of the axis (3,), and the eigenvalues (3,) of
    the reduced problem (ascending) that show whether the axis is determined.
    """
    mom = np.cross(c, n)
    wn = n * w[:, None]
    A = (mom * w[:, None]).T @ mom
    B = (mom * w[:, None]).T @ n
    N = wn.T @ n
    N_pinv = np.linalg.pinv(N, rcond=AXIS_FIT.pinv_rcond, hermitian=True)
    S = A - B @ N_pinv @ B.T
    S = 0.5 * (S + S.T)
    evals, evecs = np.linalg.eigh(S)
    a = evecs[:, 0]
    m = -N_pinv @ B.T @ a
    return a, np.cross(a, m), evals


def _meridian_residuals(c, n, point, direction):
    """sin of the angle between each normal and its meridian plane, radius of each centre, and the triple product."""
    d = c - point
    axial = np.cross(direction, d)
    r = np.linalg.norm(axial, axis=1)
    det = np.einsum("ij,ij->i", n, axial)
    return det, r


def axis_residuals(mesh: Mesh, point, direction, *, lines=None) -> tuple[float, float, float, float, float]:
    """Fit-quality figures of an axis on ``mesh`` (see module docs).

    Parameters
    ----------
    mesh : Mesh
    point, direction : (3,) float64
        A point of the axis and its direction (normalised here).
    lines : tuple, optional
        ``normal_lines(mesh)`` if already computed.

    Returns
    -------
    rms_angle_deg, median_angle_deg, rms_distance, misfit_angle_deg, profile_deviation : float
    """
    c, n, area = normal_lines(mesh) if lines is None else lines
    direction = np.asarray(direction, float) / np.linalg.norm(direction)
    det, r = _meridian_residuals(c, n, np.asarray(point, float), direction)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(r > 0, np.abs(det) / r, 0.0)
    ang = np.degrees(np.arcsin(np.clip(s, 0.0, 1.0)))
    w = area / area.sum()
    sin_axis = np.linalg.norm(np.cross(n, direction), axis=1)
    far = sin_axis > np.sin(np.radians(10.0))
    if far.any():
        dist = np.abs(det[far]) / sin_axis[far]
        rms_dist = float(np.sqrt(np.average(dist**2, weights=area[far])))
    else:
        rms_dist = 0.0
    # the profile of the outer wall (normals facing away from the axis): an inner wall
    # would make the radius two-valued
    hc = (c - point) @ direction
    radial = c - point - hc[:, None] * direction
    outer = np.einsum("ij,ij->i", n, radial) > 0.3 * np.linalg.norm(radial, axis=1)
    wall = np.flatnonzero(outer) if outer.sum() >= 20 else np.arange(len(c))
    prof = _profile_deviation(np.take(c, wall, axis=0), point, direction)
    with np.errstate(invalid="ignore", divide="ignore"):
        lean = np.where(r > 0, det / r, 0.0)
    misfit = _once_around(np.clip(lean[wall], -1.0, 1.0), hc[wall], np.take(radial, wall, axis=0), area[wall],
                          direction)
    return float(np.sqrt(np.sum(w * ang**2))), weighted_percentile(ang, w, 50.0), rms_dist, misfit, prof


def _once_around(lean: np.ndarray, h: np.ndarray, radial: np.ndarray, area: np.ndarray, direction,
                 *, slices: int = 32) -> float:
    """Area-weighted RMS, in degrees, of the part of the signed lean ``lean`` (k,) (sine of the
    normal-to-meridian angle) that turns once around the axis: in each of ``slices`` height
    slices of ``h`` (k,), the weighted least-squares fit ``a + b cos(theta) + c sin(theta)``
    of ``lean`` over the points' angles ``theta`` (from their ``radial`` (k, 3) offsets),
    taken without ``a``. A slice whose angles do not determine the fit (fewer than 10
    points, or all on one side) adds nothing."""
    if len(lean) == 0:
        return 0.0
    ref = reference_direction(direction)
    theta = np.arctan2(radial @ np.cross(direction, ref), radial @ ref)
    cos, sin = np.cos(theta), np.sin(theta)
    lo, hi = float(h.min()), float(h.max())
    idx = np.clip(((h - lo) / max(hi - lo, 1e-300) * slices).astype(np.int64), 0, slices - 1)
    basis = (np.ones_like(cos), cos, sin)
    normal = np.empty((slices, 3, 3))
    rhs = np.empty((slices, 3))
    for i in range(3):
        rhs[:, i] = np.bincount(idx, area * basis[i] * lean, slices)
        for j in range(i, 3):
            normal[:, i, j] = normal[:, j, i] = np.bincount(idx, area * basis[i] * basis[j], slices)
    count = np.bincount(idx, minlength=slices)
    coef = np.zeros((slices, 3))
    for k in np.flatnonzero(count >= 10):
        # (a slice with all its points on one side leaves the harmonic undetermined)
        if np.linalg.cond(normal[k]) < 1e8:
            coef[k] = np.linalg.solve(normal[k], rhs[k])
    part = coef[idx, 1] * cos + coef[idx, 2] * sin
    rms = float(np.sqrt(np.sum(area * part * part) / max(float(area.sum()), 1e-300)))
    return float(np.degrees(np.arcsin(min(rms, 1.0))))


def _profile_deviation(points: np.ndarray, point, direction, *, slices: int = 32) -> float:
    """Median ``|r - profile(h)|`` over ``points`` divided by their median radius.

    The profile interpolates linearly between the slices' median radii (at the slices'
    mean heights), so a sloped or curved profile gives (nearly) 0, as a surface of
    revolution should.
    """
    h = (points - point) @ direction
    r = np.linalg.norm(points - point - h[:, None] * direction, axis=1)
    lo, hi = h.min(), h.max()
    idx = np.clip(((h - lo) / max(hi - lo, 1e-300) * slices).astype(np.int64), 0, slices - 1)
    # the lower median radius of each slice: its radii grouped (a radix sort of the slice
    # numbers) and partitioned, not all sorted
    count = np.bincount(idx, minlength=slices)
    grouped = r[np.argsort(idx.astype(np.int16), kind="stable")]
    have = count > 0
    med = np.array([np.partition(grouped[s:s + c], (c - 1) // 2)[(c - 1) // 2]
                    for s, c in zip(np.cumsum(count) - count, count) if c])
    count = count[have]
    mean_h = np.bincount(idx, h, slices)[have] / count
    scale = float(np.median(r))
    if scale <= 0:
        return 0.0
    return float(np.median(np.abs(r - np.interp(h, mean_h, med))) / scale)


def _irls(c, n, area, point, direction, *, iterations: int = 40):
    """Huber-IRLS on the angle between normals and meridian planes, starting from an axis."""
    scale = None
    for _ in range(iterations):
        det, r = _meridian_residuals(c, n, point, direction)
        r_floor = 0.05 * np.median(r) + 1e-300
        s = det / np.maximum(r, r_floor)
        sigma = 1.4826 * np.median(np.abs(s))
        scale = max(sigma, AXIS_FIT.scale_floor)
        huber = np.minimum(1.0, HUBER_K * scale / np.maximum(np.abs(s), 1e-300))
        w = area * huber / np.maximum(r, r_floor) ** 2
        new_dir, new_point, _ = _line_complex_fit(c, n, w / w.sum())
        if new_dir @ direction < 0:
            new_dir = -new_dir
        change = np.linalg.norm(new_dir - direction) + np.linalg.norm(
            np.cross(new_point - point, new_dir))
        direction, point = new_dir, new_point
        if change < AXIS_FIT.converged:
            break
    return point, direction


def _profile_refine(vertices: np.ndarray, weights: np.ndarray, point, direction, *, slices: int = 64):
    """Polish the axis by making the radius constant within height slices (Huber loss).

    The radius of every vertex is compared with the profile (mean radius of its height
    slice, interpolated linearly between slice centres); the four parameters are the tilt
    of the direction and the shift of the point perpendicular to it.
    """
    e1 = reference_direction(direction)
    e2 = np.cross(direction, e1)
    h0 = (vertices - point) @ direction
    lo, hi = h0.min(), h0.max()
    if not hi > lo:
        return point, direction
    r0 = np.linalg.norm(vertices - point - h0[:, None] * direction, axis=1)
    size = float(np.sqrt(np.average(r0**2, weights=weights))) or 1.0
    edges = np.linspace(lo, hi, slices + 1)
    sw = np.sqrt(weights / weights.sum() * len(weights))

    def geometry(x):
        d = direction + x[0] * e1 + x[1] * e2
        d = d / np.linalg.norm(d)
        p = point + size * (x[2] * e1 + x[3] * e2)
        return p, d

    def residual(x):
        p, d = geometry(x)
        rel = vertices - p
        h = rel @ d
        r = np.linalg.norm(rel - h[:, None] * d, axis=1)
        idx = np.clip(np.searchsorted(edges, h) - 1, 0, slices - 1)
        wsum = np.bincount(idx, weights, slices)
        have = wsum > 0
        mean_r = np.bincount(idx, weights * r, slices)[have] / wsum[have]
        mean_h = np.bincount(idx, weights * h, slices)[have] / wsum[have]
        prof = np.interp(h, mean_h, mean_r)
        return sw * (r - prof) / size

    start = residual(np.zeros(4))
    f_scale = max(HUBER_K * 1.4826 * float(np.median(np.abs(start))), AXIS_FIT.scale_floor)
    sol = scipy.optimize.least_squares(residual, np.zeros(4), loss="huber", f_scale=f_scale,
                                       x_scale=np.full(4, AXIS_FIT.polish_x_scale),
                                       diff_step=AXIS_FIT.polish_diff_step, max_nfev=AXIS_FIT.polish_max_evaluations)
    return geometry(sol.x)


def _pca_axis(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The principal direction whose variance is most isolated from the other two, through the centroid."""
    centre = vertices.mean(axis=0)
    evals, evecs = np.linalg.eigh(np.cov((vertices - centre).T))
    gaps = [abs(evals[0] - evals[1]) / max(evals[2], 1e-300),
            0.0, abs(evals[2] - evals[1]) / max(evals[2], 1e-300)]
    k = int(np.argmax(gaps))
    return centre, evecs[:, k]


def _boundary_loops(mesh: Mesh, *, faces: bool = False) -> list:
    """Directed boundary edges (k, 2) grouped by connected boundary component (with
    ``faces``: pairs of those and the (k,) face of each edge)."""
    F = mesh.faces
    half = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    n = len(mesh.vertices)
    key = np.minimum(half[:, 0], half[:, 1]) * n + np.maximum(half[:, 0], half[:, 1])
    order = np.argsort(key, kind="stable")
    k = key[order]
    single = np.ones(len(k), bool)  # an edge used by one face only (np.unique is slow here)
    same = k[1:] == k[:-1]
    single[1:] &= ~same
    single[:-1] &= ~same
    on = order[single]
    bnd = half[on]
    if len(bnd) == 0:
        return []
    g = scipy.sparse.coo_matrix((np.ones(len(bnd)), (bnd[:, 0], bnd[:, 1])), shape=(n, n))
    _, labels = scipy.sparse.csgraph.connected_components(g, directed=False)
    lab = labels[bnd[:, 0]]
    order = np.argsort(lab, kind="stable")
    splits = np.flatnonzero(np.diff(lab[order])) + 1
    if faces:
        face = on % len(F)
        return [(bnd[idx], face[idx]) for idx in np.split(order, splits)]
    return [bnd[idx] for idx in np.split(order, splits)]


def orient(mesh: Mesh, point, direction, *, lines=None) -> tuple[np.ndarray, str, bool]:
    """Sign of the axis direction from foot to mouth (see module docs for the rule).

    Returns
    -------
    direction : (3,) float64
        ``direction`` or its opposite.
    reason : str
        The rule that decided.
    guessed : bool
        Whether only the wider end decided (rule 3).
    """
    direction = np.asarray(direction, float)
    ref = reference_direction(direction)
    h, r, theta_all = cylindrical(mesh.vertices, point, direction, ref)
    used = _used(mesh)
    h, r = h[used], r[used]
    lo, hi = h.min(), h.max()
    mid = 0.5 * (lo + hi)
    rims = []
    for loop, face in _boundary_loops(mesh, faces=True):
        dth = theta_all[loop[:, 1]] - theta_all[loop[:, 0]]
        dth = (dth + np.pi) % (2 * np.pi) - np.pi
        if abs(round(dth.sum() / (2 * np.pi))) < 1:
            continue
        seg = mesh.vertices[loop[:, 1]] - mesh.vertices[loop[:, 0]]
        edge = np.linalg.norm(seg, axis=1)
        length = float(edge.sum())
        # the edge of a flat piece across the axis (a turntable or ground plane) is no rim
        corner = mesh.vertices[mesh.faces[face]]
        normal = np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0])
        out = corner.mean(axis=1) - point
        out -= (out @ direction)[:, None] * direction
        sideways = np.abs(np.einsum("ij,ij->i", normal, out)) / np.maximum(
            np.linalg.norm(normal, axis=1) * np.linalg.norm(out, axis=1), np.finfo(float).tiny)
        if float(np.sum(edge * sideways)) < RIM_WALL * length:
            continue
        h_loop = float(np.mean((mesh.vertices[loop].reshape(-1, 3) - point) @ direction))
        rims.append((length, h_loop))
    best = max(rims) if rims else None
    c, n, area = normal_lines(mesh) if lines is None else lines
    hc = (c - point) @ direction
    radial = c - point - hc[:, None] * direction
    n_r = np.einsum("ij,ij->i", n, radial)
    distance = np.linalg.norm(radial, axis=1)
    facing_axis = n_r < -0.5 * distance
    n_a = n @ direction
    # the inner wall shows from the mouth down: it reaches the mouth's end of the vessel,
    # not the foot's (a two-sided sherd has it at both ends, a closed jar at neither). An
    # inside closed across by a surface facing along the axis (out: a base under a foot ring,
    # a lid in a neck; in: the floor of a dish scanned from above alone) is no open mouth:
    # its end does not count
    band = INNER_WALL_END * (hi - lo)
    ends, closed = [], []
    for sel in (hc <= lo + band, hc >= hi - band):
        total = area[sel].sum()
        inside = sel & facing_axis
        share = area[inside].sum() / total if total > 0 else 0.0
        shut = False
        if share > 0:
            r_in = float(np.median(distance[inside]))
            cap = sel & (np.abs(n_a) > 0.5) & (distance < r_in)
            shut = area[cap].sum() >= INNER_WALL_CAP * np.pi * r_in ** 2
        ends.append(0.0 if shut else share)
        closed.append(shut)
    guessed = False
    if abs(ends[1] - ends[0]) >= INNER_WALL_FRACTION:
        up = ends[1] > ends[0]
        reason = (f"mouth at the end the inner wall reaches ({100 * max(ends):.0f} % of the area there "
                  f"faces the axis, {100 * min(ends):.0f} % at the other end"
                  + (", whose inside a floor, base or lid closes)" if closed[0 if up else 1] else ")"))
    elif best is not None:
        up = best[1] >= mid
        reason = f"mouth at the longest open rim ({best[0]:.4g} units around)"
        other = [length for length, h_loop in rims if (h_loop >= mid) != up]
        if other:
            reason += (f"; the other end is open too ({max(other):.4g} units around): "
                       "use flip if the vessel is upside down")
    else:
        band = 0.1 * (hi - lo)
        top, bottom = r[h >= hi - band], r[h <= lo + band]
        up = top.mean() >= bottom.mean()
        reason = "no inner wall or open rim found: mouth assumed at the wider end; use flip to reverse"
        guessed = True
    return (direction if up else -direction), reason, guessed


def _finish(mesh, point, direction, *, method, orientation, flip, note="", lines=None,
            residuals: tuple[float, float, float, float, float] | None = None, guessed: bool = False) -> AxisFit:
    """The :class:`AxisFit` of an axis line; ``residuals``: its :func:`axis_residuals` when the
    caller has them (they do not depend on the point along the line or the direction's sign)."""
    direction = np.asarray(direction, float)
    direction = direction / np.linalg.norm(direction)
    if flip:
        direction = -direction
        orientation += "; flipped on request"
    h = (mesh.vertices[_used(mesh)] - point) @ direction
    foot = np.asarray(point, float) + h.min() * direction
    rms_angle, median_angle, rms_dist, misfit, prof = (axis_residuals(mesh, foot, direction, lines=lines)
                                                       if residuals is None else residuals)
    return AxisFit(point=foot, direction=direction, reference=reference_direction(direction),
                   height=float(h.max() - h.min()), method=method, orientation=orientation,
                   rms_angle_deg=rms_angle, median_angle_deg=median_angle, rms_distance=rms_dist,
                   misfit_angle_deg=misfit, profile_deviation=prof, note=note, mouth_guessed=guessed and not flip)


def manual_axis(mesh: Mesh, point, direction, *, flip: bool = False) -> AxisFit:
    """An axis given by the user, with its fit-quality figures measured on ``mesh``.

    Parameters
    ----------
    mesh : Mesh
    point : (3,) float64
        Any point of the axis, scan coordinates.
    direction : (3,) float64
        Its direction, from the foot to the mouth (need not be unit length).
    flip : bool
        Reverse the direction.

    Returns
    -------
    AxisFit
        With ``method="manual"``.
    """
    _check_mesh(mesh)
    point = np.asarray(point, float)
    direction = np.asarray(direction, float)
    if point.shape != (3,) or direction.shape != (3,) or not (
            np.isfinite(point).all() and np.isfinite(direction).all()):
        raise InvalidOptionError("axis needs 6 finite numbers: px,py,pz,dx,dy,dz")
    if np.linalg.norm(direction) == 0:
        raise InvalidOptionError("axis direction is zero; give dx,dy,dz not all 0")
    return _finish(mesh, point, direction, method="manual", orientation="as given", flip=flip)


def estimate_axis(mesh: Mesh, *, flip: bool = False, profile: bool = True,
                  max_median_angle_deg: float = MAX_MEDIAN_ANGLE_DEG) -> AxisFit:
    """Estimate the rotation axis of ``mesh`` without any prior alignment.

    Parameters
    ----------
    mesh : Mesh
        The scan (faces oriented consistently; a sherd or a holed scan works too).
    flip : bool
        Reverse the foot-to-mouth direction found.
    profile : bool
        Polish the normal-line fit by profile consistency on the outer wall (kept unless
        it worsens the median normal angle by more than 2 %).
    max_median_angle_deg : float
        Refuse axes whose median normal-to-meridian angle exceeds this.

    Returns
    -------
    AxisFit

    Raises
    ------
    AxisNotFoundError
        When no axis fits (the shape is not a surface of revolution).
    """
    _check_mesh(mesh)
    lines = normal_lines(mesh)
    c, n, area = lines
    idx = _sample(area, MAX_FIT_POINTS)
    if len(idx) < 3:
        raise InvalidInputError(f"{mesh.source or 'mesh'} has fewer than 3 vertices with area; give a real scan")
    c, n, area = c[idx], n[idx], area[idx]
    centre = np.average(c, axis=0, weights=area)
    size = float(np.sqrt(np.average(np.sum((c - centre) ** 2, axis=1), weights=area))) or 1.0
    cs = (c - centre) / size
    w = area / area.sum()
    direction, point, evals = _line_complex_fit(cs, n, w)
    note = ""
    method = "normals"
    if evals[1] <= DEGENERATE_ABS or evals[2] - evals[0] <= DEGENERATE_SPREAD * evals[2]:
        # every normal passes through (nearly) one point: a sphere. The axis through the
        # centre and the largest opening, or PCA, is as good as any: say so.
        centre_pt = _closest_point_to_lines(cs, n, w)
        loops = _boundary_loops(mesh)
        if loops:
            longest = max(loops, key=lambda lp: np.linalg.norm(
                mesh.vertices[lp[:, 1]] - mesh.vertices[lp[:, 0]], axis=1).sum())
            ring = (mesh.vertices[longest].reshape(-1, 3) - centre) / size
            ring_centre = ring.mean(axis=0)
            direction = np.linalg.eigh(np.cov((ring - ring_centre).T))[1][:, 0]  # plane normal
            if direction @ (ring_centre - centre_pt) < 0:
                direction = -direction
            method = "centre+opening"
        else:
            _, direction = _pca_axis(cs)
            method = "pca"
        direction = direction / np.linalg.norm(direction)
        point = centre_pt
        note = ("axis undetermined: the normals all pass through one point (sphere-like shape); "
                "give --axis px,py,pz,dx,dy,dz to choose it")
    else:
        point, direction = _irls(cs, n, area, point, direction)
        if profile:
            # the outer wall only (normals facing away from the axis): an inner wall would
            # make the radius two-valued within a slice
            h0 = (cs - point) @ direction
            radial = cs - point - h0[:, None] * direction
            outer = np.flatnonzero(np.einsum("ij,ij->i", n, radial) > 0.3 * np.linalg.norm(radial, axis=1))
            pick = outer[_sample(area[outer], MAX_PROFILE_POINTS)]
            weights = area[pick] if len(pick) == len(outer) else np.ones(len(pick))
            if len(pick) >= 20:
                p2, d2 = _profile_refine(cs[pick], weights, point, direction)
                # kept unless the normals disagree (outliers the profile followed)
                if _median_sin(cs, n, area, p2, d2) <= 1.02 * _median_sin(cs, n, area, point, direction) + DEGENERATE:
                    point, direction, method = p2, d2, "normals+profile"
    point = centre + size * point
    _check_support(mesh, lines[0], point, direction)
    residuals = axis_residuals(mesh, point, direction, lines=lines)
    rms_angle, median_angle, _, _, prof = residuals
    if _unsymmetric(median_angle, prof, max_median_angle_deg):
        pc, pdir = _pca_axis(mesh.vertices[_used(mesh)])
        pca_residuals = axis_residuals(mesh, pc, pdir, lines=lines)
        _, p_median, _, _, p_prof = pca_residuals
        if not _unsymmetric(p_median, p_prof, max_median_angle_deg):
            point, direction, method, residuals = pc, pdir, "pca", pca_residuals
        else:
            raise AxisNotFoundError(
                f"{mesh.source or 'the scan'} is not rotationally symmetric enough to find its axis "
                f"(radius varies by {100 * prof:.1f} % within height slices, limit "
                f"{100 * MAX_PROFILE_DEVIATION:g} %; median normal-to-meridian angle "
                f"{median_angle:.1f} deg, RMS {rms_angle:.1f} deg); give --axis px,py,pz,dx,dy,dz")
    direction, orientation, guessed = orient(mesh, point, direction, lines=lines)
    return _finish(mesh, point, direction, method=method, orientation=orientation, flip=flip, note=note,
                   lines=lines, residuals=residuals, guessed=guessed)


def _check_support(mesh: Mesh, points: np.ndarray, point, direction) -> None:
    """Refuse an axis that too few points of the scan show (:data:`MIN_POINTS_PER_SLICE`)."""
    h = (points - point) @ direction
    lo, hi = float(h.min()), float(h.max())
    idx = np.clip(((h - lo) / max(hi - lo, 1e-300) * SUPPORT_SLICES).astype(np.int64), 0, SUPPORT_SLICES - 1)
    count = np.bincount(idx, minlength=SUPPORT_SLICES)
    typical = float(np.median(count[count > 0]))
    if typical < MIN_POINTS_PER_SLICE:
        raise AxisNotFoundError(
            f"{mesh.source or 'the scan'} is no vessel to unroll: {len(points)} points with {len(mesh.faces)} faces, "
            f"{typical:g} at a typical height (at least {MIN_POINTS_PER_SLICE} show a radius there); give the "
            "scan of a vessel or a sherd, or its axis with --axis px,py,pz,dx,dy,dz")


def _used(mesh: Mesh) -> np.ndarray:
    """Mask of the vertices referenced by a face. Shape (n,) bool."""
    return np.bincount(mesh.faces.ravel(), minlength=len(mesh.vertices)) > 0


def _unsymmetric(median_angle: float, profile_deviation: float, max_median_angle_deg: float) -> bool:
    return profile_deviation > MAX_PROFILE_DEVIATION or median_angle > max_median_angle_deg


def _median_sin(c, n, area, point, direction) -> float:
    """Area-weighted median sine of the normal-to-meridian angle (normalised coordinates)."""
    det, r = _meridian_residuals(c, n, point, direction)
    return weighted_percentile(np.abs(det) / np.maximum(r, 0.05 * np.median(r) + 1e-300), area, 50.0)


def _closest_point_to_lines(c: np.ndarray, n: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted least-squares point closest to the lines (c_i, n_i). Shape (3,)."""
    P = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
    M = np.einsum("i,ijk->jk", w, P)
    b = np.einsum("i,ijk,ik->j", w, P, c)
    return np.linalg.lstsq(M, b, rcond=None)[0]
