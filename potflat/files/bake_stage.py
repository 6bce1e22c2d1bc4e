"""The bake's file stage: bake ``NAME.relaxed.ply`` (or a rollout) into ``NAME.png``, the
distortion maps, the scale layers, optional TIFFs, OBJ, sheet and plate, and
``NAME.bake.json``; the base left out of the rollout (``NAME.base.ply``) into ``NAME.base.png``
and its own maps and ``NAME.base.bake.json``. The images are streamed strip by strip from
:class:`potflat.bake.compose.Composition`; what the rollout marks comes in memory
(:class:`potflat.types.RolloutMarks`) or from ``NAME.rollout.json`` beside the input."""
from __future__ import annotations

import dataclasses
import json
import os
from contextlib import ExitStack
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from potflat import __version__
from potflat._heap import reuse_freed_memory
from potflat.bake import annotate
from potflat.bake.compose import Composition, bake
from potflat.bake.marks import FOLDED_COLOUR, REPEAT_COLOUR, rgba16
from potflat.bake.options import BakeOptions
from potflat.bake.relief import raking_key
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.files.names import (BASE_NAME_SUFFIX, STAGE_OUTPUTS, STAGES_FROM, base_ply_beside, rollout_json_beside,
                                 stage_name)
from potflat.files.outputs import superseding
from potflat.files.plate import make_plate
from potflat.files.provenance import provenance
from potflat.files.relax_stage import RelaxFiles
from potflat.io.atomic import write_bytes_atomic, write_json_atomic
from potflat.io.flat_ply import read_flat_ply
from potflat.io.images import PngWriter, TiffWriter, write_png, write_tiff_rows
from potflat.io.obj import write_textured_obj
from potflat.raster.render import Grid, Renderer
from potflat.types import FlatMesh, RolloutMarks, StepClock


@dataclass(frozen=True)
class BakeFiles:
    """What the bake's file stage wrote.

    Attributes
    ----------
    paths : dict of str to Path
        Role (``"png"``, ``"stress"``, ``"overlay"``, ``"json"``...) to the file written.
    record : dict
        The content of ``NAME.bake.json``, as written.
    """

    paths: dict[str, Path]
    record: dict


def _face_list(listed) -> np.ndarray:
    """Face indices from a sidecar's list (k,) int64; empty when not a list of whole numbers."""
    if not isinstance(listed, list) or not all(isinstance(f, int) and not isinstance(f, bool) for f in listed):
        return np.zeros(0, np.int64)
    return np.asarray(listed, dtype=np.int64)


def marks_from_record(record: dict, n_faces: int) -> RolloutMarks:
    """What the rollout marks, read from the content of ``NAME.rollout.json`` (a file the
    user may have edited: anything of the wrong shape marks nothing)."""
    att = record.get("attachments")
    roots = (_face_list(att.get("root_faces")) if isinstance(att, dict) and not att.get("kept")
             else np.zeros(0, np.int64))
    region = record.get("region")
    start = region.get("repeated_from") if isinstance(region, dict) else None
    repeated = (isinstance(start, int) and not isinstance(start, bool) and region.get("faces") == n_faces
                and 0 < start < n_faces)
    folded = record.get("folded")
    folded = folded if isinstance(folded, dict) else {}
    return RolloutMarks(attachment_roots=roots, repeated_from=start if repeated else None,
                        overlap_deg=region.get("overlap_deg") if repeated else 0.0,
                        folded_faces=_face_list(folded.get("face_indices")),
                        folded_area_mm2=folded.get("area_mm2", 0.0),
                        folded_percent=folded.get("percent_of_surface", 0.0),
                        folded_regions=folded.get("regions_total", 0))


def _rollout_record_beside(flat_ply: Path) -> tuple[dict, Path | None]:
    """The content of ``NAME.rollout.json`` beside a stage file (an empty dict when absent,
    unreadable or not an object) and that file (None when absent or unreadable)."""
    rollout_json = rollout_json_beside(flat_ply)
    try:
        data = json.loads(rollout_json.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}, None
    return (data if isinstance(data, dict) else {}), rollout_json


def _write_comparison_sheet(path: Path, rollout: FlatMesh, relaxed: FlatMesh, *, title: str) -> Path:
    """Bake the proxy rollout and the relaxed flattening and write them side by side
    (:func:`potflat.bake.annotate.comparison_sheet`) as a PNG."""
    panels = [(label, flat, bake(flat, px_per_mm=annotate.sheet_px_per_mm(flat), maps=("stress",)))
              for label, flat in (("proxy rollout", rollout), ("relaxed", relaxed))]
    return write_bytes_atomic(path, annotate.comparison_sheet(panels, title=title))


def _write_flat_obj(path: Path, flat: FlatMesh, g: Grid, band: int, texture_name: str) -> Path:
    """The flattened surface as a textured OBJ: 3D positions, texture coordinates = the flat
    coordinates in the pixel grid of ``NAME.png`` (``band`` rows added below it)."""
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
    suffixes = (*STAGE_OUTPUTS["bake"], *(f".{raking_key(a)}.png" for a in options.relief_light))
    for src in (Path(p) for p in inputs if p is not None):
        for out in (out_dir / f"{name}{s}" for s in suffixes):
            if src.exists() and out.exists() and os.path.samefile(out, src):
                raise InvalidOptionError(f"the output {out} is the input {src} and would be overwritten; "
                                         "bake into another folder (-o) or give another --name")


def _base_options(options: BakeOptions) -> BakeOptions:
    """The options the base's disc is baked with: the painting's, with its scale bar drawn into
    the image (a disc leaves a corner free), without the sheet, plate and OBJ (made of the
    relaxed flattening)."""
    return dataclasses.replace(options, sheet=False, plate=False, obj=False, scale_on_image=True)


@reuse_freed_memory()  # (its many large temporaries; its peak is under the relax stage's)
def run_bake_stage(flat_ply: str | os.PathLike, out_dir: str | os.PathLike, options: BakeOptions | None = None, *,
                   name: str | None = None, relaxed: RelaxFiles | None = None,
                   marks: RolloutMarks | None = None, flat: FlatMesh | None = None,
                   base: FlatMesh | None = None) -> BakeFiles:
    """Bake ``NAME.relaxed.ply`` (or a rollout) into images and ``NAME.bake.json``.

    Files (in ``out_dir``): ``NAME.png`` (painting, RGBA, resolution in the file),
    ``NAME.<map>.png`` (heat maps with a colour bar below the image),
    ``NAME.overlay.png`` (stress over the greyscale painting), ``NAME.scale-layer.png``
    (scale bar and optional 10 mm grid, same size as ``NAME.png``), ``NAME.scalebar.png``
    (the bar alone, true scale), optionally ``NAME.tif`` (16-bit RGBA),
    ``NAME.position.tif`` (float32 3D points) and ``NAME.sheet.png``, and
    ``NAME.attachments.png`` (where handles or other attachments left out by the rollout met
    the wall), with ``relief`` ``NAME.relief.tif`` (16-bit heights in mm), ``NAME.relief.png``,
    ``NAME.raking-AZ.png``, ``NAME.curvature.png`` and ``NAME.relief-overlay.png``
    (:mod:`potflat.bake.relief`); all images share the pixel grid of ``NAME.png`` (maps and
    some relief images add a legend band below it, and so does ``NAME.png`` when it is an
    untextured scan's relief). Baking ``NAME.relaxed.ply`` also bakes the base the rollout
    left out (``NAME.base.ply`` beside it) into ``NAME.base.png`` (its scale bar in the image),
    its maps and ``NAME.base.bake.json``, listed under ``base_`` in :attr:`BakeFiles.paths`.

    Parameters
    ----------
    flat_ply : path-like
        A stage file from ``potflat relax`` (``NAME.relaxed.ply``) or ``potflat rollout``.
    out_dir : path-like
        Output folder (created).
    options : BakeOptions, optional
    name : str, optional
        Output NAME; default: the input stem without ``.relaxed``.
    relaxed : RelaxFiles, optional
        What the relax stage's file stage wrote in this run (:func:`potflat.run_scan`): its
        flattening and figures are taken from there instead of ``flat_ply``.
    marks : RolloutMarks, optional
        What the rollout of this run marks; read from ``NAME.rollout.json`` beside the input
        when not given.
    flat : FlatMesh, optional
        The flattening ``flat_ply`` holds, when the caller has it (read otherwise).
    base : FlatMesh, optional
        The base's disc ``NAME.base.ply`` holds, when the caller has it (read otherwise).

    Returns
    -------
    BakeFiles
    """
    options = options or BakeOptions()
    flat_ply = Path(flat_ply)
    out_dir = Path(out_dir)
    name = name or stage_name(flat_ply)
    clock = StepClock()
    if flat is None:
        flat = relaxed.flat if relaxed is not None else read_flat_ply(flat_ply)
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
    rollout_json = rollout_json_beside(flat_ply)
    if marks is None:
        record, rollout_json = _rollout_record_beside(flat_ply)
        marks = marks_from_record(record, len(flat.mesh.faces))
    elif not rollout_json.is_file():
        rollout_json = None
    with superseding(out_dir, name, STAGES_FROM["bake"],
                     keep=lambda: (p for p in (flat_ply, flat.mesh.texture_path, rollout_ply, rollout_json,
                                                        base_ply_beside(flat_ply)) if p)):
        ppm = options.resolution
        try:
            r = Renderer(flat, ppm, supersample=options.supersample, max_megapixels=options.max_megapixels,
                         summary=relaxed.distortion if relaxed is not None else None,
                         zone=relaxed.zone if relaxed is not None else None,
                         reference=relaxed.reference if relaxed is not None else None, relief_mm=options.relief_mm)
        except InvalidOptionError as exc:  # the image's size: name the file
            raise InvalidOptionError(f"{flat_ply}: {exc}") from None
        g = r.grid
        clock.lap("prepare")
        if options.relief or r.paints_relief:
            r.relief  # noqa: B018 - the relief's fits, timed apart (made on first use)
            clock.lap("relief")
        comp = Composition(r, options, marks=marks)
        relief = comp.relief
        paths: dict[str, Path] = {"png": out_dir / f"{name}.png"}
        with ExitStack() as stack:
            png = stack.enter_context(PngWriter(paths["png"], g.width, g.height + comp.band, 4, px_per_mm=ppm))
            writers = {}
            for key, legend in comp.legends.items():
                paths[key] = out_dir / f"{name}.{key}.png"
                writers[key] = stack.enter_context(PngWriter(paths[key], g.width, g.height + len(legend), 4,
                                                             px_per_mm=ppm))
            paths["scale_layer"] = out_dir / f"{name}.scale-layer.png"
            layer_png = stack.enter_context(PngWriter(paths["scale_layer"], g.width, g.height, 4, px_per_mm=ppm))
            if len(comp.attachments):
                paths["attachments"] = out_dir / f"{name}.attachments.png"
                mask_png = stack.enter_context(PngWriter(paths["attachments"], g.width, g.height, 4, px_per_mm=ppm))
            relief_writers = {}
            if relief is not None:
                paths["relief_tif"] = out_dir / f"{name}.relief.tif"
                relief_tif = stack.enter_context(TiffWriter(paths["relief_tif"], shape=(g.height, g.width),
                                                            dtype=np.uint16, px_per_mm=ppm, photometric="minisblack",
                                                            description=relief.tiff_description()))
                for key in relief.keys:
                    paths[key] = out_dir / f"{name}.{key}.png"
                    relief_writers[key] = stack.enter_context(PngWriter(
                        paths[key], g.width, g.height + len(relief.legends.get(key, ())), relief.channels[key],
                        px_per_mm=ppm))
            for strip in comp.strips():
                png.write(strip.painting)
                for key, writer in writers.items():
                    writer.write(strip.maps[key])
                layer_png.write(strip.scale_layer)
                if strip.attachments is not None:
                    mask_png.write(strip.attachments)
                for key, writer in relief_writers.items():
                    writer.write(strip.relief[key])
                if relief is not None:
                    relief_tif.write(strip.relief["levels"])
            if comp.band:
                png.write(comp.band_rows())
            for key, legend in comp.legends.items():
                writers[key].write(legend)
            for key, legend in (relief.legends.items() if relief is not None else ()):
                relief_writers[key].write(legend)
        paths["scalebar"] = write_png(out_dir / f"{name}.scalebar.png", comp.layer.bar_image(), px_per_mm=ppm)
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
        figures = comp.figures()
        clock.lap("figures")
        # the painting's renderer (its texture and mip levels: gigabytes for a scan with several
        # large texture images) is let go before the base's renderer reads its own
        textured, band, scales = r.texture is not None, comp.band, comp.scales
        repeated, folded, bar_mm, on_image, scale_band = (comp.repeated, comp.folded, comp.layer.bar_mm, comp.on_image,
                                                          comp.scale_band)
        del r, comp, relief
        base_files, base_ply = None, None
        if flat_ply.name.endswith(".relaxed.ply"):
            base_ply = base_ply_beside(flat_ply)
            if base is None and base_ply.is_file():
                base = read_flat_ply(base_ply)
            if base is not None:
                base_files = run_bake_stage(base_ply, out_dir, _base_options(options),
                                            name=f"{name}{BASE_NAME_SUFFIX}", flat=base, marks=RolloutMarks())
                paths.update({f"base_{k}": p for k, p in base_files.paths.items()})
            clock.lap("base")
        if options.obj:
            paths["obj"] = _write_flat_obj(out_dir / f"{name}.flat.obj", flat, g, band, paths["png"].name)
            paths["mtl"] = paths["obj"].with_suffix(".mtl")
        if rollout_ply is not None:
            paths["sheet"] = _write_comparison_sheet(out_dir / f"{name}.sheet.png", read_flat_ply(rollout_ply), flat,
                                                     title=name)
        clock.lap("obj_sheet")
        inputs = ([flat_ply] + ([flat.mesh.texture_path] if textured else [])
                  + ([rollout_ply] if rollout_ply else []) + ([rollout_json] if rollout_json else [])
                  + ([base_ply] if base_files is not None else []))
        record = {
            **figures,
            "overlap": None if not len(repeated) else {
                "deg": marks.overlap_deg, "repeated_faces": int(repeated.sum()),
                "mark": f"dashed line {REPEAT_COLOUR[:3]} where the repeat past 360 degrees starts"},
            "folded": None if not len(folded) else {
                "faces": int(len(marks.folded_faces)), "area_mm2": marks.folded_area_mm2,
                "percent_of_surface": marks.folded_percent, "regions_total": marks.folded_regions,
                "mark": f"outlined and hatched {FOLDED_COLOUR[:3]} on the distortion maps and the overlay: where the scan "
                        "folds over itself in 3D (see NAME.rollout.json, folded)"},
            "base": None if base_files is None else {
                "what": "the base (the floor, inside) left out of the rollout, seen along the axis; its figures are in "
                        f"{base_files.paths['json'].name}",
                "files": base_files.record["files"], "image_mm": base_files.record["image_mm"],
                "lengths": base_files.record.get("lengths")},
            "scale_bar_mm": bar_mm,
            "scale_on_image": None if on_image is None else {
                "bar_mm": on_image.bar_mm, "at_px": list(on_image.at), "box_px": list(on_image.box_size),
                "band_below_px": scale_band, "grid": options.grid},
            "maps": {m: {"range": [scales[m].lo, scales[m].hi], "label": scales[m].label} for m in options.maps},
            "files": {k: p.name for k, p in paths.items()},
            "provenance": provenance(stage="bake", inputs=inputs,
                                     options={**asdict(options), "px_per_mm_effective": ppm, "name": name}),
        }
        paths["json"] = out_dir / f"{name}.bake.json"
        record["files"]["json"] = paths["json"].name
        record["timings"] = clock.total()  # the plate (made from these files) comes after
        write_json_atomic(paths["json"], record)
        if options.plate:
            plate = make_plate(flat_ply, out_dir, scale=options.plate_scale, name=name, image=options.plate_image)
            paths.update({f"plate_{k}": p for k, p in plate.paths.items()})
            record["files"].update({f"plate_{k}": p.name for k, p in plate.paths.items()})
            record["plate"] = {k: v for k, v in plate.record.items() if k not in ("files", "inputs")}
            write_json_atomic(paths["json"], record)
    return BakeFiles(paths=paths, record=record)
