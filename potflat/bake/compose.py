"""The images of a bake, composed strip by strip: the painting (with the marks and the scale
bar drawn into it), the distortion maps with their painted-zone outline and folded hatching,
the overlay, the scale layer, the attachment mask and the relief's images. One
:class:`Composition` serves the in-memory :func:`potflat.bake.bake` and the file stage, which
streams the strips to disk."""
from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from potflat.bake import annotate
from potflat.bake.marks import (
    FOLDED_COLOUR,
    REPEAT_COLOUR,
    attachment_rows,
    folded_hatch,
    image_figures,
    repeat_line,
    scale_layer_on_image,
)
from potflat.bake.options import BakeOptions
from potflat.bake.relief import ReliefImages, relief_figures
from potflat.errors import InvalidOptionError
from potflat.raster.render import Renderer, rgba8
from potflat.types import FlatMesh, RolloutMarks


@dataclass(frozen=True, eq=False)
class StripLayers:
    """Rows ``r0:r1`` of every image of a bake.

    Attributes
    ----------
    r0, r1 : int
        The rows of the painting's pixel grid.
    coverage : (k, w) float64
        Covered fraction of each pixel.
    rgb : (k, w, 3) float32
        The painting's colour in [0, 1], NaN outside.
    painting : (k, w, 4) uint8
        ``NAME.png``'s rows: the painting with the repeat's dashed line and, with
        ``scale_on_image``, the scale layer drawn where it covers no painting.
    values : dict of str to (k, w) float32
        Each distortion map's values (NaN outside).
    maps : dict of str to (k, w, 4) uint8
        Each map coloured, the painted zone outlined and folded places hatched; with the
        ``stress`` map also ``"overlay"`` (stress over the greyscale painting).
    scale_layer : (k, w, 4) uint8
        The scale bar (and grid) alone, transparent elsewhere.
    attachments : (k, w, 4) uint8 or None
        Where left-out attachments met the wall (None: none were left out).
    relief : dict of str to (k, w, c) uint8
        Each relief image's rows (:attr:`potflat.bake.relief.ReliefImages.keys`) and
        ``"levels"``, the relief TIFF's (k, w) uint16; empty without ``relief``.
    """

    r0: int
    r1: int
    coverage: np.ndarray
    rgb: np.ndarray
    painting: np.ndarray
    values: dict[str, np.ndarray]
    maps: dict[str, np.ndarray]
    scale_layer: np.ndarray
    attachments: np.ndarray | None
    relief: dict[str, np.ndarray]


class Composition:
    """How the images of one bake are composed: the maps' colour scales and legends, the scale
    layer, the marks of the rollout, the relief's images.

    Parameters
    ----------
    renderer : Renderer
        The flattening's renderer (its :attr:`~Renderer.face_values` gain the marks).
    options : BakeOptions
        Used here: ``maps`` (``stress`` adds the overlay), ``grid`` (a 10 mm grid in the scale
        layer), ``scale_on_image`` (the scale layer drawn into the painting, in a band added
        below it when no place is free), ``relief``, ``relief_light`` and ``relief_blend``.
    marks : RolloutMarks or None
        What the rollout marks (attachment roots, its repeat, folded faces).

    Attributes
    ----------
    scales : dict of str to MapScale
    legends : dict of str to (b, w, 4) uint8
        The legend band below each map image (and the overlay).
    layer : ScaleLayer
    scale_band : int
        Rows added below the painting for its scale bar (0: none).
    relief_legend : (b, w, 4) uint8 or None
        The legend in mm below a painting that is the relief in grey (an untextured scan).
    band : int
        Rows added below the painting in all: the scale bar's and the relief's legend.
    relief : ReliefImages or None
        The relief's images (with ``relief``).
    covered_px : float
        Covered pixels of the painting so far (the sum of :attr:`StripLayers.coverage`).
    """

    def __init__(self, renderer: Renderer, options: BakeOptions, *, marks: RolloutMarks | None):
        maps, grid = options.maps, options.grid
        r = self.renderer = renderer
        n_faces = len(r.flat.mesh.faces)
        marks = marks if marks is not None else RolloutMarks()
        self.attachments = marks.face_indicator("attachments", n_faces)
        self.repeated = marks.face_indicator("repeated", n_faces)
        self.folded = marks.face_indicator("folded", n_faces)
        for key, marked in (("attachments", self.attachments), ("repeated", self.repeated), ("folded", self.folded)):
            if len(marked):
                r.face_values[key] = marked
        self.maps = tuple(maps)
        scales = {m: annotate.map_scale(m, r.vertex_length_error if m == "stress" else r.face_values[m])
                  for m in self.maps}
        if r.flat.importance is not None:
            scales = {m: replace(sc, label=f"{sc.label}; {sc.outline} line: painted zone") for m, sc in scales.items()}
        if len(self.folded):
            scales = {m: replace(sc, label=f"{sc.label}; hatched: folded scan") for m, sc in scales.items()}
        self.scales = scales
        g = r.grid
        self.legends = {m: annotate.legend_band(scales[m], g.width) for m in self.maps}
        if "stress" in self.maps:
            self.legends["overlay"] = self.legends["stress"]
        self.layer = annotate.ScaleLayer(g.width, g.height, g.px_per_mm, grid=grid)
        self.on_image, self.scale_band = scale_layer_on_image(r, grid) if options.scale_on_image else (None, 0)
        self.relief_legend = None
        if r.paints_relief:
            lo, hi = r.relief_grey_range
            self.relief_legend = annotate.legend_band(annotate.MapScale(
                "relief", lo, hi, "gray", f"height above the surface smoothed at {r.relief.smoothing_mm:.3g} mm, mm",
                extend="both"), g.width)
        self.band = self.scale_band + (len(self.relief_legend) if self.relief_legend is not None else 0)
        self.relief = (ReliefImages(r, lights=options.relief_light, blend=options.relief_blend) if options.relief
                       else None)
        self.covered_px = 0.0

    def strips(self) -> Iterator[StripLayers]:
        """Every strip of rows of the images, top to bottom."""
        r = self.renderer
        for r0, r1 in r.strips():
            cov = r.coverage(r0, r1)
            self.covered_px += float(cov.sum(dtype=np.float64))
            rgb = r.painting(r0, r1)
            rgba = rgba8(rgb, cov)
            if len(self.repeated):
                rgba[repeat_line(r.scalar("repeated", r0, r1), r0)] = REPEAT_COLOUR
            painting = rgba if self.on_image is None else annotate.over(self.on_image.rows(r0, r1), rgba)
            outline = r.zone_outline(r0, r1) if self.maps else None
            hatch = folded_hatch(r.scalar("folded", r0, r1), r0) if self.maps and len(self.folded) else None
            values, maps = {}, {}
            for m in self.maps:
                values[m] = r.scalar(m, r0, r1)
                outline_rgba = annotate.OUTLINE_RGBA[self.scales[m].outline]
                rows = annotate.draw_outline(annotate.colorize(values[m], self.scales[m], cov), outline, outline_rgba)
                maps[m] = annotate.draw_outline(rows, hatch, FOLDED_COLOUR)
                if m == "stress":
                    rows = annotate.draw_outline(annotate.overlay(rgb, values[m], self.scales[m], cov), outline,
                                                 outline_rgba)
                    maps["overlay"] = annotate.draw_outline(rows, hatch, FOLDED_COLOUR)
            attachments = attachment_rows(r.scalar("attachments", r0, r1)) if len(self.attachments) else None
            relief = self.relief.rows(r0, r1, rgb, cov) if self.relief is not None else {}
            yield StripLayers(r0=r0, r1=r1, coverage=cov, rgb=rgb, painting=painting, values=values, maps=maps,
                              scale_layer=self.layer.rows(r0, r1), attachments=attachments, relief=relief)

    def band_rows(self) -> np.ndarray:
        """The rows added below the painting: its scale bar's band and the relief's legend,
        (band, w, 4) uint8."""
        g = self.renderer.grid
        parts = [self.on_image.rows(g.height, g.height + self.scale_band)] if self.scale_band else []
        if self.relief_legend is not None:
            parts.append(self.relief_legend)
        return np.concatenate(parts) if parts else np.zeros((0, g.width, 4), np.uint8)

    def figures(self) -> dict:
        """The figures of ``NAME.bake.json`` (:func:`potflat.bake.marks.image_figures`) with the
        relief's (None when neither drawn nor the painting)."""
        r = self.renderer
        relief = (self.relief.figures() if self.relief is not None
                  else relief_figures(r) if r.paints_relief else None)
        return {**image_figures(r, self.covered_px), "relief": relief}


@dataclass(frozen=True, eq=False)
class BakeResult:
    """The baked images of one flattening (in memory).

    Attributes
    ----------
    image : (h + b, w, 4) uint8
        ``NAME.png``: the painting, RGBA, alpha the covered fraction of each pixel (0 outside
        and in holes), and the band below it, if any (:attr:`painting` without it): the scale
        bar's with ``scale_on_image``, the legend of an untextured scan's relief.
    maps : dict of str to (h, w) float32
        Distortion values per pixel (NaN outside): ``stress`` as the % length error around
        each vertex (:func:`potflat.mesh.distortion.vertex_length_error`, interpolated; the
        paper's Eq. 3 stress is in the figures and the PLY), ``area`` as ln(flat area / 3D area) per face (the natural log, as every area figure),
        ``anisotropy`` as sigma_max / sigma_min per face.
    position : (h, w, 3) float32 or None
        3D point (scan units) under each pixel, NaN outside.
    px_per_mm : float
        Resolution.
    origin : (2,) float64
        ``(u, v)`` of the top-left corner of pixel (0, 0), scan units; pixel ``(r, c)``
        covers ``u`` from ``origin[0] + c / s`` and ``v`` down from ``origin[1] - r / s``
        with ``s = px_per_mm * mm_per_unit`` pixels per unit.
    map_images : dict of str to (h + b, w, 4) uint8
        Each map coloured, with its legend band below (and ``"overlay"`` with ``stress``):
        ``NAME.<map>.png`` of the file stage.
    scale_layer : (h, w, 4) uint8
        The scale bar (and grid) alone: ``NAME.scale-layer.png``.
    figures : dict
        Resolution, size, distortion figures, covered area, the relief's settings and figures
        (the figures of ``NAME.bake.json``).
    relief_height : (h, w) float32 or None
        With ``relief``: the height above the smoothed scan, mm (NaN outside).
    relief_images : dict of str to (h [+ b], w, c) uint8
        With ``relief``: each relief image (:attr:`potflat.bake.relief.ReliefImages.keys`),
        RGBA or grey and alpha, ``relief`` and ``curvature`` with their legend band below:
        ``NAME.<key>.png`` of the file stage.
    """

    image: np.ndarray
    maps: dict[str, np.ndarray]
    position: np.ndarray | None
    px_per_mm: float
    origin: np.ndarray
    map_images: dict[str, np.ndarray]
    scale_layer: np.ndarray
    figures: dict
    relief_height: np.ndarray | None = None
    relief_images: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def painting(self) -> np.ndarray:
        """The painting's own rows of :attr:`image`, without the band below them (the scale
        bar's, the legend of an untextured scan's relief). Shape (h, w, 4) uint8."""
        return self.image[:len(self.scale_layer)]


def bake(flat: FlatMesh, *, options: BakeOptions | None = None, marks: RolloutMarks | None = None,
         **option_fields) -> BakeResult:
    """Bake a flattening into a true-scale RGBA image and distortion maps, in memory.

    Parameters
    ----------
    flat : FlatMesh
        The flattening (``uv`` in scan units, u right, v up).
    options : BakeOptions, optional
        The stage's options; or give its fields as keywords (not both). Used here:
        ``px_per_mm`` or ``dpi`` (default 4 px/mm), ``maps`` (from :data:`MAP_NAMES`),
        ``position_map`` (also return the 3D point under each pixel), ``supersample``
        (sub-samples per pixel side, 0: automatic), ``max_megapixels`` (refuse larger
        images), ``grid``, ``scale_on_image``, and ``relief`` with ``relief_mm``,
        ``relief_light`` and ``relief_blend``; the other fields concern the files the file
        stage writes.
    marks : RolloutMarks, optional
        What the rollout marks on the images (:attr:`potflat.rollout.RolloutResult.marks`).

    Returns
    -------
    BakeResult

    Raises
    ------
    InvalidOptionError
        When an option is invalid, or both ``options`` and option keywords are given.

    Notes
    -----
    Everything is held in memory; for very large images use the file stage
    (``potflat bake``), which streams the same strips to disk.
    """
    if options is None:
        options = BakeOptions(**option_fields)
    elif option_fields:
        raise InvalidOptionError("give either options= or option keywords to bake(), not both")
    r = Renderer(flat, options.resolution, supersample=options.supersample, max_megapixels=options.max_megapixels,
                 relief_mm=options.relief_mm)
    comp = Composition(r, options, marks=marks)
    g = r.grid
    image = np.zeros((g.height + comp.band, g.width, 4), np.uint8)
    values = {m: np.empty((g.height, g.width), np.float32) for m in options.maps}
    map_images = {key: np.empty((g.height + len(legend), g.width, 4), np.uint8) for key, legend in comp.legends.items()}
    scale_layer = np.empty((g.height, g.width, 4), np.uint8)
    position = np.empty((g.height, g.width, 3), np.float32) if options.position_map else None
    relief = comp.relief
    height = np.empty((g.height, g.width), np.float32) if relief is not None else None
    relief_images = {key: np.empty((g.height + len(relief.legends.get(key, ())), g.width, relief.channels[key]),
                                   np.uint8) for key in relief.keys} if relief is not None else {}
    for s in comp.strips():
        image[s.r0:s.r1] = s.painting
        scale_layer[s.r0:s.r1] = s.scale_layer
        for m in options.maps:
            values[m][s.r0:s.r1] = s.values[m]
        for key in map_images:
            map_images[key][s.r0:s.r1] = s.maps[key]
        if position is not None:
            position[s.r0:s.r1] = r.position(s.r0, s.r1)
        if relief is not None:
            height[s.r0:s.r1] = r.relief_fields(s.r0, s.r1)[..., 0]
            for key in relief.keys:
                relief_images[key][s.r0:s.r1] = s.relief[key]
    if comp.band:
        image[g.height:] = comp.band_rows()
    for key, legend in comp.legends.items():
        map_images[key][g.height:] = legend
    for key, legend in (relief.legends.items() if relief is not None else ()):
        relief_images[key][g.height:] = legend
    return BakeResult(image=image, maps=values, position=position, px_per_mm=g.px_per_mm, origin=g.origin.copy(),
                      map_images=map_images, scale_layer=scale_layer, figures=comp.figures(), relief_height=height,
                      relief_images=relief_images)
