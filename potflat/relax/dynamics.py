"""The paper's damped dynamics: semi-implicit Euler with friction per step (``preset paper``)."""
from __future__ import annotations

import math
import time

import numpy as np

from potflat.errors import FoldedResultError
from potflat.relax._kernels.dynamics import dynamics_step
from potflat.relax.control import RunControl, relative_change
from potflat.relax.energy import SpringSystem
from potflat.relax.parameters import ENERGY, SOLVER, RelaxPreset
from potflat.relax.result import LevelRecord


def paper_dynamics(sp: SpringSystem, x: np.ndarray, settings: RelaxPreset,
                   run: RunControl) -> tuple[np.ndarray, bool, LevelRecord]:
    """The paper's dynamics from ``x`` (n, 2): mass 1, friction ``settings.friction_inside``
    inside and ``settings.friction_boundary`` on the boundary applied per step, the time step
    from a bound of the spring graph's largest eigenvalue; until the relative energy change
    over :attr:`SOLVER.window_dynamics` steps falls below ``settings.tol`` or ``run`` stops it.

    Returns the layout, whether it converged and the level's record.

    Raises
    ------
    FoldedResultError
        When the energy is no longer finite (diverged).
    """
    friction = np.where(sp.boundary, settings.friction_boundary, settings.friction_inside).astype(np.float64)
    lam = sp.laplacian_bound()
    dt = 1.9 / math.sqrt(lam) if lam > 0 else 1.0
    v = np.zeros_like(x)
    xo, vo = np.empty_like(x), np.empty_like(x)
    es = np.empty(sp.n)
    t0 = time.perf_counter()
    run.level = "dynamics"
    hist: list[float] = []
    converged = False
    it = 0
    while True:
        dynamics_step(x, v, sp.ptr, sp.nbr, sp.rst, sp.k, sp.relative, ENERGY.length_floor, friction, dt, xo, vo, es)
        x, xo, v, vo = xo, x, vo, v
        it += 1
        e = float(np.sum(es))  # energy before this step
        hist.append(e)
        if not np.isfinite(e):  # NaN or overflowing positions make the energy non-finite
            raise FoldedResultError(f"the paper dynamics diverged at iteration {it} (the spring energy is no longer "
                                    "finite); nothing written: use a fold-free preset (--preset standard; a "
                                    "smaller --stiffness does not help: the step scales with it)")
        if run.record(e):
            break
        if it % SOLVER.window_dynamics == 0 and relative_change(hist, SOLVER.window_dynamics) < settings.tol:
            converged = True
            break
    record = LevelRecord(level="dynamics", iterations=it, energy=sp.spring_energy(x),
                         seconds=time.perf_counter() - t0, dt=dt)
    return x, converged, record
