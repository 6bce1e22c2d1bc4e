"""A scan folder's ``manifest.json``: written last, recording the hash of the scan's inputs,
its options and potflat's version, so a rerun skips scans whose manifest matches. The
manifest is compared, never followed: inputs come from the batch file only."""
from __future__ import annotations

import json
import stat
from pathlib import Path
from typing import Any

from potflat import __version__
from potflat.files.batch.config import ScanJob
from potflat.files.pipeline import ScanResult
from potflat.files.provenance import file_sha256, options_hash

#: File written last into each finished scan folder.
MANIFEST = "manifest.json"


# --------------------------------------------------------------------------- resume
def job_key(job: ScanJob) -> str:
    """Hash of what determines a scan's outputs: scan bytes, options, potflat version."""
    import hashlib

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


def external_inputs(result: ScanResult, job: ScanJob) -> list[dict]:
    """Files the stages read besides the scan and their own outputs (e.g. textures), from
    their records."""
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

    for files in (result.rollout, result.relax, result.bake):
        walk(files.record)
    out = []
    for name, digest in sorted(found.items()):
        p = Path(name).resolve()
        if p == job.scan or p.is_relative_to(job.out_dir.resolve()):
            continue
        out.append({"path": str(p), "sha256": digest})
    return out
