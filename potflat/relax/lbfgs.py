"""The fold-free solver: preconditioned L-BFGS with a flip-free, monotone line search."""
from __future__ import annotations

import math
import time

import numpy as np

from potflat.mesh._kernels.topology import flagged_face_vertices, neighbour_means
from potflat.relax._kernels import lbfgs as kernels_lbfgs
from potflat.relax._kernels.steps import ease_scales
from potflat.relax.control import RunControl, relative_change
from potflat.relax.energy import SpringSystem
from potflat.relax.hierarchy import GridHierarchy, MultilevelPreconditioner
from potflat.relax.parameters import SOLVER
from potflat.relax.result import LevelRecord

_NO_VECTOR = np.empty(0)


class LBFGS:
    """Preconditioned L-BFGS with a flip-free, monotone line search.

    The initial inverse Hessian is ``H0 = D^-1 + coarse terms``: the inverse of the
    Hessian's diagonal bound at the current state (Jacobi, so a squeezed triangle's stiff
    barrier does not shrink everybody's step) plus the additive multilevel correction of
    :class:`potflat.relax.hierarchy.MultilevelPreconditioner` (smooth, long-range moves in one
    step), scaled by ``s.y / y.H0.y`` of the newest pair. With ``guard_overlap`` a trial point
    whose boundary overlaps itself is rejected like one of higher energy. The vector algebra
    runs in fused in-place passes (:mod:`potflat.relax._kernels.lbfgs`) over preallocated buffers.

    The start ``x`` ((n, 2) float64) becomes the solver's first position buffer when it is
    float64 and C-contiguous, not a copy (at 3M vertices 46 MB): the iterations overwrite it.

    Attributes
    ----------
    x : (n, 2) float64
        Current positions (``trial``: the line search's).
    """

    def __init__(self, sp: SpringSystem, x: np.ndarray, precond=None, *, guard_overlap: bool = False):
        kl = kernels_lbfgs
        self.kl, self.sp, self.precond = kl, sp, precond
        self.guard_overlap = guard_overlap
        self.contacts = 0  # trial points rejected because the boundary would overlap
        self.smoothed = 0  # directions smoothed at the vertices of limiting faces
        self.eased = 0  # directions scaled down around the boundary constraints holding the step
        self._scale: np.ndarray | None = None  # work space of the easing, all 1
        self._limiting = np.empty(sp.m, bool)  # faces holding the step below the natural one
        self._seen = np.zeros(sp.n, bool)  # work space of the smoothing
        size = 2 * sp.n
        self.x = np.asarray(x, dtype=np.float64, order="C")  # (taken over: see the class)
        self.trial = np.empty_like(self.x)
        self.grads = [np.empty_like(self.x), np.empty_like(self.x)]
        # one slot per pair kept (at 3M vertices each pair is 96 MB)
        self.S = np.empty((SOLVER.lbfgs_memory, size))
        self.Y = np.empty((SOLVER.lbfgs_memory, size))
        self.rho = np.zeros(SOLVER.lbfgs_memory)
        self.yhy = np.zeros(SOLVER.lbfgs_memory)
        self.slots: list[int] = []  # oldest first
        self.q = np.empty(size)
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
        q, g, S, Y, rho = self.q, self.g, self.S, self.Y, self.rho
        # the recursion's first vector: without a preconditioner H0 is applied to it in place;
        # with one it lives in ``trial`` (free until the line search; at 3M vertices 46 MB)
        tmp = q if self.precond is None else self.trial.reshape(-1)
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

    def _limiting_vertices(self) -> np.ndarray:
        """The vertices of the faces flagged by the faces' step bound (:attr:`_limiting`) that
        are not ``sp.fixed``, (k,) int64."""
        sp = self.sp
        verts = flagged_face_vertices(self._limiting, sp.faces, self._seen)
        return verts if sp.fixed is None else verts[~sp.fixed[verts]]

    def _smooth_limiting(self, t: float, gd: float, verts: np.ndarray) -> tuple[float, float]:
        """Smooth the direction ``q`` at ``verts``, the limiting faces' vertices
        (:meth:`_limiting_vertices`); kept only when it still descends and the faces allow a
        longer step than ``t``.
        Returns the faces' step bound and ``g . q``."""
        sp = self.sp
        if not 0 < len(verts) <= SOLVER.smooth_max_fraction * sp.n:
            return t, gd
        dx = self.q.reshape(-1, 2)
        before = dx[verts]
        mean = np.empty_like(before)
        for _ in range(SOLVER.smooth_rounds):
            neighbour_means(dx, verts, sp.vf_ptr, sp.vf_tri, sp.faces, mean)
            dx[verts] = mean
        # g . q changed at verts only (no pass over the whole mesh)
        g = self.g.reshape(-1, 2)[verts]
        gd_smooth = gd + float(np.sum(g * (dx[verts] - before)))
        t_smooth = sp.max_face_step_near(self.x, dx, verts, 1.0 / SOLVER.step_fraction, SOLVER.step_shrink)
        if gd_smooth < 0.0 and t_smooth > t:
            self.smoothed += 1
            return t_smooth, gd_smooth
        dx[verts] = before
        return t, gd

    def _ease_faces(self, t: float, gd: float, held: np.ndarray) -> tuple[float, float]:
        """Scale the direction ``q`` down around the faces that hold its step ``t`` below the
        natural one (around ``held``, the limiting faces' vertices: :meth:`_limiting_vertices`),
        so the rest of the mesh takes the natural step (:meth:`_ease`; a squeezed sliver
        otherwise holds every vertex's step to a few percent of it). Returns the step bound
        and ``g . q``."""
        sp, shrink, cap = self.sp, SOLVER.step_shrink, 1.0 / SOLVER.step_fraction

        def limits(dx: np.ndarray, lowered: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return sp.face_limits(self.x, dx, np.concatenate([held, lowered]), cap, shrink)

        def bound(dx: np.ndarray, lowered: np.ndarray) -> float:
            return sp.max_face_step_near(self.x, dx, np.concatenate([held, lowered]), cap, shrink)

        return self._ease(t, cap, gd, limits, bound)

    def _ease_boundary(self, t: float, t_faces: float, gd: float) -> tuple[float, float]:
        """Scale the direction ``q`` down around the boundary constraints that hold its step
        ``t`` below the faces' bound ``t_faces``, so the rest of the mesh takes the faces' step
        (:meth:`_ease`). Returns the step bound and ``g . q``."""
        sp, shrink = self.sp, SOLVER.step_shrink

        def limits(dx: np.ndarray, lowered: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            return sp.boundary_limits(self.x, dx, t_faces, shrink)

        def bound(dx: np.ndarray, lowered: np.ndarray) -> float:
            return sp.boundary_step(self.x, dx, sp.max_face_step_near(self.x, dx, lowered, t_faces, shrink), shrink)

        return self._ease(t, t_faces, gd, limits, bound)

    def _ease(self, t: float, target: float, gd: float, limits, bound) -> tuple[float, float]:
        """Scale the direction ``q`` down around the constraints that hold its step ``t`` below
        ``target``: ``limits(dx, lowered)`` gives them (each one's three vertices, (k, 3)
        int64, and its bound, (k,) float64; moving its vertices by ``s dx`` moves its bound to
        ``t / s``), ``bound(dx, lowered)`` the step bound of ``dx`` changed at the vertices
        ``lowered`` (k,) int64.

        Each holding constraint's three vertices move by the share of the step their bound
        allows, and the scale rises back to 1 over a ramp as wide as ``SOLVER.ease_width``
        times the move (:func:`ease_scales`), in up to ``SOLVER.ease_rounds`` rounds (a
        constraint the scaling itself brings closer is eased in the next). Kept when the
        eased direction descends further along its bound (``t g . q`` lower) and concerns at
        most ``SOLVER.smooth_max_fraction`` of the vertices.
        Returns the step bound and ``g . q``."""
        sp = self.sp
        dx = self.q.reshape(-1, 2)
        if self._scale is None:
            self._scale = np.ones(sp.n)
        scale, budget = self._scale, int(SOLVER.smooth_max_fraction * sp.n)
        lowered, before = [], []
        verts = np.empty(0, np.int64)
        t_eased = t
        for _ in range(SOLVER.ease_rounds):
            trios, bounds = limits(dx, verts)
            if not len(bounds):
                break
            values = bounds[:, None] / target * scale[np.maximum(trios, 0)]
            held = trios >= 0  # (a local relaxation's fixed vertices outside it: -1)
            new = ease_scales(self.x, dx, sp.ptr, sp.nbr, trios[held], values[held], target, SOLVER.ease_width,
                              budget, scale)
            lowered.append(new)
            before.append(dx[new])
            budget -= len(new)
            if budget < 0:
                break
            verts = np.concatenate(lowered)
            dx[verts] = np.concatenate(before) * scale[verts, None]
            t_eased = bound(dx, verts)
            if t_eased >= target:
                break
        verts = np.concatenate(lowered) if lowered else np.empty(0, np.int64)
        original = np.concatenate(before) if before else np.empty((0, 2))
        scale[verts] = 1.0
        g = self.g.reshape(-1, 2)[verts]
        gd_eased = gd + float(np.sum(g * (dx[verts] - original)))
        if budget >= 0 and gd_eased < 0.0 and t_eased * gd_eased < t * gd:
            self.eased += 1
            return t_eased, gd_eased
        dx[verts] = original
        return t, gd

    def run(self, run: RunControl, *, max_iter: int, tol: float, hist: list[float]) -> tuple[bool, int]:
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
            t_faces = sp.max_face_step(self.x, dx, cap=1.0 / SOLVER.step_fraction, shrink=SOLVER.step_shrink,
                                       limiting=self._limiting)
            if t_faces < 1.0 / SOLVER.step_fraction:  # faces hold the step below the natural one
                held = self._limiting_vertices()
                t_faces, gd = self._smooth_limiting(t_faces, gd, held)
                if t_faces < SOLVER.ease_face_step:
                    t_faces, gd = self._ease_faces(t_faces, gd, held)
            t = sp.boundary_step(self.x, dx, t_faces, SOLVER.step_shrink)
            if t < t_faces:  # the boundary holds it lower still
                t, gd = self._ease_boundary(t, t_faces, gd)
            t *= SOLVER.step_fraction
            trial_grad = self.grads[1 - self.cur]
            accepted = False
            for _ in range(50):
                kl.combine(self.trial.reshape(-1), 1.0, self.x.reshape(-1), t, self.q, _NO_VECTOR, 1.0,
                           _NO_VECTOR, self._part)
                if self.guard_overlap and sp.overlap(self.trial, max_pairs=1):  # (first: far cheaper than the energy)
                    self.contacts += 1
                    t *= 0.5
                    continue
                En, _es, gn = sp.evaluate(self.trial, out=trial_grad)
                if math.isfinite(En) and En <= self.E + SOLVER.armijo * t * gd:
                    accepted = True
                    break
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
            if En == 0.0 or relative_change(hist, SOLVER.window_lbfgs) < tol:
                converged = True
                break
        return converged, it


def minimise(sp: SpringSystem, x: np.ndarray, hier: GridHierarchy, *, tol: float, run: RunControl,
             notes: list[str], level: str = "fine") -> tuple[np.ndarray, bool, LevelRecord]:
    """The fold-free solve: preconditioned L-BFGS on the whole mesh from ``x`` (n, 2) until the
    relative energy change falls below ``tol`` or ``run`` stops it. ``x`` is overwritten (the
    solver works in it: :class:`LBFGS`).

    When the start's boundary does not overlap itself, no accepted step lets it: a trial
    point whose boundary segments cross is treated like one of higher energy (the step is
    halved), so the boundary can touch itself but not pass through.

    Returns
    -------
    x : (n, 2) float64
        The solved layout.
    converged : bool
    record : LevelRecord
        The level, named ``level``.
    """
    t0 = time.perf_counter()
    run.level = level
    precond = MultilevelPreconditioner(hier, theta=SOLVER.precond_theta) if hier.levels else None
    solver = LBFGS(sp, x, precond, guard_overlap=sp.overlap(x) == 0)
    del x  # (the solver's first buffer now)
    conv, its = solver.run(run, max_iter=run.max_iter, tol=tol, hist=[solver.E])
    contacts, smoothed, eased = solver.contacts, solver.smoothed, solver.eased
    if contacts:
        notes.append(f"the boundary touched itself: {contacts} trial steps that would have made it "
                     "overlap were shortened")
    x = solver.x
    del solver
    record = LevelRecord(level=run.level, vertices=sp.n, iterations=its, energy=sp.spring_energy(x),
                         seconds=time.perf_counter() - t0, boundary_contact=contacts > 0, smoothed_directions=smoothed,
                         eased_directions=eased)
    return x, conv and not run.stopped, record
