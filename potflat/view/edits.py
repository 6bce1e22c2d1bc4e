"""The page's edits as rollout options, and the rerun that applies them.

A run's options are read back from its sidecars (each stage records the options it was given
in ``provenance.options``). The page edits the rollout's: the seam through a point
(``seam_at``), an angle window (``seam`` and ``angles``), the overlap past 360 degrees
(``overlap``) and the painted zone (``importance mask`` with a mask PNG). A mask painted over
``NAME.png`` is kept as ``NAME.mask.png`` with the image it was painted over
(``NAME.mask.bake.json``, and the flattening that image was baked from,
``NAME.mask.relaxed.ply``): the rerun replaces ``NAME.png``, and the mask must keep meaning
the same place on the vessel for the command line that reproduces the rerun.

The rerun is :func:`potflat.files.pipeline.run_scan` (what ``potflat run`` calls) on the
scan the rollout read, into the run's folder under its name, with the edited rollout options
and the relax and bake options as recorded, so every stage after the rollout runs again and
the folder holds one consistent set. The options used are recorded as for every run, in each
stage's sidecar; the page's command line is made from them (:func:`command_line`).
"""
from __future__ import annotations

import dataclasses
import json
import shlex
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from potflat.errors import InvalidInputError, InvalidOptionError, PotflatError
from potflat.files.options import STAGE_OPTIONS, STAGES, option_types, options_dict
from potflat.io.atomic import atomic_path, write_json_atomic
from potflat.io.images import write_png

#: The sidecar that records each stage's options.
SIDECARS = {"rollout": ".rollout.json", "relax": ".relaxed.json", "bake": ".bake.json"}
#: Largest mask image accepted from the page (bytes of PNG).
MAX_MASK_BYTES = 256 << 20


def recorded_options(folder: Path, name: str) -> dict[str, Any]:
    """The options each stage of run ``NAME`` was given, as options dataclasses."""
    out = {}
    for stage in STAGES:
        path = folder / f"{name}{SIDECARS[stage]}"
        try:
            given = json.loads(path.read_text(encoding="utf-8"))["provenance"]["options"]
        except (OSError, ValueError, KeyError, TypeError):
            raise InvalidInputError(f"{path} does not record its options; run potflat on the scan again") from None
        cls = STAGE_OPTIONS[stage]
        fields = {f.name for f in dataclasses.fields(cls) if f.init}
        out[stage] = cls(**{k: v for k, v in given.items() if k in fields})
    return out


def scan_of(folder: Path, name: str) -> Path:
    """The scan the run's rollout read (``input`` in ``NAME.rollout.json``)."""
    path = folder / f"{name}.rollout.json"
    try:
        scan = Path(json.loads(path.read_text(encoding="utf-8"))["input"])
    except (OSError, ValueError, KeyError, TypeError):
        raise InvalidInputError(f"{path} does not name its scan; run potflat on the scan again") from None
    if not scan.is_file():
        raise InvalidInputError(f"the scan {scan} named by {path.name} is not there; put it back to rerun")
    return scan


@dataclasses.dataclass(frozen=True, kw_only=True)
class Edits:
    """What the page changed (None: unchanged).

    Attributes
    ----------
    seam_at : (3,) float or None
        The seam through this surface point (scan coordinates).
    window : (2,) float or None
        Angle window, degrees about the axis from its reference direction (the page's drag on
        the image), turned into ``seam`` and ``angles``.
    overlap : float or None
        Degrees repeated past 360.
    mask : bool
        A painted mask was saved (``NAME.mask.png``): importance ``mask``.
    clear_window : bool
        Back to an all-round rollout (no ``angles``).
    """

    seam_at: tuple[float, float, float] | None = None
    window: tuple[float, float] | None = None
    overlap: float | None = None
    mask: bool = False
    clear_window: bool = False

    @classmethod
    def from_json(cls, data: Any) -> "Edits":
        """Edits from the page's JSON, checked."""
        if not isinstance(data, dict):
            raise InvalidOptionError("edits must be a JSON object")
        unknown = set(data) - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise InvalidOptionError(f"unknown edit {sorted(unknown)[0]!r}")

        def numbers(key, n):
            value = data.get(key)
            if value is None:
                return None
            try:
                out = tuple(float(v) for v in value)
            except (TypeError, ValueError):
                raise InvalidOptionError(f"{key} must be {n} numbers") from None
            if len(out) != n or not np.isfinite(out).all():
                raise InvalidOptionError(f"{key} must be {n} finite numbers")
            return out

        overlap = data.get("overlap")
        if overlap is not None and not (isinstance(overlap, (int, float)) and np.isfinite(overlap)):
            raise InvalidOptionError("overlap must be a number of degrees")
        return cls(seam_at=numbers("seam_at", 3), window=numbers("window", 2),
                   overlap=None if overlap is None else float(overlap), mask=bool(data.get("mask", False)),
                   clear_window=bool(data.get("clear_window", False)))


def edited_options(folder: Path, name: str, edits: Edits, *, seam_deg: float | None,
                   landmark_deg: float | None) -> dict[str, Any]:
    """The run's recorded options with ``edits`` applied to the rollout's.

    Parameters
    ----------
    seam_deg : float or None
        The run's seam angle (``seam.angle_deg`` in ``NAME.rollout.json``): a window is measured
        from it when no seam point is set.
    landmark_deg : float or None
        The angle of the seam point (``seam_at``, edited or recorded) about the axis, from the
        reference direction: a window is measured from it when set.
    """
    options = recorded_options(folder, name)
    rollout = options["rollout"]
    change: dict[str, Any] = {}
    if edits.seam_at is not None:
        change.update(seam_at=edits.seam_at, landmark=None, seam=None)
    seam_at = change.get("seam_at", rollout.seam_at)
    if edits.clear_window:
        change.update(angles=None)
        if seam_at is None:
            change.update(seam=None)
    if edits.window is not None:
        a0, a1 = edits.window
        if seam_at is not None and landmark_deg is not None:  # angles from the seam point
            origin = landmark_deg
        else:  # the seam stays where it is; the window is measured from it
            origin = seam_deg if seam_deg is not None else 0.0
            change.update(seam=round(origin % 360.0, 6), landmark=None)
        lo = (a0 - origin + 180.0) % 360.0 - 180.0
        width = (a1 - a0) % 360.0 or 360.0
        change.update(angles=(round(lo, 6), round(lo + width, 6)), overlap=0.0)
    if edits.overlap is not None:
        change.update(overlap=round(edits.overlap, 6))
        if edits.overlap:
            change.update(angles=None)
    if edits.mask:
        mask, reference = mask_paths(folder, name)
        change.update(importance="mask", importance_mask=str(mask.resolve()),
                      importance_image=str(reference.resolve()), importance_band=None, importance_arc=None)
    try:
        options["rollout"] = dataclasses.replace(rollout, **change)
    except InvalidOptionError as exc:
        raise InvalidOptionError(f"these edits give invalid rollout options: {exc}") from None
    return options


def changed_stages(folder: Path, name: str, options: dict[str, Any]) -> list[str]:
    """The stages to run for ``options``: from the first whose options differ from the
    recorded ones to the last (none when nothing changed)."""
    recorded = recorded_options(folder, name)
    for i, stage in enumerate(STAGES):
        if options_dict(options[stage]) != options_dict(recorded[stage]):
            return list(STAGES[i:])
    return []


def command_line(scan: Path, out: Path, name: str, options: dict[str, Any]) -> str:
    """The ``potflat run`` command that gives the same outputs as ``options``."""
    words = ["potflat", "run", str(scan), "-o", str(out), "--name", name]
    seen = set()
    for stage in STAGES:
        cls = STAGE_OPTIONS[stage]
        defaults = options_dict(cls())
        given = options_dict(options[stage])
        for field in dataclasses.fields(cls):
            key = field.name
            if key in seen or not field.init:
                continue
            seen.add(key)
            value = given[key]
            if value == defaults[key] or value is None:
                continue
            flag = "--" + key.replace("_", "-")
            if isinstance(value, bool):
                words.append(flag if value else f"--no-{flag[2:]}")
            elif isinstance(value, list):
                variable = _variable_length(cls, key)
                words += [flag, ",".join(map(_number, value))] if variable else [flag, *map(_number, value)]
            else:
                words += [flag, _number(value)]
    return shlex.join(words)


def _variable_length(cls: type, key: str) -> bool:
    """Whether option ``key`` of ``cls`` is a variable-length tuple (a comma-separated list)."""
    import typing

    tp = option_types(cls)[key]
    for arg in (tp, *typing.get_args(tp)):
        inner = typing.get_args(arg)
        if typing.get_origin(arg) is tuple and len(inner) == 2 and inner[1] is Ellipsis:
            return True
    return False


def _number(value: Any) -> str:
    return repr(value) if isinstance(value, float) else str(value)


def mask_paths(folder: Path, name: str) -> tuple[Path, Path]:
    """``NAME.mask.png`` and the bake sidecar of the image it was painted over."""
    return folder / f"{name}.mask.png", folder / f"{name}.mask.bake.json"


def save_mask(folder: Path, name: str, png: bytes, size: tuple[int, int]) -> Path:
    """Keep a mask painted over ``NAME.png`` (white = painted), atomically, with the image it
    was painted over: ``NAME.mask.png``, ``NAME.mask.bake.json`` and ``NAME.mask.relaxed.ply``.

    Parameters
    ----------
    png : bytes
        The mask, a PNG of the image's size.
    size : (int, int)
        The image's width and height.
    """
    import io
    import shutil

    from PIL import Image

    if len(png) > MAX_MASK_BYTES:
        raise InvalidInputError(f"the mask is over {MAX_MASK_BYTES >> 20} MB; paint it over the image at its size")
    try:
        with Image.open(io.BytesIO(png)) as img:
            if img.format != "PNG":
                raise ValueError
            got = img.size
            mask = np.asarray(img.convert("L")) if got == tuple(size) else None
    except (OSError, ValueError, Image.DecompressionBombError):
        raise InvalidInputError("the mask is not a PNG image; paint it again") from None
    if mask is None:
        raise InvalidInputError(f"the mask is {got[0]} x {got[1]} px but {name}.png is {size[0]} x {size[1]}; "
                                "paint it over that image")
    mask_png, reference = mask_paths(folder, name)
    relaxed_copy = folder / f"{name}.mask.relaxed.ply"
    with atomic_path(relaxed_copy) as part:
        shutil.copyfile(folder / f"{name}.relaxed.ply", part)
    bake = json.loads((folder / f"{name}.bake.json").read_text(encoding="utf-8"))
    bake["provenance"]["inputs"][0]["path"] = str(relaxed_copy.resolve())
    write_json_atomic(reference, bake)
    write_png(mask_png, np.where(mask >= 128, 255, 0).astype(np.uint8), px_per_mm=bake.get("px_per_mm"))
    return mask_png


class Rerun:
    """A rerun of one scan in a background thread, and its state for the page.

    Attributes
    ----------
    state : str
        ``idle``, ``running``, ``done``, ``failed`` or ``unchanged``.
    message : str
        What happened, in one line.
    command : str
        The equivalent command line.
    seconds : float
    """

    def __init__(self):
        self.state, self.message, self.command, self.seconds = "idle", "", "", 0.0
        self.stages: list[str] = []
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def as_dict(self) -> dict:
        with self._lock:
            return {"state": self.state, "message": self.message, "command": self.command,
                    "seconds": round(self.seconds, 3), "stages": self.stages}

    def start(self, folder: Path, name: str, options: dict[str, Any], on_done) -> dict:
        """Run the changed stages of ``NAME`` with ``options`` in a thread; ``on_done()`` after
        the outputs are written (the page's views are then reloaded)."""
        with self._lock:
            if self.state == "running":
                raise InvalidOptionError("a rerun is already running; wait for it")
            scan = scan_of(folder, name)
            self.command = command_line(scan, folder, name, options)
            self.stages = changed_stages(folder, name, options)
            if not self.stages:
                self.state, self.message = "unchanged", "nothing changed: the outputs are those of these options"
                return {"state": self.state, "message": self.message, "command": self.command,
                        "seconds": 0.0, "stages": []}
            self.state, self.message, self.seconds = "running", f"running {', '.join(self.stages)}", 0.0
            self._thread = threading.Thread(target=self._run, args=(scan, folder, name, options, on_done),
                                            daemon=True, name="potflat-view-rerun")
            self._thread.start()
        return self.as_dict()

    def _run(self, scan: Path, folder: Path, name: str, options: dict[str, Any], on_done) -> None:
        from potflat.files.pipeline import run_scan  # here: the stages' modules load only for a rerun

        t = time.perf_counter()
        try:
            run_scan(scan, folder, name=name, **options)
            on_done()
            state, message = "done", f"{name}: {', '.join(self.stages)} done"
        except PotflatError as exc:
            state, message = "failed", str(exc)
        except Exception as exc:  # shown on the page in one line; the server goes on
            state, message = "failed", f"{type(exc).__name__}: {exc}"
        with self._lock:
            self.state, self.message, self.seconds = state, message, time.perf_counter() - t
