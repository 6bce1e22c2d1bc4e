"""Relax stage: kernels against tests/reference.py, fold-freedom, developable recovery,
determinism, scaling, extremes, the paper preset, the stage files and the CLI."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
import reference as ref
from _bench_meshes import (
    SPRINGS_ONLY,
    bumpy_patch,
    energy_never_increases,
    meshes,
    signed_areas,
    spring_system,
)

from potflat.errors import FoldedResultError, InvalidOptionError
from potflat.files.relax_stage import run_relax_stage
from potflat.mesh._kernels.topology import (
    faces_touching,
    flagged_face_vertices,
    incident_faces,
    vertex_faces,
)
from potflat.mesh.distortion import summarize
from potflat.relax import RelaxOptions, relax
from potflat.relax._kernels.steps import max_step_of
from potflat.types import FlatMesh, Mesh

SAMPLE = Path(__file__).resolve().parents[1] / "samples" / "data" / "amphora.obj"


def _procrustes_error(a, b):
    """Max distance between ``a`` and ``b`` after the best rigid motion (no reflection)."""
    a0, b0 = a - a.mean(0), b - b.mean(0)
    u, _, vt = np.linalg.svd(a0.T @ b0)
    d = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag([1, d]) @ vt
    return float(np.abs(a0 @ rot - b0).max())


@pytest.fixture(scope="module")
def bumpy():
    return bumpy_patch()


@pytest.fixture(scope="module")
def vessel():
    return meshes.vessel_rollout(1500, seed=2)


# --- kernels against the references ---------------------------------------------------------

def test_springs_and_cross_rest_lengths_match_reference(bumpy):
    from potflat.relax._kernels.springs import cross_rest_lengths
    from potflat.relax.energy import mesh_springs

    V, F = bumpy.mesh.vertices, bumpy.mesh.faces
    edges, cross, boundary = mesh_springs(F, len(V))
    r_cross = cross_rest_lengths(V, cross)
    want_pairs, want_rest = ref.springs(V, F)
    got = np.concatenate([edges, np.sort(cross[:, :2], axis=1)])
    got_rest = np.concatenate([np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1), r_cross])
    order = np.lexsort((got[:, 1], got[:, 0], np.r_[np.zeros(len(edges)), np.ones(len(cross))]))
    np.testing.assert_array_equal(got[order], want_pairs)
    np.testing.assert_allclose(got_rest[order], want_rest, rtol=1e-12)
    # cross rest lengths are intrinsic: longer than the 3D chord on a bent surface
    chord = np.linalg.norm(V[cross[:, 0]] - V[cross[:, 1]], axis=1)
    assert np.all(r_cross >= chord - 1e-12) and np.any(r_cross > chord + 1e-6)
    np.testing.assert_array_equal(np.sort(boundary, axis=1), _boundary_edges(F))
    halfedges = {tuple(h) for f in F for h in (f[[0, 1]], f[[1, 2]], f[[2, 0]])}
    assert all(tuple(h) in halfedges for h in boundary)  # oriented as in their faces


@pytest.mark.parametrize("relative", [False, True])
def test_energy_and_gradient_match_reference(bumpy, relative):
    V, F = bumpy.mesh.vertices, bumpy.mesh.faces
    pairs, rest = ref.springs(V, F)
    sp = spring_system(V, F, k=0.7, relative=relative)
    x = np.ascontiguousarray(bumpy.uv * 1.1)
    E, Es, g = sp.evaluate(x, barrier=False)
    assert Es == pytest.approx(ref.energy(x, pairs, rest, 0.7, relative), rel=1e-12)
    assert E == Es
    np.testing.assert_allclose(-g, ref.forces(x, pairs, rest, 0.7, relative), atol=1e-12)


def test_barrier_energy_and_gradient_match_reference(bumpy):
    from potflat.relax.parameters import ENERGY

    V, F = bumpy.mesh.vertices, bumpy.mesh.faces
    sp = spring_system(V, F, k=1.0, relative=False)
    x = np.ascontiguousarray(bumpy.uv.copy())
    x[:, 0] *= 0.4  # squeeze: triangles below half their rest area switch the barrier on
    E, Es, g = sp.evaluate(x)
    Eb = ref.barrier_energy(x, F, sp.a_ref, 1.0, ENERGY.barrier_mu, ENERGY.barrier_eps)
    assert Eb > 0
    assert E - Es == pytest.approx(Eb, rel=1e-10)
    num = ref.numeric_gradient(lambda y: sp.evaluate(np.ascontiguousarray(y))[0], x)
    np.testing.assert_allclose(g, num, atol=1e-6 * np.abs(num).max())
    x[:, 0] *= -1  # mirrored: every face flipped, infinite energy
    assert sp.evaluate(np.ascontiguousarray(x))[0] == np.inf


def test_max_step_matches_reference(bumpy):
    F = bumpy.mesh.faces
    sp = spring_system(bumpy.mesh.vertices, F, k=1.0, relative=False)
    rng = np.random.default_rng(0)
    for _ in range(5):
        d = rng.normal(size=bumpy.uv.shape)
        got = sp.max_face_step(bumpy.uv, d)
        want = ref.max_step(bumpy.uv, d, F)
        assert got == pytest.approx(want, abs=1e-4)
        if np.isfinite(got):
            assert np.all(signed_areas(bumpy.uv + 0.999 * got * d, F) > 0)
            assert np.any(signed_areas(bumpy.uv + 1.001 * got * d, F) <= 0)


def test_limiting_faces_are_those_whose_own_bound_is_below_the_cap(bumpy):
    sp = spring_system(bumpy.mesh.vertices, bumpy.mesh.faces, k=1.0, relative=False)
    x = np.ascontiguousarray(bumpy.uv)
    d = 0.5 * np.random.default_rng(1).normal(size=x.shape)
    flags = np.empty(sp.m, bool)
    t = sp.max_face_step(x, d, cap=1.0, limiting=flags)
    own = np.array([max_step_of(x, d, sp.faces, np.array([f]), 1.0, 1.0) for f in range(sp.m)])
    assert 0 < flags.sum() < sp.m  # a real mix
    assert np.array_equal(flags, own < 1.0)
    assert t == own.min()
    assert max_step_of(x, d, sp.faces, np.arange(sp.m), 1.0, 1.0) == t
    verts = np.unique(sp.faces[flags][:3])  # the faces around a few limiting ones
    trios, bounds = sp.face_limits(x, d, verts, 1.0, 1.0)
    around = np.flatnonzero(np.isin(sp.faces, verts).any(axis=1))
    held = around[own[around] < 1.0]
    assert 3 <= len(held) < len(around)
    assert np.array_equal(trios, sp.faces[held]) and np.array_equal(bounds, own[held])


def test_max_face_step_near_equals_the_full_bound_after_a_local_change(bumpy):
    sp = spring_system(bumpy.mesh.vertices, bumpy.mesh.faces, k=1.0, relative=False)
    x = np.ascontiguousarray(bumpy.uv)
    rng = np.random.default_rng(2)
    for _ in range(5):
        d = 0.5 * rng.normal(size=x.shape)
        flags = np.empty(sp.m, bool)
        sp.max_face_step(x, d, cap=1.0, limiting=flags)
        verts = flagged_face_vertices(flags, sp.faces, np.zeros(sp.n, bool))
        d[verts] = 0.5 * rng.normal(size=(len(verts), 2))  # changed at the limiting faces' vertices only
        assert sp.max_face_step_near(x, d, verts, 1.0, 1.0) == sp.max_face_step(x, d, cap=1.0)


def test_flagged_face_vertices_incident_faces_and_faces_touching_match_numpy():
    rng = np.random.default_rng(3)
    F = np.array([rng.choice(40, 3, replace=False) for _ in range(200)], np.int32)
    flags = rng.random(200) < 0.1
    seen = np.zeros(40, bool)
    verts = flagged_face_vertices(flags, F, seen)
    assert np.array_equal(np.sort(verts), np.unique(F[flags]))
    assert not seen.any()  # the work space is left clean for the next call
    assert len(flagged_face_vertices(np.zeros(200, bool), F, seen)) == 0
    vf_ptr, vf_tri = vertex_faces(40, F)
    got = incident_faces(verts, vf_ptr, vf_tri)
    want = np.concatenate([np.nonzero((F == v).any(axis=1))[0] for v in verts])
    assert np.array_equal(np.sort(got), np.sort(want))
    on = np.zeros(40, bool)
    on[[3, 17]] = True
    assert np.array_equal(faces_touching(on, F), np.flatnonzero(on[F].any(axis=1)))
    assert len(faces_touching(np.zeros(40, bool), F)) == 0


def test_overlap_counts_crossing_boundary():
    from potflat.mesh._segments import crossing_pairs

    x = np.array([[0, 0], [2, 0], [1, -1], [1, 1], [5, 5], [6, 5]], float)
    seg = np.array([[0, 1], [2, 3], [4, 5], [1, 2]])
    pairs = crossing_pairs(x, seg, 0.5, 100)
    assert len(pairs) == 1 and sorted(pairs[0]) == [0, 1]
    assert len(crossing_pairs(x, seg[[0, 2, 3]], 0.5, 100)) == 0


# --- the default solver ---------------------------------------------------------------------

@pytest.mark.parametrize("proxy", ["cylinder", "sphere"])
def test_default_is_fold_free_on_a_bulgy_vessel(proxy):
    flat = meshes.vessel_rollout(1500, seed=1, proxy=proxy)
    F = flat.mesh.faces
    for options in ({}, SPRINGS_ONLY):
        r = relax(flat, **options)
        assert r.flipped == 0 and r.boundary_overlap == 0
        assert np.all(signed_areas(r.flat.uv, F) > 0)
        assert summarize(flat.mesh.vertices, r.flat.uv, F).flipped == 0
        assert np.all(np.isfinite(r.flat.stress)) and r.flat.stress.shape == (len(flat.uv),)
    assert r.distortion.edge_rms < 0.6 * r.distortion_before.edge_rms


def test_energy_never_increases_under_the_default(vessel):
    r = relax(vessel, preset="standard")
    h = r.energy_history
    assert len(h) == r.iterations > 10
    assert [lv.level for lv in r.levels] == ["fine, shape first", "fine"]
    assert energy_never_increases(r)


def test_fold_free_from_a_deliberately_distorted_start(vessel):
    u, v = vessel.uv.T
    warped = np.stack([u + 25 * np.sin(v / 40), v * 1.6 + 10 * np.sin(u / 50)], axis=1)
    start = vessel.replace(uv=warped)
    assert np.all(signed_areas(warped, vessel.mesh.faces) > 0)
    r = relax(start)
    assert r.flipped == 0 and r.boundary_overlap == 0
    # it finds the same minimum as from the rollout itself (the energy trades edge length for
    # shape, so compare with that, not with a fixed fraction of the start's error)
    direct = relax(vessel)
    assert r.distortion_before.edge_rms > 1.5 * direct.distortion.edge_rms
    assert r.distortion.edge_rms == pytest.approx(direct.distortion.edge_rms, rel=0.01)
    assert r.distortion.anisotropy_p95 == pytest.approx(direct.distortion.anisotropy_p95, rel=0.01)


@pytest.mark.parametrize("start", ["orthographic", "sphere"])
def test_cylinder_patch_relaxes_to_its_development(start):
    flat, exact = meshes.cylinder_patch(24, 16, start=start)
    assert summarize(flat.mesh.vertices, flat.uv, flat.mesh.faces).edge_rms > 0.05
    r = relax(flat, tol=1e-12, max_iter=3000)
    assert r.distortion.edge_rms < 1e-4
    assert _procrustes_error(r.flat.uv, exact) < 2e-3


def test_cone_relaxes_to_its_development():
    flat, exact = meshes.cone_patch(48, 6)
    r = relax(flat, tol=1e-12, max_iter=1500)
    assert r.distortion_before.edge_rms > 0.1
    assert r.distortion.edge_rms < 1e-3
    assert _procrustes_error(r.flat.uv, exact) < 1e-2


def test_deterministic_run_to_run_and_across_thread_counts(vessel):
    a = relax(vessel, preset="preview", threads=1)
    b = relax(vessel, preset="preview", threads=1)
    c = relax(vessel, preset="preview", threads=2)
    np.testing.assert_array_equal(a.flat.uv, b.flat.uv)
    np.testing.assert_array_equal(a.flat.uv, c.flat.uv)
    np.testing.assert_array_equal(a.energy_history, c.energy_history)


def test_result_scales_with_the_input_units(vessel):
    base = relax(vessel, preset="preview")
    for factor, rtol in ((1024.0, 0.0), (1e3, 1e-7), (1e-3, 1e-7)):
        scaled = FlatMesh(vessel.mesh.replace(vertices=vessel.mesh.vertices * factor), vessel.uv * factor)
        r = relax(scaled, preset="preview")
        if rtol == 0.0:
            np.testing.assert_array_equal(r.flat.uv, base.flat.uv * factor)
        else:
            np.testing.assert_allclose(r.flat.uv / factor, base.flat.uv, rtol=0, atol=rtol * np.ptp(base.flat.uv))


# --- extremes ----------------------------------------------------------------------------------

def test_two_triangle_mesh(square_mesh):
    uv = square_mesh.vertices[:, :2] * np.array([2.0, 0.5])
    r = relax(FlatMesh(square_mesh, uv), tol=1e-12)
    assert r.flipped == 0
    assert r.distortion.edge_rms < 1e-6
    assert np.all(np.isfinite(r.flat.uv))


def test_slivers_stay_unflipped():
    flat, _ = meshes.cylinder_patch(16, 10, seed=5)
    V, uv, F = flat.mesh.vertices.copy(), flat.uv.copy(), flat.mesh.faces
    # collapse some interior vertices onto an edge of their ring: needle and cap slivers in 3D
    rng = np.random.default_rng(0)
    inner = [i for i in range(len(V)) if 0.2 < V[i, 2] < 1.3 and abs(np.arctan2(V[i, 1], V[i, 0])) < 0.8]
    for i in rng.choice(inner, 6, replace=False):
        j = F[np.nonzero((F == i).any(1))[0][0]]
        j = j[j != i]
        V[i] = 0.5 * (V[j[0]] + V[j[1]]) + 1e-9
    fd = summarize(V, uv, F)
    r = relax(FlatMesh(Mesh(V, F), uv))
    assert r.flipped == 0 and np.all(signed_areas(r.flat.uv, F) > 0)
    assert r.distortion.edge_rms < fd.edge_rms


def test_smoothing_the_direction_at_limiting_faces_keeps_every_guarantee(vessel, monkeypatch):
    import dataclasses

    import potflat.relax.energy as en
    import potflat.relax.lbfgs as rx

    # the mechanism on the springs alone (the outline term changes which faces limit a step)
    monkeypatch.setattr(en, "ENERGY", dataclasses.replace(en.ENERGY, outline_mu=0.0))
    smooth = relax(vessel, preset="standard", **SPRINGS_ONLY)
    monkeypatch.setattr(rx, "SOLVER", dataclasses.replace(rx.SOLVER, smooth_max_fraction=0.0))
    plain = relax(vessel, preset="standard", **SPRINGS_ONLY)
    assert sum(lv.smoothed_directions for lv in smooth.levels) > 0
    assert sum(lv.smoothed_directions for lv in plain.levels) == 0
    for r in (smooth, plain):
        assert r.flipped == 0 and r.boundary_overlap == 0 and r.converged
        assert np.all(np.diff(r.energy_history) <= 0)
    # longer steps, no worse result
    assert smooth.iterations < plain.iterations
    assert smooth.distortion.edge_rms <= plain.distortion.edge_rms * 1.01


def test_high_valence_fan():
    k = 24
    ang = np.linspace(0, 2 * np.pi, k, endpoint=False)
    ring = np.stack([np.cos(ang), np.sin(ang), 0.3 * np.cos(3 * ang)], axis=1)
    V = np.vstack([[0, 0, 0.5], ring])
    F = np.array([[0, 1 + i, 1 + (i + 1) % k] for i in range(k)])
    uv = V[:, :2] * 0.7
    r = relax(FlatMesh(Mesh(V, F), uv))
    assert r.flipped == 0 and r.boundary_overlap == 0
    assert np.all(np.isfinite(r.flat.uv))


def test_float32_input(vessel):
    V32 = vessel.mesh.vertices.astype(np.float32)
    uv32 = vessel.uv.astype(np.float32)
    r = relax(FlatMesh(vessel.mesh.replace(vertices=V32), uv32), preset="preview")
    assert r.flat.uv.dtype == np.float64 and r.flipped == 0


@pytest.mark.parametrize("stretch", [1.0, 4.0])
@pytest.mark.parametrize("preset", ["standard", "paper"])
def test_stretch_factors_never_nan(vessel, stretch, preset):
    r = relax(vessel, preset=preset, stretch=stretch, max_iter=400)
    assert np.all(np.isfinite(r.flat.uv)) and np.all(np.isfinite(r.energy_history))
    if preset != "paper":
        assert r.flipped == 0 and r.boundary_overlap == 0


@pytest.mark.parametrize("bad", [{"stiffness": 0.0}, {"stiffness": -1.0}, {"stretch": 0.0}, {"tol": -1e-3},
                                 {"max_iter": 0}, {"threads": 0}, {"time_budget": -1.0}, {"preset": "fast"},
                                 {"weighting": "cubic"}, {"stiffness": float("nan")}, {"max_iter": 2.5},
                                 {"simplify_mm": -0.5}, {"simplify_mm": float("inf")}, {"shape": -0.1},
                                 {"shape": float("nan")}, {"importance_contrast": 0.5}, {"importance_contrast": True},
                                 {"true_scale": "yes"}, {"area": -1.0}, {"area": float("nan")},
                                 {"max_anisotropy": 1.0}, {"max_anisotropy": "round"}, {"max_anisotropy": True},
                                 {"max_anisotropy": float("nan")}])
def test_invalid_options_raise_one_line_errors(bad):
    with pytest.raises(InvalidOptionError) as err:
        RelaxOptions(**bad)
    assert "\n" not in str(err.value)


def test_mirrored_start_is_refused(vessel):
    mirrored = vessel.replace(uv=vessel.uv * np.array([-1.0, 1.0]))
    with pytest.raises(FoldedResultError):
        relax(mirrored)


def test_degenerate_start_is_untangled(vessel):
    uv = vessel.uv.copy()
    F = vessel.mesh.faces
    interior = np.setdiff1d(np.arange(len(uv)), _boundary_edges(F))
    i = interior[len(interior) // 2]
    f = F[np.nonzero((F == i).any(1))[0][0]]
    a, b = f[f != i]
    uv[i] = 0.5 * (uv[a] + uv[b])  # collinear: zero-area triangle in the start
    r = relax(vessel.replace(uv=uv), preset="preview")
    assert r.flipped == 0 and any("untangled" in n for n in r.notes)


def _boundary_edges(F):
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    u, c = np.unique(e, axis=0, return_counts=True)
    return u[c == 1]


def test_time_budget_and_callback_stop_early(vessel):
    r = relax(vessel, callback=lambda info: info["iteration"] >= 7)
    assert r.iterations == 7 and not r.converged and r.flipped == 0
    r = relax(vessel, time_budget=1e-9)
    assert r.iterations == 1 and not r.converged and any("time_budget" in n for n in r.notes)


# --- paper preset ------------------------------------------------------------------------------

def test_paper_preset_reports_flips_honestly(vessel):
    r = relax(vessel, preset="paper", max_iter=3000)
    assert r.settings.stretch == 2.0 and r.settings.stiffness == 0.5
    assert r.flipped == int(np.sum(signed_areas(r.flat.uv, vessel.mesh.faces) <= 0))
    assert r.levels[0].dt > 0 and np.all(np.isfinite(r.flat.uv))
    assert r.energy_history[-1] < r.energy_history[0]


# --- stage files and CLI ---------------------------------------------------------------------------

def _write_rollout(tmp_path, flat, name="pot"):
    from potflat.io.flat_ply import write_flat_ply

    path = tmp_path / f"{name}.rollout.ply"
    write_flat_ply(path, flat)
    (tmp_path / f"{name}.rollout.json").write_text(json.dumps({"axis": [0, 0, 1], "proxy": {"kind": "cylinder"}}))
    return path


def test_run_relax_stage_writes_ply_and_json(tmp_path, vessel):
    from potflat.io.flat_ply import read_flat_ply

    src = _write_rollout(tmp_path, vessel)
    out = run_relax_stage(src, tmp_path / "out", RelaxOptions(preset="preview"))
    assert out.paths["ply"] == tmp_path / "out" / "pot.relaxed.ply"
    back = read_flat_ply(out.paths["ply"])
    assert back.stress is not None and back.uv.shape == vessel.uv.shape
    js = json.loads(out.paths["json"].read_text())
    assert js["fold_free"] is True and js["flipped"] == 0 and js["boundary_overlap"] == 0
    assert js["axis"] == [0, 0, 1] and js["proxy"]["kind"] == "cylinder"
    assert js["provenance"]["stage"] == "relax" and len(js["energy_history"]) >= 1
    assert js["distortion"]["edge_rms"] < js["distortion_before"]["edge_rms"]
    turning = js["outline_turning"]  # the rollout's and the relaxed outline's, the same mesh
    assert turning["rollout"] >= 1.0 and turning["relaxed"] >= 1.0
    assert np.isclose(turning["ratio"], turning["relaxed"] / turning["rollout"])
    assert turning["surface"] >= 1.0


def test_the_relaxed_outline_keeps_the_turning_of_the_scan_s_border():
    """The bundled amphora: its painted frieze makes the plain surface soft, and without the
    outline term the relaxation bent that surface's border vertices in and out along the
    seam (relaxed turning 2.2 times the scan border's own); with it, within 1.5 times."""
    from potflat import load_scan
    from potflat.mesh.boundary import outline_turning, surface_turning
    from potflat.rollout import rollout

    flat = rollout(load_scan(SAMPLE).mesh).flat
    assert flat.importance is not None and flat.importance.min() < 0.5 < flat.importance.max()
    relaxed = relax(flat).flat
    border = surface_turning(flat.mesh.vertices, flat.mesh.faces)
    assert outline_turning(flat.mesh.faces, relaxed.uv) < 1.5 * border


def test_cli_relax(tmp_path, vessel):
    from potflat_cli.main import app
    from typer.testing import CliRunner

    src = _write_rollout(tmp_path, vessel, name="hydria")
    runner = CliRunner()
    res = runner.invoke(app, ["relax", str(src), "-o", str(tmp_path / "o"), "--preset", "preview"])
    assert res.exit_code == 0, res.output
    assert "fold-free" in res.output and (tmp_path / "o" / "hydria.relaxed.json").exists()
    assert "outline: turns" in res.output
    res = runner.invoke(app, ["relax", str(src), "--stiffness", "0"])
    assert res.exit_code == 2 and "stiffness" in res.output
    res = runner.invoke(app, ["relax", "--help"])
    assert res.exit_code == 0 and "Example" in res.output


def test_progress_bar_goes_to_stderr(vessel, capsys):
    r = relax(vessel, preset="preview", progress=True)
    assert r.flipped == 0 and capsys.readouterr().out == ""


def _notched_strip(gap):
    """A 7 x 5 vertex grid (unit spacing) with a notch one cell wide and two deep cut into
    its top; flattened with the notch narrowed to ``gap``."""
    xs, ys = np.meshgrid(np.arange(7.0), np.arange(5.0))
    V = np.stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)], axis=1)
    faces = []
    for r in range(4):
        for c in range(6):
            if c == 3 and r >= 2:
                continue  # the notch
            a, b, d, e = r * 7 + c, r * 7 + c + 1, (r + 1) * 7 + c, (r + 1) * 7 + c + 1
            faces += [(a, b, e), (a, e, d)]
    uv = V[:, :2].copy()
    uv[uv[:, 0] > 3.5, 0] -= 1.0 - gap
    return FlatMesh(Mesh(V, np.array(faces)), uv)


@pytest.mark.parametrize("weighted", [False, True])
def test_contact_barrier_matches_reference(weighted):
    """With importance weights each pair's barrier takes its three vertices' mean weight."""
    from potflat.relax.parameters import ENERGY

    strip = _notched_strip(0.3)
    weight = np.random.default_rng(3).uniform(0.001, 1.0, len(strip.uv)) if weighted else None
    sp = spring_system(strip.mesh.vertices, strip.mesh.faces, k=1.0, relative=True, weight=weight)
    x = np.ascontiguousarray(strip.uv)
    sp.guard_boundary(x)
    assert sp.contact
    E, _, g = sp.evaluate(x)
    sp.contact = False
    E0 = sp.evaluate(x)[0]
    want = ref.contact_energy(x, sp.boundary_segments, sp.bprev, sp.bnext, ENERGY.contact_gap, ENERGY.contact_mu,
                              weight)
    assert want > 0 and E - E0 == pytest.approx(want, rel=1e-10)
    sp.contact = True
    num = ref.numeric_gradient(lambda y: sp.evaluate(np.ascontiguousarray(y))[0], x)
    np.testing.assert_allclose(g, num, atol=1e-6 * np.abs(num).max())
    touching = x.copy()
    touching[strip.mesh.vertices[:, 0] > 3.5, 0] -= 0.3  # the notch closed: contact
    assert sp.evaluate(np.ascontiguousarray(touching))[0] == np.inf


def test_line_search_never_accepts_an_overlapping_boundary(vessel, monkeypatch):
    """A trial point the overlap test rejects is never accepted: here a virtual wall stops
    the vertex that moves most to the left halfway."""
    from potflat.relax import energy as relax_module

    real = relax_module.SpringSystem.overlap
    seen = []

    def record(self, x, max_pairs=1000):
        seen.append(x.copy())
        return real(self, x, max_pairs)

    monkeypatch.setattr(relax_module.SpringSystem, "overlap", record)
    free = relax(vessel, preset="standard")
    start, end = seen[0], seen[-1]
    v = int(np.argmin(end[:, 0] - start[:, 0]))
    wall = start[v, 0] + 0.5 * (end[v, 0] - start[v, 0])
    assert end[v, 0] < wall - 0.1

    def walled(self, x, max_pairs=1000):
        seen.append(x.copy())
        return 5 if x[v, 0] < wall else real(self, x, max_pairs)

    seen.clear()
    monkeypatch.setattr(relax_module.SpringSystem, "overlap", walled)
    r = relax(vessel, preset="standard")
    assert seen[-1][v, 0] >= wall  # the returned state
    assert r.levels[-1].boundary_contact and any("touched" in n for n in r.notes)
    assert energy_never_increases(r) and r.flipped == 0
    assert r.levels[-1].energy > free.levels[-1].energy


def test_untangle_fixes_flipped_interior_vertices():
    from potflat.relax.start import untangle

    flat, _ = meshes.cylinder_patch(12, 10, seed=4)
    F = flat.mesh.faces
    uv = flat.uv.copy()
    sp = spring_system(flat.mesh.vertices, F, k=1.0, relative=True)
    interior = np.setdiff1d(np.arange(len(uv)), _boundary_edges(F).ravel())
    for i in interior[[3, len(interior) // 2, -4]]:
        nb = np.unique(F[(F == i).any(1)])
        nb = nb[nb != i]
        uv[i] = 2.0 * uv[nb].mean(0) - uv[i] + 1.6 * (uv[nb[0]] - uv[i])  # pushed over its neighbour
    n0 = int((signed_areas(uv, F) <= 0).sum())
    assert n0 >= 3
    x, n_bad = untangle(sp, uv, rounds=10)
    assert n_bad == n0 and int((signed_areas(x, F) <= 0).sum()) == 0
    moved = np.nonzero((x != uv).any(1))[0]
    assert 0 < len(moved) < len(uv) // 4  # only the tangled region moved


@pytest.mark.parametrize("seed", range(3))
def test_untangle_looks_only_around_its_region_and_matches_its_definition(seed):
    """Untangling checks only the faces around the vertices it moves; every round ends where
    the reference, which looks at every face in every round, ends, to the last bit, also for
    a tangle that outlasts the widening every 20 rounds and with ears among the faces."""
    from potflat.relax.start import untangle

    flat = meshes.vessel_rollout(900, seed=seed)
    F = flat.mesh.faces
    uv = flat.uv.copy()
    centre = uv[len(uv) // 2]
    near = np.linalg.norm(uv - centre, axis=1)
    patch = near < np.quantile(near, 0.2)
    uv[patch, 0] = 2.0 * centre[0] - uv[patch, 0]  # mirrored: untangled after 20-40 rounds
    sp = spring_system(flat.mesh.vertices, F, k=1.0, relative=True)
    assert (np.diff(sp.vf_ptr) == 1).any()
    for rounds in (1, 19, 20, 39, 200):
        x, n_bad = untangle(sp, uv, rounds=rounds)
        want, want_bad = ref.relax_untangle(sp, uv, rounds=rounds)
        assert n_bad == want_bad
        np.testing.assert_array_equal(x, want)
    assert (sp.signed_areas(untangle(sp, uv)[0]) > 0).all()


def _saddle_fan(K=12, flat_gap=1.0):
    """An open fan around vertex 0 whose 3D angle sum (8.67 rad) exceeds 2 pi, laid out flat
    with angle sum ``2 pi - flat_gap``: its springs pull the fan to wrap over itself."""
    a = np.arange(K + 1) * (2 * np.pi - 0.2) / K
    V = np.zeros((K + 2, 3))
    V[1:] = np.c_[np.cos(a), np.sin(a), 0.5 * np.sin(4 * a)]
    F = np.array([[0, k + 1, k + 2] for k in range(K)])
    b = np.arange(K + 1) * (2 * np.pi - flat_gap) / K
    uv = np.zeros((K + 2, 2))
    uv[1:] = np.c_[np.cos(b), np.sin(b)]
    return FlatMesh(Mesh(V, F), uv)


def _angle_sum(uv, F, b=0):
    theta = 0.0
    for f in F[(F == b).any(1)]:
        j = list(f).index(b)
        u, w = uv[f[(j + 1) % 3]] - uv[b], uv[f[(j + 2) % 3]] - uv[b]
        theta += np.arctan2(u[0] * w[1] - u[1] * w[0], u @ w)
    return theta


@pytest.mark.parametrize("weighted", [False, True])
def test_boundary_angle_barrier_and_outline_term_match_reference(weighted):
    """With importance weights a guarded vertex's barrier takes its own weight; the outline
    term holds every guarded vertex's angle sum to the surface's (short of the barrier's
    reach), whatever its weight."""
    from potflat.relax.parameters import ENERGY

    fan = _saddle_fan(flat_gap=0.15)  # the centre's gap 0.15 < ENERGY.boundary_gap: its barrier is on
    V, F = fan.mesh.vertices, fan.mesh.faces
    weight = np.random.default_rng(5).uniform(0.3, 1.0, len(V)) if weighted else None
    sp = spring_system(V, F, k=0.8, relative=True, weight=weight)
    x = np.ascontiguousarray(fan.uv)
    assert sp.guard_boundary(x) == 0 and sp.bguard.all()
    E, Es, g = sp.evaluate(x)
    boundary = np.arange(len(V))
    want = ref.boundary_angle_barrier(x, F, boundary, 0.8, ENERGY.boundary_mu, ENERGY.boundary_gap, weight)
    want += ref.barrier_energy(x, F, sp.a_ref, 0.8, ENERGY.barrier_mu, ENERGY.barrier_eps, relative=True,
                               weight=weight)
    want += ref.contact_energy(x, sp.boundary_segments, sp.bprev, sp.bnext, ENERGY.contact_gap,
                               0.8 * ENERGY.contact_mu, weight)
    outline = ref.outline_energy(x, V, F, boundary, 0.8, ENERGY.outline_mu, 2 * np.pi - ENERGY.boundary_gap)
    assert want > 0.3 * (0.3 if weighted else 1.0) and outline > 0.01
    assert E - Es == pytest.approx(want + outline, rel=1e-10)
    assert E - sp.evaluate(x, outline=False)[0] == pytest.approx(outline, rel=1e-8)
    num = ref.numeric_gradient(lambda y: sp.evaluate(np.ascontiguousarray(y))[0], x)
    np.testing.assert_allclose(g, num, atol=1e-6 * np.abs(num).max())


def test_boundary_max_step_stops_before_the_fan_wraps():
    gap = 0.3
    fan = _saddle_fan(flat_gap=gap)
    F = fan.mesh.faces
    sp = spring_system(fan.mesh.vertices, F, k=1.0, relative=True)
    x = np.ascontiguousarray(fan.uv)
    d = np.zeros_like(x)
    d[-1] = (0.0, 1.0)  # the last rim vertex (angle 2 pi - gap) moves up across the first one's ray
    assert sp.boundary_step(x, d, sp.max_face_step(x, d), 1.0) == np.inf  # no face flips, nothing guarded yet
    sp.guard_boundary(x)
    t = sp.boundary_step(x, d, sp.max_face_step(x, d), 1.0)
    assert t == pytest.approx(np.sin(gap), rel=1e-12)  # where the two boundary edges align
    assert _angle_sum(x + 0.999 * t * d, F) < 2 * np.pi < _angle_sum(x + 1.001 * t * d, F)
    assert sp.evaluate(np.ascontiguousarray(x + 1.001 * t * d))[0] == np.inf


def _facing_triangles(gap):
    """Two separate triangles, the tip of the second ``gap`` to the right of the first's
    vertical edge (its foot half way along it): positions (6, 2), boundary segments and
    boundary neighbours."""
    x = np.array([[0.0, 0.0], [-1.0, 0.5], [0.0, 1.0], [gap, 0.5], [gap + 1.0, 1.0], [gap + 1.0, 0.0]])
    seg = np.array([[0, 1], [1, 2], [2, 0], [3, 4], [4, 5], [5, 3]])
    bprev = np.array([2, 0, 1, 5, 3, 4], np.int32)
    bnext = np.array([1, 2, 0, 4, 5, 3], np.int32)
    return x, seg, bprev, bnext


@pytest.mark.parametrize("shrink", [1.0, 0.8, 0.3])
def test_contact_max_step_lets_a_pair_lose_at_most_its_share_of_distance(shrink):
    """The tip moving straight at the edge may close ``shrink`` of its gap; moving along it,
    or from beyond the barrier's reach, it is not held; a pair whose foot falls outside its
    segment is not bounded."""
    from potflat.relax._kernels.overlap import contact_max_step

    gap, dhat = 0.3, 0.5
    x, seg, bprev, bnext = _facing_triangles(gap)
    towards = np.zeros_like(x)
    towards[3:] = (-1.0, 0.0)  # the second triangle moves left, into the first
    t = contact_max_step(x, towards, seg, bprev, bnext, dhat, 1.0, np.inf, shrink)
    assert t == pytest.approx(shrink * gap, rel=1e-12)
    along = np.zeros_like(x)
    along[3:] = (0.0, 0.2)
    assert contact_max_step(x, along, seg, bprev, bnext, dhat, 1.0, np.inf, shrink) == np.inf
    assert contact_max_step(x, towards, seg, bprev, bnext, dhat, 1.0, 0.05, shrink) == 0.05  # the cap
    far, *_ = _facing_triangles(0.6)  # beyond dhat: the barrier does not act, nor does the bound
    assert contact_max_step(far, towards, seg, bprev, bnext, dhat, 1.0, np.inf, shrink) == np.inf
    high = x.copy()
    high[3:, 1] += 0.7  # the tip's foot above the edge's end
    assert contact_max_step(high, towards, seg, bprev, bnext, dhat, 1.0, np.inf, shrink) == np.inf


def test_following_a_coarse_copy_uncrosses_a_wrapped_boundary(monkeypatch):
    """A layout followed from a coarse copy whose boundary wraps over itself at one vertex
    (angle sum 2 pi + 0.6, every face positive) is moved back to a fold-free, uncrossed
    start; with no repair rounds the copy is given up (None, and a note says so)."""
    from dataclasses import replace

    from potflat.relax import start as relax_module

    fan = _saddle_fan(flat_gap=-0.6)
    F = fan.mesh.faces
    sp = spring_system(fan.mesh.vertices, F, k=1.0, relative=True)
    x = np.ascontiguousarray(fan.uv)
    assert sp.overlap(x) > 0 and (signed_areas(x, F) > 0).all()
    notes: list[str] = []
    y = relax_module.follow(sp, x, x, notes)
    assert y is not None and sp.overlap(y) == 0 and (signed_areas(y, F) > 0).all()
    assert _angle_sum(y, F) < 2 * np.pi and "cross itself" in notes[0]
    monkeypatch.setattr(relax_module, "COARSE", replace(relax_module.COARSE, follow_repair_rounds=0))
    notes.clear()
    assert relax_module.follow(sp, x, x, notes) is None and "from the rollout" in notes[-1]


def _grid(k=12):
    """A ``k`` x ``k`` vertex grid of unit squares (two triangles each), flat in 3D: the rest
    positions (n, 3), faces (m, 3) and its fold-free layout (n, 2)."""
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing="xy")
    x = np.stack([i.ravel(), j.ravel()], axis=1).astype(float)
    a = (np.arange(k - 1)[None, :] + k * np.arange(k - 1)[:, None]).ravel()
    F = np.concatenate([np.stack([a, a + 1, a + k + 1], axis=1), np.stack([a, a + k + 1, a + k], axis=1)])
    return np.c_[x, np.zeros(len(x))], F, x


def test_a_local_relaxation_keeps_clear_of_the_boundary_around_it():
    """A squeezed block at the edge of one prong of a slit grid (a slit one unit wide), whose
    rest is 2.5 times as wide as it is laid out, pushes that prong's edge across the slit
    when relaxed with the rest fixed: the other prong's boundary is outside the patch, yet
    the whole mesh's contact barrier keeps the edge off it (without it the edge comes within
    3e-13 of the other prong)."""
    from potflat.relax.local import relax_extremes
    from potflat.relax.parameters import ENERGY

    V, F, x0 = _grid(16)
    centre = x0[F].mean(axis=1)
    F = F[~((centre[:, 0] > 7) & (centre[:, 0] < 8) & (centre[:, 1] > 2))]  # every vertex stays used
    block = (x0[:, 0] >= 5) & (x0[:, 0] <= 7) & (x0[:, 1] >= 9) & (x0[:, 1] <= 12)
    V[block, 0] = 5 + 2.5 * (x0[block, 0] - 5)
    x = x0.copy()
    x[block, 0] = 5 + 0.3 * (x0[block, 0] - 5)
    sp = spring_system(V, F, k=1.0, relative=True, shape=1.0, area=1.0)
    sp.set_area_and_limit(1.0, 1.2)
    assert (signed_areas(x, F) > 0).all() and sp.overlap(x) == 0
    sp.guard_boundary(x)
    notes: list[str] = []
    y = relax_extremes(sp, x, V, notes)
    assert notes and (signed_areas(y, F) > 0).all() and sp.overlap(y) == 0
    seg = sp.boundary_segments
    right = seg[(x0[seg, 0] >= 8).all(axis=1) & (x0[seg, 1] >= 2).all(axis=1)]
    left = np.flatnonzero(sp.boundary & (x0[:, 0] <= 7) & (x0[:, 1] >= 2))
    a, b = y[right[:, 0]][None], y[right[:, 1]][None]
    p = y[left][:, None]
    t = np.clip(((p - a) * (b - a)).sum(-1) / ((b - a) ** 2).sum(-1), 0.0, 1.0)
    gap = np.linalg.norm(a + t[..., None] * (b - a) - p, axis=-1).min()
    assert y[left, 0].max() > 7.5 and gap > 0.05 * ENERGY.contact_gap


def _narrow_slit(width=0.4):
    """The 16 x 16 grid of :func:`_grid` with a slit up from row 2 between columns 7 and 8,
    the right prong laid out so that the slit is ``width`` wide (its rest one unit wide) and
    a third of a row higher (no vertex level with one across): rest positions, faces and the
    layout."""
    V, F, x0 = _grid(16)
    centre = x0[F].mean(axis=1)
    F = F[~((centre[:, 0] > 7) & (centre[:, 0] < 8) & (centre[:, 1] > 2))]
    x = x0.copy()
    right = x0[:, 0] >= 8
    x[right, 0] -= 1.0 - width  # the base's squares between the prongs squeezed and sheared
    x[right, 1] += 1.0 / 3.0
    return V, F, x


def _push_into_slit(x):
    """A direction pressing the right prong's edge into the slit around its middle (row 10)."""
    d = np.zeros_like(x)
    d[:, 0] = -np.exp(-((x[:, 0] - 7.4) ** 2 + (x[:, 1] - 10) ** 2) / 8) * (x[:, 0] > 7.2)
    return d


def test_boundary_limits_are_the_constraints_holding_the_step():
    """The fan's apex turning to 2 pi is listed with its bound; a prong pressed into a slit
    gives the pairs that lose their share of distance (times the segment's length) at their
    bounds; the least bound is
    the boundary's step bound, and scaling a constraint's three vertices' moves by ``s``
    moves its bound to ``t / s``."""
    from potflat.relax.parameters import ENERGY

    gap, shrink = 0.3, 0.8
    fan = _saddle_fan(flat_gap=gap)
    sp = spring_system(fan.mesh.vertices, fan.mesh.faces, k=1.0, relative=True)
    x = np.ascontiguousarray(fan.uv)
    sp.guard_boundary(x)
    d = np.zeros_like(x)
    d[-1] = (0.0, 1.0)  # (as in the test above: the apex's angle sum reaches 2 pi at sin(gap))
    trios, bounds = sp.boundary_limits(x, d, 10.0, shrink)
    apex = np.flatnonzero(trios[:, 0] == 0)
    assert len(apex) == 1 and set(trios[apex[0], 1:]) == {sp.bprev[0], sp.bnext[0]}
    assert bounds[apex[0]] == pytest.approx(np.sin(gap), rel=1e-12)
    assert bounds.min() == sp.boundary_step(x, d, 10.0, shrink)

    V, F, x = _narrow_slit()
    sp = spring_system(V, F, k=1.0, relative=True)
    sp.guard_boundary(x)
    d = _push_into_slit(x)
    trios, bounds = sp.boundary_limits(x, d, 10.0, shrink)
    assert len(bounds) > 3 and (bounds < 10.0).all()
    assert bounds.min() == sp.boundary_step(x, d, 10.0, shrink)

    def distance(y, v, a, b):  # times the segment's length: twice the area of the pair's triangle
        e, r = y[b] - y[a], y[v] - y[a]
        return abs(e[0] * r[1] - e[1] * r[0])

    for (v, a, b), t in zip(trios, bounds, strict=True):
        assert distance(x, v, a, b) < ENERGY.contact_gap * np.linalg.norm(x[b] - x[a])
        assert distance(x + 0.999 * t * d, v, a, b) > (1 - shrink) * distance(x, v, a, b) > distance(
            x + 1.001 * t * d, v, a, b)
    k = int(np.argmin(bounds))
    slower = d.copy()
    slower[trios[k]] *= 0.5
    again, later = sp.boundary_limits(x, slower, 10.0, shrink)
    row = np.flatnonzero((again == trios[k]).all(axis=1))[0]
    assert later[row] == pytest.approx(2 * bounds[k], rel=1e-9)


def test_a_local_relaxation_lists_the_whole_boundary_s_contact_pairs():
    """A patch of the right prong lists the pairs the whole mesh lists for the same moves,
    its vertices in its own numbering and the fixed ones outside it as -1."""
    from potflat.relax.local import _Patch

    V, F, x = _narrow_slit()
    sp = spring_system(V, F, k=1.0, relative=True)
    sp.guard_boundary(x)
    d = _push_into_slit(x)
    inside = np.flatnonzero((x[F].mean(axis=1)[:, 0] > 7.2) & (np.abs(x[F].mean(axis=1)[:, 1] - 10) < 3))
    vertices = np.unique(F[inside]).astype(np.int64)
    free = np.zeros(sp.n, bool)
    free[vertices] = True
    d[~free] = 0.0  # (the patch's fixed vertices do not move)
    patch = _Patch(sp, V, inside, vertices, free, x.copy())
    want, want_bounds = sp._contact_limits(x, d, 10.0, 0.8)
    got, bounds = patch._contact_limits(np.ascontiguousarray(x[vertices]), np.ascontiguousarray(d[vertices]),
                                        10.0, 0.8)
    assert len(got) == len(want) > 0 and (got == -1).any() and (got >= 0).any()
    np.testing.assert_array_equal(bounds, want_bounds)
    np.testing.assert_array_equal(np.where(got >= 0, vertices[np.maximum(got, 0)], -1),
                                  np.where(free[want], want, -1))


def test_ease_scales_matches_a_shortest_path_reference():
    """The scales are the sources' values plus the shortest path over the neighbour lists,
    each edge as long as its length over ``width t`` times its ends' larger move (at most 1);
    the lowered vertices are listed once each; the search stops past ``max_visit``."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    from potflat.relax._kernels.steps import ease_scales

    V, F, x = _grid(10)
    sp = spring_system(V, F, k=1.0, relative=True)
    rng = np.random.default_rng(5)
    d = rng.normal(size=x.shape)
    sources = np.array([12, 13, 57], np.int64)
    values = np.array([0.1, 0.3, 0.05])
    t, width = 0.7, 2.0
    scale = np.ones(sp.n)
    lowered = ease_scales(x, d, sp.ptr, sp.nbr, sources, values, t, width, sp.n, scale)
    u = np.repeat(np.arange(sp.n), np.diff(sp.ptr))
    v = sp.nbr.astype(np.int64)
    move = np.linalg.norm(d, axis=1)
    w = np.linalg.norm(x[u] - x[v], axis=1) / (width * t * np.maximum(move[u], move[v]))
    n = sp.n  # one more node: the sources' common start
    graph = coo_matrix((np.r_[w, values], (np.r_[u, np.full(3, n)], np.r_[v, sources])), shape=(n + 1, n + 1))
    want = np.minimum(dijkstra(graph.tocsr(), indices=n)[:n], 1.0)
    np.testing.assert_allclose(scale, want, rtol=1e-12, atol=1e-15)
    assert 0 < len(lowered) < sp.n and sorted(lowered) == sorted(np.flatnonzero(want < 1.0))
    scale[:] = 1.0
    assert len(ease_scales(x, d, sp.ptr, sp.nbr, sources, values, t, width, 5, scale)) > 5


def test_easing_the_direction_frees_a_step_held_at_the_boundary(monkeypatch):
    """A direction pressing one prong of a slit into the other: the contact bound holds the
    whole step to a fraction of what the faces allow; eased, the direction still descends,
    the step is the faces' (the pressing vertices' moves scaled down, everything away from
    them unchanged) and keeps every face, angle sum and contact pair within its bound."""
    import dataclasses

    import potflat.relax.lbfgs as rx
    from potflat.relax.lbfgs import LBFGS

    SOLVER = dataclasses.replace(rx.SOLVER, smooth_max_fraction=0.5)  # (a small mesh)
    monkeypatch.setattr(rx, "SOLVER", SOLVER)
    V, F, x = _narrow_slit()
    sp = spring_system(V, F, k=1.0, relative=True)
    sp.guard_boundary(x)
    solver = LBFGS(sp, x)
    d = _push_into_slit(x)
    solver.q[:] = d.ravel()
    solver.g = -solver.q.copy()  # (a descent direction)
    gd = float(solver.g @ solver.q)
    t_faces = sp.max_face_step(x, d, cap=1.0 / SOLVER.step_fraction, shrink=SOLVER.step_shrink)
    t = sp.boundary_step(x, d, t_faces, SOLVER.step_shrink)
    assert t < 0.5 * t_faces
    t_eased, gd_eased = solver._ease_boundary(t, t_faces, gd)
    eased = solver.q.reshape(-1, 2)
    assert t_eased == t_faces and solver.eased == 1 and gd_eased < 0.0
    assert gd_eased == pytest.approx(float(solver.g @ solver.q), rel=1e-12)
    assert sp.boundary_step(x, eased, t_faces, SOLVER.step_shrink) == t_faces
    assert sp.max_face_step(x, eased, cap=t_faces, shrink=SOLVER.step_shrink) == t_faces
    changed = np.flatnonzero((eased != d).any(axis=1))
    assert 0 < len(changed) < sp.n // 4 and (np.abs(eased[changed]) <= np.abs(d[changed])).all()
    assert (solver._scale == 1.0).all()  # the work space is left as found


def test_easing_the_direction_frees_a_step_held_by_a_sliver(monkeypatch):
    """A grid with one vertex pushed up against the row above (its two faces there slivers a
    tenth of a unit high) and a direction moving everything by a smooth shear and that vertex
    on into the row: its slivers hold the whole step to under a tenth of the natural one;
    eased, the direction still descends further, the step is the natural one (the vertex's
    move scaled down with its neighbours', everything away from it unchanged) and keeps
    every face within its bound."""
    import dataclasses

    import potflat.relax.lbfgs as rx
    from potflat.relax.lbfgs import LBFGS

    SOLVER = dataclasses.replace(rx.SOLVER, smooth_max_fraction=0.5)  # (a small mesh)
    monkeypatch.setattr(rx, "SOLVER", SOLVER)
    V, F, x = _grid(16)
    tip = 8 * 16 + 8
    x[tip, 1] += 0.9
    sp = spring_system(V, F, k=1.0, relative=True)
    sp.guard_boundary(x)
    solver = LBFGS(sp, x)
    d = np.c_[0.05 * x[:, 1], np.zeros(len(x))]
    d[tip, 1] = 1.0
    solver.q[:] = d.ravel()
    solver.g = -solver.q.copy()  # (a descent direction)
    gd = float(solver.g @ solver.q)
    cap = 1.0 / SOLVER.step_fraction
    t = sp.max_face_step(x, d, cap=cap, shrink=SOLVER.step_shrink, limiting=solver._limiting)
    assert t < 0.1 * cap and 0 < solver._limiting.sum() <= 6
    t_eased, gd_eased = solver._ease_faces(t, gd, solver._limiting_vertices())
    eased = solver.q.reshape(-1, 2)
    assert t_eased == cap and solver.eased == 1 and gd_eased < 0.0 and t_eased * gd_eased < t * gd
    assert gd_eased == pytest.approx(float(solver.g @ solver.q), rel=1e-12)
    assert sp.max_face_step(x, eased, cap=cap, shrink=SOLVER.step_shrink) == cap
    changed = np.flatnonzero((eased != d).any(axis=1))
    assert tip in changed and len(changed) < sp.n // 8
    assert (np.abs(eased[changed]) <= np.abs(d[changed])).all()
    assert (solver._scale == 1.0).all()  # the work space is left as found


@pytest.mark.parametrize("centre", [(7, 7), (7, 1)], ids=["inside", "at the boundary"])
def test_extreme_faces_of_a_start_are_relaxed_locally(centre):
    """Faces squeezed to anisotropy 23 in a fold-free layout (a 3 x 3 block of vertices
    squeezed to 8% of its height, inside the grid or with the grid's bottom edge) are relaxed
    with the vertices more than the rings around them fixed: the energy drops, the squeeze
    is undone, the layout stays fold-free and its boundary uncrossed; a layout without an
    extreme face is returned as it is."""
    from potflat.mesh.distortion import face_distortion
    from potflat.relax.local import relax_extremes
    from potflat.relax.parameters import COARSE

    V, F, x0 = _grid(16)
    sp = spring_system(V, F, k=1.0, relative=True, shape=1.0, area=1.0)
    sp.set_area_and_limit(1.0, 1.2)
    x = x0.copy()
    block = (np.abs(x0[:, 0] - centre[0]) <= 1) & (np.abs(x0[:, 1] - centre[1]) <= 1)
    x[block, 1] = centre[1] + 0.08 * (x0[block, 1] - centre[1])
    before = face_distortion(V, x, F).anisotropy
    assert (signed_areas(x, F) > 0).all() and before.max() > 20
    sp.guard_boundary(x)
    notes: list[str] = []
    y = relax_extremes(sp, x, V, notes)
    after = face_distortion(V, y, F).anisotropy
    assert len(notes) == 1 and "anisotropy above" in notes[0]
    assert sp.evaluate(y)[0] < sp.evaluate(x)[0] and after.max() < 2.0
    assert (signed_areas(y, F) > 0).all() and sp.overlap(y) == 0
    extreme_vertices = np.unique(F[before > COARSE.local_anisotropy])
    reach = np.abs(x0[extreme_vertices] - centre).max() + COARSE.local_rings  # (a ring: one step in x or y)
    far = np.abs(x0 - centre).max(axis=1) > reach
    assert np.array_equal(y[far], x[far]) and not np.array_equal(y[~far], x[~far])
    notes.clear()
    assert relax_extremes(sp, x0, V, notes) is x0 and not notes
    sp.fixed = far  # a spring system's fixed vertices: zero gradient rows
    assert not sp.evaluate(x)[2][far].any() and sp.evaluate(x)[2][~far].any()


def _folded_goal(x, k, c):
    """``x`` turned, stretched and moved, with vertex ``c`` pulled 2.5 edges across its
    neighbours (its fan folds), and the corner vertex 0 pulled below the bottom edge's far
    end (the boundary crosses itself)."""
    angle = 0.3
    rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
    goal = x @ rot.T * 1.2 + (5.0, -2.0)
    goal[c] += 2.5 * 1.2 * rot[:, 0]
    goal[0] = goal[k - 2] - 0.5 * 1.2 * rot[:, 1] - 0.2 * 1.2 * rot[:, 0]
    return np.ascontiguousarray(goal)


def test_approach_stops_short_only_around_the_folds():
    """The fold-free start moves to a followed layout that folds a vertex's fan and crosses
    its boundary: no face flips or falls below its floor, the boundary does not cross, and
    every vertex away from the fold and the crossing ends exactly where the followed layout
    has it."""
    from potflat.relax.start import approach

    k = 12
    V, F, x = _grid(k)
    c = 6 * k + 5
    goal = _folded_goal(x, k, c)
    sp = spring_system(V, F, k=1.0, relative=True)
    assert (signed_areas(goal, F) <= 0).any() and sp.overlap(goal) > 0
    y, short = approach(sp, x, goal)
    assert (signed_areas(y, F) > 0).all() and sp.overlap(y) == 0
    away = (np.abs(x - x[c]).max(axis=1) > 4) & (np.abs(x - x[0]).max(axis=1) > k - 2)
    assert np.array_equal(y[away], goal[away])
    assert 0 < short <= (~away).sum()


def _no_repair(faces, uv, reference=None, max_rings=0):
    return uv, 0, int((signed_areas(uv, faces) <= 0).sum())


def _folded_follow(monkeypatch, *, repair: bool, **coarse):
    """A 12 x 12 grid's start, a followed layout that folds a fan and crosses the boundary
    (:func:`_folded_goal`), its spring system, and ``follow`` with untangling that does
    nothing (re-embedding too unless ``repair``; ``coarse``: COARSE fields to set)."""
    from dataclasses import replace

    from potflat.relax import start as relax_module

    k = 12
    V, F, x = _grid(k)
    goal = _folded_goal(x, k, 6 * k + 5)
    sp = spring_system(V, F, k=1.0, relative=True)
    monkeypatch.setattr(relax_module, "untangle", lambda sp, x, rounds: (x, int((sp.signed_areas(x) <= 0).sum())))
    if not repair:
        monkeypatch.setattr(relax_module, "repair_folds", _no_repair)
    monkeypatch.setattr(relax_module, "COARSE", replace(relax_module.COARSE, **coarse))
    return F, x, goal, sp, relax_module.follow


def test_following_re_embeds_the_folds_untangling_leaves(monkeypatch):
    """Where untangling the followed layout leaves folds, each folded cluster is re-embedded
    in the start's shape inside its surroundings: the full mesh follows the copy exactly away
    from them, and no vertex stops short."""
    F, x, goal, sp, follow = _folded_follow(monkeypatch, repair=True)
    notes: list[str] = []
    y = follow(sp, x, goal, notes)
    assert y is not None and (signed_areas(y, F) > 0).all() and sp.overlap(y) == 0
    assert "re-embedded" in notes[-1] and not any("stop short" in n for n in notes)
    moved = np.flatnonzero((y != goal).any(axis=1))
    assert 0 < len(moved) < 0.5 * len(x)


def test_following_keeps_the_copy_where_untangling_leaves_folds(monkeypatch):
    """Where untangling the followed layout leaves folds, the full mesh still follows the
    copy (fold-free, boundary uncrossed, a note says how many vertices stopped short) rather
    than giving it up (on a grid this small the few vertices stopped short are a large share:
    the share that gives the copy up is lifted)."""
    F, x, goal, sp, follow = _folded_follow(monkeypatch, repair=False, approach_most_short=1.0)
    notes: list[str] = []
    y = follow(sp, x, goal, notes)
    assert y is not None and (signed_areas(y, F) > 0).all() and sp.overlap(y) == 0
    assert "stop short" in notes[-1]


def test_following_gives_the_copy_up_where_too_many_vertices_stop_short(monkeypatch):
    """Where more than ``approach_most_short`` of the vertices stop short of the followed
    layout, the copy is given up (the full mesh relaxes from the rollout), and a note says why."""
    F, x, goal, sp, follow = _folded_follow(monkeypatch, repair=False, approach_most_short=0.0)
    notes: list[str] = []
    assert follow(sp, x, goal, notes) is None
    assert "stop short" in notes[-2] and "relaxed the full mesh from the rollout" in notes[-1]


def test_boundary_vertex_with_a_large_angle_sum_does_not_wrap(monkeypatch):
    from potflat.relax import energy as relax_module

    fan = _saddle_fan()
    r = relax(fan, preset="standard")
    assert r.boundary_overlap == 0 and r.flipped == 0 and not r.notes
    assert r.levels[-1].level == "fine" and r.levels[-1].iterations > 0
    assert 5.5 < _angle_sum(r.flat.uv, fan.mesh.faces) < 2 * np.pi
    # without the guard (and the contact barrier it switches on) the springs drive the fan
    # to wrap: only the line search's overlap test stops them
    monkeypatch.setattr(relax_module.SpringSystem, "guard_boundary", lambda self, x: 0)
    r = relax(fan, preset="standard")
    assert any("touched" in n for n in r.notes) and r.boundary_overlap == 0


def test_a_boundary_left_touching_itself_is_not_a_crossing_after_the_final_turn(tmp_path):
    """The solve may leave a boundary vertex on a segment of the boundary to within rounding
    (touching, which the line search allows); the final rigid turn to the rollout's orientation
    then made that pair test as crossing, and relax refused its own fold-free result. Seen on
    the painted-figures benchmark's aryballos panel with ``max_anisotropy`` 1.3."""
    from potflat_synthetic.vessels import make_vessel, write_obj

    from potflat.io.scan import load_scan
    from potflat.rollout import rollout

    vessel = make_vessel("aryballos", n_vertices=40000, seed=0, painting="panel", texture_size=2048)
    rolled = rollout(load_scan(write_obj(vessel, tmp_path / "aryballos.obj")).mesh)
    result = relax(rolled.flat, max_anisotropy=1.3)  # raised FoldedResultError: 1 boundary crossing
    assert result.flipped == 0 and result.boundary_overlap == 0


def test_untangle_keeps_a_small_island_open():
    """A piece of two triangles apart from the rest (as a rollout's trimming leaves them),
    one of them folded: averaging each of its vertices over its neighbours pulls the piece
    together into a line (no vertex of it is held), and the fold stays; mirroring each
    folded ear (a triangle whose tip is on no other face) about its base unfolds it."""
    from potflat.relax.start import untangle

    flat, _ = meshes.cylinder_patch(6, 5, seed=2)
    n = len(flat.uv)
    quad = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    V = np.vstack([flat.mesh.vertices, np.c_[quad + [5.0, 0.0], np.zeros(4)]])
    F = np.vstack([flat.mesh.faces, [[n, n + 1, n + 2], [n, n + 2, n + 3]]])
    island = quad + [5.0, 0.0]
    island[3] = [1.2, 0.6] + np.array([5.0, 0.0])  # the second triangle's tip across the diagonal
    uv = np.vstack([flat.uv, island])
    assert (signed_areas(uv, F) <= 0).tolist() == [False] * (len(F) - 1) + [True]
    sp = spring_system(V, F, k=1.0, relative=True)
    x, n_bad = untangle(sp, uv)
    assert n_bad == 1 and (signed_areas(x, F) > 0).all()
    assert np.array_equal(x[:n], uv[:n])


def test_a_given_up_coarse_copy_leaves_its_anisotropy_limit_behind(vessel, monkeypatch):
    """The anisotropy limit a relaxed coarse copy found fits the copy's relaxed layout; when
    following the copy fails, the full mesh starts from the rollout and finds its own limit
    (a first solve without the area term) instead of paying the copy's limit over nearly
    every face of the unrelaxed rollout (1M dragon jar: steps held to 0.0017 of the natural
    one, stopped after 118 iterations at a higher edge-length RMS than the rollout's)."""
    from dataclasses import replace

    from potflat.relax import multilevel

    monkeypatch.setattr(multilevel, "COARSE", replace(multilevel.COARSE, min_vertices=1000))
    kept = relax(vessel, preset="standard")
    assert [lv.level for lv in kept.levels if lv.level.startswith("fine")] == ["fine"]  # the copy's limit
    monkeypatch.setattr(multilevel, "follow", lambda sp, x, target, notes: notes.append("given up") or None)
    given_up = relax(vessel, preset="standard")
    assert "given up" in given_up.notes and given_up.flipped == 0
    assert [lv.level for lv in given_up.levels] == ["fine, shape first", "fine"]


def test_a_copy_whose_followed_layout_starts_higher_than_the_rollout_is_given_up(vessel, monkeypatch):
    """A relaxed coarse copy is the full mesh's start only where the followed layout's energy
    is at most ``COARSE.follow_most_energy`` times the rollout's: one stretched to ten times
    the size is given up (a note says so), and the full mesh relaxes from the rollout with its
    own limit."""
    from dataclasses import replace

    from potflat.relax import multilevel

    monkeypatch.setattr(multilevel, "COARSE", replace(multilevel.COARSE, min_vertices=1000))
    kept = relax(vessel, preset="standard")
    assert not any("higher energy" in n for n in kept.notes)
    monkeypatch.setattr(multilevel, "follow", lambda sp, x, target, notes: 10.0 * x)
    given_up = relax(vessel, preset="standard")
    assert any("higher energy than the rollout's" in n for n in given_up.notes)
    assert [lv.level for lv in given_up.levels] == ["fine, shape first", "fine"] and given_up.flipped == 0
