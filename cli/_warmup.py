"""Compile the relax and bake stages' kernels early on a first run, on both cores.

A first run (no kernels in Numba's disk cache yet) compiles over a hundred kernels one after
the other, each on first use, on one core: the rollout's, then the relax stage's, then the
bake stage's. :func:`start` runs this module in a child process that relaxes a small
generated vessel (:func:`vessel`) in a temporary folder, so that the relax kernels are
compiled, and cached on disk (``cache=True``, :mod:`potflat._jit`), on the second core while
the run compiles and runs its rollout; then the run bakes the same vessel itself
(:func:`bake_here`: the bake kernels) while the child finishes, and loads the relax kernels
from the cache. (Baking first, before the rollout, was as fast but kept a bad scan's one-line
refusal waiting for the bake kernels.) Best effort: a kernel the child has not cached yet
when the run needs it is compiled by the run as before. Nothing is written but Numba's cache
and temporary folders, which the run removes (the child removes its own too when it ends by
itself). The child ends with the run however the run ends, killed outright (SIGKILL)
included: it watches a pipe whose other end only the run holds (the run's end closes when it
dies), and on Linux the kernel also sends it SIGTERM when the run dies (``PR_SET_PDEATHSIG``).
"""
from __future__ import annotations

import math
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from potflat.types import FlatMesh

#: The generated vessel: radius (mm) at mid-height, bulge (mm), height (mm), and the grid
#: (around, along the height). Enough vertices for the relax stage's coarse copies
#: (``COARSE.min_vertices``), so their kernels are compiled too.
RADIUS_MM, BULGE_MM, HEIGHT_MM = 40.0, 12.0, 100.0
AROUND, ALONG = 240, 100
#: Painted band (fraction of the height): the relax stage's painted-zone path.
BAND = (0.35, 0.65)
#: Seconds the run waits for a stopped child to end before killing it.
STOP_TIMEOUT_S = 5.0
#: ``prctl`` option: the signal the kernel sends a process when its parent dies (linux/prctl.h).
PR_SET_PDEATHSIG = 1


class Warmup:
    """The child process of :func:`start`, its folder and the run's end of the pipe the child
    watches (:func:`_die_with_parent`); :meth:`stop` ends them (idempotent)."""

    def __init__(self, process: subprocess.Popen, folder: Path, pipe: int):
        self.process = process
        self.folder = folder
        self.pipe = pipe

    def stop(self) -> None:
        """End the child if it still runs (SIGTERM, then SIGKILL: a kernel being compiled
        holds off the signal), reap it and remove its folder."""
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        if self.pipe >= 0:
            os.close(self.pipe)
            self.pipe = -1
        shutil.rmtree(self.folder, ignore_errors=True)


def start() -> Warmup | None:
    """Start compiling the relax kernels in a child process when they are not cached yet (a
    first run); None when they are, or when no child can be started."""
    from potflat._jit import kernels_cached

    if kernels_cached():
        return None
    try:
        folder = Path(tempfile.mkdtemp(prefix="potflat-warmup-"))
    except OSError:
        return None
    try:
        watched, held = os.pipe()  # (neither end is inherited by other children of the run)
    except OSError:
        shutil.rmtree(folder, ignore_errors=True)
        return None
    try:
        process = subprocess.Popen([sys.executable, "-m", "potflat_cli._warmup", str(folder), str(watched),
                                    str(os.getpid())], pass_fds=(watched,),
                                   stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    except OSError:
        os.close(held)
        shutil.rmtree(folder, ignore_errors=True)
        return None
    finally:
        os.close(watched)
    return Warmup(process, folder, held)


def vessel(folder: Path) -> FlatMesh:
    """A small textured vessel unrolled onto its mean cylinder, painted in a band.

    A surface of revolution bulging by :data:`BULGE_MM`, cut open along one meridian (the
    seam's vertices appear once per side), its start layout the unrolled cylinder (fold-free,
    not yet relaxed), a 64 x 64 texture written into ``folder``.

    Returns
    -------
    FlatMesh
    """
    from potflat.io.images import write_png
    from potflat.types import FlatMesh, Mesh

    theta = np.linspace(0.0, 2.0 * math.pi, AROUND + 1)
    z = np.linspace(0.0, HEIGHT_MM, ALONG)
    T, Z = np.meshgrid(theta, z)  # (ALONG, AROUND + 1)
    R = RADIUS_MM + BULGE_MM * np.sin(math.pi * Z / HEIGHT_MM)
    vertices = np.stack((R * np.cos(T), R * np.sin(T), Z), axis=-1).reshape(-1, 3)
    uv = np.stack((RADIUS_MM * T, Z), axis=-1).reshape(-1, 2)
    idx = np.arange(vertices.shape[0]).reshape(ALONG, AROUND + 1)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]  # counter-clockwise from outside
    faces = np.concatenate((np.stack((a, b, c), -1).reshape(-1, 3), np.stack((a, c, d), -1).reshape(-1, 3)))
    tex = np.stack((T / (2.0 * math.pi), Z / HEIGHT_MM), axis=-1).reshape(-1, 2)
    texture = np.zeros((64, 64, 4), np.uint8)
    texture[..., :3] = 90
    texture[24:40, ::4, :3] = (200, 120, 40)  # strokes in the band
    texture[..., 3] = 255
    path = write_png(folder / "warmup.texture.png", texture, px_per_mm=None)
    h = Z.reshape(-1) / HEIGHT_MM
    importance = ((h >= BAND[0]) & (h <= BAND[1])).astype(np.float64)
    mesh = Mesh(vertices, faces, texcoords=tex[faces], texture_path=path.resolve())
    return FlatMesh(mesh, uv, importance=importance)


def warm(folder: Path, stage: str) -> None:
    """Relax (``stage`` "relax") or bake ("bake") :func:`vessel` in ``folder`` with the
    stage's default options, as a run does."""
    from potflat.io.flat_ply import write_flat_ply

    flat = vessel(folder)
    rollout_ply = write_flat_ply(folder / "warmup.rollout.ply", flat)
    if stage == "relax":
        from potflat.relax import RelaxOptions
        from potflat.files.relax_stage import run_relax_stage

        run_relax_stage(rollout_ply, folder, RelaxOptions())
    else:
        from potflat.bake import BakeOptions
        from potflat.files.bake_stage import run_bake_stage

        run_bake_stage(rollout_ply, folder, BakeOptions())


def bake_here() -> None:
    """Compile the bake kernels in this process (:func:`warm` "bake" in a temporary folder,
    removed afterwards); a failure is ignored: the run compiles what it needs as before."""
    try:
        folder = Path(tempfile.mkdtemp(prefix="potflat-warmup-"))
    except OSError:
        return
    try:
        warm(folder, "bake")
    except Exception:  # noqa: BLE001 - best effort, never the run's failure
        pass
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _die_with_parent(parent: int, pipe: int, folder: Path) -> None:
    """End this child, removing its ``folder``, when the run that started it (process ``parent``)
    ends, however it ends: a thread waits for the end of file on ``pipe`` (the read end of a
    pipe whose write end only the run holds: the system closes it when the run dies) and,
    on Linux, the kernel sends SIGTERM when the run dies (``PR_SET_PDEATHSIG``; :func:`_main`
    handles it). The thread also ends the child while its main thread compiles.
    The run starts the child from its main thread (the death signal follows the thread that
    started the child)."""
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
        except (OSError, AttributeError):  # no prctl: the pipe alone
            pass
    if os.getppid() != parent:  # the run died before the death signal was asked for
        _end(folder)

    def watch() -> None:
        try:
            while os.read(pipe, 64):
                pass
        except OSError:
            pass
        _end(folder)

    threading.Thread(target=watch, name="potflat-warmup-parent", daemon=True).start()


def _end(folder: Path) -> None:
    """Remove ``folder`` and end this child at once (no interpreter shutdown: seconds with
    Numba's compiler loaded)."""
    shutil.rmtree(folder, ignore_errors=True)
    os._exit(1)


def _main(folder: str, pipe: str, parent: str) -> int:
    signal.signal(signal.SIGTERM, lambda signum, frame: _end(Path(folder)))  # the run's stop, or its death
    _die_with_parent(int(parent), int(pipe), Path(folder))
    try:
        warm(Path(folder), "relax")
    except (Exception, KeyboardInterrupt):
        return 1
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(_main(*sys.argv[1:4]))
