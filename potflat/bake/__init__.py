"""Stage 3, bake: true-scale images of the painting and of the flattening's distortion.

``from potflat.bake import bake, BakeOptions``. Modules: :mod:`.render` (options, the
renderer and the file stage), :mod:`.annotate` (colour scales, legends, scale bars, the
comparison sheet), :mod:`._kernels` (the rasteriser and texture sampler, Numba). Names are
imported on first use.
"""
from potflat._lazy import lazy_exports

__getattr__ = lazy_exports(__name__, dict.fromkeys(
    ("MAP_NAMES", "BakeOptions", "BakeResult", "bake", "run_bake_stage"), ".render"))
__all__ = ["MAP_NAMES", "BakeOptions", "BakeResult", "bake", "run_bake_stage"]
