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
:func:`cut_base` then cuts the base off exactly along a plane across the axis where the disc of
whole faces meets the wall (the faces across it split by :func:`potflat.mesh.split.split_faces`,
the same pieces for the disc and the rollout), so the wall's lower edge and the disc's rim are
one curve at one height. :func:`base_disc` makes the disc's flattening.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from potflat.mesh.distortion import (
    DistortionSummary,
    SurfaceReference,
    face_areas,
    length_error,
    weighted_percentiles,
)
from potflat.mesh.split import split_faces
from potflat.rollout import proxy as _proxy
from potflat.rollout.axis import AxisFit
from potflat.rollout.border import EDGE_ON_RATIO, _cut_off
from potflat.rollout.seam import CutOrigins
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
#: The plane cutting the base off moves at most this fraction of the disc's area between the
#: disc and the rollout; beyond it (a foot whose edge is far from one height) the split stays
#: along whole faces.
MAX_CUT_MOVED = 0.5
#: Percentiles of the heights where the disc of whole faces meets the wall at which a plane
#: is tried (:func:`cut_base` says which is taken).
CUT_QUANTILES = (50.0, 75.0, 90.0, 100.0)
#: Heights closer to the cut than this fraction of the vessel's height are on it.
CUT_HEIGHT_TOLERANCE = 1e-9


@dataclass(frozen=True, eq=False)
class BaseCut:
    """The plane across the axis along which the base is cut off, the faces across it split.

    Attributes
    ----------
    height : float
        The plane's height along the axis (scan units, as :meth:`AxisFit.cylindrical`): the
        median height of the vertices where the disc of whole faces meets the wall.
    faces : (k,) int64
        Scan faces split by it: their pieces below go to the disc, those above to the rollout.
    on_cut : (j,) int64
        Scan vertices counted as on the plane (:attr:`potflat.mesh.split.FaceSplit.on_cut`):
        the disc's and the rollout's pieces meet there exactly.
    """

    height: float
    faces: np.ndarray
    on_cut: np.ndarray

    def levels(self, height: np.ndarray, index: np.ndarray) -> np.ndarray:
        """Signed height above the plane (k,) float64 of the vertices ``index`` ((k,) int64,
        scan vertices and any others after them) at heights ``height`` ((k,) float64); 0 on
        the cut."""
        level = height - self.height
        level[np.isin(index, self.on_cut)] = 0.0
        return level

    def split(self, points: np.ndarray, faces: np.ndarray, vertex_height: np.ndarray):
        """:func:`potflat.mesh.split.split_faces` of ``faces`` ((m, 3) int64 rows of the cut
        faces, any order) on the scan vertices ``points`` ((n, 3) float64): the same pieces for
        the disc and the rollout."""
        ids, local = np.unique(faces, return_inverse=True)
        split = split_faces(points[ids], local.reshape(-1, 3), self.levels(vertex_height[ids], ids))
        return ids, split


def cut_base(points: np.ndarray, faces: np.ndarray, disc_faces: np.ndarray, wall_faces: np.ndarray,
             vertex_height: np.ndarray, vessel_height: float, towards: np.ndarray
             ) -> tuple[BaseCut | None, np.ndarray, str]:
    """The plane across the axis where the wall meets the disc of whole faces, the base cut off along it.

    The faces of the disc and the wall are split along a plane across the axis at a height
    where they meet (:data:`CUT_QUANTILES` of the heights of the vertices they share;
    :func:`potflat.mesh.split.split_faces`); each connected piece of the surface below or
    above it goes to the disc or the wall, whichever has the more of its area. Of the planes
    tried, the one that puts the least of the wall turned more than :data:`BASE_ANGLE_DEG`
    from the view into the disc is taken (the disc stays as true as the faces chosen for
    it), then the one moving the least area; none that moves more than :data:`MAX_CUT_MOVED`
    of the disc or puts into it a face turned away from the view. So the wall's lower edge
    and the disc's rim are one     curve at one height.

    Parameters
    ----------
    points : (n, 3) float64
    faces : (m, 3) int64
        The scan.
    disc_faces, wall_faces : (d,) int64, (w,) int64
        Scan faces of the disc and of the rest of the region.
    vertex_height : (n,) float64
        Every scan vertex's height along the axis.
    vessel_height : float
    towards : (3,) float64
        Unit vector from the disc towards its viewer (down the axis for the base seen from below).

    Returns
    -------
    cut : BaseCut or None
        None: the split stays along whole faces (``why``).
    disc_faces : (k,) int64
        Scan faces wholly in the disc (with ``cut``; else ``disc_faces``).
    why : str
    """
    d = len(disc_faces)
    both = np.concatenate([disc_faces, wall_faces]).astype(np.int64)
    graph = FaceGraph(np.take(faces, both, axis=0), shared=True)
    pairs = graph.pairs
    meet = (pairs[:, 0] < d) != (pairs[:, 1] < d)
    if not meet.any():
        return None, disc_faces, "the disc does not meet the wall"
    edge_height = vertex_height[np.unique(graph.shared[meet])]
    del graph, pairs
    tolerance = CUT_HEIGHT_TOLERANCE * vessel_height
    if np.ptp(edge_height) <= tolerance:
        return None, disc_faces, "the disc meets the wall at one height"
    # the wall's faces reaching down to the highest plane tried (the rest stays whole in the wall)
    top = float(edge_height.max()) + tolerance
    both = np.concatenate([disc_faces, wall_faces[vertex_height[np.take(faces, wall_faces, axis=0)].min(axis=1) <= top]])
    rows = np.take(faces, both, axis=0)
    best, notes = None, []
    for q in CUT_QUANTILES:
        height = float(np.quantile(edge_height, q / 100.0))
        tried = _try_cut(points, rows, d, vertex_height, height, tolerance, np.asarray(towards, np.float64))
        if isinstance(tried, str):
            notes.append(f"at the {q:g}th percentile {tried}")
        elif best is None or tried[:2] < best[:2]:
            best = tried + (q,)
    if best is None:
        return None, disc_faces, "; ".join(notes) + ": cut along whole faces"
    steep, moved, cut, whole, q = best
    cut = BaseCut(cut.height, both[cut.faces], cut.on_cut)
    return cut, both[whole], (f"cut off along the plane across the axis at the {q:g}th percentile of the "
                              f"heights where the faces facing along the axis met the wall: {len(cut.faces)} "
                              f"faces split, {moved:.1%} of the disc's area moved between disc and wall, {steep:.1%} of it "
                              f"wall more than {BASE_ANGLE_DEG:g} degrees from the view put into the disc")


def _try_cut(points, rows, d, vertex_height, height, tolerance, towards):
    """:func:`cut_base` at one ``height``: (steep wall put into the disc and area moved, both over
    the disc's area; BaseCut with its faces as rows of ``rows``; mask of ``rows`` wholly in the
    disc), or why not (str). ``rows`` (k, 3): the disc's faces (the first ``d``), then the wall's."""
    ids = np.unique(rows)
    cut = BaseCut(height, np.zeros(0, np.int64), ids[np.abs(vertex_height[ids] - height) <= tolerance])
    ids, split = cut.split(points, rows, vertex_height)
    pts = np.concatenate([points[ids], split.added(points[ids])])
    piece_area = face_areas(pts, split.faces)
    on_plane = np.zeros(len(pts), bool)
    on_plane[len(ids):] = True
    on_plane[split.on_cut] = True
    pieces = FaceGraph(split.faces, shared=True)
    part = pieces.components(~on_plane[pieces.shared].all(axis=1))  # (pieces meet across the plane along it)
    in_disc = split.parent < d
    disc_area = np.bincount(part, piece_area * in_disc)
    wall_area = np.bincount(part, piece_area * ~in_disc)
    to_disc = (disc_area > wall_area)[part]
    moved = float(piece_area[to_disc != in_disc].sum()) / float(piece_area[in_disc].sum())
    if moved > MAX_CUT_MOVED:
        return f"it would move {moved:.0%} of the disc's area"
    corner = pts[split.faces]
    facing = np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0]) @ towards  # (2 area x cosine)
    into_disc = to_disc & ~in_disc
    if np.any(into_disc & (facing <= 0.0) & (piece_area > 0.0)):
        return "it puts faces turned away from the view into the disc"
    # the wall's area the disc shows more than BASE_ANGLE_DEG from the view
    steep = float(piece_area[into_disc & (facing <= 2.0 * piece_area * math.cos(math.radians(BASE_ANGLE_DEG)))].sum())
    steep /= float(piece_area[in_disc].sum())
    n_disc = np.bincount(split.parent, to_disc, len(rows))
    n_pieces = np.bincount(split.parent, minlength=len(rows))
    mixed = (n_disc > 0) & (n_disc < n_pieces)
    if not mixed.any():
        return "it splits no face"
    if np.any(mixed[split.parent] & ((to_disc & (split.side > 0)) | (~to_disc & (split.side < 0)))):
        return "the surface above it goes to the disc"
    cut = BaseCut(height, np.flatnonzero(mixed), np.union1d(cut.on_cut, ids[split.on_cut]))
    return steep, moved, cut, n_disc == n_pieces


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
        of before the split; ``disc_area``: of the disc as made (:func:`disc_figures`).
    radius : float
        Distance from the axis (scan units) out to which the disc reaches (0: no disc).
    unrolled_error_pct, orthographic_error_pct : (float, float)
        Area-weighted median and 95th percentile (%) of the largest length error through a
        face of the disc (or, without a disc, of the candidates): in the proxy's development
        (of the faces chosen, before the cut) and in the orthographic view (of the disc as
        made). NaN without candidates.
    reason : str
        Why, in words.
    flat : FlatMesh or None
        The disc (:func:`base_disc`), made by :func:`potflat.rollout.unroll.rollout`.
    proxy : Proxy or None
        Its orthographic projection (``view``, ``up``, ``right``).
    distortion : DistortionSummary or None
        Its distortion figures.
    cut : BaseCut or None
        The plane the base is cut off along (:func:`cut_base`; ``disc_faces`` are then the
        faces wholly below it); None: along whole faces.
    cut_note : str
        How it was cut off, in words.
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
    cut: BaseCut | None = None
    cut_note: str = ""

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
            "cut": {"height_mm": self.cut.height * mm_per_unit if self.cut is not None else None,
                    "faces_split": len(self.cut.faces) if self.cut is not None else 0, "how": self.cut_note},
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
    towards : (3,) float64
        Unit vector from the disc towards its viewer (down the axis for the base seen from below).
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
    cand = ((_smooth(facing, w, graph, BASE_SMOOTH) > along)
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


def base_disc(mesh: Mesh, faces: np.ndarray, axis: AxisFit, *, view: str, up_angle: float,
              cut: BaseCut | None = None) -> tuple[FlatMesh, _proxy.Proxy]:
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
    cut : BaseCut or None
        With it, also the pieces below its plane of the faces it cuts (texture coordinates and
        colours interpolated exactly within their face).

    Returns
    -------
    flat : FlatMesh
        The faces with their own vertices and ``uv`` in scan units: a face facing the viewer
        is counter-clockwise.
    proxy : Proxy
        The ``ortho`` projection used.
    """
    n = len(mesh.vertices)
    F = np.take(mesh.faces, faces, axis=0)
    origins = CutOrigins.whole(np.asarray(faces, np.int64), np.zeros(len(faces), bool), n)
    if cut is not None and len(cut.faces):
        ids, split = cut.split(mesh.vertices, np.take(mesh.faces, cut.faces, axis=0),
                               axis.cylindrical(mesh.vertices)[0])
        below = np.flatnonzero(split.side < 0)
        local = split.faces[below]
        F = np.concatenate([F, np.where(local < len(ids), ids[np.minimum(local, len(ids) - 1)], n + local - len(ids))])
        origins = CutOrigins(face_index=np.concatenate([origins.face_index, cut.faces[split.parent[below]]]),
                             repeated=np.zeros(len(F), bool), pieces=len(faces) + np.arange(len(below)),
                             weights=split.weights[below], added_edges=ids[split.edges], added_t=split.t, n=n)
    used = np.flatnonzero(np.bincount(F.ravel(), minlength=n + len(origins.added_t)))
    new_index = np.zeros(n + len(origins.added_t), np.int64)
    new_index[used] = np.arange(len(used))
    disc = Mesh(origins.vertex_values(mesh.vertices, used), new_index[F], texture_path=mesh.texture_path,
                vertex_colors=None if mesh.vertex_colors is None else origins.vertex_values(mesh.vertex_colors, used),
                units=mesh.units, source=mesh.source, **origins.face_fields(mesh))
    up = math.cos(up_angle) * axis.reference + math.sin(up_angle) * np.cross(axis.direction, axis.reference)
    towards = -axis.direction if view == "below" else axis.direction
    ortho = _proxy.ortho_proxy(axis.direction, up, towards)
    what = "base seen from below" if view == "below" else "floor seen from above"
    prox = _proxy.Proxy(ortho.kind, ortho.params, reason=f"the {what}, orthographic, the seam upwards")
    return FlatMesh(disc, _proxy.project_ortho(prox, disc.vertices, axis.point)), prox


def disc_figures(disc: FlatMesh, axis: AxisFit, view: str) -> tuple[float, tuple[float, float]]:
    """The 3D area of the disc's faces and pieces (scan units squared) and the area-weighted
    median and 95th percentile (%) of the largest length error through them in the
    orthographic view (``1 - cos`` of each one's tilt from the view)."""
    corner = disc.mesh.vertices[disc.mesh.faces]
    normal = np.cross(corner[:, 1] - corner[:, 0], corner[:, 2] - corner[:, 0])
    twice = np.linalg.norm(normal, axis=1)
    towards = -axis.direction if view == "below" else axis.direction
    facing = np.divide(normal @ towards, twice, out=np.zeros_like(twice), where=twice > 0)
    return 0.5 * float(twice.sum()), _errors(1.0 - np.clip(facing, 0.0, 1.0), 0.5 * twice)


def unrolled_errors(flat: FlatMesh, faces: np.ndarray) -> np.ndarray:
    """Largest length error through each of the development's faces ``faces`` ((k,) int64
    indices into ``flat.mesh.faces``): :func:`potflat.mesh.distortion.length_error`. Shape (k,)."""
    reference = SurfaceReference(flat.mesh.vertices, np.take(flat.mesh.faces, faces, axis=0))
    return length_error(reference.face_distortion(flat.uv))
