"""Numba kernels for mesh loading and cleaning: an OBJ tokenizer and orientation propagation.

Arrays in, arrays out, no I/O. The OBJ kernels read the file's bytes (``uint8``) in two
passes over ranges of whole lines: :func:`obj_count` sizes the output, :func:`obj_fill` parses
into preallocated arrays (the ranges of a file side by side, in threads).
"""
from __future__ import annotations

import numpy as np

from potflat._jit import leaf, parallel, prange

#: Marker for an index that can never be valid (``0`` in an OBJ face, or malformed).
BAD_INDEX = -(2**62)


@leaf
def _is_space(c):
    return c == 32 or c == 9 or c == 13 or c == 11 or c == 12


@leaf
def _skip_spaces(buf, i, n):
    while i < n and _is_space(buf[np.uint64(i)]):
        i += 1
    return i


@leaf
def _skip_line(buf, i, n):
    while i < n and buf[np.uint64(i)] != 10:
        i += 1
    return i


@leaf
def _token_end(buf, i, n):
    while i < n and buf[np.uint64(i)] != 10 and not _is_space(buf[np.uint64(i)]):
        i += 1
    return i


@leaf
def _keyword(buf, i, n):
    """Code of the OBJ keyword at ``i``: 1 v, 2 vt, 3 f, 4 usemtl, 5 mtllib, 0 other."""
    j = _token_end(buf, i, n)
    k = j - i
    if k == 1 and buf[i] == 118:  # v
        return 1, j
    if k == 1 and buf[i] == 102:  # f
        return 3, j
    if k == 2 and buf[i] == 118 and buf[i + 1] == 116:  # vt
        return 2, j
    if k == 6 and buf[i] == 117 and buf[i + 1] == 115 and buf[i + 2] == 101 and buf[i + 3] == 109:
        return 4, j  # usem(tl)
    if k == 6 and buf[i] == 109 and buf[i + 1] == 116 and buf[i + 2] == 108 and buf[i + 3] == 108:
        return 5, j  # mtll(ib)
    return 0, j


@leaf
def _parse_float(buf, i, n):
    """Parse a decimal float at ``i``; returns (value, end, ok). ``nan``/``inf`` are parsed."""
    neg = False
    if i < n and (buf[i] == 45 or buf[i] == 43):
        neg = buf[i] == 45
        i += 1
    if i < n and (buf[i] | 32) == 110:  # nan
        return np.nan, _token_end(buf, i, n), True
    if i < n and (buf[i] | 32) == 105:  # inf
        return (-np.inf if neg else np.inf), _token_end(buf, i, n), True
    mant = 0
    ndig = 0
    exp10 = 0
    seen = False
    while i < n and 48 <= buf[np.uint64(i)] <= 57:
        seen = True
        if ndig < 18:
            mant = mant * 10 + (buf[np.uint64(i)] - 48)
            if mant > 0:
                ndig += 1
        else:
            exp10 += 1
        i += 1
    if i < n and buf[i] == 46:
        i += 1
        while i < n and 48 <= buf[np.uint64(i)] <= 57:
            seen = True
            if ndig < 18:
                mant = mant * 10 + (buf[np.uint64(i)] - 48)
                if mant > 0:
                    ndig += 1
                exp10 -= 1
            i += 1
    if not seen:
        return 0.0, i, False
    if i < n and (buf[i] | 32) == 101:  # e / E
        i += 1
        eneg = False
        if i < n and (buf[i] == 45 or buf[i] == 43):
            eneg = buf[i] == 45
            i += 1
        e = 0
        eseen = False
        while i < n and 48 <= buf[i] <= 57:
            eseen = True
            if e < 100000:
                e = e * 10 + (buf[i] - 48)
            i += 1
        if not eseen:
            return 0.0, i, False
        exp10 += -e if eneg else e
    val = float(mant)
    if mant == 0:
        val = 0.0
    elif exp10 > 0:
        val = val * 10.0 ** exp10
    elif exp10 < 0:
        if exp10 < -300:
            val = (val / 10.0 ** 300) / 10.0 ** (-exp10 - 300)
        else:
            val = val / 10.0 ** (-exp10)
    return (-val if neg else val), i, True


@leaf
def _parse_int(buf, i, n):
    """Parse a signed integer at ``i``; returns (value, end, ok)."""
    neg = False
    if i < n and (buf[i] == 45 or buf[i] == 43):
        neg = buf[i] == 45
        i += 1
    v = 0
    seen = False
    while i < n and 48 <= buf[np.uint64(i)] <= 57:
        if v < 10**15:
            v = v * 10 + (buf[np.uint64(i)] - 48)
        seen = True
        i += 1
    return (-v if neg else v), i, seen


#: The order of the counts of :func:`obj_count` (and of the running offsets of :func:`obj_fill`).
OBJ_VERTICES, OBJ_TEXCOORDS, OBJ_FACES, OBJ_CORNERS, OBJ_USEMTL, OBJ_MTLLIB, OBJ_LINES = range(7)


@leaf
def obj_count(buf, start, stop):
    """Count the records of the lines of an OBJ file in ``buf[start:stop]``.

    Parameters
    ----------
    buf : (nbytes,) uint8
        The file's content.
    start, stop : int
        A range of whole lines: ``start`` is 0 or follows a newline, ``stop`` follows a
        newline or is the end of the file.

    Returns
    -------
    counts : (7,) int64
        Vertices, texture coordinates, faces, face corners, ``usemtl`` lines, ``mtllib`` lines
        and lines (the ``OBJ_*`` indices).
    """
    n = np.int64(stop)
    counts = np.zeros(7, np.int64)
    i = np.int64(start)
    while i < n:
        counts[OBJ_LINES] += 1
        i = _skip_spaces(buf, i, n)
        if i < n and buf[i] != 10 and buf[i] != 35:
            kw, i = _keyword(buf, i, n)
            if kw == 1:
                counts[OBJ_VERTICES] += 1
            elif kw == 2:
                counts[OBJ_TEXCOORDS] += 1
            elif kw == 3:
                counts[OBJ_FACES] += 1
                while True:
                    i = _skip_spaces(buf, i, n)
                    if i >= n or buf[i] == 10 or buf[i] == 35:
                        break
                    counts[OBJ_CORNERS] += 1
                    i = _token_end(buf, i, n)
            elif kw == 4:
                counts[OBJ_USEMTL] += 1
            elif kw == 5:
                counts[OBJ_MTLLIB] += 1
        i = _skip_line(buf, i, n) + 1
    return counts


@leaf
def obj_fill(buf, start, stop, before, V, vcols, VT, corner_v, corner_vt, face_ptr, use_spans, lib_spans):
    """Parse the lines of an OBJ file in ``buf[start:stop]`` into arrays sized by
    :func:`obj_count`, at the rows after the records of the lines before them.

    Ranges of one file can be parsed in any order, also at the same time (each writes its
    own rows; serial, without the GIL).

    Parameters
    ----------
    buf : (nbytes,) uint8
        The file's content.
    start, stop : int
        A range of whole lines (as in :func:`obj_count`).
    before : (7,) int64
        :func:`obj_count` of ``buf[:start]``: where the range's rows start, its first line's
        number - 1, and the vertex and texture counts that relative (negative) indices count
        back from.
    V : (nv, 6) float64
        Output (filled with NaN): up to six numbers per ``v`` line (x y z and optional r g b).
    vcols : (nv,) int64
        Output: how many numbers each ``v`` line had.
    VT : (nvt, 2) float64
        Output (filled with 0): the first two numbers of each ``vt`` line.
    corner_v, corner_vt : (nc,) int64
        Output: 0-based vertex and texture indices of each face corner; relative (negative)
        indices resolved; ``-1`` = no texture index; :data:`BAD_INDEX` = malformed or zero index.
    face_ptr : (nf + 1,) int64
        Output (``face_ptr[0] = 0``): corners of face ``k`` are ``face_ptr[k]:face_ptr[k + 1]``.
    use_spans : (nuse, 3) int64
        Output: byte span of each ``usemtl`` line's argument and the index of the next face.
    lib_spans : (nlib, 2) int64
        Output: byte span of each ``mtllib`` line's argument.

    Returns
    -------
    bad_line : int
        1-based number (in the file) of the range's first line with an unparsable number, 0 if none.
    """
    n = np.int64(stop)
    iv = before[OBJ_VERTICES]
    ivt = before[OBJ_TEXCOORDS]
    jf = before[OBJ_FACES]
    jc = before[OBJ_CORNERS]
    ju = before[OBJ_USEMTL]
    jl = before[OBJ_MTLLIB]
    line = before[OBJ_LINES]
    bad_line = 0
    i = np.int64(start)
    while i < n:
        line += 1
        i = _skip_spaces(buf, i, n)
        if i < n and buf[i] != 10 and buf[i] != 35:
            kw, i = _keyword(buf, i, n)
            if kw == 1 or kw == 2:
                k = 0
                while True:
                    i = _skip_spaces(buf, i, n)
                    if i >= n or buf[i] == 10 or buf[i] == 35:
                        break
                    val, i, ok = _parse_float(buf, i, n)
                    if not ok or (i < n and buf[i] != 10 and not _is_space(buf[i])):
                        if bad_line == 0:
                            bad_line = line
                        i = _token_end(buf, i, n)
                        val = np.nan
                    if kw == 1 and k < 6:
                        V[iv, k] = val
                    elif kw == 2 and k < 2:
                        VT[ivt, k] = val
                    k += 1
                if kw == 1:
                    vcols[iv] = k
                    iv += 1
                else:
                    ivt += 1
            elif kw == 3:
                while True:
                    i = _skip_spaces(buf, i, n)
                    if i >= n or buf[i] == 10 or buf[i] == 35:
                        break
                    end = _token_end(buf, i, n)
                    a, i, ok = _parse_int(buf, i, end)
                    if not ok or a == 0:
                        cv = BAD_INDEX
                    elif a > 0:
                        cv = a - 1
                    else:
                        cv = iv + a
                        if cv < 0:
                            cv = BAD_INDEX
                    ct = -1
                    if i < end and buf[i] == 47:  # '/'
                        i += 1
                        if i < end and buf[i] != 47:
                            t, i, ok = _parse_int(buf, i, end)
                            if not ok or t == 0:
                                ct = BAD_INDEX
                            elif t > 0:
                                ct = t - 1
                            else:
                                ct = ivt + t
                                if ct < 0:
                                    ct = BAD_INDEX
                    i = end
                    corner_v[jc] = cv
                    corner_vt[jc] = ct
                    jc += 1
                jf += 1
                face_ptr[jf] = jc
            elif kw == 4 or kw == 5:
                i = _skip_spaces(buf, i, n)
                e = _skip_line(buf, i, n)
                while e > i and _is_space(buf[e - 1]):
                    e -= 1
                if kw == 4:
                    use_spans[ju, 0] = i
                    use_spans[ju, 1] = e
                    use_spans[ju, 2] = jf
                    ju += 1
                else:
                    lib_spans[jl, 0] = i
                    lib_spans[jl, 1] = e
                    jl += 1
        i = _skip_line(buf, i, n) + 1
    return bad_line


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


@leaf
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
    Each bucket entry carries its higher endpoint, so the sort within a bucket and the
    numbering read it in order instead of looking it up in ``F`` (0.15 s against 0.23 s at
    2M faces, 0.35 s against 0.9 s with the faces shuffled).
    """
    m = F.shape[0]
    start = np.zeros(n + 1, np.int64)
    for f in range(m):
        for k in range(3):
            start[np.uint64(min(F[f, k], F[f, (k + 1) % 3]) + 1)] += 1
    for v in range(n):
        start[v + 1] += start[v]
    fill = start[:-1].copy()
    bucket = np.empty(3 * m, np.int64)  # half-edges by lower endpoint, in id order
    other = np.empty(3 * m, np.int64)  # the higher endpoint of each
    for f in range(m):
        for k in range(3):
            a = F[f, k]
            b = F[f, (k + 1) % 3]
            lo = np.uint64(min(a, b))
            p = np.uint64(fill[lo])
            bucket[p] = 3 * f + k
            other[p] = max(a, b)
            fill[lo] = p + np.uint64(1)
    # sort each bucket by the other endpoint (buckets are small) and number the edges
    edge_of = np.empty(3 * m, np.int64)
    ne = 0
    for v in range(n):
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
        for a in range(s, e):
            if a == s or other[a - 1] != other[a]:
                ne += 1
            edge_of[np.uint64(bucket[a])] = ne - 1
    edges = np.empty((ne, 2), np.int64)
    count = np.zeros(ne, np.int64)
    halves = np.full((ne, 2), -1, np.int64)
    for v in range(n):
        for a in range(np.uint64(start[v]), np.uint64(start[v + 1])):
            x = bucket[a]
            k = np.uint64(edge_of[np.uint64(x)])
            edges[k, 0] = v
            edges[k, 1] = other[a]
            if count[k] < 2:
                halves[k, count[k]] = x
            count[k] += 1
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
def texel_spread(texcoords, faces, img):
    """Spread of the grey levels under each face: the standard deviation of the texels at its
    three corners and at their mean (nearest texel, texture coordinates wrapped into [0, 1)).

    Parameters
    ----------
    texcoords : (m, 3, 2) float64
        Texture coordinates of every face's corners, OBJ convention (v up).
    faces : (k,) int64
        The faces to measure.
    img : (h, w) uint8
        Grey levels, row 0 at the top.

    Returns
    -------
    (k,) float64
        Exact for 8-bit levels: sums of at most four of them and their squared deviations
        (multiples of 1/16) are exact in any order, so this equals NumPy's ``std``.
    """
    k = faces.shape[0]
    hgt, wid = img.shape
    out = np.empty(k)
    vals = np.empty(4)
    for i in range(k):
        f = faces[i]
        for c in range(4):
            if c < 3:
                u = texcoords[f, c, 0]
                v = texcoords[f, c, 1]
            else:
                u = (texcoords[f, 0, 0] + texcoords[f, 1, 0] + texcoords[f, 2, 0]) / 3.0
                v = (texcoords[f, 0, 1] + texcoords[f, 1, 1] + texcoords[f, 2, 1]) / 3.0
            col = min(int((u % 1.0) * wid), wid - 1)
            row = min(int((1.0 - v % 1.0) * hgt), hgt - 1)
            vals[c] = img[row, col]
        mean = (vals[0] + vals[1] + vals[2] + vals[3]) / 4.0
        ss = 0.0
        for c in range(4):
            ss += (vals[c] - mean) * (vals[c] - mean)
        out[i] = np.sqrt(ss / 4.0)
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
def _face_cross(V, a, b, c):
    """``(V[b] - V[a]) x (V[c] - V[a])`` of the triangle ``a, b, c`` (unsigned indices): its
    normal times twice its area."""
    d1x = V[b, 0] - V[a, 0]
    d1y = V[b, 1] - V[a, 1]
    d1z = V[b, 2] - V[a, 2]
    d2x = V[c, 0] - V[a, 0]
    d2y = V[c, 1] - V[a, 1]
    d2z = V[c, 2] - V[a, 2]
    return d1y * d2z - d1z * d2y, d1z * d2x - d1x * d2z, d1x * d2y - d1y * d2x


@leaf
def vertex_normal_sums(V, F):
    """Sum of the adjacent faces' cross products and a third of their areas at each vertex.

    Serial, face by face and corner by corner: the sums of ``np.bincount`` over ``F.ravel()``
    with the face values repeated three times, bit for bit.

    Parameters
    ----------
    V : (n, 3) float64
    F : (m, 3) int64
        Faces; the cross products follow their winding.

    Returns
    -------
    acc : (n, 3) float64
        ``sum (V[F1] - V[F0]) x (V[F2] - V[F0])`` over each vertex's faces.
    area : (n,) float64
        ``sum |cross| / 6`` over each vertex's faces.
    """
    n = V.shape[0]
    acc = np.zeros((n, 3))
    area = np.zeros(n)
    for f in range(F.shape[0]):
        cx, cy, cz = _face_cross(V, np.uint64(F[f, 0]), np.uint64(F[f, 1]), np.uint64(F[f, 2]))
        w = np.sqrt(cx * cx + cy * cy + cz * cz) / 6.0
        for c in range(3):
            v = np.uint64(F[f, c])
            acc[v, 0] += cx
            acc[v, 1] += cy
            acc[v, 2] += cz
            area[v] += w
    return acc, area


@leaf
def radial_parts(d, height, direction):
    """Distance from an axis and unit radial direction of offsets from a point on it.

    Parameters
    ----------
    d : (n, 3) float64
        Offsets of the points from the axis point.
    height : (n,) float64
        ``d @ direction`` (computed by the caller, so that it is NumPy's own product).
    direction : (3,) float64
        Unit axis direction.

    Returns
    -------
    radius : (n,) float64
    radial : (n, 3) float64
        Zero where the radius is zero.
    """
    n = d.shape[0]
    radius = np.empty(n)
    radial = np.zeros((n, 3))
    for i in range(n):
        q0 = d[i, 0] - height[i] * direction[0]
        q1 = d[i, 1] - height[i] * direction[1]
        q2 = d[i, 2] - height[i] * direction[2]
        r = np.sqrt(q0 * q0 + q1 * q1 + q2 * q2)
        radius[i] = r
        if r > 0:
            radial[i, 0] = q0 / r
            radial[i, 1] = q1 / r
            radial[i, 2] = q2 / r
    return radius, radial


@parallel
def triangle_areas(V, F):
    """3D area of each face.

    Parameters
    ----------
    V : (n, 3) float64
    F : (m, 3) int64

    Returns
    -------
    (m,) float64
        ``|(p1 - p0) x (p2 - p0)| / 2``, bit-identical to
        ``0.5 * np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=1)``.
    """
    m = F.shape[0]
    out = np.empty(m)
    for f in prange(m):
        cx, cy, cz = _face_cross(V, np.uint64(F[f, 0]), np.uint64(F[f, 1]), np.uint64(F[f, 2]))
        out[f] = 0.5 * np.sqrt(cx * cx + cy * cy + cz * cz)
    return out


@parallel
def face_geometry(V, F):
    """Per-face cross product, twice the area, longest squared edge and centroid.

    Parameters
    ----------
    V : (n, 3) float64
        Vertex positions.
    F : (m, 3) int64
        Faces.

    Returns
    -------
    cross : (m, 3) float64
        ``(V[F1] - V[F0]) x (V[F2] - V[F0])`` (normal times twice the area).
    area2 : (m,) float64
        Twice the area (norm of ``cross``).
    longest2 : (m,) float64
        Squared length of the longest edge.
    centroid : (m, 3) float64
        Mean of the three corners.
    """
    m = F.shape[0]
    cross = np.empty((m, 3))
    area2 = np.empty(m)
    longest2 = np.empty(m)
    centroid = np.empty((m, 3))
    for f in prange(m):
        a = np.uint64(F[f, 0])
        b = np.uint64(F[f, 1])
        c = np.uint64(F[f, 2])
        e0x = V[b, 0] - V[a, 0]
        e0y = V[b, 1] - V[a, 1]
        e0z = V[b, 2] - V[a, 2]
        e1x = V[c, 0] - V[b, 0]
        e1y = V[c, 1] - V[b, 1]
        e1z = V[c, 2] - V[b, 2]
        e2x = V[a, 0] - V[c, 0]
        e2y = V[a, 1] - V[c, 1]
        e2z = V[a, 2] - V[c, 2]
        cx, cy, cz = _face_cross(V, a, b, c)
        cross[f, 0] = cx
        cross[f, 1] = cy
        cross[f, 2] = cz
        area2[f] = np.sqrt(cx * cx + cy * cy + cz * cz)
        l0 = e0x * e0x + e0y * e0y + e0z * e0z
        l1 = e1x * e1x + e1y * e1y + e1z * e1z
        l2 = e2x * e2x + e2y * e2y + e2z * e2z
        longest2[f] = max(l0, max(l1, l2))
        centroid[f, 0] = (V[a, 0] + V[b, 0] + V[c, 0]) / 3.0
        centroid[f, 1] = (V[a, 1] + V[b, 1] + V[c, 1]) / 3.0
        centroid[f, 2] = (V[a, 2] + V[b, 2] + V[c, 2]) / 3.0
    return cross, area2, longest2, centroid


@parallel
def face_frames(V, F, area_3d, valid):
    """Each face's 3D frame for the distortion figures: the inverse of its edge matrix in a
    frame of its plane.

    With ``d1 = p1 - p0``, ``d2 = p2 - p0``, ``e1 = d1 / |d1|`` the face is
    ``Q = [[|d1|, d2 . e1], [0, 2 A / |d1|]]``; the flat map's Jacobian is ``W Q^-1``.

    Parameters
    ----------
    V : (n, 3) float64
    F : (m, 3) int64
    area_3d : (m,) float64
        3D face areas.
    valid : (m,) bool
        Non-degenerate faces.

    Returns
    -------
    (m, 4) float64
        ``Q^-1``'s entries ``(1,1), (1,2), (2,2)`` and 1.0 for a valid face (0.0 else); a
        degenerate face gets the frame of ``Q = I``-like placeholders (its figures are masked).
    """
    m = F.shape[0]
    out = np.empty((m, 4))
    for f in prange(m):
        a = F[f, 0]
        b = F[f, 1]
        c = F[f, 2]
        d1x = V[b, 0] - V[a, 0]
        d1y = V[b, 1] - V[a, 1]
        d1z = V[b, 2] - V[a, 2]
        d2x = V[c, 0] - V[a, 0]
        d2y = V[c, 1] - V[a, 1]
        d2z = V[c, 2] - V[a, 2]
        len1 = np.sqrt(d1x * d1x + d1y * d1y + d1z * d1z)
        ok = valid[f]
        len1s = len1 if (ok and len1 > 0) else 1.0
        # summed in the order numpy's einsum("ij,ij->i") uses for rows of 3 (x, z, then y): the
        # figures stay bit-identical to the former numpy implementation
        q2x = (d2x * (d1x / len1s) + d2z * (d1z / len1s)) + d2y * (d1y / len1s)
        q2y = 2.0 * area_3d[f] / len1s if ok else 1.0
        out[f, 0] = 1.0 / len1s
        out[f, 1] = -q2x / (len1s * q2y)
        out[f, 2] = 1.0 / q2y
        out[f, 3] = 1.0 if ok else 0.0
    return out


@parallel
def flat_face_maps(uv, F, frames):
    """Signed flat area and singular values of each face's 3D-to-flat map.

    Parameters
    ----------
    uv : (n, 2) float64
    F : (m, 3) int64
    frames : (m, 4) float64
        From :func:`face_frames`.

    Returns
    -------
    area_2d, sigma_max, sigma_min : (m,) float64
        ``sigma_min`` negative when the face is mirrored; both 0 for a degenerate face.
    """
    m = F.shape[0]
    area_2d = np.empty(m)
    sigma_max = np.empty(m)
    sigma_min = np.empty(m)
    for f in prange(m):
        p = np.uint64(F[f, 0])
        q1 = np.uint64(F[f, 1])
        q2 = np.uint64(F[f, 2])
        w1x = uv[q1, 0] - uv[p, 0]
        w1y = uv[q1, 1] - uv[p, 1]
        w2x = uv[q2, 0] - uv[p, 0]
        w2y = uv[q2, 1] - uv[p, 1]
        area_2d[f] = 0.5 * (w1x * w2y - w1y * w2x)
        inv11 = frames[f, 0]
        inv12 = frames[f, 1]
        inv22 = frames[f, 2]
        a = w1x * inv11
        b = w1x * inv12 + w2x * inv22
        c = w1y * inv11
        d = w1y * inv12 + w2y * inv22
        # stable closed-form 2x2 SVD: sigma = hypot(E, H) +- hypot(F, G)
        q = np.hypot(0.5 * (a + d), 0.5 * (c - b))
        r = np.hypot(0.5 * (a - d), 0.5 * (c + b))
        sigma_max[f] = (q + r) * frames[f, 3]
        sigma_min[f] = (q - r) * frames[f, 3]
    return area_2d, sigma_max, sigma_min


@parallel
def corner_angles(theta_v, F, idx, centre, shift, out):
    """Each corner's angle ``theta_v - shift`` of the faces ``F[idx]``, unwrapped to within pi
    of its face's angle ``centre``: ``c + ((t - shift - c + pi) % 2 pi - pi)`` as NumPy
    computes it (Python's float modulo).

    Parameters
    ----------
    theta_v : (n,) float64
        Vertex angles.
    F : (m, 3) int64
    idx : (k,) int64
        The faces.
    centre : (k,) float64
        Their angles.
    shift : float
    out : (k, 3) float64
        Output.
    """
    two_pi = 2.0 * np.pi
    for s in prange(idx.shape[0]):
        f = np.uint64(idx[s])
        c = centre[s]
        for j in range(3):
            out[s, j] = c + ((theta_v[np.uint64(F[f, j])] - shift - c + np.pi) % two_pi - np.pi)


@parallel
def faces_reaching(F, values, threshold, out):
    """Whether each face's corner mean of a vertex value reaches a threshold:
    ``(v[a] + v[b] + v[c]) / 3 >= threshold``, summed in NumPy's order.

    Parameters
    ----------
    F : (m, 3) int64
    values : (n,) float64
    threshold : float
    out : (m,) bool
        Output.
    """
    for f in prange(F.shape[0]):
        a = values[np.uint64(F[f, 0])]
        b = values[np.uint64(F[f, 1])]
        c = values[np.uint64(F[f, 2])]
        out[f] = (a + b + c) / 3.0 >= threshold


@leaf
def valid_face_figures(area_3d, area_2d, sigma_max, sigma_min, valid, weight, area_2d_valid, area_ratio,
                       anisotropy):
    """The per-face figures of a distortion summary, for the valid faces only, in one pass.

    Parameters
    ----------
    area_3d, area_2d, sigma_max, sigma_min : (m,) float64
        As in :class:`potflat.mesh.distortion.FaceDistortion`.
    valid : (m,) bool
    weight, area_2d_valid, area_ratio, anisotropy : (m,) float64
        Outputs, their first ``count`` entries written (the valid faces in order): the 3D area,
        the signed flat area, ``|A_2d| / A_3d`` (1 where ``A_2d`` is 0, so its log is 0) and
        ``sigma_max / |sigma_min|`` (inf, or NaN for ``0 / 0``, where ``sigma_min`` is 0, as
        NumPy divides).

    Returns
    -------
    count : int
        Valid faces.
    flipped : int
        Valid faces whose flat area is not positive.
    """
    count = 0
    flipped = 0
    for f in range(area_3d.shape[0]):
        if not valid[f]:
            continue
        a2 = area_2d[f]
        weight[count] = area_3d[f]
        area_2d_valid[count] = a2
        area_ratio[count] = abs(a2) / area_3d[f] if a2 != 0.0 else 1.0
        low = abs(sigma_min[f])
        if low != 0.0:
            anisotropy[count] = sigma_max[f] / low
        else:
            anisotropy[count] = np.inf if sigma_max[f] > 0.0 else np.nan
        if a2 <= 0.0:
            flipped += 1
        count += 1
    return count, flipped


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


@parallel
def edge_lengths(P, E):
    """Length of each edge ``E`` (e, 2) int64 between points ``P`` (n, d) float64. Shape (e,)."""
    k = E.shape[0]
    d = P.shape[1]
    out = np.empty(k)
    for i in prange(k):
        s = 0.0
        e0 = np.uint64(E[i, 0])
        e1 = np.uint64(E[i, 1])
        for j in range(d):
            x = P[e0, j] - P[e1, j]
            s += x * x
        out[i] = np.sqrt(s)
    return out


@leaf
def _strictly_inside(px, py, ax, ay, bx, by, cx, cy):
    """Whether (px, py) lies strictly inside the triangle a b c, either orientation."""
    s1 = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
    s2 = (cx - bx) * (py - by) - (cy - by) * (px - bx)
    s3 = (ax - cx) * (py - cy) - (ay - cy) * (px - cx)
    return (s1 > 0.0 and s2 > 0.0 and s3 > 0.0) or (s1 < 0.0 and s2 < 0.0 and s3 < 0.0)


@leaf
def _cell_range(lo, hi, origin, cell, cells):
    """First and last grid cell (clamped to ``0 .. cells - 1``) of the interval [lo, hi]."""
    a = int((lo - origin) / cell)
    b = int((hi - origin) / cell)
    return min(max(a, 0), cells - 1), min(max(b, 0), cells - 1)


@leaf
def _box_cells(faces, uv, t, ox, oy, cell, gx, gy):
    """The grid cells ``x0..x1`` by ``y0..y1`` of the bounding box of face ``t``."""
    a, b, c = np.uint64(faces[t, 0]), np.uint64(faces[t, 1]), np.uint64(faces[t, 2])
    x0, x1 = _cell_range(min(uv[a, 0], uv[b, 0], uv[c, 0]), max(uv[a, 0], uv[b, 0], uv[c, 0]), ox, cell, gx)
    y0, y1 = _cell_range(min(uv[a, 1], uv[b, 1], uv[c, 1]), max(uv[a, 1], uv[b, 1], uv[c, 1]), oy, cell, gy)
    return x0, x1, y0, y1


@leaf
def centre_grid(faces, uv, ox, oy, cell, gx, gy):
    """The faces binned by the grid cell of their centre, as a CSR table (counting sort):
    cell ``c`` (``cx * gy + cy``) holds ``items[start[c]:start[c + 1]]``, in face order, whose
    centres are ``centres[start[c]:start[c + 1]]``; and the number of cells under the faces'
    bounding boxes in all (the work of :func:`centres_inside`).

    faces (m, 3) int64, uv (n, 2) float64, a grid of ``gx`` x ``gy`` square cells of side
    ``cell`` from (``ox``, ``oy``). Returns start (gx * gy + 1,) int64, items (m,) int64, centres
    (m, 2) float64, covered int.
    """
    m = faces.shape[0]
    where = np.empty(m, np.int64)
    centre = np.empty((m, 2), np.float64)
    covered = 0
    for t in range(m):
        a, b, c = np.uint64(faces[t, 0]), np.uint64(faces[t, 1]), np.uint64(faces[t, 2])
        px = (uv[a, 0] + uv[b, 0] + uv[c, 0]) / 3.0
        py = (uv[a, 1] + uv[b, 1] + uv[c, 1]) / 3.0
        centre[t, 0] = px
        centre[t, 1] = py
        where[t] = _cell_range(px, px, ox, cell, gx)[0] * gy + _cell_range(py, py, oy, cell, gy)[0]
        x0, x1, y0, y1 = _box_cells(faces, uv, t, ox, oy, cell, gx, gy)
        covered += (x1 - x0 + 1) * (y1 - y0 + 1)
    start = np.zeros(gx * gy + 1, np.int64)
    for t in range(m):
        start[np.uint64(where[t] + 1)] += 1
    for k in range(1, start.shape[0]):
        start[k] += start[k - 1]
    fill = start[:-1].copy()
    items = np.empty(m, np.int64)
    centres = np.empty((m, 2), np.float64)
    for t in range(m):
        k = np.uint64(where[t])
        q = np.uint64(fill[k])
        items[q] = t
        centres[q, 0] = centre[t, 0]
        centres[q, 1] = centre[t, 1]
        fill[k] = q + np.uint64(1)
    return start, items, centres, covered


@parallel
def centres_inside(faces, uv, ox, oy, cell, gx, gy, start, items, centres, first, counts, pairs):
    """Faces whose centre lies strictly inside each face, sharing no vertex with it, through
    the grid of :func:`centre_grid`: per face the number of such faces (``first`` empty), or
    their indices written to ``pairs[first[j]:first[j] + counts[j]]`` (the faces counted
    none skipped).

    faces (m, 3) int64, uv (n, 2) float64, start/items/centres the grid's, first (m,) int64 or
    (0,), counts (m,) int64 (out when counting), pairs (k,) int64 out.
    """
    fill = first.shape[0] > 0
    for j in prange(faces.shape[0]):
        if fill and counts[j] == 0:
            continue
        b0, b1, b2 = np.uint64(faces[j, 0]), np.uint64(faces[j, 1]), np.uint64(faces[j, 2])
        x0, x1, y0, y1 = _box_cells(faces, uv, j, ox, oy, cell, gx, gy)
        n_in = 0
        for cx in range(x0, x1 + 1):
            for cy in range(y0, y1 + 1):
                k = np.uint64(cx * gy + cy)
                for q in range(np.uint64(start[k]), np.uint64(start[k + 1])):
                    # the grid's centres in order first; the faces' corners only for a centre inside
                    if not _strictly_inside(centres[q, 0], centres[q, 1], uv[b0, 0], uv[b0, 1], uv[b1, 0],
                                            uv[b1, 1], uv[b2, 0], uv[b2, 1]):
                        continue
                    i = items[q]
                    if i == j:
                        continue
                    iu = np.uint64(i)
                    a0, a1, a2 = np.uint64(faces[iu, 0]), np.uint64(faces[iu, 1]), np.uint64(faces[iu, 2])
                    if (b0 == a0 or b0 == a1 or b0 == a2 or b1 == a0 or b1 == a1 or b1 == a2
                            or b2 == a0 or b2 == a1 or b2 == a2):
                        continue
                    if fill:
                        pairs[first[j] + n_in] = i
                    n_in += 1
        if not fill:
            counts[j] = n_in


@leaf
def _mark_bins(stamp, mark, tv, lo, hi, nbins):
    """Stamp with ``mark`` the angle bins (of ``nbins``) of the points ``lo:hi``; the number
    of bins newly stamped."""
    new = 0
    for k in range(np.uint64(lo), np.uint64(hi)):
        b = np.uint64(min(np.int64(tv[k] / (2.0 * np.pi) * nbins), nbins - 1))
        if stamp[b] != mark:
            stamp[b] = mark
            new += 1
    return new


@leaf
def angle_coverage(cells, ptr, tv, targets, nh, ring_bins, target_count, own_count):
    """Angle bins covered by the points of each meridian-plane cell and of its 3 x 3 cells.

    Cells are numbered ``row * nr + ring`` (row in ``[0, nh)``, ring in ``[0, nr)``); a point
    at angle ``t`` lies in bin ``floor(t / (2 pi) * bins)`` of a ring of ``bins`` angle bins
    (the last bin at most).

    Parameters
    ----------
    cells : (u,) int64
        The cells holding points, ascending.
    ptr : (u + 1,) int64
        Cell ``cells[i]`` holds the points ``ptr[i]:ptr[i + 1]`` of ``tv``.
    tv : (s,) float64
        Angle in ``[0, 2 pi)`` of each point, grouped by cell.
    targets : (t,) int64
        Cells to measure, ascending, each within one row and one ring of a cell in ``cells``.
    nh : int
        Rows.
    ring_bins : (nr,) int64
        Angle bins of each ring (every ring in ``cells`` below ``nr - 1``).
    target_count : (t,) int64
        Output: the bins of each target's ring holding a point of its 3 x 3 cells.
    own_count : (u,) int64
        Output: the bins of each cell's ring holding one of its own points.
    """
    u = cells.shape[0]
    nr = ring_bins.shape[0]
    stamp = np.zeros(ring_bins.max(), np.int64)  # bin b was counted for the target stamped in it
    mark = 0
    for i in range(targets.shape[0]):
        row = targets[i] // nr
        ring = targets[i] % nr
        nbins = ring_bins[ring]
        mark += 1
        count = 0
        for dh in range(-1, 2):
            sh = row - dh
            if sh < 0 or sh >= nh:
                continue
            for dr in range(-1, 2):
                sr = ring - dr
                if sr < 0 or sr >= nr:
                    continue
                key = sh * nr + sr
                lo = 0  # binary search of the source cell
                hi = u
                while lo < hi:
                    mid = (lo + hi) >> 1
                    if cells[mid] < key:
                        lo = mid + 1
                    else:
                        hi = mid
                if lo < u and cells[lo] == key:
                    count += _mark_bins(stamp, mark, tv, ptr[lo], ptr[lo + 1], nbins)
        target_count[i] = count
    for j in range(u):
        mark += 1
        own_count[j] = _mark_bins(stamp, mark, tv, ptr[j], ptr[j + 1], ring_bins[cells[j] % nr])


@parallel
def segment_distances(reps, pts, idx, nearest, join, out):
    """Distance of each point to the segment between its two nearest representatives, where
    that segment is at most ``join`` long, else to the nearest one (the formulas, and their
    order, of NumPy's vector form).

    Parameters
    ----------
    reps : (q, 2) float64
        The representatives (points of a curve).
    pts : (k, 2) float64
    idx : (k, 2) int64
        Each point's two nearest representatives (a k-d tree's answer).
    nearest : (k,) float64
        The distance to the first of them.
    join : float
    out : (k,) float64
        Output: ``min(nearest, segment distance)`` where the segment is at most ``join`` long,
        else ``nearest``.
    """
    for i in prange(pts.shape[0]):
        a = np.uint64(idx[i, 0])
        b = np.uint64(idx[i, 1])
        p1x = reps[a, 0]
        p1y = reps[a, 1]
        sx = reps[b, 0] - p1x
        sy = reps[b, 1] - p1y
        L2 = sx * sx + sy * sy
        t = ((pts[i, 0] - p1x) * sx + (pts[i, 1] - p1y) * sy) / (L2 if L2 > 0.0 else 1.0)
        t = min(max(t, 0.0), 1.0)
        dx = pts[i, 0] - (p1x + t * sx)
        dy = pts[i, 1] - (p1y + t * sy)
        d = nearest[i]
        out[i] = min(d, np.sqrt(dx * dx + dy * dy)) if np.sqrt(L2) <= join else d


@leaf
def lower_medians(values, start, stop, out):
    """The lower median of each segment of ``values``: its element of rank ``ceil(k / 2) - 1``
    (from 0) among the segment's ``k`` values in ascending order (Hoare's selection on a copy).

    Parameters
    ----------
    values : (s,) float64
        No NaN.
    start, stop : (g,) int64
        Segment ``j`` is ``values[start[j]:stop[j]]`` (not empty).
    out : (g,) float64
        Output.
    """
    longest = 0
    for j in range(out.shape[0]):
        longest = max(longest, stop[j] - start[j])
    buf = np.empty(longest)
    for j in range(out.shape[0]):
        k = stop[j] - start[j]
        for q in range(k):
            buf[q] = values[start[j] + q]
        want = (k + 1) // 2 - 1
        lo = 0
        hi = k - 1
        while lo < hi:
            pivot = buf[(lo + hi) >> 1]
            a = lo
            b = hi
            while a <= b:
                while buf[a] < pivot:
                    a += 1
                while buf[b] > pivot:
                    b -= 1
                if a <= b:
                    t = buf[a]
                    buf[a] = buf[b]
                    buf[b] = t
                    a += 1
                    b -= 1
            if want <= b:
                hi = b
            elif want >= a:
                lo = a
            else:
                break
        out[j] = buf[want]


#: Key of a NaN in :func:`select_weighted_quantiles` (after every number, as NumPy sorts NaN last).
_NAN_KEY = np.uint64(0xFFFFFFFFFFFFFFFF)
_SIGN_BIT = np.uint64(0x8000000000000000)
#: Bits of the key sorted out per histogram pass, and the candidates below which the rest is sorted.
_RADIX_BITS = 16
_SORT_BELOW = 1 << 12


@leaf
def _order_key(bits):
    """Unsigned key of a float64's bits that orders as the numbers do (NaN last)."""
    if (bits & np.uint64(0x7FF0000000000000)) == np.uint64(0x7FF0000000000000) and \
            (bits & np.uint64(0x000FFFFFFFFFFFFF)) != np.uint64(0):
        return _NAN_KEY
    if bits & _SIGN_BIT:
        return ~bits
    return bits | _SIGN_BIT


@leaf
def _pick_in_order(values, bits, weights, cand, below, target):
    """The first of ``cand`` in value order whose cumulative weight (from ``below``) reaches
    ``target``; the largest when rounding keeps it from being reached."""
    keys = np.empty(cand.shape[0], np.uint64)
    for j in range(cand.shape[0]):
        keys[j] = _order_key(bits[cand[j]])
    order = np.argsort(keys)
    for j in range(order.shape[0]):
        below += weights[cand[order[j]]]
        if below >= target:
            return values[cand[order[j]]]
    return values[cand[order[-1]]]


@leaf
def _radix_histogram(bits, weights, cand, shift):
    """Weight and count of the candidates in each bucket of their key bits ``shift .. shift + 16``."""
    nb = 1 << _RADIX_BITS
    mask = np.uint64(nb - 1)
    hist_w = np.zeros(nb)
    hist_c = np.zeros(nb, np.int64)
    for i in cand:
        b = (_order_key(bits[i]) >> np.uint64(shift)) & mask
        hist_w[b] += weights[i]
        hist_c[b] += 1
    return hist_w, hist_c


@leaf
def _narrow(bits, cand, shift, hist_w, hist_c, below, target):
    """One radix pass over :func:`_radix_histogram`'s buckets: the candidates in the bucket
    where the cumulative weight (from ``below``) reaches ``target`` (the last non-empty bucket
    when rounding keeps it from being reached), and the weight below that bucket."""
    mask = np.uint64(hist_w.shape[0] - 1)
    chosen, last_below = -1, below
    for b in range(hist_w.shape[0]):
        if hist_c[b] == 0:
            continue
        if below + hist_w[b] >= target:
            chosen = b
            break
        chosen, last_below = b, below
        below += hist_w[b]
    else:
        below = last_below
    out = np.empty(hist_c[chosen], np.int64)
    j = 0
    for i in cand:
        if ((_order_key(bits[i]) >> np.uint64(shift)) & mask) == np.uint64(chosen):
            out[j] = i
            j += 1
    return out, below


@leaf
def select_weighted_quantiles(values, weights, fractions, out):
    """Weighted quantiles by radix selection (no sort of all values).

    ``out[k]`` is the smallest value ``v`` among the entries of positive weight whose
    cumulative weight ``W(<= v)`` reaches ``fractions[k] * W`` (``W`` the total positive weight,
    summed in index order); the largest value when rounding keeps it from being reached.
    NaN orders after every number, ``-0.0`` just before ``0.0``. Per fraction: histograms of the
    weights over 16 bits of an order-preserving key at a time, narrowing to the bucket the
    threshold falls in, then a sort of the last few thousand candidates.

    Parameters
    ----------
    values : (n,) float64
    weights : (n,) float64
        Entries of weight <= 0 (or NaN) do not count; at least one must be positive.
    fractions : (k,) float64
        In [0, 1].
    out : (k,) float64
        Output.
    """
    bits = values.view(np.uint64)
    total = 0.0
    count = 0
    for i in range(values.shape[0]):
        if weights[i] > 0.0:
            total += weights[i]
            count += 1
    kept = np.empty(count, np.int64)
    j = 0
    for i in range(values.shape[0]):
        if weights[i] > 0.0:
            kept[j] = i
            j += 1
    top = 64 - _RADIX_BITS  # the first pass's histogram, the same for every fraction
    if count > _SORT_BELOW:
        top_w, top_c = _radix_histogram(bits, weights, kept, top)
    else:
        top_w, top_c = np.zeros(0), np.zeros(0, np.int64)
    for k in range(fractions.shape[0]):
        target = fractions[k] * total
        cand, below, shift = kept, 0.0, 64
        while cand.shape[0] > _SORT_BELOW and shift > 0:
            shift -= _RADIX_BITS
            if shift == top:
                hist_w, hist_c = top_w, top_c
            else:
                hist_w, hist_c = _radix_histogram(bits, weights, cand, shift)
            cand, below = _narrow(bits, cand, shift, hist_w, hist_c, below, target)
        out[k] = _pick_in_order(values, bits, weights, cand, below, target)
