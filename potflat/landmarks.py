"""Landmarks on the vessel that the seam and angle ranges are measured from.

A user names a landmark instead of an angle from the axis' reference direction (which
depends on the scan's pose): a 3D point on the surface (``seam_at``, e.g. picked in
MeshLab), the centre of the painted zone (the seam goes opposite it) or the largest handle
(the seam goes through it). ``--seam DEG`` and ``--angles A0 A1`` are then measured from
the landmark; ``--angles`` alone centres the window on the painted zone.

The painted zone's centre is the area-weighted circular mean angle of the painting's
contrast (the spread of brightness over each face, as the automatic seam measures it). When
the painting goes round evenly the mean has no direction; the centre is then taken opposite
the least painted place (the automatic seam) and the JSON says so.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from potflat.errors import InvalidOptionError

#: Landmark names a user can give (``RolloutOptions.landmark``).
LANDMARKS = ("painted", "handle")
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
        ``reference`` (the axis' reference direction), ``point``, ``painted zone`` or ``handle``.
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


REFERENCE = Landmark("reference", 0.0, "the axis' reference direction")


def _circular_mean(theta: np.ndarray, weight: np.ndarray) -> tuple[float, float]:
    """Weighted circular mean angle in ``[0, 2 pi)`` and the resultant length in [0, 1]."""
    total = float(weight.sum())
    if total <= 0:
        return 0.0, 0.0
    c, s = float(np.dot(weight, np.cos(theta))), float(np.dot(weight, np.sin(theta)))
    return math.atan2(s, c) % (2 * math.pi), math.hypot(c, s) / total


def painted_centre(mesh, faces: np.ndarray, theta_c: np.ndarray, area: np.ndarray) -> tuple[float | None, str]:
    """Angle of the painted zone's centre, or None, and how it was found.

    Parameters
    ----------
    mesh : Mesh
    faces : (k,) int64
        The region's faces.
    theta_c : (k,) float64
        Their centroid angles, radians from the reference.
    area : (k,) float64

    Returns
    -------
    angle : float or None
        Radians in ``[0, 2 pi)``; None when the scan has no painting or it goes round evenly.
    detail : str
    """
    from potflat.rollout import _luminance_variation

    var, source = _luminance_variation(mesh, faces)
    if var is None:
        return None, "the scan has no texture or vertex colours: no painted zone"
    angle, length = _circular_mean(theta_c, area * var)
    if length < MIN_PAINTED_RESULTANT:
        return None, f"the painting ({source}) goes round evenly (resultant {length:.3f}): no single centre"
    return angle, f"centre of the painting's contrast ({source}), resultant {length:.2f}"


def find_landmark(mesh, axis, *, seam_at, landmark: str | None, faces: np.ndarray, theta_c: np.ndarray,
                  area: np.ndarray, attachments=None, auto_seam=None) -> tuple[Landmark, list[str]]:
    """The landmark named by the options, and notes on what was used instead where it is missing.

    Parameters
    ----------
    mesh : Mesh
    axis : AxisFit
    seam_at : (3,) float or None
        A point on the surface, scan coordinates.
    landmark : str or None
        ``painted`` or ``handle`` (:data:`LANDMARKS`), or None: the painted zone when a
        window is centred on it, else the reference direction.
    faces : (k,) int64
        The region's faces (where the painting is looked for).
    theta_c, area : (k,) float64
        Their centroid angles (radians from the reference) and areas.
    attachments : AttachmentSelection, optional
        Handles found on the scan (largest first).
    auto_seam : callable, optional
        ``() -> radians``: the automatic seam, used when the painting has no centre (its
        opposite is taken).

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
        if d > MAX_POINT_DISTANCE * max(axis.height, 1e-12):
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
    angle, detail = painted_centre(mesh, faces, theta_c, area)
    if angle is None:
        if auto_seam is None:
            notes.append(f"{detail}; angles are measured from the axis' reference direction")
            return REFERENCE, notes
        angle = (auto_seam() + math.pi) % (2 * math.pi)
        notes.append(f"{detail}; the centre is taken opposite the least painted place")
        detail = f"{detail}: opposite the least painted place"
    return Landmark("painted zone", angle, detail), notes
