"""What the bake draws besides the painting: the marks of the rollout (where attachments met
the wall, where a repeat starts, where the scan folds), the scale layer's place on the image,
and the image's figures for ``NAME.bake.json``."""
from __future__ import annotations

import math

import numpy as np

from potflat.bake import annotate
from potflat.mesh.tolerances import ROUNDING
from potflat.raster.render import Renderer, _chart_mask, outline_pixels


def _stats(values: np.ndarray, weights: np.ndarray | None = None) -> dict:
    values = np.asarray(values, float)
    if not len(values):
        return {"mean": 0.0, "p95": 0.0, "max": 0.0}
    mean = float(np.average(values, weights=weights)) if weights is not None and weights.sum() > 0 else float(values.mean())
    return {"mean": mean, "p95": float(np.percentile(values, 95)), "max": float(values.max())}


def image_figures(r: Renderer, covered_px: float) -> dict:
    """The figures of ``NAME.bake.json``: the image's grid and texture, the distortion maps'
    statistics, the whole surface's figures (``r.summary``) and the painted zone's
    (``r.zone``); ``covered_px``: the painting's covered pixels, summed."""
    g, flat = r.grid, r.flat
    mpu = flat.mesh.mm_per_unit
    fv = r.face_values
    valid = r.valid
    w = r.area_3d[valid]
    # JSON has no infinity: a collapsed flat triangle (anisotropy inf) is reported as null
    summary = {k: (v if not isinstance(v, float) or math.isfinite(v) else None) for k, v in r.summary.as_dict().items()}
    figures = {
        "px_per_mm": g.px_per_mm,
        "dpi": g.px_per_mm * 25.4,
        "units": flat.mesh.units,
        "mm_per_unit": mpu,
        "px_per_unit": g.scale,
        "image_px": [g.width, g.height],
        "image_mm": [g.width / g.px_per_mm, g.height / g.px_per_mm],
        "origin_uv": [float(g.origin[0]), float(g.origin[1])],
        "supersample": r.n,
        "mip_levels": r.mip_levels,
        "texture": str(flat.mesh.texture_path) if r.texture is not None else None,
        "texture_px": list(r.texture.shape[1::-1]) if r.texture is not None else None,
        "texels_per_pixel_median": r.texels_per_pixel_median,
        "painting": "texture" if r.texture is not None else "vertex colours" if flat.mesh.vertex_colors is not None
        else "relief",
        "stress": {**_stats(r.vertex_stress), "unit": "sqrt(mm)"},
        "area": {**_stats(np.abs(fv["area"][valid]), w), "unit": "|ln(flat area / 3D area)|"},
        "anisotropy": {**_stats(fv["anisotropy"][valid], w), "unit": "sigma_max / sigma_min"},
        "distortion": summary,
        **r.zone.as_dict(),
        "covered_area_mm2": covered_px / g.px_per_mm ** 2,
        "flattened_area_mm2": float(np.abs(r.area_2d).sum()) * mpu ** 2,
        "surface_area_mm2": float(r.area_3d.sum()) * mpu ** 2,
    }
    return figures


def attachment_rows(share: np.ndarray) -> np.ndarray:
    """RGBA rows of the attachment mask from the covered share of marked faces per pixel."""
    alpha = np.nan_to_num(share, nan=0.0)
    out = np.zeros(share.shape + (4,), np.uint8)
    out[..., :3] = ATTACHMENT_COLOUR[:3]
    out[..., 3] = np.round(alpha * ATTACHMENT_COLOUR[3]).astype(np.uint8)
    return out


def rgba16(rgb: np.ndarray, coverage: np.ndarray) -> np.ndarray:
    out = np.empty(rgb.shape[:2] + (4,), np.uint16)
    out[..., :3] = np.rint(np.clip(np.nan_to_num(rgb, nan=0.0), 0.0, 1.0) * 65535.0)
    out[..., 3] = np.rint(coverage * 65535.0)
    return out


#: Colour (RGBA) of the faces where a left-out attachment (handle, spout, knob) met the wall.
ATTACHMENT_COLOUR = (230, 0, 160, 220)


#: Colour (RGBA) of the outline and hatching of the places where the scan folds over itself in 3D.
FOLDED_COLOUR = (255, 0, 255, 255)


#: Spacing (pixels) of the hatching's diagonal lines.
FOLDED_HATCH_PX = 6


def folded_hatch(share: np.ndarray, r0: int) -> np.ndarray:
    """Pixels (k, w) bool marking where the scan folds in 3D: the outline of the faces'
    footprint (their share crossing one half) and diagonal hatching inside it."""
    rows, cols = np.indices(share.shape)
    hatch = (np.nan_to_num(share, nan=0.0) >= 0.5) & ((rows + r0 + cols) % FOLDED_HATCH_PX == 0)
    return outline_pixels(share, 0.5) | hatch


#: Colour (RGBA) of the dashed line where a rollout's repeat past 360 degrees (``overlap``) starts.
REPEAT_COLOUR = (255, 0, 200, 255)


#: Dash length of that line, pixels.
REPEAT_DASH_PX = 6


def repeat_line(share: np.ndarray, r0: int) -> np.ndarray:
    """Pixels (k, w) bool of a dashed line where the repeated part starts: where the share of
    repeated faces crosses one half from left to right (the line runs from foot to mouth)."""
    rep = np.nan_to_num(share, nan=-1.0)
    inside = rep >= 0.5
    edge = np.zeros_like(inside)
    edge[:, 1:] = inside[:, 1:] & (rep[:, :-1] >= 0) & ~inside[:, :-1]
    edge[:, :-1] |= edge[:, 1:].copy()  # two pixels wide
    rows = (np.arange(r0, r0 + len(rep)) // REPEAT_DASH_PX) % 2 == 0
    return edge & rows[:, None]


#: Shortest scale bar drawn into ``NAME.png``, as a fraction of the default (a quarter of the width).
MIN_BAR_FRACTION = 0.1


def scale_layer_on_image(r: Renderer, grid: bool):
    """The scale layer to draw into ``NAME.png``, placed where it covers no painting.

    The painting's footprint is rasterised on a grid of at most
    :data:`potflat.bake.annotate.FREE_SPOT_MASK_PX` pixels a side and the free place nearest the
    bottom-left corner is taken, for the longest round bar (from a quarter of the image width
    down to :data:`MIN_BAR_FRACTION` of that) that has one; when none has, a band is added
    below the image with the default bar.

    Returns
    -------
    layer : ScaleLayer
    band : int
        Rows added below the image (0 when the bar fits beside the painting).
    """
    g = r.grid
    f = max(1, math.ceil(max(g.width, g.height) / annotate.FREE_SPOT_MASK_PX))
    wc, hc = math.ceil(g.width / f), math.ceil(g.height / f)
    uv = r.flat.uv[r.faces]  # (m, 3, 2)
    tex = np.empty_like(uv)
    tex[..., 0] = (uv[..., 0] - g.origin[0]) * g.scale / f / wc
    tex[..., 1] = 1.0 - (g.origin[1] - uv[..., 1]) * g.scale / f / hc
    covered = _chart_mask(tex, hc, wc)
    default = annotate.ScaleLayer(g.width, g.height, g.px_per_mm, grid=grid)
    bar = default.bar_mm
    while bar >= MIN_BAR_FRACTION * default.bar_mm * (1 - ROUNDING):
        probe = annotate.ScaleLayer(g.width, g.height, g.px_per_mm, grid=grid, bar_mm=bar)
        bw, bh = probe.box_size
        spot = annotate.free_spot(covered, (math.ceil(bw / f) + 1, math.ceil(bh / f) + 1), math.ceil(probe.margin / f))
        if spot is not None:
            return annotate.ScaleLayer(g.width, g.height, g.px_per_mm, grid=grid, bar_mm=bar,
                                       at=(spot[0] * f, spot[1] * f)), 0
        bar = annotate.nice_length(bar * 0.99)
    bw, bh = default.box_size
    band = bh + 2 * default.margin
    return annotate.ScaleLayer(g.width, g.height + band, g.px_per_mm, grid=grid, bar_mm=default.bar_mm,
                               at=(default.margin, g.height + default.margin)), band
