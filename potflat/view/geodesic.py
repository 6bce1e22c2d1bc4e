"""Distances on the vessel: the shortest path through the scan's surface between two points.

The surface is the flattening's mesh with the seam's copies joined again (a path may cross
the seam). A first path runs along the mesh's edges (Dijkstra, :mod:`scipy.sparse.csgraph`),
from the three corners of one point's face to those of the other's; it is then straightened
into the exact polyhedral geodesic (the path crossing faces) by edge flips
(:class:`potpourri3d.EdgeFlipGeodesicSolver`) on the part of the surface it can lie in: the
vertices whose distances to both ends add up to little more than the first path's length.
Where that part is too large or not a manifold, the edge path is the answer (``method``
says which).
"""
from __future__ import annotations

import numpy as np

from potflat.mesh._kernels.topology import first_equal_rows
from potflat.mesh.distortion import unique_edges

#: The straightening is done on a part of the surface of at most this many faces.
MAX_GEODESIC_FACES = 400_000
#: The part of the surface searched: vertices whose two distances add up to at most this
#: factor times the edge path's length (an edge path is at most about 15 % longer than the
#: geodesic on a triangulated surface).
ELLIPSE_FACTOR = 1.2
#: Barycentric coordinates below this snap a point to its face's edge or corner (a face split
#: at a point on its edge would give degenerate triangles).
SNAP = 1e-6


class SurfaceGraph:
    """The welded surface of a cut mesh as a graph of its edges.

    Parameters
    ----------
    vertices : (n, 3) float64
    faces : (m, 3) int64
        A cut mesh (the seam's vertices appear once per side, at equal positions).
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        from scipy.sparse import csr_matrix

        V = np.ascontiguousarray(vertices, np.float64) + 0.0
        n = len(V)
        self.vertices = V
        self.rep = first_equal_rows(V.view(np.int64), False, np.zeros(n, bool))
        self.faces = self.rep[np.asarray(faces, np.int64)]
        edges = unique_edges(self.faces)
        edges = edges[edges[:, 0] != edges[:, 1]]
        w = np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1)
        self.mean_edge = float(w.mean()) if len(w) else 0.0
        both = np.concatenate([edges, edges[:, ::-1]])
        self.graph = csr_matrix((np.concatenate([w, w]), (both[:, 0], both[:, 1])), shape=(n, n))

    def _from(self, corners: np.ndarray, offsets: np.ndarray, limit: float) -> tuple[np.ndarray, np.ndarray]:
        """Distances from a point (its face's ``corners`` at ``offsets``) to every vertex within
        ``limit``, and the predecessor arrays of each corner's search."""
        from scipy.sparse.csgraph import dijkstra

        dist, pred = dijkstra(self.graph, indices=corners, limit=limit, return_predecessors=True)
        return dist + offsets[:, None], pred

    def distance(self, pa: np.ndarray, fa: int, pb: np.ndarray, fb: int, faces: np.ndarray
                 ) -> tuple[float, np.ndarray, str]:
        """Length of the shortest path through the surface from ``pa`` (on face ``fa``) to
        ``pb`` (on face ``fb``; faces of the cut mesh).

        Returns
        -------
        length : float
            Scan units.
        path : (k, 3) float64
            The path's points.
        method : str
            ``geodesic`` (the exact polyhedral geodesic), ``edges`` (along the mesh's edges) or
            ``straight`` (both points on one face).
        """
        pa, pb = np.asarray(pa, np.float64), np.asarray(pb, np.float64)
        ca, cb = self.faces[fa], self.faces[fb]
        if fa == fb or np.array_equal(np.sort(ca), np.sort(cb)):
            return float(np.linalg.norm(pb - pa)), np.stack([pa, pb]), "straight"
        oa = np.linalg.norm(self.vertices[ca] - pa, axis=1)
        ob = np.linalg.norm(self.vertices[cb] - pb, axis=1)
        limit = 2.0 * float(np.linalg.norm(pb - pa)) + 8.0 * self.mean_edge
        while True:  # the search grows until it reaches the other point
            da, pred = self._from(ca, oa, limit)
            to_b = da[:, cb] + ob[None, :]
            if np.isfinite(to_b).any() or limit > 1e12:
                break
            limit *= 4.0
        if not np.isfinite(to_b).any():
            return float("nan"), np.stack([pa, pb]), "unreachable"
        i, j = np.unravel_index(int(np.argmin(to_b)), to_b.shape)
        length = float(to_b[i, j])
        nodes = [int(cb[j])]
        while nodes[-1] != ca[i]:
            nodes.append(int(pred[i, nodes[-1]]))
        edge_path = np.concatenate([[pa], self.vertices[nodes[::-1]], [pb]])
        refined = self._straighten(pa, fa, pb, fb, faces, da.min(axis=0), length)
        if refined is not None:
            return refined[0], refined[1], "geodesic"
        return length, edge_path, "edges"

    def _straighten(self, pa, fa, pb, fb, faces, da, length):
        """The exact geodesic on the part of the surface the path can lie in; None when that
        part is too large or the solver refuses it."""
        import potpourri3d as pp3d

        ob = np.linalg.norm(self.vertices[self.faces[fb]] - pb, axis=1)
        db, _ = self._from(self.faces[fb], ob, ELLIPSE_FACTOR * length)
        db = db.min(axis=0)
        inside = (da + db) <= ELLIPSE_FACTOR * length + 2.0 * self.mean_edge
        keep = inside[self.faces].all(axis=1)
        keep[[fa, fb]] = True
        if keep.sum() > MAX_GEODESIC_FACES:
            return None
        F = self.faces[keep]
        used = np.unique(F)
        local = np.full(len(self.vertices), -1, np.int64)
        local[used] = np.arange(len(used))
        V = self.vertices[used]
        F = local[F]
        order = np.flatnonzero(keep)
        ends = []
        for p, f in ((pa, fa), (pb, fb)):
            row = int(np.searchsorted(order, f))
            tri = F[row]
            lam = _bary(p, V[tri])
            if lam.min() < SNAP:  # on an edge or a corner: the nearest corner stands for it
                ends.append(int(tri[int(np.argmax(lam))]))
                continue
            k = len(V)
            V = np.vstack([V, p])
            F = np.vstack([F, [[tri[1], tri[2], k], [tri[2], tri[0], k]]])
            F[row] = [tri[0], tri[1], k]
            ends.append(k)
        if ends[0] == ends[1]:
            return float(np.linalg.norm(pb - pa)), np.stack([pa, pb])
        try:
            solver = pp3d.EdgeFlipGeodesicSolver(V, F)
            path = np.asarray(solver.find_geodesic_path(ends[0], ends[1]), np.float64)
        except (RuntimeError, ValueError):
            return None
        if len(path) < 2 or not np.isfinite(path).all():
            return None
        path[0], path[-1] = pa, pb
        return float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()), path


def _bary(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of ``p`` (3,) in the triangle ``tri`` (3, 3) (on its plane)."""
    a, b, c = tri
    v0, v1, v2 = b - a, c - a, p - a
    d00, d01, d11 = v0 @ v0, v0 @ v1, v1 @ v1
    d20, d21 = v2 @ v0, v2 @ v1
    den = d00 * d11 - d01 * d01
    if den <= 0:
        return np.array([1.0, 0.0, 0.0])
    v = (d11 * d20 - d01 * d21) / den
    w = (d00 * d21 - d01 * d20) / den
    return np.array([1.0 - v - w, v, w])
