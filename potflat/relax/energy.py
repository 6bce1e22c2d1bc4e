"""The relaxation's energy: the paper's springs (Eq. 1) over every mesh edge and one cross
spring per winged triangle pair, the per-face shape, rigidity and area terms with their
weights (:class:`FaceTermWeights`), and the barriers that keep every triangle unflipped and
the boundary from wrapping over itself (:class:`SpringSystem`). The kernels are
:mod:`potflat.relax._kernels.springs` and :mod:`potflat.relax._kernels.overlap`."""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from potflat.mesh._kernels.geometry import signed_areas_2d
from potflat.mesh._kernels.topology import edge_table, incident_faces, vertex_faces
from potflat.mesh.boundary import corner_angle_sums, crossing_pairs
from potflat.mesh.distortion import (
    face_areas,
    face_distortion,
    row_blocks,
    weighted_percentile,
)
from potflat.relax._kernels import springs as kernels_springs
from potflat.relax._kernels.overlap import contact_barrier, contact_max_step, contact_pair_steps
from potflat.relax._kernels.springs import (
    BLOCK,
    boundary_angle_sums,
    build_csr,
    cross_rest_lengths,
    edge_springs,
    energy_gradient,
    face_barrier,
    face_terms,
    shape_coefficients,
)
from potflat.relax._kernels.steps import (
    boundary_max_step,
    boundary_vertex_steps,
    face_steps,
    max_step,
    max_step_of,
)
from potflat.relax.parameters import ENERGY, SOLVER


@dataclass(frozen=True)
class FaceTermWeights:
    """Weights of the per-face terms per unit rest area (a triangle of mean rest area weighs
    each against its springs), and the anisotropy limit.

    Attributes
    ----------
    shape : float
        The shape term's (symmetric anisotropy energy).
    rigidity : float
        The rigidity term's (as-rigid-as-possible energy).
    area : float
        The area term's (area change in proportion).
    limit : float
        The anisotropy limit's price (``ENERGY.limit_mu`` when a limit is set, else 0).
    limit_u : float
        The limit as ``u(limit) = sqrt(limit) - 1 / sqrt(limit)``; inf: none.
    area_eps : float
        The area term's smoothing at zero log area ratio.
    """

    shape: float = 0.0
    rigidity: float = 0.0
    area: float = 0.0
    limit: float = 0.0
    limit_u: float = math.inf
    area_eps: float = ENERGY.area_eps


def mesh_springs(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The springs of a triangle mesh: every edge once and a cross spring over every winged
    triangle pair, and its boundary edges.

    Parameters
    ----------
    faces : (m, 3) int32 or int64
    n : int
        Number of vertices.

    Returns
    -------
    edges : (e, 2) int64
        Each undirected edge once, ``i <= j``, sorted.
    cross : (c, 4) int64
        ``(p, q, a, b)``: the cross spring ``p-q`` over the edge ``a -> b``
        (:func:`potflat.relax._kernels.springs.edge_springs`).
    boundary : (b, 2) int64
        The edges of one face only, oriented as in their face.
    """
    _, edges, count, halves = edge_table(np.ascontiguousarray(faces, dtype=np.int64), n)
    cross, boundary = edge_springs(faces, count, halves)
    return edges, cross, boundary


_NO_FLAGS = np.empty(0, bool)


_NO_WEIGHTS = np.empty(0)


_NO_SHAPE = np.empty((0, 5))


class SpringSystem:
    """Spring system and triangles of a mesh in normalised, Morton-sorted form."""

    def __init__(self, V: np.ndarray, faces: np.ndarray, n: int, *, k: float, relative: bool,
                 weight: np.ndarray | None = None, shape: float = 0.0, rigidity: float = 0.0,
                 area: float = 0.0):
        """``V`` (n, 3) rest positions and ``faces`` (m, 3) in normalised units; ``weight``
        (n,) the vertices' importance weights (None: all 1), ``shape``, ``rigidity`` and
        ``area`` the per-face terms' weights (0: none); no anisotropy limit until
        :meth:`set_area_and_limit` sets one."""
        self.vf_ptr, self.vf_tri = vertex_faces(n, faces)
        edges, cross, self.boundary_segments = mesh_springs(faces, n)
        self.ptr, self.nbr, self.rst = build_csr(V, edges, cross, cross_rest_lengths(V, cross))
        del edges, cross  # peak memory: the spring lists are only needed for the CSR
        areas = face_areas(V, faces)
        self.a_ref = np.maximum(areas, ENERGY.area_floor)
        self.faces = np.ascontiguousarray(faces, dtype=np.int32)  # half the memory traffic
        self.weight = _NO_WEIGHTS if weight is None else np.ascontiguousarray(weight, dtype=np.float64)
        self.rest_shape = _NO_SHAPE
        self.weights = FaceTermWeights(shape=shape, rigidity=rigidity)
        if (shape > 0 or rigidity > 0 or area > 0) and len(faces):
            self.rest_shape = np.empty((len(faces), 5))
            shape_coefficients(V, self.faces, self.weight, 1.0 / float(np.mean(areas)), ENERGY.area_floor,
                                  self.rest_shape)
        self.set_area_and_limit(area, None)
        del areas
        self.k, self.relative = float(k), bool(relative)
        self.n, self.m = n, len(faces)
        self.n_springs = len(self.nbr) // 2
        self.boundary = np.zeros(n, bool)
        self.boundary[self.boundary_segments.ravel()] = True
        self.isolated = np.diff(self.vf_ptr) == 0
        self.bprev, self.bnext = boundary_neighbours(self.boundary_segments, n)
        # boundary vertices on a simple boundary path (the angle terms' vertices)
        self.simple_boundary = (self.bprev >= 0) & (self.bnext >= 0) & (self.bprev != self.bnext)
        # the outline term's angle sums: the surface's, short of the angle barrier's reach
        self.outline_target = np.minimum(corner_angle_sums(V, self.faces, self.simple_boundary),
                                         2.0 * math.pi - ENERGY.boundary_gap)
        self.outline_mu = ENERGY.outline_mu
        self.bguard = np.zeros(n, bool)  # set by guard_boundary()
        self.fixed: np.ndarray | None = None  # (n,) bool: vertices held in place (zero gradient); None: none
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
        self._blocks = np.empty(max(1, -(-self.m // BLOCK)))
        self._below = np.zeros(len(self._blocks), np.int64)  # faces near the barrier per block
        self._coef = np.empty((len(self.rest_shape), 4))  # the per-face terms' gradient coefficients
        self._e_face = np.zeros(len(self._blocks))  # and their energy per block

    def set_area_and_limit(self, area: float, limit: float | None) -> None:
        """Set the area term's weight and the anisotropy limit (None: none). Without per-face
        coefficients (no shape, rigidity or area term at construction) there is neither."""
        shaped = len(self.rest_shape) > 0
        self.weights = replace(self.weights, area=area if shaped else 0.0,
                               limit=ENERGY.limit_mu if limit is not None and shaped else 0.0,
                               limit_u=math.sqrt(limit) - 1.0 / math.sqrt(limit) if limit is not None else math.inf)

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
        cand, ok = self._angle_sums_below(x)
        self.bverts = np.ascontiguousarray(cand[ok])
        self.bguard = np.zeros(self.n, bool)
        self.bguard[self.bverts] = True
        self._bblocks = np.empty(max(1, -(-len(self.bverts) // BLOCK)))
        self.contact = len(self.boundary_segments) >= 3 and self.overlap(x) == 0
        return int((~ok).sum())

    def wrapped(self, x: np.ndarray) -> np.ndarray:
        """The boundary vertices whose fan wraps past ``2 pi`` at ``x`` (their boundary folds over
        its own faces, which the crossing test of boundary segments does not see), (k,) int64."""
        cand, ok = self._angle_sums_below(x)
        return cand[~ok]

    def _angle_sums_below(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The boundary vertices on a simple boundary path, (k,) int64, and whether their angle
        sum at ``x`` is below ``2 pi`` (k,) bool."""
        cand = np.flatnonzero(self.simple_boundary)
        theta = np.zeros(self.n)
        if len(cand):
            boundary_angle_sums(x, cand, self.vf_ptr, self.vf_tri, self.faces, theta)
        return cand, theta[cand] < 2.0 * math.pi - SOLVER.boundary_angle_slack

    def evaluate(self, x: np.ndarray, *, barrier: bool = True, outline: bool = True,
                 out: np.ndarray | None = None) -> tuple[float, float, np.ndarray]:
        """Total energy, elastic energy (springs and shape term) and gradient at ``x``
        (written into ``out`` (n, 2) when given, else a fresh array; zero at the ``fixed``
        vertices). Also sets ``diag``, the Hessian diagonal bound at ``x``. The outline term
        counts with the barriers, unless ``outline`` is False."""
        g = np.empty((self.n, 2)) if out is None else out
        w = self.weights
        face_terms(x, self.faces, self.a_ref, ENERGY.barrier_eps, self.rest_shape, w.shape, w.rigidity, w.area,
                           w.limit, w.limit_u, w.area_eps, self._areas,
                           self._below, self._coef, self._e_face)
        if barrier and len(self.bverts):
            boundary_angle_sums(x, self.bverts, self.vf_ptr, self.vf_tri, self.faces, self.theta)
        energy_gradient(x, self.ptr, self.nbr, self.rst, self.k, self.relative, ENERGY.length_floor,
                                self.weight, self.vf_ptr, self.vf_tri, self.faces,
                                self.rest_shape, self._coef, self.bprev, self.bnext, self.bguard, self.theta,
                                self.outline_target, ENERGY.boundary_mu if barrier else 0.0,
                                self.outline_mu if barrier and outline else 0.0, ENERGY.boundary_gap, g, self._es, self._eb,
                                self.diag)
        es = float(np.sum(self._es)) + float(np.sum(self._e_face))  # (zeros without per-face terms)
        if not barrier:
            return es, es, self._held(g)
        eb = float(np.sum(self._eb))
        ef = face_barrier(x, self.faces, self._areas, self.a_ref, ENERGY.barrier_mu, self.k, ENERGY.barrier_eps,
                                  self.relative, self.weight, g, self.diag, self._below)
        return es + eb + ef + self._contact_barrier(x, g), es, self._held(g)

    def _contact_barrier(self, x: np.ndarray, g: np.ndarray) -> float:
        """The contact barrier's energy at ``x`` while it is on (else 0); its gradient and
        Hessian bound are added to ``g`` (n, 2) and :attr:`diag`."""
        if not self.contact:
            return 0.0
        return contact_barrier(x, self.boundary_segments, self.bprev, self.bnext, ENERGY.contact_gap,
                               ENERGY.contact_mu * self.k, self._contact_cell, self.weight, g, self.diag)

    def _contact_step(self, x: np.ndarray, d: np.ndarray, t: float, shrink: float) -> float:
        """``t`` limited by the boundary pairs of the contact barrier while it is on."""
        if not self.contact:
            return t
        return contact_max_step(x, d, self.boundary_segments, self.bprev, self.bnext, ENERGY.contact_gap,
                                self._contact_cell, t, shrink)

    def _contact_limits(self, x: np.ndarray, d: np.ndarray, cap: float, shrink: float) -> tuple[np.ndarray, np.ndarray]:
        """The contact part of :meth:`boundary_limits` (none while the contact barrier is off)."""
        if not self.contact:
            return np.empty((0, 3), np.int64), np.empty(0)
        return contact_pair_steps(x, d, self.boundary_segments, self.bprev, self.bnext, ENERGY.contact_gap,
                                  self._contact_cell, float(cap), float(shrink))

    def _held(self, g: np.ndarray) -> np.ndarray:
        """``g`` (n, 2) with the rows of the :attr:`fixed` vertices set to zero."""
        if self.fixed is not None:
            g[self.fixed] = 0.0
        return g

    def spring_energy(self, x: np.ndarray) -> float:
        """Elastic energy without the barriers: the springs (Eq. 1 with the 1/2 per spring,
        importance-weighted) plus the shape term."""
        return self.evaluate(x, barrier=False)[1]

    def max_face_step(self, x: np.ndarray, d: np.ndarray, cap: float = np.inf, shrink: float = 1.0,
                      limiting: np.ndarray | None = None) -> float:
        """Largest ``t`` (at most ``cap``) keeping every face of ``x + t d`` above ``1 - shrink``
        of its area at ``x`` (``shrink = 1``: positively oriented); :meth:`boundary_step` adds
        the boundary's bounds. With ``limiting`` ((m,) bool) also flag the faces whose own bound
        is below ``cap``."""
        if self.m == 0:
            return cap
        max_step(x, d, self.faces, float(cap), float(shrink), self._blocks,
                         _NO_FLAGS if limiting is None else limiting)
        return float(self._blocks.min())

    def max_face_step_near(self, x: np.ndarray, d: np.ndarray, verts: np.ndarray, cap: float, shrink: float) -> float:
        """:meth:`max_face_step` for a direction ``d`` changed at ``verts`` only, from one for
        which no face away from them was limiting (its bound was at least ``cap``): only the
        faces around ``verts`` are tested."""
        faces = incident_faces(verts, self.vf_ptr, self.vf_tri)
        return max_step_of(x, d, self.faces, faces, float(cap), float(shrink))

    def face_limits(self, x: np.ndarray, d: np.ndarray, verts: np.ndarray, cap: float,
                    shrink: float) -> tuple[np.ndarray, np.ndarray]:
        """The faces around ``verts`` whose own bound of :meth:`max_face_step` along ``d`` is
        below ``cap``: their vertices, (k, 3) int64, and their bounds, (k,) float64. Moving a
        face's three vertices by ``s d`` instead moves its bound to ``t / s``."""
        faces = np.unique(incident_faces(verts, self.vf_ptr, self.vf_tri))
        own = np.empty(len(faces))
        face_steps(x, d, self.faces, faces, float(cap), float(shrink), own)
        held = own < cap
        return self.faces[faces[held]].astype(np.int64), own[held]

    def boundary_step(self, x: np.ndarray, d: np.ndarray, t: float, shrink: float) -> float:
        """``t`` limited by the guarded boundary vertices' angle sums along ``x + t d`` and, while
        the contact barrier is on, by the boundary pairs it acts on (each may lose at most
        ``shrink`` of its distance, as a face of its area)."""
        if len(self.bverts):
            boundary_max_step(x, d, self.bverts, self.bprev, self.bnext, self._bblocks)
            t = min(t, float(self._bblocks.min()))
        return self._contact_step(x, d, t, shrink)

    def boundary_limits(self, x: np.ndarray, d: np.ndarray, cap: float, shrink: float) -> tuple[np.ndarray, np.ndarray]:
        """The boundary's constraints of :meth:`boundary_step` that hold a step along ``d`` below
        ``cap``: each one's three vertices, (k, 3) int64 (a guarded vertex and its boundary
        neighbours; a boundary vertex and the segment it nears), and its bound, (k,) float64.
        Moving a constraint's three vertices by ``s d`` instead moves its bound to ``t / s``."""
        trios, bounds = [np.empty((0, 3), np.int64)], [np.empty(0)]
        if len(self.bverts):
            own = np.empty(len(self.bverts))
            boundary_vertex_steps(x, d, self.bverts, self.bprev, self.bnext, own)
            held = own < cap
            b = self.bverts[held]
            trios.append(np.stack([b, self.bprev[b], self.bnext[b]], axis=1).astype(np.int64))
            bounds.append(own[held])
        trio, bound = self._contact_limits(x, d, cap, shrink)
        trios.append(trio)
        bounds.append(bound)
        return np.concatenate(trios), np.concatenate(bounds)

    def signed_areas(self, x: np.ndarray) -> np.ndarray:
        """Signed area of every face at ``x``, shape (m,)."""
        out = np.empty(self.m)
        signed_areas_2d(np.ascontiguousarray(x, dtype=np.float64), self.faces, out)
        return out

    def overlap(self, x: np.ndarray, max_pairs: int = 1000) -> int:
        """Crossing pairs of boundary segments at ``x`` (counting stops at ``max_pairs``)."""
        return len(crossing_pairs(x, self.boundary_segments, max_pairs=max_pairs))

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


def boundary_neighbours(segments: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Each vertex's boundary predecessor and successor along the faces' orientation.

    Parameters
    ----------
    segments : (b, 2) int64
        Boundary half-edges ``a -> b`` oriented as in their faces
        (:func:`potflat.relax._kernels.springs.edge_springs`).

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


def importance_weights(importance: np.ndarray, contrast: float) -> np.ndarray:
    """Per-vertex weights from importance (n,) in [0, 1]: ``1 / contrast`` on plain surface,
    1 in the important zone, linear between. Shape (n,) float64."""
    low = 1.0 / contrast
    # exactly 1 where the importance is 1: an all-important mesh is solved as without importance
    return np.ascontiguousarray(np.where(importance >= 1.0, 1.0, low + (1.0 - low) * importance), dtype=np.float64)


def mean_edge_length(V: np.ndarray, F: np.ndarray) -> float:
    """Mean 3D length of the faces' edges (each face's three edges; shared edges count twice).

    The lengths come from a parallel kernel one block of rows at a time; each block is
    summed by numpy and the block sums are added in order, so the result does not depend on
    the thread count (and equals the former all-numpy computation bit for bit).

    Parameters
    ----------
    V : (n, 3) float64
    F : (m, 3) int64, m > 0
    """
    blocks = row_blocks(len(F))
    buf = np.empty((blocks[0].stop, 3))
    total = 0.0
    for s in blocks:
        lengths = buf[:s.stop - s.start]
        kernels_springs.halfedge_lengths(V, F[s], lengths)
        total += float(lengths.sum())
    return total / (3 * len(F))
