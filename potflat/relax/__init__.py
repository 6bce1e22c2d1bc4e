"""Stage 2, relax: fold-free elastic relaxation of a rollout.

``from potflat.relax import relax, RelaxOptions``. Modules: :mod:`.solver` (options, the
spring energy's minimisation), :mod:`.parameters` (the typed presets and the energy's,
the solvers' and the coarse copies' constants), :mod:`.hierarchy` (the multilevel preconditioner),
:mod:`.simplify` (coarse copies), :mod:`._kernels` (Numba kernels); the file stage
``run_relax_stage`` lives in :mod:`potflat.stages.relax_stage`. Names are imported on
first use.
"""
from potflat._lazy import lazy_exports

__getattr__ = lazy_exports(__name__, {**dict.fromkeys(("RelaxOptions", "RelaxResult", "relax"), ".solver"),
                                      **dict.fromkeys(("PRESETS", "RelaxPreset"), ".parameters"),
                                      "run_relax_stage": "potflat.stages.relax_stage"})
__all__ = ["PRESETS", "RelaxOptions", "RelaxPreset", "RelaxResult", "relax", "run_relax_stage"]
