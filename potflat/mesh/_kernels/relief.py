"""The relief of a surface against itself smoothed: local quadric fits over a grid of the flat
coordinates, their blend at each vertex, and volume integral invariants of the height field.

Every kernel gathers: a cell, node or vertex reads its neighbours (vertices sorted by grid
cell: ``order``, ``cell_ptr``; cells around a node) and writes only its own slot, so results
do not depend on the thread count. Arrays in, arrays out, no I/O.
"""
from __future__ import annotations

import numpy as np

from potflat._jit import leaf, parallel, prange

#: Terms of a quadric in the offsets ``x, y`` (in units of sigma): 1, x, y, x^2, x y, y^2.
TERMS = 6


@leaf
def _solve_spd(A, B):
    """Solve ``A X = B`` for a symmetric positive definite ``A`` (t, t) by Cholesky, in place:
    ``B`` (t, d) becomes ``X``. Returns False (``B`` undefined) when ``A`` is not positive
    definite to working precision."""
    t = A.shape[0]
    for j in range(t):
        s = A[j, j]
        for k in range(j):
            s -= A[j, k] * A[j, k]
        if not s > 1e-12 * A[0, 0]:
            return False
        A[j, j] = np.sqrt(s)
        for i in range(j + 1, t):
            s = A[i, j]
            for k in range(j):
                s -= A[i, k] * A[j, k]
            A[i, j] = s / A[j, j]
    for c in range(B.shape[1]):
        for i in range(t):
            s = B[i, c]
            for k in range(i):
                s -= A[i, k] * B[k, c]
            B[i, c] = s / A[i, i]
        for i in range(t - 1, -1, -1):
            s = B[i, c]
            for k in range(i + 1, t):
                s -= A[k, i] * B[k, c]
            B[i, c] = s / A[i, i]
    return True


#: Monomials ``x^p y^q`` up to degree 4, degree by degree: moment ``idx(p, q) = d (d + 1) / 2 + q``
#: with ``d = p + q``; the quadric's terms are the first :data:`TERMS`.
MOMENTS = 15


@leaf
def _idx(p, q):
    d = p + q
    return d * (d + 1) // 2 + q


@parallel
def cell_moments(uv, P, weight, order, cell_ptr, ox, oy, cell, nx, sigma, M, N):
    """Each grid cell's weighted moments of its vertices' offsets from the cell's centre.

    Parameters
    ----------
    uv : (n, 2) float64
    P : (n, d) float64
        The values fitted (3D positions, or a scalar field as one column).
    weight : (n,) float64
    order, cell_ptr
        Vertices sorted by cell: cell ``k`` (``kx = k % nx``, ``ky = k // nx``) holds
        ``order[cell_ptr[k]:cell_ptr[k + 1]]``.
    ox, oy, cell : float
        Grid origin and cell side (``uv`` units).
    nx : int
    sigma : float
        Unit of the offsets ``x, y``.
    M : (cells, 15) float64
        Output: ``sum w x^p y^q`` (:data:`MOMENTS`, up to degree 4).
    N : (cells, 6, d) float64
        Output: ``sum w x^p y^q P`` up to degree 2.
    """
    d = P.shape[1]
    for k in prange(M.shape[0]):
        for a in range(MOMENTS):
            M[k, a] = 0.0
        for a in range(TERMS):
            for c in range(d):
                N[k, a, c] = 0.0
        cx = ox + (k % nx + 0.5) * cell
        cy = oy + (k // nx + 0.5) * cell
        for t in range(np.uint64(cell_ptr[k]), np.uint64(cell_ptr[k + 1])):
            i = np.uint64(order[t])
            x = (uv[i, 0] - cx) / sigma
            y = (uv[i, 1] - cy) / sigma
            w = weight[i]
            xp = 1.0
            for p in range(5):
                v = w * xp
                for q in range(5 - p):
                    j = _idx(p, q)
                    M[k, j] += v
                    if j < TERMS:
                        for c in range(d):
                            N[k, j, c] += v * P[i, c]
                    v *= y
                xp *= x


@leaf
def _shift_table(reach, h):
    """The binomial shift of the moments about a cell's centre to a node ``(dx, dy)`` cells
    away, with that cell's Gaussian weight, for every offset within ``reach``: ``sum_w (x +
    dx h)^a (y + dy h)^b = sum over (p, q) of coef * M[idx(p, q)]``.

    Returns
    -------
    target, source : (70,) int64
        The shifted moment ``idx(a, b)`` each term adds to and the moment ``idx(p, q)`` it
        reads (``p <= a``, ``q <= b``, ``a + b <= 4``); the first 15 terms have ``a + b <= 2``
        (the quadric's own moments, which the values' sums need).
    coef : ((2 reach + 1)^2, 70) float64
        Per offset ``(dy + reach) (2 reach + 1) + dx + reach``: the terms' coefficients, 0 beyond
        ``reach`` cells of the node.
    """
    binom = np.array([[1.0, 0.0, 0.0, 0.0, 0.0], [1.0, 1.0, 0.0, 0.0, 0.0], [1.0, 2.0, 1.0, 0.0, 0.0],
                      [1.0, 3.0, 3.0, 1.0, 0.0], [1.0, 4.0, 6.0, 4.0, 1.0]])
    target = np.empty(70, np.int64)
    source = np.empty(70, np.int64)
    exps = np.empty((70, 4), np.int64)  # a - p, b - q and the binomials' rows and columns
    n = 0
    for low in range(2):  # the quadric's moments first
        for a in range(5):
            for b in range(5 - a):
                if (a + b <= 2) != (low == 0):
                    continue
                for p in range(a + 1):
                    for q in range(b + 1):
                        target[n] = _idx(a, b)
                        source[n] = _idx(p, q)
                        exps[n, 0] = a
                        exps[n, 1] = p
                        exps[n, 2] = b
                        exps[n, 3] = q
                        n += 1
    side = 2 * reach + 1
    coef = np.zeros((side * side, 70))
    for oy in range(-reach, reach + 1):
        for ox in range(-reach, reach + 1):
            if ox * ox + oy * oy > reach * reach:
                continue
            dx = ox * h
            dy = oy * h
            g = np.exp(-0.5 * (dx * dx + dy * dy))
            row = (oy + reach) * side + ox + reach
            for t in range(70):
                a, p, b, q = exps[t, 0], exps[t, 1], exps[t, 2], exps[t, 3]
                coef[row, t] = g * binom[a, p] * binom[b, q] * dx ** (a - p) * dy ** (b - q)
    return target, source, coef


@parallel
def fit_quadrics(M, N, nx, ny, cell, sigma, step, reach, need, ridge, coef, ok):
    """Weighted least-squares quadric ``P(x, y)`` (each column of ``P``) around every needed node.

    Node ``(jx, jy)`` sits at the centre of cell ``(step jx, step jy)``; it fits ``P = sum_t
    c_t phi_t(x, y)``, ``phi = (1, x, y, x^2, x y, y^2)`` in the offsets from it in units of
    ``sigma``, to the vertices of the cells within ``reach`` cells whose centres lie within
    ``reach * cell`` of it, each vertex weighted by its weight times ``exp(-d^2 / 2)``, ``d``
    the distance of its cell's centre from the node (in ``sigma``). The sums over a cell's
    vertices come from its moments about its centre (:func:`cell_moments`), shifted to the
    node by the binomial theorem (:func:`_shift_table`): the monomials are exact, only the
    Gaussian is taken per cell, so the fit reproduces any quadric exactly. The quadratic terms
    are held towards zero by ``ridge`` times the total weight (a plane where the data cannot
    fix a quadric).

    Parameters
    ----------
    M, N : the moments of :func:`cell_moments` over a grid of ``nx`` by ``ny`` cells
    cell, sigma : float
    step : int
        Cells between nodes; nodes ``ceil(nx / step)`` by ``ceil(ny / step)``.
    reach : int
    need : (nodes,) bool
        Nodes to fit (node ``j``: ``jx = j % nodes_x``).
    ridge : float
    coef : (nodes, 6, d) float64
        Output: the quadric's coefficients (rows by term, columns those of ``P``).
    ok : (nodes,) bool
        Output: whether the node has a fit.
    """
    mx = (nx + step - 1) // step
    d = N.shape[2]
    side = 2 * reach + 1
    target, source, shift = _shift_table(reach, cell / sigma)
    for j in prange(need.shape[0]):
        ok[j] = False
        if not need[j]:
            continue
        cx = (j % mx) * step
        cy = (j // mx) * step
        S = np.zeros(MOMENTS)  # sum over the cells of the weighted moments about the node
        T = np.zeros((TERMS, d))
        for ky in range(max(cy - reach, 0), min(cy + reach + 1, ny)):
            for kx in range(max(cx - reach, 0), min(cx + reach + 1, nx)):
                k = np.uint64(ky * nx + kx)
                if M[k, 0] == 0.0:
                    continue
                row = np.uint64((ky - cy + reach) * side + kx - cx + reach)
                if shift[row, 0] == 0.0:  # beyond reach
                    continue
                for t in range(70):
                    w = shift[row, t]
                    S[target[t]] += w * M[k, source[t]]
                    if t < 15:
                        for c in range(d):
                            T[target[t], c] += w * N[k, source[t], c]
        if not S[0] > 0.0:
            continue
        A = np.empty((TERMS, TERMS))
        for t1 in range(TERMS):
            d1 = 0 if t1 == 0 else (1 if t1 < 3 else 2)
            q1 = t1 - d1 * (d1 + 1) // 2
            for t2 in range(TERMS):
                d2 = 0 if t2 == 0 else (1 if t2 < 3 else 2)
                q2 = t2 - d2 * (d2 + 1) // 2
                A[t1, t2] = S[_idx(d1 - q1 + d2 - q2, q1 + q2)]
        for a in range(1, TERMS):
            A[a, a] += (ridge if a >= 3 else ridge * 1e-3) * A[0, 0]
        if _solve_spd(A, T):
            for a in range(TERMS):
                for c in range(d):
                    coef[j, a, c] = T[a, c]
            ok[j] = True


@leaf
def _corner(u, v, ox, oy, spacing, nx, ny, sigma, ok, k):
    """Corner ``k`` (0-3) of the node square around the point ``(u, v)``: the node's index
    (-1 when it is off the grid, has no fit or weighs nothing), its bilinear weight and the
    point's offset from it in units of ``sigma``."""
    fx = (u - ox) / spacing
    fy = (v - oy) / spacing
    dx = k & 1
    dy = k >> 1
    jx = int(np.floor(fx)) + dx
    jy = int(np.floor(fy)) + dy
    tx = fx - np.floor(fx)
    ty = fy - np.floor(fy)
    beta = (tx if dx else 1.0 - tx) * (ty if dy else 1.0 - ty)
    if jx < 0 or jy < 0 or jx >= nx or jy >= ny or beta <= 0.0 or not ok[np.uint64(jy * nx + jx)]:
        return -1, 0.0, 0.0, 0.0
    return jy * nx + jx, beta, (u - (ox + jx * spacing)) / sigma, (v - (oy + jy * spacing)) / sigma


@parallel
def blend_quadrics(uv, P, normal, ox, oy, spacing, nx, ny, sigma, coef, ok, height, frame):
    """The smoothed surface at every vertex: the fits of its four nearest nodes, evaluated at
    the vertex and blended bilinearly; the vertex's height above it and its normal in its frame.

    Parameters
    ----------
    uv : (n, 2) float64
    P : (n, 3) float64
    normal : (n, 3) float64
        The scan's vertex normals (any length; zero: none).
    ox, oy, spacing : float
        The first node's position and the nodes' spacing (``uv`` units).
    nx, ny : int
        Nodes along ``u`` and ``v``.
    sigma, coef, ok
        The fits of :func:`fit_quadrics`.
    height : (n,) float64
        Output: ``(P - S) . n_s``, with ``S`` the smoothed surface at the vertex and ``n_s``
        its unit normal ``S_u x S_v`` (outward when the flat layout is seen from outside); NaN
        where no node near the vertex has a fit.
    frame : (n, 3) float64
        Output: the unit vertex normal's components along ``S_u`` (image right), the unit
        vector completing the frame (image up) and ``n_s``; (0, 0, 1) without a normal.
    """
    n = uv.shape[0]
    for i in prange(n):
        s0 = s1 = s2 = 0.0
        u0 = u1 = u2 = 0.0
        v0 = v1 = v2 = 0.0
        total = 0.0
        for k in range(4):
            j, beta, x, y = _corner(uv[i, 0], uv[i, 1], ox, oy, spacing, nx, ny, sigma, ok, k)
            if j < 0:
                continue
            j = np.uint64(j)
            total += beta
            for c in range(3):
                val = (coef[j, 0, c] + coef[j, 1, c] * x + coef[j, 2, c] * y + coef[j, 3, c] * x * x
                       + coef[j, 4, c] * x * y + coef[j, 5, c] * y * y)
                du = (coef[j, 1, c] + 2.0 * coef[j, 3, c] * x + coef[j, 4, c] * y) / sigma
                dv = (coef[j, 2, c] + coef[j, 4, c] * x + 2.0 * coef[j, 5, c] * y) / sigma
                if c == 0:
                    s0 += beta * val
                    u0 += beta * du
                    v0 += beta * dv
                elif c == 1:
                    s1 += beta * val
                    u1 += beta * du
                    v1 += beta * dv
                else:
                    s2 += beta * val
                    u2 += beta * du
                    v2 += beta * dv
        frame[i, 0] = 0.0
        frame[i, 1] = 0.0
        frame[i, 2] = 1.0
        if total <= 0.0:
            height[i] = np.nan
            continue
        s0 /= total
        s1 /= total
        s2 /= total
        # n_s = S_u x S_v (the blend's weights cancel in the direction)
        n0 = u1 * v2 - u2 * v1
        n1 = u2 * v0 - u0 * v2
        n2 = u0 * v1 - u1 * v0
        ln = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        lu = np.sqrt(u0 * u0 + u1 * u1 + u2 * u2)
        if not (ln > 0.0 and lu > 0.0):
            height[i] = np.nan
            continue
        n0 /= ln
        n1 /= ln
        n2 /= ln
        u0 /= lu
        u1 /= lu
        u2 /= lu
        # t_v = n_s x t_u
        w0 = n1 * u2 - n2 * u1
        w1 = n2 * u0 - n0 * u2
        w2 = n0 * u1 - n1 * u0
        height[i] = (P[i, 0] - s0) * n0 + (P[i, 1] - s1) * n1 + (P[i, 2] - s2) * n2
        a = normal[i, 0]
        b = normal[i, 1]
        c = normal[i, 2]
        lm = np.sqrt(a * a + b * b + c * c)
        if lm > 0.0:
            frame[i, 0] = (a * u0 + b * u1 + c * u2) / lm
            frame[i, 1] = (a * w0 + b * w1 + c * w2) / lm
            frame[i, 2] = (a * n0 + b * n1 + c * n2) / lm


@parallel
def blend_scalar(uv, ox, oy, spacing, nx, ny, sigma, coef, ok, out):
    """A scalar field's smoothed value at every vertex: the one-column fits of its four nearest
    nodes (:func:`fit_quadrics`), evaluated at the vertex and blended bilinearly, as
    :func:`blend_quadrics` blends the surface's. ``out`` (n,) float64: NaN where no node near
    the vertex has a fit."""
    n = uv.shape[0]
    for i in prange(n):
        acc = 0.0
        total = 0.0
        for k in range(4):
            j, beta, x, y = _corner(uv[i, 0], uv[i, 1], ox, oy, spacing, nx, ny, sigma, ok, k)
            if j < 0:
                continue
            j = np.uint64(j)
            acc += beta * (coef[j, 0, 0] + coef[j, 1, 0] * x + coef[j, 2, 0] * y + coef[j, 3, 0] * x * x
                           + coef[j, 4, 0] * x * y + coef[j, 5, 0] * y * y)
            total += beta
        out[i] = acc / total if total > 0.0 else np.nan


@parallel
def volume_invariants(uv, height, weight, order, cell_ptr, ox, oy, cell, nx, ny, radii, out):
    """The volume integral invariant of the height field at several radii, minus its value
    for a plane, averaged over the radii.

    For radius ``r`` and a vertex ``p``: the share of the ball of radius ``r`` about ``p``
    that lies below the surface, minus one half, with the surface taken as the height field
    over the flat layout: ``sum_q w_q clamp(h_q - h_p, -a_q, a_q) / (2 sum_q w_q a_q)`` over
    the vertices ``q`` within ``r`` of ``p`` in the layout, ``a_q = sqrt(r^2 - |q - p|^2)``
    (each ``q`` stands for a column of the disc). 0 on a plane, up to +1/2 in a pit or groove
    (concave), down to -1/2 on a ridge or peak (convex).

    Parameters
    ----------
    uv : (n, 2) float64
        Flat coordinates, mm.
    height : (n,) float64
        Height above the smoothed surface, mm (NaN: left out).
    weight : (n,) float64
        Each vertex's area.
    order, cell_ptr, ox, oy, cell, nx, ny
        Vertices sorted by the cells of a grid (mm); the cell at least the largest radius.
    radii : (k,) float64
        Ball radii, mm, ascending.
    out : (n,) float64
        Output: the mean over the radii with a neighbour (NaN where the height is NaN).
    """
    n = uv.shape[0]
    nr = radii.shape[0]
    rmax2 = radii[nr - 1] * radii[nr - 1]
    for p in prange(n):
        hp = height[p]
        if np.isnan(hp):
            out[p] = np.nan
            continue
        num = np.zeros(nr)
        den = np.zeros(nr)
        px = uv[p, 0]
        py = uv[p, 1]
        cx = min(max(int((px - ox) / cell), 0), nx - 1)
        cy = min(max(int((py - oy) / cell), 0), ny - 1)
        for ky in range(max(cy - 1, 0), min(cy + 2, ny)):
            for kx in range(max(cx - 1, 0), min(cx + 2, nx)):
                k = ky * nx + kx
                for t in range(np.uint64(cell_ptr[k]), np.uint64(cell_ptr[k + 1])):
                    q = np.uint64(order[t])
                    dx = uv[q, 0] - px
                    dy = uv[q, 1] - py
                    rho2 = dx * dx + dy * dy
                    hq = height[q]
                    if rho2 >= rmax2 or np.isnan(hq):
                        continue
                    dh = hq - hp
                    for r in range(nr - 1, -1, -1):  # the balls holding q: the largest down to q's distance
                        r2 = radii[r] * radii[r]
                        if rho2 >= r2:
                            break
                        a = np.sqrt(r2 - rho2)
                        num[r] += weight[q] * min(max(dh, -a), a)
                        den[r] += weight[q] * a
        total = 0.0
        used = 0
        for r in range(nr):
            if den[r] > 0.0:
                total += num[r] / (2.0 * den[r])
                used += 1
        out[p] = total / used if used else 0.0
