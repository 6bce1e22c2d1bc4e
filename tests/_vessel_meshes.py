"""Small analytic vessel meshes for the profile, wall and attachment tests.

Every builder returns vertices in a canonical frame (axis = +z through the origin) plus
per-face construction labels; :func:`pose` moves them to an arbitrary pose.
"""
from __future__ import annotations

import numpy as np


def revolve(r, h, n_theta, *, theta0=0.0, theta1=2 * np.pi, labels=None, jitter=0.0, seed=0):
    """Revolve the meridian polyline ``(r[j], h[j])`` about +z.

    The polyline's direction decides the normals: faces are CCW seen from the side the
    normal ``(dh/ds * radial, -dr/ds)`` points to (upward along an outer wall = outward).
    Points with ``r == 0`` become a single pole vertex. ``labels[j]`` labels the faces
    between meridian points ``j`` and ``j + 1``.

    Returns ``V (n, 3), F (m, 3), face_labels (m,) object, theta_of_face (m,)``.
    """
    r = np.asarray(r, float)
    h = np.asarray(h, float)
    full = np.isclose(theta1 - theta0, 2 * np.pi)
    nt = n_theta if full else n_theta + 1
    rng = np.random.default_rng(seed)
    th = theta0 + (theta1 - theta0) * np.arange(nt) / n_theta
    V, ring = [], []
    for j in range(len(r)):
        if r[j] == 0:
            ring.append(np.full(nt, len(V)))
            V.append([0.0, 0.0, h[j]])
            continue
        t = th.copy()
        if jitter and full:
            t = t + jitter * (theta1 - theta0) / n_theta * rng.uniform(-0.5, 0.5, nt)
        idx = np.arange(len(V), len(V) + nt)
        ring.append(idx)
        V.extend(np.column_stack([r[j] * np.cos(t), r[j] * np.sin(t), np.full(nt, h[j])]))
    F, L, T = [], [], []
    nq = n_theta
    for j in range(len(r) - 1):
        a, b = ring[j], ring[j + 1]
        for i in range(nq):
            i1 = (i + 1) % nt
            q00, q10, q11, q01 = a[i], a[i1], b[i1], b[i]
            tmid = theta0 + (theta1 - theta0) * (i + 0.5) / n_theta
            lab = None if labels is None else labels[j]
            if r[j] == 0:
                tris = [(q00, q11, q01)]
            elif r[j + 1] == 0:
                tris = [(q00, q10, q11)]
            elif (i + j) % 2:
                tris = [(q00, q10, q11), (q00, q11, q01)]
            else:
                tris = [(q00, q10, q01), (q10, q11, q01)]
            for tri in tris:
                F.append(tri)
                L.append(lab)
                T.append(tmid)
    return np.asarray(V, float), np.asarray(F, np.int64), np.asarray(L, object), np.asarray(T)


def weld(V, F):
    """Merge vertices at identical positions; drop faces that collapse."""
    _, first, inv = np.unique(np.round(V, 9), axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    F2 = rank[inv.ravel()][F]
    keep = (F2[:, 0] != F2[:, 1]) & (F2[:, 1] != F2[:, 2]) & (F2[:, 0] != F2[:, 2])
    return V[first[order]], F2, keep


def pose(V, seed=1):
    """Rotate and translate ``V`` randomly; return ``(V_posed, axis_point, axis_direction)``."""
    rng = np.random.default_rng(seed)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    t = rng.normal(scale=50.0, size=3)
    return V @ q.T + t, t.copy(), q[:, 2].copy()


def vase_radius(h):
    """A smooth single-walled profile (mm) for 0 <= h <= 80."""
    return 30.0 + 8.0 * np.sin(h / 14.0) - 0.002 * (h - 40.0) ** 2


def open_vase(n_theta=96, n_h=61, jitter=0.3):
    """Open surface of revolution (outer wall only) with ``vase_radius``."""
    h = np.linspace(0.0, 80.0, n_h)
    return revolve(vase_radius(h), h, n_theta, jitter=jitter)


def arc(c, radius, a0, a1, n):
    t = np.linspace(a0, a1, n)
    return c[0] + radius * np.cos(t), c[1] + radius * np.sin(t)


def cup(n_theta=72, foot_ring=False, table=0.0):
    """Closed two-walled cup: base, outer wall, rounded rim, inner wall, floor; with
    ``table > 0`` the base is replaced by a flat ring facing up, joined to the foot, out to
    ``table`` times the rim's radius (a table scanned with the cup).

    Labels: "base", "ring", "table", "outer", "rim", "inner", "floor".
    """
    R, H, t = 40.0, 60.0, 3.0
    rs, hs, lab = [], [], []

    def add(r, h, name):
        rs.extend(np.atleast_1d(r))
        hs.extend(np.atleast_1d(h))
        lab.extend([name] * len(np.atleast_1d(r)))

    if table:  # the base hidden by a table out to ``table`` times the rim's radius, joined to the foot
        add(np.linspace(table * R, 30, 13), np.zeros(13), "table")
    elif foot_ring:
        add(np.linspace(0, 26, 9), np.full(9, 4.0), "base")
        add(np.full(3, 26.0), [3.0, 2.0, 1.0], "ring")
        add(np.linspace(26, 30, 3)[:], np.zeros(3), "ring")
    else:
        add(np.linspace(0, 30, 10), np.zeros(10), "base")
    hh = np.linspace(0, H, 25)[1:]
    add(30 + (R - 30) * np.sqrt(hh / H), hh, "outer")
    rr, zz = arc((R - t / 2, H), t / 2, 0.0, np.pi, 9)
    add(rr[1:], zz[1:], "rim")
    hh = np.linspace(H, 8.0, 22)[1:]
    add(30 - t + (R - 30) * np.sqrt(hh / H), hh, "inner")
    rf = rs[-1]
    add(np.linspace(rf, 0, 10)[1:], np.full(9, 8.0), "floor")
    # the label of segment j is the label of its end point j + 1
    return revolve(rs, hs, n_theta, labels=lab[1:] + [None], jitter=0.3)


def plate(n_theta=96, spacing=2.0, broad_rim_drop=2.5):
    """Closed plate (mm): underside with a foot ring, a rounded rim edge, a broad rim 25 wide
    sloping down ``broad_rim_drop`` towards the axis, the well, a flat floor.

    Labels: "underside", "foot", "edge", "broad rim", "well", "floor".
    """
    top = 35.0
    path = [((0.0, 3.0), None), ((66.0, 3.0), "underside"), ((68.0, 0.0), "foot"), ((76.0, 0.0), "foot"),
            ((78.0, 4.0), "foot"), ((100.0, 14.0), "underside"), ((120.0, 28.0), "underside"),
            ((122.0, 32.0), "edge"), ((120.0, top), "edge"), ((95.0, top - broad_rim_drop), "broad rim"),
            ((75.0, 9.0), "well"), ((0.0, 8.0), "floor")]
    return _revolve_path(path, n_theta, spacing)


def dish(n_theta=96, spacing=1.0):
    """The face of :func:`plate` alone, as photographed lying on a table: the rim's edge from
    the table up, the broad rim, the well and the floor, facing up (an open sheet whose
    concave side is the scanned one).

    Labels: "edge", "broad rim", "well", "floor".
    """
    path = [((123.0, 30.0), None), ((122.0, 32.0), "edge"), ((120.0, 35.0), "edge"), ((95.0, 32.5), "broad rim"),
            ((75.0, 9.0), "well"), ((0.0, 8.0), "floor")]
    return _revolve_path(path, n_theta, spacing)


def _revolve_path(path, n_theta, spacing):
    """:func:`revolve` of the polyline ``path`` ``[((r, h), label of the segment ending there), ...]``
    with points about ``spacing`` apart."""
    rs, hs, lab = [path[0][0][0]], [path[0][0][1]], []
    for ((r0, h0), _), ((r1, h1), name) in zip(path[:-1], path[1:]):
        k = max(2, int(np.ceil(np.hypot(r1 - r0, h1 - h0) / spacing)))
        t = np.arange(1, k + 1) / k
        rs.extend(r0 + t * (r1 - r0))
        hs.extend(h0 + t * (h1 - h0))
        lab.extend([name] * k)
    return revolve(rs, hs, n_theta, labels=lab + [None], jitter=0.3)


def handle_tube(R=40.0, hc=50.0, loop=22.0, tube=4.0, n_path=64, n_ring=12, extend=0.0):
    """A tube along a half loop in the meridian plane y = 0 whose end rings touch radius R
    (``extend`` > 0 buries the ends inside)."""
    phi = np.linspace(-extend, np.pi + extend, n_path)
    c = np.column_stack([R + loop * np.sin(phi), np.zeros_like(phi), hc + loop * np.cos(phi)])
    tang = np.gradient(c, axis=0)
    tang /= np.linalg.norm(tang, axis=1)[:, None]
    side = np.array([0.0, 1.0, 0.0])
    nrm = np.cross(side, tang)
    psi = 2 * np.pi * np.arange(n_ring) / n_ring
    V = (c[:, None, :] + tube * (np.cos(psi)[None, :, None] * nrm[:, None, :]
                                + np.sin(psi)[None, :, None] * side[None, None, :])).reshape(-1, 3)
    F = []
    for i in range(n_path - 1):
        for k in range(n_ring):
            a, b = i * n_ring + k, i * n_ring + (k + 1) % n_ring
            c0, d = a + n_ring, b + n_ring
            F += [(a, b, d), (a, d, c0)]
    F = np.asarray(F, np.int64)
    # orient outwards: normals should point away from the centreline
    tri = V[F]
    nrmf = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    cen = tri.mean(axis=1)
    near = c[np.argmin(np.linalg.norm(cen[:, None, :] - c[None, :, :], axis=2), axis=1)]
    if np.einsum("ij,ij->i", nrmf, cen - near).mean() < 0:
        F = F[:, ::-1]
    return V, F


def cylinder_with_handle(n_theta=120, n_h=51, noise=0.0, seed=0):
    """Open cylinder R=40, 0<=h<=100, plus a handle tube; returns V, F, is_handle."""
    h = np.linspace(0.0, 100.0, n_h)
    Vb, Fb, _, _ = revolve(np.full(n_h, 40.0), h, n_theta, jitter=0.3, seed=seed)
    if noise:
        rng = np.random.default_rng(seed)
        rad = Vb[:, :2] / np.linalg.norm(Vb[:, :2], axis=1)[:, None]
        Vb[:, :2] += rad * rng.normal(scale=noise, size=(len(Vb), 1))
    Vh, Fh = handle_tube()
    V = np.vstack([Vb, Vh])
    F = np.vstack([Fb, Fh + len(Vb)])
    is_handle = np.r_[np.zeros(len(Fb), bool), np.ones(len(Fh), bool)]
    return V, F, is_handle


def sherd_shell(theta_span=np.pi / 2, n_theta=30, thickness=4.0):
    """Closed thin shell of a wall fragment: outer, inner, top/bottom breaks and side breaks.

    Labels: "outer", "inner", "break".
    """
    h = np.linspace(15.0, 65.0, 26)
    ro = vase_radius(h)
    ri = ro - thickness
    # meridian loop: outer up, top break inwards, inner down, bottom break outwards
    r = np.r_[ro, ri[::-1], ro[0]]
    z = np.r_[h, h[::-1], h[0]]
    lab = ["outer"] * (len(h) - 1) + ["break"] + ["inner"] * (len(h) - 1) + ["break"]
    V, F, L, _ = revolve(r, z, n_theta, theta0=0.0, theta1=theta_span, labels=lab + [None])
    nt = n_theta + 1
    caps, cap_lab = [], []
    npts = len(r)
    for i, sgn in ((0, -1.0), (nt - 1, 1.0)):
        ids = np.arange(npts) * nt + i  # meridian point j of ring i
        outer_ids, inner_ids = ids[: len(h)], ids[len(h): 2 * len(h)][::-1]
        for j in range(len(h) - 1):
            for tri in ((outer_ids[j], outer_ids[j + 1], inner_ids[j + 1]), (outer_ids[j], inner_ids[j + 1], inner_ids[j])):
                tri = np.asarray(tri)
                p = V[tri]
                n = np.cross(p[1] - p[0], p[2] - p[0])
                tdir = np.array([-np.sin(theta_span if i else 0.0), np.cos(theta_span if i else 0.0), 0.0])
                if n @ tdir * sgn < 0:
                    tri = tri[::-1]
                caps.append(tri)
                cap_lab.append("break")
    F = np.vstack([F, np.asarray(caps, np.int64)])
    L = np.r_[L, np.asarray(cap_lab, object)]
    V, F, keep = weld(V, F)
    return V, F[keep], L[keep]


def cylinder_with_knob(n_theta=180, n_h=76, height=12.0, radius=10.0, seed=0):
    """Open cylinder R=40, 0<=h<=100, with a smooth knob pushed out of the wall (one surface).

    Returns ``V, F, bump`` with ``bump`` (n,) the radial displacement of every vertex.
    """
    h = np.linspace(0.0, 100.0, n_h)
    V, F, _, _ = revolve(np.full(n_h, 40.0), h, n_theta, jitter=0.3, seed=seed)
    centre = np.array([40.0, 0.0, 50.0])
    d = np.linalg.norm(V - centre, axis=1)
    bump = np.where(d < radius, height * np.cos(0.5 * np.pi * d / radius) ** 2, 0.0)
    rad = V[:, :2] / np.linalg.norm(V[:, :2], axis=1)[:, None]
    V = V.copy()
    V[:, :2] += rad * bump[:, None]
    return V, F, bump
