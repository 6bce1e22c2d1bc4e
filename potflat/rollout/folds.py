"""Where the scan itself folds over in 3D: creases, flaps of scan noise, duplicated sheets.

A vessel's wall, seen from the painted side, runs over the proxy surface once: its
development (the proxy's map of each point's height and angle, before untangling) covers
each place once and keeps every face's orientation. Two things break that, and only the
scan can cause them (the development itself is one-to-one):

* a face **facing into the wall**: its flat signed area is negative (its normal points
  against the proxy's normal on the painted side): the middle sheet of a crease, a flap
  turned over, the far side of a spike's sliver;
* a face **lying over another sheet**: its centre falls inside another face of the
  development that shares no vertex with it (every face whose bounding box covers the
  centre's cell of a grid is tested): both sheets of a duplicated, misregistered pass, and
  the outer sheets of a crease.

A face found so is judged again on the development smoothed over about :data:`FOLD_MIN_MM`
around it, and counts only when it is still so: a scan's noise turns single faces over where
its wall is nearly edge-on to the proxy (a jar's shoulder), and a fold that narrow does not show
in the image; a crease, a flap or a duplicated sheet wider than that stays.

Such faces cannot be laid flat true to scale: the relaxation squeezes them (no image is
refused for them) and the report says where they are, how large, and the bake marks them
on the distortion maps.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from potflat.mesh._kernels.grids import centre_grid, centres_inside
from potflat.mesh._kernels.topology import incident_faces, neighbour_means, vertex_faces
from potflat.mesh.distortion import bounds, face_areas
from potflat.mesh.embedding import signed_areas

#: Grid cells per face of the overlap test (about one face per cell, a few per face's box).
OVERLAP_CELLS_PER_FACE = 1.0
#: A grid whose faces' boxes cover more than this many cells per face gets cells twice as
#: large (long sliver triangles of a spike would otherwise cover many small cells, each
#: visited for the centres in it).
OVERLAP_MAX_CELLS_PER_FACE = 16
#: Folds narrower than about this (mm, two pixels of the default image) are the scan's noise: a
#: face found folded counts only when it is still so on the development smoothed over this
#: distance around it (:func:`smoothing_steps`).
FOLD_MIN_MM = 1.0
#: At most this many smoothing steps (a mesh with edges under about 0.14 mm is smoothed over less).
FOLD_MAX_STEPS = 100
#: Edges whose median length sets the smoothing (every k-th of the mesh's).
EDGE_SAMPLE = 100_000
#: Folded regions listed one by one in the JSON (the largest first); the rest are counted.
MAX_REGIONS = 20
#: A note warns when more than this share (percent) of the unrolled surface is folded.
WARN_FOLDED_PERCENT = 0.5


@dataclass(frozen=True, eq=False)
class ScanFolds:
    """Faces of a rollout where the scan folds over itself in 3D.

    Attributes
    ----------
    faces : (k,) int64
        Rollout faces (indices into the rollout's faces) folded in 3D.
    facing_in, overlapping : int
        How many face into the wall, and how many lie over another sheet (a face can be both).
    smoothing_steps : int
        The smoothing of the development they were judged on (:func:`smoothing_steps`).
    area_mm2, surface_mm2 : float
        3D area of those faces, and of the whole rollout.
    regions : list of dict
        Connected clusters (sharing a vertex), largest first: ``faces``, ``area_mm2``,
        ``height_mm`` [low, high] above the foot, ``band`` the same as fractions of the
        vessel's height (``--band`` values), ``angle_deg`` [low, high] in the rollout's angles,
        ``centroid`` (scan coordinates).
    """

    faces: np.ndarray
    facing_in: int
    overlapping: int
    smoothing_steps: int
    area_mm2: float
    surface_mm2: float
    regions: list

    @property
    def percent(self) -> float:
        """Folded share of the unrolled surface, percent."""
        return 100.0 * self.area_mm2 / self.surface_mm2 if self.surface_mm2 > 0 else 0.0

    def as_dict(self) -> dict:
        """JSON-ready description (see ``docs/formats.md``, ``folded``)."""
        return {
            "faces": int(len(self.faces)), "area_mm2": self.area_mm2, "percent_of_surface": self.percent,
            "facing_in": self.facing_in, "overlapping": self.overlapping,
            "regions_total": len(self.regions), "regions": self.regions[:MAX_REGIONS],
            "face_indices": self.faces.tolist(),
            "smoothed_mm": FOLD_MIN_MM, "smoothing_steps": self.smoothing_steps,
            "method": "faces facing into the wall (negative area in the proxy's development before untangling) or "
                      "lying over another sheet of the scan (centre inside a face of that development sharing no "
                      f"vertex), and still so with the development smoothed around them over about {FOLD_MIN_MM:g} "
                      "mm; potflat.rollout.folds",
        }

    def note(self) -> str | None:
        """A warning for the rollout's notes when the folded share is large, else None."""
        if self.percent <= WARN_FOLDED_PERCENT:
            return None
        big = self.regions[0]
        return (f"{self.percent:.1f} % of the unrolled surface ({self.area_mm2:.0f} mm2 in {len(self.regions)} "
                f"places, the largest {big['area_mm2']:.0f} mm2 at {big['height_mm'][0]:.0f}-{big['height_mm'][1]:.0f} "
                f"mm above the foot) folds over itself (a crease, a flap or a duplicated sheet of the scan, or a kept "
                "attachment): it is squeezed flat in the image and hatched on the distortion maps; clean the scan there if painting "
                "matters")


def overlapping_faces(faces: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Faces of a 2D layout that lie over another: the centre of one strictly inside the
    other, the two sharing no vertex (both are marked).

    Parameters
    ----------
    faces : (m, 3) int
    uv : (n, 2) float64

    Returns
    -------
    (m,) bool
    """

    faces = np.ascontiguousarray(faces, dtype=np.int64)
    uv = np.ascontiguousarray(uv, dtype=np.float64)
    m = len(faces)
    out = np.zeros(m, bool)
    if m < 2:
        return out
    in_use = np.zeros(len(uv), bool)
    in_use[faces.ravel()] = True
    used = uv[in_use]
    lo, hi = bounds(used)
    extent = float(max(hi[0] - lo[0], hi[1] - lo[1]))
    if not extent > 0:
        return out
    cell = max(math.sqrt(float((hi[0] - lo[0]) * (hi[1] - lo[1])) / (OVERLAP_CELLS_PER_FACE * m)), extent / 65536.0)
    while True:
        gx, gy = int((hi[0] - lo[0]) / cell) + 1, int((hi[1] - lo[1]) / cell) + 1
        start, items, centres, covered = centre_grid(faces, uv, lo[0], lo[1], cell, gx, gy)
        if covered <= OVERLAP_MAX_CELLS_PER_FACE * m or gx * gy == 1:
            break
        cell *= 2.0
    counts = np.empty(m, np.int64)
    nothing = np.empty(0, np.int64)
    centres_inside(faces, uv, lo[0], lo[1], cell, gx, gy, start, items, centres, nothing, counts, nothing)
    hit = counts > 0
    if hit.any():
        first = np.zeros(m, np.int64)
        np.cumsum(counts[:-1], out=first[1:])
        pairs = np.empty(int(counts.sum()), np.int64)
        centres_inside(faces, uv, lo[0], lo[1], cell, gx, gy, start, items, centres, first, counts, pairs)
        out[hit] = True
        out[pairs] = True
    return out


def smoothing_steps(vertices: np.ndarray, edges: np.ndarray, mm_per_unit: float) -> int:
    """The smoothing steps of :func:`fold_masks` that reach about :data:`FOLD_MIN_MM` on a mesh.

    A step takes each vertex halfway to the mean of its edge neighbours, a move of about
    ``sqrt(1 / 2)`` edge lengths on average; ``k`` steps spread it over ``sqrt(k / 2)`` of
    the median edge length: ``k = 2 (FOLD_MIN_MM / edge)^2`` rounded, 0 on a mesh whose edges
    are longer than 2 mm, at most :data:`FOLD_MAX_STEPS`.

    Parameters
    ----------
    vertices : (n, 3) float64
        3D positions, scan units.
    edges : (e, 2) int64
        The mesh's edges (the median length of about :data:`EDGE_SAMPLE` of them, spread over the list).
    mm_per_unit : float

    Returns
    -------
    int
    """
    if not len(edges):
        return 0
    some = edges[::max(1, len(edges) // EDGE_SAMPLE)]  # (the median of a spread sample: no gather of every edge)
    edge_mm = float(np.median(np.linalg.norm(vertices[some[:, 0]] - vertices[some[:, 1]], axis=1))) * mm_per_unit
    if not edge_mm > 0:
        return 0
    return int(min(round(2.0 * (FOLD_MIN_MM / edge_mm) ** 2), FOLD_MAX_STEPS))


def fold_masks(faces: np.ndarray, raw_uv: np.ndarray, *, steps: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Faces facing into the wall and faces lying over another sheet (see the module's
    docstring); with ``steps``, only those still so once the development around them is
    smoothed ``steps`` times (:func:`smoothing_steps`, :func:`_smoothed_around`).

    Parameters
    ----------
    faces : (m, 3) int64
    raw_uv : (n, 2) float64
        The proxy's development, before untangling.
    steps : int
        Each vertex halfway to the mean of its edge neighbours, this many times.

    Returns
    -------
    facing_in, overlapping : (m,) bool
    """
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    facing, over = signed_areas(faces, raw_uv) < 0, overlapping_faces(faces, raw_uv)
    folded = facing | over
    if steps > 0 and folded.any():
        uv, near = _smoothed_around(faces, raw_uv, folded, steps)
        facing[folded] &= signed_areas(faces[folded], uv) < 0
        over_near = np.zeros(len(faces), bool)
        over_near[near] = overlapping_faces(faces[near], uv)
        over &= over_near
    return facing, over


def _smoothed_around(faces: np.ndarray, raw_uv: np.ndarray, folded: np.ndarray,
                     steps: int) -> tuple[np.ndarray, np.ndarray]:
    """The development ``raw_uv`` (n, 2) smoothed ``steps`` times within ``steps`` rings of the
    ``folded`` (m,) faces, the rest left in place, and the faces (k,) int64 touching that
    region. A vertex of a folded face depends on the start within ``steps`` rings only, and
    the first wrong value (the region's edge, whose outer neighbours do not move) travels one
    ring a step from the second step, so the folded faces move exactly as in a smoothing of
    the whole development, at the cost of the region."""
    n = len(raw_uv)
    vf_ptr, vf_tri = vertex_faces(n, faces)
    inside = np.zeros(n, bool)
    frontier = np.unique(faces[folded])
    inside[frontier] = True
    for _ in range(steps):
        reached = np.unique(faces[incident_faces(frontier, vf_ptr, vf_tri)])
        frontier = reached[~inside[reached]]
        inside[frontier] = True
    region = np.flatnonzero(inside)
    uv = np.array(raw_uv, dtype=np.float64, order="C")
    corners = faces.astype(np.int32)  # (the relaxation's face type: one compiled kernel)
    mean = np.empty((len(region), 2))
    for _ in range(steps):
        neighbour_means(uv, region, vf_ptr, vf_tri, corners, mean)
        uv[region] = 0.5 * (uv[region] + mean)
    return uv, np.unique(incident_faces(region, vf_ptr, vf_tri))


def scan_folds(vertices: np.ndarray, faces: np.ndarray, facing_in: np.ndarray, overlapping: np.ndarray, *,
               height: np.ndarray, vessel_height: float, angle_deg: np.ndarray, mm_per_unit: float,
               steps: int = 0) -> ScanFolds:
    """Measure and locate the folded faces found by :func:`fold_masks`.

    Parameters
    ----------
    vertices : (n, 3) float64
        The rollout's 3D vertices.
    faces : (m, 3) int64
    facing_in, overlapping : (m,) bool
    height : (n,) float64
        Height of each vertex above the foot along the axis, scan units.
    vessel_height : float
        The vessel's height (scan units): heights as fractions of it are ``--band`` values.
    angle_deg : (n,) float64
        Angle of each vertex in the rollout's angles, degrees.
    mm_per_unit : float
    steps : int
        The smoothing steps ``facing_in`` and ``overlapping`` were judged with.

    Returns
    -------
    ScanFolds
    """
    import scipy.sparse
    import scipy.sparse.csgraph

    area = face_areas(vertices, faces) * mm_per_unit ** 2
    folded = np.flatnonzero(facing_in | overlapping).astype(np.int64)
    regions = []
    if len(folded):
        sub = faces[folded]
        inc = scipy.sparse.coo_matrix((np.ones(sub.size), (np.repeat(np.arange(len(sub)), 3), sub.ravel())),
                                      shape=(len(sub), len(vertices))).tocsr()
        _, label = scipy.sparse.csgraph.connected_components(inc @ inc.T, directed=False)
        a = area[folded]
        for c in np.argsort(-np.bincount(label, a), kind="stable"):
            mine = label == c
            verts = np.unique(sub[mine])
            w = a[mine]
            cen = vertices[sub[mine]].mean(axis=1)
            centroid = (w @ cen / w.sum()) if w.sum() > 0 else cen.mean(axis=0)
            h = height[verts]
            band = h / vessel_height if vessel_height > 0 else np.zeros(len(h))
            regions.append({"faces": int(mine.sum()), "area_mm2": float(w.sum()),
                            "height_mm": [float(h.min() * mm_per_unit), float(h.max() * mm_per_unit)],
                            "band": [float(band.min()), float(band.max())],
                            "angle_deg": [float(angle_deg[verts].min()), float(angle_deg[verts].max())],
                            "centroid": [float(x) for x in centroid]})
    return ScanFolds(faces=folded, facing_in=int(facing_in.sum()), overlapping=int(overlapping.sum()),
                     smoothing_steps=int(steps),
                     area_mm2=float(area[folded].sum()), surface_mm2=float(area.sum()), regions=regions)
