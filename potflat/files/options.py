"""The stages' options as the command line and batch files give them: by stage name, read
from text or YAML values and checked by the options dataclasses themselves (light to import:
no numpy beyond the options modules)."""
from __future__ import annotations

import dataclasses
import difflib
import enum
import json
import re
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from potflat.bake.options import BakeOptions
from potflat.errors import InvalidOptionError
from potflat.relax.options import RelaxOptions
from potflat.rollout.options import RolloutOptions


@dataclass(frozen=True)
class RunOptions:
    """The options of all three stages of a run.

    Attributes
    ----------
    rollout : RolloutOptions
    relax : RelaxOptions
    bake : BakeOptions
    """

    rollout: RolloutOptions = dataclasses.field(default_factory=RolloutOptions)
    relax: RelaxOptions = dataclasses.field(default_factory=RelaxOptions)
    bake: BakeOptions = dataclasses.field(default_factory=BakeOptions)


#: Each stage's options dataclass, in the order the stages run.
STAGE_OPTIONS: dict[str, type] = {"rollout": RolloutOptions, "relax": RelaxOptions, "bake": BakeOptions}

#: The stages in the order they run.
STAGES: tuple[str, ...] = tuple(STAGE_OPTIONS)


def options_dict(options: Any) -> dict[str, Any]:
    """A stage options dataclass as a JSON-ready dict (tuples become lists)."""
    return json.loads(json.dumps(dataclasses.asdict(options), default=str))


def option_types(cls: type) -> dict[str, Any]:
    """Field name to resolved type hint of a stage options dataclass ``cls`` (fields only)."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints.get(f.name, Any) for f in dataclasses.fields(cls) if f.init}


def describe_type(tp: Any) -> str:
    """A short English description of a type hint, for messages ("a number", ...)."""
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        parts = [describe_type(a) for a in args if a is not type(None)]
        return " or ".join(parts) + (" or null" if type(None) in args else "")
    if origin is typing.Literal:
        return "one of " + ", ".join(map(str, args))
    if origin is tuple:
        if len(args) == 2 and args[1] is Ellipsis:
            return f"a list of {_plural(args[0])}"
        if args and all(a == args[0] for a in args):
            return f"a list of {len(args)} {_plural(args[0])}"
        return "a list of " + ", ".join(describe_type(a) for a in args)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        return "one of " + ", ".join(str(m.value) for m in tp)
    return {bool: "true or false", int: "a whole number", float: "a number", str: "text",
            Path: "a path"}.get(tp, getattr(tp, "__name__", str(tp)))


def _plural(tp: Any) -> str:
    return {int: "whole numbers", float: "numbers", str: "names", bool: "true/false values"}.get(
        tp, describe_type(tp))


def coerce_option(tp: Any, value: Any) -> Any:
    """Convert a YAML or command-line value to the type hint ``tp`` of an option field.

    Numbers may be given for floats, integral numbers for ints, lists (or comma-separated
    text) for tuples, text for paths and enums. Range checks are left to the options
    dataclass itself.

    Raises
    ------
    InvalidOptionError
        If ``value`` cannot be read as ``tp``; the message names the expected type.
    """
    origin, args = typing.get_origin(tp), typing.get_args(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        for arg in args:
            if arg is type(None):
                continue
            try:
                return coerce_option(arg, value)
            except InvalidOptionError:
                continue
        raise _type_error(tp, value)
    if origin is typing.Literal:
        if value in args:
            return value
        close = difflib.get_close_matches(str(value), [str(a) for a in args], n=1)
        hint = f" (did you mean {close[0]}?)" if close else ""
        raise InvalidOptionError(f"must be {describe_type(tp)}, got {value!r}{hint}")
    if origin is tuple:
        if isinstance(value, str):
            value = [v.strip() for v in value.split(",") if v.strip()]
        if not isinstance(value, (list, tuple)):
            raise _type_error(tp, value)
        if len(args) == 2 and args[1] is Ellipsis:
            item_types = [args[0]] * len(value)
        else:
            item_types = list(args)
            if len(value) != len(item_types):
                raise _type_error(tp, value)
        try:
            return tuple(coerce_option(t, v) for t, v in zip(item_types, value))
        except InvalidOptionError:
            raise _type_error(tp, value) from None
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        for member in tp:
            if value in (member, member.value, member.name):
                return member
        raise _type_error(tp, value)
    if tp is bool:
        if isinstance(value, bool):
            return value
    elif tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        if isinstance(value, float) and value.is_integer():
            return int(value)
        if isinstance(value, str) and re.fullmatch(r"[+-]?\d+", value.strip()):
            return int(value)
    elif tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        if isinstance(value, str):
            try:
                return float(value)
            except ValueError:
                pass
    elif tp is str:
        if isinstance(value, str):
            return value
    elif tp is Path:
        if isinstance(value, (str, Path)):
            return Path(value)
    else:
        return value
    raise _type_error(tp, value)


def _type_error(tp: Any, value: Any) -> InvalidOptionError:
    shown = "null" if value is None else repr(value)
    return InvalidOptionError(f"must be {describe_type(tp)}, got {shown}")


def resolve_options(**given: Any) -> RunOptions:
    """Options of every stage: the given ones, checked, or the defaults.

    Parameters
    ----------
    **given
        ``rollout=``, ``relax=``, ``bake=``: an options instance, a dict of option
        values, or ``None`` for the defaults.
    """
    out = {}
    for stage, cls in STAGE_OPTIONS.items():
        value = given.get(stage)
        if value is None:
            value = cls()
        elif isinstance(value, dict):
            value = cls(**value)
        elif not isinstance(value, cls):
            raise InvalidOptionError(
                f"{stage}= must be a {cls.__name__} (or a dict of its fields), got {type(value).__name__}")
        out[stage] = value
    return RunOptions(**out)
