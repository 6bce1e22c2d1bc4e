"""The base at the foot (the floor, inside): left out of the rollout where a development would
smear it, and shown as its own disc, an orthographic view along the axis.

A cylinder, cone or sphere develops a ring around the axis into a strip as long as the proxy's
circumference, so a flat or domed base (a floor, the underside of a foot) comes out as a wide,
lobed flange whose painting is smeared: the relaxation cannot give back a disc's shape to a
strip. Seen along the axis the same faces are nearly true: an orthographic view shortens
lengths across a face by the cosine of its tilt, at most ``1 - cos 45 deg`` = 29% for the
faces taken here and nothing on a flat base.

:func:`split_base` finds the **candidates**: the region's faces whose normal (averaged over
:data:`BASE_SMOOTH` rings of neighbours, or its own where the development folds the face
edge-on) is within :data:`BASE_ANGLE_DEG` of the axis, facing the viewer (down for the outer
side, seen from below; up for the inner side, the floor seen from above), in connected pieces
at the foot
(reaching down to the region's lowest point, or in towards the axis in its lower quarter), one
of them reaching the axis (an open foot's edge is no base). It then decides by
measured distortion, not by the normal alone: in rings around the axis (:data:`BASE_RINGS`)
from the axis outwards, the largest length error of each face in the development (the
proxy's, :func:`potflat.mesh.distortion.length_error`) is compared with the orthographic
view's, area-weighted; the rings where the development is the less true one, out to the
first where it is not, go to the disc, the rest stays in the rollout (a base that curves
smoothly into the wall unrolls well near the wall). Pieces of the region that leaving the
disc out cuts off from the rest (the inside of a foot ring between its underside and the
base) go with it, the faces of them that face away from the viewer in neither image; when
they are larger than half the disc, the wall goes on beyond it (a shoulder and a neck seen
along an axis pointing the wrong way): no disc.
:func:`base_disc` makes the disc's flattening.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from potflat.mesh.distortion import (
    DistortionSummary,
    SurfaceReference,
    length_error,
    weighted_percentiles,
)
from potflat.rollout import proxy as _proxy
from potflat.rollout.axis import AxisFit
from potflat.rollout.border import EDGE_ON_RATIO, _cut_off
from potflat.rollout.walls import FaceGraph, _smooth
from potflat.types import FlatMesh, Mesh

#: A face faces along the axis when its normal is within this angle (degrees) of it.
BASE_ANGLE_DEG = 45.0
#: Rounds of averaging each face's normal with its neighbours' before the angle is judged.
BASE_SMOOTH = 3
#: Rings around the axis (over the candidates' radius) in which development and view are compared.
BASE_RINGS = 20
#: A piece of candidates is at the foot when its lowest point is within this fraction of the
#: vessel's height of the region's lowest point ...
FOOT_FRACTION = 0.05
#: ... or it reaches closer to the axis than this fraction of the region's largest radius, no
#: higher than this fraction of the vessel's height above the region's lowest point (a kylix's
#: bowl over its stem is no base).
NEAR_AXIS_FRACTION, BASE_HEIGHT_FRACTION = 0.25, 0.25
#: A face's length error in the development counts at most this much (a flipped or edge-on
#: face: the development has lost the face's shape entirely).
MAX_UNROLLED_ERROR = 1.0
#: A disc below this share of the region's area is not made (a few faces of noise at the foot).
MIN_DISC_SHARE = 0.001
#: Faces facing along the axis whose removal cuts off more than this fraction of their own area
#: from the wall are no base (a shoulder between a body and a neck).
MAX_CUT_OFF = 0.5


@dataclass(frozen=True, eq=False)
class BaseSplit:
    """Where the faces at the foot that face along the axis went: the rollout or the disc.

    Attributes
    ----------
    view : str
        ``below`` (the outer side: the base's underside) or ``above`` (the inner side: the
        floor seen from inside).
    disc_faces : (k,) int64
        Scan faces left out of the rollout and shown in the disc.
    hidden_faces : (j,) int64
        Scan faces cut off with the disc that face away from its view: in neither image.
    kept_faces : (i,) int64
        Candidates kept in the rollout, where the development is truer than the view.
    candidate_faces : int
        Faces at the foot facing along the axis (before the decision).
    disc_area, hidden_area, kept_area, region_area : float
        3D areas (scan units squared); ``region_area``: the whole region the rollout was made
        of before the split.
    radius : float
        Distance from the axis (scan units) out to which the disc reaches (0: no disc).
    unrolled_error_pct, orthographic_error_pct : (float, float)
        Area-weighted median and 95th percentile (%) of the largest length error through a
        face of the disc (or, without a disc, of the candidates): in the proxy's development
        and in the orthographic view. NaN without candidates.
    reason : str
        Why, in words.
    flat : FlatMesh or None
        The disc (:func:`base_disc`), made by :func:`potflat.rollout.unroll.rollout`.
    proxy : Proxy or None
        Its orthographic projection (``view``, ``up``, ``right``).
    distortion : DistortionSummary or None
        Its distortion figures.
    """

    view: str
    disc_faces: np.ndarray
    hidden_faces: np.ndarray
    kept_faces: np.ndarray
    candidate_faces: int
    disc_area: float
    hidden_area: float
    kept_area: float
    region_area: float
    radius: float
    unrolled_error_pct: tuple[float, float]
    orthographic_error_pct: tuple[float, float]
    reason: str
    flat: FlatMesh | None = None
    proxy: _proxy.Proxy | None = None
    distortion: DistortionSummary | None = None

    @property
    def left_out(self) -> bool:
        """Whether the base was left out of the rollout (and a disc made)."""
        return len(self.disc_faces) > 0

    def summary(self, mm_per_unit: float) -> dict:
        """JSON-ready figures (lengths in mm, areas in mm², errors in %)."""
        s2 = mm_per_unit ** 2

        def pct(pair):
            return [float(x) if math.isfinite(x) else None for x in pair]

        return {
            "left_out": self.left_out,
            "view": self.view,
            "reason": self.reason,
            "candidate_faces": self.candidate_faces,
            "faces_in_disc": len(self.disc_faces),
            "area_in_disc_mm2": self.disc_area * s2,
            "faces_kept_in_rollout": len(self.kept_faces),
            "area_kept_in_rollout_mm2": self.kept_area * s2,
            "faces_in_neither": len(self.hidden_faces),
            "area_in_neither_mm2": self.hidden_area * s2,
            "percent_of_region": 100.0 * self.disc_area / self.region_area if self.region_area > 0 else 0.0,
            "radius_mm": self.radius * mm_per_unit,
            "length_error_unrolled_pct": pct(self.unrolled_error_pct),
            "length_error_disc_pct": pct(self.orthographic_error_pct),
            "proxy": self.proxy.as_dict() if self.proxy is not None else None,
            "distortion": self.distortion.as_dict() if self.distortion is not None else None,
        }


def _errors(values: np.ndarray, weights: np.ndarray) -> tuple[float, float]:
    if not len(values) or weights.sum() <= 0:
        return float("nan"), float("nan")
    median, p95 = weighted_percentiles(100.0 * values, weights, (50.0, 95.0))
    return float(median), float(p95)


def split_base(mesh: Mesh, region: np.ndarray, unrolled_error: np.ndarray, *, n_axial: np.ndarray,
               height: np.ndarray, radius: np.ndarray, vertex_radius: np.ndarray, vertex_theta: np.ndarray,
               area: np.ndarray, vessel_height: float, side: str, keep: bool = False) -> BaseSplit:
    """Decide which faces at the foot leave the rollout for the disc (see the module docs).

    Parameters
    ----------
    mesh : Mesh
        The scan.
    region : (k,) int64
        Scan faces of the region to unroll (the selected side, band and angles).
    unrolled_error : (k,) float64
        Largest length error through each of them in the proxy's development
        (:func:`potflat.mesh.distortion.length_error`; 1 = 100%).
    n_axial, height, radius, area : (m,) float64
        Per scan face: the unit normal's component along the axis (towards the mouth), the
        centroid's height along the axis and distance from it, the 3D area.
    vertex_radius, vertex_theta : (n,) float64
        Each scan vertex's distance from the axis and angle about it (radians).
    vessel_height : float
        The scan's extent along the axis.
    side : str
        ``outer`` (the base, seen from below) or ``inner`` (the floor, seen from above).
    keep : bool
        Keep the faces in the rollout whatever the figures say (they are still reported).

    Returns
    -------
    BaseSplit
        Without ``flat``, ``proxy`` and ``distortion`` (:func:`base_disc` makes them).
    """
    view = "below" if side == "outer" else "above"
    facing = -n_axial[region] if side == "outer" else n_axial[region]  # cosine between normal and view
    w = area[region]
    region_area = float(w.sum())
    empty = np.zeros(0, np.int64)
    graph = FaceGraph(np.take(mesh.faces, region, axis=0))
    along = math.cos(math.radians(BASE_ANGLE_DEG))
    dev = np.minimum(unrolled_error, MAX_UNROLLED_ERROR)
    # the normals averaged over a few rings: the split follows the surface, not the scan's noise;
    # and every face facing along the axis that the development folds edge-on (the averaging
    # misses a flat base's last faces at a sharp corner, and the fan of a few large triangles);
    # never a face turned away (it would fold the view)
    cand = ((_smooth(facing, w, graph.matrix(), BASE_SMOOTH) > along)
            | ((facing > along) & (dev > 1.0 - EDGE_ON_RATIO))) & (facing > 0.0)
    if cand.any():
        piece = graph.components(cand[graph.pairs[:, 0]] & cand[graph.pairs[:, 1]])
        lowest = np.full(piece.max() + 1, np.inf)
        closest = np.full(piece.max() + 1, np.inf)
        np.minimum.at(lowest, piece[cand], height[region[cand]])
        corners = np.take(mesh.faces, region[cand], axis=0)
        reach = vertex_radius[corners].min(axis=1)
        # a face spanning the axis (a flat bottom triangulated by chords between rim vertices):
        # its corners' angles leave no gap of half a turn
        angle = np.sort(vertex_theta[corners], axis=1)
        gap = np.maximum(np.maximum(angle[:, 1] - angle[:, 0], angle[:, 2] - angle[:, 1]),
                         2.0 * math.pi - (angle[:, 2] - angle[:, 0]))
        reach[gap < math.pi] = 0.0
        np.minimum.at(closest, piece[cand], reach)
        low = height[region].min()
        near_axis = ((closest <= NEAR_AXIS_FRACTION * radius[region].max())
                     & (lowest <= low + BASE_HEIGHT_FRACTION * vessel_height))
        at_foot = (lowest <= low + FOOT_FRACTION * vessel_height) | near_axis
        # a base reaches the axis: an open foot's ragged edge facing along it is no base
        cand &= (at_foot & near_axis.any())[piece]
    n_cand = int(cand.sum())
    orth = 1.0 - np.clip(facing, 0.0, 1.0)

    def no_disc(reason: str) -> BaseSplit:
        return BaseSplit(view=view, disc_faces=empty, hidden_faces=empty, kept_faces=region[cand].astype(np.int64),
                         candidate_faces=n_cand, disc_area=0.0, hidden_area=0.0, kept_area=float(w[cand].sum()),
                         region_area=region_area, radius=0.0, unrolled_error_pct=_errors(dev[cand], w[cand]),
                         orthographic_error_pct=_errors(orth[cand], w[cand]), reason=reason)

    if not n_cand:
        return no_disc("no base: no faces at the foot around the axis face along it")
    # rings around the axis, from the axis out: the disc reaches out to the first ring the
    # development shows at least as truly as the orthographic view
    r = radius[region]
    edges = np.linspace(0.0, float(r[cand].max()) * (1.0 + 1e-9), BASE_RINGS + 1)
    ring = np.clip(np.searchsorted(edges, r, side="right") - 1, 0, BASE_RINGS - 1)
    ring_area = np.bincount(ring[cand], w[cand], BASE_RINGS)
    ring_dev = np.bincount(ring[cand], (w * dev)[cand], BASE_RINGS)
    ring_orth = np.bincount(ring[cand], (w * orth)[cand], BASE_RINGS)
    truer = (ring_area == 0) | (ring_dev > ring_orth)
    reach = int(np.argmin(truer)) if not truer.all() else BASE_RINGS
    disc = cand & (ring < reach)
    if not disc.any():
        return no_disc("the faces at the foot facing along the axis unroll more truly than a view along the axis "
                       "shows them: kept in the rollout")
    # pieces of the region that the disc cuts off from the rest go with it
    part = graph.components()
    cut = _cut_off(graph, ~disc, w, part, np.bincount(part, w))
    if w[cut].sum() > MAX_CUT_OFF * w[disc].sum():  # the wall goes on past them: a shoulder, a neck
        return no_disc("the faces facing along the axis near it lie between two parts of the wall (a shoulder, not a "
                       "base): kept in the rollout")
    hidden = cut & (facing <= 0.0)
    disc |= cut & ~hidden
    if w[disc].sum() < MIN_DISC_SHARE * region_area:
        return no_disc(f"the faces at the foot facing along the axis are {100 * w[disc].sum() / region_area:.2g} % "
                       "of the surface: too few for an image of their own, kept in the rollout")
    if keep:
        return no_disc("kept in the rollout, as asked (keep_base)")
    kept = cand & ~disc
    unrolled, orthographic = _errors(dev[disc], w[disc]), _errors(orth[disc], w[disc])
    what = "base" if side == "outer" else "floor"
    reason = (f"the {what} faces along the axis: unrolled, lengths there would be off by {unrolled[0]:.0f} % "
              f"(median; {unrolled[1]:.0f} % over 95 % of it), seen from {view} they are off by "
              f"{orthographic[0]:.1f} % ({orthographic[1]:.0f} %)")
    return BaseSplit(view=view, disc_faces=region[disc].astype(np.int64), hidden_faces=region[hidden].astype(np.int64),
                     kept_faces=region[kept].astype(np.int64), candidate_faces=n_cand, disc_area=float(w[disc].sum()),
                     hidden_area=float(w[hidden].sum()), kept_area=float(w[kept].sum()), region_area=region_area,
                     radius=float(edges[reach] if reach < BASE_RINGS else r[disc].max()),
                     unrolled_error_pct=unrolled, orthographic_error_pct=orthographic, reason=reason)


def base_disc(mesh: Mesh, faces: np.ndarray, axis: AxisFit, *, view: str, up_angle: float
              ) -> tuple[FlatMesh, _proxy.Proxy]:
    """The orthographic view of the scan faces ``faces`` ((k,) int64) along the axis.

    Parameters
    ----------
    mesh : Mesh
        The scan (its texture coordinates and colours go with the faces).
    faces : (k,) int64
    axis : AxisFit
    view : str
        ``below`` (the viewer under the foot, looking up the axis) or ``above``.
    up_angle : float
        Radians about the axis from its reference direction: the direction shown upwards
        (the rollout's seam, so the disc's top is where the rollout's two sides meet).

    Returns
    -------
    flat : FlatMesh
        The faces with their own vertices and ``uv`` in scan units: a face facing the viewer
        is counter-clockwise.
    proxy : Proxy
        The ``ortho`` projection used.
    """
    F = np.take(mesh.faces, faces, axis=0)
    used = np.flatnonzero(np.bincount(F.ravel(), minlength=len(mesh.vertices)))
    new_index = np.zeros(len(mesh.vertices), np.int64)
    new_index[used] = np.arange(len(used))
    disc = Mesh(mesh.vertices[used], new_index[F], texture_path=mesh.texture_path,
                vertex_colors=None if mesh.vertex_colors is None else mesh.vertex_colors[used],
                units=mesh.units, source=mesh.source, **mesh.face_fields(faces))
    up = math.cos(up_angle) * axis.reference + math.sin(up_angle) * np.cross(axis.direction, axis.reference)
    towards = -axis.direction if view == "below" else axis.direction
    ortho = _proxy.ortho_proxy(axis.direction, up, towards)
    what = "base seen from below" if view == "below" else "floor seen from above"
    prox = _proxy.Proxy(ortho.kind, ortho.params, reason=f"the {what}, orthographic, the seam upwards")
    return FlatMesh(disc, _proxy.project_ortho(prox, disc.vertices, axis.point)), prox


def unrolled_errors(flat: FlatMesh, faces: np.ndarray) -> np.ndarray:
    """Largest length error through each of the development's faces ``faces`` ((k,) int64
    indices into ``flat.mesh.faces``): :func:`potflat.mesh.distortion.length_error`. Shape (k,)."""
    reference = SurfaceReference(flat.mesh.vertices, np.take(flat.mesh.faces, faces, axis=0))
    return length_error(reference.face_distortion(flat.uv))
