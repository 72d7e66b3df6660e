"""A live CAN bus through python-can: open it, record it to BLF, and hold its frames as :class:`CanFrames`."""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import can
import numpy as np
from can.util import channel2int

from mountcal.io.can.frames import CanFrames

BUS_ERRORS = (can.CanError, OSError, ValueError, ImportError)


def open_bus(interface: str, channel: str) -> Any:
    """A python-can bus (any interface: socketcan, virtual, pcan, vector, …)."""
    return can.Bus(interface=interface, channel=channel)


def recorder(path: Path) -> Any:
    """python-can's BLF writer: every frame as received; ``stop()`` closes the file."""
    return can.BLFWriter(str(path))


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

    def add(self, msg: Any) -> None:
        if self.start_ms is None:
            self.start_ms = int(msg.timestamp * 1000) / 1000  # BLFWriter's start (ms) and tick origin
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
