"""The relaxation's schedule: :func:`relax`, which relaxes coarse copies first, or a first
solve at a lower importance contrast, then the full mesh from their layout.

Relax stage: fold-free elastic relaxation of a rollout (the paper's spring model, Eq. 1).

Springs along every mesh edge plus one cross spring over every winged triangle pair (rest
length: the opposite vertices' distance with the pair unfolded flat about the shared edge),
all in 2D. Two solvers minimise the same spring energy:

* the default presets (``preview``, ``standard``, ``archival``, which differ in their
  convergence tolerance): L-BFGS with a flip-avoiding, monotone line search (no step ever
  lets a triangle's signed area reach zero, the energy never increases), a barrier that
  only acts on triangles squeezed below half their rest area, a barrier that keeps each
  boundary vertex's flat angle sum below 2 pi (its fan cannot wrap over itself; the step
  bound includes it), preconditioned by Jacobi plus additive multilevel corrections on
  bilinear grids over the rollout's domain (:mod:`potflat.relax.hierarchy`), so smooth, long-range
  moves take few iterations. The result is checked for flipped triangles and boundary
  self-overlap; a folded result is never returned.
* ``paper``: the paper's damped dynamics (stretch 2, k = 0.5, mass 1, friction 0.01 inside
  and 1 on the boundary applied per step, semi-implicit Euler, time step from a bound of the
  spring graph's largest eigenvalue: stiffness and valence), reported with its flip count,
  whatever it is; a state that is no longer finite stops it (nothing is written).

Large meshes first relax coarse copies (grid clusters of the start layout,
:mod:`potflat.relax.simplify`) and start from them; ``preview`` relaxes only a copy at the image's
resolution, and the full mesh follows it.

See ``docs/method.md`` for the method and ``docs/performance.md`` for measurements.
"""
from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from potflat._heap import release_free_memory
from potflat._jit import numba_threads
from potflat.errors import FoldedResultError, InvalidInputError, InvalidOptionError
from potflat.mesh.distortion import DistortionSummary, SurfaceReference, bounds, true_scale_factor, zone_summary
from potflat.mesh._kernels.topology import faces_in_vertex_order
from potflat.relax.control import RunControl, progress_bar
from potflat.relax.dynamics import paper_dynamics
from potflat.relax.energy import SpringSystem, importance_weights, mean_edge_length
from potflat.relax.hierarchy import GridHierarchy
from potflat.relax.lbfgs import minimise
from potflat.relax.local import relax_extremes
from potflat.relax.options import RelaxOptions
from potflat.relax.parameters import COARSE, ENERGY, SOLVER, RelaxPreset
from potflat.relax.result import LevelRecord, RelaxResult, RelaxTimings
from potflat.relax.simplify import cell_side, grid_simplification, interpolate
from potflat.relax.start import check_not_mirrored, fold_free_start, follow, turned_like, untangle, unwrap_boundary
from potflat.types import FlatMesh, Mesh

@dataclass(frozen=True)
class CoarseStart:
    """A relaxed coarse copy of the rollout and the full mesh's layout following it."""

    result: RelaxResult | None  # None: the copy could not be relaxed fold-free
    uv: np.ndarray | None  # (n, 2) float64: the full mesh's layout following the copy's
    final: bool  # the full mesh only follows (preview at the image's resolution), no iterations on it
    notes: list[str]


def budget_left(deadline: float) -> float | None:
    """The time budget (s) of a first or coarse solve: what is left before ``deadline``, at
    least ``SOLVER.min_time_budget``; None without a deadline."""
    return None if deadline == np.inf else max(deadline - time.perf_counter(), SOLVER.min_time_budget)


@dataclass(frozen=True)
class SofterStart:
    """The relaxation at a lower importance contrast, the start of the one at the full contrast."""

    uv: np.ndarray | None  # (n, 2) float64: its layout (None once the full solve has taken it)
    contrast: float
    result: RelaxResult  # without its layout (peak memory)

    def note(self, contrast: float) -> list[str]:
        """The notes of the relaxation at ``contrast`` that started from this one."""
        return [f"relaxed first with plain surface {self.contrast:g}x softer than the painting "
                f"({self.result.iterations} iterations), then {contrast:g}x"] + [
                f"first solve: {note}" for note in self.result.notes]


def softer_start(flat: FlatMesh, options: RelaxOptions, progress: bool, callback, deadline: float,
                 limit, copies: bool = True) -> SofterStart:
    """The relaxation of the full mesh at the lower importance contrast
    :attr:`SOLVER.contrast_start <potflat.relax.parameters.SolverParameters.contrast_start>`,
    from which the higher one is reached (when :func:`contrast_staged` and no relaxed coarse
    copy takes it); without ``copies`` no coarse copy of its own (one was given up)."""
    low = SOLVER.contrast_start
    budget = budget_left(deadline)
    sub = _relax(flat, replace(options, importance_contrast=low, time_budget=budget, true_scale=False), progress,
                 callback, summaries=False, fine_iterations=SOLVER.contrast_start_iterations, limit=limit,
                 copies=copies)
    return SofterStart(uv=sub.flat.uv, contrast=low, result=replace(sub, flat=None))


def contrast_staged(flat: FlatMesh, settings: RelaxPreset) -> bool:
    """Whether the full importance contrast is reached from a relaxation at the lower
    :attr:`SOLVER.contrast_start <potflat.relax.parameters.SolverParameters.contrast_start>`:
    a painted zone at a higher contrast (else the weights would not change)."""
    return painted_zone(flat, settings) and settings.importance_contrast > SOLVER.contrast_start


def coarse_start(flat: FlatMesh, options: RelaxOptions, settings: RelaxPreset, progress: bool,
                 callback, deadline: float, limit) -> CoarseStart | None:
    """Relax a coarse copy of ``flat`` (grid clusters of its start layout, :mod:`potflat.relax.simplify`).

    With ``simplify_mm`` the cells have that side and the full mesh will only follow the
    coarse result (when the copy has at most ``COARSE.max_fraction`` of the vertices and
    covers ``COARSE.min_coverage`` of them); else,
    for meshes of at least ``COARSE.min_vertices``, the cells hold about
    ``COARSE.cell_vertices`` vertices and the coarse result is the full solve's start.
    None when neither applies; ``result`` None (with a note) when the copy could not be
    relaxed fold-free.
    """
    V, uv = flat.mesh.vertices, flat.uv
    spacing = settings.simplify_mm
    simple, final = None, False
    if spacing:  # no more resolution than the image resolves
        simple = grid_simplification(V, uv, spacing / flat.mesh.mm_per_unit)
        final = (COARSE.min_copy <= len(simple.vertices) <= COARSE.max_fraction * len(V)
                 and float(np.mean(interpolate(simple, uv, simple.uv)[1])) >= COARSE.min_coverage)
    if not final:
        if not (settings.coarse_start and len(V) >= COARSE.min_vertices):
            return None
        simple = grid_simplification(V, uv, cell_side(uv, COARSE.cell_vertices))
        if len(simple.vertices) < COARSE.min_copy:
            return None
    budget = budget_left(deadline)
    tagged = None if callback is None else (lambda info: callback({**info, "level": "coarse"}))
    try:
        importance = None
        if flat.importance is not None:  # a coarse vertex is as important as its cluster on average
            count = np.bincount(simple.cluster, minlength=len(simple.vertices))
            importance = np.bincount(simple.cluster, flat.importance, len(simple.vertices)) / np.maximum(count, 1)
        sub = _relax(FlatMesh(Mesh(simple.vertices, simple.faces, units=flat.mesh.units), simple.uv,
                              importance=importance),
                     replace(options, simplify_mm=0.0, time_budget=budget, true_scale=False,
                             tol=settings.tol if final else settings.tol * COARSE.start_tol_factor),
                     progress, tagged, summaries=False, limit=limit, outline=final)
    except FoldedResultError as exc:
        return CoarseStart(result=None, uv=None, final=False, notes=[
            f"the {len(simple.vertices)}-vertex coarse copy could not be relaxed fold-free ({exc}); "
            "relaxed the full mesh from the rollout"])
    what = (f"relaxed a coarse copy at {spacing:g} mm resolution ({len(simple.vertices)} vertices); the full mesh "
            "follows it piecewise linearly" if final else
            f"started from a relaxed coarse copy ({len(simple.vertices)} vertices)")
    notes = [what] + [f"coarse copy: {note}" for note in sub.notes]
    return CoarseStart(result=sub, uv=interpolate(simple, uv, sub.flat.uv)[0], final=final, notes=notes)


def painted_zone(flat: FlatMesh, settings: RelaxPreset) -> bool:
    """Whether the importance weights set a painted zone apart from plain surface: an
    importance that is not uniform, at a contrast above 1 (a uniform one, painted all over
    or an all-black mask, weighs every vertex alike)."""
    imp = flat.importance
    return imp is not None and settings.importance_contrast > 1 and float(imp.min()) < float(imp.max())


def anisotropy_limit_setting(settings: RelaxPreset, area: float):
    """The anisotropy limit the settings ask for with the area term's weight ``area``:
    ``"auto"`` (found by a first solve without the area term), a number, or None (no limit)."""
    lim = settings.max_anisotropy
    if lim == "auto":
        return "auto" if area > 0 else None
    return float(lim) if math.isfinite(lim) else None


def relax(flat: FlatMesh, *, options: RelaxOptions | None = None, progress: bool = False,
          callback: Callable[[dict], bool | None] | None = None,
          distortion_before: DistortionSummary | None = None, **kwargs) -> RelaxResult:
    """Relax a rollout's flattening by minimising the paper's spring energy.

    Parameters
    ----------
    flat : FlatMesh
        The rollout: ``flat.mesh.vertices`` (n, 3) give the rest lengths, ``flat.uv`` (n, 2)
        the start, ``flat.mesh.faces`` (m, 3) a cut (disk-like) mesh.
    options : RelaxOptions, optional
        Or give its fields as keyword arguments (``relax(flat, preset="archival")``).
    progress : bool
        Show a progress bar on stderr.
    callback : callable, optional
        Called after every iteration with ``{"iteration", "energy", "level"}``; return True
        to stop early.
    distortion_before : DistortionSummary, optional
        The figures of ``flat`` as given, when the caller has them (:func:`potflat.run_scan`:
        the rollout stage's); :attr:`RelaxResult.distortion_before` then, else computed.

    Returns
    -------
    RelaxResult

    Raises
    ------
    InvalidInputError
        Empty mesh or non-finite coordinates.
    FoldedResultError
        With a fold-free preset, when the start cannot be untangled or the result would
        have flipped triangles or an overlapping boundary (nothing folded is returned).
    """
    if options is None:
        options = RelaxOptions(**kwargs)
    elif kwargs:
        raise InvalidOptionError("give either options= or option keywords to relax(), not both")
    return _relax(flat, options, progress, callback, summaries=True, before=distortion_before)


@dataclass(frozen=True)
class _Frame:
    """The solver's frame of a mesh: lengths in mean 3D edge lengths (``unit``), the layout
    centred on its bounding box (``centre``), vertices in a locality-preserving order
    (``order``: the Morton curve of the start layout)."""

    order: np.ndarray  # (n,) int64
    centre: np.ndarray  # (2,) float64
    unit: float

    def into(self, uv: np.ndarray) -> np.ndarray:
        """A layout (n, 2) in scan units as the solver holds it."""
        return np.take((uv - self.centre) / self.unit, self.order, axis=0)

    def out_of(self, x: np.ndarray) -> np.ndarray:
        """A solver's layout (n, 2) back in scan units and the mesh's vertex order."""
        uv = np.empty_like(x)
        uv[self.order] = x * self.unit + self.centre
        return uv


@dataclass(frozen=True)
class _Plan:
    """What a relaxation solves before its own mesh, and with which area term and limit."""

    area: float  # the area term's weight (0 with a painted zone)
    limit: float | str | None  # the anisotropy limit: a number, "auto" (found by a first solve) or None
    limit_of_copy: bool  # the limit is the one the coarse copy's solve found
    coarse: CoarseStart | None  # a relaxed coarse copy (None: none, or it could not be relaxed)
    softer: SofterStart | None  # a first relaxation at a lower importance contrast
    notes: list[str]


def _checked_arrays(flat: FlatMesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``flat``'s vertices (n, 3) float64, layout (n, 2) float64 and faces (m, 3) int64,
    contiguous; refused when empty or not finite."""
    V = np.ascontiguousarray(flat.mesh.vertices, dtype=np.float64)
    uv = np.ascontiguousarray(flat.uv, dtype=np.float64)
    F = np.ascontiguousarray(flat.mesh.faces, dtype=np.int64)
    if len(V) == 0 or len(F) == 0:
        raise InvalidInputError("the rollout has no faces; nothing to relax (check the rollout stage's output)")
    if not (np.isfinite(V).all() and np.isfinite(uv).all()):
        raise InvalidInputError("the rollout has NaN or infinite coordinates; run the rollout stage again")
    return V, uv, F


def _plan(flat: FlatMesh, options: RelaxOptions, settings: RelaxPreset, progress: bool, callback,
          deadline: float, limit, copies: bool) -> _Plan:
    """Relax what comes before ``flat`` itself: a coarse copy (which nests), or else, with a
    painted zone at a high contrast, a first solve at a lower contrast; and find the area
    term's weight and the anisotropy limit (``limit``: one found by an earlier solve, or
    ``"auto"``: from the settings); a coarse copy only with ``copies``."""
    fold_free = settings.solver != "dynamics"
    # a painted zone takes no area term: the plain surface takes the distortion already, and
    # the area term would trade the painting's shape for its area
    area = settings.area if fold_free and not painted_zone(flat, settings) else 0.0
    if limit == "auto":  # (not passed down by the caller)
        limit = anisotropy_limit_setting(settings, area) if fold_free else None
    # a coarse copy reaches a higher importance contrast by itself (in turn, its smallest copy
    # relaxes at the lower contrast first), so the full mesh is solved once; without a relaxed
    # copy (a small mesh, or one that could not be relaxed fold-free) the full mesh takes the
    # lower contrast's first solve itself
    coarse = coarse_start(flat, options, settings, progress, callback, deadline, limit) if fold_free and copies else None
    softer = None
    if fold_free and contrast_staged(flat, settings) and (coarse is None or coarse.result is None):
        softer = softer_start(flat, options, progress, callback, deadline, limit)
    if limit == "auto" and softer is not None and softer.result.anisotropy_limit is not None:
        limit = softer.result.anisotropy_limit  # the first solve found it: every later solve uses it
    found = None if coarse is None or coarse.result is None else coarse.result.anisotropy_limit
    limit_of_copy = limit == "auto" and found is not None
    if limit_of_copy:  # (None: the copy stopped early; this solve finds it)
        limit = found
    notes = [] if softer is None else softer.note(settings.importance_contrast)
    notes += list(coarse.notes) if coarse is not None else []
    if coarse is not None and coarse.result is None:
        coarse = None
    return _Plan(area=area, limit=limit, limit_of_copy=limit_of_copy, coarse=coarse, softer=softer, notes=notes)


def _spring_system(V: np.ndarray, F: np.ndarray, start_uv: np.ndarray, flat: FlatMesh, settings: RelaxPreset,
                   plan: _Plan, unit: float) -> tuple[SpringSystem, GridHierarchy, _Frame, np.ndarray | None]:
    """The spring system of ``V`` (n, 3) and ``F`` (m, 3) in the solver's frame of the start
    layout ``start_uv`` (n, 2), the preconditioner's grids, the frame, and the vertices'
    importance weights (None: all 1)."""
    fold_free = settings.solver != "dynamics"
    n = len(V)
    lo, hi = bounds(start_uv)
    centre = 0.5 * (lo + hi)
    # locality-preserving order (Morton curve of the layout) and the preconditioner's grids
    hier = GridHierarchy.build((start_uv - centre) / unit, min_vertices_per_cell=settings.cell_vertices)
    frame = _Frame(order=hier.order, centre=centre, unit=unit)
    inverse = np.empty(n, np.int64)
    inverse[frame.order] = np.arange(n)
    Vs = np.take(V, frame.order, axis=0) / unit  # (rows gathered by take: 2-4x faster than indexing)
    # faces in the vertices' order too: the face passes and gathers read nearby memory
    # (2.5M benchmark vessel: an evaluation of the energy and gradient 1.6x faster)
    Fs = faces_in_vertex_order(F, inverse)
    del inverse
    weight = None
    if fold_free and flat.importance is not None and settings.importance_contrast > 1:
        weight = importance_weights(flat.importance[frame.order], settings.importance_contrast)
    sp = SpringSystem(Vs, Fs, n, k=settings.stiffness, relative=settings.weighting == "relative",
                      weight=weight, shape=settings.shape if fold_free else 0.0,
                      rigidity=settings.rigidity if fold_free else 0.0, area=plan.area)
    if plan.limit != "auto":
        sp.set_area_and_limit(plan.area, plan.limit)
    return sp, hier, frame, weight


def _start(sp: SpringSystem, x: np.ndarray, V: np.ndarray, frame: _Frame, plan: _Plan, fold_free: bool,
           notes: list[str], *, local: bool, deadline: float) -> tuple[np.ndarray, np.ndarray | None, bool, float]:
    """The solve's start from the layout ``x`` (n, 2, solver frame) of the rest positions ``V``
    (n, 3): untangled and fold-free (fold-free presets), then where the relaxed coarse copy
    takes it when that can be made fold-free (:func:`potflat.relax.start.follow`) and, for a
    copy that is only the solve's start, has an energy at most ``COARSE.follow_most_energy``
    times ``x``'s; then, with ``local``, with its extreme faces relaxed locally
    (:func:`potflat.relax.local.relax_extremes`, stopped at ``deadline``).

    Returns the start, the folded layout it replaces when it is Tutte's disc (else None),
    whether it follows the copy and the seconds spent following it."""
    folded_start = None
    if fold_free:
        check_not_mirrored(sp, x)
        x, n_bad = untangle(sp, x)
        if n_bad:
            if (sp.signed_areas(x) <= 0).any():
                folded_start = x
                x, from_disc = fold_free_start(sp, x, n_bad, notes)
                if not from_disc:
                    folded_start = None
            else:
                notes.append(f"untangled {n_bad} flipped or degenerate triangles of the rollout before relaxing")
        x = unwrap_boundary(sp, x, notes, "the rollout")
        wrapped = sp.guard_boundary(x)
    t_follow = time.perf_counter()
    followed = None
    if plan.coarse is not None:
        judged = fold_free and not plan.coarse.final  # a start for the full mesh's solve, not its result
        # (judged without the outline term: a followed border is the copy's, smooth between its
        # vertices, while the full mesh's border keeps every bend of the scan's)
        energy = sp.evaluate(x, outline=False)[0] if judged else math.inf
        followed = follow(sp, x, frame.into(plan.coarse.uv), notes)
        if followed is not None and fold_free:
            wrapped_x, wrapped = wrapped, sp.guard_boundary(followed)
            if judged and not sp.evaluate(followed, outline=False)[0] <= COARSE.follow_most_energy * energy:
                notes.append("following the coarse copy gave a start of higher energy than the rollout's; relaxed "
                             "the full mesh from the rollout")
                followed, wrapped = None, wrapped_x
                sp.guard_boundary(x)
            elif judged and local:
                relaxed = relax_extremes(sp, followed, np.take(V, frame.order, axis=0) / frame.unit, notes,
                                         deadline=deadline)
                if relaxed is not followed:  # (a vertex pressed against the angle-sum barrier can end in its slack)
                    relaxed = unwrap_boundary(sp, relaxed, notes, "the relaxed patches")
                    followed, wrapped = relaxed, sp.guard_boundary(relaxed)
        if followed is not None:
            x = followed
    t_follow = time.perf_counter() - t_follow
    if fold_free and wrapped:
        notes.append(f"{wrapped} boundary vertices already wrap past 2 pi in the start; their angle "
                     "sums are not guarded (the final boundary check still applies)")
    return x, folded_start, followed is not None, t_follow


def _solve(sp: SpringSystem, x: np.ndarray, hier: GridHierarchy, frame: _Frame, V: np.ndarray,
           settings: RelaxPreset, plan: _Plan, coarse: CoarseStart | None, run: RunControl,
           t_follow: float, notes: list[str], *,
           shape_tol: float) -> tuple[np.ndarray, bool, list[LevelRecord], float | str | None]:
    """Solve the full mesh from ``x`` (or only follow the coarse copy: ``preview``); a solve
    without the area term that sets the anisotropy limit stops at ``shape_tol``. ``x`` may be
    overwritten (:func:`potflat.relax.lbfgs.minimise`).

    Returns the layout, whether it converged, the levels solved (the first solve's and the
    coarse copies' first) and the anisotropy limit used."""
    limit = plan.limit
    levels: list[LevelRecord] = []
    if plan.softer is not None:
        levels.extend(replace(level, importance_contrast=plan.softer.contrast) for level in plan.softer.result.levels)
    if coarse is not None:
        levels.extend(replace(level, level=level.level.replace("fine", "coarse")) for level in coarse.result.levels)
    if coarse is not None and coarse.final:
        levels.append(LevelRecord(level="follow", vertices=sp.n, iterations=0, energy=sp.spring_energy(x),
                                  seconds=t_follow))
        return x, coarse.result.converged, levels, limit
    if settings.solver == "dynamics":
        x, converged, record = paper_dynamics(sp, x, settings, run)
        return x, converged, levels + [record], limit
    if limit == "auto":
        # the energy without the area term first: its anisotropy sets the limit
        sp.set_area_and_limit(0.0, None)
        x, converged, record = minimise(sp, x, hier, tol=shape_tol, run=run, notes=notes, level="fine, shape first")
        levels.append(record)
        limit = None if run.stopped else sp.anisotropy_percentile(np.take(V, frame.order, axis=0), x,
                                                                  ENERGY.limit_percentile)
        if limit is None or not math.isfinite(limit):  # (nan: no face with a rest area)
            return x, converged, levels, None
        sp.set_area_and_limit(plan.area, limit)
    x, converged, record = minimise(sp, x, hier, tol=settings.tol, run=run, notes=notes)
    return x, converged, levels + [record], limit


def _relax(flat: FlatMesh, options: RelaxOptions, progress: bool, callback, *, summaries: bool,
           before: DistortionSummary | None = None,
           fine_iterations: int | None = None, limit="auto", copies: bool = True,
           outline: bool = True) -> RelaxResult:
    """:func:`relax`; without ``summaries`` (a coarse copy, whose layout is all its caller
    reads) the result's distortion summaries are None and its stress is not computed;
    ``before``: the start's summary when the caller has it (with ``summaries`` only);
    ``fine_iterations``: when a coarse copy was relaxed, at most this many iterations on
    ``flat`` itself (a first solve that only smooths); ``limit``: the anisotropy limit found
    by an earlier solve (``"auto"``: from the settings); ``copies``: whether a coarse copy
    may be relaxed first; ``outline``: whether the outline term is on (not for a coarse copy
    that is only a start: its simplified border is not the image's, and holding its angle
    sums bent the copy into starts the full mesh could not follow)."""
    settings = options.resolved()
    V, uv, F = _checked_arrays(flat)
    n = len(V)
    fold_free = settings.solver != "dynamics"
    t_start = time.perf_counter()
    deadline = t_start + (options.time_budget or np.inf)
    with numba_threads(options.threads):
        unit = mean_edge_length(V, F)
    if not unit > 0:
        raise InvalidInputError("all edges of the rollout have zero length; check the scan's units and faces")
    plan = _plan(flat, options, settings, progress, callback, deadline, limit, copies)
    with numba_threads(options.threads):
        while True:
            notes = list(plan.notes)
            start_uv = flat.uv if plan.softer is None else plan.softer.uv
            sp, hier, frame, weight = _spring_system(V, F, start_uv, flat, settings, plan, unit)
            if not outline:
                sp.outline_mu = 0.0
            x = frame.into(start_uv) * (settings.stretch if plan.softer is None else 1.0)
            del start_uv
            if plan.softer is not None:  # its layout is in x now (peak memory)
                plan = replace(plan, softer=replace(plan.softer, uv=None))
            # (the local step on the full mesh only: a copy's layout only starts the next, and
            # relaxed locally it can change which copy the full mesh follows)
            x, folded_start, followed, t_follow = _start(sp, x, V, frame, plan, fold_free, notes, local=summaries,
                                                         deadline=deadline)
            if plan.coarse is None or followed:
                break
            # the copy is given up: every decision taken because of it is taken again (its
            # anisotropy limit fits the copy's layout, not the rollout; the first solve at the
            # lower importance contrast was the copy's)
            plan = replace(plan, coarse=None, notes=notes)
            if plan.limit_of_copy:
                plan = replace(plan, limit="auto", limit_of_copy=False)
            if not contrast_staged(flat, settings):
                break
            del sp, hier, x, folded_start
            softer = softer_start(flat, options, progress, callback, deadline, plan.limit, copies=False)
            found = softer.result.anisotropy_limit
            plan = replace(plan, softer=softer, notes=softer.note(settings.importance_contrast) + notes,
                           limit=found if plan.limit == "auto" and found is not None else plan.limit)
        # only the copy's result is read from here on (peak memory: the solve comes next)
        coarse = None if plan.coarse is None else replace(plan.coarse, uv=None)
        plan = replace(plan, coarse=None)  # (``coarse`` is what is left of it)
        # the setup's freed temporaries back to the system before the solve (the stage's peak;
        # 140 MiB at 3M vertices after a rollout in the same process, whose arrays fill the heap)
        release_free_memory()
        t_setup = time.perf_counter()

        bar = progress_bar(settings.max_iter) if progress else contextlib.nullcontext(None)
        with bar as report:
            prefix = [] if plan.softer is None else list(plan.softer.result.energy_history)
            prefix += [] if coarse is None else list(coarse.result.energy_history)
            # (a first solve without a coarse copy must converge: nothing else moves its plain surface far)
            capped = coarse is not None and fine_iterations is not None and fine_iterations < settings.max_iter
            run = RunControl((fine_iterations if capped else settings.max_iter) + len(prefix), deadline, callback,
                             report)
            run.history.extend(prefix)
            # (looser on the full mesh only: a copy's layout starts the next, and looser there it
            # changes which copy the full mesh follows)
            shape_tol = settings.tol * (SOLVER.shape_first_tol_factor if summaries else 1.0)
            x, converged, levels, limit = _solve(sp, x, hier, frame, V, settings, plan, coarse, run, t_follow, notes,
                                                 shape_tol=shape_tol)
        t_solve = time.perf_counter()

        # checked as solved: the turn below moves the layout rigidly, which makes or undoes no fold
        # or crossing, but its rounding can make a boundary vertex that the solve left touching a
        # segment within 1e-15 test as crossing it (an aryballos panel with max_anisotropy 1.3)
        finite = bool(np.isfinite(x).all())
        flipped = int((sp.signed_areas(x) <= 0).sum()) if finite else len(F)
        overlap = sp.overlap(x) if finite else 1
        if fold_free:  # back to the rollout's orientation, the painting counting most
            turn = np.ones(n) if weight is None else weight.copy()
            if folded_start is not None:  # relaxed from Tutte's disc: only what was not folded counts
                turn[sp.faces[sp.signed_areas(folded_start) <= 0].ravel()] = 0.0
            # the rollout's layout (its orientation is the result's) or the folded start
            x = turned_like(x, frame.into(uv) if folded_start is None else folded_start, turn)
            finite = finite and bool(np.isfinite(x).all())
        del sp, hier  # release the spring system before the distortion summaries (peak memory)
    if fold_free and (flipped or overlap or not finite):
        raise FoldedResultError(
            f"relaxation ended with {flipped} flipped triangles and {overlap} boundary crossings; "
            "nothing written: this is a bug in potflat, please report it with the rollout file")
    if not finite:
        raise FoldedResultError("the paper dynamics diverged (positions no longer finite); nothing written: use a "
                                "fold-free preset (standard)")
    uv_out = frame.out_of(x)
    factor = 1.0
    # the 3D side of every figure below, computed once (not at all for a first or coarse solve)
    surface = SurfaceReference(V, F) if settings.true_scale or summaries else None
    if settings.true_scale:
        factor = true_scale_factor(V, uv_out, F, flat.importance, reference=surface)
        uv_out = frame.centre + (uv_out - frame.centre) * factor
    after = stress = zone = None
    if summaries:
        before = before if before is not None else surface.summarize(uv)
        # the relaxed map's per-face and per-edge figures, once for its summary and its zone's
        fd = surface.face_distortion(uv_out)
        edge_error = surface.edge_length_error(uv_out)
        after = surface.summarize(uv_out, fd=fd, edge_error=edge_error)
        stress = surface.vertex_stress(uv_out, flat.mesh.mm_per_unit)
    t_check = time.perf_counter()
    if summaries:
        zone = zone_summary(V, uv_out, F, flat.importance, reference=surface, fd=fd, edge_error=edge_error)
        del fd, edge_error
    t_end = time.perf_counter()
    stopped = [f"stopped by {run.stopped}"] if run.stopped and not (capped and run.stopped == "max_iter") else []
    return RelaxResult(
        flat=flat.replace(uv=uv_out, stress=stress),
        energy_history=np.asarray(run.history, dtype=np.float64),
        iterations=len(run.history),
        converged=bool(converged),
        flipped=flipped,
        boundary_overlap=overlap,
        distortion=after,
        distortion_before=before,
        zone=zone,
        timings=RelaxTimings(setup=t_setup - t_start, solve=t_solve - t_setup, check=t_check - t_solve,
                             figures=t_end - t_check, total=t_end - t_start),
        preset=options.preset,
        levels=tuple(levels),
        settings=settings,
        scale_factor=factor,
        anisotropy_limit=None if limit == "auto" else limit,
        notes=tuple(notes + stopped),
        reference=surface if summaries else None,
    )
