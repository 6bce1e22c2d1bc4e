"""Spring-model kernels of the relax stage (paper Eq. 1 and 2), all in 2D.

Arrays in, arrays out, no I/O. Parallel kernels only write to per-iteration slots:
forces are gathered per vertex over a CSR adjacency (each spring stored once per
endpoint), sums are returned per vertex or per fixed-size block and added up serially,
the mesh's edges are counted per vertex, then filled at the summed offsets, so every
result is bit-identical run to run and for any thread count.

Energy (normalised units, ``coef = k`` or ``k / r^2``)::

    E = 1/2 sum_springs coef (|x_i - x_j| - r)^2  +  sum_faces B(A_f)

with the barrier ``B = mu k a_ref phi(A / (eps a_ref))``, ``phi(a) = a - 1 - log a`` for
``a < 1`` and 0 above: it is zero unless a triangle is squeezed below ``eps`` of its
reference area, and infinite for a flipped one.

A second barrier keeps the boundary from wrapping over itself at a vertex: for each guarded
boundary vertex ``b`` (one incoming and one outgoing boundary half-edge, ``prv -> b -> nxt``)
the flat interior angle sum ``Theta_b`` (the sum of its faces' angles at ``b``, which with
positively oriented faces equals the angle swept from ``nxt - b`` counter-clockwise to
``prv - b``) must stay below ``2 pi``: ``mu_b k w_b phi((2 pi - Theta_b) / gap)``, ``w_b`` the
vertex's importance weight (1 without importance). Every face
may keep its orientation while a fan with ``Theta_b > 2 pi`` overlaps itself, so the face
barrier alone does not prevent this. ``Theta_b`` depends only on ``b``, ``prv`` and ``nxt``
(the inner fan edges cancel), so its gradient touches three boundary vertices and is
gathered per vertex through ``prv``/``nxt``.
"""
from __future__ import annotations

import math

import numpy as np

from potflat._jit import leaf, parallel, prange

#: Block size of the deterministic reductions (independent of the thread count).
BLOCK = 4096


@leaf
def edge_springs(faces, count, halves):
    """Cross springs and boundary edges of a triangle mesh, from its edge table
    (:func:`potflat.mesh._kernels.topology.edge_table`), in the table's edge order.

    Parameters
    ----------
    faces : (m, 3) int32 or int64
    count : (e,) int64
        Half-edges (faces) on each edge.
    halves : (e, 2) int64
        The first two half-edges of each edge (lowest ids); half-edge ``3 f + c`` runs from
        ``faces[f, c]`` to ``faces[f, (c + 1) % 3]``.

    Returns
    -------
    cross : (c, 4) int64
        One row ``(p, q, a, b)`` per edge shared by exactly two faces: the shared edge
        ``a -> b`` as it runs in the face with the smaller half-edge index, ``p`` its vertex
        opposite the edge and ``q`` the other face's; rows with ``p == q`` (e.g. a duplicate
        face) are left out.
    boundary : (b, 2) int64
        The edges used by one face only, each oriented as in its face (``a -> b``
        counter-clockwise). Edges of three or more faces are in neither.
    """
    ne = count.shape[0]
    nc = 0
    nb = 0
    for e in range(ne):
        if count[e] == 1:
            nb += 1
        elif count[e] == 2:
            h0 = halves[e, 0]
            h1 = halves[e, 1]
            if faces[h0 // 3, (h0 % 3 + 2) % 3] != faces[h1 // 3, (h1 % 3 + 2) % 3]:
                nc += 1
    cross = np.empty((nc, 4), np.int64)
    boundary = np.empty((nb, 2), np.int64)
    nc = 0
    nb = 0
    for e in range(ne):
        h0 = halves[e, 0]
        f0 = h0 // 3
        c0 = h0 % 3
        if count[e] == 1:
            boundary[nb, 0] = faces[f0, c0]
            boundary[nb, 1] = faces[f0, (c0 + 1) % 3]
            nb += 1
        elif count[e] == 2:
            h1 = halves[e, 1]
            p = faces[f0, (c0 + 2) % 3]
            q = faces[h1 // 3, (h1 % 3 + 2) % 3]
            if p != q:
                cross[nc, 0] = p
                cross[nc, 1] = q
                cross[nc, 2] = faces[f0, c0]
                cross[nc, 3] = faces[f0, (c0 + 1) % 3]
                nc += 1
    return cross, boundary


@parallel
def halfedge_lengths(V, faces, out):
    """Length of every face's three edges.

    Parameters
    ----------
    V : (n, d) float64
    faces : (m, 3) int32 or int64
    out : (m, 3) float64
        Output: ``out[f, c] = |V[faces[f, (c + 1) % 3]] - V[faces[f, c]]|``, bit-identical
        to ``np.linalg.norm(V[faces[:, [1, 2, 0]]] - V[faces], axis=2)``.
    """
    for f in prange(faces.shape[0]):
        for c in range(3):
            a = np.uint32(faces[f, c])
            b = np.uint32(faces[f, (c + 1) % 3])
            acc = 0.0
            for d in range(V.shape[1]):
                t = V[b, d] - V[a, d]
                acc += t * t
            out[f, c] = math.sqrt(acc)


@parallel
def cross_rest_lengths(V, cross):
    """Intrinsic rest length of each cross spring: the distance of the two opposite
    vertices with the winged pair unfolded flat about the shared edge.

    Parameters
    ----------
    V : (n, 3) float64
    cross : (c, 4) int64
        Rows ``(p, q, a, b)`` from :func:`halfedge_springs`.

    Returns
    -------
    (c,) float64
        Falls back to the 3D chord when the shared edge has zero length.
    """
    nc = cross.shape[0]
    out = np.empty(nc)
    for s in prange(nc):
        p, q, a, b = cross[s, 0], cross[s, 1], cross[s, 2], cross[s, 3]
        ab = 0.0
        ap = 0.0
        bp = 0.0
        aq = 0.0
        bq = 0.0
        pq = 0.0
        for d in range(3):
            ab += (V[b, d] - V[a, d]) ** 2
            ap += (V[p, d] - V[a, d]) ** 2
            bp += (V[p, d] - V[b, d]) ** 2
            aq += (V[q, d] - V[a, d]) ** 2
            bq += (V[q, d] - V[b, d]) ** 2
            pq += (V[q, d] - V[p, d]) ** 2
        L = math.sqrt(ab)
        if L <= 0.0:
            out[s] = math.sqrt(pq)
        else:
            xp = (ap - bp + ab) / (2.0 * L)
            xq = (aq - bq + ab) / (2.0 * L)
            yp = math.sqrt(max(ap - xp * xp, 0.0))
            yq = -math.sqrt(max(aq - xq * xq, 0.0))
            out[s] = math.sqrt((xp - xq) ** 2 + (yp - yq) ** 2)
    return out


@leaf
def build_csr(V, edges, cross, cross_rest):
    """Per-vertex adjacency of the springs: each spring once per endpoint.

    Parameters
    ----------
    V : (n, d) float64
        Rest positions: an edge spring's rest length is its length here.
    edges : (e, 2) int64
        Edge springs.
    cross : (c, 4) int64
        Cross springs: rows ``(p, q, a, b)`` from :func:`halfedge_springs` join ``p`` and ``q``.
    cross_rest : (c,) float64
        Their rest lengths (:func:`cross_rest_lengths`).

    Returns
    -------
    ptr : (n + 1,) int64
    nbr : (2 (e + c),) int32
        The other endpoint; within each vertex the edge springs in ``edges``' order, then the
        cross springs in ``cross``' order.
    rst : (2 (e + c),) float64
        The rest length.
    """
    n = V.shape[0]
    ne = edges.shape[0]
    nc = cross.shape[0]
    deg = np.zeros(n + 1, np.int64)
    for s in range(ne):
        deg[np.uint64(edges[s, 0] + 1)] += 1
        deg[np.uint64(edges[s, 1] + 1)] += 1
    for s in range(nc):
        deg[np.uint64(cross[s, 0] + 1)] += 1
        deg[np.uint64(cross[s, 1] + 1)] += 1
    ptr = np.cumsum(deg)
    fill = ptr[:-1].copy()
    nbr = np.empty(2 * (ne + nc), np.int32)
    rst = np.empty(2 * (ne + nc))
    for s in range(ne):
        i = np.uint64(edges[s, 0])
        j = np.uint64(edges[s, 1])
        acc = 0.0
        for d in range(V.shape[1]):
            t = V[i, d] - V[j, d]
            acc += t * t
        _put_spring(fill, nbr, rst, i, j, math.sqrt(acc))
    for s in range(nc):
        _put_spring(fill, nbr, rst, np.uint64(cross[s, 0]), np.uint64(cross[s, 1]), cross_rest[s])
    return ptr, nbr, rst


@leaf
def _put_spring(fill, nbr, rst, i, j, r):
    """Store spring ``(i, j)`` (unsigned) of rest length ``r`` at both endpoints' next CSR slots."""
    slot = np.uint64(fill[i])
    nbr[slot] = j
    rst[slot] = r
    fill[i] += 1
    slot = np.uint64(fill[j])
    nbr[slot] = i
    rst[slot] = r
    fill[j] += 1


@leaf
def _phi(a):
    """Barrier profile: ``a - 1 - log a`` below 1, 0 above, inf at or below 0."""
    if a >= 1.0:
        return 0.0
    if a <= 0.0:
        return np.inf
    return a - 1.0 - math.log(a)


@parallel
def face_terms(x, faces, a_ref, eps, shape, w_shape, w_rigidity, w_area, w_limit, limit_u, area_eps, areas, below,
               coef, e_face):
    """One pass over the faces: signed areas, per block of :data:`BLOCK` faces how many are
    not above ``eps`` of their reference area (the faces :func:`face_barrier` acts on; NaN
    areas count), and the per-face terms' energy and the coefficients with which
    :func:`energy_gradient` gathers their gradient at each corner.

    A face's terms depend on its flat area ``A_f``, its map's Dirichlet energy ``D`` and
    ``M = D / A_f`` (:func:`shape_coefficients`); their gradient at a corner ``i`` is
    ``P dD_i + Q dA_i``, ``dD_i`` and ``dA_i`` the gradients of ``D`` and ``A_f`` at ``i``,
    and the Hessian diagonal bound at ``i`` takes ``R (cot_j + cot_l) + S |dA_i|^2``. So the
    divisions, square roots and logarithm of a face are taken once, not once per corner.

    Parameters
    ----------
    x : (n, 2) float64
    faces : (m, 3) int32 or int64
    a_ref : (m,) float64
    eps : float
    shape : (m, 5) or (0, 5) float64
        :func:`shape_coefficients`; empty: no per-face terms (``coef`` and ``e_face`` untouched).
    w_shape, w_rigidity, w_area, w_limit : float
        The per-face terms' weights per unit rest area: shape, rigidity, area and anisotropy
        limit (:class:`potflat.relax.energy.FaceTermWeights`).
    limit_u : float
        The anisotropy limit as ``u(limit) = sqrt(limit) - 1 / sqrt(limit)`` (inf: none).
    area_eps : float
        The area term's smoothing at zero log area ratio.
    areas : (m,) float64
        Output: signed areas.
    below : (ceil(m / BLOCK),) int64
        Output: counts per block.
    coef : (m, 4) or (0, 4) float64
        Output: ``P, Q, R, S`` per face (zeros for a face with non-positive flat area).
    e_face : (ceil(m / BLOCK),) float64
        Output: the per-face terms' energy per block (infinite when a face has non-positive
        flat area).
    """
    m = faces.shape[0]
    shaped = shape.shape[0] > 0
    s_shape = 2.0 * w_shape
    s_rigid = w_rigidity
    s_area = w_area
    s_limit = w_limit
    u_lim = limit_u
    a_eps = area_eps
    for b in prange(below.shape[0]):
        count = 0
        eb = 0.0
        for t in range(np.uint64(b * BLOCK), np.uint64(min(m, (b + 1) * BLOCK))):
            a0 = np.uint32(faces[t, 0])
            a1 = np.uint32(faces[t, 1])
            a2 = np.uint32(faces[t, 2])
            area = 0.5 * ((x[a1, 0] - x[a0, 0]) * (x[a2, 1] - x[a0, 1])
                          - (x[a1, 1] - x[a0, 1]) * (x[a2, 0] - x[a0, 0]))
            areas[t] = area
            if not area >= eps * a_ref[t]:
                count += 1
            if not shaped:
                continue
            if area <= 0.0:
                eb = np.inf
                for c in range(4):
                    coef[t, c] = 0.0
                continue
            # edges opposite corners 0, 1, 2 and the map's Dirichlet energy
            e0x = x[a2, 0] - x[a1, 0]
            e0y = x[a2, 1] - x[a1, 1]
            e1x = x[a0, 0] - x[a2, 0]
            e1y = x[a0, 1] - x[a2, 1]
            e2x = x[a1, 0] - x[a0, 0]
            e2y = x[a1, 1] - x[a0, 1]
            dir_ = 0.25 * (shape[t, 0] * (e0x * e0x + e0y * e0y) + shape[t, 1] * (e1x * e1x + e1y * e1y)
                           + shape[t, 2] * (e2x * e2x + e2y * e2y))
            wa = shape[t, 3]
            # shape term 2 s wa (M - 1) and limit b wa max(0, u - u_lim)^2, u = sqrt(2 (M - 1)):
            # dE/dM times dM = (dD - M dA) / A
            inv = 1.0 / area
            ratio = dir_ * inv
            cm = s_shape * wa
            energy = cm * (ratio - 1.0)
            if s_limit > 0.0 and ratio > 1.0:
                u = math.sqrt(2.0 * (ratio - 1.0))
                over = u - u_lim
                if over > 0.0:
                    energy += s_limit * wa * over * over
                    cm += 2.0 * s_limit * wa * over / u
            wi = cm * inv
            cp = wi
            cq = -wi * ratio
            cr = 0.5 * wi
            cs = 0.0
            if s_rigid > 0.0 or s_area > 0.0:
                ia = 1.0 / shape[t, 4]
            if s_rigid > 0.0:
                # ARAP energy r wa ((s1 - 1)^2 + (s2 - 1)^2), s1 + s2 = q = sqrt(2 (D + A) / A_rest)
                rho = s_rigid * wa
                ra = rho * ia
                q = math.sqrt(2.0 * (dir_ + area) * ia)
                iq = 1.0 / q
                energy += rho * (2.0 * dir_ * ia - 2.0 * q + 2.0)
                cp += 2.0 * ra * (1.0 - iq)
                cq -= 2.0 * ra * iq
                cr += ra
            if s_area > 0.0:
                # a wa (sqrt(L^2 + eps^2) - eps), L = log(A / A_rest): about a wa |L|; the
                # diagonal takes its majorising curvature a wa / sqrt(L^2 + eps^2)
                lg = math.log(area * ia)
                root = math.sqrt(lg * lg + a_eps * a_eps)
                ca = s_area * wa / root
                energy += s_area * wa * (root - a_eps)
                cq += ca * lg * inv
                cs = ca * inv * inv
            coef[t, 0] = cp
            coef[t, 1] = cq
            coef[t, 2] = cr
            coef[t, 3] = cs
            eb += energy
        below[b] = count
        if shaped:
            e_face[b] = eb


@leaf
def _angle_barrier_slope(theta, sb, gap):
    """Boundary angle barrier at angle sum ``theta``: ``dB / dTheta`` and the factor of its
    Hessian diagonal bound (both 0 where the barrier is off, i.e. the gap is at least ``gap``)."""
    a = (2.0 * math.pi - theta) / gap
    if not 0.0 < a < 1.0:
        return 0.0, 0.0
    return -sb * (1.0 - 1.0 / a) / gap, sb / (a * a * gap * gap)


@leaf
def _boundary_slope(theta, target, sb, so, gap):
    """A guarded boundary vertex's angle terms at angle sum ``theta``: ``dE / dTheta`` and the
    factor of their Hessian diagonal bound, of the barrier (weight ``sb``) and of the outline
    term ``so (theta - target)^2`` (``so = 0``: none)."""
    cb, h = _angle_barrier_slope(theta, sb, gap)
    if so > 0.0:
        cb += 2.0 * so * (theta - target)
        h += 2.0 * so
    return cb, h


@parallel
def energy_gradient(x, ptr, nbr, rst, k, relative, r_floor, weight, vf_ptr, vf_tri, faces, shape, coef,
                    bprev, bnext, bguard, theta, target, mu_b, mu_o, gap, grad, e_spring, e_barrier, diag):
    """Spring, boundary angle barrier and outline energy per vertex, and the gradient of these
    and of the per-face terms, gathered per vertex.

    The face barrier is added afterwards by :func:`face_barrier` (it acts on few faces).
    The per-face terms' gradient is gathered from the coefficients :func:`face_terms`
    computed for each face at ``x``; their energy is :func:`face_terms`' too.

    Parameters
    ----------
    x : (n, 2) float64
        Positions (normalised units).
    ptr, nbr, rst : CSR from :func:`build_csr`
    k : float
        Stiffness.
    relative : bool
        Weight each spring by ``1 / max(r, r_floor)^2`` (relative length error).
    r_floor : float
    weight : (n,) or (0,) float64
        Importance weight of each vertex (:mod:`potflat.importance`): a spring's coefficient
        is multiplied by the mean of its endpoints' weights, a guarded vertex's angle barrier
        by its own. Empty: every weight is 1.
    vf_ptr, vf_tri : CSR from :func:`vertex_faces`
    faces : (m, 3) int32 or int64
    shape : (m, 5) or (0, 5) float64
        Each face's rest angles and weight (:func:`shape_coefficients`). Empty: no per-face
        terms.
    coef : (m, 4) or (0, 4) float64
        The per-face terms' coefficients at ``x`` (:func:`face_terms`).
    bprev, bnext : (n,) int32
        Each vertex's unique boundary predecessor and successor (-1: none or not unique).
    bguard : (n,) bool
        Boundary vertices whose angle sum is guarded.
    theta : (n,) float64
        Flat interior angle sums of the guarded vertices at ``x`` (:func:`boundary_angle_sums`).
    target : (n,) or (0,) float64
        The outline term's angle sum of each guarded vertex (its rest angle sum); empty
        with ``mu_o = 0``.
    mu_b, mu_o, gap : float
        Angle barrier weight (times ``k`` and the vertex's importance weight), outline term
        weight (times ``k``: ``mu_o k (Theta - target)^2`` per guarded vertex, whatever its
        importance) and the barrier's activation (radians below ``2 pi``); a weight of 0
        disables its term.
    grad : (n, 2) float64
        Output: dE/dx.
    e_spring, e_barrier : (n,) float64
        Output: each vertex's share of the spring energy and its angle barrier energy.
    diag : (n,) float64
        Output: a bound of the Hessian's diagonal per vertex (sum of spring coefficients plus
        the barrier's curvature), the Jacobi preconditioner of the fine-level solve.
    """
    n = x.shape[0]
    weighted = weight.shape[0] > 0
    shaped = shape.shape[0] > 0
    for i in prange(n):
        gx = 0.0
        gy = 0.0
        es = 0.0
        hd = 0.0
        xi = x[i, 0]
        yi = x[i, 1]
        for p in range(np.uint64(ptr[i]), np.uint64(ptr[i + 1])):
            j = np.uint32(nbr[p])  # (unsigned: no negative-index wraparound at each read)
            dx = xi - x[j, 0]
            dy = yi - x[j, 1]
            ln = math.sqrt(dx * dx + dy * dy)
            r = rst[p]
            c = k
            if relative:
                rr = max(r, r_floor)
                c = k / (rr * rr)
            if weighted:
                c *= 0.5 * (weight[i] + weight[j])
            hd += c
            dl = ln - r
            es += 0.25 * c * dl * dl
            if ln > 0.0:
                f = c * dl / ln
                gx += f * dx
                gy += f * dy
        if shaped:
            for q in range(np.uint64(vf_ptr[i]), np.uint64(vf_ptr[i + 1])):
                t = np.uint32(vf_tri[q])
                ci = 0
                if faces[t, 1] == i:
                    ci = 1
                elif faces[t, 2] == i:
                    ci = 2
                c_j = np.uint32((ci + 1) % 3)
                c_l = np.uint32((ci + 2) % 3)
                j = np.uint32(faces[t, c_j])
                l = np.uint32(faces[t, c_l])
                # cotangents of the rest angles at j and l
                ct_j = shape[t, c_j]
                ct_l = shape[t, c_l]
                # the gradients at i of the map's Dirichlet energy and of the flat area
                dgx = 0.5 * (ct_l * (xi - x[j, 0]) + ct_j * (xi - x[l, 0]))
                dgy = 0.5 * (ct_l * (yi - x[j, 1]) + ct_j * (yi - x[l, 1]))
                agx = 0.5 * (x[j, 1] - x[l, 1])
                agy = 0.5 * (x[l, 0] - x[j, 0])
                gx += coef[t, 0] * dgx + coef[t, 1] * agx
                gy += coef[t, 0] * dgy + coef[t, 1] * agy
                hd += coef[t, 2] * (ct_l + ct_j) + coef[t, 3] * (agx * agx + agy * agy)
        eb = 0.0
        if (mu_b > 0.0 or mu_o > 0.0) and (bprev[i] >= 0 or bnext[i] >= 0):
            sb = mu_b * k  # times the guarded vertex's importance weight
            so = mu_o * k
            # own angle sum: depends on x_i through u = x_nxt - x_i and w = x_prv - x_i
            if bguard[i]:
                a = (2.0 * math.pi - theta[i]) / gap
                sw = sb * weight[i] if weighted else sb
                to = target[i] if so > 0.0 else 0.0
                if sw > 0.0 and a <= 0.0:
                    eb = np.inf
                elif (sw > 0.0 and a < 1.0) or so > 0.0:
                    if sw > 0.0 and a < 1.0:
                        eb += sw * (a - 1.0 - math.log(a))
                    eb += so * (theta[i] - to) * (theta[i] - to)
                    cb, h = _boundary_slope(theta[i], to, sw, so, gap)
                    ux = x[bnext[i], 0] - xi
                    uy = x[bnext[i], 1] - yi
                    wx = x[bprev[i], 0] - xi
                    wy = x[bprev[i], 1] - yi
                    uu = ux * ux + uy * uy
                    ww = wx * wx + wy * wy
                    tx = -(uy / uu - wy / ww)
                    ty = -(-ux / uu + wx / ww)
                    gx += cb * tx
                    gy += cb * ty
                    hd += h * (tx * tx + ty * ty)
            # as the successor of its predecessor p: Theta_p grows with arg(x_i - x_p) decreasing
            pv = bprev[i]
            if pv >= 0 and bguard[pv]:
                cb, h = _boundary_slope(theta[pv], target[pv] if so > 0.0 else 0.0,
                                        sb * weight[pv] if weighted else sb, so, gap)
                if h > 0.0:
                    ux = xi - x[pv, 0]
                    uy = yi - x[pv, 1]
                    uu = ux * ux + uy * uy
                    tx = uy / uu
                    ty = -ux / uu
                    gx += cb * tx
                    gy += cb * ty
                    hd += h * (tx * tx + ty * ty)
            # as the predecessor of its successor q
            qv = bnext[i]
            if qv >= 0 and bguard[qv]:
                cb, h = _boundary_slope(theta[qv], target[qv] if so > 0.0 else 0.0,
                                        sb * weight[qv] if weighted else sb, so, gap)
                if h > 0.0:
                    wx = xi - x[qv, 0]
                    wy = yi - x[qv, 1]
                    ww = wx * wx + wy * wy
                    tx = -wy / ww
                    ty = wx / ww
                    gx += cb * tx
                    gy += cb * ty
                    hd += h * (tx * tx + ty * ty)
        diag[i] = hd
        grad[i, 0] = gx
        grad[i, 1] = gy
        e_spring[i] = es
        e_barrier[i] = eb


@parallel
def shape_coefficients(V, faces, weight, inv_mean_area, area_floor, out):
    """Rest angles and weights of the per-face terms of :func:`energy_gradient`.

    For a face with rest (3D) triangle of area ``A`` and the linear map ``J`` from it to
    the flat triangle (singular values ``sigma_1 >= sigma_2 > 0``, flat area ``A_flat``),
    with ``w`` its importance weight and every weight per mean rest area:

    * shape: ``s w A (sigma_1 / sigma_2 + sigma_2 / sigma_1 - 2)`` (the MIPS energy): zero
      for a similarity, so it charges shear but neither scale nor rotation, about
      ``s w A S^2`` for a small ``S = log(sigma_1 / sigma_2)`` (the anisotropy the maps
      show) and infinite for a collapsed triangle. With ``M = |J|^2 / (2 det J) = D /
      A_flat``, ``D = 1/4 sum_edges cot(opposite angle) |x_a - x_b|^2`` the map's Dirichlet
      energy, it is ``2 s w A (M - 1)``;
    * rigidity: the as-rigid-as-possible energy ``r w A ((sigma_1 - 1)^2 + (sigma_2 -
      1)^2)``: it charges shear and scale alike (about ``2 r w A (a^2 + s^2)`` for an area
      change ``a`` and a shear ``s``), with ``sigma_1 + sigma_2 = sqrt(2 (D + A_flat) / A)``;
    * area: ``a w A (sqrt(L^2 + eps^2) - eps)``, ``L = log(A_flat / A)``: the area change
      in proportion (not squared), so area distortion gathers where the shape needs it
      rather than spreading over the surface;
    * anisotropy limit: ``b w A max(0, u - u_lim)^2``, ``u = sqrt(sigma_1 / sigma_2) -
      sqrt(sigma_2 / sigma_1) = sqrt(2 (M - 1))`` (``log(sigma_1 / sigma_2)`` to within 1% up
      to an anisotropy of 1.6, and a square root where the logarithm needs more): nothing up
      to the limit ``u_lim``, a steep price above it.

    Parameters
    ----------
    V : (n, 3) float64
        Rest positions.
    faces : (m, 3) int32 or int64
    weight : (n,) or (0,) float64
        Importance weight per vertex (a face takes its corners' mean); empty: 1.
    inv_mean_area : float
        One over the mean rest area.
    area_floor : float
        Faces with a smaller rest area (degenerate, their angles meaningless) get no terms.
    out : (m, 5) float64
        Output: the cotangents of the rest angles at corners 0, 1, 2, ``w A`` over the mean
        rest area, and ``A``.
    """
    for t in prange(faces.shape[0]):
        a0 = faces[t, 0]
        a1 = faces[t, 1]
        a2 = faces[t, 2]
        e1x = V[a1, 0] - V[a0, 0]
        e1y = V[a1, 1] - V[a0, 1]
        e1z = V[a1, 2] - V[a0, 2]
        e2x = V[a2, 0] - V[a0, 0]
        e2y = V[a2, 1] - V[a0, 1]
        e2z = V[a2, 2] - V[a0, 2]
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        twice = math.sqrt(nx * nx + ny * ny + nz * nz)
        if 0.5 * twice <= area_floor:
            for c in range(4):
                out[t, c] = 0.0
            out[t, 4] = 1.0
            continue
        w_imp = 1.0
        if weight.shape[0] > 0:
            w_imp = (weight[a0] + weight[a1] + weight[a2]) / 3.0
        e3x = V[a2, 0] - V[a1, 0]
        e3y = V[a2, 1] - V[a1, 1]
        e3z = V[a2, 2] - V[a1, 2]
        # cot of the angle at a corner = (dot of its two edges) / (twice the area)
        out[t, 0] = (e1x * e2x + e1y * e2y + e1z * e2z) / twice
        out[t, 1] = (-e1x * e3x - e1y * e3y - e1z * e3z) / twice
        out[t, 2] = (e2x * e3x + e2y * e3y + e2z * e3z) / twice
        out[t, 3] = w_imp * 0.5 * twice * inv_mean_area
        out[t, 4] = 0.5 * twice


@leaf
def face_barrier(x, faces, areas, a_ref, mu, k, eps, relative, weight, grad, diag, below):
    """Add the face barrier to ``grad`` and ``diag``; return its energy.

    Serial over the faces in order (deterministic); only faces squeezed below ``eps`` of
    their reference area contribute, usually a small fraction, so only the blocks that
    hold one (``below``, from :func:`face_terms`) are visited, instead of a gather
    over every vertex's incident faces.

    Parameters
    ----------
    x : (n, 2) float64
    faces : (m, 3) int32 or int64
    areas : (m,) float64
        Signed face areas at ``x`` (:func:`face_areas`).
    a_ref : (m,) float64
        Reference (rest) area of each face, floored.
    mu, k, eps : float
        Barrier weight, stiffness and activation threshold (fraction of ``a_ref``).
    relative : bool
        Weight each face's barrier by ``mu k`` (relative spring weighting: the springs'
        energy is dimensionless) instead of ``mu k a_ref`` (uniform: energy ~ length^2).
    weight : (n,) or (0,) float64
        Importance weight of each vertex: a face's barrier is multiplied by the mean of its
        corners' weights, like its springs. Empty: every weight is 1.
    grad, diag : (n, 2), (n,) float64
        Updated in place: gradient and Hessian diagonal bound.
    below : (ceil(m / BLOCK),) int64
        Faces not above ``eps a_ref`` per block of :data:`BLOCK` (:func:`face_terms`):
        blocks with none are skipped.

    Returns
    -------
    float
        ``sum mu k w phi(A / (eps a_ref))`` (``w = 1`` or ``a_ref``); inf when a face has
        non-positive area.
    """
    total = 0.0
    m = faces.shape[0]
    for b in range(below.shape[0]):
        if below[b] == 0:
            continue
        for t in range(b * BLOCK, min(m, (b + 1) * BLOCK)):
            area = areas[t]
            th = eps * a_ref[t]
            if area >= th:
                continue
            if area <= 0.0:
                total = np.inf
                continue
            a = area / th
            scale = mu * k if relative else mu * k * a_ref[t]
            if weight.shape[0] > 0:
                scale *= (weight[faces[t, 0]] + weight[faces[t, 1]] + weight[faces[t, 2]]) / 3.0
            total += scale * (a - 1.0 - math.log(a))
            dphi = scale * (1.0 - 1.0 / a) / th
            h = scale / (area * area)
            for c in range(3):
                i = faces[t, c]
                j1 = faces[t, (c + 1) % 3]
                j2 = faces[t, (c + 2) % 3]
                ax = 0.5 * (x[j1, 1] - x[j2, 1])
                ay = 0.5 * (x[j2, 0] - x[j1, 0])
                grad[i, 0] += dphi * ax
                grad[i, 1] += dphi * ay
                diag[i] += h * (ax * ax + ay * ay)
    return total


@parallel
def boundary_angle_sums(x, verts, vf_ptr, vf_tri, faces, out):
    """Flat interior angle sum of each listed boundary vertex (sum of its faces' angles).

    Parameters
    ----------
    x : (n, 2) float64
    verts : (b,) int64
        Distinct vertices.
    vf_ptr, vf_tri : CSR from :func:`vertex_faces`
    faces : (m, 3) int32 or int64
    out : (n,) float64
        Output at the rows ``verts`` (other rows untouched). Each face angle is
        ``atan2(cross, dot)`` of its two edges at the vertex, in ``(-pi, pi]``.
    """
    for s in prange(verts.shape[0]):
        i = verts[s]
        acc = 0.0
        for p in range(vf_ptr[i], vf_ptr[i + 1]):
            t = vf_tri[p]
            a0 = faces[t, 0]
            a1 = faces[t, 1]
            a2 = faces[t, 2]
            if a0 == i:
                j1 = a1
                j2 = a2
            elif a1 == i:
                j1 = a2
                j2 = a0
            else:
                j1 = a0
                j2 = a1
            ux = x[j1, 0] - x[i, 0]
            uy = x[j1, 1] - x[i, 1]
            wx = x[j2, 0] - x[i, 0]
            wy = x[j2, 1] - x[i, 1]
            acc += math.atan2(ux * wy - uy * wx, ux * wx + uy * wy)
        out[i] = acc


