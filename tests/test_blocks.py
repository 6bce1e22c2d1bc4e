"""Work done in blocks of faces (to bound memory on big scans) gives the same bits as one block.

``potflat.mesh.distortion.row_blocks`` cuts per-face and per-edge work into blocks of
``distortion.BLOCK`` rows. Here BLOCK is set to a few rows, so every blocked loop runs
many uneven blocks (including a last block of one row), and the results are compared bit
for bit with the same computation in a single block, and with plain references.
"""
import numpy as np
import pytest
import scipy.sparse
import scipy.sparse.csgraph
from potflat_synthetic.vessels import make_vessel

from potflat.io.flat_ply import read_flat_ply, write_flat_ply
from potflat.mesh import distortion
from potflat.mesh.cleaning import clean_mesh
from potflat.mesh.embedding import signed_areas
from potflat.rollout.profile import vessel_profile
from potflat.rollout.seam import cut_open
from potflat.rollout.unroll import rollout


def _same(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.fixture(scope="module")
def vessel():
    return make_vessel("hydria", n_vertices=1500, seed=4, handles=True, texture_size=64)


def _in_blocks(monkeypatch, size, fn):
    with monkeypatch.context() as mp:
        mp.setattr(distortion, "BLOCK", size)
        return fn()


def test_row_blocks_cover_every_row_once():
    for m, size in [(0, 4), (1, 4), (4, 4), (9, 4), (10, 3)]:
        rows = np.concatenate([np.arange(m)[s] for s in distortion.row_blocks(m, size)] or [np.zeros(0, int)])
        assert rows.tolist() == list(range(m))
        assert all(s.stop - s.start <= size for s in distortion.row_blocks(m, size))


@pytest.mark.parametrize("size", [1, 7, 64])
def test_distortion_figures_do_not_depend_on_the_blocks(monkeypatch, vessel, size):
    mesh = vessel.mesh
    rng = np.random.default_rng(0)
    uv = mesh.vertices[:, :2] + 0.01 * rng.normal(size=(len(mesh.vertices), 2))
    V, F = mesh.vertices, mesh.faces
    edges = distortion.unique_edges(F)

    def figures():
        fd = distortion.face_distortion(V, uv, F)
        return ([fd.area_3d, fd.area_2d, fd.sigma_max, fd.sigma_min, fd.valid,
                 distortion.face_areas(V, F), distortion.edge_length_error(V, uv, edges),
                 distortion.vertex_stress(V, uv, F, 0.1), signed_areas(F, uv)],
                distortion.summarize(V, uv, F))

    (small, s_small), (one, s_one) = _in_blocks(monkeypatch, size, figures), _in_blocks(monkeypatch, len(F), figures)
    assert all(_same(a, b) for a, b in zip(small, one))
    assert s_small == s_one
    # plain references
    p0, p1, p2 = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    assert _same(small[5], 0.5 * np.linalg.norm(np.cross(p1 - p0, p2 - p0), axis=1))
    w0, w1, w2 = uv[F[:, 0]], uv[F[:, 1]], uv[F[:, 2]]
    ref_signed = 0.5 * ((w1[:, 0] - w0[:, 0]) * (w2[:, 1] - w0[:, 1]) - (w1[:, 1] - w0[:, 1]) * (w2[:, 0] - w0[:, 0]))
    assert _same(small[8], ref_signed)


@pytest.mark.parametrize("size", [1, 7, 1 << 18])
def test_median_edge_length_matches_numpy(monkeypatch, vessel, size):
    V, F = vessel.mesh.vertices, vessel.mesh.faces[:-1]  # an odd count of faces: 3 m lengths, an odd median
    for faces in (F, vessel.mesh.faces):  # an even count: the mean of the two middle lengths
        got = _in_blocks(monkeypatch, size, lambda: distortion.median_edge_length(V, faces))
        assert got == float(np.median(np.linalg.norm(V[faces[:, [1, 2, 0]]] - V[faces], axis=2)))


def test_unique_edges_match_numpy_unique():
    rng = np.random.default_rng(3)
    F = rng.integers(0, 40, size=(300, 3))
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    assert _same(distortion.unique_edges(F), np.unique(e, axis=0))
    assert distortion.unique_edges(np.zeros((0, 3), np.int64)).shape == (0, 2)


def test_cut_open_matches_a_sparse_graph_reference():
    """Corners of a vertex are joined across each shared edge where the two faces agree on
    its angle (within pi); reference: scipy's connected components of that corner graph."""
    nx, ny = 7, 6
    F = []
    for j in range(ny - 1):
        for i in range(nx - 1):
            a = j * nx + i
            F += [[a, a + 1, a + nx], [a + 1, a + nx + 1, a + nx]]
    F = np.array(F)
    rng = np.random.default_rng(5)
    theta = rng.uniform(0, 6, size=F.shape)
    new_faces, vertex_index, th, _, _ = cut_open(F, theta)
    corner_v, t = F.ravel(), theta.ravel()
    halves = {}
    for h in range(3 * len(F)):
        f, k = divmod(h, 3)
        halves.setdefault(frozenset((F[f, k], F[f, (k + 1) % 3])), []).append(h)
    rows, cols = [], []
    for g, h in (pair for pair in halves.values() if len(pair) == 2):
        for c1 in (g, g - g % 3 + (g + 1) % 3):
            for c2 in (h, h - h % 3 + (h + 1) % 3):
                if corner_v[c1] == corner_v[c2] and abs(t[c1] - t[c2]) < np.pi:
                    rows.append(c1)
                    cols.append(c2)
    graph = scipy.sparse.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(3 * len(F),) * 2)
    n_ref, labels = scipy.sparse.csgraph.connected_components(graph, directed=False)
    new_corner = new_faces.ravel()
    assert len(set(zip(labels, new_corner))) == n_ref == len(vertex_index)  # the same partition
    assert n_ref > nx * ny  # the random angles did cut
    assert _same(vertex_index[new_corner], corner_v)
    lowest = {c: np.flatnonzero(new_corner == c).min() for c in set(new_corner)}
    assert _same(th[new_corner], t[[lowest[c] for c in new_corner]])


def test_rollout_profile_and_stage_file_do_not_depend_on_the_blocks(monkeypatch, vessel, tmp_path):
    def run(tag):
        mesh, _ = clean_mesh(vessel.mesh)
        res = rollout(mesh)
        prof = vessel_profile(mesh, res.axis.point, res.axis.direction, labels=res.walls.labels)
        path = write_flat_ply(tmp_path / tag / "x.rollout.ply", res.flat)
        return res, prof, path.read_bytes()

    small, one = _in_blocks(monkeypatch, 5, lambda: run("small")), _in_blocks(monkeypatch, 10**9, lambda: run("one"))
    for a, b in zip(small[:2], one[:2]):
        assert a.__class__ is b.__class__
    assert _same(small[0].flat.uv, one[0].flat.uv) and _same(small[0].flat.mesh.faces, one[0].flat.mesh.faces)
    assert _same(small[0].flat.mesh.texcoords, one[0].flat.mesh.texcoords)
    assert small[0].distortion == one[0].distortion and small[0].seam_angle == one[0].seam_angle
    assert _same(small[1].outer_radius, one[1].outer_radius)
    assert small[2] == one[2]
    back = read_flat_ply(tmp_path / "small" / "x.rollout.ply")
    assert _same(back.uv, small[0].flat.uv) and _same(back.mesh.faces, small[0].flat.mesh.faces)
