"""`potflat rollout`: find the axis, cut a seam and unroll a scan onto a proxy surface."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from potflat_cli._errors import user_errors
from potflat_cli._options import Json, Name, OutputDir, Quiet, with_stage_options

HELP = """Unroll a vessel scan: find its rotation axis, fit a cylinder/cone/sphere, cut a seam, develop it.

Writes NAME.rollout.ply (3D positions + flattened u v, texture coordinates or colours; the input of 'potflat relax'), NAME.rollout.json (axis, proxy, seam, region, walls, attachments left out, trimmed border, counts, cleaning report, distortion) the profile NAME.profile.csv / NAME.profile.svg, and NAME.base.ply (the base, or the floor with --side inner, seen along the axis) when the development would smear it. The outer wall is unrolled (--side inner: the inside); handles are left out unless --keep-attachments, the base unless --keep-base. Angles are degrees counter-clockwise about the axis (mouth up), measured from a landmark when one is named (--seam-at X Y Z, --landmark painted|handle), else: the seam from the axis' reference direction (printed), --angles from the seam, or centred on the painted zone when --angles comes alone. Exit codes: 0 success, 2 bad input or options (e.g. no rotational symmetry: give --axis).

Example:  potflat rollout scans/amphora.obj -o out --band 0.2 0.7 --proxy cone
"""

Scan = Annotated[Path, typer.Argument(help="The scan: OBJ (+MTL, texture), PLY, STL, OFF, GLB/glTF.")]


@user_errors
@with_stage_options("rollout")
def rollout_command(scan: Scan, output: OutputDir = None, name: Name = None, quiet: Quiet = False,
                    json: Json = False, *, options: dict) -> None:
    """Unroll a vessel scan onto a proxy surface."""
    # imported here, not at the top: 'potflat --help' stays free of Numba and SciPy
    from potflat.errors import InvalidOptionError

    if output is not None and output.exists() and not output.is_dir():
        raise InvalidOptionError(f"--output {output} is a file; give a folder")
    _rollout(scan, output, options["rollout"], name=name, quiet=quiet, as_json=json)


rollout_command.__doc__ = HELP


def _rollout(scan: Path, output: Path | None, options, *, name: str | None, quiet: bool, as_json: bool) -> None:
    # imported here, not at the top: 'potflat --help' stays free of Numba and SciPy
    from potflat_cli._stage import run_stage
    from rich.console import Console

    from potflat.mesh.distortion import distortion_words
    from potflat.files.rollout_stage import base_line, run_rollout_stage

    result = run_stage(f"rolling out {scan.name}", lambda: run_rollout_stage(scan, output or Path(name or scan.stem), options, name=name),
                       quiet=quiet, as_json=as_json)
    if result is None:
        return
    s = result.record
    out = Console(highlight=False)
    ax, px, d, c, u = s["axis"], s["proxy"], s["distortion"], s["counts"], s["units"]
    fmt = ", ".join
    out.print(f"[bold]{result.paths['ply']}[/] and {result.paths['json'].name}")
    out.print(f"axis ({ax['method']}): point {fmt(f'{x:.4g}' for x in ax['point'])}, direction "
              f"{fmt(f'{x:.4f}' for x in ax['direction'])}; residual {ax['rms_angle_deg']:.2f} deg RMS "
              f"(median {ax['median_angle_deg']:.2f}, misfit {ax['misfit_angle_deg']:.2f}), "
              f"{ax['rms_distance']:.3g} {u} RMS; {ax['orientation']}")
    if ax["note"]:
        out.print(f"[yellow]note:[/] {ax['note']}")
    params = ", ".join(f"{k} {v:.4g}" for k, v in px["params"].items() if isinstance(v, float))
    out.print(f"proxy {px['type']} ({params}): {px['reason']}")
    if s["seam"].get("landmark"):
        lm = s["seam"]["landmark"]
        out.print(f"landmark: {lm['kind']} at {lm['angle_deg']:.1f} deg ({lm['detail']})")
    out.print(f"seam {s['seam']['angle_deg']:.1f} deg ({s['seam']['method']}) from reference "
              f"{fmt(f'{x:.4f}' for x in ax['reference_direction'])}; {c['faces']} faces, "
              f"{c['vertices']} vertices, {c['seam_vertices_duplicated']} seam vertices duplicated")
    w, at, tr = s["walls"], s["attachments"], s["trimmed"]
    mm2 = "mm\N{SUPERSCRIPT TWO}"
    out.print(f"{w['side']} wall: {w['faces_selected']} faces"
              + (f" (two-walled scan: {w['faces_inner' if w['side'] == 'outer' else 'faces_outer']} faces "
                 f"of the other wall left out)" if w["two_walled"] else ""))
    if at["faces"]:
        what = "kept" if at["kept"] else "left out"
        out.print(f"attachments {what}: {len(at['components'])} ({at['faces']} faces, {at['area_mm2']:.4g} {mm2})")
    if s["base"] is not None and s["base"]["candidate_faces"]:
        out.print(base_line(s["base"], result.paths.get("base_ply")))
    if tr["faces"] or s["untangled"]["faces"]:
        out.print(f"trimmed {tr['faces']} folded border faces ({tr['area_mm2']:.4g} {mm2}: rim top, base "
                  f"underside, breaks); untangled {s['untangled']['faces']} folded faces inside")
    out.print(f"profile: {result.paths['profile_csv'].name}, {result.paths['profile_svg'].name}")
    for note in s["notes"]:
        out.print(f"[yellow]note:[/] {note}")
    for warning in s["cleaning"]["warnings"]:  # what loading the scan found (no texture, repeats, ...)
        out.print(f"[yellow]warning:[/] {warning}")
    if s.get("importance"):
        out.print(f"importance ({s['importance']['method']}): {s['importance']['reason']}")
    flipped = f"[red]{d['flipped']} flipped[/]" if d["flipped"] else "0 flipped"
    out.print(f"distortion: {distortion_words({**d, 'flipped': None})}, {flipped} (edge-length RMS {d['edge_rms']:.4f}, "
              f"mean |ln area ratio| {d['area_mean_abs_log']:.4f}, anisotropy mean {d['anisotropy_mean']:.3f})")
