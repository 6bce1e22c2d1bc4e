"""`potflat bake`: true-scale images of the painting and distortion maps from a flattening."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from potflat_cli._errors import user_errors
from potflat_cli._options import Json, Name, Quiet, StageOutputDir

HELP = """Bake a flattening (NAME.relaxed.ply, or NAME.rollout.ply to compare) into true-scale images.

Writes NAME.png (the painting, RGBA, resolution stored in the file), NAME.<map>.png heat maps with colour bars, NAME.overlay.png (stress over the greyscale painting), NAME.scale-layer.png and NAME.scalebar.png, NAME.bake.json (figures and provenance); optionally NAME.tif (16-bit), NAME.position.tif (3D point per pixel) and NAME.sheet.png (rollout vs relaxed), NAME.plate.svg/.pdf/.png (--plate), NAME.flat.obj/.mtl (--obj). A rollout input writes NAME.rollout.* instead. Exit codes: 0 success, 2 bad input or options.

Example:  potflat bake out/amphora.relaxed.ply --dpi 600 --sheet --grid
"""

Input = Annotated[Path, typer.Argument(help="NAME.relaxed.ply (or NAME.rollout.ply) written by potflat.",
                                       exists=True, dir_okay=False, readable=True)]


@user_errors
def bake_command(
    flat_ply: Input,
    output: StageOutputDir = None,
    px_per_mm: Annotated[float | None, typer.Option(
        "--px-per-mm", help="Resolution in pixels per millimetre \\[default: 4].")] = None,
    dpi: Annotated[float | None, typer.Option(
        "--dpi", help="Resolution in dots per inch (instead of --px-per-mm).")] = None,
    maps: Annotated[str | None, typer.Option(
        "--maps", help="Comma-separated distortion maps: stress,area,anisotropy (or 'none').")] = None,
    sheet: Annotated[bool, typer.Option(
        "--sheet", help="Also write NAME.sheet.png: the rollout beside the relaxed result, with stress maps.")] = False,
    position_map: Annotated[bool, typer.Option(
        "--position-map", help="Also write NAME.position.tif: the 3D point (scan units) under each pixel.")] = False,
    grid: Annotated[bool, typer.Option("--grid", help="Draw a labelled 10 mm grid in the scale layer.")] = False,
    tiff: Annotated[bool, typer.Option("--tiff", help="Also write the painting as a 16-bit RGBA TIFF.")] = False,
    supersample: Annotated[int | None, typer.Option(
        "--supersample", help="Sub-samples per pixel side, 1-8 \\[default: automatic from the texture density].")] = None,
    max_megapixels: Annotated[float | None, typer.Option(
        "--max-megapixels", help="Refuse images larger than this \\[default: 1000].")] = None,
    scale_on_image: Annotated[bool, typer.Option(
        "--scale-on-image", help="Draw the scale bar (and the grid, with --grid) into NAME.png itself, where it "
                                 "covers no painting (in a band below the image when no place is free).")] = False,
    plate: Annotated[bool, typer.Option(
        "--plate", help="Also write the archaeological plate NAME.plate.svg/.pdf/.png: section and outside "
                        "view, the rollout below, scale bar and caption (as 'potflat plate').")] = False,
    plate_scale: Annotated[str | None, typer.Option(
        "--plate-scale", metavar="1:N", help="Print scale of the plate, e.g. 1:2 \\[default: the largest of "
                                             "1:1, 1:2, 1:3, 1:4, 1:5, 1:10, 1:20, 1:50 that fits A4].")] = None,
    obj: Annotated[bool, typer.Option(
        "--obj", help="Also write NAME.flat.obj/.mtl: the surface in 3D with the flat coordinates as texture "
                      "coordinates into NAME.png (opens in MeshLab and Blender).")] = False,
    name: Name = None,
    quiet: Quiet = False,
    json: Json = False,
) -> None:
    """Bake a flattening into true-scale images and distortion maps."""
    from potflat_cli._options import options_from_cli

    values = {"px_per_mm": px_per_mm, "dpi": dpi, "sheet": sheet or None, "position_map": position_map or None,
              "grid": grid or None, "tiff": tiff or None, "supersample": supersample, "max_megapixels": max_megapixels,
              "maps": maps, "scale_on_image": scale_on_image or None, "plate": plate or None,
              "plate_scale": plate_scale, "obj": obj or None}
    options = options_from_cli("bake", values)
    _bake(flat_ply, output, options, name=name, quiet=quiet, as_json=json)


bake_command.__doc__ = HELP


def _bake(flat_ply: Path, output: Path | None, options, *, name: str | None, quiet: bool, as_json: bool) -> None:
    from potflat_cli._stage import run_stage
    from rich.console import Console

    from potflat.bake import run_bake_stage
    from potflat.mesh.distortion import distortion_words

    result = run_stage(f"baking {flat_ply.name}", lambda: run_bake_stage(flat_ply, output or flat_ply.parent, options, name=name),
                       quiet=quiet, as_json=as_json)
    if result is None:
        return
    s = result.summary
    out = Console(highlight=False)
    w, h = s["image_px"]
    out.print(f"[bold]{result.paths['png']}[/]: {w} x {h} px = {s['image_mm'][0]:.1f} x {s['image_mm'][1]:.1f} mm "
              f"at {s['px_per_mm']:.4g} px/mm ({s['dpi']:.4g} dpi), painting from {s['painting']}")
    out.print(f"{distortion_words(s['distortion'])}; stress (paper Eq. 3) mean {s['stress']['mean']:.3g} / p95 "
              f"{s['stress']['p95']:.3g} / max {s['stress']['max']:.3g} sqrt(mm); anisotropy p95 {s['anisotropy']['p95']:.3f}; "
              f"covered {s['covered_area_mm2']:.0f} of {s['flattened_area_mm2']:.0f} mm2")
    out.print("wrote " + ", ".join(sorted(p.name for p in result.paths.values())))
