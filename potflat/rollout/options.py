"""Options of the rollout stage: light (no scipy, trimesh or Numba), so the command line
builds its options and ``--help`` without importing the algorithm."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from potflat.errors import InvalidOptionError
from potflat.types import UNITS_MM, canonical_units

#: Proxy kinds that are developments around the axis, simplest first (``auto`` chooses among
#: them, :mod:`potflat.rollout.proxy`).
DEVELOPABLE = ("cylinder", "cone", "sphere")
#: All proxy kinds.
KINDS = (*DEVELOPABLE, "ortho")
#: Ways to find where the painting is (:mod:`potflat.importance`).
IMPORTANCE_METHODS = ("auto", "none", "mask", "texture-mask", "band")

#: Sides accepted by :func:`potflat.rollout.walls.select_wall`.
SIDES = ("outer", "inner")
#: Landmark names a user can give (``RolloutOptions.landmark``; :mod:`potflat.rollout.landmarks`).
LANDMARKS = ("painted", "handle")


@dataclass(frozen=True, kw_only=True)
class RolloutOptions:
    """Options of the rollout stage (names equal the CLI options, ``_`` for ``-``).

    Attributes
    ----------
    units : str or None
        Length unit of the scan file (``mm``, ``cm``, ``m``, ``um``, ``in``); None: the unit
        the file declares (a PLY ``comment units``, an STL header, glTF's metres), else mm.
        Used when reading the file; :func:`rollout` itself uses :attr:`Mesh.units`.
    texture : bool
        Use the scan's texture image; off: the geometry (and vertex colours) only, e.g. when
        the texture file is missing or corrupt. Used when reading the file.
    keep_orientation : bool
        Keep the scan's faces facing as most of them face in the file (the side the scanner
        saw), and take them as they face when telling the walls apart. By default an open
        scan is turned to face out of the body it encloses with its holes capped, which for
        the face of a dish, plate or bowl scanned alone (a sheet open towards its concave
        side) is its underside: with this option and ``side="inner"`` it is unrolled as the
        inside it is, seen from within. Used when reading the file and by the walls.
    proxy : str
        ``auto``, ``cylinder``, ``cone``, ``sphere`` or ``ortho``.
    axis : tuple of 6 float or None
        Manual axis ``(px, py, pz, dx, dy, dz)``: a point and a direction from foot to mouth.
    flip : bool
        Reverse the axis direction (mouth and foot swapped).
    seam : float or None
        Seam angle in degrees from the landmark (``seam_at`` or ``landmark``), else from the
        axis' reference direction; chosen automatically when None.
    band : (float, float) or None
        Height band as fractions of the axial extent, 0 = foot, 1 = mouth; the faces across
        its planes are cut along them (with the ``ortho`` proxy, the faces whose centres lie
        in it are taken).
    angles : (float, float) or None
        Angle range in degrees, e.g. -60 to 60, at most 360 wide: from the landmark when
        one is named, else from ``seam`` when given, else from the painted zone's centre (the
        window is centred on the painting; the seam stays automatic).
    view : tuple of 3 float or None
        For ``proxy="ortho"``: direction from the vessel to the viewer (``x,y,z``, scan
        coordinates); default: from the axis towards the region's centre (from the region
        towards the axis for the inner side).
    side : str
        Painted side to unroll: ``outer`` (the outside, default) or ``inner`` (the inside
        seen from within: a cup's interior, a kylix tondo). Two-walled scans are split at
        the rim (:func:`potflat.rollout.walls.select_wall`).
    keep_attachments : bool
        Keep handles, spouts and knobs (parts off the surface of revolution) in the rollout;
        by default they are left out and reported, and the painting around their roots stays.
    keep_base : bool
        Keep the faces at the foot that face along the axis (a flat or domed base, the
        underside of a foot; with ``side="inner"`` the floor) in the rollout. By default,
        where the proxy's development would show them less truly than a view along the axis
        (it smears a disc into a wide flange), they are left out of the rollout and shown as
        their own disc, an orthographic view from below (the floor: from above),
        ``NAME.base.png`` (:mod:`potflat.rollout.base`).
    seam_at : tuple of 3 float or None
        A point on the surface (scan coordinates, e.g. picked in MeshLab): the landmark; the
        seam goes through it (or ``seam`` degrees from it).
    landmark : str or None
        ``painted``: the seam goes opposite the centre of the painted zone; ``handle``: through
        the largest handle (:mod:`potflat.rollout.landmarks`). ``seam`` and ``angles`` are measured from it.
    overlap : float
        Degrees of surface repeated past 360 at the end of an all-round rollout, so a motif
        crossing the seam is seen whole once (the bake marks where the repeat starts).
    profile_mm : float or None
        Height step of the profile (``NAME.profile.csv/.svg``, the plate's section), mm;
        None: one median edge length of the scan, as fine as its edges.
    importance : str
        Where the painting is, which the relax stage keeps true and the bake stage reports
        (:mod:`potflat.importance`): ``auto`` (found in the colours; none for a scan without
        colours or painted all over), ``none`` (the whole surface alike), ``mask`` (a PNG
        painted over a potflat image, ``importance_mask``), ``texture-mask`` (a PNG in the
        texture's space, ``importance_mask``) or ``band`` (``importance_band`` and/or
        ``importance_arc``).
    importance_mask : str or None
        The mask image (white = important) for ``mask`` and ``texture-mask``.
    importance_image : str or None
        For ``mask``: the ``NAME.bake.json`` of the image the mask was painted over (default:
        the one beside the mask whose image has the mask's size).
    importance_band : (float, float) or None
        For ``importance="band"``: heights as fractions of the axial extent (0 foot, 1 mouth).
    importance_arc : (float, float) or None
        For ``importance="band"``: angle range in degrees from the seam.
    """

    units: str | None = field(default=None, metadata={"choices": tuple(UNITS_MM)})
    texture: bool = True
    keep_orientation: bool = False
    proxy: str = field(default="auto", metadata={"choices": ("auto", *KINDS)})
    axis: tuple[float, ...] | None = field(default=None, metadata={"metavar": "px,py,pz,dx,dy,dz"})
    flip: bool = False
    seam: float | None = field(default=None, metadata={"metavar": "DEG"})
    band: tuple[float, float] | None = field(default=None, metadata={"metavar": "LO HI"})
    angles: tuple[float, float] | None = field(default=None, metadata={"metavar": "A0 A1"})
    view: tuple[float, ...] | None = field(default=None, metadata={"metavar": "x,y,z"})
    side: str = field(default="outer", metadata={"choices": SIDES})
    keep_attachments: bool = False
    keep_base: bool = False
    seam_at: tuple[float, float, float] | None = field(default=None, metadata={"metavar": "X Y Z"})
    landmark: str | None = field(default=None, metadata={"choices": LANDMARKS})
    overlap: float = field(default=0.0, metadata={"metavar": "DEG"})
    profile_mm: float | None = field(default=None, metadata={"metavar": "MM"})
    importance: str = field(default="auto", metadata={"choices": IMPORTANCE_METHODS})
    importance_mask: str | None = field(default=None, metadata={"metavar": "PNG"})
    importance_image: str | None = field(default=None, metadata={"metavar": "NAME.bake.json"})
    importance_band: tuple[float, float] | None = field(default=None, metadata={"metavar": "LO HI"})
    importance_arc: tuple[float, float] | None = field(default=None, metadata={"metavar": "A0 A1"})

    def __post_init__(self) -> None:
        if self.importance not in IMPORTANCE_METHODS:
            raise InvalidOptionError(f"unknown importance {self.importance!r}; use one of {', '.join(IMPORTANCE_METHODS)}")
        if (self.importance in ("mask", "texture-mask")) != (self.importance_mask is not None):
            raise InvalidOptionError("give importance_mask (--importance-mask PNG) with importance mask or "
                                     "texture-mask, and only then")
        if self.importance_image is not None and self.importance != "mask":
            raise InvalidOptionError("importance_image (--importance-image) goes with importance mask")
        for name in ("band", "angles", "importance_band", "importance_arc"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, _height_band(name, getattr(self, name)) if name.endswith("band")
                                   else _angle_range(name, getattr(self, name)))
        if (self.importance == "band") != (self.importance_band is not None or self.importance_arc is not None):
            raise InvalidOptionError("give importance_band and/or importance_arc with importance band, and only then")
        if self.seam_at is not None:
            object.__setattr__(self, "seam_at", _floats("seam_at", self.seam_at, 3, "X Y Z"))
        if self.landmark is not None and self.landmark not in LANDMARKS:
            raise InvalidOptionError(f"landmark {self.landmark!r} is unknown; use {' or '.join(LANDMARKS)}, or give "
                                     "a point with seam_at")
        if self.seam_at is not None and self.landmark is not None:
            raise InvalidOptionError("give either seam_at (a point) or landmark, not both")
        over = _floats("overlap", (self.overlap,), 1, "DEG")[0]
        if not 0.0 <= over <= 180.0:
            raise InvalidOptionError(f"overlap must be 0 to 180 degrees, got {over:g}")
        if over and self.angles is not None:
            raise InvalidOptionError("overlap repeats an all-round rollout past 360 degrees; drop --angles or --overlap")
        object.__setattr__(self, "overlap", over)
        if self.profile_mm is not None:
            step = _floats("profile_mm", (self.profile_mm,), 1, "MM")[0]
            if step <= 0:
                raise InvalidOptionError(f"profile_mm must be a positive height step in mm, got {step:g}")
            object.__setattr__(self, "profile_mm", step)
        if self.side not in SIDES:
            raise InvalidOptionError(f"side {self.side!r} is unknown; use outer or inner")
        for name in ("keep_attachments", "keep_base"):
            if not isinstance(getattr(self, name), bool):
                raise InvalidOptionError(f"{name} must be true or false, got {getattr(self, name)!r}")
        if self.units is not None:
            if canonical_units(self.units) is None:
                raise InvalidOptionError(f"units {self.units!r} is unknown; use one of {', '.join(UNITS_MM)}")
            object.__setattr__(self, "units", canonical_units(self.units))
        if not isinstance(self.texture, bool):
            raise InvalidOptionError(f"texture must be true or false, got {self.texture!r}")
        if self.proxy not in ("auto", *KINDS):
            raise InvalidOptionError(
                f"proxy {self.proxy!r} is unknown; use auto, {', '.join(KINDS)}")
        if self.axis is not None:
            ax = _floats("axis", self.axis, 6, "px,py,pz,dx,dy,dz")
            if not any(ax[3:]):
                raise InvalidOptionError("axis direction is zero; give dx,dy,dz not all 0")
            object.__setattr__(self, "axis", ax)
        if self.seam is not None:
            object.__setattr__(self, "seam", _floats("seam", (self.seam,), 1, "DEG")[0])
        if self.view is not None:
            view = _floats("view", self.view, 3, "x,y,z")
            if not any(view):
                raise InvalidOptionError("view direction is zero; give x,y,z not all 0")
            if self.proxy != "ortho":
                raise InvalidOptionError("view applies only to proxy ortho; add --proxy ortho or drop --view")
            object.__setattr__(self, "view", view)

    def input_files(self) -> tuple[str, ...]:
        """The files these options name, which the rollout reads: the importance mask and the
        bake JSON it was painted over."""
        return tuple(p for p in (self.importance_mask, self.importance_image) if p is not None)

    def as_dict(self) -> dict:
        """The options as a JSON-ready dict."""
        return {f.name: (list(v) if isinstance(v := getattr(self, f.name), tuple) else v)
                for f in fields(self)}


def _floats(name: str, values, count: int, form: str) -> tuple[float, ...]:
    try:
        out = tuple(float(x) for x in values)
    except (TypeError, ValueError):
        raise InvalidOptionError(f"{name} needs {count} numbers ({form})") from None
    if len(out) != count or not all(math.isfinite(x) for x in out):
        raise InvalidOptionError(f"{name} needs {count} finite numbers ({form}), got {len(out)}")
    return out


def _height_band(name: str, value) -> tuple[float, float]:
    """A height band ``(LO, HI)``, fractions with ``0 <= LO < HI <= 1``, or one error line."""
    lo, hi = _floats(name, value, 2, "LO HI")
    if not 0.0 <= lo < hi <= 1.0:
        raise InvalidOptionError(f"{name.replace('_', ' ')} {lo:g} {hi:g} is invalid; give fractions of the height "
                                 "with 0 <= LO < HI <= 1")
    return lo, hi


def _angle_range(name: str, value) -> tuple[float, float]:
    """An angle range ``(A0, A1)`` in degrees from the seam, at most 360 wide, or one error line."""
    a0, a1 = _floats(name, value, 2, "A0 A1")
    if not a0 < a1 <= a0 + 360.0:
        raise InvalidOptionError(f"{name.replace('_', ' ')} {a0:g} {a1:g} are invalid; give A0 < A1 <= A0 + 360 "
                                 "(degrees from the seam)")
    return a0, a1
