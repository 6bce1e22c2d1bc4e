"""``potflat``: rollout, relax and bake painted pottery scans into true-scale images."""
from __future__ import annotations

import typer

from potflat_cli.commands import bake, batch, relax, rollout, run

app = typer.Typer(
    name="potflat",
    help="Flatten textured 3D scans of painted pottery into true-scale images.",
    no_args_is_help=True,
    pretty_exceptions_show_locals=False,
    add_completion=False,
)


def _version(value: bool) -> None:
    if value:
        from potflat import __version__

        typer.echo(f"potflat {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True,
                                 help="Print the version and exit."),
) -> None:
    """Flatten textured 3D scans of painted pottery into true-scale images."""


app.command("rollout")(rollout.rollout_command)
app.command("relax")(relax.relax_command)
app.command("bake")(bake.bake_command)
app.command("run")(run.run_command)
app.command("batch")(batch.batch_command)
