"""Stage 3, bake: true-scale images of the painting and of the flattening's distortion.

``from potflat.bake import bake, BakeOptions``. Modules: :mod:`.options` (the stage's
options, light to import), :mod:`.render` (the renderer and its strip API, :func:`bake`),
:mod:`.compose` (the images composed strip by strip: painting, maps, overlay, scale layer),
:mod:`.annotate` (colour scales, legends, scale bars, the comparison sheet),
:mod:`._kernels` (Numba). Names are imported on first use.
"""
from potflat._lazy import lazy_exports

__getattr__ = lazy_exports(__name__, {**dict.fromkeys(("MAP_NAMES", "BakeOptions"), ".options"),
                                      **dict.fromkeys(("BakeResult", "bake"), ".compose")})
__all__ = ["MAP_NAMES", "BakeOptions", "BakeResult", "bake"]
