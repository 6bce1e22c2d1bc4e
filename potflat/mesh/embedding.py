"""Fold-free layouts of a disk-like triangle mesh: local repair of folded clusters and the
global Tutte embedding.

A start layout with folded (flipped) triangles cannot be relaxed by a flip-free solver.
:func:`repair_folds` re-embeds each cluster of flipped faces inside its fixed surroundings:
the cluster's vertices, grown ring by ring, are placed at the harmonic (Tutte, uniform
weights) interpolation of the ring around them, or, given a fold-free layout the folded one
derives from, in that layout's shape (mean value coordinates inside, similar faces along
the mesh's boundary), until no face around them is flipped. Where that fails,
:func:`tutte_embedding` maps the whole mesh into a disc: the longest boundary loop on a
circle (by arc length), every other vertex the mean of its neighbours, holes closed by a
virtual vertex each. By Tutte's theorem this has no flipped triangle on a disk-topology
mesh whose graph is 3-connected (any triangulated disk without edges joining two boundary
vertices across the interior in a degenerate way; measured, not assumed: the caller checks).
"""
from __future__ import annotations

import math

import numpy as np

from potflat.mesh.distortion import bounds
from potflat.mesh._kernels.geometry import signed_areas_2d as face_areas
from potflat.mesh._kernels.topology import edge_table, incident_faces, union_find, vertex_faces

#: Rings by which a folded cluster is grown at most before giving up on local repair.
REPAIR_MAX_RINGS = 12


def signed_areas(faces: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Signed flat area of each face of a 2D layout, positive when counter-clockwise.

    Parameters
    ----------
    faces : (m, 3) int
    uv : (n, 2) float64

    Returns
    -------
    (m,) float64
        ``((b - a) x (c - a)) / 2`` of the corners ``a, b, c``: the relax solver's parallel
        kernel (:func:`potflat.relax._kernels.springs.face_areas`), with its face type (int32).

    Raises
    ------
    ValueError
        When ``faces`` is not (m, 3), ``uv`` not (n, 2), or a face names a vertex outside
        ``uv`` (the kernel would read outside the array).
    """
    faces, uv = np.asarray(faces), np.asarray(uv)
    if faces.ndim != 2 or faces.shape[1] != 3 or uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"signed_areas(faces (m, 3), uv (n, 2)): got {faces.shape} and {uv.shape}")
    if len(faces) and (faces.min() < 0 or faces.max() >= len(uv)):
        raise ValueError(f"signed_areas: face indices {faces.min()}..{faces.max()} outside the {len(uv)} vertices")
    out = np.empty(len(faces))
    face_areas(np.ascontiguousarray(uv, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int32), out)
    return out


def _adjacency(faces: np.ndarray, n: int):
    """Symmetric vertex adjacency (CSR, ones) of the mesh edges (none from a vertex to itself)."""
    edges = fan_edges(np.arange(len(faces)), faces)[0]
    return neighbour_rows(np.arange(n), edges[edges[:, 0] != edges[:, 1]], n)


def boundary_loops(faces: np.ndarray, n: int) -> list[np.ndarray]:
    """The boundary loops of a triangle mesh, each as vertex indices in the order of its faces'
    edges (counter-clockwise around the surface; the outer loop of a disk runs with the
    surface on its left). Vertices where the boundary touches itself start a new loop."""
    he = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = he[:, 0].astype(np.int64) * n + he[:, 1]
    rev = he[:, 1].astype(np.int64) * n + he[:, 0]
    present = np.sort(key)  # (sorted and searched: np.isin hashes, 3 s at 3M half-edges)
    at = np.minimum(np.searchsorted(present, rev), len(present) - 1)
    border = he[present[at] != rev]
    nxt: dict[int, int] = {}
    for a, b in border:
        nxt.setdefault(int(a), int(b))
    loops, seen = [], set()
    for start in sorted(nxt):
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen and v in nxt:
            seen.add(v)
            loop.append(v)
            v = nxt[v]
        if len(loop) >= 3:
            loops.append(np.asarray(loop, np.int64))
    return loops


def repair_folds(faces: np.ndarray, uv: np.ndarray, *, reference: np.ndarray | None = None,
                 max_rings: int = REPAIR_MAX_RINGS) -> tuple[np.ndarray, int, int]:
    """Re-embed every cluster of flipped faces inside its fixed surroundings.

    Each cluster (flipped faces sharing vertices) frees its vertices and one more ring at a
    time, up to ``max_rings``, and places them inside the fixed rest; a cluster is done when
    no face touching a freed vertex is flipped.

    Without ``reference`` the freed vertices are the harmonic interpolation (Tutte, uniform
    weights) of the ring around them, and mesh-boundary vertices stay fixed (their ring would
    be open). With a fold-free ``reference`` layout of the same mesh (the layout ``uv``
    derives from), the freed vertices keep its shape: an inner vertex is the mean of its
    neighbours by their mean value coordinates in ``reference`` (Floater's: positive on a
    fold-free layout, and exact for any affine image of it, whatever the triangles' shapes),
    and mesh-boundary vertices are freed too, each the mean over its faces of where the face
    similar to its ``reference`` shape built on the other two corners puts it (weighted by
    the square of that opposite edge's length), all solved at once. A cluster whose ring is
    a similarity image of ``reference`` is refilled with that image.

    Parameters
    ----------
    faces : (m, 3) int (any integer type)
    uv : (n, 2) float64
    reference : (n, 2) float64, optional
        A fold-free layout of the mesh.
    max_rings : int

    Returns
    -------
    uv : (n, 2) float64
        The repaired layout.
    repaired : int
        Flipped faces at the start that are no longer flipped.
    left : int
        Faces still flipped (0: fold-free).
    """
    import scipy.sparse as sp

    n = len(uv)
    uv = np.ascontiguousarray(uv, dtype=np.float64).copy()
    flipped = signed_areas(faces, uv) <= 0
    start = int(flipped.sum())
    if not start:
        return uv, 0, 0
    # (the mesh's edges are only looked at around the clusters: a whole-mesh adjacency and
    # boundary would be most of the relax stage's peak memory at 3M vertices)
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    vf_ptr, vf_tri = vertex_faces(n, faces)
    # clusters: flipped faces joined through shared vertices
    verts = np.unique(faces[flipped].ravel())
    label = vertex_clusters(verts, faces, vf_ptr, vf_tri)
    for c in range(label.max() + 1 if len(label) else 0):
        region = verts[label == c]
        for _ in range(max_rings):
            near = np.unique(incident_faces(region, vf_ptr, vf_tri))
            edges, count = fan_edges(near, faces)
            on_border = np.isin(region, edges[count == 1])
            inner, border = region[~on_border], region[on_border]
            if reference is None:
                free, rows = inner, neighbour_rows(inner, edges, n)
            else:
                free = np.concatenate([inner, border])
                rows = sp.vstack([_mean_value_rows(inner, reference, faces, vf_ptr, vf_tri, n),
                                  _similar_rows(border, reference, faces, vf_ptr, vf_tri, n)]).tocsr()
            before = uv[free]
            uv[free] = _solve_rows(uv, free, rows)
            if np.all(signed_areas(faces[near], uv) > 0):
                break
            uv[free] = before
            region = np.union1d(region, edges.ravel())  # (the vertices of the faces around it)
    left = int((signed_areas(faces, uv) <= 0).sum())
    return uv, start - left, left


def vertex_clusters(verts: np.ndarray, faces: np.ndarray, vf_ptr: np.ndarray, vf_tri: np.ndarray) -> np.ndarray:
    """The connected parts of a set of vertices, joined by the mesh's edges between two of them.

    Only the faces around the set are looked at (not the whole mesh's edges).

    Parameters
    ----------
    verts : (p,) int64
        The vertices, sorted, without repeats.
    faces : (m, 3) int64
    vf_ptr, vf_tri : (n + 1,), (3 m,) int64
        The faces of each vertex (:func:`potflat.mesh._kernels.topology.vertex_faces`).

    Returns
    -------
    (p,) int64
        The part of each vertex, numbered in order of each part's lowest vertex.
    """
    n = len(vf_ptr) - 1
    inside = np.zeros(n, bool)
    inside[verts] = True
    edges = fan_edges(np.unique(incident_faces(verts, vf_ptr, vf_tri)), faces)[0]
    edges = edges[inside[edges].all(axis=1)]
    local = np.full(n, -1, np.int64)
    local[verts] = np.arange(len(verts))
    return union_find(len(verts), local[edges[:, 0]], local[edges[:, 1]])[0]


def fan_edges(around: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The edges of the faces ``around`` ((s,) int, unique: every face with a corner at some
    vertices, as ``np.unique(incident_faces(verts, ...))`` gives them): (e, 2) int64, each
    once (smaller end first, sorted), and the number of those faces on each (e,) int64,
    which is the mesh's for every edge with an end at those vertices (1: an edge of the
    mesh's boundary). The edge table of those faces alone, their vertices numbered
    compactly (its cost is theirs, not the mesh's)."""
    verts, local = np.unique(faces[around], return_inverse=True)
    _, edges, count, _ = edge_table(local.reshape(-1, 3).astype(np.int64), len(verts))
    return verts[edges].astype(np.int64), count


def neighbour_rows(verts: np.ndarray, edges: np.ndarray, n: int):
    """Each of ``verts`` (k,)'s edge neighbours among ``edges`` ((e, 2), each once; all of a
    vertex's edges there), weight 1: a (k, n) sparse matrix."""
    import scipy.sparse as sp

    a, b = edges[:, 0], edges[:, 1]
    ends = [(_rows_of(verts, a), b), (_rows_of(verts, b), a)]
    r = np.concatenate([r[r >= 0] for r, _ in ends])
    c = np.concatenate([c[r >= 0] for r, c in ends])
    return sp.coo_matrix((np.ones(len(r)), (r, c)), shape=(len(verts), n)).tocsr()


def _rows_of(verts: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The row of each of ``v`` in ``verts`` ((k,) int, without repeats), -1 where it is not
    there; costs what ``verts`` and ``v`` do, not the mesh."""
    if not len(verts):
        return np.full(len(v), -1, np.int64)
    by_vertex = np.argsort(verts, kind="stable")
    ordered = verts[by_vertex]
    at = np.minimum(np.searchsorted(ordered, v), len(verts) - 1)
    return np.where(ordered[at] == v, by_vertex[at], -1).astype(np.int64)


def _solve_rows(uv: np.ndarray, free: np.ndarray, rows) -> np.ndarray:
    """The positions (k, 2) of the ``free`` (k,) vertices of ``uv`` (n, 2) when each is the
    combination of the others given by its row of ``rows`` ((k, n) sparse, real or complex: a
    complex weight turns and scales the neighbour's position, as points of the complex
    plane), rows normalised to sum 1, solved for all free vertices at once. Its cost is the
    rows', not the mesh's."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    k = len(free)
    if not k:
        return np.empty((0, 2))
    rows = rows.tocsr()
    names, at = np.unique(rows.indices, return_inverse=True)  # the vertices the rows name, numbered
    rows = sp.csr_matrix((rows.data, at.ravel(), rows.indptr), shape=(k, len(names)))
    rows = sp.diags(1.0 / np.asarray(rows.sum(axis=1)).ravel()) @ rows
    col = _rows_of(free, names)
    w = rows.tocoo()
    inner = col[w.col] >= 0
    among = sp.coo_matrix((w.data[inner], (w.row[inner], col[w.col[inner]])), shape=(k, k))
    lap = sp.eye(k, dtype=w.data.dtype) - among
    fixed = sp.coo_matrix((w.data[~inner], (w.row[~inner], w.col[~inner])), shape=(k, len(names))).tocsr()
    held = uv[names]
    if np.iscomplexobj(w.data):
        z = spsolve(lap.tocsc(), fixed @ (held[:, 0] + 1j * held[:, 1]))
        return np.stack([z.real, z.imag], axis=1)
    return np.asarray(spsolve(lap.tocsc(), fixed @ held)).reshape(-1, 2)


def _similar_rows(verts: np.ndarray, reference: np.ndarray, faces: np.ndarray, vf_ptr: np.ndarray,
                  vf_tri: np.ndarray, n: int):
    """For each of ``verts`` (k,), over its faces ``(v, a, b)``: ``v = a + r (b - a)`` with
    the complex ratio ``r = (x_v - x_a) / (x_b - x_a)`` of ``reference`` (the face similar to
    its reference shape), weighted by ``|x_b - x_a|^2``: a (k, n) complex sparse matrix, rows
    not normalised."""
    import scipy.sparse as sp

    row, v, a, b = _corners(verts, faces, vf_ptr, vf_tri)
    zv, za, zb = (reference[i, 0] + 1j * reference[i, 1] for i in (v, a, b))
    base = zb - za
    weight = np.abs(base) ** 2
    ratio = (zv - za) / np.where(weight > 0, base, 1.0)
    weight = np.where(weight > 0, weight, 0.0)
    return sp.coo_matrix((np.concatenate([weight * (1.0 - ratio), weight * ratio]),
                          (np.concatenate([row, row]), np.concatenate([a, b]))), shape=(len(verts), n)).tocsr()


def _mean_value_rows(verts: np.ndarray, reference: np.ndarray, faces: np.ndarray, vf_ptr: np.ndarray,
                     vf_tri: np.ndarray, n: int):
    """Mean value coordinates of each of ``verts`` (k,) in ``reference`` (n, 2): its one-ring
    neighbours' weights ``(tan(a/2) + tan(b/2)) / |x_v - x_u|``, ``a, b`` its angles at ``v``
    in the two faces on edge ``vu``; a (k, n) sparse matrix, rows not normalised."""
    import scipy.sparse as sp

    row, v, b, c = _corners(verts, faces, vf_ptr, vf_tri)
    eb, ec = reference[b] - reference[v], reference[c] - reference[v]
    lb, lc = np.linalg.norm(eb, axis=1), np.linalg.norm(ec, axis=1)
    cos = np.clip((eb * ec).sum(axis=1) / np.maximum(lb * lc, 1e-300), -1.0, 1.0)
    half = np.tan(0.5 * np.arccos(cos))
    w = np.concatenate([half / np.maximum(lb, 1e-300), half / np.maximum(lc, 1e-300)])
    return sp.coo_matrix((w, (np.concatenate([row, row]), np.concatenate([b, c]))), shape=(len(verts), n)).tocsr()


def _corners(verts: np.ndarray, faces: np.ndarray, vf_ptr: np.ndarray, vf_tri: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every face around each of ``verts`` (k,) as ``(row, v, a, b)``, (s,) int64 each: the
    row of ``verts`` it belongs to, and the face's corners in order from that vertex ``v``."""
    row = np.repeat(np.arange(len(verts)), vf_ptr[verts + 1] - vf_ptr[verts])
    tri = faces[incident_faces(verts, vf_ptr, vf_tri)]
    corner = np.argmax(tri == verts[row, None], axis=1)
    pick = np.arange(len(tri))
    return row, tri[pick, corner], tri[pick, (corner + 1) % 3], tri[pick, (corner + 2) % 3]


def _disc(faces: np.ndarray, n: int, scale: float) -> np.ndarray | None:
    """Tutte's embedding of one connected disk-like mesh (see :func:`tutte_embedding`)."""
    loops = boundary_loops(faces, n)
    if not loops:
        return None
    loops.sort(key=len, reverse=True)
    outer, holes = loops[0], loops[1:]
    extra = []
    for k, loop in enumerate(holes):  # close each hole by a fan around a virtual vertex
        back = loop[::-1]
        extra.append(np.stack([back, np.roll(back, -1), np.full(len(loop), n + k)], axis=1))
    all_faces = np.concatenate([faces] + extra) if extra else faces
    total = n + len(holes)
    radius = scale * len(outer) / (2.0 * math.pi)
    angle = 2.0 * math.pi * np.arange(len(outer)) / len(outer)
    uv = np.zeros((total, 2))
    uv[outer, 0] = radius * np.cos(angle)
    uv[outer, 1] = radius * np.sin(angle)
    free = np.ones(total, bool)
    free[outer] = False
    inner = np.flatnonzero(free)
    uv[inner] = _solve_rows(uv, inner, _adjacency(all_faces, total)[inner])
    return uv[:n]


def tutte_embedding(faces: np.ndarray, n: int, scale: float = 1.0) -> np.ndarray | None:
    """Tutte's embedding of a disk-like mesh, each connected part in a disc of its own.

    The longest boundary loop of a part goes on a circle (its vertices evenly spaced,
    ``scale`` apart), every other vertex to the mean of its neighbours; each other boundary
    loop (a hole) is closed by a virtual vertex joined to it. The parts' discs lie side by
    side, apart; unreferenced vertices stay at the origin.

    Parameters
    ----------
    faces : (m, 3) int64
    n : int
        Number of vertices.
    scale : float
        Length of a boundary edge on the circle.

    Returns
    -------
    (n, 2) float64 or None
        None when a part has no boundary (a closed surface cannot be laid flat).
    """
    import scipy.sparse.csgraph as csg

    out = np.zeros((n, 2))
    used = np.zeros(n, bool)
    used[faces.ravel()] = True
    count, label = csg.connected_components(_adjacency(faces, n), directed=False)
    offset = 0.0
    for c in np.unique(label[used]):
        verts = np.flatnonzero(label == c)
        local = np.full(n, -1, np.int64)
        local[verts] = np.arange(len(verts))
        part = local[faces[label[faces[:, 0]] == c]]
        disc = _disc(part, len(verts), scale)
        if disc is None:
            return None
        lo, hi = bounds(disc)
        out[verts] = disc - [lo[0] - offset, 0.0]
        offset += (hi[0] - lo[0]) + 2.0 * scale
    return out
