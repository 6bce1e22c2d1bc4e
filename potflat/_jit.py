"""The one place where Numba JIT options are chosen.

Use these decorators instead of calling :func:`numba.njit` with options elsewhere:

* :data:`leaf` - serial kernels, cached on disk.
* :data:`parallel` - kernels using ``prange``; cached (safe in current Numba).

``fastmath`` is off everywhere: solver loops must not produce NaN or depend on
reassociation (see umap #1228). Results must be bit-for-bit deterministic run to run,
so parallel kernels only write to per-iteration slots (gather, never scatter ``+=``).

Hot loops index with unsigned integers (``np.uint32(faces[t, 0])``, ``range(np.uint64(lo),
np.uint64(hi))``): Numba wraps a negative signed index at every read (Python semantics),
which costs a compare and a select per read and keeps LLVM from vectorising a loop over
contiguous entries (relax at 2.5M vertices: the energy and gradient 0.74-0.85x, the fused
L-BFGS passes 0.6-0.8x, results bit-identical). Only for indexing: NumPy's rules make an
unsigned and a signed integer combine into a float.

Importing potflat sets nothing process-wide. Numba's thread pool here is OpenMP's, which
busy-waits between parallel regions unless ``OMP_WAIT_POLICY=PASSIVE`` is in the environment
before the first parallel kernel runs: the solvers run many short parallel regions per
iteration, and busy-waiting made the relax solver up to 20x slower on a machine shared with
other jobs (docs/performance.md). The ``potflat`` command sets it for its own process
(:mod:`potflat_cli._process`); an application calling the library sets it itself.
"""
from __future__ import annotations

import contextlib

import numba

leaf = numba.njit(cache=True, nogil=True, fastmath=False)
parallel = numba.njit(cache=True, nogil=True, parallel=True, fastmath=False)
prange = numba.prange


@contextlib.contextmanager
def numba_threads(n: int | None):
    """Run the block with at most ``n`` Numba threads (restored afterwards, also on error); None: unchanged."""
    if n is None:
        yield
        return
    old = numba.get_num_threads()
    numba.set_num_threads(max(1, min(int(n), numba.config.NUMBA_NUM_THREADS)))
    try:
        yield
    finally:
        numba.set_num_threads(old)


def worker_threads() -> int:
    """Threads a library call outside Numba may use (scipy's ``workers=``): the Numba thread
    count in force, so :func:`numba_threads` (``--threads``) limits those calls too."""
    return numba.get_num_threads()


def kernels_cached() -> bool:
    """Whether the kernels were compiled and cached by an earlier run of this potflat with this
    Numba (else the first call of each compiles it: a few minutes in all, worth telling the user).

    Read from the spring kernels' cache index files (in the package's ``__pycache__`` folders,
    or under ``NUMBA_CACHE_DIR``): an index counts when this version of Numba wrote it (the
    first item pickled in it) for the source as it is now: its stamp, which Numba checks before
    loading, is the source's SHA-256 (or, for a Numba that stamps by time, its modification
    time and size), so a reinstall or checkout that rewrites an unchanged source keeps it.
    """
    import hashlib
    import pickle
    from pathlib import Path

    package = Path(__file__).resolve().parent
    place = Path(numba.config.CACHE_DIR) if numba.config.CACHE_DIR else package
    source = package / "relax" / "_kernels" / "springs.py"
    try:
        st = source.stat()
        fresh = (hashlib.sha256(source.read_bytes()).digest(), (st.st_mtime, st.st_size))
        for index in (place.rglob("springs.*.nbi") if place.is_dir() else ()):
            with open(index, "rb") as f:
                if pickle.load(f) != numba.__version__:
                    continue
                stamp = pickle.loads(f.read())[0]
            if any(stamp == s for s in fresh):
                return True
    except (OSError, pickle.UnpicklingError, EOFError, ValueError, TypeError, IndexError):
        return True  # cannot tell: say nothing
    return False


__all__ = ["kernels_cached", "leaf", "numba_threads", "parallel", "prange", "worker_threads"]
