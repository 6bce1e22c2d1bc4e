"""Relax the extreme faces of a followed start locally, the rest of the layout fixed.

Following a relaxed coarse copy leaves a few faces far more anisotropic than the limit (scan
facets the copy's piecewise-linear map cannot undo, and what untangling and re-embedding moved,
mostly along the boundary): in the 1M-vertex copies of the shared real scans they hold most of
the followed start's energy, and the full mesh's solve spends most of its iterations pushing
them. :func:`relax_extremes` solves those patches alone first, every other vertex fixed.
"""
from __future__ import annotations

import math

import numpy as np

from potflat.mesh.distortion import face_distortion
from potflat.relax._kernels.overlap import contact_barrier, contact_max_step, contact_pair_steps
from potflat.relax.control import RunControl
from potflat.relax.energy import SpringSystem
from potflat.relax.lbfgs import LBFGS
from potflat.relax.parameters import COARSE, ENERGY

#: Faces whose anisotropy is computed at once (bounds the temporaries of the 3D frames).
_FACES_PER_PASS = 1 << 20


class _Patch(SpringSystem):
    """The spring system of some faces of a mesh's (``whole``), with the per-face terms,
    weights and limit of ``whole`` and the vertices not ``free`` :attr:`fixed`; its overlap and
    contact barrier are those of ``whole``'s boundary in ``layout`` with the patch's vertices
    moved (a patch's own boundary runs through the mesh and misses the boundary segments
    around it that its vertices can come near)."""

    def __init__(self, whole: SpringSystem, V: np.ndarray, faces: np.ndarray, vertices: np.ndarray,
                 free: np.ndarray, layout: np.ndarray):
        local = np.full(whole.n, -1, np.int64)
        local[vertices] = np.arange(len(vertices))
        weight = whole.weight[vertices] if len(whole.weight) else None
        super().__init__(np.ascontiguousarray(V[vertices]), local[whole.faces[faces]], len(vertices), k=whole.k,
                         relative=whole.relative, weight=weight, shape=whole.weights.shape,
                         rigidity=whole.weights.rigidity, area=whole.weights.area)
        if len(whole.rest_shape):  # (normalised by the whole mesh's mean face area, not the patch's)
            self.rest_shape = np.ascontiguousarray(whole.rest_shape[faces])
        self.a_ref = np.ascontiguousarray(whole.a_ref[faces])
        self.weights = whole.weights
        self.fixed = ~free[vertices]
        self.outline_mu = 0.0  # (the patch's boundary runs through the mesh: no outline there)
        self.whole, self.vertices, self.layout = whole, vertices, layout
        # the whole boundary, its vertices numbered apart: rows of it in the patch, and their patch vertices
        on = np.flatnonzero(whole.boundary)
        row = np.full(whole.n, -1, np.int64)
        row[on] = np.arange(len(on))
        self._seg = np.ascontiguousarray(row[whole.boundary_segments])
        self._prev = np.where(whole.bprev[on] >= 0, row[whole.bprev[on]], -1).astype(whole.bprev.dtype)
        self._next = np.where(whole.bnext[on] >= 0, row[whole.bnext[on]], -1).astype(whole.bnext.dtype)
        self._weight = whole.weight[on] if len(whole.weight) else whole.weight
        self._at = np.ascontiguousarray(layout[on])
        self._rows = np.flatnonzero(local[on] >= 0)
        self._mine = local[on][self._rows]

    def _contact_barrier(self, x: np.ndarray, g: np.ndarray) -> float:
        if not self.whole.contact:
            return 0.0
        self._at[self._rows] = x[self._mine]
        grad, diag = np.zeros_like(self._at), np.zeros(len(self._at))
        energy = contact_barrier(self._at, self._seg, self._prev, self._next, ENERGY.contact_gap,
                                 ENERGY.contact_mu * self.whole.k, self.whole._contact_cell, self._weight, grad, diag)
        g[self._mine] += grad[self._rows]
        self.diag[self._mine] += diag[self._rows]
        return energy

    def _contact_step(self, x: np.ndarray, d: np.ndarray, t: float, shrink: float) -> float:
        if not self.whole.contact:
            return t
        self._at[self._rows] = x[self._mine]
        along = np.zeros_like(self._at)
        along[self._rows] = d[self._mine]
        return contact_max_step(self._at, along, self._seg, self._prev, self._next, ENERGY.contact_gap,
                                self.whole._contact_cell, t, shrink)

    def _contact_limits(self, x: np.ndarray, d: np.ndarray, cap: float, shrink: float) -> tuple[np.ndarray, np.ndarray]:
        """The whole boundary's pairs, their vertices outside the patch (fixed) given as -1."""
        if not self.whole.contact:
            return np.empty((0, 3), np.int64), np.empty(0)
        self._at[self._rows] = x[self._mine]
        along = np.zeros_like(self._at)
        along[self._rows] = d[self._mine]
        trio, bound = contact_pair_steps(self._at, along, self._seg, self._prev, self._next, ENERGY.contact_gap,
                                         self.whole._contact_cell, float(cap), float(shrink))
        patch_of_row = np.full(len(self._at), -1, np.int64)
        patch_of_row[self._rows] = self._mine
        return patch_of_row[trio], bound

    def overlap(self, x: np.ndarray, max_pairs: int = 1000) -> int:
        self.layout[self.vertices] = x
        return self.whole.overlap(self.layout, max_pairs)


def relax_extremes(sp: SpringSystem, x: np.ndarray, V: np.ndarray, notes: list[str], *,
                   deadline: float = math.inf) -> np.ndarray:
    """``x`` (n, 2) with its patches of extreme faces relaxed, every other vertex fixed.

    The faces whose anisotropy in ``x`` exceeds ``COARSE.local_anisotropy``, grown by
    ``COARSE.local_rings`` rings of vertices, are relaxed by L-BFGS (Jacobi preconditioned,
    at most ``COARSE.local_iterations`` iterations, tolerance ``COARSE.local_tol``) with the
    energy of ``sp``; a boundary vertex of the mesh keeps all its faces in the patch, so its
    angle sum stays guarded, the contact barrier acts between the whole mesh's boundary
    segments, and the line search rejects steps that make the whole mesh's boundary overlap
    (when it did not). Kept (with a note) when fold-free and of lower energy than ``x``.

    Parameters
    ----------
    sp : SpringSystem
        The mesh's spring system, its anisotropy limit set.
    x : (n, 2) float64
        A fold-free layout (the solver's frame).
    V : (n, 3) float64
        Rest positions as ``sp`` was built from them (its vertex order and units).
    notes : list of str
        Appended to when the patches are relaxed.
    deadline : float
        ``time.perf_counter()`` at which the patches' solve stops (the relaxation's time budget).

    Returns
    -------
    (n, 2) float64
        The layout; ``x`` itself when no face is extreme or the relaxed layout is not kept.
    """
    faces = sp.faces
    extreme = np.empty(len(faces), bool)
    for lo in range(0, len(faces), _FACES_PER_PASS):  # (in passes: all faces' figures at once set the stage's peak)
        part = faces[lo:lo + _FACES_PER_PASS].astype(np.int64)
        extreme[lo:lo + len(part)] = face_distortion(V, x, part).anisotropy > COARSE.local_anisotropy
    if not extreme.any():
        return x
    free = np.zeros(sp.n, bool)
    free[faces[extreme].ravel()] = True
    for _ in range(COARSE.local_rings):
        free[faces[free[faces].any(axis=1)].ravel()] = True
    patch_faces = free[faces].any(axis=1)
    touched_boundary = np.zeros(sp.n, bool)
    touched_boundary[faces[patch_faces].ravel()] = True
    touched_boundary &= sp.boundary
    patch_faces |= touched_boundary[faces].any(axis=1)
    patch_faces = np.flatnonzero(patch_faces)
    vertices = np.unique(faces[patch_faces].ravel()).astype(np.int64)
    patch = _Patch(sp, V, patch_faces, vertices, free, x.copy())
    start = np.ascontiguousarray(x[vertices])
    patch.guard_boundary(start)
    solver = LBFGS(patch, start, None, guard_overlap=sp.overlap(x) == 0)
    run = RunControl(COARSE.local_iterations, deadline, None, None)
    _, iterations = solver.run(run, max_iter=COARSE.local_iterations, tol=COARSE.local_tol, hist=[solver.E])
    relaxed = x.copy()
    relaxed[vertices] = solver.x
    if (sp.signed_areas(relaxed) <= 0).any() or not sp.evaluate(relaxed)[0] < sp.evaluate(x)[0]:
        return x
    notes.append(f"relaxed the {int(extreme.sum())} triangles of the followed start with anisotropy above "
                 f"{COARSE.local_anisotropy:g} and {int(free.sum()) - len(np.unique(faces[extreme]))} vertices "
                 f"around them, the rest fixed, in {iterations} iterations")
    return relaxed
