"""`potflat rollout`: find the axis, cut a seam and unroll a scan onto a proxy surface."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer
from potflat_cli._errors import user_errors
from potflat_cli._options import Json, Name, OutputDir, Quiet

HELP = """Unroll a vessel scan: find its rotation axis, fit a cylinder/cone/sphere, cut a seam, develop it.

Writes NAME.rollout.ply (3D positions + flattened u v, texture coordinates or colours; the input of 'potflat relax'), NAME.rollout.json (axis, proxy, seam, region, walls, attachments left out, trimmed border, counts, cleaning report, distortion) and the profile NAME.profile.csv / NAME.profile.svg. The outer wall is unrolled (--side inner: the inside); handles are left out unless --keep-attachments. Angles are degrees counter-clockwise about the axis (mouth up), measured from a landmark when one is named (--seam-at X Y Z, --landmark painted|handle), else: the seam from the axis' reference direction (printed), --angles from the seam, or centred on the painted zone when --angles comes alone. Exit codes: 0 success, 2 bad input or options (e.g. no rotational symmetry: give --axis).

Example:  potflat rollout scans/amphora.obj -o out --band 0.2 0.7 --proxy cone
"""

Scan = Annotated[Path, typer.Argument(help="The scan: OBJ (+MTL, texture), PLY, STL, OFF, GLB/glTF.")]


@user_errors
def rollout_command(
    scan: Scan,
    output: OutputDir = None,
    proxy: Annotated[Optional[str], typer.Option(
        "--proxy", help="Proxy surface: auto (least distortion), cylinder, cone, sphere, ortho "
                        "(orthographic view, for small cutouts) \\[default: auto].")] = None,
    axis: Annotated[Optional[str], typer.Option(
        "--axis", help="Manual axis px,py,pz,dx,dy,dz (a point and the direction foot to mouth, "
                       "scan coordinates) \\[default: estimated from the normals].")] = None,
    flip: Annotated[bool, typer.Option("--flip", help="Reverse the axis (swap mouth and foot).")] = False,
    seam: Annotated[Optional[float], typer.Option(
        "--seam", help="Seam angle, degrees from the landmark (--seam-at, --landmark), else from the reference "
                       "direction \\[default: where the painting is least dense, or a gap].")] = None,
    seam_at: Annotated[Optional[tuple[float, float, float]], typer.Option(
        "--seam-at", metavar="X Y Z", help="A point on the surface (scan coordinates, e.g. picked in MeshLab): "
                                           "the seam goes through it; --seam and --angles are measured from it.")] = None,
    landmark: Annotated[Optional[str], typer.Option(
        "--landmark", help="painted: the seam goes opposite the centre of the painted zone; handle: through the "
                           "largest handle. --seam and --angles are measured from it.")] = None,
    overlap: Annotated[Optional[float], typer.Option(
        "--overlap", metavar="DEG", help="Repeat the surface past 360 degrees by DEG, so a motif crossing the seam "
                                         "is seen whole once; the bake marks where the repeat starts.")] = None,
    band: Annotated[Optional[tuple[float, float]], typer.Option(
        "--band", help="Height band LO HI as fractions of the height, 0 = foot, 1 = mouth "
                       "\\[default: 0 1].")] = None,
    angles: Annotated[Optional[tuple[float, float]], typer.Option(
        "--angles", help="Angle range A0 A1 in degrees, e.g. -60 60: from the landmark, else from --seam, else "
                         "centred on the painted zone (the seam stays automatic) \\[default: all round].")] = None,
    view: Annotated[Optional[str], typer.Option(
        "--view", help="With --proxy ortho: direction x,y,z from the vessel to the viewer "
                       "\\[default: towards the region's centre].")] = None,
    side: Annotated[Optional[str], typer.Option(
        "--side", help="Painted side: outer (the outside) or inner (the inside seen from within: a cup's "
                       "interior, a kylix tondo); two-walled scans are split at the rim \\[default: outer].")] = None,
    keep_attachments: Annotated[bool, typer.Option(
        "--keep-attachments", help="Keep handles, spouts and knobs in the rollout (by default they are "
                                   "left out and reported; the painting around their roots stays).")] = False,
    profile_mm: Annotated[Optional[float], typer.Option(
        "--profile-mm", metavar="MM", help="Height step of the profile (NAME.profile.csv/.svg, the plate's "
                                           "section), mm \\[default: one edge length of the scan].")] = None,
    units: Annotated[Optional[str], typer.Option(
        "--units", help="Length unit of the scan: mm, cm, m, um, in \\[default: as the file "
                        "declares (PLY comment, STL header, glTF metres), else mm].")] = None,
    texture: Annotated[bool, typer.Option(
        "--texture/--no-texture", help="Use the scan's texture image; --no-texture loads the geometry "
                                       "(and vertex colours) only, e.g. when the texture is missing or corrupt.")] = True,
    importance: Annotated[Optional[str], typer.Option(
        "--importance", help="Where the painting is (kept true by relax, reported by bake): auto (found in the "
                             "colours), none (the whole surface alike), mask (--importance-mask painted over a "
                             "potflat image), texture-mask (--importance-mask in the texture's space), band "
                             "(--importance-band / --importance-arc) \\[default: auto].")] = None,
    importance_mask: Annotated[Optional[str], typer.Option(
        "--importance-mask", help="PNG mask, white = important: painted over a potflat image (--importance mask) "
                                  "or in texture space (--importance texture-mask).")] = None,
    importance_image: Annotated[Optional[str], typer.Option(
        "--importance-image", help="NAME.bake.json of the image the mask was painted over \\[default: the one "
                                   "beside the mask with the mask's size].")] = None,
    importance_band: Annotated[Optional[tuple[float, float]], typer.Option(
        "--importance-band", help="With --importance band: heights LO HI as fractions, 0 = foot, 1 = mouth.")] = None,
    importance_arc: Annotated[Optional[tuple[float, float]], typer.Option(
        "--importance-arc", help="With --importance band: angles A0 A1 in degrees from the seam.")] = None,
    name: Name = None,
    quiet: Quiet = False,
    json: Json = False,
) -> None:
    """Unroll a vessel scan onto a proxy surface."""
    from potflat_cli._options import options_from_cli

    from potflat.errors import InvalidOptionError

    if output is not None and output.exists() and not output.is_dir():
        raise InvalidOptionError(f"--output {output} is a file; give a folder")
    values = {"proxy": proxy, "axis": axis, "flip": flip or None, "seam": seam, "band": band,
              "angles": angles, "view": view, "units": units, "texture": None if texture else False,
              "side": side, "keep_attachments": keep_attachments or None, "profile_mm": profile_mm,
              "seam_at": seam_at, "landmark": landmark, "overlap": overlap, "importance": importance,
              "importance_mask": importance_mask, "importance_image": importance_image,
              "importance_band": importance_band, "importance_arc": importance_arc}
    options = options_from_cli("rollout", values)
    _rollout(scan, output, options, name=name, quiet=quiet, as_json=json)


rollout_command.__doc__ = HELP


def _rollout(scan: Path, output: Path | None, options, *, name: str | None, quiet: bool, as_json: bool) -> None:
    from potflat_cli._stage import run_stage
    from rich.console import Console

    from potflat.mesh.distortion import distortion_words
    from potflat.rollout import run_rollout_stage

    result = run_stage(f"rolling out {scan.name}", lambda: run_rollout_stage(scan, output or Path(name or scan.stem), options, name=name),
                       quiet=quiet, as_json=as_json)
    if result is None:
        return
    s = result.summary
    out = Console(highlight=False)
    ax, px, d, c, u = s["axis"], s["proxy"], s["distortion"], s["counts"], s["units"]
    fmt = ", ".join
    out.print(f"[bold]{result.paths['ply']}[/] and {result.paths['json'].name}")
    out.print(f"axis ({ax['method']}): point {fmt(f'{x:.4g}' for x in ax['point'])}, direction "
              f"{fmt(f'{x:.4f}' for x in ax['direction'])}; residual {ax['rms_angle_deg']:.2f} deg RMS "
              f"(median {ax['median_angle_deg']:.2f}), {ax['rms_distance']:.3g} {u} RMS; {ax['orientation']}")
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
