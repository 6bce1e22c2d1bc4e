"""The one place where Numba JIT options are chosen.

Use these decorators instead of calling :func:`numba.njit` with options elsewhere:

* :data:`leaf` - serial kernels, cached on disk.
* :data:`parallel` - kernels using ``prange``; cached (safe in current Numba).

``fastmath`` is off everywhere: solver loops must not produce NaN or depend on
reassociation (see umap #1228). Results must be bit-for-bit deterministic run to run,
so parallel kernels only write to per-iteration slots (gather, never scatter ``+=``).
"""
from __future__ import annotations

import numba

leaf = numba.njit(cache=True, nogil=True, fastmath=False)
parallel = numba.njit(cache=True, nogil=True, parallel=True, fastmath=False)
prange = numba.prange

__all__ = ["leaf", "parallel", "prange"]
