"""The installed mountcal version: one lookup, for provenance, output metadata, fleet keys and ``--version``."""

from __future__ import annotations

import functools
import importlib.metadata


@functools.cache  # a metadata lookup costs ~0.4 ms, and a fleet asks once per log for its key
def software_version() -> str:
    """The installed distribution's version ("unknown" when run from a source tree not installed)."""
    try:
        return importlib.metadata.version("mountcal")
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


__version__ = software_version()
