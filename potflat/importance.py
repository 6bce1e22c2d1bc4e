"""Importance: where the painting is, so that the relaxation keeps it true to scale and shape
and lets plain surface take the distortion.

The importance of a vertex is a number from 0 (plain surface) to 1 (painting). The relax
stage weights springs, barrier and shape term by it (:attr:`RelaxOptions.importance_contrast`)
and the bake stage reports the distortion inside the important zone and outside it, and
draws the zone's outline on the maps. Ways to obtain it:

* ``auto`` (the default for scans with a texture or vertex colours): the painting is found
  in its own colours. The rollout's start layout is rendered at :data:`DETECT_PX_PER_MM`;
  a pixel shows *detail* where the colour's local standard deviation (CIELAB, within
  :data:`DETAIL_MM`) is well above the surface's noise floor (a low percentile of it, times
  :data:`DETAIL_OVER_NOISE`, and at least :data:`DETAIL_MIN_DELTA_E`): brush strokes,
  figure outlines and bands have it; glaze, a lighting gradient across the vessel and
  scanner noise do not. Detail closer than :data:`GAP_MM` is joined into one zone, enclosed
  plain areas are filled, specks below :data:`MIN_ZONE_MM` across are dropped.

  Clay has detail of its own (firing clouds, dirt, pinholes, chips), and so have the edges of
  shadows and highlights, so whether there is a painting at all is decided first, where the
  colours are evidence: not within :data:`EDGE_MARGIN_MM` of the outline or a hole (a scan's
  texture is bled and shadowed there) nor where the layout smears the texture
  (:data:`SMEAR_ANISOTROPY`). A zone is kept where its detail stands clear of the plain
  surface's own (:data:`CLEAR_OVER_TEXTURE`), and there is a painting when the kept zones'
  strokes (lines, dots and figures narrower than about :data:`GAP_MM`, measured by
  morphological top-hats, which a step between two large areas such as a shadow's edge does
  not move: :data:`STROKE_MM`) stand clear of the plain surface's over
  :data:`PAINTING_FRACTION` of it. Otherwise the whole surface counts alike, and the reason
  says so. The zone is
  then made again, the same way, from the strokes within :data:`DETAIL_REACH_MM` of it
  (pixels whose colour is unlike the plain surface's around it), so that it ends on the
  outermost strokes rather than where the detail window stops seeing them, and is softened
  outwards. Rendering
  on the surface's own layout makes it blind to texture-atlas seams. Faces without texture
  coordinates (:attr:`potflat.types.Mesh.untextured_faces`) hold no colour evidence: they are
  left out of the rendering like the space outside the surface, so they neither show detail
  nor make an edge with their textured neighbours. A scan painted nearly all over
  (:data:`ALL_OVER_FRACTION`) or showing no painting gets no importance: the whole surface
  counts alike, exactly as without importance.
* a mask painted over an image potflat made (white = important), mapped back to the surface
  through the flattening that made that image (:func:`image_mask_importance`);
* a mask in the texture's own space (:func:`texture_mask_importance`);
* a height band and angle range (:func:`band_importance`).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from potflat._jit import worker_threads
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.io.flat_ply import read_flat_ply
from potflat.io.images import read_mask
from potflat.mesh.distortion import face_areas, face_distortion, important_faces
from potflat.raster.render import fill_faces, paint
from potflat.types import FlatMesh

#: Resolution of the auto detection's rendering (px/mm of the start layout).
DETECT_PX_PER_MM = 2.0
#: Radius (Gaussian sigma, mm) of the colour statistics that measure detail.
DETAIL_MM = 1.5
#: A pixel shows detail when its local colour deviation exceeds this many times the surface's
#: noise floor (the deviation's :data:`NOISE_PERCENTILE`-th percentile: plain surface and the
#: flat colour inside figures, present even on a vessel painted all over) ...
DETAIL_OVER_NOISE = 4.0
NOISE_PERCENTILE = 10.0
#: ... and this many CIELAB units (about twice a just-noticeable difference).
DETAIL_MIN_DELTA_E = 5.0
#: Detail closer than this (mm) is one painted zone (the background between figures of a frieze).
GAP_MM = 25.0
#: Painted zones smaller than a disc of this diameter (mm) are dropped (specks, scratches, noise).
MIN_ZONE_MM = 12.0
#: Detail is found up to about this far (mm) outside a painting's outermost stroke: the colour
#: statistics' window (:data:`DETAIL_MM`) straddles an edge out to where the far side's share
#: of the window, p, has ``sqrt(p (1 - p))`` times the edge's colour difference below the
#: threshold: 2.8 sigmas for black against white (100 CIELAB units). So the zone is not the
#: detail itself: it is made again from the strokes (pixels unlike the plain surface) within
#: this distance of the detail, and ends on them; every mm of plain surface inside the stiff
#: zone is curved surface the painting must share its distortion with.
DETAIL_REACH_MM = 3.0 * DETAIL_MM
#: Width (Gaussian sigma, mm) of the zone's soft edge, outside the zone (inside, importance is 1).
SOFT_EDGE_MM = 1.0
#: A zone covering at least this share of the surface means: painted all over (no importance).
ALL_OVER_FRACTION = 0.8
#: Colours within this distance (mm) of the surface's outline or of a hole are no evidence of a
#: painting: a scan's texture there is bled from the background, shadowed or blurred (70% of an
#: unpainted photogrammetry pot's colour detail lay there).
EDGE_MARGIN_MM = 6.0
#: Nor are the colours where the start layout stretches the surface this many times more in one
#: direction than across it (its anisotropy): the texture is drawn out into streaks there (a
#: base or a foot turned towards the axis, unrolled as a flange). Stretched strips narrower than
#: the detail window (:data:`DETAIL_MM`: single slivers of an irregular triangulation) count as
#: evidence.
SMEAR_ANISOTROPY = 4.0
#: A painting stands clear of the surface's own texture (clay, firing clouds, dirt, pinholes,
#: chips), which has detail too: detail counts as the painting's where it is this many times
#: the :data:`TEXTURE_PERCENTILE`-th percentile of the plain surface's (the evidence farther than
#: :data:`DETAIL_REACH_MM` from any detail). A zone is kept where at least a :data:`MIN_ZONE_MM`
#: disc's area of its detail stands clear so.
CLEAR_OVER_TEXTURE = 2.0
TEXTURE_PERCENTILE = 99.0
#: A painting is made of strokes: lines, dots, figures and the ground between them. Their
#: contrast is measured by morphological top-hats (the colour against the surface's with such
#: structures opened or closed away) of this radius (mm: strokes narrower than twice it) and of
#: twice it (figures narrower than about :data:`GAP_MM`), each standing clear of the plain
#: surface's at its own scale. A top-hat is blind to a step between two larger areas: the edge of
#: a shadow, a highlight, a lit rim or a firing cloud, which the detail (a standard deviation)
#: sees as well as a stroke.
STROKE_MM = 6.0
#: There is a painting when the strokes of its zones stand clear of the surface's own (by
#: :data:`CLEAR_OVER_TEXTURE`, and by twice the detail threshold: a stroke's contrast, where the
#: detail of an edge is half of it) over at least this share of the evidence; a chip, a
#: scratch, a cluster of marks or the ragged edge of a shadow does not.
PAINTING_FRACTION = 0.01
#: The sentence every "no zone" finding ends with.
ALIKE = "the whole surface counts alike"
#: How every finding of no painting in the colours begins (:func:`found_no_painting`).
NO_PAINTING = "no painting found"


@dataclass(frozen=True)
class Importance:
    """Importance of each vertex of a flattening and how it was found.

    Attributes
    ----------
    values : (n,) float64 or None
        0 (plain) to 1 (painting) per vertex; None: the whole surface counts alike.
    method : str
        One of :data:`potflat.rollout.options.IMPORTANCE_METHODS`.
    zone_fraction : float
        Share of the surface's area in the important zone (1 when ``values`` is None).
    reason : str
        One sentence for the JSON and the console: what was found.
    """

    values: np.ndarray | None
    method: str
    zone_fraction: float
    reason: str

    def as_dict(self) -> dict:
        """JSON-ready description (without the values)."""
        return {"method": self.method, "zone_fraction": self.zone_fraction, "reason": self.reason,
                "uniform": self.values is None}


def _zone_fraction(flat: FlatMesh, values: np.ndarray) -> float:
    area = face_areas(flat.mesh.vertices, flat.mesh.faces)
    total = float(area.sum())
    return float(area[important_faces(flat.mesh.faces, values)].sum()) / total if total > 0 else 0.0


def _result(flat: FlatMesh, values: np.ndarray, method: str, what: str) -> Importance:
    values = np.clip(np.ascontiguousarray(values, dtype=np.float64), 0.0, 1.0)
    if values.min(initial=1.0) >= 1.0 or values.max(initial=0.0) <= 0.0:
        which = "everything" if values.min(initial=1.0) >= 1.0 else "nothing"
        return Importance(None, method, 1.0, f"{what} marks {which} as important: the whole surface counts alike")
    frac = _zone_fraction(flat, values)
    return Importance(values, method, frac, f"{what}: {100 * frac:.0f}% of the surface is important")


def _gaussian(img: np.ndarray, sigma_px: float) -> np.ndarray:
    import cv2

    return cv2.GaussianBlur(img, (0, 0), sigmaX=max(sigma_px, 0.3), borderType=cv2.BORDER_REPLICATE)


def _disc(radius_px: float) -> np.ndarray:
    import cv2

    r = max(1, int(round(radius_px)))
    return cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))


def detail_map(rgba: np.ndarray, px_per_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Local colour deviation of an image of the painting, and the covered pixels.

    Parameters
    ----------
    rgba : (h, w, 4) uint8
        The painting (alpha: covered fraction).
    px_per_mm : float

    Returns
    -------
    deviation : (h, w) float32
        Standard deviation of the CIELAB colour within :data:`DETAIL_MM` (Gaussian window,
        normalised over the covered pixels only, so the outline adds none).
    covered : (h, w) bool
    """
    lab, covered = _lab(rgba)
    return _deviation(lab, covered, px_per_mm), covered


def _deviation(lab: np.ndarray, covered: np.ndarray, px_per_mm: float) -> np.ndarray:
    """:func:`detail_map`'s deviation (h, w) float32 from the CIELAB colours (h, w, 3) float32
    and the covered pixels (h, w) bool."""
    w = covered.astype(np.float32)
    sigma = DETAIL_MM * px_per_mm
    window = _gaussian(w, sigma)
    mean = _masked_mean(lab, w, sigma, window)
    mean_sq = _masked_mean(lab * lab, w, sigma, window)
    var = np.maximum(mean_sq - mean * mean, 0.0).sum(axis=2)
    return np.sqrt(var).astype(np.float32)


def _lab(rgba: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CIELAB colours (h, w, 3) float32 of an RGBA image and its covered pixels (h, w) bool."""
    import cv2

    covered = rgba[..., 3] > 127
    return cv2.cvtColor(rgba[..., :3].astype(np.float32) / 255.0, cv2.COLOR_RGB2LAB), covered


def _masked_mean(values: np.ndarray, weight: np.ndarray, sigma_px: float,
                 window_weight: np.ndarray | None = None) -> np.ndarray:
    """Gaussian-windowed mean (h, w, c) of ``values`` (h, w, c) over the pixels of ``weight``
    (h, w); ``window_weight``: ``_gaussian(weight, sigma_px)`` when the caller has it."""
    if window_weight is None:
        window_weight = _gaussian(weight, sigma_px)
    norm = np.maximum(window_weight, 1e-6)
    return _gaussian(values * weight[..., None], sigma_px) / norm[..., None]


def painted_zone_image(rgba: np.ndarray, px_per_mm: float, evidence: np.ndarray | None = None
                       ) -> tuple[np.ndarray | None, str]:
    """The painted zone of an image of the painting (see the module notes).

    First whether there is a painting, where the colours are evidence (away from the outline
    and holes, :data:`EDGE_MARGIN_MM`, and within ``evidence``): zones whose detail stands
    clear of the surface's own texture (:data:`CLEAR_OVER_TEXTURE`) and whose strokes do over
    :data:`PAINTING_FRACTION` of it (:data:`STROKE_MM`); then where it is.

    Parameters
    ----------
    rgba : (h, w, 4) uint8
    px_per_mm : float
    evidence : (h, w) bool, optional
        Pixels whose colours can show a painting (default: all; :func:`auto_importance` leaves out
        where the layout smears the texture, :data:`SMEAR_ANISOTROPY`).

    Returns
    -------
    zone : (h, w) float32 in [0, 1] or None
        Soft-edged zone; None when the image shows no painting or is painted nearly all over.
    reason : str
    """
    import cv2

    lab, covered = _lab(rgba)
    deviation = _deviation(lab, covered, px_per_mm)
    if covered.sum() < 16:
        return None, f"too little surface to look for a painting: {ALIKE}"
    noise = float(np.percentile(deviation[covered], NOISE_PERCENTILE))
    threshold = max(DETAIL_OVER_NOISE * noise, DETAIL_MIN_DELTA_E)  # (CIELAB units, as a colour difference too)
    detail = ((deviation > threshold) & covered).astype(np.uint8)
    evidence = _evidence(covered, px_per_mm, evidence)
    if not (detail & evidence).any():
        return None, f"{NO_PAINTING} (no colour detail above {threshold:.1f} CIELAB units): {ALIKE}"
    # join detail into zones, fill enclosed plain areas, drop specks and what does not stand
    # clear of the surface's own texture, then the same on the strokes
    zone = _joined(detail, covered, px_per_mm)
    count, labels, stats, _ = cv2.connectedComponentsWithStats(zone, connectivity=8)
    min_area = math.pi * (0.5 * MIN_ZONE_MM) ** 2  # mm²
    big = stats[:, cv2.CC_STAT_AREA] >= min_area * px_per_mm ** 2
    big[0] = False
    if not big.any():
        return None, f"{NO_PAINTING} (only specks of colour detail): {ALIKE}"
    # a zone counts where its detail stands clear of the surface's own texture; there is a
    # painting when the strokes of those zones do
    plain = evidence & (cv2.dilate(zone, _disc(DETAIL_REACH_MM * px_per_mm)) == 0)
    clear = _clear_of(deviation, plain, threshold)
    clear_area = np.bincount(labels[(deviation > clear) & evidence], minlength=count) / px_per_mm ** 2
    keep = big & (clear_area >= min_area)
    strokes = _clear_strokes(lab, covered, plain, 2.0 * threshold, px_per_mm)
    share = float(keep[labels[strokes & evidence]].sum()) / float(evidence.sum())
    if share < PAINTING_FRACTION:
        return None, (f"{NO_PAINTING}: the colour detail is the surface's own texture and light (clay, firing "
                      "clouds, dirt, chips, shadows, highlights); strokes standing clear of it cover "
                      f"{100 * share:.2f}% of the surface, a painting's {100 * PAINTING_FRACTION:g}% or more: "
                      f"{ALIKE} (a painting can be marked by hand: --importance mask)")
    zone = keep[labels].astype(np.uint8)
    zone = _on_the_strokes(zone, covered, labels, _unlike_plain(lab, zone, covered, threshold, px_per_mm),
                           px_per_mm)
    fraction = float(zone.sum()) / float(covered.sum())
    if fraction >= ALL_OVER_FRACTION:
        return None, f"painted all over ({100 * fraction:.0f}% of the surface): {ALIKE}"
    hard = zone.astype(np.float32)
    soft = np.maximum(hard, np.clip(_gaussian(hard, SOFT_EDGE_MM * px_per_mm), 0.0, 1.0))
    return soft, f"painted zone found in the colours (detail above {threshold:.1f} CIELAB units)"


def _evidence(covered: np.ndarray, px_per_mm: float, evidence: np.ndarray | None) -> np.ndarray:
    """The covered pixels (h, w) bool farther than :data:`EDGE_MARGIN_MM` from the outline and
    holes, and in ``evidence`` (h, w) bool when given."""
    import cv2

    # distance to the nearest uncovered pixel, the image's frame counting as uncovered
    inside = np.pad(covered, 1).astype(np.uint8)
    far = cv2.distanceTransform(inside, cv2.DIST_L2, 5)[1:-1, 1:-1] > EDGE_MARGIN_MM * px_per_mm
    return covered & far if evidence is None else covered & far & evidence


def _clear_of(contrast: np.ndarray, plain: np.ndarray, least: float) -> float:
    """The contrast (CIELAB units) a painting reaches and the surface's own texture does not:
    :data:`CLEAR_OVER_TEXTURE` times the :data:`TEXTURE_PERCENTILE`-th percentile of
    ``contrast`` (h, w) over the ``plain`` (h, w) bool pixels, at least ``least`` (all of it
    when there are no plain pixels: painted all over)."""
    if plain.sum() < 16:
        return least
    return max(CLEAR_OVER_TEXTURE * float(np.percentile(contrast[plain], TEXTURE_PERCENTILE)), least)


def _clear_strokes(lab: np.ndarray, covered: np.ndarray, plain: np.ndarray, least: float,
                   px_per_mm: float) -> np.ndarray:
    """The pixels (h, w) bool of strokes standing clear of the plain surface's (``plain`` (h, w)
    bool; :func:`_clear_of`, at least ``least`` CIELAB units) at either scale of
    :data:`STROKE_MM`: per channel of the CIELAB colours ``lab`` (h, w, 3) float32, lightly
    smoothed (a third of :data:`DETAIL_MM`), the larger of the white and the black top-hat, the
    three combined as a colour difference (the larger scale's at half the resolution, its
    contrast interpolated back). Uncovered pixels (``covered`` (h, w) bool False) take the
    colour of the surface around them first, so the outline makes no stroke."""
    import cv2

    weight = covered.astype(np.float32)
    smooth = _masked_mean(lab, weight, DETAIL_MM / 3.0 * px_per_mm)
    around = _masked_mean(lab, weight, 2.0 * DETAIL_MM * px_per_mm)
    channels = [np.ascontiguousarray(c) for c in np.moveaxis(np.where(covered[..., None], smooth, around), 2, 0)]
    h, w = covered.shape
    strokes = np.zeros(covered.shape, bool)
    disc = _disc(STROKE_MM * px_per_mm)
    for shrink in (1, 2):  # the same disc at half the resolution is the larger scale (as fine as its figures need)
        size = (max(1, w // shrink), max(1, h // shrink))
        contrast = np.zeros(size[::-1], np.float32)
        for c in channels:
            c = c if shrink == 1 else cv2.resize(c, size, interpolation=cv2.INTER_AREA)
            top = np.maximum(cv2.morphologyEx(c, cv2.MORPH_TOPHAT, disc), cv2.morphologyEx(c, cv2.MORPH_BLACKHAT, disc))
            contrast += top * top
        contrast = np.sqrt(contrast if shrink == 1 else cv2.resize(contrast, (w, h), interpolation=cv2.INTER_LINEAR))
        strokes |= contrast > _clear_of(contrast, plain, least)
    return strokes


def _unlike_plain(lab: np.ndarray, zone: np.ndarray, covered: np.ndarray, threshold: float,
                  px_per_mm: float) -> np.ndarray:
    """Pixels whose CIELAB colour (``lab`` (h, w, 3) float32) differs by more than
    ``threshold`` (CIELAB units) from the plain surface around the zone (its mean colour
    within :data:`DETAIL_REACH_MM`, so that a lighting gradient does not count), and by more
    than half the difference of the painting nearby (a stroke's edge pixel counts by its
    larger part); where no plain surface is that near, every pixel differs.

    Returns
    -------
    (h, w) bool
    """
    import cv2

    lab = _gaussian(lab, 0.5)  # half a pixel: less noise, and an edge's half way stays put
    plain = (covered & (zone == 0)).astype(np.float32)
    sigma = DETAIL_REACH_MM * px_per_mm
    window = _gaussian(plain, sigma)
    near = window > 1e-3
    difference = np.sqrt(((lab - _masked_mean(lab, plain, sigma, window)) ** 2).sum(axis=2))
    halfway = 0.5 * cv2.dilate(difference, _disc(DETAIL_MM * px_per_mm))
    return ~near | (difference > np.maximum(halfway, threshold))


def _joined(mask: np.ndarray, covered: np.ndarray, px_per_mm: float) -> np.ndarray:
    """``mask`` (h, w) uint8 with gaps narrower than :data:`GAP_MM` closed and the plain areas
    it encloses filled, on the covered pixels (h, w) bool."""
    import cv2

    zone = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, _disc(0.5 * GAP_MM * px_per_mm))
    zone &= covered.astype(np.uint8)
    outside = np.zeros((zone.shape[0] + 2, zone.shape[1] + 2), np.uint8)
    outside[1:-1, 1:-1] = zone
    cv2.floodFill(outside, None, (0, 0), 2)
    return (outside[1:-1, 1:-1] != 2).astype(np.uint8)  # zone and what it encloses


def _on_the_strokes(zone: np.ndarray, covered: np.ndarray, labels: np.ndarray, painted: np.ndarray,
                    px_per_mm: float) -> np.ndarray:
    """The zone made again from the strokes themselves: the pixels unlike the plain surface
    within :data:`DETAIL_REACH_MM` of the zone, joined and filled as the detail was
    (:func:`_joined`). Its edge then lies on the outermost strokes, while the background
    between figures stays in it; a zone component without such pixels keeps its own extent.

    Parameters
    ----------
    zone : (h, w) uint8
        1 in the zone.
    covered : (h, w) bool
    labels : (h, w) int32
        Component labels of ``zone`` (0 outside it).
    painted : (h, w) bool
        Pixels unlike the plain surface (:func:`_unlike_plain`).
    px_per_mm : float

    Returns
    -------
    (h, w) uint8
    """
    import cv2

    strokes = painted & covered & (cv2.dilate(zone, _disc(DETAIL_REACH_MM * px_per_mm)) > 0)
    found = np.zeros(int(labels.max()) + 1, bool)
    found[labels[strokes & (zone > 0)]] = True
    found[0] = False
    return _joined(strokes.astype(np.uint8), covered, px_per_mm) | (zone & ~found[labels])


def sample_image(image: np.ndarray, px: np.ndarray) -> np.ndarray:
    """Bilinear samples of a one-channel image at pixel positions (pixel centres at +0.5).

    Parameters
    ----------
    image : (h, w) float
    px : (k, 2) float64
        (column, row) positions in pixels, (0, 0) the top-left corner of the image.

    Returns
    -------
    (k,) float64
        Edge pixels extend outwards.
    """
    h, w = image.shape
    x = np.clip(px[:, 0] - 0.5, 0.0, w - 1.0)
    y = np.clip(px[:, 1] - 0.5, 0.0, h - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), w - 2) if w > 1 else np.zeros(len(x), np.int64)
    y0 = np.minimum(np.floor(y).astype(np.int64), h - 2) if h > 1 else np.zeros(len(y), np.int64)
    x1, y1 = np.minimum(x0 + 1, w - 1), np.minimum(y0 + 1, h - 1)
    fx, fy = x - x0, y - y0
    img = image.astype(np.float64)
    top = img[y0, x0] * (1 - fx) + img[y0, x1] * fx
    bottom = img[y1, x0] * (1 - fx) + img[y1, x1] * fx
    return top * (1 - fy) + bottom * fy


def _pixels(uv: np.ndarray, origin: np.ndarray, px_per_unit: float) -> np.ndarray:
    """Pixel positions (column, row) of flat points in an image with the bake's grid."""
    out = np.empty_like(uv)
    out[:, 0] = (uv[:, 0] - origin[0]) * px_per_unit
    out[:, 1] = (origin[1] - uv[:, 1]) * px_per_unit
    return out


def auto_importance(flat: FlatMesh) -> Importance:
    """Find the painted zone in the scan's colours (see the module notes).

    Parameters
    ----------
    flat : FlatMesh
        A flattening whose mesh has a texture or vertex colours (else: no importance).
    """
    mesh = flat.mesh
    if (mesh.texcoords is None or mesh.texture_path is None) and mesh.vertex_colors is None:
        return Importance(None, "auto", 1.0, "no texture or vertex colours: the whole surface counts alike")

    px_per_mm = DETECT_PX_PER_MM
    image, origin = paint(flat, px_per_mm, leave_out_untextured=True)  # no colour evidence there
    pixels = _pixels(flat.uv, origin, px_per_mm * mesh.mm_per_unit)
    zone, reason = painted_zone_image(image, px_per_mm, evidence=~_smeared(flat, pixels, image.shape[:2], px_per_mm))
    if zone is None:
        return Importance(None, "auto", 1.0, reason)
    return _result(flat, sample_image(zone, pixels), "auto", reason)


def found_no_painting(importance: Importance) -> bool:
    """Whether ``importance`` is the finding, in the scan's colours, that they show no
    painting (not: no colours, painted all over, or another method)."""
    return importance.method == "auto" and importance.values is None and importance.reason.startswith(NO_PAINTING)


def _smeared(flat: FlatMesh, pixels: np.ndarray, shape: tuple[int, int], px_per_mm: float) -> np.ndarray:
    """The pixels (h, w) bool of ``shape`` where the flattening stretches the surface
    :data:`SMEAR_ANISOTROPY` times more one way than the other (``pixels`` (n, 2): the
    vertices' positions in the image), in strips at least as wide as the detail window."""
    import cv2

    mesh = flat.mesh
    anisotropy = face_distortion(mesh.vertices, flat.uv, mesh.faces).anisotropy
    stretched = fill_faces(pixels, mesh.faces[~(anisotropy < SMEAR_ANISOTROPY)], *shape)  # (collapsed ones too)
    return cv2.morphologyEx(stretched.astype(np.uint8), cv2.MORPH_OPEN, _disc(DETAIL_MM * px_per_mm)) > 0


def _reference_for(mask_path: Path, shape: tuple[int, int], reference: Path | None) -> Path:
    """The ``NAME.bake.json`` of the image a mask was painted over."""
    if reference is not None:
        return Path(reference)
    found = []
    for candidate in sorted(mask_path.parent.glob("*.bake.json")):
        try:
            px = json.loads(candidate.read_text()).get("image_px")
        except (OSError, ValueError, AttributeError):
            continue
        if px == [shape[1], shape[0]]:
            found.append(candidate)
    if len(found) != 1:
        what = "no" if not found else "several"
        raise InvalidInputError(
            f"{what} potflat image of the mask's size ({shape[1]} x {shape[0]} px) beside {mask_path}; "
            "keep the mask in the folder of the image you painted it over, or name that image's "
            "NAME.bake.json with --importance-image")
    return found[0]


def _closest_on_faces(points: np.ndarray, V: np.ndarray, F: np.ndarray, candidates: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """For each point the closest of its candidate faces and the barycentric coordinates of
    the closest point on it.

    Parameters
    ----------
    points : (k, 3) float64
    V : (n, 3) float64
    F : (m, 3) int64
    candidates : (k, c) int64
        Candidate faces of each point.

    Returns
    -------
    face : (k,) int64
    bary : (k, 3) float64
    """
    k, c = candidates.shape
    best_d = np.full(k, np.inf)
    face = candidates[:, 0].copy()
    bary = np.full((k, 3), 1.0 / 3.0)
    for j in range(c):
        f = F[candidates[:, j]]
        a, b, cc = V[f[:, 0]], V[f[:, 1]], V[f[:, 2]]
        e0, e1, d = b - a, cc - a, points - a
        d00 = np.einsum("ij,ij->i", e0, e0)
        d01 = np.einsum("ij,ij->i", e0, e1)
        d11 = np.einsum("ij,ij->i", e1, e1)
        d20 = np.einsum("ij,ij->i", d, e0)
        d21 = np.einsum("ij,ij->i", d, e1)
        den = d00 * d11 - d01 * d01
        den = np.where(np.abs(den) > 0, den, 1.0)
        v = (d11 * d20 - d01 * d21) / den
        w = (d00 * d21 - d01 * d20) / den
        lam = np.stack([1.0 - v - w, v, w], axis=1)
        lam = np.clip(lam, 0.0, None)
        lam /= np.maximum(lam.sum(axis=1, keepdims=True), 1e-300)
        q = lam[:, :1] * a + lam[:, 1:2] * b + lam[:, 2:] * cc
        dist = np.einsum("ij,ij->i", q - points, q - points)
        better = dist < best_d
        best_d[better], face[better], bary[better] = dist[better], candidates[better, j], lam[better]
    return face, bary


def image_mask_importance(flat: FlatMesh, mask_path: str | Path, reference: str | Path | None = None) -> Importance:
    """Importance from a mask painted over an image potflat made (white = important).

    The image's ``NAME.bake.json`` (``reference``; default: the one beside the mask whose
    image has the mask's size) gives its pixel grid and the flattening it was baked from (read
    from the JSON's own folder, whatever folder the JSON names).
    Each vertex of ``flat`` is located on that flattening's 3D surface (the closest point of
    the nearest faces) and reads the mask where that point lies in the image. On the same
    scan this is exact: a vertex finds itself.

    Parameters
    ----------
    flat : FlatMesh
    mask_path : path-like
        Same size as the image it was painted over.
    reference : path-like, optional
        ``NAME.bake.json`` of that image.
    """
    from scipy.spatial import cKDTree

    mask_path = Path(mask_path)
    mask = read_mask(mask_path)
    ref_json = _reference_for(mask_path, mask.shape, None if reference is None else Path(reference))
    try:
        meta = json.loads(ref_json.read_text())
        origin = np.asarray(meta["origin_uv"], dtype=np.float64)
        px_per_unit = float(meta["px_per_unit"])
        ply_name = Path(meta["provenance"]["inputs"][0]["path"]).name
    except (OSError, ValueError, KeyError, IndexError, TypeError):
        raise InvalidInputError(f"{ref_json} is not a potflat bake JSON; name the NAME.bake.json of the image "
                                "the mask was painted over") from None
    if meta.get("image_px") != [mask.shape[1], mask.shape[0]]:
        raise InvalidInputError(f"the mask {mask_path} is {mask.shape[1]} x {mask.shape[0]} px but the image of "
                                f"{ref_json} is {meta.get('image_px')}; paint the mask over that image at its size")
    # the flattening is read beside the JSON the user named, never where the JSON points
    ply = ref_json.parent / ply_name
    if not ply.is_file() or ply.resolve().parent != ref_json.parent.resolve():
        raise InvalidInputError(f"the flattening {ply_name!r} named by {ref_json} is not beside it; keep the "
                                "image's stage PLY in its folder")
    ref = read_flat_ply(ply)
    RV, RF = ref.mesh.vertices, ref.mesh.faces
    centroids = RV[RF].mean(axis=1)
    points = flat.mesh.vertices
    k = min(8, len(RF))

    _, cand = cKDTree(centroids).query(points, k=k, workers=worker_threads())
    cand = np.asarray(cand, np.int64).reshape(len(points), k)
    # a vertex of the same scan finds itself: take its own position where it is a corner
    face, bary = _closest_on_faces(points, RV, RF, cand)
    uv = np.einsum("ij,ijk->ik", bary, ref.uv[RF[face]])
    values = sample_image(mask, _pixels(uv, origin, px_per_unit))
    return _result(flat, values, "mask", f"mask {mask_path.name} over the image of {ref_json.name}")


def texture_mask_importance(flat: FlatMesh, mask_path: str | Path) -> Importance:
    """Importance from a mask in the texture's own space (white = important, any size).

    Each vertex takes the mean of the mask at its face corners' texture coordinates (the
    corners of untextured faces have none and count for nothing; a vertex of those alone is
    plain).
    """
    mesh = flat.mesh
    if mesh.texcoords is None:
        raise InvalidInputError(f"{mesh.source or 'the scan'} has no texture coordinates, so a texture-space mask "
                                "cannot be placed; paint the mask over a potflat image instead (--importance PNG)")

    mask = read_mask(mask_path)
    h, w = mask.shape
    tc = mesh.texcoords.reshape(-1, 2)
    tc = np.where((tc < 0.0) | (tc > 1.0), tc % 1.0, tc)  # repeating textures wrap; 1.0 stays the edge
    px = np.stack([tc[:, 0] * w, (1.0 - tc[:, 1]) * h], axis=1)
    corner = sample_image(mask, px)
    idx = mesh.faces.ravel()
    if mesh.untextured_faces is not None:
        textured = np.repeat(~mesh.untextured_faces, 3)
        idx, corner = idx[textured], corner[textured]
    count = np.bincount(idx, minlength=len(mesh.vertices))
    values = np.bincount(idx, corner, len(mesh.vertices)) / np.maximum(count, 1)
    return _result(flat, values, "texture-mask", f"texture-space mask {Path(mask_path).name}")


def band_importance(flat: FlatMesh, height_fraction: np.ndarray, angle_deg: np.ndarray,
                    band: tuple[float, float] | None, angles: tuple[float, float] | None) -> Importance:
    """Importance 1 inside a height band and angle range, 0 outside.

    Parameters
    ----------
    flat : FlatMesh
    height_fraction : (n,) float64
        Each vertex's height as a fraction of the scan's axial extent (0 foot, 1 mouth).
    angle_deg : (n,) float64
        Each vertex's angle from the seam, degrees.
    band : (float, float) or None
        None: all heights.
    angles : (float, float) or None
        Degrees from the seam; None: all the way round.
    """
    inside = np.ones(len(flat.uv), bool)
    if band is not None:
        inside &= (height_fraction >= band[0]) & (height_fraction <= band[1])
    if angles is not None:
        rel = (angle_deg - angles[0]) % 360.0
        inside &= rel <= (angles[1] - angles[0])
    what = " and ".join(p for p in (f"heights {band[0]:g}-{band[1]:g}" if band else "",
                                    f"angles {angles[0]:g} to {angles[1]:g} deg" if angles else "") if p)
    if not inside.any():
        raise InvalidOptionError(f"the importance band ({what}) holds no part of the rollout; widen it")
    return _result(flat, inside.astype(np.float64), "band", f"band {what}")
