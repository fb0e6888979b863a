"""Lazy package attributes (PEP 562): a package names the module that defines each of its public
names, and that module is imported when the name is first used, so importing the package stays
cheap (the command line answers ``--help`` without loading torch or Lightning)."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable, Mapping
from typing import Any

__all__ = ["lazy_attributes"]


def lazy_attributes(
    package: str, names: Mapping[str, str], namespace: dict[str, Any], subpackages: Iterable[str] = ()
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``(__getattr__, __dir__)`` for ``package``: ``names`` maps a public name to the module
    that defines it, relative to the package (``".core"``); ``subpackages`` are reachable as
    attributes without importing them first. A name, once imported, is stored in ``namespace``
    (the package's ``globals()``), so later look-ups skip ``__getattr__``."""
    subpackages = tuple(subpackages)

    def __getattr__(name: str) -> Any:
        if name in subpackages:
            return importlib.import_module(f".{name}", package)
        if name not in names:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(names[name], package), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted({*namespace, *names, *subpackages})

    return __getattr__, __dir__
