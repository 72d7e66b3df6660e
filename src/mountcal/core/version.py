"""The installed mountcal version: one lookup, for provenance, output metadata, fleet keys and ``--version``."""

from __future__ import annotations

import importlib.metadata


def software_version() -> str:
    """The installed distribution's version ("unknown" when run from a source tree not installed)."""
    try:
        return importlib.metadata.version("mountcal")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


__version__ = software_version()
