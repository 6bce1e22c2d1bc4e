"""`potflat relax`: fold-free elastic relaxation of a rollout."""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from potflat_cli._errors import user_errors
from potflat_cli._options import Json, Quiet, StageName, StageOutputDir, with_stage_options

HELP = """Relax a rollout into a fold-free flattening: writes NAME.relaxed.ply (with per-vertex stress) and NAME.relaxed.json (energy history, flips, boundary check, distortion before/after, timings, provenance).

Presets: preview (relaxes a coarse copy at the image's resolution, stops early), standard, archival (tight convergence): fold-free, verified; paper: the paper's damped dynamics (may fold; flips reported). Exit codes: 0 success, 2 bad input or options, or a result that would be folded (nothing is written).

Example:  potflat relax out/hydria.rollout.ply -o out --preset standard --time-budget 60
"""

Input = Annotated[Path, typer.Argument(help="NAME.rollout.ply written by 'potflat rollout'.",
                                       exists=True, dir_okay=False, readable=True)]


@user_errors
@with_stage_options("relax")
def relax_command(rollout_ply: Input, output: StageOutputDir = None, name: StageName = None, quiet: Quiet = False,
                  json: Json = False, *, options: dict) -> None:
    """Relax a rollout into a fold-free flattening."""
    # imported here, not at the top: 'potflat --help' stays free of Numba and SciPy
    from potflat.mesh.boundary import turning_words
    from potflat.mesh.distortion import distortion_words
    from potflat.files.relax_stage import run_relax_stage
    from potflat._jit import kernels_cached
    from potflat_cli._stage import FIRST_RUN, run_stage

    show_progress = sys.stderr.isatty() and not (quiet or json)
    if show_progress and not kernels_cached():
        print(f"note: {FIRST_RUN}", file=sys.stderr)
    out = run_stage(None if show_progress else f"relaxing {rollout_ply.name}",
                    lambda: run_relax_stage(rollout_ply, output if output is not None else rollout_ply.parent,
                                            options["relax"], name=name, progress=show_progress),
                    quiet=quiet, as_json=json)
    if out is None:
        return
    s = out.record
    before, after = s["distortion_before"], s["distortion"]
    state = "converged" if s["converged"] else "not converged (" + ", ".join(s["notes"][-1:]) + ")"
    fold = ("fold-free" if s["fold_free"]
            else f"FOLDED: {s['flipped']} flipped triangles, {s['boundary_overlap']} boundary crossings")
    typer.echo(f"{out.paths['ply']}: preset {s['preset']}, {s['iterations']} iterations, {state}, "
               f"{s['timings']['solve']:.1f} s")
    typer.echo(f"  edge-length RMS {before['edge_rms']:.4f} -> {after['edge_rms']:.4f}, "
               f"mean |ln area ratio| {before['area_mean_abs_log']:.4f} -> {after['area_mean_abs_log']:.4f}, {fold}")
    typer.echo(f"  whole surface now: {distortion_words({**after, 'flipped': None})}")
    typer.echo(f"  {s['lengths']}")
    typer.echo(f"  {turning_words(s['outline_turning'])}")


relax_command.__doc__ = HELP
