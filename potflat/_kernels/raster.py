"""Triangle rasterisation and barycentric sampling kernels for the bake stage.

Raster coordinates: ``x`` to the right, ``y`` down, in samples; sample ``(r, c)`` has its
centre at ``(c + 0.5, r + 0.5)``. Triangles are binned into blocks of rows; a parallel
loop runs over blocks, so every thread writes only its own rows (no races) and, within a
block, triangles are visited in increasing face index: where triangles overlap (a fold)
the lowest face index wins, whatever the number of threads.
"""
from __future__ import annotations

import numpy as np

from potflat._kernels._jit import leaf, parallel, prange


@leaf
def bin_triangles(pix: np.ndarray, faces: np.ndarray, block_rows: float, nblocks: int):
    """Bin triangles into horizontal blocks of ``block_rows`` raster rows.

    Parameters
    ----------
    pix : (n, 2) float64
        Vertex positions in raster coordinates.
    faces : (m, 3) int64
    block_rows : float
        Rows per block (in the units of ``pix``).
    nblocks : int

    Returns
    -------
    ptr : (nblocks + 1,) int64
        Block ``b`` holds ``idx[ptr[b]:ptr[b + 1]]``.
    idx : (k,) int64
        Face indices, ascending within each block.
    """
    m = faces.shape[0]
    b0 = np.empty(m, np.int64)
    b1 = np.empty(m, np.int64)
    counts = np.zeros(nblocks + 1, np.int64)
    for f in range(m):
        y0 = pix[faces[f, 0], 1]
        y1 = pix[faces[f, 1], 1]
        y2 = pix[faces[f, 2], 1]
        lo = min(y0, min(y1, y2))
        hi = max(y0, max(y1, y2))
        a = int(np.floor(lo / block_rows))
        b = int(np.floor(hi / block_rows))
        a = min(max(a, 0), nblocks - 1)
        b = min(max(b, 0), nblocks - 1)
        b0[f] = a
        b1[f] = b
        for k in range(a, b + 1):
            counts[k + 1] += 1
    ptr = np.cumsum(counts)
    fill = ptr[:-1].copy()
    idx = np.empty(ptr[-1], np.int64)
    for f in range(m):
        for k in range(b0[f], b1[f] + 1):
            idx[fill[k]] = f
            fill[k] += 1
    return ptr, idx


@parallel
def rasterize_rows(pix, faces, ptr, idx, block_rows, row0, nrows, width, eps, face_out, bary_out):
    """Find the triangle under each sample of raster rows ``[row0, row0 + nrows)``.

    Parameters
    ----------
    pix : (n, 2) float64
        Vertex positions in raster coordinates.
    faces : (m, 3) int64
    ptr, idx : int64 arrays
        Row-block bins from :func:`bin_triangles` (blocks of ``block_rows`` rows).
    block_rows : int
        Raster rows per block; ``row0`` must be a multiple of it.
    row0, nrows, width : int
        The rows to rasterise and the raster width.
    eps : float
        Barycentric tolerance, so samples exactly on a shared edge are never lost.
    face_out : (nrows, width) int32
        Output: face index under each sample, -1 where none (must be filled with -1).
    bary_out : (nrows, width, 2) float64
        Output: barycentric weights of corners 1 and 2 (clamped into the triangle).
    """
    nblk = (nrows + block_rows - 1) // block_rows
    first = row0 // block_rows
    for bi in prange(nblk):
        b = first + bi
        ylo = b * block_rows
        yhi = min(ylo + block_rows, row0 + nrows)
        for k in range(ptr[b], ptr[b + 1]):
            f = idx[k]
            x0 = pix[faces[f, 0], 0]
            y0 = pix[faces[f, 0], 1]
            x1 = pix[faces[f, 1], 0]
            y1 = pix[faces[f, 1], 1]
            x2 = pix[faces[f, 2], 0]
            y2 = pix[faces[f, 2], 1]
            d = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
            if d == 0.0:
                continue
            rlo = max(ylo, int(np.ceil(min(y0, min(y1, y2)) - 0.5 - eps)))
            rhi = min(yhi - 1, int(np.floor(max(y0, max(y1, y2)) - 0.5 + eps)))
            clo = max(0, int(np.ceil(min(x0, min(x1, x2)) - 0.5 - eps)))
            chi = min(width - 1, int(np.floor(max(x0, max(x1, x2)) - 0.5 + eps)))
            for r in range(rlo, rhi + 1):
                py = r + 0.5
                rr = r - row0
                for c in range(clo, chi + 1):
                    if face_out[rr, c] >= 0:
                        continue
                    px = c + 0.5
                    w1 = ((px - x0) * (y2 - y0) - (x2 - x0) * (py - y0)) / d
                    w2 = ((x1 - x0) * (py - y0) - (px - x0) * (y1 - y0)) / d
                    w0 = 1.0 - w1 - w2
                    if w0 >= -eps and w1 >= -eps and w2 >= -eps:
                        w1 = min(max(w1, 0.0), 1.0)
                        w2 = min(max(w2, 0.0), 1.0 - w1)
                        face_out[rr, c] = f
                        bary_out[rr, c, 0] = w1
                        bary_out[rr, c, 1] = w2


@parallel
def interpolate_vertex_attr(face, bary, faces, attr, out):
    """Barycentric interpolation of a per-vertex attribute at each sample.

    Parameters
    ----------
    face : (h, w) int32
        Face under each sample (-1: none).
    bary : (h, w, 2) float64
    faces : (m, 3) int64
    attr : (n, k) float64
    out : (h, w, k) float32
        Output; NaN where ``face`` is -1.
    """
    h, w = face.shape
    k = attr.shape[1]
    for r in prange(h):
        for c in range(w):
            f = face[r, c]
            if f < 0:
                for j in range(k):
                    out[r, c, j] = np.nan
                continue
            w1 = bary[r, c, 0]
            w2 = bary[r, c, 1]
            w0 = 1.0 - w1 - w2
            a = faces[f, 0]
            b = faces[f, 1]
            e = faces[f, 2]
            for j in range(k):
                out[r, c, j] = w0 * attr[a, j] + w1 * attr[b, j] + w2 * attr[e, j]


@leaf
def _bilinear(tex, x, y, ch):
    """Bilinear tap of channel ``ch`` at continuous texel position (x, y), edges clamped."""
    h, w = tex.shape[0], tex.shape[1]
    fx = x - 0.5
    fy = y - 0.5
    i0 = int(np.floor(fx))
    j0 = int(np.floor(fy))
    tx = fx - i0
    ty = fy - j0
    i1 = min(max(i0 + 1, 0), w - 1)
    j1 = min(max(j0 + 1, 0), h - 1)
    i0 = min(max(i0, 0), w - 1)
    j0 = min(max(j0, 0), h - 1)
    top = (1.0 - tx) * tex[j0, i0, ch] + tx * tex[j0, i1, ch]
    bot = (1.0 - tx) * tex[j1, i0, ch] + tx * tex[j1, i1, ch]
    return (1.0 - ty) * top + ty * bot


@parallel
def sample_texture(face, bary, texcoords, lod, levels, out):
    """Trilinear texture sampling through per-corner texture coordinates.

    Parameters
    ----------
    face : (h, w) int32
        Face under each sample (-1: none).
    bary : (h, w, 2) float64
    texcoords : (m, 3, 2) float64
        Per-corner texture coordinates, OBJ convention ((0, 0) bottom-left, v up).
    lod : (m,) float64
        Mip level of detail per face (0: full resolution; fractions blend two levels).
    levels : typed List of (H_l, W_l, C) arrays
        The mip pyramid, level 0 first.
    out : (h, w, C) float32
        Output in the texture's value range; NaN where ``face`` is -1.
    """
    h, w = face.shape
    nch = out.shape[2]
    top = len(levels) - 1
    H0 = levels[0].shape[0]
    W0 = levels[0].shape[1]
    for r in prange(h):
        for c in range(w):
            f = face[r, c]
            if f < 0:
                for j in range(nch):
                    out[r, c, j] = np.nan
                continue
            w1 = bary[r, c, 0]
            w2 = bary[r, c, 1]
            w0 = 1.0 - w1 - w2
            s = w0 * texcoords[f, 0, 0] + w1 * texcoords[f, 1, 0] + w2 * texcoords[f, 2, 0]
            t = w0 * texcoords[f, 0, 1] + w1 * texcoords[f, 1, 1] + w2 * texcoords[f, 2, 1]
            x = s * W0
            y = (1.0 - t) * H0
            lv = min(max(lod[f], 0.0), float(top))
            l0 = int(np.floor(lv))
            frac = lv - l0
            l1 = min(l0 + 1, top)
            t0 = levels[l0]
            sx0 = t0.shape[1] / W0
            sy0 = t0.shape[0] / H0
            t1 = levels[l1]
            sx1 = t1.shape[1] / W0
            sy1 = t1.shape[0] / H0
            for j in range(nch):
                v = _bilinear(t0, x * sx0, y * sy0, j)
                if frac > 0.0:
                    v = (1.0 - frac) * v + frac * _bilinear(t1, x * sx1, y * sy1, j)
                out[r, c, j] = v
