"""Turn user errors into one-line messages on stderr and exit code 2."""
from __future__ import annotations

import functools
import sys
from pathlib import Path

import typer

from potflat_cli import INTERRUPTED

#: Exit codes, documented in docs/cli.md.
EXIT_OK, EXIT_FAILED, EXIT_USAGE = 0, 1, 2
#: Signals received (SIGINT, SIGTERM): checked between stages, between a batch's results and
#: at the end, since the KeyboardInterrupt the handler raises is lost when it lands in a finaliser.
STOP: list[int] = []
#: Whether this command said it was interrupted (:func:`interrupted`: once).
TOLD: list[bool] = []


def interrupted() -> "typer.Exit":
    """Say :data:`INTERRUPTED` (once per command, whichever layer sees the stop first) and
    return the Exit (code 130) to raise."""
    if not TOLD:
        TOLD.append(True)
        print(f"error: {INTERRUPTED}", file=sys.stderr)
    return typer.Exit(code=130)


def check_stop() -> None:
    """Raise KeyboardInterrupt if a stop signal arrived (see :data:`STOP`)."""
    if STOP:
        raise KeyboardInterrupt


def fail(message: str, code: int = EXIT_USAGE) -> "typer.Exit":
    """Print ``error: message`` to stderr (on one line) and return the Exit to raise."""
    print(f"error: {one_line(message)}", file=sys.stderr)
    return typer.Exit(code=code)


def one_line(message: str) -> str:
    """``message`` with control characters escaped (a newline in a file name stays ``\\n``)."""
    return "".join(c if c.isprintable() else repr(c)[1:-1] for c in message)


def user_errors(func):
    """Decorator for command functions: PotflatError and file-system errors become exit code 2."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        from potflat.errors import PotflatError

        try:
            result = func(*args, **kwargs)
            check_stop()
            return result
        except KeyboardInterrupt:
            raise interrupted() from None
        except MemoryError:
            from potflat.errors import out_of_memory

            # the command's input: its first path argument (the scan, stage file or batch file)
            given = next((v for v in (*args, *kwargs.values()) if isinstance(v, Path)), "the input")
            raise fail(str(out_of_memory(given))) from None
        except Exception as exc:
            if STOP:  # whatever the interrupt broke: e.g. a Numba call it landed in raises SystemError
                raise interrupted() from None
            if isinstance(exc, PotflatError):
                raise fail(str(exc)) from None
            if isinstance(exc, (FileNotFoundError, PermissionError, IsADirectoryError, NotADirectoryError)):
                # e.g. an output folder under a regular file: -o notes.txt/out
                raise fail(f"{exc.filename}: {exc.strerror}; check the path (every folder in it must be a "
                           "writable folder)") from None
            if isinstance(exc, OSError):  # disk full, file too large, I/O error: outputs are never left half-written
                where = f"{exc.filename}: " if exc.filename else "writing the outputs: "
                raise fail(f"{where}{exc.strerror or exc}; check the free disk space, quotas and the output "
                           "folder, then run again") from None
            raise

    return wrapper
