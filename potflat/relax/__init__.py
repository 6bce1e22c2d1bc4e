"""Stage 2, relax: fold-free elastic relaxation of a rollout.

``from potflat.relax import relax, RelaxOptions``. Modules: :mod:`.options` (the stage's
options, light to import), :mod:`.parameters` (the typed presets and the energy's, the
solvers' and the coarse copies' constants), :mod:`.multilevel` (:func:`relax`: the schedule
of coarse copies and solves), :mod:`.energy` (the spring energy and its barriers),
:mod:`.lbfgs` (the fold-free solver), :mod:`.dynamics` (the paper's dynamics),
:mod:`.start` (untangled, fold-free starts), :mod:`.local` (a followed start's extreme faces
relaxed with the rest fixed), :mod:`.control` (iteration control),
:mod:`.result` (what a relaxation gives), :mod:`.hierarchy` (the multilevel preconditioner),
:mod:`.simplify` (coarse copies), :mod:`._kernels` (Numba kernels). Names are imported on
first use.
"""
from potflat._lazy import lazy_exports

__getattr__ = lazy_exports(__name__, {"RelaxOptions": ".options", "relax": ".multilevel",
                                      **dict.fromkeys(("RelaxResult", "LevelRecord", "RelaxTimings"), ".result"),
                                      **dict.fromkeys(("PRESETS", "RelaxPreset"), ".parameters")})
__all__ = ["PRESETS", "LevelRecord", "RelaxOptions", "RelaxPreset", "RelaxResult", "RelaxTimings", "relax"]
