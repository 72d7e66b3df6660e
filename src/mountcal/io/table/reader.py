"""Sample tables in the registry (:mod:`mountcal.io.registry`): CSV and Parquet with ``t_s, ax, ay, az``."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from mountcal.io.reader import LogReader

if TYPE_CHECKING:
    from mountcal.io.logs import LogOptions
    from mountcal.samples import LogSummary, Samples


class TableReader(LogReader):
    name = "table"
    suffixes = (".csv", ".parquet", ".pq")
    description = "CSV or Parquet sample table (t_s, ax, ay, az)"

    def read(self, path: Path, options: LogOptions) -> Samples:
        from mountcal.io.table.read import read_table

        return read_table(path)

    def iter_chunks(self, path: Path, options: LogOptions, max_samples: int) -> Iterator[Samples]:
        from mountcal.io.table.read import iter_table

        return iter_table(path, max_samples)

    def inspect(self, path: Path, options: LogOptions) -> LogSummary:
        from mountcal.samples import summary

        return summary(self.read(path, options), path.suffix.lstrip(".").lower(), "table")


__all__ = ["TableReader"]
