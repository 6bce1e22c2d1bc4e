"""Relief decoration with known answers: incised lines and relief dots of known depth, height
and width on curved vessels, with and without scanner noise.

:func:`relief_patch` meshes a piece of a vessel's wall (the shoulder of a hydria by default,
or a sphere) finely enough to resolve sub-millimetre detail and cuts grooves into it and
raises dots on it; :func:`relief_vessel` does the same on a whole vessel (a bulgy hydria or a
spherical body, open at both ends), meshed like :func:`potflat_synthetic.vessels.make_vessel`
meshes one. Every feature has a raised-cosine section: a groove of depth ``D`` and width
``W`` lies ``D (1 + cos(2 pi d / W)) / 2`` below the wall at distance ``d < W / 2`` from its
centre line, a dot of height ``D`` and diameter ``W`` as far above it. The displacement is
along the wall's normal, so the relief measured against the smooth wall is exactly the
displacement (:attr:`ReliefScan.relief_mm`); scanner noise is added after, as a Gaussian
displacement of each vertex along the normal. Units are mm; the scans are untextured, in the
canonical frame of :mod:`potflat_synthetic.vessels` (axis = z, foot at the origin).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from potflat_synthetic.geometry import (
    _Generatrix,
    _normals2d,
    _planar_delaunay,
    _project_to_generatrix,
    _revolve,
)
from potflat_synthetic.spec import _SPECS
from potflat_synthetic.vessels import _check_float, _check_int

from potflat.errors import InvalidOptionError
from potflat.types import FlatMesh, Mesh

#: Walls :func:`relief_patch` and :func:`relief_vessel` can carry the decoration on.
RELIEF_KINDS = ("hydria", "sphere")
#: Radius (mm) of the sphere kind; its body spans latitudes within :data:`SPHERE_LATITUDE` degrees.
SPHERE_RADIUS = 60.0
SPHERE_LATITUDE = 70.0
#: Height along the hydria's wall (arc length from its foot, mm) of a patch's centre: its shoulder,
#: curved both ways (radius about 115 mm about the axis, 75-500 mm along the profile).
HYDRIA_SHOULDER_S = 350.0

#: The default decoration of a patch: grooves ``(depth, width)`` in mm, each a vertical line
#: (along the wall's meridian) and a horizontal one (along a parallel), and dots ``(height,
#: diameter)`` in mm.
DEFAULT_GROOVES = ((0.1, 0.5), (0.2, 0.5), (0.5, 0.5), (0.2, 0.3))
DEFAULT_DOTS = ((0.1, 0.5), (0.2, 0.5), (0.5, 0.5), (0.3, 1.0))
#: Spacing (mm) of the features on a patch, and their clearance from its border.
FEATURE_PITCH = 3.0
BORDER_MM = 5.0


@dataclass(frozen=True)
class Groove:
    """An incised line of raised-cosine section.

    Attributes
    ----------
    direction : str
        ``"meridian"`` (along the wall from foot to mouth, at angle :attr:`at`) or
        ``"parallel"`` (around the wall, at arc length :attr:`at` from the wall's start).
    at : float
        The centre line's angle about the axis (rad) or its arc length along the profile (mm).
    span : (float, float)
        Where it runs: arc lengths (mm) of a meridian's ends, angles (rad) of a parallel's.
    depth, width : float
        mm.
    """

    direction: str
    at: float
    span: tuple
    depth: float
    width: float


@dataclass(frozen=True)
class Dot:
    """A relief dot (a boss) of raised-cosine section: ``height`` and ``diameter`` in mm, centred
    at arc length ``s`` (mm) along the profile and angle ``theta`` (rad) about the axis."""

    s: float
    theta: float
    height: float
    diameter: float


@dataclass(frozen=True, eq=False)
class ReliefScan:
    """A scan of a decorated wall and the truth about its relief.

    Attributes
    ----------
    kind : str
        One of :data:`RELIEF_KINDS`.
    mesh : Mesh
        The scan (mm, canonical frame, faces counter-clockwise seen from outside), untextured.
    uv : (n, 2) float64
        A development of the smooth wall: ``u = r(s0) (theta - theta0)``, ``v = s`` (arc
        length along the profile), about the patch's centre ``s0, theta0``: isometric up to the
        change of radius across the patch (a patch only; None for a whole vessel).
    grooves : tuple of Groove
    dots : tuple of Dot
    noise_mm : float
        Standard deviation of the scanner noise added along the normal.
    relief_mm : (n,) float64
        The decoration's displacement of each vertex along the wall's outward normal (without
        the noise): what a relief measurement should find.
    s, theta : (n,) float64
        Each vertex's arc length along the profile and angle about the axis.
    """

    kind: str
    mesh: Mesh
    uv: np.ndarray | None
    grooves: tuple
    dots: tuple
    noise_mm: float
    relief_mm: np.ndarray
    s: np.ndarray
    theta: np.ndarray
    _geometry: _Generatrix

    @property
    def flat(self) -> FlatMesh:
        """The scan with its development :attr:`uv` (a patch only)."""
        if self.uv is None:
            raise ValueError("a whole vessel has no development here; flatten it with potflat")
        return FlatMesh(self.mesh, self.uv)

    def radius_at(self, s) -> np.ndarray:
        """The wall's radius (mm) at arc lengths ``s`` along the profile."""
        return np.interp(np.asarray(s, float), self._geometry.s, self._geometry.r)

    def wall_points(self, s, theta) -> np.ndarray:
        """Points ``(k, 3)`` of the smooth wall at arc lengths ``s`` and angles ``theta``."""
        return _wall(self._geometry, np.asarray(s, float).ravel(), np.asarray(theta, float).ravel())[0]

    def wall_coordinates(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Arc length ``s`` (mm) and angle ``theta`` (rad) of the points of the wall nearest
        ``points`` ``(k, 3)`` (on or near the scan)."""

        p = np.asarray(points, float).reshape(-1, 3)
        return _project_to_generatrix(self._geometry, np.hypot(p[:, 0], p[:, 1]), p[:, 2]), np.arctan2(p[:, 1], p[:, 0])

    def relief_at(self, points) -> np.ndarray:
        """The decoration's displacement (mm) at the points of the wall nearest ``points``
        ``(k, 3)``: the relief a measurement should find there."""
        return displacement(self._geometry, *self.wall_coordinates(points), self.grooves, self.dots)

    def distance_on_wall(self, feature, points) -> np.ndarray:
        """How far (mm, along the wall) the points of the wall nearest ``points`` ``(k, 3)`` lie
        from a groove's centre line (inf off its span) or a dot's centre."""
        s, theta = self.wall_coordinates(points)
        if isinstance(feature, Dot):
            centre = self.wall_points([feature.s], [feature.theta])
            return np.linalg.norm(self.wall_points(s, theta) - centre, axis=1)
        d, inside = _groove_distance(self._geometry, s, theta, feature)
        return np.where(inside, np.abs(d), np.inf)


def _sphere_generatrix() -> _Generatrix:
    """The section of a spherical body: a circular arc of :data:`SPHERE_RADIUS` between
    latitudes -:data:`SPHERE_LATITUDE` and +:data:`SPHERE_LATITUDE` (open at both ends)."""
    lat = np.radians(np.linspace(-SPHERE_LATITUDE, SPHERE_LATITUDE, 4097))
    r = SPHERE_RADIUS * np.cos(lat)
    z = SPHERE_RADIUS * (np.sin(lat) + math.sin(math.radians(SPHERE_LATITUDE)))
    s = SPHERE_RADIUS * (lat - lat[0])
    return _Generatrix(r=r, z=z, s=s, s_outer=(0.0, float(s[-1])), s_inner=math.inf, s_floor=math.inf)


def _generatrix(kind: str) -> _Generatrix:
    """The wall's section: the sphere's arc, or a C2 cubic spline through the vessel's profile
    points (a thrown wall curves smoothly; the piecewise-cubic profile of
    :func:`potflat_synthetic.vessels.make_vessel` bends by steps at its points, which a
    relief measurement would rightly show as faint lines)."""
    if kind not in RELIEF_KINDS:
        raise InvalidOptionError(f"unknown relief kind {kind!r}; use one of {', '.join(RELIEF_KINDS)}")
    if kind == "sphere":
        return _sphere_generatrix()
    from scipy.interpolate import CubicSpline

    pts = np.asarray(_SPECS[kind].points, float)
    t = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(pts, axis=0).T))])
    tt = np.linspace(0.0, t[-1], 16385)
    z = CubicSpline(t, pts[:, 0])(tt)
    r = CubicSpline(t, pts[:, 1])(tt)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(r), np.diff(z)))])
    return _Generatrix(r=r, z=z, s=s, s_outer=(0.0, float(s[-1])), s_inner=math.inf, s_floor=math.inf)


def _wall(g: _Generatrix, s: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points and unit outward normals ``(k, 3)`` of the wall at arc lengths ``s``, angles ``theta``."""
    r = np.interp(s, g.s, g.r)
    z = np.interp(s, g.s, g.z)
    nrm = _normals2d(g.r, g.z)
    nr = np.interp(s, g.s, nrm[:, 0])
    nz = np.interp(s, g.s, nrm[:, 1])
    c, sn = np.cos(theta), np.sin(theta)
    P = np.stack([r * c, r * sn, z], axis=1)
    N = np.stack([nr * c, nr * sn, nz], axis=1)
    return P, N / np.linalg.norm(N, axis=1, keepdims=True)


def _raised_cosine(d: np.ndarray, width: float) -> np.ndarray:
    """``(1 + cos(2 pi d / width)) / 2`` within ``width / 2`` of 0, else 0."""
    return np.where(np.abs(d) < 0.5 * width, 0.5 * (1.0 + np.cos(2.0 * math.pi * d / width)), 0.0)


def _groove_distance(g: _Generatrix, s: np.ndarray, theta: np.ndarray, groove: Groove):
    """Signed distance (mm, along the wall) of wall points from a groove's centre line, and
    whether they lie along its span."""
    if groove.direction == "meridian":
        d = np.interp(s, g.s, g.r) * ((theta - groove.at + math.pi) % (2 * math.pi) - math.pi)
        return d, (s >= groove.span[0]) & (s <= groove.span[1])
    arc = groove.span[1] - groove.span[0]
    inside = ((theta - groove.span[0]) % (2 * math.pi) <= arc) if arc < 2 * math.pi else np.ones(len(s), bool)
    return s - groove.at, inside


def displacement(g: _Generatrix, s: np.ndarray, theta: np.ndarray, grooves, dots) -> np.ndarray:
    """The decoration's displacement (mm, along the outward normal) at arc lengths ``s`` and
    angles ``theta`` of the wall: minus each groove's depth profile, plus each dot's."""
    out = np.zeros(len(s))
    for gr in grooves:
        d, inside = _groove_distance(g, s, theta, gr)
        out -= gr.depth * _raised_cosine(d, gr.width) * inside
    if dots:
        P = _wall(g, s, theta)[0]
        for dot in dots:
            C = _wall(g, np.array([dot.s]), np.array([dot.theta]))[0][0]
            out += dot.height * _raised_cosine(np.linalg.norm(P - C, axis=1), dot.diameter)
    return out


def _decorate(kind, g, P, F, s, theta, grooves, dots, noise_mm, seed, uv) -> ReliefScan:
    relief = displacement(g, s, theta, grooves, dots)
    _, N = _wall(g, s, theta)
    noise = np.random.default_rng([seed, 1]).normal(0.0, noise_mm, len(s)) if noise_mm > 0 else 0.0
    V = P + (relief + noise)[:, None] * N
    return ReliefScan(kind=kind, mesh=Mesh(V, F, units="mm"), uv=uv, grooves=tuple(grooves), dots=tuple(dots),
                      noise_mm=float(noise_mm), relief_mm=relief, s=s, theta=theta, _geometry=g)


def _check_features(grooves, dots) -> None:
    for depth, width in grooves:
        _check_float("groove depth", depth, 0.01, 5.0)
        _check_float("groove width", width, 0.05, 20.0)
    for height, diameter in dots:
        _check_float("dot height", height, 0.01, 5.0)
        _check_float("dot diameter", diameter, 0.05, 20.0)


def relief_patch(kind: str = "hydria", *, size_mm: float = 36.0, spacing_mm: float = 0.1,
                 grooves=DEFAULT_GROOVES, dots=DEFAULT_DOTS, noise_mm: float = 0.0, seed: int = 0) -> ReliefScan:
    """A square piece of a vessel's wall with grooves and dots of known depth and width.

    The patch is centred on the hydria's shoulder (:data:`HYDRIA_SHOULDER_S`) or on the
    sphere's equator, ``size_mm`` along the profile and as wide around the axis, meshed with
    jittered rows of vertices about ``spacing_mm`` apart (planar Delaunay in the development).
    Each ``(depth, width)`` of ``grooves`` is cut twice: as a parallel line across the lower
    half of the patch and as a meridian line in the upper half, from the left; the ``(height,
    diameter)`` of ``dots`` are raised in a row across the upper half, from the right. Lines and
    dots are :data:`FEATURE_PITCH` apart and :data:`BORDER_MM` from the border.

    Parameters
    ----------
    kind : str
        One of :data:`RELIEF_KINDS`.
    size_mm : float
        Side of the patch, 10 to 200 mm; it must hold the features at their pitch.
    spacing_mm : float
        Vertex spacing, 0.02 to 5 mm.
    grooves, dots : sequence of (float, float)
        mm; depths and heights 0.01-5, widths and diameters 0.05-20.
    noise_mm : float
        Scanner noise (standard deviation along the normal, mm), 0 to 1.
    seed : int

    Returns
    -------
    ReliefScan
        With :attr:`ReliefScan.uv`, the development.
    """
    size = _check_float("size_mm", size_mm, 10.0, 200.0)
    h = _check_float("spacing_mm", spacing_mm, 0.02, 5.0)
    noise_mm = _check_float("noise_mm", noise_mm, 0.0, 1.0)
    seed = _check_int("seed", seed, 0, 2**63 - 1)
    grooves, dots = tuple(grooves), tuple(dots)
    _check_features(grooves, dots)
    if (2 * BORDER_MM + (len(grooves) + len(dots)) * FEATURE_PITCH > size
            or 2 * BORDER_MM + 2 * len(grooves) * FEATURE_PITCH > size):
        raise InvalidOptionError(f"a patch of {size:g} mm cannot hold {len(grooves)} grooves and {len(dots)} dots "
                                 f"{FEATURE_PITCH:g} mm apart; make it larger")
    if (size / h) ** 2 > 4e6:
        raise InvalidOptionError(f"a {size:g} mm patch at {h:g} mm spacing would have over 4M vertices")
    g = _generatrix(kind)
    s0 = HYDRIA_SHOULDER_S if kind == "hydria" else 0.5 * float(g.s[-1])
    r0 = float(np.interp(s0, g.s, g.r))
    rng = np.random.default_rng(seed)
    dv = h * math.sqrt(3.0) / 2.0
    rows = np.arange(-0.5 * size, 0.5 * size + 1e-9, dv)
    cols = np.arange(-0.5 * size, 0.5 * size + 1e-9, h)
    U, Vv = np.meshgrid(cols, rows)
    U = U + np.where(np.arange(len(rows)) % 2, 0.5 * h, 0.0)[:, None]
    U += rng.uniform(-0.2, 0.2, U.shape) * h
    Vv = Vv + rng.uniform(-0.2, 0.2, Vv.shape) * dv
    keep = (np.abs(U) <= 0.5 * size) & (np.abs(Vv) <= 0.5 * size)
    uv = np.stack([U[keep], Vv[keep]], axis=1)
    s = s0 + uv[:, 1]
    theta = uv[:, 0] / r0
    F = _planar_delaunay(uv).astype(np.int64)
    e1, e2 = uv[F[:, 1]] - uv[F[:, 0]], uv[F[:, 2]] - uv[F[:, 0]]
    back = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    F[back] = F[back][:, ::-1]
    lo = -0.5 * size + BORDER_MM
    hi = 0.5 * size - BORDER_MM
    found_grooves = []
    for k, (depth, width) in enumerate(grooves):
        at = lo + (k + 0.5) * FEATURE_PITCH
        found_grooves.append(Groove("parallel", s0 - 0.5 * FEATURE_PITCH - k * FEATURE_PITCH, (lo / r0, hi / r0),
                                    float(depth), float(width)))
        found_grooves.append(Groove("meridian", at / r0, (s0 + 0.5 * FEATURE_PITCH, s0 + hi), float(depth),
                                    float(width)))
    found_dots = [Dot(s0 + 0.5 * (0.5 * FEATURE_PITCH + hi), (hi - (k + 0.5) * FEATURE_PITCH) / r0, float(height),
                      float(diameter)) for k, (height, diameter) in enumerate(dots)]
    P = _wall(g, s, theta)[0]
    return _decorate(kind, g, P, F, s, theta, found_grooves, found_dots, noise_mm, seed, np.ascontiguousarray(uv))


def relief_vessel(kind: str = "hydria", *, n_vertices: int = 250000, grooves=((0.5, 3.0),), dots=((0.5, 4.0),),
                  noise_mm: float = 0.0, seed: int = 0) -> ReliefScan:
    """A whole vessel (open at foot and mouth) with grooves around it and dots on it.

    The wall is meshed as :func:`potflat_synthetic.vessels.make_vessel` meshes one (jittered
    rings joined by strips, no seam). Each ``(depth, width)`` of ``grooves`` is cut as a
    parallel all the way round and as a meridian from foot to mouth (at angles spread over
    the circumference); the ``(height, diameter)`` of ``dots`` are raised on a ring around the
    widest part. The vertices are far apart on a whole vessel (1.25 mm on the hydria at the
    default size), so the default features are wide enough for the mesh to hold them.

    Parameters
    ----------
    kind : str
        One of :data:`RELIEF_KINDS`.
    n_vertices : int
        About, 2000 to 5,000,000.
    grooves, dots : sequence of (float, float)
        mm, as :func:`relief_patch` takes them.
    noise_mm : float
    seed : int

    Returns
    -------
    ReliefScan
        Without a development (``uv`` None).
    """
    n_vertices = _check_int("n_vertices", n_vertices, 2000, 5_000_000)
    noise_mm = _check_float("noise_mm", noise_mm, 0.0, 1.0)
    seed = _check_int("seed", seed, 0, 2**63 - 1)
    grooves, dots = tuple(grooves), tuple(dots)
    _check_features(grooves, dots)
    g = _generatrix(kind)
    P, F, s, theta, _ = _revolve(g, n_vertices, np.random.default_rng(seed))
    length = float(g.s[-1])
    widest = float(g.s[int(np.argmax(g.r))])
    found_grooves = []
    for k, (depth, width) in enumerate(grooves):
        found_grooves.append(Groove("parallel", length * (k + 1) / (len(grooves) + 2), (0.0, 2 * math.pi),
                                    float(depth), float(width)))
        found_grooves.append(Groove("meridian", 2 * math.pi * (k + 0.5) / max(len(grooves), 1) - math.pi,
                                    (0.1 * length, 0.9 * length), float(depth), float(width)))
    found_dots = [Dot(widest, 2 * math.pi * (k + 0.25) / max(len(dots), 1) - math.pi, float(height),
                      float(diameter)) for k, (height, diameter) in enumerate(dots)]
    return _decorate(kind, g, P, F, s, theta, found_grooves, found_dots, noise_mm, seed, None)
