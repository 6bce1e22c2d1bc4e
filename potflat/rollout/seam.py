"""Where the rollout is cut open: the seam's angle (where the painting is least dense, a gap,
or the user's), the faces cut exactly along the seam's meridian and a window's sides
(:func:`cut_region`), and the cut that duplicates the vertices along them (:func:`cut_open`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from potflat.io.images import read_texture_grey
from potflat.mesh._kernels.geometry import angular_window_sums, corner_angles, texel_far_share, texel_histogram
from potflat.mesh._kernels.topology import corner_joins, half_edge_keys, union_find
from potflat.mesh.split import cut_moves, plane_levels, plane_weights, split_faces
from potflat.mesh.tolerances import ROUNDING
from potflat.types import Mesh

TWO_PI = 2.0 * np.pi


#: Angular bins (per turn) used to find gaps in a region.
SEAM_BINS = 360


#: Width (degrees) of the window, centred on a face's angle, over which the seam's cost is
#: summed.
SEAM_WINDOW_DEG = 5.0
#: Windows the seam's cost is summed over: one centred on each face, or on this many faces
#: evenly spread through a larger region's face list.
SEAM_WINDOWS = 200_000
#: The seam goes to the angle within this many degrees of the window chosen that is farthest
#: from every vertex's angle.
SEAM_SNAP_DEG = 0.5


#: Most lattice steps along a face's edge at which the seam's cost samples the texture (15
#: points per face, corners included); fewer on faces whose median edge spans fewer texels,
#: down to the corners alone on faces smaller than a texel.
INK_STEPS = 4
#: Grey levels (of 255) by which a sample must differ from its ground's grey to count as
#: painted: blue, black or red paint on a light or red ground differs by 60 and more, the
#: ground's own mottling and the scan's shading of it mostly by less.
INK_CONTRAST = 30
#: The ground grey and the lattice's spacing are taken from at most this many of a region's
#: faces, evenly spread through its face list.
INK_LEVEL_FACES = 200_000
#: Bands of equal height (of the region's) in each of which the ground grey is found on its
#: own: decoration runs in horizontal zones, each on its own ground, so black figures on a
#: terracotta belt of a black-glazed vessel are painting there, not the glaze.
GROUND_BANDS = 32

_LUMA = np.array([0.299, 0.587, 0.114])


def _painted_share(mesh: Mesh, faces: np.ndarray, area: np.ndarray,
                   height: np.ndarray) -> tuple[np.ndarray | None, str]:
    """Per-face share of samples that are painted: whose grey level differs from their
    ground's by more than :data:`INK_CONTRAST`; and its source. The ground is found in each
    of :data:`GROUND_BANDS` bands of the region's height on its own (:func:`_ground_levels`):
    light clay, a white slip, a black glaze, or a terracotta belt on a glazed body. Texture:
    samples on a lattice of about a texel's spacing (at most :data:`INK_STEPS` steps along an
    edge); vertex colours: the face's corners. Faces without texture count as unpainted.

    Parameters
    ----------
    mesh : Mesh
    faces : (k,) int64
        The region's faces.
    area : (k,) float64
        Their areas.
    height : (k,) float64
        Their centroids' heights along the axis.

    Returns
    -------
    share : (k,) float64 or None
        In [0, 1]; None without texture or vertex colours.
    source : str
        ``texture``, ``colours`` or ``geometry``.
    """
    if mesh.texcoords is not None and mesh.texture_path is not None:
        img = read_texture_grey(mesh.texture_path)
        if img is not None and img.size:
            band = _height_bands(height)
            tc = np.ascontiguousarray(mesh.texcoords, dtype=np.float64)
            idx = np.ascontiguousarray(faces, dtype=np.int64)
            img = np.ascontiguousarray(img)
            stride = max(-(-len(idx) // INK_LEVEL_FACES), 1)
            some = np.ascontiguousarray(idx[::stride])
            some_weight = np.array(area[::stride], dtype=np.float64)
            if mesh.untextured_faces is not None:  # no colour, no painting to keep whole
                some_weight[mesh.untextured_faces[some]] = 0.0
            edge_texels = np.hypot(*((tc[some, 1] - tc[some, 0]) * (img.shape[1], img.shape[0])).T)
            steps = int(np.clip(np.ceil(np.median(edge_texels)), 1, INK_STEPS)) if len(some) else 1
            hist = texel_histogram(tc, some, img, some_weight, steps, np.ascontiguousarray(band[::stride]),
                                   GROUND_BANDS)
            share = texel_far_share(tc, idx, img, _ground_levels(hist)[band], INK_CONTRAST, steps)
            if mesh.untextured_faces is not None:
                share[mesh.untextured_faces[idx]] = 0.0
            return share, "texture"
    if mesh.vertex_colors is not None:
        band = _height_bands(height)
        grey = np.clip(np.rint(mesh.vertex_colors[:, :3].astype(np.float64) @ _LUMA), 0, 255).astype(np.int64)
        corners = grey[mesh.faces[faces]]
        hist = np.bincount((band[:, None] * 256 + corners).ravel(), np.repeat(area / 3.0, 3),
                           GROUND_BANDS * 256).reshape(GROUND_BANDS, 256)
        return (np.abs(corners - _ground_levels(hist)[band][:, None]) > INK_CONTRAST).mean(axis=1), "colours"
    return None, "geometry"


def _height_bands(height: np.ndarray) -> np.ndarray:
    """The band of :data:`GROUND_BANDS` equal bands of the heights' range each height
    ((k,) float64) lies in, (k,) int64."""
    height = np.asarray(height, dtype=np.float64)
    span = float(np.ptp(height)) if len(height) else 0.0
    if span <= 0.0:
        return np.zeros(len(height), np.int64)
    return np.clip(((height - height.min()) / span * GROUND_BANDS).astype(np.int64), 0, GROUND_BANDS - 1)


def _ground_levels(hist: np.ndarray) -> np.ndarray:
    """The ground grey of each band from its histogram of grey levels weighted by area
    ((g, 256) float64): the level with the most weight within :data:`INK_CONTRAST` of it, so a
    light ground that the scan's shading spreads over many levels outweighs a dark paint of
    less area packed into a few. A band without samples takes the whole region's. (g,) int64."""
    near = np.ones(2 * INK_CONTRAST + 1)
    whole = int(np.argmax(np.convolve(hist.sum(axis=0), near, mode="same")))
    levels = np.array([np.argmax(np.convolve(h, near, mode="same")) for h in hist], dtype=np.int64)
    levels[hist.sum(axis=1) <= 0.0] = whole
    return levels


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


def _least_window(theta: np.ndarray, weight: np.ndarray) -> float:
    """Angle (radians) in the middle of the widest run of faces whose window of
    :data:`SEAM_WINDOW_DEG`, centred on the face's angle, holds the least weight.

    The windows are centred on the faces themselves (on at most :data:`SEAM_WINDOWS` of
    them, evenly spread through the face list), so the choice depends on the surface alone,
    not on the direction the angles are counted from (the scan's pose).

    Parameters
    ----------
    theta : (k,) float64
        Face-centroid angles, radians in ``[0, 2 pi)``.
    weight : (k,) float64
        Their costs.
    """
    theta = np.ascontiguousarray(theta, dtype=np.float64)
    stride = max(-(-len(theta) // SEAM_WINDOWS), 1)
    centres = np.sort(theta[::stride])
    buckets = int(2 ** np.ceil(np.log2(max(len(theta) / 32.0, 1024.0))))
    cost = angular_window_sums(theta, np.ascontiguousarray(weight, dtype=np.float64), centres,
                               float(np.radians(SEAM_WINDOW_DEG) / 2.0), buckets)
    low = cost <= cost.min() + ROUNDING * max(cost.max(), 1e-300)
    if low.all():
        return float(centres[0])
    ring = (np.arange(len(centres)) + int(np.argmin(low))) % len(centres)  # from a window above the least: no run wraps
    edges = np.diff(np.concatenate([[0], low[ring].astype(np.int8), [0]]))
    first, last = centres[ring[edges[:-1] == 1]], centres[ring[np.flatnonzero(edges == -1) - 1]]
    width = (last - first) % TWO_PI
    i = int(np.argmax(width))
    return float((first[i] + 0.5 * width[i]) % TWO_PI)


def choose_seam(mesh: Mesh, faces: np.ndarray, theta_c: np.ndarray, area: np.ndarray, height: np.ndarray,
                covered: np.ndarray | None = None, theta_v: np.ndarray | None = None) -> tuple[float, str]:
    """Seam angle (radians from the reference) where the region is least painted.

    Each face costs its area times (its painted share + 10 % of the mean share) when a
    texture or vertex colours exist, its area otherwise. The painted share is the share of
    its samples whose grey differs from the ground's by more than :data:`INK_CONTRAST`, the
    ground being the dominant grey of the face's band of height (:func:`_painted_share`), so
    a figure costs as much where it is filled as at its outline, and a painted ground (black
    glaze) as little as a plain one. The costs are
    summed over a window of :data:`SEAM_WINDOW_DEG` about each face's angle, and the seam
    goes to the middle of the widest run of faces with the least (:func:`_least_window`),
    then as far from every vertex's angle as it can be within :data:`SEAM_SNAP_DEG`
    (:func:`_snap_to_gap`), so that no vertex is put on the cut by rounding. When the
    region has an empty sector (no face spans it: a sherd, a scan with a gap from foot to
    rim) the seam goes to the middle of the widest one, and nothing needs to be cut.

    Parameters
    ----------
    mesh : Mesh
    faces : (k,) int64
        Indices of the region's faces.
    theta_c : (k,) float64
        Angles of their centroids, radians in ``[0, 2 pi)`` from the reference.
    area : (k,) float64
        Their areas.
    height : (k,) float64
        Their centroids' heights along the axis.
    covered : (SEAM_BINS,) bool, optional
        Angle bins (from the reference) covered by the faces' angular spans.
    theta_v : (v,) float64, optional
        Angles of the region's vertices (radians from the reference); without them, the
        faces' centroids stand in.

    Returns
    -------
    angle : float
        Radians in ``[0, 2 pi)``.
    method : str
        ``texture``, ``colours``, ``geometry``, or ``gap`` when the region has an empty sector.
    """
    if covered is not None and (gap := _gap_middle(covered)) is not None:
        return gap, "gap"
    painted, method = _painted_share(mesh, faces, area, height)
    weight = area if painted is None else area * (painted + 0.1 * max(float(np.average(painted, weights=area)), 1e-12))
    return _snap_to_gap(theta_c if theta_v is None else theta_v, _least_window(theta_c, weight),
                        np.radians(SEAM_SNAP_DEG)), method


def _snap_to_gap(theta: np.ndarray, angle: float, half_width: float) -> float:
    """The angle within ``half_width`` of ``angle`` farthest from all of ``theta`` (radians,
    vertex angles): in the gap between two of them that leaves the most room on both sides."""
    offset = (np.asarray(theta, dtype=np.float64) - angle + np.pi) % TWO_PI - np.pi
    if not len(offset):
        return angle
    below, above = offset[offset < -half_width], offset[offset > half_width]
    near = np.sort(np.concatenate([offset[np.abs(offset) <= half_width],
                                   [below.max() if len(below) else offset.max() - TWO_PI],
                                   [above.min() if len(above) else offset.min() + TWO_PI]]))
    lo, hi = near[:-1], near[1:]
    at = np.clip(0.5 * (lo + hi), -half_width, half_width)
    room = np.minimum(at - lo, hi - at)
    return float((angle + at[int(np.argmax(room))]) % TWO_PI)


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


def _auto_seam(mesh: Mesh, sel: np.ndarray, theta_c, theta_v, area, h_c) -> tuple[float, str]:
    corners = _corner_angles(theta_v, mesh.faces, sel, theta_c[sel])
    used = np.zeros(len(theta_v), bool)
    used[mesh.faces[sel]] = True
    return choose_seam(mesh, sel, theta_c[sel], area[sel], h_c[sel], _covered(theta_c[sel], corners), theta_v[used])


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


@dataclass(frozen=True, eq=False)
class CutOrigins:
    """Where the faces and vertices of a cut region come from in the scan (:func:`cut_region`).

    Attributes
    ----------
    face_index : (m,) int64
        The scan face of each face (a face cut in pieces appears once per piece).
    repeated : (m,) bool
        Faces that repeat the start past 360 degrees (they come last).
    pieces : (p,) int64
        The faces that are pieces of a cut scan face, or a scan face with a corner moved
        onto a cut.
    weights : (p, 3, 3) float64
        Their corners as weights of their scan face's corners (a moved corner's: of its
        projection onto the face's plane).
    added_edges : (j, 2) int64
        The edge each added vertex (index ``n + j``) lies on; an end may be an earlier added
        vertex.
    added_t : (j,) float64
        Where on it: ``(1 - t) x[a] + t x[b]``.
    n : int
        Vertices of the scan.
    """

    face_index: np.ndarray
    repeated: np.ndarray
    pieces: np.ndarray
    weights: np.ndarray
    added_edges: np.ndarray
    added_t: np.ndarray
    n: int

    @classmethod
    def whole(cls, face_index: np.ndarray, repeated: np.ndarray, n: int) -> "CutOrigins":
        """Scan faces taken whole (a region that needs no cut)."""
        return cls(face_index=face_index, repeated=repeated, pieces=np.zeros(0, np.int64),
                   weights=np.zeros((0, 3, 3)), added_edges=np.zeros((0, 2), np.int64), added_t=np.zeros(0), n=n)

    def vertex_values(self, values: np.ndarray, index: np.ndarray) -> np.ndarray:
        """A per-vertex value of the scan at the vertices ``index``, the added ones
        interpolated along their edges.

        Parameters
        ----------
        values : (n, ...) array
            Positions, or colours (rounded back to their integer type).
        index : (k,) int64
            Vertices (``>= n``: added).

        Returns
        -------
        (k, ...) array of the dtype of ``values``
        """
        index = np.asarray(index, np.int64)
        added = index >= self.n
        if not added.any():
            return np.take(values, index, axis=0)
        at = np.zeros((len(self.added_t),) + values.shape[1:])
        done = np.zeros(len(self.added_t), bool)
        ends = self.added_edges
        while not done.all():  # (an added vertex may lie on an edge of earlier ones: a few rounds)
            known = (ends < self.n) | done[np.maximum(ends - self.n, 0)]
            ready = np.flatnonzero(~done & known.all(axis=1))
            a, b = (np.where((e < self.n).reshape((-1,) + (1,) * (values.ndim - 1)),
                             np.take(values, np.minimum(e, self.n - 1), axis=0), at[np.maximum(e - self.n, 0)])
                    for e in ends[ready].T)
            t = self.added_t[ready].reshape((-1,) + (1,) * (values.ndim - 1))
            at[ready] = a + t * (b - a)
            done[ready] = True
        if np.issubdtype(values.dtype, np.integer):
            info = np.iinfo(values.dtype)
            at = np.clip(np.rint(at), info.min, info.max)
        out = np.empty((len(index),) + values.shape[1:], values.dtype)
        out[~added] = np.take(values, index[~added], axis=0)
        out[added] = at[index[added] - self.n]
        return out

    def face_fields(self, mesh: Mesh) -> dict:
        """``mesh.face_fields`` of the faces' scan faces (:meth:`potflat.types.Mesh.face_fields`),
        the pieces' texture coordinates interpolated within their scan face."""
        fields = mesh.face_fields(self.face_index)
        if fields["texcoords"] is not None and len(self.pieces):
            fields["texcoords"][self.pieces] = self.weights @ mesh.texcoords[self.face_index[self.pieces]]
        return fields

    def subset(self, keep: np.ndarray) -> "CutOrigins":
        """The same for the faces ``keep`` ((m,) bool) selects."""
        row = np.cumsum(keep) - 1
        kept = keep[self.pieces]
        return CutOrigins(face_index=self.face_index[keep], repeated=self.repeated[keep], pieces=row[self.pieces[kept]],
                          weights=self.weights[kept], added_edges=self.added_edges, added_t=self.added_t, n=self.n)


def cut_region(V: np.ndarray, F: np.ndarray, faces: np.ndarray, centre: np.ndarray, corner_theta: np.ndarray, *,
               start: float, end: float, repeat_from: float | None, meridian, floors=()
               ) -> tuple[np.ndarray, np.ndarray, CutOrigins]:
    """The region between the unwrapped angles ``start`` and ``end``, its faces cut exactly
    along the meridians there.

    Every face lies at its unwrapped angles and a turn before and after; each such copy
    that reaches into ``(start, end)`` is kept, and a copy across ``start``, ``end`` or
    ``repeat_from`` is cut along that angle's meridian half-plane
    (:func:`potflat.mesh.split.split_faces`): vertices are added where edges cross it, and
    the pieces outside the region are left out. So the region's sides are exact meridians
    (straight in every development) at any resolution. A vertex closer to a meridian than
    :data:`potflat.mesh.split.CUT_SNAP` of a crossing edge is moved along that edge onto it
    (:func:`potflat.mesh.split.cut_moves`): it becomes an added vertex there, and the faces
    around it pieces whose corner has the weights their plane gives the new point
    (:func:`potflat.mesh.split.plane_weights`). A corner on a cut gets exactly the
    meridian's angle. Faces spanning half a turn or more (around the axis
    itself) are not cut: kept once where their centre lies in the region.

    Parameters
    ----------
    V : (n, 3) float64
    F : (f, 3) int64
        The scan.
    faces : (k,) int64
        The candidate faces, in order.
    centre : (k,) float64
        Their unwrapped angles (radians from the origin of the region's angles).
    corner_theta : (k, 3) float64
        Their corners' angles unwrapped to within pi of ``centre``.
    start, end : float
        The region, unwrapped radians; ``end - start`` at most one and a half turns.
    repeat_from : float or None
        Where a repeat past 360 degrees starts (faces beyond it are ``repeated``); None: no
        repeat.
    meridian : callable
        ``meridian(angle)``: a point of the axis and the unit normal of the meridian plane
        at unwrapped ``angle``, the normal pointing towards increasing angles.
    floors : sequence of ((f,) bool, callable, callable)
        Cuts along level sets made before the meridians', in order: the line between the
        two walls (:class:`potflat.rollout.walls.WallCut`), a base cut off
        (:class:`potflat.rollout.base.BaseCut`). Each is the scan faces it splits,
        ``levels(ids, points)``, the signed level of the vertices ``ids`` (scan vertices,
        then vertices an earlier cut added) at ``points`` (k, 3), and ``angle(points)``, the
        angle of points (k, 3) in the region's angles (any turn); those faces (and their
        pieces) are cut along it (the base's the same pieces as its disc) and their pieces
        on its positive side kept.

    Returns
    -------
    faces : (m, 3) int64
        The region's faces: index ``i < n`` is vertex ``i`` of the scan, ``n + j`` the
        ``j``-th added vertex (:class:`CutOrigins`).
    corner_theta : (m, 3) float64
        Unwrapped angle of each corner; exactly the meridian's at a corner on a cut.
    origins : CutOrigins
    """
    n = len(V)
    lo, hi = corner_theta.min(axis=1), corner_theta.max(axis=1)
    narrow = hi - lo < np.pi
    parts = []
    for k in (0, -1, 1):
        shift = TWO_PI * k
        meets = narrow & (hi + shift > start) & (lo + shift < end)
        if k == 0:
            meets |= ~narrow & (centre >= start) & (centre <= end)
        sel = np.flatnonzero(meets)
        parts.append((sel, corner_theta[sel] + shift))
    rows_face = np.concatenate([faces[sel] for sel, _ in parts])
    T = np.concatenate([t for _, t in parts])
    rows_narrow = np.concatenate([narrow[sel] for sel, _ in parts])
    del parts
    row_faces = np.take(F, rows_face, axis=0)
    # the cut angles, grouped by meridian (angles a whole turn apart share one)
    cuts = sorted({start, end} | ({repeat_from} if repeat_from is not None else set()))
    planes: dict[float, list[float]] = {}
    for c in cuts:
        planes.setdefault(round(float(c % TWO_PI), 12) % round(TWO_PI, 12), []).append(c)
    pieces_w = np.zeros((0, 3, 3))
    piece_of = np.full(len(rows_face), -1, np.int64)  # row -> its row in pieces_w
    added_edges, added_t, added_pts = np.zeros((0, 2), np.int64), np.zeros(0), np.zeros((0, 3))

    def splice(rows, ids, split, keep_piece, corner_theta_of):
        """Replace each row across a cut by its pieces that ``keep_piece(piece, src)`` keeps (in place)."""
        nonlocal T, row_faces, rows_face, rows_narrow, piece_of, pieces_w, added_edges, added_t, added_pts
        # added vertices (their ends are vertices of the scan or earlier added ones)
        base = n + len(added_t)
        added_edges = np.concatenate([added_edges, ids[split.edges]])
        added_t = np.concatenate([added_t, split.t])
        added_pts = np.concatenate([added_pts, split.added(pts_of(ids))])
        piece = np.arange(len(split.parent))  # (grouped by face, in order)
        src = rows[split.parent]
        keep = keep_piece(piece, src)
        piece, src = piece[keep], src[keep]
        w = split.weights[piece]
        new_T = corner_theta_of(w, src)
        local_faces = split.faces[piece]
        new_faces = np.where(local_faces < len(ids), ids[np.minimum(local_faces, len(ids) - 1)],
                             base + local_faces - len(ids))
        parent_w = piece_of[src]
        if len(pieces_w):  # a piece of a piece: its corners as weights of the scan face's
            w = np.where((parent_w >= 0)[:, None, None], w @ pieces_w[np.maximum(parent_w, 0)], w)
        # each row across is replaced by its kept pieces, in place: the other rows are
        # compacted (np.delete) and the pieces inserted before the row that followed theirs
        # (one array at a time, the old one dropped at once: these are the region's largest)
        before = src - np.searchsorted(rows, src)
        stay_pieces = np.delete(piece_of, rows)
        kept = np.flatnonzero(stay_pieces >= 0)
        pieces_w = np.concatenate([pieces_w[stay_pieces[kept]], w])
        stay_pieces[kept] = np.arange(len(kept))
        piece_of = np.insert(stay_pieces, before, len(kept) + np.arange(len(w)))
        del stay_pieces, kept
        T = np.insert(np.delete(T, rows, axis=0), before, new_T, axis=0)
        row_faces = np.insert(np.delete(row_faces, rows, axis=0), before, new_faces, axis=0)
        rows_narrow = np.insert(np.delete(rows_narrow, rows), before, True)
        rows_face = np.insert(np.delete(rows_face, rows), before, rows_face[src])

    def pts_of(ids):
        """Points (..., 3) of the vertices ``ids`` (int64, any shape)."""
        out = np.empty(ids.shape + (3,))
        scan = ids < n
        out[scan] = V[ids[scan]]
        out[~scan] = added_pts[ids[~scan] - n]
        return out

    def move_onto_cut(verts, towards, t, points):
        """Replace the vertices ``verts`` in every row by added vertices at ``points`` on their
        edges to ``towards`` (at ``t``); the rows they are corners of become pieces."""
        nonlocal row_faces, piece_of, pieces_w, added_edges, added_t, added_pts
        base = n + len(added_t)
        added_edges = np.concatenate([added_edges, np.stack([verts, towards], axis=1)])
        added_t = np.concatenate([added_t, t])
        added_pts = np.concatenate([added_pts, points])
        new_id = np.full(base, -1, np.int64)
        new_id[verts] = base + np.arange(len(verts))
        moved = new_id[row_faces] >= 0
        rows = np.flatnonzero(moved.any(axis=1))
        at, hit = row_faces[rows], moved[rows]
        corners = pts_of(at)
        # each moved corner as weights of its row's corners (the row's linear map extended)
        b = np.broadcast_to(np.eye(3), (len(rows), 3, 3)).copy()
        r, c = np.nonzero(hit)
        b[r, c] = plane_weights(corners[r], added_pts[new_id[at[r, c]] - n])
        prev = piece_of[rows]
        old = prev >= 0
        w = b.copy()
        w[old] = b[old] @ pieces_w[prev[old]]
        pieces_w = np.concatenate([pieces_w, w[~old]])
        pieces_w[prev[old]] = w[old]
        piece_of[rows[~old]] = len(pieces_w) - np.count_nonzero(~old) + np.arange(np.count_nonzero(~old))
        row_faces[rows] = np.where(hit, new_id[at], at)

    for cut_faces, levels, angle in floors:  # the level cuts first: the pieces on their positive side stay
        rows = np.flatnonzero(cut_faces[rows_face])
        if len(rows):
            ids, local = np.unique(row_faces[rows], return_inverse=True)
            pts = pts_of(ids)
            split = split_faces(pts, local.reshape(-1, 3), levels(ids, pts))

            def floor_theta(w, src, ids=ids, pts=pts, angle=angle):
                # each corner's angle at its point, unwrapped next to its face's corners'
                near = np.einsum("kij,kj->ki", w, T[src])
                corners = pts[np.searchsorted(ids, row_faces[src])]
                at = angle((w @ corners).reshape(-1, 3)).reshape(near.shape)
                return near + (at - near + np.pi) % TWO_PI - np.pi

            splice(rows, ids, split, lambda piece, src, split=split: split.side[piece] > 0, floor_theta)
    if floors:  # the part a level cut keeps of a face reaching into the region can lie wholly outside it
        inside = ~rows_narrow | ((T.max(axis=1) > start) & (T.min(axis=1) < end))
        if not inside.all():
            T, row_faces, rows_face, rows_narrow, piece_of = (a[inside] for a in (T, row_faces, rows_face, rows_narrow,
                                                                                    piece_of))
    for values in planes.values():
        r_lo, r_hi = T.min(axis=1), T.max(axis=1)
        across = np.zeros(len(T), bool)
        c_row = np.zeros(len(T))
        for c in values:
            hit = rows_narrow & (r_lo < c) & (c < r_hi)
            across |= hit
            c_row[hit] = c
        rows = np.flatnonzero(across)
        if not len(rows):
            continue
        # the faces across it, on their own vertices
        point, normal = meridian(values[0])
        ids, local = np.unique(row_faces[rows], return_inverse=True)
        local = local.reshape(-1, 3)
        pts = pts_of(ids)
        level = plane_levels(pts, point, normal)
        near, towards, t = cut_moves(local, level)
        if len(near):  # the vertices the cut would snap to, moved onto the meridian
            move_onto_cut(ids[near], ids[towards], t, pts[near] + t[:, None] * (pts[towards] - pts[near]))
            ids, local = np.unique(row_faces[rows], return_inverse=True)
            local = local.reshape(-1, 3)
            pts = pts_of(ids)
            level = plane_levels(pts, point, normal)
            level[ids >= n + len(added_t) - len(near)] = 0.0
        split = split_faces(pts, local, level)
        on_cut = np.zeros(n + len(added_t), bool)
        on_cut[ids[split.on_cut]] = True
        if split.on_cut.size:  # a corner on the cut gets the meridian's angle, in every face
            at = on_cut[row_faces]
            # and so does every vertex at its angle: copies of a vertex (a non-manifold one
            # split into fans) are not left beside it
            at |= _among(T, np.unique(T[at]))
            T[at] = values[0] + TWO_PI * np.round((T[at] - values[0]) / TWO_PI)

        def keep_piece(piece, src, split=split, c_row=c_row):
            c_src = c_row[src]
            return ((split.side[piece] > 0) & (c_src < end)) | ((split.side[piece] < 0) & (c_src > start))

        def corner_theta_of(w, src, c_row=c_row):
            # each row across the cut becomes its face's pieces inside the region
            is_corner = w.max(axis=2) == 1.0
            return np.where(is_corner, np.take_along_axis(T[src], np.argmax(w, axis=2), axis=1), c_row[src][:, None])

        splice(rows, ids, split, keep_piece, corner_theta_of)
    repeated = (rows_narrow & (T.min(axis=1) >= repeat_from) if repeat_from is not None
                else np.zeros(len(T), bool))
    if repeated.any():  # repeats last
        order = np.concatenate([np.flatnonzero(~repeated), np.flatnonzero(repeated)])
        T, row_faces, rows_face, piece_of, repeated = (a[order] for a in (T, row_faces, rows_face, piece_of, repeated))
    pieces = np.flatnonzero(piece_of >= 0)
    weights = pieces_w[piece_of[pieces]]
    cut = ~np.all(weights == np.eye(3), axis=(1, 2))  # (not a face left whole by its vertices on the cut)
    return row_faces, T, CutOrigins(face_index=rows_face, repeated=repeated, pieces=pieces[cut], weights=weights[cut],
                                    added_edges=added_edges, added_t=added_t, n=n)


#: Rows of a (k, 3) array :func:`_among` looks up at once (its temporaries: some 100 MB).
_AMONG_ROWS = 1 << 20


def _among(values: np.ndarray, sorted_set: np.ndarray) -> np.ndarray:
    """Which of ``values`` ((k, 3) float64) are exactly in ``sorted_set`` ((m,) float64,
    sorted, unique): ``np.isin`` by binary search, a block of rows at a time (``np.isin`` of
    a large array sorts it with the set, several copies of its size at once)."""
    out = np.zeros(values.shape, bool)
    if not len(sorted_set):
        return out
    last = len(sorted_set) - 1
    for lo in range(0, len(values), _AMONG_ROWS):
        block = values[lo:lo + _AMONG_ROWS]
        out[lo:lo + _AMONG_ROWS] = sorted_set[np.minimum(np.searchsorted(sorted_set, block), last)] == block
    return out
