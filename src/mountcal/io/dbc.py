"""DBC files: loading with cantools, and decoding whole columns of frames with numpy.

cantools decodes one frame at a time in Python; here a signal of n frames is a handful of numpy
shifts and masks over the (n, 8 to 64) payload table, byte by byte. Both byte orders are supported
(Intel/little-endian: ``start`` is the least significant bit; Motorola/big-endian: ``start`` is the
most significant bit in the DBC's sawtooth numbering), any start bit and length up to 64, two's
complement signed values and IEEE-754 float signals, and messages with one multiplexer.
"""

from __future__ import annotations

import logging
import re
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mountcal.errors import InputError
from mountcal.io.can_frames import DATA_WIDTH, CanFrames
from mountcal.paths import input_file

FloatArray = NDArray[np.float64]
U64Array = NDArray[np.uint64]

# opendbc writes comments cantools rejects: `CM_ SG_ <id> "..."` (no signal name), `CM_ <id> "..."`
_NAMELESS_COMMENT = re.compile(r'^CM_ (?:SG_ )?\d+ "(?:[^"\\]|\\.)*";[ \t]*\r?$\n?', re.MULTILINE | re.DOTALL)


def load_dbc(path: str | Path) -> Any:
    """Load a DBC file (or any database cantools reads) into a ``cantools`` database.

    Tries cantools' strict mode, then ``strict=False`` (overlapping signals, as in opendbc's
    Toyota file), then, for a DBC, drops the signal-less ``CM_`` comment lines cantools cannot parse
    (opendbc's Honda and Hyundai files); comments carry no decoding information.

    Raises
    ------
    InputError
        When the file is missing or no attempt parses; the message quotes cantools' reason.
    """
    path = input_file(path, "a DBC file")  # not a FIFO or a device: reading ends
    stat = path.stat()
    return _load_cached(str(path.resolve()), stat.st_mtime_ns, stat.st_size)


@lru_cache(maxsize=16)
def _load_cached(path: str, mtime_ns: int, size: int) -> Any:
    import cantools

    errors: list[str] = []
    with _quiet_cantools():
        for strict in (True, False):
            try:
                return cantools.database.load_file(path, strict=strict)
            except Exception as err:  # cantools raises its own errors, ValueError, KeyError, ...
                errors.append(f"{type(err).__name__}: {err}")
                last = err
        if path.lower().endswith(".dbc"):
            text = Path(path).read_text(encoding="cp1252")
            cleaned, dropped = _NAMELESS_COMMENT.subn("", text)
            if dropped:
                try:
                    return cantools.database.load_string(cleaned, database_format="dbc", strict=False)
                except Exception as err:  # as above
                    errors.append(f"after dropping {dropped} signal-less CM_ lines, {type(err).__name__}: {err}")
                    last = err
    raise InputError(
        path,
        "a DBC file cantools can parse",
        "; ".join(dict.fromkeys(errors)),
        "Fix the line cantools names (or remove it if it is only a comment) and try again.",
    ) from last


class _DropOverwriteNotes(logging.Filter):
    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith("Overwriting message")


@contextmanager
def _quiet_cantools() -> Iterator[None]:
    """Silence cantools' notes about duplicate message names (mountcal resolves names itself)."""
    logger = logging.getLogger("cantools.database.can.database")
    note_filter = _DropOverwriteNotes()
    logger.addFilter(note_filter)
    try:
        yield
    finally:
        logger.removeFilter(note_filter)


def payload_bytes(message: Any, signal_names: Sequence[str] | None = None) -> int:
    """Bytes of payload the given signals (and their multiplexers) need, at least 1."""
    signals = _signals(message, signal_names)
    needed = [_last_byte(s) + 1 for s in signals]
    needed += [_last_byte(message.get_signal_by_name(s.multiplexer_signal)) + 1 for s in _muxed(signals)]
    return max(needed, default=1)


def decode(frames: CanFrames, message: Any, signal_names: Sequence[str] | None = None) -> dict[str, FloatArray]:
    """Physical values of signals of one message, for every frame of a table.

    Parameters
    ----------
    frames : CanFrames
        n frames, all of ``message`` (select them first, e.g. by arbitration id).
    message : cantools Message
        The DBC message.
    signal_names : sequence of str, optional
        Signals to decode; all of the message's by default.

    Returns
    -------
    dict of str to ndarray, shape (n,)
        ``raw * scale + offset`` in the DBC's unit. NaN where a frame is too short for the signal
        or carries another multiplexer value.

    Raises
    ------
    InputError
        For a signal the message lacks, a signal longer than 64 bits, or nested multiplexing.
    """
    out: dict[str, FloatArray] = {}
    mux_values: dict[str, U64Array] = {}
    for signal in _signals(message, signal_names):
        raw = raw_values(frames.data, signal)
        value = _physical(raw, signal)
        value[frames.dlc < _last_byte(signal) + 1] = np.nan
        if signal.multiplexer_ids:
            mux = message.get_signal_by_name(signal.multiplexer_signal)
            if mux.multiplexer_ids:
                raise InputError(
                    f"DBC message {message.name}",
                    "at most one level of multiplexing",
                    f"{signal.name} under {mux.name}, itself multiplexed",
                    "Decode this message with cantools instead, or map a non-multiplexed signal.",
                )
            if mux.name not in mux_values:
                mux_values[mux.name] = raw_values(frames.data, mux)
            other = ~np.isin(mux_values[mux.name], np.asarray(signal.multiplexer_ids, np.uint64))
            value[other | (frames.dlc < _last_byte(mux) + 1)] = np.nan
        out[signal.name] = value
    return out


def raw_values(data: NDArray[np.uint8], signal: Any) -> U64Array:
    """The raw (unscaled, unsigned) bit field of a signal in each row of ``data``.

    Parameters
    ----------
    data : ndarray, shape (n, w), uint8
        Payloads, zero-padded; bytes past w read as zero.
    signal : cantools Signal
        Its ``start``, ``length`` and ``byte_order``.

    Returns
    -------
    ndarray, shape (n,), uint64
    """
    length = int(signal.length)
    if not 1 <= length <= 64 or _last_byte(signal) >= DATA_WIDTH:
        raise InputError(
            f"DBC signal {signal.name}",
            "a signal of 1 to 64 bits inside a 64-byte payload",
            f"{length} bits from start bit {signal.start}",
            "Check the signal definition in the DBC.",
        )
    lsb, first, last = _bit_span(signal)
    if last < 8 <= data.shape[1]:
        return _raw_from_word(data, signal, lsb, length)
    value = np.zeros(data.shape[0], np.uint64)
    for j in range(first, min(last, data.shape[1] - 1) + 1):
        # weight of byte j's bit 0 relative to the signal's LSB
        shift = 8 * j - lsb if signal.byte_order == "little_endian" else lsb - 8 * j - 7
        column = data[:, j].astype(np.uint64)
        value |= column << np.uint64(shift) if shift >= 0 else column >> np.uint64(-shift)
    if length < 64:
        value &= np.uint64((1 << length) - 1)
    return value


def _raw_from_word(data: NDArray[np.uint8], signal: Any, lsb: int, length: int) -> U64Array:
    """A signal within the first 8 bytes: one shift and mask of each row read as a 64-bit word
    (little-endian for Intel signals; big-endian for Motorola, where linear bit l sits at 63 − l)."""
    order = "<u8" if signal.byte_order == "little_endian" else ">u8"
    words = np.ascontiguousarray(data[:, :8]).view(order)[:, 0].astype(np.uint64)
    shift = lsb if signal.byte_order == "little_endian" else 63 - lsb
    value = words >> np.uint64(shift)
    if length < 64:
        value &= np.uint64((1 << length) - 1)
    return value


def _bit_span(signal: Any) -> tuple[int, int, int]:
    """(LSB position, first byte, last byte); LSB in Intel numbering or Motorola linear numbering."""
    start, length = int(signal.start), int(signal.length)
    if signal.byte_order == "little_endian":
        return start, start // 8, (start + length - 1) // 8
    msb = 8 * (start // 8) + 7 - start % 8  # linear: byte-major, most significant bit first
    lsb = msb + length - 1
    return lsb, msb // 8, lsb // 8


def _last_byte(signal: Any) -> int:
    return _bit_span(signal)[2]


def _physical(raw: U64Array, signal: Any) -> FloatArray:
    """Raw bits → physical value: float reinterpretation or two's complement, then scale/offset."""
    length = int(signal.length)
    number: NDArray[Any]
    if signal.is_float and length == 32:
        number = raw.astype(np.uint32).view(np.float32).astype(np.float64)
    elif signal.is_float and length == 64:
        number = raw.view(np.float64)
    elif signal.is_signed and length == 64:
        number = raw.view(np.int64)
    elif signal.is_signed:
        half = np.uint64(1 << (length - 1))
        number = (raw ^ half).astype(np.int64) - np.int64(1 << (length - 1))
    else:
        number = raw
    return np.asarray(number, np.float64) * float(signal.scale) + float(signal.offset)


def _signals(message: Any, signal_names: Sequence[str] | None) -> list[Any]:
    if signal_names is None:
        return list(message.signals)
    known = {s.name: s for s in message.signals}
    missing = [name for name in signal_names if name not in known]
    if missing:
        raise InputError(
            f"DBC message {message.name}",
            "signals " + ", ".join(missing),
            "only " + ", ".join(sorted(known)),
            "Check the signal names (they are case-sensitive).",
        )
    return [known[name] for name in signal_names]


def _muxed(signals: list[Any]) -> list[Any]:
    return [s for s in signals if s.multiplexer_ids]


__all__ = ["decode", "load_dbc", "payload_bytes", "raw_values"]
