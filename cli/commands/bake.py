"""`potflat bake`: true-scale images of the painting and distortion maps from a flattening."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer
from potflat_cli._errors import user_errors
from potflat_cli._options import Json, Quiet, StageName, StageOutputDir, with_stage_options

HELP = """Bake a flattening (NAME.relaxed.ply, or NAME.rollout.ply to compare) into true-scale images.

Writes NAME.png (the painting, RGBA, resolution stored in the file), NAME.<map>.png heat maps with colour bars, NAME.overlay.png (stress over the greyscale painting), NAME.scale-layer.png and NAME.scalebar.png, NAME.bake.json (figures and provenance); optionally NAME.tif (16-bit), NAME.position.tif (3D point per pixel) and NAME.sheet.png (rollout vs relaxed), NAME.plate.svg/.pdf/.png (--plate), NAME.flat.obj/.mtl (--obj). A base the rollout left out (NAME.base.ply beside the input) is baked too: NAME.base.png (scale bar in the image), its maps and NAME.base.bake.json. A rollout input writes NAME.rollout.* instead. Exit codes: 0 success, 2 bad input or options.

Example:  potflat bake out/amphora.relaxed.ply --dpi 600 --sheet --grid
"""

Input = Annotated[Path, typer.Argument(help="NAME.relaxed.ply (or NAME.rollout.ply) written by potflat.",
                                       exists=True, dir_okay=False, readable=True)]


@user_errors
@with_stage_options("bake")
def bake_command(flat_ply: Input, output: StageOutputDir = None, name: StageName = None, quiet: Quiet = False,
                 json: Json = False, *, options: dict) -> None:
    """Bake a flattening into true-scale images and distortion maps."""
    _bake(flat_ply, output, options["bake"], name=name, quiet=quiet, as_json=json)


bake_command.__doc__ = HELP


def _bake(flat_ply: Path, output: Path | None, options, *, name: str | None, quiet: bool, as_json: bool) -> None:
    # imported here, not at the top: 'potflat --help' stays free of Numba and SciPy
    from potflat_cli._stage import run_stage
    from rich.console import Console

    from potflat.files.bake_stage import run_bake_stage
    from potflat.mesh.distortion import distortion_words

    result = run_stage(f"baking {flat_ply.name}", lambda: run_bake_stage(flat_ply, output or flat_ply.parent, options, name=name),
                       quiet=quiet, as_json=as_json)
    if result is None:
        return
    s = result.record
    out = Console(highlight=False)
    w, h = s["image_px"]
    out.print(f"[bold]{result.paths['png']}[/]: {w} x {h} px = {s['image_mm'][0]:.1f} x {s['image_mm'][1]:.1f} mm "
              f"at {s['px_per_mm']:.4g} px/mm ({s['dpi']:.4g} dpi), painting from {s['painting']}")
    out.print(f"{distortion_words(s['distortion'])}; stress (paper Eq. 3) mean {s['stress']['mean']:.3g} / p95 "
              f"{s['stress']['p95']:.3g} / max {s['stress']['max']:.3g} sqrt(mm); anisotropy p95 {s['anisotropy']['p95']:.3f}; "
              f"covered {s['covered_area_mm2']:.0f} of {s['flattened_area_mm2']:.0f} mm2")
    out.print("wrote " + ", ".join(sorted(p.name for p in result.paths.values())))
