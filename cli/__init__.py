"""The ``potflat`` command line (installed as the package ``potflat_cli``).

An interrupt is one line and exit code 130 from the command's first instruction: while the
command imports itself (a second or so, before :class:`potflat_cli.main._Group` takes over
the signals), Ctrl-C or SIGTERM ends it at once, nothing having been written yet.
"""
import os as _os
import signal as _signal
import sys as _sys

#: What an interrupted command says.
INTERRUPTED = ("interrupted; no output is half-written or mixed with an earlier run's (an earlier run's outputs "
               "are restored; without one, the stages finished are kept)")


def _stopped_while_starting(signum, frame) -> None:
    _os.write(2, f"error: {INTERRUPTED}\n".encode())
    _os._exit(130)


def _is_the_command() -> bool:
    """Whether this process is the ``potflat`` command (the console script or ``python -m
    potflat_cli``), not a program importing the package."""
    argv = getattr(_sys, "orig_argv", [])
    return _os.path.basename(_sys.argv[0]) in ("potflat", "potflat.exe") or argv[1:3] == ["-m", "potflat_cli"]


if _is_the_command():
    for _sig in (_signal.SIGINT, _signal.SIGTERM):
        _signal.signal(_sig, _stopped_while_starting)
