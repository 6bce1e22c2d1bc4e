"""potflat._heap: large allocations from glibc's heap inside the block when the application opted
in, mappings again after the last block."""
import ctypes
import os
import threading

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
    with _heap.heap_tuning(), _heap.reuse_freed_memory():
        assert _mapped_by_allocation() == 0
    assert _mapped_by_allocation() >= LARGE  # restored


def test_without_the_opt_in_the_library_changes_nothing():
    assert not _heap.heap_tuning_allowed()
    with _heap.reuse_freed_memory():
        assert _mapped_by_allocation() >= LARGE
    with _heap.heap_tuning():
        pass
    assert not _heap.heap_tuning_allowed()  # the opt-in ends with its block
    with _heap.reuse_freed_memory():
        assert _mapped_by_allocation() >= LARGE


@pytest.mark.parametrize("name, value", [("MALLOC_MMAP_MAX_", "65536"),
                                         ("GLIBC_TUNABLES", "glibc.malloc.trim_threshold=131072")])
def test_the_users_own_malloc_settings_stand(monkeypatch, name, value):
    monkeypatch.setenv(name, value)
    assert _heap.user_settings()
    with _heap.heap_tuning(), _heap.reuse_freed_memory():
        assert _mapped_by_allocation() >= LARGE


def test_the_tuning_lasts_until_the_last_of_nested_and_overlapping_blocks_ends():
    _mapped_bytes()  # (skips without glibc)
    inside, leave = threading.Event(), threading.Event()

    def stage_in_another_thread():
        with _heap.reuse_freed_memory():
            inside.set()
            leave.wait(60)

    other = threading.Thread(target=stage_in_another_thread)
    with _heap.heap_tuning():
        with _heap.reuse_freed_memory():
            with _heap.reuse_freed_memory():
                pass
            assert _mapped_by_allocation() == 0  # the inner block's end kept the outer's tuning
            other.start()
            assert inside.wait(60)
        try:
            assert _mapped_by_allocation() == 0  # this thread's block ended, the other's runs on
        finally:
            leave.set()
            other.join()
        assert _mapped_by_allocation() >= LARGE  # the last block put the settings back


def test_settings_restored_when_the_block_raises():
    with pytest.raises(KeyError):
        with _heap.heap_tuning(), _heap.reuse_freed_memory():
            raise KeyError("stop")
    assert _mapped_by_allocation() >= LARGE


def _resident_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def test_release_hands_the_kept_memory_back():
    _mapped_bytes()  # (skips without glibc)
    with _heap.heap_tuning(), _heap.reuse_freed_memory():
        block = np.ones(LARGE // 8)
        del block  # (kept in the heap: the block's trim threshold is above it)
        before = _resident_bytes()
        _heap.release_free_memory()
        assert before - _resident_bytes() >= 0.9 * LARGE


def test_without_glibc_the_block_just_runs(monkeypatch):
    monkeypatch.setattr(_heap, "_glibc", lambda: None)
    ran = []
    with _heap.heap_tuning(), _heap.reuse_freed_memory():
        ran.append(True)
    assert ran == [True]


def test_the_first_block_hands_back_what_was_free_before_it(monkeypatch):
    calls = []

    class _Libc:
        def mallopt(self, param, value):
            calls.append(("mallopt", param))
            return 1

        def malloc_trim(self, pad):
            calls.append(("trim", pad))
            return 1

    libc = _Libc()
    monkeypatch.setattr(_heap, "_glibc", lambda: libc)
    monkeypatch.setattr(_heap, "user_settings", lambda: False)
    with _heap.heap_tuning():
        with _heap.reuse_freed_memory():
            assert calls[-1] == ("trim", 0)  # after the tuning, before the block's own work
            calls.clear()
            with _heap.reuse_freed_memory():  # (nested: the heap is the outer block's)
                pass
            assert calls == []
    assert calls[-1] == ("trim", 0)  # the last block's end
