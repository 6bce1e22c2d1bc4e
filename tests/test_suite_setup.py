"""The test run's own set-up (tests/conftest.py): the kernel cache kept between runs, keyed by
the kernel sources; the real scans found beside the checkout."""
from __future__ import annotations

import os

import pytest

import conftest


def test_the_kernel_cache_is_keyed_by_the_kernel_sources(tmp_path):
    for folder in (*conftest.KERNEL_SOURCES, "tests"):
        (tmp_path / folder).mkdir()
        (tmp_path / folder / "a.py").write_text("X = 1\n")
    first = conftest.sources_hash(tmp_path)
    (tmp_path / "tests" / "a.py").write_text("X = 2\n")
    assert conftest.sources_hash(tmp_path) == first  # not a kernel source
    for folder in conftest.KERNEL_SOURCES:
        (tmp_path / folder / "a.py").write_text(f"X = 1  # {folder}\n")
        assert conftest.sources_hash(tmp_path) != first, folder
        first = conftest.sources_hash(tmp_path)
    (tmp_path / "potflat" / "a.py").rename(tmp_path / "potflat" / "b.py")
    assert conftest.sources_hash(tmp_path) != first  # a moved file too


def test_the_kernel_cache_keeps_the_most_recently_used(tmp_path):
    class Cache:
        def mkdir(self, name):
            (tmp_path / name).mkdir(exist_ok=True)
            return tmp_path / name

    class Config:
        cache = Cache()

    for age, name in enumerate(("numba-a", "numba-b", "numba-c", "numba-d", "other")):
        (tmp_path / name).mkdir()
        os.utime(tmp_path / name, (1e9 - age, 1e9 - age))
    folder = conftest.kernel_cache(Config())
    assert folder.name == f"numba-{conftest.sources_hash()}"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([folder.name, "numba-a", "numba-b", "other"])


def test_real_scans_are_found_beside_the_checkout_or_skipped_with_the_reason(tmp_path):
    checkout = tmp_path / "clone"
    checkout.mkdir()
    with pytest.raises(pytest.skip.Exception, match="real scans are not at .*shared/data/real"):
        conftest.real_scans_folder(checkout)
    (tmp_path / "shared" / "data" / "real").mkdir(parents=True)
    assert conftest.real_scans_folder(checkout) == tmp_path / "shared" / "data" / "real"


def test_without_pytests_cache_the_kernel_cache_is_removed_at_the_end():
    cleanups = []

    class Config:
        cache = None
        add_cleanup = cleanups.append

    folder = conftest.kernel_cache(Config())
    assert folder.is_dir() and len(cleanups) == 1
    cleanups[0]()
    assert not folder.exists()


@pytest.mark.parametrize("worker", [False, True])
def test_the_relax_kernels_are_warmed_up_once_per_run_not_in_each_worker(monkeypatch, worker):
    from potflat_cli import _warmup

    started = []
    monkeypatch.setattr(_warmup, "start", lambda: started.append(1) or "child")

    class Config:
        stash = pytest.Stash()

    if worker:  # how pytest-xdist marks a worker's config
        Config.workerinput = {"workerid": "gw0"}

    class Session:
        config = Config()

    conftest.pytest_sessionstart(Session())
    assert len(started) == (0 if worker else 1)
    assert Session.config.stash.get(conftest.WARMUP, None) == (None if worker else "child")
