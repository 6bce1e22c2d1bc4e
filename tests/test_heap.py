"""potflat._heap: large allocations from glibc's heap inside the block, mappings again after it."""
import ctypes
import os

import numpy as np
import pytest

from potflat import _heap

LARGE = 96 * 2**20  # above glibc's largest mmap threshold (32 MB)


class _MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks",
                 "keepcost")]


def _mapped_bytes() -> int:
    """Bytes glibc holds in mappings of their own (``mallinfo2().hblkhd``)."""
    libc = _heap._glibc()
    if libc is None or not hasattr(libc, "mallinfo2"):
        pytest.skip("needs glibc 2.33 or newer")
    libc.mallinfo2.restype = _MallInfo2
    return libc.mallinfo2().hblkhd


def _mapped_by_allocation() -> int:
    before = _mapped_bytes()
    block = np.ones(LARGE // 8)  # (touched, so that it is really allocated)
    grown = _mapped_bytes() - before
    del block
    return grown


def test_large_allocations_come_from_the_heap_inside_the_block_only():
    assert _mapped_by_allocation() >= LARGE  # glibc's default: a mapping of its own
    with _heap.reuse_freed_memory():
        assert _mapped_by_allocation() == 0
    assert _mapped_by_allocation() >= LARGE  # restored


def test_settings_restored_when_the_block_raises():
    with pytest.raises(KeyError):
        with _heap.reuse_freed_memory():
            raise KeyError("stop")
    assert _mapped_by_allocation() >= LARGE


def _resident_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def test_release_hands_the_kept_memory_back():
    _mapped_bytes()  # (skips without glibc)
    with _heap.reuse_freed_memory():
        block = np.ones(LARGE // 8)
        del block  # (kept in the heap: the block's trim threshold is above it)
        before = _resident_bytes()
        _heap.release_free_memory()
        assert before - _resident_bytes() >= 0.9 * LARGE


def test_without_glibc_the_block_just_runs(monkeypatch):
    monkeypatch.setattr(_heap, "_glibc", lambda: None)
    ran = []
    with _heap.reuse_freed_memory():
        ran.append(True)
    assert ran == [True]
