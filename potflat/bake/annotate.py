"""Colour scales, legends, scale bar, metric grid and the comparison sheet of the bake stage.

Drawn with matplotlib (colour bars, the sheet) and Pillow (scale bar, grid), always at
the bake's own pixel grid so every layer lines up with ``NAME.png``.
"""
from __future__ import annotations

import io
import math
from dataclasses import dataclass

import numpy as np

from potflat.bake._kernels import heat_rgba
from potflat.mesh import distortion
from potflat.mesh.distortion import bounds, percent_from_log
from potflat.mesh.tolerances import ROUNDING
from potflat.types import FlatMesh

#: Longest side in pixels of each baked panel of the comparison sheet.
SHEET_PANEL_PX = 900

#: Opacity of the heat map in the stress overlay.
OVERLAY_ALPHA = 0.6
#: Grid spacing in millimetres.
GRID_MM = 10.0


@dataclass(frozen=True)
class MapScale:
    """How a distortion map's values become colours.

    Attributes
    ----------
    name : str
        ``stress``, ``area`` or ``anisotropy``.
    lo, hi : float
        Values mapped to the ends of the colour map (values beyond are clipped).
    cmap : str
        Matplotlib colour map name.
    label : str
        Quantity and unit, shown under the colour bar.
    outline : str
        Colour of the painted zone's outline (a key of :data:`OUTLINE_RGBA`): one that stands
        out against the map's colour for no distortion, which fills the zone.
    extend : str
        Ends of the colour bar with an arrow for values beyond: ``max`` or ``both``.
    """

    name: str
    lo: float
    hi: float
    cmap: str
    label: str
    outline: str = "white"
    extend: str = "max"

    def lut(self) -> np.ndarray:
        """(256, 3) uint8 colour table."""
        import matplotlib

        cm = matplotlib.colormaps[self.cmap]
        return np.rint(cm(np.linspace(0.0, 1.0, 256))[:, :3] * 255).astype(np.uint8)


def map_scale(name: str, values: np.ndarray, *, hi: float | None = None) -> MapScale:
    """The colour scale of map ``name`` for these per-vertex (stress) or per-face values.

    The upper end is the 99th percentile (so one bad triangle does not wash out the map);
    the colour bar shows an arrow when values go beyond it.

    Parameters
    ----------
    name : str
        ``stress`` (% length error around each vertex), ``area`` (ln area ratio) or ``anisotropy`` (ratio >= 1).
    values : (k,) float64
    hi : float, optional
        Fixed upper end (to share one scale between images).

    Returns
    -------
    MapScale
    """
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    p99 = lambda x: float(np.percentile(x, 99)) if len(x) else 0.0
    if name == "stress":
        top = hi if hi is not None else max(p99(v), 0.5)
        return MapScale(name, 0.0, top, "magma",
                        "length error around each point, %")
    if name == "area":
        half = hi if hi is not None else max(p99(np.abs(v)), 0.035)
        return MapScale(name, -half, half, "RdBu_r", "area ratio flat / 3D (log scale)",
                        outline="black", extend="both")  # (white at ratio 1)
    if name == "anisotropy":
        top = hi if hi is not None else max(p99(v), 1.05)
        return MapScale(name, 1.0, top, "viridis", "anisotropy σmax / σmin (1 = no shear)")
    raise ValueError(f"unknown map {name!r}")


def colorize(values: np.ndarray, scale: MapScale, coverage: np.ndarray) -> np.ndarray:
    """Heat map rows: (k, w) values and coverage -> (k, w, 4) uint8 (transparent outside)."""

    values = np.ascontiguousarray(values, dtype=np.float32)
    out = np.empty(values.shape + (4,), np.uint8)
    heat_rgba(values, float(scale.lo), float(scale.hi), scale.lut(), np.ascontiguousarray(coverage, np.float32),
              values, 1.0, out)
    return out


def overlay(rgb: np.ndarray, values: np.ndarray, scale: MapScale, coverage: np.ndarray) -> np.ndarray:
    """Heat map over the greyscale painting: (k, w, 3) rgb in [0, 1], (k, w) values -> (k, w, 4) uint8."""

    grey = np.ascontiguousarray(rgb @ np.array([0.299, 0.587, 0.114], np.float32), dtype=np.float32)
    out = np.empty(values.shape + (4,), np.uint8)
    heat_rgba(np.ascontiguousarray(values, dtype=np.float32), float(scale.lo), float(scale.hi), scale.lut(),
              np.ascontiguousarray(coverage, np.float32), grey, OVERLAY_ALPHA, out)
    return out


#: Colours of the important zone's outline on the maps (RGBA), by :attr:`MapScale.outline`.
OUTLINE_RGBA = {"white": (255, 255, 255, 255), "black": (0, 0, 0, 255)}


def draw_outline(rows: np.ndarray, outline: np.ndarray | None, rgba=OUTLINE_RGBA["white"]) -> np.ndarray:
    """Map rows (k, w, 4) uint8 with an outline (k, w) bool drawn in ``rgba`` (the important
    zone's: :data:`OUTLINE_RGBA` of the map's :attr:`MapScale.outline`) (in place; returned).
    ``None``: unchanged."""
    if outline is not None:
        rows[outline] = rgba
    return rows


def _colorbar(ax, scale: MapScale, fontsize: float, orientation: str = "horizontal"):
    import matplotlib
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.ticker import FixedLocator, FuncFormatter, MaxNLocator

    mappable = ScalarMappable(Normalize(scale.lo, scale.hi), matplotlib.colormaps[scale.cmap])
    cb = ax.figure.colorbar(mappable, cax=ax, orientation=orientation, extend=scale.extend)
    cb.set_label(scale.label, fontsize=fontsize)
    cb.ax.tick_params(labelsize=fontsize)
    axis = cb.ax.xaxis if orientation == "horizontal" else cb.ax.yaxis
    if scale.name == "area":
        # ticks at round area ratios, placed on the (natural) log axis
        ratios = MaxNLocator(6).tick_values(math.exp(scale.lo), math.exp(scale.hi))
        ticks = np.log(ratios[(ratios > 0)])
        axis.set_major_locator(FixedLocator(ticks[(ticks >= scale.lo) & (ticks <= scale.hi)]))
        axis.set_major_formatter(FuncFormatter(lambda t, _: f"{math.exp(t):.3g}"))
    else:
        axis.set_major_locator(MaxNLocator(6))
    return cb


def legend_band(scale: MapScale, width: int) -> np.ndarray:
    """A colour bar with its label and unit, as rows to put under a map.

    Parameters
    ----------
    scale : MapScale
    width : int
        Image width in pixels.

    Returns
    -------
    (h, width, 4) uint8
        White legend box at the left, transparent elsewhere; ``h`` grows with ``width``.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    bh = int(np.clip(round(width * 0.08), 72, 260))
    lw = int(min(width, 7 * bh))
    fig = Figure(figsize=(lw / 100.0, bh / 100.0), dpi=100, facecolor="white")
    canvas = FigureCanvasAgg(fig)
    fontsize = bh * 0.14 * 0.72  # points at 100 dpi: 14% of the band height in pixels
    cax = fig.add_axes([0.05, 0.66, 0.9, 0.2])
    _colorbar(cax, scale, fontsize)
    canvas.draw()
    box = np.asarray(canvas.buffer_rgba())
    band = np.zeros((bh, width, 4), np.uint8)
    band[:, :lw] = box[:bh, :lw]
    return band


def _font(size_px: int):
    from matplotlib import font_manager
    from PIL import ImageFont

    return ImageFont.truetype(font_manager.findfont("DejaVu Sans"), max(6, int(size_px)))


def nice_length(limit: float) -> float:
    """The largest 1-2-5 x 10^k not above ``limit`` (> 0)."""
    k = math.floor(math.log10(limit))
    for m in (5.0, 2.0, 1.0):
        if m * 10.0 ** k <= limit * (1 + ROUNDING):
            return m * 10.0 ** k
    return 10.0 ** k


class ScaleLayer:
    """Scale bar (and optional 10 mm grid) drawn at the bake's pixel grid.

    Parameters
    ----------
    width, height : int
        Size of ``NAME.png``.
    px_per_mm : float
    grid : bool
        Draw grid lines every :data:`GRID_MM` from the top-left image corner, labelled in mm.

    at : (int, int), optional
        Top-left pixel ``(x, y)`` of the bar's box; default: the bottom-left corner of the image.
    bar_mm : float, optional
        Bar length; default: the round length nearest below a quarter of the image width.
    """

    def __init__(self, width: int, height: int, px_per_mm: float, *, grid: bool = False,
                 at: tuple[int, int] | None = None, bar_mm: float | None = None):
        self.width, self.height, self.px_per_mm, self.grid = width, height, px_per_mm, grid
        self.bar_mm = bar_mm if bar_mm is not None else nice_length(0.25 * width / px_per_mm)
        bar_px = self.bar_mm * px_per_mm
        self.font_px = int(np.clip(round(bar_px / 9), 10, 96))
        self.grid_font_px = int(np.clip(round(GRID_MM * px_per_mm * 0.3), 9, 48))
        self.thick = int(max(3, round(bar_px / 30)))
        self.margin = max(4, self.font_px // 2)
        self.label_step = next((s for s in (10, 20, 50, 100, 200, 500, 1000, 2000, 5000)
                                if s * px_per_mm >= 4 * self.grid_font_px), 1e9)
        bw, bh = self.box_size
        self.at = at if at is not None else (self.margin, self.height - bh - self.margin)

    def _draw_bar(self, draw, x0: float, y0: float) -> None:
        ppm, L = self.px_per_mm, self.bar_mm
        lead = round(L / 10 ** math.floor(math.log10(L)))
        segments = 4 if lead == 2 else 5
        x_end = x0 + L * ppm
        for i in range(segments):
            xa = x0 + i * L * ppm / segments
            xb = x0 + (i + 1) * L * ppm / segments
            draw.rectangle([round(xa), y0, max(round(xa), round(xb) - 1), y0 + self.thick - 1],
                           fill=(0, 0, 0, 255) if i % 2 == 0 else (255, 255, 255, 255), outline=(0, 0, 0, 255))
        label = f"{L:g} mm"
        draw.text((x0, y0 + self.thick + self.margin // 2), "0", fill=(0, 0, 0, 255), font=self._f)
        draw.text((x_end, y0 + self.thick + self.margin // 2), label, fill=(0, 0, 0, 255), font=self._f, anchor="ra")

    @property
    def _f(self):
        if not hasattr(self, "_font_cache"):
            self._font_cache = _font(self.font_px), _font(self.grid_font_px)
        return self._font_cache[0]

    @property
    def _gf(self):
        self._f  # noqa: B018 - fills the cache
        return self._font_cache[1]

    @property
    def box_size(self) -> tuple[int, int]:
        """Width and height in pixels of the bar's white box."""
        return (math.ceil(self.bar_mm * self.px_per_mm) + 2 * self.margin,
                self.thick + self.font_px + 3 * self.margin)

    def bar_image(self) -> np.ndarray:
        """The scale bar alone on white, at true scale. Shape (h, w, 4) uint8."""
        from PIL import Image, ImageDraw

        w, h = self.box_size
        img = Image.new("RGBA", (w, h), (255, 255, 255, 255))
        self._draw_bar(ImageDraw.Draw(img), self.margin, self.margin)
        return np.asarray(img)

    def rows(self, r0: int, r1: int) -> np.ndarray:
        """Rows ``r0:r1`` of the layer (transparent but for bar, grid and labels). Shape (k, w, 4) uint8."""
        from PIL import Image, ImageDraw

        img = Image.new("RGBA", (self.width, r1 - r0), (0, 0, 0, 0))
        draw = ImageDraw.Draw(img)
        ppm = self.px_per_mm
        if self.grid:
            line = max(1, round(ppm * 0.1))
            colour = (40, 40, 40, 150)
            step = GRID_MM * ppm
            for i in range(1, int(self.width / step) + 1):
                x = round(i * step)
                draw.line([(x, 0), (x, r1 - r0)], fill=colour, width=line)
            for i in range(max(1, int(r0 / step)), int(r1 / step) + 1):
                y = round(i * step) - r0
                draw.line([(0, y), (self.width, y)], fill=colour, width=line)
            k = round(self.label_step / GRID_MM)
            for i in range(k, int(self.width / step) + 1, k):
                draw.text((round(i * step) + 2, 2 - r0), f"{i * GRID_MM:g}", fill=(0, 0, 0, 255), font=self._gf)
            for i in range(k, int(self.height / step) + 1, k):
                y = round(i * step)
                if r0 - 2 * self.grid_font_px <= y <= r1 + 2 * self.grid_font_px:
                    draw.text((2, y + 2 - r0), f"{i * GRID_MM:g}", fill=(0, 0, 0, 255), font=self._gf)
            draw.text((2, 2 - r0), "mm", fill=(0, 0, 0, 255), font=self._gf)
        bw, bh = self.box_size
        bx, by = self.at
        if by + bh >= r0 and by <= r1:
            draw.rectangle([bx, by - r0, bx + bw, by + bh - r0], fill=(255, 255, 255, 210))
            self._draw_bar(draw, bx + self.margin, by + self.margin - r0)
        return np.asarray(img)


def over(top: np.ndarray, bottom: np.ndarray) -> np.ndarray:
    """Alpha-composite RGBA rows ``top`` over ``bottom`` (both (k, w, 4) uint8, straight alpha)."""
    ta = top[..., 3:4].astype(np.float32) / 255.0
    ba = bottom[..., 3:4].astype(np.float32) / 255.0
    alpha = ta + ba * (1.0 - ta)
    rgb = (top[..., :3] * ta + bottom[..., :3] * ba * (1.0 - ta)) / np.maximum(alpha, 1e-6)
    return np.concatenate([np.rint(np.clip(rgb, 0, 255)), np.rint(alpha * 255.0)], axis=-1).astype(np.uint8)


#: Longest side of the coverage mask searched for a free place for the scale bar, pixels.
FREE_SPOT_MASK_PX = 2048


def free_spot(covered: np.ndarray, box: tuple[int, int], margin: int) -> tuple[int, int] | None:
    """Top-left ``(x, y)`` of a ``box`` (w, h) that covers no True pixel of ``covered``.

    Of the free places ``margin`` away from the image border, the one nearest the bottom-left
    corner (where a scale bar is looked for) is taken.

    Parameters
    ----------
    covered : (h, w) bool
        Pixels that must stay clear (the painting, grown by a pixel).
    box : (int, int)
        Box width and height in pixels.
    margin : int
        Distance kept from the image border, pixels.

    Returns
    -------
    (int, int) or None
        None when no place is free.
    """
    import cv2

    h, w = covered.shape
    bw, bh = box
    if bw + 2 * margin > w or bh + 2 * margin > h:
        return None
    integral = cv2.integral(covered.astype(np.uint8))  # (h + 1, w + 1)
    sums = (integral[bh:, bw:] - integral[:-bh, bw:] - integral[bh:, :-bw] + integral[:-bh, :-bw])
    free = sums == 0  # free[y, x]: box with top-left (x, y) is clear
    free[:margin] = False
    free[:, :margin] = False
    free[h - bh - margin + 1:] = False
    free[:, w - bw - margin + 1:] = False
    ys, xs = np.nonzero(free)
    if not len(ys):
        return None
    best = int(np.argmin(xs.astype(np.float64) ** 2 + (h - bh - ys).astype(np.float64) ** 2))
    return int(xs[best]), int(ys[best])


def _zone_line(flat: FlatMesh) -> str:
    """The distortion inside the important zone and outside it, in one line for a sheet."""

    zones = distortion.zone_figures(flat.mesh.vertices, flat.uv, flat.mesh.faces, flat.importance)
    parts = []
    for key, name in (("important", "painted zone" if flat.importance is not None else "whole surface"),
                      ("rest", "plain surface")):
        z = zones[key]
        if z.distortion is not None:
            parts.append(f"{name}: lengths off {z.length_error_median_pct:.1f}% (median), "
                         f"{z.length_error_p95_pct:.1f}% (p95), anisotropy p95 {z.distortion.anisotropy_p95:.2f}")
    return "\n".join(parts)


def comparison_sheet(panels, *, title: str = "") -> bytes:
    """Side-by-side sheet: proxy rollout vs relaxed, painting and stress map with figures.

    Both stress maps use one colour scale. The panels are baked by the caller, so this
    module draws only.

    Parameters
    ----------
    panels : sequence of (str, FlatMesh, BakeResult)
        Label, flattening and its bake (with the ``stress`` map) of each column.
    title : str

    Returns
    -------
    bytes
        The sheet as a PNG file's content.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    panels = [(label, res, distortion.vertex_length_error(flat.mesh.vertices, flat.uv, flat.mesh.faces),
               distortion.summarize(flat.mesh.vertices, flat.uv, flat.mesh.faces),
               _zone_line(flat)) for label, flat, res in panels]
    hi = max(map_scale("stress", p[2]).hi for p in panels)
    scale = map_scale("stress", np.zeros(1), hi=hi)
    aspect = max(p[1].image.shape[0] / p[1].px_per_mm for p in panels) / max(
        p[1].image.shape[1] / p[1].px_per_mm for p in panels)
    panel_h = min(6.4 * aspect, 8.0)
    fig_h = 2 * panel_h + 3.4
    fig = Figure(figsize=(14, fig_h), dpi=100, facecolor="white")
    canvas = FigureCanvasAgg(fig)
    gs = fig.add_gridspec(3, 2, height_ratios=[panel_h, panel_h, 0.25], hspace=1.1 / panel_h + 0.1, wspace=0.12,
                          left=0.05, right=0.98, top=1 - 0.8 / fig_h, bottom=0.7 / fig_h)
    fig.suptitle(f"{title}: what relaxation bought" if title else "proxy rollout vs relaxed", fontsize=15)
    # one millimetre scale for all panels, so the two flattenings compare at true relative size
    max_w = max(p[1].image.shape[1] / p[1].px_per_mm for p in panels)
    max_h = max(p[1].image.shape[0] / p[1].px_per_mm for p in panels)
    for col, (label, res, stress, summ, zones) in enumerate(panels):
        h, w = res.image.shape[:2]
        extent = [0, w / res.px_per_mm, h / res.px_per_mm, 0]
        ax = fig.add_subplot(gs[0, col])
        ax.imshow(res.image, extent=extent, interpolation="antialiased")
        ax.set_title(f"{label}\n{zones}", fontsize=10)
        ax.set_xlabel("mm")
        heat = colorize(res.maps["stress"], scale, res.image[..., 3] / 255.0)
        ax2 = fig.add_subplot(gs[1, col])
        ax2.imshow(heat, extent=extent, interpolation="antialiased")
        ax2.set_title(f"lengths off by {100 * summ.edge_rms:.1f} % RMS   areas by "
                      f"{percent_from_log(summ.area_mean_abs_log):.1f} % (mean |ln| {summ.area_mean_abs_log:.4f})\n"
                      f"anisotropy p95 {summ.anisotropy_p95:.3f}   flipped {summ.flipped}   "
                      f"length error p95 {np.percentile(stress, 95):.3g} %", fontsize=10)
        ax2.set_xlabel("mm")
        for a in (ax, ax2):
            a.set_xlim(0, max_w)
            a.set_ylim(max_h, 0)
    _colorbar(fig.add_subplot(gs[2, :]), scale, 10)
    canvas.draw()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    return buf.getvalue()



def sheet_px_per_mm(flat: FlatMesh, max_px: int = SHEET_PANEL_PX) -> float:
    """Resolution of a comparison-sheet panel: its longest side ``max_px`` pixels."""
    lo, hi = bounds(flat.uv)
    ext = (hi - lo) * flat.mesh.mm_per_unit
    return max(1e-3, max_px / max(ext.max(), 1e-9))
