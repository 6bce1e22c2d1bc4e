"""Stage 2, relax: fold-free elastic relaxation of a rollout.

``from potflat.relax import relax, RelaxOptions``. Modules: :mod:`.solver` (options, the
spring energy's minimisation and the file stage), :mod:`.hierarchy` (the multilevel
preconditioner), :mod:`.simplify` (coarse copies), :mod:`._kernels` (Numba kernels).
Names are imported on first use.
"""
from potflat._lazy import lazy_exports

__getattr__ = lazy_exports(__name__, dict.fromkeys(
    ("PRESETS", "RelaxOptions", "RelaxResult", "relax", "run_relax_stage"), ".solver"))
__all__ = ["PRESETS", "RelaxOptions", "RelaxResult", "relax", "run_relax_stage"]
