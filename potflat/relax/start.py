"""The solve's start: untangled, fold-free, with a boundary that does not cross itself,
whether it comes from the rollout or from a relaxed coarse copy the full mesh follows."""
from __future__ import annotations

import math

import numpy as np

from potflat.errors import FoldedResultError, NotADiskError
from potflat.mesh.boundary import crossing_pairs
from potflat.mesh.embedding import repair_folds, signed_areas, tutte_embedding
from potflat.mesh._kernels.topology import incident_faces, neighbour_means
from potflat.relax._kernels.steps import vertex_max_steps
from potflat.relax.energy import SpringSystem
from potflat.relax.parameters import COARSE, ENERGY


def untangle(sp: SpringSystem, x: np.ndarray, rounds: int = 200) -> tuple[np.ndarray, int]:
    """Move the vertices of non-positive faces to their edge neighbours' mean until none is left.

    Averages over mesh edges only: the cross springs reach across the winged pair, and
    averaging over them too left 81 of 83 flips of a sea-vase rollout in place (edges only:
    all fixed in 6 rounds). The tip of an ear (a boundary vertex of one face) is not
    averaged: the mean of its two neighbours lies on the ear's base, which leaves the ear
    with zero area for good, and a small piece apart from the rest (a rollout's trimming
    leaves some) is pulled together into a line; a folded ear is mirrored about its base
    instead (:func:`unfold_ears`).
    Returns the positions and the number of faces that were flipped at the start.
    """
    bad = np.flatnonzero(sp.signed_areas(x) <= 0)
    n_bad = len(bad)
    if n_bad == 0:
        return x, 0
    x = x.copy()
    region = np.zeros(sp.n, bool)
    members = np.zeros(0, np.int64)  # (region's vertices, sorted)
    ear_tip = np.diff(sp.vf_ptr) == 1
    for r in range(rounds):
        members = _joined(region, members, sp.faces[bad])
        if r % 20 == 19:  # widen the region around persistent tangles
            members = _joined(region, members, sp.faces[incident_faces(members, sp.vf_ptr, sp.vf_tri)])
        tip = ear_tip[members]
        verts = members[~tip]
        mean = np.empty((len(verts), 2))
        neighbour_means(x, verts, sp.vf_ptr, sp.vf_tri, sp.faces, mean)
        x[verts] = mean
        unfold_ears(sp, x, members[tip])
        # only the faces around the region's vertices moved, so only they can be flipped
        near = incident_faces(members, sp.vf_ptr, sp.vf_tri)
        bad = near[signed_areas(sp.faces[near], x) <= 0]
        if not len(bad):
            break
    return x, n_bad


def _joined(region: np.ndarray, members: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The vertices of ``faces`` ((k, 3)) added to a region: ``region`` (n,) bool is set for them
    in place; returns its sorted vertices ``members`` (int64) with them."""
    new = np.unique(faces).astype(np.int64)
    new = new[~region[new]]
    if not len(new):
        return members
    region[new] = True
    return np.union1d(members, new)


def check_not_mirrored(sp: SpringSystem, x: np.ndarray) -> None:
    """Refuse a start ``x`` (the rollout's layout, before untangling moves it) whose area
    mostly faces the other way: it shows the surface from the wrong side (every face flipped,
    as pages joined on one edge unroll: nothing is left to turn the result by).

    Raises
    ------
    FoldedResultError
        With the fix.
    """
    areas = sp.signed_areas(x)
    facing, away = areas[areas > 0].sum(), -areas[areas < 0].sum()
    if away > facing:
        raise FoldedResultError(
            "the rollout is mirrored (most of its area faces the other way): it shows the surface from the wrong "
            "side; nothing written: make it again with potflat rollout (--side inner for a vessel's inside)")


def unfold_ears(sp: SpringSystem, x: np.ndarray, tips: np.ndarray) -> None:
    """Mirror every folded ear among ``tips`` (boundary vertices of one face) about its base,
    the line through its other two corners (a tip on that line is moved off it by
    ``ENERGY.ear_lift`` of the base's length); ``x`` (n, 2) is changed in place."""
    if not len(tips):
        return
    face = sp.vf_tri[sp.vf_ptr[tips]]
    corner = np.argmax(sp.faces[face] == tips[:, None], axis=1)
    a = x[sp.faces[face, (corner + 1) % 3]]
    base = x[sp.faces[face, (corner + 2) % 3]] - a
    length = np.linalg.norm(base, axis=1)
    p = x[tips] - a
    fold = (base[:, 0] * p[:, 1] - base[:, 1] * p[:, 0] <= 0) & (length > 0)
    if not fold.any():
        return
    unit = base[fold] / length[fold, None]
    normal = np.stack([-unit[:, 1], unit[:, 0]], axis=1)  # towards the ear's inner side
    along = (p[fold] * unit).sum(axis=1)
    height = np.maximum(-(p[fold] * normal).sum(axis=1), ENERGY.ear_lift * length[fold])
    x[tips[fold]] = a[fold] + along[:, None] * unit + height[:, None] * normal


def fold_free_start(sp: SpringSystem, x: np.ndarray, n_bad: int, notes: list[str]) -> tuple[np.ndarray, bool]:
    """A fold-free start from a layout ``x`` that untangling left folded: each folded cluster
    re-embedded inside its fixed surroundings (:func:`potflat.mesh.embedding.repair_folds`),
    else Tutte's embedding of the whole mesh (:func:`potflat.mesh.embedding.tutte_embedding`).
    Returns the start and whether it is Tutte's disc (whose orientation is arbitrary).

    Raises
    ------
    FoldedResultError
        When the layout is mirrored; :class:`potflat.errors.NotADiskError` when neither gives
        a fold-free layout (the mesh is not disk-like).
    """
    faces = sp.faces.astype(np.int64)
    y, repaired, left = repair_folds(faces, x)
    if not left:
        notes.append(f"the rollout had {n_bad} flipped or degenerate triangles; untangling left "
                     f"{repaired}, re-embedded inside their surroundings (a harmonic map of each folded cluster)")
        return np.ascontiguousarray(y), False
    disc = tutte_embedding(faces, sp.n)
    if disc is None or (sp.signed_areas(disc) <= 0).any():
        raise NotADiskError(
            f"the rollout has {left} folded triangles that no fold-free layout of this mesh removes: it is not a "
            "disk (a handle kept with the wall, a closed part, or faces joined at a single edge by three or more); "
            "nothing written")
    notes.append(f"the rollout had {n_bad} flipped or degenerate triangles and {left} stayed folded after a local "
                 "repair; relaxed from Tutte's embedding of the whole mesh into a disc, then turned to the rollout's "
                 "orientation")
    return np.ascontiguousarray(disc), True


def turned_like(x: np.ndarray, reference: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """``x`` (n, 2) rotated and moved (no mirroring) to fit ``reference`` (n, 2) best, each
    vertex counting with ``weight`` (n,): the relaxed layout keeps the rollout's orientation
    (axis vertical, mouth up) however the solver turned it on the way (the energy does not
    care; a weak plain surface lets it drift)."""
    total = weight.sum()
    w = weight / total if total > 0 else np.full(len(x), 1.0 / len(x))  # nothing counts more: all alike
    ca, cb = w @ x, w @ reference
    h = ((x - ca) * w[:, None]).T @ (reference - cb)
    angle = math.atan2(h[0, 1] - h[1, 0], h[0, 0] + h[1, 1])
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    return np.ascontiguousarray((x - ca) @ rot.T + cb)


def follow(sp: SpringSystem, x: np.ndarray, target: np.ndarray, notes: list[str]) -> np.ndarray | None:
    """The full mesh's layout following a relaxed coarse copy: ``target`` (n, 2), the copy's
    piecewise-linear map of the fold-free start ``x`` (n, 2), untangled; each cluster that
    untangling leaves folded re-embedded in ``x``'s shape inside its surroundings
    (:func:`potflat.mesh.embedding.repair_folds` with ``x`` as the reference, at most
    ``COARSE.follow_reembed_rings`` rings), after each number of untangling rounds in
    ``COARSE.follow_untangle_rounds`` in turn until none is left folded; where that fails,
    approached from ``x`` as near as stays fold-free (:func:`approach`) from the one that
    left the fewest; with its boundary uncrossed (:func:`uncross_boundary`) and unwrapped
    (:func:`unwrap_boundary`). None (with a note) when it cannot be made fold-free and
    uncrossed."""
    best = None
    for rounds in COARSE.follow_untangle_rounds:
        goal, n_bad = untangle(sp, target, rounds=rounds)
        folded = int((sp.signed_areas(goal) <= 0).sum())
        repaired = 0
        if folded:
            goal, repaired, folded = repair_folds(sp.faces, goal, reference=x,
                                                  max_rings=COARSE.follow_reembed_rings)
        if best is None or folded < best[3]:
            best = (goal, n_bad, repaired, folded)
        if not folded:
            break
    goal, n_bad, repaired, folded = best
    if n_bad:
        notes.append(f"untangled {n_bad} triangles flipped by following the coarse copy")
    if repaired:
        notes.append(f"re-embedded {repaired} triangles that untangling left folded inside their surroundings, "
                     "in the start's shape")
    if folded:
        goal, short = approach(sp, x, goal)
        notes.append(f"untangling and re-embedding left {folded} triangles of the followed layout folded; {short} "
                     "vertices around them stop short of it")
        if short > COARSE.approach_most_short * sp.n:
            notes.append(f"more than {100 * COARSE.approach_most_short:g}% of the vertices stop short: relaxed the "
                         "full mesh from the rollout")
            return None
        folded = int((sp.signed_areas(goal) <= 0).sum())
    pairs = np.zeros((0, 2), np.int64) if folded else crossing_pairs(goal, sp.boundary_segments)
    if len(pairs):
        goal = uncross_boundary(sp, goal, pairs)
        notes.append(f"moved the boundary back where following the coarse copy made it cross itself "
                     f"({len(pairs)} crossing pairs of boundary segments)")
        folded = bool((sp.signed_areas(goal) <= 0).any()) or sp.overlap(goal) > 0
    if folded:
        notes.append("following the coarse copy folded the full mesh; relaxed the full mesh from the rollout")
        return None
    return unwrap_boundary(sp, goal, notes, "the followed layout")


def approach(sp: SpringSystem, start: np.ndarray, goal: np.ndarray) -> tuple[np.ndarray, int]:
    """A fold-free layout as near ``goal`` (n, 2, folded somewhere) as the fold-free ``start``
    (n, 2) reaches: ``start``, carried by the orientation-preserving affine map that fits it
    to ``goal`` best, moves towards ``goal`` in ``COARSE.approach_steps`` shares, each vertex
    as far along its share as keeps every face around it above ``COARSE.approach_floor`` of
    its smaller area (aligned start or goal); a vertex whose move still lets a face fall below
    that, or lets the boundary cross itself (when it does not at the start), goes back for
    the round. Every vertex whose faces allow it ends at ``goal``; the
    others (around the folds) stop short. Returns the layout and how many stopped short."""
    y = _aligned(start, goal)
    faces = sp.faces
    a_start, a_goal = sp.signed_areas(y), sp.signed_areas(goal)
    floors = 2.0 * COARSE.approach_floor * np.where(a_goal > 0, np.minimum(a_start, a_goal), a_start)
    del a_start, a_goal
    seg = sp.boundary_segments
    guard = len(crossing_pairs(y, seg, max_pairs=1)) == 0  # the boundary stays uncrossed if it starts so
    active = np.arange(sp.n, dtype=np.int64)
    touched = np.zeros(sp.m, bool)
    for r in range(COARSE.approach_rounds):
        share = 1.0 / max(COARSE.approach_steps - r, 1)
        d = np.zeros_like(y)
        d[active] = (goal[active] - y[active]) * share
        t = np.empty(len(active))
        vertex_max_steps(y, d, faces, sp.vf_ptr, sp.vf_tri, floors, active, t)
        t[t < 1.0] *= COARSE.approach_margin
        prev = y[active]
        y[active] += t[:, None] * d[active]
        row = np.full(sp.n, -1, np.int64)
        row[active] = np.arange(len(active))
        touched[incident_faces(active, sp.vf_ptr, sp.vf_tri)] = True
        near = np.flatnonzero(touched)
        touched[near] = False
        while True:  # a face below its floor, else crossing boundary segments: their moved vertices go back
            low = near[2.0 * signed_areas(faces[near], y) < floors[near]]
            back = _moved(faces[low].ravel(), row, y, prev)
            if guard and not len(back):  # (the crossing test looks at the whole boundary: once the faces hold)
                back = _moved(seg[crossing_pairs(y, seg).ravel()].ravel(), row, y, prev)
            if not len(back):
                break
            y[back] = prev[row[back]]
            t[row[back]] = 0.0
            near = np.unique(incident_faces(back, sp.vf_ptr, sp.vf_tri))
        done = t >= 1.0 if share >= 1.0 else np.zeros(len(active), bool)
        y[active[done]] = goal[active[done]]
        moved = bool((t > 0).any())
        active = active[~done]
        if not len(active) or (share >= 1.0 and not moved):
            break
    return y, len(active)


def _moved(v: np.ndarray, row: np.ndarray, y: np.ndarray, prev: np.ndarray) -> np.ndarray:
    """The vertices among ``v`` that are moving (``row`` (n,) their row in ``prev``, -1: not)
    and are away from their position ``prev`` of the round's start."""
    v = np.unique(v).astype(np.int64)
    v = v[row[v] >= 0]
    return v[(y[v] != prev[row[v]]).any(axis=1)]


def _aligned(x: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """``x`` (n, 2) carried by the affine map that fits it to ``goal`` (n, 2) best (least
    squares), or as it is when that map mirrors or flattens."""
    mx, mg = x.mean(axis=0), goal.mean(axis=0)
    a, *_ = np.linalg.lstsq(x - mx, goal - mg, rcond=None)
    if not np.linalg.det(a) > 0:
        return x.copy()
    return np.ascontiguousarray((x - mx) @ a + mg)


def uncross_boundary(sp: SpringSystem, x: np.ndarray, pairs: np.ndarray) -> np.ndarray:
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
        x = _averaged(sp, x, region, r)
        pairs = crossing_pairs(x, seg)
    return x


def _averaged(sp: SpringSystem, x: np.ndarray, region: np.ndarray, r: int) -> np.ndarray:
    """Round ``r`` of a boundary repair: ``region`` (n,) bool widened by a ring every
    ``COARSE.follow_repair_widen`` rounds (in place), its vertices moved to their edge
    neighbours' mean in ``x`` (n, 2, in place), then untangled. Returns the positions."""
    if r % COARSE.follow_repair_widen == COARSE.follow_repair_widen - 1:
        region[sp.faces[region[sp.faces].any(axis=1)].ravel()] = True
    verts = np.nonzero(region)[0]
    mean = np.empty((len(verts), 2))
    neighbour_means(x, verts, sp.vf_ptr, sp.vf_tri, sp.faces, mean)
    x[verts] = mean
    return untangle(sp, x)[0]


def unwrap_boundary(sp: SpringSystem, x: np.ndarray, notes: list[str], start: str) -> np.ndarray:
    """``x`` (n, 2, fold-free, its boundary uncrossed) with every boundary vertex whose fan
    wraps past ``2 pi`` (:meth:`SpringSystem.wrapped`) unwrapped: those vertices, a ring
    more every ``COARSE.follow_repair_widen`` rounds, move to their edge neighbours' mean,
    untangling after each round, for at most ``COARSE.follow_repair_rounds`` rounds, then the
    boundary is uncrossed where that made it cross itself (:func:`uncross_boundary`). Kept
    (with a note naming ``start``, the layout ``x`` is) when fold-free, uncrossed and with
    fewer such vertices; else ``x``.

    A wrapped fan is a fold of the boundary over its own faces that no crossing test of
    boundary segments sees and no angle-sum barrier guards: the solve's steps that wrap it
    further make boundary segments two apart cross, the line search halves them, and the
    whole solve stalls there before it has converged."""
    wrapped = sp.wrapped(x)
    if not len(wrapped) or sp.overlap(x):
        return x
    y = x.copy()
    region = np.zeros(sp.n, bool)
    left = wrapped
    for r in range(COARSE.follow_repair_rounds):
        region[left] = True
        y = _averaged(sp, y, region, r)
        left = sp.wrapped(y)
        if not len(left):
            break
    pairs = crossing_pairs(y, sp.boundary_segments)
    if len(pairs):
        y = uncross_boundary(sp, y, pairs)
        left = sp.wrapped(y)
    if len(left) >= len(wrapped) or (sp.signed_areas(y) <= 0).any() or sp.overlap(y) > 0:
        return x
    notes.append(f"unwrapped {len(wrapped) - len(left)} boundary vertices whose triangles wrapped past 2 pi in "
                 f"{start} (the boundary folded over itself)")
    return y
