"""Lazy re-exports of a package: names resolved from its modules on first use."""
from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any


def lazy_exports(package: str, names: dict[str, str]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``package`` resolving each of ``names`` (name to module
    path, relative to ``package`` like ``".unroll"`` or absolute) on first access, so
    importing the package, or one light module of it, does not import its heavy modules."""

    def __getattr__(name: str) -> Any:
        if name in names:
            return getattr(importlib.import_module(names[name], package), name)
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__
