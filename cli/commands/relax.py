"""`potflat relax` (placeholder until the stage lands)."""
from __future__ import annotations

from potflat_cli._errors import fail


def relax_command() -> None:
    """Not available yet."""
    raise fail("'potflat relax' is not implemented yet")
