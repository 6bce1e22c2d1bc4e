"""Kernels of the relax solver against plain numpy references: grid transfers, the multilevel
preconditioner, the fused L-BFGS passes and the untangling average."""
from __future__ import annotations

import numpy as np
import pytest

from potflat.relax._kernels import lbfgs as kl
from potflat.relax._kernels import grid as relax_grid
from potflat._jit import numba_threads
from potflat.relax.hierarchy import GridHierarchy, MultilevelPreconditioner


@pytest.fixture(scope="module")
def hier():
    rng = np.random.default_rng(0)
    ref = rng.random((3000, 2)) * [3.0, 1.0]
    return GridHierarchy.build(ref, min_vertices_per_cell=4.0)


def test_restrict_is_the_transpose_of_prolong(hier):
    rng = np.random.default_rng(1)
    n = len(hier.un)
    for level in hier.levels:
        c = rng.normal(size=(hier.n_nodes(level), 2))
        g = rng.normal(size=(n, 2))
        lhs = np.sum(g * hier.prolong(level, c))
        rhs = np.sum(hier.restrict(level, hier.cell_start(level), g) * c)
        assert lhs == pytest.approx(rhs, rel=1e-12)


def test_morton_codes_interleave_the_quantised_coordinates():
    rng = np.random.default_rng(5)
    un = np.concatenate([rng.random((500, 2)), [[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]]])
    codes = np.empty(len(un), np.int64)
    relax_grid.morton_codes(un, codes)
    top = (1 << relax_grid.QBITS) - 1
    for (u, v), code in zip(un, codes):
        qx, qy = (min(max(int(c * (1 << relax_grid.QBITS)), 0), top) for c in (u, v))
        ref = sum((((qx >> b) & 1) << (2 * b)) | (((qy >> b) & 1) << (2 * b + 1)) for b in range(relax_grid.QBITS))
        assert code == ref


def test_restrict_with_kept_fractions_and_dirty_work_space_is_unchanged(hier):
    rng = np.random.default_rng(6)
    level = hier.levels[-1]
    g = rng.normal(size=(len(hier.un), 2))
    start = hier.cell_start(level)
    fresh = hier.restrict(level, start, g)
    work = rng.normal(size=(1 << (2 * level), 4, 2))  # garbage from an earlier call
    kept = hier.restrict(level, start, g, frac=hier.fractions(level), corners=work)
    assert np.array_equal(fresh, kept)
    frac = hier.fractions(level)
    assert frac.min() >= 0.0 and frac.max() <= 1.0


def test_grid_transfers_are_nested_and_transposed(hier):
    rng = np.random.default_rng(2)
    level = hier.levels[-2]
    c = rng.normal(size=(hier.n_nodes(level), 2))
    finer = np.zeros((hier.n_nodes(level + 1), 2))
    relax_grid.grid_prolong_add(c, level, finer)
    # a coarse bilinear field is the same field on the finer grid
    np.testing.assert_allclose(hier.prolong(level + 1, finer), hier.prolong(level, c), atol=1e-12)
    f = rng.normal(size=finer.shape)
    down = np.empty_like(c)
    relax_grid.grid_restrict(f, level, down)
    assert np.sum(f * finer) == pytest.approx(np.sum(down * c), rel=1e-12)


def test_preconditioner_is_symmetric_positive_and_matches_its_parts(hier):
    rng = np.random.default_rng(3)
    n = len(hier.un)
    diag = rng.uniform(0.5, 20.0, n)
    pc = MultilevelPreconditioner(hier, theta=2.0)
    pc.refresh(diag)
    a, b = rng.normal(size=(n, 2)), rng.normal(size=(n, 2))
    ha, hb = np.empty_like(a), np.empty_like(b)
    pc.apply(a, ha)
    pc.apply(b, hb)
    assert np.sum(b * ha) == pytest.approx(np.sum(a * hb), rel=1e-11)
    aha = np.sum(a * ha)
    jacobi = np.sum(a * a / diag[:, None])
    assert aha > jacobi > 0
    assert pc.coarse_norm(pc.restrict(a)) == pytest.approx(aha - jacobi, rel=1e-10)
    # the restriction is linear: H0 of a combination from the combined restrictions
    c = 0.3 * a - 1.7 * b
    hc, hc_nodes = np.empty_like(c), np.empty_like(c)
    pc.apply(c, hc)
    pc.apply(c, hc_nodes, restricted=0.3 * pc.restrict(a) - 1.7 * pc.restrict(b))
    np.testing.assert_allclose(hc_nodes, hc, rtol=1e-12, atol=1e-12 * np.abs(hc).max())
    # a constant field is a coarse field: the coarse terms dominate it
    ones = np.ones((n, 2))
    h1 = np.empty_like(ones)
    pc.apply(ones, h1)
    assert np.sum(ones * h1) > 5 * np.sum(1.0 / diag) * 2


def test_fused_passes_match_numpy_and_do_not_depend_on_threads():
    rng = np.random.default_rng(4)
    N = 2 * (kl.PARALLEL_BLOCKS * kl.BLOCK + 61)  # threaded path, a partial last block
    q0, y, s, g_old = (rng.normal(size=N) for _ in range(4))
    diag = rng.uniform(0.1, 5.0, N // 2)
    parts = np.empty(-(-N // kl.BLOCK))
    results = []
    for threads in (1, 2):
        with numba_threads(threads):
            q = q0.copy()
            kl.combine(q, 0.5, q, -1.5, y, diag, 2.0, s, parts)
            dot = float(np.sum(parts))
            s_out, y_out = np.empty(N), np.empty(N)
            p2 = np.empty_like(parts)
            kl.pair(q, 0.3, y, g_old, diag, s_out, y_out, parts, p2)
            results.append((q, dot, s_out, y_out, float(np.sum(parts)), float(np.sum(p2))))
    want_q = (0.5 * q0 - 1.5 * y) * 2.0 / np.repeat(diag, 2)
    np.testing.assert_allclose(results[0][0], want_q, rtol=1e-14)
    assert results[0][1] == pytest.approx(np.dot(s, want_q), rel=1e-12)
    np.testing.assert_allclose(results[0][2], 0.3 * want_q, rtol=1e-15)
    np.testing.assert_allclose(results[0][3], y - g_old, rtol=1e-15)
    assert results[0][4] == pytest.approx(np.dot(0.3 * want_q, y - g_old), rel=1e-12)
    assert results[0][5] == pytest.approx(np.sum((y - g_old) ** 2 / np.repeat(diag, 2)), rel=1e-12)
    for a, b in zip(results[0], results[1]):
        assert np.array_equal(a, b)  # bit for bit, whatever the number of threads


def test_neighbour_means_count_each_edge_neighbour_once():
    from potflat.mesh._kernels.topology import vertex_faces
    from potflat.mesh._kernels.topology import neighbour_means

    faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4], [0, 4, 1], [1, 4, 5]])
    x = np.random.default_rng(5).normal(size=(6, 2))
    ptr, tri = vertex_faces(6, faces)
    verts = np.arange(6)
    out = np.empty((6, 2))
    neighbour_means(x, verts, ptr, tri, faces, out)
    for v in verts:
        nbrs = {int(u) for f in faces if v in f for u in f if u != v}
        np.testing.assert_allclose(out[v], x[sorted(nbrs)].mean(axis=0), rtol=1e-14)


def test_faces_in_vertex_order_renumber_and_sort_stably_by_the_smallest_corner():
    from potflat.mesh._kernels.topology import faces_in_vertex_order

    rng = np.random.default_rng(7)
    faces = rng.integers(0, 40, size=(300, 3)).astype(np.int64)  # many ties, unused vertices
    new_index = rng.permutation(50).astype(np.int64)
    renumbered = new_index[faces]
    expected = renumbered[np.argsort(renumbered.min(axis=1), kind="stable")]
    np.testing.assert_array_equal(faces_in_vertex_order(faces, new_index), expected)
    assert faces_in_vertex_order(np.empty((0, 3), np.int64), new_index).shape == (0, 3)


def test_face_barrier_visits_only_blocks_with_squeezed_faces_and_matches_the_full_scan():
    from potflat.mesh._kernels.geometry import signed_areas_2d
    from potflat.relax._kernels import springs as ks

    rng = np.random.default_rng(3)
    n, m = 3000, 3 * ks.BLOCK + 17  # several blocks, the last one short
    x = rng.random((n, 2))
    faces = rng.integers(0, n, size=(2 * m, 3)).astype(np.int32)
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])][:m]
    areas = np.empty(m)
    signed_areas_2d(x, faces, areas)
    faces[areas < 0] = faces[areas < 0][:, ::-1]  # positively oriented
    faces[m - 1] = faces[m - 1, ::-1]  # but the last face: flipped (infinite barrier)
    a_ref = np.full(m, 0.02)
    a_ref[: 2 * ks.BLOCK] = 1e-30  # the first two blocks: every face far above the barrier
    a_ref[100] = 1e3  # ... but one
    below = np.empty(-(-m // ks.BLOCK), np.int64)
    ks.face_terms(x, faces, a_ref, 0.5, np.empty((0, 5)), 0.0, 0.0, 0.0, 0.0, np.inf, 0.05, areas, below,
                  np.empty((0, 4)), np.empty(0))
    want = np.empty(m)
    signed_areas_2d(x, faces, want)
    np.testing.assert_array_equal(areas, want)
    squeezed = ~(areas >= 0.5 * a_ref)
    np.testing.assert_array_equal(below, np.add.reduceat(squeezed.astype(np.int64), np.arange(0, m, ks.BLOCK)))
    assert below[0] == 1 and below[1] == 0 and below[-1] > 0
    weight = rng.random(n)
    x = np.ascontiguousarray(x)
    results = []
    for blocks in (below, np.ones_like(below)):  # the skipping scan and the full scan
        grad, diag = np.zeros((n, 2)), np.zeros(n)
        energy = ks.face_barrier(x, faces, areas, a_ref, 1.0, 1.0, 0.5, True, weight, grad, diag, blocks)
        results.append((energy, grad, diag))
    assert results[0][0] == results[1][0] == np.inf  # the flipped face
    np.testing.assert_array_equal(results[0][1], results[1][1])
    np.testing.assert_array_equal(results[0][2], results[1][2])


def test_library_calls_take_the_thread_limit_of_numba_threads():
    import numba

    from potflat._jit import numba_threads, worker_threads

    assert worker_threads() == numba.get_num_threads()
    with numba_threads(1):
        assert worker_threads() == 1  # scipy's workers= follow --threads
    assert worker_threads() == numba.get_num_threads()
