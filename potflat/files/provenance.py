"""Provenance recorded beside every output: versions, options, input hashes."""
from __future__ import annotations

import hashlib
import json
import os
import platform
import sys
from pathlib import Path
from typing import Any

import potflat


def file_sha256(path: str | os.PathLike, *, chunk: int = 1 << 20) -> str:
    """SHA-256 hex digest of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def options_hash(options: dict[str, Any]) -> str:
    """A stable hash of JSON-serialisable options (key order does not matter)."""
    text = json.dumps(options, sort_keys=True, default=str)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def versions() -> dict[str, str]:
    """Versions of potflat, Python and the numerical libraries that shape the result."""
    import numpy

    out = {"potflat": potflat.__version__, "python": sys.version.split()[0],
           "numpy": numpy.__version__, "platform": platform.platform()}
    for name in ("numba", "scipy", "trimesh", "cv2", "zlib_ng"):
        mod = sys.modules.get(name)
        if mod is not None:
            out[name] = getattr(mod, "__version__", "?")
    return out


def provenance(*, stage: str, inputs: list[str | os.PathLike], options: dict[str, Any]) -> dict[str, Any]:
    """The provenance block of a stage's JSON sidecar.

    Parameters
    ----------
    stage : str
        ``"rollout"``, ``"relax"`` or ``"bake"``.
    inputs : list of path-like
        Files the stage read; each is recorded with its SHA-256.
    options : dict
        The stage's options as given (JSON-serialisable).
    """
    return {
        "stage": stage,
        "inputs": [{"path": str(Path(p)), "sha256": file_sha256(p)} for p in inputs],
        "options": options,
        "versions": versions(),
    }
