"""`potflat rollout` (placeholder until the stage lands)."""
from __future__ import annotations

from potflat_cli._errors import fail


def rollout_command() -> None:
    """Not available yet."""
    raise fail("'potflat rollout' is not implemented yet")
