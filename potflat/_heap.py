"""Freed memory kept for reuse while a stage makes many large temporaries (glibc's malloc only),
when the application asks for it.

glibc serves every allocation above its mmap threshold (at most 32 MB) with a mapping of its
own and unmaps it on free, so each large NumPy or Numba temporary is a fresh mapping whose
pages the kernel zeroes on first touch. The rollout of a 3M-vertex scan makes thousands of
them (each pass over 6M faces is 50-150 MB): without this, 16-18 s of its 48-55 s go to the
kernel as system time (page faults).
:func:`reuse_freed_memory` has glibc serve the block's allocations from its heap instead and
keep what is freed there for the next one, then hands the unused memory back to the system
(``malloc_trim``) and puts glibc's settings back.

glibc's settings belong to the whole process and glibc has no getter for them, so a library
call never changes them on its own: :func:`reuse_freed_memory` tunes the heap only inside
:func:`heap_tuning`, which an application enters to opt in (the ``potflat`` command does,
around its commands). The settings it puts back are those in force before potflat changed
any: glibc's defaults (the tuning is left out when the environment sets glibc's trim or mmap
parameters: the user's settings stand). One exception the C library imposes: ``mallopt``
turns glibc's dynamic mmap threshold off for the rest of the process, so afterwards the trim
threshold is the largest that rule gives it (:data:`DEFAULT_TRIM_THRESHOLD`) and the mmap
threshold stays where the rule had brought it. Elsewhere (macOS, Windows, musl) nothing is
tuned.
"""
from __future__ import annotations

import contextlib
import ctypes
import functools
import os
import sys
import threading

#: ``mallopt`` parameters (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4
#: glibc's default number of mappings (``M_MMAP_MAX``), put back after the last block.
DEFAULT_MMAP_MAX = 65536
#: The trim threshold put back after the last block: the largest that glibc's dynamic rule
#: gives it (twice the 32 MB mmap threshold; any ``mallopt`` turns that rule off).
DEFAULT_TRIM_THRESHOLD = 64 * 2**20
#: The trim threshold inside the blocks: free memory at the top of the heap is not handed back.
KEEP_TRIM_THRESHOLD = 2**31 - 1
#: Environment variables and ``GLIBC_TUNABLES`` names by which a user sets what the blocks
#: would change: when any is set, nothing is tuned.
USER_SETTINGS = ("MALLOC_TRIM_THRESHOLD_", "MALLOC_MMAP_MAX_", "MALLOC_MMAP_THRESHOLD_")
USER_TUNABLES = ("glibc.malloc.trim_threshold", "glibc.malloc.mmap_max", "glibc.malloc.mmap_threshold")

_lock = threading.Lock()
#: Open :func:`heap_tuning` blocks (the application's opt-in) and open blocks of
#: :func:`reuse_freed_memory` that tuned the heap; both under :data:`_lock`.
_allowed = 0
_tuned = 0


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


def user_settings() -> bool:
    """Whether the environment sets glibc's trim threshold, mmap threshold or mappings."""
    tunables = os.environ.get("GLIBC_TUNABLES", "")
    return any(name in os.environ for name in USER_SETTINGS) or any(name in tunables for name in USER_TUNABLES)


@contextlib.contextmanager
def heap_tuning():
    """Let the stages tune glibc's heap (:func:`reuse_freed_memory`) while the block runs: an
    application's opt-in, as the ``potflat`` command's. Blocks may nest and overlap across
    threads; the last one to end closes the opt-in."""
    global _allowed
    with _lock:
        _allowed += 1
    try:
        yield
    finally:
        with _lock:
            _allowed -= 1


def heap_tuning_allowed() -> bool:
    """Whether a :func:`heap_tuning` block is open in this process."""
    return _allowed > 0


@contextlib.contextmanager
def reuse_freed_memory():
    """Run the block (or, as ``@reuse_freed_memory()``, the function) with large allocations
    served from glibc's heap and freed memory kept there for reuse, when the application opted
    in (:func:`heap_tuning`); else it just runs.

    Blocks may nest and overlap across threads: the first to start returns the heap's free
    memory to the system and tunes the heap, the last to end puts the settings back and
    returns the free memory again (also on error).
    The block's peak resident memory grows by what the heap cannot reuse: a trade of memory
    for time (the 3M-vertex benchmark amphora's rollout stage: 2.88 GiB and a whole run of
    79 s untuned, 3.14 GiB and 56 s tuned).
    """
    global _tuned
    libc = _glibc()
    with _lock:
        first = _tuned == 0
        tuned = _allowed > 0 and libc is not None and (_tuned > 0 or _tune(libc))
        if tuned:
            _tuned += 1
            if first:  # what an earlier stage left free goes back first, not under this block's peak
                release_free_memory()
    try:
        yield
    finally:
        if tuned:
            with _lock:
                _tuned -= 1
                if _tuned == 0:
                    libc.mallopt(M_MMAP_MAX, DEFAULT_MMAP_MAX)
                    libc.mallopt(M_TRIM_THRESHOLD, DEFAULT_TRIM_THRESHOLD)
                    release_free_memory()


def _tune(libc) -> bool:
    """Serve large allocations from the heap and keep its free memory; False when the user's
    settings stand or glibc refuses."""
    if user_settings() or not libc.mallopt(M_MMAP_MAX, 0):
        return False
    libc.mallopt(M_TRIM_THRESHOLD, KEEP_TRIM_THRESHOLD)
    return True


def release_free_memory() -> None:
    """Hand the heap's free memory back to the system (``malloc_trim``; glibc only): what a
    stage's setup freed amid live arrays stays resident otherwise, on top of the peak to come.
    No setting changes."""
    libc = _glibc()
    if libc is not None:
        libc.malloc_trim(0)
