"""Slow, plain numpy reference implementations of the kernels (tiny meshes only)."""
from __future__ import annotations

import itertools

import numpy as np


def springs(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Edge springs and cross springs with their rest lengths, by brute force.

    Cross springs join the two opposite vertices of every edge shared by two faces; the rest
    length is their distance after rotating one face about the shared edge into the plane
    of the other (the pair unfolded flat).

    Returns
    -------
    pairs : (s, 2) int64
        Sorted rows (edges first, then cross springs, each sorted by vertex pair).
    rest : (s,) float64
    """
    edge_faces: dict[tuple[int, int], list[int]] = {}
    for f, tri in enumerate(F):
        for a, b in ((tri[0], tri[1]), (tri[1], tri[2]), (tri[2], tri[0])):
            edge_faces.setdefault((min(a, b), max(a, b)), []).append(f)
    edges = sorted(edge_faces)
    out_pairs = [list(e) for e in edges]
    out_rest = [float(np.linalg.norm(V[a] - V[b])) for a, b in edges]
    cross = []
    for (a, b), fs in edge_faces.items():
        if len(fs) != 2:
            continue
        p = next(v for v in F[fs[0]] if v not in (a, b))
        q = next(v for v in F[fs[1]] if v not in (a, b))
        if p == q:
            continue
        cross.append((min(p, q), max(p, q), unfolded_distance(V[a], V[b], V[p], V[q])))
    cross.sort()
    out_pairs += [[p, q] for p, q, _ in cross]
    out_rest += [r for _, _, r in cross]
    return np.array(out_pairs, np.int64).reshape(-1, 2), np.array(out_rest)


def halfedge_springs(F: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edges, cross springs and boundary edges by a stable sort of all half-edges by edge
    (the relax kernel's former algorithm): ``potflat.relax._kernels.springs.halfedge_springs``
    must return exactly this for every mesh.

    Half-edge ``h = 3 f + c`` runs from ``F[f, c]`` to ``F[f, (c + 1) % 3]``. Per edge, in
    ``(i, j)`` order: one face: a boundary row ``(a, b)`` as in its face; exactly two faces:
    a cross row ``(p, q, a, b)`` from the half-edge with the smaller ``h`` (``a -> b``, ``p``
    opposite it) and the other face's opposite vertex ``q``, unless ``p == q``; three or
    more faces: only the edge.
    """
    F = np.asarray(F, np.int64).reshape(-1, 3)
    heads = np.roll(F, -1, axis=1).ravel()
    tails = F.ravel()
    keys = np.minimum(tails, heads) * n + np.maximum(tails, heads)
    order = np.argsort(keys, kind="stable")
    groups: dict[int, list[int]] = {}
    for h in order:
        groups.setdefault(int(keys[h]), []).append(int(h))
    edges, cross, boundary = [], [], []
    for key, hs in groups.items():  # in key order: dicts keep insertion order
        edges.append((key // n, key % n))
        f0, c0 = divmod(hs[0], 3)
        if len(hs) == 1:
            boundary.append((F[f0, c0], F[f0, (c0 + 1) % 3]))
        elif len(hs) == 2:
            f1, c1 = divmod(hs[1], 3)
            p, q = F[f0, (c0 + 2) % 3], F[f1, (c1 + 2) % 3]
            if p != q:
                cross.append((p, q, F[f0, c0], F[f0, (c0 + 1) % 3]))
    return (np.array(edges, np.int64).reshape(-1, 2), np.array(cross, np.int64).reshape(-1, 4),
            np.array(boundary, np.int64).reshape(-1, 2))


def spring_csr(V: np.ndarray, edges: np.ndarray, cross: np.ndarray,
               cross_rest: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-vertex spring adjacency by a stable sort of the springs' endpoints (the relax
    kernel's former numpy assembly): springs ``edges`` then ``cross[:, :2]``, edge rest
    lengths by ``np.linalg.norm``; each spring listed at its first, then its second endpoint.

    Returns
    -------
    ptr : (n + 1,) int64
    nbr : (2 s,) int32
    rst : (2 s,) float64
    """
    n = len(V)
    pairs = np.concatenate([edges, cross[:, :2]])
    rest = np.concatenate([np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1), cross_rest])
    owner = pairs.ravel()  # spring s at entries 2 s (first endpoint) and 2 s + 1 (second)
    other = pairs[:, ::-1].ravel()
    order = np.argsort(owner, kind="stable")
    ptr = np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=n))]).astype(np.int64)
    return ptr, other[order].astype(np.int32), np.repeat(rest, 2)[order]


def unfolded_distance(a, b, p, q) -> float:
    """Distance of ``p`` and ``q`` after unfolding triangles ``(a, b, p)`` and ``(a, b, q)``
    flat about ``ab`` (``q`` rotated about the edge into the plane of ``abp``, opposite side)."""
    a, b, p, q = (np.asarray(v, float) for v in (a, b, p, q))
    e = (b - a) / np.linalg.norm(b - a)
    # in-plane coordinates along the edge and perpendicular distance from it
    def coords(v):
        t = np.dot(v - a, e)
        h = np.linalg.norm((v - a) - t * e)
        return t, h
    tp, hp = coords(p)
    tq, hq = coords(q)
    return float(np.hypot(tp - tq, hp + hq))


def energy(x: np.ndarray, pairs: np.ndarray, rest: np.ndarray, k: float, relative: bool,
           r_floor: float = 1e-3) -> float:
    """Paper Eq. 1 with the 1/2 per spring: ``1/2 sum coef (|x_i - x_j| - r)^2``."""
    l = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
    coef = k / np.maximum(rest, r_floor) ** 2 if relative else np.full(len(rest), k)
    return float(0.5 * np.sum(coef * (l - rest) ** 2))


def forces(x: np.ndarray, pairs: np.ndarray, rest: np.ndarray, k: float, relative: bool,
           r_floor: float = 1e-3) -> np.ndarray:
    """Paper Eq. 2: the Hookean restoring force on every vertex (= minus the energy gradient)."""
    out = np.zeros_like(x)
    for (i, j), r in zip(pairs, rest):
        d = x[i] - x[j]
        l = np.linalg.norm(d)
        coef = k / max(r, r_floor) ** 2 if relative else k
        if l > 0:
            f = -coef * (l - r) * d / l
            out[i] += f
            out[j] -= f
    return out


def barrier_energy(x: np.ndarray, F: np.ndarray, a_ref: np.ndarray, k: float, mu: float, eps: float,
                   relative: bool = False, weight: np.ndarray | None = None) -> float:
    """``sum mu k w phi(A / (eps a_ref))`` with ``phi(a) = a - 1 - log a`` below 1 and
    ``w = 1`` (relative weighting) or ``a_ref``, times the mean importance weight of the
    face's corners (``weight`` None: 1)."""
    e1 = x[F[:, 1]] - x[F[:, 0]]
    e2 = x[F[:, 2]] - x[F[:, 0]]
    A = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    a = A / (eps * a_ref)
    if np.any(a <= 0):
        return np.inf
    phi = np.where(a < 1, a - 1 - np.log(np.minimum(a, 1)), 0.0)
    w_face = 1.0 if weight is None else weight[F].mean(axis=1)
    return float(np.sum(mu * k * (1.0 if relative else a_ref) * w_face * phi))


def numeric_gradient(fun, x: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central finite differences of a scalar function of an (n, 2) array."""
    g = np.zeros_like(x)
    for i, d in itertools.product(range(len(x)), range(2)):
        xp, xm = x.copy(), x.copy()
        xp[i, d] += h
        xm[i, d] -= h
        g[i, d] = (fun(xp) - fun(xm)) / (2 * h)
    return g


def max_step(x: np.ndarray, d: np.ndarray, F: np.ndarray, samples: int = 200001, t_max: float = 10.0) -> float:
    """First ``t`` in ``[0, t_max]`` at which some face's signed area of ``x + t d`` reaches 0,
    found by dense sampling (inf when none does)."""
    ts = np.linspace(0.0, t_max, samples)
    for f in F:
        e1 = x[f[1]] - x[f[0]] + ts[:, None] * (d[f[1]] - d[f[0]])
        e2 = x[f[2]] - x[f[0]] + ts[:, None] * (d[f[2]] - d[f[0]])
        A = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        hit = np.nonzero(A <= 0)[0]
        if len(hit):
            t_max = min(t_max, ts[hit[0]])
    return t_max if t_max < 10.0 else np.inf


def boundary_angle_barrier(x: np.ndarray, F: np.ndarray, verts, k: float, mu: float, gap: float,
                           weight: np.ndarray | None = None) -> float:
    """``sum mu k w_b phi((2 pi - Theta_b) / gap)`` over ``verts``, ``Theta_b`` the sum of the
    angles at ``b`` of its faces (each from ``acos``, so only for positively oriented faces),
    ``w_b`` the vertex's importance weight (None: 1)."""
    total = 0.0
    for b in verts:
        theta = 0.0
        for f in F:
            if b not in f:
                continue
            j = list(f).index(b)
            u = x[f[(j + 1) % 3]] - x[b]
            w = x[f[(j + 2) % 3]] - x[b]
            theta += np.arccos(np.clip(np.dot(u, w) / np.linalg.norm(u) / np.linalg.norm(w), -1, 1))
        a = (2 * np.pi - theta) / gap
        if a <= 0:
            return np.inf
        if a < 1:
            total += mu * k * (1.0 if weight is None else weight[b]) * (a - 1 - np.log(a))
    return total


def outline_energy(x: np.ndarray, V: np.ndarray, F: np.ndarray, verts, k: float, mu: float, cap: float) -> float:
    """``sum mu k (Theta_b - min(Theta3_b, cap))^2`` over ``verts``: ``Theta_b`` the flat sum of
    the angles at ``b`` of its faces in ``x``, ``Theta3_b`` the same on the rest positions ``V``
    (each angle from ``acos``)."""
    def angle_sum(P, b):
        total = 0.0
        for f in F:
            if b in f:
                j = list(f).index(b)
                u, w = P[f[(j + 1) % 3]] - P[b], P[f[(j + 2) % 3]] - P[b]
                total += np.arccos(np.clip(np.dot(u, w) / np.linalg.norm(u) / np.linalg.norm(w), -1, 1))
        return total

    return sum(mu * k * (angle_sum(x, b) - min(angle_sum(V, b), cap)) ** 2 for b in verts)


def contact_energy(x: np.ndarray, seg: np.ndarray, bprev: np.ndarray, bnext: np.ndarray, dhat: float,
                   kappa: float, weight: np.ndarray | None = None) -> float:
    """Boundary contact barrier by brute force over all (vertex, segment) pairs, each pair
    weighted by the mean importance weight of its three vertices (None: 1)."""
    total = 0.0
    for v in seg[:, 0]:
        near = {int(v), int(bprev[v]), int(bnext[v])}
        for a, b in seg:
            if int(a) in near or int(b) in near:
                continue
            e = x[b] - x[a]
            w = np.clip(np.dot(x[v] - x[a], e) / np.dot(e, e), 0.0, 1.0)
            d = np.linalg.norm(x[v] - (x[a] + w * e))
            if d < dhat:
                r = d / dhat
                w_pair = 1.0 if weight is None else (weight[v] + weight[a] + weight[b]) / 3
                total += kappa * w_pair * (r - 1 - np.log(r))
    return total


def weighted_spring_energy(x: np.ndarray, pairs: np.ndarray, rest: np.ndarray, k: float, relative: bool,
                           weight: np.ndarray, r_floor: float = 1e-3) -> float:
    """Paper Eq. 1 with each spring weighted by the mean of its endpoints' importance weights."""
    l = np.linalg.norm(x[pairs[:, 0]] - x[pairs[:, 1]], axis=1)
    coef = k / np.maximum(rest, r_floor) ** 2 if relative else np.full(len(rest), k)
    coef = coef * 0.5 * (weight[pairs[:, 0]] + weight[pairs[:, 1]])
    return float(0.5 * np.sum(coef * (l - rest) ** 2))


def shape_energy(V: np.ndarray, F: np.ndarray, x: np.ndarray, weight: np.ndarray, scale: float,
                 rigidity: float = 0.0, area: float = 0.0, limit: tuple[float, float] | None = None,
                 eps: float = 0.05) -> float:
    """``sum_f w_f A_f (s (sigma_1 / sigma_2 + sigma_2 / sigma_1 - 2) + r ((sigma_1 - 1)^2 +
    (sigma_2 - 1)^2) + a (sqrt(L^2 + eps^2) - eps) + b max(0, u(sigma_1 / sigma_2) -
    u(lim))^2)``, ``u(a) = sqrt(a) - 1 / sqrt(a)``, by an SVD of each face's map from its rest triangle (in a 2D frame of its
    plane) to the flat one; ``w_f`` the mean of the corners' weights, ``s`` the scale, ``r``
    the rigidity, ``a`` the area weight (per unit area), ``L = log(A_flat / A_f)``, and
    ``limit = (b, lim)`` (b per unit area)."""
    total = 0.0
    for f in F:
        p0, p1, p2 = V[f]
        e1, e2 = p1 - p0, p2 - p0
        length = np.linalg.norm(e1)
        n = np.cross(e1, e2)
        rest_area = 0.5 * np.linalg.norm(n)
        b1 = e1 / length
        b2 = np.cross(n / np.linalg.norm(n), b1)
        rest = np.array([[length, e2 @ b1], [0.0, e2 @ b2]])
        flat = np.column_stack([x[f[1]] - x[f[0]], x[f[2]] - x[f[0]]])
        s = np.linalg.svd(flat @ np.linalg.inv(rest), compute_uv=False)
        if np.linalg.det(flat) <= 0:
            return np.inf
        log_area = np.log(s[0] * s[1])
        u = np.sqrt(s[0] / s[1]) - np.sqrt(s[1] / s[0])
        over = 0.0 if limit is None else max(0.0, u - (np.sqrt(limit[1]) - 1.0 / np.sqrt(limit[1])))
        total += weight[f].mean() * rest_area * (
            scale * (s[0] / s[1] + s[1] / s[0] - 2.0) + rigidity * ((s[0] - 1.0) ** 2 + (s[1] - 1.0) ** 2)
            + area * (np.sqrt(log_area**2 + eps**2) - eps) + (0.0 if limit is None else limit[0] * over**2))
    return float(total)


def clip_faces(points: np.ndarray, faces: np.ndarray, level: np.ndarray, snap: float):
    """Each triangle clipped by the zero set of a level linear along edges (Sutherland-Hodgman
    against both half-spaces), the kernel's contract for ``potflat.mesh.split.split_faces``.

    Vertices closer to the cut than ``snap`` of a crossing edge (by the level's change along
    it) count as on it, as do those at level 0.

    Returns
    -------
    polygons : list of dict
        Per face, ``{+1: [points], -1: [points]}``: the corners of the part on each side (a
        part with no area is left out).
    added : dict
        ``(a, b) -> t`` for every edge (smaller vertex first) cut at ``(1 - t) x[a] + t x[b]``.
    on_cut : list of int
        The vertices on the cut, sorted.
    """
    level = np.array(level, dtype=float)
    near = set()
    for tri in faces:
        for c in range(3):
            a, b = int(tri[c]), int(tri[(c + 1) % 3])
            if level[a] == 0.0:
                near.add(a)
            if level[a] * level[b] < 0:
                t = level[a] / (level[a] - level[b])
                if t < snap:
                    near.add(a)
                if t > 1 - snap:
                    near.add(b)
    for v in near:
        level[v] = 0.0
    added, polygons = {}, []
    for tri in faces:
        parts = {}
        for side in (1, -1):
            poly = []
            for c in range(3):
                a, b = int(tri[c]), int(tri[(c + 1) % 3])
                la, lb = side * level[a], side * level[b]
                if la >= 0:
                    poly.append(points[a])
                if la * lb < 0:
                    lo, hi = min(a, b), max(a, b)
                    t = level[lo] / (level[lo] - level[hi])
                    added[(lo, hi)] = t
                    poly.append(points[lo] + t * (points[hi] - points[lo]))
            if len(poly) >= 3 and any(side * level[int(v)] > 0 for v in tri):
                parts[side] = poly
        polygons.append(parts)
    return polygons, added, sorted(near)


def polygon_area(poly) -> float:
    """Area of a planar polygon in 3D (corners in order)."""
    p = np.asarray(poly, float)
    return 0.5 * float(np.linalg.norm(sum(np.cross(p[i], p[(i + 1) % len(p)]) for i in range(len(p)))))


def relief_fit(uv: np.ndarray, P: np.ndarray, weight: np.ndarray, cell_centres: np.ndarray, node: np.ndarray,
               sigma: float, reach: float, ridge: float) -> np.ndarray:
    """The relief's weighted least-squares quadric about ``node``, by a direct solve: the
    vertices whose cell centre (``cell_centres``, (n, 2)) lies within ``reach`` (uv units) of the
    node, each weighted by its weight times the Gaussian of its cell centre's distance, fitted
    by ``1, x, y, x^2, x y, y^2`` of its own offset (in ``sigma``); the linear terms' diagonal
    gains ``1e-3 ridge``, the quadratic terms' ``ridge``, times the total weight. Returns the
    coefficients (6, 3); NaN where no vertex is in reach."""
    d = (cell_centres - node) / sigma
    near = (d**2).sum(axis=1) <= (reach / sigma) ** 2 * (1 + 1e-12)
    if not near.any():
        return np.full((6, 3), np.nan)
    g = weight[near] * np.exp(-0.5 * (d[near] ** 2).sum(axis=1))
    x, y = ((uv[near] - node) / sigma).T
    phi = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=1)
    A = phi.T @ (g[:, None] * phi)
    A += np.diag([0.0, 1e-3 * ridge, 1e-3 * ridge, ridge, ridge, ridge]) * A[0, 0]
    return np.linalg.solve(A, phi.T @ (g[:, None] * P[near]))


def relief_blend(uv: np.ndarray, P: np.ndarray, normal: np.ndarray, nodes: np.ndarray, coef: np.ndarray,
                 sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """Each vertex's height above the blend of the fits of its four nearest nodes and its unit
    normal in the smoothed surface's frame, loop by loop. ``nodes``: (ny, nx, 2) positions on a
    regular grid; ``coef``: (ny, nx, 6, 3), NaN for a node without a fit."""
    step = nodes[0, 1, 0] - nodes[0, 0, 0]
    height = np.full(len(uv), np.nan)
    frame = np.tile([0.0, 0.0, 1.0], (len(uv), 1))
    for i, p in enumerate(uv):
        f = (p - nodes[0, 0]) / step
        base = np.floor(f).astype(int)
        t = f - base
        S, Su, Sv, total = np.zeros(3), np.zeros(3), np.zeros(3), 0.0
        for dy in (0, 1):
            for dx in (0, 1):
                jx, jy = base[0] + dx, base[1] + dy
                if not (0 <= jx < nodes.shape[1] and 0 <= jy < nodes.shape[0]) or np.isnan(coef[jy, jx]).any():
                    continue
                beta = (t[0] if dx else 1 - t[0]) * (t[1] if dy else 1 - t[1])
                if beta <= 0:
                    continue
                x, y = (p - nodes[jy, jx]) / sigma
                c = coef[jy, jx]
                S += beta * np.array([1, x, y, x * x, x * y, y * y]) @ c
                Su += beta * np.array([0, 1, 0, 2 * x, y, 0]) @ c / sigma
                Sv += beta * np.array([0, 0, 1, 0, x, 2 * y]) @ c / sigma
                total += beta
        if total == 0:
            continue
        n = np.cross(Su, Sv)
        n /= np.linalg.norm(n)
        tu = Su / np.linalg.norm(Su)
        tv = np.cross(n, tu)
        height[i] = (P[i] - S / total) @ n
        m = normal[i] / np.linalg.norm(normal[i])
        frame[i] = [m @ tu, m @ tv, m @ n]
    return height, frame


def relief_blend_scalar(uv: np.ndarray, nodes: np.ndarray, coef: np.ndarray, sigma: float) -> np.ndarray:
    """A scalar field's blend of the one-column fits ``coef`` (ny, nx, 6) of its four nearest
    nodes at each vertex, loop by loop (NaN where none has a fit)."""
    step = nodes[0, 1, 0] - nodes[0, 0, 0]
    out = np.full(len(uv), np.nan)
    for i, p in enumerate(uv):
        f = (p - nodes[0, 0]) / step
        base = np.floor(f).astype(int)
        t = f - base
        acc = total = 0.0
        for dy in (0, 1):
            for dx in (0, 1):
                jx, jy = base[0] + dx, base[1] + dy
                beta = (t[0] if dx else 1 - t[0]) * (t[1] if dy else 1 - t[1])
                if not (0 <= jx < nodes.shape[1] and 0 <= jy < nodes.shape[0]) or beta <= 0:
                    continue
                x, y = (p - nodes[jy, jx]) / sigma
                acc += beta * np.array([1, x, y, x * x, x * y, y * y]) @ coef[jy, jx]
                total += beta
        if total:
            out[i] = acc / total
    return out


def volume_invariant(uv: np.ndarray, height: np.ndarray, weight: np.ndarray, radii) -> np.ndarray:
    """The relief's volume invariant by all pairs: for each vertex and radius, the share of the
    ball below the height field minus one half, ``sum w clamp(h_q - h_p, -a, a) / (2 sum w a)``
    over the vertices within the radius (``a = sqrt(r^2 - d^2)``), averaged over the radii."""
    out = np.empty(len(uv))
    for p in range(len(uv)):
        d2 = ((uv - uv[p]) ** 2).sum(axis=1)
        values = []
        for r in radii:
            inside = d2 < r * r
            a = np.sqrt(r * r - d2[inside])
            den = (weight[inside] * a).sum()
            if den > 0:
                values.append((weight[inside] * np.clip(height[inside] - height[p], -a, a)).sum() / (2 * den))
        out[p] = np.mean(values) if values else 0.0
    return out


def relief_rows(fields, coverage, lights, gain, curve_hi, curve_span, rgb, grey_lo, grey_scale, blend,
                mm_per_level, zero_level):
    """The relief's images of a strip in numpy: raking light per light (grey, alpha), the
    concavity's grey, the overlay of painting and relief grey, the TIFF's levels."""
    alpha = np.rint(coverage * 255.0).astype(np.uint8)
    inside = np.isfinite(fields[..., 0])
    to8 = lambda x: np.rint(np.clip(np.nan_to_num(x, nan=0.0), 0.0, 1.0) * 255.0).astype(np.uint8)
    normal = fields[..., 1:4].astype(np.float64)
    length = np.linalg.norm(normal, axis=-1)
    raking = np.stack([np.stack([to8(np.where(length > 0, normal @ light / np.where(length > 0, length, 1) * gain, 0)),
                                 alpha], axis=-1) for light in lights])
    curvature = np.stack([to8(np.where(inside, (curve_hi - fields[..., 4]) / curve_span, 0)), alpha], axis=-1)
    grey = np.where(inside, np.clip((fields[..., 0] - grey_lo) * grey_scale, 0, 1), 0.0)[..., None]
    overlay = np.concatenate([to8((1 - blend) * np.clip(np.nan_to_num(rgb, nan=0.0), 0, 1) + blend * grey),
                              alpha[..., None]], axis=-1)
    level = np.where(inside, np.rint(fields[..., 0] / mm_per_level) + zero_level, 0)
    return raking, curvature, overlay, np.clip(level, 0, 65535).astype(np.uint16)


def border_folds(faces: np.ndarray, uv: np.ndarray, area_3d: np.ndarray, points: np.ndarray | None = None
                 ) -> np.ndarray:
    """:func:`potflat.rollout.border.border_folds` rebuilding everything from the kept faces at
    every pass (edge table, face adjacency, pieces, overlapping faces, the teeth' trimmed
    neighbours)."""
    from potflat.mesh.boundary import edges_and_boundary
    from potflat.mesh.embedding import signed_areas
    from potflat.rollout import border as B
    from potflat.rollout.folds import overlapping_faces
    from potflat.rollout.seam import cut_open
    from potflat.rollout.walls import FaceGraph

    faces = np.asarray(faces, np.int64)
    m, n = len(faces), len(uv)
    keep = np.ones(m, bool)
    graph = FaceGraph(faces)
    part = graph.components()
    part_area = np.bincount(part, area_3d)
    spiked = False
    for _ in range(B.BORDER_PASSES):
        idx = np.flatnonzero(keep)
        if len(idx) == 0:
            break
        sub, area = faces[idx], area_3d[idx]
        edges, seg, owner = edges_and_boundary(sub, n)
        flat = signed_areas(sub, uv)
        drop = np.zeros(len(idx), bool)
        if (flat <= 0).any():  # edge-on strips with a flip, touching the border
            sel = np.flatnonzero(flat < B.EDGE_ON_RATIO * area)
            comp = FaceGraph(sub[sel]).components()
            k = int(comp.max()) + 1
            has_flip = np.bincount(comp[flat[sel] <= 0], minlength=k) > 0
            touches = np.bincount(comp[np.isin(sub[sel], seg).any(axis=1)], minlength=k) > 0
            drop[sel] = (has_flip & touches)[comp]
        same = None if points is None else B._same_place(points, seg)
        f, e = (sub, edges) if same is None else (same[sub], same[edges])
        pinched = np.bincount(e.ravel(), minlength=n) - np.bincount(f.ravel(), minlength=n) >= 2
        local = np.flatnonzero(pinched[f].any(axis=1))
        if len(local):  # the smaller fans at pinched vertices
            new_faces, vertex_index, _, _, _ = cut_open(f[local], np.zeros((len(local), 3)))
            fan_area = np.bincount(new_faces.ravel(), np.repeat(area[local], 3), len(vertex_index))
            minor = np.zeros(len(vertex_index), bool)
            for v in np.unique(vertex_index[pinched[vertex_index]]):
                copies = np.flatnonzero(vertex_index == v)
                minor[copies[copies != copies[np.argmax(fan_area[copies])]]] = True
            drop[local] |= minor[new_faces].any(axis=1)
        if len(idx) < m:  # pieces cut off their part
            pairs = graph.pairs
            piece = graph.components(keep[pairs[:, 0]] & keep[pairs[:, 1]])
            piece_area = np.bincount(piece, np.where(keep, area_3d, 0.0))
            small = np.array([piece_area[piece[i]] < B.CUT_OFF_FRACTION * part_area[part[i]] for i in idx])
            drop |= small
        if not drop.any():
            a, b = B.crossing_segments(uv, seg)
            if len(a):  # the crossing region: owners, overlapping or squeezed faces joined to them
                region = np.zeros(m, bool)
                region[idx[overlapping_faces(sub, uv) | (flat < B.SQUEEZED_RATIO * area)]] = True
                owners = idx[np.concatenate([owner[a], owner[b]])]
                region[owners] = True
                pairs = graph.pairs
                label = graph.components(region[pairs[:, 0]] & region[pairs[:, 1]])
                drop = (region & np.isin(label, label[owners]))[idx]
        if not drop.any() and not spiked and len(idx) < m:  # teeth along the trimmed border, once
            spiked = True
            trimmed_corner = np.isin(np.arange(n), faces[~keep])
            for j, f in enumerate(idx):
                around = [g for g in range(m) if not keep[g] and len(set(faces[g]) & set(faces[f])) == 2]
                drop[j] = len(around) >= 2 or trimmed_corner[faces[f]].all()
        if not drop.any():
            break
        keep[idx[drop]] = False
    return ~keep



def untangle(faces: np.ndarray, uv: np.ndarray, rounds: int, widen: int) -> tuple[np.ndarray, int, int]:
    """:func:`potflat.rollout.border.untangle` by its definition: each round the region's
    movable vertices (not on the boundary) move to the plain mean of their edge neighbours,
    the region (the vertices of flipped faces) growing by the vertices of every face around it
    still flipped and, every ``widen`` rounds, each of its connected parts (through mesh edges)
    holding a vertex of such a face by the vertices of every face touching it; its vertices,
    faces and parts found from scratch every round."""
    import scipy.sparse as sp
    import scipy.sparse.csgraph as csg

    n = len(uv)
    pairs = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    edges, count = np.unique(pairs, axis=0, return_counts=True)
    movable = np.ones(n, bool)
    movable[edges[count == 1].ravel()] = False
    both = np.concatenate([edges, edges[:, ::-1]])
    neighbours = sp.coo_matrix((np.ones(len(both)), (both[:, 0], both[:, 1])), shape=(n, n)).tocsr()
    neighbours.sort_indices()

    def flipped(x):
        e1, e2 = x[faces[:, 1]] - x[faces[:, 0]], x[faces[:, 2]] - x[faces[:, 0]]
        return e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] <= 0

    bad = flipped(uv)
    if not bad.any():
        return uv, 0, 0
    x = uv.copy()
    region = np.zeros(n, bool)
    region[faces[bad].ravel()] = True
    still = bad
    for r in range(rounds):
        if r % widen == widen - 1:
            verts = np.flatnonzero(region)
            _, label = csg.connected_components(neighbours[verts][:, verts], directed=False)
            part = np.full(n, -1)
            part[verts] = label
            tangled = np.isin(part, part[faces[still].ravel()]) & region
            region[faces[tangled[faces].any(axis=1)].ravel()] = True
        region &= movable
        idx = np.flatnonzero(region)
        if len(idx) == 0:
            break
        rows = neighbours[idx]
        x[idx] = (rows @ x) / np.maximum(np.diff(rows.indptr), 1)[:, None]
        still = region[faces].any(axis=1) & flipped(x)
        if not still.any():
            break
        region[faces[still].ravel()] = True
    return x, int(bad.sum()), int(np.count_nonzero(np.any(x != uv, axis=1)))


def relax_untangle(sp, x: np.ndarray, rounds: int = 200) -> tuple[np.ndarray, int]:
    """:func:`potflat.relax.start.untangle` by its definition, every face's area looked at in
    every round: the vertices of flipped faces (and, every 20 rounds, of every face touching
    them) join the region, whose vertices move to their edge neighbours' mean (an ear's tip
    is mirrored about its base instead)."""
    from potflat.mesh._kernels.topology import neighbour_means
    from potflat.relax.start import unfold_ears

    bad = sp.signed_areas(x) <= 0
    n_bad = int(bad.sum())
    if n_bad == 0:
        return x, 0
    x = x.copy()
    region = np.zeros(sp.n, bool)
    ear_tip = np.diff(sp.vf_ptr) == 1
    for r in range(rounds):
        bad = sp.signed_areas(x) <= 0
        if not bad.any():
            break
        region[sp.faces[bad].ravel()] = True
        if r % 20 == 19:
            region[sp.faces[region[sp.faces].any(axis=1)].ravel()] = True
        verts = np.flatnonzero(region & ~ear_tip)
        mean = np.empty((len(verts), 2))
        neighbour_means(x, verts, sp.vf_ptr, sp.vf_tri, sp.faces, mean)
        x[verts] = mean
        unfold_ears(sp, x, np.flatnonzero(region & ear_tip))
    return x, n_bad
