"""Mesh geometry kernels: face normals, areas (3D, and signed 2D of a flattening), frames
and flat maps, corner angles, edge lengths, radial parts, the texture's grey levels under faces.

Arrays in, arrays out, no I/O; deterministic for any thread count.
"""
from __future__ import annotations


import numpy as np

from potflat._jit import leaf, parallel, prange


@leaf
def _lattice_texel(texcoords, f, img, a, b, steps):
    """Grey level (nearest texel, texture coordinates wrapped into [0, 1)) at the point of
    face ``f`` with barycentric coordinates ``(a, b, steps - a - b) / steps``."""
    hgt, wid = img.shape
    c = steps - a - b
    u = (a * texcoords[f, 0, 0] + b * texcoords[f, 1, 0] + c * texcoords[f, 2, 0]) / steps
    v = (a * texcoords[f, 0, 1] + b * texcoords[f, 1, 1] + c * texcoords[f, 2, 1]) / steps
    col = min(int((u % 1.0) * wid), wid - 1)
    row = min(int((1.0 - v % 1.0) * hgt), hgt - 1)
    return img[row, col]


@leaf
def texel_histogram(texcoords, faces, img, weights, steps, group, n_groups):
    """Weighted histograms of the grey levels under faces, one per group of faces, sampled on
    a triangular lattice.

    Each face is sampled at the ``(steps + 1)(steps + 2) / 2`` points whose barycentric
    coordinates are multiples of ``1 / steps`` (its corners among them); every sample adds
    its face's weight divided by the number of samples to its group's histogram. Serial, so
    the sums are the same bits for any thread count.

    Parameters
    ----------
    texcoords : (m, 3, 2) float64
        Texture coordinates of every face's corners, OBJ convention (v up).
    faces : (k,) int64
        The faces to sample.
    img : (h, w) uint8
        Grey levels, row 0 at the top.
    weights : (k,) float64
        Weight of each of ``faces`` (its area).
    steps : int
        Lattice steps along a face's edge, at least 1.
    group : (k,) int64
        Group of each of ``faces``, in ``[0, n_groups)``.
    n_groups : int

    Returns
    -------
    (n_groups, 256) float64
    """
    hist = np.zeros((n_groups, 256))
    per = (steps + 1) * (steps + 2) // 2
    for i in range(faces.shape[0]):
        w = weights[i] / per
        g = group[i]
        for a in range(steps + 1):
            for b in range(steps + 1 - a):
                hist[g, _lattice_texel(texcoords, faces[i], img, a, b, steps)] += w
    return hist


@parallel
def texel_far_share(texcoords, faces, img, levels, contrast, steps):
    """Share of each face's lattice samples (as in :func:`texel_histogram`) whose grey level
    differs from the face's level in ``levels`` by more than ``contrast``.

    Parameters
    ----------
    texcoords : (m, 3, 2) float64
    faces : (k,) int64
    img : (h, w) uint8
    levels : (k,) int64
        Grey level of each of ``faces``' ground, 0-255.
    contrast : int
        Grey levels, 0-255.
    steps : int
        Lattice steps along a face's edge, at least 1.

    Returns
    -------
    (k,) float64
        In [0, 1].
    """
    k = faces.shape[0]
    per = (steps + 1) * (steps + 2) // 2
    out = np.empty(k)
    for i in prange(k):
        far = 0
        for a in range(steps + 1):
            for b in range(steps + 1 - a):
                if abs(np.int64(_lattice_texel(texcoords, faces[i], img, a, b, steps)) - levels[i]) > contrast:
                    far += 1
        out[i] = far / per
    return out


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


@parallel
def signed_areas_2d(x, faces, out):
    """Signed area of every face.

    Parameters
    ----------
    x : (n, 2) float64
    faces : (m, 3) int32 or int64
    out : (m,) float64
    """
    for t in prange(faces.shape[0]):
        a0 = np.uint32(faces[t, 0])
        a1 = np.uint32(faces[t, 1])
        a2 = np.uint32(faces[t, 2])
        out[t] = 0.5 * ((x[a1, 0] - x[a0, 0]) * (x[a2, 1] - x[a0, 1])
                        - (x[a1, 1] - x[a0, 1]) * (x[a2, 0] - x[a0, 0]))


@leaf
def _circular_range_sum(prefix, first, count):
    """Sum of ``count`` consecutive buckets from ``first`` (any integer, taken modulo the
    number of buckets), from their prefix sums."""
    buckets = prefix.shape[0] - 1
    a = first % buckets
    if a + count <= buckets:
        return prefix[a + count] - prefix[a]
    return (prefix[buckets] - prefix[a]) + prefix[a + count - buckets]


@leaf
def _checked_sum(theta, weight, start, centre, half, first, last):
    """Sum of the weights of the angles (sorted by bucket) in buckets ``first`` .. ``last``
    (taken modulo the number of buckets) that lie within ``half`` of ``centre``, circularly."""
    two_pi = 2.0 * np.pi
    buckets = start.shape[0] - 1
    total = 0.0
    for b in range(first, last + 1):
        bb = b % buckets
        for k in range(start[bb], start[bb + 1]):
            d = theta[k] - centre
            if d > np.pi:
                d -= two_pi
            elif d < -np.pi:
                d += two_pi
            if abs(d) <= half:
                total += weight[k]
    return total


@parallel
def angular_window_sums(theta, weight, centres, half, buckets):
    """Sum of the weights of the angles within ``half`` of each centre, circularly.

    The angles are sorted into ``buckets`` equal buckets (a counting sort); a window adds
    the buckets wholly inside it from their prefix sums and checks the angles of the two
    buckets at either end one by one, so every angle counts exactly when its circular
    distance from the centre (``theta - centre`` brought into ``[-pi, pi]``) is at most
    ``half``.

    Parameters
    ----------
    theta : (n,) float64
        Angles, radians in ``[0, 2 pi)``.
    weight : (n,) float64
    centres : (m,) float64
        Window centres, radians in ``[0, 2 pi)``.
    half : float
        Half the window's width, radians, less than a quarter turn.
    buckets : int
        At least 8.

    Returns
    -------
    (m,) float64
    """
    two_pi = 2.0 * np.pi
    n = theta.shape[0]
    width = two_pi / buckets
    bucket = np.empty(n, np.int64)
    start = np.zeros(buckets + 1, np.int64)
    prefix = np.zeros(buckets + 1)
    for i in range(n):
        b = min(int(theta[i] / width), buckets - 1)
        bucket[i] = b
        start[b + 1] += 1
        prefix[b + 1] += weight[i]
    for b in range(buckets):
        start[b + 1] += start[b]
        prefix[b + 1] += prefix[b]
    sorted_theta, sorted_weight = np.empty(n), np.empty(n)
    fill = start[:-1].copy()
    for i in range(n):
        sorted_theta[fill[bucket[i]]] = theta[i]
        sorted_weight[fill[bucket[i]]] = weight[i]
        fill[bucket[i]] += 1
    m = centres.shape[0]
    out = np.empty(m)
    for j in prange(m):
        c = centres[j]
        first = int(np.floor((c - half) / width)) - 1
        last = int(np.floor((c + half) / width)) + 1
        if last - first >= 4:  # buckets first + 2 .. last - 2 lie wholly inside
            out[j] = (_circular_range_sum(prefix, first + 2, last - first - 3)
                      + _checked_sum(sorted_theta, sorted_weight, start, c, half, first, first + 1)
                      + _checked_sum(sorted_theta, sorted_weight, start, c, half, last - 1, last))
        else:
            out[j] = _checked_sum(sorted_theta, sorted_weight, start, c, half, first, last)
    return out
