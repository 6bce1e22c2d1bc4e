"""Freed memory kept for reuse while a stage makes many large temporaries (glibc's malloc only).

glibc serves every allocation above its mmap threshold (at most 32 MB) with a mapping of its
own and unmaps it on free, so each large NumPy or Numba temporary is a fresh mapping whose
pages the kernel zeroes on first touch. The rollout of a 3M-vertex scan makes thousands of
them (each pass over 6M faces is 50-150 MB): without this, 16-18 s of its 48-55 s go to the
kernel as system time (page faults).
:func:`reuse_freed_memory` has glibc serve the block's allocations from its heap instead and
keep what is freed there for the next one, then hands the unused memory back to the system
(``malloc_trim``) and restores glibc's settings. Elsewhere (macOS, Windows, musl) it does
nothing.
"""
from __future__ import annotations

import contextlib
import ctypes
import functools
import sys

#: ``mallopt`` parameters (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4
#: glibc's default number of mappings (``M_MMAP_MAX``), restored after the block.
DEFAULT_MMAP_MAX = 65536
#: The trim threshold restored after the block: the largest its dynamic rule reaches (twice
#: the 32 MB mmap threshold; any explicit setting turns that rule off).
DEFAULT_TRIM_THRESHOLD = 64 * 2**20
#: The trim threshold inside the block: free memory at the top of the heap is not handed back.
KEEP_TRIM_THRESHOLD = 2**31 - 1


@functools.cache
def _glibc():
    """The C library when it is glibc (it has ``mallopt`` and ``malloc_trim``), else None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None)
        libc.gnu_get_libc_version  # (only glibc has it)
    except (OSError, AttributeError):
        return None
    return libc


@contextlib.contextmanager
def reuse_freed_memory():
    """Run the block (or, as ``@reuse_freed_memory()``, the function) with large allocations
    served from glibc's heap and freed memory kept there for reuse; afterwards the settings
    are restored and the free memory is returned to the system (also on error). Blocks must
    not nest.

    The block's peak resident memory may grow by what the heap cannot reuse (at 3M vertices
    the rollout stage's 2886 MiB became 2981 MiB), so only a stage whose peak is not the
    run's should take it.
    """
    libc = _glibc()
    if libc is None or not libc.mallopt(M_MMAP_MAX, 0):
        yield
        return
    libc.mallopt(M_TRIM_THRESHOLD, KEEP_TRIM_THRESHOLD)
    try:
        yield
    finally:
        libc.mallopt(M_MMAP_MAX, DEFAULT_MMAP_MAX)
        libc.mallopt(M_TRIM_THRESHOLD, DEFAULT_TRIM_THRESHOLD)
        release_free_memory()


def release_free_memory() -> None:
    """Hand the heap's free memory back to the system (``malloc_trim``; glibc only): what a
    stage's setup freed amid live arrays stays resident otherwise, on top of the peak to come."""
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)
