"""The benchmark meshes (``benchmarks/_meshes.py``: bulgy vessels, cylinder and cone patches)
and the painted-figure measure (``benchmarks/_figures.py``) for the tests, and the signed
face areas the tests check them with."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np


def load_benchmark(name: str):
    """The module ``benchmarks/NAME.py``."""
    spec = importlib.util.spec_from_file_location(name, Path(__file__).parents[1] / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


meshes = load_benchmark("_meshes")
figures = load_benchmark("_figures")

#: Relax options of the springs alone (no shape term, no final scaling): what the tests of the
#: springs' edge-length figures run.
SPRINGS_ONLY = {"shape": 0.0, "rigidity": 0.0, "area": 0.0, "true_scale": False}


def energy_never_increases(result) -> bool:
    """Each level of a relax result (its ``levels``, in order) never increased its energy:
    each minimises its own (the area term joins after a first solve without it)."""
    h, start = result.energy_history, 0
    for level in result.levels:
        if np.any(np.diff(h[start:start + level.iterations]) > 0):
            return False
        start += level.iterations
    return start == len(h)


def signed_areas(uv: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Signed area of every face of the layout ``uv`` (n, 2), shape (m,)."""
    e1 = uv[F[:, 1]] - uv[F[:, 0]]
    e2 = uv[F[:, 2]] - uv[F[:, 0]]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])



def bumpy_patch():
    """A tiny non-planar irregular mesh (random heights over a jittered lattice) with its
    cylinder-patch layout: the kernels' reference cases."""
    from potflat.types import FlatMesh, Mesh

    flat, _ = meshes.cylinder_patch(5, 4, seed=3)
    V = flat.mesh.vertices.copy()
    V[:, 0] += np.random.default_rng(1).normal(0, 0.05, len(V))
    return FlatMesh(Mesh(V, flat.mesh.faces), flat.uv)


def spring_system(V: np.ndarray, F: np.ndarray, **kw):
    """The relax solver's spring system of a mesh (``V`` (n, 3), ``F`` (m, 3))."""
    from potflat.relax.energy import SpringSystem

    return SpringSystem(np.ascontiguousarray(V, float), np.ascontiguousarray(F, np.int64), len(V), **kw)
