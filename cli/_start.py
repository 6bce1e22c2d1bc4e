"""How the ``potflat`` process starts: glibc's allocator asked for transparent huge pages.

The arrays of a big scan are allocated by ``malloc`` outside NumPy (Numba's kernels, OpenCV,
the loaders), and each large block is mapped afresh in 4 KiB pages: their page faults were a
sixth of the rollout's CPU time at 3M vertices. With glibc's ``glibc.malloc.hugetlb=1``
tunable those blocks are advised huge pages, as NumPy advises its own: the 1M-vertex rollout
0.91x, the 3M relax 0.93x, peak memory unchanged (docs/performance.md). The tunable is read
when a process starts, so the command restarts itself once with it (a few tens of
milliseconds); children (the first run's warm-up, batch workers) inherit it. A user's own
setting of it (``GLIBC_TUNABLES=glibc.malloc.hugetlb=0`` turns it off) is kept.
"""
from __future__ import annotations

import os
import sys

#: The glibc tunable asked for, and the first glibc version that has it.
HUGE_PAGES_TUNABLE = "glibc.malloc.hugetlb"
HUGE_PAGES_GLIBC = (2, 35)


def huge_pages_environment(environ: dict[str, str], platform: str, libc: tuple[str, str]) -> dict[str, str] | None:
    """The environment to restart with, or None when the process should go on as it is.

    Parameters
    ----------
    environ : dict
        The process environment.
    platform : str
        ``sys.platform``.
    libc : (str, str)
        ``platform.libc_ver()``: the C library's name and version.
    """
    tunables = environ.get("GLIBC_TUNABLES", "")
    if platform != "linux" or libc[0] != "glibc" or HUGE_PAGES_TUNABLE in tunables:
        return None
    try:
        version = tuple(int(part) for part in libc[1].split(".")[:2])
    except ValueError:
        return None
    if version < HUGE_PAGES_GLIBC:
        return None
    setting = f"{HUGE_PAGES_TUNABLE}=1"
    return {**environ, "GLIBC_TUNABLES": f"{tunables}:{setting}" if tunables else setting}


def restart_with_huge_pages() -> None:
    """Replace this process by the same command with :func:`huge_pages_environment` (when it
    gives one); on any failure to restart, go on as it is."""
    import platform

    environ = huge_pages_environment(dict(os.environ), sys.platform, platform.libc_ver())
    if environ is None or not getattr(sys, "orig_argv", None):
        return
    try:
        os.execve(sys.executable, [sys.executable, *sys.orig_argv[1:]], environ)
    except OSError:
        return


def main() -> None:
    """The ``potflat`` command (console script and ``python -m potflat_cli``)."""
    restart_with_huge_pages()
    from potflat_cli.main import app

    try:
        app(prog_name="potflat")
    except SystemExit as stop:
        from potflat_cli._errors import STOP

        if not STOP:
            raise
        # Interrupted. Under ``python -m``, CPython ends the process by SIGINT at exit, whatever
        # the exit code, once a KeyboardInterrupt has left an ``exec`` of a string (a dataclass or
        # a Numba wrapper being made where the signal landed), even though it was caught later.
        # End here with the command's code (130), after the exit handlers.
        import atexit

        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(stop.code if isinstance(stop.code, int) else 1)
