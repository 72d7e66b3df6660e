"""Package exports that load on first use, so that ``import mountcal`` costs milliseconds."""

from __future__ import annotations

import importlib
import sys
import types
from collections.abc import Mapping
from typing import Any


def install(package: str, homes: Mapping[str, str]) -> None:
    """Make the names of ``homes`` (name → the module defining it) attributes of ``package`` that
    are imported on first access (PEP 562 style) and then kept.

    A submodule named like an export (``mountcal.calibrate`` beside the function ``calibrate``)
    does not replace the export when it is imported, as it would on a plain package.
    """

    class LazyPackage(types.ModuleType):
        def __getattr__(self, name: str) -> Any:
            home = homes.get(name)
            if home is None:
                raise AttributeError(f"module {package!r} has no attribute {name!r}")
            value = getattr(importlib.import_module(home), name)
            types.ModuleType.__setattr__(self, name, value)
            return value

        def __setattr__(self, name: str, value: Any) -> None:
            if name in homes and isinstance(value, types.ModuleType):
                return  # the import system binding a submodule: the export keeps the name
            types.ModuleType.__setattr__(self, name, value)

        def __dir__(self) -> list[str]:
            return sorted({*self.__dict__, *homes})

    sys.modules[package].__class__ = LazyPackage


__all__ = ["install"]
