"""What a relaxation gives: :class:`RelaxResult`, with a :class:`LevelRecord` per solved level
and the :class:`RelaxTimings` of its phases."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from potflat.mesh.distortion import DistortionSummary, SurfaceReference, ZoneSummary
from potflat.relax.parameters import RelaxPreset
from potflat.types import FlatMesh


@dataclass(frozen=True, kw_only=True)
class LevelRecord:
    """One level of a relaxation: a coarse copy, the full mesh, or the full mesh following a copy.

    Attributes
    ----------
    level : str
        ``"coarse"`` (a coarse copy; ``"coarse, shape first"`` its first solve without the
        area term), ``"fine"`` (the full mesh; ``"fine, shape first"`` likewise), ``"follow"``
        (the full mesh only follows a copy) or ``"dynamics"`` (the paper's dynamics).
    iterations : int
    energy : float
        Spring energy (without barriers) at the level's end, in its normalised units.
    seconds : float
    vertices : int or None
        Vertices of the level's mesh (None for the dynamics).
    boundary_contact : bool or None
        Whether the boundary touched itself (trial steps that would have made it overlap
        were shortened); L-BFGS levels only.
    smoothed_directions : int or None
        Search directions smoothed at the faces limiting the step; L-BFGS levels only.
    eased_directions : int or None
        Search directions scaled down around the boundary constraints limiting the step;
        L-BFGS levels only.
    dt : float or None
        The dynamics' time step; the dynamics only.
    importance_contrast : float or None
        The importance contrast of a first relaxation at a lower contrast (None: the full one).
    """

    level: str
    iterations: int
    energy: float
    seconds: float
    vertices: int | None = None
    boundary_contact: bool | None = None
    smoothed_directions: int | None = None
    eased_directions: int | None = None
    dt: float | None = None
    importance_contrast: float | None = None


@dataclass(frozen=True, kw_only=True)
class RelaxTimings:
    """Seconds per phase of a relaxation.

    Attributes
    ----------
    setup : float
        Springs, preconditioner grids, coarse copies, untangling.
    solve : float
    check : float
        Fold checks, distortion summaries, stress.
    figures : float
        The painted zone's figures.
    total : float
    """

    setup: float
    solve: float
    check: float
    figures: float
    total: float


@dataclass(frozen=True, kw_only=True)
class RelaxResult:
    """Outcome of :func:`relax`.

    Attributes
    ----------
    flat : FlatMesh
        The relaxed flattening (same vertices and faces, new ``uv``) with per-vertex
        ``stress`` (the paper's Eq. 3 over mesh edges in sqrt(mm), from
        :func:`potflat.mesh.distortion.vertex_stress`).
    energy_history : (k,) float64
        The minimised energy after each iteration, all levels in order (the coarse copies'
        first; each level in its own normalised units: lengths divided by its mean 3D edge
        length): springs plus the barrier for the fold-free presets (never increases within
        a level), springs only for ``paper``.
    iterations : int
        Iterations (steps) taken, all levels together.
    converged : bool
        The convergence test passed (False when stopped by the iteration cap or time budget).
    flipped : int
        Faces with non-positive signed area in the result (always 0 unless preset ``paper``).
    boundary_overlap : int
        Crossing pairs of boundary segments in the result (0: the boundary does not overlap itself).
    distortion : DistortionSummary
        Distortion of the result.
    distortion_before : DistortionSummary
        Distortion of the input flattening.
    zone : ZoneSummary or None
        How true the result is in the painted zone and in the rest
        (:func:`potflat.mesh.distortion.zone_summary`); None for a coarse copy's solve.
    timings : RelaxTimings
    preset : str
    levels : tuple of LevelRecord
        Per level, in the order solved: coarse copies, then the full mesh.
    settings : RelaxPreset
        The resolved settings (the preset's values with the options applied).
    scale_factor : float
        The uniform factor applied after solving for true scale (``true_scale``; 1 without):
        the median length scale in the important zone (the whole surface without one) is 1.
    anisotropy_limit : float or None
        The anisotropy limit the solve used (``max_anisotropy`` resolved; None: none).
    notes : tuple of str
        What the solver had to do beyond the plan (untangling, fallback), for the JSON.
    reference : SurfaceReference or None
        The 3D side of the figures above (of ``flat``'s vertices and faces), for the bake of
        the same mesh (:func:`potflat.run_scan`); None when no figures were computed.
    """

    flat: FlatMesh
    energy_history: np.ndarray
    iterations: int
    converged: bool
    flipped: int
    boundary_overlap: int
    distortion: DistortionSummary
    distortion_before: DistortionSummary
    zone: ZoneSummary | None
    timings: RelaxTimings
    preset: str
    levels: tuple[LevelRecord, ...]
    settings: RelaxPreset
    scale_factor: float = 1.0
    notes: tuple[str, ...] = ()
    anisotropy_limit: float | None = None
    reference: SurfaceReference | None = None
