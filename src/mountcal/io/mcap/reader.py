"""The MCAP format in the registry (:mod:`mountcal.io.registry`): ROS 2 Imu, CDR or JSON."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from mountcal.io.reader import LogReader

if TYPE_CHECKING:
    from mountcal.io.reader import LogOptions
    from mountcal.io.samples import LogSummary, Samples


class McapReader(LogReader):
    name = "mcap"
    suffixes = (".mcap",)
    description = "MCAP with ROS 2 sensor_msgs/Imu"

    def read(self, path: Path, options: LogOptions) -> Samples:
        if options.field is not None:  # an Imu or Vector3 inside another message: read by its definition
            from mountcal.io.mcap.topics import read_mcap_topics

            return read_mcap_topics(path, topic=options.topic, field=options.field)
        from mountcal.io.mcap.read import read_mcap

        return read_mcap(path, topic=options.topic)

    def iter_chunks(self, path: Path, options: LogOptions, max_samples: int) -> Iterator[Samples]:
        if options.field is not None:
            return super().iter_chunks(path, options, max_samples)
        from mountcal.io.mcap.read import iter_mcap

        return iter_mcap(path, topic=options.topic, max_samples=max_samples)

    def inspect(self, path: Path, options: LogOptions) -> LogSummary:
        from mountcal.io.mcap.inspect import inspect_mcap

        return inspect_mcap(path)


__all__ = ["McapReader"]
