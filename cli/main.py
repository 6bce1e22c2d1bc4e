"""``potflat``: rollout, relax and bake painted pottery scans into true-scale images."""
from __future__ import annotations

import typer
from typer.core import TyperGroup

from potflat_cli.commands import bake, batch, plate, relax, rollout, run

HELP = """Flatten textured 3D scans of painted pottery into true-scale images.

Stages: rollout (axis, proxy, seam, unroll) -> relax (fold-free elastic relaxation) -> bake (true-scale PNG and distortion maps). 'run' does all three on one scan, 'batch' on many scans from a YAML file; 'plate' composes the publication plate.

Exit codes: 0 success, 1 some scans of a batch failed, 2 bad input or options (message on stderr), 130 interrupted.

Example:  potflat run samples/data/amphora.obj -o out/
"""


class _Group(TyperGroup):
    """Builds the full ``run`` command (every stage option) only when ``run`` is invoked."""

    def resolve_command(self, ctx, args):
        name, command, rest = super().resolve_command(ctx, args)
        if name == "run":
            mini = typer.Typer(pretty_exceptions_show_locals=False, add_completion=False)
            mini.command("run")(run.full_command())
            command = typer.main.get_command(mini)
        return name, command, rest


app = typer.Typer(
    name="potflat",
    cls=_Group,
    help=HELP,
    no_args_is_help=True,
    pretty_exceptions_show_locals=False,
    add_completion=False,
)


def _version(value: bool) -> None:
    if value:
        from potflat import __version__

        typer.echo(f"potflat {__version__}")
        raise typer.Exit()


@app.callback(help=HELP)
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
app.command("plate")(plate.plate_command)
