"""The rollout's file stage: read a scan, roll it out, write ``NAME.rollout.ply``,
``NAME.rollout.json`` (see ``docs/formats.md``) and the profile ``NAME.profile.csv`` /
``NAME.profile.svg`` (see ``docs/profile.md``). The algorithm is :mod:`potflat.rollout`."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from potflat import __version__
from potflat._heap import reuse_freed_memory
from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.files.names import STAGES_FROM
from potflat.files.outputs import superseding
from potflat.files.provenance import provenance
from potflat.io.atomic import check_output_name, write_json_atomic
from potflat.io.flat_ply import as_stored, write_flat_ply
from potflat.io.scan import check_plausible_size, check_scan_file, load_scan, scan_inputs
from potflat.mesh.distortion import DistortionSummary
from potflat.rollout.notes import rollout_notes
from potflat.rollout.options import RolloutOptions
from potflat.rollout.profile import write_profile_csv, write_profile_svg
from potflat.rollout.unroll import RolloutResult, rollout
from potflat.types import FlatMesh, RolloutMarks, StepClock


@dataclass(frozen=True, eq=False)
class RolloutFiles:
    """What the rollout's file stage wrote, and what the next stage takes in memory.

    Attributes
    ----------
    paths : dict of str to Path
        ``"ply"``, ``"json"``, ``"profile_csv"``, ``"profile_svg"`` to the file written.
    record : dict
        The content of ``NAME.rollout.json``, as written.
    flat : FlatMesh
        The flattening exactly as ``NAME.rollout.ply`` holds it (what ``potflat relax``
        reads from the file).
    distortion : DistortionSummary
        Its distortion figures.
    marks : RolloutMarks
        What the bake marks on the images (attachment roots, the repeat, folded faces).
    base : FlatMesh or None
        The base left out of the rollout, seen along the axis, as ``NAME.base.ply`` holds it
        (None when the rollout kept it or there is none).
    """

    paths: dict[str, Path]
    record: dict
    flat: FlatMesh
    distortion: DistortionSummary
    marks: RolloutMarks
    base: FlatMesh | None = None


@reuse_freed_memory()  # (its many large temporaries: see reuse_freed_memory for the trade)
def run_rollout_stage(scan_path, out_dir, options: RolloutOptions | None = None, *,
                      name: str | None = None, check: Callable[[FlatMesh], None] | None = None) -> RolloutFiles:
    """Read a scan, roll it out, write ``NAME.rollout.ply``, ``NAME.rollout.json`` and its profile.

    A base left out of the rollout (:mod:`potflat.rollout.base`) is written as ``NAME.base.ply``,
    its orthographic view along the axis, for the bake. The rollout's profile
    (:attr:`RolloutResult.profile`: both walls around its axis,
    attachments left out) is written as ``NAME.profile.csv`` and ``NAME.profile.svg`` (a
    section drawing, see ``docs/profile.md``).

    Parameters
    ----------
    scan_path : path-like
        The scan (any format :func:`potflat.io.scan.load_scan` reads).
    out_dir : path-like
        Output folder (created if needed).
    options : RolloutOptions, optional
    name : str, optional
        Output stem; default: the scan's file stem.
    check : callable, optional
        Called with the flattening before anything is written; it may raise to stop the run
        (``potflat run`` checks the size of the image to come).

    Returns
    -------
    RolloutFiles

    Raises
    ------
    InvalidOptionError
        When an output would overwrite the input, or the name is not a plain file stem.
    """
    options = options or RolloutOptions()
    scan_path, out_dir = Path(scan_path), Path(out_dir)
    name = check_output_name(name or scan_path.stem, what="name" if name else f"the name of {scan_path}")
    paths = {"ply": out_dir / f"{name}.rollout.ply", "json": out_dir / f"{name}.rollout.json",
             "profile_csv": out_dir / f"{name}.profile.csv", "profile_svg": out_dir / f"{name}.profile.svg"}
    base_ply = out_dir / f"{name}.base.ply"
    for out in (*paths.values(), base_ply):
        if out.resolve() == scan_path.resolve():
            raise InvalidOptionError(
                f"output {out} would overwrite the input scan; choose another output folder or --name")
    check_scan_file(scan_path)
    with superseding(out_dir, name, STAGES_FROM["rollout"],
                     keep=lambda: (scan_path, *scan_inputs(scan_path), *options.input_files())):
        clock = StepClock()
        loaded = load_scan(scan_path, units=options.units, texture="use" if options.texture else "ignore",
                           outward=not options.keep_orientation)
        check_plausible_size(loaded, scan_path)
        mesh, cleaning = loaded.mesh, loaded.report.as_dict()
        del loaded
        clock.lap("load")
        result = rollout(mesh, options=options)
        clock.lap("rollout")
        if check is not None:
            check(result.flat)
        del mesh
        profile = result.profile
        if not np.isfinite(profile.outer_radius).any():  # (its drawing, and every later stage, needs an outer wall)
            raise InvalidInputError(
                f"{scan_path}: no part of it faces away from the axis found, so it has no outer wall to unroll (a flat "
                "piece such as a tile or a plate's floor, or a vessel's inside alone); give the scan of a vessel or a "
                "sherd, or its axis with --axis px,py,pz,dx,dy,dz")
        record = {"stage": "rollout", "name": name, "input": str(scan_path), **rollout_record(result),
                  "profile": profile.summary(),
                  "cleaning": cleaning,
                  "files": {role: path.name for role, path in paths.items()}}
        record["provenance"] = provenance(stage="rollout", inputs=[scan_path], options=options.as_dict())
        comments = (f"potflat {__version__} rollout of {scan_path.name}",)
        write_flat_ply(paths["ply"], result.flat, comments=comments)
        base = result.base.flat if result.base is not None else None
        if base is not None:
            base_comments = (f"potflat {__version__} base of {scan_path.name}, seen from {result.base.view}",)
            paths["base_ply"] = write_flat_ply(base_ply, base, comments=base_comments)
            record["files"]["base_ply"] = base_ply.name
        write_profile_csv(profile, paths["profile_csv"])
        write_profile_svg(profile, paths["profile_svg"], title=f"{name}: profile ({profile.units})")
        clock.lap("write")
        record["timings"] = {**clock.total(), "rollout_steps": result.timings}
        write_json_atomic(paths["json"], record)
    return RolloutFiles(paths=paths, record=record, flat=as_stored(result.flat, paths["ply"], comments=comments),
                        distortion=result.distortion, marks=result.marks,
                        base=None if base is None else as_stored(base, base_ply, comments=base_comments))


def base_line(base: dict, base_ply: Path | None) -> str:
    """One line of a run's summary: where the faces at the foot facing along the axis went
    (``base``: the ``base`` block of ``NAME.rollout.json``; ``base_ply``: the disc's file)."""
    what = "base" if base["view"] == "below" else "floor"
    if not base["left_out"]:
        return f"{what} kept in the rollout ({base['candidate_faces']} faces facing along the axis): {base['reason']}"
    where = f" in {base_ply.name}" if base_ply is not None else ""
    return (f"{what} left out of the rollout ({base['faces_in_disc']} faces, {base['area_in_disc_mm2']:.4g} mm\N{SUPERSCRIPT TWO}, "
            f"{base['percent_of_region']:.0f} % of the surface), shown on its own{where}: {base['reason']}; "
            "--keep-base keeps it in the rollout")


def rollout_record(result: RolloutResult) -> dict:
    """The figures of a rollout as ``NAME.rollout.json`` records them (without the file and
    provenance fields)."""
    mesh = result.flat.mesh
    return {
        "units": mesh.units,
        "mm_per_unit": mesh.mm_per_unit,
        "axis": result.axis.as_dict(),
        "proxy": result.proxy.as_dict(),
        "seam": {"angle_deg": result.seam_angle, "method": result.seam_method, "cut": result.region.cut,
                 "landmark": result.landmark.as_dict() if result.landmark is not None else None,
                 "theta_origin_deg": result.theta_origin},
        "region": result.region.as_dict(),
        "counts": {
            "vertices": len(mesh.vertices), "faces": len(mesh.faces),
            "input_faces": result.region.faces_total,
            "input_faces_unrolled": int(np.count_nonzero(np.bincount(result.face_index))),
            "input_vertices_used": int(len(result.vertex_index) - result.seam_vertices - result.split_vertices
                                       - result.cut_vertices),
            "seam_vertices_duplicated": result.seam_vertices,
            "vertices_added_by_cut": result.cut_vertices,
            "faces_split_by_cut": result.cut_faces,
            "nonmanifold_vertices_split": result.split_vertices,
        },
        "distortion": result.distortion.as_dict(),
        "importance": result.importance.as_dict() if result.importance is not None else None,
        "boundary_overlap": result.boundary_overlap,
        "outline_turning": result.outline_turning,
        "walls": {**result.walls.summary(), "line": None if result.wall_cut is None else result.wall_cut.summary()},
        "attachments": _attachments_summary(result),
        "base": result.base.summary(mesh.mm_per_unit) if result.base is not None else None,
        "trimmed": _trimmed_summary(result, mesh.mm_per_unit),
        "disk_cut": {"faces": len(result.disk_cut_faces), "area_mm2": result.disk_cut_area * mesh.mm_per_unit ** 2,
                     "handles": result.disk_cut.handles, "nonmanifold_edges": result.disk_cut.nonmanifold_edges,
                     "closed_parts": result.disk_cut.closed_parts, "reason": result.disk_cut.reason},
        "notes": rollout_notes(result),
        "folded": result.folds.as_dict() if result.folds is not None else None,
        "untangled": {"faces": result.untangled_faces, "vertices_moved": result.untangled_vertices,
                      "reason": "faces folded inside the development by the scan's own creases and "
                                "slivers, unfolded by moving their vertices to their neighbours' mean"},
    }


def _attachments_summary(result: RolloutResult) -> dict:
    att = result.attachments
    summary = att.summary()
    return {**summary, "kept": result.attachments_kept,
            "faces_left_out": 0 if result.attachments_kept else att.n_faces,
            "area_left_out_mm2": 0.0 if result.attachments_kept else summary["area_mm2"],
            "root_faces": result.attachment_roots.tolist(),
            "root_faces_note": "rollout faces (indices into the PLY's faces) where a left-out "
                               "attachment met the wall, to mask in the bake"}


def _trimmed_summary(result: RolloutResult, mm_per_unit: float) -> dict:
    """Counts and area of the folded border faces left out (see :func:`potflat.rollout.border.border_folds`)."""
    return {"faces": len(result.trimmed), "area_mm2": result.trimmed_area * mm_per_unit ** 2,
            "reason": "border faces that fold the development over: strips edge-on to the proxy "
                      "(rim top, base underside, break faces) and overlapping border faces"}
