"""Landmarks on the vessel that the seam and angle ranges are measured from.

A user names a landmark instead of an angle from the axis' reference direction (which
depends on the scan's pose): a 3D point on the surface (``seam_at``, e.g. picked in
MeshLab), the centre of the painted zone (the seam goes opposite it) or the largest handle
(the seam goes through it). ``--seam DEG`` and ``--angles A0 A1`` are then measured from
the landmark; ``--angles`` alone centres the window on the painted zone.

The painted zone is the rollout's importance zone (:mod:`potflat.importance`: found in the
colours, or given as a mask or a band); its centre is the area-weighted circular mean angle
of the zone. Without a zone (no colours, ``importance none``) or when it goes round evenly,
the centre is taken opposite the least painted place (the automatic seam) and the JSON says so.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from potflat.errors import InvalidOptionError
from potflat.mesh.tolerances import DEGENERATE

#: The painting's contrast has a centre when its weighted circular mean has at least this
#: length (1 = all in one direction, 0 = evenly round).
MIN_PAINTED_RESULTANT = 0.05
#: A ``seam_at`` point farther than this fraction of the vessel's height from every vertex
#: is refused (a typo or a point from another scan).
MAX_POINT_DISTANCE = 0.05


@dataclass(frozen=True)
class Landmark:
    """Where the seam and angle ranges are measured from.

    Attributes
    ----------
    kind : str
        ``point``, ``painted zone`` or ``handle``.
    angle : float
        Radians counter-clockwise about the axis from its reference direction, in ``[0, 2 pi)``.
    detail : str
        How it was found, in words (for the JSON).
    point : tuple of 3 float or None
        The 3D point (scan coordinates), for ``point`` and ``handle``.
    """

    kind: str
    angle: float
    detail: str
    point: tuple | None = None

    def as_dict(self) -> dict:
        """JSON-ready description (angle in degrees)."""
        return {"kind": self.kind, "angle_deg": math.degrees(self.angle), "detail": self.detail,
                "point": None if self.point is None else [float(x) for x in self.point]}


def _circular_mean(theta: np.ndarray, weight: np.ndarray) -> tuple[float, float]:
    """Weighted circular mean angle in ``[0, 2 pi)`` and the resultant length in [0, 1]."""
    total = float(weight.sum())
    if total <= 0:
        return 0.0, 0.0
    c, s = float(np.dot(weight, np.cos(theta))), float(np.dot(weight, np.sin(theta)))
    return math.atan2(s, c) % (2 * math.pi), math.hypot(c, s) / total


def zone_centre(theta: np.ndarray, weight: np.ndarray) -> tuple[float | None, float]:
    """Angle of the centre of a zone on the vessel, or None when it goes round evenly.

    Parameters
    ----------
    theta : (n,) float64
        Angles of the surface's points, radians from the reference.
    weight : (n,) float64
        How much each point belongs to the zone (importance times area).

    Returns
    -------
    angle : float or None
        Radians in ``[0, 2 pi)``; None when the weighted circular mean is shorter than
        :data:`MIN_PAINTED_RESULTANT`.
    resultant : float
    """
    angle, length = _circular_mean(theta, weight)
    return (angle if length >= MIN_PAINTED_RESULTANT else None), length


def find_landmark(mesh, axis, *, seam_at, landmark: str | None, painted_zone, auto_seam,
                  attachments=None) -> tuple[Landmark, list[str]]:
    """The landmark named by the options, and notes on what was used instead where it is missing.

    Parameters
    ----------
    mesh : Mesh
    axis : AxisFit
    seam_at : (3,) float or None
        A point on the surface, scan coordinates.
    landmark : str or None
        ``painted`` or ``handle`` (:data:`LANDMARKS`), or None: the painted zone (a window
        centred on it).
    painted_zone : callable
        ``() -> (radians or None, str)``: the centre of the painted (importance) zone and how
        it was found, or None and why there is none.
    auto_seam : callable
        ``() -> radians``: the automatic seam (the least painted place); without a painted
        zone its opposite is taken.
    attachments : AttachmentSelection, optional
        Handles found on the scan (largest first).

    Returns
    -------
    Landmark
    notes : list of str

    Raises
    ------
    InvalidOptionError
        ``seam_at`` far from the scan's surface.
    """
    notes: list[str] = []
    if seam_at is not None:
        p = np.asarray(seam_at, np.float64)
        d = float(np.sqrt(np.min(np.sum((mesh.vertices - p) ** 2, axis=1))))
        if d > MAX_POINT_DISTANCE * max(axis.height, DEGENERATE):
            mm = mesh.mm_per_unit
            raise InvalidOptionError(
                f"seam_at {p[0]:g} {p[1]:g} {p[2]:g} lies {d * mm:.3g} mm from the scan's surface; pick a point on "
                "the vessel (scan coordinates, e.g. MeshLab's point picking on this file)")
        return Landmark("point", float(axis.cylindrical(p[None])[2][0]), "the given point on the surface",
                        tuple(p)), notes
    if landmark == "handle":
        if attachments is not None and attachments.components:
            c = np.asarray(attachments.components[0].centroid, np.float64)
            return Landmark("handle", float(axis.cylindrical(c[None])[2][0]),
                            f"centre of the largest of {len(attachments.components)} handles/attachments",
                            tuple(c)), notes
        notes.append("no handle was found on the scan: angles are measured from the painted zone's centre instead")
    angle, detail = painted_zone()
    if angle is None:
        angle = (auto_seam() + math.pi) % (2 * math.pi)
        notes.append(f"no painted zone to centre on ({detail}); its centre is taken opposite the least painted "
                     "place (the automatic seam)")
        detail = f"opposite the least painted place: {detail}"
    return Landmark("painted zone", angle, detail), notes
