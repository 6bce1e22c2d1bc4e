"""libigl ARAP from a rollout: the reference flattening the benchmarks compare with."""
from __future__ import annotations

import time

import numpy as np

from potflat.types import FlatMesh

#: ARAP iterations (libigl ``arap_solve``'s ``max_iter``).
ARAP_ITERATIONS = 10


def libigl_arap(flat: FlatMesh, iterations: int = ARAP_ITERATIONS) -> tuple[np.ndarray, float, float]:
    """Flatten with libigl's ARAP (per-triangle energy) from ``flat.uv``.

    ARAP fits rotations, so it needs a start that is not mirrored (a mirrored start folds
    most triangles in the first iteration): a start with negative total signed area is
    mirrored in ``u`` for the solve and the result mirrored back. One vertex of each
    connected piece, and every vertex of no face, is pinned at its start (a piece or a
    vertex without one makes the global system singular: the precomputation or the solve
    fails).

    Parameters
    ----------
    flat : FlatMesh
        ``mesh.vertices`` (n, 3), ``mesh.faces`` (m, 3) and the start ``uv`` (n, 2).
    iterations : int
        Local/global iterations.

    Returns
    -------
    uv : (n, 2) float64
        The ARAP layout.
    precompute : float
        Seconds of ``arap_precomputation``.
    seconds : float
        Seconds in all (precomputation and solve).
    """
    import igl

    V, F = flat.mesh.vertices, flat.mesh.faces
    e1, e2 = flat.uv[F[:, 1]] - flat.uv[F[:, 0]], flat.uv[F[:, 2]] - flat.uv[F[:, 0]]
    mirror = np.array([-1.0, 1.0]) if (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum() < 0 else np.ones(2)
    start = np.ascontiguousarray(flat.uv * mirror)
    t0 = time.perf_counter()
    pinned = _pinned_vertices(F, len(V))
    data = igl.ARAPData()
    data.energy = igl.ARAP_ENERGY_TYPE_ELEMENTS
    data.max_iter = iterations
    igl.arap_precomputation(V, F, 2, pinned.astype(np.int32), data)
    t1 = time.perf_counter()
    uv = igl.arap_solve(start[pinned].copy(), data, start.copy())
    return np.asarray(uv, np.float64) * mirror, t1 - t0, time.perf_counter() - t0


def _pinned_vertices(faces: np.ndarray, n: int) -> np.ndarray:
    """The lowest vertex index of each connected piece of ``faces`` (pieces joined by shared
    vertices) and every vertex of no face, sorted, ``(k,)`` int64."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]]])
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    used = np.zeros(n, bool)
    used[faces.ravel()] = True
    _, first = np.unique(label[used], return_index=True)
    return np.sort(np.concatenate([np.flatnonzero(used)[first], np.flatnonzero(~used)]))
