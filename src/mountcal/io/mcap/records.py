"""The MCAP file, record by record: magic, footer, summary (schemas, channels, statistics) and the
top-level walk of the data section, each checked against the file's bounds. Damage is an
:class:`~mountcal.core.errors.InputError` naming the byte.

A file without its footer and closing magic was cut short (:mod:`mountcal.io.whole`): refused,
or with ``--allow-truncated`` read without a summary, its data section walked up to the last
whole record (the channels found on the way).
"""

from __future__ import annotations

import os
import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, BinaryIO

import numpy as np
from numpy.typing import NDArray

from mountcal.core.errors import InputError
from mountcal.io.ros2 import cdr
from mountcal.io.whole import found_cut

I64Array = NDArray[np.int64]
U8Array = NDArray[np.uint8]


MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
OP_MESSAGE_INDEX, OP_STATISTICS, OP_DATA_END = 0x07, 0x0B, 0x0F
RECORD_HEAD = struct.Struct("<BQ")  # opcode, body length
_FOOTER = struct.Struct("<BQQQI")  # the whole footer record: opcode, length, summary start/offset, crc
MESSAGE_HEAD = 22  # channel id u16, sequence u32, log time u64, publish time u64
LOOSE_BATCH_BYTES = 8 << 20  # messages outside chunks are batched up to this size
READ_AHEAD = 3  # chunks decompressed ahead of the decoding
READ_AHEAD_BYTES = 32 << 20  # a larger chunk is decompressed when its turn comes, not ahead
MAX_CHUNK_OTHERS = 1 << 17  # non-message records in one chunk: a schema and a channel per channel id

_KIND_OF_SCHEMA = {
    f"{pkg}/{sep}{name}": kind
    for pkg, name, kind in (
        ("sensor_msgs", "Imu", "imu"),
        ("sensor_msgs", "Temperature", "temperature"),
        ("sensor_msgs", "NavSatFix", "fix"),
        ("nav_msgs", "Odometry", "odom"),
    )
    for sep in ("msg/", "")
}
TYPE_NAME = {
    "imu": "sensor_msgs/msg/Imu",
    "temperature": "sensor_msgs/msg/Temperature",
    "fix": "sensor_msgs/msg/NavSatFix",
    "odom": "nav_msgs/msg/Odometry",
}
ARGUMENT = {"imu": "topic", "temperature": "temperature_topic", "fix": "fix_topic", "odom": "odom_topic"}
ENCODINGS = ("cdr", "json")

# --------------------------------------------------------------------------- records of the file


class Corrupt(Exception):
    """The bytes break the MCAP format; the text says where and how."""


@dataclass(frozen=True)
class Schema:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True)
class McapChannel:
    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str] = field(default_factory=dict)  # what the writer says of the channel (mountcal.io.frame)


@dataclass(frozen=True)
class _Statistics:
    message_count: int
    start_ns: int
    end_ns: int
    channel_counts: dict[int, int]


class _Body:
    """A cursor over one record's body; reading past its end raises :class:`Corrupt`."""

    def __init__(self, data: bytes | memoryview, what: str) -> None:
        self.data, self.pos, self.what = data, 0, what

    def take(self, fmt: str) -> int:
        size = struct.calcsize(fmt)
        if self.pos + size > len(self.data):
            raise Corrupt(f"{self.what} record ends early")
        (value,) = struct.unpack_from(fmt, self.data, self.pos)
        self.pos += size
        return int(value)

    def bytes(self, length_fmt: str = "<I") -> bytes:
        n = self.take(length_fmt)
        if self.pos + n > len(self.data):
            raise Corrupt(f"{self.what} record ends early")
        out = bytes(self.data[self.pos : self.pos + n])
        self.pos += n
        return out

    def text(self) -> str:
        try:
            return self.bytes().decode()
        except UnicodeDecodeError as err:
            raise Corrupt(f"{self.what} record holds a string that is not UTF-8") from err


def parse_schema(body: bytes | memoryview) -> Schema:
    b = _Body(body, "schema")
    return Schema(b.take("<H"), b.text(), b.text(), b.bytes())


def parse_channel(body: bytes | memoryview) -> McapChannel:
    b = _Body(body, "channel")
    channel_id, schema_id = b.take("<H"), b.take("<H")
    topic, encoding = b.text(), b.text()
    metadata = {}
    if b.pos < len(b.data):  # the metadata map: its byte length, then key and value strings
        pairs = _Body(b.bytes(), "channel metadata")
        while pairs.pos < len(pairs.data):
            key = pairs.text()
            metadata[key] = pairs.text()
    return McapChannel(channel_id, schema_id, topic, encoding, metadata)


def _parse_statistics(body: bytes | memoryview) -> _Statistics:
    b = _Body(body, "statistics")
    message_count = b.take("<Q")
    b.pos += 2 + 4 * 4  # schema (u16), channel, attachment, metadata and chunk (u32) counts
    start_ns, end_ns = b.take("<Q"), b.take("<Q")
    pairs = np.frombuffer(b.bytes(), dtype=np.dtype([("id", "<u2"), ("count", "<u8")]))
    counts = {int(i): int(n) for i, n in zip(pairs["id"], pairs["count"], strict=True)}
    return _Statistics(message_count, start_ns, end_ns, counts)


def record_field(data: U8Array, at: I64Array, offset: int, dtype: str) -> NDArray[Any]:
    """One field of the records at ``at`` (record bounds already checked), shape (n,)."""
    return cdr.Rows(data, at).read(offset, dtype)[:, 0]


# --------------------------------------------------------------------------- the file as a whole


@dataclass
class Log:
    """An opened MCAP file: its channels and schemas, and where its data section ends."""

    file: BinaryIO
    where: str
    data_end: int  # byte offset at which the data-section walk stops
    schemas: dict[int, Schema]
    channels: dict[int, McapChannel]
    statistics: _Statistics | None
    cut: bool = False  # cut short (allowed): the data section runs to the last whole record

    def kind(self, channel: McapChannel) -> str | None:
        schema = self.schemas.get(channel.schema_id)
        return None if schema is None else _KIND_OF_SCHEMA.get(schema.name)

    def type_name(self, channel: McapChannel) -> str:
        schema = self.schemas.get(channel.schema_id)
        return "(no schema)" if schema is None else schema.name

    def topics(self) -> dict[str, list[McapChannel]]:
        out: dict[str, list[McapChannel]] = {}
        for channel in self.channels.values():
            out.setdefault(channel.topic, []).append(channel)
        return out

    def listing(self) -> str:
        """The topics and their types, for error messages."""
        items = [f"{t!r} ({self.type_name(chs[0])})" for t, chs in self.topics().items()]
        return ", ".join(items) if items else "no topics at all"


def damaged(where: str, found: str, todo: str = "") -> InputError:
    return InputError(
        where,
        "a complete, readable MCAP file",
        found,
        todo
        or "Copy the file again if it was transferred; `mcap recover` (the mcap CLI) salvages the "
        "readable part of a damaged or interrupted recording into a new file.",
    )


_RECOVER = "`mcap recover` (the mcap CLI) salvages the readable part of an interrupted recording into a new file."


def read_layout(file: BinaryIO, where: str) -> Log:
    size = os.fstat(file.fileno()).st_size
    if size == 0:
        raise InputError(
            where, "an MCAP file", "an empty file (0 bytes)", "Check the path and that the recording was written."
        )
    head = file.read(len(MAGIC))
    if head != MAGIC[: len(head)]:
        raise InputError(
            where,
            "an MCAP file (magic 89 4D 43 41 50 30 0D 0A)",
            f"a file starting {head.hex(' ')}",
            "Pass an .mcap file.",
        )
    tail_bytes = len(MAGIC) + _FOOTER.size
    file.seek(max(0, size - len(MAGIC)))
    if size < 2 * len(MAGIC) + tail_bytes or file.read(len(MAGIC)) != MAGIC:
        found_cut(where, size, "its footer and the closing MCAP magic", hint=_RECOVER)
        return Log(file, where, size, {}, {}, None, cut=True)  # allowed: read up to the last whole record
    file.seek(size - tail_bytes)
    footer = file.read(_FOOTER.size)
    opcode, length, summary_start, _, summary_crc = _FOOTER.unpack(footer)
    if opcode != OP_FOOTER or length != _FOOTER.size - RECORD_HEAD.size or summary_start > size - tail_bytes:
        raise Corrupt(f"a damaged footer record at byte {size - tail_bytes}")
    log = Log(file, where, size - tail_bytes, {}, {}, None)
    if summary_start:
        log.data_end = summary_start
        _read_summary(log, footer, summary_start, size - tail_bytes, summary_crc)
    return log


def _read_summary(log: Log, footer: bytes, start: int, end: int, crc: int) -> None:
    log.file.seek(start)
    data = log.file.read(end - start)
    if crc and zlib.crc32(footer[:-4], zlib.crc32(data)) != crc:
        raise Corrupt(f"a summary section (bytes {start}–{end}) whose CRC does not match")
    for opcode, at, length in walk_records(data, 0, len(data), "summary section"):
        body = memoryview(data)[at : at + length]
        if opcode == OP_SCHEMA:
            schema = parse_schema(body)
            log.schemas[schema.id] = schema
        elif opcode == OP_CHANNEL:
            channel = parse_channel(body)
            log.channels[channel.id] = channel
        elif opcode == OP_STATISTICS:
            log.statistics = _parse_statistics(body)


def walk_records(buf: bytes | memoryview, start: int, end: int, what: str) -> Iterator[tuple[int, int, int]]:
    """Records (opcode, body offset, body length) in ``buf[start:end]``, which they must tile.

    A generator: a section of millions of tiny records costs time, not memory.
    """
    pos, unpack = start, RECORD_HEAD.unpack_from
    while pos < end:
        if pos + RECORD_HEAD.size > end:
            raise Corrupt(f"a record header cut off at byte {pos} of the {what}")
        opcode, length = unpack(buf, pos)
        body = pos + RECORD_HEAD.size
        if body + length > end:
            raise Corrupt(f"a record (opcode 0x{opcode:02x}) at byte {pos} of the {what} running past its end")
        yield opcode, body, length
        pos = body + length


def chunk_others(records: Iterator[tuple[int, int, int]], what: str, found: int = 0) -> list[tuple[int, int, int]]:
    """The non-message records of a chunk (its schemas and channels), at most ``MAX_CHUNK_OTHERS``
    in all with the ``found`` ones already listed: more is filler, not a recording."""
    out = []
    for record in records:
        out.append(record)
        if len(out) + found > MAX_CHUNK_OTHERS:
            raise Corrupt(f"more than {MAX_CHUNK_OTHERS} records other than messages in the {what}")
    return out


def walk_file(log: Log) -> Iterator[tuple[int, int, int]]:
    """Top-level records (opcode, body offset, body length) of the data section, in file order."""
    pos = len(MAGIC)
    while pos < log.data_end:
        log.file.seek(pos)
        head = log.file.read(RECORD_HEAD.size)
        if len(head) < RECORD_HEAD.size:
            if log.cut:
                return  # the cut: the whole records before it are the file
            raise Corrupt(f"a record header cut off at byte {pos}")
        opcode, length = RECORD_HEAD.unpack(head)
        body = pos + RECORD_HEAD.size
        if log.cut and body + length > log.data_end:
            return
        if body + length > log.data_end:
            raise Corrupt(
                f"a record (opcode 0x{opcode:02x}) at byte {pos} claiming {length} bytes, past the data section"
            )
        if pos == len(MAGIC) and opcode != OP_HEADER:
            raise Corrupt(f"opcode 0x{opcode:02x} where the header record belongs (byte {pos})")
        if opcode == OP_DATA_END:
            return
        yield opcode, body, length
        pos = body + length
