"""`potflat run`: rollout, relax and bake one scan in one go."""
from __future__ import annotations

import inspect
from pathlib import Path
from typing import Annotated, Any

import typer

from potflat_cli._errors import check_stop, user_errors
from potflat_cli._options import Json, Name, OutputDir, Quiet

HELP = """Run rollout, relax and bake on one scan: NAME.rollout.ply/.json, NAME.relaxed.ply/.json, NAME.png, NAME.bake.json and the distortion maps, all in OUTDIR.

Every option of 'potflat rollout', 'potflat relax' and 'potflat bake' is accepted, with the same name and default. Exit codes: 0 success, 2 bad input or options (message on stderr), 130 interrupted.

Example:  potflat run samples/data/amphora.obj -o out/ --proxy cone --preset preview --px-per-mm 4
"""

Scan = Annotated[Path, typer.Argument(help="Textured scan (OBJ, PLY, STL, OFF, GLB/glTF).")]


def run_command(scan: Scan, output: OutputDir = None, name: Name = None,
                quiet: Quiet = False, json: Json = False) -> None:
    """Run rollout, relax and bake on one scan (stage options: see 'potflat run --help')."""
    # Only listed in 'potflat --help': invoking 'run' resolves to full_command(), which
    # adds every stage option (built on demand so other commands stay fast to start).
    full_command()(scan=scan, output=output, name=name, quiet=quiet, json=json)


def full_command():
    """``run`` with one option per stage option field (see potflat_cli._options)."""
    from potflat.stages.pipeline import STAGES
    from potflat_cli._options import stage_parameters

    base = list(inspect.signature(run_command, eval_str=True).parameters.values())
    params, seen = [], {p.name for p in base}
    for stage in STAGES:
        for p in stage_parameters(stage):
            if p.name not in seen:  # an option used by two stages is given once
                seen.add(p.name)
                params.append(p)

    @user_errors
    def run(**values: Any) -> None:
        _run(values)

    run.__signature__ = inspect.Signature(base + params)
    run.__annotations__ = {p.name: p.annotation for p in base + params}
    run.__doc__ = HELP
    return run


def _run(values: dict[str, Any]) -> None:
    import json as json_module

    from rich.console import Console

    from potflat.mesh.distortion import distortion_words
    from potflat.stages.pipeline import STAGES, run_scan
    from potflat_cli import _warmup as potflat_warmup
    from potflat_cli._options import options_from_cli
    from potflat_cli._stage import say_compiling, with_compile_note

    options = {stage: options_from_cli(stage, values) for stage in STAGES}
    scan = Path(values["scan"])
    err = Console(stderr=True, quiet=values["quiet"] or values["json"])
    started, warmup = [], None
    with err.status(f"{scan.name}: starting") as status:
        def progress(stage: str) -> None:
            nonlocal warmup
            check_stop()
            if not started:  # after run_scan checked the input: a refusal stays one line
                started.append(stage)
                say_compiling(err)
                # on a first run the relax kernels compile in a child process meanwhile
                warmup = potflat_warmup.start()
            status.update(with_compile_note(f"{scan.name}: {stage}"))
            if stage == "relax" and warmup is not None:
                # the scan rolled out (bad input is refused before this): the bake kernels
                # compile here while the child finishes the relax kernels
                potflat_warmup.bake_here()
        out_dir = values["output"] or Path(values["name"] or scan.stem)  # ./NAME/, never the scan's folder
        try:
            result = run_scan(scan, out_dir, name=values["name"], progress=progress, **options)
        finally:
            if warmup is not None:
                warmup.stop()
    figures = result.figures
    if values["json"]:
        print(json_module.dumps({
            "name": result.name, "scan": str(result.scan), "output": str(result.out_dir),
            "seconds": {k: round(v, 3) for k, v in result.seconds.items()},
            "figures": figures, "paths": {k: str(v) for k, v in result.paths.items()}}, indent=2))
        return
    if values["quiet"]:
        return
    out = Console()
    out.print(f"[bold]{result.name}[/]: done in {result.seconds['total']:.1f} s, "
              f"outputs in {result.out_dir}")
    shown = ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}"
                      for k, v in figures.items() if v is not None)
    if shown:
        out.print(f"  whole-surface distortion: {distortion_words(figures)} ({shown}; area figures are natural logs)")
    relaxed = result.stages["relax"].summary
    if relaxed.get("lengths"):
        out.print(f"  {relaxed['lengths']}")
    for key, path in result.paths.items():
        out.print(f"  {key:<16} {path}", highlight=False)
    rolled = result.stages["rollout"].summary
    for note in rolled.get("notes", []) + rolled["cleaning"]["warnings"]:  # and what loading the scan found
        out.print(f"[yellow]warning:[/] {note}", highlight=False)
