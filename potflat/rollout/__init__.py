"""Stage 1, rollout: axis, painted wall, attachments, proxy, profile and the unrolling.

``from potflat.rollout import rollout, RolloutOptions``. Modules: :mod:`.options` (the
stage's options, light to import), :mod:`.axis` (axis fit), :mod:`.walls` (outer/inner
wall), :mod:`.attachments` (handles, spouts), :mod:`.proxy` (cylinder/cone/sphere fits and
developments), :mod:`.profile` (the vessel profile), :mod:`.unroll` (the rollout algorithm).
Names are imported on first use, so the options come without scipy.
"""
from potflat._lazy import lazy_exports

__getattr__ = lazy_exports(__name__, {"RolloutOptions": ".options", "RolloutResult": ".unroll", "rollout": ".unroll"})
__all__ = ["RolloutOptions", "RolloutResult", "rollout"]
