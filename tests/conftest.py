"""Shared fixtures. Numba's on-disk cache goes to a temporary folder so stale caches
from another checkout can never mask an edit."""
from __future__ import annotations

import os
import tempfile

os.environ.setdefault("NUMBA_CACHE_DIR", tempfile.mkdtemp(prefix="potflat-numba-cache-"))

import numpy as np  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture
def square_mesh():
    """Two triangles forming a unit square in the z=0 plane, CCW from +z."""
    from potflat.types import Mesh

    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    F = np.array([[0, 1, 2], [1, 3, 2]])
    return Mesh(V, F)
