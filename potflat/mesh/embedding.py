"""Fold-free layouts of a disk-like triangle mesh: local repair of folded clusters and the
global Tutte embedding.

A start layout with folded (flipped) triangles cannot be relaxed by a flip-free solver.
:func:`repair_folds` re-embeds each cluster of flipped faces inside its fixed surroundings:
the cluster's vertices, grown ring by ring, are placed at the harmonic (Tutte, uniform
weights) interpolation of the ring around them, until no face around them is flipped. Where
that fails, :func:`tutte_embedding` maps the whole mesh into a disc: the longest boundary
loop on a circle (by arc length), every other vertex the mean of its neighbours, holes closed
by a virtual vertex each. By Tutte's theorem this has no flipped triangle on a disk-topology
mesh whose graph is 3-connected (any triangulated disk without edges joining two boundary
vertices across the interior in a degenerate way; measured, not assumed: the caller checks).
"""
from __future__ import annotations

import math

import numpy as np

from potflat.mesh.distortion import bounds
from potflat.mesh._kernels.geometry import signed_areas_2d as face_areas

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
    """

    out = np.empty(len(faces))
    face_areas(np.ascontiguousarray(uv, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int32), out)
    return out


def _adjacency(faces: np.ndarray, n: int):
    """Symmetric vertex adjacency (CSR, ones) of the mesh edges."""
    import scipy.sparse as sp

    i = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]])
    j = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    a = sp.coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n)).tocsr()
    a = ((a + a.T) > 0).astype(np.float64)
    a.setdiag(0.0)
    a.eliminate_zeros()
    return a


def _harmonic(adj, uv: np.ndarray, free: np.ndarray) -> np.ndarray:
    """``uv`` with the ``free`` vertices moved to the uniform-weight harmonic interpolation
    of the others (each free vertex the mean of its neighbours)."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    idx = np.flatnonzero(free)
    out = uv.copy()
    if not len(idx):
        return out
    deg = np.asarray(adj.sum(axis=1)).ravel()
    a_ff = adj[idx][:, idx]
    a_fb = adj[idx][:, ~free]
    lap = sp.diags(deg[idx]) - a_ff
    rhs = a_fb @ uv[~free]
    sol = spsolve(lap.tocsc(), rhs)
    out[idx] = np.asarray(sol).reshape(-1, 2)
    return out


def boundary_loops(faces: np.ndarray, n: int) -> list[np.ndarray]:
    """The boundary loops of a triangle mesh, each as vertex indices in the order of its faces'
    edges (counter-clockwise around the surface; the outer loop of a disk runs with the
    surface on its left). Vertices where the boundary touches itself start a new loop."""
    he = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    key = he[:, 0].astype(np.int64) * n + he[:, 1]
    rev = he[:, 1].astype(np.int64) * n + he[:, 0]
    border = he[~np.isin(key, rev)]
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


def repair_folds(faces: np.ndarray, uv: np.ndarray, *, max_rings: int = REPAIR_MAX_RINGS
                 ) -> tuple[np.ndarray, int, int]:
    """Re-embed every cluster of flipped faces inside its fixed surroundings.

    Each cluster (flipped faces sharing vertices) frees its vertices and one more ring at a
    time, up to ``max_rings``, and places them harmonically inside the fixed rest; a cluster
    is done when no face touching a freed vertex is flipped. Mesh-boundary vertices stay
    fixed (their ring would be open).

    Parameters
    ----------
    faces : (m, 3) int64
    uv : (n, 2) float64
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
    import scipy.sparse.csgraph as csg

    n = len(uv)
    uv = np.ascontiguousarray(uv, dtype=np.float64).copy()
    flipped = signed_areas(faces, uv) <= 0
    start = int(flipped.sum())
    if not start:
        return uv, 0, 0
    adj = _adjacency(faces, n)
    on_border = np.zeros(n, bool)
    for loop in boundary_loops(faces, n):
        on_border[loop] = True
    # clusters: flipped faces joined through shared vertices
    bad = faces[flipped]
    touched = np.zeros(n, bool)
    touched[bad.ravel()] = True
    sub = adj[touched][:, touched]
    _, label = csg.connected_components(sub, directed=False)
    verts = np.flatnonzero(touched)
    for c in range(label.max() + 1 if len(label) else 0):
        region = np.zeros(n, bool)
        region[verts[label == c]] = True
        for _ in range(max_rings):
            free = region & ~on_border
            trial = _harmonic(adj, uv, free)
            near = region[faces].any(axis=1)
            if np.all(signed_areas(faces[near], trial) > 0):
                uv = trial
                break
            region = region | (adj @ region.astype(np.float64) > 0)
    left = int((signed_areas(faces, uv) <= 0).sum())
    return uv, start - left, left


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
    return _harmonic(_adjacency(all_faces, total), uv, free)[:n]


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
