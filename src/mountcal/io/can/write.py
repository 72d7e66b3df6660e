"""CAN logs written by python-can (BLF, ASC, candump ``.log``, TRC, CSV; MF4 through its ``MF4Writer``),
every payload encoded by cantools from a DBC: the writing half of :mod:`mountcal.io.can`.

A value is converted from SI to its signal's DBC unit (:mod:`.signals`, the reader's table) and
clipped to the signal's range, as the sensor would saturate; the clipped values are counted.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from mountcal.core.errors import InputError
from mountcal.io.can.signals import UNIT_HINT, UNIT_KIND, message_refs, si_scale
from mountcal.io.samples import FloatArray


@dataclass
class EncodedMessage:
    """One CAN message's frames: times on the log's clock (s, before ``start_time_s``) and payloads."""

    message: Any  # cantools Message
    t_s: FloatArray
    data: list[bytes]


def resolve_signal(db: Any, text: str, role: str, where: str) -> tuple[Any, Any]:
    """The cantools message and signal of ``"message.signal"`` (message by name or id) to write ``role`` to."""
    message_text, _, signal_name = str(text).partition(".")
    messages = message_refs(db, message_text)
    signal = next((s for m in messages for s in m.signals if s.name == signal_name), None)
    if signal is None:
        raise InputError(
            where,
            f'a signal "{text}" for {role}',
            "no such message.signal in the DBC",
            "Pass the DBC the layout was made for, or name the signals with signals= (message.signal).",
        )
    message = next(m for m in messages if signal in m.signals)
    if signal.multiplexer_ids or message.is_multiplexed():
        raise InputError(where, f"a plain (not multiplexed) message for {role}", f"{message.name}", "Map another.")
    return message, signal


def signal_unit(signal: Any, role: str, where: str) -> tuple[float, float]:
    """(scale, offset) from the signal's DBC unit to SI; InputError for a unit of another quantity."""
    scale = si_scale(role, str(signal.unit or ""))
    if scale is None:
        kind = UNIT_KIND[role]
        raise InputError(
            where,
            f"a {kind} unit ({UNIT_HINT[kind]}) for {role} ({signal.name})",
            repr(signal.unit),
            "Use a DBC whose signal has one of these units.",
        )
    return scale


CAN_FORMATS = {".blf": "blf", ".asc": "asc", ".log": "log", ".trc": "trc", ".csv": "csv", ".mf4": "mf4"}


def can_format(path: str | os.PathLike[str], others: tuple[str, ...] = ()) -> str:
    """The CAN log format a path's suffix asks for; InputError when there is none (naming the
    ``others`` suffixes the caller also writes)."""
    suffix = Path(path).suffix.lower()
    if suffix not in CAN_FORMATS:
        raise InputError(
            str(path),
            f"a {'' if others else 'CAN '}log name ending in " + ", ".join((*others, *CAN_FORMATS)),
            f"a name ending in {suffix or '(nothing)'}",
            "Name the file by the format to write.",
        )
    return CAN_FORMATS[suffix]


def _range(signal: Any) -> tuple[float, float]:
    """The physical range a signal can be encoded in: its DBC minimum/maximum, else its raw range."""
    raw_lo = -(2 ** (signal.length - 1)) if signal.is_signed else 0
    raw_hi = 2 ** (signal.length - 1) - 1 if signal.is_signed else 2**signal.length - 1
    ends = sorted((raw_lo * signal.scale + signal.offset, raw_hi * signal.scale + signal.offset))
    lo = ends[0] if signal.minimum is None else max(float(signal.minimum), ends[0])
    hi = ends[1] if signal.maximum is None else min(float(signal.maximum), ends[1])
    return lo, hi


def physical(signal: Any, role: str, si: FloatArray, saturated: Counter[str], message: Any) -> FloatArray:
    """SI values in the signal's unit, clipped to its range (the clipped ones counted)."""
    scale, offset = signal_unit(signal, role, "")
    value = (si - offset) / scale
    if role == "heading":
        value = np.mod(value, 360.0 if scale == 1.0 else 2.0 * math.pi)  # a compass heading, not a count of turns
    lo, hi = _range(signal)
    out = (value < lo) | (value > hi)
    if out.any():
        saturated[f"{message.name}.{signal.name}"] += int(out.sum())
    return np.clip(value, lo, hi)


def _fill(signal: Any) -> float:
    lo, hi = _range(signal)
    return float(np.clip(0.0, lo, hi))


def encode(message: Any, columns: dict[str, FloatArray], n: int, where: str) -> list[bytes]:
    """cantools-encoded payloads of n frames; signals without a column get their fill value."""
    names = [s.name for s in message.signals]
    values = [
        columns[name].tolist() if name in columns else [_fill(message.get_signal_by_name(name))] * n for name in names
    ]
    try:
        return [
            bytes(message.encode(dict(zip(names, row, strict=True)), scaling=True, strict=True))
            for row in zip(*values, strict=True)
        ]
    except Exception as err:  # cantools raises EncodeError, ValueError, KeyError, ... for layouts it cannot fill
        raise InputError(
            where, f"a message {message.name} cantools can encode", f"{type(err).__name__}: {err}", "Check the DBC."
        ) from err


def write_frames(
    tmp: Path, fmt: str, encoded: list[EncodedMessage], start_time_s: float, dbc_path: Path, channel: int
) -> None:
    """Feed every frame, in time order (ties in message order), to python-can's writer for ``fmt``."""
    import can

    relative = np.concatenate([e.t_s for e in encoded])
    order = np.argsort(relative, kind="stable")
    t_s = (relative + start_time_s).tolist()
    ids = [int(e.message.frame_id) for e in encoded for _ in e.data]
    extended = [bool(e.message.is_extended_frame) for e in encoded for _ in e.data]
    data = [d for e in encoded for d in e.data]
    writers: dict[str, Any] = {
        "blf": can.BLFWriter,
        "asc": can.ASCWriter,
        "log": can.CanutilsLogWriter,
        "trc": can.TRCWriter,
        "csv": can.CSVWriter,
    }
    if fmt == "mf4":
        writer = can.MF4Writer(tmp, database=dbc_path)
        _pin_mf4_start(writer, math.floor(min(t_s, default=0.0) * 1000.0) / 1000.0)
    else:
        writer = writers[fmt](tmp)
    try:
        for i in order.tolist():
            frame = can.Message(
                timestamp=t_s[i],
                arbitration_id=ids[i],
                is_extended_id=extended[i],
                channel=channel,
                dlc=len(data[i]),
                data=data[i],
            )
            writer.on_message_received(frame)
    finally:
        writer.stop()


def _pin_mf4_start(writer: Any, start_s: float) -> None:
    """Give python-can's MF4Writer the log's start instead of the wall-clock time of writing.

    MF4Writer stamps the file with ``datetime.now()`` and stores frame times relative to it. Pinned
    to the log's first frame (truncated to the millisecond, as python-can's BLFWriter does) the
    header says when the log began and the file depends on the data alone — but for asammdf's
    file-history time stamps.
    """
    if not all(hasattr(writer, name) for name in ("_mdf", "_start_time", "last_timestamp")):
        return  # another python-can: its own start stays, frame times are still right, the file is not repeatable
    start = datetime.fromtimestamp(start_s, UTC)
    writer._mdf.header.start_time = start
    writer._start_time = writer.last_timestamp = start.timestamp()  # the very float the reader adds back


__all__ = [
    "CAN_FORMATS",
    "EncodedMessage",
    "can_format",
    "encode",
    "physical",
    "resolve_signal",
    "signal_unit",
    "write_frames",
]
