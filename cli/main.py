"""``potflat``: rollout, relax and bake painted pottery scans into true-scale images."""
from __future__ import annotations

import typer
from typer.core import TyperGroup

from potflat_cli.commands import bake, batch, plate, relax, rollout, run, view, warmup

HELP = """Flatten textured 3D scans of painted pottery into true-scale images.

Stages: rollout (axis, proxy, seam, unroll) -> relax (fold-free elastic relaxation) -> bake (true-scale PNG and distortion maps). 'run' does all three on one scan, 'batch' on many scans from a YAML file; 'plate' composes the publication plate; 'view' opens a finished run in the browser; 'warmup' compiles potflat's kernels once, before the first run needs them.

Exit codes: 0 success, 1 some scans of a batch failed, 2 bad input or options (message on stderr), 130 interrupted.

Example:  potflat run samples/data/amphora.obj -o out/
"""


def split_pairs(args: list[str], pair_options) -> list[str]:
    """``--band 0.2,0.8`` and ``--band=0.2,0.8`` as ``--band 0.2 0.8`` for the options in
    ``pair_options`` (Click's two-value options)."""
    out: list[str] = []
    tokens = iter(args)
    for arg in tokens:
        flag, eq, value = arg.partition("=")
        if flag not in pair_options or (not eq and (value := next(tokens, None)) is None):
            out.append(arg)
            continue
        parts = value.replace(",", " ").split()
        out += [flag, *parts] if len(parts) == 2 else [flag, value]
    return out


def _interrupt(signum, frame) -> None:
    """Ctrl-C and SIGTERM (a cluster's or a service manager's stop): clean up and stop (outside
    Numba's compiler: :func:`potflat._interrupts.raise_interrupt`)."""
    from potflat._interrupts import raise_interrupt
    from potflat_cli._errors import STOP

    STOP.append(signum)  # remembered: an interrupt raised inside a finaliser is swallowed by Python
    raise_interrupt(signum, frame)


def _quiet_unraisable(unraisable) -> None:
    """``sys.unraisablehook``: an interrupt raised where Python cannot raise it (a finaliser, a
    weakref callback) is remembered (:data:`STOP`) and ends the command with its one line, so
    Python's "Exception ignored ... Traceback" is not printed for it. Once stopping, neither is
    a finaliser's error (whatever the interrupt broke). Before a stop, every unraisable error
    is printed."""
    import sys

    from potflat_cli._errors import STOP

    if STOP:
        return
    sys.__unraisablehook__(unraisable)


class _Group(TyperGroup):
    """Builds the full ``run`` command (every stage option) only when ``run`` is invoked.

    Usage errors (a missing argument, a value out of range, a directory given as a file)
    are one ``error:`` line and exit code 2, like every other bad input; SIGTERM is
    handled like SIGINT. Commands run with the process settings of
    :func:`potflat_cli._process.command_settings`.
    """

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True, **extra):
        import signal
        import sys
        import threading

        try:  # Typer 0.29+ carries its own copy of Click
            from typer import _click as click
        except ImportError:
            import click

        from potflat._interrupts import ignore_interrupts
        from potflat_cli import _is_the_command
        from potflat_cli._errors import EXIT_USAGE, STOP, TOLD, fail, interrupted
        from potflat_cli._process import command_settings

        STOP.clear()
        TOLD.clear()
        args = list(sys.argv[1:] if args is None else args)
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, _interrupt)
            sys.unraisablehook = _quiet_unraisable
        if not standalone_mode:
            with command_settings():
                return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        try:
            with command_settings():
                code = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
            if STOP:  # (Typer turns an interrupt outside a command into exit code 130, silently)
                code = interrupted().exit_code
        except click.exceptions.NoArgsIsHelpError as exc:
            exc.show()
            code = EXIT_USAGE
        except click.ClickException as exc:
            command = getattr(getattr(exc, "ctx", None), "command_path", None) or "potflat"
            message = " ".join(exc.format_message().split()).rstrip(".")
            fail(f"{message[:1].lower()}{message[1:]}; see '{command} --help'", exc.exit_code)
            code = exc.exit_code
        except (typer.Abort, KeyboardInterrupt):
            code = interrupted().exit_code
        except Exception:
            if not STOP:
                raise
            code = interrupted().exit_code  # whatever the interrupt broke while the command was being built
        if _is_the_command() and threading.current_thread() is threading.main_thread():
            # done: a stop signal from here on changes nothing, and Python's shutdown (a few
            # tenths of a second with Numba loaded) puts the default handlers back, which would
            # let it kill the finished command (exit -15 instead of its code)
            ignore_interrupts()
        sys.exit(code or 0)

    def resolve_command(self, ctx, args):
        name, command, rest = super().resolve_command(ctx, args)
        if command is not None:
            pairs = {opt for p in command.params if p.nargs == 2 for opt in p.opts}
            rest = split_pairs(rest, pairs)  # --band 0.2,0.8 as --band 0.2 0.8
            if "--help" in rest:
                _show_choices(command, ctx)
        return name, command, rest

    def get_help_option(self, ctx):
        option = super().get_help_option(ctx)
        _show_metavars([*self.params, option])  # 'potflat --help': nothing after --help and --version either
        return option


def _show_choices(command, ctx) -> None:
    """:func:`_show_metavars` for a command's parameters and its ``--help``."""
    _show_metavars([*getattr(command, "params", ()), command.get_help_option(ctx)])


def _show_metavars(params) -> None:
    """In ``--help``: nothing after on/off flags, ``--help`` included (instead of ``<bool>``),
    arguments by their name in capitals in the usage line (``SCAN``, not ``{scan}``), and
    ``A B|A,B`` for the options that take two values."""
    for param in params:
        if param is None:
            continue
        if getattr(param, "is_flag", False):
            param.metavar = ""
        elif param.param_type_name == "argument":  # (Typer writes a required one as '{scan}')
            shown = param.name.upper() if param.required else f"[{param.name.upper()}]"
            param._usage_display_name = lambda shown=shown: shown
        elif param.nargs == 2 and param.metavar is None:  # --band 0.2 0.8 or --band 0.2,0.8 (split_pairs)
            param.metavar = "A B|A,B"


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
app.command("view")(view.view_command)
app.command("warmup")(warmup.warmup_command)
