"""Painted figures (issue: importance and the shape term): the weighted springs and the shape
term against references, importance found in the colours, masks and bands, true scale, the
zone figures and outline, and that importance makes a painted panel measurably truer."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
import reference as ref
from _bench_meshes import bumpy_patch, energy_never_increases, meshes, signed_areas, spring_system

from potflat import importance as imp
from potflat.mesh.distortion import face_distortion, important_faces, true_scale_factor, zone_figures
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.relax import relax
from potflat.types import FlatMesh, Mesh


@pytest.fixture(scope="module")
def bumpy():
    return bumpy_patch()


# --- the energy -----------------------------------------------------------------------------

@pytest.mark.parametrize("relative, shape, rigidity, area, limit", [
    (False, 0.3, 0.0, 0.0, None), (True, 0.3, 0.0, 0.0, None), (True, 0.3, 0.8, 0.0, None),
    (False, 0.0, 0.8, 0.0, None), (True, 0.3, 0.8, 1.5, None), (True, 0.0, 0.0, 1.5, 1.2), (True, 0.3, 0.8, 1.5, 1.2)])
def test_weighted_springs_and_shape_term_match_reference(bumpy, relative, shape, rigidity, area, limit):
    from potflat.relax.parameters import ENERGY

    V, F = bumpy.mesh.vertices, bumpy.mesh.faces
    pairs, rest = ref.springs(V, F)
    weight = np.random.default_rng(4).uniform(0.05, 1.0, len(V))
    sp = spring_system(V, F, k=0.7, relative=relative, weight=weight, shape=shape, rigidity=rigidity, area=area)
    sp.set_area_and_limit(area, limit)
    x = np.ascontiguousarray(bumpy.uv * np.array([1.1, 0.93]))
    E, Es, g = sp.evaluate(x, barrier=False)
    from potflat.mesh.distortion import face_areas

    mean_area = float(np.mean(face_areas(V, F)))
    if limit is not None:  # the test's layout must reach past the limit on some faces, not on all
        aniso = face_distortion(V, x, F).anisotropy
        assert 0 < np.count_nonzero(aniso > limit) < len(F)
    want = ref.weighted_spring_energy(x, pairs, rest, 0.7, relative, weight) + ref.shape_energy(
        V, F, x, weight, shape / mean_area, rigidity / mean_area, area / mean_area,
        None if limit is None else (ENERGY.limit_mu / mean_area, limit), ENERGY.area_eps)
    assert Es == pytest.approx(want, rel=1e-10)
    num = ref.numeric_gradient(lambda y: sp.evaluate(np.ascontiguousarray(y), barrier=False)[0], x)
    np.testing.assert_allclose(g, num, atol=1e-6 * np.abs(num).max())


def test_shape_term_is_zero_for_a_similarity_and_infinite_when_folded():
    flat, exact = meshes.cylinder_patch(6, 5, seed=2)
    F = flat.mesh.faces
    V = np.column_stack([exact, np.zeros(len(exact))])  # a plane: ``exact`` is its isometric layout
    sp = spring_system(V, F, k=1.0, relative=True, shape=1.0)
    rot = np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
    for x in (exact, 2.5 * exact @ rot.T):  # isometric, then a similarity: no shape energy
        spring_free = spring_system(V, F, k=1.0, relative=True)
        e_shape = sp.evaluate(np.ascontiguousarray(x), barrier=False)[1] - spring_free.evaluate(
            np.ascontiguousarray(x), barrier=False)[1]
        assert abs(e_shape) < 1e-9
    sheared = np.ascontiguousarray(exact @ np.array([[1.0, 0.4], [0.0, 1.0]]).T)
    assert sp.evaluate(sheared, barrier=False)[1] > spring_free.evaluate(sheared, barrier=False)[1] + 1e-3
    folded = np.ascontiguousarray(exact * np.array([-1.0, 1.0]))
    assert sp.evaluate(folded, barrier=False)[1] == np.inf


def test_rigidity_term_is_zero_for_a_rotation_and_charges_a_uniform_scale():
    flat, exact = meshes.cylinder_patch(6, 5, seed=2)
    F = flat.mesh.faces
    V = np.column_stack([exact, np.zeros(len(exact))])
    rigid = spring_system(V, F, k=1.0, relative=True, rigidity=1.0)
    spring_free = spring_system(V, F, k=1.0, relative=True)
    rot = np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])

    def term(x):
        x = np.ascontiguousarray(x)
        return rigid.evaluate(x, barrier=False)[1] - spring_free.evaluate(x, barrier=False)[1]

    assert abs(term(exact @ rot.T)) < 1e-9
    # a uniform scale by 1.2: every face pays A ((1.2 - 1)^2 + (1.2 - 1)^2) per mean face area
    from potflat.mesh.distortion import face_areas

    areas = face_areas(V, F)
    assert term(1.2 * exact @ rot.T) == pytest.approx(2 * 0.04 * areas.sum() / areas.mean(), rel=1e-9)


def test_uniform_weights_reproduce_the_result_without_importance_exactly():
    flat = meshes.vessel_rollout(1500, seed=2)
    plain = relax(flat)
    ones = relax(flat.replace(importance=np.ones(len(flat.uv))))
    np.testing.assert_array_equal(plain.flat.uv, ones.flat.uv)
    np.testing.assert_array_equal(plain.energy_history, ones.energy_history)
    # contrast 1 weights nothing (the importance still says where true scale is measured)
    half = relax(flat.replace(importance=np.linspace(0, 1, len(flat.uv))), importance_contrast=1.0, true_scale=False)
    np.testing.assert_array_equal(relax(flat, true_scale=False).flat.uv, half.flat.uv)


def test_shape_term_keeps_figures_rounder_and_never_folds():
    flat = meshes.vessel_rollout(3000, seed=1)
    springs = relax(flat, shape=0.0, rigidity=0.0, area=0.0)
    shaped = relax(flat, shape=0.5, rigidity=0.0, area=0.0)
    rigid = relax(flat, shape=0.0, rigidity=2.0, area=0.0)
    for r in (springs, shaped, rigid):
        assert r.flipped == 0 and r.boundary_overlap == 0
        assert np.all(signed_areas(r.flat.uv, flat.mesh.faces) > 0)
        assert np.all(np.diff(r.energy_history[-r.levels[-1].iterations:]) <= 0)
    assert shaped.distortion.anisotropy_p95 < springs.distortion.anisotropy_p95 - 0.1
    assert rigid.distortion.anisotropy_p95 < springs.distortion.anisotropy_p95 - 0.1
    assert shaped.distortion.area_mean_abs_log > springs.distortion.area_mean_abs_log  # the trade


def test_area_term_gathers_area_distortion_within_the_anisotropy_of_a_solve_without_it():
    from potflat.mesh.distortion import weighted_percentile
    from potflat.relax.parameters import ENERGY

    flat = meshes.vessel_rollout(1500, seed=1)
    F = flat.mesh.faces
    without = relax(flat, area=0.0)
    r = relax(flat)  # the default: the area term, its limit found by a first solve without it
    assert [lv.level for lv in without.levels] == ["fine"]
    assert [lv.level for lv in r.levels] == ["fine, shape first", "fine"]
    assert without.anisotropy_limit is None
    # that first solve is the solve without the area term to the looser tolerance: the limit
    # is its 80th percentile, within 0.2% of the converged solve's
    from potflat.relax.parameters import PRESETS, SOLVER

    loose = relax(flat, area=0.0, tol=PRESETS["standard"].tol * SOLVER.shape_first_tol_factor)
    fd, fd_loose = (face_distortion(flat.mesh.vertices, res.flat.uv, F) for res in (without, loose))
    assert r.anisotropy_limit == pytest.approx(
        weighted_percentile(fd_loose.anisotropy, fd_loose.area_3d, ENERGY.limit_percentile), rel=1e-9)
    assert r.anisotropy_limit == pytest.approx(
        weighted_percentile(fd.anisotropy, fd.area_3d, ENERGY.limit_percentile), rel=2e-3)
    assert loose.levels[0].iterations < without.levels[0].iterations
    # less area distortion (about 20% here), figures no less round
    assert r.distortion.area_mean_abs_log < 0.9 * without.distortion.area_mean_abs_log
    assert r.distortion.anisotropy_p95 <= without.distortion.anisotropy_p95
    assert r.flipped == 0 and r.boundary_overlap == 0 and np.all(signed_areas(r.flat.uv, F) > 0)
    assert energy_never_increases(r)


def test_a_given_anisotropy_limit_holds_and_inf_means_none():
    from potflat.mesh.distortion import weighted_percentile

    flat = meshes.vessel_rollout(1500, seed=1)
    F = flat.mesh.faces
    free = relax(flat, area=0.0)
    limited = relax(flat, max_anisotropy=1.2)
    assert limited.anisotropy_limit == 1.2 and [lv.level for lv in limited.levels] == ["fine"]
    aniso = {name: face_distortion(flat.mesh.vertices, res.flat.uv, F) for name, res in
             (("free", free), ("limited", limited))}
    p90 = {name: weighted_percentile(fd.anisotropy, fd.area_3d, 90.0) for name, fd in aniso.items()}
    assert p90["free"] > 1.4 and p90["limited"] < 1.25  # a steep price above the limit (soft: the area term pulls)
    assert limited.flipped == 0 and np.all(signed_areas(limited.flat.uv, F) > 0)
    unlimited = relax(flat, max_anisotropy=float("inf"))  # the area term alone
    assert unlimited.anisotropy_limit is None and [lv.level for lv in unlimited.levels] == ["fine"]
    assert unlimited.distortion.area_mean_abs_log < 0.7 * free.distortion.area_mean_abs_log


def test_a_painted_zone_takes_no_area_term():
    flat = meshes.vessel_rollout(1500, seed=1)
    zone = (flat.uv[:, 1] > np.percentile(flat.uv[:, 1], 40)) & (flat.uv[:, 1] < np.percentile(flat.uv[:, 1], 60))
    painted = flat.replace(importance=zone.astype(np.float64))
    r = relax(painted)
    assert r.anisotropy_limit is None and not any("shape first" in lv.level for lv in r.levels)
    np.testing.assert_array_equal(r.flat.uv, relax(painted, area=0.0).flat.uv)
    # painted all over, or a mask that is all black (uniform importance): no zone, the area term applies
    for uniform in (np.ones(len(flat.uv)), np.zeros(len(flat.uv))):
        assert relax(flat.replace(importance=uniform)).anisotropy_limit is not None


def test_true_scale_sets_the_zone_median_scale_to_one():
    flat = meshes.vessel_rollout(1500, seed=2)
    zone = (flat.uv[:, 1] > np.median(flat.uv[:, 1])).astype(float)
    for importance in (None, zone):
        f = flat.replace(importance=importance)
        r = relax(f)
        z = zone_figures(f.mesh.vertices, r.flat.uv, f.mesh.faces, importance)["important"]
        assert z.scale_median == pytest.approx(1.0, abs=1e-9)
        assert r.scale_factor != 1.0
        off = relax(f, true_scale=False)
        assert off.scale_factor == 1.0
        np.testing.assert_allclose(r.flat.uv - r.flat.uv.mean(0), r.scale_factor * (off.flat.uv - off.flat.uv.mean(0)),
                                   atol=1e-9 * np.ptp(off.flat.uv))


def test_zone_figures_of_an_isometric_layout_are_exact():
    flat, exact = meshes.cylinder_patch(12, 8, seed=1)
    V = np.column_stack([exact, np.zeros(len(exact))])  # a plane: ``exact`` is its isometric layout
    flat = FlatMesh(Mesh(V, flat.mesh.faces), exact)
    zone = np.zeros(len(exact))
    zone[: len(exact) // 2] = 1.0
    z = zone_figures(flat.mesh.vertices, exact, flat.mesh.faces, zone)
    for key in ("important", "rest"):
        assert z[key].scale_median == pytest.approx(1.0, abs=1e-9)
        assert z[key].length_error_p95_pct < 1e-6
    assert z["important"].area_fraction + z["rest"].area_fraction == pytest.approx(1.0)
    assert true_scale_factor(flat.mesh.vertices, 1.25 * exact, flat.mesh.faces, zone) == pytest.approx(0.8)


# --- extremes ---------------------------------------------------------------------------------

def test_weights_at_the_extremes_stay_fold_free():
    flat = meshes.vessel_rollout(1500, seed=3)
    F = flat.mesh.faces
    one_face = np.zeros(len(flat.uv))
    one_face[F[len(F) // 2]] = 1.0
    for importance in (one_face, np.zeros(len(flat.uv)), np.ones(len(flat.uv))):
        r = relax(flat.replace(importance=importance), importance_contrast=1000.0)
        assert r.flipped == 0 and r.boundary_overlap == 0 and np.isfinite(r.flat.uv).all()
    # the one important face keeps its size (true scale is measured there) and its shape
    fd = face_distortion(flat.mesh.vertices, relax(flat.replace(importance=one_face), importance_contrast=1000.0).flat.uv, F)
    face = len(F) // 2
    assert important_faces(F, one_face)[face] and important_faces(F, one_face).sum() <= 4  # it and its neighbours
    assert abs(np.log(fd.sigma_max[face] * fd.sigma_min[face])) < 0.05
    assert fd.sigma_max[face] / fd.sigma_min[face] < 1.05


def test_a_high_contrast_is_reached_from_a_softer_solve_to_the_same_layout(monkeypatch):
    """Above ``SOLVER.contrast_start`` the relaxation first solves at that contrast, then at
    the full one from there; it ends where a direct solve ends, fold-free. At or below it,
    or with every vertex wholly important, there is one solve."""
    from dataclasses import replace

    import potflat.relax.multilevel as solver
    from potflat.relax.parameters import SOLVER

    flat = meshes.vessel_rollout(1500, seed=3)
    height = flat.uv[:, 1]
    importance = np.clip((height - np.quantile(height, 0.4)) / (0.05 * np.ptp(height)), 0.0, 1.0)
    flat = flat.replace(importance=importance)
    kw = {"preset": "archival", "importance_contrast": 1000.0, "true_scale": False}
    two = relax(flat, **kw)
    softer = [lv for lv in two.levels if lv.importance_contrast == SOLVER.contrast_start]
    assert softer and any("softer than the painting" in note for note in two.notes)
    assert two.flipped == 0 and two.boundary_overlap == 0
    monkeypatch.setattr(solver, "SOLVER", replace(SOLVER, contrast_start=1000.0))
    one = relax(flat, **kw)
    assert not any(lv.importance_contrast is not None for lv in one.levels)
    F, V = flat.mesh.faces, flat.mesh.vertices
    zone = important_faces(F, importance)
    a, b = face_distortion(V, two.flat.uv, F), face_distortion(V, one.flat.uv, F)
    assert np.allclose(a.sigma_max[zone] / a.sigma_min[zone], b.sigma_max[zone] / b.sigma_min[zone], atol=2e-3)
    assert np.allclose(a.sigma_max[zone] * a.sigma_min[zone], b.sigma_max[zone] * b.sigma_min[zone], atol=2e-3)
    monkeypatch.undo()
    for other in ({**kw, "importance_contrast": SOLVER.contrast_start}, kw):
        got = relax(flat.replace(importance=np.ones(len(importance))) if other is kw else flat, **other)
        assert not any(lv.importance_contrast is not None for lv in got.levels)


def test_with_a_coarse_copy_only_the_copy_takes_the_softer_first_solve(monkeypatch):
    """With a coarse copy, the lower contrast is solved on the copy only (the copy relaxes at
    it, then at the full contrast) and the full mesh is solved once, at the full contrast; it
    ends where the full mesh relaxed at both contrasts in turn (no copy) does, fold-free."""
    from dataclasses import replace

    import potflat.relax.multilevel as solver
    from potflat.relax.parameters import COARSE, SOLVER

    flat = meshes.vessel_rollout(3000, seed=3)
    height = flat.uv[:, 1]
    importance = np.clip((height - np.quantile(height, 0.4)) / (0.05 * np.ptp(height)), 0.0, 1.0)
    flat = flat.replace(importance=importance)
    kw = {"preset": "archival", "importance_contrast": 1000.0, "true_scale": False}
    monkeypatch.setattr(solver, "COARSE", replace(COARSE, min_vertices=1000))
    staged = relax(flat, **kw)
    first = [lv for lv in staged.levels if lv.importance_contrast == SOLVER.contrast_start]
    assert first and all(lv.vertices < len(flat.uv) for lv in first)  # the lower contrast on the copy only
    assert [lv.level for lv in staged.levels].count("fine") == 1
    assert staged.levels[-1].vertices == len(flat.uv) and staged.levels[-1].importance_contrast is None
    assert any(note.startswith("coarse copy: relaxed first with plain surface") for note in staged.notes)
    assert staged.flipped == 0 and staged.boundary_overlap == 0 and staged.converged
    monkeypatch.setattr(solver, "COARSE", replace(COARSE, min_vertices=10**9))  # no copy
    direct = relax(flat, **kw)
    assert [lv.vertices for lv in direct.levels if lv.importance_contrast] == [len(flat.uv)]
    F, V = flat.mesh.faces, flat.mesh.vertices
    zone = important_faces(F, importance)
    a, b = face_distortion(V, staged.flat.uv, F), face_distortion(V, direct.flat.uv, F)
    # (the two converged layouts differ by at most 0.0024 in a face's anisotropy, 0.0005 at p99)
    assert np.allclose(a.sigma_max[zone] / a.sigma_min[zone], b.sigma_max[zone] / b.sigma_min[zone], atol=3e-3)
    assert np.allclose(a.sigma_max[zone] * a.sigma_min[zone], b.sigma_max[zone] * b.sigma_min[zone], atol=2e-3)


def test_without_a_relaxed_copy_the_full_mesh_takes_the_softer_first_solve(monkeypatch):
    """A coarse copy that cannot be relaxed fold-free leaves the lower contrast's first solve
    to the full mesh (a note for each), and the result is fold-free."""
    from dataclasses import replace

    import potflat.relax.multilevel as solver
    from potflat.errors import FoldedResultError
    from potflat.relax.parameters import COARSE, SOLVER

    flat = meshes.vessel_rollout(3000, seed=3)
    height = flat.uv[:, 1]
    flat = flat.replace(importance=np.clip((height - np.quantile(height, 0.4)) / (0.05 * np.ptp(height)), 0.0, 1.0))
    monkeypatch.setattr(solver, "COARSE", replace(COARSE, min_vertices=1000))
    real = solver._relax

    def copies_fold(sub, *args, **kw):
        if len(sub.uv) < len(flat.uv):
            raise FoldedResultError("the copy folds (test)")
        return real(sub, *args, **kw)

    monkeypatch.setattr(solver, "_relax", copies_fold)
    r = relax(flat, importance_contrast=1000.0, true_scale=False)
    first = [lv for lv in r.levels if lv.importance_contrast == SOLVER.contrast_start]
    assert [lv.vertices for lv in first] == [len(flat.uv)]
    assert any("could not be relaxed fold-free" in note for note in r.notes)
    assert any(note.startswith("relaxed first with plain surface") for note in r.notes)
    assert r.flipped == 0 and r.boundary_overlap == 0


def test_a_mask_that_marks_nothing_or_everything_means_no_importance(tmp_path):
    import cv2

    flat, exact = meshes.cylinder_patch(8, 6)
    flat = flat.replace(uv=exact)
    for value in (0, 255):
        path = tmp_path / f"m{value}.png"
        cv2.imwrite(str(path), np.full((16, 16), value, np.uint8))
        tex = flat.replace(mesh=flat.mesh.replace(texcoords=np.full((len(flat.mesh.faces), 3, 2), 0.5)))
        got = imp.texture_mask_importance(tex, path)
        assert got.values is None and "alike" in got.reason


# --- finding the painting -------------------------------------------------------------------

def _painted_image(size=(400, 900), px_per_mm=2.0, panel=True, shading=True, seed=0):
    """Terracotta with a lighting gradient and noise; black and cream circles in a panel."""
    rng = np.random.default_rng(seed)
    h, w = size
    img = np.zeros((h, w, 4), np.uint8)
    yy, xx = np.mgrid[0:h, 0:w]
    base = np.array([188, 94, 52], float)
    light = (0.7 + 0.4 * xx / w + 0.1 * np.sin(yy / h * 3)) if shading else np.ones((h, w))
    rgb = base[None, None] * light[..., None] + (rng.normal(0, 3, (h, w, 3)) if shading else 0)
    inside = np.zeros((h, w), bool)
    if panel:
        r = 10 * px_per_mm
        for k, cx in enumerate(range(int(w * 0.3), int(w * 0.7), int(3.5 * r))):
            disc = (xx - cx) ** 2 + (yy - h / 2) ** 2 <= r * r
            rgb[disc] = (28, 22, 20) if k % 2 == 0 else (232, 214, 178)
            inside |= disc
    img[..., :3] = np.clip(rgb, 0, 255)
    img[..., 3] = 255
    return img, inside


def test_painted_zone_is_found_against_lighting_and_noise():
    img, circles = _painted_image()
    zone, reason = imp.painted_zone_image(img, 2.0)
    assert zone is not None, reason
    assert np.all(zone[circles] > 0.99)  # every painted pixel is in the zone
    h, w = circles.shape
    assert zone[:, : int(0.2 * w)].max() < 0.01 and zone[:, int(0.8 * w):].max() < 0.01  # plain stays plain


def _panel_on_glaze(columns: slice, layout_from: int = 0):
    """A reserved clay panel (rows 100-199, ``columns``) with dark figures in it, on black
    glaze; columns left of ``layout_from`` lie outside the layout (alpha 0). Returns the
    RGBA image (300, 600, 4) and the panel's mask."""
    h, w = 300, 600
    img = np.zeros((h, w, 4), np.uint8)
    img[:, layout_from:, :3], img[:, layout_from:, 3] = (24, 20, 18), 255
    panel = np.zeros((h, w), bool)
    panel[100:200, columns] = True
    img[panel, :3] = (188, 94, 52)
    yy, xx = np.mgrid[0:h, 0:w]
    img[panel & ((xx // 8) % 3 == 0) & (yy > 120) & (yy < 180), :3] = (28, 22, 20)  # figures
    return img, panel


def test_the_zone_ends_on_a_panels_edge():
    """A reserved clay panel (with detail inside) on black glaze: the stiff zone covers the
    panel whole and ends on its edge (the detail window reaches about 4 mm past a strong
    edge; the zone is pulled back through glaze-coloured pixels to the clay)."""
    from scipy import ndimage

    px_per_mm = 2.0
    img, panel = _panel_on_glaze(slice(152, 452))  # (a figure on its edge would be glaze on glaze)
    zone, reason = imp.painted_zone_image(img, px_per_mm)
    assert zone is not None, reason
    assert zone[panel].min() == 1.0  # the whole panel is wholly important
    outside_mm = ndimage.distance_transform_edt(~panel) / px_per_mm
    assert outside_mm[zone >= 1.0].max() == 0.0
    assert zone[outside_mm > 4 * imp.SOFT_EDGE_MM].max() < 0.01


def test_the_zone_ends_on_a_panels_edge_through_noise_and_a_lighting_gradient():
    """Scanner noise on the glaze and light falling off across the vessel do not hold the
    zone's edge off the panel, nor leave specks of zone on the glaze."""
    from scipy import ndimage

    px_per_mm = 2.0
    img, panel = _panel_on_glaze(slice(152, 452))  # (a figure on its edge would be glaze on glaze)
    rng = np.random.default_rng(0)
    light = np.linspace(0.7, 1.1, img.shape[1])[None, :, None]
    noisy = img[..., :3] * light + rng.normal(0.0, 3.0, img[..., :3].shape)
    img[..., :3] = np.clip(np.round(noisy), 0, 255).astype(np.uint8)
    zone, reason = imp.painted_zone_image(img, px_per_mm)
    assert zone is not None, reason
    assert zone[panel].min() == 1.0
    outside_mm = ndimage.distance_transform_edt(~panel) / px_per_mm
    assert outside_mm[zone >= 1.0].max() <= 0.5  # one pixel
    assert zone[outside_mm > 4 * imp.SOFT_EDGE_MM].max() < 0.01


def test_the_ground_between_figures_at_the_zones_edge_stays_in_it():
    """The zone ends on the outermost strokes but keeps the plain ground between figures: two
    bars 6 mm apart hanging from a band keep the ground between them down to their ends
    (pulling the zone back from the plain surface ate into it from below)."""
    px_per_mm = 2.0
    h, w = 300, 600
    img = np.zeros((h, w, 4), np.uint8)
    img[..., :3], img[..., 3] = (188, 94, 52), 255
    img[100:110, 50:550, :3] = (28, 22, 20)  # a band
    img[110:170, 200:208, :3] = (28, 22, 20)  # two bars hanging from it
    img[110:170, 220:228, :3] = (28, 22, 20)
    zone, reason = imp.painted_zone_image(img, px_per_mm)
    assert zone is not None, reason
    assert zone[110:168, 208:220].min() == 1.0  # the ground between them, to their ends
    assert zone[175:185, 200:228].max() < 0.1  # not the plain surface below them
    assert zone[90:96, 200:228].max() < 0.1  # nor above the band


def test_a_painting_cut_by_the_layout_border_keeps_its_extent_there():
    """The zone is pulled back from plain surface only: where the painting runs into the
    layout's border (the seam, the rim) it stays important up to the border."""
    img, panel = _panel_on_glaze(slice(50, 300), layout_from=50)  # runs into the layout's left border
    zone, reason = imp.painted_zone_image(img, 2.0)
    assert zone is not None, reason
    assert zone[panel].min() == 1.0  # up to the border (pulled back from it, columns 50-55 would drop)


def test_a_zone_thinner_than_the_detail_reach_keeps_its_extent():
    """A faint painted line, whose detail is narrower than twice the reach, is not eroded away
    (on a vessel painted with a band too: a lone faint line is too little to be a painting)."""
    px_per_mm = 2.0
    h, w = 200, 400
    img = np.zeros((h, w, 4), np.uint8)
    img[..., :3], img[..., 3] = (188, 94, 52), 255
    img[20:40, :, :3] = (28, 22, 20)  # a band 10 mm wide, 30 mm from the line
    line = np.zeros((h, w), bool)
    line[99:101, 100:300] = True  # 1 mm wide, 100 mm long, a few CIELAB units darker
    img[line, :3] = (150, 70, 35)
    deviation, _ = imp.detail_map(img, px_per_mm)
    detail = deviation[60:] > imp.DETAIL_MIN_DELTA_E
    assert detail.any() and detail.sum(axis=0).max() < 2 * imp.DETAIL_REACH_MM * px_per_mm  # thinner than the reach
    zone, reason = imp.painted_zone_image(img, px_per_mm)
    assert zone is not None, reason
    assert zone[line].min() == 1.0


def test_no_painting_and_painted_all_over_give_no_importance():
    plain, _ = _painted_image(panel=False)
    zone, reason = imp.painted_zone_image(plain, 2.0)
    assert zone is None and "no paint" in reason
    img = _painted_image(shading=False, panel=False)[0]
    yy, xx = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    img[((xx // 20 + yy // 20) % 2 == 0)] = (28, 22, 20, 255)  # a chequer all over
    zone, reason = imp.painted_zone_image(img, 2.0)
    assert zone is None and "all over" in reason


def _clay_image(seed=0, px_per_mm=2.0, size_mm=(200, 500)):
    """Unpainted photographed clay: firing clouds, grain, dirt, pinholes, a cluster of ring
    marks and a bright chip along a scratch, light falling off across the vessel, a lit band
    along the rim and two holes whose texture is bled dark around them. Returns RGBA."""
    import cv2

    rng = np.random.default_rng(seed)
    h, w = int(size_mm[0] * px_per_mm), int(size_mm[1] * px_per_mm)
    yy, xx = np.mgrid[0:h, 0:w] / px_per_mm  # mm

    def blur(a, mm):
        return cv2.GaussianBlur(np.asarray(a, np.float32), (0, 0), mm * px_per_mm)

    clouds = blur(rng.normal(0, 1, (h, w)), 15.0)
    light = 0.75 + 0.35 * np.cos(xx / size_mm[1] * np.pi)
    rgb = np.array([110, 96, 82], np.float32) * (light * (1 + 0.2 * np.tanh(clouds / clouds.std())))[..., None]
    rgb += blur(rng.normal(0, 3, (h, w, 3)), 0.4)  # grain
    rgb -= (np.clip(4 * blur(rng.random((h, w)) < 0.002, 0.6), 0, 1) * 25)[..., None]  # dirt
    marks = np.zeros((h, w), np.float32)
    for _ in range(40):  # pinholes
        cv2.circle(marks, (int(rng.uniform(0, w)), int(rng.uniform(0, h))), int(rng.uniform(0.7, 1.5) * px_per_mm), 1.0, -1)
    for _ in range(12):  # ring marks, in a cluster
        centre = (int((380 + rng.uniform(-25, 25)) * px_per_mm), int((120 + rng.uniform(-25, 25)) * px_per_mm))
        cv2.circle(marks, centre, int(rng.uniform(2, 4) * px_per_mm), 0.8, max(1, int(0.6 * px_per_mm)))
    rgb -= (blur(marks, 0.3) * 35)[..., None]
    scratch = np.zeros((h, w), np.float32)
    cv2.line(scratch, (int(150 * px_per_mm), int(90 * px_per_mm)), (int(175 * px_per_mm), int(80 * px_per_mm)), 1.0,
             int(1.2 * px_per_mm))
    rgb += (blur(scratch, 0.3) * 45)[..., None]
    rgb += (np.clip(1 - yy / 4.0, 0, 1) * 60)[..., None]  # the lit rim
    covered = np.ones((h, w), bool)
    for cx, cy in ((100, 140), (300, 60)):  # holes
        d = np.hypot(xx - cx, yy - cy)
        covered &= d > 4
        rgb *= (1 - 0.5 * np.clip(1 - (d - 4) / 3, 0, 1))[..., None]
    img = np.zeros((h, w, 4), np.uint8)
    img[..., :3] = np.clip(np.rint(rgb), 0, 255)
    img[..., 3] = np.where(covered, 255, 0)
    return img


def _figures(shape, px_per_mm=2.0, x0_mm=20.0, y0_mm=110.0):
    """A frieze 110 x 60 mm: two bands, two silhouettes and a spiral between them. (h, w) bool."""
    import cv2

    m = np.zeros(shape, np.uint8)

    def p(x, y):
        return int((x0_mm + x) * px_per_mm), int((y0_mm + y) * px_per_mm)

    cv2.rectangle(m, p(0, 0), p(110, 4), 1, -1)
    cv2.rectangle(m, p(0, 56), p(110, 60), 1, -1)
    for x in (18, 92):
        cv2.ellipse(m, p(x, 32), (int(9 * px_per_mm), int(16 * px_per_mm)), 0, 0, 360, 1, -1)
    t = np.linspace(0, 6 * np.pi, 200)
    spiral = np.stack([55 + (1 + 2.2 * t) * np.cos(t), 30 + (1 + 2.2 * t) * np.sin(t)], axis=1)
    cv2.polylines(m, [np.array([p(x, y) for x, y in spiral], np.int32)], False, 1, max(1, int(1.5 * px_per_mm)))
    return m > 0


def test_unpainted_clay_gives_no_painted_zone():
    """Clay's own texture (firing clouds, dirt, pinholes, ring marks, a chip, light, a lit rim,
    holes) shows colour detail above the detail threshold, but none that stands clear of the
    surface's own texture where the colours are evidence: no zone, and the reason says why."""
    for seed in range(3):
        img = _clay_image(seed)
        covered = img[..., 3] > 127
        deviation, _ = imp.detail_map(img, 2.0)
        assert (deviation[covered] > imp.DETAIL_MIN_DELTA_E).mean() > 0.002  # there is detail to be fooled by
        zone, reason = imp.painted_zone_image(img, 2.0)
        assert zone is None, reason
        assert reason.startswith("no painting found") and "own texture" in reason and imp.ALIKE in reason


def test_a_painting_on_clay_is_found_and_the_clay_marks_are_not_joined_to_it():
    """The same clay with a black-figure frieze (and a faded red one on the right): the zone
    covers both friezes, not the ring marks, the rim or the holes farther than the joining
    distance from them. (The bright chip along the scratch is as strong and long as a brush
    stroke: on a painted surface it is one.)"""
    from scipy import ndimage

    img = _clay_image(0)
    covered = img[..., 3] > 127
    black = _figures(covered.shape) & covered
    red = _figures(covered.shape, x0_mm=200.0, y0_mm=100.0) & covered
    rgb = img[..., :3].astype(float)
    rgb[black] = (28, 22, 20)
    rgb[red] = 0.5 * rgb[red] + 0.5 * np.array([170.0, 50.0, 30.0])  # faded to half
    img[..., :3] = np.clip(np.rint(rgb), 0, 255).astype(np.uint8)
    zone, reason = imp.painted_zone_image(img, 2.0)
    assert zone is not None, reason
    assert zone[black].min() == 1.0 and zone[red].min() == 1.0
    far_mm = ndimage.distance_transform_edt(~(black | red)) / 2.0
    yy, xx = np.mgrid[0:covered.shape[0], 0:covered.shape[1]] / 2.0
    chip = (np.abs(xx - 162) < 20) & (np.abs(yy - 85) < 15)
    assert zone[covered & (far_mm > imp.GAP_MM) & ~chip].max() < 0.5


def test_colour_detail_next_to_the_outline_and_holes_is_no_evidence():
    """A lit band along the rim and dark rims around holes (texture bled at a scan's borders)
    are strong detail, but no painting; the same band away from the border is one."""
    img, _ = _painted_image(panel=False)
    h, w = img.shape[:2]
    rgb = img[..., :3].astype(float)
    rgb[:8] += 80  # a lit band 4 mm wide along the top
    yy, xx = np.mgrid[0:h, 0:w]
    for cx in (200, 450, 700):  # holes 6 mm across, bled dark 3 mm around
        d = np.hypot(xx - cx, yy - h / 2)
        img[d <= 6, 3] = 0
        rgb[(d > 6) & (d <= 12)] *= 0.4
    img[..., :3] = np.clip(rgb, 0, 255).astype(np.uint8)
    zone, reason = imp.painted_zone_image(img, 2.0)
    assert zone is None and reason.startswith("no painting found"), reason
    img[8:16, :, :3] = img[:8, :, :3]  # the band again, but 4 mm inside
    img[:8, :, 3] = 0
    moved = img.copy()
    moved[60:68, :, :3] = np.clip(moved[60:68, :, :3].astype(float) + 80, 0, 255).astype(np.uint8)  # and 26 mm in
    zone, reason = imp.painted_zone_image(moved, 2.0)
    assert zone is not None and zone[60:68, 100:-100].min() == 1.0, reason


def test_where_the_layout_smears_the_texture_is_no_evidence():
    """A strip of the start layout stretched 5:1 (a base unrolled as a flange) draws the
    texture's specks out into streaks: those pixels are left out of the evidence (a single
    stretched triangle is not), and streaks there are no painting."""
    from potflat.raster.render import make_grid

    xs, ys = np.meshgrid(np.arange(0.0, 101.0, 2.0), np.arange(0.0, 61.0, 2.0))
    V = np.column_stack([xs.ravel(), ys.ravel(), np.zeros(xs.size)])
    nx = xs.shape[1]
    q = (np.arange(ys.shape[0] - 1)[:, None] * nx + np.arange(nx - 1)[None, :]).ravel()
    F = np.concatenate([np.column_stack([q, q + 1, q + nx + 1]), np.column_stack([q, q + nx + 1, q + nx])])
    uv = V[:, :2].copy()
    low = uv[:, 1] < 20
    uv[low, 1] = 20 - 5 * (20 - uv[low, 1])  # rows below 20 mm stretched 5x upright
    flat = FlatMesh(Mesh(V, F), uv)
    g = make_grid(flat, 2.0, 1000.0)
    pixels = imp._pixels(uv, g.origin, 2.0)
    smeared = imp._smeared(flat, pixels, (g.height, g.width), 2.0)
    rows = np.flatnonzero(smeared.any(axis=1))
    # the stretched strip spans 100 mm of the image's 140 (rows 80-280 of 280), the rest none
    assert 0.95 * 200 < len(rows) <= 201 and rows.min() >= 79
    assert smeared[rows.min() + 5: rows.max() - 5, 10:-10].all()
    one = V[:, :2].copy()
    one[F[len(F) // 2][0]] += (0.0, 1.5)  # one triangle stretched, its neighbours less
    assert not imp._smeared(flat.replace(uv=one), imp._pixels(one, g.origin, 2.0), (g.height, g.width), 2.0).any()
    # streaks in a smeared strip: detail, but no evidence of a painting
    img, _ = _painted_image(panel=False)
    rng = np.random.default_rng(1)
    streaks = np.zeros(img.shape[:2], bool)
    for r in rng.integers(330, 395, 30):
        c = int(rng.integers(0, 800))
        streaks[r:r + 2, c:c + 80] = True
    img[streaks, :3] = (235, 230, 220)
    assert imp.painted_zone_image(img, 2.0)[0] is not None  # taken for strokes where they are evidence
    evidence = np.ones(img.shape[:2], bool)
    evidence[320:, :] = False
    zone, reason = imp.painted_zone_image(img, 2.0, evidence=evidence)
    assert zone is None, reason


def _glaze_in_shadow(seed=0, px_per_mm=2.0, size_mm=(200, 500)):
    """White glaze photographed in a vessel's mouth: a cast shadow over its lower half with a
    ragged edge 1 mm soft, a lit lip 10 mm wide below the rim, light falling off, noise.
    Returns RGBA."""
    import cv2

    rng = np.random.default_rng(seed)
    h, w = int(size_mm[0] * px_per_mm), int(size_mm[1] * px_per_mm)
    yy, xx = np.mgrid[0:h, 0:w] / px_per_mm
    edge = 100 + np.cumsum(rng.normal(0, 1.5, w)) / np.sqrt(px_per_mm)  # the shadow's edge, mm
    edge += 8 * np.sin(xx[0] / 23.0)
    shadow = cv2.GaussianBlur((yy > edge[None, :]).astype(np.float32), (0, 0), 1.0 * px_per_mm)
    lip = ((yy > 10) & (yy < 20)).astype(np.float32)
    light = (0.8 + 0.2 * np.cos(xx / size_mm[1] * np.pi)) * (1 - 0.55 * shadow) * (1 + 0.12 * lip)
    rgb = np.array([214, 212, 204], np.float32) * light[..., None] * 0.9 + rng.normal(0, 1.5, (h, w, 3))
    img = np.zeros((h, w, 4), np.uint8)
    img[..., :3] = np.clip(np.rint(rgb), 0, 255)
    img[..., 3] = 255
    return img


def test_shadows_and_highlights_are_no_painting_and_a_line_drawing_in_them_is_one():
    """The edge of a cast shadow and of a lit lip are strong colour detail (steps of 30-60
    CIELAB units), but steps between two large areas, not strokes: no painting. A drawing of
    black lines 1 mm wide across the same light and shadow is one. (The shadow's edge, detail
    joined to the drawing's, stays in its zone.)"""
    import cv2

    for seed in range(2):
        img = _glaze_in_shadow(seed)
        deviation, _ = imp.detail_map(img, 2.0)
        assert deviation.max() > 2 * imp.DETAIL_MIN_DELTA_E  # a step of 30 units or more
        zone, reason = imp.painted_zone_image(img, 2.0)
        assert zone is None and reason.startswith("no painting found") and "shadows" in reason, reason
    lines = np.zeros(img.shape[:2], np.uint8)
    for k in range(6):  # six waves, 160 mm long, 12 mm apart, crossing the shadow's edge
        x = np.arange(300, 620)
        y = 140 + 24 * k + 10 * np.sin(x / 15.0)
        cv2.polylines(lines, [np.stack([x, y], axis=1).astype(np.int32)], False, 1, 2)
    drawing = img.copy()
    drawing[lines > 0, :3] = (30, 30, 32)
    zone, reason = imp.painted_zone_image(drawing, 2.0)
    assert zone is not None, reason
    assert zone[lines > 0].min() == 1.0
    assert zone[:50].max() < 0.5  # not the lit lip


def test_highlights_on_black_glaze_are_no_painting_and_red_figures_on_it_are():
    """Lustrous black glaze photographed with soft highlights (bright blobs 8-30 mm across):
    no painting. Reserved clay figures with black lines inside them (red-figure): found, and
    the zone covers them."""
    import cv2

    rng = np.random.default_rng(3)
    h, w = 500, 1200
    yy, xx = np.mgrid[0:h, 0:w]
    rgb = np.full((h, w, 3), (30.0, 26.0, 24.0)) * (0.8 + 0.2 * np.cos(xx / w * np.pi))[..., None]
    for _ in range(25):
        cx, cy, r = rng.uniform(0, w), rng.uniform(0, h), rng.uniform(8, 30)
        rgb += (np.clip(1 - np.hypot(xx - cx, yy - cy) / r, 0, 1) ** 2 * 120)[..., None]
    rgb += rng.normal(0, 2, rgb.shape)
    img = np.zeros((h, w, 4), np.uint8)
    img[..., :3], img[..., 3] = np.clip(np.rint(rgb), 0, 255), 255
    zone, reason = imp.painted_zone_image(img, 2.0)
    assert zone is None and reason.startswith("no paint"), reason
    figures = _figures((h, w), x0_mm=150.0, y0_mm=80.0)
    figures = cv2.morphologyEx(figures.astype(np.uint8), cv2.MORPH_DILATE, np.ones((5, 5), np.uint8)) > 0
    img[figures, :3] = (188, 94, 52)  # the figures reserved in the clay's colour ...
    inner = (xx // 2 % 9 == 0) & figures & (yy > 200) & (yy < 260)
    img[inner, :3] = (28, 22, 20)  # ... and lines drawn in them
    zone, reason = imp.painted_zone_image(img, 2.0)
    assert zone is not None, reason
    assert zone[cv2.erode(figures.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0].min() == 1.0


def _textured(vessel, folder: Path) -> Mesh:
    """The vessel's mesh with its texture written to ``folder``."""
    from potflat.io.images import write_png

    path = write_png(folder / f"{vessel.kind}.png", vessel.texture, px_per_mm=None)
    return vessel.mesh.replace(texture_path=path)


def test_auto_importance_on_a_generated_vessel_covers_the_frieze_not_the_plain_body(tmp_path):
    from potflat.rollout import rollout
    from potflat_synthetic.vessels import make_vessel

    vessel = make_vessel("hydria", n_vertices=6000, seed=2)
    ro = rollout(_textured(vessel, tmp_path))
    assert ro.importance.method == "auto" and ro.importance.values is not None
    V, F = ro.flat.mesh.vertices, ro.flat.mesh.faces
    zone = important_faces(F, ro.flat.importance)
    centroid = V[F].mean(axis=1)
    in_circle = np.zeros(len(F), bool)
    for c in vessel.features:
        in_circle |= np.linalg.norm(centroid - c.centre, axis=1) <= c.radius
    assert zone[in_circle].mean() > 0.99
    assert 0.1 < ro.importance.zone_fraction < 0.8


def test_rollout_without_colours_has_no_importance():
    from potflat.rollout import rollout
    from potflat_synthetic.vessels import make_vessel

    vessel = make_vessel("cylinder", n_vertices=2000, seed=1)
    ro = rollout(vessel.mesh.replace(texcoords=None, texture_path=None))
    assert ro.importance.values is None and "no texture" in ro.importance.reason


# --- masks and bands ------------------------------------------------------------------------

def test_image_mask_round_trip_is_exact_on_a_developable_vessel(tmp_path):
    """image -> surface -> image: every vertex reads the mask exactly where the image shows
    it, and the important faces are those the painted rectangle covers."""
    import cv2

    from potflat.bake import BakeOptions

    from potflat.files.bake_stage import run_bake_stage
    from potflat.io.flat_ply import write_flat_ply
    from potflat.rollout import rollout
    from potflat_synthetic.vessels import make_vessel

    mesh = _textured(make_vessel("cylinder", n_vertices=3000, seed=4), tmp_path)
    first = relax(rollout(mesh, importance="none").flat)
    write_flat_ply(tmp_path / "v.relaxed.ply", first.flat)
    run_bake_stage(tmp_path / "v.relaxed.ply", tmp_path, BakeOptions(px_per_mm=1.0, maps=()))
    meta = json.loads((tmp_path / "v.bake.json").read_text())
    w, h = meta["image_px"]
    mask = np.zeros((h, w), np.uint8)
    r0, r1, c0, c1 = int(0.3 * h), int(0.7 * h), int(0.3 * w), int(0.6 * w)
    mask[r0:r1, c0:c1] = 255
    cv2.imwrite(str(tmp_path / "v.mask.png"), mask)

    again = rollout(mesh, importance="mask", importance_mask=str(tmp_path / "v.mask.png"))
    px = imp._pixels(first.flat.uv, np.asarray(meta["origin_uv"]), meta["px_per_unit"])
    np.testing.assert_allclose(again.flat.importance, imp.sample_image(mask / 255.0, px), atol=1e-12)
    # faces whose corners all lie a pixel inside the rectangle are important, those outside are not
    F = again.flat.mesh.faces
    col, row = px[F][..., 0], px[F][..., 1]
    inside = ((col > c0 + 1.5) & (col < c1 - 1.5) & (row > r0 + 1.5) & (row < r1 - 1.5)).all(axis=1)
    outside = ((col < c0 - 1.5) | (col > c1 + 1.5) | (row < r0 - 1.5) | (row > r1 + 1.5)).all(axis=1)
    zone = important_faces(F, again.flat.importance)
    assert inside.any() and np.all(zone[inside]) and not np.any(zone[outside])
    # relaxed with that zone: still fold-free, the zone true to scale
    second = relax(again.flat)
    z = zone_figures(again.flat.mesh.vertices, second.flat.uv, F, again.flat.importance)["important"]
    assert second.flipped == 0 and z.length_error_p95_pct < 1.0
    # a mask of another size is refused with one line
    cv2.imwrite(str(tmp_path / "small.png"), mask[:10, :10])
    with pytest.raises(InvalidInputError, match="size"):
        rollout(mesh, importance="mask", importance_mask=str(tmp_path / "small.png"))


def test_band_importance_selects_heights_and_angles():
    from potflat.rollout import rollout
    from potflat_synthetic.vessels import make_vessel

    vessel = make_vessel("cylinder", n_vertices=3000, seed=1)
    ro = rollout(vessel.mesh, importance="band", importance_band=(0.25, 0.75), importance_arc=(0.0, 180.0))
    frac = ro.importance.zone_fraction
    assert frac == pytest.approx(0.25, abs=0.04)  # half the height, half the way round
    with pytest.raises(InvalidOptionError, match="importance band"):
        rollout(vessel.mesh, importance="band", importance_band=(0.6, 0.4))
    with pytest.raises(InvalidOptionError, match="importance_mask"):
        rollout(vessel.mesh, importance="mask")


def test_texture_mask_importance_reads_the_texture_space(tmp_path):
    import cv2

    flat, exact = meshes.cylinder_patch(10, 8)
    F = flat.mesh.faces
    tc = (exact - exact.min(0)) / np.ptp(exact, axis=0)  # texture coordinates = the development
    mesh = flat.mesh.replace(texcoords=tc[F])
    mask = np.zeros((64, 64), np.uint8)
    mask[:, :32] = 255  # left half of the texture
    path = tmp_path / "mask.png"
    cv2.imwrite(str(path), mask)
    got = imp.texture_mask_importance(FlatMesh(mesh, exact), path)
    left = tc[:, 0] < 0.45
    right = tc[:, 0] > 0.55
    assert np.all(got.values[left] == 1.0) and np.all(got.values[right] == 0.0)
    with pytest.raises(InvalidInputError, match="not found"):
        imp.texture_mask_importance(FlatMesh(mesh, exact), tmp_path / "missing.png")


def test_unknown_importance_is_one_line():
    from potflat.rollout import RolloutOptions

    with pytest.raises(InvalidOptionError, match="unknown importance"):
        RolloutOptions(importance="painted")


def test_a_painted_panel_comes_out_rounder_and_truer_with_importance(tmp_path):
    """A whole hydria painted in a panel only (black glaze elsewhere, lighting and noise):
    with the painted zone found in the colours its circles are rounder and closer to true
    size than with the whole surface alike, fold-free."""
    from _bench_meshes import figures

    from potflat.rollout import rollout
    from potflat_synthetic.vessels import make_vessel

    vessel = make_vessel("hydria", n_vertices=8000, seed=3, painting="panel", shading=True)
    mesh = _textured(vessel, tmp_path)
    found = rollout(mesh)
    assert found.importance.values is not None and found.importance.zone_fraction < 0.5
    alike = found.flat.replace(importance=None)
    with_zone, without = relax(found.flat), relax(alike)
    a, b = figures.measure_figures(with_zone.flat, vessel.features), figures.measure_figures(without.flat, vessel.features)
    assert a.measured == b.measured >= 3
    assert with_zone.flipped == 0 and without.flipped == 0
    assert a.anisotropy_p95 - 1 < 0.5 * (b.anisotropy_p95 - 1)
    assert abs(a.area_ratio - 1) < 0.5 * abs(b.area_ratio - 1)
