"""potflat: true-to-scale flat images of painted pottery from textured 3D scans.

Stages, each a plain function with keyword-only options:

* :func:`potflat.load_scan` - read and clean a scan (OBJ, PLY, STL, OFF, GLB/glTF).
* :func:`potflat.rollout` - find the axis, fit a proxy, cut a seam and unroll.
* :func:`potflat.relax` - fold-free elastic relaxation of the rollout.
* :func:`potflat.bake` - texture and distortion maps as true-scale images.

Heavy modules (Numba kernels) are imported on first use, so ``import potflat`` is fast.
"""
from __future__ import annotations

import importlib

__version__ = "0.1.0"

_LAZY = {
    "load_scan": "potflat.io.scan",
    "rollout": "potflat.rollout",
    "RolloutResult": "potflat.rollout",
    "relax": "potflat.relax",
    "RelaxResult": "potflat.relax",
    "bake": "potflat.bake",
    "BakeResult": "potflat.bake",
    "Mesh": "potflat.types",
    "FlatMesh": "potflat.types",
    "PotflatError": "potflat.errors",
    "read_flat_ply": "potflat.io.stage",
    "write_flat_ply": "potflat.io.stage",
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'potflat' has no attribute {name!r}")
