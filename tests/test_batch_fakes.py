"""Fake stages for pipeline and batch tests.

They follow the stages' contract (frozen kw_only options dataclasses validating themselves,
file stages writing ``NAME.rollout.ply``, ``NAME.relaxed.ply``, ``NAME.png``... with a
provenance block and returning the file layer's typed results) and are fast and
deterministic, so the batch machinery is tested apart from the numerics.
``install(monkeypatch)`` puts them in place of the real ones; the tests of this file check them.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
import types
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import pytest

from potflat.errors import InvalidInputError, InvalidOptionError
from potflat.files import options as file_options
from potflat.files import pipeline
from potflat.files.bake_stage import BakeFiles
from potflat.files.provenance import provenance
from potflat.files.relax_stage import RelaxFiles
from potflat.files.rollout_stage import RolloutFiles
from potflat.io.atomic import write_bytes_atomic, write_json_atomic
from potflat.mesh.distortion import ZoneFigures, ZoneSummary
from potflat.types import RolloutMarks

MAPS = ("stress", "area", "anisotropy")


@dataclass(frozen=True, kw_only=True)
class RolloutOptions:
    """Fake rollout options.

    Attributes
    ----------
    units : str
        Length unit of the scan.
    proxy : str
        Proxy surface.
    axis : tuple of 6 floats or None
        Axis point and direction.
    flip : bool
        Mirror the result.
    seam : float or None
        Seam angle in degrees.
    band : tuple of 2 floats or None
        Height band as fractions.
    """

    units: Literal["um", "mm", "cm", "m", "in"] = "mm"
    proxy: Literal["auto", "cylinder", "cone", "sphere", "ortho"] = "auto"
    axis: tuple[float, float, float, float, float, float] | None = None
    flip: bool = False
    seam: float | None = None
    band: tuple[float, float] | None = None

    def __post_init__(self):
        if self.band is not None and not 0 <= self.band[0] < self.band[1] <= 1:
            raise InvalidOptionError(f"band must be two fractions 0 <= low < high <= 1, got {self.band}")

    def input_files(self) -> tuple[str, ...]:
        return ()


@dataclass(frozen=True, kw_only=True)
class RelaxOptions:
    """Fake relax options."""

    preset: Literal["preview", "default", "archival", "paper"] = "default"
    tol: float = 1e-6
    max_iter: int = 10000
    threads: int | None = None
    simplify_mm: float | None = 0.0  # given: run_scan leaves it (it never reads the real default)

    def __post_init__(self):
        if self.max_iter < 1:
            raise InvalidOptionError(f"max_iter must be at least 1, got {self.max_iter}")


@dataclass(frozen=True, kw_only=True)
class BakeOptions:
    """Fake bake options."""

    px_per_mm: float = 10.0
    maps: tuple[str, ...] = MAPS
    sheet: bool = False

    def __post_init__(self):
        if not self.px_per_mm > 0:
            raise InvalidOptionError(f"px_per_mm must be positive, got {self.px_per_mm}")
        bad = [m for m in self.maps if m not in MAPS]
        if bad:
            raise InvalidOptionError(f"maps: unknown map {bad[0]!r}; use any of {', '.join(MAPS)}")


#: Scan names for which a fake stage misbehaves: name -> ("raise" | "exit" | "interrupt", stage).
SABOTAGE: dict[str, tuple[str, str]] = {}


def _digest(*parts: bytes) -> bytes:
    h = hashlib.sha256()
    for p in parts:
        h.update(p)
    return h.digest()


def _opts(options) -> bytes:
    return json.dumps(asdict(options), sort_keys=True).encode()


def _sabotage(name: str, stage: str) -> None:
    how, at = SABOTAGE.get(name, ("", ""))
    if at == stage and how == "raise":
        raise RuntimeError(f"{stage} exploded\nsecond line")
    if at == stage and how == "exit":
        os._exit(3)
    if at == stage and how == "interrupt":
        raise KeyboardInterrupt


def run_rollout_stage(scan_path, out_dir, options, *, name=None, check=None):
    scan, out = Path(scan_path), Path(out_dir)
    name = name or scan.stem
    data = scan.read_bytes()
    if not (data.startswith(b"v ") or data.startswith(b"ply\n") and b"end_header" in data):
        raise InvalidInputError(f"{scan}: not a readable mesh (truncated or corrupt); re-export the scan")
    _sabotage(name, "rollout")
    inputs = [scan] + [p for p in [scan.with_suffix(".png")] if p.exists()]
    texture = b"".join(p.read_bytes() for p in inputs[1:])
    ply = write_bytes_atomic(out / f"{name}.rollout.ply", _digest(data, texture, _opts(options)))
    summary = {"distortion": {"edge_rms": 0.2, "flipped": 0}, "cleaning": {"warnings": []},
               "provenance": provenance(stage="rollout", inputs=inputs, options=asdict(options))}
    js = write_json_atomic(out / f"{name}.rollout.json", summary)
    return RolloutFiles(paths={"ply": ply, "json": js}, record=summary, flat=None,
                        distortion=types.SimpleNamespace(**summary["distortion"]), marks=RolloutMarks())


def _zone(figures: dict) -> ZoneFigures:
    return ZoneFigures(area_fraction=figures["area_fraction"], faces=0, scale_median=1.0,
                       length_error_median_pct=figures["length_error_median_pct"],
                       length_error_p95_pct=figures["length_error_p95_pct"], distortion=None)


def run_relax_stage(rollout_ply, out_dir, options, *, name=None, rolled=None, check=None):
    src, out = Path(rollout_ply), Path(out_dir)
    name = name or src.name.split(".")[0]
    _sabotage(name, "relax")
    data = src.read_bytes()
    ply = write_bytes_atomic(out / f"{name}.relaxed.ply", _digest(data, _opts(options)))
    summary = {"distortion": {"edge_rms": round(0.01 + data[0] / 1e4, 6), "area_mean_abs_log": 0.02,
                              "anisotropy_p95": 1.1, "flipped": 0},
               "important_zone": {"area_fraction": 0.25, "length_error_median_pct": 1.0 + data[1] / 1e3,
                                  "length_error_p95_pct": 2.5},
               "rest": {"area_fraction": 0.75, "length_error_median_pct": 30.0, "length_error_p95_pct": 55.0},
               "outline_turning": {"rollout": 1.5, "relaxed": 1.6, "ratio": 1.6 / 1.5},
               "provenance": provenance(stage="relax", inputs=[src], options=asdict(options))}
    js = write_json_atomic(out / f"{name}.relaxed.json", summary)
    zone = ZoneSummary(important_zone=_zone(summary["important_zone"]), rest=_zone(summary["rest"]), lengths="")
    return RelaxFiles(paths={"ply": ply, "json": js}, record=summary, flat=None,
                      distortion=types.SimpleNamespace(**summary["distortion"]), zone=zone, reference=None)


def run_bake_stage(relaxed_ply, out_dir, options, *, name=None, relaxed=None, marks=None, flat=None, base=None):
    src, out = Path(relaxed_ply), Path(out_dir)
    name = name or src.name.split(".")[0]
    _sabotage(name, "bake")
    data = src.read_bytes()
    paths = {"png": write_bytes_atomic(out / f"{name}.png", _digest(data, _opts(options)))}
    for m in options.maps:
        paths[m] = write_bytes_atomic(out / f"{name}.{m}.png", _digest(data, m.encode()))
    summary = {"provenance": provenance(stage="bake", inputs=[src], options=asdict(options))}
    paths["json"] = write_json_atomic(out / f"{name}.bake.json", summary)
    return BakeFiles(paths=paths, record=summary)


def install(monkeypatch) -> None:
    """Run these fakes instead of the stages (their options and file stages)."""
    this = sys.modules[__name__]
    for stage, cls, run in (("rollout", RolloutOptions, run_rollout_stage),
                            ("relax", RelaxOptions, run_relax_stage),
                            ("bake", BakeOptions, run_bake_stage)):
        monkeypatch.setitem(file_options.STAGE_OPTIONS, stage, cls)
        monkeypatch.setattr(pipeline, run.__name__, run)
    monkeypatch.setattr(this, "SABOTAGE", {})


def write_scan(path: Path, seed: int = 0) -> Path:
    """A tiny OBJ (a square pyramid) whose bytes depend on ``seed``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(f"v 0 0 {seed}\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0.5 1\n"
                    "f 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\n")
    return path


def test_fake_options_validate():
    with pytest.raises(InvalidOptionError, match="band"):
        RolloutOptions(band=(0.6, 0.2))
    with pytest.raises(InvalidOptionError, match="max_iter"):
        RelaxOptions(max_iter=0)
    with pytest.raises(InvalidOptionError, match="px_per_mm"):
        BakeOptions(px_per_mm=0)


def test_fake_rollout_rejects_garbage(tmp_path):
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelem")
    with pytest.raises(InvalidInputError, match="corrupt"):
        run_rollout_stage(bad, tmp_path / "out", RolloutOptions())
