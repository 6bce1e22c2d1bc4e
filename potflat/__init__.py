"""potflat: true-to-scale flat images of painted pottery from textured 3D scans.

Stages, each a plain function with keyword-only options, in the module of its name
(``from potflat.rollout import rollout``):

* :func:`potflat.load_scan` - read and clean a scan (OBJ, PLY, STL, OFF, GLB/glTF).
* :func:`potflat.rollout.rollout` - find the axis, fit a proxy, cut a seam and unroll.
* :func:`potflat.relax.relax` - fold-free elastic relaxation of the rollout.
* :func:`potflat.bake.bake` - texture and distortion maps as true-scale images.
* :func:`potflat.run_scan` - all three, from a scan file to images.

The stage functions are not re-exported at the top level: ``potflat.rollout`` is the
module once it is imported, and a name that changes meaning with import order is a trap.

Heavy modules (Numba kernels) are imported on first use, so ``import potflat`` is fast.
"""
from __future__ import annotations

import importlib

__version__ = "0.1.0"

_LAZY = {
    "load_scan": "potflat.io.scan",
    "LoadedScan": "potflat.io.scan",
    "CleaningReport": "potflat.mesh.cleaning",
    "clean_mesh": "potflat.mesh.cleaning",
    "estimate_axis": "potflat.rollout.axis",
    "RolloutOptions": "potflat.rollout",
    "RolloutResult": "potflat.rollout",
    "run_rollout_stage": "potflat.files.rollout_stage",
    "RelaxOptions": "potflat.relax",
    "RelaxResult": "potflat.relax",
    "run_relax_stage": "potflat.files.relax_stage",
    "BakeOptions": "potflat.bake",
    "BakeResult": "potflat.bake.compose",
    "run_bake_stage": "potflat.files.bake_stage",
    "run_scan": "potflat.files.pipeline",
    "ScanResult": "potflat.files.pipeline",
    "load_batch": "potflat.files.batch.config",
    "run_batch": "potflat.files.batch.execution",
    "BatchFileError": "potflat.files.batch.config",
    "select_wall": "potflat.rollout.walls",
    "detect_attachments": "potflat.rollout.attachments",
    "vessel_profile": "potflat.rollout.profile",
    "write_profile_csv": "potflat.rollout.profile",
    "write_profile_svg": "potflat.rollout.profile",
    "Mesh": "potflat.types",
    "FlatMesh": "potflat.types",
    "RolloutMarks": "potflat.types",
    "PotflatError": "potflat.errors",
    "read_flat_ply": "potflat.io.flat_ply",
    "write_flat_ply": "potflat.io.flat_ply",
}

__all__ = ["__version__", *_LAZY]


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'potflat' has no attribute {name!r}")
