"""The bake's file stage: bake ``NAME.relaxed.ply`` (or a rollout) into ``NAME.png``, the
distortion maps, the scale layers, optional TIFFs, OBJ, sheet and plate, and
``NAME.bake.json``. The images are streamed strip by strip from
:class:`potflat.bake.render.Renderer`; the rollout's sidecar (in memory or
``NAME.rollout.json`` beside the input) says where attachments and a repeat are marked."""
from __future__ import annotations

import json
import os
from contextlib import ExitStack
from dataclasses import asdict, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from potflat._heap import reuse_freed_memory
from potflat.bake.render import (
    FOLDED_COLOUR,
    REPEAT_COLOUR,
    BakeOptions,
    Renderer,
    attachment_rows,
    comparison_sheet,
    folded_hatch,
    image_figures,
    repeat_line,
    rgba8,
    rgba16,
    scale_layer_on_image,
)
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.stages.names import rollout_json_beside, stage_name
from potflat.types import FlatMesh, StageOutput, StepClock

if TYPE_CHECKING:
    from potflat.bake.render import _Grid
    from potflat.mesh.distortion import DistortionSummary, SurfaceReference, ZoneSummary


def _rollout_sidecar(flat_ply: Path, rollout_summary: dict | None = None) -> tuple[dict, Path | None]:
    """The rollout's summary (``rollout_summary`` when handed over in memory, else
    ``NAME.rollout.json`` beside the input; an empty dict when absent or unreadable) and that
    JSON file (for provenance) or None."""
    rollout_json = rollout_json_beside(flat_ply)
    if rollout_summary is not None:
        return rollout_summary, rollout_json if rollout_json.is_file() else None
    try:
        data = json.loads(rollout_json.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}, None
    # a sidecar of another shape (null, a list: edited by hand) has nothing to mark
    return (data if isinstance(data, dict) else {}), rollout_json


def _face_marks(listed, n_faces: int) -> np.ndarray:
    """A per-face indicator (n_faces,) float64 of the face indices ``listed`` in a sidecar;
    empty when the list is empty, not a list of whole numbers or out of range."""
    if not isinstance(listed, list) or not all(isinstance(f, int) and not isinstance(f, bool) for f in listed):
        return np.zeros(0)
    listed = np.asarray(listed, dtype=np.int64)
    if not len(listed) or listed.min() < 0 or listed.max() >= n_faces:
        return np.zeros(0)
    marks = np.zeros(n_faces)
    marks[listed] = 1.0
    return marks


def _attachment_roots(sidecar: dict, n_faces: int) -> np.ndarray:
    """Faces where the rollout left out an attachment, from ``NAME.rollout.json``: a per-face
    indicator (n_faces,) float64, empty when there is nothing to show."""
    att = sidecar.get("attachments")
    if not isinstance(att, dict) or att.get("kept"):
        return np.zeros(0)
    return _face_marks(att.get("root_faces"), n_faces)


def _folded_faces(sidecar: dict, n_faces: int) -> np.ndarray:
    """Faces where the scan folds over itself in 3D (``folded.face_indices`` of
    ``NAME.rollout.json``): a per-face indicator (n_faces,) float64, empty when none."""
    folded = sidecar.get("folded")
    return _face_marks(folded.get("face_indices") if isinstance(folded, dict) else None, n_faces)


def _repeated_faces(sidecar: dict, n_faces: int) -> np.ndarray:
    """Faces that repeat the start of the rollout past 360 degrees (``overlap``), from
    ``NAME.rollout.json``: a per-face indicator (n_faces,) float64, empty when none."""
    region = sidecar.get("region")
    start = region.get("repeated_from") if isinstance(region, dict) else None
    if not isinstance(start, int) or region.get("faces") != n_faces or not 0 < start < n_faces:
        return np.zeros(0)
    marks = np.zeros(n_faces)
    marks[int(start):] = 1.0
    return marks


def _write_flat_obj(path: Path, flat: FlatMesh, g: _Grid, band: int, texture_name: str) -> Path:
    """The flattened surface as a textured OBJ: 3D positions, texture coordinates = the flat
    coordinates in the pixel grid of ``NAME.png`` (``band`` rows added below it)."""
    from potflat import __version__
    from potflat.io.obj import write_textured_obj

    height = g.height + band
    vt = np.empty_like(flat.uv)
    vt[:, 0] = (flat.uv[:, 0] - g.origin[0]) * g.scale / g.width
    vt[:, 1] = 1.0 - (g.origin[1] - flat.uv[:, 1]) * g.scale / height
    header = (f"potflat {__version__}: {flat.mesh.source.name if flat.mesh.source else 'flattening'}, "
              f"units {flat.mesh.units}; texture coordinates = the flat layout in {texture_name} "
              f"({g.px_per_mm:g} px/mm)")
    return write_textured_obj(path, flat.mesh.vertices, flat.mesh.faces, vt, flat.mesh.faces, texture_name,
                              header=header)


def _check_not_inputs(out_dir: Path, name: str, options: BakeOptions, inputs: list) -> None:
    """Refuse to bake when an output name is an input file (e.g. the scan's texture ``NAME.png``
    when baking into the scan's own folder): the input would be replaced."""
    suffixes = (".png", ".tif", ".position.tif", ".sheet.png", ".bake.json", ".overlay.png", ".scale-layer.png",
                ".attachments.png", ".flat.obj", ".flat.mtl", ".plate.svg", ".plate.pdf", ".plate.png",
                ".scalebar.png", *(f".{m}.png" for m in options.maps))
    for src in (Path(p) for p in inputs if p is not None):
        for out in (out_dir / f"{name}{s}" for s in suffixes):
            if src.exists() and out.exists() and os.path.samefile(out, src):
                raise InvalidOptionError(f"the output {out} is the input {src} and would be overwritten; "
                                         "bake into another folder (-o) or give another --name")


@reuse_freed_memory()  # (its many large temporaries; its peak is under the relax stage's)
def run_bake_stage(flat_ply: str | os.PathLike, out_dir: str | os.PathLike, options: BakeOptions | None = None, *,
                   name: str | None = None, flat: FlatMesh | None = None,
                   rollout_summary: dict | None = None, distortion: DistortionSummary | None = None,
                   zone: ZoneSummary | None = None, reference: SurfaceReference | None = None) -> StageOutput:
    """Bake ``NAME.relaxed.ply`` (or a rollout) into images and ``NAME.bake.json``.

    Files (in ``out_dir``): ``NAME.png`` (painting, RGBA, resolution in the file),
    ``NAME.<map>.png`` (heat maps with a colour bar below the image),
    ``NAME.overlay.png`` (stress over the greyscale painting), ``NAME.scale-layer.png``
    (scale bar and optional 10 mm grid, same size as ``NAME.png``), ``NAME.scalebar.png``
    (the bar alone, true scale), optionally ``NAME.tif`` (16-bit RGBA),
    ``NAME.position.tif`` (float32 3D points) and ``NAME.sheet.png``, and
    ``NAME.attachments.png`` (where handles or other attachments left out by the rollout met
    the wall, from ``NAME.rollout.json`` beside the input); all images share
    the pixel grid of ``NAME.png`` (maps add a legend band below it).

    Parameters
    ----------
    flat_ply : path-like
        A stage file from ``potflat relax`` (``NAME.relaxed.ply``) or ``potflat rollout``.
    out_dir : path-like
        Output folder (created).
    options : BakeOptions, optional
    name : str, optional
        Output NAME; default: the input stem without ``.relaxed``.
    flat : FlatMesh, optional
        The content of ``flat_ply`` already in memory (:func:`potflat.run_scan`); read from
        the file when not given.
    rollout_summary : dict, optional
        The rollout stage's summary in memory (where attachments met the wall); read from
        ``NAME.rollout.json`` beside the input when not given.
    distortion : DistortionSummary, optional
        The whole-surface figures of ``flat`` when the caller has them (:func:`potflat.run_scan`:
        the relax stage's); computed when not given.
    zone : ZoneSummary, optional
        :func:`potflat.mesh.distortion.zone_summary` of ``flat`` when the caller has it (the
        relax stage's ``important_zone``, ``rest`` and ``lengths``); computed when not given.
    reference : SurfaceReference, optional
        The 3D side of ``flat``'s figures (:class:`potflat.mesh.distortion.SurfaceReference`)
        when the caller has it (:func:`potflat.run_scan`: the relax stage's); built when not given.

    Returns
    -------
    StageOutput
        ``paths`` by role and the JSON sidecar content as ``summary``.
    """
    from potflat.bake import annotate
    from potflat.io.atomic import write_json_atomic
    from potflat.io.images import PngWriter, write_png, write_tiff_rows
    from potflat.io.flat_ply import read_flat_ply
    from potflat.stages.provenance import provenance

    options = options or BakeOptions()
    flat_ply = Path(flat_ply)
    out_dir = Path(out_dir)
    name = name or stage_name(flat_ply)
    clock = StepClock()
    if flat is None:
        flat = read_flat_ply(flat_ply)
    rollout_ply = None
    if options.sheet:
        if not flat_ply.name.endswith(".relaxed.ply"):
            raise InvalidOptionError(f"the sheet compares NAME.rollout.ply with NAME.relaxed.ply; bake the relaxed file, not {flat_ply.name}")
        rollout_ply = flat_ply.with_name(flat_ply.name[: -len(".relaxed.ply")] + ".rollout.ply")
        if not rollout_ply.is_file():
            raise InvalidInputError(f"--sheet needs {rollout_ply.name} beside {flat_ply}; copy it there or drop --sheet")
    if options.plate and not flat_ply.name.endswith(".relaxed.ply"):
        raise InvalidOptionError(f"the plate is made from NAME.relaxed.ply; bake the relaxed file, not {flat_ply.name}")
    _check_not_inputs(out_dir, name, options, [flat_ply, flat.mesh.texture_path, rollout_ply])
    sidecar, rollout_json = _rollout_sidecar(flat_ply, rollout_summary)
    attachment_marks = _attachment_roots(sidecar, len(flat.mesh.faces))
    repeated = _repeated_faces(sidecar, len(flat.mesh.faces))
    folded = _folded_faces(sidecar, len(flat.mesh.faces))
    ppm = options.resolution
    r = Renderer(flat, ppm, supersample=options.supersample, max_megapixels=options.max_megapixels,
                 summary=distortion, zone=zone, reference=reference)
    g = r.grid
    clock.lap("prepare")
    if len(attachment_marks):
        r.face_values["attachments"] = attachment_marks
    if len(repeated):
        r.face_values["repeated"] = repeated
    if len(folded):
        r.face_values["folded"] = folded
    paths: dict[str, Path] = {"png": out_dir / f"{name}.png"}
    scales = {m: annotate.map_scale(m, r.vertex_length_error if m == "stress" else r.face_values[m])
              for m in options.maps}
    if flat.importance is not None:
        scales = {m: replace(sc, label=f"{sc.label}; {sc.outline} line: painted zone") for m, sc in scales.items()}
    if len(folded):
        scales = {m: replace(sc, label=f"{sc.label}; hatched: folded scan") for m, sc in scales.items()}
    legends = {m: annotate.legend_band(scales[m], g.width) for m in options.maps}
    if "stress" in options.maps:
        legends["overlay"] = legends["stress"]
    layer = annotate.ScaleLayer(g.width, g.height, ppm, grid=options.grid)
    on_image, band = scale_layer_on_image(r, options.grid) if options.scale_on_image else (None, 0)
    covered = 0.0
    with ExitStack() as stack:
        png = stack.enter_context(PngWriter(paths["png"], g.width, g.height + band, 4, px_per_mm=ppm))
        writers = {}
        for key, legend in legends.items():
            paths[key] = out_dir / f"{name}.{key}.png"
            writers[key] = stack.enter_context(PngWriter(paths[key], g.width, g.height + len(legend), 4,
                                                         px_per_mm=ppm))
        paths["scale_layer"] = out_dir / f"{name}.scale-layer.png"
        layer_png = stack.enter_context(PngWriter(paths["scale_layer"], g.width, g.height, 4, px_per_mm=ppm))
        if len(attachment_marks):
            paths["attachments"] = out_dir / f"{name}.attachments.png"
            mask_png = stack.enter_context(PngWriter(paths["attachments"], g.width, g.height, 4, px_per_mm=ppm))
        for r0, r1 in r.strips():
            cov = r.coverage(r0, r1)
            covered += float(cov.sum(dtype=np.float64))
            rgb = r.painting(r0, r1)
            rgba = rgba8(rgb, cov)
            if len(repeated):
                rgba[repeat_line(r.scalar("repeated", r0, r1), r0)] = REPEAT_COLOUR
            png.write(rgba if on_image is None else annotate.over(on_image.rows(r0, r1), rgba))
            outline = r.zone_outline(r0, r1) if options.maps else None
            hatch = folded_hatch(r.scalar("folded", r0, r1), r0) if options.maps and len(folded) else None
            for m in options.maps:
                values = r.scalar(m, r0, r1)
                rows = annotate.draw_outline(annotate.colorize(values, scales[m], cov), outline,
                                             annotate.OUTLINE_RGBA[scales[m].outline])
                writers[m].write(annotate.draw_outline(rows, hatch, FOLDED_COLOUR))
                if m == "stress":
                    rows = annotate.draw_outline(annotate.overlay(rgb, values, scales[m], cov), outline,
                                                 annotate.OUTLINE_RGBA[scales[m].outline])
                    writers["overlay"].write(annotate.draw_outline(rows, hatch, FOLDED_COLOUR))
            layer_png.write(layer.rows(r0, r1))
            if len(attachment_marks):
                mask_png.write(attachment_rows(r.scalar("attachments", r0, r1)))
        if band:
            png.write(on_image.rows(g.height, g.height + band))
        for key, legend in legends.items():
            writers[key].write(legend)
    paths["scalebar"] = write_png(out_dir / f"{name}.scalebar.png", layer.bar_image(), px_per_mm=ppm)
    clock.lap("render")
    if options.tiff:
        paths["tiff"] = write_tiff_rows(out_dir / f"{name}.tif",
                                        (rgba16(r.painting(a, b), r.coverage(a, b)) for a, b in r.strips()),
                                        shape=(g.height, g.width, 4), dtype=np.uint16, px_per_mm=ppm, photometric="rgb")
    if options.position_map:
        paths["position"] = write_tiff_rows(out_dir / f"{name}.position.tif", (r.position(a, b) for a, b in r.strips()),
                                            shape=(g.height, g.width, 3), dtype=np.float32, px_per_mm=ppm,
                                            photometric="rgb")
    clock.lap("tiff")
    figures = image_figures(r, covered)
    clock.lap("figures")
    if options.obj:
        paths["obj"] = _write_flat_obj(out_dir / f"{name}.flat.obj", flat, g, band, paths["png"].name)
        paths["mtl"] = paths["obj"].with_suffix(".mtl")
    if rollout_ply is not None:
        paths["sheet"] = comparison_sheet(out_dir / f"{name}.sheet.png", read_flat_ply(rollout_ply), flat, title=name)
    clock.lap("obj_sheet")
    inputs = ([flat_ply] + ([flat.mesh.texture_path] if r.texture is not None else [])
              + ([rollout_ply] if rollout_ply else []) + ([rollout_json] if rollout_json else []))
    summary = {
        **figures,
        "overlap": None if not len(repeated) else {
            "deg": sidecar["region"].get("overlap_deg"), "repeated_faces": int(repeated.sum()),
            "mark": f"dashed line {REPEAT_COLOUR[:3]} where the repeat past 360 degrees starts"},
        "folded": None if not len(folded) else {
            **{k: sidecar["folded"].get(k) for k in ("faces", "area_mm2", "percent_of_surface", "regions_total")},
            "mark": f"outlined and hatched {FOLDED_COLOUR[:3]} on the distortion maps and the overlay: where the scan "
                    "folds over itself in 3D (see NAME.rollout.json, folded)"},
        "scale_bar_mm": layer.bar_mm,
        "scale_on_image": None if on_image is None else {
            "bar_mm": on_image.bar_mm, "at_px": list(on_image.at), "box_px": list(on_image.box_size),
            "band_below_px": band, "grid": options.grid},
        "maps": {m: {"range": [scales[m].lo, scales[m].hi], "label": scales[m].label} for m in options.maps},
        "files": {k: p.name for k, p in paths.items()},
        "provenance": provenance(stage="bake", inputs=inputs,
                                 options={**asdict(options), "px_per_mm_effective": ppm, "name": name}),
    }
    paths["json"] = out_dir / f"{name}.bake.json"
    summary["files"]["json"] = paths["json"].name
    summary["timings"] = clock.total()  # the plate (made from these files) comes after
    write_json_atomic(paths["json"], summary)
    if options.plate:
        from potflat.bake.plate import make_plate

        plate = make_plate(flat_ply, out_dir, scale=options.plate_scale, name=name)
        paths.update({f"plate_{k}": p for k, p in plate.paths.items()})
        summary["files"].update({f"plate_{k}": p.name for k, p in plate.paths.items()})
        summary["plate"] = {k: v for k, v in plate.summary.items() if k not in ("files", "inputs")}
        write_json_atomic(paths["json"], summary)
    return StageOutput(paths=paths, summary=summary)
