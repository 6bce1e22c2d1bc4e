"""`potflat batch`: many scans from a YAML file, resumable, in parallel or on a Dask cluster."""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from potflat_cli._errors import EXIT_USAGE, check_stop, one_line, user_errors
from potflat_cli._options import Json, Quiet

BatchFile = Annotated[Path, typer.Argument(help="YAML batch file (schema: docs/cli.md).")]
BatchOutput = Annotated[Optional[Path], typer.Option(
    "--output", "-o", help="Output folder, one sub-folder per scan \\[default: the batch file's 'output:'].",
    file_okay=False)]
Workers = Annotated[Optional[int], typer.Option(
    "--workers", "-w", min=1,
    help="Local worker processes \\[default: one per core, at most one per scan]. "
         "Each gets cores/workers Numba threads; lower it for very large scans (memory).")]
Scheduler = Annotated[Optional[str], typer.Option(
    "--scheduler", metavar="ADDRESS",
    help="Run on an existing Dask cluster (e.g. tcp://10.0.0.5:8786) instead of local "
         "processes; needs: pip install 'dask\\[distributed]'. See docs/cluster.md.")]
Force = Annotated[bool, typer.Option("--force", help="Redo every scan, even those already complete.")]


@user_errors
def batch_command(batch_file: BatchFile, workers: Workers = None, scheduler: Scheduler = None,
                  output: BatchOutput = None, force: Force = False, quiet: Quiet = False,
                  json: Json = False) -> None:
    """Run rollout, relax and bake on every scan of a YAML batch file.

    The whole file is checked before any work starts. Scans whose outputs are complete and made with the same scan, options and potflat version are skipped (--force redoes them). A failing scan never stops the others. The summary is printed and written as summary.csv and summary.json in the output folder.

    Exit codes: 0 all scans done or skipped; 1 some failed; 2 bad batch file or options; 130 interrupted.

    Example:  potflat batch samples/batch.yaml --workers 2
    """
    # imported here, not at the top: 'potflat --help' stays free of Numba and SciPy
    import json as json_module

    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    from potflat.files.batch.config import BatchFileError, load_batch

    from potflat.files.batch.execution import run_batch
    from potflat_cli._stage import with_compile_note

    try:
        batch = load_batch(batch_file, output=output)
    except BatchFileError as exc:
        for problem in exc.problems:
            print(f"error: {one_line(problem)}", file=sys.stderr)
        raise typer.Exit(EXIT_USAGE) from None
    err = Console(stderr=True)
    progress = Progress(TextColumn("[bold]batch"), BarColumn(), MofNCompleteColumn(),
                        TimeElapsedColumn(), TextColumn("{task.description}"),
                        console=err, disable=quiet)
    task = progress.add_task("", total=len(batch.jobs))

    def on_plan(to_run: int, skipped: int) -> None:
        progress.start()  # only now: the output folder is locked and the plan made
        if not quiet:
            where = f"on {scheduler}" if scheduler else "locally"
            err.print(with_compile_note(f"{len(batch.jobs)} scans: {skipped} already complete, {to_run} to run "
                                        f"{where}; results in {batch.output}"), highlight=False)

    def on_result(report) -> None:
        check_stop()
        progress.advance(task)
        if report.status == "failed":
            err.print(f"[red]failed[/]  {report.name}: {report.error}", highlight=False)
        elif not quiet:
            style = {"done": "green", "skipped": "dim"}.get(report.status, "yellow")
            err.print(f"[{style}]{report.status:<7}[/] {report.name} {_figures(report)}",
                      highlight=False)

    try:
        summary = run_batch(batch, workers=workers, scheduler=scheduler, force=force,
                            on_result=on_result, on_plan=on_plan)
    finally:
        progress.stop()
    if json:
        print(json_module.dumps(summary.to_dict(), indent=2))
    elif not quiet:
        _print_table(summary)
    raise typer.Exit(summary.exit_code)


def _figures(report) -> str:
    f = report.figures
    parts = []
    if report.seconds:
        parts.append(f"{report.seconds:.1f} s")
    # imported here, not at the top: 'potflat --help' stays free of Numba and SciPy
    from potflat.mesh.distortion import distortion_words

    return ", ".join(parts + [distortion_words(f)])


def _print_table(summary) -> None:
    # imported here, not at the top: 'potflat --help' stays free of Numba and SciPy
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"potflat batch: {summary.batch}", title_justify="left")
    for column, justify in (("scan", "left"), ("status", "left"), ("time s", "right"),
                            ("painted: lengths off % (median / p95)", "right"), ("edge RMS", "right"),
                            ("flipped", "right"), ("error", "left")):
        table.add_column(column, justify=justify, overflow="fold")
    styles = {"done": "green", "skipped": "dim", "failed": "red", "interrupted": "yellow", "cancelled": "yellow"}
    for r in summary.reports:
        rms, flips = r.figures.get("edge_rms"), r.figures.get("flipped")
        median, p95 = r.figures.get("painted_length_error_median_pct"), r.figures.get("painted_length_error_p95_pct")
        table.add_row(r.name, f"[{styles[r.status]}]{r.status}[/]",
                      f"{r.seconds:.1f}" if r.status != "skipped" else "",
                      "" if median is None or p95 is None else f"{median:.1f} / {p95:.1f}",
                      "" if rms is None else f"{rms:.4f}", "" if flips is None else str(flips),
                      r.error)
    out = Console()
    out.print(table)
    c = summary.counts
    out.print(f"{c['done']} done, {c['skipped']} skipped, {c['failed']} failed"
              + (f", {c['interrupted']} interrupted" if c["interrupted"] else "")
              + (f", {c['cancelled']} cancelled" if c["cancelled"] else "")
              + f" in {summary.seconds:.1f} s; summary.csv and summary.json in {summary.output}",
              highlight=False)
