"""What a ROS 1 bag holds (``mountcal inspect``): topics, types, counts, rates and fields, from its index
records alone (no chunk is decompressed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mountcal.io.bag import ros1
from mountcal.io.bag.read import ros1_topics
from mountcal.io.samples import LogSummary, Stream


def inspect_ros1(path: str | Path) -> LogSummary:
    """Topics with their type, message count, rate ((count − 1) / time span of its records) and fields."""
    bag = ros1.open_bag(path)
    try:
        spans = ros1.record_spans(bag)
        topics = ros1_topics(bag)
    except ros1.Corrupt as err:
        raise ros1.damaged(bag.where, str(err)) from err
    finally:
        bag.file.close()
    streams = []
    first_all, last_all = np.inf, -np.inf
    for name, topic in topics.items():
        seen = [spans[i] for i in topic.ids if i in spans]
        count = sum(s[0] for s in seen)
        first = min((s[1] for s in seen), default=0)
        last = max((s[2] for s in seen), default=0)
        if seen:
            first_all, last_all = min(first_all, first), max(last_all, last)
        rate = (count - 1) / ((last - first) * 1e-9) if count > 1 and last > first else 0.0
        fields = tuple(f for f, _ in topic.types[topic.type_name][1]) if topic.types is not None else ()
        streams.append(Stream(name, topic.type_name, count, rate, fields))
    duration = (last_all - first_all) * 1e-9 if last_all > first_all else 0.0
    return LogSummary(bag.where, "ros1 bag", float(duration), tuple(streams))


__all__ = ["inspect_ros1"]
