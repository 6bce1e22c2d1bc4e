"""The benchmark meshes (``benchmarks/_meshes.py``: bulgy vessels, cylinder and cone patches)
for the tests, and the signed face areas the tests check them with."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

_spec = importlib.util.spec_from_file_location("_meshes", Path(__file__).parents[1] / "benchmarks" / "_meshes.py")
meshes = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(meshes)


def signed_areas(uv: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Signed area of every face of the layout ``uv`` (n, 2), shape (m,)."""
    e1 = uv[F[:, 1]] - uv[F[:, 0]]
    e2 = uv[F[:, 2]] - uv[F[:, 0]]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
