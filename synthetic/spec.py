"""What a synthetic vessel is made of: its kinds and parts, colours, profiles and painted
features (the data :func:`potflat_synthetic.vessels.make_vessel` builds from).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Vessel kinds accepted by :func:`potflat_synthetic.vessels.make_vessel`.
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

