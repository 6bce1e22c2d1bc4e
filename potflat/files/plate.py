"""The archaeological plate: profile section and outside view, the rollout below, at a stated scale.

:func:`make_plate` composes, from the files of one flattened scan, the vessel drawing as it is
published: left of the axis the outside view (the scan's painted surface seen from the
rollout's centre, orthographic), right of it the wall section (the profile), the rollout
below at the same stated scale (1:1, 1:2, ...), a scale bar and a caption. It writes

* ``NAME.plate.svg``: text as text, the profile and scale bar as vector paths, the outside
  view and the rollout as embedded images (editable in Inkscape or Illustrator);
* ``NAME.plate.pdf``: the same;
* ``NAME.plate.png``: a preview at :data:`PREVIEW_DPI`.

SVG and PDF pages are sized in millimetres so that printing at 100 % gives the stated
scale. The rollout is ``NAME.png`` as baked, or its relief in raking light
(``NAME.raking-AZ.png`` of a bake with ``--relief``), or both one above the other (its pixels
embedded unchanged); the outside view is rendered at :data:`VIEW_DPI` on paper.
"""
from __future__ import annotations

import io
import math
import os
import textwrap
import time
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from potflat import __version__
from potflat.bake import bake
from potflat.bake.annotate import nice_length
from potflat.bake.options import PLATE_IMAGES, parse_scale
from potflat.bake.relief import raking_key
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.files.names import stage_name
from potflat.io.atomic import write_bytes_atomic
from potflat.io.flat_ply import read_flat_ply
from potflat.mesh.distortion import distortion_words, painted_zone_distortion
from potflat.rollout.profile import _runs, read_profile_csv, section_polygon
from potflat.types import FlatMesh

#: Scales tried when none is given, largest first (drawing mm per vessel mm).
PLATE_SCALES = (1.0, 1 / 2, 1 / 3, 1 / 4, 1 / 5, 1 / 10, 1 / 20, 1 / 50)
#: Paper sizes the plate's page is measured against (portrait, mm), smallest first: the automatic
#: scale is the largest of :data:`PLATE_SCALES` whose page fits the first.
PAPERS = {"A4": (210.0, 297.0), "A3": (297.0, 420.0)}
#: Page margin, gap between the parts, caption font size (pt) and line height, mm.
MARGIN_MM, GAP_MM, FONT_PT, LINE_MM = 12.0, 8.0, 7.5, 4.2
#: Mean width of a caption character in ems (for wrapping the caption to the page).
CHAR_EM = 0.56
#: Resolution of the PNG preview, and of the outside view on paper, dots per inch.
PREVIEW_DPI, VIEW_DPI = 150.0, 300.0


@dataclass(frozen=True)
class PlateFiles:
    """What :func:`make_plate` wrote.

    Attributes
    ----------
    paths : dict of str to Path
        ``"svg"``, ``"pdf"``, ``"png"`` to the file written.
    record : dict
        Scale, page size, figures and the files, as ``NAME.bake.json`` records them.
    """

    paths: dict[str, Path]
    record: dict


def scale_label(scale: float) -> str:
    """``1:5`` for 0.2, ``2:1`` for 2, ``1:2.5`` for 0.4."""
    if scale >= 1:
        return f"{scale:.3g}:1"
    return f"1:{1 / scale:.3g}"


@dataclass(frozen=True)
class _Sources:
    """What the plate is made of, read from the files beside ``NAME.relaxed.ply``."""

    name: str
    flat: object  # FlatMesh
    rollout: dict
    relax: dict
    bake: dict
    profile: object  # Profile in mm
    rollouts: tuple  # (what, (h, w, 4) uint8) of each rollout image, top to bottom: NAME.png and/or its relief
    inputs: tuple


def _read_json(path: Path, hint: str) -> dict:
    import json

    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise InvalidInputError(f"{path} is missing; {hint}") from None
    except (OSError, ValueError) as exc:
        raise InvalidInputError(f"{path}: unreadable ({exc}); {hint}") from None


def _read_rgba(path: Path) -> np.ndarray:
    """A baked ``NAME.png`` as (h, w, 4) uint8 (with its alpha, which the texture reader drops)."""
    from PIL import Image

    try:
        with Image.open(path) as img:
            return np.asarray(img.convert("RGBA"))
    except (OSError, ValueError, Image.DecompressionBombError) as exc:
        raise InvalidInputError(f"{path}: unreadable image ({exc}); bake it again") from None


def _relief_image(bake: dict, bake_dir: Path, relaxed_ply: Path) -> tuple[str, Path]:
    """What the relief image of a bake shows and its file (the raking light from the bake's
    first azimuth)."""
    relief = bake.get("relief") if isinstance(bake.get("relief"), dict) else {}
    lights = relief.get("light_azimuth_deg")
    again = f"bake it with --relief first: potflat bake {relaxed_ply} --relief"
    if not isinstance(lights, list) or not lights:
        raise InvalidInputError(f"the bake of {relaxed_ply.name} has no relief images; {again}")
    key = raking_key(float(lights[0]))
    png = bake_dir / bake.get("files", {}).get(key, f"{key}.png")
    if not png.is_file():
        raise InvalidInputError(f"{png} is missing; {again}")
    return f"relief in raking light from {float(lights[0]):g} degrees", png


def _sources(relaxed_ply: Path, name: str | None, bake_dir: Path, image: str) -> _Sources:
    if not relaxed_ply.name.endswith(".relaxed.ply"):
        raise InvalidInputError(f"{relaxed_ply.name}: the plate is made from NAME.relaxed.ply (with the rollout, "
                                "relax and bake files beside it); give that file")
    stem = stage_name(relaxed_ply)
    folder = relaxed_ply.parent
    rerun = "run potflat run (or rollout, relax and bake) into this folder first"
    rollout = _read_json(folder / f"{stem}.rollout.json", rerun)
    relax = _read_json(folder / f"{stem}.relaxed.json", rerun)
    bake_json = bake_dir / f"{name or stem}.bake.json"
    bake = _read_json(bake_json, f"bake it first: potflat bake {relaxed_ply}")
    png = bake_dir / bake.get("files", {}).get("png", f"{name or stem}.png")
    csv = folder / rollout.get("files", {}).get("profile_csv", f"{stem}.profile.csv")
    if not png.is_file():
        raise InvalidInputError(f"{png} is missing; bake it first: potflat bake {relaxed_ply}")
    profile = read_profile_csv(csv, rollout.get("profile", {}))
    shown = []
    if image in ("painting", "both"):
        shown.append(("painting" if bake.get("painting") != "relief" else "relief", png))
    if image in ("relief", "both"):
        shown.append(_relief_image(bake, bake_dir, relaxed_ply))
    return _Sources(name=name or stem, flat=read_flat_ply(relaxed_ply), rollout=rollout, relax=relax, bake=bake,
                    profile=profile, rollouts=tuple((what, _read_rgba(path)) for what, path in shown),
                    inputs=(relaxed_ply, folder / f"{stem}.rollout.json", folder / f"{stem}.relaxed.json",
                            bake_json, *(path for _, path in shown), csv))


def view_direction(rollout_summary: dict) -> np.ndarray:
    """Unit direction from the axis towards the viewer of the outside view: the rollout's centre.

    The centre angle is the middle of the angles the rollout covers (measured from the seam,
    or from the landmark of a window), turned from the axis' reference direction,
    counter-clockwise about the axis (mouth up). Shape (3,) float64.
    """
    ax = rollout_summary["axis"]
    a = np.asarray(ax["direction"], np.float64)
    ref = np.asarray(ax["reference_direction"], np.float64)
    region = rollout_summary.get("region", {})
    lo, hi = region.get("theta_range_deg") or (0.0, 360.0)
    hi -= region.get("overlap_deg") or 0.0  # the repeat past 360 degrees is not part of the view
    seam = rollout_summary["seam"]
    origin = seam.get("theta_origin_deg", seam["angle_deg"])  # angles of a window start at its landmark
    phi = math.radians(origin + 0.5 * (lo + hi))
    d = math.cos(phi) * ref + math.sin(phi) * np.cross(a, ref)
    return d / np.linalg.norm(d)


def outside_view(flat, rollout_summary: dict, px_per_mm: float):
    """Orthographic outside view of the flattened surface from the rollout's centre.

    The faces turned towards the viewer (:func:`view_direction`) are projected onto the plane
    of the axis (``x`` to the right of the axis, ``y`` up the axis from the profile's
    origin) and baked with the painting, as :func:`potflat.bake.bake` bakes a flattening.

    Parameters
    ----------
    flat : FlatMesh
        ``NAME.relaxed.ply`` (its 3D vertices, faces and painting).
    rollout_summary : dict
        ``NAME.rollout.json`` (axis, seam, profile origin).
    px_per_mm : float
        Resolution of the view, pixels per vessel millimetre.

    Returns
    -------
    BakeResult
        ``uv`` frame: scan units, ``x`` from the axis, ``y`` from the profile's origin.
    """

    mesh = flat.mesh
    a = np.asarray(rollout_summary["axis"]["direction"], np.float64)
    a /= np.linalg.norm(a)
    origin = np.asarray(rollout_summary.get("profile", {}).get("origin") or rollout_summary["axis"]["point"], np.float64)
    d = view_direction(rollout_summary)
    right = np.cross(a, d)
    V, F = mesh.vertices, mesh.faces
    normal = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    front = np.flatnonzero(normal @ d > 0)
    if len(front) == 0:
        raise InvalidInputError(f"{mesh.source or 'the flattening'} shows no face towards the viewer; "
                                "cannot draw its outside view")
    sub = mesh.replace(faces=F[front], **mesh.face_fields(front))
    rel = V - origin
    uv = np.stack([rel @ right, rel @ a], axis=1)
    return bake(FlatMesh(sub, uv), px_per_mm=px_per_mm, maps=(), max_megapixels=200.0)


def _page_mm(scale: float, drawing_mm: tuple[float, float], rollout_mm: tuple[float, float], gaps_mm: float,
             caption: list[tuple[str, str]]) -> tuple[float, float, list[tuple[str, str]]]:
    """The page's width and height (mm) at ``scale`` for a drawing and rollout images of these
    sizes (vessel mm; ``gaps_mm`` between the images, on paper), and the caption's lines wrapped
    to its width."""
    draw_w, draw_h = drawing_mm[0] * scale, drawing_mm[1] * scale
    roll_w, roll_h = rollout_mm[0] * scale, rollout_mm[1] * scale + gaps_mm
    page_w = max(draw_w, roll_w, 120.0) + 2 * MARGIN_MM
    chars = max(40, int((page_w - 2 * MARGIN_MM) / (FONT_PT * 25.4 / 72 * CHAR_EM)))
    lines = [(piece, weight) for text, weight in caption for piece in textwrap.wrap(text, chars)]
    page_h = 2 * MARGIN_MM + draw_h + GAP_MM + roll_h + GAP_MM + 8.0 + len(lines) * LINE_MM
    return page_w, page_h, lines


def _fits(page_mm, paper: str) -> bool:
    """Whether a page of ``page_mm`` (width, height) fits on ``paper``, upright or turned."""
    return all(a <= b + 1e-6 for a, b in zip(sorted(page_mm), PAPERS[paper]))


def paper_of(page_mm) -> str | None:
    """The smallest of :data:`PAPERS` a page of ``page_mm`` (width, height) fits; None when
    it fits none."""
    return next((name for name in PAPERS if _fits(page_mm, name)), None)


def paper_words(facts: dict) -> str:
    """The page's paper in words, from the plate's ``facts`` (its record): ``fits A4``,
    ``fits A3, larger than A4: 1:5 fits A4`` or ``larger than A3: 1:10 fits A4, 1:5 fits A3``."""
    names, paper = list(PAPERS), facts["paper"]
    if paper == names[0]:
        return f"fits {paper}"
    smaller = names[:names.index(paper)] if paper else names
    size = f"fits {paper}, larger than {names[0]}" if paper else f"larger than {names[-1]}"
    hints = [f"{facts['largest_scale_on'][name]} fits {name}" for name in smaller
             if facts["largest_scale_on"].get(name)]
    return size + (": " + ", ".join(hints) if hints else "")


def _plate_date() -> str:
    """Today (UTC), or the date of ``SOURCE_DATE_EPOCH`` when set (reproducible outputs)."""
    epoch = os.environ.get("SOURCE_DATE_EPOCH")
    stamp = float(epoch) if epoch and epoch.strip().isdigit() else time.time()
    return datetime.fromtimestamp(stamp, tz=timezone.utc).date().isoformat()


def _scale_bar(ax, x0: float, y0: float, scale: float, max_paper_mm: float) -> float:
    """Draw a bar of alternating blocks at paper ``(x0, y0)`` (mm, bottom left); returns its paper length."""
    from matplotlib.patches import Rectangle

    length = nice_length(max_paper_mm / scale)  # vessel mm
    lead = round(length / 10 ** math.floor(math.log10(length)))
    blocks = 4 if lead == 2 else 5
    paper = length * scale
    for k in range(blocks):
        ax.add_patch(Rectangle((x0 + k * paper / blocks, y0), paper / blocks, 1.5, facecolor="black" if k % 2 == 0
                               else "white", edgecolor="black", linewidth=0.4))
    unit, value = ("cm", length / 10) if length >= 10 else ("mm", length)
    ax.text(x0, y0 - 1.2, "0", ha="center", va="top", fontsize=FONT_PT)
    ax.text(x0 + paper, y0 - 1.2, f"{value:g} {unit}", ha="center", va="top", fontsize=FONT_PT)
    return paper


def compose_plate(src: _Sources, scale: float | None):
    """The plate as a matplotlib figure sized in millimetres; returns ``(figure, facts)``."""
    from matplotlib.figure import Figure

    prof = src.profile
    ro = prof.outer_radius
    ok = np.isfinite(ro)
    if not ok.any():
        raise InvalidInputError(f"{src.name}: the profile has no outer wall radius; run potflat rollout again")
    rmax = float(np.nanmax(np.r_[ro[ok], prof.inner_radius[np.isfinite(prof.inner_radius)]]))
    h_lo, h_hi = prof.height_range
    roll_ppm = float(src.bake["px_per_mm"])
    sizes = [(img.shape[1] / roll_ppm, img.shape[0] / roll_ppm) for _, img in src.rollouts]
    roll_w, roll_h = max(w for w, _ in sizes), sum(h for _, h in sizes)
    gaps = GAP_MM * (len(sizes) - 1)  # between the rollout images, on paper
    figures, where = painted_zone_distortion(src.relax)
    proxy = src.rollout.get("proxy", {}).get("type", "?")
    preset = src.relax.get("preset") or src.relax.get("options", {}).get("preset", "?")
    date = _plate_date()

    def caption(scale: float) -> list[tuple[str, str]]:
        return [
            (src.name, "bold"),
            (f"Rollout computed from a 3D scan by potflat {__version__} on {date}: proxy {proxy}, relaxation "
             f"preset {preset}.", "normal"),
            (f"Distortion in the {where}: {distortion_words(figures)}.", "normal"),
            (f"Scale {scale_label(scale)} when printed at 100 %. Left of the axis the outside view, right of it "
             f"the section; the rollout below ({', then '.join(what for what, _ in src.rollouts)}), seen from "
             "outside, mouth up.", "normal"),
        ]

    def drawing(px_per_mm: float):
        """The outside view at ``px_per_mm`` and the drawing's half width and heights (vessel mm)."""
        view = outside_view(src.flat, src.rollout, px_per_mm)
        vx0, vy1 = view.origin * src.flat.mesh.mm_per_unit  # mm: left edge, top edge
        vy0 = vy1 - view.painting.shape[0] / view.px_per_mm
        return view, max(rmax, -vx0), min(h_lo, vy0), max(h_hi, vy1)

    def largest_on(paper: str, extent: tuple[float, float]) -> float | None:
        """The largest of :data:`PLATE_SCALES` at which the page fits ``paper``."""
        return next((s for s in PLATE_SCALES
                     if _fits(_page_mm(s, extent, (roll_w, roll_h), gaps, caption(s))[:2], paper)), None)

    if scale is None:  # the largest whose page fits A4, from the view's extent at 1 px/mm (+ a pixel each side)
        _, half, y_lo, y_hi = drawing(1.0)
        scale = largest_on(next(iter(PAPERS)), (2 * half + 2.0, y_hi - y_lo + 2.0)) or PLATE_SCALES[-1]
    view, half, y_lo, y_hi = drawing(min(VIEW_DPI / 25.4 * scale, 40.0))
    s_px = view.px_per_mm * src.flat.mesh.mm_per_unit  # view pixels per scan unit
    vx0, vy1 = view.origin * src.flat.mesh.mm_per_unit
    vy0 = vy1 - view.painting.shape[0] / view.px_per_mm
    extent = (2 * half, y_hi - y_lo)
    draw_w, draw_h = extent[0] * scale, extent[1] * scale
    paper_roll = (roll_w * scale, roll_h * scale + gaps)
    label = scale_label(scale)
    page_w, page_h, lines = _page_mm(scale, extent, (roll_w, roll_h), gaps, caption(scale))
    fits = {paper: scale_label(s) if (s := largest_on(paper, extent)) else None for paper in PAPERS}
    fig = Figure(figsize=(page_w / 25.4, page_h / 25.4), facecolor="white")
    paper = fig.add_axes((0, 0, 1, 1))
    paper.set_xlim(0, page_w)
    paper.set_ylim(0, page_h)
    paper.set_axis_off()

    # vessel drawing: outside view left of the axis, section right of it
    cx = page_w / 2
    top = page_h - MARGIN_MM
    vessel = fig.add_axes(((cx - half * scale) / page_w, (top - draw_h) / page_h, draw_w / page_w, draw_h / page_h))
    vessel.set_xlim(-half, half)
    vessel.set_ylim(y_lo, y_hi)
    vessel.set_axis_off()
    axis_col = int(round(-view.origin[0] * s_px))
    if axis_col > 0:
        vessel.imshow(view.painting[:, :axis_col], extent=(vx0, vx0 + axis_col / view.px_per_mm, vy0, vy1),
                      interpolation="none", aspect="auto")
    hs = prof.heights
    for i, j in _runs(ok):
        vessel.plot(-ro[i:j], hs[i:j], color="black", linewidth=0.4, solid_joinstyle="round")
    section = section_polygon(prof)
    if section is not None:
        vessel.fill(section[0], section[1], facecolor="black", edgecolor="black", linewidth=0.3)
    for i, j in _runs(ok):
        vessel.plot(ro[i:j], hs[i:j], color="black", linewidth=1.2, solid_joinstyle="round", solid_capstyle="round")
    k_top, k_bot = np.flatnonzero(ok)[[-1, 0]]
    for k in (k_top, k_bot):
        vessel.plot([-ro[k], ro[k]], [hs[k], hs[k]], color="black", linewidth=0.4)
    vessel.plot([0, 0], [y_lo, y_hi], color="black", linewidth=0.4, linestyle=(0, (8, 2, 1.5, 2)))

    # rollout images below, same scale, one above the other
    roll_top = top - draw_h - GAP_MM
    y = roll_top
    for (_, image), (w, h) in zip(src.rollouts, sizes):
        paper_w, paper_h = w * scale, h * scale
        rx = cx - paper_w / 2
        roll = fig.add_axes((rx / page_w, (y - paper_h) / page_h, paper_w / page_w, paper_h / page_h))
        roll.imshow(image, extent=(0, w, 0, h), interpolation="none", aspect="auto")
        roll.set_xlim(0, w)
        roll.set_ylim(0, h)
        roll.set_axis_off()
        y -= paper_h + GAP_MM

    # scale bar and caption
    bar_y = roll_top - paper_roll[1] - GAP_MM + 2.0
    bar_paper = _scale_bar(paper, MARGIN_MM, bar_y, scale, min(60.0, page_w - 2 * MARGIN_MM - 30.0))
    paper.text(MARGIN_MM + bar_paper + 6.0, bar_y + 0.75, f"scale {label}", va="center", fontsize=FONT_PT)
    y = bar_y - 6.0
    for text, weight in lines:
        paper.text(MARGIN_MM, y, text, fontsize=FONT_PT, fontweight=weight, va="top", wrap=False)
        y -= LINE_MM
    facts = {"scale": scale, "scale_label": label, "page_mm": [page_w, page_h], "paper": paper_of((page_w, page_h)),
             "largest_scale_on": fits, "drawing_mm": [draw_w, draw_h],
             "rollout_mm": list(paper_roll), "distortion_where": where, "distortion": figures, "date": date,
             "proxy": proxy, "preset": preset, "rollout_images": [what for what, _ in src.rollouts],
             "profile_rows": int(ok.sum()),
             "profile_step_mm": float(np.median(np.diff(hs))) if len(hs) > 1 else None}
    return fig, facts


def make_plate(relaxed_ply: str | os.PathLike, out_dir: str | os.PathLike | None = None, *,
               scale: float | str | None = None, name: str | None = None, image: str = "painting") -> PlateFiles:
    """Write ``NAME.plate.svg``, ``NAME.plate.pdf`` and ``NAME.plate.png`` for a flattened scan.

    Parameters
    ----------
    relaxed_ply : path-like
        ``NAME.relaxed.ply``; ``NAME.rollout.json``, ``NAME.profile.csv`` and
        ``NAME.relaxed.json`` must lie beside it.
    out_dir : path-like, optional
        Folder holding the bake's ``NAME.bake.json`` and ``NAME.png``, where the plate is
        written; default: the folder of ``relaxed_ply``.
    scale : float or str, optional
        Print scale (``"1:2"``, ``0.5``); default: the largest of :data:`PLATE_SCALES` at
        which drawing and rollout fit an A4 page.
    name : str, optional
        Output NAME and caption title; default the stage name.
    image : str
        The rollout as ``painting`` (``NAME.png``), as ``relief`` (the raking light from the
        first azimuth of a bake with ``--relief``) or ``both``, one above the other.

    Returns
    -------
    PlateFiles
        ``paths`` (``svg``, ``pdf``, ``png``) and ``record`` (scale, page size in mm,
        figures quoted).
    """
    import matplotlib

    if image not in PLATE_IMAGES:
        raise InvalidOptionError(f"unknown plate image {image!r}; choose from {', '.join(PLATE_IMAGES)}")
    relaxed_ply = Path(relaxed_ply)
    out = Path(out_dir) if out_dir is not None else relaxed_ply.parent
    src = _sources(relaxed_ply, name, out, image)
    fig, facts = compose_plate(src, parse_scale(scale))
    paths = {}
    rc = {"svg.fonttype": "none", "pdf.fonttype": 42, "svg.hashsalt": src.name}
    with matplotlib.rc_context(rc):
        for fmt, meta in (("svg", {"Date": None}), ("pdf", {"CreationDate": None, "ModDate": None}), ("png", None)):
            buf = io.BytesIO()
            kwargs = {"dpi": PREVIEW_DPI} if fmt == "png" else {"metadata": {**meta, "Title": f"{src.name}: plate"}}
            fig.savefig(buf, format=fmt, facecolor="white", **kwargs)
            paths[fmt] = write_bytes_atomic(out / f"{src.name}.plate.{fmt}", buf.getvalue())
    return PlateFiles(paths=paths, record={**facts, "files": {k: p.name for k, p in paths.items()},
                                              "inputs": [str(p) for p in src.inputs]})
