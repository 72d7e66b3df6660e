"""The clock of a ROS topic's ``header.stamp``, against the recorder's (an MCAP ``log_time``, a bag's record time).

A driver stamps its messages with whatever clock it has: Unix time, or often the device's or the computer's
boot time (seconds since power-on), while the recorder times every message on receipt in Unix time. A
topic stamped on another clock than the others does not overlap them (a speed lost, a drive that looks
parked) and dates nothing (a protocol sheet, the fleet's dates). Per topic, the offset ``record − stamp``
of its stamped messages (a sample of each block, gathered with numpy) tells which clock it is on:

- received within ``OTHER_CLOCK_S`` (60 s) after its stamp, and stamped no more than ``AHEAD_S`` (1 s) after its
  receipt: the same clock. Transport and queueing latency is milliseconds to a second or two, never negative; no
  boot clock is that close to Unix time. Left as stamped. Stamps steadily ahead of their receipt (a GNSS
  receiver's GPS time, 18 s ahead of UTC) are on another clock: before, they were left 18 s off the other topics.
- further, on a recorder dated in Unix time, and either undated (before 2000-01-01: a boot or hardware
  clock) or beside another topic on the recorder's clock: moved onto the recorder's clock by its median
  offset, one constant, so the stamps keep their own spacing; said as the convention ``stamp_clock``
  (**inferred**). A topic whose stamps are dated but all far from the recorder's, with no topic on it,
  is left: a log recorded again from a replay has every stamp so, rightly.
- not moved where the offset is not steady (the 5th to 95th percentiles more than ``STEADY_S`` apart: a
  clock that jumped, a resync), or where some of its messages carry no stamp (timed by the recorder:
  two clocks in one topic); topics left on different clocks are said in a note.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from mountcal.core.result import Convention
from mountcal.io.samples import Channel, Samples

I64Array = NDArray[np.int64]
NS = 1_000_000_000
DATED_S = 946_684_800.0  # 2000-01-01 UTC: stamps before it, beside a dated recorder, are on a boot clock
OTHER_CLOCK_S = 60.0  # beyond any transport latency, far below any boot clock's distance from Unix time
AHEAD_S = 1.0  # stamps later than their receipt by more than this are on another clock (no latency is negative)
STEADY_S = 10.0  # a steady clock's offset spread (latency jitter, crystal drift over hours) stays below
KEEP_PER_BLOCK = 64  # offsets kept of each block: enough for percentiles, bounded memory on long logs


@dataclass
class _Topic:
    offsets: list[I64Array] = field(default_factory=list)  # record − stamp, ns, a strided sample per block
    records: list[I64Array] = field(default_factory=list)  # their record times, ns
    stamped: int = 0
    unset: int = 0


@dataclass(frozen=True)
class _Clock:
    topic: str
    offset_s: float  # median record − stamp
    spread_s: float  # 5th to 95th percentile of the offset
    off_steady: float  # fraction of the sampled offsets further than STEADY_S from the median
    first_stamp_s: float
    stamps_dated: bool
    records_dated: bool
    unset: int


class StampClocks:
    """Per topic, ``header.stamp`` against the record time, gathered a block at a time; which samples'
    keys (``"imu"``, ``Samples.channels``) each topic gave."""

    def __init__(self, record_name: str, max_blocks: int | None = None) -> None:
        self.record_name = record_name  # "log_time", "the bag's record time"
        self.max_blocks = max_blocks  # a stream's bound: each topic judged on its first blocks (a steady clock shows)
        self._topics: dict[str, _Topic] = {}
        self._keys: dict[str, str] = {}

    def add(self, topic: str, sec: I64Array, nanosec: I64Array, record_ns: I64Array, keys: Iterable[str]) -> None:
        """One block's messages of ``topic``: stamps (``sec``, ``nanosec``) and record times (ns)."""
        tally = self._topics.setdefault(topic, _Topic())
        for key in keys:
            self._keys.setdefault(key, topic)
        if self.max_blocks is not None and len(tally.offsets) >= self.max_blocks:
            return
        stamp = sec.astype(np.int64) * NS + nanosec.astype(np.int64)
        record = record_ns.astype(np.int64)
        unset = stamp == 0  # timed by the recorder (see the readers' stamp rule)
        n_unset = int(np.count_nonzero(unset))
        if n_unset:
            stamp, record = stamp[~unset], record[~unset]
        tally.unset += n_unset
        tally.stamped += stamp.size
        if stamp.size:
            step = max(1, stamp.size // KEEP_PER_BLOCK)
            tally.offsets.append(record[::step] - stamp[::step])
            tally.records.append(record[::step])

    def _clocks(self) -> list[_Clock]:
        out = []
        for topic, tally in self._topics.items():
            if not tally.stamped:
                continue
            offsets = np.concatenate(tally.offsets)
            records = np.concatenate(tally.records)
            median = int(np.median(offsets))
            lo, hi = np.percentile(offsets, [5.0, 95.0])
            out.append(
                _Clock(
                    topic,
                    median / NS,
                    float(hi - lo) / NS,
                    float(np.mean(np.abs(offsets - median) > STEADY_S * NS)),
                    float(records[0] - offsets[0]) / NS,
                    float(np.median(records - offsets)) / NS >= DATED_S,
                    float(np.median(records)) / NS >= DATED_S,
                    tally.unset,
                )
            )
        return out

    def settle(self, samples: Samples) -> Samples:
        """``samples`` with the topics on another clock moved onto the recorder's and said (module doc);
        unchanged when every topic is on it."""
        clocks = self._clocks()
        near = [c for c in clocks if _on_recorder(c)]
        shifts: dict[str, float] = {}
        said, notes = [], []
        for c in clocks:
            if _on_recorder(c):
                if c.spread_s > STEADY_S:
                    notes.append(_unsteady(c, self.record_name))
                continue
            if not c.records_dated or (c.stamps_dated and not near and not _ahead(c)):
                continue  # which clock is right, the data cannot tell (a replay); said below if topics disagree
            if c.spread_s > STEADY_S:
                notes.append(_unsteady(c, self.record_name))
            elif c.unset:
                notes.append(
                    f"header.stamp of {c.topic} is {c.offset_s:+.3f} s from the recorder's clock ({self.record_name}), "
                    f"but {c.unset} of its messages carry no stamp (timed by the recorder): two clocks in one topic, "
                    "times left as they are"
                )
            else:
                shifts[c.topic] = c.offset_s
                said.append(_moved(c))
        left = {c.topic: c.offset_s - shifts.get(c.topic, 0.0) for c in clocks}
        if left and max(left.values()) - min(left.values()) > OTHER_CLOCK_S:
            apart = ", ".join(f"{t} {o:+.3f} s" for t, o in left.items())
            notes.append(
                f"the topics read are on different clocks ({self.record_name} − header.stamp: {apart}): their samples "
                "may not overlap in time (a speed or heading lost, a drive taken for a stop)"
            )
        if not shifts and not notes:
            return samples
        conventions = samples.conventions
        if said:
            by = f"header.stamp against {self.record_name}"
            conventions = (*conventions, Convention("stamp_clock", "; ".join(said), "inferred", by))
        return replace(
            samples,
            t_s=self._moved(samples.t_s, "imu", shifts),
            channels={k: Channel(self._moved(c.t_s, k, shifts), c.value) for k, c in samples.channels.items()},
            notes=(*samples.notes, *notes),
            conventions=conventions,
        )

    def _moved(self, t_s: NDArray[np.float64], key: str, shifts: dict[str, float]) -> NDArray[np.float64]:
        shift = shifts.get(self._keys.get(key, ""), 0.0)
        return t_s + shift if shift else t_s


def _on_recorder(c: _Clock) -> bool:
    """Whether a topic's stamps are on the recorder's clock: received within OTHER_CLOCK_S after their stamp, and
    not stamped more than AHEAD_S after their receipt (which no one clock does: a GNSS receiver's GPS time, 18 s
    ahead of UTC, or a driver's computer whose clock is ahead)."""
    return -AHEAD_S <= c.offset_s <= OTHER_CLOCK_S


def _ahead(c: _Clock) -> bool:
    """Whether a topic's stamps are steadily ahead of their receipt: never the recorder's clock, nor a replay's
    (whose stamps lie in the past), so moved onto the recorder's also where no topic is on it."""
    return -OTHER_CLOCK_S <= c.offset_s < -AHEAD_S


def _moved(c: _Clock) -> str:
    clock = "a clock that dates nothing (boot or device time)" if not c.stamps_dated else "another clock"
    if c.stamps_dated and _ahead(c):
        clock = (
            f"another clock, {-c.offset_s:.3f} s ahead of the recorder's (stamped after it was received: GPS time "
            "runs 18 s ahead of UTC)"
        )
    return (
        f"header.stamp of {c.topic} on {clock}, first stamp {c.first_stamp_s:.3f} s: moved onto the recorder's "
        f"clock (Unix time) by its median offset {c.offset_s:+.3f} s"
    )


def _unsteady(c: _Clock, record_name: str) -> str:
    return (
        f"header.stamp of {c.topic} against {record_name} is not steady: the offset spreads over {c.spread_s:.1f} s "
        f"(5th–95th percentile; median {c.offset_s:+.3f} s), {100 * c.off_steady:.0f} % of its messages more than "
        f"{STEADY_S:g} s from the median: a clock that jumped; times left as stamped"
    )


__all__ = ["AHEAD_S", "DATED_S", "OTHER_CLOCK_S", "STEADY_S", "StampClocks"]
