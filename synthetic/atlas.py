"""The synthetic vessels' multi-chart texture atlas, packed and painted as photogrammetry
software bakes one (UV seams inside the surface).
"""
from __future__ import annotations

import itertools
import math

import numpy as np
from potflat_synthetic.geometry import (
    _Generatrix,
    _wrap,
)
from potflat_synthetic.spec import (
    _GUTTER_PX,
    ATLAS_BACKGROUND,
    PART_BREAK,
    PART_HANDLE,
    PART_INNER,
)


def _shelf_pack(sizes, width, pad):
    """Bottom-up shelf packing of rectangles ``sizes`` (k, 2); positions and total height."""
    order = np.argsort(-sizes[:, 1], kind="stable")
    pos = np.zeros_like(sizes)
    x = y = float(pad)
    shelf = 0.0
    for i in order:
        w, hgt = sizes[i]
        if x + w + pad > width and x > pad:
            y += shelf + pad
            x, shelf = float(pad), 0.0
        pos[i] = (x, y)
        x += w + pad
        shelf = max(shelf, hgt)
    return pos, y + shelf + pad


def _atlas_coords(chart_uv, face_chart, size, rng):
    """Place per-chart layouts into a ``size``-pixel square: texture coords (m, 3, 2)."""
    import cv2

    n_ch = int(face_chart.max()) + 1
    dims = np.zeros((n_ch, 2))
    order = np.argsort(face_chart, kind="stable")
    bounds = np.searchsorted(face_chart[order], np.arange(n_ch + 1))
    local = chart_uv[order].reshape(-1, 2)
    for c in range(n_ch):
        uv = local[3 * bounds[c]:3 * bounds[c + 1]]  # a view: edited in place
        if len(uv) == 0:
            continue
        # align the chart's minimum-area box with the atlas, then a random quarter turn
        sub = uv[:: max(1, len(uv) // 60000)].astype(np.float32)
        (_, _), (_, _), box_deg = cv2.minAreaRect(sub)
        a = -math.radians(box_deg) + rng.integers(0, 4) * math.pi / 2
        rot = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
        uv[:] = uv @ (rot.T * rng.uniform(0.8, 1.2))
        uv -= uv.min(axis=0)
        dims[c] = uv.max(axis=0)
    pad = 2 * _GUTTER_PX + 2
    lo, hi = 0.0, (size - 2 * pad) / max(dims.max(), 1e-12)
    for _ in range(50):
        k = 0.5 * (lo + hi)
        _, total = _shelf_pack(dims * k, size, pad)
        if total <= size and (dims * k).max() + 2 * pad <= size:
            lo = k
        else:
            hi = k
    pos, _ = _shelf_pack(dims * lo, size, pad)
    px = np.empty_like(chart_uv)
    px[order] = local.reshape(-1, 3, 2) * lo + pos[face_chart[order]][:, None, :]
    return px / size, lo


def _chart_layouts(V, F, vs, vth, face_part, face_handle, handle_radii, g: _Generatrix, n_sectors,
                   rng, preset=None):
    """Chart of every face and its corners' local 2D layout (mm), CCW.

    ``preset`` = (piece id per face, -1 for none; corner layouts (m, 3, 2)) for faces laid
    out by the caller (a sherd's break faces, welded handle roots), one chart per piece.
    """
    m = len(F)
    sc = vs[F].mean(axis=1)
    chart = np.full(m, -1, np.int64)
    uv = np.zeros((m, 3, 2))
    next_id = 0
    body = (face_part != PART_HANDLE) & (face_part != PART_BREAK)
    back = (face_part == PART_INNER) & (not math.isfinite(g.s_inner))  # a thick sherd's back
    # planar charts: the flat base and the inner floor
    for sel in (body & (sc < g.s_outer[0]), body & (sc > g.s_floor)):
        if np.any(sel):
            chart[sel] = next_id
            uv[sel] = V[F[sel]][:, :, :2]
            next_id += 1
    # wall charts: angle sectors x height bands, unwrapped (r * dtheta, s)
    phase = rng.uniform(0.0, 2 * math.pi)
    cth = np.arctan2(V[F, 1].mean(axis=1), V[F, 0].mean(axis=1))
    sector = np.floor(((cth - phase) % (2 * math.pi)) / (2 * math.pi / n_sectors)).astype(np.int64)
    sector = np.minimum(sector, n_sectors - 1)
    pieces = [(g.s_outer[0], g.s_outer[1]), (g.s_outer[1], g.s_floor)]
    for (lo, hi), rest in itertools.product(pieces, (body & ~back & (chart < 0), back)):
        if not math.isfinite(hi):
            continue
        edges = np.linspace(lo, hi, 3)
        band = np.clip(np.searchsorted(edges, sc, side="right") - 1, 0, 1)
        in_piece = rest & (sc >= lo) & (sc <= hi) if hi < g.s_floor else rest & (sc >= lo)
        for b in range(2):
            for k in range(n_sectors):
                sel = in_piece & (band == b) & (sector == k)
                if not np.any(sel):
                    continue
                centre = phase + (k + 0.5) * 2 * math.pi / n_sectors
                vv = F[sel]
                r = np.hypot(V[vv, 0], V[vv, 1])
                uv[sel, :, 0] = r * _wrap(vth[vv] - centre)
                uv[sel, :, 1] = vs[vv]
                chart[sel] = next_id
                next_id += 1
                rest &= ~sel
    if preset is not None:
        piece, corner_uv = preset
        for p in np.unique(piece[piece >= 0]):
            sel = piece == p
            uv[sel] = corner_uv[sel]
            chart[sel] = next_id
            next_id += 1
    # handles: two charts per tube (half turns), unwrapped (radius * dphi, arc length)
    for h, radius in enumerate(handle_radii):
        fsel = np.flatnonzero(face_handle == h)
        vv = F[fsel]
        cphi = np.arctan2(np.sin(vth[vv]).mean(axis=1), np.cos(vth[vv]).mean(axis=1)) % (2 * math.pi)
        for half in range(2):
            sel = fsel[(cphi >= math.pi) == bool(half)]
            if len(sel) == 0:
                continue
            vv = F[sel]
            uv[sel, :, 0] = radius * _wrap(vth[vv] - math.pi * (half + 0.5))
            uv[sel, :, 1] = vs[vv]
            chart[sel] = next_id
            next_id += 1
    if np.any(chart < 0):
        raise RuntimeError("face without a texture chart")
    # every chart counter-clockwise, like the surface seen from outside
    p = uv
    area = ((p[:, 1, 0] - p[:, 0, 0]) * (p[:, 2, 1] - p[:, 0, 1])
            - (p[:, 2, 0] - p[:, 0, 0]) * (p[:, 1, 1] - p[:, 0, 1]))
    mirrored = np.bincount(chart, weights=area, minlength=next_id) < 0
    uv[mirrored[chart], :, 0] *= -1.0
    return chart, uv


def _render_atlas(vessel_paint, plain, V_world, F, face_part, texcoords, size, shade=None) -> np.ndarray:
    """Texture atlas: every texel painted at its 3D point, with gutters around the charts.

    Texels whose centre lies within :data:`_GUTTER_PX` pixels outside a chart take the
    painting at the nearest point of the nearest triangle, so bilinear sampling at chart
    borders never reads the background. ``shade(colours, world_points)``, when given,
    lights the texels' colours.
    """
    from potflat_synthetic._kernels import rasterize_faces

    tri = np.empty(texcoords.shape, np.float64)
    tri[..., 0] = texcoords[..., 0] * size
    tri[..., 1] = (1.0 - texcoords[..., 1]) * size
    face, bary, _ = rasterize_faces(np.ascontiguousarray(tri), size, size, float(_GUTTER_PX))
    cov = face >= 0
    fid = face[cov]
    P = np.einsum("nk,nkd->nd", bary[cov], V_world[F[fid]])
    colours = np.empty((len(fid), 3), np.uint8)
    part = face_part[fid]
    painted = np.ones(len(fid), bool)
    for p, rgb in plain.items():
        colours[part == p] = rgb
        painted &= part != p
    colours[painted] = vessel_paint(P[painted])
    if shade is not None:
        colours = shade(colours, P)
    img = np.empty((size, size, 3), np.uint8)
    img[:] = ATLAS_BACKGROUND
    img[cov] = colours
    return img

