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

from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.core.paths import input_file
from mountcal.io.can.frames import DATA_WIDTH, CanFrames

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
    encoding = _text_encoding(path)
    with _quiet_cantools():
        for strict in (True, False):
            try:
                return cantools.database.load_file(path, encoding=encoding, strict=strict)
            except Exception as err:  # cantools raises its own errors, ValueError, KeyError, ...
                errors.append(f"{type(err).__name__}: {err}")
                last = err
        if path.lower().endswith(".dbc"):
            text = Path(path).read_text(encoding=encoding or "cp1252", errors="replace")  # as cantools reads it
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


def _text_encoding(path: str) -> str | None:
    """The encoding of a DBC's text: UTF-8 where the file is valid UTF-8 beyond ASCII (a unit written
    ``°/s`` or ``m/s²`` by a tool of today), else None, cantools' default for DBC (cp1252, Vector's).

    Read as cp1252, UTF-8's ``°`` is ``Â°``: ``°/s`` became no known unit and the gyro was refused for a
    unit the DBC states plainly. A cp1252 file with such characters is not valid UTF-8 (``°`` is the lone
    byte 0xB0), so the two cannot be confused; files of other formats keep cantools' own encoding.
    """
    if not path.lower().endswith(".dbc"):
        return None
    raw = Path(path).read_bytes()
    if raw.isascii():
        return None
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError:
        return None
    return "utf-8-sig" if raw.startswith(b"\xef\xbb\xbf") else "utf-8"


def load_dbcs(paths: str | Path | Sequence[str | Path]) -> Any:
    """One cantools database from one DBC or several (the IMU in one, the vehicle in another).

    Raises
    ------
    InputError
        When a file does not load (see :func:`load_dbc`), or two files define a message of the same
        name or the same frame id: which one a frame means would be a guess.
    """
    if isinstance(paths, str | Path):
        return load_dbc(paths)
    paths = list(paths)
    if not paths:
        raise InputError(option("dbc"), "at least one DBC file", "none", f"Pass the DBC file as {option('dbc')}.")
    if len(paths) == 1:
        return load_dbc(paths[0])
    import cantools

    owner_of_name: dict[str, str] = {}
    # the frames a message takes, as (value, mask, extended): its own key, and for a whole 29-bit
    # id also its PGN key, which a J1939 message of another file would match
    owner_of_key: dict[tuple[int, int, bool], tuple[str, Any]] = {}
    owner_of_pgn: dict[tuple[int, int, bool], tuple[str, Any]] = {}
    clashes: list[str] = []
    messages: list[Any] = []
    for path in paths:
        db = load_dbc(path)
        for message in db.messages:
            name, key, pgn = message.name, *_match_keys(message)
            other = next(
                (o for o in (owner_of_key.get(key), owner_of_pgn.get(key), owner_of_key.get(pgn or key))
                 if o is not None and o[0] != str(path)),
                None,
            )  # fmt: skip
            if owner_of_name.get(name, str(path)) != str(path):
                clashes.append(f"message name {name} in {owner_of_name[name]} and {path}")
            elif other is not None:
                ident = frame_id_text(int(message.frame_id), bool(message.is_extended_frame))
                theirs = frame_id_text(int(other[1].frame_id), bool(other[1].is_extended_frame))
                clashes.append(f"frame id {ident} ({name} in {path}) matches {theirs} ({other[1].name} in {other[0]})")
            owner_of_name.setdefault(name, str(path))
            owner_of_key.setdefault(key, (str(path), message))
            if pgn is not None:
                owner_of_pgn.setdefault(pgn, (str(path), message))
            messages.append(message)
    if clashes:
        shown = "; ".join(clashes[:5]) + (f"; and {len(clashes) - 5} more" if len(clashes) > 5 else "")
        raise InputError(
            " + ".join(str(p) for p in paths),
            "DBC files that define different messages",
            shown,
            "Drop the duplicate DBC, or remove the message from one of the files.",
        )
    return cantools.database.can.Database(messages=messages, strict=False)


def frame_id_text(ident: int, extended: bool) -> str:
    """A frame id as it is usually written: 3 hex digits for 11-bit ids, 8 for 29-bit ones."""
    return f"0x{ident:08X}" if extended else f"0x{ident:03X}"


# J1939 (SAE J1939-21): a 29-bit id is priority (3 bits), EDP, DP, PDU format PF (8), PDU specific
# PS (8), source address (8). The PGN is EDP, DP, PF and, when PF >= 240 (PDU2), PS; for PDU1 the
# PS is a destination address and not part of it.
_J1939_PDU2 = 0x03FFFF00  # id bits of the PGN of a PDU2 message
_J1939_PDU1 = 0x03FF0000  # of a PDU1 message


def id_match(message: Any) -> tuple[int, int]:
    """``(value, mask)``: a frame with ``arbitration_id & mask == value`` (and the message's id kind)
    is this message.

    A message of the J1939 protocol (cantools sets ``protocol == "j1939"`` from a DBC whose
    ``ProtocolType`` is J1939, for messages whose ``VFrameFormat`` is ``J1939PG``) is matched by its
    parameter group number: any priority, any source address (and any destination for PDU1), as
    J1939 tools do. Any other message, including an ``ExtendedCAN`` one in a J1939 DBC, is matched by
    its whole id, source address included.
    """
    ident = int(message.frame_id)
    if message.protocol == "j1939" and message.is_extended_frame:
        mask = _J1939_PDU2 if (ident >> 16) & 0xFF >= 240 else _J1939_PDU1
        return ident & mask, mask
    return ident, 0x1FFFFFFF


def _match_keys(message: Any) -> tuple[tuple[int, int, bool], tuple[int, int, bool] | None]:
    """The message's (value, mask, extended) and, for one matched by its whole 29-bit id, the key
    of its PGN (what a J1939 message of the same PGN has as its own key)."""
    value, mask = id_match(message)
    extended = bool(message.is_extended_frame)
    if mask != 0x1FFFFFFF or not extended:
        return (value, mask, extended), None
    pgn_mask = _J1939_PDU2 if (value >> 16) & 0xFF >= 240 else _J1939_PDU1
    return (value, mask, extended), (value & pgn_mask, pgn_mask, extended)


def select_frames(frames: CanFrames, message: Any) -> CanFrames:
    """The frames of ``message`` (by :func:`id_match`) in a table of frames."""
    value, mask = id_match(message)
    ids = frames.arbitration_id if mask == 0x1FFFFFFF else frames.arbitration_id & np.uint32(mask)
    return frames.take((ids == value) & (frames.is_extended == bool(message.is_extended_frame)))


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
        or carries another multiplexer value, and for every signal of a frame whose multiplexer
        value the DBC does not define (:func:`undefined_multiplexer`: cantools refuses such a frame).

    Raises
    ------
    InputError
        For a signal the message lacks, a signal longer than 64 bits, or nested multiplexing.
    """
    out: dict[str, FloatArray] = {}
    mux_values: dict[str, U64Array] = {}
    refused = undefined_multiplexer(frames, message)
    for signal in _signals(message, signal_names):
        raw = raw_values(frames.data, signal)
        value = _physical(raw, signal)
        value[(frames.dlc < _last_byte(signal) + 1) | refused] = np.nan
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


def undefined_multiplexer(frames: CanFrames, message: Any) -> NDArray[np.bool_]:
    """Frames whose multiplexer value the DBC does not define: a multiplexer of ``message`` that fits in
    the frame holds a value no signal of the message is defined under.

    cantools' ``decode_message`` refuses such a frame whole (``DecodeError``), its static signals too:
    the DBC does not say what the frame is. A frame too short for the multiplexer is not refused
    (its signals that fit decode, as cantools' ``allow_truncated`` decodes them).
    """
    out = np.zeros(len(frames), np.bool_)
    for mux in message.signals:
        if not mux.is_multiplexer or mux.multiplexer_ids:  # nested multiplexers: refused by decode
            continue
        defined = {i for s in message.signals if s.multiplexer_signal == mux.name for i in s.multiplexer_ids or ()}
        if defined:
            values = raw_values(frames.data, mux)
            out |= ~np.isin(values, np.asarray(sorted(defined), np.uint64)) & (frames.dlc > _last_byte(mux))
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
    """Raw bits → physical value: float reinterpretation or two's complement, then scale/offset.

    Any bits are a value: a NaN payload (signalling ones too) stays NaN and a float beyond the range once
    scaled becomes inf, without a numpy warning (cantools' Python floats give the same); the readers drop and
    count them."""
    length = int(signal.length)
    number: NDArray[Any]
    with np.errstate(over="ignore", invalid="ignore"):
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


__all__ = [
    "decode",
    "frame_id_text",
    "id_match",
    "load_dbc",
    "load_dbcs",
    "payload_bytes",
    "raw_values",
    "select_frames",
    "undefined_multiplexer",
]
