"""``python -m potflat_cli``: the ``potflat`` command."""
import sys

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
    import os

    atexit._run_exitfuncs()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(stop.code if isinstance(stop.code, int) else 1)
