"""`potflat plate`: the archaeological plate of a flattened scan (SVG, PDF, PNG preview)."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer
from potflat_cli._errors import user_errors
from potflat_cli._options import Json, Quiet, StageName, StageOutputDir

HELP = """Compose the archaeological plate of a flattened scan: the outside view and the profile section side by side (left and right of the axis), the rollout below at one stated scale, a scale bar and a caption (name, computed from a 3D scan, proxy, preset, distortion, scale, date, potflat version).

Writes NAME.plate.svg (text as text, profile as vector paths, images embedded) and NAME.plate.pdf, both sized so that printing at 100 % gives the scale, and NAME.plate.png, a preview. Reads NAME.relaxed.ply with NAME.rollout.json, NAME.profile.csv and NAME.relaxed.json beside it, and NAME.bake.json and NAME.png in OUTDIR (as 'potflat run' leaves them). The profile's height step is the rollout's --profile-mm. Exit codes: 0 success, 2 bad input or options.

Example:  potflat plate out/amphora.relaxed.ply --scale 1:5
"""

Input = Annotated[Path, typer.Argument(help="NAME.relaxed.ply written by potflat (bake it first).",
                                       exists=True, dir_okay=False, readable=True)]


@user_errors
def plate_command(
    relaxed_ply: Input,
    output: StageOutputDir = None,
    scale: Annotated[Optional[str], typer.Option(
        "--scale", metavar="1:N", help="Print scale, e.g. 1:1, 1:2, 1:5 \\[default: the largest of 1:1, 1:2, 1:3, "
                                       "1:4, 1:5, 1:10, 1:20, 1:50 that fits A4].")] = None,
    name: StageName = None,
    image: Annotated[Optional[str], typer.Option(
        "--image", metavar="[painting|relief|both]",
        help="The rollout as the painting (NAME.png), as its relief in raking light (NAME.raking-AZ.png of a bake "
             "with --relief, the first azimuth) or both, one above the other \\[default: painting].")] = None,
    quiet: Quiet = False,
    json: Json = False,
) -> None:
    """Compose the archaeological plate of a flattened scan."""
    # imported here, not at the top: 'potflat --help' stays free of Numba and SciPy
    from potflat_cli._stage import run_stage
    from rich.console import Console

    from potflat.files.plate import make_plate, paper_words

    result = run_stage(f"composing the plate of {relaxed_ply.name}",
                       lambda: make_plate(relaxed_ply, output, scale=scale, name=name, image=image or "painting"),
                       quiet=quiet, as_json=json)
    if result is None:
        return
    s = result.record
    out = Console(highlight=False)
    out.print(f"[bold]{result.paths['svg']}[/]: {s['page_mm'][0]:.1f} x {s['page_mm'][1]:.1f} mm at "
              f"{s['scale_label']} ({paper_words(s)}), distortion in the {s['distortion_where']}; also "
              f"{result.paths['pdf'].name}, {result.paths['png'].name}")


plate_command.__doc__ = HELP
