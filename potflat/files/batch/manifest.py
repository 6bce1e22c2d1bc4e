"""A scan folder's ``manifest.json``: written last, recording the hash of the scan's inputs,
its options and potflat's version, so a rerun skips scans whose manifest matches. The
manifest is compared, never followed: inputs come from the batch file only (the scan and the
files it and its options name)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from potflat import __version__
from potflat.files.batch.config import ScanJob
from potflat.files.provenance import file_sha256, options_hash
from potflat.io.scan import scan_inputs

#: File written last into each finished scan folder.
MANIFEST = "manifest.json"


# --------------------------------------------------------------------------- resume
def job_inputs(job: ScanJob) -> tuple[Path, ...]:
    """The files a scan's run reads, found from the batch file alone: the scan, the files it
    names (material libraries, textures, buffers: :func:`~potflat.io.scan.scan_inputs`) and
    the files its options name (an importance mask and the bake JSON it was painted over)."""
    named = (Path(p) for p in job.options.rollout.input_files())
    return (job.scan, *scan_inputs(job.scan), *(p.resolve() for p in named if p.is_file()))


def job_key(job: ScanJob) -> str:
    """Hash of what determines a scan's outputs: the bytes of every file of
    :func:`job_inputs`, the options and potflat's version."""
    import hashlib

    text = json.dumps({"inputs_sha256": [file_sha256(p) for p in job_inputs(job)],
                       "options": options_hash(job.options_json()), "potflat": __version__}, sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()


#: Largest manifest read (potflat's own are a few kilobytes).
MANIFEST_MAX_BYTES = 1 << 20


def read_manifest(out_dir: Path) -> dict | None:
    """The manifest of a finished scan folder, or ``None`` if absent, unreadable, a symbolic
    link or over :data:`MANIFEST_MAX_BYTES`."""
    import os

    try:
        fd = os.open(Path(out_dir) / MANIFEST, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
        with os.fdopen(fd, "rb") as fh:
            data = fh.read(MANIFEST_MAX_BYTES + 1)
        data = json.loads(data) if len(data) <= MANIFEST_MAX_BYTES else None
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def is_complete(job: ScanJob, key: str) -> dict | None:
    """The manifest if ``job``'s outputs are complete and made from the same inputs, else None.

    Complete means: the manifest's key equals ``key`` (:func:`job_key`: the inputs' bytes and
    the options, from the batch file) and every output it lists exists inside the scan's
    folder with the recorded size. Nothing else in the manifest is read: it names no file
    potflat reads.
    """

    manifest = read_manifest(job.out_dir)
    if manifest is None or manifest.get("key") != key or manifest.get("complete") is not True:
        return None
    outputs = manifest.get("outputs")
    if not isinstance(outputs, dict):
        return None
    for rel, size in outputs.items():
        target = output_inside(job.out_dir, rel)
        if target is None or not target.is_file() or target.stat().st_size != size:
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
