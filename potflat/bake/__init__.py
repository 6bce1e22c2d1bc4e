"""Stage 3, bake: true-scale images of the painting and of the flattening's distortion.

``from potflat.bake import bake, BakeOptions``. Modules: :mod:`.render` (options, the
renderer and its strip API), :mod:`.annotate` (colour scales, legends, scale bars, the
comparison sheet), :mod:`.plate` (the archaeological plate), :mod:`._kernels` (the
rasteriser and texture sampler, Numba); the file stage ``run_bake_stage`` lives in
:mod:`potflat.stages.bake_stage`. Names are imported on first use.
"""
from potflat._lazy import lazy_exports

__getattr__ = lazy_exports(__name__, {**dict.fromkeys(("MAP_NAMES", "BakeOptions", "BakeResult", "bake"), ".render"),
                                      "run_bake_stage": "potflat.stages.bake_stage"})
__all__ = ["MAP_NAMES", "BakeOptions", "BakeResult", "bake", "run_bake_stage"]
