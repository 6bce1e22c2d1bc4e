"""`potflat relax`: fold-free elastic relaxation of a rollout."""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Optional

import typer

from potflat_cli._errors import user_errors


@user_errors
def relax_command(
    rollout_ply: Path = typer.Argument(..., help="NAME.rollout.ply written by 'potflat rollout'."),
    out_dir: Optional[Path] = typer.Option(None, "-o", "--out-dir", help="Output folder (default: beside the input)."),
    preset: str = typer.Option("standard", "--preset",
                               help="preview | standard | archival (fold-free, increasingly thorough) | paper (the paper's dynamics, may fold)."),
    tol: Optional[float] = typer.Option(None, "--tol", help="Stop when the relative energy change per iteration falls below this."),
    max_iter: Optional[int] = typer.Option(None, "--max-iter", help="Iteration cap (all levels together)."),
    time_budget: Optional[float] = typer.Option(None, "--time-budget", help="Seconds of relaxation at most; the state reached is kept."),
    threads: Optional[int] = typer.Option(None, "--threads", help="Number of threads (default: all cores)."),
    stretch: Optional[float] = typer.Option(None, "--stretch", help="Initial uniform scale of the rollout (paper: 2)."),
    stiffness: Optional[float] = typer.Option(None, "--stiffness", help="Spring stiffness k > 0 (paper: 0.5)."),
    weighting: Optional[str] = typer.Option(None, "--weighting", help="uniform (absolute length errors) | relative (1/r^2)."),
) -> None:
    """Relax a rollout into a fold-free flattening: writes NAME.relaxed.ply and NAME.relaxed.json.

    Example:

        potflat relax out/hydria.rollout.ply -o out --preset standard --time-budget 60
    """
    from potflat.relax import RelaxOptions, run_relax_stage

    options = RelaxOptions(preset=preset, tol=tol, max_iter=max_iter, time_budget=time_budget, threads=threads,
                           stretch=stretch, stiffness=stiffness, weighting=weighting)
    out = run_relax_stage(rollout_ply, out_dir if out_dir is not None else rollout_ply.parent, options,
                          progress=sys.stderr.isatty())
    s = out.summary
    before, after = s["distortion_before"], s["distortion"]
    state = "converged" if s["converged"] else "not converged (" + ", ".join(s["notes"][-1:]) + ")"
    fold = "fold-free" if s["fold_free"] else f"FOLDED: {s['flipped']} flipped triangles, {s['boundary_overlap']} boundary crossings"
    typer.echo(f"{out.paths['ply']}: preset {s['preset']}, {s['iterations']} iterations, {state}, "
               f"{s['timings']['solve']:.1f} s")
    typer.echo(f"  edge-length RMS {before['edge_rms']:.4f} -> {after['edge_rms']:.4f}, "
               f"mean |log area ratio| {before['area_mean_abs_log']:.4f} -> {after['area_mean_abs_log']:.4f}, {fold}")
