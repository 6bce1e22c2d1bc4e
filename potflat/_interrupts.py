"""Interrupts (Ctrl-C, SIGTERM) that never land inside Numba's compiler.

A Python signal handler runs in the main thread between two of its bytecodes, wherever that
is. Raised inside Numba's compiler or its on-disk cache loader (a kernel's first call in a
process), a KeyboardInterrupt can leave a kernel half-linked into the JIT engine; a kernel
loaded afterwards then has its environment written through a null address and the process
dies of a segmentation fault instead of cleaning up. :func:`raise_interrupt`, the handler that
applications install (the ``potflat`` command and the batch's worker processes), raises
KeyboardInterrupt at once anywhere else and, inside the compiler, as soon as the compiler has
returned: a kernel loads in milliseconds, one compiles in seconds.
"""
from __future__ import annotations

import os
import signal
import sys

#: Packages whose Python code compiles and loads kernels.
COMPILER_PACKAGES = ("numba", "llvmlite")
#: Seconds between the checks whether a deferred interrupt can be raised.
RECHECK_S = 0.005


def in_compiler(frame) -> bool:
    """Whether ``frame`` or one of its callers runs code of :data:`COMPILER_PACKAGES` (only
    those already imported count).

    Parameters
    ----------
    frame : frame or None
        The frame a signal handler was given.
    """
    folders = tuple(os.path.dirname(module.__file__) + os.sep for name in COMPILER_PACKAGES
                    if getattr(module := sys.modules.get(name), "__file__", None))
    while folders and frame is not None:
        if frame.f_code.co_filename.startswith(folders):
            return True
        frame = frame.f_back
    return False


def raise_interrupt(signum: int, frame) -> None:
    """Signal handler: raise KeyboardInterrupt where the main thread is, or, when that is inside
    the compiler (:func:`in_compiler`), check again every :data:`RECHECK_S` seconds (SIGALRM)
    and raise once it has left. Where there is no interval timer (Windows), at once."""
    if signum == getattr(signal, "SIGALRM", None):
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
    if hasattr(signal, "setitimer") and in_compiler(frame):
        signal.signal(signal.SIGALRM, raise_interrupt)
        signal.setitimer(signal.ITIMER_REAL, RECHECK_S)
        return
    raise KeyboardInterrupt


def ignore_interrupts() -> None:
    """Ignore Ctrl-C and SIGTERM from now on and drop an interrupt :func:`raise_interrupt` has
    deferred (the end of a process whose work is done)."""
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)
    if hasattr(signal, "setitimer"):
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
