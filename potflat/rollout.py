"""Stage 1, rollout: find the axis, select the region, cut a seam and unroll on a proxy.

``rollout(mesh)`` returns a :class:`RolloutResult` whose :attr:`~RolloutResult.flat` is a
disk-topology mesh covering every selected face, with seam vertices duplicated (one copy per
side) and no triangle deleted or altered. ``run_rollout_stage(scan, out_dir)`` reads a scan
and writes ``NAME.rollout.ply`` and ``NAME.rollout.json`` (see ``docs/formats.md``).

Angles: the reference direction of the axis (:attr:`AxisFit.reference`) is 0 degrees; the
seam angle is measured from it counter-clockwise about the axis (axis pointing up). Angles
of the region (``angles``) and of the output (``u = R theta`` on a cylinder) are measured
from the seam. A region that does not go all the way round (a sherd, a frieze, a scan
with a gap from foot to rim) needs no cut.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph

from potflat import proxy as _proxy
from potflat.axis import AxisFit, estimate_axis, manual_axis
from potflat.distortion import DistortionSummary, summarize
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.types import UNITS_MM, FlatMesh, Mesh, StageOutput

TWO_PI = 2.0 * np.pi
#: Angular bins (per turn) used to choose the seam and to find gaps in a region.
SEAM_BINS = 360
#: Width (bins) of the circular moving average applied to the seam cost.
SEAM_SMOOTH = 5


@dataclass(frozen=True, kw_only=True)
class RolloutOptions:
    """Options of the rollout stage (names equal the CLI options, ``_`` for ``-``).

    Attributes
    ----------
    units : str or None
        Length unit of the scan file (``mm``, ``cm``, ``m``, ``um``, ``in``); None: the unit
        the file declares (a PLY ``comment units``, an STL header, glTF's metres), else mm.
        Used when reading the file; :func:`rollout` itself uses :attr:`Mesh.units`.
    texture : bool
        Use the scan's texture image; False loads the geometry (and vertex colours) only,
        e.g. when the texture file is missing or corrupt. Used when reading the file.
    proxy : str
        ``auto``, ``cylinder``, ``cone``, ``sphere`` or ``ortho``.
    axis : tuple of 6 float or None
        Manual axis ``(px, py, pz, dx, dy, dz)``: a point and a direction from foot to mouth.
    flip : bool
        Reverse the axis direction (mouth and foot swapped).
    seam : float or None
        Seam angle in degrees from the axis' reference direction; chosen automatically when
        None (0 when ``angles`` is given).
    band : (float, float) or None
        Height band as fractions of the axial extent, 0 = foot, 1 = mouth.
    angles : (float, float) or None
        Angle range in degrees relative to the seam, e.g. ``(-60, 60)``; at most 360 wide.
    view : tuple of 3 float or None
        For ``proxy="ortho"``: direction from the vessel to the viewer (``x,y,z``, scan
        coordinates); default: from the axis towards the region's centre.
    """

    units: str | None = None
    texture: bool = True
    proxy: str = "auto"
    axis: tuple[float, ...] | None = None
    flip: bool = False
    seam: float | None = None
    band: tuple[float, float] | None = None
    angles: tuple[float, float] | None = None
    view: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.units is not None and self.units not in UNITS_MM:
            raise InvalidOptionError(f"units {self.units!r} is unknown; use one of {', '.join(UNITS_MM)}")
        if not isinstance(self.texture, bool):
            raise InvalidOptionError(f"texture must be true or false, got {self.texture!r}")
        if self.proxy not in ("auto", *_proxy.KINDS):
            raise InvalidOptionError(
                f"proxy {self.proxy!r} is unknown; use auto, {', '.join(_proxy.KINDS)}")
        if self.axis is not None:
            ax = _floats("axis", self.axis, 6, "px,py,pz,dx,dy,dz")
            if not any(ax[3:]):
                raise InvalidOptionError("axis direction is zero; give dx,dy,dz not all 0")
            object.__setattr__(self, "axis", ax)
        if self.seam is not None:
            object.__setattr__(self, "seam", _floats("seam", (self.seam,), 1, "DEG")[0])
        if self.band is not None:
            lo, hi = _floats("band", self.band, 2, "LO HI")
            if not 0.0 <= lo < hi <= 1.0:
                raise InvalidOptionError(
                    f"band {lo:g} {hi:g} is invalid; give fractions of the height with 0 <= LO < HI <= 1")
            object.__setattr__(self, "band", (lo, hi))
        if self.angles is not None:
            a0, a1 = _floats("angles", self.angles, 2, "A0 A1")
            if not a0 < a1 <= a0 + 360.0:
                raise InvalidOptionError(
                    f"angles {a0:g} {a1:g} are invalid; give A0 < A1 <= A0 + 360 (degrees from the seam)")
            object.__setattr__(self, "angles", (a0, a1))
        if self.view is not None:
            view = _floats("view", self.view, 3, "x,y,z")
            if not any(view):
                raise InvalidOptionError("view direction is zero; give x,y,z not all 0")
            if self.proxy != "ortho":
                raise InvalidOptionError("view applies only to proxy ortho; add --proxy ortho or drop --view")
            object.__setattr__(self, "view", view)

    def as_dict(self) -> dict:
        """The options as a JSON-ready dict."""
        return {f.name: (list(v) if isinstance(v := getattr(self, f.name), tuple) else v)
                for f in fields(self)}


def _floats(name: str, values, count: int, form: str) -> tuple[float, ...]:
    try:
        out = tuple(float(x) for x in values)
    except (TypeError, ValueError):
        raise InvalidOptionError(f"{name} needs {count} numbers ({form})") from None
    if len(out) != count or not all(math.isfinite(x) for x in out):
        raise InvalidOptionError(f"{name} needs {count} finite numbers ({form}), got {len(out)}")
    return out


@dataclass(frozen=True)
class Region:
    """The part of the scan that was unrolled.

    Attributes
    ----------
    band : (float, float)
        Height band, fractions of the axial extent (0 = foot, 1 = mouth).
    angles_deg : (float, float) or None
        Requested angle range from the seam, degrees.
    height_range : (float, float)
        Heights above the foot covered by the selected faces, scan units.
    theta_range_deg : (float, float)
        Angles from the seam covered by the output vertices, degrees.
    faces, faces_total : int
        Faces selected, faces in the scan.
    cut : bool
        Whether the region went all the way round and had to be cut open.
    """

    band: tuple[float, float]
    angles_deg: tuple[float, float] | None
    height_range: tuple[float, float]
    theta_range_deg: tuple[float, float]
    faces: int
    faces_total: int
    cut: bool

    def as_dict(self) -> dict:
        """JSON-ready description."""
        d = asdict(self)
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in d.items()}


@dataclass(frozen=True, eq=False)
class RolloutResult:
    """The rollout of a scan.

    Attributes
    ----------
    flat : FlatMesh
        The cut region with its flattened ``uv`` (scan units).
    axis : AxisFit
        Axis used, with its fit quality.
    proxy : Proxy
        Proxy used, its parameters, the candidates' figures and the reason.
    seam_angle : float
        Seam angle in degrees from the axis' reference direction, in ``[0, 360)``.
    seam_method : str
        How the seam was chosen (``user``, ``texture``, ``colours``, ``geometry``, ``gap``).
    region : Region
        What was selected.
    distortion : DistortionSummary
        Distortion of the rollout.
    face_index : (m_out,) int64
        Input face of each output face.
    vertex_index : (n_out,) int64
        Input vertex of each output vertex.
    seam_vertices : int
        Vertex copies added by the cut (each seam vertex once more).
    split_vertices : int
        Vertex copies added where the input was not manifold (a vertex whose faces form
        separate fans becomes one vertex per fan).
    """

    flat: FlatMesh
    axis: AxisFit
    proxy: _proxy.Proxy
    seam_angle: float
    seam_method: str
    region: Region
    distortion: DistortionSummary
    face_index: np.ndarray
    vertex_index: np.ndarray
    seam_vertices: int
    split_vertices: int


def _wrap_pi(x: np.ndarray) -> np.ndarray:
    return (x + np.pi) % TWO_PI - np.pi


def _luminance_variation(mesh: Mesh, faces: np.ndarray) -> tuple[np.ndarray | None, str]:
    """Per-face spread of brightness (std of samples at its corners), and its source."""
    if mesh.texcoords is not None and mesh.texture_path is not None:
        import cv2

        img = cv2.imread(str(mesh.texture_path), cv2.IMREAD_REDUCED_GRAYSCALE_4)
        if img is not None and img.size:
            tc = mesh.texcoords[faces]
            pts = np.concatenate([tc, tc.mean(axis=1, keepdims=True)], axis=1) % 1.0
            hgt, wid = img.shape[:2]
            col = np.minimum((pts[..., 0] * wid).astype(np.int64), wid - 1)
            row = np.minimum(((1.0 - pts[..., 1]) * hgt).astype(np.int64), hgt - 1)
            return img[row, col].astype(np.float64).std(axis=1), "texture"
    if mesh.vertex_colors is not None:
        rgb = mesh.vertex_colors[:, :3].astype(np.float64)
        lum = rgb @ np.array([0.299, 0.587, 0.114])
        return lum[mesh.faces[faces]].std(axis=1), "colours"
    return None, "geometry"


def _longest_min_run(cost: np.ndarray) -> int:
    """Index of the middle of the longest circular run of (near-)minimal bins."""
    low = cost <= cost.min() + 1e-9 * max(cost.max(), 1e-300)
    if low.all():
        return 0
    k = len(cost)
    start = int(np.argmin(low))  # a non-minimal bin: runs do not wrap past it
    rolled = np.roll(low, -start)
    best_len, best_mid, run = 0, 0, 0
    for i in range(k + 1):
        if i < k and rolled[i]:
            run += 1
            continue
        if run > best_len:
            best_len, best_mid = run, (i - run + (run - 1) / 2.0)
        run = 0
    return int(round(start + best_mid)) % k


def choose_seam(mesh: Mesh, faces: np.ndarray, theta_c: np.ndarray, area: np.ndarray,
                covered: np.ndarray | None = None) -> tuple[float, str]:
    """Seam angle (radians from the reference) where the region is least painted.

    Each face costs its area times (the spread of brightness at its corners + 10 % of the
    mean spread) when a texture or vertex colours exist, its area otherwise; the costs are
    summed per degree of angle, smoothed over :data:`SEAM_SMOOTH` degrees, and the seam goes
    to the middle of the longest run of minimal cost. When the region has an empty sector
    (no face spans it: a sherd, a scan with a gap from foot to rim) the seam goes to the
    middle of the widest one, and nothing needs to be cut.

    Parameters
    ----------
    mesh : Mesh
    faces : (k,) int64
        Indices of the region's faces.
    theta_c : (k,) float64
        Angles of their centroids, radians in ``[0, 2 pi)`` from the reference.
    area : (k,) float64
        Their areas.
    covered : (SEAM_BINS,) bool, optional
        Angle bins (from the reference) covered by the faces' angular spans.

    Returns
    -------
    angle : float
        Radians in ``[0, 2 pi)``.
    method : str
        ``texture``, ``colours``, ``geometry``, or ``gap`` when the region has an empty sector.
    """
    if covered is not None and (gap := _gap_middle(covered)) is not None:
        return gap, "gap"
    var, method = _luminance_variation(mesh, faces)
    weight = area if var is None else area * (var + 0.1 * max(float(np.average(var, weights=area)), 1e-12))
    bins = np.minimum((theta_c / TWO_PI * SEAM_BINS).astype(np.int64), SEAM_BINS - 1)
    cost = np.bincount(bins, weight, SEAM_BINS)
    kernel = np.ones(SEAM_SMOOTH) / SEAM_SMOOTH
    pad = SEAM_SMOOTH // 2
    smooth = np.convolve(np.concatenate([cost[-pad:], cost, cost[:pad]]), kernel, mode="valid")
    k = _longest_min_run(smooth)
    return (k + 0.5) / SEAM_BINS * TWO_PI, method


def cut_open(faces: np.ndarray, corner_theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """Cut a mesh where the unwrapped angles of a vertex's corners disagree.

    Corners of the same vertex stay one vertex when they are joined through shared edges
    whose faces agree on the vertex's angle (differ by less than pi); otherwise they
    become separate copies. So vertices on the seam get one copy per side, no face is
    changed, and a vertex whose faces form separate fans (a non-manifold input) becomes one
    vertex per fan.

    Parameters
    ----------
    faces : (m, 3) int64
        Faces (indices into the original vertices).
    corner_theta : (m, 3) float64
        Unwrapped angle of each face corner.

    Returns
    -------
    new_faces : (m, 3) int64
        Faces indexing the new vertices.
    vertex_index : (n_out,) int64
        Original vertex of each new vertex (sorted, so the input order is kept).
    theta : (n_out,) float64
        Angle of each new vertex.
    seam_vertices : int
        Copies made because of the angle (the cut).
    split_vertices : int
        Further copies made for separate fans.
    """
    m = len(faces)
    corner_v = faces.ravel()
    th = corner_theta.ravel()
    ia = np.arange(3 * m).reshape(m, 3)
    ib = ia[:, [1, 2, 0]]
    va, vb = faces.ravel(), faces[:, [1, 2, 0]].ravel()
    ca, cb = ia.ravel(), ib.ravel()
    swap = va > vb
    lo_v, hi_v = np.where(swap, vb, va), np.where(swap, va, vb)
    lo_c, hi_c = np.where(swap, cb, ca), np.where(swap, ca, cb)
    order = np.lexsort((hi_v, lo_v))
    lo_v, hi_v, lo_c, hi_c = lo_v[order], hi_v[order], lo_c[order], hi_c[order]
    same = (lo_v[1:] == lo_v[:-1]) & (hi_v[1:] == hi_v[:-1])
    rows, cols = [], []
    for c in (lo_c, hi_c):
        a, b = c[:-1][same], c[1:][same]
        ok = np.abs(th[a] - th[b]) < np.pi
        rows.append(a[ok])
        cols.append(b[ok])
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    graph = scipy.sparse.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * m, 3 * m))
    n_comp, labels = scipy.sparse.csgraph.connected_components(graph, directed=False)
    by_label = np.argsort(labels, kind="stable")
    starts = np.searchsorted(labels[by_label], np.arange(n_comp))
    first = by_label[starts]  # lowest corner of each component
    vertex_of = corner_v[first]
    perm = np.lexsort((first, vertex_of))
    rank = np.empty(n_comp, np.int64)
    rank[perm] = np.arange(n_comp)
    new_faces = rank[labels].reshape(m, 3)
    vertex_index = vertex_of[perm]
    theta = th[first][perm]
    base = np.count_nonzero(np.bincount(corner_v))
    # copies of one vertex made by the cut differ in angle by whole turns
    turns = np.floor(theta / TWO_PI + 0.5).astype(np.int64)
    o = np.lexsort((turns, vertex_index))
    distinct = 1 + np.count_nonzero((np.diff(vertex_index[o]) != 0) | (np.diff(turns[o]) != 0))
    seam = distinct - base
    return new_faces, vertex_index, theta, int(seam), int(n_comp - base - seam)


def rollout(mesh: Mesh, *, options: RolloutOptions | None = None, face_mask: np.ndarray | None = None,
            **option_fields) -> RolloutResult:
    """Unroll a scan: axis, region, seam cut and proxy development.

    Parameters
    ----------
    mesh : Mesh
        The scan (outward-oriented faces), e.g. ``load_scan(path).mesh``.
    options : RolloutOptions, optional
        All options; or give them as keywords (``rollout(mesh, proxy="cone")``), not both.
    face_mask : (m,) bool, optional
        Faces that may be unrolled (e.g. the outer wall from
        :func:`potflat.walls.select_wall`, without handles); the band and angles select
        within them. The axis is fitted on the whole scan and the band's fractions refer
        to the whole scan's height.
    **option_fields
        Fields of :class:`RolloutOptions`.

    Returns
    -------
    RolloutResult

    Raises
    ------
    AxisNotFoundError
        When no axis is given and the scan has no rotational symmetry.
    InvalidOptionError
        When an option is invalid or the region selects no face.
    """
    if options is None:
        options = RolloutOptions(**option_fields)
    elif option_fields:
        raise InvalidOptionError("give either options= or option keywords to rollout(), not both")
    if not isinstance(mesh, Mesh):
        raise InvalidInputError(f"rollout needs a potflat Mesh, got {type(mesh).__name__}")
    if len(mesh.faces) == 0:
        raise InvalidInputError(f"{mesh.source or 'mesh'} has no faces; give a triangle mesh of the vessel")
    if options.axis is not None:
        axis = manual_axis(mesh, options.axis[:3], options.axis[3:], flip=options.flip)
    else:
        axis = estimate_axis(mesh, flip=options.flip)

    V, F = mesh.vertices, mesh.faces
    p0, p1, p2 = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=1)
    h_c, _, theta_c = axis.cylindrical((p0 + p1 + p2) / 3.0)
    band = options.band or (0.0, 1.0)
    face_index, seam, seam_method, corner_theta = _select(
        mesh, axis, options, face_mask, band, h_c, theta_c, area)
    sub_f = F[face_index]

    if options.proxy == "ortho":  # a projection: nothing to cut
        vertex_index = np.flatnonzero(np.bincount(sub_f.ravel(), minlength=len(V)))
        new_index = np.zeros(len(V), np.int64)
        new_index[vertex_index] = np.arange(len(vertex_index))
        new_faces = new_index[sub_f]
        theta_new = np.zeros(len(vertex_index))
        theta_new[new_faces.ravel()] = corner_theta.ravel()
        n_seam = n_split = 0
    else:
        new_faces, vertex_index, theta_new, n_seam, n_split = cut_open(sub_f, corner_theta)

    cut_mesh = Mesh(
        V[vertex_index], new_faces,
        texcoords=None if mesh.texcoords is None else mesh.texcoords[face_index],
        texture_path=mesh.texture_path,
        vertex_colors=None if mesh.vertex_colors is None else mesh.vertex_colors[vertex_index],
        units=mesh.units, source=mesh.source)
    h, r, _ = axis.cylindrical(cut_mesh.vertices)
    vert_area = np.bincount(new_faces.ravel(), np.repeat(area[face_index] / 3.0, 3), len(vertex_index))

    if options.proxy == "ortho":
        view = options.view if options.view is not None else _default_view(
            axis, theta_c[face_index], area[face_index], seam)
        prox = _proxy.ortho_proxy(axis.direction, axis.reference, np.asarray(view, float))
        prox = _proxy.Proxy(prox.kind, prox.params, reason="requested (orthographic projection)")
        uv = _proxy.project_ortho(prox, cut_mesh.vertices, axis.point)
        summary = summarize(cut_mesh.vertices, uv, new_faces)
    elif options.proxy == "auto":
        prox, uv, summary = _proxy.choose(cut_mesh.vertices, new_faces, h, r, theta_new, vert_area)
    else:
        prox = _proxy.fit(options.proxy, h, r, theta_new, vert_area)
        prox = _proxy.Proxy(prox.kind, prox.params, reason="requested")
        uv = _proxy.develop(prox, h, r, theta_new)
        summary = summarize(cut_mesh.vertices, uv, new_faces)

    region = Region(
        band=tuple(band), angles_deg=options.angles,
        height_range=(float(h_c[face_index].min()), float(h_c[face_index].max())),
        theta_range_deg=(float(np.degrees(theta_new.min())), float(np.degrees(theta_new.max()))),
        faces=len(face_index), faces_total=len(F), cut=n_seam > 0)
    return RolloutResult(
        flat=FlatMesh(cut_mesh, uv), axis=axis, proxy=prox,
        seam_angle=float(math.degrees(seam) % 360.0), seam_method=seam_method, region=region,
        distortion=summary, face_index=face_index, vertex_index=vertex_index,
        seam_vertices=n_seam, split_vertices=n_split)


def _select(mesh: Mesh, axis: AxisFit, options: RolloutOptions, face_mask, band, h_c, theta_c, area):
    """Faces of the region, the seam (radians, and how it was chosen) and the corners' unwrapped angles."""
    V, F = mesh.vertices, mesh.faces
    theta_v = axis.cylindrical(V)[2]
    frac = h_c / axis.height if axis.height > 0 else np.zeros(len(F))
    keep = (frac >= band[0]) & (frac <= band[1])
    if face_mask is not None:
        face_mask = np.asarray(face_mask)
        if face_mask.dtype != bool or face_mask.shape != (len(F),):
            raise InvalidInputError(f"face_mask must be a bool array of shape ({len(F)},), got "
                                    f"{face_mask.dtype} {face_mask.shape}")
        keep &= face_mask
    if options.seam is not None:
        seam, seam_method = math.radians(options.seam % 360.0), "user"
    elif options.angles is not None:
        seam, seam_method = 0.0, "user"
    else:
        sel = np.flatnonzero(keep)
        if len(sel) == 0:
            raise InvalidOptionError(f"band {band[0]:g} {band[1]:g} selects no faces; widen it")
        corners = theta_c[sel, None] + _wrap_pi(theta_v[F[sel]] - theta_c[sel, None])
        seam, seam_method = choose_seam(mesh, sel, theta_c[sel], area[sel],
                                        _covered(theta_c[sel], corners))

    # centroid angle from the seam, in [lo, lo + 2 pi): faces are unwrapped around it
    lo = math.radians(options.angles[0]) if options.angles is not None else 0.0
    rel_c = (theta_c - seam - lo) % TWO_PI + lo
    if options.angles is not None:
        keep &= rel_c <= math.radians(options.angles[1])
    face_index = np.flatnonzero(keep)
    if len(face_index) == 0:
        raise InvalidOptionError("the band and angle range select no faces; widen --band or --angles")
    sub_f = F[face_index]
    if options.angles is None and seam_method == "user":
        # a region that does not go round is not cut: unwrap from the middle of its gap
        corners = rel_c[face_index, None] + _wrap_pi(theta_v[sub_f] - seam - rel_c[face_index, None])
        gap = _gap_middle(_covered(rel_c[face_index], corners))
        if gap is not None:
            rel_c = (theta_c - seam - gap) % TWO_PI + gap
            rel_c -= TWO_PI * np.round(np.average(rel_c[face_index], weights=area[face_index]) / TWO_PI)
    corner_theta = rel_c[face_index, None] + _wrap_pi(theta_v[sub_f] - seam - rel_c[face_index, None])
    return face_index, seam, seam_method, corner_theta


def _default_view(axis: AxisFit, theta_c: np.ndarray, area: np.ndarray, seam: float) -> np.ndarray:
    """From the axis towards the region's (area-weighted) centre angle; opposite the seam if all round."""
    s, c = area @ np.sin(theta_c), area @ np.cos(theta_c)
    angle = math.atan2(s, c) if np.hypot(s, c) >= 1e-6 * area.sum() else seam + math.pi
    other = np.cross(axis.direction, axis.reference)
    return math.cos(angle) * axis.reference + math.sin(angle) * other


def _covered(theta_c: np.ndarray, corner_theta: np.ndarray) -> np.ndarray:
    """Which of the :data:`SEAM_BINS` angle bins the faces' angular spans cover.

    Parameters
    ----------
    theta_c : (k,) float64
        Face centroid angles (radians, any origin).
    corner_theta : (k, 3) float64
        Corner angles unwrapped around ``theta_c`` (same origin).

    Returns
    -------
    (SEAM_BINS,) bool
        Bin ``i`` covers ``[i, i + 1)`` turns / SEAM_BINS from the origin. Faces spanning
        half a turn or more (around the axis itself) are ignored.
    """
    lo, hi = corner_theta.min(axis=1), corner_theta.max(axis=1)
    narrow = hi - lo < np.pi
    b0 = np.floor(lo[narrow] / TWO_PI * SEAM_BINS).astype(np.int64)
    b1 = np.floor(hi[narrow] / TWO_PI * SEAM_BINS).astype(np.int64) + 1
    s0, s1 = b0 % SEAM_BINS, b1 % SEAM_BINS
    delta = np.bincount(s0, minlength=SEAM_BINS) - np.bincount(s1, minlength=SEAM_BINS)
    delta[0] += np.count_nonzero(s1 <= s0)
    return np.cumsum(delta)[:SEAM_BINS] > 0


def _gap_middle(covered: np.ndarray) -> float | None:
    """Middle (radians from the bins' origin) of the longest uncovered sector, None if all covered."""
    if covered.all():
        return None
    return (_longest_min_run(covered.astype(np.float64)) + 0.5) / SEAM_BINS * TWO_PI


def rollout_summary(result: RolloutResult) -> dict:
    """The JSON-ready figures of a rollout (the sidecar without file and provenance fields)."""
    mesh = result.flat.mesh
    return {
        "units": mesh.units,
        "mm_per_unit": mesh.mm_per_unit,
        "axis": result.axis.as_dict(),
        "proxy": result.proxy.as_dict(),
        "seam": {"angle_deg": result.seam_angle, "method": result.seam_method, "cut": result.region.cut},
        "region": result.region.as_dict(),
        "counts": {
            "vertices": len(mesh.vertices), "faces": len(mesh.faces),
            "input_faces": result.region.faces_total,
            "input_vertices_used": int(len(result.vertex_index) - result.seam_vertices - result.split_vertices),
            "seam_vertices_duplicated": result.seam_vertices,
            "nonmanifold_vertices_split": result.split_vertices,
        },
        "distortion": result.distortion.as_dict(),
    }


def run_rollout_stage(scan_path, out_dir, options: RolloutOptions | None = None, *,
                      name: str | None = None) -> StageOutput:
    """Read a scan, roll it out, write ``NAME.rollout.ply`` and ``NAME.rollout.json``.

    Parameters
    ----------
    scan_path : path-like
        The scan (any format :func:`potflat.io.scan.load_scan` reads).
    out_dir : path-like
        Output folder (created if needed).
    options : RolloutOptions, optional
    name : str, optional
        Output stem; default: the scan's file stem.

    Returns
    -------
    StageOutput
        ``paths`` with ``"ply"`` and ``"json"``; ``summary`` = the JSON content.

    Raises
    ------
    InvalidOptionError
        When an output would overwrite the input, or the name is not a plain file stem.
    """
    from potflat import __version__
    from potflat.io.atomic import write_json_atomic
    from potflat.io.scan import load_scan
    from potflat.io.stage import write_flat_ply
    from potflat.provenance import provenance

    options = options or RolloutOptions()
    scan_path, out_dir = Path(scan_path), Path(out_dir)
    name = name or scan_path.stem
    if not name or Path(name).name != name or name in (".", ".."):
        raise InvalidOptionError(f"name {name!r} must be a plain file stem without folders")
    ply_path = out_dir / f"{name}.rollout.ply"
    json_path = out_dir / f"{name}.rollout.json"
    for out in (ply_path, json_path):
        if out.resolve() == scan_path.resolve():
            raise InvalidOptionError(
                f"output {out} would overwrite the input scan; choose another output folder or --name")
    loaded = load_scan(scan_path, units=options.units, texture="use" if options.texture else "ignore")
    result = rollout(loaded.mesh, options=options)
    summary = {"stage": "rollout", "name": name, "input": str(scan_path), **rollout_summary(result),
               "cleaning": loaded.report.as_dict(),
               "files": {"ply": ply_path.name, "json": json_path.name}}
    summary["provenance"] = provenance(stage="rollout", inputs=[scan_path], options=options.as_dict())
    write_flat_ply(ply_path, result.flat, comments=(f"potflat {__version__} rollout of {scan_path.name}",))
    write_json_atomic(json_path, summary)
    return StageOutput({"ply": ply_path, "json": json_path}, summary)
