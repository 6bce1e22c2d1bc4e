"""Run one scan through all three stages: rollout -> relax -> bake.

The stages are found by name (``potflat.rollout``, ``potflat.relax``, ``potflat.bake``),
each providing an options dataclass (``RolloutOptions``...) and a file-level function
(``run_rollout_stage``...). They are imported on first use, so importing this module is
cheap and the batch schema can be derived from the options dataclasses.
"""
from __future__ import annotations

import dataclasses
import difflib
import enum
import importlib
import re
import time
import types
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from potflat.errors import InvalidOptionError, PotflatError
from potflat.stages.names import STAGE_INPUT
from potflat.types import StageOutput

#: The stages in the order they run.
STAGES: tuple[str, ...] = ("rollout", "relax", "bake")

#: The distortion figures a batch summary reports (keys of DistortionSummary).
FIGURES: tuple[str, ...] = ("edge_rms", "area_mean_abs_log", "anisotropy_p95", "flipped")
#: ... and the painted zone's and the plain surface's: the share of the surface that is painted,
#: and how far lengths read off the image are off there and on the plain surface (median and
#: 95th percentile, %): column name to (key in ``NAME.relaxed.json``, figure).
ZONE_FIGURES: dict[str, tuple[str, str]] = {
    "painted_area_fraction": ("important_zone", "area_fraction"),
    "painted_length_error_median_pct": ("important_zone", "length_error_median_pct"),
    "painted_length_error_p95_pct": ("important_zone", "length_error_p95_pct"),
    "plain_length_error_median_pct": ("rest", "length_error_median_pct"),
    "plain_length_error_p95_pct": ("rest", "length_error_p95_pct"),
}


def options_class(stage: str) -> type:
    """The options dataclass of ``stage`` (``RolloutOptions``...), without importing the
    stage's algorithm (the command line builds its options and help from it).

    Parameters
    ----------
    stage : str
        ``"rollout"``, ``"relax"`` or ``"bake"``.
    """
    if stage not in STAGES:
        raise ValueError(f"unknown stage {stage!r}; one of {', '.join(STAGES)}")
    return getattr(importlib.import_module(f"potflat.{stage}"), f"{stage.capitalize()}Options")


def stage_api(stage: str) -> tuple[type, Callable[..., StageOutput]]:
    """The options dataclass and the file-level function of ``stage``.

    Parameters
    ----------
    stage : str
        ``"rollout"``, ``"relax"`` or ``"bake"``.

    Returns
    -------
    options_class : type
        ``RolloutOptions``, ``RelaxOptions`` or ``BakeOptions``.
    run : callable
        ``run_<stage>_stage(input_path, out_dir, options, *, name=None) -> StageOutput``.
    """
    cls = options_class(stage)
    return cls, getattr(importlib.import_module(f"potflat.stages.{stage}_stage"), f"run_{stage}_stage")


def options_dict(options: Any) -> dict[str, Any]:
    """A stage options dataclass as a JSON-ready dict (tuples become lists)."""
    import json

    return json.loads(json.dumps(dataclasses.asdict(options), default=str))


@dataclass(frozen=True)
class ScanResult:
    """What :func:`run_scan` produced for one scan.

    Attributes
    ----------
    name : str
        Output name: files are ``NAME.rollout.ply``, ``NAME.relaxed.ply``, ``NAME.png``...
    scan : Path
        The scan that was read.
    out_dir : Path
        Folder holding every output.
    stages : dict of str to StageOutput
        ``"rollout"``, ``"relax"``, ``"bake"`` to what each stage wrote.
    seconds : dict of str to float
        Wall time of each stage, and ``"total"``.
    """

    name: str
    scan: Path
    out_dir: Path
    stages: dict
    seconds: dict

    @property
    def paths(self) -> dict[str, Path]:
        """Every file written, keyed ``"<stage>.<role>"`` (e.g. ``"bake.png"``)."""
        return {f"{stage}.{role}": Path(p) for stage, out in self.stages.items()
                for role, p in out.paths.items()}

    @property
    def figures(self) -> dict[str, Any]:
        """Distortion figures of the final flattening (:data:`FIGURES`, from the relax stage)."""
        return {k: getattr(self.stages["relax"].distortion, k) for k in FIGURES}

    @property
    def zone_figures(self) -> dict[str, Any]:
        """The painted zone's and the plain surface's figures (:data:`ZONE_FIGURES`, from the
        relax stage; without a painted zone the whole surface is the painted zone and the plain
        surface's figures are None)."""
        summary = self.stages["relax"].summary
        return {column: (summary.get(key) or {}).get(figure) for column, (key, figure) in ZONE_FIGURES.items()}


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


def resolve_options(**given: Any) -> dict[str, Any]:
    """Options instances for every stage: the given ones, checked, or the defaults.

    Parameters
    ----------
    **given
        ``rollout=``, ``relax=``, ``bake=``: an options instance, a dict of option
        values, or ``None`` for the defaults.
    """
    out = {}
    for stage in STAGES:
        cls = options_class(stage)
        value = given.get(stage)
        if value is None:
            value = cls()
        elif isinstance(value, dict):
            value = cls(**value)
        elif not isinstance(value, cls):
            raise InvalidOptionError(
                f"{stage}= must be a {cls.__name__} (or a dict of its fields), got {type(value).__name__}")
        out[stage] = value
    return out


def partial_marker(out: Path, name: str) -> Path:
    """The hidden file :func:`run_scan` keeps in ``out`` while it writes ``NAME.*`` (removed when
    every stage is done): a later run recognises the files of an interrupted run as potflat's own."""
    return out / f".{name}.potflat-incomplete"


def _check_painting_name_is_free(out: Path, name: str) -> None:
    """Refuse before any work when ``NAME.png`` exists in ``out`` and was not baked by potflat
    (typically the scan's own texture, when the output folder is the scan's folder): the bake
    would stop there after rollout and relax had run. A painting left by an interrupted potflat
    run (:func:`partial_marker`) is potflat's own."""
    painting = out / f"{name}.png"
    if (painting.exists() and not (out / f"{name}.bake.json").exists()
            and not partial_marker(out, name).exists()):
        raise InvalidOptionError(f"{painting} exists and was not made by potflat (the scan's texture?) and would be "
                                 "overwritten; give another output folder (-o) or --name")


def _preview_at_image_resolution(options: dict) -> dict:
    """A relax preset that relaxes a coarse copy (``preview``) does so at 2 pixels of the image
    it is baked into, unless ``simplify_mm`` was given."""
    relax, bake = options["relax"], options["bake"]
    if relax.simplify_mm is not None:  # given
        return options
    if relax.resolved().simplify_mm:
        options = {**options, "relax": dataclasses.replace(relax, simplify_mm=2.0 / bake.resolution)}
    return options


def _image_check(bake) -> Callable:
    """A check of the rollout's flattening: would the baked image be of a sane size? Run before
    the rollout writes anything, so an absurd resolution (or a scan in the wrong unit) stops the
    run before any file exists rather than at the bake, after rollout and relax."""
    def check(flat) -> None:
        import numpy as np

        from potflat.bake.render import image_size

        used = np.zeros(len(flat.uv), bool)
        used[flat.mesh.faces.ravel()] = True
        if used.any():
            from potflat.mesh.distortion import bounds

            lo, hi = bounds(flat.uv[used])
            image_size((hi - lo) * flat.mesh.mm_per_unit, bake.resolution,
                       bake.max_megapixels)
    return check


def run_scan(scan_path, out_dir, *, rollout=None, relax=None, bake=None, name: str | None = None,
             progress: Callable[[str], None] | None = None) -> ScanResult:
    """Run rollout, relax and bake on one scan, writing every output into ``out_dir``.

    Parameters
    ----------
    scan_path : path-like
        The textured scan (OBJ, PLY, ...).
    out_dir : path-like
        Output folder (created if needed).
    rollout, relax, bake : RolloutOptions, RelaxOptions, BakeOptions, dict or None
        Options of each stage; ``None`` uses the stage's defaults.
    name : str, optional
        Output name; defaults to the scan's file stem.
    progress : callable, optional
        Called with the stage name (``"rollout"``, ``"relax"``, ``"bake"``) as each starts.

    Returns
    -------
    ScanResult

    Raises
    ------
    PotflatError
        From the stage that failed; outputs of the stages already done are kept.
    """
    from potflat.io.atomic import check_output_name, output_lock, remove_stale_parts, write_json_atomic
    from potflat.io.scan import check_scan_file

    scan = Path(scan_path)
    out = Path(out_dir)
    name = check_output_name(name or scan.stem, what="name" if name else f"the name of {scan}")
    check_scan_file(scan)
    options = _preview_at_image_resolution(resolve_options(rollout=rollout, relax=relax, bake=bake))
    _check_painting_name_is_free(out, name)
    stages: dict[str, StageOutput] = {}
    seconds: dict[str, float] = {}
    start = time.perf_counter()
    source, handed = scan, {}
    with output_lock(out):
        remove_stale_parts(out)  # left by a killed run; no other potflat process writes here now
        for stage in STAGES:
            if progress is not None:
                progress(stage)
            if stage in STAGE_INPUT:
                source = out / f"{name}{STAGE_INPUT[stage]}"
                if not source.is_file():
                    raise PotflatError(f"{source}: the previous stage did not write it; "
                                       "this is a bug in potflat, please report it")
            if stage == "bake":  # NAME.png is written before NAME.bake.json: mark it as potflat's own
                marker = write_json_atomic(partial_marker(out, name), {"potflat": "incomplete", "scan": str(scan)})
            _, run = stage_api(stage)
            t = time.perf_counter()
            if stage == "rollout":
                handed = {"check": _image_check(options["bake"])}
            stages[stage] = run(source, out, options[stage], name=name, **handed)
            # the flattening, its figures and the rollout's summary go on in memory (computed
            # once, not again); the files are the record (and the stage commands' input)
            done = stages[stage]
            handed = ({"flat": done.flat, "rollout_summary": stages["rollout"].summary, "distortion": done.distortion,
                       **({"zone": done.zone} if done.zone is not None else {}),
                       **({"reference": done.reference} if done.reference is not None else {})}
                      if done.flat is not None else {})
            if done.reference is not None:  # (the next stage's alone: the result does not keep it)
                stages[stage] = dataclasses.replace(done, reference=None)
            seconds[stage] = time.perf_counter() - t
        marker.unlink()
    seconds["total"] = time.perf_counter() - start
    return ScanResult(name=name, scan=scan, out_dir=out, stages=stages, seconds=seconds)
