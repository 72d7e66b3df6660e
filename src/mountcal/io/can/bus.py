"""A live CAN bus through python-can: open it, record it to BLF, and hold its frames as :class:`CanFrames`."""

from __future__ import annotations

import math
import struct
from collections import Counter
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import can
import numpy as np
from can.util import channel2int

from mountcal.core.atomic import GrowingFile
from mountcal.io.can.frames import CanFrames

# What a BLF file can stamp: SYSTEMTIME's years (to 9999) for the start and the last frame, and
# unsigned 64-bit nanoseconds from the start. Stamps before 1970 are refused as well: a bus
# clock (Unix time, or time since the interface started) is never negative.
LAST_STAMP_S = datetime(9999, 12, 31, 23, 59, 59, tzinfo=UTC).timestamp()
LONGEST_S = (2**64 - 1) / 1e9
BLF_FIRST_START_S = 631152000.0  # 1990: python-can's BLFWriter writes an earlier start as none (zeros)
_BLF_OBJECT_HEADER = 16  # signature, sizes, type: zeros there end a BLF file for a reader
_LARGEST_OBJECT = 1024  # bytes: BLFWriter's objects are at most ~120 (a CAN FD frame of 64 bytes)

BUS_ERRORS = (can.CanError, OSError, ValueError, ImportError)


def open_bus(interface: str, channel: str) -> Any:
    """A python-can bus (any interface: socketcan, virtual, pcan, vector, …)."""
    return can.Bus(interface=interface, channel=channel)


class Recording:
    """A session's BLF recording (python-can's ``BLFWriter``), readable at every moment.

    The writer's log containers reach the file whole, each holding whole frames (flushed before
    python-can would cut a frame between two containers) and followed by the file header rewritten
    to cover it (:class:`~mountcal.core.atomic.GrowingFile`): a session killed at any point leaves a BLF
    of every frame up to the last container written (≈ 2 700 classic frames each), and a full disk
    cuts the file back to that and raises :class:`~mountcal.core.paths.SystemFailure` saying so.
    :meth:`add` refuses (and counts) a frame the format cannot hold, rather than losing the session
    to the writer's exception.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.file = GrowingFile(path, "the recording", hidden=_BLF_OBJECT_HEADER)
        try:
            self.writer = can.BLFWriter(self.file)  # type: ignore[arg-type]  # a file object, as python-can allows
            self.file.commit()
        except BaseException:
            self.file.close()
            raise
        self.refused: Counter[str] = Counter()

    def add(self, msg: Any) -> bool:
        """Record ``msg``; False (and counted in :attr:`refused`) when its stamp or fields cannot be written."""
        t = msg.timestamp
        start = self.writer.start_timestamp
        if not (math.isfinite(t) and 0.0 <= t <= LAST_STAMP_S and (start is None or t - start < LONGEST_S)):
            self.refused[
                "frames with a timestamp a BLF recording cannot hold (not finite, before 1970 or after 9999)"
            ] += 1
            return False
        try:
            self.writer.on_message_received(msg)
        except (struct.error, ValueError, OverflowError, TypeError) as err:
            self.refused[f"frames the BLF writer refused ({type(err).__name__})"] += 1
            return False
        buffered = self.writer.file_size() - self.file.tell()
        if buffered >= self.writer.max_container_size - _LARGEST_OBJECT:
            self.writer._flush()  # now, whole objects: python-can's own flush cuts one across two containers
        if self.file.pending:  # a container was written: header after it, both whole in the file
            self._rewrite_header()
            self.file.commit()
        return True

    def _rewrite_header(self) -> None:
        end = self.file.tell()
        self.file.seek(0)
        self.writer._write_header(end)  # what BLFWriter.stop writes, kept current
        self.file.seek(end)

    def close(self) -> None:
        """The last container and the final header; the file closed (also after a failed write)."""
        if self.file.failed:
            self.file.close()
            return
        self.writer.stop()  # flushes, rewrites the header, closes the file (which commits)


class BusFrames:
    """Received frames as growing lists; timestamps as the BLF recording will return them."""

    def __init__(self) -> None:
        self.t: list[float] = []
        self.channel: list[int] = []
        self.ident: list[int] = []
        self.ext: list[bool] = []
        self.dlc: list[int] = []
        self.data: list[bytes] = []
        self.start_ms: float | None = None
        self.start_read: float = 0.0
        self.last_t = -np.inf
        self.count = 0
        self._held = CanFrames.empty()  # frames already turned into arrays

    def add(self, msg: Any, start_s: float | None = None) -> None:
        """Hold ``msg``; ``start_s`` is the recording's start (BLFWriter's, set by the first frame it wrote)."""
        if self.start_ms is None:
            self.start_ms = int(msg.timestamp * 1000) / 1000 if start_s is None else start_s  # BLFWriter's tick origin
            if self.start_ms < BLF_FIRST_START_S:  # python-can writes no start before 1990: it reads back as 0
                self.start_read = 0.0
            else:
                whole = datetime.fromtimestamp(round(self.start_ms, 3), tz=UTC)
                self.start_read = whole.replace(microsecond=whole.microsecond // 1000 * 1000).timestamp()
        ticks = max(int((msg.timestamp - self.start_ms) * 1e9), 0)
        self.last_t = ticks / 1e9 + self.start_read
        self.count += 1
        self.t.append(self.last_t)
        ch = channel2int(msg.channel)
        self.channel.append(0 if ch is None else ch)
        self.ident.append(msg.arbitration_id)
        self.ext.append(bool(msg.is_extended_id))
        self.dlc.append(len(msg.data))
        self.data.append(bytes(msg.data))

    def table(self) -> CanFrames:
        """Every frame so far (the new ones converted once, in one batch)."""
        if self.t:
            self._held = CanFrames.concat([self._held, self._batch()])
            for part in (self.t, self.channel, self.ident, self.ext, self.dlc, self.data):
                part.clear()
        return self._held

    def _batch(self) -> CanFrames:
        n = len(self.t)
        width = max(8, max((len(d) for d in self.data), default=8))
        buf = np.zeros((n, width), np.uint8)
        flat = np.frombuffer(b"".join(self.data), np.uint8)
        lengths = np.asarray(self.dlc, np.int64)
        rows = np.repeat(np.arange(n), lengths)
        cols = np.arange(flat.size) - np.repeat(np.cumsum(lengths) - lengths, lengths)
        buf[rows, cols] = flat
        return CanFrames(
            np.asarray(self.t, np.float64),
            np.asarray(self.channel, np.int64),
            np.asarray(self.ident, np.uint32),
            np.asarray(self.ext, np.bool_),
            np.asarray(self.dlc, np.uint8),
            buf,
        )
