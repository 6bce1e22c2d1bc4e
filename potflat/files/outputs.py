"""One consistent set of outputs per name in a folder.

A run of a stage (or of all three) supersedes the outputs an earlier run wrote for the same
``NAME`` in the folder, its own stage's and those made from them (a new rollout makes the
old relaxation and images stale): before it writes, :func:`superseding` moves them into a
hidden folder ``.NAME.potflat-earlier`` beside them. When the run completes they are
removed; when it fails or is interrupted, its own outputs are removed and the earlier ones
moved back, so the folder holds what it held before. With no earlier outputs, the stages the
run finished are kept (one run's outputs) and the unfinished stage's are removed. A run
killed outright (SIGKILL) leaves the hidden folder: the next run into the folder moves its
files back first.
"""
from __future__ import annotations

import contextlib
import contextvars
import os
import shutil
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from potflat.files.names import BASE_NAME_SUFFIX, stage_outputs
from potflat.io.atomic import output_lock, remove_stale_parts

#: (folder, NAME) pairs whose outputs an enclosing :func:`superseding` block already handles
#: (:func:`potflat.run_scan` around its stages' runners).
_HANDLED: contextvars.ContextVar[frozenset] = contextvars.ContextVar("potflat_superseding", default=frozenset())


def earlier_folder(folder: Path, name: str) -> Path:
    """The hidden folder holding the earlier outputs of ``name`` while a run replaces them."""
    return folder / f".{name}.potflat-earlier"


class Superseding:
    """The state of a :func:`superseding` block: the stages it writes and those finished."""

    def __init__(self, stages: tuple[str, ...]):
        self.stages = stages
        self.finished: list[str] = []

    def done(self, stage: str) -> None:
        """Record that ``stage`` wrote all its outputs."""
        self.finished.append(stage)


@contextlib.contextmanager
def superseding(folder: str | os.PathLike, name: str, stages: tuple[str, ...], *,
                keep: Callable[[], Iterable[str | os.PathLike]] = tuple) -> Iterator[Superseding]:
    """Write ``stages``' outputs for ``name`` into ``folder`` as one consistent set (see the
    module's description), holding the folder's :func:`~potflat.io.atomic.output_lock`.

    Parameters
    ----------
    folder : path-like
        The output folder (created if needed).
    name : str
        The outputs' NAME.
    stages : tuple of str
        The stages whose outputs the block writes or makes stale
        (:data:`potflat.files.names.STAGES_FROM`).
    keep : callable
        Returns the run's input files: never moved aside or removed, whatever their names.

    Yields
    ------
    Superseding
        Tell it each stage that finished (:meth:`Superseding.done`).

    Notes
    -----
    Inside a block for the same folder and name (:func:`potflat.run_scan` around the stage
    runners), or for the painting whose base's disc ``name`` is (``NAME.base``, baked inside
    the bake of ``NAME``), the block does nothing: the outer one handles the outputs and
    holds the lock.
    """
    folder = Path(folder)
    key = (os.path.abspath(folder), name)
    run = Superseding(stages)
    if key in _HANDLED.get() or (key[0], name.removesuffix(BASE_NAME_SUFFIX)) in _HANDLED.get():
        yield run
        return
    with output_lock(folder):
        remove_stale_parts(folder)  # left by a killed run; no other potflat process writes here now
        aside = earlier_folder(folder, name)
        _move_back(aside, folder)  # left by a killed run
        inputs = {os.path.realpath(p) for p in keep()}
        earlier = [p for p in stage_outputs(folder, name, stages) if os.path.realpath(p) not in inputs]
        if earlier:
            aside.mkdir()
            for path in earlier:
                os.replace(path, aside / path.name)
        token = _HANDLED.set(_HANDLED.get() | {key})
        try:
            yield run
        except BaseException:
            pending = stages if earlier else tuple(s for s in stages if s not in run.finished)
            for path in stage_outputs(folder, name, pending):
                if os.path.realpath(path) not in inputs:
                    with contextlib.suppress(OSError):
                        os.unlink(path)
            _move_back(aside, folder)
            raise
        finally:
            _HANDLED.reset(token)
        shutil.rmtree(aside, ignore_errors=True)


def _move_back(aside: Path, folder: Path) -> None:
    """Move every file of ``aside`` back into ``folder`` (replacing what has its name) and
    remove ``aside``. Anything else by that name (a link, a file: planted) is removed, never
    followed."""
    import stat

    try:
        mode = os.lstat(aside).st_mode
    except OSError:  # none
        return
    if not stat.S_ISDIR(mode):
        with contextlib.suppress(OSError):
            os.unlink(aside)
        return
    try:
        entries = list(os.scandir(aside))
    except OSError:
        return
    for entry in entries:
        with contextlib.suppress(OSError):
            os.replace(entry.path, folder / entry.name)
    shutil.rmtree(aside, ignore_errors=True)
