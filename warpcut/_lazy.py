"""Package attributes loaded on first use (PEP 562), so that importing a package stays light (no Warp, no
rerun) until a heavy name is asked for."""

from __future__ import annotations

import sys
from collections.abc import Callable
from importlib import import_module


def lazy_attributes(
    package: str, table: dict[str, str]
) -> tuple[Callable[[str], object], Callable[[], list]]:
    """``(__getattr__, __dir__)`` for ``package``: ``table`` maps a name to the module that defines it, which
    is imported when the name is first read (the value is then kept in the package)."""
    namespace = sys.modules[package].__dict__

    def __getattr__(name: str) -> object:  # noqa: N807 (the module hook's name)
        if name in table:
            value = getattr(import_module(table[name]), name)
            namespace[name] = value
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def __dir__() -> list:  # noqa: N807
        return sorted(set(namespace) | set(table))

    return __getattr__, __dir__
