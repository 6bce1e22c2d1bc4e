"""The development's border: faces that fold it over (edge-on strips, overlapping border
faces) trimmed off, and faces folded inside it untangled."""
from __future__ import annotations

import numpy as np

from potflat.mesh._kernels.topology import faces_touching, incident_faces, small_pieces, union_find, vertex_faces
from potflat.mesh.boundary import crossing_pairs, edges_and_boundary
from potflat.mesh.embedding import fan_edges, neighbour_rows, signed_areas, vertex_clusters
from potflat.rollout.folds import overlapping_faces
from potflat.rollout.seam import cut_open
from potflat.rollout.walls import (
    FaceGraph,
)

#: Rounds of :func:`untangle`; its region widens by one ring every ``UNTANGLE_WIDEN`` rounds.
UNTANGLE_ROUNDS, UNTANGLE_WIDEN = 200, 20


#: A face is edge-on to the proxy when its flat area is below this fraction of its 3D area.
EDGE_ON_RATIO = 0.05


#: Rounds of trimming folded border faces: each cuts them from the development, and all but
#: the last develop what is kept again on its proxy, fitted (or chosen) again without them.
TRIM_ROUNDS = 3


#: Passes of :func:`border_folds` over one development (each peels what the last exposed).
BORDER_PASSES = 50
#: Where the border crosses itself, faces whose flat area is below this fraction of their 3D
#: area (the thin rows along a fold) are trimmed with the crossing region (:func:`border_folds`).
SQUEEZED_RATIO = 0.25
#: A piece that trimming cuts off a connected part of the development is trimmed with it
#: when its area is below this fraction of that part's (:func:`border_folds`).
CUT_OFF_FRACTION = 0.1


def border_folds(faces: np.ndarray, uv: np.ndarray, area_3d: np.ndarray, *,
                 points: np.ndarray | None = None, graph: FaceGraph | None = None) -> np.ndarray:
    """Faces at the border of a development that fold it over: to trim before relaxing.

    Two kinds, peeled in up to :data:`BORDER_PASSES` passes (each pass looks at the border
    the previous one exposed):
    * **edge-on strips**: a face is edge-on when its flat signed area is below
      :data:`EDGE_ON_RATIO` times its 3D area (it faces along the proxy surface, not out
      of it: a rim top, a flat base's underside, the break faces of a thick sherd, the wall
      of a hole through a thick wall). A connected strip of edge-on faces that contains a
      flipped face (signed area <= 0) and reaches the boundary (the outline, the seam, a
      hole) is not part of the painted surface and cannot be unrolled without a fold.
    * **overlapping border**: where boundary segments cross or touch another boundary
      segment (a ragged rim or hole edge whose thin border faces overlap their neighbours, a
      flap folded back over the wall), the whole crossing region at once: the faces owning
      them and, joined to them through shared edges, the faces lying over another
      (:func:`potflat.rollout.folds.overlapping_faces`: both sheets) or squeezed below
      :data:`SQUEEZED_RATIO` of their 3D area (the thin rows of a fold).
    * **pinched vertices**: where a vertex's faces form separate fans (they meet at the
      vertex only, e.g. after trimming), all but the fan of largest area are left out, so
      the development does not touch itself. Boundary vertices at the same 3D place (with
      ``points``: the copies of a non-manifold vertex that cleaning the scan split into one
      per fan) count as one vertex.
    * **cut-off pieces**: a piece that trimming separated from a connected part of the
      development, with less than :data:`CUT_OFF_FRACTION` of that part's area (the
      outside of a foot beyond the edge-on band where the surface turns under): left as
      it is, it lies over the wall and would be peeled a ring of faces per pass.
    * **teeth**: once nothing else is to trim, the faces left standing along what was
      trimmed, with two edges or all three corners on trimmed faces (a noisy rim top's
      edge-on faces are trimmed face by face), in one pass: the trimmed border's outline
      without its spikes, and no deeper.

    Folds enclosed by well-unrolled faces (scan noise, slivers) are left to :func:`untangle`.

    The edge table, face adjacency, flat areas and overlapping faces are found once; a pass
    updates the border around the faces the last one peeled (:class:`_KeptBorder`) and
    looks at those faces' surroundings, so a pass costs about the faces it touches.

    Parameters
    ----------
    faces : (m, 3) int64
        Faces of the cut mesh.
    uv : (n, 2) float64
        Its development.
    area_3d : (m,) float64
        3D area of each face.
    points : (n, 3) float64, optional
        The vertices' 3D positions (to find copies of a vertex, see above).
    graph : FaceGraph, optional
        ``FaceGraph(faces)`` when the caller has it (its edge table and adjacency are reused).

    Returns
    -------
    (m,) bool
    """
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    keep = np.ones(len(faces), bool)
    graph = FaceGraph(faces) if graph is None else graph
    border = _KeptBorder(faces, len(uv), graph.edge_table)
    part = graph.components()
    part_area = np.bincount(part, area_3d)
    flat = signed_areas(faces, uv)
    edge_on = np.flatnonzero(flat < EDGE_ON_RATIO * area_3d)
    flipped = np.flatnonzero(flat <= 0)
    squeezed = np.flatnonzero(flat < SQUEEZED_RATIO * area_3d)
    over = None  # faces lying over another among all faces (those among the kept are a subset)
    dropped = None
    spiked = False
    for _ in range(BORDER_PASSES):
        if not keep.any():
            break
        seg, owner = border.segments()
        same = None if points is None else _same_place(points, seg)
        drop = (_edge_on_strips(faces, keep, flat, edge_on, flipped, seg, len(uv))
                | _minor_fans(faces, area_3d, keep, border, same))
        if dropped is not None:
            drop |= _cut_off(graph, keep, area_3d, part, part_area, changed=dropped)
        if not drop.any():  # overlaps are judged on a border without folded strips
            a, b = crossing_segments(uv, seg)
            if len(a):
                if over is None:
                    over = np.flatnonzero(overlapping_faces(faces, uv))
                drop = _crossing_region(graph, faces, keep, uv, over, squeezed, np.concatenate([owner[a], owner[b]]))
        if not drop.any() and not spiked and not keep.all():
            drop, spiked = _spikes(faces, graph, keep, len(uv)), True
        if not drop.any():
            break
        keep[drop] = False
        dropped = np.flatnonzero(drop)
        border.drop(dropped, keep)
    return ~keep


def _spikes(faces: np.ndarray, graph: FaceGraph, keep: np.ndarray, n: int) -> np.ndarray:
    """The teeth left standing along a trimmed border ((m,) bool): kept faces with two or
    three edges on faces trimmed, or with all three corners on them."""
    a, b = graph.pairs[:, 0], graph.pairs[:, 1]
    m = len(keep)
    count = (np.bincount(a[keep[a] & ~keep[b]], minlength=m) + np.bincount(b[keep[b] & ~keep[a]], minlength=m))
    on_trimmed = np.zeros(n, bool)
    on_trimmed[faces[~keep].ravel()] = True
    return keep & ((count >= 2) | on_trimmed[faces].all(axis=1))


class _KeptBorder:
    """The boundary of the kept faces of a mesh, updated as faces are dropped.

    Holds each edge's count of kept faces, which half-edges are boundary (their edge has one
    kept face) and each vertex's kept edges minus kept corners (:func:`_minor_fans`); dropping
    faces updates them around those faces only.

    Parameters
    ----------
    faces : (m, 3) int64
    n : int
        Number of vertices.
    table : tuple
        The faces' :func:`potflat.mesh._kernels.topology.edge_table` (not modified).
    """

    def __init__(self, faces: np.ndarray, n: int, table: tuple) -> None:
        self.faces = faces
        self.edge_of, self.edges, count, self.halves = table
        self.count = count.copy()
        self.boundary = self.count[self.edge_of] == 1  # per half-edge (all faces kept)
        many = count > 2  # edges of more than two faces: their halves beyond the first two
        extra = np.flatnonzero(many[self.edge_of]) if many.any() else np.zeros(0, np.int64)
        self.extra_edge, self.extra = self.edge_of[extra], extra
        self.excess = (np.bincount(self.edges.ravel(), minlength=n)
                       - np.bincount(faces.ravel(), minlength=n))  # kept edges - kept corners per vertex

    def segments(self) -> tuple[np.ndarray, np.ndarray]:
        """Boundary segments (b, 2) int64 in face order, and the face of each."""
        half = np.flatnonzero(self.boundary)
        face, k = half // 3, half % 3
        return np.stack([self.faces[face, k], self.faces[face, (k + 1) % 3]], axis=1), face

    def drop(self, dropped: np.ndarray, keep: np.ndarray) -> None:
        """Update after the faces ``dropped`` (k,) int64 left ``keep`` (m,) bool (already cleared)."""
        halves = (3 * dropped[:, None] + np.arange(3)).ravel()
        edge = self.edge_of[halves]
        np.subtract.at(self.count, edge, 1)
        np.add.at(self.excess, self.faces[dropped].ravel(), 1)
        self.boundary[halves] = False
        touched = np.unique(edge)
        gone = touched[self.count[touched] == 0]
        np.subtract.at(self.excess, self.edges[gone].ravel(), 1)
        near = self.halves[touched].ravel()
        if len(self.extra):
            near = np.concatenate([near, self.extra[np.isin(self.extra_edge, touched)]])
        near = near[near >= 0]
        near = near[keep[near // 3]]
        self.boundary[near] = self.count[self.edge_of[near]] == 1

    def faces_at(self, vertices: np.ndarray) -> np.ndarray:
        """The faces (sorted, unique) with a corner at one of ``vertices`` (k,) int64 (a mask
        over the corners: a vertex-to-face table of the whole mesh would set the rollout's peak)."""
        at = np.zeros(len(self.excess), bool)
        at[vertices] = True
        return faces_touching(at, self.faces)


def _crossing_region(graph: FaceGraph, faces: np.ndarray, keep: np.ndarray, uv: np.ndarray, over: np.ndarray,
                     squeezed: np.ndarray, owners: np.ndarray) -> np.ndarray:
    """The faces (m,) bool of the regions where the border of the kept faces (``keep`` (m,)
    bool) crosses itself: the ``owners`` of crossing segments and the kept faces lying over
    another kept face or squeezed (:data:`SQUEEZED_RATIO`) joined to them through shared
    edges (``graph``: the whole development's face adjacency). ``over`` are the faces lying
    over another among all faces (a kept face lies over a kept face only if both are
    there), ``squeezed`` the squeezed faces."""
    region = np.zeros(len(faces), bool)
    cand = over[keep[over]]
    region[cand[overlapping_faces(faces[cand], uv)]] = True
    region[squeezed[keep[squeezed]]] = True
    region[owners] = True
    sel = np.flatnonzero(region)
    indptr, indices = graph.neighbours
    count = indptr[sel + 1] - indptr[sel]
    row = np.repeat(np.arange(len(sel)), count)
    other = indices[np.repeat(indptr[sel], count) + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)]
    at = np.minimum(np.searchsorted(sel, other), len(sel) - 1)
    inside = sel[at] == other
    label, _ = union_find(len(sel), row[inside], at[inside])
    reached = np.zeros(len(sel), bool)
    reached[label[np.searchsorted(sel, owners)]] = True
    region[sel[~reached[label]]] = False
    return region


def _cut_off(graph: FaceGraph, keep: np.ndarray, area_3d: np.ndarray, part: np.ndarray,
             part_area: np.ndarray, changed: np.ndarray | None = None) -> np.ndarray:
    """Kept faces (``keep`` (m,) bool) of the pieces that trimming cut off a connected part of
    the development, with less than :data:`CUT_OFF_FRACTION` of its area (see
    :func:`border_folds`); ``graph`` is the whole development's face adjacency, ``part`` (m,)
    each face's part before trimming, ``part_area`` the parts' areas.

    With ``changed`` (k,) int64, the faces dropped since every piece was last at least that
    large: only the pieces next to them are looked at, each explored until it reaches that
    area (:func:`potflat.mesh._kernels.topology.small_pieces`)."""
    if changed is not None:
        indptr, indices = graph.neighbours
        return small_pieces(indptr, indices, keep, np.ascontiguousarray(area_3d, dtype=np.float64), changed,
                            CUT_OFF_FRACTION * part_area[part])
    pairs = graph.pairs
    piece = graph.components(keep[pairs[:, 0]] & keep[pairs[:, 1]])
    area = np.bincount(piece, np.where(keep, area_3d, 0.0))
    of = np.zeros(len(area), np.int64)
    of[piece] = part
    return (area < CUT_OFF_FRACTION * part_area[of])[piece] & keep


def crossing_segments(uv: np.ndarray, seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of segments that cross or touch (:func:`potflat.mesh.boundary.crossing_pairs`),
    but for pairs of two zero-length segments.

    Parameters
    ----------
    uv : (n, 2) float64
    seg : (b, 2) int64

    Returns
    -------
    a, b : (k,) int64
        Indices into ``seg`` of each crossing pair.
    """
    pairs = crossing_pairs(uv, seg)
    a, b = pairs[:, 0], pairs[:, 1]
    length = np.linalg.norm(uv[seg[:, 1]] - uv[seg[:, 0]], axis=1) if len(seg) else np.zeros(0)
    real = length[a] + length[b] > 0
    return a[real], b[real]


def _same_place(points: np.ndarray, seg: np.ndarray) -> np.ndarray | None:
    """Each vertex's representative among the boundary vertices (``seg`` (b, 2)) at its 3D
    place (the lowest index), itself elsewhere; None when no two are at one place."""
    ends = np.unique(seg)
    p = points[ends]
    order = np.lexsort(p.T[::-1])
    dup = np.all(p[order[1:]] == p[order[:-1]], axis=1)
    if not dup.any():
        return None
    first = np.concatenate([[True], ~dup])
    rep = np.arange(len(points))
    rep[ends[order]] = ends[order][np.flatnonzero(first)[np.cumsum(first) - 1]]
    return rep


def _minor_fans(faces: np.ndarray, area_3d: np.ndarray, keep: np.ndarray, border: _KeptBorder,
                same: np.ndarray | None = None) -> np.ndarray:
    """Kept faces (``keep`` (m,) bool) of the smaller fans at vertices whose kept faces form
    several fans (see :func:`border_folds`); ``same`` (n,) maps copies of a vertex to one of
    them. Returns (m,) bool.

    A vertex with ``k`` faces in open fans has ``k`` plus one edge per fan, so a vertex
    with at least two more edges than faces is pinched (``border.excess``); only the faces
    around those are cut apart (:func:`cut_open`) to find the fans.
    """
    excess = border.excess if same is None else np.bincount(same, border.excess, len(same))
    pinched = excess >= 2
    out = np.zeros(len(faces), bool)
    if not pinched.any():
        return out
    local = border.faces_at(np.flatnonzero(pinched if same is None else pinched[same]))
    local = local[keep[local]]
    sub = faces[local] if same is None else same[faces[local]]
    new_faces, vertex_index, _, _, _ = cut_open(sub, np.zeros((len(local), 3)))
    fan_area = np.bincount(new_faces.ravel(), np.repeat(area_3d[local], 3), len(vertex_index))
    # keep the largest fan of each pinched vertex
    order = np.lexsort((-fan_area, vertex_index))
    first = np.ones(len(order), bool)
    first[1:] = vertex_index[order][1:] != vertex_index[order][:-1]
    minor = np.zeros(len(vertex_index), bool)
    minor[order[~first]] = True
    minor &= pinched[vertex_index]
    out[local] = minor[new_faces].any(axis=1)
    return out


def _edge_on_strips(faces: np.ndarray, keep: np.ndarray, flat: np.ndarray, edge_on: np.ndarray,
                    flipped: np.ndarray, seg: np.ndarray, n: int) -> np.ndarray:
    """Edge-on strips of kept faces (``keep`` (m,) bool) that contain a flipped face and touch
    the boundary ``seg`` (see :func:`border_folds`); ``flat`` (m,) the faces' flat signed areas,
    ``edge_on`` and ``flipped`` the edge-on and flipped faces of all; ``n`` vertices.
    Returns (m,) bool."""
    out = np.zeros(len(faces), bool)
    if not keep[flipped].any():
        return out
    sel = edge_on[keep[edge_on]]
    sub = faces[sel]
    comp = FaceGraph(sub).components()
    on_border = np.zeros(n, bool)
    on_border[seg.ravel()] = True
    k = int(comp.max()) + 1
    has_flip = np.bincount(comp[flat[sel] <= 0], minlength=k) > 0
    touches = np.bincount(comp[on_border[sub].any(axis=1)], minlength=k) > 0
    out[sel] = (has_flip & touches)[comp]
    return out


def _tangled_parts(region: np.ndarray, faces: np.ndarray, vf_ptr: np.ndarray, vf_tri: np.ndarray,
                   tangled: np.ndarray) -> np.ndarray:
    """The vertices of the connected parts of ``region`` ((n,) bool; parts joined by the mesh's
    edges between region vertices) that hold a vertex of the faces ``tangled`` ((k, 3)), (p,)
    int64."""
    verts = np.flatnonzero(region)
    label = vertex_clusters(verts, faces, vf_ptr, vf_tri)
    hit = np.zeros(int(label.max()) + 1 if len(label) else 0, bool)
    held = tangled.ravel()
    hit[label[np.searchsorted(verts, held[region[held]])]] = True  # (a boundary vertex is in no part)
    return verts[hit[label]]


def untangle(faces: np.ndarray, uv: np.ndarray, *, table: tuple | None = None) -> tuple[np.ndarray, int, int]:
    """Unfold folds inside a development by moving their vertices to their neighbours' mean.

    The vertices of flipped faces (signed area <= 0) move to the mean of their edge
    neighbours (Jacobi steps), for up to :data:`UNTANGLE_ROUNDS` rounds; boundary vertices
    stay. The region takes the vertices of every face still flipped after a round, and every
    :data:`UNTANGLE_WIDEN` rounds its connected parts that still hold one grow by a ring: a
    tangle that averaging has not undone gets more room, the parts already untangled stay
    as they are (on a scan with vertex noise, widening every part would spread the averaging
    over most of the development, each widening making new flips). Such folds come from the
    scan (a crease, a sliver, a spike, vertex noise), not from the development; the relax
    stage then restores the lengths around them.

    Parameters
    ----------
    faces : (m, 3) int64
    uv : (n, 2) float64
    table : tuple, optional
        ``edges_and_boundary(faces, len(uv))`` when the caller has it.

    Returns
    -------
    uv : (n, 2) float64
        A new array (``uv`` itself when nothing was flipped).
    flipped : int
        Faces flipped before.
    moved : int
        Vertices moved.
    """
    import scipy.sparse as sp

    bad = signed_areas(faces, uv) <= 0
    n_bad = int(bad.sum())
    if n_bad == 0:
        return uv, 0, 0
    n = len(uv)
    seg = (table if table is not None else edges_and_boundary(faces, n))[1]
    movable = np.ones(n, bool)
    movable[seg.ravel()] = False
    vf_ptr, vf_tri = vertex_faces(n, np.ascontiguousarray(faces, dtype=np.int64))
    x = uv.copy()
    region = np.zeros(n, bool)
    region[faces[bad].ravel()] = True
    # the region's vertices in the order they joined it (``idx``), their neighbour rows (each
    # row's columns sorted) and the faces around them, all extended as the region grows: a
    # noisy scan's region grows in most rounds, and a round costs what its new vertices touch
    in_region = np.zeros(n, bool)
    around = np.zeros(len(faces), bool)
    idx, rows, near = np.zeros(0, np.int64), None, None
    still = np.flatnonzero(bad)  # (faces flipped after the last round)
    for r in range(UNTANGLE_ROUNDS):
        if r % UNTANGLE_WIDEN == UNTANGLE_WIDEN - 1:  # widen the parts of the region around persistent tangles
            grow = _tangled_parts(region, faces, vf_ptr, vf_tri, faces[still])
            region[faces[incident_faces(grow, vf_ptr, vf_tri)].ravel()] = True
        region &= movable
        new = np.flatnonzero(region & ~in_region)  # (the region only grows)
        if len(new):
            in_region[new] = True
            new_faces = np.unique(incident_faces(new, vf_ptr, vf_tri))
            around[new_faces] = True
            near = np.flatnonzero(around)
            new_rows = neighbour_rows(new, fan_edges(new_faces, faces)[0], n)
            idx = np.concatenate([idx, new])
            rows = new_rows if rows is None else sp.vstack([rows, new_rows], format="csr")
            degree = np.maximum(np.diff(rows.indptr), 1)[:, None].astype(np.float64)
        if not len(idx):
            break
        x[idx] = (rows @ x) / degree
        still = near[signed_areas(faces[near], x) <= 0]
        if len(still) == 0:
            break
        region[faces[still].ravel()] = True
    return x, n_bad, int(np.count_nonzero(np.any(x != uv, axis=1)))
