"""Options of the relax stage: light to import (the command line builds its options and help
from :class:`RelaxOptions` without importing the solver)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from potflat.errors import InvalidOptionError
from potflat.relax.parameters import PRESETS, WEIGHTINGS, RelaxPreset

#: The fields of :class:`RelaxOptions` that override the preset's setting of the same name.
PRESET_FIELDS = ("tol", "max_iter", "stretch", "stiffness", "weighting", "simplify_mm", "shape", "rigidity",
                 "area", "max_anisotropy", "importance_contrast", "true_scale")


@dataclass(frozen=True, kw_only=True)
class RelaxOptions:
    """Options of the relax stage (field names are the CLI options with ``_`` for ``-``).

    Attributes
    ----------
    preset : str
        ``preview``, ``standard`` (default), ``archival`` (fold-free preconditioned L-BFGS,
        increasingly thorough: tolerance 1e-3, 1e-4, 1e-7) or ``paper`` (the paper's damped
        dynamics, may fold).
    tol : float or None
        Stop when the relative energy decrease per iteration (averaged over a window) falls
        below this. None: the preset's.
    max_iter : int or None
        Iteration cap. None: the preset's.
    time_budget : float or None
        Seconds of relaxation after which the best state so far is returned (not converged).
    threads : int or None
        Numba threads (None: Numba's default).
    stretch : float or None
        Uniform initial scale of the rollout (the paper's s). None: the preset's (2 for paper, else 1).
    stiffness : float or None
        Spring stiffness k (> 0). None: the preset's (0.5 for paper).
    weighting : str or None
        ``uniform`` (the paper: absolute length errors) or ``relative`` (each spring weighted
        by 1/r^2: relative length errors). None: the preset's.
    simplify_mm : float or None
        Relax a coarse copy of the mesh (its start layout clustered in square cells of this
        side, in mm) and let the full mesh follow it piecewise linearly: no more resolution
        than the image resolves (0.5 mm is 2 pixels at the default 4 px/mm). Only when the
        copy has at most a third of the vertices and covers 95% of them (a mesh not that much
        finer than the cells is relaxed itself). 0: relax the full mesh. None: the preset's
        (0.5 for ``preview``, 0 for the others).
    shape : float or None
        Weight of the shape term (>= 0): each triangle's symmetric anisotropy energy
        ``A (sigma_1 / sigma_2 + sigma_2 / sigma_1 - 2)`` per mean triangle area, added to
        the springs. The springs alone charge shear half as much as area change; the shape
        term charges shear only (about ``A log(sigma_1 / sigma_2)^2``), so larger values keep
        figures rounder and lines straighter at some cost in area. 0: the springs alone.
        None: the preset's (0 for ``paper``).
    rigidity : float or None
        Weight of the rigidity term (>= 0): each triangle's as-rigid-as-possible energy
        ``A ((sigma_1 - 1)^2 + (sigma_2 - 1)^2)`` per mean triangle area, added to the springs
        and the shape term. It charges shear and area change alike, per triangle, which the
        springs of an irregular mesh do not: it evens out triangle-to-triangle shear (the
        speckle of the anisotropy map). 0: none. None: the preset's (2; 0 for ``paper``).
    area : float or None
        Weight of the area term (>= 0): each triangle's ``A (sqrt(L^2 + 0.05^2) - 0.05)`` per
        mean triangle area, ``L = log(A_flat / A)``: area change in proportion, not squared,
        so the area distortion gathers where the shape can take it (within the anisotropy
        limit) instead of spreading evenly. Used on vessels without a painted zone (painted
        all over, or no colours): with one, the plain surface takes the distortion already.
        0: none. None: the preset's (2; 0 for ``paper``).
    max_anisotropy : float, "auto" or None
        The anisotropy (long over short axis of a triangle's map) above which a steep price
        starts (``100 A (u(sigma_1 / sigma_2) - u(limit))^2`` per mean triangle area, ``u(a) =
        sqrt(a) - 1 / sqrt(a)``, about ``log a``; soft:
        the area term can push a little past it). ``"auto"``: with the area term, the 80th
        percentile of the anisotropy a first solve without the area term reaches (figures
        no less round than without it); inf: no limit. None: the preset's (``"auto"``).
    importance_contrast : float or None
        How much stiffer the important (painted) zone is than plain surface (>= 1): springs,
        barrier and shape term of plain surface are weighted one over the contrast, so the
        distortion goes there. 1: the whole surface alike. Used when the flattening
        carries an importance (:attr:`potflat.types.FlatMesh.importance`). None: the preset's.
    true_scale : bool or None
        Scale the result uniformly so that the median length scale in the important zone
        (the whole surface without one) is exactly 1: lengths read off the image with its
        scale bar are right where the painting is. None: the preset's (off for ``paper``).
    """

    preset: str = field(default="standard", metadata={"choices": tuple(PRESETS)})
    tol: float | None = None
    max_iter: int | None = None
    time_budget: float | None = field(default=None, metadata={"metavar": "SECONDS"})
    threads: int | None = None
    stretch: float | None = None
    stiffness: float | None = None
    weighting: str | None = field(default=None, metadata={"choices": WEIGHTINGS})
    simplify_mm: float | None = field(default=None, metadata={"metavar": "MM"})
    shape: float | None = None
    rigidity: float | None = None
    area: float | None = None
    max_anisotropy: float | Literal["auto"] | None = field(default=None, metadata={"metavar": "NUMBER|auto|inf"})
    importance_contrast: float | None = None
    true_scale: bool | None = None

    def __post_init__(self) -> None:
        if self.preset not in PRESETS:
            raise InvalidOptionError(f"unknown relax preset {self.preset!r}; use one of {', '.join(PRESETS)}")
        _positive("tol", self.tol)
        _positive("time_budget", self.time_budget)
        _positive("stretch", self.stretch)
        _positive("stiffness", self.stiffness)
        for name in ("max_iter", "threads"):
            val = getattr(self, name)
            if val is not None and (isinstance(val, bool) or not isinstance(val, (int, np.integer)) or val < 1):
                raise InvalidOptionError(f"{name.replace('_', '-')} must be a whole number >= 1, got {val!r}")
        _at_least("simplify_mm", self.simplify_mm, 0, "0: no simplification")
        _at_least("shape", self.shape, 0, "0: springs only")
        _at_least("rigidity", self.rigidity, 0, "0: no rigidity term")
        _at_least("area", self.area, 0, "0: no area term")
        lim = self.max_anisotropy
        if lim is not None and lim != "auto" and not (
                isinstance(lim, (int, float, np.floating)) and not isinstance(lim, bool) and lim > 1):
            raise InvalidOptionError(f"max-anisotropy must be 'auto' or a number above 1 (inf: no limit), got {lim!r}")
        _at_least("importance_contrast", self.importance_contrast, 1, "1: the whole surface alike")
        if self.true_scale is not None and not isinstance(self.true_scale, (bool, np.bool_)):
            raise InvalidOptionError(f"true-scale must be true or false, got {self.true_scale!r}")
        if self.weighting is not None and self.weighting not in WEIGHTINGS:
            raise InvalidOptionError(f"unknown weighting {self.weighting!r}; use one of {', '.join(WEIGHTINGS)}")

    def resolved(self) -> RelaxPreset:
        """The preset's settings with the options given here applied (:data:`PRESET_FIELDS`)."""
        given = {name: getattr(self, name) for name in PRESET_FIELDS if getattr(self, name) is not None}
        return replace(PRESETS[self.preset], **given)


def _finite_number(val) -> bool:
    """Whether ``val`` is a finite real number (not a bool)."""
    return (not isinstance(val, bool) and isinstance(val, (int, float, np.floating, np.integer))
            and math.isfinite(val))


def _positive(name: str, val) -> None:
    """``val`` is None or a finite number > 0; else the option's one-line error."""
    if val is not None and not (_finite_number(val) and val > 0):
        raise InvalidOptionError(f"{name.replace('_', '-')} must be a positive number, got {val!r}")


def _at_least(name: str, val, low: float, meaning: str) -> None:
    """``val`` is None or a finite number >= ``low``; else the option's one-line error, saying
    what ``low`` means (``meaning``)."""
    if val is not None and not (_finite_number(val) and val >= low):
        raise InvalidOptionError(f"{name.replace('_', '-')} must be a number >= {low:g} ({meaning}), got {val!r}")
