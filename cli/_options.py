"""Typer options shared by several commands, and the stage options derived from the stages.

The stage options of ``potflat run`` are generated from the options dataclasses
(``RolloutOptions``, ``RelaxOptions``, ``BakeOptions``): one ``--field-name`` option per
field, typed like the field, defaulting to the stage's own default, with the help text of
the same option of ``potflat rollout/relax/bake`` (or the dataclass docstring). So the
names, types and defaults can never drift from the stages and the batch file schema.
"""
from __future__ import annotations

import dataclasses
import inspect
import re
import types
import typing
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

OutputDir = Annotated[Optional[Path], typer.Option(
    "--output", "-o", help="Output folder, created if needed \\[default: the input's folder].",
    file_okay=False)]
Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="Print nothing but errors.")]
Json = Annotated[bool, typer.Option("--json", help="Print a JSON summary to stdout (nothing else).")]
Name = Annotated[Optional[str], typer.Option("--name", help="Output file name stem \\[default: the scan's stem].")]

_PANELS = {"rollout": "Rollout options", "relax": "Relax options", "bake": "Bake options"}


def _cli_type(tp: Any) -> Any:
    """The type Typer parses for a field of type ``tp`` (always optional: None = default)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        rest = [a for a in args if a is not type(None)]
        return _cli_type(rest[0]) if len(rest) == 1 else Optional[str]
    if origin is tuple and (len(args) == 2 and args[1] is Ellipsis):
        return Optional[str]  # comma-separated list
    if origin in (tuple, typing.Literal) or tp in (bool, int, float, str, Path):
        return Optional[tp]
    return Optional[str]


def _docstring_help(cls: type) -> dict[str, str]:
    """Field descriptions from a numpydoc ``Attributes``/``Parameters`` section."""
    doc = inspect.getdoc(cls) or ""
    out: dict[str, str] = {}
    current = None
    for line in doc.splitlines():
        match = re.match(r"^(\w+)\s*:", line)
        if match:
            current = match.group(1)
            out[current] = ""
        elif current and line.startswith((" ", "\t")) and line.strip():
            out[current] = (out[current] + " " + line.strip()).strip()
        elif not line.strip():
            continue
        else:
            current = None
    return out


def _command_help(stage: str) -> dict[str, str]:
    """Help texts of the options of ``potflat <stage>`` by parameter name."""
    import importlib

    func = getattr(importlib.import_module(f"potflat_cli.commands.{stage}"), f"{stage}_command")
    hints = typing.get_type_hints(func, include_extras=True)
    out = {}
    for name, param in inspect.signature(func).parameters.items():
        infos = [param.default] + list(getattr(hints.get(name), "__metadata__", ()))
        for info in infos:
            if isinstance(info, typer.models.OptionInfo) and info.help:
                out[name] = info.help
    return out


def stage_parameters(stage: str) -> list[inspect.Parameter]:
    """Keyword parameters (Typer options) for every option field of ``stage``.

    Each is ``--field-name`` (``_`` becomes ``-``), defaults to ``None`` meaning the
    stage's default (shown in the help), booleans are ``--flag/--no-flag``, fixed-length
    tuples take that many values (``--band 0.2 0.6``), variable-length ones a
    comma-separated list.
    """
    from potflat.stages.pipeline import option_types, options_class

    cls = options_class(stage)
    helps = {**_docstring_help(cls), **_command_help(stage)}
    defaults = {f.name: f.default for f in dataclasses.fields(cls)}
    params = []
    for name, tp in option_types(cls).items():
        flag = "--" + name.replace("_", "-")
        cli_type = _cli_type(tp)
        default = defaults.get(name)
        # a flag that is off by default is just --flag, as in the stage commands
        on_off = cli_type == Optional[bool] and default is not False
        decls = (f"{flag}/--no-{flag[2:]}",) if on_off else (flag,)
        text = (helps.get(name) or f"{stage} option {name}.").replace("``", "'")
        if "[default" not in text and default is not dataclasses.MISSING and default is not False:
            text += f" \\[default: {_shown_default(default)}]"
        info = typer.Option(*decls, help=text, rich_help_panel=_PANELS[stage], show_default=False)
        params.append(inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY,
                                        annotation=Annotated[cli_type, info], default=None))
    return params


def _shown_default(value: Any) -> str:
    if value is None:
        return "auto"
    if isinstance(value, (tuple, list)):
        return ",".join(map(str, value)) if value else "none"
    if isinstance(value, bool):
        return "on" if value else "off"
    return str(getattr(value, "value", value))


def options_from_cli(stage: str, values: dict[str, Any]):
    """Build ``stage``'s options dataclass from command-line values (``None`` = default).

    Raises
    ------
    InvalidOptionError
        Naming the option (``--px-per-mm ...``) and what is wrong.
    """
    from potflat.errors import InvalidOptionError
    from potflat.stages.pipeline import coerce_option, option_types, options_class

    cls = options_class(stage)
    kwargs = {}
    for name, tp in option_types(cls).items():
        value = values.get(name)
        if value is None:
            continue
        try:
            kwargs[name] = coerce_option(tp, value)
        except InvalidOptionError as exc:
            raise InvalidOptionError(f"--{name.replace('_', '-')} {exc}") from None
    return cls(**kwargs)
