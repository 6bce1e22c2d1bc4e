"""What the ``potflat`` command sets for its own process, which the library never sets on its
own: OpenMP's passive wait and the stages' heap tuning."""
from __future__ import annotations

import contextlib
import os

#: OpenMP's wait policy for the command and the processes it starts (batch workers, the
#: warm-up): threads sleep between parallel regions instead of spinning, which on a shared
#: machine made the relax solver up to 20x faster (docs/performance.md). Read by OpenMP when
#: Numba first starts its thread pool, so set before any kernel runs; the user's own wins.
WAIT_POLICY = ("OMP_WAIT_POLICY", "PASSIVE")


@contextlib.contextmanager
def command_settings():
    """Run a command with :data:`WAIT_POLICY` in the environment (unless the user set one)
    and the stages' heap tuning allowed (:func:`potflat._heap.heap_tuning`); both put back
    as they were afterwards, also on error. Blocks may nest."""
    from potflat._heap import heap_tuning

    name, value = WAIT_POLICY
    added = name not in os.environ
    if added:
        os.environ[name] = value
    try:
        with heap_tuning():
            yield
    finally:
        if added:
            os.environ.pop(name, None)
