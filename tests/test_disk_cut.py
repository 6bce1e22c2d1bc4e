"""A selected wall that is not a disk (a handle joined to it at both ends, a closed part, an
edge shared by three faces) is cut into one by the rollout (:mod:`potflat.rollout.topology`)
instead of being refused by the relax stage: two-walled bowls with a handle from the outer
into the inner wall, welded or joined at non-manifold edges, unroll on either side."""
from __future__ import annotations

import json

import numpy as np
import pytest
from potflat_cli.main import app
from typer.testing import CliRunner

from potflat.mesh.embedding import signed_areas, tutte_embedding
from potflat.relax import relax
from potflat.rollout import rollout
from potflat.rollout.seam import cut_open
from potflat.rollout.topology import disk_cut
from potflat_synthetic.vessels import PART_HANDLE, PART_INNER, make_vessel, write_ply_colored


def _torus(n_major=24, n_minor=12, R=40.0, r=10.0):
    u, v = np.meshgrid(np.arange(n_major), np.arange(n_minor), indexing="ij")
    a, b = 2 * np.pi * u / n_major, 2 * np.pi * v / n_minor
    V = np.stack([(R + r * np.cos(b)) * np.cos(a), (R + r * np.cos(b)) * np.sin(a), r * np.sin(b)], -1).reshape(-1, 3)
    idx = np.arange(n_major * n_minor).reshape(n_major, n_minor)
    i0, j0 = idx, np.roll(idx, -1, axis=0)
    i1, j1 = np.roll(idx, -1, axis=1), np.roll(np.roll(idx, -1, axis=0), -1, axis=1)
    F = np.concatenate([np.stack([i0, j0, j1], -1).reshape(-1, 3), np.stack([i0, j1, i1], -1).reshape(-1, 3)])
    return V, F


def _lays_flat(V, F, leave):
    """The faces left are disks: Tutte's embedding (each piece in a disc) folds none of them."""
    faces, index, _, _, _ = cut_open(F[~leave], np.zeros((int((~leave).sum()), 3)))  # (pinched vertices apart)
    disc = tutte_embedding(faces, len(index))
    return disc is not None and bool(np.all(signed_areas(faces, disc) > 0))


def test_a_torus_is_opened_and_cut_through_its_handle():
    V, F = _torus()
    assert tutte_embedding(F, len(V)) is None  # closed: no layout at all
    offset = np.hypot(V[:, 0], V[:, 1])  # the outer equator stands furthest off
    cut = disk_cut(F, V, offset)
    assert cut.closed_parts == 1 and cut.handles == 1 and cut.nonmanifold_edges == 0
    assert cut.faces.sum() < 0.2 * len(F) and _lays_flat(V, F, cut.faces)
    # the loop goes round the tube (12 edges), not round the ring (24): through the base point
    assert np.ptp(np.arctan2(V[F[cut.faces]][..., 1], V[F[cut.faces]][..., 0])) < np.pi


def test_a_disk_is_left_whole_and_a_fin_on_an_edge_is_cut_off():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.5, 1.0]], float)
    F = np.array([[0, 1, 2], [1, 3, 2]])
    assert not disk_cut(F, V).faces.any()
    fin = np.vstack([F, [[1, 2, 4]]])  # a third face on the edge 1-2
    cut = disk_cut(fin, V)
    assert cut.nonmanifold_edges == 1 and cut.faces.tolist() == [False, False, True]


@pytest.fixture(scope="module", params=["welded", "joined"])
def bowl(request):
    return make_vessel("bowl", n_vertices=8000, seed=1, texture_size=128, handles=request.param)


def test_the_bowl_s_handle_goes_from_the_outer_into_the_inner_wall(bowl):
    F = bowl.mesh.faces
    handle = np.unique(F[bowl.face_part == PART_HANDLE])
    inner = np.unique(F[bowl.face_part == PART_INNER])
    assert np.intersect1d(handle, inner).size > 0  # welded (or joined) into the inner wall too
    key = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    _, count = np.unique(key, axis=0, return_counts=True)
    assert (count.max() == 3) == (bowl.options["handles"] == "joined")


@pytest.mark.parametrize("side", ["outer", "inner"])
@pytest.mark.parametrize("keep", [False, True])
def test_the_bowl_unrolls_and_relaxes_on_either_side(bowl, side, keep):
    """The mesh as given (the joined bowl's non-manifold edges uncleaned): no refusal."""
    res = rollout(bowl.mesh, side=side, keep_attachments=keep, importance="none")
    assert res.distortion.flipped == 0 and res.boundary_overlap == 0
    out = relax(res.flat)
    assert out.flipped == 0 and out.boundary_overlap == 0


def test_kept_handles_of_a_two_walled_kylix_are_cut_and_relax():
    kylix = make_vessel("kylix", n_vertices=10000, seed=1, texture_size=64, walls=2, handles="welded")
    res = rollout(kylix.mesh, keep_attachments=True, importance="none")
    assert res.disk_cut.handles == 2 and np.all(kylix.face_part[res.disk_cut_faces] == PART_HANDLE)
    assert relax(res.flat).flipped == 0


@pytest.mark.parametrize("side", ["outer", "inner"])
def test_the_bowl_runs_from_its_file_on_either_side(bowl, side, tmp_path):
    scan = write_ply_colored(bowl, tmp_path / "bowl.ply")
    result = CliRunner().invoke(app, ["run", str(scan), "-o", str(tmp_path / "out"), "--side", side,
                                      "--px-per-mm", "1", "-q"])
    assert result.exit_code == 0, result.output
    relaxed = json.loads((tmp_path / "out" / "bowl.relaxed.json").read_text())
    assert relaxed["flipped"] == 0 and relaxed["boundary_overlap"] == 0
    assert json.loads((tmp_path / "out" / "bowl.rollout.json").read_text())["walls"]["side"] == side


def test_the_colonoware_pots_inside_is_cut_into_a_disk_and_relaxes(real_scans):
    """Refused before ("... folded triangles that no fold-free layout of this mesh removes: it is
    not a disk"): the scan's inner wall has tunnels (a crack bridged to the other side, specks)."""
    from potflat.io.scan import load_scan
    from potflat.mesh.distortion import face_areas

    mesh = load_scan(real_scans / "colonoware-pot.glb").mesh
    res = rollout(mesh, side="inner", importance="none")
    assert res.disk_cut.handles > 0
    assert res.disk_cut_area < 0.01 * face_areas(res.flat.mesh.vertices, res.flat.mesh.faces).sum()
    out = relax(res.flat)
    assert out.flipped == 0 and out.boundary_overlap == 0


def test_vertices_per_piece_counts_a_vertex_shared_by_two_pieces_in_both():
    """Each piece's distinct vertices: by scattering when every vertex lies in one piece, by
    sorting when cuts left one in two (a bowtie: two triangles meeting at vertex 2)."""
    from potflat.rollout.topology import _vertices_per_piece

    apart = np.array([[0, 1, 2], [3, 4, 5], [3, 5, 6]])
    np.testing.assert_array_equal(_vertices_per_piece(apart, np.repeat([0, 1, 1], 3), 7, 2), [3, 4])
    bowtie = np.array([[0, 1, 2], [2, 3, 4]])
    np.testing.assert_array_equal(_vertices_per_piece(bowtie, np.repeat([0, 1], 3), 5, 2), [3, 3])
