"""Core data types shared by every stage.

Conventions (see ``docs/formats.md``):

* Lengths are in the scan's own units; :attr:`Mesh.units` names them and
  :attr:`Mesh.mm_per_unit` converts to millimetres. Nothing is rescaled silently.
* Faces are counter-clockwise seen from outside the vessel (outward normals).
* Texture coordinates are per face corner, OBJ convention: ``(0, 0)`` is the bottom-left
  of the texture image, ``v`` points up. A textured scan's faces that have none (another
  material without an image, filled holes) are flagged in :attr:`Mesh.untextured_faces`:
  their coordinates mean nothing and are never read.
* Flattened coordinates ``uv`` are in the same units as the 3D positions, ``u`` to the
  right and ``v`` up (towards the vessel's mouth), seen from outside: a flattened face
  keeps its counter-clockwise orientation, so a flipped triangle has negative signed area.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path
import numpy as np

from potflat.errors import InvalidInputError

#: Millimetres per unit for the length units potflat accepts.
UNITS_MM: dict[str, float] = {"um": 1e-3, "mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}


#: Other names of the units (lower case): "meter", "metre", "millimetres", "µm", "inch"...
UNIT_ALIASES: dict[str, str] = {
    **{f"{stem}{end}": unit for unit, stems in (("mm", ("millimeter", "millimetre")), ("cm", ("centimeter", "centimetre")),
                                                 ("m", ("meter", "metre")), ("um", ("micrometer", "micrometre", "micron")))
       for stem in stems for end in ("", "s")},
    "µm": "um", "μm": "um", "inch": "in", "inches": "in", '"': "in",
}


def canonical_units(units: str) -> str | None:
    """The key of :data:`UNITS_MM` that ``units`` names (``"Metres"`` -> ``"m"``), or None."""
    if not isinstance(units, str):
        return None
    key = units.strip().lower()
    return key if key in UNITS_MM else UNIT_ALIASES.get(key)


def mm_per_unit(units: str) -> float:
    """Millimetres per scan unit for ``units`` (one of :data:`UNITS_MM`)."""
    try:
        return UNITS_MM[units]
    except KeyError:
        raise InvalidInputError(
            f"unknown length unit {units!r}; use one of {', '.join(UNITS_MM)}"
        ) from None


def _as_array(name: str, arr, dtype, shape_tail: tuple[int, ...]) -> np.ndarray:
    out = np.ascontiguousarray(arr, dtype=dtype)
    if out.ndim != 1 + len(shape_tail) or out.shape[1:] != shape_tail:
        want = "(n" + "".join(f", {s}" for s in shape_tail) + ")"
        raise InvalidInputError(f"{name} must have shape {want}, got {out.shape}")
    return out


def _check_face_indices(faces: np.ndarray, n_vertices: int, source: Path | None) -> None:
    """Every index of ``faces`` (m, 3) names one of ``n_vertices`` vertices (the kernels index
    unchecked)."""
    if not len(faces):
        return
    lo, hi = int(faces.min()), int(faces.max())
    if lo < 0 or hi >= n_vertices:
        where = f"{source}: " if source is not None else ""
        bad = lo if lo < 0 else hi
        raise InvalidInputError(
            f"{where}a face names vertex {bad}, but there are {n_vertices} vertices (0 to {n_vertices - 1}); "
            "the file is corrupt or truncated: export the scan again")


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh in 3D with optional texture or vertex colours.

    Attributes
    ----------
    vertices : (n, 3) float64
        Positions in scan units.
    faces : (m, 3) int64
        Vertex indices, counter-clockwise seen from outside.
    texcoords : (m, 3, 2) float64 or None
        Texture coordinate of each face corner (OBJ convention, v up).
    untextured_faces : (m,) bool or None
        True for the faces that have no texture coordinates (their ``texcoords`` rows mean
        nothing): they are drawn as untextured surface (its relief in grey) and hold no colour
        evidence of painting. None: every face is textured (an all-False flag becomes None);
        only with ``texcoords``. Follows the faces wherever ``texcoords`` does
        (:meth:`face_fields`).
    texture_path : Path or None
        Absolute path of the texture image that ``texcoords`` refer to.
    vertex_colors : (n, 4) uint8 or None
        RGBA colour per vertex, for scans without a texture.
    units : str
        Length unit of ``vertices`` (key of :data:`UNITS_MM`).
    source : Path or None
        File the mesh was read from, for messages and provenance.
    """

    vertices: np.ndarray
    faces: np.ndarray
    texcoords: np.ndarray | None = None
    texture_path: Path | None = None
    vertex_colors: np.ndarray | None = None
    units: str = "mm"
    source: Path | None = None
    untextured_faces: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "vertices", _as_array("vertices", self.vertices, np.float64, (3,)))
        object.__setattr__(self, "faces", _as_array("faces", self.faces, np.int64, (3,)))
        _check_face_indices(self.faces, len(self.vertices), self.source)
        if self.texcoords is not None:
            tc = _as_array("texcoords", self.texcoords, np.float64, (3, 2))
            if len(tc) != len(self.faces):
                raise InvalidInputError("texcoords must have one (3, 2) entry per face")
            object.__setattr__(self, "texcoords", tc)
        if self.untextured_faces is not None:
            object.__setattr__(self, "untextured_faces", _untextured_flag(self.untextured_faces, self.texcoords,
                                                                          len(self.faces)))
        if self.vertex_colors is not None:
            vc = np.asarray(self.vertex_colors)
            if vc.ndim == 2 and vc.shape[1] == 3:
                vc = np.concatenate([vc, np.full((len(vc), 1), 255, vc.dtype)], axis=1)
            vc = _as_array("vertex_colors", vc, np.uint8, (4,))
            if len(vc) != len(self.vertices):
                raise InvalidInputError("vertex_colors must have one entry per vertex")
            object.__setattr__(self, "vertex_colors", vc)
        if self.texture_path is not None:
            object.__setattr__(self, "texture_path", Path(self.texture_path))
        mm_per_unit(self.units)

    @property
    def mm_per_unit(self) -> float:
        """Millimetres per unit of :attr:`vertices`."""
        return mm_per_unit(self.units)

    def replace(self, **changes) -> "Mesh":
        """A copy with some fields replaced (validated again)."""
        return replace(self, **changes)

    def face_fields(self, index: np.ndarray) -> dict:
        """The per-face fields of the faces ``index`` selects, for :meth:`replace` with those faces.

        Parameters
        ----------
        index : (k,) int64 or (m,) bool
            Faces to keep, in their new order.

        Returns
        -------
        dict
            ``texcoords`` ((k, 3, 2) float64 or None) and ``untextured_faces`` ((k,) bool or None).
        """
        index = np.asarray(index)
        if index.dtype == bool:
            index = np.flatnonzero(index)
        # (rows gathered by take: 4x faster than indexing for the (k, 3, 2) coordinates)
        return {"texcoords": None if self.texcoords is None else np.take(self.texcoords, index, axis=0),
                "untextured_faces": None if self.untextured_faces is None else self.untextured_faces[index]}


def _untextured_flag(flag, texcoords: np.ndarray | None, m: int) -> np.ndarray | None:
    """``flag`` as a C-contiguous (m,) bool array, or None when no face is flagged."""
    arr = np.asarray(flag)
    if arr.shape != (m,):
        raise InvalidInputError(f"untextured_faces must have one flag per face, shape ({m},), got {arr.shape}")
    if arr.dtype != np.bool_:
        if not (np.issubdtype(arr.dtype, np.integer) and np.isin(arr, (0, 1)).all()):
            raise InvalidInputError(f"untextured_faces must be booleans (or 0 and 1), got {arr.dtype} values")
        arr = arr.astype(bool)
    if texcoords is None:
        raise InvalidInputError("untextured_faces flags faces of a textured mesh; give texcoords too "
                                "(or no flag: without texture coordinates every face is untextured)")
    return np.ascontiguousarray(arr) if arr.any() else None


@dataclass(frozen=True, eq=False)
class FlatMesh:
    """A cut (disk- or multi-disk-topology) mesh with a 2D flattening: the stage file content.

    Attributes
    ----------
    mesh : Mesh
        The 3D mesh; seam vertices appear once per side.
    uv : (n, 2) float64
        Flattened position of each vertex, in the units of ``mesh``.
    stress : (n,) float64 or None
        Per-vertex residual stress (the paper's Eq. 3), when known.
    comments : tuple of str
        Provenance lines carried into stage files.
    importance : (n,) float64 or None
        How much each vertex belongs to the important (painted) zone, from 0 (plain surface,
        may take the distortion) to 1 (painting, kept true); None: the whole surface matters
        alike (:mod:`potflat.importance`).
    """

    mesh: Mesh
    uv: np.ndarray
    stress: np.ndarray | None = None
    comments: tuple[str, ...] = field(default_factory=tuple)
    importance: np.ndarray | None = None

    def __post_init__(self) -> None:
        uv = _as_array("uv", self.uv, np.float64, (2,))
        if len(uv) != len(self.mesh.vertices):
            raise InvalidInputError("uv must have one row per vertex")
        object.__setattr__(self, "uv", uv)
        if self.stress is not None:
            st = np.ascontiguousarray(self.stress, dtype=np.float64)
            if st.shape != (len(uv),):
                raise InvalidInputError("stress must have one value per vertex")
            object.__setattr__(self, "stress", st)
        if self.importance is not None:
            imp = np.ascontiguousarray(self.importance, dtype=np.float64)
            if imp.shape != (len(uv),):
                raise InvalidInputError("importance must have one value per vertex")
            if not (np.isfinite(imp).all() and imp.min(initial=0.0) >= 0.0 and imp.max(initial=0.0) <= 1.0):
                raise InvalidInputError("importance must be finite and between 0 and 1")
            object.__setattr__(self, "importance", imp)

    def replace(self, **changes) -> "FlatMesh":
        """A copy with some fields replaced (validated again)."""
        return replace(self, **changes)


@dataclass(frozen=True, eq=False)
class RolloutMarks:
    """Places of a rollout that the bake marks on its images (faces index the rollout's faces,
    which the relaxation keeps).

    Attributes
    ----------
    attachment_roots : (k,) int64
        Faces where an attachment left out of the rollout (a handle, a spout) met the wall;
        empty when none was left out.
    repeated_from : int or None
        The first face that repeats the start of the rollout past 360 degrees (``overlap``);
        the faces from it on are the repeat. None: no repeat.
    overlap_deg : float
        Degrees repeated past 360 (0 without a repeat).
    folded_faces : (j,) int64
        Faces where the scan folds over itself in 3D (creases, flaps, duplicated sheets).
    folded_area_mm2, folded_percent : float
        Their 3D area, and its share of the unrolled surface in percent.
    folded_regions : int
        Connected places they make up.
    """

    attachment_roots: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    repeated_from: int | None = None
    overlap_deg: float = 0.0
    folded_faces: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    folded_area_mm2: float = 0.0
    folded_percent: float = 0.0
    folded_regions: int = 0

    def face_indicator(self, which: str, n_faces: int) -> np.ndarray:
        """A per-face indicator (n_faces,) float64 of ``"attachments"``, ``"repeated"`` or
        ``"folded"``; empty when there is nothing to mark or an index is out of range (the
        marks belong to another mesh)."""
        if which == "repeated":
            if self.repeated_from is None or not 0 < self.repeated_from < n_faces:
                return np.zeros(0)
            out = np.zeros(n_faces)
            out[self.repeated_from:] = 1.0
            return out
        faces = {"attachments": self.attachment_roots, "folded": self.folded_faces}[which]
        if not len(faces) or faces.min() < 0 or faces.max() >= n_faces:
            return np.zeros(0)
        out = np.zeros(n_faces)
        out[faces] = 1.0
        return out


class StepClock:
    """Wall seconds of a stage's steps, for its JSON (``timings``): ``lap(name)`` closes the
    step since the last lap; :meth:`total` gives every step and ``total``."""

    def __init__(self) -> None:
        import time

        self._now = time.perf_counter
        self._start = self._last = self._now()
        self.steps: dict[str, float] = {}

    def lap(self, name: str) -> None:
        """Close step ``name`` (added to an earlier step of that name)."""
        now = self._now()
        self.steps[name] = self.steps.get(name, 0.0) + now - self._last
        self._last = now

    def total(self) -> dict[str, float]:
        """Seconds per step and ``total`` since the clock started."""
        return {**self.steps, "total": self._now() - self._start}

