"""The vessel's profile: radius against height around its axis, as data, CSV and drawing.

:func:`vessel_profile` bins the scan along the axis and takes, in every height bin and for
each wall separately (outer / inner, see :mod:`potflat.rollout.walls`), the weighted median distance
of the scan's vertices from the axis. Each face contributes its three corners with weight
``area / 3 * |n_r|`` (``n_r`` the normal's radial component), which is the face's area
projected onto a cylinder around the axis: nearly horizontal parts (a flat base, a bowl's
floor, the top of the rim) carry almost no weight, so they do not pull the radius of the
bin they cut through. Medians make the profile robust to handles, noise and holes; it works
on sherds (any angular coverage) because it only uses distances from the axis.

:func:`write_profile_csv` and :func:`write_profile_svg` export it; the SVG is a section
drawing as archaeologists publish it beside a rollout (see ``docs/profile.md``).
"""
from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import escape

import numpy as np

from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.io.atomic import write_bytes_atomic
from potflat.mesh.distortion import median_edge_length, weighted_percentile
from potflat.rollout.walls import (
    INNER,
    OUTER,
    FaceFrame,
    binned_median,
    check_axis,
    check_mesh,
    cylindrical,
    face_frame,
    wall_labels,
)
from potflat.types import Mesh

#: Bins whose weight is below this fraction of the side's median bin weight get no radius.
_MIN_BIN_WEIGHT_FRACTION = 0.01
#: Automatic bin width in median edge lengths (as fine as the scan's edges), and the bin count limits.
_AUTO_BIN_EDGES = 1.0
_AUTO_BINS_MIN, _AUTO_BINS_MAX = 8, 5000
#: Runs of at most this many empty bins between measured ones are interpolated (so are longer
#: runs that the wall's faces cross: long triangles of a designed mesh, as the goblet's underside).
_MAX_GAP_BINS = 2
#: Faces reaching closer to the axis than this fraction of the largest radius count as base/floor.
_NEAR_AXIS_FRACTION = 0.25


@dataclass(frozen=True)
class Profile:
    """Radius of the outer and the inner wall against height along the axis.

    Attributes
    ----------
    heights : (k,) float64
        Bin centres, scan units along the axis, measured from ``origin`` (the scan's lowest
        point projected on the axis), so the foot is at 0 and the mouth at the top.
    bin_edges : (k + 1,) float64
        Bin boundaries, same frame as ``heights``.
    outer_radius : (k,) float64
        Weighted median distance of the outer wall from the axis (NaN where it has no data).
    inner_radius : (k,) float64
        Same for the inner wall; NaN where there is only one wall.
    outer_spread, inner_spread : (k,) float64
        Robust spread (interquartile range / 1.349) of the radii in each bin.
    outer_count, inner_count : (k,) int64
        Scan vertices of each wall whose height falls into the bin.
    origin : (3,) float64
        Point on the axis at height 0, scan coordinates.
    axis_direction : (3,) float64
        Unit axis direction, foot to mouth.
    units : str
        Length unit of the scan (``mm_per_unit`` converts to millimetres).
    mm_per_unit : float
    two_walled : bool
        True when the scan has an inner wall.
    base_height : float
        Height of the closed base's underside near the axis (NaN when the scan has no base).
    floor_height : float
        Height of the inner floor near the axis (NaN when the inner wall does not reach it).
    """

    heights: np.ndarray
    bin_edges: np.ndarray
    outer_radius: np.ndarray
    inner_radius: np.ndarray
    outer_spread: np.ndarray
    inner_spread: np.ndarray
    outer_count: np.ndarray
    inner_count: np.ndarray
    origin: np.ndarray
    axis_direction: np.ndarray
    units: str
    mm_per_unit: float
    two_walled: bool
    base_height: float = float("nan")
    floor_height: float = float("nan")

    @property
    def height_range(self) -> tuple[float, float]:
        """``(lowest, highest)`` bin edge, scan units."""
        return float(self.bin_edges[0]), float(self.bin_edges[-1])

    @property
    def max_radius(self) -> float:
        """Largest outer radius, scan units (NaN when the profile is empty)."""
        r = self.outer_radius[np.isfinite(self.outer_radius)]
        return float(r.max()) if len(r) else float("nan")

    def outer_radius_at(self, h: np.ndarray) -> np.ndarray:
        """Outer radius interpolated at heights ``h`` ((s,) float64, profile frame); NaN outside."""
        return _interp(self.heights, self.outer_radius, np.asarray(h, dtype=np.float64))

    def summary(self) -> dict:
        """JSON-ready figures (millimetres)."""
        s = self.mm_per_unit
        return {
            "bins": len(self.heights),
            "height_mm": float((self.bin_edges[-1] - self.bin_edges[0]) * s),
            "max_radius_mm": self.max_radius * s,
            "two_walled": self.two_walled,
            "origin": self.origin.tolist(),
            "axis_direction": self.axis_direction.tolist(),
            "bin_mm": float((self.bin_edges[1] - self.bin_edges[0]) * s) if len(self.heights) else None,
            "base_height_mm": float(self.base_height * s) if np.isfinite(self.base_height) else None,
            "floor_height_mm": float(self.floor_height * s) if np.isfinite(self.floor_height) else None,
        }


def _interp(x: np.ndarray, y: np.ndarray, at: np.ndarray) -> np.ndarray:
    ok = np.isfinite(y)
    if not ok.any():
        return np.full(at.shape, np.nan)
    return np.interp(at, x[ok], y[ok], left=np.nan, right=np.nan)


def vessel_profile(mesh: Mesh, axis_point, axis_direction, *, bins: int | None = None,
                   face_mask=None, labels=None, frame: FaceFrame | None = None) -> Profile:
    """Measure the vessel's profile (outer and inner radius against height).

    Parameters
    ----------
    mesh : Mesh
        The scan (open, holed and partial meshes are fine).
    axis_point : (3,) array_like
        A point on the axis, scan units.
    axis_direction : (3,) array_like
        Axis direction, foot to mouth.
    bins : int, optional
        Number of height bins. Default: bins one median edge length high, as fine as the
        scan's edges (between 8 and 5000).
    face_mask : (m,) bool, optional
        Faces to measure (e.g. without attachments); default all.
    labels : (m,) int8, optional
        Wall side per face (``WallSelection.labels``: 1 outer, -1 inner), to reuse a
        :func:`potflat.rollout.walls.select_wall` result; computed when omitted.
    frame : FaceFrame, optional
        ``face_frame(mesh, axis_point, axis_direction)`` when the caller has it (with the
        adjacency when ``labels`` is omitted); computed when omitted.

    Returns
    -------
    Profile

    Raises
    ------
    InvalidOptionError
        ``bins`` not a positive integer.
    InvalidInputError
        Bad mesh, axis, mask or labels.
    """
    if bins is not None and (isinstance(bins, bool) or not isinstance(bins, (int, np.integer)) or bins < 1):
        raise InvalidOptionError(f"bins must be a positive integer, got {bins!r}")
    check_mesh(mesh)
    p, a = check_axis(axis_point, axis_direction)
    m = len(mesh.faces)
    if face_mask is None:
        use = np.ones(m, dtype=bool)
    else:
        use = np.asarray(face_mask, dtype=bool)
        if use.shape != (m,):
            raise InvalidInputError(f"face_mask must have one entry per face ({m}), got shape {use.shape}")
        if not use.any():
            raise InvalidInputError("face_mask selects no faces; select at least part of the vessel")
    fr = face_frame(mesh, p, a, adjacency=labels is None) if frame is None else frame
    if labels is None:
        labels, _ = wall_labels(fr)
    else:
        labels = np.asarray(labels)
        if labels.shape != (m,) or not ((labels == OUTER) | (labels == INNER)).all():
            raise InvalidInputError("labels must hold 1 (outer) or -1 (inner) for every face")

    F = mesh.faces if use.all() else np.take(mesh.faces, np.flatnonzero(use), axis=0)
    lab = labels[use]
    h_v, r_v, _ = cylindrical(mesh.vertices, p, a)
    n = len(mesh.vertices)
    used_v = np.flatnonzero(np.bincount(F.ravel(), minlength=n))
    h0 = float(h_v[used_v].min())
    h1 = float(h_v[used_v].max())
    if bins is None:
        med_edge = median_edge_length(mesh.vertices, F)
        bins = int(np.clip(math.ceil((h1 - h0) / max(_AUTO_BIN_EDGES * med_edge, 1e-300)),
                           _AUTO_BINS_MIN, _AUTO_BINS_MAX))
    span = h1 - h0 if h1 > h0 else 1.0
    edges = np.linspace(0.0, span, int(bins) + 1)
    hh = h_v - h0

    centres = 0.5 * (edges[:-1] + edges[1:])
    out = {}
    for name, side in (("outer", OUTER), ("inner", INNER)):
        sel = lab == side
        Fs = np.take(F, np.flatnonzero(sel), axis=0).ravel()
        # vertex weight: projected area of its faces that face away from (outer) / towards
        # (inner) the axis, i.e. their area on a cylinder around the axis
        wf = fr.area[use][sel] / 3.0 * np.maximum(side * fr.n_radial[use][sel], 0.0)
        wv = np.bincount(Fs, weights=np.repeat(wf, 3), minlength=n)
        verts = np.flatnonzero(np.bincount(Fs, minlength=n))
        (q25, q50, q75, hmed), total = binned_median(
            hh[verts], r_v[verts], wv[verts], edges, (0.25, 0.5, 0.75), extra=hh[verts])
        if (total > 0).any():
            low = total < _MIN_BIN_WEIGHT_FRACTION * np.median(total[total > 0])
            q25[low] = q50[low] = q75[low] = hmed[low] = np.nan
        b = np.clip(np.searchsorted(edges, hh[verts], side="right") - 1, 0, int(bins) - 1)
        out[name] = (_at_centres(centres, hmed, q50, _crossed(hh, F[sel], edges)), (q75 - q25) / 1.349,
                     np.bincount(b, minlength=int(bins)).astype(np.int64))
    rmax = float(np.nanmax(np.r_[out["outer"][0], 0.0]))
    r_f = r_v[mesh.faces]
    near = use & (np.minimum(np.minimum(r_f[:, 0], r_f[:, 1]), r_f[:, 2]) < _NEAR_AXIS_FRACTION * rmax)
    del r_f
    base = near & (labels == OUTER) & (fr.n_axial < -0.5)
    floor = near & (labels == INNER) & (fr.n_axial > 0.5)
    return Profile(
        heights=centres,
        bin_edges=edges,
        outer_radius=out["outer"][0],
        inner_radius=out["inner"][0],
        outer_spread=out["outer"][1],
        inner_spread=out["inner"][1],
        outer_count=out["outer"][2],
        inner_count=out["inner"][2],
        origin=p + h0 * a,
        axis_direction=a,
        units=mesh.units,
        mm_per_unit=mesh.mm_per_unit,
        two_walled=bool(np.isfinite(out["inner"][0]).any()),
        base_height=weighted_percentile(fr.height[base] - h0, fr.area[base], 50.0),
        floor_height=weighted_percentile(fr.height[floor] - h0, fr.area[floor], 50.0),
    )


def _crossed(h: np.ndarray, faces: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Which height bins (``edges``) the faces cross: (bins,) bool, from each face's lowest
    to its highest corner (``h`` the vertices' heights)."""
    bins = len(edges) - 1
    if not len(faces):
        return np.zeros(bins, bool)
    hf = h[faces]
    lo = np.clip(np.searchsorted(edges, hf.min(axis=1), side="right") - 1, 0, bins - 1)
    hi = np.clip(np.searchsorted(edges, hf.max(axis=1), side="right") - 1, 0, bins - 1)
    starts = np.bincount(lo, minlength=bins + 1) - np.bincount(hi + 1, minlength=bins + 1)
    return np.cumsum(starts)[:bins] > 0


def _at_centres(centres: np.ndarray, h: np.ndarray, r: np.ndarray, crossed: np.ndarray | None = None) -> np.ndarray:
    """Radius at the bin centres from per-bin (median height, median radius) points.

    Within a bin where r(h) is monotonic, the weighted median radius is the radius at the
    weighted median height, so the points lie on the profile; linear interpolation moves
    them to the bin centres. Gaps of up to ``_MAX_GAP_BINS`` empty bins (a coarse mesh) are
    bridged, and so are longer ones the wall's faces cross throughout (``crossed``: triangles
    longer than the bins, with no vertex there); other gaps (holes) and the ends stay NaN.
    """
    ok = np.isfinite(h) & np.isfinite(r)
    out = np.full(len(centres), np.nan)
    if ok.sum() == 0:
        return out
    if ok.sum() == 1:
        out[ok] = r[ok]
        return out
    hk, rk = h[ok], r[ok]
    order = np.argsort(hk, kind="stable")
    hk, rk = hk[order], rk[order]
    est = np.interp(centres, hk, rk)
    lo, hi = centres < hk[0], centres > hk[-1]
    if hk[1] > hk[0]:
        est[lo] = rk[0] + (centres[lo] - hk[0]) * (rk[1] - rk[0]) / (hk[1] - hk[0])
    if hk[-1] > hk[-2]:
        est[hi] = rk[-1] + (centres[hi] - hk[-1]) * (rk[-1] - rk[-2]) / (hk[-1] - hk[-2])
    keep = ok.copy()
    idx = np.flatnonzero(ok)
    for i, j in itertools.pairwise(idx):
        if 1 < j - i <= _MAX_GAP_BINS + 1 or (j - i > 1 and crossed is not None and crossed[i + 1:j].all()):
            keep[i + 1:j] = True
    out[keep] = est[keep]
    return out


def write_profile_csv(profile: Profile, path) -> Path:
    """Write the profile as CSV in millimetres, atomically.

    Columns: ``height_mm`` (bin centre above the foot), ``outer_radius_mm``,
    ``inner_radius_mm``; an empty field means no data (e.g. no inner wall at that height).

    Parameters
    ----------
    profile : Profile
    path : str or Path

    Returns
    -------
    Path
    """
    _check_profile(profile)
    s = profile.mm_per_unit

    def fmt(x: float) -> str:
        return "" if not np.isfinite(x) else f"{x * s:.4f}"

    lines = ["height_mm,outer_radius_mm,inner_radius_mm"]
    for h, ro, ri in zip(profile.heights, profile.outer_radius, profile.inner_radius):
        lines.append(f"{h * s:.4f},{fmt(ro)},{fmt(ri)}")
    return write_bytes_atomic(path, ("\n".join(lines) + "\n").encode("utf-8"))


def _check_profile(profile) -> None:
    if not isinstance(profile, Profile):
        raise InvalidInputError(f"expected a Profile from vessel_profile, got {type(profile).__name__}")


def section_polygon(profile: Profile) -> tuple[np.ndarray, np.ndarray] | None:
    """The wall section as a closed polygon, right of the axis (radius >= 0).

    It runs up the outer wall and down the inner wall over the longest stretch where both
    were scanned; when the inner wall reaches the floor of a closed vessel it continues
    through the base to the axis. ``None`` when the scan has no inner wall (the drawing
    then shows the outer line only).

    Parameters
    ----------
    profile : Profile

    Returns
    -------
    radius, height : (p,) float64 and (p,) float64, or None
        Polygon corners, scan units (height in the profile's frame).
    """
    ro, ri, hs = profile.outer_radius, profile.inner_radius, profile.heights
    ok_o = np.isfinite(ro)
    ok_i = np.isfinite(ri) & ok_o
    if not ok_i.any():
        return None
    i0, i1 = max(_runs(ok_i), key=lambda r: r[1] - r[0])
    rs = np.r_[ro[i0:i1], ri[i0:i1][::-1]]
    ys = np.r_[hs[i0:i1], hs[i0:i1][::-1]]
    fh, bh = profile.floor_height, profile.base_height
    if np.isfinite(fh) and np.isfinite(bh) and fh > bh:
        # closed vessel: the section runs through the base, from the foot to the floor
        below = np.flatnonzero(ok_o[:i0] & (hs[:i0] > bh))
        r_bh = float(np.interp(bh, hs[ok_o], ro[ok_o]))
        rs = np.r_[0.0, r_bh, ro[below], rs, 0.0]
        ys = np.r_[bh, bh, hs[below], ys, fh]
    return rs.astype(np.float64), ys.astype(np.float64)


def read_profile_csv(path, summary: dict) -> Profile:
    """Read ``NAME.profile.csv`` back as a :class:`Profile` in millimetres.

    Parameters
    ----------
    path : str or Path
        The CSV written by :func:`write_profile_csv`.
    summary : dict
        The ``profile`` entry of ``NAME.rollout.json`` (:meth:`Profile.summary`): axis,
        base and floor heights.

    Returns
    -------
    Profile
        Heights and radii in millimetres (units ``mm``); ``origin`` and ``axis_direction``
        are copied from ``summary`` (scan coordinates); spreads NaN and counts 0 (the CSV
        does not hold them).

    Raises
    ------
    InvalidInputError
        When the file is missing, unreadable or has no rows.
    """
    import warnings

    path = Path(path)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # an empty file: reported below
            rows = np.genfromtxt(path, delimiter=",", skip_header=1, dtype=np.float64, ndmin=2, missing_values="",
                                 filling_values=np.nan)
    except (OSError, ValueError) as exc:
        raise InvalidInputError(f"{path}: cannot read the profile ({exc}); run potflat rollout again") from None
    if rows.size == 0 or rows.shape[1] != 3 or not np.isfinite(rows[:, 0]).all():
        raise InvalidInputError(f"{path}: not a potflat profile (height_mm,outer_radius_mm,inner_radius_mm); "
                                "run potflat rollout again")
    h = rows[:, 0]
    step = float(summary.get("bin_mm") or (np.median(np.diff(h)) if len(h) > 1 else 1.0))
    edges = np.r_[h - 0.5 * step, h[-1] + 0.5 * step]
    nan = np.full(len(h), np.nan)
    zero = np.zeros(len(h), np.int64)
    get = lambda key: float(summary[key]) if summary.get(key) is not None else float("nan")  # noqa: E731
    return Profile(heights=h, bin_edges=edges, outer_radius=rows[:, 1], inner_radius=rows[:, 2],
                   outer_spread=nan, inner_spread=nan, outer_count=zero, inner_count=zero,
                   origin=np.asarray(summary.get("origin", (0.0, 0.0, 0.0)), np.float64),
                   axis_direction=np.asarray(summary.get("axis_direction", (0.0, 0.0, 1.0)), np.float64),
                   units="mm", mm_per_unit=1.0, two_walled=bool(np.isfinite(rows[:, 2]).any()),
                   base_height=get("base_height_mm"), floor_height=get("floor_height_mm"))


def _runs(ok: np.ndarray) -> list[tuple[int, int]]:
    """Index ranges ``[i, j)`` of consecutive True values."""
    d = np.diff(np.r_[0, ok.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


def _nice_bar_cm(height_mm: float) -> int:
    """Scale-bar length in cm: the largest of 1, 2, 5, 10, 20, 50 not above half the height."""
    best = 1
    for c in (1, 2, 5, 10, 20, 50):
        if c * 10.0 <= 0.5 * height_mm:
            best = c
    return best


#: Publication scales tried by ``write_profile_svg(scale=None)``, largest first.
PUBLICATION_SCALES = (1.0, 1 / 2, 1 / 3, 1 / 4, 1 / 5, 1 / 10, 1 / 20)
#: The automatic scale keeps the drawing within this page area (A4 minus margins), mm.
_PAGE_MM = (180.0, 250.0)


def auto_scale(profile: Profile) -> float:
    """The largest of :data:`PUBLICATION_SCALES` at which the drawing fits an A4 page."""
    _check_profile(profile)
    lo, hi = profile.height_range
    height = (hi - lo) * profile.mm_per_unit
    width = 2 * np.nan_to_num(profile.max_radius, nan=0.0) * profile.mm_per_unit
    for s in PUBLICATION_SCALES:
        if width * s <= _PAGE_MM[0] and height * s <= _PAGE_MM[1]:
            return s
    return PUBLICATION_SCALES[-1]


def write_profile_svg(profile: Profile, path, *, scale: float | None = None, title: str | None = None) -> Path:
    """Draw the profile as an archaeological section drawing (SVG, true scale), atomically.

    Right of the axis: the wall section, filled black between the outer and the inner line
    where both walls were scanned (closed to the axis through the base when the inner wall
    reaches the floor), otherwise a thick outer line. Left of the axis: the outer silhouette
    (exterior view), with the rim and base lines across. A dash-dot centre line marks the
    axis; a scale bar in centimetres sits below. ``width``/``height`` are in millimetres, so
    the file prints at ``1 : 1/scale``.

    Parameters
    ----------
    profile : Profile
    path : str or Path
    scale : float, optional
        Drawing millimetres per vessel millimetre (1.0 = 1:1, 0.5 = 1:2). Default: the
        largest of 1:1, 1:2, 1:3, 1:4, 1:5, 1:10, 1:20 at which the drawing fits an A4 page
        (:func:`auto_scale`).
    title : str, optional
        Caption written below the drawing.

    Returns
    -------
    Path
    """
    _check_profile(profile)
    if scale is None:
        scale = auto_scale(profile)
    if not (isinstance(scale, (int, float)) and not isinstance(scale, bool) and math.isfinite(scale) and scale > 0):
        raise InvalidOptionError(f"scale must be a positive number (drawing mm per vessel mm), got {scale!r}")
    mm = profile.mm_per_unit * float(scale)  # drawing mm per scan unit
    ro, ri, hs = profile.outer_radius, profile.inner_radius, profile.heights
    ok_o = np.isfinite(ro)
    if not ok_o.any():
        raise InvalidInputError(
            "the profile has no outer wall radius at any height (no wall faces away from the axis); "
            "check the axis or the scan")
    h_lo, h_hi = profile.height_range
    rmax = float(np.nanmax(np.r_[ro[ok_o], ri[np.isfinite(ri)]]))
    margin = 10.0
    half = rmax * mm
    draw_h = (h_hi - h_lo) * mm
    bar_cm = _nice_bar_cm((h_hi - h_lo) * profile.mm_per_unit)
    bar_len = bar_cm * 10.0 * scale
    width = 2 * margin + max(2 * half, bar_len + 20.0)
    height = 2 * margin + draw_h + 22.0 + (6.0 if title else 0.0)
    cx = width / 2

    def X(r):
        return cx + np.asarray(r) * mm

    def Y(h):
        return margin + (h_hi - np.asarray(h)) * mm

    def pts(xs, ys) -> str:
        return " ".join(f"{x:.3f},{y:.3f}" for x, y in zip(np.atleast_1d(xs), np.atleast_1d(ys)))

    thick, thin = 0.7, 0.25
    parts = []
    # exterior view (left): silhouette, rim and base lines
    for i, j in _runs(ok_o):
        parts.append(f'<polyline points="{pts(X(-ro[i:j]), Y(hs[i:j]))}" fill="none" stroke="black" '
                     f'stroke-width="{thin}" stroke-linejoin="round"/>')
    top, bot = np.flatnonzero(ok_o)[[-1, 0]]
    for k in (top, bot):
        parts.append(f'<line x1="{X(-ro[k]):.3f}" y1="{Y(hs[k]):.3f}" x2="{cx:.3f}" y2="{Y(hs[k]):.3f}" '
                     f'stroke="black" stroke-width="{thin}"/>')
    # section (right)
    section = section_polygon(profile)
    if section is not None:
        parts.append(f'<polygon points="{pts(X(section[0]), Y(section[1]))}" fill="black" stroke="black" '
                     f'stroke-width="{thin}" stroke-linejoin="round"/>')
    for i, j in _runs(ok_o):
        parts.append(f'<polyline points="{pts(X(ro[i:j]), Y(hs[i:j]))}" fill="none" stroke="black" '
                     f'stroke-width="{thick}" stroke-linejoin="round" stroke-linecap="round"/>')
    # centre axis, dash-dot
    parts.append(f'<line x1="{cx:.3f}" y1="{margin - 4:.3f}" x2="{cx:.3f}" y2="{margin + draw_h + 4:.3f}" '
                 f'stroke="black" stroke-width="{thin}" stroke-dasharray="6 1.5 1 1.5"/>')
    # scale bar: alternating 1 cm blocks (or one block per bar/5 for long bars)
    by = margin + draw_h + 10.0
    bx = cx - bar_len / 2
    n_blocks = bar_cm if bar_cm <= 10 else 5
    block = bar_len / n_blocks
    for k in range(n_blocks):
        fill = "black" if k % 2 == 0 else "white"
        parts.append(f'<rect x="{bx + k * block:.3f}" y="{by:.3f}" width="{block:.3f}" height="1.5" '
                     f'fill="{fill}" stroke="black" stroke-width="0.15"/>')
    font = 'font-family="sans-serif" font-size="3" text-anchor="middle"'
    parts.append(f'<text x="{bx:.3f}" y="{by + 5.5:.3f}" {font}>0</text>')
    parts.append(f'<text x="{bx + bar_len:.3f}" y="{by + 5.5:.3f}" {font}>{bar_cm} cm</text>')
    ratio = "1:1" if scale == 1 else (f"1:{1 / scale:.3g}" if scale < 1 else f"{scale:.3g}:1")
    parts.append(f'<text x="{bx + bar_len + 8:.3f}" y="{by + 1.5:.3f}" {font}>{ratio}</text>')
    if title:
        parts.append(f'<text x="{cx:.3f}" y="{by + 11.5:.3f}" {font}>{escape(title)}</text>')
    svg = (
        '<?xml version="1.0" encoding="UTF-8"?>\n'
        f'<svg xmlns="http://www.w3.org/2000/svg" version="1.1" width="{width:.3f}mm" '
        f'height="{height:.3f}mm" viewBox="0 0 {width:.3f} {height:.3f}">\n'
        f'<title>{escape(title or "vessel profile")}</title>\n'
        '<rect x="0" y="0" width="100%" height="100%" fill="white"/>\n'
        + "\n".join(parts)
        + "\n</svg>\n"
    )
    return write_bytes_atomic(path, svg.encode("utf-8"))
