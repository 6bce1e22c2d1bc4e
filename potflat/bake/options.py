"""Options of the bake stage: light to import (the command line builds its options and help
from :class:`BakeOptions` without importing the renderer)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from potflat.errors import InvalidOptionError

#: Largest print scale accepted (drawing mm per vessel mm): 10:1, for small sherds.
MAX_SCALE = 10.0


def parse_scale(value) -> float | None:
    """A print scale as drawing mm per vessel mm.

    Parameters
    ----------
    value : str, float or None
        ``"1:5"``, ``"1/5"``, ``0.2``, ``"auto"`` or None (automatic).

    Returns
    -------
    float or None
        None for automatic.

    Raises
    ------
    InvalidOptionError
        Not a positive ratio.
    """
    if value is None or (isinstance(value, str) and value.strip().lower() in ("", "auto")):
        return None
    try:
        if isinstance(value, str) and (":" in value or "/" in value):
            a, b = value.replace("/", ":").split(":")
            scale = float(a) / float(b)
        else:
            scale = float(value)
    except (TypeError, ValueError, ZeroDivisionError):
        raise InvalidOptionError(f"plate scale {value!r} is not a scale; give e.g. 1:1, 1:2, 1:5 or auto") from None
    if not math.isfinite(scale) or scale <= 0:
        raise InvalidOptionError(f"plate scale {value!r} must be positive, e.g. 1:2")
    if scale > MAX_SCALE:
        raise InvalidOptionError(
            f"plate scale {value!r} would draw the vessel {scale:g} times its size; give e.g. 1:2 (in a YAML file "
            "in quotes, '1:5': unquoted, YAML reads 1:5 as the number 65)")
    return scale


def _number_in(value, lo: float, hi: float) -> bool:
    """Whether ``value`` is a finite number (not a bool) from ``lo`` to ``hi``."""
    return (not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)
            and lo <= value <= hi)


#: Distortion maps :func:`bake` can make.
MAP_NAMES = ("stress", "area", "anisotropy")


#: px/mm used when neither ``px_per_mm`` nor ``dpi`` is given.
DEFAULT_PX_PER_MM = 4.0

#: Raking-light azimuths drawn by default, degrees clockwise from image up (315: from the upper left).
RELIEF_LIGHT_DEG = (315.0, 45.0)
#: Most raking-light azimuths one bake draws.
MAX_RELIEF_LIGHTS = 8
#: Largest relief smoothing scale accepted, mm.
MAX_RELIEF_MM = 1000.0
#: What the plate can show of the rollout (``plate_image``).
PLATE_IMAGES = ("painting", "relief", "both")


@dataclass(frozen=True, kw_only=True)
class BakeOptions:
    """Options of the bake stage (field names are the CLI option names).

    Attributes
    ----------
    px_per_mm : float or None
        Output resolution in pixels per millimetre (give this or ``dpi``; default 4).
    dpi : float or None
        Output resolution in dots per inch (25.4 dpi is 1 px/mm).
    maps : tuple of str
        Distortion maps to write (``"none"``: no maps); ``"stress"`` also writes the overlay.
    sheet : bool
        Write the rollout-vs-relaxed comparison sheet (needs ``NAME.rollout.ply`` beside the input).
    position_map : bool
        Write a float32 TIFF of the 3D point under each pixel (NaN outside).
    grid : bool
        Draw a labelled 10 mm grid in the scale layer.
    tiff : bool
        Also write the painting as a 16-bit RGBA TIFF.
    supersample : int
        Sub-samples per pixel side (1-8); 0 chooses from the texture density (2-4).
    max_megapixels : float
        Refuse images larger than this (protects laptops from a mistyped resolution).
    scale_on_image : bool
        Draw the scale bar (and the grid, with ``grid``) into ``NAME.png`` itself, where it
        covers no painting (in a band added below the image when no such place is free).
    plate : bool
        Also write the archaeological plate ``NAME.plate.svg/.pdf/.png`` (needs the rollout's
        and relaxation's files beside the input).
    plate_scale : str, float or None
        Print scale of the plate, e.g. ``1:2`` or 0.5; None: the largest of 1:1, 1:2, 1:3, 1:4, 1:5,
        1:10, 1:20, 1:50 at which it fits an A4 page.
    obj : bool
        Also write ``NAME.flat.obj`` + ``NAME.flat.mtl``: the scan's surface (3D, scan units)
        with the flat coordinates as texture coordinates into ``NAME.png`` (the painting
        re-baked in the flat layout), for MeshLab and Blender.
    relief : bool
        Also write the relief, on the pixel grid of ``NAME.png``: ``NAME.relief.tif`` (16-bit,
        the height above the scan smoothed at ``relief_mm``, in mm: its scale is in
        ``NAME.bake.json`` and the TIFF's description), ``NAME.relief.png`` (coloured, with a
        legend), ``NAME.raking-AZ.png`` (raking light from each azimuth of ``relief_light``),
        ``NAME.curvature.png`` (concave and convex detail at several radii, like MSII) and, for
        a painted scan, ``NAME.relief-overlay.png``. An untextured scan's ``NAME.png`` is its
        relief in grey with a legend in mm, with or without this.
    relief_mm : float
        Scale of the smoothed surface the relief is measured against, mm: narrower detail
        (incisions, stamps, relief decoration) is relief, the wider form is taken out.
    relief_light : tuple of float
        Azimuths of the raking light, degrees clockwise from image up (315: from the upper left).
    relief_blend : float
        Share of the relief in ``NAME.relief-overlay.png``, 0 (the painting alone) to 1 (the relief alone).
    plate_image : str
        What the plate shows of the rollout: the painting, the relief (raking light from the
        first azimuth of ``relief_light``; needs ``relief``) or both, one above the other.
    """

    px_per_mm: float | None = None
    dpi: float | None = None
    maps: tuple[str, ...] = field(default=MAP_NAMES, metadata={"choices": (*MAP_NAMES, "none"), "metavar": "MAP,MAP"})
    sheet: bool = False
    position_map: bool = False
    grid: bool = False
    tiff: bool = False
    supersample: int = 0
    max_megapixels: float = 1000.0
    scale_on_image: bool = False
    plate: bool = False
    plate_scale: str | float | None = field(default=None, metadata={"metavar": "1:N"})
    obj: bool = False
    relief: bool = False
    relief_mm: float = 4.0
    relief_light: tuple[float, ...] = field(default=RELIEF_LIGHT_DEG, metadata={"metavar": "DEG,DEG"})
    relief_blend: float = 0.5
    plate_image: str = field(default="painting", metadata={"choices": PLATE_IMAGES})

    def __post_init__(self) -> None:
        for name in ("scale_on_image", "plate", "obj", "relief"):
            if not isinstance(getattr(self, name), bool):
                raise InvalidOptionError(f"{name} must be true or false, got {getattr(self, name)!r}")
        if self.plate_scale is not None:
            parse_scale(self.plate_scale)
        if self.px_per_mm is not None and self.dpi is not None:
            raise InvalidOptionError("give either px_per_mm (--px-per-mm) or dpi (--dpi), not both")
        for name in ("px_per_mm", "dpi", "max_megapixels"):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))
                                      or not math.isfinite(value) or value <= 0):
                raise InvalidOptionError(f"{name} must be a positive number, got {value!r}")
        maps = (self.maps,) if isinstance(self.maps, str) else tuple(self.maps)
        if maps == ("none",):
            maps = ()
        unknown = [m for m in maps if m not in MAP_NAMES]
        if unknown:
            raise InvalidOptionError(f"unknown map {unknown[0]!r}; choose from {', '.join(MAP_NAMES)}")
        object.__setattr__(self, "maps", tuple(dict.fromkeys(maps)))
        if isinstance(self.supersample, bool) or not isinstance(self.supersample, int) or not 0 <= self.supersample <= 8:
            raise InvalidOptionError(f"supersample must be an integer from 0 (automatic) to 8, got {self.supersample!r}")
        if not _number_in(self.relief_mm, 0.0, MAX_RELIEF_MM) or self.relief_mm == 0:
            raise InvalidOptionError(f"relief_mm must be a number of mm above 0 and up to {MAX_RELIEF_MM:g}, "
                                     f"got {self.relief_mm!r}")
        lights = (self.relief_light,) if isinstance(self.relief_light, (int, float)) else tuple(self.relief_light)
        if not 1 <= len(lights) <= MAX_RELIEF_LIGHTS or not all(_number_in(a, -math.inf, math.inf) for a in lights):
            raise InvalidOptionError(f"relief_light must be 1 to {MAX_RELIEF_LIGHTS} azimuths in degrees, "
                                     f"e.g. 315,45; got {self.relief_light!r}")
        object.__setattr__(self, "relief_light", tuple(dict.fromkeys(float(a) % 360.0 for a in lights)))
        if not _number_in(self.relief_blend, 0.0, 1.0):
            raise InvalidOptionError(f"relief_blend must be a number from 0 to 1, got {self.relief_blend!r}")
        if self.plate_image not in PLATE_IMAGES:
            raise InvalidOptionError(f"unknown plate_image {self.plate_image!r}; choose from {', '.join(PLATE_IMAGES)}")
        if self.plate_image != "painting" and not self.relief:
            raise InvalidOptionError(f"plate_image {self.plate_image} draws the relief: add relief (--relief)")

    @property
    def resolution(self) -> float:
        """The effective pixels per millimetre."""
        if self.dpi is not None:
            return self.dpi / 25.4
        return float(self.px_per_mm) if self.px_per_mm is not None else DEFAULT_PX_PER_MM
