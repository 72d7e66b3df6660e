"""CAN logs in the registry (:mod:`mountcal.io.registry`): every python-can / asammdf format, with a DBC."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.io.reader import LogReader

if TYPE_CHECKING:
    from mountcal.io.reader import LogOptions
    from mountcal.io.samples import LogSummary, Samples

CAN_SUFFIXES = (".blf", ".asc", ".log", ".trc", ".mf4", ".mdf")  # always CAN; a .csv is CAN with a DBC


class CanReader(LogReader):
    name = "can"
    suffixes = (*CAN_SUFFIXES, ".csv")
    description = "CAN (BLF, ASC, candump log, TRC, MF4; CSV with --dbc) decoded with a DBC"

    def claims(self, path: Path, options: LogOptions) -> bool:
        suffix = path.suffix.lower()
        return suffix in CAN_SUFFIXES or (suffix == ".csv" and options.dbc is not None)

    def read(self, path: Path, options: LogOptions) -> Samples:
        from mountcal.io.can.read import read_can

        return _clocked(read_can(path, _dbc(path, options), mapping=options.mapping, channel=options.channel), path)

    def iter_chunks(self, path: Path, options: LogOptions, max_samples: int) -> Iterator[Samples]:
        from mountcal.io.can.read import iter_can

        dbc = _dbc(path, options)
        chunks = iter_can(path, dbc, mapping=options.mapping, channel=options.channel, max_samples=max_samples)
        return (_clocked(chunk, path) for chunk in chunks)

    def inspect(self, path: Path, options: LogOptions) -> LogSummary:
        from mountcal.io.can.read import inspect_can

        return inspect_can(path, options.dbc)  # without a DBC: ids per channel


def _clocked(samples: Samples, path: Path) -> Samples:
    """The samples saying their clock where an MF4's header keeps local time (read as UTC, the same on every
    machine: :func:`mountcal.io.can.mf4.start_s`); every other CAN log's clock goes without saying."""
    if path.suffix.lower() not in (".mf4", ".mdf"):
        return samples
    from mountcal.io.can.mf4 import local_time_header

    if not local_time_header(path):
        return samples
    from dataclasses import replace

    from mountcal.core.result import Convention

    clock = Convention(
        "clock",
        "the recorder's local time, its time zone not recorded; read as UTC (absolute times, such as a protocol "
        "sheet's or the fleet's dates, are then off by that zone's offset)",
        "stated",
        f"the MF4 header's local-time flag ({path.name})",
    )
    return replace(samples, conventions=(*samples.conventions, clock))


def _dbc(path: Path, options: LogOptions) -> str | tuple[str, ...]:
    if options.dbc is None:
        raise InputError(
            str(path),
            "a DBC to decode this CAN log",
            f"no {option('dbc')}",
            f"Pass the DBC file as {option('dbc')} (and the signal mapping as {option('mapping')} when the signals "
            "are not named plainly).",
        )
    return options.dbc


__all__ = ["CAN_SUFFIXES", "CanReader"]
