"""Synthetic painted vessels with known geometry: test, benchmark and demo data.

:func:`make_vessel` builds a surface of revolution with an archaeological profile (or a
cylinder / cone frustum as developable known-answer cases), meshes it with irregular
triangles (jittered rings of samples joined by strips, planar Delaunay caps at closed
poles; no seam duplication: one connected manifold like a real scan), poses it
arbitrarily in space, paints it with measurable features and bakes the painting into a
multi-chart texture atlas as photogrammetry software does (UV seams lie inside the
surface). Real-vessel kinds too: two-walled cups, handles (intersecting or welded), holes and
sherds.

:func:`write_obj` writes OBJ + MTL + PNG (one ``v`` per 3D point, several ``vt`` where
charts meet), :func:`write_ply_colored` a binary vertex-coloured PLY. Units are mm.

The painting is a function of the 3D surface point (:meth:`SyntheticVessel.paint`), so
it is exact whatever the parameterisation: filled circles are the surface points within
a 3D distance of a centre on the surface, bands are height ranges along the axis, bars
are arc-length ranges about a meridian.
"""
from __future__ import annotations

import itertools
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from potflat.errors import InvalidOptionError
from potflat.types import Mesh

#: Vessel kinds accepted by :func:`make_vessel`.
KINDS = (
    "amphora", "hydria", "lekythos", "alabastron", "kylix", "aryballos",
    "cylinder", "cone", "cup", "bowl", "sherd",
)

#: Face/vertex part labels (:attr:`SyntheticVessel.face_part`).
PART_OUTER, PART_INNER, PART_RIM, PART_BASE, PART_HANDLE, PART_BREAK = 0, 1, 2, 3, 4, 5
PART_NAMES = ("outer", "inner", "rim", "base", "handle", "break")

TERRACOTTA = (188, 94, 52)
BLACK = (28, 22, 20)
CREAM = (232, 214, 178)
CLAY = (176, 120, 88)
ATLAS_BACKGROUND = (127, 127, 127)

#: Paintings accepted by :func:`make_vessel` (see its ``painting`` parameter).
PAINTINGS = ("frieze", "belt", "panel", "allover")
#: Widths (degrees about the axis) a ``panel`` may take; the one holding most whole circles wins.
PANEL_WIDTHS_DEG = (120.0, 110.0, 130.0, 100.0, 140.0)
#: Lighting factor range of ``shading=True`` (darkest, brightest) and the per-texel noise
#: (standard deviation in grey levels).
SHADING_RANGE = (0.7, 1.1)
SHADING_NOISE = 2.0
#: Pitch of the ``allover`` circle lattice (centre spacing, in circle radii) and of its lines (mm).
LATTICE_PITCH = 2.6
LATTICE_LINES_MM = 8.0
#: Clearance (mm) kept between a feature circle and the edge of the painted zone or a handle root.
ZONE_MARGIN = 3.0

#: Radius (mm) of the painted frieze circles.
CIRCLE_RADIUS = 10.0
#: Width (mm, arc length about the axis) of the painted vertical bars.
BAR_WIDTH = 10.0
_GUTTER_PX = 4


@dataclass(frozen=True)
class _Handle:
    theta: float       # angle of the handle's mid-plane (rad, canonical frame)
    z0: float          # attachment heights and angle offsets of both ends
    dtheta0: float
    z1: float
    dtheta1: float
    reach: float       # how far the loop stands off the wall (mm)
    radius: float      # tube radius (mm)
    inner1: bool = False  # the second end on the inner wall: the handle arches over the rim
    lift: float = 0.0  # raises the loop's middle (mm), to clear the rim


@dataclass(frozen=True)
class _Spec:
    points: tuple      # (height, radius) control points, foot to mouth, mm
    frieze: float      # frieze centre height as a fraction of the wall height
    floor: float | None = None   # interior floor height when the vessel has two walls
    handles: tuple = ()
    walls: int = 1
    base: bool = False


_SPECS: dict[str, _Spec] = {
    "amphora": _Spec(
        ((0, 48), (12, 46), (40, 40), (100, 78), (170, 122), (240, 142), (290, 132),
         (330, 100), (352, 70), (365, 60), (400, 58), (414, 64), (420, 72)),
        frieze=0.55,
        handles=(_Handle(math.pi / 2, 385, 0, 312, 0, 55, 9),
                 _Handle(3 * math.pi / 2, 385, 0, 312, 0, 55, 9)),
    ),
    "hydria": _Spec(
        ((0, 68), (14, 66), (28, 58), (70, 100), (150, 150), (215, 165), (260, 150),
         (295, 110), (318, 72), (340, 62), (372, 66), (390, 86), (400, 96)),
        frieze=0.45,
        handles=(_Handle(math.pi, 370, 0, 282, 0, 45, 8),
                 _Handle(math.pi / 2, 232, -0.22, 232, 0.22, 40, 7),
                 _Handle(3 * math.pi / 2, 232, -0.22, 232, 0.22, 40, 7)),
    ),
    "lekythos": _Spec(
        ((0, 34), (8, 37), (18, 28), (40, 44), (120, 52), (205, 56), (228, 52), (246, 30),
         (254, 14), (290, 12), (302, 20), (318, 25), (330, 22)),
        frieze=0.45,
        handles=(_Handle(math.pi, 282, 0, 238, 0, 22, 5),),
    ),
    "alabastron": _Spec(
        ((0, 14), (6, 26), (25, 36), (110, 42), (160, 36), (180, 20), (188, 12), (194, 13),
         (198, 24), (202, 30)),
        frieze=0.45,
    ),
    "kylix": _Spec(
        ((0, 55), (3, 54), (8, 40), (16, 14), (40, 11), (50, 16), (58, 40), (68, 80),
         (80, 112), (92, 128), (100, 132)),
        frieze=0.80, floor=58.0,
        handles=(_Handle(0.0, 86, -0.28, 86, 0.28, 30, 6),
                 _Handle(math.pi, 86, -0.28, 86, 0.28, 30, 6)),
    ),
    "aryballos": _Spec(
        ((0, 10), (5, 24), (18, 37), (38, 42), (55, 37), (66, 22), (71, 10), (77, 9),
         (80, 13), (83, 20), (86, 21)),
        frieze=0.44,
    ),
    "cylinder": _Spec(((0, 100), (200, 100)), frieze=0.5),
    "cone": _Spec(((0, 60), (200, 120)), frieze=0.5),
    "cup": _Spec(
        ((0, 38), (4, 40), (20, 52), (50, 70), (75, 80), (90, 84)),
        frieze=0.5, floor=5.0, walls=2, base=True,
    ),
    "bowl": _Spec(
        ((0, 40), (3, 44), (15, 62), (35, 78), (55, 86), (65, 88)),
        frieze=0.5, floor=5.0, walls=2, base=True,
        handles=(_Handle(0.0, 40, 0.0, 52, 0.0, 20, 5, inner1=True, lift=45),),
    ),
}


@dataclass(frozen=True)
class PaintedCircle:
    """A filled painted circle: the surface points within ``radius`` (3D distance) of ``centre``.

    Attributes
    ----------
    centre : (3,) float64
        Centre on the surface, world coordinates (mm).
    radius : float
        Radius in mm (3D Euclidean distance; differs from geodesic by < 0.01 mm here).
    colour : tuple of int
        RGB colour.
    side : str
        ``"outer"`` or ``"inner"`` wall.
    height : float
        Height of the centre along the axis above :attr:`SyntheticVessel.axis_point`.
    angle : float
        Angle of the centre about the axis (rad, counter-clockwise seen from the mouth),
        measured from the pose's canonical x axis (:attr:`SyntheticVessel.pose` column 0).
    """

    centre: np.ndarray
    radius: float
    colour: tuple
    side: str
    height: float
    angle: float


@dataclass(frozen=True)
class Hole:
    """A patch of faces removed from the outer wall: faces whose centroid lies within
    ``radius`` (mm, 3D distance) of ``centre`` (world coordinates, on the surface)."""

    centre: np.ndarray
    radius: float


@dataclass(frozen=True)
class Painting:
    """The painting, in the canonical frame (axis = z through the origin, foot at z = 0).

    Attributes
    ----------
    circles : tuple of PaintedCircle
        Frieze circles (and the inner tondo's centre circle), drawn on top of everything.
    bands : tuple of (float, float, tuple)
        ``(z_low, z_high, rgb)`` horizontal bands on the outer wall (heights along the axis).
    bars : tuple of (float, float, float, float, tuple)
        ``(angle, width, z_low, z_high, rgb)``: vertical bars, the points whose arc length
        ``r * |angle difference|`` about the axis is at most ``width / 2``.
    grid : tuple or None
        ``(z_low, z_high, spacing, n_meridians, line_width, rgb)``: a hatched grid zone,
        lines every ``spacing`` mm in height and ``n_meridians`` meridian lines, each
        ``line_width`` mm wide.
    tondo : tuple or None
        ``(centre_z, radius, rgb)``: a disc on the inner floor around the axis (two walls).
    kind : str
        One of :data:`PAINTINGS`.
    zone : tuple or None
        ``(z_low, z_high, angle, half_width)``: the painted zone of the outer wall, heights
        along the axis and, for a panel, the angles within ``half_width`` (rad) of ``angle``
        (None for a belt); the rest of the outer wall is black glaze. None: the whole outer
        wall is painted.
    """

    circles: tuple
    bands: tuple
    bars: tuple
    grid: tuple | None
    tondo: tuple | None
    kind: str = "frieze"
    zone: tuple | None = None


@dataclass(frozen=True, eq=False)
class SyntheticVessel:
    """A synthetic painted vessel and the truth about it.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    mesh : Mesh
        World-coordinate mesh in mm, faces CCW seen from outside, per-corner ``texcoords``
        into :attr:`texture` (``texture_path`` is None until written).
    texture : (S, S, 3) uint8
        The texture atlas, row 0 at the top (texture coordinate v = 1).
    axis_point : (3,) float64
        Point on the rotation axis at the foot (canonical height 0).
    axis_direction : (3,) float64
        Unit axis direction from the foot to the mouth.
    profile : (k, 2) float64
        Outer wall profile: columns ``height`` (along the axis from ``axis_point``,
        strictly increasing) and ``radius`` (mm). The surface's generatrix is exactly this
        polyline, so ``np.interp(h, profile[:, 0], profile[:, 1])`` is exact on the wall.
    generatrix : (g, 2) float64
        The whole section curve ``(radius, height)``: base, outer wall, rim, inner wall,
        floor, in order along the surface.
    painting : Painting
        Painting description (canonical frame).
    features : tuple of PaintedCircle
        Painted circles with known radius, world coordinates (also in :attr:`painting`).
    holes : tuple of Hole
        Patches removed from the surface.
    pose : (4, 4) float64
        Canonical -> world transform (rotation and translation).
    face_part, vertex_part : (m,) / (n,) int8
        Part label (:data:`PART_NAMES`) of every face / vertex.
    face_chart : (m,) int64
        Texture chart of every face.
    options : dict
        The arguments of :func:`make_vessel`.
    """

    kind: str
    mesh: Mesh
    texture: np.ndarray
    axis_point: np.ndarray
    axis_direction: np.ndarray
    profile: np.ndarray
    generatrix: np.ndarray
    painting: Painting
    features: tuple
    holes: tuple
    pose: np.ndarray
    face_part: np.ndarray
    vertex_part: np.ndarray
    face_chart: np.ndarray
    options: dict
    _geometry: "_Generatrix" = field(repr=False)

    def radius_at(self, heights) -> np.ndarray:
        """Outer wall radius (mm) at ``heights`` along the axis from :attr:`axis_point`."""
        return np.interp(np.asarray(heights, float), self.profile[:, 0], self.profile[:, 1])

    def to_canonical(self, points) -> np.ndarray:
        """World points ``(n, 3)`` to the canonical frame (axis = z, foot at the origin)."""
        p = np.asarray(points, float).reshape(-1, 3)
        return (p - self.pose[:3, 3]) @ self.pose[:3, :3]

    def paint(self, points) -> np.ndarray:
        """Painting colour (``(n, 3)`` uint8) at world points on (or near) the body surface.

        The point is projected to the nearest point of the section curve, so the colour is
        exact on the surface and well defined on chords of its triangles. Handles are
        painted plain black (see :meth:`vertex_colors`).
        """
        return _paint(self.painting, self._geometry, self.to_canonical(points))

    def vertex_colors(self) -> np.ndarray:
        """Colour of every mesh vertex as a scan shows it, ``(n, 3)`` uint8.

        The painting (:meth:`paint`); handles are black, a thick sherd's back and break
        faces plain clay (:data:`CLAY`); with ``shading`` lit and noisy like the texture.
        """
        col = self.paint(self.mesh.vertices)
        for part, rgb in _plain_colours(self._geometry).items():
            col[self.vertex_part == part] = rgb
        if self.options.get("shading", False):
            col = _shade(col, self.to_canonical(self.mesh.vertices), self._geometry,
                         _shading_rng(self.options["seed"], 1))
        return col

    def painted_zone(self, points) -> np.ndarray:
        """Whether world points ``(n, 3)`` on the body lie in the painted zone, ``(n,)`` bool.

        The zone is the part of the outer wall that carries the painting (the whole outer
        wall for ``frieze`` and ``allover``; the belt or the panel, see
        :attr:`Painting.zone`); the inner wall and handles are not in it.
        """
        return _in_zone(self.painting, self._geometry, self.to_canonical(points))

    def zone_faces(self) -> np.ndarray:
        """Faces of the outer wall whose centroid lies in the painted zone, ``(m,)`` bool."""
        F = self.mesh.faces
        return (self.face_part == PART_OUTER) & self.painted_zone(self.mesh.vertices[F].mean(axis=1))


# --------------------------------------------------------------------------- geometry


@dataclass(frozen=True, eq=False)
class _Generatrix:
    """Section polyline ``(r, z)`` with arc length ``s`` and part breaks."""

    r: np.ndarray
    z: np.ndarray
    s: np.ndarray
    s_outer: tuple      # (start, end) of the outer wall
    s_inner: float      # start of the inner wall (end of the rim), inf with one wall
    s_floor: float      # start of the inner floor, inf with one wall


def _smooth_profile(points, n=4097) -> tuple[np.ndarray, np.ndarray]:
    """Dense ``(r, z)`` of the smooth curve through control points ``(z, r)``."""
    from scipy.interpolate import PchipInterpolator

    pts = np.asarray(points, float)
    z, r = pts[:, 0], pts[:, 1]
    t = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(z), np.diff(r)))])
    tt = np.linspace(0.0, t[-1], n)
    zz = PchipInterpolator(t, z)(tt)
    rr = PchipInterpolator(t, r)(tt)
    if np.any(np.diff(zz) <= 0) or np.any(rr <= 0):
        raise RuntimeError("profile control points must give a strictly rising, positive curve")
    return rr, zz


def _normals2d(r, z) -> np.ndarray:
    """Unit outward normals ``(dz, -dr)`` of a polyline in the (r, z) plane, per point."""
    dr, dz = np.gradient(r), np.gradient(z)
    n = np.stack([dz, -dr], axis=1)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _build_generatrix(spec: _Spec, *, walls: int, base: bool, thickness: float) -> _Generatrix:
    r_o, z_o = _smooth_profile(spec.points)
    rs, zs = [], []
    if base:
        t = np.linspace(0.0, 1.0, 513)[:-1]
        rs.append(r_o[0] * t)
        zs.append(np.full_like(t, z_o[0]))
    n_base = sum(len(a) for a in rs)
    rs.append(r_o)
    zs.append(z_o)
    n_outer_end = n_base + len(r_o) - 1
    if walls == 2:
        nrm = _normals2d(r_o, z_o)
        dr, dz = r_o[-1] - r_o[-2], z_o[-1] - z_o[-2]
        tan = np.array([dr, dz]) / math.hypot(dr, dz)
        centre = np.array([r_o[-1], z_o[-1]]) - 0.5 * thickness * nrm[-1]
        phi = np.linspace(0.0, math.pi, 129)[1:]
        arc = centre + 0.5 * thickness * (np.cos(phi)[:, None] * nrm[-1] + np.sin(phi)[:, None] * tan)
        rs.append(arc[:, 0])
        zs.append(arc[:, 1])
        inner = (np.stack([r_o, z_o], axis=1) - thickness * nrm)[::-1][1:]
        keep = inner[:, 1] > spec.floor
        last = int(np.argmin(keep))  # first point below the floor
        if keep[last] or last == 0:
            raise RuntimeError("inner wall does not reach the floor height")
        a, b = inner[last - 1], inner[last]
        w = (a[1] - spec.floor) / (a[1] - b[1])
        cut = a + w * (b - a)
        inner = np.vstack([inner[:last], cut])
        seg = np.diff(inner, axis=0)
        if np.any(np.einsum("ij,ij->i", seg[1:], seg[:-1]) <= 0):
            raise RuntimeError("wall thickness too large for the profile's curvature")
        rs.append(inner[:, 0])
        zs.append(inner[:, 1])
        t = np.linspace(0.0, 1.0, 513)[1:]
        rs.append(cut[0] * (1.0 - t))
        zs.append(np.full_like(t, spec.floor))
    r = np.concatenate(rs)
    z = np.concatenate(zs)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(r), np.diff(z)))])
    s_outer = (float(s[n_base]), float(s[n_outer_end]))
    if walls == 2:
        s_inner = float(s[n_outer_end + 128])
        s_floor = float(s[-513])
    else:
        s_inner = s_floor = math.inf
    return _Generatrix(r=r, z=z, s=s, s_outer=s_outer, s_inner=s_inner, s_floor=s_floor)


def _outer_polyline(g: _Generatrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(s, r, z)`` of the section polyline's points on the outer wall (z rising)."""
    sel = (g.s >= g.s_outer[0]) & (g.s <= g.s_outer[1])
    return g.s[sel], g.r[sel], g.z[sel]


def _wall_polyline(g: _Generatrix, inner: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(r, z, normal)`` of the section polyline's points on the outer or the inner wall, the
    normals pointing out of the vessel's material (the inner wall's into the cavity)."""
    if inner:
        sel = (g.s >= g.s_inner) & (g.s <= g.s_floor)
        pr, pz = g.r[sel], g.z[sel]
    else:
        _, pr, pz = _outer_polyline(g)
    return pr, pz, _normals2d(pr, pz)


def _project_to_generatrix(g: _Generatrix, r, z) -> np.ndarray:
    """Arc length ``s`` of the nearest point of the section polyline to each ``(r, z)``."""
    from scipy.spatial import cKDTree

    pts = np.stack([g.r, g.z], axis=1)
    q = np.stack([r, z], axis=1)
    _, idx = cKDTree(pts).query(q, workers=-1)
    best_s = g.s[idx].copy()
    best_d = np.full(len(q), np.inf)
    for lo in (idx - 1, idx):
        lo = np.clip(lo, 0, len(pts) - 2)
        a, b = pts[lo], pts[lo + 1]
        ab = b - a
        t = np.clip(np.einsum("ij,ij->i", q - a, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
        d = np.linalg.norm(a + t[:, None] * ab - q, axis=1)
        better = d < best_d
        best_d[better] = d[better]
        best_s[better] = (g.s[lo] + t * (g.s[lo + 1] - g.s[lo]))[better]
    return best_s


def _wrap(a):
    """Angle difference wrapped to [-pi, pi)."""
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi


def _ring_strip_faces(rows, theta, n_row, k_lo, k_hi) -> np.ndarray:
    """Triangles between consecutive closed rings of points, rows ``k_lo .. k_hi``.

    Each ring's edges (between angle-sorted neighbours, closing around 2 pi) are swept
    together with the next ring's edges in the order of their mid-angles; an edge's
    triangle takes the vertex that is current on the other ring at that moment. This is
    a valid strip triangulation of every pair of rings (no seam, no duplicated points).
    Faces are counter-clockwise in the (angle, row) plane. Returns global vertex indices.
    """
    two_pi = 2 * math.pi
    sel = np.flatnonzero((rows >= k_lo) & (rows <= k_hi))
    order = sel[np.lexsort((theta[sel], rows[sel]))]
    loc = rows[order] - k_lo
    th = theta[order]
    counts = n_row[k_lo:k_hi + 1]
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    i_in = np.arange(len(order)) - start[loc]
    nxt = start[loc] + (i_in + 1) % counts[loc]
    th0 = th[start]
    mid = th + 0.5 * ((th[nxt] - th) % two_pi)
    key = 10.0 * loc + (mid - th0[loc])  # rows 10 apart, each spanning [0, 2 pi)
    faces = []
    for step, side in ((1, "left"), (-1, "right")):
        e = np.flatnonzero((loc + step >= 0) & (loc + step < len(counts)))
        other = loc[e] + step
        q = 10.0 * other + (mid[e] - th0[other]) % two_pi
        c = np.searchsorted(key, q, side=side) - start[other]
        apex = order[start[other] + c % counts[other]]
        if step == 1:
            faces.append(np.stack([order[e], order[nxt[e]], apex], axis=1))
        else:
            faces.append(np.stack([order[nxt[e]], order[e], apex], axis=1))
    return np.concatenate(faces)


def _planar_delaunay(xy) -> np.ndarray:
    from scipy.spatial import Delaunay

    tri = Delaunay(xy).simplices
    p = xy[tri]
    area = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
            - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    return tri[np.abs(area) > 1e-14]


def _row_points(n_per_row, row_s, ds, jitter_rows, rng):
    """Jittered sample points ``(row, s, theta)`` on rows of a periodic band."""
    rows = np.repeat(np.arange(len(n_per_row)), n_per_row)
    starts = np.concatenate([[0], np.cumsum(n_per_row)[:-1]])
    j = np.arange(len(rows)) - starts[rows]
    phase = rng.uniform(0.0, 2 * math.pi, len(n_per_row))
    jt = rng.uniform(-0.3, 0.3, len(rows))
    js = rng.uniform(-0.3, 0.3, len(rows))
    theta = (phase[rows] + 2 * math.pi * (j + jt) / n_per_row[rows]) % (2 * math.pi)
    theta[n_per_row[rows] == 1] = 0.0
    s = row_s[rows] + np.where(jitter_rows[rows], js * ds, 0.0)
    return rows, s, theta


def _revolve(g: _Generatrix, n_target: int, rng) -> tuple:
    """Irregular triangulation of the surface of revolution of ``g``.

    Returns vertices (canonical), faces (CCW from outside), per-vertex ``s`` and ``theta``.
    """
    L = float(g.s[-1])
    area = float(np.sum(2 * math.pi * 0.5 * (g.r[1:] + g.r[:-1]) * np.diff(g.s)))
    h = math.sqrt(2.0 * area / (math.sqrt(3.0) * n_target))
    K = max(2, int(math.ceil(L / (h * math.sqrt(3.0) / 2))))
    row_s = np.linspace(0.0, L, K + 1)
    ds = L / K
    row_r = np.interp(row_s, g.s, g.r)
    pole0, pole1 = g.r[0] == 0.0, g.r[-1] == 0.0
    r_cap = 2.5 * h
    ka, kb = 0, K
    if pole0:
        ka = int(np.argmax(row_r >= r_cap))
    if pole1:
        kb = K - int(np.argmax(row_r[::-1] >= r_cap))
    if not (0 <= ka < kb <= K) or row_r[ka] < r_cap or row_r[kb] < r_cap:
        raise InvalidOptionError(
            f"n_vertices={n_target} is too small for this vessel; use at least 2000"
        )
    n_row = np.where(row_r == 0.0, 1, np.maximum(3, np.rint(2 * math.pi * row_r / h))).astype(np.int64)
    jitter = np.ones(K + 1, bool)
    jitter[[0, K, ka, kb]] = False
    rows, s, theta = _row_points(n_row, row_s, ds, jitter, rng)
    r = np.interp(s, g.s, g.r)
    z = np.interp(s, g.s, g.z)
    V = np.stack([r * np.cos(theta), r * np.sin(theta), z], axis=1)

    faces = [_ring_strip_faces(rows, theta, n_row, ka, kb)]
    for cap in ((rows <= ka) if pole0 else None, (rows >= kb) if pole1 else None):
        if cap is None:
            continue
        ci = np.flatnonzero(cap)
        faces.append(_orient_outward(g, V, ci[_planar_delaunay(V[ci, :2])], s))
    F = np.concatenate(faces).astype(np.int64)
    _check_manifold(F, len(V), holes_expected=int(not pole0) + int(not pole1))
    return V, F, s, theta, h


def _orient_outward(g: _Generatrix, V, F, s) -> np.ndarray:
    """Flip faces whose normal disagrees with the analytic outward normal."""
    nrm = _normals2d(g.r, g.z)
    sc = s[F].mean(axis=1)
    nr = np.interp(sc, g.s, nrm[:, 0])
    nz = np.interp(sc, g.s, nrm[:, 1])
    c = V[F].mean(axis=1)
    rc = np.maximum(np.hypot(c[:, 0], c[:, 1]), 1e-300)
    ref = np.stack([nr * c[:, 0] / rc, nr * c[:, 1] / rc, nz], axis=1)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    flip = np.einsum("ij,ij->i", fn, ref) < 0
    F = F.copy()
    F[flip] = F[flip][:, ::-1]
    return F


def _check_manifold(F, n_vertices, holes_expected) -> None:
    """Internal consistency: an oriented 2-manifold, all vertices used, Euler characteristic
    ``2 - holes_expected`` (genus 0 with that many boundary loops, or a closed surface of
    genus ``holes_expected / 2``)."""
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = np.sort(directed[:, 0] * n_vertices + directed[:, 1])
    if np.any(key[1:] == key[:-1]):
        raise RuntimeError("synthetic mesh is not consistently oriented")
    und = np.sort(np.minimum(directed[:, 0], directed[:, 1]) * n_vertices
                  + np.maximum(directed[:, 0], directed[:, 1]))
    n_edges = 1 + int(np.count_nonzero(und[1:] != und[:-1]))
    used = np.zeros(n_vertices, bool)
    used[F.ravel()] = True
    chi = int(used.sum()) - n_edges + len(F)
    if not used.all() or chi != 2 - holes_expected:
        raise RuntimeError(f"synthetic mesh topology is wrong (euler {chi}, {used.sum()}/{n_vertices} used)")


def _bezier(p, t):
    t = t[:, None]
    return ((1 - t) ** 3) * p[0] + 3 * ((1 - t) ** 2) * t * p[1] + 3 * (1 - t) * t * t * p[2] + t ** 3 * p[3]


def _handle_mesh(g: _Generatrix, hd: _Handle, h: float, rng, sink: float) -> tuple:
    """Tube mesh of one handle whose open ends sink ``sink`` mm into the wall.

    Returns V, F, arc length and angle per vertex, and both ends as (surface point,
    unit wall normal, indices of the end ring's vertices, the wall's part).
    """

    def anchor(z, th, inner):
        pr, pz, nrm = _wall_polyline(g, inner)
        i = int(np.argmin(np.abs(pz - z)))
        n3 = np.array([nrm[i, 0] * math.cos(th), nrm[i, 0] * math.sin(th), nrm[i, 1]])
        p3 = np.array([pr[i] * math.cos(th), pr[i] * math.sin(th), pz[i]])
        return p3 - sink * n3, n3

    a0, n0 = anchor(hd.z0, hd.theta + hd.dtheta0, False)
    a1, n1 = anchor(hd.z1, hd.theta + hd.dtheta1, hd.inner1)
    up = np.array([0.0, 0.0, hd.lift])
    ctrl = np.array([a0, a0 + hd.reach * n0 + up, a1 + hd.reach * n1 + up, a1])
    tt = np.linspace(0.0, 1.0, 2001)
    c = _bezier(ctrl, tt)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
    length = float(arc[-1])
    K = max(2, int(math.ceil(length / (h * math.sqrt(3.0) / 2))))
    row_s = np.linspace(0.0, length, K + 1)
    n = max(6, int(round(2 * math.pi * hd.radius / h)))
    n_row = np.full(K + 1, n, np.int64)
    jitter = np.ones(K + 1, bool)
    jitter[[0, K]] = False
    _, s, phi = _row_points(n_row, row_s, length / K, jitter, rng)
    t_of_s = np.interp(s, arc, tt)
    centre = _bezier(ctrl, t_of_s)
    # rotation-minimising frame along the centreline (double reflection), interpolated
    tan = np.gradient(c, axis=0)
    tan /= np.linalg.norm(tan, axis=1, keepdims=True)
    frame = np.empty_like(c)
    ref = np.cross(tan[0], np.cross(a1 - a0, tan[0]) if np.linalg.norm(np.cross(a1 - a0, tan[0])) > 1e-9
                   else np.array([0.0, 0.0, 1.0]))
    frame[0] = ref / np.linalg.norm(ref)
    for i in range(len(c) - 1):
        v1 = c[i + 1] - c[i]
        rl = frame[i] - 2.0 * (v1 @ frame[i]) / (v1 @ v1) * v1
        tl = tan[i] - 2.0 * (v1 @ tan[i]) / (v1 @ v1) * v1
        v2 = tan[i + 1] - tl
        frame[i + 1] = rl - 2.0 * (v2 @ rl) / (v2 @ v2) * v2 if v2 @ v2 > 1e-30 else rl
    other = np.stack([np.interp(t_of_s, tt, frame[:, k]) for k in range(3)], axis=1)
    tangent = np.stack([np.interp(t_of_s, tt, tan[:, k]) for k in range(3)], axis=1)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    other -= np.einsum("ij,ij->i", other, tangent)[:, None] * tangent
    other /= np.linalg.norm(other, axis=1, keepdims=True)
    side = np.cross(tangent, other)
    V = centre + hd.radius * (np.cos(phi)[:, None] * other + np.sin(phi)[:, None] * side)
    rows = np.repeat(np.arange(K + 1), n)
    F = _ring_strip_faces(rows, phi, n_row, 0, K).astype(np.int64)
    _check_manifold(F, len(V), holes_expected=2)
    ends = ((a0 + sink * n0, n0, np.flatnonzero(rows == 0), PART_OUTER),
            (a1 + sink * n1, n1, np.flatnonzero(rows == K), PART_INNER if hd.inner1 else PART_OUTER))
    return V, F, s, phi, ends


def _weld_handles(V, F, arrays, face_arrays, ends, h, keep_wall=False):
    """Weld handle tubes into the wall: cut a hole around each root, stitch it to the ring.

    ``arrays`` are per-vertex arrays and ``face_arrays`` per-face arrays (the first one
    the face part) to carry along; ``ends`` = (root point, wall normal, ring vertex
    indices, tube radius, the wall's part). The hole (wall faces within the tube radius
    plus 1.5 ``h`` of the root, grown where its outline is not star-shaped around the root;
    never through the other wall behind it) is stitched to the tube's end ring by a strip of
    handle faces. ``keep_wall``: the hole's faces stay, so every edge of its outline has
    three faces (a non-manifold join, as scans merged from several passes have). Returns V,
    F, arrays, face arrays and the stitched faces' preset chart layout (face indices,
    tangent-plane projection, two charts per root).
    """
    face_part = face_arrays[0]
    near = [np.zeros(len(V), bool) for _ in ends]
    frames = []
    for k, (A, nA, ring, a, _) in enumerate(ends):
        d = np.linalg.norm(V - A, axis=1)
        d[ring] = np.inf
        near[k] |= d <= a + max(1.5 * h, 1.0)
        e1 = np.cross(nA, [1.0, 0.0, 0.0] if abs(nA[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        frames.append((e1, np.cross(nA, e1)))
    for _ in range(20):
        cut = np.zeros(len(F), bool)
        for k, end in enumerate(ends):
            cut |= (face_part == end[4]) & near[k][F].any(axis=1)
        remove = _remove_faces(F, cut)
        Fk = F[~remove]
        used = np.zeros(len(V), bool)
        used[Fk.ravel()] = True
        if keep_wall:  # (the hole's faces come back: every vertex stays)
            used[:] = True
        old = np.flatnonzero(used)
        new = np.cumsum(used) - 1
        Vk, Fk = V[used], new[Fk]
        n = len(Vk)
        directed = np.concatenate([Fk[:, [0, 1]], Fk[:, [1, 2]], Fk[:, [2, 0]]])
        key = directed[:, 0] * n + directed[:, 1]
        on_border = ~np.isin(key, directed[:, 1] * n + directed[:, 0])
        bnd = directed[on_border]
        bnd_part = np.tile(face_part[~remove], 3)[on_border]
        nxt = dict(zip(bnd[:, 0].tolist(), bnd[:, 1].tolist()))
        is_handle_vertex = np.zeros(n, bool)
        is_handle_vertex[Fk[face_part[~remove] == PART_HANDLE].ravel()] = True
        stitched, uvs, pieces, grow = [], [], [], False
        for k, ((A, nA, ring, _, part), (e1, e2)) in enumerate(zip(ends, frames)):
            # the boundary loop of the root's wall nearest to the root
            start = np.flatnonzero(~is_handle_vertex[bnd[:, 0]] & (bnd_part == part))
            first = bnd[start[np.argmin(np.linalg.norm(Vk[bnd[start, 0]] - A, axis=1))], 0]
            hole = [int(first)]
            while nxt[hole[-1]] != hole[0]:
                hole.append(nxt[hole[-1]])
            hole = np.array(hole)
            if any(np.isin(hole, f).any() for f in stitched):
                raise InvalidOptionError("the mesh is too coarse to weld the handles; use more n_vertices")
            ang = lambda idx: np.arctan2((Vk[idx] - A) @ e2, (Vk[idx] - A) @ e1) % (2 * math.pi)  # noqa: E731
            turn = _wrap(ang(np.roll(hole, -1)) - ang(hole))
            wrong = np.sign(turn) != np.sign(turn.sum())
            if np.any(wrong) or abs(abs(turn.sum()) - 2 * math.pi) > 1e-6:
                near[k][old[hole[wrong | np.roll(wrong, 1)]]] = True  # cut the notch away
                grow = True
                continue
            ring = new[ring]
            idx = np.concatenate([hole, ring])
            rows = np.concatenate([np.zeros(len(hole), np.int64), np.ones(len(ring), np.int64)])
            faces = idx[_ring_strip_faces(rows, ang(idx), np.array([len(hole), len(ring)]), 0, 1)]
            u, v = hole[0], hole[1]
            if np.any((faces == u) & (np.roll(faces, -1, axis=1) == v)):
                faces = faces[:, ::-1]
            stitched.append(faces)
            P = Vk[faces] - A
            uvs.append(np.stack([P @ e1, P @ e2], axis=2))
            c = P.mean(axis=1)
            pieces.append((np.arctan2(c @ e2, c @ e1) >= 0).astype(np.int64) + 2 * len(pieces))
        if not grow:
            break
    else:
        raise InvalidOptionError("the mesh is too coarse to weld the handles; use more n_vertices")
    kept = ~remove | keep_wall  # (with keep_wall every vertex stayed: the faces' indices hold)
    V, F = Vk, np.concatenate([Fk, F[remove & kept]])
    arrays = [a[used] for a in arrays]
    face_arrays = [np.concatenate([a[~remove], a[remove & kept]]) for a in face_arrays]
    m0 = len(F)
    extra = np.concatenate(stitched)
    F = np.concatenate([F, extra])
    fills = [PART_HANDLE] + [-1] * (len(face_arrays) - 1)
    face_arrays = [np.concatenate([a, np.full(len(extra), f, a.dtype)]) for a, f in zip(face_arrays, fills)]
    preset = (np.arange(m0, len(F)), np.concatenate(uvs), np.concatenate(pieces))
    return V, F, arrays, face_arrays, preset


# --------------------------------------------------------------------------- painting


def _layout_painting(g: _Generatrix, spec: _Spec, walls: int, rng, painting: str = "frieze") -> Painting:
    """The painting of kind ``painting`` (:data:`PAINTINGS`); draws the same random numbers
    for every kind, so the mesh does not depend on the painting."""
    z_lo = float(np.interp(g.s_outer[0], g.s, g.z))
    z_hi = float(np.interp(g.s_outer[1], g.s, g.z))
    H = z_hi - z_lo
    _, prof_r, prof_z = _outer_polyline(g)
    rc = CIRCLE_RADIUS
    zf = z_lo + spec.frieze * H
    rf = float(np.interp(zf, prof_z, prof_r))
    n_c = int(np.clip(math.floor(2 * math.pi * rf / (3.2 * rc)), 3, 12))
    phase = float(rng.uniform(0.0, 2 * math.pi))
    circles = []
    for k in range(n_c):
        th = (phase + 2 * math.pi * k / n_c) % (2 * math.pi)
        centre = np.array([rf * math.cos(th), rf * math.sin(th), zf])
        circles.append(PaintedCircle(centre, rc, BLACK if k % 2 == 0 else CREAM, "outer", zf, th))
    foot_top = z_lo + 0.04 * H
    bands = [
        (-math.inf, foot_top, BLACK),
        (zf - rc - 7.0, zf - rc - 3.0, BLACK),
        (zf + rc + 3.0, zf + rc + 7.0, BLACK),
        (z_hi - 3.0, math.inf, BLACK),
    ]
    G = float(np.clip(0.15 * H, 10.0, 30.0))
    grid = None
    g0, g1 = zf + rc + 10.0, min(zf + rc + 10.0 + G, z_hi - 8.0)
    if g1 - g0 >= 5.0:
        r_mid = float(np.interp(0.5 * (g0 + g1), prof_z, prof_r))
        grid = (g0, g1, 5.0, max(8, int(round(2 * math.pi * r_mid / 5.0))), 1.0, BLACK)
    bars = []
    b1, b0 = zf - rc - 10.0, max(zf - rc - 10.0 - G, foot_top + 3.0)
    if b1 - b0 >= 5.0:
        for k in (0, n_c // 2):
            th = (phase + 2 * math.pi * (k + 0.5) / n_c) % (2 * math.pi)
            bars.append((th, BAR_WIDTH, b0, b1, BLACK))
    tondo = None
    if walls == 2:
        floor_r = float(np.interp(g.s_floor, g.s, g.r))
        rt = min(30.0, 0.9 * floor_r)
        tondo = (spec.floor, rt, TERRACOTTA)
        circles.append(PaintedCircle(np.array([0.0, 0.0, spec.floor]), rc, BLACK, "inner", spec.floor, 0.0))
    if painting == "frieze":
        return Painting(tuple(circles), tuple(bands), tuple(bars), grid, tondo)
    inner = [c for c in circles if c.side == "inner"]
    frieze = [c for c in circles if c.side == "outer"]
    if painting == "allover":
        n_mer = max(8, int(round(2 * math.pi * float(prof_r.max()) / LATTICE_LINES_MM)))
        lines = (foot_top, z_hi - 3.0, LATTICE_LINES_MM, n_mer, 1.0, BLACK)
        lattice = _lattice_circles(g, spec, phase)
        return Painting(tuple(lattice + inner), (bands[0], bands[-1]), (), lines, tondo, kind=painting)
    # belt: the frieze between its frame bands; panel: from the bars below to the grid above
    zone = (zf - rc - 7.0, zf + rc + 7.0, None, math.pi)
    if painting == "panel":
        zone = _panel_zone(g, spec, frieze, min(zone[0], b0 if bars else math.inf),
                           max(zone[1], g1 if grid is not None else -math.inf))
        frieze = [c for c in frieze if _circle_in_zone(g, zone, c)]
        frieze.sort(key=lambda c: abs(float(_wrap(c.angle - zone[2]))))  # the central one first
    return Painting(tuple(frieze + inner), tuple(bands), tuple(bars), grid, tondo, kind=painting, zone=zone)


def _handle_roots(g: _Generatrix, spec: _Spec) -> list:
    """Where the profile's handles meet the wall: (canonical point, tube radius) per end."""
    out = []
    for hd in spec.handles:
        for z, dth, inner in ((hd.z0, hd.dtheta0, False), (hd.z1, hd.dtheta1, hd.inner1)):
            pr, pz, _ = _wall_polyline(g, inner)
            order = np.argsort(pz)
            r, th = float(np.interp(z, pz[order], pr[order])), hd.theta + dth
            out.append((np.array([r * math.cos(th), r * math.sin(th), z]), hd.radius))
    return out


def _circle_outline(g: _Generatrix, c: PaintedCircle, k: int = 48) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(z, theta, r)`` of ``k`` points about the outline of an outer-wall circle (first order
    in its radius: arc length along the profile and along the parallel)."""
    sc = float(_project_to_generatrix(g, np.array([math.hypot(*c.centre[:2])]), np.array([c.centre[2]]))[0])
    a = np.linspace(0.0, 2 * math.pi, k, endpoint=False)
    s = sc + c.radius * np.sin(a)
    r = np.interp(s, g.s, g.r)
    return np.interp(s, g.s, g.z), c.angle + c.radius * np.cos(a) / r, r


def _circle_in_zone(g: _Generatrix, zone: tuple, c: PaintedCircle) -> bool:
    """Whether circle ``c`` lies in ``zone`` with :data:`ZONE_MARGIN` to spare."""
    z, th, r = _circle_outline(g, c)
    z_lo, z_hi, centre, half = zone
    ok = (z >= z_lo + ZONE_MARGIN) & (z <= z_hi - ZONE_MARGIN)
    if centre is not None:
        ok &= np.abs(_wrap(th - centre)) * r <= half * r - ZONE_MARGIN
    return bool(np.all(ok))


def _panel_zone(g: _Generatrix, spec: _Spec, circles: list, z_lo: float, z_hi: float) -> tuple:
    """A panel of one of :data:`PANEL_WIDTHS_DEG` centred on a frieze circle or between two,
    holding the most whole circles (then: far from the handles, the first width listed)."""
    roots = [math.atan2(p[1], p[0]) for p, _ in _handle_roots(g, spec)]
    angles = [c.angle for c in circles]
    n = len(angles)
    centres = angles + [a + 0.5 * float(_wrap(angles[(i + 1) % n] - a)) for i, a in enumerate(angles)]
    best, best_key = None, None
    for w_deg in PANEL_WIDTHS_DEG:
        for th in centres:
            zone = (z_lo, z_hi, th % (2 * math.pi), math.radians(w_deg) / 2)
            count = sum(_circle_in_zone(g, zone, c) for c in circles)
            clear = min((abs(float(_wrap(th - a))) for a in roots), default=math.pi)
            key = (count, round(clear, 6))
            if best_key is None or key > best_key:
                best, best_key = zone, key
    return best


def _lattice_circles(g: _Generatrix, spec: _Spec, phase: float) -> list:
    """Circles of radius :data:`CIRCLE_RADIUS` in staggered rows over the whole outer wall:
    rows :data:`LATTICE_PITCH` radii apart along the profile where the wall's radius is at
    least 2.5 circle radii, clear of the wall's ends and of the handle roots."""
    rc = CIRCLE_RADIUS
    pitch = LATTICE_PITCH * rc
    s0, s1 = g.s_outer
    n_rows = int((s1 - s0 - 2 * (rc + 4.0)) // pitch) + 1
    first = 0.5 * (s0 + s1) - 0.5 * (n_rows - 1) * pitch
    roots = _handle_roots(g, spec)
    out = []
    for k in range(max(n_rows, 0)):
        s = first + k * pitch
        r, z = float(np.interp(s, g.s, g.r)), float(np.interp(s, g.s, g.z))
        n = int(2 * math.pi * r // pitch)
        if r < 2.5 * rc or n < 3:
            continue
        for j in range(n):
            th = (phase + 2 * math.pi * (j + 0.5 * (k % 2)) / n) % (2 * math.pi)
            centre = np.array([r * math.cos(th), r * math.sin(th), z])
            if any(np.linalg.norm(centre - p) < rc + a + 8.0 for p, a in roots):
                continue
            out.append(PaintedCircle(centre, rc, BLACK if len(out) % 2 == 0 else CREAM, "outer", z, th))
    return out


def _in_zone(p: Painting, g: _Generatrix, P) -> np.ndarray:
    """Canonical points ``P`` in the painting's zone of the outer wall, ``(n,)`` bool."""
    P = np.asarray(P, float).reshape(-1, 3)
    if not math.isfinite(g.s_inner):
        return _zone_mask(p.zone, P)
    s = _project_to_generatrix(g, np.hypot(P[:, 0], P[:, 1]), P[:, 2])
    return (s <= 0.5 * (g.s_outer[1] + g.s_inner)) & _zone_mask(p.zone, P)


def _zone_mask(zone: tuple | None, P: np.ndarray) -> np.ndarray:
    """Canonical points ``P`` within the heights and angles of ``zone`` (:attr:`Painting.zone`)."""
    ok = np.ones(len(P), bool)
    if zone is not None:
        z_lo, z_hi, centre, half = zone
        ok &= (P[:, 2] >= z_lo) & (P[:, 2] <= z_hi)
        if centre is not None:
            ok &= np.abs(_wrap(np.arctan2(P[:, 1], P[:, 0]) - centre)) <= half
    return ok


def _shading_rng(seed: int, stream: int) -> np.random.Generator:
    """The random numbers of the lighting and noise of ``shading=True`` (apart from the mesh's)."""
    return np.random.default_rng([seed, 0x5EAD, stream])


def _shade(colours: np.ndarray, P, g: _Generatrix, rng) -> np.ndarray:
    """Colours lit by a smooth gradient (factor :data:`SHADING_RANGE` across the vessel: a side
    light about the axis and a vertical fall-off) plus per-sample noise (:data:`SHADING_NOISE`
    grey levels), as a scan's texture shows them. ``P`` canonical points, ``(n, 3)``."""
    light = float(rng.uniform(0.0, 2 * math.pi))
    P = np.asarray(P, float).reshape(-1, 3)
    z0, z1 = float(g.z.min()), float(g.z.max())
    t = 0.7 * np.cos(np.arctan2(P[:, 1], P[:, 0]) - light) \
        + 0.3 * np.clip(2.0 * (P[:, 2] - z0) / max(z1 - z0, 1e-9) - 1.0, -1.0, 1.0)
    lo, hi = SHADING_RANGE
    factor = 0.5 * (lo + hi) + 0.5 * (hi - lo) * t
    out = colours * factor[:, None] + rng.normal(0.0, SHADING_NOISE, colours.shape)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def _paint(p: Painting, g: _Generatrix, P) -> np.ndarray:
    """Colours ``(n, 3)`` uint8 of canonical points ``P`` on the body surface."""
    P = np.asarray(P, float).reshape(-1, 3)
    r = np.hypot(P[:, 0], P[:, 1])
    z = P[:, 2]
    theta = np.arctan2(P[:, 1], P[:, 0])
    s = _project_to_generatrix(g, r, z)
    inner = s > 0.5 * (g.s_outer[1] + g.s_inner) if math.isfinite(g.s_inner) else np.zeros(len(P), bool)
    outer = ~inner
    col = np.empty((len(P), 3), np.uint8)
    col[:] = TERRACOTTA
    if p.grid is not None:
        z0, z1, spacing, n_mer, width, rgb = p.grid
        zone = outer & (z >= z0) & (z <= z1)
        hz = np.abs((z - z0 + 0.5 * spacing) % spacing - 0.5 * spacing) <= 0.5 * width
        step = 2 * math.pi / n_mer
        ang = np.abs(((theta % step) + 0.5 * step) % step - 0.5 * step) * r
        col[zone & (hz | (ang <= 0.5 * width))] = rgb
    for z0, z1, rgb in p.bands:
        col[outer & (z >= z0) & (z <= z1)] = rgb
    for th, width, z0, z1, rgb in p.bars:
        col[outer & (z >= z0) & (z <= z1) & (np.abs(_wrap(theta - th)) * r <= 0.5 * width)] = rgb
    if p.tondo is not None:
        col[inner] = BLACK
        zc, rt, rgb = p.tondo
        d = np.linalg.norm(P - np.array([0.0, 0.0, zc]), axis=1)
        col[inner & (d <= rt)] = rgb
        col[inner & (d <= rt - 2.0) & (d >= rt - 4.0)] = BLACK
    for c in p.circles:
        side = outer if c.side == "outer" else inner
        col[side & (np.linalg.norm(P - c.centre, axis=1) <= c.radius)] = c.colour
    if p.zone is not None:
        col[outer & ~_zone_mask(p.zone, P)] = BLACK
    return col


# --------------------------------------------------------------------------- holes, sherds


def _remove_faces(F, remove) -> np.ndarray:
    """Remove faces, then also the faces at pinch vertices, until the boundary is clean."""
    remove = remove.copy()
    while True:
        keep = F[~remove]
        directed = np.concatenate([keep[:, [0, 1]], keep[:, [1, 2]], keep[:, [2, 0]]])
        n = int(F.max()) + 1
        und = np.sort(directed, axis=1)
        key = und[:, 0] * n + und[:, 1]
        uniq, cnt = np.unique(key, return_counts=True)
        boundary = np.isin(key, uniq[cnt == 1])
        starts = np.bincount(directed[boundary, 0], minlength=n)
        pinch = np.flatnonzero(starts > 1)
        if len(pinch) == 0:
            return remove
        remove |= np.isin(F, pinch).any(axis=1)


def _largest_component(F, keep) -> np.ndarray:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    idx = np.flatnonzero(keep)
    m = len(idx)
    if m == 0:
        return keep
    # faces are connected when they share a vertex through the face-vertex incidence
    n = int(F.max()) + 1
    rows = np.repeat(np.arange(m), 3)
    inc = coo_matrix((np.ones(3 * m), (rows, F[idx].ravel())), shape=(m, n)).tocsr()
    adj = inc @ inc.T
    _, lab = connected_components(adj, directed=False)
    big = np.argmax(np.bincount(lab))
    out = np.zeros_like(keep)
    out[idx[lab == big]] = True
    return out


def _compact(V, F, *arrays):
    """Drop unused vertices; returns V, F and the vertex arrays reindexed."""
    used = np.zeros(len(V), bool)
    used[F.ravel()] = True
    new = np.cumsum(used) - 1
    return (V[used], new[F]) + tuple(a[used] for a in arrays)


def _thicken_sherd(g: _Generatrix, V, F, vs, vth, thickness):
    """Give a one-sided patch a back (offset inwards along the section normal) and break faces.

    Returns the new V, F, vs, vth, face parts, vertex parts and the break faces' preset
    chart layout (face indices, corner layouts (k, 3, 2) in mm, piece ids).
    """
    n, m = len(V), len(F)
    nrm = _normals2d(g.r, g.z)
    nr, nz = np.interp(vs, g.s, nrm[:, 0]), np.interp(vs, g.s, nrm[:, 1])
    back = V - thickness * np.stack([nr * np.cos(vth), nr * np.sin(vth), nz], axis=1)
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = directed[:, 0] * n + directed[:, 1]
    rev = directed[:, 1] * n + directed[:, 0]
    bnd = directed[~np.isin(key, rev)]
    nxt = dict(zip(bnd[:, 0].tolist(), bnd[:, 1].tolist()))
    if len(nxt) != len(bnd):
        raise RuntimeError("sherd boundary has a pinch vertex")
    sides, uvs, pieces = [], [], []
    todo = set(nxt)
    while todo:  # one strip of break faces per boundary loop (outline and through-holes)
        loop = [min(todo)]
        while nxt[loop[-1]] != loop[0]:
            loop.append(nxt[loop[-1]])
        todo -= set(loop)
        a = np.array(loop)
        b = np.roll(a, -1)
        ell = np.linalg.norm(V[b] - V[a], axis=1)
        c = np.concatenate([[0.0], np.cumsum(ell)[:-1]])
        zero, full = np.zeros_like(c), np.full_like(c, thickness)
        sides += [np.stack([b, a, a + n], axis=1), np.stack([b, a + n, b + n], axis=1)]
        uvs += [np.stack([np.stack([c + ell, zero], 1), np.stack([c, zero], 1), np.stack([c, full], 1)], 1),
                np.stack([np.stack([c + ell, zero], 1), np.stack([c, full], 1), np.stack([c + ell, full], 1)], 1)]
        k = np.minimum((4 * c / (c[-1] + ell[-1])).astype(np.int64), 3) + 4 * (len(pieces) // 2)
        pieces += [k, k]
    side = np.concatenate(sides)
    n_loops = len(pieces) // 2
    F2 = np.concatenate([F, F[:, ::-1] + n, side])
    V2 = np.concatenate([V, back])
    face_part = np.concatenate([np.full(m, PART_OUTER, np.int8), np.full(m, PART_INNER, np.int8),
                                np.full(len(side), PART_BREAK, np.int8)])
    vertex_part = np.concatenate([np.full(n, PART_OUTER, np.int8), np.full(n, PART_INNER, np.int8)])
    _check_manifold(F2, len(V2), holes_expected=2 * (n_loops - 1))  # genus = through-holes
    preset = (np.arange(2 * m, 2 * m + len(side)), np.concatenate(uvs), np.concatenate(pieces))
    return V2, F2, np.concatenate([vs, vs]), np.concatenate([vth, vth]), face_part, vertex_part, preset


def _plain_colours(g: _Generatrix) -> dict:
    """Parts painted in one plain colour instead of the painting."""
    plain = {PART_HANDLE: BLACK, PART_BREAK: CLAY}
    if not math.isfinite(g.s_inner):
        plain[PART_INNER] = CLAY  # the back of a thick sherd
    return plain


# --------------------------------------------------------------------------- atlas


def _shelf_pack(sizes, width, pad):
    """Bottom-up shelf packing of rectangles ``sizes`` (k, 2); positions and total height."""
    order = np.argsort(-sizes[:, 1], kind="stable")
    pos = np.zeros_like(sizes)
    x = y = float(pad)
    shelf = 0.0
    for i in order:
        w, hgt = sizes[i]
        if x + w + pad > width and x > pad:
            y += shelf + pad
            x, shelf = float(pad), 0.0
        pos[i] = (x, y)
        x += w + pad
        shelf = max(shelf, hgt)
    return pos, y + shelf + pad


def _atlas_coords(chart_uv, face_chart, size, rng):
    """Place per-chart layouts into a ``size``-pixel square: texture coords (m, 3, 2)."""
    import cv2

    n_ch = int(face_chart.max()) + 1
    dims = np.zeros((n_ch, 2))
    order = np.argsort(face_chart, kind="stable")
    bounds = np.searchsorted(face_chart[order], np.arange(n_ch + 1))
    local = chart_uv[order].reshape(-1, 2)
    for c in range(n_ch):
        uv = local[3 * bounds[c]:3 * bounds[c + 1]]  # a view: edited in place
        if len(uv) == 0:
            continue
        # align the chart's minimum-area box with the atlas, then a random quarter turn
        sub = uv[:: max(1, len(uv) // 60000)].astype(np.float32)
        (_, _), (_, _), box_deg = cv2.minAreaRect(sub)
        a = -math.radians(box_deg) + rng.integers(0, 4) * math.pi / 2
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        uv[:] = uv @ (rot.T * rng.uniform(0.8, 1.2))
        uv -= uv.min(axis=0)
        dims[c] = uv.max(axis=0)
    pad = 2 * _GUTTER_PX + 2
    lo, hi = 0.0, (size - 2 * pad) / max(dims.max(), 1e-12)
    for _ in range(50):
        k = 0.5 * (lo + hi)
        _, total = _shelf_pack(dims * k, size, pad)
        if total <= size and (dims * k).max() + 2 * pad <= size:
            lo = k
        else:
            hi = k
    pos, _ = _shelf_pack(dims * lo, size, pad)
    px = np.empty_like(chart_uv)
    px[order] = local.reshape(-1, 3, 2) * lo + pos[face_chart[order]][:, None, :]
    return px / size, lo


def _chart_layouts(V, F, vs, vth, face_part, face_handle, handle_radii, g: _Generatrix, n_sectors,
                   rng, preset=None):
    """Chart of every face and its corners' local 2D layout (mm), CCW.

    ``preset`` = (piece id per face, -1 for none; corner layouts (m, 3, 2)) for faces laid
    out by the caller (a sherd's break faces, welded handle roots), one chart per piece.
    """
    m = len(F)
    sc = vs[F].mean(axis=1)
    chart = np.full(m, -1, np.int64)
    uv = np.zeros((m, 3, 2))
    next_id = 0
    body = (face_part != PART_HANDLE) & (face_part != PART_BREAK)
    back = (face_part == PART_INNER) & (not math.isfinite(g.s_inner))  # a thick sherd's back
    # planar charts: the flat base and the inner floor
    for sel in (body & (sc < g.s_outer[0]), body & (sc > g.s_floor)):
        if np.any(sel):
            chart[sel] = next_id
            uv[sel] = V[F[sel]][:, :, :2]
            next_id += 1
    # wall charts: angle sectors x height bands, unwrapped (r * dtheta, s)
    phase = rng.uniform(0.0, 2 * math.pi)
    cth = np.arctan2(V[F, 1].mean(axis=1), V[F, 0].mean(axis=1))
    sector = np.floor(((cth - phase) % (2 * math.pi)) / (2 * math.pi / n_sectors)).astype(np.int64)
    sector = np.minimum(sector, n_sectors - 1)
    pieces = [(g.s_outer[0], g.s_outer[1]), (g.s_outer[1], g.s_floor)]
    for (lo, hi), rest in itertools.product(pieces, (body & ~back & (chart < 0), back)):
        if not math.isfinite(hi):
            continue
        edges = np.linspace(lo, hi, 3)
        band = np.clip(np.searchsorted(edges, sc, side="right") - 1, 0, 1)
        in_piece = rest & (sc >= lo) & (sc <= hi) if hi < g.s_floor else rest & (sc >= lo)
        for b in range(2):
            for k in range(n_sectors):
                sel = in_piece & (band == b) & (sector == k)
                if not np.any(sel):
                    continue
                centre = phase + (k + 0.5) * 2 * math.pi / n_sectors
                vv = F[sel]
                r = np.hypot(V[vv, 0], V[vv, 1])
                uv[sel, :, 0] = r * _wrap(vth[vv] - centre)
                uv[sel, :, 1] = vs[vv]
                chart[sel] = next_id
                next_id += 1
                rest &= ~sel
    if preset is not None:
        piece, corner_uv = preset
        for p in np.unique(piece[piece >= 0]):
            sel = piece == p
            uv[sel] = corner_uv[sel]
            chart[sel] = next_id
            next_id += 1
    # handles: two charts per tube (half turns), unwrapped (radius * dphi, arc length)
    for h, radius in enumerate(handle_radii):
        fsel = np.flatnonzero(face_handle == h)
        vv = F[fsel]
        cphi = np.arctan2(np.sin(vth[vv]).mean(axis=1), np.cos(vth[vv]).mean(axis=1)) % (2 * math.pi)
        for half in range(2):
            sel = fsel[(cphi >= math.pi) == bool(half)]
            if len(sel) == 0:
                continue
            vv = F[sel]
            uv[sel, :, 0] = radius * _wrap(vth[vv] - math.pi * (half + 0.5))
            uv[sel, :, 1] = vs[vv]
            chart[sel] = next_id
            next_id += 1
    if np.any(chart < 0):
        raise RuntimeError("face without a texture chart")
    # every chart counter-clockwise, like the surface seen from outside
    p = uv
    area = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
            - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    mirrored = np.bincount(chart, weights=area, minlength=next_id) < 0
    uv[mirrored[chart], :, 0] *= -1.0
    return chart, uv


def _render_atlas(vessel_paint, plain, V_world, F, face_part, texcoords, size, shade=None) -> np.ndarray:
    """Texture atlas: every texel painted at its 3D point, with gutters around the charts.

    Texels whose centre lies within :data:`_GUTTER_PX` pixels outside a chart take the
    painting at the nearest point of the nearest triangle, so bilinear sampling at chart
    borders never reads the background. ``shade(colours, world_points)``, when given,
    lights the texels' colours.
    """
    from potflat_synthetic._kernels import rasterize_faces

    tri = np.empty(texcoords.shape, np.float64)
    tri[..., 0] = texcoords[..., 0] * size
    tri[..., 1] = (1.0 - texcoords[..., 1]) * size
    face, bary, _ = rasterize_faces(np.ascontiguousarray(tri), size, size, float(_GUTTER_PX))
    cov = face >= 0
    fid = face[cov]
    P = np.einsum("nk,nkd->nd", bary[cov], V_world[F[fid]])
    colours = np.empty((len(fid), 3), np.uint8)
    part = face_part[fid]
    painted = np.ones(len(fid), bool)
    for p, rgb in plain.items():
        colours[part == p] = rgb
        painted &= part != p
    colours[painted] = vessel_paint(P[painted])
    if shade is not None:
        colours = shade(colours, P)
    img = np.empty((size, size, 3), np.uint8)
    img[:] = ATLAS_BACKGROUND
    img[cov] = colours
    return img


# --------------------------------------------------------------------------- public API


def _check_int(name, value, lo, hi):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
        raise InvalidOptionError(f"{name} must be an integer from {lo} to {hi}, got {value!r}")
    return int(value)


def _check_float(name, value, lo, hi):
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
            or not lo <= float(value) <= hi:
        raise InvalidOptionError(f"{name} must be a number from {lo} to {hi}, got {value!r}")
    return float(value)


def _random_pose(rng) -> np.ndarray:
    """Random rotation (axis at least 15 degrees from every coordinate axis) and shift."""
    from scipy.spatial.transform import Rotation

    while True:
        q = rng.normal(size=4)
        R = Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()
        if np.max(np.abs(R[:, 2])) < math.cos(math.radians(15.0)):
            break
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = rng.uniform(-150.0, 150.0, 3)
    return T


def make_vessel(
    kind: str,
    *,
    n_vertices: int = 20000,
    seed: int = 0,
    pose: bool = True,
    texture_size: int = 1024,
    base: bool | None = None,
    walls: int | None = None,
    thickness: float = 4.0,
    handles: bool | str = False,
    holes: int = 0,
    sherd_of: str = "hydria",
    sherd_span: float = 80.0,
    sherd_thickness: float = 0.0,
    painting: str = "frieze",
    shading: bool = False,
) -> SyntheticVessel:
    """Build a synthetic painted vessel with known axis, profile, painting and pose.

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`: a profile (``amphora`` ... ``aryballos``), a developable
        ``cylinder`` (R 100, H 200 mm) or ``cone`` frustum (R 60 -> 120 over 200 mm), a
        two-walled ``cup`` or ``bowl`` or a ``sherd`` (fragment of ``sherd_of``).
    n_vertices : int
        Target vertex count (about; the body alone), 500 to 20,000,000.
    seed : int
        Random seed: the same arguments give identical output.
    pose : bool
        Apply a random rotation and translation (axis not aligned to any coordinate axis).
    texture_size : int
        Side of the square texture atlas in pixels (64 to 16384).
    base : bool or None
        Close the foot with a flat base disc (default: only for ``cup`` and ``bowl``).
    walls : int or None
        1 = outer wall only; 2 = outer and inner wall joined by a rounded rim, a closed
        shell (``cup``, ``bowl`` and ``kylix`` only; default 2 for ``cup`` and ``bowl``). The inner floor carries
        a painted tondo.
    thickness : float
        Wall thickness in mm for ``walls=2`` (1 to 10).
    handles : bool or str
        Add handle tubes (``amphora``, ``hydria``, ``lekythos``, ``kylix``; ``bowl``: one
        handle arching over the rim from the outer wall into the inner wall), part of the
        same mesh (:data:`PART_HANDLE`). ``True`` or ``"intersecting"``: separate tubes whose
        open ends sink 2 mm into the intact wall (as in merged scans); ``"welded"``: the wall
        is cut around each root and stitched to the tube, one manifold surface of genus
        = number of handles (as in a single scan surface); ``"joined"``: stitched so, but
        the wall under each root kept, every edge of the root's outline shared by three faces
        (a non-manifold join).
    holes : int
        Number of holes cut into the painted outer wall (0 to 20).
    sherd_of : str
        Parent profile of a ``sherd``.
    sherd_span : float
        Angular width of a ``sherd`` in degrees (10 to 300); it covers about 60% of the
        wall height around the frieze, with irregular break edges.
    sherd_thickness : float
        0 = the sherd's painted outer surface only; otherwise (1 to 15 mm) a closed
        fragment: the back is the outer surface offset inwards along the section normal,
        joined by break faces (:data:`PART_BREAK`); back and breaks are plain clay.
    painting : str
        One of :data:`PAINTINGS`. ``frieze``: a frieze of circles between black bands, a
        hatched grid above and bars below on terracotta. ``belt``: the frieze between its
        bands, lustrous black glaze on the rest of the outer wall. ``panel``: a panel of
        100-140 degrees around a group of the frieze's circles, from the bars to the grid,
        black glaze elsewhere (also on the rest of the frieze). ``allover``: staggered rows of circles
        over the whole outer wall (where it is wide enough) on a lattice of thin lines, no
        large plain area. The painted zone is :meth:`SyntheticVessel.painted_zone`; the
        feature circles are those inside it.
    shading : bool
        Light the texture (and vertex colours) like a scan: a smooth gradient (factor
        :data:`SHADING_RANGE` across the vessel) and per-texel noise (:data:`SHADING_NOISE`
        grey levels). :meth:`SyntheticVessel.paint` stays the unlit painting. The mesh and
        painting do not depend on it.

    The options ``painting`` and ``shading`` are recorded in :attr:`SyntheticVessel.options`
    only when they are not the defaults, so existing vessels' files stay byte-identical.

    Returns
    -------
    SyntheticVessel
    """
    if kind not in KINDS:
        raise InvalidOptionError(f"unknown vessel kind {kind!r}; use one of {', '.join(KINDS)}")
    n_vertices = _check_int("n_vertices", n_vertices, 500, 20_000_000)
    seed = _check_int("seed", seed, 0, 2**63 - 1)
    texture_size = _check_int("texture_size", texture_size, 64, 16384)
    holes = _check_int("holes", holes, 0, 20)
    thickness = _check_float("thickness", thickness, 1.0, 10.0)
    sherd_span = _check_float("sherd_span", sherd_span, 10.0, 300.0)
    if sherd_thickness != 0:
        sherd_thickness = _check_float("sherd_thickness", sherd_thickness, 1.0, 15.0)
        if kind != "sherd":
            raise InvalidOptionError(f"sherd_thickness applies to kind 'sherd', not {kind!r}; drop it")
    if not isinstance(pose, bool):
        raise InvalidOptionError(f"pose must be True or False, got {pose!r}")
    if handles not in (False, True, "intersecting", "welded", "joined") or not isinstance(handles, (bool, str)):
        raise InvalidOptionError(f"handles must be False, True, 'intersecting', 'welded' or 'joined', got {handles!r}")
    handles = "intersecting" if handles is True else handles
    if painting not in PAINTINGS:
        raise InvalidOptionError(f"unknown painting {painting!r}; use one of {', '.join(PAINTINGS)}")
    if not isinstance(shading, bool):
        raise InvalidOptionError(f"shading must be True or False, got {shading!r}")
    if base is not None and not isinstance(base, bool):
        raise InvalidOptionError(f"base must be True, False or None, got {base!r}")
    parent = kind
    if kind == "sherd":
        if sherd_of not in _SPECS:
            raise InvalidOptionError(f"sherd_of must be one of {', '.join(_SPECS)}, got {sherd_of!r}")
        parent = sherd_of
        if handles or base or walls == 2:
            raise InvalidOptionError("a sherd has no handles, base or inner wall; drop those options")
    spec = _SPECS[parent]
    if walls is None:
        walls = 1 if kind == "sherd" else spec.walls
    if walls not in (1, 2) or isinstance(walls, bool):
        raise InvalidOptionError(f"walls must be 1 or 2, got {walls!r}")
    if walls == 2 and spec.floor is None:
        raise InvalidOptionError(f"walls=2 is available for cup, bowl and kylix, not {kind}; use walls=1")
    if handles and not spec.handles:
        raise InvalidOptionError(f"{kind} has no handles; use handles=False")
    base = (spec.base and kind != "sherd") if base is None else base
    options = dict(kind=kind, n_vertices=n_vertices, seed=seed, pose=pose, texture_size=texture_size,
                   base=base, walls=walls, thickness=thickness, handles=handles, holes=holes,
                   sherd_of=sherd_of if kind == "sherd" else None,
                   sherd_span=sherd_span if kind == "sherd" else None,
                   sherd_thickness=float(sherd_thickness) if kind == "sherd" else None)
    if painting != "frieze":
        options["painting"] = painting
    if shading:
        options["shading"] = True

    rng = np.random.default_rng(seed)
    g = _build_generatrix(spec, walls=walls, base=base, thickness=thickness)
    painting = _layout_painting(g, spec, walls, rng, painting)

    region = None
    n_body = n_vertices
    if kind == "sherd":
        region = _sherd_region(g, painting, sherd_span, rng)
        n_body = int(min(20_000_000, n_vertices / region[-1]))
    V, F, vs, vth, h = _revolve(g, n_body, rng)
    vertex_part = _parts_of(g, vs)
    face_part = _parts_of(g, vs[F].mean(axis=1))
    face_handle = np.full(len(F), -1, np.int64)
    handle_radii = []
    ends = []
    if handles:
        for hd in spec.handles:
            hV, hF, hs, hphi, hends = _handle_mesh(g, hd, h, rng, sink=2.0 if handles == "intersecting" else 0.0)
            ends += [(A, nA, ring + len(V), hd.radius, part) for A, nA, ring, part in hends]
            F = np.concatenate([F, hF + len(V)])
            V = np.concatenate([V, hV])
            vs, vth = np.concatenate([vs, hs]), np.concatenate([vth, hphi])
            vertex_part = np.concatenate([vertex_part, np.full(len(hV), PART_HANDLE, np.int8)])
            face_part = np.concatenate([face_part, np.full(len(hF), PART_HANDLE, np.int8)])
            face_handle = np.concatenate([face_handle, np.full(len(hF), len(handle_radii))])
            handle_radii.append(hd.radius)
    preset = None  # caller-made chart layouts: (piece per face or -1, corner layouts)
    if handles in ("welded", "joined"):
        chi = len(V) - len(np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]),
                                                  axis=1), axis=0)) + len(F)
        V, F, (vs, vth, vertex_part), (face_part, face_handle), weld = _weld_handles(
            V, F, [vs, vth, vertex_part], [face_part, face_handle], ends, h, keep_wall=handles == "joined")
        if handles == "welded":
            _check_manifold(F, len(V), holes_expected=2 - (chi - 2 * len(spec.handles)))
        preset = (np.full(len(F), -1, np.int64), np.zeros((len(F), 3, 2)))
        preset[0][weld[0]], preset[1][weld[0]] = weld[2], weld[1]

    remove = np.zeros(len(F), bool)
    circles = painting.circles
    if region is not None:
        inside, circle_ok = region[0], region[1]
        cth = np.arctan2(V[F, 1].mean(axis=1), V[F, 0].mean(axis=1))
        keep = (face_part == PART_OUTER) & inside(cth, vs[F].mean(axis=1))
        keep = _largest_component(F, keep)
        remove = _remove_faces(F, ~keep)
        remove = ~_largest_component(F, ~remove)
        circles = tuple(c for c in circles if circle_ok(c))
    hole_list = []
    if holes:
        avoid = [(A, a + 2 * h + 5.0) for A, _, _, a, _ in ends]
        hole_list = _place_holes(g, painting, holes, rng, region, avoid)
        cen = V[F].mean(axis=1)
        for hc, hr in hole_list:
            remove |= (face_part == PART_OUTER) & (np.linalg.norm(cen - hc, axis=1) <= hr)
        remove = _remove_faces(F, remove)
    if np.any(remove):
        F, face_part, face_handle = F[~remove], face_part[~remove], face_handle[~remove]
        if preset is not None:
            preset = (preset[0][~remove], preset[1][~remove])
        V, F, vs, vth, vertex_part = _compact(V, F, vs, vth, vertex_part)

    if kind == "sherd" and sherd_thickness > 0:
        V, F, vs, vth, face_part, vertex_part, breaks = _thicken_sherd(g, V, F, vs, vth, sherd_thickness)
        face_handle = np.full(len(F), -1, np.int64)
        preset = (np.full(len(F), -1, np.int64), np.zeros((len(F), 3, 2)))
        preset[0][breaks[0]], preset[1][breaks[0]] = breaks[2], breaks[1]
    n_sectors = 12 if kind == "sherd" else 4
    face_chart, chart_uv = _chart_layouts(V, F, vs, vth, face_part, face_handle, handle_radii,
                                          g, n_sectors, rng, preset)
    texcoords, _ = _atlas_coords(chart_uv, face_chart, texture_size, rng)

    T = _random_pose(rng) if pose else np.eye(4)
    R, t = T[:3, :3], T[:3, 3]
    Vw = V @ R.T + t
    mesh = Mesh(Vw, F, texcoords=texcoords, units="mm")
    features = tuple(
        PaintedCircle(c.centre @ R.T + t, c.radius, c.colour, c.side, c.height, c.angle) for c in circles
    )
    _, prof_r, prof_z = _outer_polyline(g)
    profile = np.stack([prof_z, prof_r], axis=1)
    vessel = SyntheticVessel(
        kind=kind, mesh=mesh, texture=np.zeros((1, 1, 3), np.uint8),
        axis_point=t.copy(), axis_direction=R[:, 2].copy(), profile=profile,
        generatrix=np.stack([g.r, g.z], axis=1), painting=painting, features=features,
        holes=tuple(Hole(hc @ R.T + t, hr) for hc, hr in hole_list), pose=T,
        face_part=face_part, vertex_part=vertex_part, face_chart=face_chart, options=options,
        _geometry=g,
    )
    shade = None
    if shading:
        def shade(colours, P):
            return _shade(colours, vessel.to_canonical(P), g, _shading_rng(seed, 0))
    texture = _render_atlas(vessel.paint, _plain_colours(g), Vw, F, face_part, texcoords, texture_size, shade)
    object.__setattr__(vessel, "texture", texture)
    return vessel


def _parts_of(g: _Generatrix, s) -> np.ndarray:
    part = np.full(len(s), PART_OUTER, np.int8)
    part[s < g.s_outer[0]] = PART_BASE
    part[s > g.s_outer[1]] = PART_RIM
    part[s > g.s_inner] = PART_INNER
    return part


def _sherd_region(g: _Generatrix, painting: Painting, span_deg: float, rng):
    """Region test of a sherd around the first frieze circle, and its area fraction."""
    c0 = painting.circles[0]
    s_lo_w, s_hi_w = g.s_outer
    sf = float(_project_to_generatrix(g, np.array([math.hypot(*c0.centre[:2])]), np.array([c0.centre[2]]))[0])
    half_s = 0.3 * (s_hi_w - s_lo_w)
    s0, s1 = max(s_lo_w, sf - half_s), min(s_hi_w, sf + half_s)
    span = math.radians(span_deg)
    th0 = c0.angle + rng.uniform(-0.2, 0.2) * span
    amp_t, amp_s = 0.08 * span / 2, 0.1 * (s1 - s0) / 2
    n1 = (rng.uniform(0, 2 * math.pi, 3), rng.uniform(-1, 1, 3))
    n2 = (rng.uniform(0, 2 * math.pi, 3), rng.uniform(-1, 1, 3))

    def noise(n, x):
        ph, a = n
        return sum(a[k] * np.sin((k + 1) * x + ph[k]) for k in range(3)) / 3.0

    def inside(theta, s):
        d = _wrap(theta - th0)
        u = 2 * math.pi * (np.asarray(s) - s0) / max(s1 - s0, 1e-9)
        ok_t = np.abs(d) <= span / 2 + amp_t * noise(n1, u)
        ok_s = (s >= s0 + amp_s * noise(n2, d * 2 * math.pi / span)) & \
               (s <= s1 + amp_s * noise(n2, d * 2 * math.pi / span + 1.0))
        return ok_t & ok_s

    def circle_ok(c):
        r = math.hypot(*c.centre[:2])
        sc = float(_project_to_generatrix(g, np.array([r]), np.array([c.centre[2]]))[0])
        a = np.linspace(0, 2 * math.pi, 32, endpoint=False)
        m = c.radius + 6.0
        return bool(np.all(inside(c.angle + m * np.cos(a) / r, sc + m * np.sin(a))))

    sel = (g.s >= s0) & (g.s <= s1)
    rs = g.r * sel
    frac = (span / (2 * math.pi)) * np.trapezoid(rs, g.s) / np.trapezoid(g.r, g.s)
    return inside, circle_ok, float(frac)


def _place_holes(g: _Generatrix, painting: Painting, n: int, rng, region, avoid):
    """Hole centres and radii on the painted outer wall, clear of circles, of the discs
    ``avoid`` (centre, radius) and of each other."""
    z_lo = float(np.interp(g.s_outer[0], g.s, g.z))
    z_hi = float(np.interp(g.s_outer[1], g.s, g.z))
    H = z_hi - z_lo
    zf = painting.circles[0].height
    a, b = max(z_lo + 0.1 * H, zf - 40.0), min(z_hi - 0.1 * H, zf + 40.0)
    prof_s, pr, pz = _outer_polyline(g)
    out = []
    for _ in range(2000):
        if len(out) == n:
            return out
        z = rng.uniform(a, b)
        th = rng.uniform(0, 2 * math.pi)
        rad = rng.uniform(6.0, 12.0)
        r = float(np.interp(z, pz, pr))
        c = np.array([r * math.cos(th), r * math.sin(th), z])
        if any(np.linalg.norm(c - pc.centre) < pc.radius + rad + 3.0 for pc in painting.circles):
            continue
        if any(np.linalg.norm(c - oc) < orad + rad + 6.0 for oc, orad in out + avoid):
            continue
        if region is not None:
            sc = float(np.interp(z, pz, prof_s))
            aa = np.linspace(0, 2 * math.pi, 32, endpoint=False)
            if not np.all(region[0](th + (rad + 8.0) * np.cos(aa) / r, sc + (rad + 8.0) * np.sin(aa))):
                continue
        out.append((c, rad))
    raise InvalidOptionError(f"cannot place {n} holes on this {'sherd' if region else 'vessel'}; use fewer")


# --------------------------------------------------------------------------- writers


def obj_texcoord_indices(vessel: SyntheticVessel) -> tuple[np.ndarray, np.ndarray]:
    """The OBJ ``vt`` table: one entry per (vertex, chart) pair.

    Returns
    -------
    vt : (t, 2) float64
        Texture coordinates.
    corner_vt : (m, 3) int64
        0-based ``vt`` index of every face corner.
    """
    F = vessel.mesh.faces
    n_ch = int(vessel.face_chart.max()) + 1
    key = (F * n_ch + vessel.face_chart[:, None]).ravel()
    _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    vt = vessel.mesh.texcoords.reshape(-1, 2)[first]
    return vt, inv.reshape(F.shape).astype(np.int64)


def write_obj(vessel: SyntheticVessel, path: str | os.PathLike) -> Path:
    """Write ``vessel`` as OBJ + MTL + PNG (``NAME.obj``, ``NAME.mtl``, ``NAME.png``).

    One ``v`` per 3D point (mm) and one ``vt`` per (vertex, texture chart): where charts
    meet, a vertex has several texture coordinates, so a loader must weld by position.
    Faces are ``f v/vt`` triples, counter-clockwise seen from outside. Every file is
    written atomically; the OBJ last.

    Parameters
    ----------
    vessel : SyntheticVessel
    path : path-like
        Output ``.obj`` path; the MTL and PNG are written beside it with the same stem.

    Returns
    -------
    Path
        The OBJ path.
    """
    import cv2

    from potflat.io.atomic import write_bytes_atomic
    from potflat.io.obj import write_textured_obj

    path = Path(path)
    if path.suffix.lower() != ".obj":
        raise InvalidOptionError(f"{path} does not end in .obj; give an .obj output path")
    png = path.with_suffix(".png")
    ok, buf = cv2.imencode(".png", vessel.texture[:, :, ::-1], [cv2.IMWRITE_PNG_COMPRESSION, 9])
    if not ok:
        raise RuntimeError("PNG encoding failed")
    write_bytes_atomic(png, buf.tobytes())
    vt, corner_vt = obj_texcoord_indices(vessel)
    return write_textured_obj(path, vessel.mesh.vertices, vessel.mesh.faces, vt, corner_vt, png.name,
                              header=f"potflat synthetic {vessel.kind} seed {vessel.options['seed']}, units mm",
                              vertex_format="%.4f")


def write_ply_colored(vessel: SyntheticVessel, path: str | os.PathLike) -> Path:
    """Write ``vessel`` as a binary little-endian PLY with per-vertex painting colours.

    Vertex properties ``x y z`` (double, mm) and ``red green blue`` (uchar); faces
    ``vertex_indices`` (uchar count, int indices), counter-clockwise seen from outside.

    Returns
    -------
    Path
        ``path``.
    """
    from potflat.io.atomic import write_bytes_atomic

    path = Path(path)
    mesh = vessel.mesh
    n, m = len(mesh.vertices), len(mesh.faces)
    vert = np.empty(n, dtype=[("x", "<f8"), ("y", "<f8"), ("z", "<f8"),
                              ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    vert["x"], vert["y"], vert["z"] = mesh.vertices.T
    col = vessel.vertex_colors()
    vert["red"], vert["green"], vert["blue"] = col.T
    face = np.empty(m, dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face["n"] = 3
    face["i"] = mesh.faces
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"comment potflat synthetic {vessel.kind} seed {vessel.options['seed']}\n"
        "comment units mm\n"
        f"element vertex {n}\nproperty double x\nproperty double y\nproperty double z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        f"element face {m}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    return write_bytes_atomic(path, header.encode("ascii") + vert.tobytes() + face.tobytes())


def truth(vessel: SyntheticVessel) -> dict:
    """JSON-ready ground truth: axis, pose, profile, painted features, holes, options.

    The profile is sampled about every millimetre of arc length (interpolating it
    linearly is then within a few micrometres of the exact polyline, see
    :attr:`SyntheticVessel.profile`).
    """
    p = vessel.painting
    prof = vessel.profile
    step = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(prof, axis=0), axis=1))])
    keep = np.unique(np.concatenate([np.searchsorted(step, np.arange(0.0, step[-1], 1.0)),
                                     [len(prof) - 1]]))
    return {
        "kind": vessel.kind,
        "units": "mm",
        "options": vessel.options,
        "axis_point": vessel.axis_point,
        "axis_direction": vessel.axis_direction,
        "pose": vessel.pose,
        "profile": {"height": prof[keep, 0].round(6), "radius": prof[keep, 1].round(6),
                    "note": "outer wall, sampled about every 1 mm of arc length"},
        "circles": [{"centre": c.centre, "radius": c.radius, "colour": list(c.colour),
                     "side": c.side, "height": c.height, "angle": c.angle} for c in vessel.features],
        "bands": [{"z_low": lo if math.isfinite(lo) else None, "z_high": hi if math.isfinite(hi) else None,
                   "colour": list(c)} for lo, hi, c in p.bands],
        "bars": [{"angle": a, "width": w, "z_low": lo, "z_high": hi, "colour": list(c)}
                 for a, w, lo, hi, c in p.bars],
        "holes": [{"centre": h.centre, "radius": h.radius} for h in vessel.holes],
        "counts": {"vertices": len(vessel.mesh.vertices), "faces": len(vessel.mesh.faces),
                   "charts": int(vessel.face_chart.max()) + 1},
    }


def write_truth(vessel: SyntheticVessel, path: str | os.PathLike) -> Path:
    """Write :func:`truth` as JSON (atomically); returns ``path``."""
    from potflat.io.atomic import write_json_atomic

    return write_json_atomic(path, truth(vessel))
