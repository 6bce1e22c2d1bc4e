"""The rollout's file stage: read a scan, roll it out, write ``NAME.rollout.ply``,
``NAME.rollout.json`` (see ``docs/formats.md``) and the profile ``NAME.profile.csv`` /
``NAME.profile.svg`` (see ``docs/profile.md``). The algorithm is :mod:`potflat.rollout`."""
from __future__ import annotations

from pathlib import Path

from potflat._heap import reuse_freed_memory
from potflat.errors import InvalidOptionError
from potflat.rollout.options import RolloutOptions
from potflat.rollout.unroll import rollout, rollout_summary
from potflat.types import StageOutput, StepClock


@reuse_freed_memory()  # (its many large temporaries; its peak is under the relax stage's)
def run_rollout_stage(scan_path, out_dir, options: RolloutOptions | None = None, *,
                      name: str | None = None, check=None) -> StageOutput:
    """Read a scan, roll it out, write ``NAME.rollout.ply``, ``NAME.rollout.json`` and its profile.

    The rollout's profile (:attr:`RolloutResult.profile`: both walls around its axis,
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
        Called with the flattening (:class:`FlatMesh`) before anything is written; it may
        raise to stop the run (``potflat run`` checks the size of the image to come).

    Returns
    -------
    StageOutput
        ``paths`` with ``"ply"``, ``"json"``, ``"profile_csv"`` and ``"profile_svg"``;
        ``summary`` = the JSON content.

    Raises
    ------
    InvalidOptionError
        When an output would overwrite the input, or the name is not a plain file stem.
    """
    from potflat import __version__
    from potflat.io.atomic import check_output_name, write_json_atomic
    from potflat.io.scan import check_plausible_size, load_scan
    from potflat.io.flat_ply import as_stored, write_flat_ply
    from potflat.rollout.profile import write_profile_csv, write_profile_svg
    from potflat.stages.provenance import provenance

    options = options or RolloutOptions()
    scan_path, out_dir = Path(scan_path), Path(out_dir)
    name = check_output_name(name or scan_path.stem, what="name" if name else f"the name of {scan_path}")
    ply_path = out_dir / f"{name}.rollout.ply"
    json_path = out_dir / f"{name}.rollout.json"
    csv_path = out_dir / f"{name}.profile.csv"
    svg_path = out_dir / f"{name}.profile.svg"
    for out in (ply_path, json_path, csv_path, svg_path):
        if out.resolve() == scan_path.resolve():
            raise InvalidOptionError(
                f"output {out} would overwrite the input scan; choose another output folder or --name")
    clock = StepClock()
    loaded = load_scan(scan_path, units=options.units, texture="use" if options.texture else "ignore")
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
    summary = {"stage": "rollout", "name": name, "input": str(scan_path), **rollout_summary(result),
               "profile": profile.summary(),
               "cleaning": cleaning,
               "files": {"ply": ply_path.name, "json": json_path.name, "profile_csv": csv_path.name,
                         "profile_svg": svg_path.name}}
    summary["provenance"] = provenance(stage="rollout", inputs=[scan_path], options=options.as_dict())
    comments = (f"potflat {__version__} rollout of {scan_path.name}",)
    write_flat_ply(ply_path, result.flat, comments=comments)
    write_profile_csv(profile, csv_path)
    write_profile_svg(profile, svg_path, title=f"{name}: profile ({profile.units})")
    clock.lap("write")
    summary["timings"] = {**clock.total(), "rollout_steps": result.timings}
    write_json_atomic(json_path, summary)
    return StageOutput({"ply": ply_path, "json": json_path, "profile_csv": csv_path, "profile_svg": svg_path},
                       summary, flat=as_stored(result.flat, ply_path, comments=comments),
                       distortion=result.distortion)
