"""The stage files' names: ``NAME`` and a suffix per stage, and how ``NAME`` is found again
from a stage file (light: no numpy)."""
from __future__ import annotations

import os
from pathlib import Path

from potflat.bake.options import MAP_NAMES

#: The stage file each stage after the first reads: ``NAME`` and this suffix.
STAGE_INPUT = {"relax": ".rollout.ply", "bake": ".relaxed.ply"}
#: The files the bake writes for a painting ``NAME`` (and for its base's disc, ``NAME.base``).
_BAKE_OUTPUTS = (".png", *(f".{m}.png" for m in (*MAP_NAMES, "overlay")), ".scale-layer.png", ".attachments.png",
                 ".scalebar.png", ".tif", ".position.tif", ".flat.obj", ".flat.mtl", ".sheet.png", ".bake.json",
                 ".plate.svg", ".plate.pdf", ".plate.png", ".relief.tif", ".relief.png", ".curvature.png",
                 ".relief-overlay.png")
#: The files each stage writes: ``NAME`` and these suffixes, and those of :data:`STAGE_PATTERNS`.
#: The rollout's base left out (``NAME.base.ply``) is baked with the painting (``NAME.base.png``...).
STAGE_OUTPUTS = {
    "rollout": (".rollout.ply", ".rollout.json", ".profile.csv", ".profile.svg", ".base.ply"),
    "relax": (".relaxed.ply", ".relaxed.json"),
    "bake": (*_BAKE_OUTPUTS, *(f".base{suffix}" for suffix in _BAKE_OUTPUTS)),
}
#: The files each stage writes with names it makes: ``NAME``, then one of these beginnings and
#: endings: the rollout's copy of the scan's texture (``NAME.texture.EXT``), the raking lights
#: (``NAME.raking-AZ.png``, ``NAME.base.raking-AZ.png``).
STAGE_PATTERNS = {"rollout": ((".texture.", ""),), "relax": (),
                  "bake": ((".raking-", ".png"), (".base.raking-", ".png"))}
#: The suffix of the base's disc's ``NAME`` (``NAME.base``): baked inside the bake of ``NAME``.
BASE_NAME_SUFFIX = ".base"
#: Each stage and the stages made from its outputs: a new run of the stage supersedes theirs.
STAGES_FROM = {"rollout": ("rollout", "relax", "bake"), "relax": ("relax", "bake"), "bake": ("bake",)}


def stage_outputs(folder: Path, name: str, stages: tuple[str, ...]) -> list[Path]:
    """The files in ``folder`` named as ``stages`` name their outputs for ``name`` (whoever
    wrote them), sorted; symbolic links count as files (they are never followed)."""
    names = {f"{name}{suffix}" for stage in stages for suffix in STAGE_OUTPUTS[stage]}
    patterns = [(f"{name}{begin}", end) for stage in stages for begin, end in STAGE_PATTERNS[stage]]
    try:
        entries = list(os.scandir(folder))
    except OSError:
        return []
    return sorted(Path(e.path) for e in entries
                  if (e.name in names or any(e.name.startswith(b) and e.name.endswith(x) for b, x in patterns))
                  and (e.is_symlink() or e.is_file()))


def stage_name(path: Path) -> str:
    """Output NAME for a stage file: ``X.relaxed.ply`` -> ``X``; ``X.rollout.ply`` -> ``X.rollout``."""
    stem = path.name[: -len(path.suffix)] if path.suffix else path.name
    return stem.removesuffix(".relaxed")


def relax_name(rollout_ply: Path) -> str:
    """Default NAME of a relax run: ``X.rollout.ply`` -> ``X`` (the name without ``.ply`` and
    ``.rollout``)."""
    stem = rollout_ply.name
    for suffix in (".ply", ".rollout"):
        stem = stem.removesuffix(suffix)
    return stem


def rollout_json_beside(flat_ply: Path) -> Path:
    """The rollout's sidecar ``X.rollout.json`` beside a stage file ``X.rollout.ply`` or
    ``X.relaxed.ply``."""
    stem = flat_ply.name.removesuffix(".ply").removesuffix(".relaxed").removesuffix(".rollout")
    return flat_ply.with_name(f"{stem}.rollout.json")


def base_ply_beside(flat_ply: Path) -> Path:
    """The base's orthographic view ``X.base.ply`` beside a stage file ``X.rollout.ply`` or
    ``X.relaxed.ply`` (written by the rollout when it leaves the base out)."""
    stem = flat_ply.name.removesuffix(".ply").removesuffix(".relaxed").removesuffix(".rollout")
    return flat_ply.with_name(f"{stem}{BASE_NAME_SUFFIX}.ply")
