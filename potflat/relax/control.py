"""What the Python loop of every solver shares: the energy history, the iteration cap, the
time budget, the caller's callback and the progress bar."""
from __future__ import annotations

import contextlib
import time

import numpy as np
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn


class RunControl:
    """Bookkeeping shared by the solvers: the energy history (all levels), the iteration cap,
    the deadline, the caller's callback and the progress report.

    Parameters
    ----------
    max_iter : int
        Iterations at most, counting the history already recorded.
    deadline : float
        ``time.perf_counter()`` after which the run stops (inf: none).
    callback : callable or None
        Called after every iteration with ``{"iteration", "energy", "level"}``; True stops.
    progress : callable or None
        ``progress(iteration, energy, level)``, every tenth iteration.
    """

    def __init__(self, max_iter: int, deadline: float, callback, progress):
        self.history: list[float] = []
        self.max_iter = max_iter
        self.deadline = deadline
        self.callback = callback
        self.progress = progress
        self.level = ""
        self.stopped = ""

    def record(self, energy: float) -> bool:
        """Store one iteration; True when the run must stop (cap, budget, callback)."""
        self.history.append(energy)
        it = len(self.history)
        if self.progress is not None and (it % 10 == 0 or it == 1):
            self.progress(it, energy, self.level)
        if self.callback is not None and self.callback({"iteration": it, "energy": energy, "level": self.level}):
            self.stopped = "callback"
        elif it >= self.max_iter:
            self.stopped = "max_iter"
        elif time.perf_counter() > self.deadline:
            self.stopped = "time_budget"
        return bool(self.stopped)


def relative_change(hist: list[float], window: int) -> float:
    """The energy's relative change per iteration over the last ``window`` iterations of
    ``hist`` (inf while it is shorter)."""
    if len(hist) <= window:
        return np.inf
    old, new = hist[-1 - window], hist[-1]
    return abs(old - new) / (window * max(abs(new), 1e-300))


@contextlib.contextmanager
def progress_bar(total: int):
    """A progress bar on stderr for ``total`` iterations, giving the ``progress`` callable of
    :class:`RunControl`."""
    with Progress(TextColumn("relax {task.fields[level]}"), BarColumn(), TextColumn("{task.completed} it"),
                  TextColumn("E={task.fields[energy]:.4g}"), TimeElapsedColumn(), transient=True,
                  console=Console(stderr=True)) as prog:
        task = prog.add_task("relax", total=total, level="", energy=float("nan"))

        def report(it: int, energy: float, level: str) -> None:
            prog.update(task, completed=it, energy=energy, level=level)

        yield report
