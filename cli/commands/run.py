"""`potflat run` (placeholder until the stage lands)."""
from __future__ import annotations

from potflat_cli._errors import fail


def run_command() -> None:
    """Not available yet."""
    raise fail("'potflat run' is not implemented yet")
