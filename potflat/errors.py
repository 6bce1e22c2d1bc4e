"""Exceptions raised by potflat.

Every error that a user can cause (bad file, bad option) is a :class:`PotflatError`
whose message is one line saying what is wrong, which file, and what to do. The CLI
maps these to exit code 2 and prints only the message.
"""
from __future__ import annotations


class PotflatError(Exception):
    """Base class of all user-facing potflat errors (CLI exit code 2)."""


class InvalidInputError(PotflatError, ValueError):
    """An input file or array cannot be used (corrupt, empty, NaN, wrong shape...)."""


class InvalidOptionError(PotflatError, ValueError):
    """An option has a value outside its valid range or of the wrong type."""


class AxisNotFoundError(PotflatError):
    """No rotation axis fits the scan well enough; give one with ``axis=``."""


class FoldedResultError(PotflatError):
    """A flattening result would contain flipped triangles or boundary overlap."""


def out_of_memory(path) -> InvalidInputError:
    """The one-line error for running out of memory on the input ``path`` (a
    :class:`MemoryError` anywhere while it is read or flattened)."""
    import os

    try:
        size = os.stat(path).st_size
        shown = f" ({size / 1024**3:.1f} GiB)" if size >= 1024**3 else f" ({size / 1024**2:.0f} MiB)"
    except (OSError, TypeError, ValueError):
        shown = ""
    return InvalidInputError(f"{path}{shown}: out of memory reading or flattening it; give a smaller file (decimate "
                             "the scan) or run where more memory is available")


class NotADiskError(FoldedResultError):
    """A rollout that no layout in the plane shows without a fold: it is not a disk (the relax
    stage's file layer adds what to do, from the rollout's record)."""
