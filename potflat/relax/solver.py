"""Relax stage: fold-free elastic relaxation of a rollout (the paper's spring model, Eq. 1).

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
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from potflat.mesh.distortion import (
    DistortionSummary,
    SurfaceReference,
    bounds,
    face_areas,
    face_distortion,
    row_blocks,
    true_scale_factor,
    weighted_percentile,
    zone_summary,
)
from potflat.errors import FoldedResultError, InvalidInputError, InvalidOptionError
from potflat.mesh.boundary import crossing_pairs
from potflat.relax.parameters import COARSE, ENERGY, PRESETS, SOLVER, WEIGHTINGS
from potflat.types import FlatMesh, Mesh



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
        barrier and shape term of plain surface are weighted ``1 / importance_contrast``, so
        the distortion goes there. 1: the whole surface alike. Used when the flattening
        carries an importance (:attr:`potflat.types.FlatMesh.importance`). None: the preset's.
    true_scale : bool or None
        Scale the result uniformly so that the median length scale in the important zone
        (the whole surface without one) is exactly 1: lengths read off the image with its
        scale bar are right where the painting is. None: the preset's (off for ``paper``).
    """

    preset: str = "standard"
    tol: float | None = None
    max_iter: int | None = None
    time_budget: float | None = None
    threads: int | None = None
    stretch: float | None = None
    stiffness: float | None = None
    weighting: str | None = None
    simplify_mm: float | None = None
    shape: float | None = None
    rigidity: float | None = None
    area: float | None = None
    max_anisotropy: float | Literal["auto"] | None = None
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

    def resolved(self) -> dict:
        """The preset's settings with the options given here applied."""
        out = PRESETS[self.preset].settings()
        for name in ("tol", "max_iter", "stretch", "stiffness", "weighting", "simplify_mm", "shape",
                     "rigidity", "area", "max_anisotropy", "importance_contrast", "true_scale"):
            if getattr(self, name) is not None:
                out[name] = getattr(self, name)
        out["time_budget"] = self.time_budget
        return out


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


@dataclass(frozen=True)
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
    zone : dict
        How true the result is in the painted zone and in the rest
        (:func:`potflat.mesh.distortion.zone_summary`: ``important_zone``, ``rest``, ``lengths``).
    timings : dict
        Seconds per phase: ``setup`` (springs, hierarchy, untangling), ``solve``, ``check``
        (fold checks, distortion summaries, stress), ``figures`` (``zone``), ``total``.
    preset : str
    levels : tuple of dict
        Per level (``coarse`` copies, then ``fine`` for the full mesh, or ``follow`` when it
        only follows a copy): name, vertices, iterations, spring energy (without barrier) at
        its end, seconds; the solved levels also whether the boundary touched itself and how
        many search directions were smoothed at faces limiting the step.
    settings : dict
        The resolved settings (preset values with options applied).
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
    zone: dict | None
    timings: dict
    preset: str
    levels: tuple = ()
    settings: dict = field(default_factory=dict)
    scale_factor: float = 1.0
    notes: tuple = ()
    anisotropy_limit: float | None = None
    reference: SurfaceReference | None = None


_NO_FLAGS = np.empty(0, bool)
_NO_WEIGHTS = np.empty(0)
_NO_SHAPE = np.empty((0, 5))


class _Springs:
    """Spring system and triangles of a mesh in normalised, Morton-sorted form."""

    def __init__(self, V: np.ndarray, faces: np.ndarray, n: int, *, k: float, relative: bool,
                 weight: np.ndarray | None = None, shape: float = 0.0, rigidity: float = 0.0,
                 area: float = 0.0):
        """``V`` (n, 3) rest positions and ``faces`` (m, 3) in normalised units; ``weight``
        (n,) the vertices' importance weights (None: all 1), ``shape``, ``rigidity`` and
        ``area`` the per-face terms' weights (0: none); no anisotropy limit until
        :meth:`set_area_and_limit` sets one."""
        from potflat.relax._kernels import overlap as relax_overlap
        from potflat.relax._kernels import springs as ks

        self.ks, self.ko = ks, relax_overlap
        self.vf_ptr, self.vf_tri = ks.vertex_faces(n, faces)
        edges, cross, self.boundary_segments = ks.halfedge_springs(faces, self.vf_ptr, self.vf_tri, True)
        self.ptr, self.nbr, self.rst = ks.build_csr(V, edges, cross, ks.cross_rest_lengths(V, cross))
        del edges, cross  # peak memory: the spring lists are only needed for the CSR
        areas = face_areas(V, faces)
        self.a_ref = np.maximum(areas, ENERGY.area_floor)
        self.faces = np.ascontiguousarray(faces, dtype=np.int32)  # half the memory traffic
        self.weight = _NO_WEIGHTS if weight is None else np.ascontiguousarray(weight, dtype=np.float64)
        self.shape = _NO_SHAPE
        # per unit rest area: a triangle of mean area weighs ``shape`` against its springs
        self.terms = np.array([shape, rigidity, 0.0, 0.0, math.inf, ENERGY.area_eps])
        if (shape > 0 or rigidity > 0 or area > 0) and len(faces):
            self.shape = np.empty((len(faces), 5))
            ks.shape_coefficients(V, self.faces, self.weight, 1.0 / float(np.mean(areas)), ENERGY.area_floor,
                                  self.shape)
        self.set_area_and_limit(area, None)
        del areas
        self.k, self.relative = float(k), bool(relative)
        self.n, self.m = n, len(faces)
        self.n_springs = len(self.nbr) // 2
        self.boundary = np.zeros(n, bool)
        self.boundary[self.boundary_segments.ravel()] = True
        self.isolated = np.diff(self.vf_ptr) == 0
        self.bprev, self.bnext = _boundary_neighbours(self.boundary_segments, n)
        self.bguard = np.zeros(n, bool)  # set by guard_boundary()
        self.contact = False  # set by guard_boundary()
        seg = self.boundary_segments
        # the contact search's grid cell (at least the barrier's reach)
        self._contact_cell = max(ENERGY.contact_gap, 2.0 * float(np.mean(np.linalg.norm(V[seg[:, 0]] - V[seg[:, 1]], axis=1)))
                                 if len(seg) else 1.0)
        self.bverts = np.zeros(0, np.int64)
        self.theta = np.zeros(n)
        self._bblocks = np.empty(1)
        self._es = np.empty(n)
        self._eb = np.empty(n)
        self._areas = np.empty(self.m)
        self.diag = np.empty(n)
        self._blocks = np.empty(max(1, -(-self.m // ks.BLOCK)))
        self._below = np.zeros(len(self._blocks), np.int64)  # faces near the barrier per block
        self._coef = np.empty((len(self.shape), 4))  # the per-face terms' gradient coefficients
        self._e_face = np.zeros(len(self._blocks))  # and their energy per block

    def set_area_and_limit(self, area: float, limit: float | None) -> None:
        """Set the area term's weight and the anisotropy limit (None: none). Without per-face
        coefficients (no shape, rigidity or area term at construction) there is neither."""
        shaped = len(self.shape) > 0
        self.terms[2] = area if shaped else 0.0
        self.terms[3] = ENERGY.limit_mu if limit is not None and shaped else 0.0
        self.terms[4] = math.sqrt(limit) - 1.0 / math.sqrt(limit) if limit is not None else math.inf

    def anisotropy_percentile(self, V: np.ndarray, x: np.ndarray, q: float) -> float:
        """The ``q``-th percentile (0-100) of the faces' anisotropy ``sigma_1 / sigma_2`` in the
        layout ``x`` of the rest positions ``V`` (n, 3) (any scales), weighted by rest area."""
        fd = face_distortion(V, x, self.faces.astype(np.int64))
        return weighted_percentile(fd.anisotropy, fd.area_3d, q)

    def guard_boundary(self, x: np.ndarray) -> int:
        """Guard the angle sum of every boundary vertex below ``2 pi`` from ``x`` on.

        Vertices whose fan already wraps past ``2 pi`` at ``x`` (or whose boundary is not a
        simple path through them) stay unguarded. Returns how many already wrapped.
        """
        cand = np.nonzero((self.bprev >= 0) & (self.bnext >= 0) & (self.bprev != self.bnext))[0]
        theta = np.zeros(self.n)
        if len(cand):
            self.ks.boundary_angle_sums(x, cand, self.vf_ptr, self.vf_tri, self.faces, theta)
        ok = theta[cand] < 2.0 * math.pi - SOLVER.boundary_angle_slack
        self.bverts = np.ascontiguousarray(cand[ok])
        self.bguard = np.zeros(self.n, bool)
        self.bguard[self.bverts] = True
        self._bblocks = np.empty(max(1, -(-len(self.bverts) // self.ks.BLOCK)))
        self.contact = len(self.boundary_segments) >= 3 and self.overlap(x) == 0
        return int((~ok).sum())

    def evaluate(self, x: np.ndarray, *, barrier: bool = True,
                 out: np.ndarray | None = None) -> tuple[float, float, np.ndarray]:
        """Total energy, elastic energy (springs and shape term) and gradient at ``x``
        (written into ``out`` (n, 2) when given, else a fresh array). Also sets ``diag``,
        the Hessian diagonal bound at ``x``."""
        g = np.empty((self.n, 2)) if out is None else out
        self.ks.face_terms(x, self.faces, self.a_ref, ENERGY.barrier_eps, self.shape, self.terms, self._areas,
                           self._below, self._coef, self._e_face)
        if barrier and len(self.bverts):
            self.ks.boundary_angle_sums(x, self.bverts, self.vf_ptr, self.vf_tri, self.faces, self.theta)
        self.ks.energy_gradient(x, self.ptr, self.nbr, self.rst, self.k, self.relative, ENERGY.length_floor,
                                self.weight, self.vf_ptr, self.vf_tri, self.faces,
                                self.shape, self._coef, self.bprev, self.bnext, self.bguard, self.theta, ENERGY.boundary_mu if barrier else 0.0,
                                ENERGY.boundary_gap, g, self._es, self._eb, self.diag)
        es = float(np.sum(self._es)) + float(np.sum(self._e_face))  # (zeros without per-face terms)
        if not barrier:
            return es, es, g
        eb = float(np.sum(self._eb))
        ef = self.ks.face_barrier(x, self.faces, self._areas, self.a_ref, ENERGY.barrier_mu, self.k, ENERGY.barrier_eps,
                                  self.relative, self.weight, g, self.diag, self._below)
        ec = 0.0
        if self.contact:
            ec = self.ko.contact_barrier(x, self.boundary_segments, self.bprev, self.bnext, ENERGY.contact_gap,
                                         ENERGY.contact_mu * self.k, self._contact_cell, self.weight, g, self.diag)
        return es + eb + ef + ec, es, g

    def spring_energy(self, x: np.ndarray) -> float:
        """Elastic energy without the barriers: the springs (Eq. 1 with the 1/2 per spring,
        importance-weighted) plus the shape term."""
        return self.evaluate(x, barrier=False)[1]

    def max_step(self, x: np.ndarray, d: np.ndarray, cap: float = np.inf, shrink: float = 1.0,
                 limiting: np.ndarray | None = None) -> float:
        """Largest ``t`` (at most ``cap``) keeping every face of ``x + t d`` above ``1 - shrink``
        of its area at ``x`` (``shrink = 1``: positively oriented), every guarded boundary
        vertex's angle sum below ``2 pi`` and every boundary pair of the contact barrier above
        ``1 - shrink`` of its distance (:meth:`_boundary_step`). With ``limiting`` ((m,) bool)
        also flag the faces whose own bound is below ``cap``."""
        if self.m == 0:
            return cap
        self.ks.max_step(x, d, self.faces, float(cap), float(shrink), self._blocks,
                         _NO_FLAGS if limiting is None else limiting)
        return self._boundary_step(x, d, float(self._blocks.min()), float(shrink))

    def max_step_near(self, x: np.ndarray, d: np.ndarray, verts: np.ndarray, cap: float, shrink: float) -> float:
        """:meth:`max_step` for a direction ``d`` changed at ``verts`` only, from one for which
        no face away from them was limiting (its bound was at least ``cap``): only the faces
        around ``verts``, the guarded boundary and the contact pairs are tested."""
        faces = self.ks.incident_faces(verts, self.vf_ptr, self.vf_tri)
        return self._boundary_step(x, d, self.ks.max_step_of(x, d, self.faces, faces, float(cap), float(shrink)),
                                   float(shrink))

    def _boundary_step(self, x: np.ndarray, d: np.ndarray, t: float, shrink: float) -> float:
        """``t`` limited by the guarded boundary vertices' angle sums along ``x + t d`` and, while
        the contact barrier is on, by the boundary pairs it acts on (each may lose at most
        ``shrink`` of its distance, as a face of its area)."""
        if len(self.bverts):
            self.ks.boundary_max_step(x, d, self.bverts, self.bprev, self.bnext, self._bblocks)
            t = min(t, float(self._bblocks.min()))
        if self.contact:
            t = self.ko.contact_max_step(x, d, self.boundary_segments, self.bprev, self.bnext, ENERGY.contact_gap,
                                         self._contact_cell, t, shrink)
        return t

    def signed_areas(self, x: np.ndarray) -> np.ndarray:
        """Signed area of every face at ``x``, shape (m,)."""
        out = np.empty(self.m)
        self.ks.face_areas(np.ascontiguousarray(x, dtype=np.float64), self.faces, out)
        return out

    def overlap(self, x: np.ndarray) -> int:
        """Crossing pairs of boundary segments at ``x`` (counting stops at 1000)."""
        return len(crossing_pairs(x, self.boundary_segments, max_pairs=1000))

    def laplacian_bound(self) -> float:
        """An upper bound of the spring graph Laplacian's largest eigenvalue from the actual
        stiffness and valence (Gershgorin: twice the largest sum of a vertex's spring
        stiffnesses). A power iteration approaches the eigenvalue from below, and a step from
        its estimate diverged on real scans (plastic and sea vase: positions beyond 1e150)."""
        if self.relative:
            coef = self.k / np.maximum(self.rst, ENERGY.length_floor) ** 2
            rows = np.bincount(np.repeat(np.arange(self.n), np.diff(self.ptr)), weights=coef, minlength=self.n)
        else:
            rows = self.k * np.diff(self.ptr).astype(np.float64)
        return 2.0 * float(rows.max(initial=0.0))


def _boundary_neighbours(segments: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Each vertex's boundary predecessor and successor along the faces' orientation.

    Parameters
    ----------
    segments : (b, 2) int64
        Boundary half-edges ``a -> b`` oriented as in their faces (:func:`halfedge_springs`).

    Returns
    -------
    bprev, bnext : (n,) int32
        ``bnext[a] = b`` and ``bprev[b] = a``; -1 where a vertex has no or several boundary
        half-edges leaving (arriving), i.e. off the boundary or where the boundary touches itself.
    """
    bprev = np.full(n, -1, np.int32)
    bnext = np.full(n, -1, np.int32)
    if len(segments) == 0:
        return bprev, bnext
    a, b = segments[:, 0], segments[:, 1]
    keep = np.bincount(a, minlength=n)[a] == 1
    bnext[a[keep]] = b[keep]
    keep = np.bincount(b, minlength=n)[b] == 1
    bprev[b[keep]] = a[keep]
    return bprev, bnext


class _Run:
    """Bookkeeping shared by the solvers: history, budget, progress, callback."""

    def __init__(self, max_iter: int, deadline: float, callback, progress):
        self.history: list[float] = []
        self.max_iter = max_iter
        self.deadline = deadline
        self.callback = callback
        self.progress = progress
        self.level = ""
        self.stopped = ""

    def record(self, energy: float) -> bool:
        """Store one iteration; True when the run must stop (cap, budget, callback)."""
        self.history.append(energy)
        it = len(self.history)
        if self.progress is not None and (it % 10 == 0 or it == 1):
            self.progress(it, energy, self.level)
        if self.callback is not None and self.callback({"iteration": it, "energy": energy, "level": self.level}):
            self.stopped = "callback"
        elif it >= self.max_iter:
            self.stopped = "max_iter"
        elif time.perf_counter() > self.deadline:
            self.stopped = "time_budget"
        return bool(self.stopped)


def _relative_change(hist: list[float], window: int) -> float:
    if len(hist) <= window:
        return np.inf
    old, new = hist[-1 - window], hist[-1]
    return abs(old - new) / (window * max(abs(new), 1e-300))


_NO_VECTOR = np.empty(0)


class _LBFGS:
    """Preconditioned L-BFGS with a flip-free, monotone line search.

    The initial inverse Hessian is ``H0 = D^-1 + coarse terms``: the inverse of the
    Hessian's diagonal bound at the current state (Jacobi, so a squeezed triangle's stiff
    barrier does not shrink everybody's step) plus the additive multilevel correction of
    :class:`potflat.relax.hierarchy.MultilevelPreconditioner` (smooth, long-range moves in one
    step), scaled by ``s.y / y.H0.y`` of the newest pair. With ``guard_overlap`` a trial point
    whose boundary overlaps itself is rejected like one of higher energy. The vector algebra
    runs in fused in-place passes (:mod:`potflat.relax._kernels.lbfgs`) over preallocated buffers.

    Attributes
    ----------
    x : (n, 2) float64
        Current positions (``trial``: the line search's).
    """

    def __init__(self, sp: _Springs, x: np.ndarray, precond=None, *, guard_overlap: bool = False):
        from potflat.relax._kernels import lbfgs as kl

        self.kl, self.sp, self.precond = kl, sp, precond
        self.guard_overlap = guard_overlap
        self.contacts = 0  # trial points rejected because the boundary would overlap
        self.smoothed = 0  # directions smoothed at the vertices of limiting faces
        self._limiting = np.empty(sp.m, bool)  # faces holding the step below the natural one
        self._seen = np.zeros(sp.n, bool)  # work space of the smoothing
        size = 2 * sp.n
        self.x = np.array(x, dtype=np.float64, order="C")
        self.trial = np.empty_like(self.x)
        self.grads = [np.empty_like(self.x), np.empty_like(self.x)]
        # one slot per pair kept (at 3M vertices each pair is 96 MB)
        self.S = np.empty((SOLVER.lbfgs_memory, size))
        self.Y = np.empty((SOLVER.lbfgs_memory, size))
        self.rho = np.zeros(SOLVER.lbfgs_memory)
        self.yhy = np.zeros(SOLVER.lbfgs_memory)
        self.slots: list[int] = []  # oldest first
        self.q = np.empty(size)
        self._tmp = np.empty(size) if precond is not None else None
        self._part = np.empty(max(1, -(-size // kl.BLOCK)))
        self._part2 = np.empty_like(self._part)
        self.cur = 0  # index of grads holding the current gradient
        self.E, _es, g = sp.evaluate(self.x, out=self.grads[self.cur])
        self.g = g.reshape(-1)
        if precond is not None:
            precond.refresh(sp.diag)
            # the restrictions of the gradient and of every pair's y: the two-loop recursion's
            # vector, a combination of these, is restricted on the grid nodes (no vertex pass)
            self.rg = precond.restrict(g)
            self.RY = np.empty((SOLVER.lbfgs_memory,) + self.rg.shape)

    def _combine(self, q, c, src, a, y, diag, scale, s) -> float:
        self.kl.combine(q, c, src, a, y, diag, scale, s, self._part)
        return float(np.sum(self._part))

    def _initial(self, r: np.ndarray, scale: float, s: np.ndarray, restricted: np.ndarray | None) -> float:
        """``q = scale H0 r`` (``restricted``: the preconditioner's restriction of ``r``);
        returns ``s . q``."""
        if self.precond is None:
            return self._combine(self.q, scale, r, 0.0, r, self.sp.diag, 1.0, s)
        self.precond.apply(r.reshape(-1, 2), self.q.reshape(-1, 2), restricted=restricted)
        return self._combine(self.q, scale, self.q, 0.0, self.q, _NO_VECTOR, 1.0, s)

    def _direction(self) -> float:
        """Set ``q`` to the L-BFGS direction (two-loop recursion); return ``g . q``."""
        q, g, tmp, S, Y, rho = self.q, self.g, self._tmp, self.S, self.Y, self.rho
        tmp = q if tmp is None else tmp  # without a preconditioner H0 is applied in place
        order = self.slots[::-1]  # newest first
        preconditioned = self.precond is not None
        if not order:
            return self._initial(g, -1.0, g, self.rg if preconditioned else None)
        gamma = 1.0 / (rho[order[0]] * self.yhy[order[0]])  # s.y / y.H0.y of the newest pair
        alpha = {}
        part = self._combine(tmp, -1.0, g, 0.0, g, _NO_VECTOR, 1.0, S[order[0]])
        rtmp = -self.rg if preconditioned else None
        for k, j in enumerate(order):
            alpha[j] = rho[j] * part
            nxt = S[order[k + 1]] if k + 1 < len(order) else _NO_VECTOR
            part = self._combine(tmp, 1.0, tmp, -alpha[j], Y[j], _NO_VECTOR, 1.0, nxt)
            if preconditioned:
                rtmp -= alpha[j] * self.RY[j]
        part = self._initial(tmp, gamma, Y[order[-1]], rtmp)
        for k, j in enumerate(order[::-1]):  # oldest first
            beta = rho[j] * part
            nxt = Y[order[-2 - k]] if k + 1 < len(order) else g
            part = self._combine(q, 1.0, q, alpha[j] - beta, S[j], _NO_VECTOR, 1.0, nxt)
        return part

    def _store_pair(self, t: float, g_new: np.ndarray) -> None:
        """Store ``s = t q``, ``y = g_new - g`` (``sp.diag`` is the Hessian bound at the new point).

        With the memory full the oldest pair's slot takes the new pair, so a pair refused for
        its curvature (``s . y <= 0``; none in the relaxations of the samples, the real scans
        and the 0.3M-3M benchmark vessels) leaves one pair fewer until the next."""
        if len(self.slots) == SOLVER.lbfgs_memory:
            slot = self.slots.pop(0)
        else:
            used = set(self.slots)
            slot = next(i for i in range(SOLVER.lbfgs_memory) if i not in used)
        self.kl.pair(self.q, t, g_new, self.g, self.sp.diag, self.S[slot], self.Y[slot], self._part, self._part2)
        sy, yhy = float(np.sum(self._part)), float(np.sum(self._part2))
        if self.precond is not None:  # H0 = D^-1 (in yhy already) + the coarse terms
            self.precond.refresh(self.sp.diag)
            rg_new = self.precond.restrict(g_new.reshape(-1, 2))
            np.subtract(rg_new, self.rg, out=self.RY[slot])
            self.rg = rg_new  # (the new point's: the caller moves there next)
            yhy += self.precond.coarse_norm(self.RY[slot])
        if sy > 1e-300 and yhy > 0.0:
            self.rho[slot], self.yhy[slot] = 1.0 / sy, yhy
            self.slots.append(slot)

    def _smooth_limiting(self, t: float, gd: float) -> tuple[float, float]:
        """Smooth the direction ``q`` at the vertices of the limiting faces (those flagged by
        the step bound ``t``); kept only when it still descends and allows a longer step.
        Returns the step and ``g . q``."""
        sp = self.sp
        verts = sp.ks.flagged_face_vertices(self._limiting, sp.faces, self._seen)
        if not 0 < len(verts) <= SOLVER.smooth_max_fraction * sp.n:  # none: the boundary limits the step
            return t, gd
        dx = self.q.reshape(-1, 2)
        before = dx[verts]
        mean = np.empty_like(before)
        for _ in range(SOLVER.smooth_rounds):
            sp.ks.neighbour_means(dx, verts, sp.vf_ptr, sp.vf_tri, sp.faces, mean)
            dx[verts] = mean
        # g . q changed at verts only (no pass over the whole mesh)
        g = self.g.reshape(-1, 2)[verts]
        gd_smooth = gd + float(np.sum(g * (dx[verts] - before)))
        t_smooth = SOLVER.step_fraction * sp.max_step_near(self.x, dx, verts, 1.0 / SOLVER.step_fraction, SOLVER.step_shrink)
        if gd_smooth < 0.0 and t_smooth > t:
            self.smoothed += 1
            return t_smooth, gd_smooth
        dx[verts] = before
        return t, gd

    def run(self, run: _Run, *, max_iter: int, tol: float, hist: list[float]) -> tuple[bool, int]:
        """Up to ``max_iter`` iterations; returns (converged, iterations).

        ``hist`` is the energy history of the relative-change test, extended here.
        """
        sp, kl = self.sp, self.kl
        it = 0
        converged = False
        while it < max_iter:
            gd = self._direction()
            if not gd < 0.0:
                self.slots.clear()
                gd = self._direction()
                if not gd < 0.0:
                    converged = True  # zero gradient
                    break
            dx = self.q.reshape(-1, 2)
            t = SOLVER.step_fraction * sp.max_step(self.x, dx, cap=1.0 / SOLVER.step_fraction, shrink=SOLVER.step_shrink,
                                            limiting=self._limiting)
            if t < 1.0:  # a face or the boundary holds the step below the natural one
                t, gd = self._smooth_limiting(t, gd)
            trial_grad = self.grads[1 - self.cur]
            accepted = False
            for _ in range(50):
                kl.combine(self.trial.reshape(-1), 1.0, self.x.reshape(-1), t, self.q, _NO_VECTOR, 1.0,
                           _NO_VECTOR, self._part)
                En, _es, gn = sp.evaluate(self.trial, out=trial_grad)
                if math.isfinite(En) and En <= self.E + SOLVER.armijo * t * gd:
                    if not self.guard_overlap or sp.overlap(self.trial) == 0:
                        accepted = True
                        break
                    self.contacts += 1
                t *= 0.5
            if not accepted or t == 0.0:
                converged = True  # no descent possible at machine precision
                break
            g_new = gn.reshape(-1)
            self._store_pair(t, g_new)
            self.x, self.trial = self.trial, self.x
            self.cur = 1 - self.cur
            self.E, self.g = En, g_new
            it += 1
            hist.append(En)
            if run.record(En):
                break
            if En == 0.0 or _relative_change(hist, SOLVER.window_lbfgs) < tol:
                converged = True
                break
        return converged, it


def _minimise(sp: _Springs, x: np.ndarray, hier, settings: dict, run: _Run, levels_out: list, notes: list, *,
              level: str = "fine"):
    """The fold-free solve: preconditioned L-BFGS on the whole mesh (``level`` its name in
    ``levels_out``).

    When the start's boundary does not overlap itself, no accepted step lets it: a trial
    point whose boundary segments cross is treated like one of higher energy (the step is
    halved), so the boundary can touch itself but not pass through.
    """
    from potflat.relax.hierarchy import MultilevelPreconditioner

    t0 = time.perf_counter()
    run.level = level
    precond = MultilevelPreconditioner(hier, theta=SOLVER.precond_theta) if hier.levels else None
    solver = _LBFGS(sp, x, precond, guard_overlap=sp.overlap(x) == 0)
    del x
    conv, its = solver.run(run, max_iter=run.max_iter, tol=settings["tol"], hist=[solver.E])
    contacts, smoothed = solver.contacts, solver.smoothed
    if contacts:
        notes.append(f"the boundary touched itself: {contacts} trial steps that would have made it "
                     "overlap were shortened")
    x = solver.x
    del solver
    levels_out.append({"level": run.level, "vertices": sp.n, "iterations": its, "energy": sp.spring_energy(x),
                       "seconds": time.perf_counter() - t0, "boundary_contact": contacts > 0,
                       "smoothed_directions": smoothed})
    return x, conv and not run.stopped


def _dynamics(sp: _Springs, x: np.ndarray, settings: dict, run: _Run, levels_out: list):
    friction = np.where(sp.boundary, settings["friction_boundary"], settings["friction_inside"]).astype(np.float64)
    lam = sp.laplacian_bound()
    dt = 1.9 / math.sqrt(lam) if lam > 0 else 1.0
    v = np.zeros_like(x)
    xo, vo = np.empty_like(x), np.empty_like(x)
    es = np.empty(sp.n)
    t0 = time.perf_counter()
    run.level = "dynamics"
    hist: list[float] = []
    converged = False
    it = 0
    while True:
        sp.ks.dynamics_step(x, v, sp.ptr, sp.nbr, sp.rst, sp.k, sp.relative, ENERGY.length_floor, friction, dt, xo, vo, es)
        x, xo, v, vo = xo, x, vo, v
        it += 1
        e = float(np.sum(es))  # energy before this step
        hist.append(e)
        if not np.isfinite(e):  # NaN or overflowing positions make the energy non-finite
            raise FoldedResultError(f"the paper dynamics diverged at iteration {it} (the spring energy is no longer "
                                    "finite); nothing written: use a fold-free preset (--preset standard; a "
                                    "smaller --stiffness does not help: the step scales with it)")
        if run.record(e):
            break
        if it % SOLVER.window_dynamics == 0 and _relative_change(hist, SOLVER.window_dynamics) < settings["tol"]:
            converged = True
            break
    levels_out.append({"level": "dynamics", "iterations": it, "energy": sp.spring_energy(x),
                           "seconds": time.perf_counter() - t0, "dt": dt})
    return x, converged


def _untangle(sp: _Springs, x: np.ndarray, rounds: int = 200) -> tuple[np.ndarray, int]:
    """Move the vertices of non-positive faces to their edge neighbours' mean until none is left.

    Averages over mesh edges only: the cross springs reach across the winged pair, and
    averaging over them too left 81 of 83 flips of a sea-vase rollout in place (edges only:
    all fixed in 6 rounds).
    Returns the positions and the number of faces that were flipped at the start.
    """
    bad = sp.signed_areas(x) <= 0
    n_bad = int(bad.sum())
    if n_bad == 0:
        return x, 0
    x = x.copy()
    region = np.zeros(sp.n, bool)
    for r in range(rounds):
        bad = sp.signed_areas(x) <= 0
        if not bad.any():
            break
        region[sp.faces[bad].ravel()] = True
        if r % 20 == 19:  # widen the region around persistent tangles
            region[sp.faces[region[sp.faces].any(axis=1)].ravel()] = True
        verts = np.nonzero(region)[0]
        mean = np.empty((len(verts), 2))
        sp.ks.neighbour_means(x, verts, sp.vf_ptr, sp.vf_tri, sp.faces, mean)
        x[verts] = mean
    return x, n_bad


def _fold_free_start(sp: _Springs, x: np.ndarray, n_bad: int, notes: list[str]) -> tuple[np.ndarray, bool]:
    """A fold-free start from a layout ``x`` that untangling left folded: each folded cluster
    re-embedded inside its fixed surroundings (:func:`potflat.mesh.embedding.repair_folds`),
    else Tutte's embedding of the whole mesh (:func:`potflat.mesh.embedding.tutte_embedding`).
    Returns the start and whether it is Tutte's disc (whose orientation is arbitrary).

    Raises
    ------
    FoldedResultError
        When neither gives a fold-free layout (the mesh is not disk-like), with the fix.
    """
    from potflat.mesh.embedding import repair_folds, tutte_embedding

    areas = sp.signed_areas(x)
    if np.abs(areas[areas < 0]).sum() > np.abs(areas[areas > 0]).sum():
        raise FoldedResultError(
            "the rollout is mirrored (most of its area faces the other way): it shows the surface from the wrong "
            "side; nothing written: make it again with potflat rollout (--side inner for a vessel's inside)")
    faces = sp.faces.astype(np.int64)
    y, repaired, left = repair_folds(faces, x)
    if not left:
        notes.append(f"the rollout had {n_bad} flipped or degenerate triangles; untangling left "
                     f"{repaired}, re-embedded inside their surroundings (a harmonic map of each folded cluster)")
        return np.ascontiguousarray(y), False
    disc = tutte_embedding(faces, sp.n)
    if disc is None or (sp.signed_areas(disc) <= 0).any():
        raise FoldedResultError(
            f"the rollout has {left} folded triangles that no fold-free layout of this mesh removes: it is not a "
            "disk (a handle kept with the wall, a closed part, or faces joined at a single edge by three or more); "
            "nothing written: run the rollout without --keep-attachments, or with --band LO HI leaving that part "
            "out (folded.regions[].band in the rollout's JSON: where the folds are, as --band fractions)")
    notes.append(f"the rollout had {n_bad} flipped or degenerate triangles and {left} stayed folded after a local "
                 "repair; relaxed from Tutte's embedding of the whole mesh into a disc, then turned to the rollout's "
                 "orientation")
    return np.ascontiguousarray(disc), True


def _turned_like(x: np.ndarray, reference: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """``x`` (n, 2) rotated and moved (no mirroring) to fit ``reference`` (n, 2) best, each
    vertex counting with ``weight`` (n,): the relaxed layout keeps the rollout's orientation
    (axis vertical, mouth up) however the solver turned it on the way (the energy does not
    care; a weak plain surface lets it drift)."""
    w = weight / weight.sum()
    ca, cb = w @ x, w @ reference
    h = ((x - ca) * w[:, None]).T @ (reference - cb)
    angle = math.atan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    return np.ascontiguousarray((x - ca) @ rot.T + cb)


@dataclass(frozen=True)
class _CoarseStart:
    """A relaxed coarse copy of the rollout and the full mesh's layout following it."""

    result: RelaxResult | None  # None: the copy could not be relaxed fold-free
    uv: np.ndarray | None  # (n, 2) float64: the full mesh's layout following the copy's
    final: bool  # the full mesh only follows (preview at the image's resolution), no iterations on it
    notes: list


def _budget_left(deadline: float) -> float | None:
    """The time budget (s) of a first or coarse solve: what is left before ``deadline``, at
    least ``SOLVER.min_time_budget``; None without a deadline."""
    return None if deadline == np.inf else max(deadline - time.perf_counter(), SOLVER.min_time_budget)


@dataclass(frozen=True)
class _SofterStart:
    """The relaxation at a lower importance contrast, the start of the one at the full contrast."""

    uv: np.ndarray | None  # (n, 2) float64: its layout (None once the full solve has taken it)
    contrast: float
    result: RelaxResult  # without its layout (peak memory)

    def note(self, contrast: float) -> list[str]:
        """The notes of the relaxation at ``contrast`` that started from this one."""
        return [f"relaxed first with plain surface {self.contrast:g}x softer than the painting "
                f"({self.result.iterations} iterations), then {contrast:g}x"] + [
                f"first solve: {note}" for note in self.result.notes]


def _softer_start(flat: FlatMesh, options: RelaxOptions, settings: dict, progress: bool,
                  callback, deadline: float, limit) -> _SofterStart:
    """The relaxation of the full mesh at the lower importance contrast
    :attr:`SOLVER.contrast_start <potflat.relax.parameters.SolverParameters.contrast_start>`,
    from which the higher one is reached (when :func:`_contrast_staged` and no relaxed coarse
    copy takes it)."""
    low = SOLVER.contrast_start
    budget = _budget_left(deadline)
    sub = _relax(flat, replace(options, importance_contrast=low, time_budget=budget, true_scale=False), progress,
                 callback, summaries=False, fine_iterations=SOLVER.contrast_start_iterations, limit=limit)
    return _SofterStart(uv=sub.flat.uv, contrast=low, result=replace(sub, flat=None))


def _contrast_staged(flat: FlatMesh, settings: dict) -> bool:
    """Whether the full importance contrast is reached from a relaxation at the lower
    :attr:`SOLVER.contrast_start <potflat.relax.parameters.SolverParameters.contrast_start>`:
    a painted zone at a higher contrast (else the weights would not change)."""
    return _painted_zone(flat, settings) and settings["importance_contrast"] > SOLVER.contrast_start


def _coarse_start(flat: FlatMesh, options: RelaxOptions, settings: dict, progress: bool,
                  callback, deadline: float, limit) -> _CoarseStart | None:
    """Relax a coarse copy of ``flat`` (grid clusters of its start layout, :mod:`potflat.relax.simplify`).

    With ``simplify_mm`` the cells have that side and the full mesh will only follow the
    coarse result (when the copy has at most ``COARSE.max_fraction`` of the vertices and
    covers ``COARSE.min_coverage`` of them); else,
    for meshes of at least ``COARSE.min_vertices``, the cells hold about
    ``COARSE.cell_vertices`` vertices and the coarse result is the full solve's start.
    None when neither applies; ``result`` None (with a note) when the copy could not be
    relaxed fold-free.
    """
    from potflat.relax.simplify import cell_side, grid_simplification, interpolate

    V, uv = flat.mesh.vertices, flat.uv
    spacing = settings["simplify_mm"]
    simple, final = None, False
    if spacing:  # no more resolution than the image resolves
        simple = grid_simplification(V, uv, spacing / flat.mesh.mm_per_unit)
        final = (COARSE.min_copy <= len(simple.vertices) <= COARSE.max_fraction * len(V)
                 and float(np.mean(interpolate(simple, uv, simple.uv)[1])) >= COARSE.min_coverage)
    if not final:
        if not (settings["coarse_start"] and len(V) >= COARSE.min_vertices):
            return None
        simple = grid_simplification(V, uv, cell_side(uv, COARSE.cell_vertices))
        if len(simple.vertices) < COARSE.min_copy:
            return None
    budget = _budget_left(deadline)
    tagged = None if callback is None else (lambda info: callback({**info, "level": "coarse"}))
    try:
        importance = None
        if flat.importance is not None:  # a coarse vertex is as important as its cluster on average
            count = np.bincount(simple.cluster, minlength=len(simple.vertices))
            importance = np.bincount(simple.cluster, flat.importance, len(simple.vertices)) / np.maximum(count, 1)
        sub = _relax(FlatMesh(Mesh(simple.vertices, simple.faces, units=flat.mesh.units), simple.uv,
                              importance=importance),
                     replace(options, simplify_mm=0.0, time_budget=budget, true_scale=False), progress, tagged,
                     summaries=False, limit=limit)
    except FoldedResultError as exc:
        return _CoarseStart(result=None, uv=None, final=False, notes=[
            f"the {len(simple.vertices)}-vertex coarse copy could not be relaxed fold-free ({exc}); "
            "relaxed the full mesh from the rollout"])
    what = (f"relaxed a coarse copy at {spacing:g} mm resolution ({len(simple.vertices)} vertices); the full mesh "
            "follows it piecewise linearly" if final else
            f"started from a relaxed coarse copy ({len(simple.vertices)} vertices)")
    notes = [what] + [f"coarse copy: {note}" for note in sub.notes]
    return _CoarseStart(result=sub, uv=interpolate(simple, uv, sub.flat.uv)[0], final=final, notes=notes)


def _follow(sp: _Springs, x: np.ndarray, notes: list[str]) -> np.ndarray | None:
    """The full mesh's layout ``x`` following a relaxed coarse copy, untangled and with its
    boundary uncrossed (:func:`_uncross_boundary`); None (with a note) when it cannot be made
    fold-free."""
    x, n_bad = _untangle(sp, x)
    if n_bad:
        notes.append(f"untangled {n_bad} triangles flipped by following the coarse copy")
    folded = bool((sp.signed_areas(x) <= 0).any())
    pairs = np.zeros((0, 2), np.int64) if folded else crossing_pairs(x, sp.boundary_segments)
    if len(pairs):
        x = _uncross_boundary(sp, x, pairs)
        notes.append(f"moved the boundary back where following the coarse copy made it cross itself "
                     f"({len(pairs)} crossing pairs of boundary segments)")
        folded = bool((sp.signed_areas(x) <= 0).any()) or sp.overlap(x) > 0
    if folded:
        notes.append("following the coarse copy folded the full mesh; relaxed the full mesh from the rollout")
        return None
    return x


def _uncross_boundary(sp: _Springs, x: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Move the vertices of crossing boundary segments (``pairs`` (k, 2) of
    ``sp.boundary_segments``, crossing at ``x``) to their edge neighbours' mean, which pulls a
    kinked boundary vertex inside, untangling after each round, until the boundary no longer
    crosses itself or ``COARSE.follow_repair_rounds`` have passed; the moved region widens by
    a ring every ``COARSE.follow_repair_widen`` rounds. Returns the positions (the caller
    checks them)."""
    seg = sp.boundary_segments
    x = x.copy()
    region = np.zeros(sp.n, bool)
    for r in range(COARSE.follow_repair_rounds):
        if not len(pairs):
            break
        region[seg[pairs.ravel()].ravel()] = True
        if r % COARSE.follow_repair_widen == COARSE.follow_repair_widen - 1:
            region[sp.faces[region[sp.faces].any(axis=1)].ravel()] = True
        verts = np.nonzero(region)[0]
        mean = np.empty((len(verts), 2))
        sp.ks.neighbour_means(x, verts, sp.vf_ptr, sp.vf_tri, sp.faces, mean)
        x[verts] = mean
        x, _ = _untangle(sp, x)
        pairs = crossing_pairs(x, seg)
    return x


def _painted_zone(flat: FlatMesh, settings: dict) -> bool:
    """Whether the importance weights set a painted zone apart from plain surface: an
    importance that is not uniform, at a contrast above 1 (a uniform one, painted all over
    or an all-black mask, weighs every vertex alike)."""
    imp = flat.importance
    return imp is not None and settings["importance_contrast"] > 1 and float(imp.min()) < float(imp.max())


def _limit(settings: dict, area: float):
    """The anisotropy limit the settings ask for with the area term's weight ``area``:
    ``"auto"`` (found by a first solve without the area term), a number, or None (no limit)."""
    lim = settings["max_anisotropy"]
    if lim == "auto":
        return "auto" if area > 0 else None
    return float(lim) if math.isfinite(lim) else None


def _importance_weights(importance: np.ndarray, contrast: float) -> np.ndarray:
    """Per-vertex weights from importance (n,) in [0, 1]: ``1 / contrast`` on plain surface,
    1 in the important zone, linear between. Shape (n,) float64."""
    low = 1.0 / contrast
    # exactly 1 where the importance is 1: an all-important mesh is solved as without importance
    return np.ascontiguousarray(np.where(importance >= 1.0, 1.0, low + (1.0 - low) * importance), dtype=np.float64)


def _mean_edge_length(V: np.ndarray, F: np.ndarray) -> float:
    """Mean 3D length of the faces' edges (each face's three edges; shared edges count twice).

    The lengths come from a parallel kernel one block of rows at a time; each block is
    summed by numpy and the block sums are added in order, so the result does not depend on
    the thread count (and equals the former all-numpy computation bit for bit).

    Parameters
    ----------
    V : (n, 3) float64
    F : (m, 3) int64, m > 0
    """
    from potflat.relax._kernels.springs import halfedge_lengths

    blocks = row_blocks(len(F))
    buf = np.empty((blocks[0].stop, 3))
    total = 0.0
    for s in blocks:
        lengths = buf[:s.stop - s.start]
        halfedge_lengths(V, F[s], lengths)
        total += float(lengths.sum())
    return total / (3 * len(F))


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


def _relax(flat: FlatMesh, options: RelaxOptions, progress: bool, callback, *, summaries: bool,
           before: DistortionSummary | None = None,
           fine_iterations: int | None = None, limit="auto") -> RelaxResult:
    """:func:`relax`; without ``summaries`` (a coarse copy, whose layout is all its caller
    reads) the result's distortion summaries are None and its stress is not computed;
    ``before``: the start's summary when the caller has it (with ``summaries`` only);
    ``fine_iterations``: when a coarse copy
    was relaxed, at most this many iterations on ``flat`` itself (a first solve that only
    smooths); ``limit``: the anisotropy limit found by an earlier solve (see :func:`_limit`;
    ``"auto"``: from the settings)."""
    settings = options.resolved()
    V = np.ascontiguousarray(flat.mesh.vertices, dtype=np.float64)
    uv = np.ascontiguousarray(flat.uv, dtype=np.float64)
    F = np.ascontiguousarray(flat.mesh.faces, dtype=np.int64)
    n = len(V)
    if n == 0 or len(F) == 0:
        raise InvalidInputError("the rollout has no faces; nothing to relax (check the rollout stage's output)")
    if not (np.isfinite(V).all() and np.isfinite(uv).all()):
        raise InvalidInputError("the rollout has NaN or infinite coordinates; run the rollout stage again")
    fold_free = settings["solver"] != "dynamics"
    t_start = time.perf_counter()
    deadline = t_start + (settings["time_budget"] or np.inf)

    from potflat._heap import release_free_memory
    from potflat._jit import numba_threads

    # normalised units: lengths / mean 3D edge length, layout centred on its bounding box
    with numba_threads(options.threads):
        unit = _mean_edge_length(V, F)
    if not unit > 0:
        raise InvalidInputError("all edges of the rollout have zero length; check the scan's units and faces")
    # a painted zone takes no area term: the plain surface takes the distortion already, and
    # the area term would trade the painting's shape for its area
    area = settings["area"] if fold_free and not _painted_zone(flat, settings) else 0.0
    if limit == "auto":  # (not passed down by the caller)
        limit = _limit(settings, area) if fold_free else None
    # a coarse copy reaches a higher importance contrast by itself (in turn, its smallest copy
    # relaxes at the lower contrast first), so the full mesh is solved once; without a relaxed
    # copy (a small mesh, or one that could not be relaxed fold-free) the full mesh takes the
    # lower contrast's first solve itself
    coarse = _coarse_start(flat, options, settings, progress, callback, deadline, limit) if fold_free else None
    softer = None
    if fold_free and _contrast_staged(flat, settings) and (coarse is None or coarse.result is None):
        softer = _softer_start(flat, options, settings, progress, callback, deadline, limit)
    if limit == "auto" and softer is not None and softer.result.anisotropy_limit is not None:
        limit = softer.result.anisotropy_limit  # the first solve found it: every later solve uses it
    start = flat if softer is None else flat.replace(uv=softer.uv)
    found = None if coarse is None or coarse.result is None else coarse.result.anisotropy_limit
    if limit == "auto" and found is not None:  # (None: the copy stopped early; this solve finds it)
        limit = found
    notes: list[str] = [] if softer is None else softer.note(settings["importance_contrast"])
    notes += list(coarse.notes) if coarse is not None else []
    if coarse is not None and coarse.result is None:
        coarse = None
    with numba_threads(options.threads):
        lo, hi = bounds(start.uv)
        centre = 0.5 * (lo + hi)
        x_in = (start.uv - centre) / unit
        del start  # the first solve's layout is in x_in now (peak memory)
        if softer is not None:
            softer = replace(softer, uv=None)
        from potflat.relax.hierarchy import GridHierarchy
        from potflat.relax._kernels.springs import faces_in_vertex_order

        # locality-preserving order (Morton curve of the layout) and the preconditioner's grids
        hier = GridHierarchy.build(x_in, min_vertices_per_cell=settings.get("cell_vertices", 8.0))
        order = hier.order
        inverse = np.empty(n, np.int64)
        inverse[order] = np.arange(n)
        Vs = np.take(V, order, axis=0) / unit  # (rows gathered by take: 2-4x faster than indexing)
        # faces in the vertices' order too: the face passes and gathers read nearby memory
        # (2.5M benchmark vessel: an evaluation of the energy and gradient 1.6x faster)
        Fs = faces_in_vertex_order(F, inverse)
        weight = None
        if fold_free and flat.importance is not None and settings["importance_contrast"] > 1:
            weight = _importance_weights(flat.importance[order], settings["importance_contrast"])
        sp = _Springs(Vs, Fs, n, k=settings["stiffness"], relative=settings["weighting"] == "relative",
                      weight=weight, shape=settings["shape"] if fold_free else 0.0,
                      rigidity=settings["rigidity"] if fold_free else 0.0, area=area)
        if limit != "auto":
            sp.set_area_and_limit(area, limit)
        del Vs, Fs, inverse
        x = np.take(x_in, order, axis=0) * (settings["stretch"] if softer is None else 1.0)
        del x_in  # (the rollout's layout, the result's orientation, is formed again after the solve)
        t_follow = time.perf_counter()
        if coarse is not None:
            followed = _follow(sp, np.take((coarse.uv - centre) / unit, order, axis=0), notes)
            if followed is None:
                coarse = None
            else:  # only the copy's result is read from here on (peak memory: the solve comes next)
                x, coarse = followed, replace(coarse, uv=None)
        t_follow = time.perf_counter() - t_follow
        folded_start = None
        if fold_free:
            x, n_bad = _untangle(sp, x)
            if n_bad:
                if (sp.signed_areas(x) <= 0).any():
                    folded_start = x
                    x, from_disc = _fold_free_start(sp, x, n_bad, notes)
                    if not from_disc:
                        folded_start = None
                else:
                    notes.append(f"untangled {n_bad} flipped or degenerate triangles of the rollout before relaxing")
            wrapped = sp.guard_boundary(x)
            if wrapped:
                notes.append(f"{wrapped} boundary vertices already wrap past 2 pi in the start; their angle "
                             "sums are not guarded (the final boundary check still applies)")
        # the setup's freed temporaries back to the system before the solve (the stage's peak;
        # 140 MiB at 3M vertices after a rollout in the same process, whose arrays fill the heap)
        release_free_memory()
        t_setup = time.perf_counter()

        bar = _progress_bar(settings["max_iter"]) if progress else contextlib.nullcontext(None)
        with bar as report:
            levels: list[dict] = []
            prefix = [] if softer is None else list(softer.result.energy_history)
            prefix += [] if coarse is None else list(coarse.result.energy_history)
            # (a first solve without a coarse copy must converge: nothing else moves its plain surface far)
            capped = coarse is not None and fine_iterations is not None and fine_iterations < settings["max_iter"]
            run = _Run((fine_iterations if capped else settings["max_iter"]) + len(prefix), deadline, callback, report)
            run.history.extend(prefix)
            if softer is not None:
                levels.extend({**level, "importance_contrast": softer.contrast} for level in softer.result.levels)
            if coarse is not None:
                levels.extend({**level, "level": level["level"].replace("fine", "coarse")}
                              for level in coarse.result.levels)
            if coarse is not None and coarse.final:
                levels.append({"level": "follow", "vertices": n, "iterations": 0, "energy": sp.spring_energy(x),
                               "seconds": t_follow})
                converged = coarse.result.converged
            elif fold_free and limit == "auto":
                # the energy without the area term first: its anisotropy sets the limit
                sp.set_area_and_limit(0.0, None)
                x, converged = _minimise(sp, x, hier, settings, run, levels, notes, level="fine, shape first")
                limit = None if run.stopped else sp.anisotropy_percentile(np.take(V, order, axis=0), x,
                                                                          ENERGY.limit_percentile)
                if limit is not None and math.isfinite(limit):  # (nan: no face with a rest area)
                    sp.set_area_and_limit(area, limit)
                    x, converged = _minimise(sp, x, hier, settings, run, levels, notes)
                else:
                    limit = None
            elif fold_free:
                x, converged = _minimise(sp, x, hier, settings, run, levels, notes)
            else:
                x, converged = _dynamics(sp, x, settings, run, levels)
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
            start = np.take((uv - centre) / unit, order, axis=0) if folded_start is None else folded_start
            x = _turned_like(x, start, turn)
        del sp, hier  # release the spring system before the distortion summaries (peak memory)
    if fold_free and (flipped or overlap or not finite):
        raise FoldedResultError(
            f"relaxation ended with {flipped} flipped triangles and {overlap} boundary crossings; "
            "nothing written: this is a bug in potflat, please report it with the rollout file")
    if not finite:
        raise FoldedResultError("the paper dynamics diverged (positions no longer finite); nothing written: use a "
                                "fold-free preset (standard)")
    uv_out = np.empty_like(x)
    uv_out[order] = x * unit + centre
    factor = 1.0
    # the 3D side of every figure below, computed once (not at all for a first or coarse solve)
    surface = SurfaceReference(V, F) if settings["true_scale"] or summaries else None
    if settings["true_scale"]:
        factor = true_scale_factor(V, uv_out, F, flat.importance, reference=surface)
        uv_out = centre + (uv_out - centre) * factor
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
        timings={"setup": t_setup - t_start, "solve": t_solve - t_setup, "check": t_check - t_solve,
                 "figures": t_end - t_check, "total": t_end - t_start},
        preset=options.preset,
        levels=tuple(levels),
        settings=settings,
        scale_factor=factor,
        anisotropy_limit=None if limit == "auto" else limit,
        notes=tuple(notes + ([f"stopped by {run.stopped}"] if run.stopped and not (capped and run.stopped == "max_iter")
                             else [])),
        reference=surface if summaries else None,
    )


@contextlib.contextmanager
def _progress_bar(total: int):
    from rich.console import Console
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    with Progress(TextColumn("relax {task.fields[level]}"), BarColumn(), TextColumn("{task.completed} it"),
                  TextColumn("E={task.fields[energy]:.4g}"), TimeElapsedColumn(), transient=True,
                  console=Console(stderr=True)) as prog:
        task = prog.add_task("relax", total=total, level="", energy=float("nan"))

        def report(it: int, energy: float, level: str) -> None:
            prog.update(task, completed=it, energy=energy, level=level)

        yield report
