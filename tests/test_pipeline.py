"""potflat.files.pipeline: run_scan over the three stages, option coercion and resolution."""
from __future__ import annotations

import typing
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import test_batch_fakes as fakes
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.files.options import coerce_option, describe_type, option_types, resolve_options
from potflat.files.pipeline import FIGURES, run_scan


@pytest.fixture
def fake_stages(monkeypatch):
    fakes.install(monkeypatch)


def test_run_scan_runs_three_stages_in_order(tmp_path, fake_stages):
    scan = fakes.write_scan(tmp_path / "in" / "hydria.obj")
    seen = []
    result = run_scan(scan, tmp_path / "out", progress=seen.append,
                      bake={"px_per_mm": 2.0, "maps": ("stress",)})
    assert seen == ["rollout", "relax", "bake"]
    assert result.name == "hydria"
    names = sorted(p.name for p in (tmp_path / "out").iterdir())
    assert names == ["hydria.bake.json", "hydria.png", "hydria.relaxed.json", "hydria.relaxed.ply",
                     "hydria.rollout.json", "hydria.rollout.ply", "hydria.stress.png"]
    assert set(result.paths) == {"rollout.ply", "rollout.json", "relax.ply", "relax.json",
                                 "bake.png", "bake.stress", "bake.json"}
    assert all(p.is_file() for p in result.paths.values())
    assert result.figures["flipped"] == 0 and result.figures["edge_rms"] > 0
    assert set(vars(result.seconds)) == {"rollout", "relax", "bake", "total"}


def test_run_scan_name_and_options_objects(tmp_path, fake_stages):
    scan = fakes.write_scan(tmp_path / "a.obj")
    result = run_scan(scan, tmp_path / "o", name="other", relax=fakes.RelaxOptions(preset="preview"))
    assert result.name == "other" and (tmp_path / "o" / "other.png").is_file()
    assert result.relax.record["provenance"]["options"]["preset"] == "preview"


def test_run_scan_failure_keeps_finished_stages(tmp_path, fake_stages):
    scan = fakes.write_scan(tmp_path / "a.obj")
    fakes.SABOTAGE["a"] = ("raise", "relax")
    with pytest.raises(RuntimeError, match="relax exploded"):
        run_scan(scan, tmp_path / "o")
    assert (tmp_path / "o" / "a.rollout.ply").is_file()
    assert not (tmp_path / "o" / "a.relaxed.ply").exists()


def test_run_scan_corrupt_scan_is_a_user_error(tmp_path, fake_stages):
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"\x00garbage")
    with pytest.raises(InvalidInputError, match="bad.ply"):
        run_scan(bad, tmp_path / "o")


def test_resolve_options_checks_types(fake_stages):
    opts = resolve_options(rollout={"proxy": "cone"})
    assert opts.rollout.proxy == "cone" and opts.relax == fakes.RelaxOptions()
    with pytest.raises(InvalidOptionError, match="RelaxOptions"):
        resolve_options(relax=fakes.BakeOptions())
    with pytest.raises(InvalidOptionError, match="px_per_mm"):
        resolve_options(bake={"px_per_mm": -1.0})


def test_option_types_from_dataclass(fake_stages):
    types_ = option_types(fakes.RolloutOptions)
    assert list(types_)[:3] == ["units", "proxy", "axis"]
    assert types_["band"] == typing.Optional[tuple[float, float]]


@pytest.mark.parametrize("tp, value, expected", [
    (float, 4, 4.0),
    (float, "2.5", 2.5),
    (int, 3.0, 3),
    (int, "7", 7),
    (bool, True, True),
    (str, "cone", "cone"),
    (Path, "a/b", Path("a/b")),
    (typing.Optional[tuple[float, float]], [0.2, 0.6], (0.2, 0.6)),
    (typing.Optional[tuple[float, float]], "0.2, 0.6", (0.2, 0.6)),
    (typing.Optional[tuple[float, float]], None, None),
    (tuple[str, ...], "stress,area", ("stress", "area")),
    (tuple[str, ...], ["stress"], ("stress",)),
    (typing.Literal["auto", "cone"], "cone", "cone"),
    (typing.Any, {"x": 1}, {"x": 1}),
])
def test_coerce_option_accepts(tp, value, expected):
    assert coerce_option(tp, value) == expected


@pytest.mark.parametrize("tp, value, message", [
    (float, True, "must be a number, got True"),
    (float, "abc", "must be a number"),
    (int, 2.5, "must be a whole number"),
    (bool, "yes", "must be true or false"),
    (str, 3, "must be text"),
    (typing.Optional[tuple[float, float]], [1.0], "a list of 2 numbers or null"),
    (typing.Optional[tuple[float, float]], 0.5, "a list of 2 numbers"),
    (tuple[float, float], ["a", "b"], "a list of 2 numbers"),
    (typing.Literal["auto", "cone"], "cnoe", "did you mean cone"),
    (float, None, "got null"),
])
def test_coerce_option_rejects(tp, value, message):
    with pytest.raises(InvalidOptionError, match=message):
        coerce_option(tp, value)


def test_describe_type():
    assert describe_type(tuple[str, ...]) == "a list of names"
    assert describe_type(typing.Literal["a", "b"]) == "one of a, b"


def test_run_refuses_early_when_the_painting_would_replace_the_scan_texture(tmp_path):
    """`potflat run pot.obj` into the scan's own folder, whose texture is pot.png: refused
    before any stage runs (nothing written), and the texture is kept."""
    import pytest

    from potflat.errors import InvalidOptionError
    from potflat.files.pipeline import run_scan

    scan = tmp_path / "pot.obj"
    scan.write_text("v 0 0 0\n")
    texture = tmp_path / "pot.png"
    texture.write_bytes(b"texture")
    with pytest.raises(InvalidOptionError, match="pot.png exists and was not made by potflat"):
        run_scan(scan, tmp_path)
    assert texture.read_bytes() == b"texture"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pot.obj", "pot.png"]


@pytest.mark.parametrize("relax, bake, want", [
    ({"preset": "preview"}, {"px_per_mm": 8.0}, 0.25),
    ({"preset": "preview"}, {"dpi": 254.0}, 0.2),
    ({"preset": "preview", "simplify_mm": 1.0}, {"px_per_mm": 8.0}, 1.0),
    ({"preset": "standard"}, {"px_per_mm": 8.0}, None),
])
def test_preview_relaxes_at_two_pixels_of_the_image(relax, bake, want):
    from potflat.files.pipeline import _preview_at_image_resolution

    options = _preview_at_image_resolution(resolve_options(relax=relax, bake=bake))
    assert options.relax.simplify_mm == pytest.approx(want) if want is not None else options.relax.simplify_mm is None


def test_run_scan_hands_the_flattening_on_in_memory(tmp_path, monkeypatch):
    """Relax and bake take the previous stage's flattening from memory (its file is the record),
    exactly as the file holds it; the figures come typed from the relax stage."""
    import potflat.io.flat_ply
    from potflat_synthetic.vessels import make_vessel, write_obj

    scan = write_obj(make_vessel("amphora", n_vertices=3000, seed=2, texture_size=128), tmp_path / "in" / "a.obj")

    def no_reading(path):
        raise AssertionError(f"run_scan read {path} back")

    monkeypatch.setattr(potflat.io.flat_ply, "read_flat_ply", no_reading)
    result = run_scan(scan, tmp_path / "out", relax={"preset": "preview"}, bake={"px_per_mm": 1.0, "maps": ()})
    monkeypatch.undo()
    relaxed = result.relax
    assert result.figures == {k: relaxed.record["distortion"][k] for k in FIGURES}
    back = potflat.io.flat_ply.read_flat_ply(result.paths["relax.ply"])
    assert back.uv.tobytes() == relaxed.flat.uv.tobytes()
    assert back.mesh.texcoords.tobytes() == relaxed.flat.mesh.texcoords.tobytes()
    assert back.mesh.texture_path == relaxed.flat.mesh.texture_path


def test_every_stage_json_records_its_timings_by_step(tmp_path):
    """rollout.json, relaxed.json and bake.json each say how long their steps took."""
    from pathlib import Path

    from potflat.files.pipeline import run_scan

    sample = Path(__file__).parents[1] / "samples" / "data" / "cone.obj"
    result = run_scan(sample, tmp_path, bake={"px_per_mm": 1.0, "maps": ()})
    rollout = result.rollout.record["timings"]
    assert {"load", "rollout", "write", "total"} <= set(rollout)
    assert {"axis", "walls", "profile", "unroll", "untangle", "importance", "total"} <= set(rollout["rollout_steps"])
    relax = result.relax.record["timings"]
    assert {"setup", "solve", "check", "figures", "write", "total"} <= set(relax)
    bake = result.bake.record["timings"]
    assert {"prepare", "render", "figures", "total"} <= set(bake)
    for timings in (rollout, rollout["rollout_steps"], relax, bake):
        steps = [v for k, v in timings.items() if k != "total" and isinstance(v, float)]
        assert all(v >= 0 for v in steps) and sum(steps) <= timings["total"] + 1e-6


def test_run_scan_computes_each_flattenings_figures_once(tmp_path, monkeypatch):
    """relax takes the rollout's figures from the rollout stage, and bake the relaxed
    flattening's (whole surface and painted zone, and their 3D side) from the relax stage,
    instead of computing them again; they are what the stage commands compute from the files."""
    import potflat.mesh.distortion as distortion
    import potflat.relax.multilevel as solver
    from potflat.files.bake_stage import run_bake_stage
    from potflat_synthetic.vessels import make_vessel, write_obj

    scan = write_obj(make_vessel("amphora", n_vertices=3000, seed=2, texture_size=128), tmp_path / "in" / "a.obj")
    stage, computed = ["before"], []
    summarize, zone_summary = distortion.SurfaceReference.summarize, distortion.zone_summary

    def zone_counted(*args, **kwargs):
        computed.append((stage[-1], "zone"))
        return zone_summary(*args, **kwargs)

    layouts = []  # the layouts summarised in the relax stage

    def summarize_counted(self, uv, **handed):
        computed.append((stage[-1], "summarize"))
        if stage[-1] == "relax":
            layouts.append(np.array(uv))
        return summarize(self, uv, **handed)

    reference_init = distortion.SurfaceReference.__init__

    def reference_counted(self, *args, **kwargs):
        computed.append((stage[-1], "reference"))
        reference_init(self, *args, **kwargs)

    monkeypatch.setattr(distortion.SurfaceReference, "summarize", summarize_counted)
    monkeypatch.setattr(distortion.SurfaceReference, "__init__", reference_counted)
    monkeypatch.setattr(distortion, "zone_summary", zone_counted)
    monkeypatch.setattr(solver, "zone_summary", zone_counted)
    bake = {"px_per_mm": 1.0, "maps": ("stress",)}
    result = run_scan(scan, tmp_path / "out", relax={"preset": "preview"}, bake=bake, progress=stage.append)
    assert ("relax", "zone") in computed and ("relax", "summarize") in computed
    assert not [c for c in computed if c[0] == "bake"]
    assert result.relax.reference is None  # handed to the bake, not kept by the result
    rollout_uv = result.rollout.flat.uv
    assert layouts and not any(uv.shape == rollout_uv.shape and np.array_equal(uv, rollout_uv) for uv in layouts)
    assert result.relax.record["distortion_before"] == result.rollout.record["distortion"]
    stage.append("bake again")
    again = run_bake_stage(result.paths["relax.ply"], tmp_path / "again", resolve_options(bake=bake).bake)
    assert {("bake again", "zone"), ("bake again", "summarize"), ("bake again", "reference")} <= set(computed)
    for png in ("png", "stress"):  # the maps from the handed 3D side as from the file's
        ran, baked = (np.asarray(Image.open(out.paths[png])) for out in (result.bake, again))
        np.testing.assert_array_equal(ran, baked)
    for key in ("distortion", "important_zone", "rest", "lengths"):
        assert result.bake.record[key] == again.record[key]
    assert result.bake.record["important_zone"] == result.relax.record["important_zone"]
    zone = result.relax.record["important_zone"]
    assert result.zone_figures["painted_length_error_median_pct"] == zone["length_error_median_pct"] > 0
    assert result.zone_figures["painted_area_fraction"] == zone["area_fraction"] < 1  # the sample's frieze
    assert result.zone_figures["plain_length_error_p95_pct"] == result.relax.record["rest"][
        "length_error_p95_pct"]


def test_the_painted_zone_outline_stands_out_on_every_map(tmp_path):
    """The zone is drawn in the map's colour for no distortion; its outline is white on the
    stress and anisotropy maps (dark at no distortion) and black on the area map (white at an
    unchanged area), and each legend names its colour."""
    from PIL import Image

    from potflat_synthetic.vessels import make_vessel, write_obj

    scan = write_obj(make_vessel("amphora", n_vertices=3000, seed=2, texture_size=128), tmp_path / "in" / "a.obj")
    result = run_scan(scan, tmp_path / "out", relax={"preset": "preview"},
                      bake={"px_per_mm": 2.0, "maps": ("stress", "area", "anisotropy")})
    assert result.relax.record["important_zone"]["area_fraction"] < 1  # a painted zone was found
    labels = result.bake.record["maps"]
    for name, colour in (("stress", (255, 255, 255, 255)), ("anisotropy", (255, 255, 255, 255)),
                         ("area", (0, 0, 0, 255))):
        image = np.asarray(Image.open(result.paths[f"bake.{name}"]).convert("RGBA"))
        height = Image.open(result.paths["bake.png"]).height  # the map above its legend band
        assert (image[:height] == colour).all(axis=2).sum() > 50, name
        assert f"{'black' if colour[0] == 0 else 'white'} line: painted zone" in labels[name]["label"]
