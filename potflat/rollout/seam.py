"""Where the rollout is cut open: the seam's angle (where the painting is least dense, a gap,
or the user's), and the cut that duplicates the vertices along it."""
from __future__ import annotations

import numpy as np

from potflat.io.images import read_texture_grey_quarter
from potflat.mesh._kernels.geometry import corner_angles, texel_spread
from potflat.mesh._kernels.topology import corner_joins, half_edge_keys, union_find
from potflat.mesh.tolerances import ROUNDING
from potflat.types import Mesh

TWO_PI = 2.0 * np.pi


#: Angular bins (per turn) used to choose the seam and to find gaps in a region.
SEAM_BINS = 360


#: Width (bins) of the circular moving average applied to the seam cost.
SEAM_SMOOTH = 5


def _luminance_variation(mesh: Mesh, faces: np.ndarray) -> tuple[np.ndarray | None, str]:
    """Per-face spread of brightness (std of samples at its corners), and its source."""
    if mesh.texcoords is not None and mesh.texture_path is not None:
        img = read_texture_grey_quarter(mesh.texture_path)
        if img is not None and img.size:
            spread = texel_spread(np.ascontiguousarray(mesh.texcoords, dtype=np.float64),
                                  np.ascontiguousarray(faces, dtype=np.int64), np.ascontiguousarray(img))
            if mesh.untextured_faces is not None:  # no colour, no painting to keep whole
                spread[mesh.untextured_faces[faces]] = 0.0
            return spread, "texture"
    if mesh.vertex_colors is not None:
        rgb = mesh.vertex_colors[:, :3].astype(np.float64)
        lum = rgb @ np.array([0.299, 0.587, 0.114])
        return lum[mesh.faces[faces]].std(axis=1), "colours"
    return None, "geometry"


def _longest_min_run(cost: np.ndarray) -> int:
    """Index of the middle of the longest circular run of (near-)minimal bins."""
    low = cost <= cost.min() + ROUNDING * max(cost.max(), 1e-300)
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
    return round(start + best_mid) % k


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
    return _snap_to_gap(theta_c, (k + 0.5) / SEAM_BINS * TWO_PI, TWO_PI / SEAM_BINS), method


def _snap_to_gap(theta_c: np.ndarray, angle: float, half_width: float) -> float:
    """Move ``angle`` to the middle of the widest gap between face-centroid angles within
    ``half_width`` of it, so the cut lies at a place of the surface, not of the bin grid
    (whose origin, the reference direction, depends on the scan's pose)."""
    offset = (theta_c - angle + np.pi) % TWO_PI - np.pi
    near = np.sort(offset[np.abs(offset) <= half_width])
    if len(near) < 2:
        return angle
    gaps = np.diff(near)
    i = int(np.argmax(gaps))
    return float((angle + 0.5 * (near[i] + near[i + 1])) % TWO_PI)


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
    F = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
    corner_v = F.ravel()
    th = np.ascontiguousarray(corner_theta, dtype=np.float64).ravel()
    # half-edges on the same edge are neighbours when sorted by (lower vertex, higher vertex,
    # turn of the angle at the lower vertex) (stable: by id on ties). The turn puts the faces of
    # an edge listed twice (a rollout repeated past 360 degrees) next to those they join: 0+,
    # 2 pi-, 2 pi+. Their corners at each end are joined where the faces agree on the angle.
    # (NumPy's sort of the keys, nearly sorted in a scan's face order, is faster than a
    # counting sort by edge, whose scattered writes miss the cache.)
    key = half_edge_keys(F, th, int(corner_v.max()) + 1 if m else 1)
    a, b = corner_joins(F, th, key, np.argsort(key, kind="stable"))
    del key
    labels, n_comp = union_find(3 * m, a, b)
    del a, b
    # components are numbered in order of their lowest corner: where the running maximum grows
    run = np.maximum.accumulate(labels)
    first = np.flatnonzero(np.concatenate([[m > 0], run[1:] != run[:-1]]))  # lowest corner of each
    del run
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


def _auto_seam(mesh: Mesh, sel: np.ndarray, theta_c, theta_v, area) -> tuple[float, str]:
    corners = _corner_angles(theta_v, mesh.faces, sel, theta_c[sel])
    return choose_seam(mesh, sel, theta_c[sel], area[sel], _covered(theta_c[sel], corners))


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
    # (column by column: NumPy's reduction along a row of three is 2.5x slower)
    lo = np.minimum(np.minimum(corner_theta[:, 0], corner_theta[:, 1]), corner_theta[:, 2])
    hi = np.maximum(np.maximum(corner_theta[:, 0], corner_theta[:, 1]), corner_theta[:, 2])
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


def _corner_angles(theta_v: np.ndarray, F: np.ndarray, idx: np.ndarray, centre: np.ndarray,
                   shift: float = 0.0) -> np.ndarray:
    """Corner angles of the faces ``F[idx]``, ``theta_v - shift`` unwrapped to within pi of
    ``centre`` ((k,) angle of each face). Shape (k, 3)."""

    out = np.empty((len(idx), 3))
    corner_angles(np.ascontiguousarray(theta_v, dtype=np.float64), np.ascontiguousarray(F, dtype=np.int64),
                  np.ascontiguousarray(idx, dtype=np.int64), np.ascontiguousarray(centre, dtype=np.float64),
                  float(shift), out)
    return out
