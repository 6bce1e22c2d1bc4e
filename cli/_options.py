"""The command line's options: the ones every command shares, and each stage's options
generated from its options dataclass (``RolloutOptions``, ``RelaxOptions``, ``BakeOptions``).

A stage option is ``--field-name``, typed like its field, with the field's description in
the dataclass docstring as its help, its allowed values (a field's ``choices`` metadata) and
its default (the dataclass's, or each relax preset's). So the names, types, help and defaults
can never drift from the stages and the batch file schema: a new option is one field.
"""
from __future__ import annotations

import dataclasses
import functools
import inspect
import re
import types
import typing
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, Optional

import typer

from potflat.files.options import STAGE_OPTIONS, coerce_option, option_types
from potflat.errors import InvalidOptionError
from potflat.relax.options import PRESET_FIELDS, RelaxOptions
from potflat.relax.parameters import PRESETS

OutputDir = Annotated[Optional[Path], typer.Option(
    "--output", "-o", help="Output folder, created if needed \\[default: ./NAME/ in the current folder; "
                           "never the scan's folder unless given].",
    file_okay=False)]
StageOutputDir = Annotated[Optional[Path], typer.Option(
    "--output", "-o", help="Output folder, created if needed \\[default: the folder of the input file].",
    file_okay=False)]
Quiet = Annotated[bool, typer.Option("--quiet", "-q", help="Print nothing but errors.")]
Json = Annotated[bool, typer.Option("--json", help="Print a JSON summary to stdout (nothing else).")]
Name = Annotated[Optional[str], typer.Option("--name", help="Output file name stem \\[default: the scan's stem].")]
StageName = Annotated[Optional[str], typer.Option(
    "--name", help="Output file name stem \\[default: the input's NAME, as in NAME.relaxed.ply].")]

_PANELS = {"rollout": "Rollout options", "relax": "Relax options", "bake": "Bake options"}
#: Longest list of allowed values shown as the metavar (``[a|b|c]``); a longer one shows ``NAME``.
MAX_METAVAR = 15


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


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _cli_literal(text: str, fields: set[str]) -> str:
    """A docstring literal (````x````) in the command line's words: an option's field name as
    its flag (``seam_at`` -> --seam-at, ``proxy="ortho"`` -> --proxy ortho), a quoted value
    without its quotes (``"auto"`` -> auto), anything else in quotes."""
    name, eq, value = text.partition("=")
    if name.strip() in fields:
        return _flag(name.strip()) + (f" {value.strip().strip(chr(34) + chr(39))}" if eq else "")
    if len(text) > 1 and text[0] == text[-1] and text[0] in "\"'":
        return text[1:-1]
    return f"'{text}'"


def _plain(text: str, fields: set[str] = frozenset()) -> str:
    """Docstring markup in the command line's words: a parenthesised reference to the code
    (``(:mod:`potflat.importance`)``) dropped, :role:`~a.b` as b, :role:`t <a.b>` as t, a
    literal by :func:`_cli_literal` (field names of ``fields`` as flags), ``None`` (an
    option not given) as "not given"."""
    text = re.sub(r"\s*\(:\w+:`[^`]*`\)", "", text)
    text = re.sub(r":\w+:`~?([^`<]*?)\s*<[^>]*>`", r"\1", text)
    text = re.sub(r":\w+:`~?([^`]*)`", lambda m: m.group(1).rsplit(".", 1)[-1], text)
    text = re.sub(r"``([^`]*)``", lambda m: _cli_literal(m.group(1), fields), text)
    text = re.sub(r"\bNone\b", "not given", text)
    return text.replace("[", "\\[")


def field_help(cls: type) -> dict[str, str]:
    """Each field's description in the numpydoc ``Attributes`` section of ``cls``'s docstring,
    in the command line's words (:func:`_plain`; a line ``a, b : type`` describes both)."""
    doc = inspect.getdoc(cls) or ""
    out: dict[str, str] = {}
    current: list[str] = []
    for line in doc.splitlines():
        match = re.match(r"^(\w+(?:\s*,\s*\w+)*)\s*:", line)
        if match and not line.startswith((" ", "\t")):
            current = [n.strip() for n in match.group(1).split(",")]
            for name in current:
                out[name] = ""
        elif current and line.startswith((" ", "\t")) and line.strip():
            for name in current:
                out[name] = (out[name] + " " + line.strip()).strip()
        elif line.strip():
            current = []
    fields = {f.name for options in STAGE_OPTIONS.values() for f in dataclasses.fields(options)}
    return {name: _plain(text, fields) for name, text in out.items()}


def _shown(value: Any) -> str:
    if isinstance(value, (tuple, list)):
        return ",".join(map(str, value)) if value else "none"
    if isinstance(value, bool):
        return "on" if value else "off"
    return f"{value:g}" if isinstance(value, float) else str(getattr(value, "value", value))


def _preset_default(name: str) -> str:
    """A relax option's default by preset: the default preset's value, then the others'
    (``0.25 (paper: 0)``)."""
    default = _shown(getattr(PRESETS[RelaxOptions().preset], name))
    others: dict[str, list[str]] = {}
    for preset, settings in PRESETS.items():
        value = _shown(getattr(settings, name))
        if value != default:
            others.setdefault(value, []).append(preset)
    return default + (" (" + "; ".join(f"{', '.join(p)}: {v}" for v, p in others.items()) + ")" if others else "")


def _choices(field: dataclasses.Field) -> tuple[str, ...]:
    return tuple(str(c) for c in field.metadata.get("choices", ()))


def stage_parameters(stage: str) -> list[inspect.Parameter]:
    """Keyword parameters (Typer options) for every option field of ``stage``.

    Each is ``--field-name`` (``_`` becomes ``-``), defaults to ``None`` meaning the
    stage's default (shown in the help), booleans are ``--flag`` (off by default) or
    ``--flag/--no-flag``, fixed-length tuples take that many values (``--band 0.2 0.6``),
    variable-length ones a comma-separated list.
    """
    cls = STAGE_OPTIONS[stage]
    helps = field_help(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    params = []
    for name, tp in option_types(cls).items():
        field = fields[name]
        flag = "--" + name.replace("_", "-")
        cli_type = _cli_type(tp)
        default = field.default
        on_off = cli_type == Optional[bool] and default is not False  # a flag off by default is just --flag
        decls = (f"{flag}/--no-{flag[2:]}",) if on_off else (flag,)
        text = helps.get(name) or f"{stage} option {name}."
        choices = _choices(field)
        if choices:
            text += f" One of: {', '.join(choices)}."
        if stage == "relax" and name in PRESET_FIELDS:
            text += f" \\[default: {_preset_default(name)}]"
        elif default is not dataclasses.MISSING and default is not None and default is not False:
            text += f" \\[default: {_shown(default)}]"
        metavar = field.metadata.get("metavar")
        if metavar is None and choices:
            metavar = "[" + "|".join(choices) + "]"
            metavar = metavar if len(metavar) <= MAX_METAVAR else "NAME"
        info = typer.Option(*decls, help=text, rich_help_panel=_PANELS[stage], show_default=False, metavar=metavar)
        params.append(inspect.Parameter(name, inspect.Parameter.KEYWORD_ONLY,
                                        annotation=Annotated[cli_type, info], default=None))
    return params


def options_from_cli(stage: str, values: dict[str, Any]):
    """Build ``stage``'s options dataclass from command-line values (``None`` = default).

    Raises
    ------
    InvalidOptionError
        Naming the option (``--px-per-mm ...``) and what is wrong.
    """
    cls = STAGE_OPTIONS[stage]
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


def with_stage_options(*stages: str) -> Callable[[Callable], Callable]:
    """Give a command the options of ``stages``, generated from their options dataclasses.

    The decorated function takes its own parameters and ``options``: a dict of stage name to
    its options dataclass, built from the command line (an option shared by two stages is
    given once)."""
    def decorate(func: Callable) -> Callable:
        own = [p for p in inspect.signature(func, eval_str=True).parameters.values() if p.name != "options"]
        seen, extra = {p.name for p in own}, []
        for stage in stages:
            for p in stage_parameters(stage):
                if p.name not in seen:
                    seen.add(p.name)
                    extra.append(p)

        @functools.wraps(func)
        def command(**values: Any) -> Any:
            options = {stage: options_from_cli(stage, values) for stage in stages}
            return func(**{p.name: values[p.name] for p in own}, options=options)

        command.__signature__ = inspect.Signature(own + extra)
        command.__annotations__ = {p.name: p.annotation for p in own + extra}
        del command.__wrapped__  # Typer reads the signature given here, not the function's
        return command
    return decorate
