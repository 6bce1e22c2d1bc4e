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


#: Distortion maps :func:`bake` can make.
MAP_NAMES = ("stress", "area", "anisotropy")


#: px/mm used when neither ``px_per_mm`` nor ``dpi`` is given.
DEFAULT_PX_PER_MM = 4.0


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

    def __post_init__(self) -> None:
        for name in ("scale_on_image", "plate", "obj"):
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

    @property
    def resolution(self) -> float:
        """The effective pixels per millimetre."""
        if self.dpi is not None:
            return self.dpi / 25.4
        return float(self.px_per_mm) if self.px_per_mm is not None else DEFAULT_PX_PER_MM
