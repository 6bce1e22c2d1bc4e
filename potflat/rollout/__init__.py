"""Stage 1, rollout: axis, painted wall, attachments, proxy, profile and the unrolling.

``from potflat.rollout import rollout, RolloutOptions``. Modules: :mod:`.axis` (axis fit),
:mod:`.walls` (outer/inner wall), :mod:`.attachments` (handles, spouts), :mod:`.proxy`
(cylinder/cone/sphere fits and developments), :mod:`.profile` (the vessel profile),
:mod:`.unroll` (options, the rollout algorithm and the file stage).
"""
from potflat.rollout.unroll import RolloutOptions, RolloutResult, rollout, run_rollout_stage

__all__ = ["RolloutOptions", "RolloutResult", "rollout", "run_rollout_stage"]
