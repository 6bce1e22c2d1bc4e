"""A development must be a disk (with holes): cut a selected wall that is not one.

No layout in the plane without a fold exists for a piece of surface with a handle (a loop that
does not bound: a handle kept with the wall, or joined to it where the attachments were not
found), for a closed part, or where three or more faces share an edge. :func:`disk_cut`
finds such places in a development's mesh and the faces to leave out so that every piece is
a disk with holes:

* **faces joined at an edge by three or more**: the two faces that continue each other best
  (opposite directions along the edge, the smallest angle between their normals) stay
  joined, the others are left out;
* **a closed part**: one face is left out (a hole);
* **a handle** (genus ``g > 0``, from Euler's formula ``V - E + F = 2 - 2 g - b`` with ``b``
  boundary loops): of the greedy system of loops through a base point (Erickson and
  Whittlesey, 2005: a shortest-path tree from the base point, a dual spanning tree of the
  longest loops; the ``2 g`` loops left do not bound), the one whose cycle, without its stem
  to the base point, is shortest is cut by leaving out the faces that touch it: round a
  handle rather than across the wall. The base point is the vertex standing furthest off
  the surface of revolution (on a kept handle); the step repeats until no handle is left.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra, minimum_spanning_tree

from potflat.mesh._kernels.topology import edge_table, union_find
from potflat.rollout.walls import FaceGraph, unique_ints

#: Rounds of cuts at most (each removes handles, one closed part or every non-manifold edge).
MAX_CUTS = 16
#: Cycles round handles shorter than this many median edge lengths, or than this factor times
#: the shortest, are cut together in one round; longer ones in later rounds, shortest first.
SHORT_CYCLE_EDGES, SHORT_CYCLE_RATIO = 8.0, 1.5


@dataclass(frozen=True)
class DiskCut:
    """What :func:`disk_cut` left out of a development to make every piece a disk.

    Attributes
    ----------
    faces : (m,) bool
        Faces of the development to leave out.
    nonmanifold_edges : int
        Edges shared by three or more faces.
    closed_parts : int
        Pieces without a boundary.
    handles : int
        Handles found (the pieces' genus) and cut through.
    """

    faces: np.ndarray
    nonmanifold_edges: int
    closed_parts: int
    handles: int

    @property
    def reason(self) -> str:
        """What was not a disk, in words (empty when nothing was cut)."""
        parts = []
        if self.handles:
            parts.append(f"{self.handles} handle{'s' if self.handles > 1 else ''} (a part joined to the wall at both "
                         "ends) cut through")
        if self.nonmanifold_edges:
            parts.append(f"{self.nonmanifold_edges} edges shared by three or more faces cut along")
        if self.closed_parts:
            parts.append(f"{self.closed_parts} closed part{'s' if self.closed_parts > 1 else ''} opened")
        return "; ".join(parts)


def _normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    n = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]], vertices[faces[:, 2]] - vertices[faces[:, 0]])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, length, out=np.zeros_like(n), where=length > 0)


def _nonmanifold_extra(faces: np.ndarray, vertices: np.ndarray, edge_of: np.ndarray, edges: np.ndarray,
                       count: np.ndarray) -> np.ndarray:
    """Faces (m,) bool on edges of three or more faces, beyond the pair that continue each other best."""
    out = np.zeros(len(faces), bool)
    bad = np.flatnonzero(count >= 3)
    if not len(bad):
        return out
    half = np.flatnonzero(np.isin(edge_of, bad))
    half = half[np.argsort(edge_of[half], kind="stable")]
    normal = _normals(vertices, faces)
    groups = np.split(half, np.flatnonzero(np.diff(edge_of[half])) + 1)
    for group in groups:
        face = group // 3
        forward = faces[face, group % 3] == edges[edge_of[group[0]], 0]  # runs the edge from its smaller end
        best, pair = -np.inf, (0, 1)
        for i in range(len(face)):
            for j in range(i + 1, len(face)):
                score = float(normal[face[i]] @ normal[face[j]]) + (2.0 if forward[i] != forward[j] else 0.0)
                if score > best:
                    best, pair = score, (i, j)
        drop = np.ones(len(face), bool)
        drop[list(pair)] = False
        out[face[drop]] = True
    return out


def _handle_cycles(faces: np.ndarray, vertices: np.ndarray, base: int) -> list[tuple[float, np.ndarray]]:
    """Cycles that do not bound on the connected surface ``faces`` (every vertex index used;
    boundary loops capped by a dual node each), shortest first, as (length, vertices): the
    greedy system of loops through ``base`` (``2 g`` of them, a pair per handle), each without
    the stem it shares with the way back to ``base``. Empty when every loop bounds (genus 0)."""
    n = len(vertices)
    edge_of, edges, count, halves = edge_table(faces, n)
    length = np.linalg.norm(vertices[edges[:, 1]] - vertices[edges[:, 0]], axis=1)
    length = np.maximum(length, 1e-12 * max(float(length.max(initial=0.0)), 1e-300))
    graph = sp.csr_matrix((np.r_[length, length], (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])),
                          shape=(n, n))
    dist, pred = dijkstra(graph, indices=base, return_predecessors=True)
    # tree edges: each vertex's edge to its predecessor
    in_tree = np.zeros(len(edges), bool)
    child = np.flatnonzero(pred >= 0)
    lo, hi = np.minimum(child, pred[child]), np.maximum(child, pred[child])
    key = edges[:, 0] * n + edges[:, 1]
    in_tree[np.searchsorted(key, lo * n + hi)] = True
    # dual graph: faces, and one node per boundary loop
    m = len(faces)
    border = count == 1
    loop_of = np.zeros(n, np.int64)
    if border.any():
        loop_of, _ = union_find(n, edges[border, 0], edges[border, 1])
    face_a = halves[:, 0] // 3
    face_b = np.where(border, m + loop_of[edges[:, 0]], halves[:, 1] // 3)
    loop_length = dist[edges[:, 0]] + length + dist[edges[:, 1]]
    free = np.flatnonzero(~in_tree)
    a, b = np.minimum(face_a[free], face_b[free]), np.maximum(face_a[free], face_b[free])
    # a maximum spanning tree of the dual by loop length leaves the shortest loops out
    order = np.lexsort((-loop_length[free], b, a))
    first = np.ones(len(order), bool)
    first[1:] = (a[order][1:] != a[order][:-1]) | (b[order][1:] != b[order][:-1])
    kept = order[first]
    weight = loop_length.max(initial=0.0) + 1.0 - loop_length[free[kept]]
    nodes = m + n
    tree = minimum_spanning_tree(sp.csr_matrix((weight, (a[kept], b[kept])), shape=(nodes, nodes))).tocoo()
    in_cotree = np.zeros(len(free), bool)
    pair_key = a * nodes + b
    tree_key = np.minimum(tree.row, tree.col).astype(np.int64) * nodes + np.maximum(tree.row, tree.col)
    kept_key = pair_key[kept]
    in_cotree[kept[np.isin(kept_key, tree_key)]] = True
    left = free[~in_cotree]
    if not len(left):
        return None

    def to_base(v: int) -> list[int]:
        path = [v]
        while pred[path[-1]] >= 0:
            path.append(int(pred[path[-1]]))
        return path[::-1]  # from the base point

    cycles = []
    for e in left:
        paths = [to_base(int(v)) for v in edges[e]]
        shared = 0
        while shared < min(map(len, paths)) and paths[0][shared] == paths[1][shared]:
            shared += 1
        fork = paths[0][shared - 1] if shared else base  # where the two paths part: the cycle leaves the stem
        cycles.append((float(loop_length[e] - 2.0 * dist[fork]),
                       np.asarray(paths[0][max(shared - 1, 0):] + paths[1][shared:], np.int64)))
    return sorted(cycles, key=lambda c: c[0])


def _vertices_per_piece(faces: np.ndarray, corner_piece: np.ndarray, n: int, k: int) -> np.ndarray:
    """How many distinct vertices each of ``k`` pieces has, from the piece of every corner of
    ``faces`` (m, 3) (``corner_piece`` (3 m,)): a vertex lies in one piece (its faces' fans
    are split) unless cuts left it in several, then counted by sorting (piece, vertex) keys."""
    corners = faces.ravel()
    owner = np.full(n, -1, np.int64)
    owner[corners] = corner_piece
    if np.array_equal(owner[corners], corner_piece):  # (no (3 m,) keys sorted: 3M vertices, 0.3 GB less)
        return np.bincount(owner[owner >= 0], minlength=k)
    return np.bincount(unique_ints(corner_piece * n + corners) // n, minlength=k)


def disk_cut(faces: np.ndarray, vertices: np.ndarray, offset: np.ndarray | None = None) -> DiskCut:
    """Faces to leave out of a development so that every piece is a disk with holes.

    Parameters
    ----------
    faces : (m, 3) int64
        The development's faces (a vertex whose faces form separate fans already split).
    vertices : (n, 3) float64
        Their 3D positions.
    offset : (n,) float64, optional
        How far each vertex stands off the surface of revolution: the loop around a handle
        goes through the furthest one (NaN counts as 0); default the first vertex of the piece.

    Returns
    -------
    DiskCut
    """
    faces = np.ascontiguousarray(faces, dtype=np.int64)
    n, m = len(vertices), len(faces)
    offset = np.zeros(n) if offset is None else np.nan_to_num(np.asarray(offset, float), nan=0.0)
    leave = np.zeros(m, bool)
    nonmanifold = closed = 0
    handles = None  # (the pieces' genus when first counted)
    for _ in range(MAX_CUTS):
        idx = np.flatnonzero(~leave)
        sub = faces[idx]
        table = edge_table(sub, n)
        edge_of, edges, count, _ = table
        extra = _nonmanifold_extra(sub, vertices, edge_of, edges, count)
        if extra.any():
            nonmanifold += int(np.count_nonzero(count >= 3))
            leave[idx[extra]] = True
            continue
        piece = FaceGraph(sub, table).components()  # (the graph and its pairs go at once: peak memory)
        del table
        k = int(piece.max()) + 1 if len(piece) else 0
        # Euler characteristic and boundary loops of every piece
        corner_piece = np.repeat(piece, 3)
        n_vert = _vertices_per_piece(sub, corner_piece, n, k)
        edge_piece = np.empty(len(edges), np.int64)
        edge_piece[edge_of] = corner_piece
        n_edge = np.bincount(edge_piece, minlength=k)
        border = count == 1
        loops = np.zeros(k, np.int64)
        if border.any():
            label, _ = union_find(n, edges[border, 0], edges[border, 1])
            roots = unique_ints(edge_piece[border] * n + label[edges[border, 0]])
            loops = np.bincount(roots // n, minlength=k)
        euler = n_vert - n_edge + np.bincount(piece, minlength=k)
        genus = (2 - euler - loops) // 2
        if (loops == 0).any():
            p = int(np.argmax(loops == 0))
            leave[idx[np.argmax(piece == p)]] = True  # one face out: a hole
            closed += 1
            continue
        if handles is None:
            handles = int(genus[genus > 0].sum())
        if not (genus > 0).any():
            break
        p = int(np.argmax(genus))
        part = np.flatnonzero(piece == p)
        used = unique_ints(sub[part])
        local = np.full(n, -1, np.int64)
        local[used] = np.arange(len(used))
        cycles = _handle_cycles(local[sub[part]], vertices[used], int(np.argmax(offset[used])))
        if not cycles:
            break
        # the shortest, and with it every other cycle nearly as short (or a few edges long: a scan's
        # tiny tunnels) that crosses none taken: cycles of one handle cross, those of several
        # independent ones cut together leave one piece
        ends = sub[part]
        short = max(SHORT_CYCLE_EDGES * float(np.median(np.linalg.norm(vertices[ends[:, 1]] - vertices[ends[:, 0]],
                                                                       axis=1))), SHORT_CYCLE_RATIO * cycles[0][0])
        on_loop = np.zeros(n, bool)
        for length, cycle in cycles:
            if not on_loop.any() or (length <= short and not on_loop[used[cycle]].any()):
                on_loop[used[cycle]] = True
        leave[idx[part[on_loop[ends].any(axis=1)]]] = True
    return DiskCut(faces=leave, nonmanifold_edges=nonmanifold, closed_parts=closed, handles=handles or 0)
