"""Geometry of the synthetic vessels: the generatrix, its revolved mesh, handles, holes and
sherds (canonical frame: axis = z, foot at the origin; mm).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from potflat_synthetic.spec import (
    BLACK,
    CLAY,
    PART_BASE,
    PART_BREAK,
    PART_HANDLE,
    PART_INNER,
    PART_OUTER,
    PART_RIM,
    Painting,
    _Handle,
    _Spec,
)

from potflat.errors import InvalidOptionError


@dataclass(frozen=True, eq=False)
class _Generatrix:
    """Section polyline ``(r, z)`` with arc length ``s`` and part breaks."""

    r: np.ndarray
    z: np.ndarray
    s: np.ndarray
    s_outer: tuple      # (start, end) of the outer wall
    s_inner: float      # start of the inner wall (end of the rim), inf with one wall
    s_floor: float      # start of the inner floor, inf with one wall


def _smooth_profile(points, n=4097) -> tuple[np.ndarray, np.ndarray]:
    """Dense ``(r, z)`` of the smooth curve through control points ``(z, r)``."""
    from scipy.interpolate import PchipInterpolator

    pts = np.asarray(points, float)
    z, r = pts[:, 0], pts[:, 1]
    t = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(z), np.diff(r)))])
    tt = np.linspace(0.0, t[-1], n)
    zz = PchipInterpolator(t, z)(tt)
    rr = PchipInterpolator(t, r)(tt)
    if np.any(np.diff(zz) <= 0) or np.any(rr <= 0):
        raise RuntimeError("profile control points must give a strictly rising, positive curve")
    return rr, zz


def _normals2d(r, z) -> np.ndarray:
    """Unit outward normals ``(dz, -dr)`` of a polyline in the (r, z) plane, per point."""
    dr, dz = np.gradient(r), np.gradient(z)
    n = np.stack([dz, -dr], axis=1)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _build_generatrix(spec: _Spec, *, walls: int, base: bool, thickness: float) -> _Generatrix:
    r_o, z_o = _smooth_profile(spec.points)
    rs, zs = [], []
    if base:
        t = np.linspace(0.0, 1.0, 513)[:-1]
        rs.append(r_o[0] * t)
        zs.append(np.full_like(t, z_o[0]))
    n_base = sum(len(a) for a in rs)
    rs.append(r_o)
    zs.append(z_o)
    n_outer_end = n_base + len(r_o) - 1
    if walls == 2:
        nrm = _normals2d(r_o, z_o)
        dr, dz = r_o[-1] - r_o[-2], z_o[-1] - z_o[-2]
        tan = np.array([dr, dz]) / math.hypot(dr, dz)
        centre = np.array([r_o[-1], z_o[-1]]) - 0.5 * thickness * nrm[-1]
        phi = np.linspace(0.0, math.pi, 129)[1:]
        arc = centre + 0.5 * thickness * (np.cos(phi)[:, None] * nrm[-1] + np.sin(phi)[:, None] * tan)
        rs.append(arc[:, 0])
        zs.append(arc[:, 1])
        inner = (np.stack([r_o, z_o], axis=1) - thickness * nrm)[::-1][1:]
        keep = inner[:, 1] > spec.floor
        last = int(np.argmin(keep))  # first point below the floor
        if keep[last] or last == 0:
            raise RuntimeError("inner wall does not reach the floor height")
        a, b = inner[last - 1], inner[last]
        w = (a[1] - spec.floor) / (a[1] - b[1])
        cut = a + w * (b - a)
        inner = np.vstack([inner[:last], cut])
        seg = np.diff(inner, axis=0)
        if np.any(np.einsum("ij,ij->i", seg[1:], seg[:-1]) <= 0):
            raise RuntimeError("wall thickness too large for the profile's curvature")
        rs.append(inner[:, 0])
        zs.append(inner[:, 1])
        t = np.linspace(0.0, 1.0, 513)[1:]
        rs.append(cut[0] * (1.0 - t))
        zs.append(np.full_like(t, spec.floor))
    r = np.concatenate(rs)
    z = np.concatenate(zs)
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(r), np.diff(z)))])
    s_outer = (float(s[n_base]), float(s[n_outer_end]))
    if walls == 2:
        s_inner = float(s[n_outer_end + 128])
        s_floor = float(s[-513])
    else:
        s_inner = s_floor = math.inf
    return _Generatrix(r=r, z=z, s=s, s_outer=s_outer, s_inner=s_inner, s_floor=s_floor)


def _outer_polyline(g: _Generatrix) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(s, r, z)`` of the section polyline's points on the outer wall (z rising)."""
    sel = (g.s >= g.s_outer[0]) & (g.s <= g.s_outer[1])
    return g.s[sel], g.r[sel], g.z[sel]


def _wall_polyline(g: _Generatrix, inner: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(r, z, normal)`` of the section polyline's points on the outer or the inner wall, the
    normals pointing out of the vessel's material (the inner wall's into the cavity)."""
    if inner:
        sel = (g.s >= g.s_inner) & (g.s <= g.s_floor)
        pr, pz = g.r[sel], g.z[sel]
    else:
        _, pr, pz = _outer_polyline(g)
    return pr, pz, _normals2d(pr, pz)


def _project_to_generatrix(g: _Generatrix, r, z) -> np.ndarray:
    """Arc length ``s`` of the nearest point of the section polyline to each ``(r, z)``."""
    from scipy.spatial import cKDTree

    pts = np.stack([g.r, g.z], axis=1)
    q = np.stack([r, z], axis=1)
    _, idx = cKDTree(pts).query(q, workers=-1)
    best_s = g.s[idx].copy()
    best_d = np.full(len(q), np.inf)
    for lo in (idx - 1, idx):
        lo = np.clip(lo, 0, len(pts) - 2)
        a, b = pts[lo], pts[lo + 1]
        ab = b - a
        t = np.clip(np.einsum("ij,ij->i", q - a, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
        d = np.linalg.norm(a + t[:, None] * ab - q, axis=1)
        better = d < best_d
        best_d[better] = d[better]
        best_s[better] = (g.s[lo] + t * (g.s[lo + 1] - g.s[lo]))[better]
    return best_s


def _wrap(a):
    """Angle difference wrapped to [-pi, pi)."""
    return (np.asarray(a) + math.pi) % (2 * math.pi) - math.pi


def _ring_strip_faces(rows, theta, n_row, k_lo, k_hi) -> np.ndarray:
    """Triangles between consecutive closed rings of points, rows ``k_lo .. k_hi``.

    Each ring's edges (between angle-sorted neighbours, closing around 2 pi) are swept
    together with the next ring's edges in the order of their mid-angles; an edge's
    triangle takes the vertex that is current on the other ring at that moment. This is
    a valid strip triangulation of every pair of rings (no seam, no duplicated points).
    Faces are counter-clockwise in the (angle, row) plane. Returns global vertex indices.
    """
    two_pi = 2 * math.pi
    sel = np.flatnonzero((rows >= k_lo) & (rows <= k_hi))
    order = sel[np.lexsort((theta[sel], rows[sel]))]
    loc = rows[order] - k_lo
    th = theta[order]
    counts = n_row[k_lo:k_hi + 1]
    start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    i_in = np.arange(len(order)) - start[loc]
    nxt = start[loc] + (i_in + 1) % counts[loc]
    th0 = th[start]
    mid = th + 0.5 * ((th[nxt] - th) % two_pi)
    key = 10.0 * loc + (mid - th0[loc])  # rows 10 apart, each spanning [0, 2 pi)
    faces = []
    for step, side in ((1, "left"), (-1, "right")):
        e = np.flatnonzero((loc + step >= 0) & (loc + step < len(counts)))
        other = loc[e] + step
        q = 10.0 * other + (mid[e] - th0[other]) % two_pi
        c = np.searchsorted(key, q, side=side) - start[other]
        apex = order[start[other] + c % counts[other]]
        if step == 1:
            faces.append(np.stack([order[e], order[nxt[e]], apex], axis=1))
        else:
            faces.append(np.stack([order[nxt[e]], order[e], apex], axis=1))
    return np.concatenate(faces)


def _planar_delaunay(xy) -> np.ndarray:
    from scipy.spatial import Delaunay

    tri = Delaunay(xy).simplices
    p = xy[tri]
    area = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
            - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    return tri[np.abs(area) > 1e-14]


def _row_points(n_per_row, row_s, ds, jitter_rows, rng):
    """Jittered sample points ``(row, s, theta)`` on rows of a periodic band."""
    rows = np.repeat(np.arange(len(n_per_row)), n_per_row)
    starts = np.concatenate([[0], np.cumsum(n_per_row)[:-1]])
    j = np.arange(len(rows)) - starts[rows]
    phase = rng.uniform(0.0, 2 * math.pi, len(n_per_row))
    jt = rng.uniform(-0.3, 0.3, len(rows))
    js = rng.uniform(-0.3, 0.3, len(rows))
    theta = (phase[rows] + 2 * math.pi * (j + jt) / n_per_row[rows]) % (2 * math.pi)
    theta[n_per_row[rows] == 1] = 0.0
    s = row_s[rows] + np.where(jitter_rows[rows], js * ds, 0.0)
    return rows, s, theta


def _revolve(g: _Generatrix, n_target: int, rng) -> tuple:
    """Irregular triangulation of the surface of revolution of ``g``.

    Returns vertices (canonical), faces (CCW from outside), per-vertex ``s`` and ``theta``.
    """
    L = float(g.s[-1])
    area = float(np.sum(2 * math.pi * 0.5 * (g.r[1:] + g.r[:-1]) * np.diff(g.s)))
    h = math.sqrt(2.0 * area / (math.sqrt(3.0) * n_target))
    K = max(2, int(math.ceil(L / (h * math.sqrt(3.0) / 2))))
    row_s = np.linspace(0.0, L, K + 1)
    ds = L / K
    row_r = np.interp(row_s, g.s, g.r)
    pole0, pole1 = g.r[0] == 0.0, g.r[-1] == 0.0
    r_cap = 2.5 * h
    ka, kb = 0, K
    if pole0:
        ka = int(np.argmax(row_r >= r_cap))
    if pole1:
        kb = K - int(np.argmax(row_r[::-1] >= r_cap))
    if not (0 <= ka < kb <= K) or row_r[ka] < r_cap or row_r[kb] < r_cap:
        raise InvalidOptionError(
            f"n_vertices={n_target} is too small for this vessel; use at least 2000"
        )
    n_row = np.where(row_r == 0.0, 1, np.maximum(3, np.rint(2 * math.pi * row_r / h))).astype(np.int64)
    jitter = np.ones(K + 1, bool)
    jitter[[0, K, ka, kb]] = False
    rows, s, theta = _row_points(n_row, row_s, ds, jitter, rng)
    r = np.interp(s, g.s, g.r)
    z = np.interp(s, g.s, g.z)
    V = np.stack([r * np.cos(theta), r * np.sin(theta), z], axis=1)

    faces = [_ring_strip_faces(rows, theta, n_row, ka, kb)]
    for cap in ((rows <= ka) if pole0 else None, (rows >= kb) if pole1 else None):
        if cap is None:
            continue
        ci = np.flatnonzero(cap)
        faces.append(_orient_outward(g, V, ci[_planar_delaunay(V[ci, :2])], s))
    F = np.concatenate(faces).astype(np.int64)
    _check_manifold(F, len(V), holes_expected=int(not pole0) + int(not pole1))
    return V, F, s, theta, h


def _orient_outward(g: _Generatrix, V, F, s) -> np.ndarray:
    """Flip faces whose normal disagrees with the analytic outward normal."""
    nrm = _normals2d(g.r, g.z)
    sc = s[F].mean(axis=1)
    nr = np.interp(sc, g.s, nrm[:, 0])
    nz = np.interp(sc, g.s, nrm[:, 1])
    c = V[F].mean(axis=1)
    rc = np.maximum(np.hypot(c[:, 0], c[:, 1]), 1e-300)
    ref = np.stack([nr * c[:, 0] / rc, nr * c[:, 1] / rc, nz], axis=1)
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    flip = np.einsum("ij,ij->i", fn, ref) < 0
    F = F.copy()
    F[flip] = F[flip][:, ::-1]
    return F


def _check_manifold(F, n_vertices, holes_expected) -> None:
    """Internal consistency: an oriented 2-manifold, all vertices used, Euler characteristic
    ``2 - holes_expected`` (genus 0 with that many boundary loops, or a closed surface of
    genus ``holes_expected / 2``)."""
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = np.sort(directed[:, 0] * n_vertices + directed[:, 1])
    if np.any(key[1:] == key[:-1]):
        raise RuntimeError("synthetic mesh is not consistently oriented")
    und = np.sort(np.minimum(directed[:, 0], directed[:, 1]) * n_vertices
                  + np.maximum(directed[:, 0], directed[:, 1]))
    n_edges = 1 + int(np.count_nonzero(und[1:] != und[:-1]))
    used = np.zeros(n_vertices, bool)
    used[F.ravel()] = True
    chi = int(used.sum()) - n_edges + len(F)
    if not used.all() or chi != 2 - holes_expected:
        raise RuntimeError(f"synthetic mesh topology is wrong (euler {chi}, {used.sum()}/{n_vertices} used)")


def _bezier(p, t):
    t = t[:, None]
    return ((1 - t) ** 3) * p[0] + 3 * ((1 - t) ** 2) * t * p[1] + 3 * (1 - t) * t * t * p[2] + t ** 3 * p[3]


def _handle_mesh(g: _Generatrix, hd: _Handle, h: float, rng, sink: float) -> tuple:
    """Tube mesh of one handle whose open ends sink ``sink`` mm into the wall.

    Returns V, F, arc length and angle per vertex, and both ends as (surface point,
    unit wall normal, indices of the end ring's vertices, the wall's part).
    """

    def anchor(z, th, inner):
        pr, pz, nrm = _wall_polyline(g, inner)
        i = int(np.argmin(np.abs(pz - z)))
        n3 = np.array([nrm[i, 0] * math.cos(th), nrm[i, 0] * math.sin(th), nrm[i, 1]])
        p3 = np.array([pr[i] * math.cos(th), pr[i] * math.sin(th), pz[i]])
        return p3 - sink * n3, n3

    a0, n0 = anchor(hd.z0, hd.theta + hd.dtheta0, False)
    a1, n1 = anchor(hd.z1, hd.theta + hd.dtheta1, hd.inner1)
    up = np.array([0.0, 0.0, hd.lift])
    ctrl = np.array([a0, a0 + hd.reach * n0 + up, a1 + hd.reach * n1 + up, a1])
    tt = np.linspace(0.0, 1.0, 2001)
    c = _bezier(ctrl, tt)
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(c, axis=0), axis=1))])
    length = float(arc[-1])
    K = max(2, int(math.ceil(length / (h * math.sqrt(3.0) / 2))))
    row_s = np.linspace(0.0, length, K + 1)
    n = max(6, int(round(2 * math.pi * hd.radius / h)))
    n_row = np.full(K + 1, n, np.int64)
    jitter = np.ones(K + 1, bool)
    jitter[[0, K]] = False
    _, s, phi = _row_points(n_row, row_s, length / K, jitter, rng)
    t_of_s = np.interp(s, arc, tt)
    centre = _bezier(ctrl, t_of_s)
    # rotation-minimising frame along the centreline (double reflection), interpolated
    tan = np.gradient(c, axis=0)
    tan /= np.linalg.norm(tan, axis=1, keepdims=True)
    frame = np.empty_like(c)
    ref = np.cross(tan[0], np.cross(a1 - a0, tan[0]) if np.linalg.norm(np.cross(a1 - a0, tan[0])) > 1e-9
                   else np.array([0.0, 0.0, 1.0]))
    frame[0] = ref / np.linalg.norm(ref)
    for i in range(len(c) - 1):
        v1 = c[i + 1] - c[i]
        rl = frame[i] - 2.0 * (v1 @ frame[i]) / (v1 @ v1) * v1
        tl = tan[i] - 2.0 * (v1 @ tan[i]) / (v1 @ v1) * v1
        v2 = tan[i + 1] - tl
        frame[i + 1] = rl - 2.0 * (v2 @ rl) / (v2 @ v2) * v2 if v2 @ v2 > 1e-30 else rl
    other = np.stack([np.interp(t_of_s, tt, frame[:, k]) for k in range(3)], axis=1)
    tangent = np.stack([np.interp(t_of_s, tt, tan[:, k]) for k in range(3)], axis=1)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    other -= np.einsum("ij,ij->i", other, tangent)[:, None] * tangent
    other /= np.linalg.norm(other, axis=1, keepdims=True)
    side = np.cross(tangent, other)
    V = centre + hd.radius * (np.cos(phi)[:, None] * other + np.sin(phi)[:, None] * side)
    rows = np.repeat(np.arange(K + 1), n)
    F = _ring_strip_faces(rows, phi, n_row, 0, K).astype(np.int64)
    _check_manifold(F, len(V), holes_expected=2)
    ends = ((a0 + sink * n0, n0, np.flatnonzero(rows == 0), PART_OUTER),
            (a1 + sink * n1, n1, np.flatnonzero(rows == K), PART_INNER if hd.inner1 else PART_OUTER))
    return V, F, s, phi, ends


def _weld_handles(V, F, arrays, face_arrays, ends, h, keep_wall=False):
    """Weld handle tubes into the wall: cut a hole around each root, stitch it to the ring.

    ``arrays`` are per-vertex arrays and ``face_arrays`` per-face arrays (the first one
    the face part) to carry along; ``ends`` = (root point, wall normal, ring vertex
    indices, tube radius, the wall's part). The hole (wall faces within the tube radius
    plus 1.5 ``h`` of the root, grown where its outline is not star-shaped around the root;
    never through the other wall behind it) is stitched to the tube's end ring by a strip of
    handle faces. ``keep_wall``: the hole's faces stay, so every edge of its outline has
    three faces (a non-manifold join, as scans merged from several passes have). Returns V,
    F, arrays, face arrays and the stitched faces' preset chart layout (face indices,
    tangent-plane projection, two charts per root).
    """
    face_part = face_arrays[0]
    near = [np.zeros(len(V), bool) for _ in ends]
    frames = []
    for k, (A, nA, ring, a, _) in enumerate(ends):
        d = np.linalg.norm(V - A, axis=1)
        d[ring] = np.inf
        near[k] |= d <= a + max(1.5 * h, 1.0)
        e1 = np.cross(nA, [1.0, 0.0, 0.0] if abs(nA[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        frames.append((e1, np.cross(nA, e1)))
    for _ in range(20):
        cut = np.zeros(len(F), bool)
        for k, end in enumerate(ends):
            cut |= (face_part == end[4]) & near[k][F].any(axis=1)
        remove = _remove_faces(F, cut)
        Fk = F[~remove]
        used = np.zeros(len(V), bool)
        used[Fk.ravel()] = True
        if keep_wall:  # (the hole's faces come back: every vertex stays)
            used[:] = True
        old = np.flatnonzero(used)
        new = np.cumsum(used) - 1
        Vk, Fk = V[used], new[Fk]
        n = len(Vk)
        directed = np.concatenate([Fk[:, [0, 1]], Fk[:, [1, 2]], Fk[:, [2, 0]]])
        key = directed[:, 0] * n + directed[:, 1]
        on_border = ~np.isin(key, directed[:, 1] * n + directed[:, 0])
        bnd = directed[on_border]
        bnd_part = np.tile(face_part[~remove], 3)[on_border]
        nxt = dict(zip(bnd[:, 0].tolist(), bnd[:, 1].tolist()))
        is_handle_vertex = np.zeros(n, bool)
        is_handle_vertex[Fk[face_part[~remove] == PART_HANDLE].ravel()] = True
        stitched, uvs, pieces, grow = [], [], [], False
        for k, ((A, nA, ring, _, part), (e1, e2)) in enumerate(zip(ends, frames)):
            # the boundary loop of the root's wall nearest to the root
            start = np.flatnonzero(~is_handle_vertex[bnd[:, 0]] & (bnd_part == part))
            first = bnd[start[np.argmin(np.linalg.norm(Vk[bnd[start, 0]] - A, axis=1))], 0]
            hole = [int(first)]
            while nxt[hole[-1]] != hole[0]:
                hole.append(nxt[hole[-1]])
            hole = np.array(hole)
            if any(np.isin(hole, f).any() for f in stitched):
                raise InvalidOptionError("the mesh is too coarse to weld the handles; use more n_vertices")
            ang = lambda idx: np.arctan2((Vk[idx] - A) @ e2, (Vk[idx] - A) @ e1) % (2 * math.pi)
            turn = _wrap(ang(np.roll(hole, -1)) - ang(hole))
            wrong = np.sign(turn) != np.sign(turn.sum())
            if np.any(wrong) or abs(abs(turn.sum()) - 2 * math.pi) > 1e-6:
                near[k][old[hole[wrong | np.roll(wrong, 1)]]] = True  # cut the notch away
                grow = True
                continue
            ring = new[ring]
            idx = np.concatenate([hole, ring])
            rows = np.concatenate([np.zeros(len(hole), np.int64), np.ones(len(ring), np.int64)])
            faces = idx[_ring_strip_faces(rows, ang(idx), np.array([len(hole), len(ring)]), 0, 1)]
            u, v = hole[0], hole[1]
            if np.any((faces == u) & (np.roll(faces, -1, axis=1) == v)):
                faces = faces[:, ::-1]
            stitched.append(faces)
            P = Vk[faces] - A
            uvs.append(np.stack([P @ e1, P @ e2], axis=2))
            c = P.mean(axis=1)
            pieces.append((np.arctan2(c @ e2, c @ e1) >= 0).astype(np.int64) + 2 * len(pieces))
        if not grow:
            break
    else:
        raise InvalidOptionError("the mesh is too coarse to weld the handles; use more n_vertices")
    kept = ~remove | keep_wall  # (with keep_wall every vertex stayed: the faces' indices hold)
    V, F = Vk, np.concatenate([Fk, F[remove & kept]])
    arrays = [a[used] for a in arrays]
    face_arrays = [np.concatenate([a[~remove], a[remove & kept]]) for a in face_arrays]
    m0 = len(F)
    extra = np.concatenate(stitched)
    F = np.concatenate([F, extra])
    fills = [PART_HANDLE] + [-1] * (len(face_arrays) - 1)
    face_arrays = [np.concatenate([a, np.full(len(extra), f, a.dtype)]) for a, f in zip(face_arrays, fills)]
    preset = (np.arange(m0, len(F)), np.concatenate(uvs), np.concatenate(pieces))
    return V, F, arrays, face_arrays, preset

# --------------------------------------------------------------------------- holes, sherds


def _remove_faces(F, remove) -> np.ndarray:
    """Remove faces, then also the faces at pinch vertices, until the boundary is clean."""
    remove = remove.copy()
    while True:
        keep = F[~remove]
        directed = np.concatenate([keep[:, [0, 1]], keep[:, [1, 2]], keep[:, [2, 0]]])
        n = int(F.max()) + 1
        und = np.sort(directed, axis=1)
        key = und[:, 0] * n + und[:, 1]
        uniq, cnt = np.unique(key, return_counts=True)
        boundary = np.isin(key, uniq[cnt == 1])
        starts = np.bincount(directed[boundary, 0], minlength=n)
        pinch = np.flatnonzero(starts > 1)
        if len(pinch) == 0:
            return remove
        remove |= np.isin(F, pinch).any(axis=1)


def _largest_component(F, keep) -> np.ndarray:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    idx = np.flatnonzero(keep)
    m = len(idx)
    if m == 0:
        return keep
    # faces are connected when they share a vertex through the face-vertex incidence
    n = int(F.max()) + 1
    rows = np.repeat(np.arange(m), 3)
    inc = coo_matrix((np.ones(3 * m), (rows, F[idx].ravel())), shape=(m, n)).tocsr()
    adj = inc @ inc.T
    _, lab = connected_components(adj, directed=False)
    big = np.argmax(np.bincount(lab))
    out = np.zeros_like(keep)
    out[idx[lab == big]] = True
    return out


def _compact(V, F, *arrays):
    """Drop unused vertices; returns V, F and the vertex arrays reindexed."""
    used = np.zeros(len(V), bool)
    used[F.ravel()] = True
    new = np.cumsum(used) - 1
    return (V[used], new[F]) + tuple(a[used] for a in arrays)


def _thicken_sherd(g: _Generatrix, V, F, vs, vth, thickness):
    """Give a one-sided patch a back (offset inwards along the section normal) and break faces.

    Returns the new V, F, vs, vth, face parts, vertex parts and the break faces' preset
    chart layout (face indices, corner layouts (k, 3, 2) in mm, piece ids).
    """
    n, m = len(V), len(F)
    nrm = _normals2d(g.r, g.z)
    nr, nz = np.interp(vs, g.s, nrm[:, 0]), np.interp(vs, g.s, nrm[:, 1])
    back = V - thickness * np.stack([nr * np.cos(vth), nr * np.sin(vth), nz], axis=1)
    directed = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    key = directed[:, 0] * n + directed[:, 1]
    rev = directed[:, 1] * n + directed[:, 0]
    bnd = directed[~np.isin(key, rev)]
    nxt = dict(zip(bnd[:, 0].tolist(), bnd[:, 1].tolist()))
    if len(nxt) != len(bnd):
        raise RuntimeError("sherd boundary has a pinch vertex")
    sides, uvs, pieces = [], [], []
    todo = set(nxt)
    while todo:  # one strip of break faces per boundary loop (outline and through-holes)
        loop = [min(todo)]
        while nxt[loop[-1]] != loop[0]:
            loop.append(nxt[loop[-1]])
        todo -= set(loop)
        a = np.array(loop)
        b = np.roll(a, -1)
        ell = np.linalg.norm(V[b] - V[a], axis=1)
        c = np.concatenate([[0.0], np.cumsum(ell)[:-1]])
        zero, full = np.zeros_like(c), np.full_like(c, thickness)
        sides += [np.stack([b, a, a + n], axis=1), np.stack([b, a + n, b + n], axis=1)]
        uvs += [np.stack([np.stack([c + ell, zero], 1), np.stack([c, zero], 1), np.stack([c, full], 1)], 1),
                np.stack([np.stack([c + ell, zero], 1), np.stack([c, full], 1), np.stack([c + ell, full], 1)], 1)]
        k = np.minimum((4 * c / (c[-1] + ell[-1])).astype(np.int64), 3) + 4 * (len(pieces) // 2)
        pieces += [k, k]
    side = np.concatenate(sides)
    n_loops = len(pieces) // 2
    F2 = np.concatenate([F, F[:, ::-1] + n, side])
    V2 = np.concatenate([V, back])
    face_part = np.concatenate([np.full(m, PART_OUTER, np.int8), np.full(m, PART_INNER, np.int8),
                                np.full(len(side), PART_BREAK, np.int8)])
    vertex_part = np.concatenate([np.full(n, PART_OUTER, np.int8), np.full(n, PART_INNER, np.int8)])
    _check_manifold(F2, len(V2), holes_expected=2 * (n_loops - 1))  # genus = through-holes
    preset = (np.arange(2 * m, 2 * m + len(side)), np.concatenate(uvs), np.concatenate(pieces))
    return V2, F2, np.concatenate([vs, vs]), np.concatenate([vth, vth]), face_part, vertex_part, preset


def _plain_colours(g: _Generatrix) -> dict:
    """Parts painted in one plain colour instead of the painting."""
    plain = {PART_HANDLE: BLACK, PART_BREAK: CLAY}
    if not math.isfinite(g.s_inner):
        plain[PART_INNER] = CLAY  # the back of a thick sherd
    return plain


def _parts_of(g: _Generatrix, s) -> np.ndarray:
    part = np.full(len(s), PART_OUTER, np.int8)
    part[s < g.s_outer[0]] = PART_BASE
    part[s > g.s_outer[1]] = PART_RIM
    part[s > g.s_inner] = PART_INNER
    return part


def _sherd_region(g: _Generatrix, painting: Painting, span_deg: float, rng):
    """Region test of a sherd around the first frieze circle, and its area fraction."""
    c0 = painting.circles[0]
    s_lo_w, s_hi_w = g.s_outer
    sf = float(_project_to_generatrix(g, np.array([math.hypot(*c0.centre[:2])]), np.array([c0.centre[2]]))[0])
    half_s = 0.3 * (s_hi_w - s_lo_w)
    s0, s1 = max(s_lo_w, sf - half_s), min(s_hi_w, sf + half_s)
    span = math.radians(span_deg)
    th0 = c0.angle + rng.uniform(-0.2, 0.2) * span
    amp_t, amp_s = 0.08 * span / 2, 0.1 * (s1 - s0) / 2
    n1 = (rng.uniform(0, 2 * math.pi, 3), rng.uniform(-1, 1, 3))
    n2 = (rng.uniform(0, 2 * math.pi, 3), rng.uniform(-1, 1, 3))

    def noise(n, x):
        ph, a = n
        return sum(a[k] * np.sin((k + 1) * x + ph[k]) for k in range(3)) / 3.0

    def inside(theta, s):
        d = _wrap(theta - th0)
        u = 2 * math.pi * (np.asarray(s) - s0) / max(s1 - s0, 1e-9)
        ok_t = np.abs(d) <= span / 2 + amp_t * noise(n1, u)
        ok_s = (s >= s0 + amp_s * noise(n2, d * 2 * math.pi / span)) & \
               (s <= s1 + amp_s * noise(n2, d * 2 * math.pi / span + 1.0))
        return ok_t & ok_s

    def circle_ok(c):
        r = math.hypot(*c.centre[:2])
        sc = float(_project_to_generatrix(g, np.array([r]), np.array([c.centre[2]]))[0])
        a = np.linspace(0, 2 * math.pi, 32, endpoint=False)
        m = c.radius + 6.0
        return bool(np.all(inside(c.angle + m * np.cos(a) / r, sc + m * np.sin(a))))

    sel = (g.s >= s0) & (g.s <= s1)
    rs = g.r * sel
    frac = (span / (2 * math.pi)) * np.trapezoid(rs, g.s) / np.trapezoid(g.r, g.s)
    return inside, circle_ok, float(frac)


def _place_holes(g: _Generatrix, painting: Painting, n: int, rng, region, avoid):
    """Hole centres and radii on the painted outer wall, clear of circles, of the discs
    ``avoid`` (centre, radius) and of each other."""
    z_lo = float(np.interp(g.s_outer[0], g.s, g.z))
    z_hi = float(np.interp(g.s_outer[1], g.s, g.z))
    H = z_hi - z_lo
    zf = painting.circles[0].height
    a, b = max(z_lo + 0.1 * H, zf - 40.0), min(z_hi - 0.1 * H, zf + 40.0)
    prof_s, pr, pz = _outer_polyline(g)
    out = []
    for _ in range(2000):
        if len(out) == n:
            return out
        z = rng.uniform(a, b)
        th = rng.uniform(0, 2 * math.pi)
        rad = rng.uniform(6.0, 12.0)
        r = float(np.interp(z, pz, pr))
        c = np.array([r * math.cos(th), r * math.sin(th), z])
        if any(np.linalg.norm(c - pc.centre) < pc.radius + rad + 3.0 for pc in painting.circles):
            continue
        if any(np.linalg.norm(c - oc) < orad + rad + 6.0 for oc, orad in out + avoid):
            continue
        if region is not None:
            sc = float(np.interp(z, pz, prof_s))
            aa = np.linspace(0, 2 * math.pi, 32, endpoint=False)
            if not np.all(region[0](th + (rad + 8.0) * np.cos(aa) / r, sc + (rad + 8.0) * np.sin(aa))):
                continue
        out.append((c, rad))
    raise InvalidOptionError(f"cannot place {n} holes on this {'sherd' if region else 'vessel'}; use fewer")

