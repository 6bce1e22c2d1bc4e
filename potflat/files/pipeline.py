"""Run one scan through all three stages: rollout -> relax -> bake, each stage's file
stage writing its outputs as it goes and handing its result to the next in memory."""
from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from potflat.bake.options import BakeOptions
from potflat.errors import InvalidOptionError
from potflat.files.bake_stage import BakeFiles, run_bake_stage
from potflat.files.options import RunOptions, resolve_options
from potflat.files.relax_stage import RelaxFiles, run_relax_stage
from potflat.files.rollout_stage import RolloutFiles, run_rollout_stage
from potflat.files.names import STAGES_FROM
from potflat.files.outputs import superseding
from potflat.io.atomic import check_output_name, write_json_atomic
from potflat.io.scan import check_scan_file, scan_inputs
from potflat.mesh.distortion import bounds
from potflat.raster.render import image_size
from potflat.types import FlatMesh

#: The distortion figures a batch summary reports (keys of DistortionSummary).
FIGURES: tuple[str, ...] = ("edge_rms", "area_mean_abs_log", "anisotropy_p95", "flipped")
#: ... and the painted zone's and the plain surface's: the share of the surface that is painted,
#: and how far lengths read off the image are off there and on the plain surface (median and
#: 95th percentile, %): column name to (:class:`~potflat.mesh.distortion.ZoneSummary` field,
#: :class:`~potflat.mesh.distortion.ZoneFigures` field).
ZONE_FIGURES: dict[str, tuple[str, str]] = {
    "painted_area_fraction": ("important_zone", "area_fraction"),
    "painted_length_error_median_pct": ("important_zone", "length_error_median_pct"),
    "painted_length_error_p95_pct": ("important_zone", "length_error_p95_pct"),
    "plain_length_error_median_pct": ("rest", "length_error_median_pct"),
    "plain_length_error_p95_pct": ("rest", "length_error_p95_pct"),
}


@dataclass(frozen=True)
class StageSeconds:
    """Wall seconds of each stage of a run, and of the whole run."""

    rollout: float
    relax: float
    bake: float
    total: float


@dataclass(frozen=True, eq=False)
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
    rollout : RolloutFiles
    relax : RelaxFiles
        (without its :attr:`~RelaxFiles.reference`, which only the bake needed)
    bake : BakeFiles
    seconds : StageSeconds
    """

    name: str
    scan: Path
    out_dir: Path
    rollout: RolloutFiles
    relax: RelaxFiles
    bake: BakeFiles
    seconds: StageSeconds

    @property
    def paths(self) -> dict[str, Path]:
        """Every file written, keyed ``"<stage>.<role>"`` (e.g. ``"bake.png"``)."""
        return {f"{stage}.{role}": Path(p) for stage, files in (("rollout", self.rollout), ("relax", self.relax),
                                                                ("bake", self.bake))
                for role, p in files.paths.items()}

    @property
    def figures(self) -> dict[str, Any]:
        """Distortion figures of the final flattening (:data:`FIGURES`)."""
        return {k: getattr(self.relax.distortion, k) for k in FIGURES}

    @property
    def zone_figures(self) -> dict[str, Any]:
        """The painted zone's and the plain surface's figures (:data:`ZONE_FIGURES`; without a
        painted zone the whole surface is the painted zone and the plain surface's figures are
        None)."""
        out = {}
        for column, (zone, figure) in ZONE_FIGURES.items():
            value = getattr(getattr(self.relax.zone, zone), figure)
            out[column] = value if np.isfinite(value) else None
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


def _preview_at_image_resolution(options: RunOptions) -> RunOptions:
    """A relax preset that relaxes a coarse copy (``preview``) does so at 2 pixels of the image
    it is baked into, unless ``simplify_mm`` was given."""
    if options.relax.simplify_mm is not None:  # given
        return options
    if options.relax.resolved().simplify_mm:
        return dataclasses.replace(options, relax=dataclasses.replace(options.relax,
                                                                      simplify_mm=2.0 / options.bake.resolution))
    return options


def _image_check(bake: BakeOptions, scan: Path) -> Callable[[FlatMesh], None]:
    """A check of a flattening: would the baked image be of a sane size? Run on the rollout's
    before the rollout writes anything, so an absurd resolution stops the run before any file
    exists, and on the relaxed one (its extent is the image's, up to 1.6 times the rollout's
    area) before the relax stage writes: :func:`run_scan` then removes the rollout's files too.
    The message names the scan."""
    def check(flat: FlatMesh) -> None:
        used = np.zeros(len(flat.uv), bool)
        used[flat.mesh.faces.ravel()] = True
        if used.any():
            lo, hi = bounds(flat.uv[used])
            try:
                image_size((hi - lo) * flat.mesh.mm_per_unit, bake.resolution, bake.max_megapixels)
            except InvalidOptionError as exc:
                raise InvalidOptionError(f"{scan}: {exc}") from None
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
        From the stage that failed. The outputs in ``out_dir`` stay one consistent set
        (:func:`potflat.files.outputs.superseding`): an earlier run's are restored, or, with
        none, the stages this run finished are kept.
    """
    scan = Path(scan_path)
    out = Path(out_dir)
    name = check_output_name(name or scan.stem, what="name" if name else f"the name of {scan}")
    check_scan_file(scan)
    options = _preview_at_image_resolution(resolve_options(rollout=rollout, relax=relax, bake=bake))
    _check_painting_name_is_free(out, name)
    say = progress if progress is not None else (lambda stage: None)
    start = time.perf_counter()
    inputs = (scan, *scan_inputs(scan), *options.rollout.input_files())
    with superseding(out, name, STAGES_FROM["rollout"], keep=lambda: inputs) as run:
        say("rollout")
        t = time.perf_counter()
        image_check = _image_check(options.bake, scan)
        rolled = run_rollout_stage(scan, out, options.rollout, name=name, check=image_check)
        run.done("rollout")
        t_rollout, t = time.perf_counter() - t, time.perf_counter()
        say("relax")
        try:
            relaxed = run_relax_stage(rolled.paths["ply"], out, options.relax, name=name, rolled=rolled,
                                      check=image_check)
        except InvalidOptionError:  # the image size: this run's options, not the scan, so nothing of it stays
            run.finished.clear()
            raise
        run.done("relax")
        t_relax, t = time.perf_counter() - t, time.perf_counter()
        say("bake")
        # NAME.png is written before NAME.bake.json: mark it as potflat's own until the bake is done
        marker = write_json_atomic(partial_marker(out, name), {"potflat": "incomplete", "scan": str(scan)})
        try:
            baked = run_bake_stage(relaxed.paths["ply"], out, options.bake, name=name, relaxed=relaxed,
                                   marks=rolled.marks, base=rolled.base)
            run.done("bake")
        finally:  # (a failed or interrupted bake's images are removed with it)
            marker.unlink(missing_ok=True)
        t_bake = time.perf_counter() - t
    seconds = StageSeconds(rollout=t_rollout, relax=t_relax, bake=t_bake, total=time.perf_counter() - start)
    return ScanResult(name=name, scan=scan, out_dir=out, rollout=rolled,
                      relax=dataclasses.replace(relaxed, reference=None), bake=baked, seconds=seconds)
