"""The stage files' names: ``NAME`` and a suffix per stage, and how ``NAME`` is found again
from a stage file (light: no numpy)."""
from __future__ import annotations

from pathlib import Path

#: The stage file each stage after the first reads: ``NAME`` and this suffix.
STAGE_INPUT = {"relax": ".rollout.ply", "bake": ".relaxed.ply"}


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
    return flat_ply.with_name(f"{stem}.base.ply")
