"""Geometric tolerances shared by every stage: one place, so a check means the same
everywhere (each value is the one its checks always used; outputs depend on them).

Not here: the guards against division by zero (``max(x, 1e-300)``), the relax solver's
parameters (:mod:`potflat.relax.parameters`) and thresholds that are choices about a
vessel, not about rounding (those are named constants in their modules).
"""

#: Relative slack of a comparison that must hold for values equal up to rounding (a ratio
#: reaching 1, a length fitting its limit, a pixel centre on the edge two faces share).
ROUNDING = 1e-9
#: A length, norm, determinant or area at most this (in the units of the comparison, or
#: relative to the scale it is compared with) counts as zero: a degenerate direction, face
#: or texture map.
DEGENERATE = 1e-12
