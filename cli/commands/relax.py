"""`potflat relax`: fold-free elastic relaxation of a rollout."""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer

from potflat_cli._errors import user_errors
from potflat_cli._options import Json, Name, Quiet, StageOutputDir

HELP = """Relax a rollout into a fold-free flattening: writes NAME.relaxed.ply (with per-vertex stress) and NAME.relaxed.json (energy history, flips, boundary check, distortion before/after, timings, provenance).

Presets: preview (relaxes a coarse copy at the image's resolution, stops early), standard, archival (tight convergence): fold-free, verified; paper: the paper's damped dynamics (may fold; flips reported). Exit codes: 0 success, 2 bad input or options, or a result that would be folded (nothing is written).

Example:  potflat relax out/hydria.rollout.ply -o out --preset standard --time-budget 60
"""

Input = Annotated[Path, typer.Argument(help="NAME.rollout.ply written by 'potflat rollout'.",
                                       exists=True, dir_okay=False, readable=True)]


@user_errors
def relax_command(
    rollout_ply: Input,
    output: StageOutputDir = None,
    preset: Annotated[str, typer.Option(
        "--preset", help="preview | standard | archival (fold-free) | paper (the paper's dynamics, may fold).")] = "standard",
    tol: Annotated[float | None, typer.Option(
        "--tol", help="Stop when the relative energy change per iteration falls below this \\[default: per preset].")] = None,
    max_iter: Annotated[int | None, typer.Option(
        "--max-iter", help="Iteration cap \\[default: per preset].")] = None,
    time_budget: Annotated[float | None, typer.Option(
        "--time-budget", help="Seconds of relaxation at most; the state reached is kept (not converged).")] = None,
    threads: Annotated[int | None, typer.Option("--threads", help="Number of threads \\[default: all cores].")] = None,
    stretch: Annotated[float | None, typer.Option(
        "--stretch", help="Initial uniform scale of the rollout \\[default: 2 for paper, else 1].")] = None,
    stiffness: Annotated[float | None, typer.Option(
        "--stiffness", help="Spring stiffness k > 0 \\[default: 0.5 for paper, else 1].")] = None,
    weighting: Annotated[str | None, typer.Option(
        "--weighting", help="uniform (absolute length errors, the paper) | relative (1/r^2) \\[default: per preset].")] = None,
    simplify_mm: Annotated[float | None, typer.Option(
        "--simplify-mm", help="Relax a coarse copy with cells of this side (mm) and let the full mesh follow it; "
        "0: the full mesh \\[default: 0.5 for preview (2 px at 4 px/mm), else 0].")] = None,
    shape: Annotated[float | None, typer.Option(
        "--shape", help="Weight of the shape term (>= 0): rounder figures and straighter lines at some cost in "
                        "area; 0: the springs alone \\[default: 0.25, 0 for paper].")] = None,
    rigidity: Annotated[float | None, typer.Option(
        "--rigidity", help="Weight of the rigidity (as-rigid-as-possible) term (>= 0): evens out shear from "
                           "triangle to triangle; 0: none \\[default: 2, 0 for paper].")] = None,
    area: Annotated[float | None, typer.Option(
        "--area", help="Weight of the area term (>= 0) on vessels without a painted zone: area distortion gathered "
                       "where the shape can take it, not spread evenly; 0: none \\[default: 2, 0 for paper].")] = None,
    max_anisotropy: Annotated[str | None, typer.Option(
        "--max-anisotropy", help="Anisotropy (long/short axis) above which a steep price starts: a number > 1, inf "
                                 "(none) or auto (what a solve without the area term reaches, 80th percentile) "
                                 "\\[default: auto].")] = None,
    importance_contrast: Annotated[float | None, typer.Option(
        "--importance-contrast", help="How much stiffer the painted zone is than plain surface (>= 1; 1: the whole "
                                      "surface alike) \\[default: 1000, 100 for preview, 1 for paper].")] = None,
    true_scale: Annotated[bool | None, typer.Option(
        "--true-scale/--no-true-scale", help="Scale the result so that the median length scale in the painted zone "
                                             "is 1 \\[default: on, off for paper].")] = None,
    name: Name = None,
    quiet: Quiet = False,
    json: Json = False,
) -> None:
    from potflat.mesh.distortion import distortion_words
    from potflat.stages.relax_stage import run_relax_stage
    from potflat_cli._options import options_from_cli
    from potflat_cli._stage import run_stage, with_compile_note

    options = options_from_cli("relax", {
        "preset": preset, "tol": tol, "max_iter": max_iter, "time_budget": time_budget, "threads": threads,
        "stretch": stretch, "stiffness": stiffness, "weighting": weighting, "simplify_mm": simplify_mm,
        "shape": shape, "rigidity": rigidity, "area": area, "max_anisotropy": max_anisotropy,
        "importance_contrast": importance_contrast, "true_scale": true_scale})
    show_progress = sys.stderr.isatty() and not (quiet or json)
    if show_progress and with_compile_note("") != "":
        print(f"note: {with_compile_note('').strip(' ()')}", file=sys.stderr)
    out = run_stage(None if show_progress else f"relaxing {rollout_ply.name}",
                    lambda: run_relax_stage(rollout_ply, output if output is not None else rollout_ply.parent,
                                            options, name=name, progress=show_progress),
                    quiet=quiet, as_json=json)
    if out is None:
        return
    s = out.summary
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


relax_command.__doc__ = HELP
