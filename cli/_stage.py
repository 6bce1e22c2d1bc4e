"""Running one stage from its command: a status line on stderr, ``--json`` on stdout."""
from __future__ import annotations

import json
from collections.abc import Callable


def with_compile_note(status: str) -> str:
    """``status`` plus a note when this run compiles the kernels (the first run is silent for
    about a minute otherwise)."""
    from potflat._jit import kernels_cached

    return status if kernels_cached() else f"{status} (first run: compiling potflat's kernels, about a minute, once)"


def run_stage(status: str | None, call: Callable, *, quiet: bool, as_json: bool):
    """Run ``call()`` (a ``run_<stage>_stage``) under a status spinner on stderr.

    ``status=None`` shows no spinner (for a stage that draws its own progress bar: rich
    allows one live display at a time).

    With ``as_json`` the stage's summary (without provenance) is printed to stdout.

    Returns
    -------
    StageOutput or None
        The result when a human-readable summary should follow, else ``None``.
    """
    from rich.console import Console

    if status is None:
        result = call()
    else:
        with Console(stderr=True, quiet=quiet or as_json).status(with_compile_note(status)):
            result = call()
    if as_json:
        print(json.dumps({k: v for k, v in result.summary.items() if k != "provenance"}, indent=2))
        return None
    return None if quiet else result
