"""Mesh topology of the relax stage against the plain references in tests/reference.py:
:func:`potflat.relax.energy.mesh_springs` (edges, cross springs, boundary: the edge table and
:func:`potflat.relax._kernels.springs.edge_springs`) on awkward meshes, the spring CSR, the
mean edge length and :func:`potflat.mesh.distortion.unique_edges`; all bit-identical to the
references and for any thread count."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
import reference as ref
from _bench_meshes import meshes

from potflat._jit import numba_threads
from potflat.mesh import distortion
from potflat.relax._kernels import springs as ks
from potflat.relax.energy import mesh_springs


def _fan(k: int) -> tuple[np.ndarray, int]:
    """A closed fan of ``k`` triangles around vertex 0 (valence ``k``, ``2 k`` half-edges
    from it to higher vertices), rim vertices shuffled so that they come unsorted."""
    rim = 1 + np.random.default_rng(k).permutation(k)
    return np.array([[0, rim[t], rim[(t + 1) % k]] for t in range(k)]), k + 1


def _meshes() -> dict[str, tuple[np.ndarray, int]]:
    """Named ``(faces, n)``: the awkward cases, then random triangle soups."""
    vessel = meshes.vessel_rollout(1500, seed=2).mesh
    out = {
        "no faces": (np.zeros((0, 3), np.int64), 3),
        "one triangle": (np.array([[0, 1, 2]]), 3),
        "two triangles": (np.array([[0, 1, 2], [2, 1, 3]]), 4),
        "two triangles, second opposite edge first": (np.array([[1, 3, 2], [0, 1, 2]]), 4),
        "two triangles, inconsistent orientation": (np.array([[0, 1, 2], [1, 2, 3]]), 4),
        "non-manifold edge (3 faces)": (np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [2, 1, 5]]), 6),
        "non-manifold edge (4 faces)": (np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [1, 0, 5]]), 6),
        "duplicate face": (np.array([[0, 1, 2], [0, 1, 2], [2, 1, 3]]), 4),
        "duplicate face, reversed": (np.array([[0, 1, 2], [2, 1, 0]]), 3),
        "degenerate faces": (np.array([[0, 0, 1], [1, 2, 2], [3, 3, 3], [0, 1, 2], [2, 1, 4]]), 5),
        "repeated vertex on a shared edge": (np.array([[0, 1, 0], [1, 0, 2]]), 3),
        "isolated vertices": (np.array([[2, 5, 7], [7, 5, 9]]), 12),
        "bowtie vertex": (np.array([[0, 1, 2], [0, 3, 4]]), 5),
        "fan of valence 8": _fan(8),
        "fan of valence 16 (insertion sort)": _fan(16),
        "fan of valence 17 (heap sort)": _fan(17),
        "fan of valence 100 (heap sort)": _fan(100),
        "vessel": (vessel.faces, len(vessel.vertices)),
    }
    rng = np.random.default_rng(7)
    for t in range(40):
        n = int(rng.integers(1, 25))
        out[f"random soup {t}"] = (rng.integers(0, n, size=(int(rng.integers(1, 50)), 3)), n)
    return out


MESHES = _meshes()


def _same(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def test_awkward_cases_cover_each_kind_of_edge():
    """The cases contain self-loop edges, p == q pairs, cross springs, edges of 3+ faces,
    and big fans."""
    F, n = MESHES["degenerate faces"]
    edges, _, _ = ref.halfedge_springs(F, n)
    assert np.any(edges[:, 0] == edges[:, 1])
    assert len(ref.halfedge_springs(*MESHES["duplicate face, reversed"])[1]) == 0
    assert len(ref.halfedge_springs(*MESHES["two triangles"])[1]) == 1
    F, n = MESHES["non-manifold edge (3 faces)"]
    edges, cross, boundary = ref.halfedge_springs(F, n)
    assert len(edges) > len(boundary) + len(cross)


@pytest.mark.parametrize("name", list(MESHES))
def test_mesh_springs_equal_the_sorting_reference(name):
    F, n = MESHES[name]
    want = ref.halfedge_springs(F, n)
    for threads in (1, 2):
        with numba_threads(threads):
            for faces in (np.ascontiguousarray(F, np.int64), np.ascontiguousarray(F, np.int32)):
                got = mesh_springs(faces, n)
                assert all(_same(g, w) for g, w in zip(got, want)), name


@pytest.mark.parametrize("name", ["two triangles", "non-manifold edge (3 faces)", "degenerate faces",
                                  "duplicate face", "fan of valence 100 (heap sort)", "vessel", "random soup 3"])
def test_spring_csr_equals_the_numpy_assembly(name):
    F, n = MESHES[name]
    V = np.random.default_rng(1).normal(size=(n, 3))
    F = np.asarray(F, np.int64)
    edges, cross, _ = mesh_springs(F, n)
    cross_rest = ks.cross_rest_lengths(V, cross)
    want = ref.spring_csr(V, edges, cross, cross_rest)
    assert all(_same(g, w) for g, w in zip(ks.build_csr(V, edges, cross, cross_rest), want))
    with numba_threads(1):
        assert _same(ks.cross_rest_lengths(V, cross), cross_rest)


def test_mean_edge_length_equals_numpy_and_ignores_blocks_and_threads(monkeypatch):
    from potflat.relax.energy import mean_edge_length

    flat = meshes.vessel_rollout(1500, seed=2)
    V, F = flat.mesh.vertices, flat.mesh.faces
    for size in (len(F), 1000, 7):  # the block sums are those of the same numpy blocks
        monkeypatch.setattr(distortion, "BLOCK", size)
        want = sum(float(np.linalg.norm(V[F[s, [1, 2, 0]]] - V[F[s]], axis=2).sum())
                   for s in distortion.row_blocks(len(F))) / (3 * len(F))
        for threads in (1, 2):
            with numba_threads(threads):
                assert mean_edge_length(V, F) == want


@pytest.mark.parametrize("name", ["no faces", "degenerate faces", "isolated vertices", "vessel", "random soup 5"])
def test_unique_edges_are_the_reference_edges(name):
    F, n = MESHES[name]
    want = ref.halfedge_springs(F, max(n, 1))[0]
    assert _same(distortion.unique_edges(F), want)
    assert _same(distortion.unique_edges(np.asarray(F, np.int32)), want)
