"""Shared fixtures and the test run's process settings.

Numba's on-disk cache is kept between runs in pytest's cache folder
(``.pytest_cache/d/numba-<hash>``), in a folder named by a hash of every source file of
``potflat`` and ``potflat_synthetic``: an edit anywhere in them starts an empty cache, so a
kernel whose callee or constant changed is compiled again, never taken stale from the cache
(Numba itself only checks the kernel's own file). ``--cache-clear`` gives a cold run.
On a cold cache the relax kernels compile in a child process meanwhile, as on a first
``potflat run``. The run waits as the ``potflat`` command does (OpenMP's passive wait), both
set before any kernel is imported; a ``NUMBA_CACHE_DIR`` or ``OMP_WAIT_POLICY`` of the user's
wins.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

CHECKOUT = Path(__file__).resolve().parents[1]
#: Folders whose Python sources key the kernel cache.
KERNEL_SOURCES = ("potflat", "synthetic")
#: Kernel caches kept: the most recently used (other sources' caches, e.g. other branches).
KEPT_CACHES = 3


def sources_hash(root: Path = CHECKOUT) -> str:
    """A hash of every ``.py`` file under :data:`KERNEL_SOURCES` (paths and contents)."""
    h = hashlib.sha256()
    for folder in KERNEL_SOURCES:
        for path in sorted((root / folder).rglob("*.py")):
            h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return h.hexdigest()[:16]


def kernel_cache(config) -> Path:
    """This run's Numba cache folder, made if needed and marked as just used; all but the
    :data:`KEPT_CACHES` most recently used are removed. When pytest's cache is off, a
    temporary folder, removed at the end of the run."""
    name = f"numba-{sources_hash()}"
    cache = getattr(config, "cache", None)
    if cache is None:  # -p no:cacheprovider
        folder = Path(tempfile.mkdtemp(prefix=f"potflat-{name}-"))
        config.add_cleanup(lambda: shutil.rmtree(folder, ignore_errors=True))
        return folder
    folder = cache.mkdir(name)
    os.utime(folder)
    caches = sorted(folder.parent.glob("numba-*"), key=lambda p: p.stat().st_mtime, reverse=True)
    for old in caches[KEPT_CACHES:]:
        shutil.rmtree(old, ignore_errors=True)
    return folder


def pytest_configure(config):
    if "NUMBA_CACHE_DIR" not in os.environ:
        os.environ["NUMBA_CACHE_DIR"] = str(kernel_cache(config))
        if "numba" in sys.modules:  # (imported by a plugin: read the setting again)
            sys.modules["numba"].config.reload_config()
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


#: The warm-up child of a run on a cold kernel cache.
WARMUP = pytest.StashKey[object]()


def pytest_sessionstart(session):
    """On a cold kernel cache, compile the relax kernels in a child process as a first ``potflat
    run`` does (:func:`potflat_cli._warmup.start`), on the second core, while the first tests
    compile the rollout's and the bake's."""
    from potflat_cli import _warmup

    if not hasattr(session.config, "workerinput"):  # once per run: not in each pytest-xdist worker
        session.config.stash[WARMUP] = _warmup.start()


def pytest_sessionfinish(session):
    warmup = session.config.stash.get(WARMUP, None)
    if warmup is not None:
        warmup.stop()


def real_scans_folder(checkout: Path = CHECKOUT) -> Path:
    """``shared/data/real`` beside the checkout (how CI provides the real scans); skips the
    test, with the reason, when it is not there."""
    folder = checkout.parent / "shared" / "data" / "real"
    if not folder.is_dir():
        pytest.skip(f"the real scans are not at {folder} (shared/ beside the checkout)")
    return folder


@pytest.fixture
def real_scans() -> Path:
    """The real scans' folder (:func:`real_scans_folder`)."""
    return real_scans_folder()


@pytest.fixture
def square_mesh():
    """Two triangles forming a unit square in the z=0 plane, CCW from +z."""
    from potflat.types import Mesh

    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    F = np.array([[0, 1, 2], [1, 3, 2]])
    return Mesh(V, F)
