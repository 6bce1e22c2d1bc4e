"""`potflat bake` (placeholder until the stage lands)."""
from __future__ import annotations

from potflat_cli._errors import fail


def bake_command() -> None:
    """Not available yet."""
    raise fail("'potflat bake' is not implemented yet")
