"""Read IMU samples (and temperature, GNSS fix, odometry) from MCAP logs, vectorized.

The reader walks the MCAP records itself and decodes whole chunks at a time with numpy: for each
chunk it locates the message records from the chunk's message index (checked to tile the chunk
exactly), or from a fixed stride, or — only when neither holds — by a plain loop over the records;
then every field is gathered for all messages of a topic at once (:mod:`mountcal.io.ros2.cdr`). There is
no per-message Python on this path; JSON-encoded channels are the exception (one ``json.loads`` per
message). Chunks are decompressed and CRC-checked on one background thread, a few chunks ahead of
the decoding, so memory stays bounded (see ``docs/performance-mcap.md`` for figures).

Conventions of every function here:

- **Time**: a message's time is its ``header.stamp`` (``sec + nanosec·1e-9``, seconds); where the
  stamp is zero (unset) the MCAP ``log_time`` (the recorder's receive time) is used instead. The
  rule is applied per message and identically on every topic, so all channels share one clock when
  the senders stamp their messages. Times are float64 seconds (sub-microsecond resolution at
  Unix-epoch magnitudes).
- **Units**: SI as in :class:`~mountcal.samples.Samples`; vectors in the IMU message's
  ``frame_id`` frame, taken as the sensor frame ``s`` (``axis_map`` ``"x,y,z"``).
- **Drops**: samples with a NaN or infinite value are dropped and counted in ``Samples.dropped``;
  so are GNSS fixes with ``status < 0`` (no fix) and odometry orientations that are not a rotation.
- **Gyro**: ``angular_velocity_covariance[0] = −1`` (REP 145: not provided) in any message of a read
  or chunk means no gyro (``gyro_s`` None), counted as ``imu_gyro_marked_unknown``; its zeros
  would otherwise read as a vehicle that never turns.
- **Errors**: anything wrong with the file or the request raises
  :class:`~mountcal.errors.InputError` naming the file, what was expected, what was found and what to
  do. The input file is only read.
"""

from __future__ import annotations

import array
import json
import os
import struct
import zlib
from collections import Counter, deque
from collections.abc import Generator, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import closing
from dataclasses import dataclass
from typing import Any, BinaryIO

import lz4.frame
import numpy as np
import zstandard
from numpy.typing import NDArray

from mountcal.errors import InputError
from mountcal.io.inputs import block_too_large, check_regular_file, max_block_bytes, max_rows, too_many_rows
from mountcal.io.ros2 import cdr
from mountcal.samples import Channel, FloatArray, LogSummary, Samples, Stream
from mountcal.threads import helpers_allowed

I64Array = NDArray[np.int64]
U8Array = NDArray[np.uint8]

_MAGIC = b"\x89MCAP0\r\n"
_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
_OP_MESSAGE_INDEX, _OP_STATISTICS, _OP_DATA_END = 0x07, 0x0B, 0x0F
_RECORD_HEAD = struct.Struct("<BQ")  # opcode, body length
_FOOTER = struct.Struct("<BQQQI")  # the whole footer record: opcode, length, summary start/offset, crc
_MESSAGE_HEAD = 22  # channel id u16, sequence u32, log time u64, publish time u64
_LOOSE_BATCH_BYTES = 8 << 20  # messages outside chunks are batched up to this size
_READ_AHEAD = 3  # chunks decompressed ahead of the decoding
_READ_AHEAD_BYTES = 32 << 20  # a larger chunk is decompressed when its turn comes, not ahead
_MAX_CHUNK_OTHERS = 1 << 17  # non-message records in one chunk: a schema and a channel per channel id

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
_TYPE_NAME = {
    "imu": "sensor_msgs/msg/Imu",
    "temperature": "sensor_msgs/msg/Temperature",
    "fix": "sensor_msgs/msg/NavSatFix",
    "odom": "nav_msgs/msg/Odometry",
}
_ARGUMENT = {"imu": "topic", "temperature": "temperature_topic", "fix": "fix_topic", "odom": "odom_topic"}
_ENCODINGS = ("cdr", "json")


# --------------------------------------------------------------------------- records of the file


class _Corrupt(Exception):
    """The bytes break the MCAP format; the text says where and how."""


@dataclass(frozen=True)
class _Schema:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True)
class _McapChannel:
    id: int
    schema_id: int
    topic: str
    message_encoding: str


@dataclass(frozen=True)
class _Statistics:
    message_count: int
    start_ns: int
    end_ns: int
    channel_counts: dict[int, int]


class _Body:
    """A cursor over one record's body; reading past its end raises :class:`_Corrupt`."""

    def __init__(self, data: bytes | memoryview, what: str) -> None:
        self.data, self.pos, self.what = data, 0, what

    def take(self, fmt: str) -> int:
        size = struct.calcsize(fmt)
        if self.pos + size > len(self.data):
            raise _Corrupt(f"{self.what} record ends early")
        (value,) = struct.unpack_from(fmt, self.data, self.pos)
        self.pos += size
        return int(value)

    def bytes(self, length_fmt: str = "<I") -> bytes:
        n = self.take(length_fmt)
        if self.pos + n > len(self.data):
            raise _Corrupt(f"{self.what} record ends early")
        out = bytes(self.data[self.pos : self.pos + n])
        self.pos += n
        return out

    def text(self) -> str:
        try:
            return self.bytes().decode()
        except UnicodeDecodeError as err:
            raise _Corrupt(f"{self.what} record holds a string that is not UTF-8") from err


def _parse_schema(body: bytes | memoryview) -> _Schema:
    b = _Body(body, "schema")
    return _Schema(b.take("<H"), b.text(), b.text(), b.bytes())


def _parse_channel(body: bytes | memoryview) -> _McapChannel:
    b = _Body(body, "channel")
    channel_id, schema_id = b.take("<H"), b.take("<H")
    return _McapChannel(channel_id, schema_id, b.text(), b.text())


def _parse_statistics(body: bytes | memoryview) -> _Statistics:
    b = _Body(body, "statistics")
    message_count = b.take("<Q")
    b.pos += 2 + 4 * 4  # schema (u16), channel, attachment, metadata and chunk (u32) counts
    start_ns, end_ns = b.take("<Q"), b.take("<Q")
    pairs = np.frombuffer(b.bytes(), dtype=np.dtype([("id", "<u2"), ("count", "<u8")]))
    counts = {int(i): int(n) for i, n in zip(pairs["id"], pairs["count"], strict=True)}
    return _Statistics(message_count, start_ns, end_ns, counts)


def _record_field(data: U8Array, at: I64Array, offset: int, dtype: str) -> NDArray[Any]:
    """One field of the records at ``at`` (record bounds already checked), shape (n,)."""
    return cdr.Rows(data, at).read(offset, dtype)[:, 0]


# --------------------------------------------------------------------------- the file as a whole


@dataclass
class _Log:
    """An opened MCAP file: its channels and schemas, and where its data section ends."""

    file: BinaryIO
    where: str
    data_end: int  # byte offset at which the data-section walk stops
    schemas: dict[int, _Schema]
    channels: dict[int, _McapChannel]
    statistics: _Statistics | None

    def kind(self, channel: _McapChannel) -> str | None:
        schema = self.schemas.get(channel.schema_id)
        return None if schema is None else _KIND_OF_SCHEMA.get(schema.name)

    def type_name(self, channel: _McapChannel) -> str:
        schema = self.schemas.get(channel.schema_id)
        return "(no schema)" if schema is None else schema.name

    def topics(self) -> dict[str, list[_McapChannel]]:
        out: dict[str, list[_McapChannel]] = {}
        for channel in self.channels.values():
            out.setdefault(channel.topic, []).append(channel)
        return out

    def listing(self) -> str:
        """The topics and their types, for error messages."""
        items = [f"{t!r} ({self.type_name(chs[0])})" for t, chs in self.topics().items()]
        return ", ".join(items) if items else "no topics at all"


def _fail(where: str, found: str, todo: str = "") -> InputError:
    return InputError(
        where,
        "a complete, readable MCAP file",
        found,
        todo
        or "Copy the file again if it was transferred; `mcap recover` (the mcap CLI) salvages the "
        "readable part of a damaged or interrupted recording into a new file.",
    )


def _open(path: str | os.PathLike[str], *, discover: bool = True) -> _Log:
    """Open ``path`` and read its layout and summary.

    Without a summary listing the channels, ``discover`` finds them by reading the data section.
    """
    where = str(path)
    check_regular_file(path, "MCAP log")
    try:
        file = open(path, "rb")  # closed by the caller, which owns the _Log
    except OSError as err:
        raise InputError(
            where, "a readable MCAP file", f"{type(err).__name__}: {err.strerror}", "Check the path."
        ) from err
    try:
        log = _read_layout(file, where)
        if discover and not log.channels:  # no summary, or one without channels
            log.schemas, log.channels = _discover(log)
        return log
    except _Corrupt as err:
        file.close()
        raise _fail(where, str(err)) from err
    except BaseException:
        file.close()
        raise


def _read_layout(file: BinaryIO, where: str) -> _Log:
    size = os.fstat(file.fileno()).st_size
    if size == 0:
        raise InputError(
            where, "an MCAP file", "an empty file (0 bytes)", "Check the path and that the recording was written."
        )
    head = file.read(len(_MAGIC))
    if head != _MAGIC[: len(head)]:
        raise InputError(
            where,
            "an MCAP file (magic 89 4D 43 41 50 30 0D 0A)",
            f"a file starting {head.hex(' ')}",
            "Pass an .mcap file.",
        )
    tail_bytes = len(_MAGIC) + _FOOTER.size
    file.seek(max(0, size - len(_MAGIC)))
    if size < 2 * len(_MAGIC) + tail_bytes or file.read(len(_MAGIC)) != _MAGIC:
        raise _Corrupt(f"a file of {size} bytes without the closing MCAP magic: it is truncated")
    file.seek(size - tail_bytes)
    footer = file.read(_FOOTER.size)
    opcode, length, summary_start, _, summary_crc = _FOOTER.unpack(footer)
    if opcode != _OP_FOOTER or length != _FOOTER.size - _RECORD_HEAD.size or summary_start > size - tail_bytes:
        raise _Corrupt(f"a damaged footer record at byte {size - tail_bytes}")
    log = _Log(file, where, size - tail_bytes, {}, {}, None)
    if summary_start:
        log.data_end = summary_start
        _read_summary(log, footer, summary_start, size - tail_bytes, summary_crc)
    return log


def _read_summary(log: _Log, footer: bytes, start: int, end: int, crc: int) -> None:
    log.file.seek(start)
    data = log.file.read(end - start)
    if crc and zlib.crc32(footer[:-4], zlib.crc32(data)) != crc:
        raise _Corrupt(f"a summary section (bytes {start}–{end}) whose CRC does not match")
    for opcode, at, length in _walk(data, 0, len(data), "summary section"):
        body = memoryview(data)[at : at + length]
        if opcode == _OP_SCHEMA:
            schema = _parse_schema(body)
            log.schemas[schema.id] = schema
        elif opcode == _OP_CHANNEL:
            channel = _parse_channel(body)
            log.channels[channel.id] = channel
        elif opcode == _OP_STATISTICS:
            log.statistics = _parse_statistics(body)


def _walk(buf: bytes | memoryview, start: int, end: int, what: str) -> Iterator[tuple[int, int, int]]:
    """Records (opcode, body offset, body length) in ``buf[start:end]``, which they must tile.

    A generator: a section of millions of tiny records costs time, not memory.
    """
    pos, unpack = start, _RECORD_HEAD.unpack_from
    while pos < end:
        if pos + _RECORD_HEAD.size > end:
            raise _Corrupt(f"a record header cut off at byte {pos} of the {what}")
        opcode, length = unpack(buf, pos)
        body = pos + _RECORD_HEAD.size
        if body + length > end:
            raise _Corrupt(f"a record (opcode 0x{opcode:02x}) at byte {pos} of the {what} running past its end")
        yield opcode, body, length
        pos = body + length


def _chunk_others(records: Iterator[tuple[int, int, int]], what: str, found: int = 0) -> list[tuple[int, int, int]]:
    """The non-message records of a chunk (its schemas and channels), at most ``_MAX_CHUNK_OTHERS``
    in all with the ``found`` ones already listed: more is filler, not a recording."""
    out = []
    for record in records:
        out.append(record)
        if len(out) + found > _MAX_CHUNK_OTHERS:
            raise _Corrupt(f"more than {_MAX_CHUNK_OTHERS} records other than messages in the {what}")
    return out


def _walk_file(log: _Log) -> Iterator[tuple[int, int, int]]:
    """Top-level records (opcode, body offset, body length) of the data section, in file order."""
    pos = len(_MAGIC)
    while pos < log.data_end:
        log.file.seek(pos)
        head = log.file.read(_RECORD_HEAD.size)
        if len(head) < _RECORD_HEAD.size:
            raise _Corrupt(f"a record header cut off at byte {pos}")
        opcode, length = _RECORD_HEAD.unpack(head)
        body = pos + _RECORD_HEAD.size
        if body + length > log.data_end:
            raise _Corrupt(
                f"a record (opcode 0x{opcode:02x}) at byte {pos} claiming {length} bytes, past the data section"
            )
        if pos == len(_MAGIC) and opcode != _OP_HEADER:
            raise _Corrupt(f"opcode 0x{opcode:02x} where the header record belongs (byte {pos})")
        if opcode == _OP_DATA_END:
            return
        yield opcode, body, length
        pos = body + length


# --------------------------------------------------------------------------- chunks → record tables


@dataclass(frozen=True)
class _Unit:
    """A run of records decoded at once: one decompressed chunk, or a batch of loose records."""

    data: U8Array  # the records, back to back, each an opcode, a u64 length and a body
    messages: I64Array  # offsets of the message records in ``data``, in file order
    lengths: I64Array  # their body lengths, each at least the 22-byte message header
    others: list[tuple[int, int, int]]  # the other records: (opcode, body offset, body length)
    what: str  # where in the file, for messages


_MAX_CHUNK_BYTES = 4 << 30  # as the mcap library's record size limit: a larger claim is damage


def _decompress(job: _Job) -> U8Array:
    """The records of a chunk, decompressed and checked against the chunk's size and CRC."""
    try:
        if job.compression == "zstd" and job.out is not None:
            records = _unzstd(job.data, job.out)
        elif job.compression == "lz4":
            records = _unlz4(job.data, job.size)
        else:
            records = np.frombuffer(job.data, dtype=np.uint8)
    except (zstandard.ZstdError, RuntimeError, ValueError) as err:
        raise _Corrupt(f"a chunk at byte {job.at} that does not decompress ({job.compression}: {err})") from err
    if records.size != job.size or (job.crc and zlib.crc32(records.data) != job.crc):
        raise _Corrupt(f"a chunk at byte {job.at} whose content fails its size or CRC check")
    return records


def _unlz4(data: bytes | memoryview, size: int) -> U8Array:
    """Decompress an lz4 frame, stopping one byte past ``size``: a frame inflating to more than
    the chunk states is refused without inflating the rest."""
    out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1)
    if len(out) > size:
        raise ValueError("more data than the chunk's stated uncompressed size")
    return np.frombuffer(out, dtype=np.uint8)


def _unzstd(data: bytes | memoryview, out: U8Array) -> U8Array:
    """Decompress a zstd frame into ``out`` (allocated by the reading thread: see :func:`_prefetch`).

    Returns the filled part of ``out``; a frame shorter or longer than ``out`` shows as a size
    mismatch or an error.
    """
    view, filled = out.data, 0
    with zstandard.ZstdDecompressor().stream_reader(data, read_across_frames=True) as reader:
        while filled < len(view):
            got = reader.readinto(view[filled:])
            if got == 0:
                break
            filled += got
        if filled == len(view) and reader.read(1):
            raise ValueError("more data than the chunk's stated uncompressed size")
    return out[:filled]


def _messages_from_index(data: U8Array, at: I64Array, what: str) -> _Unit | None:
    """The unit whose messages the chunk's index lists, checked to tile ``data`` exactly.

    Gaps between the indexed messages may hold only non-message records (the schema and channel
    records of the chunk). Returns None when the index does not describe this chunk.
    """
    n = data.size
    if at.size == 0 or at[0] < 0 or at[-1] + _RECORD_HEAD.size > n:
        return None
    if np.any(_record_field(data, at, 0, "u1") != _OP_MESSAGE):
        return None
    length = _record_field(data, at, 1, "<u8")
    if np.any(length > n) or np.any(length < _MESSAGE_HEAD):
        return None
    end = at + _RECORD_HEAD.size + length.astype(np.int64)
    gap_start = np.concatenate([[0], end])
    gap_end = np.concatenate([at, [n]])
    if np.any(gap_end < gap_start):
        return None  # overlapping or repeated entries
    others: list[tuple[int, int, int]] = []
    for i in np.flatnonzero(gap_end > gap_start):  # normally just the leading schema/channel records
        try:
            records = _chunk_others(_walk(data.data, int(gap_start[i]), int(gap_end[i]), what), what, len(others))
        except _Corrupt:
            return None
        if any(op == _OP_MESSAGE for op, _, _ in records):
            return None  # a message the index does not list
        others += records
    return _Unit(data, at, length.astype(np.int64), others, what)


def _messages_by_stride(data: U8Array, what: str) -> _Unit | None:
    """The unit when all records after the leading non-message ones are messages of one length."""
    n, pos = data.size, 0
    others: list[tuple[int, int, int]] = []
    while pos + _RECORD_HEAD.size <= n and data[pos] != _OP_MESSAGE and len(others) < 64:
        opcode, length = _RECORD_HEAD.unpack_from(data.data, pos)
        others.append((int(opcode), pos + _RECORD_HEAD.size, int(length)))
        pos += _RECORD_HEAD.size + int(length)
    if pos + _RECORD_HEAD.size > n or data[pos] != _OP_MESSAGE:
        return None
    length = int(_RECORD_HEAD.unpack_from(data.data, pos)[1])
    stride = _RECORD_HEAD.size + length
    if length < _MESSAGE_HEAD or (n - pos) % stride:
        return None
    at = pos + stride * np.arange((n - pos) // stride, dtype=np.int64)
    if np.any(_record_field(data, at, 0, "u1") != _OP_MESSAGE) or np.any(_record_field(data, at, 1, "<u8") != length):
        return None
    return _Unit(data, at, np.full(at.size, length, dtype=np.int64), others, what)


def _messages_by_walk(data: U8Array, what: str) -> _Unit:
    """The unit found by stepping through the records one by one (the slow, general way).

    Message offsets and lengths go to compact arrays (each message record is at least 31 bytes,
    so they take at most half the chunk's size); other records are capped in number.
    """
    at, lengths = array.array("q"), array.array("q")
    others: list[tuple[int, int, int]] = []
    for opcode, pos, length in _walk(data.data, 0, data.size, what):
        if opcode != _OP_MESSAGE:
            others.append((opcode, pos, length))
            if len(others) > _MAX_CHUNK_OTHERS:
                raise _Corrupt(f"more than {_MAX_CHUNK_OTHERS} records other than messages in the {what}")
        elif length < _MESSAGE_HEAD:
            raise _Corrupt(f"a message record shorter than its 22-byte header in the {what}")
        else:
            at.append(pos - _RECORD_HEAD.size)
            lengths.append(length)
    return _Unit(data, np.array(at, dtype=np.int64), np.array(lengths, dtype=np.int64), others, what)


def _unit(data: U8Array, index: I64Array | None, what: str) -> _Unit:
    """Locate the message records of ``data``: by its index, by stride, or by walking them."""
    unit = _messages_from_index(data, np.sort(index), what) if index is not None else None
    return unit or _messages_by_stride(data, what) or _messages_by_walk(data, what)


@dataclass(frozen=True)
class _Job:
    """Bytes read from the file, to be turned into records (possibly on the worker thread)."""

    at: int  # file offset of the chunk record's body, or of the first loose record
    data: bytes | memoryview  # the chunk's (compressed) records, or loose records back to back
    compression: str  # "zstd", "lz4" or "" (none; also for loose records)
    size: int  # the records' length once decompressed
    crc: int  # CRC-32 of the decompressed records, 0 when the writer did not compute it
    out: U8Array | None  # zstd decompresses into this buffer
    index: I64Array | None  # message record offsets from the chunk's message index, when indexed
    chunk: bool


def _jobs(log: _Log, wanted: frozenset[int] | None) -> Iterator[_Job]:
    """Every chunk (and batch of loose records) of the data section, in file order.

    A chunk whose message index lists none of the ``wanted`` channel ids is skipped unread; with
    ``wanted=None`` nothing is skipped.
    """
    chunk: tuple[int, int] | None = None
    index: dict[int, I64Array] = {}
    loose, loose_at = bytearray(), 0
    for opcode, at, length in _walk_file(log):
        if opcode == _OP_MESSAGE_INDEX and chunk is not None:
            channel_id, pairs = _read_message_index(log, at, length)
            index[channel_id] = pairs[:, 1].astype(np.int64)
            continue
        if chunk is not None:
            yield from _chunk_job(log, chunk, index, wanted)
            chunk, index = None, {}
        if opcode == _OP_CHUNK:
            chunk = (at, length)
        elif opcode in (_OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE):
            loose_at = loose_at if loose else at - _RECORD_HEAD.size
            log.file.seek(at - _RECORD_HEAD.size)
            loose += log.file.read(_RECORD_HEAD.size + length)
        if loose and (opcode == _OP_CHUNK or len(loose) > _LOOSE_BATCH_BYTES):
            yield _loose_job(loose_at, loose)
            loose.clear()
    if chunk is not None:
        yield from _chunk_job(log, chunk, index, wanted)
    if loose:
        yield _loose_job(loose_at, loose)


def _read_message_index(log: _Log, at: int, length: int) -> tuple[int, NDArray[np.uint64]]:
    """A message index record: its channel id and its (log time, offset) pairs, shape (m, 2)."""
    log.file.seek(at)
    body = log.file.read(length)
    if length < 6 or len(body) != length:
        raise _Corrupt(f"a damaged message index record at byte {at}")
    channel_id, records_len = struct.unpack_from("<HI", body, 0)
    if records_len != length - 6 or records_len % 16:
        raise _Corrupt(f"a message index record at byte {at} with an inconsistent length")
    pairs = np.frombuffer(body, dtype="<u8", offset=6).reshape(-1, 2).astype(np.uint64)
    return int(channel_id), pairs


def _chunk_job(
    log: _Log, chunk: tuple[int, int], index: dict[int, I64Array], wanted: frozenset[int] | None
) -> Iterator[_Job]:
    at, length = chunk
    if wanted is not None and index and wanted.isdisjoint(index):
        return  # indexed, and none of its messages are wanted
    if length > max_block_bytes() + (1 << 16):  # checked before reading it: a header holds a name
        raise block_too_large(log.where, f"an MCAP chunk (at byte {at})", f"a chunk record of {length} bytes")
    log.file.seek(at)
    body = log.file.read(length)
    try:
        _, _, size, crc, name_len = struct.unpack_from("<QQQII", body, 0)
        compression = body[32 : 32 + name_len].decode()
        (data_len,) = struct.unpack_from("<Q", body, 32 + name_len)
    except (struct.error, UnicodeDecodeError) as err:
        raise _Corrupt(f"a damaged chunk header at byte {at}") from err
    data = memoryview(body)[40 + name_len : 40 + name_len + data_len]
    if len(data) != data_len or size > _MAX_CHUNK_BYTES:
        raise _Corrupt(f"a chunk at byte {at} whose stated sizes do not fit the file")
    if size > max_block_bytes() or data_len > max_block_bytes():
        raise block_too_large(log.where, f"an MCAP chunk (at byte {at})", f"a chunk stating {size} bytes")
    if compression not in ("zstd", "lz4", ""):
        raise _Corrupt(f"a chunk at byte {at} compressed with {compression!r} (readable: zstd, lz4, none)")
    # The output buffer is allocated here, on the reading thread, and freed here after decoding:
    # buffers allocated on the worker and freed on this thread cost fresh pages (and time) per chunk.
    out = np.empty(size, dtype=np.uint8) if compression == "zstd" else None
    offsets = np.concatenate(list(index.values())) if index else None
    yield _Job(at, data, compression, size, crc, out, offsets, chunk=True)


def _loose_job(at: int, loose: bytearray) -> _Job:
    data = bytes(loose)
    return _Job(at, data, "", len(data), 0, None, None, chunk=False)


def _payload(job: _Job) -> U8Array:
    """The records of a job: a chunk decompressed and CRC-checked, or the loose records as they are."""
    return _decompress(job) if job.chunk else np.frombuffer(job.data, dtype=np.uint8)


def _prefetch(jobs: Iterator[_Job]) -> Generator[tuple[_Job, U8Array], None, None]:
    """Each job with its records, decompressed on a background thread a few chunks ahead.

    zstd, lz4 and CRC-32 release the GIL, so on two or more cores decompression overlaps the numpy
    decoding done by the caller (inline where :func:`~mountcal.threads.helpers_allowed` says no).
    A job the worker has not started when its turn comes is done by the caller instead of waited
    for, which balances the two threads and keeps a descheduled worker (a busy machine) from
    stalling the read. The read-ahead is bounded (``_READ_AHEAD`` chunks), so memory does not grow
    with the log.
    """
    if not helpers_allowed():
        yield from ((job, _payload(job)) for job in jobs)
        return
    with ThreadPoolExecutor(1, thread_name_prefix="mountcal-mcap") as pool:
        pending: deque[tuple[_Job, Future[U8Array]]] = deque()
        try:
            for job in jobs:
                if job.size > _READ_AHEAD_BYTES:  # a big chunk: alone in memory, not read ahead
                    while pending:
                        yield _next_done(pending)
                    yield job, _payload(job)
                    continue
                pending.append((job, pool.submit(_payload, job)))
                if len(pending) > _READ_AHEAD:
                    yield _next_done(pending)
            while pending:
                yield _next_done(pending)
        finally:
            for _, future in pending:
                future.cancel()


def _next_done(pending: deque[tuple[_Job, Future[U8Array]]]) -> tuple[_Job, U8Array]:
    """The oldest job with its records: from the worker, or done here if the worker has not begun."""
    job, future = pending.popleft()
    return job, _payload(job) if future.cancel() else future.result()


def _units(log: _Log, wanted: frozenset[int] | None) -> Generator[_Unit, None, None]:
    """The units of :func:`_jobs`, decompressed and with their message records located."""
    with closing(_prefetch(_jobs(log, wanted))) as prefetched:  # stop the worker on any exit
        for job, data in prefetched:
            what = f"{'chunk' if job.chunk else 'records'} at byte {job.at}"
            unit = _unit(data, job.index if job.chunk else None, what)
            del job, data  # hold one chunk, not two, while the next one is read
            yield unit
            del unit


def _discover(log: _Log) -> tuple[dict[int, _Schema], dict[int, _McapChannel]]:
    """Schemas and channels of a log without a usable summary, by reading its data section."""
    schemas, channels = {}, {}
    with closing(_units(log, None)) as units:
        for unit in units:
            for opcode, at, length in unit.others:
                if opcode == _OP_SCHEMA:
                    schema = _parse_schema(unit.data.data[at : at + length])
                    schemas[schema.id] = schema
                elif opcode == _OP_CHANNEL:
                    channel = _parse_channel(unit.data.data[at : at + length])
                    channels[channel.id] = channel
            del unit  # not held while the next chunk is read
    return schemas, channels


# --------------------------------------------------------------------------- choosing topics


@dataclass(frozen=True)
class _Selection:
    kind: str  # "imu", "temperature", "fix", "odom"
    topic: str
    channel_ids: frozenset[int]
    encoding: str  # "cdr" or "json"


def _schema_fields(text: str) -> tuple[tuple[str, str], ...]:
    """Top-level (type base name, field name) of a ``ros2msg`` definition; constants skipped."""
    out = []
    for line in text.split("\n=====", 1)[0].splitlines():
        words = line.split("#", 1)[0].split()
        if len(words) < 2 or "=" in words[1] or (len(words) > 2 and words[2].startswith("=")):
            continue
        out.append((words[0].rsplit("/", 1)[-1], words[1]))
    return tuple(out)


def _select(log: _Log, kind: str, topic: str | None) -> _Selection | None:
    """The topic to read for ``kind``: the one named, else the only one of that type."""
    topics = log.topics()
    argument, flag = _ARGUMENT[kind], f"--{_ARGUMENT[kind].replace('_', '-')}"
    candidates = [t for t, chs in topics.items() if log.kind(chs[0]) == kind]
    names = ", ".join(map(repr, candidates))
    if topic is not None:
        if topic not in topics:
            raise InputError(
                log.where,
                f"a topic named {topic!r}",
                f"topics {log.listing()}",
                f"Pass one of the {_TYPE_NAME[kind]} topics ({names}) as {argument}= (CLI: {flag})."
                if candidates
                else f"The log has no {_TYPE_NAME[kind]} topic to pass as {argument}= (CLI: {flag}).",
            )
        chosen = topics[topic]
        if any(log.kind(ch) != kind for ch in chosen):
            raise InputError(
                log.where,
                f"topic {topic!r} of type {_TYPE_NAME[kind]}",
                f"type {log.type_name(chosen[0])}",
                f"Pass a {_TYPE_NAME[kind]} topic as {argument}= (CLI: {flag})"
                + (f": {names}." if candidates else "; the log has none."),
            )
    else:
        if len(candidates) != 1:
            if kind != "imu" and not candidates:
                return None
            raise InputError(
                log.where,
                f"exactly one {_TYPE_NAME[kind]} topic",
                f"{len(candidates)}: {names}" if candidates else f"none; the topics are {log.listing()}",
                f"Name the topic to read with {argument}= (CLI: {flag}).",
            )
        topic = candidates[0]
        chosen = topics[topic]
    return _Selection(kind, topic, frozenset(ch.id for ch in chosen), _check_encoding(log, kind, topic, chosen))


def _check_encoding(log: _Log, kind: str, topic: str, channels: Sequence[_McapChannel]) -> str:
    encodings = {ch.message_encoding for ch in channels}
    encoding = encodings.pop()
    if encodings or encoding not in _ENCODINGS:
        raise InputError(
            log.where,
            f"topic {topic!r} encoded as CDR (ROS 2) or JSON",
            f"message encoding {encoding!r}",
            "Convert the log to ROS 2 CDR (for example with rosbags-convert) or export it to CSV.",
        )
    schema = log.schemas.get(channels[0].schema_id)
    if encoding == "cdr" and schema is not None and schema.encoding == "ros2msg":
        declared = _schema_fields(schema.data.decode(errors="replace"))
        if declared != cdr.FIELDS[kind]:
            raise InputError(
                log.where,
                f"topic {topic!r} with the standard {_TYPE_NAME[kind]} fields "
                f"({', '.join(name for _, name in cdr.FIELDS[kind])})",
                f"a schema declaring {', '.join(f'{t} {n}' for t, n in declared) or 'no fields'}",
                "Export this topic to CSV, or convert it to the standard message.",
            )
    return encoding


# --------------------------------------------------------------------------- decoding


@dataclass
class _Piece:
    """Decoded, finite, time-sorted values of one kind from one unit."""

    t_s: FloatArray
    columns: dict[str, FloatArray]


_JSON_PATHS: dict[str, dict[str, list[tuple[str, ...]]]] = {
    "imu": {
        "acc": [("linear_acceleration", c) for c in "xyz"],
        "gyro": [("angular_velocity", c) for c in "xyz"],
    },
    "temperature": {"temperature": [("temperature",)]},
    "fix": {
        "status": [("status", "status")],
        "lat": [("latitude",)],
        "lon": [("longitude",)],
        "alt": [("altitude",)],
    },
    "odom": {
        "vx": [("twist", "twist", "linear", "x")],
        "quat": [("pose", "pose", "orientation", c) for c in "xyzw"],
    },
}


def _json_value(message: object, path: tuple[str, ...]) -> float:
    value = message
    for key in path:
        if not isinstance(value, dict) or key not in value:
            raise cdr.CdrError(f"a JSON message without the field {'.'.join(path)}")
        value = value[key]
    if value is None:
        return float("nan")  # JSON has no NaN; writers emit null
    if not isinstance(value, int | float):
        raise cdr.CdrError(f"a JSON message whose {'.'.join(path)} is not a number")
    return float(value)


def _json_stamp(message: object) -> tuple[int, int]:
    """``header.stamp`` as (sec, nanosec) — ``nsec`` also accepted — or (0, 0) when absent."""
    header = message.get("header") if isinstance(message, dict) else None
    stamp = header.get("stamp") if isinstance(header, dict) else None
    if not isinstance(stamp, dict):
        return 0, 0
    sec, nanosec = stamp.get("sec", 0), stamp.get("nanosec", stamp.get("nsec", 0))
    if not isinstance(sec, int) or not isinstance(nanosec, int):
        raise cdr.CdrError("a JSON message whose header.stamp is not a pair of integers")
    return sec, nanosec


def _decode_json(kind: str, data: U8Array, start: I64Array, size: I64Array) -> cdr.Decoded:
    """Per-message JSON decoding (the one non-vectorized path), same result shape as CDR's."""
    paths = _JSON_PATHS[kind]
    rows, stamps, unknown = [], [], []
    raw = data.tobytes()
    for s, n in zip(start.tolist(), size.tolist(), strict=True):
        try:
            message = json.loads(raw[s : s + n])
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            raise cdr.CdrError(f"a message that is not JSON ({err})") from err
        stamps.append(_json_stamp(message))
        unknown.append(_json_gyro_unknown(message))
        rows.append([_json_value(message, p) for col in paths.values() for p in col])
    table = np.array(rows, dtype=np.float64).reshape(len(rows), -1)
    sec, nanosec = np.array(stamps, dtype=np.int64).reshape(-1, 2).T
    columns, i = {}, 0
    for name, col in paths.items():
        block = table[:, i : i + len(col)]
        columns[name] = block[:, 0] if len(col) == 1 else block
        i += len(col)
    if kind == "imu":
        columns["gyro_unknown"] = np.array(unknown, np.float64)
    return cdr.Decoded(sec, nanosec, columns)


def _json_gyro_unknown(message: object) -> bool:
    """Whether ``angular_velocity_covariance[0]`` is −1 (the field may be absent in JSON)."""
    cov = message.get("angular_velocity_covariance") if isinstance(message, dict) else None
    return isinstance(cov, list) and bool(cov) and cov[0] == -1


def _times(decoded: cdr.Decoded, log_ns: NDArray[np.uint64]) -> FloatArray:
    """Header stamp in seconds, or the log time where the stamp is zero (see the module doc)."""
    sec, nanosec = decoded.sec, decoded.nanosec
    unset = (sec == 0) & (nanosec == 0)
    if unset.any():
        sec = np.where(unset, (log_ns // np.uint64(10**9)).astype(np.int64), sec)
        nanosec = np.where(unset, (log_ns % np.uint64(10**9)).astype(np.int64), nanosec)
    return sec.astype(np.float64) + nanosec.astype(np.float64) * 1e-9


def _decode(unit: _Unit, mine: NDArray[np.bool_], sel: _Selection) -> cdr.Decoded:
    """Fields of the unit's messages selected by ``mine`` (``sel``'s topic), with ``t`` in seconds."""
    at, size = unit.messages, unit.lengths - _MESSAGE_HEAD
    if not mine.all():
        at, size = at[mine], size[mine]
    start = at + _RECORD_HEAD.size + _MESSAGE_HEAD
    if sel.encoding == "cdr":
        decoded = cdr.DECODERS[sel.kind](unit.data, start, size)
    else:
        decoded = _decode_json(sel.kind, unit.data, start, size)
    log_ns = _record_field(unit.data, at, _RECORD_HEAD.size + 6, "<u8")
    return cdr.Decoded(decoded.sec, decoded.nanosec, {"t": _times(decoded, log_ns), **decoded.columns})


def _sorted(t: FloatArray) -> bool:
    return bool(np.all(t[1:] >= t[:-1]))


def _keep(t: FloatArray, columns: dict[str, FloatArray], ok: NDArray[np.bool_]) -> _Piece:
    """Rows where ``ok``, stably sorted by time (copies skipped when there is nothing to do)."""
    if not ok.all():
        t, columns = t[ok], {k: v[ok] for k, v in columns.items()}
    if not _sorted(t):
        order = np.argsort(t, kind="stable")
        t, columns = t[order], {k: v[order] for k, v in columns.items()}
    return _Piece(t, columns)


def _finite(*arrays: FloatArray) -> NDArray[np.bool_]:
    """Rows where every value is finite (times need no check: they come from integers)."""
    ok = np.ones(arrays[0].shape[0], dtype=bool)
    with np.errstate(all="ignore"):  # a finite sum proves every term finite: the usual, cheap case
        if all(np.isfinite(a.sum()) for a in arrays):
            return ok
    for a in arrays:
        ok &= np.isfinite(a).reshape(a.shape[0], -1).all(axis=1)
    return ok


def _heading_deg(quat: FloatArray) -> FloatArray:
    """Compass heading (clockwise from north, [0, 360)) from an ENU orientation (x, y, z, w)."""
    x, y, z, w = quat.T
    yaw = np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))  # counter-clockwise from east
    heading = np.mod(90.0 - np.degrees(yaw), 360.0)
    return np.where(heading >= 360.0, heading - 360.0, heading)


def _pieces(decoded: cdr.Decoded, kind: str, dropped: Counter[str]) -> dict[str, _Piece]:
    """Finite, sorted samples (``"imu"``) or channels (keyed like ``Samples.channels``)."""
    c = decoded.columns
    t = c["t"]
    if kind == "imu":
        unknown = c["gyro_unknown"] > 0  # the gyro of these messages is not used (see _gyro)
        ok = _finite(c["acc"]) & (unknown | _finite(c["gyro"]))
        dropped["imu_nonfinite"] += int((~ok).sum())
        return {"imu": _keep(t, {"acc": c["acc"], "gyro": c["gyro"], "gyro_unknown": c["gyro_unknown"]}, ok)}
    if kind == "temperature":
        ok = _finite(c["temperature"])
        dropped["temperature_c_nonfinite"] += int((~ok).sum())
        return {"temperature_c": _keep(t, {"value": c["temperature"]}, ok)}
    if kind == "fix":
        fix = c["status"] >= 0
        ok = fix & _finite(c["lat"], c["lon"], c["alt"])
        dropped["fix_no_fix"] += int((~fix).sum())
        dropped["fix_nonfinite"] += int((fix & ~ok).sum())
        return {
            key: _keep(t, {"value": c[col]}, ok)
            for key, col in (("lat_deg", "lat"), ("lon_deg", "lon"), ("alt_m", "alt"))
        }
    speed_ok = _finite(c["vx"])
    norm = np.linalg.norm(c["quat"], axis=1)
    heading_ok = _finite(c["quat"]) & (np.abs(norm - 1.0) < 0.1)  # else not a rotation
    dropped["speed_mps_nonfinite"] += int((~speed_ok).sum())
    dropped["heading_deg_invalid_orientation"] += int((~heading_ok).sum())
    return {
        "speed_mps": _keep(t, {"value": c["vx"]}, speed_ok),
        "heading_deg": _keep(t, {"value": _heading_deg(c["quat"])}, heading_ok),
    }


def _decode_unit(unit: _Unit, selections: Sequence[_Selection], where: str) -> tuple[dict[str, _Piece], Counter[str]]:
    """One unit's finite, time-sorted pieces of every selection, and what was dropped."""
    channel = _record_field(unit.data, unit.messages, _RECORD_HEAD.size, "<u2")
    pieces: dict[str, _Piece] = {}
    dropped: Counter[str] = Counter()
    for sel in selections:
        ids = list(sel.channel_ids)
        mine = channel == ids[0] if len(ids) == 1 else np.isin(channel, ids)
        if not mine.any():
            continue
        try:
            decoded = _decode(unit, mine, sel)
        except cdr.CdrError as err:
            raise InputError(
                where,
                f"{_TYPE_NAME[sel.kind]} messages on {sel.topic!r} laid out as the schema says",
                f"{err}, in the {unit.what}",
                "The file is damaged or mislabelled; export the topic to CSV instead.",
            ) from err
        pieces.update(_pieces(decoded, sel.kind, dropped))
    return pieces, dropped


def _decoded_units(
    log: _Log, selections: Sequence[_Selection]
) -> Generator[tuple[dict[str, _Piece], Counter[str]], None, None]:
    """Per unit, in file order: the pieces of every selection and what was dropped."""
    wanted = frozenset(i for s in selections for i in s.channel_ids)
    with closing(_units(log, wanted)) as units:
        for unit in units:
            decoded = _decode_unit(unit, selections, log.where)
            del unit  # not held while the next chunk is read
            yield decoded


def _concat(pieces: list[_Piece]) -> _Piece:
    """Join pieces and sort by time (stable, so file order breaks ties)."""
    joined = _join_unsorted(pieces)
    if _sorted(joined.t_s):
        return joined
    order = np.argsort(joined.t_s, kind="stable")
    return _Piece(joined.t_s[order], {k: v[order] for k, v in joined.columns.items()})


# --------------------------------------------------------------------------- public API


def _no_samples(log: _Log, topic: str, dropped: Counter[str]) -> InputError:
    found = f"no messages on {topic!r}"
    if dropped["imu_nonfinite"]:
        found = f"{dropped['imu_nonfinite']} messages on {topic!r}, all with NaN or infinite values"
    return InputError(log.where, "IMU samples", found, "Check the recording, or pass another topic=.")


def _read(path: str | os.PathLike[str], fn_topics: dict[str, str | None]) -> Samples:
    log = _open(path)
    try:
        return _read_open(log, fn_topics)
    except _Corrupt as err:
        raise _fail(log.where, str(err)) from err
    finally:
        log.file.close()


def _read_open(log: _Log, topics: dict[str, str | None]) -> Samples:
    imu = _select(log, "imu", topics["imu"])
    assert imu is not None  # the IMU topic is never optional
    aux = [_select(log, kind, topic) for kind, topic in topics.items() if kind != "imu" and topic != ""]
    selections = [imu, *(s for s in aux if s is not None)]
    collected: dict[str, list[_Piece]] = {}
    dropped: Counter[str] = Counter()
    held, limit = 0, max_rows()
    with closing(_decoded_units(log, selections)) as units:
        for pieces, drops in units:
            dropped.update(drops)
            for key, piece in pieces.items():
                collected.setdefault(key, []).append(piece)
                held += piece.t_s.size
            if held > limit:  # counted a chunk at a time, before the whole log is held
                raise too_many_rows(log.where, "samples (all topics read)", held)
    if not collected.get("imu") or not sum(p.t_s.size for p in collected["imu"]):
        raise _no_samples(log, imu.topic, dropped)
    samples = _concat(collected.pop("imu"))
    channels = {}
    for key, parts in collected.items():
        joined = _concat(parts)
        channels[key] = Channel(joined.t_s, joined.columns["value"])
    return Samples(
        t_s=samples.t_s,
        acc_s=samples.columns["acc"],
        gyro_s=_gyro(samples, dropped),
        channels=channels,
        source=log.where,
        dropped={k: v for k, v in dropped.items() if v},
    )


def _gyro(piece: _Piece, dropped: Counter[str]) -> FloatArray | None:
    """The gyro column, or None when messages mark it unknown (``angular_velocity_covariance[0]
    = −1``, REP 145: an accelerometer without a gyro publishes zeros there). Where only some do,
    none is used: zeros among real rates would read as standing still; the count is reported."""
    unknown = int(np.count_nonzero(piece.columns["gyro_unknown"]))
    if not unknown:
        return piece.columns["gyro"]
    dropped["imu_gyro_marked_unknown"] += unknown
    return None


def read_mcap(
    path: str | os.PathLike[str],
    *,
    topic: str | None = None,
    temperature_topic: str | None = None,
    fix_topic: str | None = None,
    odom_topic: str | None = None,
) -> Samples:
    """Read the IMU samples of an MCAP log, with temperature, GNSS fix and odometry channels.

    Parameters
    ----------
    path : str or path-like
        The ``.mcap`` file (ROS 2 CDR or JSON messages; chunks uncompressed, zstd or lz4).
    topic : str, optional
        The ``sensor_msgs/msg/Imu`` topic. Default: the only one in the log (an error when there
        are none or several).
    temperature_topic, fix_topic, odom_topic : str, optional
        ``sensor_msgs/msg/Temperature``, ``sensor_msgs/msg/NavSatFix`` and
        ``nav_msgs/msg/Odometry`` topics. Default: the only one of that type, if any (an error
        when several); ``""`` reads none.

    Returns
    -------
    Samples
        ``t_s`` (n,) in s, sorted (stamp rule in the module docstring); ``acc_s`` (n, 3)
        ``linear_acceleration`` in m/s² and ``gyro_s`` (n, 3) ``angular_velocity`` in rad/s, sensor
        frame = the IMU message's ``frame_id``. ``channels``: ``temperature_c`` (°C);
        ``lat_deg``, ``lon_deg`` (degrees), ``alt_m`` (m, WGS 84 ellipsoid); ``speed_mps`` =
        ``twist.twist.linear.x`` (m/s, negative when reversing); ``heading_deg`` = 90° − yaw of
        ``pose.pose.orientation``, wrapped to [0, 360) — a compass heading only if the odometry
        frame is ENU-aligned (REP 103), which wheel-odometry ``odom`` frames usually are not.
        ``dropped`` counts discarded samples by reason.

    Raises
    ------
    InputError
        The file is missing, empty, truncated or damaged; the IMU topic is missing or ambiguous;
        an encoding or compression is not supported; or no finite IMU sample remains.
    """
    return _read(path, {"imu": topic, "temperature": temperature_topic, "fix": fix_topic, "odom": odom_topic})


def iter_mcap(
    path: str | os.PathLike[str], *, topic: str | None = None, max_samples: int = 100_000
) -> Iterator[Samples]:
    """Stream the IMU samples of an MCAP log in batches of at most ``max_samples``, bounded memory.

    The file is checked and the topic chosen (as in :func:`read_mcap`) before this returns; then
    one MCAP chunk at a time is decoded. Each batch is sorted by time; batches follow the file's
    chunk order, which is time order for recorders that write chunks as they go. Concatenated, the
    batches equal :func:`read_mcap`'s IMU samples whenever chunks do not overlap in time.

    Parameters
    ----------
    path : str or path-like
        The ``.mcap`` file.
    topic : str, optional
        The ``sensor_msgs/msg/Imu`` topic; default: the only one.
    max_samples : int
        Largest batch, in samples (≥ 1).

    Yields
    ------
    Samples
        ``t_s`` (m,), ``acc_s`` and ``gyro_s`` (m, 3), m ≤ ``max_samples``, as in :func:`read_mcap`
        but without aux channels; ``dropped`` counts the samples dropped from the chunks that fed
        this batch.

    Raises
    ------
    InputError
        As :func:`read_mcap`, the file-level problems immediately, damage found in a later chunk
        when the iteration reaches it.
    """
    if max_samples < 1:
        raise ValueError(f"max_samples must be at least 1, got {max_samples}")
    log = _open(path)
    try:
        selection = _select(log, "imu", topic)
    finally:
        log.file.close()
    assert selection is not None  # the IMU topic is never optional
    return _iter_batches(path, selection, max_samples)


def _iter_batches(path: str | os.PathLike[str], selection: _Selection, max_samples: int) -> Iterator[Samples]:
    log = _open(path, discover=False)  # the channels were chosen already
    try:
        yield from _batches(log, selection, max_samples)
    except _Corrupt as err:
        raise _fail(log.where, str(err)) from err
    finally:
        log.file.close()


def _batches(log: _Log, selection: _Selection, max_samples: int) -> Iterator[Samples]:
    pending: list[_Piece] = []
    count, total = 0, 0
    dropped: Counter[str] = Counter()
    with closing(_decoded_units(log, [selection])) as units:
        for pieces, drops in units:
            dropped.update(drops)
            if "imu" in pieces and pieces["imu"].t_s.size:
                pending.append(pieces["imu"])
                count += pieces["imu"].t_s.size
            while count >= max_samples:
                joined = _join_unsorted(pending)
                yield _batch(log, joined, 0, max_samples, dropped)
                pending = [_slice(joined, max_samples, count)]
                count, total, dropped = count - max_samples, total + max_samples, Counter()
    if count:
        yield _batch(log, _join_unsorted(pending), 0, count, dropped)
    elif not total:
        raise _no_samples(log, selection.topic, dropped)


def _join_unsorted(pieces: list[_Piece]) -> _Piece:
    if len(pieces) == 1:
        return pieces[0]
    return _Piece(
        np.concatenate([p.t_s for p in pieces]),
        {k: np.concatenate([p.columns[k] for p in pieces]) for k in pieces[0].columns},
    )


def _slice(piece: _Piece, start: int, stop: int) -> _Piece:
    return _Piece(piece.t_s[start:stop], {k: v[start:stop] for k, v in piece.columns.items()})


def _batch(log: _Log, piece: _Piece, start: int, stop: int, dropped: Counter[str]) -> Samples:
    """Rows ``start:stop`` of ``piece`` as Samples of their own (copied, sorted by time)."""
    part = _concat([_slice(piece, start, stop)])
    gyro = _gyro(part, dropped)
    return Samples(
        t_s=part.t_s.copy(),
        acc_s=part.columns["acc"].copy(),
        gyro_s=None if gyro is None else gyro.copy(),
        source=log.where,
        dropped={k: v for k, v in dropped.items() if v},
    )


def inspect_mcap(path: str | os.PathLike[str]) -> LogSummary:
    """What an MCAP log holds: topics, types, message counts, rates and duration.

    Counts and duration come from the summary's statistics record, per-topic rates from the
    chunks' message indexes: no chunk is decompressed, so damage inside a chunk goes unnoticed
    here (:func:`read_mcap` finds it). Only a log without indexes is scanned in full.

    Returns
    -------
    LogSummary
        One :class:`~mountcal.samples.Stream` per topic: ``kind`` is the schema name,
        ``rate_hz`` = (count − 1) / (last − first log time), ``fields`` the top-level fields of a
        ``ros2msg`` schema. ``duration_s`` spans the first to the last message's log time.
    """
    log = _open(path)
    try:
        spans = _spans_from_indexes(log) or _spans_from_scan(log)
    except _Corrupt as err:
        raise _fail(log.where, str(err)) from err
    finally:
        log.file.close()
    streams = tuple(_stream(log, topic, channels, spans) for topic, channels in log.topics().items())
    stats = log.statistics
    if stats is not None and stats.message_count:
        duration = (stats.end_ns - stats.start_ns) * 1e-9
    else:
        seen = [s for s in spans.values() if s[0]]
        duration = (max(s[2] for s in seen) - min(s[1] for s in seen)) * 1e-9 if seen else 0.0
    return LogSummary(source=log.where, format="mcap", duration_s=duration, streams=streams)


def _stream(log: _Log, topic: str, channels: list[_McapChannel], spans: _Spans) -> Stream:
    """One topic's line of :func:`inspect_mcap` (its channels merged)."""
    ids = [ch.id for ch in channels if ch.id in spans]
    if log.statistics is not None:
        count = sum(log.statistics.channel_counts.get(ch.id, 0) for ch in channels)
    else:
        count = sum(spans[i][0] for i in ids)
    first = min((spans[i][1] for i in ids), default=0)
    last = max((spans[i][2] for i in ids), default=0)
    rate = (count - 1) / ((last - first) * 1e-9) if count > 1 and last > first else 0.0
    schema = log.schemas.get(channels[0].schema_id)
    fields: tuple[str, ...] = ()
    if schema is not None and schema.encoding == "ros2msg":
        fields = tuple(name for _, name in _schema_fields(schema.data.decode(errors="replace")))
    return Stream(topic, log.type_name(channels[0]), count, rate, fields)


_Spans = dict[int, tuple[int, int, int]]  # channel id → (count, first, last log time in ns)


def _merge(spans: _Spans, channel_id: int, log_ns: NDArray[np.uint64]) -> None:
    if log_ns.size:
        n, first, last = spans.get(channel_id, (0, 2**64, 0))
        spans[channel_id] = (n + log_ns.size, min(first, int(log_ns.min())), max(last, int(log_ns.max())))


def _spans_from_indexes(log: _Log) -> _Spans | None:
    """Per-channel spans from the message index records, or None when a chunk has none."""
    spans: _Spans = {}
    chunk_indexed = True
    for opcode, at, length in _walk_file(log):
        if opcode == _OP_MESSAGE:
            return None
        if opcode == _OP_CHUNK:
            if not chunk_indexed:
                return None
            chunk_indexed = False
        elif opcode == _OP_MESSAGE_INDEX:
            chunk_indexed = True
            channel_id, pairs = _read_message_index(log, at, length)
            _merge(spans, channel_id, pairs[:, 0])
    return spans if chunk_indexed else None


def _spans_from_scan(log: _Log) -> _Spans:
    """Per-channel spans by decompressing and walking every chunk."""
    spans: _Spans = {}
    with closing(_units(log, None)) as units:
        for unit in units:
            channel = _record_field(unit.data, unit.messages, _RECORD_HEAD.size, "<u2")
            log_ns = _record_field(unit.data, unit.messages, _RECORD_HEAD.size + 6, "<u8")
            del unit  # not held while the next chunk is read
            for channel_id in np.unique(channel).tolist():
                _merge(spans, channel_id, log_ns[channel == channel_id])
    return spans
