"""`potflat batch` (placeholder until the stage lands)."""
from __future__ import annotations

from potflat_cli._errors import fail


def batch_command() -> None:
    """Not available yet."""
    raise fail("'potflat batch' is not implemented yet")
