"""The relax stage's file stage: read ``NAME.rollout.ply`` (or take it in memory), relax it
(:func:`potflat.relax.relax`), write ``NAME.relaxed.ply`` and ``NAME.relaxed.json``."""
from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from potflat.errors import NotADiskError
from potflat.files.names import STAGES_FROM, relax_name
from potflat.files.outputs import superseding
from potflat.files.provenance import provenance
from potflat.files.rollout_stage import RolloutFiles
from potflat.io.atomic import write_json_atomic
from potflat.io.flat_ply import as_stored, read_flat_ply, write_flat_ply
from potflat.io.images import check_texture_image
from potflat.mesh.boundary import edges_and_boundary, outline_turning, surface_turning
from potflat.mesh.distortion import DistortionSummary, SurfaceReference, ZoneSummary
from potflat.relax.multilevel import relax
from potflat.relax.options import RelaxOptions
from potflat.relax.result import LevelRecord, RelaxResult
from potflat.types import FlatMesh, StepClock


@dataclass(frozen=True, eq=False)
class RelaxFiles:
    """What the relax stage's file stage wrote, and what the bake takes in memory.

    Attributes
    ----------
    paths : dict of str to Path
        ``"ply"`` and ``"json"`` to the file written.
    record : dict
        The content of ``NAME.relaxed.json``, as written.
    flat : FlatMesh
        The relaxed flattening exactly as ``NAME.relaxed.ply`` holds it.
    distortion : DistortionSummary
        Its distortion figures.
    zone : ZoneSummary
        Its painted zone's figures.
    reference : SurfaceReference or None
        The 3D side of those figures, for the bake of the same mesh (None once handed on).
    """

    paths: dict[str, Path]
    record: dict
    flat: FlatMesh
    distortion: DistortionSummary
    zone: ZoneSummary
    reference: SurfaceReference | None


def _history_for_json(h: np.ndarray, limit: int = 1000) -> list[float]:
    """The energy history, thinned to at most ``limit`` entries (first and last kept)."""
    if len(h) <= limit:
        return [float(e) for e in h]
    idx = np.unique(np.linspace(0, len(h) - 1, limit).round().astype(np.int64))
    return [float(h[i]) for i in idx]


def _settings_for_json(result: RelaxResult, options: RelaxOptions) -> dict:
    """The resolved settings as ``NAME.relaxed.json`` records them (the preset's fields it
    sets, the options applied, and the time budget)."""
    return {**{k: v for k, v in asdict(result.settings).items() if v is not None}, "time_budget": options.time_budget}


def _level_for_json(level: LevelRecord) -> dict:
    """One level of the relaxation as ``NAME.relaxed.json`` records it (the fields it has)."""
    return {k: v for k, v in asdict(level).items() if v is not None}


def _turning(start: FlatMesh, relaxed: FlatMesh) -> dict:
    """The outline's total turning (:func:`potflat.mesh.boundary.outline_turning`) of the
    rollout and of the relaxed layout (the same mesh), and the scan boundary's own on the
    surface (:func:`potflat.mesh.boundary.surface_turning`)."""
    segments = edges_and_boundary(start.mesh.faces, len(start.uv))[1]
    before, after = (outline_turning(start.mesh.faces, f.uv, segments=segments) for f in (start, relaxed))
    surface = surface_turning(start.mesh.vertices, start.mesh.faces, segments=segments)
    return {"rollout": before, "relaxed": after, "ratio": after / before if before > 0 else None,
            "surface": surface,
            "method": "sum of the absolute exterior angles of every boundary loop over 2 pi (1: convex outline); "
                      "surface: the same on the scan (pi less the 3D corner angles at each boundary vertex), "
                      "which a layout keeping every triangle's shape has"}


def _not_a_disk_advice(rollout_record: dict, rollout_json: Path) -> str:
    """What to do about a rollout that is not a disk, from what its record (``NAME.rollout.json``,
    ``rollout_json``; ``{}`` when there is none) says the rollout did."""
    fixes = []
    if "disk_cut" not in rollout_record:  # made before the rollout cut such parts open
        fixes.append("make the rollout again with potflat rollout, which cuts a handle joined at both ends, a closed "
                     "part or an edge of three faces open")
    attachments = rollout_record.get("attachments")
    if isinstance(attachments, dict) and attachments.get("kept") and attachments.get("faces"):
        fixes.append(f"run the rollout without --keep-attachments (it kept {attachments['faces']} faces of handles, "
                     "spouts or knobs)")
    folded = rollout_record.get("folded")
    regions = folded.get("regions") if isinstance(folded, dict) else None
    band = regions[0].get("band") if isinstance(regions, list) and regions and isinstance(regions[0], dict) else None
    if isinstance(band, list) and len(band) == 2 and all(isinstance(b, (int, float)) for b in band):
        fixes.append(f"or with --band LO HI leaving out where the scan folds over itself (in {rollout_json.name}: "
                     f"folded.regions[].band, the largest place at {band[0]:.2f} to {band[1]:.2f})")
    if not fixes:
        fixes.append("leave the part that folds out of the rollout (--band LO HI, --angles A0 A1)")
    return "; ".join(fixes)


def run_relax_stage(rollout_ply: str | Path, out_dir: str | Path, options: RelaxOptions | None = None, *,
                    name: str | None = None, progress: bool = False,
                    rolled: RolloutFiles | None = None,
                    check: Callable[[FlatMesh], None] | None = None) -> RelaxFiles:
    """Relax ``NAME.rollout.ply`` and write ``NAME.relaxed.ply`` and ``NAME.relaxed.json``.

    Parameters
    ----------
    rollout_ply : path-like
        The rollout stage's output.
    out_dir : path-like
        Folder for the outputs (created if needed).
    options : RelaxOptions, optional
    name : str, optional
        Output stem (default: the input's name without ``.rollout.ply``).
    progress : bool
        Show a progress bar.
    rolled : RolloutFiles, optional
        What the rollout's file stage wrote in this run (:func:`potflat.run_scan`): its
        flattening, figures and record are taken from there instead of ``rollout_ply`` and
        ``NAME.rollout.json`` beside it.
    check : callable, optional
        Called with the relaxed flattening before anything is written; it may raise to stop the
        run (``potflat run`` checks the size of the image to come).

    Returns
    -------
    RelaxFiles
    """
    options = options or RelaxOptions()
    rollout_ply = Path(rollout_ply)
    out_dir = Path(out_dir)
    stem = relax_name(rollout_ply)
    name = name or stem
    clock = StepClock()
    if rolled is None:
        flat, distortion = read_flat_ply(rollout_ply), None
        clock.lap("read")
    else:
        flat, distortion = rolled.flat, rolled.distortion
    if flat.mesh.texture_path is not None:  # copied beside the output: missing or no image, say so before relaxing
        check_texture_image(flat.mesh.texture_path)
    rollout_json = rollout_ply.with_name(f"{stem}.rollout.json")
    rj = {}
    if rolled is not None or rollout_json.exists():
        try:
            rj = rolled.record if rolled is not None else json.loads(rollout_json.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            rj = {}
        if not isinstance(rj, dict):  # a sidecar holding null, a list...: nothing to copy from it
            rj = {}
    with superseding(out_dir, name, STAGES_FROM["relax"],
                     keep=lambda: (p for p in (rollout_ply, rollout_json, flat.mesh.texture_path) if p is not None)):
        try:
            result = relax(flat, options=options, progress=progress, distortion_before=distortion)
        except NotADiskError as exc:
            raise NotADiskError(f"{exc}: {_not_a_disk_advice(rj, rollout_json)}") from None
        clock.lap("relax")
        if check is not None:
            check(result.flat)
        ply_path = out_dir / f"{name}.relaxed.ply"
        json_path = out_dir / f"{name}.relaxed.json"
        record = {
            "preset": result.preset,
            "options": asdict(options),
            "settings": _settings_for_json(result, options),
            "iterations": result.iterations,
            "converged": result.converged,
            "flipped": result.flipped,
            "boundary_overlap": result.boundary_overlap,
            "outline_turning": _turning(flat, result.flat),
            "fold_free": result.flipped == 0 and result.boundary_overlap == 0,
            "fold_free_verified_by": "signed area of every face > 0 and no crossing boundary segments, checked after solving",
            "energy_history": _history_for_json(result.energy_history),
            "energy_units": "lengths divided by the mean 3D edge length; springs + barrier (fold-free presets) or springs only (paper)",
            "spring_energy": result.levels[-1].energy if result.levels else None,
            "stress": "paper Eq. 3 over mesh edges in sqrt(mm) (potflat.mesh.distortion.vertex_stress)",
            "levels": [_level_for_json(level) for level in result.levels],
            "notes": list(result.notes),
            "distortion_before": result.distortion_before.as_dict(),
            "distortion": result.distortion.as_dict(),
            "importance": ("none: the whole surface counts alike" if result.flat.importance is None else
                           f"per vertex in {ply_path.name}; springs, barrier and shape term of plain surface weighted "
                           f"1/{result.settings.importance_contrast:g}"),
            **result.zone.as_dict(),
            "true_scale_factor": result.scale_factor,
            "anisotropy_limit": result.anisotropy_limit,
            "units": flat.mesh.units,
            "vertices": len(flat.mesh.vertices),
            "faces": len(flat.mesh.faces),
        }
        for key in ("axis", "proxy", "units"):
            if key in rj:
                record[key] = rj[key]
        folded = rj.get("folded")
        if isinstance(folded, dict):  # where the scan folds in 3D: the figures, the faces stay in the rollout's JSON
            record["folded"] = {k: v for k, v in folded.items() if k != "face_indices"}
        inputs = [rollout_ply] + ([rollout_json] if rollout_json.exists() else [])
        record["provenance"] = provenance(stage="relax", inputs=inputs, options=asdict(options))
        comments = (f"potflat relax preset {result.preset}",)
        write_flat_ply(ply_path, result.flat, comments=comments)
        clock.lap("write")
        # the solver's own steps, then the stage's (its total: reading to writing)
        steps = clock.total()
        del steps["relax"]
        record["timings"] = {**{k: v for k, v in asdict(result.timings).items() if k != "total"}, **steps}
        write_json_atomic(json_path, record)
    return RelaxFiles(paths={"ply": ply_path, "json": json_path}, record=record,
                      flat=as_stored(result.flat, ply_path, comments=comments), distortion=result.distortion,
                      zone=result.zone, reference=result.reference)
