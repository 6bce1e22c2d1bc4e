"""Mesh topology kernels: the edge table, vertex-face adjacency, neighbour means, union-find,
face pairs, orientation propagation, equal rows.

Arrays in, arrays out, no I/O; deterministic for any thread count (gather, never scatter).
"""
from __future__ import annotations

import numba
import numpy as np

from potflat._jit import leaf, parallel, prange




@parallel
def neighbour_means(x, verts, vf_ptr, vf_tri, faces, out):
    """Mean of ``x`` (positions, or a search direction) over each listed vertex's edge
    neighbours (each neighbour counted once).

    Parameters
    ----------
    x : (n, 2) float64
    verts : (k,) int64
    vf_ptr, vf_tri : CSR from :func:`vertex_faces`
    faces : (m, 3) int32 or int64
    out : (k, 2) float64
        Output (the vertex's own value when it has no neighbour).
    """
    for k in prange(verts.shape[0]):
        i = verts[k]
        sx = 0.0
        sy = 0.0
        cnt = 0
        lo = vf_ptr[i]
        for p in range(lo, vf_ptr[i + 1]):
            f = vf_tri[p]
            for c in range(3):
                j = faces[f, c]
                if j == i:
                    continue
                seen = False
                for p2 in range(lo, p):
                    f2 = vf_tri[p2]
                    if faces[f2, 0] == j or faces[f2, 1] == j or faces[f2, 2] == j:
                        seen = True
                        break
                if not seen:
                    sx += x[j, 0]
                    sy += x[j, 1]
                    cnt += 1
        if cnt:
            out[k, 0] = sx / cnt
            out[k, 1] = sy / cnt
        else:
            out[k, 0] = x[i, 0]
            out[k, 1] = x[i, 1]


@leaf
def propagate_orientation(nbr, same):
    """Make face orientations consistent by breadth-first search over face adjacency.

    Parameters
    ----------
    nbr : (m, 3) int64
        Face across each edge ``(F[f, k], F[f, (k + 1) % 3])`` when that edge is manifold
        (exactly two faces), else -1.
    same : (m, 3) int8
        1 when the neighbour traverses the shared edge in the same direction (inconsistent).

    Returns
    -------
    flip : (m,) int64
        1 for faces to reverse so that each component is consistently oriented; the
        first face (lowest index) of each component keeps its orientation.
    component : (m,) int64
        Component label of each face (by manifold edges), numbered in order of first face.
    conflicts : int
        Adjacent pairs left inconsistent (non-orientable or contradictory input).
    """
    m = nbr.shape[0]
    flip = np.zeros(m, np.int64)
    component = np.full(m, -1, np.int64)
    queue = np.empty(m, np.int64)
    conflicts = 0
    ncomp = 0
    for seed in range(m):
        if component[seed] >= 0:
            continue
        component[seed] = ncomp
        head = 0
        tail = 1
        queue[0] = seed
        while head < tail:
            f = queue[head]
            fu = np.uint64(f)
            head += 1
            for k in range(3):
                g = nbr[fu, k]
                if g < 0:
                    continue
                gu = np.uint64(g)
                want = flip[fu] ^ same[fu, k]
                if component[gu] < 0:
                    component[gu] = ncomp
                    flip[gu] = want
                    queue[tail] = g
                    tail += 1
                elif flip[gu] != want and g > f:
                    conflicts += 1
        ncomp += 1
    return flip, component, conflicts


@leaf
def fan_joins(h1, h2, same):
    """Face corners joined across manifold edges (the fans around each vertex).

    Parameters
    ----------
    h1, h2 : (k,) int64
        The two half-edges of each manifold edge; half-edge ``3 f + j`` runs from corner
        ``3 f + j`` to corner ``3 f + (j + 1) % 3``.
    same : (k,) bool
        True when both run the edge the same way.

    Returns
    -------
    a, b : (2 k,) int64
        Corners at the same vertex: first each edge's start corner of ``h1``, then its end
        corner, each with the corner of ``h2`` at that vertex.
    """
    k = h1.shape[0]
    a = np.empty(2 * k, np.int64)
    b = np.empty(2 * k, np.int64)
    for i in range(k):
        g = h1[i]
        h = h2[i]
        g_end = g - g % 3 + (g + 1) % 3
        h_end = h - h % 3 + (h + 1) % 3
        a[i] = g
        a[k + i] = g_end
        if same[i]:
            b[i] = h
            b[k + i] = h_end
        else:
            b[i] = h_end
            b[k + i] = h
    return a, b


@leaf
def _find(parent, x):
    p = np.uint64(parent[x])
    while p != x:
        parent[x] = parent[p]
        x = np.uint64(parent[x])
        p = np.uint64(parent[x])
    return x


@leaf
def union_find(n, a, b):
    """Connected components of a graph given as an edge list.

    Parameters
    ----------
    n : int
        Number of nodes.
    a, b : (k,) int64
        Edge end points.

    Returns
    -------
    label : (n,) int64
        Component of each node, numbered in order of the component's lowest node.
    count : int
        Number of components.
    """
    parent = np.arange(n)
    for i in range(a.shape[0]):
        x = _find(parent, np.uint64(a[i]))
        y = _find(parent, np.uint64(b[i]))
        if x < y:
            parent[y] = x
        elif y < x:
            parent[x] = y
    label = np.full(n, -1, np.int64)
    count = 0
    for v in range(n):
        r = _find(parent, np.uint64(v))
        if label[r] < 0:
            label[r] = count
            count += 1
        label[v] = label[r]
    return label, count


@leaf
def _sorted3(a, b, c):
    """The three values in increasing order."""
    if a > b:
        a, b = b, a
    if b > c:
        b, c = c, b
    if a > b:
        a, b = b, a
    return a, b, c


@leaf
def first_equal_rows(K, unordered, skip):
    """First occurrence of each row, by one pass through a hash table (linear time).

    Parameters
    ----------
    K : (k, 3) int64
        Rows compared value for value (positions as their bits: ``V.view(np.int64)`` with
        ``-0.0`` already normalised to ``0.0``; or faces).
    unordered : bool
        Compare rows as sets of three values (a face and its reversed or rotated copies).
    skip : (k,) bool
        Rows left out: each is its own first occurrence and matches no other row.

    Returns
    -------
    rep : (k,) int64
        Lowest index of a row equal to each row (``rep[i] <= i``; ``i`` for skipped rows).

    Notes
    -----
    Open addressing with linear probing, at most half full; the rows enter in index order,
    so the first equal row met is the lowest. At 6M faces 0.35 s against 1.0 s for sorting
    the rows' hashes (faces in shuffled order 0.43 s against 1.2 s).
    """
    k = K.shape[0]
    size = 16
    while size < 2 * k:
        size *= 2
    mask = np.uint64(size - 1)
    table = np.full(size, -1, np.int64)
    rep = np.empty(k, np.int64)
    for i in range(k):
        rep[i] = i
        if skip[i]:
            continue
        a, b, c = K[i, 0], K[i, 1], K[i, 2]
        if unordered:
            a, b, c = _sorted3(a, b, c)
        h = (np.uint64(a) * np.uint64(0x9E3779B97F4A7C15) ^ np.uint64(b) * np.uint64(0xC2B2AE3D27D4EB4F)
             ^ np.uint64(c) * np.uint64(0x165667B19E3779F9))
        slot = (h ^ (h >> np.uint64(29))) & mask
        while True:
            j = table[slot]
            if j < 0:
                table[slot] = i
                break
            x, y, z = K[j, 0], K[j, 1], K[j, 2]
            if unordered:
                x, y, z = _sorted3(x, y, z)
            if x == a and y == b and z == c:
                rep[i] = j
                break
            slot = (slot + np.uint64(1)) & mask
    return rep


def edge_table(F, n):
    """Undirected edges of a triangle mesh by counting sort (linear time, deterministic).

    Parameters
    ----------
    F : (m, 3) int64
        Faces; half-edge ``3 f + k`` goes from ``F[f, k]`` to ``F[f, (k + 1) % 3]``.
    n : int
        Number of vertices.

    Returns
    -------
    edge_of : (3 m,) int64
        Undirected edge id of each half-edge.
    edges : (ne, 2) int64
        Endpoints (smaller first), sorted lexicographically.
    count : (ne,) int64
        Number of half-edges (faces) on each edge.
    halves : (ne, 2) int64
        The first two half-edges of each edge (lowest ids), ``-1`` if absent.

    Notes
    -----
    The half-edges are bucketed by their lower endpoint, each bucket entry carrying the
    higher one (the sort within a bucket and the numbering read it in order instead of
    looking it up in ``F``). Each thread buckets the half-edges of its own range of lower
    endpoints, reading every face, so no two threads write the same place and the buckets
    hold their half-edges in id order whatever the thread count; the buckets are then sorted
    and numbered per vertex.
    """
    return _edge_table(F, n, max(1, min(numba.get_num_threads(), n)))


@parallel
def _edge_table(F, n, ranges):
    """:func:`edge_table` with the lower endpoints split into ``ranges`` ranges, one per thread."""
    m = F.shape[0]
    start = np.zeros(n + 1, np.int64)
    for r in prange(ranges):
        v0 = r * n // ranges
        v1 = (r + 1) * n // ranges
        own = np.zeros(v1 - v0, np.int64)
        for f in range(m):
            for k in range(3):
                lo = min(F[f, k], F[f, (k + 1) % 3])
                if v0 <= lo < v1:
                    own[lo - v0] += 1
        start[v0 + 1:v1 + 1] = own
    for v in range(n):
        start[v + 1] += start[v]
    bucket = np.empty(3 * m, np.int64)  # half-edges by lower endpoint, in id order
    other = np.empty(3 * m, np.int64)  # the higher endpoint of each
    for r in prange(ranges):
        v0 = r * n // ranges
        v1 = (r + 1) * n // ranges
        fill = start[v0:v1].copy()
        for f in range(m):
            for k in range(3):
                a = F[f, k]
                b = F[f, (k + 1) % 3]
                lo = min(a, b)
                if v0 <= lo < v1:
                    p = np.uint64(fill[lo - v0])
                    bucket[p] = 3 * f + k
                    other[p] = max(a, b)
                    fill[lo - v0] = p + np.uint64(1)
    # sort each bucket by the other endpoint (buckets are small, ties in id order) and count its edges
    first = np.zeros(n + 1, np.int64)
    for v in prange(n):
        s = start[v]
        e = start[v + 1]
        for a in range(s + 1, e):
            x = bucket[a]
            hx = other[a]
            b = a - 1
            while b >= s and (other[b] > hx or (other[b] == hx and bucket[b] > x)):
                bucket[b + 1] = bucket[b]
                other[b + 1] = other[b]
                b -= 1
            bucket[b + 1] = x
            other[b + 1] = hx
        distinct = 0
        for a in range(s, e):
            if a == s or other[a - 1] != other[a]:
                distinct += 1
        first[v + 1] = distinct
    for v in range(n):
        first[v + 1] += first[v]
    ne = first[n]
    edge_of = np.empty(3 * m, np.int64)
    edges = np.empty((ne, 2), np.int64)
    count = np.empty(ne, np.int64)
    halves = np.full((ne, 2), -1, np.int64)
    for v in prange(n):
        k = first[v]
        a = start[v]
        e = start[v + 1]
        while a < e:  # one run of equal higher endpoints: one edge
            b = a
            while b < e and other[b] == other[a]:
                edge_of[np.uint64(bucket[b])] = k
                b += 1
            edges[k, 0] = v
            edges[k, 1] = other[a]
            count[k] = b - a
            halves[k, 0] = bucket[a]
            if b - a > 1:
                halves[k, 1] = bucket[a + 1]
            k += 1
            a = b
    return edge_of, edges, count, halves


@leaf
def face_pairs(edges, count, halves, n):
    """Faces on each edge used by exactly two distinct faces, ordered by the edge's (larger,
    smaller) endpoint: a stable counting sort of :func:`edge_table`'s edges by the larger one.

    Parameters
    ----------
    edges, count, halves
        From :func:`edge_table` (edges sorted by (smaller, larger) endpoint).
    n : int
        Number of vertices.

    Returns
    -------
    pairs : (p, 2) int64
        The two faces, lower first.
    shared : (p, 2) int64
        The shared edge's endpoints, smaller first.
    """
    ne = edges.shape[0]
    start = np.zeros(n + 1, np.int64)
    for e in range(ne):
        if count[e] == 2 and halves[e, 0] // 3 != halves[e, 1] // 3:
            start[np.uint64(edges[e, 1] + 1)] += 1
    for v in range(n):
        start[v + 1] += start[v]
    p = start[n]
    pairs = np.empty((p, 2), np.int64)
    shared = np.empty((p, 2), np.int64)
    for e in range(ne):
        f0 = halves[e, 0] // 3
        f1 = halves[e, 1] // 3
        if count[e] == 2 and f0 != f1:
            hi = np.uint64(edges[e, 1])
            k = np.uint64(start[hi])
            start[hi] = k + np.uint64(1)
            pairs[k, 0] = min(f0, f1)
            pairs[k, 1] = max(f0, f1)
            shared[k, 0] = edges[e, 0]
            shared[k, 1] = edges[e, 1]
    return pairs, shared


@leaf
def _corner_ends(F, h):
    """Corners of half-edge ``h`` (uint64) at its lower and at its higher vertex (``h`` first on a tie)."""
    three = np.uint64(3)  # unsigned division (an int64 literal would make it a float)
    nh = h - h % three + (h + np.uint64(1)) % three
    if F[h // three, h % three] > F[nh // three, nh % three]:
        return nh, h
    return h, nh


@leaf
def half_edge_keys(F, theta, n):
    """Sort key of each half-edge: its edge's (lower, higher) endpoint, then the turn of the
    angle at its lower vertex (``floor(theta / 2 pi + 1/2)``, clipped to [-4, 3]).

    Parameters
    ----------
    F : (m, 3) int64
        Faces; corner ``3 f + k`` is ``F[f, k]`` and half-edge ``3 f + k`` starts there.
    theta : (3 m,) float64
        Unwrapped angle of each corner.
    n : int
        Number of vertices (above every index in ``F``).

    Returns
    -------
    (3 m,) int64
        ``(lower * n + higher) * 8 + turn + 4``.
    """
    m3 = 3 * F.shape[0]
    key = np.empty(m3, np.int64)
    three = np.uint64(3)
    for h in range(np.uint64(m3)):
        lo, hi = _corner_ends(F, h)
        t = np.floor(theta[lo] / (2.0 * np.pi) + 0.5)
        key[h] = (F[lo // three, lo % three] * n + F[hi // three, hi % three]) * 8 + int(min(max(t, -4.0), 3.0)) + 4
    return key


@leaf
def corner_joins(F, theta, key, order):
    """Corners of the same vertex that agree on its unwrapped angle across a shared edge.

    Two half-edges next to each other in ``order`` on the same edge join their corners at
    the lower vertex, and those at the higher vertex, where the angles differ by less than pi.

    Parameters
    ----------
    F : (m, 3) int64
    theta : (3 m,) float64
        Unwrapped angle of each corner.
    key : (3 m,) int64
        :func:`half_edge_keys`.
    order : (3 m,) int64
        The half-edges sorted by ``key`` (stably).

    Returns
    -------
    a, b : (k,) int64
        Corners to join.
    """
    m3 = order.shape[0]
    a = np.empty(2 * m3, np.int64)
    b = np.empty(2 * m3, np.int64)
    k = 0
    for i in range(m3 - 1):
        if key[order[i]] // 8 != key[order[i + 1]] // 8:
            continue
        lo1, hi1 = _corner_ends(F, np.uint64(order[i]))
        lo2, hi2 = _corner_ends(F, np.uint64(order[i + 1]))
        if abs(theta[lo1] - theta[lo2]) < np.pi:
            a[k] = lo1
            b[k] = lo2
            k += 1
        if abs(theta[hi1] - theta[hi2]) < np.pi:
            a[k] = hi1
            b[k] = hi2
            k += 1
    return a[:k], b[:k]


@leaf
def pair_sums(pairs, x):
    """Sum of ``x`` over each node's partners: the symmetric adjacency matrix of ``pairs``
    times ``x``, without the matrix (serial, in the pairs' order).

    Parameters
    ----------
    pairs : (p, 2) int64
        Node pairs, in ``[0, m)``.
    x : (m,) float64

    Returns
    -------
    (m,) float64
    """
    out = np.zeros(x.shape[0])
    for e in range(pairs.shape[0]):
        a = pairs[e, 0]
        b = pairs[e, 1]
        out[a] += x[b]
        out[b] += x[a]
    return out


@leaf
def pair_csr(pairs, m):
    """Symmetric CSR adjacency of ``m`` nodes from node pairs, each pair once per endpoint.

    Within a row the neighbours are sorted (stably: the pairs' order, the first endpoints'
    entries before the second endpoints'), as a stable sort of ``i * m + j`` over
    ``i = [pairs[:, 0], pairs[:, 1]]``, ``j = [pairs[:, 1], pairs[:, 0]]`` would give them.

    Parameters
    ----------
    pairs : (p, 2) int64
        Node pairs, in ``[0, m)``.
    m : int
        Number of nodes.

    Returns
    -------
    indptr : (m + 1,) int64
    indices : (2 p,) int64
        Neighbour of each entry.
    pair_of : (2 p,) int64
        Pair of each entry.
    """
    p = pairs.shape[0]
    # entry k is pair k % p at its endpoint k // p (the first endpoints' entries first)
    indptr = np.zeros(m + 1, np.int64)
    for k in range(2 * p):
        indptr[np.uint64(pairs[k % p, k // p] + 1)] += 1
    for r in range(m):
        indptr[r + 1] += indptr[r]
    fill = indptr[:-1].copy()
    indices = np.empty(2 * p, np.int64)
    pair_of = np.empty(2 * p, np.int64)
    for k in range(2 * p):
        e = k % p
        i = np.uint64(pairs[e, k // p])
        q = np.uint64(fill[i])
        indices[q] = pairs[e, 1 - k // p]
        pair_of[q] = e
        fill[i] = q + np.uint64(1)
    for r in range(m):  # insertion sort by neighbour, stable (rows are short)
        s = indptr[r]
        for a in range(s + 1, indptr[r + 1]):
            x = indices[a]
            y = pair_of[a]
            b = a - 1
            while b >= s and indices[b] > x:
                indices[b + 1] = indices[b]
                pair_of[b + 1] = pair_of[b]
                b -= 1
            indices[b + 1] = x
            pair_of[b + 1] = y
    return indptr, indices, pair_of


@leaf
def mark_face_edges(F, part, edges, first, out):
    """Mark the edges of some faces among a mesh's sorted undirected edges.

    Parameters
    ----------
    F : (m, 3) int64
    part : (m,) bool
        The faces whose edges to mark.
    edges : (e, 2) int64
        The undirected edges of ``F`` (smaller endpoint first), sorted (``unique_edges``).
    first : (n + 1,) int64
        Where each vertex's edges start in ``edges`` as their smaller endpoint.
    out : (e,) bool
        Output (filled with False): True on each edge of a face of ``part``.
    """
    for f in range(F.shape[0]):
        if not part[f]:
            continue
        for k in range(3):
            a = F[f, k]
            b = F[f, (k + 1) % 3]
            lo = np.uint64(min(a, b))
            hi = max(a, b)
            for e in range(np.uint64(first[lo]), np.uint64(first[lo + np.uint64(1)])):
                if edges[e, 1] == hi:
                    out[e] = True
                    break


@leaf
def vertex_faces(n, faces):
    """Incident faces of each vertex (CSR, faces in increasing order).

    Returns
    -------
    ptr : (n + 1,) int64
    tri : (3 m,) int32
    """
    m = faces.shape[0]
    deg = np.zeros(n + 1, np.int64)
    for f in range(m):
        for c in range(3):
            deg[np.uint64(faces[f, c] + 1)] += 1
    ptr = np.cumsum(deg)
    fill = ptr[:-1].copy()
    tri = np.empty(3 * m, np.int32)
    for f in range(m):
        for c in range(3):
            v = np.uint64(faces[f, c])
            tri[np.uint64(fill[v])] = f
            fill[v] += 1
    return ptr, tri


@leaf
def faces_in_vertex_order(faces, new_index):
    """The faces with their corners renumbered by ``new_index``, ordered by their smallest
    new corner index (stable: ties keep their order).

    With the vertices renumbered in a locality-preserving order, the faces in this order are
    local too: the per-face passes and the per-vertex gathers over incident faces then read
    nearby memory. One counting sort, ``O(n + m)`` (equal to ``G[np.argsort(G.min(axis=1),
    kind="stable")]`` for ``G = new_index[faces]``, without its temporaries).

    Parameters
    ----------
    faces : (m, 3) int64
    new_index : (n,) int64
        The new index of every vertex (a permutation of ``range(n)``).

    Returns
    -------
    (m, 3) int64
    """
    n = new_index.shape[0]
    m = faces.shape[0]
    start = np.zeros(n + 1, np.int64)
    for f in range(m):
        start[min(new_index[faces[f, 0]], new_index[faces[f, 1]], new_index[faces[f, 2]]) + 1] += 1
    for i in range(n):
        start[i + 1] += start[i]
    out = np.empty((m, 3), np.int64)
    for f in range(m):
        a = new_index[faces[f, 0]]
        b = new_index[faces[f, 1]]
        c = new_index[faces[f, 2]]
        v = min(a, b, c)
        row = start[v]
        out[row, 0] = a
        out[row, 1] = b
        out[row, 2] = c
        start[v] += 1
    return out


@leaf
def flagged_face_vertices(flags, faces, seen):
    """The vertices of the flagged faces, each once, in order of first appearance.

    Parameters
    ----------
    flags : (m,) bool
    faces : (m, 3) int32 or int64
    seen : (n,) bool
        Work space, all False on entry and on return.

    Returns
    -------
    (k,) int64
    """
    count = 0
    for f in range(flags.shape[0]):
        if flags[f]:
            count += 3
    out = np.empty(count, np.int64)
    k = 0
    for f in range(flags.shape[0]):
        if flags[f]:
            for c in range(3):
                v = faces[f, c]
                if not seen[v]:
                    seen[v] = True
                    out[k] = v
                    k += 1
    for p in range(k):
        seen[out[p]] = False
    return out[:k]


@leaf
def faces_touching(flags, faces):
    """The faces with a corner at a flagged vertex, in order.

    Parameters
    ----------
    flags : (n,) bool
    faces : (m, 3) int32 or int64

    Returns
    -------
    (k,) int64
    """
    out = np.empty(faces.shape[0], np.int64)
    k = 0
    for f in range(faces.shape[0]):
        if flags[faces[f, 0]] or flags[faces[f, 1]] or flags[faces[f, 2]]:
            out[k] = f
            k += 1
    return out[:k].copy()


@leaf
def incident_faces(verts, vf_ptr, vf_tri):
    """The faces incident to the listed vertices, concatenated per vertex (a face shared by
    several listed vertices appears once per vertex).

    Parameters
    ----------
    verts : (k,) int64
    vf_ptr, vf_tri : CSR from :func:`vertex_faces`

    Returns
    -------
    (sum of the valences,) int64
    """
    total = 0
    for v in verts:
        total += vf_ptr[v + 1] - vf_ptr[v]
    out = np.empty(total, np.int64)
    k = 0
    for v in verts:
        for p in range(vf_ptr[v], vf_ptr[v + 1]):
            out[k] = vf_tri[p]
            k += 1
    return out


@leaf
def small_pieces(indptr, indices, keep, area, changed, limit):
    """Kept faces in the pieces next to the ``changed`` faces whose area is below their limit.

    A piece is a connected set of kept faces (over the adjacency ``indptr``, ``indices``);
    each piece with a face next to a changed face is explored from that face until its area
    reaches that face's limit (then it is large enough, and so is any piece reaching a face
    found so) or it is exhausted (then it is small).

    Parameters
    ----------
    indptr : (m + 1,) int64
    indices : (2 p,) int64
        Face adjacency (CSR).
    keep : (m,) bool
    area : (m,) float64
    changed : (k,) int64
        Faces whose removal may have cut pieces off.
    limit : (m,) float64
        The area below which a piece holding the face is small.

    Returns
    -------
    (m,) bool
        The faces of the small pieces.
    """
    m = keep.shape[0]
    # 0: not looked at, 1: in a large enough piece, 2: in a small piece, 3: being explored
    state = np.zeros(m, np.int8)
    stack = np.empty(m, np.int64)
    seen = np.empty(m, np.int64)
    for d in changed:
        for q in range(indptr[d], indptr[d + 1]):
            s = indices[q]
            if not keep[s] or state[s] != 0:
                continue
            state[s] = 3
            stack[0] = s
            seen[0] = s
            top, n_seen = 1, 1
            total = area[s]
            large = total >= limit[s]
            while top > 0 and not large:
                top -= 1
                f = stack[top]
                for p in range(indptr[f], indptr[f + 1]):
                    g = indices[p]
                    if not keep[g] or state[g] == 3:
                        continue
                    if state[g] == 1:
                        large = True
                        break
                    state[g] = 3
                    stack[top] = g
                    top += 1
                    seen[n_seen] = g
                    n_seen += 1
                    total += area[g]
                    if total >= limit[s]:
                        large = True
                        break
            mark = 1 if large else 2
            for j in range(n_seen):
                state[seen[j]] = mark
    return state == 2
