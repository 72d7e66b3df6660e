"""ROS bags in the registry (:mod:`mountcal.io.registry`): a ROS 1 ``.bag``, a ROS 2 bag folder, a lone
ROS 2 ``.db3``."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from mountcal.io.reader import LogReader

if TYPE_CHECKING:
    from mountcal.io.folder import Folder
    from mountcal.io.reader import LogOptions
    from mountcal.io.samples import LogSummary, Samples


class BagReader(LogReader):
    name = "bag"
    suffixes = (".bag", ".db3")
    description = "ROS 1 bag or ROS 2 bag folder (metadata.yaml with .db3 or .mcap)"

    def claims(self, path: Path, options: LogOptions) -> bool:
        if path.suffix.lower() in self.suffixes:
            return True
        from mountcal.io.bag.ros2 import bag_folder

        return bag_folder(path) is not None

    def claims_folder(self, folder: Folder, options: LogOptions) -> bool:
        from mountcal.io.bag.ros2 import holds_bag

        return holds_bag(folder)

    def read(self, path: Path, options: LogOptions) -> Samples:
        if path.suffix.lower() == ".bag":
            from mountcal.io.bag.read import read_ros1

            return read_ros1(path, topic=options.topic, field=options.field)
        from mountcal.io.bag.ros2 import read_ros2

        return read_ros2(path, topic=options.topic, field=options.field)

    def inspect(self, path: Path, options: LogOptions) -> LogSummary:
        if path.suffix.lower() == ".bag":
            from mountcal.io.bag.inspect import inspect_ros1

            return inspect_ros1(path)
        from mountcal.io.bag.ros2 import inspect_ros2

        return inspect_ros2(path)


__all__ = ["BagReader"]
