"""The relax stage's parameters, one frozen object per concern.

:data:`PRESETS` (typed :class:`RelaxPreset` settings, which :class:`~potflat.relax.RelaxOptions`
overrides field by field), :data:`ENERGY` (the barriers and floors of the energy),
:data:`SOLVER` (steps, line search and stopping of the two solvers) and :data:`COARSE` (when
and how coarse copies are relaxed first). Light to import (the command line lists the
presets from here). Every value changes the outputs; the comments say how each was chosen.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, kw_only=True)
class RelaxPreset:
    """The settings of one relax preset (``None`` fields are not set by it).

    Attributes
    ----------
    solver : str
        ``"lbfgs"`` (fold-free, preconditioned) or ``"dynamics"`` (the paper's damped dynamics).
    stretch, stiffness : float
        Initial uniform scale of the rollout and spring stiffness k.
    weighting : str
        One of :data:`WEIGHTINGS`.
    tol : float
        Relative energy decrease per iteration (averaged over :data:`SOLVER`'s window) to stop at.
    max_iter : int
    coarse_start : bool
        Start large meshes from a relaxed coarse copy (:data:`COARSE`).
    cell_vertices : float
        Vertices per cell of the coarsest grid of the multilevel preconditioner (L-BFGS),
        whose vertex order every solver uses.
    simplify_mm : float
        Relax only a copy with cells of this side (mm); 0: the full mesh.
    friction_inside, friction_boundary : float or None
        The dynamics' friction inside and on the boundary (``dynamics`` only).
    shape, rigidity, area, max_anisotropy, importance_contrast, true_scale
        The painted figures' defaults (measured in ``docs/performance.md``, "Painted
        figures" and "Relax options"): the shape, rigidity and area terms' weights, the anisotropy limit
        (``"auto"``: found by a first solve without the area term), how much stiffer the
        important zone is than plain surface, and the final scaling to true scale in the
        important zone.
    """

    solver: str
    stretch: float
    stiffness: float
    weighting: str
    tol: float
    max_iter: int
    coarse_start: bool
    cell_vertices: float = 8.0
    simplify_mm: float = 0.0
    friction_inside: float | None = None
    friction_boundary: float | None = None
    shape: float = 0.25
    rigidity: float = 2.0
    area: float = 2.0
    max_anisotropy: float | str = "auto"
    importance_contrast: float = 1000.0
    true_scale: bool = True

#: Spring weightings: ``uniform`` (the paper: absolute length errors) or ``relative``.
WEIGHTINGS = ("uniform", "relative")

_FOLD_FREE = {"solver": "lbfgs", "stretch": 1.0, "stiffness": 1.0, "weighting": "relative", "cell_vertices": 8.0,
              "coarse_start": True}
#: The presets by name: three fold-free ones, increasingly thorough, and the paper's dynamics.
PRESETS: dict[str, RelaxPreset] = {
    "preview": RelaxPreset(**_FOLD_FREE, tol=1e-3, max_iter=300, simplify_mm=0.5, importance_contrast=100.0),
    "standard": RelaxPreset(**_FOLD_FREE, tol=1e-4, max_iter=2000),
    "archival": RelaxPreset(**_FOLD_FREE, tol=1e-7, max_iter=20000),
    "paper": RelaxPreset(solver="dynamics", stretch=2.0, stiffness=0.5, weighting="uniform", tol=1e-7,
                         max_iter=100000, friction_inside=0.01, friction_boundary=1.0, coarse_start=False,
                         shape=0.0, rigidity=0.0, area=0.0, importance_contrast=1.0, true_scale=False),
}


@dataclass(frozen=True, kw_only=True)
class EnergyParameters:
    """Barriers and floors of the relax energy (lengths in mean edge lengths).

    Attributes
    ----------
    barrier_mu, barrier_eps : float
        Face barrier: weight (times k times the face's rest area) and activation (fraction
        of the rest area).
    boundary_mu, boundary_gap : float
        Boundary angle barrier: weight (times k) and activation (radians below 2 pi of a
        boundary vertex's flat interior angle sum).
    outline_mu : float
        Outline term: weight (times k, at every guarded boundary vertex whatever its
        importance) of the squared difference between the vertex's flat angle sum and its
        sum on the surface, so the outline keeps the scan boundary's own turning instead of
        gathering the distortion in teeth (a vertex's sum off by ``d`` radians costs
        ``mu k d^2``; a spring off its length by a fraction ``e``, ``k e^2 / 2``).
    contact_mu, contact_gap : float
        Boundary contact barrier: weight (times k) and activation distance between a
        boundary vertex and a boundary segment that is not its own (active when the start's
        boundary does not overlap itself).
    area_floor, length_floor : float
        Floor of rest areas (squared lengths) and of spring lengths.
    limit_mu : float
        Weight of the anisotropy limit per unit rest area (per mean face area).
    limit_percentile : float
        ``max_anisotropy="auto"``: the percentile (by rest area) of the anisotropy of the
        solve without the area term that becomes the limit (80: the largest at which every
        generated vessel's painted circles came out rounder than under libigl ARAP).
    area_eps : float
        Smoothing of the area term at zero log area ratio.
    ear_lift : float
        Untangling: a folded ear (a triangle whose tip is on no other face) is mirrored about
        its base; a tip lying on the base is lifted off it by this fraction of the base.
    """

    barrier_mu: float = 1.0
    barrier_eps: float = 0.5
    boundary_mu: float = 1.0
    boundary_gap: float = 0.5
    outline_mu: float = 0.3
    contact_mu: float = 1.0
    contact_gap: float = 0.5
    area_floor: float = 1e-2
    length_floor: float = 1e-3
    limit_mu: float = 100.0
    limit_percentile: float = 80.0
    area_eps: float = 0.05
    ear_lift: float = 0.1


@dataclass(frozen=True, kw_only=True)
class SolverParameters:
    """Steps, line search and stopping of the two solvers.

    Attributes
    ----------
    lbfgs_memory : int
        L-BFGS memory (pairs kept).
    armijo : float
        Armijo constant of the monotone line search.
    step_fraction : float
        Fraction of the flip-free step taken at most.
    step_shrink : float
        Largest fraction of its area a triangle may lose in one step (the log barrier alone
        grows too slowly to stop steps that each go most of the way to collapse: at 2.5M
        vertices, 19 triangles ended below 1e-11 of their rest area without this limit).
    smooth_rounds, smooth_max_fraction : int, float
        Direction smoothing: when a few triangles hold the flip-free step below the natural
        one (typically slivers, whose area reacts to the smallest uneven move of their
        vertices), the direction at their vertices is replaced by their edge neighbours'
        mean, ``smooth_rounds`` times, if at most ``smooth_max_fraction`` of the vertices
        are concerned.
    ease_rounds, ease_width : int, float
        Direction easing: when faces still hold the step below the natural one after
        smoothing, or the boundary (a guarded angle sum or a contact pair) holds it below
        the faces' bound, the direction is scaled down around the constraints holding it,
        rising back to 1 over ``ease_width`` times the eased move, in up to ``ease_rounds``
        rounds (within ``smooth_max_fraction`` of the vertices). Faces are eased only when
        they hold the step below ``ease_face_step`` of the natural one. Squeezed slivers
        held a fifth of the plastic vase's first 20 full-mesh steps at 1M below a tenth of
        the natural one (167-242 iterations in all over starts differing in their last
        bits; eased at the faces: 117-143).
    ease_face_step : float
        An eased direction leaves the quasi-Newton one, and easing more often moves the slow
        tails of the relaxation both ways (full-mesh iterations over starts differing in their
        last bits, 0.3 against 0.1): plastic vase at 3M 346, 251, 265 against 461, 247, 298,
        at 1M 126, 143, 130, 117 against 133, 100, 114, 129; sea vase at 3M 123 against 221,
        at 1M 83, 111, 82, 105 against 83, 111, 82, 108; the colonoware pot, dragon jar,
        goblet and synthetic vessel at 1M within 3 iterations. Easing every limiting face (a bound of
        1.2) made one of three 3000-vertex vessels relaxed from Tutte's disc stop at a 1.1 %
        higher energy, the two others lower; 0.3 left them within 0.4 %.
    precond_theta : float
        Weight of the multilevel preconditioner's coarse terms against its Jacobi term
        (measured: 1 needs 30-50% more iterations than 2; 4 about as many as 2 but more
        backtracking).
    window_lbfgs, window_dynamics : int
        Window (iterations) of the relative-energy-change test. (L-BFGS with 5: a few
        iterations cut short by a nearly collapsed triangle passed the test on the 2.5M
        benchmark vessel at edge RMS 0.157; with 10 it went on to 0.1454.)
    boundary_angle_slack : float
        Radians below 2 pi under which a boundary vertex's angle sum counts as open.
    min_time_budget : float
        Seconds a coarse copy gets at the least from what is left of the time budget.
    contrast_start : float
        A higher importance contrast is reached in two relaxations: the first at this
        contrast, the second at the full one from the first's layout (with its own coarse
        copy and preconditioner grids). With the plain surface a thousand times softer than
        the painting, the preconditioner's coarse corrections (which average stiffness over
        the zone's edge) barely move the plain surface: on the bundled amphora a direct solve
        took 646 iterations against 145 + 121 this way, to the same figures. A mesh with a
        coarse copy leaves both relaxations to the copy (which nests: the smallest copy
        takes the first) and is solved once, at the full contrast, from the copy's layout:
        2.5M textured amphora 16.5 s and 36 full-mesh iterations against 22.3 s and 10 + 34,
        with lower edge-length RMS.
    shape_first_tol_factor : float
        The full mesh's solve without the area term, whose anisotropy sets the limit
        (``max_anisotropy="auto"``), stops at this multiple of the preset's tolerance: a
        percentile of the anisotropy settles before the layout does. Plastic vase (its coarse
        copy given up), iterations of that solve + the second and relax seconds with 1 and 3:
        0.1M 93 + 37 and 77 + 38 (1.8 and 1.6 s), 0.3M 168 + 41 and 141 + 40 (6.5 and 5.5 s),
        1M 189 + 44 and 155 + 51 (23.7 and 19.4 s), 3M 284 + 159 both; the limit within 0.02%.
        With 10 the 3M limit moved by 0.35% and the second solve took 551 iterations.
    contrast_start_iterations : int
        Iterations the first of those relaxations spends on its mesh when it started from a
        relaxed coarse copy (the copies converge): it only has to smooth the layout the
        second's coarse copy starts from. Since the copies take the first relaxation this
        applies only when the copy at the full contrast could not be relaxed fold-free and
        the full mesh takes the first relaxation itself. (Without a coarse copy, below
        ``COARSE.min_vertices``, it converges: capped at 10, the bundled amphora took 355
        iterations in all against 241.) Iterations on the full mesh in all (first +
        second), on the 0.3M, 1M and 3M textured amphorae of ``bench_scale`` when the full
        mesh took both: converged first solve 104, 87, 53; 5 first iterations 78, 85, 58;
        10: 58, 55, 40; 20: 94, 84 (0.3M, 1M).
    """

    lbfgs_memory: int = 4
    armijo: float = 1e-4
    step_fraction: float = 0.9
    step_shrink: float = 0.8
    smooth_rounds: int = 3
    smooth_max_fraction: float = 0.01
    ease_rounds: int = 3
    ease_width: float = 4.0
    ease_face_step: float = 0.3
    precond_theta: float = 2.0
    window_lbfgs: int = 10
    window_dynamics: int = 100
    boundary_angle_slack: float = 1e-9
    min_time_budget: float = 1e-3
    contrast_start: float = 100.0
    contrast_start_iterations: int = 10
    shape_first_tol_factor: float = 3.0


@dataclass(frozen=True, kw_only=True)
class CoarseParameters:
    """Coarse copies (grid clusters of the start layout, :mod:`potflat.relax.simplify`).

    A copy has at least ``min_copy`` vertices; the full mesh only follows one
    (``simplify_mm``) when the copy has at most ``max_fraction`` of its vertices (else
    relaxing the copy costs about as much as the full mesh: 0.5M benchmark vessel, a 57%
    copy at 0.5 mm, 7.8 s against 6.2 s) and covers at least ``min_coverage`` of them (cells
    much smaller than the edges leave blocks empty: the goblet scan's copy at 2 mm cells
    covered 38% of its vertices); meshes of at least ``min_vertices`` start their solve from
    a relaxed copy with about ``cell_vertices`` vertices per cell (which nests in turn).
    Where following a copy makes the full mesh's boundary cross itself (a kink of a few
    boundary vertices outside the copy's border), the crossing vertices are moved to their
    neighbours' mean for at most ``follow_repair_rounds`` rounds, widening the moved region
    every ``follow_repair_widen`` rounds, before the copy is given up (1M benchmark amphora:
    one crossing, fixed in one round; giving the copy up cost 1365 iterations, 168 s,
    instead of about 60).
    A copy the full mesh starts from is solved to ``start_tol_factor`` times the
    tolerance (its iterations are cheap; stopped at the full tolerance the goblet's 1M copy
    kept 42 faces squeezed below 1/20 of their area, which the full mesh then kept: 0.1 % of
    the surface at anisotropy above 20; at a tenth, the 1M relaxations took 1-2 s less on
    the synthetic vessel and the colonoware pot, 10 s less on the sea vase).
    Following untangles for the first of ``follow_untangle_rounds``, then re-embeds each
    cluster left folded in the start's shape inside its surroundings, grown by up to
    ``follow_reembed_rings`` rings (:func:`potflat.mesh.embedding.repair_folds`); where
    clusters are left, the same after the next number of rounds. Untangling's ever wider
    averaging bends the boundary out of shape around a fold it cannot undo (at 1M the dragon
    jar's folds went from 242 to 16 in 20 rounds, then back up to 122 after 200, which 40
    rings do not all re-embed), yet on the goblet at 0.1M it is the 200 rounds' layout that
    re-embeds (20 rounds: 17 triangles left at 40 rings, and at 100); the folds left are
    mostly strips of slivers along the boundary (subdivided slivers of the scan), which 12
    rings did not reach across on the goblet and the plastic vase at 1M and 40 did; on the
    sea vase at 3M, 40 left 2 triangles at its boundary folded in both layouts (the copy was
    then given up: 356 full-mesh iterations, 202 s) and 80 re-embeds them (a cluster grows
    only as far as it needs, so a larger bound costs nothing where fewer rings do).
    The followed layout is the full mesh's start only when its energy is at most
    ``follow_most_energy`` times the rollout's: a followed start far above the rollout's
    energy is the slower one (``relax()`` alone, followed start against the rollout's:
    plastic vase at 3M, 2.44 times the energy, 1052 full-mesh iterations against 364 + 114,
    222 s against 98; colonoware pot at 1M, 2.40 times, 154 against 53 + 53, 8.0 s against
    5.2), one near or below it mostly the faster (plastic vase at 0.1M, 1.20 times, 78 against
    75 + 40, 1.3 s against 1.5; at 0.3M, 1.29 times, 73 against 114 + 40, 3.2 s against 4.7).
    The plastic vase's 1M start is 0.94 times the rollout's; the other shared scans' followed
    starts at 1M are far below (sea vase 0.26, dragon jar 0.11, goblet 0.013 times).
    Where that still leaves the followed layout folded, the full mesh instead moves from its
    start towards it in ``approach_steps`` equal shares and at most ``approach_rounds``
    rounds, each vertex as far as keeps every face around it above ``approach_floor`` of its
    smaller area (start or followed; ``approach_margin`` of the bound where one limits), so
    that it stops short only around the folds (:func:`potflat.relax.start.approach`). When
    more than ``approach_most_short`` of the vertices stop short, the distorted patch they
    leave costs the full mesh more than a solve from the rollout, and the copy is given up
    (1M copies: the dragon jar's 2.6 % short took 509 full-mesh iterations, 50 s, against 286
    iterations, 18 s, from the rollout; the plastic vase's 0.5 % took 315, 38 s).
    A followed start that the full mesh solves has its faces of anisotropy above
    ``local_anisotropy``, grown by ``local_rings`` rings, relaxed first with every other
    vertex fixed, for at most ``local_iterations`` iterations to the tolerance ``local_tol``
    (:func:`potflat.relax.local.relax_extremes`): they hold most of the followed start's
    energy (the anisotropy limit's term) and took most of the full mesh's iterations (1M
    copies, full-mesh iterations without and with: sea vase 162 and 86, dragon jar 81 and 48,
    goblet 90 and 83, colonoware pot 190 and 96; with 300 local iterations the sea vase's
    full mesh took 101). The same ``follow_repair_*`` rounds
    unwrap a start's boundary vertices whose triangles wrap past 2 pi
    (:func:`potflat.relax.start.unwrap_boundary`).
    """

    min_copy: int = 100
    start_tol_factor: float = 0.1
    max_fraction: float = 1.0 / 3.0
    min_coverage: float = 0.95
    min_vertices: int = 20_000
    cell_vertices: float = 16.0
    follow_repair_rounds: int = 30
    follow_repair_widen: int = 3
    follow_untangle_rounds: tuple[int, ...] = (20, 200)
    follow_reembed_rings: int = 80
    follow_most_energy: float = 2.0
    approach_steps: int = 30
    approach_rounds: int = 100
    approach_floor: float = 0.1
    approach_margin: float = 0.9
    approach_most_short: float = 0.01
    local_anisotropy: float = 5.0
    local_rings: int = 2
    local_iterations: int = 100
    local_tol: float = 1e-7


#: The energy's barriers and floors.
ENERGY = EnergyParameters()
#: The solvers' steps and stopping.
SOLVER = SolverParameters()
#: The coarse copies.
COARSE = CoarseParameters()
