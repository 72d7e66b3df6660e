"""Raw CAN frames in bulk: one array per field (:mod:`mountcal.io.can.files` reads them from any
python-can log format).

Every reader returns :class:`CanFrames`, a frozen table of n frames (data frames only: remote and
error frames carry no signal values and are not part of it). Conventions:

- ``t_s`` is in seconds on the log's clock, exactly as python-can's reader of the same format
  reports ``Message.timestamp`` (absolute Unix time for BLF and MF4, whatever the text file says for
  the text formats).
- ``channel`` is the channel number as python-can reports it: Vector's 1-based ``CAN 1`` in BLF and
  ASC becomes 0, an MF4 ``BusChannel`` is kept as the file gives it (CANedge ``CAN 2`` is 2), ``can1`` in a
  candump log is 1. Formats without a channel (CSV) give -1.
- ``dlc`` is the number of data bytes the frame carries in the log (python-can's ``len(Message.data)``: its
  ``Message.dlc`` where the two agree; for CAN FD the length, not the 4-bit code; a classic DLC of 9 to 15
  carries 8, a BLF CAN FD object's DLC more than its stored bytes carries those); ``data`` is zero-padded
  to 8 bytes, or to 64 when a frame is longer (CAN FD). A signal beyond ``dlc`` has no value (NaN), never
  the padding's zeros.

Speed: BLF is parsed here, not through python-can (whose ``BLFReader`` is kept only as the
cross-check of the tests): containers are inflated with ISA-L (``isal``, zlib-compatible and 1.7×
faster than zlib here) in a small thread pool, which releases the GIL;
a batch of them is first read as one strided record array while its objects repeat the first
one's size and kind (a classic CAN log is all 48-byte CAN_MESSAGEs); anything else goes through
a general scan that locates every ``LOBJ`` signature with numpy, verifies the object chain
vectorised and gathers the fields of the wanted frames with fancy indexing. MF4 bus logs are read
with asammdf's record arrays of raw values, each numeric field then through the file's conversion
for it (CANedge firmware 01.07+ stores ``BusChannel`` and ``IDE`` as 0-bit channels whose value is
the conversion's constant), as python-can's ``MF4Reader`` reads them. The text formats (ASC,
candump ``.log``, TRC, CSV) go through python-can's readers, batched into arrays; they are the slow
formats.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

DATA_WIDTH = 64  # the longest CAN FD payload: the widest CanFrames.data
CLASSIC_WIDTH = 8  # the narrowest: a log of classic frames only keeps 8 bytes per row


@dataclass(frozen=True)
class CanFrames:
    """A table of n CAN data frames, one array per field.

    Attributes
    ----------
    t_s : ndarray, shape (n,), float64
        Reception time in seconds on the log's clock.
    channel : ndarray, shape (n,), int64
        Bus channel as python-can numbers it; -1 where the format has none.
    arbitration_id : ndarray, shape (n,), uint32
        11- or 29-bit identifier (without flag bits).
    is_extended : ndarray, shape (n,), bool
        True for 29-bit identifiers.
    dlc : ndarray, shape (n,), uint8
        Number of data bytes the log holds for the frame (at most its DLC's length).
    data : ndarray, shape (n, w), uint8
        Payload, zero beyond ``dlc``; w is 8 when no frame is longer (classic CAN), up to 64 for
        CAN FD. Bytes past w read as zero.
    """

    t_s: FloatArray
    channel: IntArray
    arbitration_id: NDArray[np.uint32]
    is_extended: NDArray[np.bool_]
    dlc: NDArray[np.uint8]
    data: NDArray[np.uint8]

    def __post_init__(self) -> None:
        n = self.t_s.shape[0]
        for name in ("t_s", "channel", "arbitration_id", "is_extended", "dlc"):
            if getattr(self, name).shape != (n,):
                raise ValueError(f"CanFrames.{name} must have shape ({n},); got {getattr(self, name).shape}")
        if self.data.ndim != 2 or self.data.shape[0] != n or not CLASSIC_WIDTH <= self.data.shape[1] <= DATA_WIDTH:
            raise ValueError(f"CanFrames.data must have shape ({n}, 8 to {DATA_WIDTH}); got {self.data.shape}")

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @classmethod
    def empty(cls) -> CanFrames:
        """A table with no frames."""
        return cls(
            np.empty(0, np.float64),
            np.empty(0, np.int64),
            np.empty(0, np.uint32),
            np.empty(0, np.bool_),
            np.empty(0, np.uint8),
            np.empty((0, CLASSIC_WIDTH), np.uint8),
        )

    def take(self, index: NDArray[Any] | slice) -> CanFrames:
        """The frames selected by a boolean mask, an index array or a slice."""
        if isinstance(index, np.ndarray) and index.dtype == np.bool_:
            index = np.flatnonzero(index)  # once, not once per field
        data = self.data
        if not isinstance(index, slice) and data.flags.c_contiguous and data.shape[1] % 8 == 0:
            # rows as whole 8-byte words: a 1-D gather, several times faster than a row gather of bytes
            data = data.view(np.uint64)[index].view(np.uint8)
        else:
            data = data[index]
        return CanFrames(
            self.t_s[index],
            self.channel[index],
            self.arbitration_id[index],
            self.is_extended[index],
            self.dlc[index],
            data,
        )

    @classmethod
    def concat(cls, parts: Iterable[CanFrames]) -> CanFrames:
        """All frames of ``parts``, in order."""
        parts = [p for p in parts if len(p)]
        if not parts:
            return cls.empty()
        if len(parts) == 1:
            return parts[0]
        width = max(p.data.shape[1] for p in parts)
        return cls(
            np.concatenate([p.t_s for p in parts]),
            np.concatenate([p.channel for p in parts]),
            np.concatenate([p.arbitration_id for p in parts]),
            np.concatenate([p.is_extended for p in parts]),
            np.concatenate([p.dlc for p in parts]),
            np.concatenate([_widen(p.data, width) for p in parts]),
        )


def _widen(data: NDArray[np.uint8], width: int) -> NDArray[np.uint8]:
    """Payload rows zero-padded to ``width`` bytes."""
    if data.shape[1] == width:
        return data
    return np.pad(data, ((0, 0), (0, width - data.shape[1])))


# ---------------------------------------------------------------------------------------------
# Shared helpers


class Filter:
    """The frame selection of a reader: arbitration ids and a channel, both optional."""

    def __init__(self, ids: Collection[int] | None, channel: int | None) -> None:
        self.ids = None if ids is None else np.unique(np.asarray(list(ids), dtype=np.uint32))
        self.channel = channel
        self._table: NDArray[np.bool_] | None = None
        if self.ids is not None and (self.ids.shape[0] == 0 or self.ids[-1] < 2048):
            self._table = np.zeros(2048 + 1, np.bool_)  # 11-bit ids: one lookup instead of isin
            self._table[self.ids] = True

    def id_mask(self, arbitration_id: NDArray[Any]) -> NDArray[np.bool_] | None:
        """Which frames have a wanted id, or None for all."""
        if self.ids is None:
            return None
        if self._table is not None:
            return np.asarray(self._table[np.minimum(arbitration_id, 2048)], dtype=np.bool_)
        return np.isin(arbitration_id, self.ids)

    def mask(self, arbitration_id: NDArray[Any], channel: IntArray) -> NDArray[np.bool_] | None:
        """Which frames to keep, or None for all."""
        mask = self.id_mask(arbitration_id)
        if self.channel is not None:
            on_channel = channel == self.channel
            mask = on_channel if mask is None else mask & on_channel
        return mask


def pad_payload(payload: NDArray[np.uint8], length: NDArray[Any]) -> NDArray[np.uint8]:
    """Payload bytes (m, w) as (m, 8) when no row is longer than 8 bytes, else (m, 64); zero from
    ``length`` on."""
    m, width = payload.shape
    width = min(width, DATA_WIDTH)
    out_width = CLASSIC_WIDTH if width <= CLASSIC_WIDTH or length.max(initial=0) <= CLASSIC_WIDTH else DATA_WIDTH
    width = min(width, out_width)
    out = np.zeros((m, out_width), np.uint8)
    np.multiply(payload[:, :width], np.arange(width)[None, :] < length[:, None], out=out[:, :width], casting="unsafe")
    return out


__all__ = ["CLASSIC_WIDTH", "DATA_WIDTH", "CanFrames", "Filter", "pad_payload"]
