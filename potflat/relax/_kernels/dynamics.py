"""The paper's damped spring dynamics: one semi-implicit Euler step (``preset paper``).

Arrays in, arrays out, no I/O; deterministic for any thread count.
"""
from __future__ import annotations

import math

import numpy as np

from potflat._jit import parallel, prange



@parallel
def dynamics_step(x, v, ptr, nbr, rst, k, relative, r_floor, friction, dt, x_out, v_out, e_spring):
    """One semi-implicit Euler step of the paper's damped spring system (mass 1).

    ``v <- (1 - c_i) v + dt F``, ``x <- x + dt v`` with friction ``c_i`` applied per step.

    Parameters
    ----------
    x, v : (n, 2) float64
        Positions and velocities now.
    ptr, nbr, rst, k, relative, r_floor
        Springs as in :func:`energy_gradient`.
    friction : (n,) float64
    dt : float
    x_out, v_out : (n, 2) float64
        Output: the state after the step.
    e_spring : (n,) float64
        Output: each vertex's share of the spring energy at ``x`` (before the step).
    """
    n = x.shape[0]
    for i in prange(n):
        fx = 0.0
        fy = 0.0
        es = 0.0
        xi = x[i, 0]
        yi = x[i, 1]
        for p in range(np.uint64(ptr[i]), np.uint64(ptr[i + 1])):
            j = np.uint32(nbr[p])  # (unsigned: no negative-index wraparound at each read)
            dx = xi - x[j, 0]
            dy = yi - x[j, 1]
            ln = math.sqrt(dx * dx + dy * dy)
            r = rst[p]
            c = k
            if relative:
                rr = max(r, r_floor)
                c = k / (rr * rr)
            dl = ln - r
            es += 0.25 * c * dl * dl
            if ln > 0.0:
                f = c * dl / ln
                fx -= f * dx
                fy -= f * dy
        keep = 1.0 - friction[i]
        vx = keep * v[i, 0] + dt * fx
        vy = keep * v[i, 1] + dt * fy
        v_out[i, 0] = vx
        v_out[i, 1] = vy
        x_out[i, 0] = xi + dt * vx
        x_out[i, 1] = yi + dt * vy
        e_spring[i] = es
