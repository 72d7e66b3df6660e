"""Package exports that load on first use, so that ``import mountcal`` costs milliseconds."""

from __future__ import annotations

import importlib
import sys
import types
from collections.abc import Mapping
from typing import Any


def install(package: str, homes: Mapping[str, str]) -> None:
    """Make the names of ``homes`` (name → the module defining it) attributes of ``package`` that
    are imported on first access (PEP 562 style) and then kept. No export is named like a submodule
    (the layout test checks it), so importing a submodule never replaces an export.
    """

    class LazyPackage(types.ModuleType):
        def __getattr__(self, name: str) -> Any:
            home = homes.get(name)
            if home is None:
                raise AttributeError(f"module {package!r} has no attribute {name!r}")
            value = getattr(importlib.import_module(home), name)
            types.ModuleType.__setattr__(self, name, value)
            return value

        def __dir__(self) -> list[str]:
            return sorted({*self.__dict__, *homes})

    sys.modules[package].__class__ = LazyPackage


__all__ = ["install"]
