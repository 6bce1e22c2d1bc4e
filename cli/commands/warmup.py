"""`potflat warmup`: compile and cache potflat's kernels now, before the first run needs them."""
from __future__ import annotations

from potflat_cli._errors import check_stop, user_errors
from potflat_cli._options import Quiet

HELP = """Compile and cache potflat's kernels now, so that no run waits for them: after installing, or in a cluster job before a batch (every later process loads them from the cache, a batch's workers too).

Rolls out, relaxes and bakes a generated painted vessel in a temporary folder, removed afterwards (the relax kernels compile meanwhile in a second process); nothing else is written but Numba's cache (NUMBA_CACHE_DIR if set, else the package's __pycache__ folders). Exit codes: 0 success, 130 interrupted.

Example:  potflat warmup
"""


@user_errors
def warmup_command(quiet: Quiet = False) -> None:
    """Compile and cache potflat's kernels now."""
    # imported here, not at the top: 'potflat --help' stays free of Numba and SciPy
    import shutil
    import tempfile
    import time
    from pathlib import Path

    from rich.console import Console

    from potflat_cli import _warmup as potflat_warmup
    from potflat_cli._stage import PROGRESS, StageLog, with_compile_note

    err = Console(stderr=True, quiet=quiet)
    log = StageLog(err)
    started = time.perf_counter()
    child = potflat_warmup.start()  # the relax kernels on the second core (None: already cached)
    folder = Path(tempfile.mkdtemp(prefix="potflat-warmup-"))
    try:
        with err.status(with_compile_note("warming up")) as status:
            def progress(stage: str) -> None:
                check_stop()
                status.update(with_compile_note(f"warming up: {stage}"))
                log.start(f"warming up: {stage}")

            potflat_warmup.warm_everything(folder, progress)
            log.end()
    finally:
        if child is not None:
            child.stop()
        shutil.rmtree(folder, ignore_errors=True)
    err.print(f"{PROGRESS}kernels compiled and cached in {time.perf_counter() - started:.0f} s; runs load them from "
              "now on", highlight=False)


warmup_command.__doc__ = HELP
