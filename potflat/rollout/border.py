"""The development's border: faces that fold it over (edge-on strips, overlapping border
faces) trimmed off, and faces folded inside it untangled."""
from __future__ import annotations

import numpy as np
import scipy.sparse

from potflat.mesh._kernels.topology import edge_table
from potflat.mesh.boundary import crossing_pairs, edges_and_boundary
from potflat.mesh.embedding import signed_areas
from potflat.rollout.folds import overlapping_faces
from potflat.rollout.seam import cut_open
from potflat.rollout.walls import (
    FaceGraph,
)

#: Rounds of :func:`untangle`; its region widens by one ring every ``UNTANGLE_WIDEN`` rounds.
UNTANGLE_ROUNDS, UNTANGLE_WIDEN = 200, 20


#: A face is edge-on to the proxy when its flat area is below this fraction of its 3D area.
EDGE_ON_RATIO = 0.05


#: Rounds of trimming folded border faces: all but the last unroll again without them (the
#: proxy is refitted), the last removes them from the development as it is.
TRIM_ROUNDS = 3


#: Passes of :func:`border_folds` over one development (each peels what the last exposed).
BORDER_PASSES = 50
#: Where the border crosses itself, faces whose flat area is below this fraction of their 3D
#: area (the thin rows along a fold) are trimmed with the crossing region (:func:`border_folds`).
SQUEEZED_RATIO = 0.25
#: A piece that trimming cuts off a connected part of the development is trimmed with it
#: when its area is below this fraction of that part's (:func:`border_folds`).
CUT_OFF_FRACTION = 0.1


def border_folds(faces: np.ndarray, uv: np.ndarray, area_3d: np.ndarray, *, table: tuple | None = None,
                 points: np.ndarray | None = None) -> np.ndarray:
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

    Folds enclosed by well-unrolled faces (scan noise, slivers) are left to :func:`untangle`.

    Parameters
    ----------
    faces : (m, 3) int64
        Faces of the cut mesh.
    uv : (n, 2) float64
        Its development.
    area_3d : (m,) float64
        3D area of each face.
    table : tuple, optional
        ``edges_and_boundary(faces, len(uv))`` when the caller has it (used by the first pass).
    points : (n, 3) float64, optional
        The vertices' 3D positions (to find copies of a vertex, see above).

    Returns
    -------
    (m,) bool
    """
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    keep = np.ones(len(faces), bool)
    # the edges and face adjacency once; each pass reads its border off them by counting
    edge_of, all_edges, _, _ = edge_table(faces, len(uv))
    graph = FaceGraph(faces)
    part = graph.components()
    part_area = np.bincount(part, area_3d)
    for _ in range(BORDER_PASSES):
        idx = np.flatnonzero(keep)
        if len(idx) == 0:
            break
        sub = faces[idx]
        full = len(idx) == len(faces)  # sub is faces itself
        if table is not None and full:
            edges, seg, owner = table
        else:
            edges, seg, owner = _kept_edges(faces, edge_of, all_edges, idx)
        same = None if points is None else _same_place(points, seg)
        drop = _edge_on_strips(sub, uv, area_3d[idx], seg) | _minor_fans(sub, area_3d[idx], edges, len(uv), same)
        if not full:
            drop |= _cut_off(graph, keep, area_3d, part, part_area)[idx]
        if not drop.any():  # overlaps are judged on a border without folded strips
            a, b = crossing_segments(uv, seg)
            if len(a):
                drop = _crossing_region(graph, faces, idx, uv, area_3d, idx[np.concatenate([owner[a], owner[b]])])[idx]
        if not drop.any():
            break
        keep[idx[drop]] = False
    return ~keep


def _crossing_region(graph: FaceGraph, faces: np.ndarray, idx: np.ndarray, uv: np.ndarray, area_3d: np.ndarray,
                     owners: np.ndarray) -> np.ndarray:
    """The faces (m,) bool of the regions where the border of the faces ``idx`` crosses itself:
    the ``owners`` of crossing segments and the faces lying over another face or squeezed
    (:data:`SQUEEZED_RATIO`) joined to them through shared edges (``graph``: the whole
    development's face adjacency)."""
    region = np.zeros(len(faces), bool)
    sub = faces[idx]
    region[idx[overlapping_faces(sub, uv) | (signed_areas(sub, uv) < SQUEEZED_RATIO * area_3d[idx])]] = True
    region[owners] = True
    pairs = graph.pairs
    label = graph.components(region[pairs[:, 0]] & region[pairs[:, 1]])
    reached = np.zeros(int(label.max()) + 1, bool)
    reached[label[owners]] = True
    return region & reached[label]


def _kept_edges(faces: np.ndarray, edge_of: np.ndarray, edges: np.ndarray, idx: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`potflat.mesh.boundary.edges_and_boundary` of the faces ``idx`` of ``faces``, read
    off the whole mesh's edge table (``edge_of``, ``edges`` from
    :func:`potflat.mesh._kernels.topology.edge_table`) by counting each edge's kept faces: the
    edges of the kept faces, their boundary segments (in face order) and each segment's face
    (an index into ``idx``)."""
    halves = (3 * idx[:, None] + np.arange(3)).ravel()
    edge = edge_of[halves]
    count = np.bincount(edge, minlength=len(edges))
    one = count[edge] == 1
    face, k = halves[one] // 3, halves[one] % 3
    seg = np.stack([faces[face, k], faces[face, (k + 1) % 3]], axis=1)
    return edges[count > 0], seg, np.flatnonzero(one) // 3


def _cut_off(graph: FaceGraph, keep: np.ndarray, area_3d: np.ndarray, part: np.ndarray,
             part_area: np.ndarray) -> np.ndarray:
    """Kept faces (``keep`` (m,) bool) of the pieces that trimming cut off a connected part of
    the development, with less than :data:`CUT_OFF_FRACTION` of its area (see
    :func:`border_folds`); ``graph`` is the whole development's face adjacency, ``part`` (m,)
    each face's part before trimming, ``part_area`` the parts' areas."""
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


def _minor_fans(faces: np.ndarray, area_3d: np.ndarray, edges: np.ndarray, n: int,
                same: np.ndarray | None = None) -> np.ndarray:
    """Faces of the smaller fans at vertices whose faces form several fans (see :func:`border_folds`);
    ``same`` (n,) maps copies of a vertex to one of them.

    A vertex with ``k`` faces in open fans has ``k`` plus one edge per fan, so a vertex
    with at least two more edges than faces is pinched; only the faces around those are cut
    apart (:func:`cut_open`) to find the fans.
    """
    if same is not None:
        faces, edges = same[faces], same[edges]
    pinched = np.bincount(edges.ravel(), minlength=n) - np.bincount(faces.ravel(), minlength=n) >= 2
    out = np.zeros(len(faces), bool)
    if not pinched.any():
        return out
    local = np.flatnonzero(pinched[faces].any(axis=1))
    new_faces, vertex_index, _, _, _ = cut_open(faces[local], np.zeros((len(local), 3)))
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


def _edge_on_strips(faces: np.ndarray, uv: np.ndarray, area_3d: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Edge-on strips that contain a flipped face and touch the boundary (see :func:`border_folds`)."""
    flat = signed_areas(faces, uv)
    out = np.zeros(len(faces), bool)
    if not (flat <= 0).any():
        return out
    sel = np.flatnonzero(flat < EDGE_ON_RATIO * area_3d)
    sub = faces[sel]
    comp = FaceGraph(sub).components()
    on_border = np.zeros(len(uv), bool)
    on_border[seg.ravel()] = True
    k = int(comp.max()) + 1
    has_flip = np.bincount(comp[flat[sel] <= 0], minlength=k) > 0
    touches = np.bincount(comp[on_border[sub].any(axis=1)], minlength=k) > 0
    out[sel] = (has_flip & touches)[comp]
    return out


def untangle(faces: np.ndarray, uv: np.ndarray, *, table: tuple | None = None) -> tuple[np.ndarray, int, int]:
    """Unfold folds inside a development by moving their vertices to their neighbours' mean.

    The vertices of flipped faces (signed area <= 0) move to the mean of their edge
    neighbours (Jacobi steps), the region widening by one ring every
    :data:`UNTANGLE_WIDEN` rounds, for up to :data:`UNTANGLE_ROUNDS` rounds; boundary
    vertices stay. Such folds come from the scan (a crease, a sliver, a spike), not from
    the development; the relax stage then restores the lengths around them.

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
    bad = signed_areas(faces, uv) <= 0
    n_bad = int(bad.sum())
    if n_bad == 0:
        return uv, 0, 0
    n = len(uv)
    edges, seg, _ = table if table is not None else edges_and_boundary(faces, n)
    A = scipy.sparse.coo_matrix((np.ones(2 * len(edges)), (np.r_[edges[:, 0], edges[:, 1]],
                                                            np.r_[edges[:, 1], edges[:, 0]])), shape=(n, n)).tocsr()
    deg = np.maximum(np.diff(A.indptr), 1).astype(np.float64)
    movable = np.ones(n, bool)
    movable[seg.ravel()] = False
    # faces of each vertex (CSR), to re-check only the faces around the moved vertices
    corner_order = np.argsort(faces.ravel(), kind="stable")
    vf_ptr = np.concatenate([[0], np.cumsum(np.bincount(faces.ravel(), minlength=n))])
    x = uv.copy()
    region = np.zeros(n, bool)
    region[faces[bad].ravel()] = True
    for r in range(UNTANGLE_ROUNDS):
        if r % UNTANGLE_WIDEN == UNTANGLE_WIDEN - 1:  # widen the region around persistent tangles
            region |= (A @ region.astype(np.float64)) > 0
        region &= movable
        idx = np.flatnonzero(region)
        if len(idx) == 0:
            break
        x[idx] = (A[idx] @ x) / deg[idx, None]
        count = vf_ptr[idx + 1] - vf_ptr[idx]
        offset = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
        near = np.unique(corner_order[np.repeat(vf_ptr[idx], count) + offset] // 3)
        still = near[signed_areas(faces[near], x) <= 0]
        if len(still) == 0:
            break
        region[faces[still].ravel()] = True
    return x, n_bad, int(np.count_nonzero(np.any(x != uv, axis=1)))
