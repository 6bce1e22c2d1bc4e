"""`potflat run`: rollout, relax and bake one scan in one go."""
from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from potflat_cli._errors import check_stop, user_errors
from potflat_cli._options import Json, Name, OutputDir, Quiet, with_stage_options

HELP = """Run rollout, relax and bake on one scan: NAME.rollout.ply/.json, NAME.relaxed.ply/.json, NAME.png, NAME.bake.json and the distortion maps, and NAME.base.png (the base seen from below, when left out of the rollout), all in OUTDIR.

Every option of 'potflat rollout', 'potflat relax' and 'potflat bake' is accepted, with the same name and default. Exit codes: 0 success, 2 bad input or options (message on stderr), 130 interrupted.

Example:  potflat run samples/data/amphora.obj -o out/ --proxy cone --preset preview --px-per-mm 4
"""

Scan = Annotated[Path, typer.Argument(help="Textured scan (OBJ, PLY, STL, OFF, GLB/glTF).")]


@user_errors
@with_stage_options("rollout", "relax", "bake")
def run_command(scan: Scan, output: OutputDir = None, name: Name = None, quiet: Quiet = False,
                json: Json = False, *, options: dict) -> None:
    """Run rollout, relax and bake on one scan."""
    _run(scan, output, name, quiet, json, options)


run_command.__doc__ = HELP


def _run(scan: Path, output: Path | None, name: str | None, quiet: bool, as_json: bool, options: dict) -> None:
    # imported here, not at the top: 'potflat --help' stays free of Numba and SciPy
    import json as json_module
    from dataclasses import asdict

    from rich.console import Console

    from potflat.files.pipeline import run_scan
    from potflat.files.rollout_stage import base_line
    from potflat.mesh.boundary import turning_words
    from potflat.mesh.distortion import distortion_words
    from potflat_cli import _warmup as potflat_warmup
    from potflat_cli._stage import StageLog, say_compiling, with_compile_note

    scan = Path(scan)
    err = Console(stderr=True, quiet=quiet or as_json)
    started, warmup, log = [], None, StageLog(err)
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
            log.start(f"{scan.name}: {stage}")
            if stage == "relax" and warmup is not None:
                # the scan rolled out (bad input is refused before this): the bake kernels
                # compile here while the child finishes the relax kernels
                potflat_warmup.bake_here()
        out_dir = output or Path(name or scan.stem)  # ./NAME/, never the scan's folder
        try:
            result = run_scan(scan, out_dir, name=name, progress=progress, **options)
            log.end()
        finally:
            if warmup is not None:
                warmup.stop()
    figures = result.figures
    if as_json:
        print(json_module.dumps({
            "name": result.name, "scan": str(result.scan), "output": str(result.out_dir),
            "seconds": {k: round(v, 3) for k, v in asdict(result.seconds).items()},
            "figures": figures, "paths": {k: str(v) for k, v in result.paths.items()}}, indent=2))
        return
    if quiet:
        return
    out = Console()
    out.print(f"[bold]{result.name}[/]: done in {result.seconds.total:.1f} s, "
              f"outputs in {result.out_dir}")
    out.print(f"  whole-surface distortion: {distortion_words(figures)}"
              + (f", shapes stretched at most {figures['anisotropy_p95']:.2f} times over 95 % of the surface"
                 if figures.get("anisotropy_p95") is not None else ""))
    importance = result.rollout.record.get("importance")
    if importance:  # where the painting was found, or that the whole surface counted alike
        out.print(f"  importance ({importance['method']}): {importance['reason']}", highlight=False)
    relaxed = result.relax.record
    if relaxed.get("lengths"):
        out.print(f"  {relaxed['lengths']}")
    if relaxed.get("outline_turning"):
        out.print(f"  {turning_words(relaxed['outline_turning'])}", highlight=False)
    base = result.rollout.record.get("base")
    if base is not None and base["candidate_faces"]:
        out.print(f"  {base_line(base, result.paths.get('bake.base_png'))}", highlight=False)
    for key, path in result.paths.items():
        out.print(f"  {key:<16} {path}", highlight=False)
    rolled = result.rollout.record
    for note in rolled.get("notes", []) + rolled["cleaning"]["warnings"]:  # and what loading the scan found
        out.print(f"[yellow]warning:[/] {note}", highlight=False)
