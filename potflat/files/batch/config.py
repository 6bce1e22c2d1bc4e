"""Batch files: many scans through all stages, read and validated up front.

A batch file (YAML, documented in ``docs/cli.md``)::

    output: results/            # one folder per scan below it
    defaults: {proxy: auto, px_per_mm: 4}
    scans:
      - path: scans/hydria.obj
      - path: scans/amphora-*.ply
        band: [0.2, 0.6]

:func:`load_batch` validates the whole file before any work starts (every problem is a
one-line ``FILE:LINE: what; fix`` message in :class:`BatchFileError`). :func:`run_batch`
runs the scans in a local process pool or on a Dask cluster; one failing scan never stops
the others. Each finished scan folder gets a ``manifest.json``, written last, recording the
hash of its inputs, options and potflat version: a rerun skips scans whose manifest matches.
"""
from __future__ import annotations

import difflib
import glob
import itertools
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.files.options import (
    STAGE_OPTIONS,
    RunOptions,
    coerce_option,
    option_types,
    options_dict,
)
from potflat.io.atomic import check_output_name
from potflat.io.scan import SCAN_EXTENSIONS

#: Top-level keys of a batch file.
TOP_KEYS = ("output", "defaults", "scans")


#: Keys of a scan entry besides the stage options.
SCAN_KEYS = ("path", "name")


#: Largest batch file read (characters), values once YAML aliases are expanded, and characters
#: of one value: a batch file lists scans and options, never data.
MAX_BATCH_BYTES = 4_000_000


MAX_YAML_NODES = 1_000_000


MAX_YAML_SCALAR = 4096


#: Most files a ``path:`` pattern may match (a pattern over a whole disk is a mistake).
MAX_GLOB_MATCHES = 100_000


class BatchFileError(InvalidInputError):
    """A batch file is invalid; ``problems`` holds one ``FILE:LINE: message`` per problem."""

    def __init__(self, problems: list[str]):
        self.problems = list(problems)
        super().__init__("\n".join(self.problems))


# --------------------------------------------------------------------------- YAML with lines
class _LineDict(dict):
    """A mapping from the batch file that remembers the line of itself and of each key."""

    line: int = 1
    lines: dict


class _LineList(list):
    """A sequence from the batch file that remembers the line of itself and of each item."""

    line: int = 1
    lines: list


class _Loader(yaml.SafeLoader):
    """SafeLoader building :class:`_LineDict`/:class:`_LineList` (safe tags only)."""


def _construct_map(loader: _Loader, node: yaml.MappingNode) -> _LineDict:
    loader.flatten_mapping(node)
    out = _LineDict()
    out.line, out.lines = node.start_mark.line + 1, {}
    for key_node, value_node in node.value:
        key = loader.construct_object(key_node, deep=True)
        line = key_node.start_mark.line + 1
        try:
            hash(key)
        except TypeError:
            raise yaml.MarkedYAMLError(problem="a key must be a plain name",
                                       problem_mark=key_node.start_mark) from None
        if key in out:
            raise yaml.MarkedYAMLError(problem=f"{key!r} is given twice (first on line "
                                       f"{out.lines[key]}); keep one", problem_mark=key_node.start_mark)
        out[key] = loader.construct_object(value_node, deep=True)
        out.lines[key] = line
    return out


def _construct_seq(loader: _Loader, node: yaml.SequenceNode) -> _LineList:
    out = _LineList(loader.construct_object(child, deep=True) for child in node.value)
    out.line, out.lines = node.start_mark.line + 1, [c.start_mark.line + 1 for c in node.value]
    return out


class _TooLarge(yaml.MarkedYAMLError):
    """A batch file value beyond the bounds (:data:`MAX_YAML_NODES`, :data:`MAX_YAML_SCALAR`)."""


def _bounded_load(text: str) -> Any:
    """Parse ``text`` with :class:`_Loader` after checking the size of the document once its
    aliases are expanded (a "billion laughs" of nested aliases is refused before it is built)
    and the length of every scalar."""
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        sizes: dict[int, int] = {}

        def size(n: yaml.Node) -> int:
            if id(n) in sizes:
                return sizes[id(n)]
            sizes[id(n)] = 1  # a recursive alias counts once (the loader refuses it later)
            if isinstance(n, yaml.ScalarNode):
                if len(n.value) > MAX_YAML_SCALAR:
                    raise _TooLarge(problem=f"a value of {len(n.value)} characters is not an option (at most "
                                    f"{MAX_YAML_SCALAR}); shorten it", problem_mark=n.start_mark)
                total = 1
            elif isinstance(n, yaml.MappingNode):
                total = 1 + sum(size(k) + size(v) for k, v in n.value)
            else:
                total = 1 + sum(size(c) for c in n.value)
            if total > MAX_YAML_NODES:
                raise _TooLarge(problem=f"this value expands to more than {MAX_YAML_NODES} values (nested "
                                "aliases?); write the options out without aliases", problem_mark=n.start_mark)
            sizes[id(n)] = total
            return total

        size(node)
        return loader.construct_document(node)
    finally:
        loader.dispose()


def _line(node: Any, key: Any = None) -> int:
    if isinstance(node, _LineDict) and key in node.lines:
        return node.lines[key]
    if isinstance(node, _LineList) and isinstance(key, int) and key < len(node.lines):
        return node.lines[key]
    return getattr(node, "line", 1)


# --------------------------------------------------------------------------- batch model
@dataclass(frozen=True)
class ScanJob:
    """One scan of a batch, with its options resolved and validated.

    Attributes
    ----------
    name : str
        Output name (the scan's stem unless given): its folder is ``output/NAME``.
    scan : Path
        Absolute path of the scan.
    out_dir : Path
        Absolute output folder of this scan.
    options : RunOptions
        The options of every stage.
    line : int
        Line of the batch file entry that produced this job.
    """

    name: str
    scan: Path
    out_dir: Path
    options: RunOptions
    line: int = 0

    def options_json(self) -> dict[str, dict]:
        """The options of every stage as JSON-ready dicts."""
        return {stage: options_dict(getattr(self.options, stage)) for stage in STAGE_OPTIONS}


@dataclass(frozen=True)
class Batch:
    """A validated batch file.

    Attributes
    ----------
    path : Path
        The batch file.
    output : Path
        Absolute output folder; each scan gets ``output/NAME``.
    jobs : tuple of ScanJob
        The scans in file order (glob matches sorted by path).
    """

    path: Path
    output: Path
    jobs: tuple


def option_stages() -> dict[str, list[tuple[str, Any]]]:
    """Every stage option name to the (stage, type hint) pairs that use it."""
    out: dict[str, list[tuple[str, Any]]] = {}
    for stage, cls in STAGE_OPTIONS.items():
        for name, tp in option_types(cls).items():
            out.setdefault(name, []).append((stage, tp))
    return out


def load_batch(path: str | os.PathLike, *, output: str | os.PathLike | None = None) -> Batch:
    """Read and validate a batch file completely.

    Parameters
    ----------
    path : path-like
        The YAML batch file. Relative paths inside it are relative to its folder.
    output : path-like, optional
        Output folder overriding the file's ``output:`` (relative to the working directory).

    Returns
    -------
    Batch

    Raises
    ------
    BatchFileError
        Listing every problem found, one ``FILE:LINE: what is wrong; the fix`` line each.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise BatchFileError([f"{path}: cannot read the batch file: {reason}; "
                              "give the path of a readable YAML file"]) from None
    if len(text) > MAX_BATCH_BYTES:
        raise BatchFileError([f"{path}: the batch file is {len(text)} characters long, over "
                              f"{MAX_BATCH_BYTES}; list the scans with patterns (path: scans/*.obj)"])
    try:
        data = _bounded_load(text)
    except _TooLarge as exc:
        raise BatchFileError([f"{path}:{exc.problem_mark.line + 1}: {exc.problem}"]) from None
    except RecursionError:
        raise BatchFileError([f"{path}: values nested too deeply to be options; write a flat list of "
                              "scans and options"]) from None
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark else 1
        what = " ".join(str(exc.problem or exc.context or "syntax error").split())
        raise BatchFileError([f"{path}:{line}: invalid YAML: {what}; check the indentation, "
                              "colons and quotes on this line and the one above"]) from None
    except yaml.YAMLError as exc:
        raise BatchFileError([f"{path}:1: invalid YAML: {' '.join(str(exc).split())}; "
                              "fix the syntax"]) from None
    return _Validator(path, output).batch(data)


class _Validator:
    """Collects every problem of a batch file, then builds the jobs."""

    def __init__(self, path: Path, output: str | os.PathLike | None):
        self.path = path
        self.base = path.resolve().parent
        self.output_override = output
        self.found: dict[str, int] = {}  # each problem's text and line, as found
        self.options = option_stages()

    @property
    def problems(self) -> list[str]:
        """The problems found, in line order."""
        return sorted(self.found, key=self.found.get)

    def problem(self, line: int, message: str) -> None:
        # (once: e.g. a bad default seen again by every scan entry)
        self.found.setdefault(f"{self.path}:{line}: {message}", line)

    def batch(self, data: Any) -> Batch:
        if not isinstance(data, _LineDict):
            got = "an empty file" if data is None else f"a {type(data).__name__}"
            self.problem(_line(data), f"the batch file must be a mapping with keys "
                         f"{', '.join(TOP_KEYS)}, got {got}; see the example in docs/cli.md")
            raise BatchFileError(self.problems)
        for key in data:
            if key not in TOP_KEYS:
                self.unknown_key(data, key, TOP_KEYS, "top-level key", options_hint=True)
        output = self.output_dir(data)
        defaults = self.mapping(data, "defaults")
        self.check_option_keys(defaults, where="defaults")
        base_options = self.stage_values(defaults)
        jobs = self.scans(data, output, base_options)
        if self.problems:
            raise BatchFileError(self.problems)
        return Batch(path=self.path, output=output, jobs=tuple(jobs))

    def unknown_key(self, node: _LineDict, key: Any, valid: tuple[str, ...], what: str,
                    *, where: str = "", options_hint: bool = False) -> None:
        close = difflib.get_close_matches(str(key), list(valid), n=1, cutoff=0.6)
        if close:
            fix = f"did you mean '{close[0]}'?"
        elif options_hint and str(key) in self.options:
            fix = "stage options go under 'defaults:' or under a scan entry"
        else:
            fix = f"valid keys: {', '.join(valid)}"
        self.problem(_line(node, key), f"unknown {what} '{key}'{where}; {fix}")

    def output_dir(self, data: _LineDict) -> Path:
        if self.output_override is not None:
            return Path(self.output_override).resolve()
        value = data.get("output")
        if "output" not in data:
            self.problem(data.line, "missing 'output:' (the folder for the results); "
                         "add e.g. 'output: results/' or pass --output")
            return self.base / "results"
        if not isinstance(value, str) or not value.strip():
            self.problem(_line(data, "output"), f"'output' must be a folder path (text), got "
                         f"{_shown(value)}; write e.g. 'output: results/'")
            return self.base / "results"
        out = (self.base / Path(value).expanduser()).resolve()
        if out.exists() and not out.is_dir():
            self.problem(_line(data, "output"), f"'output' {out} is a file, not a folder; "
                         "choose a folder path")
        return out

    def mapping(self, data: _LineDict, key: str) -> _LineDict:
        value = data.get(key)
        if value is None:
            empty = _LineDict()
            empty.line, empty.lines = _line(data, key), {}
            return empty
        if not isinstance(value, _LineDict):
            self.problem(_line(data, key), f"'{key}' must be a mapping of option: value, got "
                         f"{_shown(value)}; write e.g. '{key}: {{proxy: auto, px_per_mm: 4}}'")
            empty = _LineDict()
            empty.line, empty.lines = _line(data, key), {}
            return empty
        return value

    def check_option_keys(self, node: _LineDict, *, where: str, extra: tuple[str, ...] = ()) -> None:
        for key in node:
            if key in extra:
                continue
            if key not in self.options:
                self.unknown_key(node, key, tuple(sorted(self.options)) + extra, "option",
                                 where=f" in {where}")

    def stage_values(self, node: _LineDict) -> dict[str, dict[str, tuple[Any, int]]]:
        """Stage -> option -> (coerced value, line) for the option keys of ``node``."""
        out: dict[str, dict[str, tuple[Any, int]]] = {}
        for key, value in node.items():
            for stage, tp in self.options.get(key, ()):
                try:
                    coerced = coerce_option(tp, value)
                except InvalidOptionError as exc:
                    self.problem(_line(node, key), f"'{key}' {exc}; fix the value")
                    break
                out.setdefault(stage, {})[key] = (coerced, _line(node, key))
        return out

    def build_options(self, values: dict[str, dict[str, tuple[Any, int]]], line: int) -> RunOptions | None:
        built = {}
        for stage, cls in STAGE_OPTIONS.items():
            given = values.get(stage, {})
            try:
                built[stage] = cls(**{k: v for k, (v, _) in given.items()})
            except (InvalidOptionError, TypeError, ValueError) as exc:
                message = " ".join(str(exc).split())
                self.problem(_culprit_line(cls, given, message, line), message)
                return None
        return RunOptions(**built)

    def scans(self, data: _LineDict, output: Path, base: dict) -> list[ScanJob]:
        scans = data.get("scans")
        if "scans" not in data:
            self.problem(data.line, "missing 'scans:' (the list of scans); add e.g. "
                         "'scans: [{path: scans/vase.obj}]'")
            return []
        if not isinstance(scans, _LineList) or not scans:
            self.problem(_line(data, "scans"), f"'scans' must be a non-empty list of entries "
                         f"'- path: FILE-OR-PATTERN', got {_shown(scans)}")
            return []
        jobs: list[ScanJob] = []
        seen_files: dict[Path, int] = {}
        repeats: dict[Path, list[int]] = {}  # lines listing a scan again
        patterns: set[int] = set()  # lines of entries whose path is a pattern
        seen_names: dict[str, tuple[Path, int]] = {}
        base_lines = {stage: dict(v) for stage, v in base.items()}
        built_defaults = None
        for index, entry in enumerate(scans):
            line = _line(scans, index)
            if isinstance(entry, str):
                entry_map = _LineDict(path=entry)
                entry_map.line, entry_map.lines = line, {"path": line}
                entry = entry_map
            if not isinstance(entry, _LineDict):
                self.problem(line, f"a scan entry must be '- path: FILE-OR-PATTERN' (plus options), "
                             f"got {_shown(entry)}")
                continue
            self.check_option_keys(entry, where="scan entry", extra=SCAN_KEYS)
            files = self.scan_files(entry, output)
            if isinstance(entry.get("path"), str) and glob.escape(entry["path"]) != entry["path"]:
                patterns.add(line)
            name = entry.get("name")
            if name is not None:
                try:
                    check_output_name(name, what="'name'")
                except InvalidOptionError as exc:
                    self.problem(_line(entry, "name"), str(exc))
                    name = None
            if name is not None and len(files) > 1:
                self.problem(_line(entry, "name"), f"'name' needs a path matching one file, but "
                             f"the pattern matches {len(files)}; remove 'name' or use one file per entry")
                name = None
            overrides = self.stage_values(entry)
            merged = {stage: {**base_lines.get(stage, {}), **overrides.get(stage, {})}
                      for stage in set(base_lines) | set(overrides)}
            if overrides:
                options = self.build_options(merged, line)
            else:
                if built_defaults is None:
                    built_defaults = self.build_options(merged, line) or {}
                options = built_defaults or None
            for scan in files:
                scan_name = name or scan.stem
                if name is None:
                    try:
                        check_output_name(scan_name, what=f"the name of {scan}")
                    except InvalidOptionError as exc:
                        self.problem(line, f"{exc} (with 'name:')")
                        continue
                if scan in seen_files:
                    repeats.setdefault(scan, []).append(line)
                    continue
                seen_files[scan] = line
                folder_key = scan_name.casefold()  # one folder on case-insensitive file systems
                if folder_key in seen_names:
                    other, other_line = seen_names[folder_key]
                    self.problem(line, f"{scan} and {other} (line {other_line}) would both write to "
                                 f"{output / scan_name}; give one of them its own entry with 'name:'")
                    continue
                seen_names[folder_key] = (scan, line)
                if options is not None:
                    jobs.append(ScanJob(name=scan_name, scan=scan, out_dir=output / scan_name,
                                        options=options, line=line))
        for scan, again in repeats.items():  # one line per scan, however often it is listed again
            first = seen_files[scan]
            shown = ", ".join(map(str, again[:5])) + (f" and {len(again) - 5} more" if len(again) > 5 else "")
            narrow = " (narrow the pattern)" if patterns & {first, *again} else ""
            self.problem(again[0], f"{scan}, listed on line {first}, is listed again on line{'s' * (len(again) > 1)} "
                         f"{shown}; list each scan once{narrow}")
        return jobs

    def scan_files(self, entry: _LineDict, output: Path) -> list[Path]:
        if "path" not in entry:
            self.problem(entry.line, "scan entry without 'path:'; add 'path: FILE-OR-PATTERN'")
            return []
        value = entry["path"]
        line = _line(entry, "path")
        if not isinstance(value, str) or not value.strip():
            self.problem(line, f"'path' must be a file path or glob pattern (text), got {_shown(value)}")
            return []
        pattern = str(self.base / Path(value).expanduser())
        if glob.escape(pattern) == pattern:
            scan = Path(pattern).resolve()
            if not scan.exists():
                self.problem(line, f"scan file {scan} does not exist; fix the path (relative "
                             f"paths are relative to {self.base})")
                return []
            if not scan.is_file():
                self.problem(line, f"{scan} is not a file; give a scan file or a pattern like "
                             f"'{value.rstrip('/')}/*.obj'")
                return []
            if scan.suffix.lower() not in SCAN_EXTENSIONS:
                self.problem(line, f"{scan} is not a scan format potflat reads "
                             f"({' '.join(SCAN_EXTENSIONS)}); convert it or fix the path")
                return []
            return [scan]
        fixed = Path(*[part for part in itertools.takewhile(lambda q: glob.escape(q) == q, Path(pattern).parts)])
        if not fixed.resolve().is_relative_to(self.base) or ".." in Path(pattern).parts[len(fixed.parts):]:
            self.problem(line, f"pattern '{value}' reaches outside the batch file's folder {self.base}; "
                         "move the batch file up or name the files one by one")
            return []
        found = []
        for p in glob.iglob(pattern, recursive=True):
            if len(found) == MAX_GLOB_MATCHES:
                self.problem(line, f"pattern '{value}' matches more than {MAX_GLOB_MATCHES} files; "
                             "narrow it (e.g. scans/*.obj)")
                return []
            found.append(Path(p).resolve())
        found = [p for p in sorted(set(found)) if p.is_file() and p.is_relative_to(self.base)
                 and not p.is_relative_to(output)]
        matches = [p for p in found if p.suffix.lower() in SCAN_EXTENSIONS]
        if not matches:
            what = (f"{len(found)} files but no scan ({' '.join(SCAN_EXTENSIONS)})" if found
                    else f"no file (looked in {self.base})")
            self.problem(line, f"pattern '{value}' matches {what}; fix the pattern or the folder")
        return matches


def _culprit_line(cls: type, given: dict[str, tuple[Any, int]], message: str, line: int) -> int:
    """The line of the option that made ``cls(**given)`` fail with ``message``: of the options
    without which it builds, the first one refused even alone (a bad value), else the first
    (two options that do not go together), else the first the message names, else ``line``
    (the scan entry's)."""
    def builds(keys) -> bool:
        try:
            cls(**{k: given[k][0] for k in keys})
        except (InvalidOptionError, TypeError, ValueError):
            return False
        return True

    fixes = [k for k in given if builds([other for other in given if other != k])]
    bad = [k for k in fixes if not builds([k])] or fixes
    named = [k for k in given if any(form in message for form in (k, k.replace("_", "-"), k.replace("_", " ")))]
    return given[(bad or named)[0]][1] if bad or named else line


def _shown(value: Any) -> str:
    if value is None:
        return "nothing"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    return repr(value)



_Loader.add_constructor("tag:yaml.org,2002:map", _construct_map)
_Loader.add_constructor("tag:yaml.org,2002:seq", _construct_seq)
