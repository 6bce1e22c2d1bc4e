"""Running one stage from its command: a status line on stderr, ``--json`` on stdout."""
from __future__ import annotations

import json
import time
from collections.abc import Callable

#: How a line of progress begins on stderr (:class:`StageLog`, :func:`say_compiling`); an error
#: line begins with ``error:``.
PROGRESS = "potflat: "
#: What a first run says: it compiles over a hundred kernels, for as long as the cores it gets
#: take (benchmarks/bench_first_run.py measures it).
FIRST_RUN = "first run: compiling potflat's kernels once, a few minutes (more on a busy machine)"


def with_compile_note(status: str) -> str:
    """``status`` plus a note when this run compiles the kernels (the first run is silent for
    a few minutes otherwise)."""
    from potflat._jit import kernels_cached

    return status if kernels_cached() else f"{status} ({FIRST_RUN})"


def say_compiling(console) -> None:
    """One plain line on ``console`` (stderr) when this run compiles the kernels and no live
    status line can say so (stderr is not a terminal: a log, a pipe, a batch job)."""
    from potflat._jit import kernels_cached

    if not console.is_terminal and not kernels_cached():
        console.print(f"{PROGRESS}{FIRST_RUN}", highlight=False, soft_wrap=True)


class StageLog:
    """One plain line when a stage starts and one when it ends, with its seconds, on
    ``console`` (stderr) when it is not a terminal (a log, a pipe, a batch job), where no live
    status line shows what the command is doing; nothing on a terminal (the status line says
    it). A stage that fails gets no end line: the error line follows."""

    def __init__(self, console):
        self.console = console
        self.what: str | None = None
        self.started = 0.0

    def start(self, what: str) -> None:
        """``what`` (e.g. ``amphora.obj: relax``) starts; the stage before it, if any, ended."""
        self.end()
        self.what, self.started = what, time.perf_counter()
        self._say(f"{what} ...")

    def end(self) -> None:
        """The stage that started last ended."""
        if self.what is not None:
            self._say(f"{self.what}: done in {time.perf_counter() - self.started:.1f} s")
            self.what = None

    def _say(self, line: str) -> None:
        if not self.console.is_terminal:
            self.console.print(f"{PROGRESS}{line}", highlight=False, soft_wrap=True)


def run_stage(status: str | None, call: Callable, *, quiet: bool, as_json: bool):
    """Run ``call()`` (a ``run_<stage>_stage``) under a status spinner on stderr.

    ``status=None`` shows no spinner (for a stage that draws its own progress bar: rich
    allows one live display at a time).

    With ``as_json`` the stage's summary (without provenance) is printed to stdout.

    Returns
    -------
    the stage's files (with their record) or None
        The result when a human-readable summary should follow, else ``None``.
    """
    from rich.console import Console

    console = Console(stderr=True, quiet=quiet or as_json)
    say_compiling(console)
    if status is None:
        result = call()
    else:
        log = StageLog(console)
        log.start(status)
        with console.status(with_compile_note(status)):
            result = call()
        log.end()
    if as_json:
        print(json.dumps({k: v for k, v in result.record.items() if k != "provenance"}, indent=2))
        return None
    return None if quiet else result
