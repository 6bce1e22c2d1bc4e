"""Batches: many scans through all stages, validated up front, resumable, in parallel.

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

import contextlib
import csv
import dataclasses
import difflib
import glob
import io
import itertools
import json
import os
import re
import stat
import time
import traceback
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import yaml

from potflat._jit import numba_threads
from potflat.errors import InvalidInputError, InvalidOptionError, PotflatError
from potflat.io.atomic import check_output_name
from potflat.stages.pipeline import FIGURES, ZONE_FIGURES

#: Top-level keys of a batch file.
TOP_KEYS = ("output", "defaults", "scans")
#: Keys of a scan entry besides the stage options.
SCAN_KEYS = ("path", "name")
#: File written last into each finished scan folder.
MANIFEST = "manifest.json"
#: Statuses of a scan in a batch summary.
STATUSES = ("done", "skipped", "failed", "interrupted", "cancelled")
#: Start method of local worker processes: fresh interpreters, so no Numba thread pool or
#: lock is inherited from the parent (fork is unsafe once threads exist).
START_METHOD = "spawn"
#: How long to try reaching a Dask scheduler before giving up.
CONNECT_TIMEOUT = "20s"
#: Largest batch file read (characters), values once YAML aliases are expanded, and characters
#: of one value: a batch file lists scans and options, never data.
MAX_BATCH_BYTES = 4_000_000
MAX_YAML_NODES = 1_000_000
MAX_YAML_SCALAR = 4096
#: Most files a ``path:`` pattern may match (a pattern over a whole disk is a mistake).
MAX_GLOB_MATCHES = 100_000
#: Columns of ``summary.csv``.
CSV_COLUMNS = ("name", "status", "seconds", *FIGURES, *ZONE_FIGURES, "error", "scan", "output")


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


_Loader.add_constructor("tag:yaml.org,2002:map", _construct_map)
_Loader.add_constructor("tag:yaml.org,2002:seq", _construct_seq)


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
    options : dict of str to options dataclass
        ``"rollout"``, ``"relax"``, ``"bake"`` to the stage options.
    line : int
        Line of the batch file entry that produced this job.
    """

    name: str
    scan: Path
    out_dir: Path
    options: dict
    line: int = 0

    def options_json(self) -> dict[str, dict]:
        """The options of every stage as JSON-ready dicts."""
        from potflat.stages.pipeline import options_dict

        return {stage: options_dict(opts) for stage, opts in self.options.items()}


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
    from potflat.stages.pipeline import STAGES, option_types, options_class

    out: dict[str, list[tuple[str, Any]]] = {}
    for stage in STAGES:
        for name, tp in option_types(options_class(stage)).items():
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
        self.problems: list[str] = []
        self.options = option_stages()

    def problem(self, line: int, message: str) -> None:
        text = f"{self.path}:{line}: {message}"
        if text not in self.problems:  # e.g. a bad default seen again by every scan entry
            self.problems.append(text)

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
        from potflat.stages.pipeline import coerce_option

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

    def build_options(self, values: dict[str, dict[str, tuple[Any, int]]], line: int) -> dict | None:
        from potflat.stages.pipeline import STAGES, options_class

        built = {}
        for stage in STAGES:
            cls = options_class(stage)
            given = values.get(stage, {})
            try:
                built[stage] = cls(**{k: v for k, (v, _) in given.items()})
            except (InvalidOptionError, TypeError, ValueError) as exc:
                message = " ".join(str(exc).split())
                at = next((ln for k, (_, ln) in given.items() if k in message
                           or k.replace("_", "-") in message), line)
                self.problem(at, message)
                return None
        return built

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
                    self.problem(line, f"{scan} is already listed on line {seen_files[scan]}; "
                                 "list each scan once (narrow the pattern)")
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
        return jobs

    def scan_files(self, entry: _LineDict, output: Path) -> list[Path]:
        from potflat.io.scan import SCAN_EXTENSIONS

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


def _shown(value: Any) -> str:
    if value is None:
        return "nothing"
    if isinstance(value, dict):
        return "a mapping"
    if isinstance(value, list):
        return "a list"
    return repr(value)


# --------------------------------------------------------------------------- resume
def job_key(job: ScanJob) -> str:
    """Hash of what determines a scan's outputs: scan bytes, options, potflat version."""
    import hashlib

    from potflat import __version__
    from potflat.stages.provenance import file_sha256, options_hash

    text = json.dumps({"scan_sha256": file_sha256(job.scan), "options": options_hash(job.options_json()),
                       "potflat": __version__}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


def read_manifest(out_dir: Path) -> dict | None:
    """The manifest of a finished scan folder, or ``None`` if absent or unreadable."""
    try:
        data = json.loads((Path(out_dir) / MANIFEST).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def is_complete(job: ScanJob, key: str) -> dict | None:
    """The manifest if ``job``'s outputs are complete and made from the same inputs, else None.

    Complete means: the manifest's key equals ``key``, every output it lists exists with
    the recorded size, and every other input the stages read (e.g. the texture) still has
    the recorded SHA-256.
    """
    from potflat.stages.provenance import file_sha256

    manifest = read_manifest(job.out_dir)
    if manifest is None or manifest.get("key") != key or manifest.get("complete") is not True:
        return None
    outputs, inputs = manifest.get("outputs"), manifest.get("inputs", [])
    if not isinstance(outputs, dict) or not isinstance(inputs, list):
        return None
    for rel, size in outputs.items():
        target = output_inside(job.out_dir, rel)
        if target is None or not target.is_file() or target.stat().st_size != size:
            return None
    for item in inputs:
        try:
            source = Path(item["path"])
            if not stat.S_ISREG(source.stat().st_mode) or file_sha256(source) != item["sha256"]:
                return None  # never hash a device or a pipe (/dev/zero would never end)
        except (OSError, KeyError, TypeError, ValueError, RuntimeError):
            return None
    return manifest


def output_inside(out_dir: Path, rel: Any) -> Path | None:
    """``out_dir / rel`` if ``rel`` (read from a manifest) names a path inside ``out_dir``, else None.

    Nothing read from an output folder may direct potflat to a path outside it: absolute
    paths, ``..`` and symbolic links leading out are refused.
    """
    if not isinstance(rel, str) or not rel or "\0" in rel or Path(rel).is_absolute():
        return None
    base = Path(out_dir).resolve()
    try:
        target = (base / rel).resolve()
    except (OSError, RuntimeError):
        return None
    return target if target != base and target.is_relative_to(base) else None


def _external_inputs(result, job: ScanJob) -> list[dict]:
    """Files the stages read besides the scan and their own outputs (e.g. textures)."""
    found: dict[str, str] = {}

    def walk(node: Any) -> None:
        if isinstance(node, dict):
            inputs = node.get("inputs")
            if isinstance(inputs, list):
                for item in inputs:
                    if isinstance(item, dict) and "path" in item and "sha256" in item:
                        found[str(item["path"])] = str(item["sha256"])
            for value in node.values():
                walk(value)
        elif isinstance(node, list):
            for value in node:
                walk(value)

    for stage_output in result.stages.values():
        walk(stage_output.summary)
    out = []
    for name, digest in sorted(found.items()):
        p = Path(name).resolve()
        if p == job.scan or p.is_relative_to(job.out_dir.resolve()):
            continue
        out.append({"path": str(p), "sha256": digest})
    return out


# --------------------------------------------------------------------------- one scan
@dataclass(frozen=True)
class ScanReport:
    """The outcome of one scan in a batch (a row of the summary).

    Attributes
    ----------
    name : str
        Output name.
    scan : str
        Scan path.
    output : str
        Scan output folder.
    status : str
        ``done``, ``skipped`` (already complete), ``failed``, ``interrupted`` (stopped while it
        ran) or ``cancelled`` (the batch was interrupted before it started).
    seconds : float
        Wall time spent on this scan in this run.
    figures : dict
        Distortion figures of the relaxed result (:data:`potflat.stages.pipeline.FIGURES`), and
        of its painted zone and plain surface (:data:`potflat.stages.pipeline.ZONE_FIGURES`).
    error : str
        One-line error message for failed scans, else ``""``.
    """

    name: str
    scan: str
    output: str
    status: str
    seconds: float = 0.0
    figures: dict = dataclasses.field(default_factory=dict)
    error: str = ""

    def row(self) -> dict[str, Any]:
        """The report as a flat dict (the summary's columns)."""
        row = {"name": self.name, "status": self.status, "seconds": round(self.seconds, 3)}
        row.update({k: self.figures.get(k) for k in (*FIGURES, *ZONE_FIGURES)})
        row.update(error=self.error, scan=self.scan, output=self.output)
        return row


def one_line(exc: BaseException, *, limit: int = 400) -> str:
    """An exception as one line: the message of user errors, ``Type: message`` otherwise."""
    text = " ".join(re.sub(r"\x1b\[[0-9;]*[A-Za-z]", "", str(exc)).split())  # no colour codes
    if not isinstance(exc, PotflatError):
        text = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _report(job: ScanJob, status: str, seconds: float = 0.0, figures: dict | None = None,
            error: str = "") -> ScanReport:
    return ScanReport(name=job.name, scan=str(job.scan), output=str(job.out_dir), status=status,
                      seconds=seconds, figures=dict(figures or {}), error=error)


def run_job(job: ScanJob, key: str, *, threads: int | None = None) -> ScanReport:
    """Run one scan of a batch; never raises an ``Exception`` (failures become reports).

    The old manifest is first replaced by a partial one (``complete: false``, the marker of
    potflat's own unfinished outputs); the new one is written last, after every output, so an
    interrupted or failed scan is never taken as complete. Outputs that an earlier
    run wrote and this one did not (e.g. a map no longer asked for) are removed.
    ``error.log`` in the scan folder keeps the traceback of a failure.
    """
    from potflat import __version__
    from potflat.io.atomic import write_bytes_atomic, write_json_atomic
    from potflat.stages.pipeline import run_scan

    start = time.perf_counter()
    old = read_manifest(job.out_dir) or {}
    old_outputs = old.get("outputs") if isinstance(old.get("outputs"), dict) else {}
    try:
        # marker first: the folder holds potflat's own (partial) outputs until the final manifest
        write_json_atomic(job.out_dir / MANIFEST, {"complete": False, "name": job.name, "scan": str(job.scan),
                                                    "potflat": __version__, "outputs": old_outputs})
        with numba_threads(threads):
            result = run_scan(job.scan, job.out_dir, name=job.name, **job.options)
        outputs = {}
        for p in sorted(result.paths.values()):
            p = Path(p).resolve()
            rel = p.relative_to(job.out_dir.resolve()).as_posix()
            outputs[rel] = p.stat().st_size
        for rel in old_outputs:
            target = output_inside(job.out_dir, rel)
            if rel not in outputs and target is not None and rel != MANIFEST:
                with contextlib.suppress(OSError):
                    target.unlink()
        with contextlib.suppress(FileNotFoundError):
            (job.out_dir / "error.log").unlink()
        seconds = time.perf_counter() - start
        figures = {**result.figures, **result.zone_figures}
        write_json_atomic(job.out_dir / MANIFEST, {
            "complete": True, "key": key, "name": job.name, "scan": str(job.scan), "potflat": __version__,
            "options": job.options_json(), "outputs": outputs,
            "inputs": _external_inputs(result, job), "figures": figures,
            "seconds": round(seconds, 3)})
        return _report(job, "done", seconds, figures)
    except Exception as exc:  # noqa: BLE001 - failure isolation: any error is this scan's
        with contextlib.suppress(Exception):
            write_bytes_atomic(job.out_dir / "error.log", traceback.format_exc().encode())
        return _report(job, "failed", time.perf_counter() - start, error=one_line(exc))


def _run_job_on_dask_worker(job: ScanJob, key: str) -> ScanReport:
    """:func:`run_job` with Numba threads shared among the worker's task threads."""
    from distributed import get_worker

    worker = get_worker()
    nthreads = getattr(getattr(worker, "state", None), "nthreads", None) or worker.nthreads
    return run_job(job, key, threads=max(1, _cores() // max(1, nthreads)))


def _cores() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def default_workers(n_scans: int) -> int:
    """Default number of local worker processes: one per core, at most one per scan."""
    return max(1, min(_cores(), n_scans))


# --------------------------------------------------------------------------- summary
@dataclass(frozen=True)
class BatchSummary:
    """Every scan's outcome, in batch order.

    Attributes
    ----------
    batch : Path
        The batch file.
    output : Path
        The output folder (holding ``summary.csv`` and ``summary.json``).
    reports : tuple of ScanReport
    seconds : float
        Wall time of the whole batch.
    """

    batch: Path
    output: Path
    reports: tuple
    seconds: float

    @property
    def counts(self) -> dict[str, int]:
        """Number of scans per status."""
        return {s: sum(r.status == s for r in self.reports) for s in STATUSES}

    @property
    def exit_code(self) -> int:
        """0 if every scan is done or skipped, 1 if any failed, was interrupted or cancelled."""
        return 0 if all(r.status in ("done", "skipped") for r in self.reports) else 1

    def to_dict(self) -> dict[str, Any]:
        """The summary as JSON-ready data (the content of ``summary.json``)."""
        from potflat import __version__

        return {"batch": str(self.batch), "output": str(self.output), "potflat": __version__,
                "seconds": round(self.seconds, 3), "counts": self.counts,
                "scans": [r.row() for r in self.reports]}

    def write(self) -> tuple[Path, Path]:
        """Write ``summary.json`` and ``summary.csv`` into the output folder, atomically."""
        from potflat.io.atomic import write_bytes_atomic, write_json_atomic

        json_path = write_json_atomic(self.output / "summary.json", self.to_dict())
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=CSV_COLUMNS, lineterminator="\n")
        writer.writeheader()
        for report in self.reports:
            writer.writerow({k: ("" if v is None else v) for k, v in report.row().items()})
        csv_path = write_bytes_atomic(self.output / "summary.csv", buffer.getvalue().encode())
        return csv_path, json_path


# --------------------------------------------------------------------------- scheduling
def run_batch(batch: Batch, *, workers: int | None = None, scheduler: str | None = None,
              force: bool = False, on_result: Callable[[ScanReport], None] | None = None,
              on_plan: Callable[[int, int], None] | None = None) -> BatchSummary:
    """Run every scan of ``batch``; write and return the summary.

    Parameters
    ----------
    batch : Batch
        From :func:`load_batch`.
    workers : int, optional
        Local worker processes (default :func:`default_workers`); 1 runs in this process.
        Each worker gets ``cores // workers`` Numba threads. Ignored with ``scheduler``.
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:8786``) to run the scans on
        instead; needs ``pip install 'dask[distributed]'`` here and on the workers, and the
        scan and output paths must be the same on every worker (a shared file system).
    force : bool
        Redo every scan, even those whose outputs are complete.
    on_result : callable, optional
        Called with each :class:`ScanReport` as it arrives (skipped scans first).
    on_plan : callable, optional
        Called once with (scans to run, scans skipped) before any work.

    Returns
    -------
    BatchSummary
        Also written as ``summary.json``, ``summary.csv`` and the report ``index.html``
        (:mod:`potflat.stages.report`) in ``batch.output``, even when interrupted (unfinished scans are
        then ``interrupted``).
    """
    from potflat.io.atomic import output_lock

    start = time.perf_counter()
    wall_start = time.time()
    reports: dict[int, ScanReport] = {}
    todo: list[tuple[int, ScanJob, str]] = []
    emit = on_result or (lambda report: None)
    if workers is not None and workers < 1:
        raise InvalidOptionError(f"--workers must be at least 1, got {workers}")
    client = _dask_client(scheduler) if scheduler is not None else None  # fail before any work
    with output_lock(batch.output, what="potflat batch"):
        try:
            for index, job in enumerate(batch.jobs):
                try:
                    key = job_key(job)
                except OSError as exc:  # the scan vanished or became unreadable since validation
                    reports[index] = _report(job, "failed", error=f"{job.scan}: cannot read: "
                                             f"{exc.strerror or one_line(exc)}; check the file")
                    continue
                manifest = None if force else is_complete(job, key)
                if manifest is not None:
                    reports[index] = _report(job, "skipped", figures=manifest.get("figures"))
                else:
                    todo.append((index, job, key))
            if on_plan is not None:
                on_plan(len(todo), len(reports))
            for index in sorted(reports):
                emit(reports[index])

            def record(index: int, report: ScanReport) -> None:
                reports[index] = report
                emit(report)

            if client is not None:
                _run_dask(todo, client, record)
            else:
                n = workers or default_workers(len(todo))
                if n == 1 or len(todo) <= 1:
                    for index, job, key in todo:
                        record(index, run_job(job, key))
                else:
                    _run_pool(todo, n, record)
        finally:
            if client is not None:
                client.close()
            ordered = tuple(reports.get(i) or _unfinished(job, wall_start) for i, job in enumerate(batch.jobs))
            summary = BatchSummary(batch=batch.path, output=batch.output, reports=ordered,
                                   seconds=time.perf_counter() - start)
            with contextlib.suppress(PotflatError, OSError):
                summary.write()
                from potflat.stages.report import write_report

                write_report(summary)
    return summary


def _unfinished(job: ScanJob, since: float) -> ScanReport:
    """The report of a scan that has none when the batch stops: ``interrupted`` if it started
    (its partial manifest was written in this run, at wall time ``since`` or later), with the
    time it ran, else ``cancelled``."""
    manifest = job.out_dir / MANIFEST
    try:
        started = manifest.stat().st_mtime
    except OSError:
        started = None
    if started is not None and started >= since - 1.0 and (read_manifest(job.out_dir) or {}).get("complete") is False:
        return _report(job, "interrupted", max(0.0, time.time() - started),
                       error="interrupted while it ran; rerun the batch to redo it")
    return _report(job, "cancelled", error="not started: the batch was interrupted; rerun it to resume")


def _worker_start(parent: int) -> None:
    """Set-up of a local worker process: Ctrl-C is the parent's to handle (it ends the workers);
    SIGTERM interrupts the scan (its temporaries are removed) and ends the worker; the worker is
    sent SIGTERM when the parent dies, however it dies (Linux)."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _interrupt)
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    if os.getppid() != parent:  # the parent died before the line above
        os._exit(130)


def _interrupt(signum, frame) -> None:
    raise KeyboardInterrupt


def _run_job_in_worker(job: ScanJob, key: str, threads: int, heap_tuning: bool) -> ScanReport:
    """:func:`run_job` in a pool worker, with the heap tuning allowed when the batch's process
    allowed it (:func:`potflat._heap.heap_tuning`); an interrupt (SIGTERM from the parent) ends
    the worker once the scan's temporaries are removed, so it can never start a queued scan."""
    from potflat import _heap

    try:
        with _heap.heap_tuning() if heap_tuning else contextlib.nullcontext():
            return run_job(job, key, threads=threads)
    except KeyboardInterrupt:
        os._exit(130)


#: Seconds the workers get to remove their temporaries after the batch is interrupted.
WORKER_STOP_SECONDS = 10.0


def _run_pool(todo: list, workers: int, record: Callable[[int, ScanReport], None]) -> None:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed
    from concurrent.futures.process import BrokenProcessPool

    from potflat._heap import heap_tuning_allowed

    threads, heap_tuning = max(1, _cores() // workers), heap_tuning_allowed()
    context = multiprocessing.get_context(START_METHOD)
    crashed = []
    start = dict(mp_context=context, initializer=_worker_start, initargs=(os.getpid(),))
    with ProcessPoolExecutor(max_workers=workers, **start) as pool:
        try:
            futures = {pool.submit(_run_job_in_worker, job, key, threads, heap_tuning): (index, job, key)
                       for index, job, key in todo}
            for future in as_completed(futures):
                index, job, key = futures[future]
                try:
                    record(index, future.result())
                except BrokenProcessPool:
                    crashed.append((index, job, key))
        except BaseException:
            _stop_workers(pool)
            raise
    # A worker process died (killed, out of memory, crashed in native code): the pool is
    # broken and every unfinished scan is affected. Retry each alone in a fresh process, so
    # only the scan that kills its process again is reported failed.
    for index, job, key in sorted(crashed, key=lambda item: item[0]):
        with ProcessPoolExecutor(max_workers=1, **start) as pool:
            try:
                report = pool.submit(_run_job_in_worker, job, key, threads, heap_tuning).result()
            except BrokenProcessPool:
                report = _report(job, "failed", error=(
                    "the worker process died (killed, out of memory or crashed); run this scan "
                    f"alone with 'potflat run {job.scan}' to see why"))
            except BaseException:
                _stop_workers(pool)
                raise
        record(index, report)


def _stop_workers(pool) -> None:
    """Cancel the queued scans and end the workers of ``pool`` (SIGTERM: they remove their
    temporaries), killing those still alive after :data:`WORKER_STOP_SECONDS`."""
    from multiprocessing.connection import wait

    processes = list((getattr(pool, "_processes", None) or {}).values())  # shutdown() forgets them
    pool.shutdown(wait=False, cancel_futures=True)
    running = {}  # sentinel -> process: the sentinel is ready once the process has ended, whichever
    for proc in processes:  # thread reaps it (the executor's own thread may, so join can return early)
        with contextlib.suppress(Exception):
            proc.terminate()
            running[proc.sentinel] = proc
    deadline = time.monotonic() + WORKER_STOP_SECONDS
    with contextlib.suppress(OSError, ValueError):  # a sentinel closed meanwhile: kill what is left
        while running and time.monotonic() < deadline:
            for sentinel in wait(list(running), max(0.0, deadline - time.monotonic())):
                running.pop(sentinel)
    for proc in running.values():
        with contextlib.suppress(Exception):
            proc.kill()


def _dask_client(address: str):
    """A Dask client connected to the scheduler at ``address`` (clear errors otherwise)."""
    try:
        from distributed import Client
    except ImportError:
        raise InvalidOptionError("--scheduler needs Dask distributed, which is not installed; "
                                 "install it with: pip install 'dask[distributed]'") from None
    try:
        return Client(address, timeout=CONNECT_TIMEOUT, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise InvalidOptionError(f"cannot connect to the Dask scheduler at {address}: "
                                 f"{one_line(exc)}; check the address or start one with "
                                 "'dask scheduler'") from None


def _run_dask(todo: list, client, record: Callable[[int, ScanReport], None]) -> None:
    from distributed import as_completed

    futures = {client.submit(_run_job_on_dask_worker, job, key, pure=False,
                             key=f"potflat-{job.name}-{key[:12]}-{index}"): (index, job)
               for index, job, key in todo}
    try:
        for future in as_completed(futures, loop=client.loop):
            index, job = futures[future]
            try:
                report = future.result()
            except Exception as exc:  # noqa: BLE001 - a lost worker fails this scan only
                report = _report(job, "failed", error=f"on the Dask cluster: {one_line(exc)}")
            record(index, report)
    except BaseException:
        client.cancel(list(futures))
        raise
