"""Streaming MCAP output of vehicle-frame samples (tables: :mod:`mountcal.io.table.write`).

- :class:`McapOut`: an MCAP file written record by record. It either copies an input MCAP through
  — every chunk, message index, schema, channel, attachment and metadata record byte for byte,
  so every message keeps its channel, schema, sequence, log and publish time — and adds a
  vehicle-frame IMU channel beside the original one; or it holds that IMU channel alone. The new
  messages are ``sensor_msgs/msg/Imu`` in CDR, built for a whole chunk at once with numpy.

Every output is written through :func:`mountcal.atomic.atomic_output`: a process killed mid-write
leaves nothing behind.
"""

from __future__ import annotations

import io
import os
import struct
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

import lz4.frame
import numpy as np
import pyarrow.parquet as pq
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import (
    AttachmentIndex,
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from numpy.typing import NDArray

from mountcal.errors import InputError
from mountcal.io.ros2 import cdr
from mountcal.io.ros2.definitions import ros2_definition
from mountcal.io.ros2.imu import ImuMessages, decode_imu_messages, encode_imu_messages

FloatArray = NDArray[np.float64]
U8Array = NDArray[np.uint8]

MAGIC = b"\x89MCAP0\r\n"
IMU_SCHEMA_NAME = "sensor_msgs/msg/Imu"
IMU_DEFINITION = ros2_definition(IMU_SCHEMA_NAME)  # the one ROS 2 definition text mountcal writes
_MESSAGE_HEAD = 22  # channel id u16, sequence u32, log time u64, publish time u64
_RECORD_HEAD = 9  # opcode u8, length u64


# --------------------------------------------------------------------------- tables


# --------------------------------------------------------------------------- CDR sensor_msgs/msg/Imu


# --------------------------------------------------------------------------- MCAP, record by record


def _message_records(
    channel_id: int, sequence: NDArray[Any], log_ns: NDArray[Any], publish_ns: NDArray[Any], payload: U8Array
) -> bytes:
    """Message records of equal-length payloads, back to back (one numpy structured array)."""
    n, size = payload.shape
    dtype = np.dtype(
        [
            ("opcode", "u1"),
            ("length", "<u8"),
            ("channel", "<u2"),
            ("sequence", "<u4"),
            ("log", "<u8"),
            ("publish", "<u8"),
            ("data", "u1", (size,)),
        ]
    )
    rows = np.empty(n, dtype=dtype)
    rows["opcode"] = int(Opcode.MESSAGE)
    rows["length"] = _MESSAGE_HEAD + size
    rows["channel"] = channel_id
    rows["sequence"] = np.asarray(sequence, np.uint64).astype(np.uint32)
    rows["log"] = log_ns
    rows["publish"] = publish_ns
    rows["data"] = payload
    return rows.tobytes()


def _message_index(channel_id: int, log_ns: NDArray[Any], offsets: NDArray[Any]) -> bytes:
    pairs = np.empty((log_ns.shape[0], 2), dtype="<u8")
    pairs[:, 0], pairs[:, 1] = log_ns, offsets
    body = struct.pack("<HI", channel_id, pairs.nbytes) + pairs.tobytes()
    return struct.pack("<BQ", int(Opcode.MESSAGE_INDEX), len(body)) + body


def _chunk_record(records: bytes, start_ns: int, end_ns: int, compression: str) -> tuple[bytes, int]:
    """A chunk record holding ``records``, and the size of its compressed records field."""
    if compression == "zstd":
        data = zstandard.ZstdCompressor(level=3).compress(records)
    elif compression == "lz4":
        data = lz4.frame.compress(records)
    else:
        data = records
    name = compression.encode()
    body = b"".join(
        [
            struct.pack("<QQQI", start_ns, end_ns, len(records), zlib.crc32(records)),
            struct.pack("<I", len(name)),
            name,
            struct.pack("<Q", len(data)),
            data,
        ]
    )
    return struct.pack("<BQ", int(Opcode.CHUNK), len(body)) + body, len(data)


def _built(builder: RecordBuilder) -> bytes:
    """The bytes a record builder holds (mcap's ``end`` is untyped)."""
    return bytes(builder.end())  # type: ignore[no-untyped-call]


@dataclass
class _Counts:
    messages: dict[int, int] = field(default_factory=dict)
    start_ns: int | None = None
    end_ns: int | None = None
    chunks: int = 0

    def add(self, channel_id: int, n: int, start_ns: int, end_ns: int) -> None:
        if n <= 0:
            return
        self.messages[channel_id] = self.messages.get(channel_id, 0) + n
        self.start_ns = start_ns if self.start_ns is None else min(self.start_ns, start_ns)
        self.end_ns = end_ns if self.end_ns is None else max(self.end_ns, end_ns)


class McapOut:
    """An MCAP file written record by record, with a complete summary (indexed, CRC-checked).

    Call :meth:`start`, declare schemas and channels, add chunks — copied ones
    (:meth:`copy_chunk`) or new ones of fixed-length messages (:meth:`add_messages`) — and
    attachments or metadata (:meth:`copy_record`), then :meth:`finish`.
    """

    def __init__(self, file: BinaryIO, compression: str = "zstd") -> None:
        self.file = file
        self.compression = compression
        self.schemas: dict[int, Schema] = {}
        self.channels: dict[int, Channel] = {}
        self.chunk_indexes: list[ChunkIndex] = []
        self.attachment_indexes: list[AttachmentIndex] = []
        self.metadata_indexes: list[MetadataIndex] = []
        self.counts = _Counts()
        self._crc = 0

    def _write(self, data: bytes) -> int:
        at = self.file.tell()
        self.file.write(data)
        self._crc = zlib.crc32(data, self._crc)
        return at

    def _record(self, record: Any) -> None:
        builder = RecordBuilder()
        record.write(builder)
        self._write(_built(builder))

    def start(self, profile: str = "ros2", library: str = "mountcal") -> None:
        self._write(MAGIC)
        self._record(Header(profile=profile, library=library))

    def add_schema(self, schema: Schema) -> None:
        self.schemas[schema.id] = schema
        self._record(schema)

    def add_channel(self, channel: Channel) -> None:
        self.channels[channel.id] = channel
        self._record(channel)

    def copy_chunk(self, raw: bytes, index: ChunkIndex, counts: Mapping[int, int]) -> None:
        """Write a chunk record and its message index records exactly as read from another file.

        ``raw`` is the chunk record followed by its message index records, ``index`` the source
        file's chunk index of it, ``counts`` its messages per channel.
        """
        at = self._write(raw)
        shift = at - index.chunk_start_offset
        self.chunk_indexes.append(
            ChunkIndex(
                message_start_time=index.message_start_time,
                message_end_time=index.message_end_time,
                chunk_start_offset=at,
                chunk_length=index.chunk_length,
                message_index_offsets={k: v + shift for k, v in index.message_index_offsets.items()},
                message_index_length=index.message_index_length,
                compression=index.compression,
                compressed_size=index.compressed_size,
                uncompressed_size=index.uncompressed_size,
            )
        )
        self.counts.chunks += 1
        for channel_id, n in counts.items():
            self.counts.add(channel_id, n, index.message_start_time, index.message_end_time)

    def add_messages(
        self,
        channel_id: int,
        sequence: NDArray[Any],
        log_ns: NDArray[Any],
        publish_ns: NDArray[Any],
        payload: U8Array,
    ) -> None:
        """A new chunk of n messages on one channel, payloads of equal length (shape (n, L))."""
        n = payload.shape[0]
        if n == 0:
            return
        records = _message_records(channel_id, sequence, log_ns, publish_ns, payload)
        start_ns, end_ns = int(np.min(log_ns)), int(np.max(log_ns))
        chunk, compressed = _chunk_record(records, start_ns, end_ns, self.compression)
        at = self._write(chunk)
        offsets = np.arange(n, dtype=np.uint64) * np.uint64(_RECORD_HEAD + _MESSAGE_HEAD + payload.shape[1])
        index_at = self._write(_message_index(channel_id, np.asarray(log_ns, np.uint64), offsets))
        self.chunk_indexes.append(
            ChunkIndex(
                message_start_time=start_ns,
                message_end_time=end_ns,
                chunk_start_offset=at,
                chunk_length=len(chunk),
                message_index_offsets={channel_id: index_at},
                message_index_length=self.file.tell() - index_at,
                compression=self.compression,
                compressed_size=compressed,
                uncompressed_size=len(records),
            )
        )
        self.counts.chunks += 1
        self.counts.add(channel_id, n, start_ns, end_ns)

    def copy_record(self, raw: bytes, index: AttachmentIndex | MetadataIndex) -> None:
        """An attachment or metadata record copied from another file, with its index."""
        at = self._write(raw)
        if isinstance(index, AttachmentIndex):
            self.attachment_indexes.append(
                AttachmentIndex(
                    offset=at,
                    length=index.length,
                    log_time=index.log_time,
                    create_time=index.create_time,
                    data_size=index.data_size,
                    name=index.name,
                    media_type=index.media_type,
                )
            )
        else:
            self.metadata_indexes.append(MetadataIndex(offset=at, length=index.length, name=index.name))

    def finish(self) -> None:
        """Data end, the summary (schemas, channels, statistics, indexes), its offsets, footer, magic."""
        self._record(DataEnd(data_section_crc=self._crc))
        summary_start = self.file.tell()
        builder = RecordBuilder()
        offsets: list[SummaryOffset] = []
        c = self.counts
        statistics = Statistics(
            message_count=sum(c.messages.values()),
            schema_count=len(self.schemas),
            channel_count=len(self.channels),
            attachment_count=len(self.attachment_indexes),
            metadata_count=len(self.metadata_indexes),
            chunk_count=c.chunks,
            message_start_time=c.start_ns or 0,
            message_end_time=c.end_ns or 0,
            channel_message_counts=dict(c.messages),
        )
        groups: list[tuple[int, list[Any]]] = [
            (Opcode.SCHEMA, list(self.schemas.values())),
            (Opcode.CHANNEL, list(self.channels.values())),
            (Opcode.STATISTICS, [statistics]),
            (Opcode.CHUNK_INDEX, self.chunk_indexes),
            (Opcode.ATTACHMENT_INDEX, self.attachment_indexes),
            (Opcode.METADATA_INDEX, self.metadata_indexes),
        ]
        for opcode, records in groups:
            if not records:
                continue
            group_start = builder.count
            for record in records:
                record.write(builder)
            offsets.append(SummaryOffset(opcode, summary_start + group_start, builder.count - group_start))
        offset_start = summary_start + builder.count
        for offset in offsets:
            offset.write(builder)
        summary = _built(builder)
        self.file.write(summary)
        footer_head = struct.pack("<BQQQ", int(Opcode.FOOTER), 20, summary_start, offset_start)
        crc = zlib.crc32(footer_head, zlib.crc32(summary))
        builder = RecordBuilder()
        Footer(summary_start=summary_start, summary_offset_start=offset_start, summary_crc=crc).write(builder)
        self.file.write(_built(builder))
        self.file.write(MAGIC)


# --------------------------------------------------------------------------- reading what to copy


@dataclass(frozen=True)
class SourceChunk:
    """One chunk of an input MCAP: its bytes (with message indexes) and where its IMU messages are."""

    raw: bytes
    index: ChunkIndex
    counts: dict[int, int]
    records: U8Array  # decompressed records, only when the chunk holds IMU messages (else empty)
    imu_at: NDArray[np.int64]  # offsets in ``records`` of the IMU message records, in file order


def chunk_counts(raw: bytes, index: ChunkIndex) -> dict[int, int] | None:
    """Messages per channel from a chunk's message index records (None when it has none)."""
    if index.message_index_length == 0:
        return None
    counts: dict[int, int] = {}
    pos = index.chunk_length
    while pos < len(raw):
        _, length = struct.unpack_from("<BQ", raw, pos)
        channel_id, records_len = struct.unpack_from("<HI", raw, pos + _RECORD_HEAD)
        counts[channel_id] = counts.get(channel_id, 0) + records_len // 16
        pos += _RECORD_HEAD + length
    return counts


def decompress_chunk(raw: bytes, where: str) -> U8Array:
    """The records of a chunk record (``raw`` starts with it), decompressed and CRC-checked."""
    try:
        _, _, size, crc, name_len = struct.unpack_from("<QQQII", raw, _RECORD_HEAD)
        at = _RECORD_HEAD + 32
        compression = raw[at : at + name_len].decode()
        (data_len,) = struct.unpack_from("<Q", raw, at + name_len)
        data = raw[at + name_len + 8 : at + name_len + 8 + data_len]
        if compression == "zstd":
            out: bytes = zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
        elif compression == "lz4":
            out = lz4.frame.decompress(data)
        elif compression == "":
            out = bytes(data)
        else:
            raise ValueError(f"compression {compression!r}")
    except (struct.error, UnicodeDecodeError, ValueError, zstandard.ZstdError, RuntimeError) as err:
        raise InputError(
            where,
            "readable MCAP chunks (zstd, lz4 or none)",
            f"a chunk that does not decode ({err})",
            "Check the file.",
        ) from err
    if len(out) != size or (crc and zlib.crc32(out) != crc):
        raise InputError(where, "chunks that pass their CRC", "a damaged chunk", "The file is corrupt; re-record it.")
    return np.frombuffer(out, dtype=np.uint8)


def walk_messages(records: U8Array) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Offsets and channel ids of every message record in a chunk's records, by walking them.

    Used only for a chunk without message index records (a per-record loop: the rare slow path).
    """
    offsets, channels = [], []
    pos, n, data = 0, records.size, records.data
    while pos + _RECORD_HEAD <= n:
        opcode, length = struct.unpack_from("<BQ", data, pos)
        if opcode == Opcode.MESSAGE:
            offsets.append(pos)
            channels.append(struct.unpack_from("<H", data, pos + _RECORD_HEAD)[0])
        pos += _RECORD_HEAD + int(length)
    return np.asarray(offsets, dtype=np.int64), np.asarray(channels, dtype=np.int64)


def indexed_offsets(raw: bytes, index: ChunkIndex, channel_ids: frozenset[int]) -> NDArray[np.int64]:
    """Offsets (in the decompressed records) of the messages of ``channel_ids``, from the message
    index records that follow the chunk in ``raw``; sorted, i.e. in file order."""
    parts = []
    for channel_id, at in index.message_index_offsets.items():
        if channel_id not in channel_ids:
            continue
        pos = at - index.chunk_start_offset
        (records_len,) = struct.unpack_from("<I", raw, pos + _RECORD_HEAD + 2)
        pairs = np.frombuffer(raw, dtype="<u8", count=records_len // 8, offset=pos + _RECORD_HEAD + 6)
        parts.append(pairs.reshape(-1, 2)[:, 1].astype(np.int64))
    return np.sort(np.concatenate(parts)) if parts else np.empty(0, np.int64)


def message_fields(records: U8Array, at: NDArray[np.int64]) -> dict[str, NDArray[Any]]:
    """Header fields of the message records at offsets ``at``: sequence, log and publish time (ns),
    and each payload's start and size in ``records``."""
    length = cdr.gather(records, at + 1, 8).view("<u8")[:, 0].astype(np.int64)
    if np.any(length < _MESSAGE_HEAD) or np.any(at + _RECORD_HEAD + length > records.size):
        raise cdr.CdrError("a message record whose length does not fit its chunk")
    head = at + _RECORD_HEAD
    return {
        "sequence": cdr.gather(records, head + 2, 4).view("<u4")[:, 0],
        "log_ns": cdr.gather(records, head + 6, 8).view("<u8")[:, 0],
        "publish_ns": cdr.gather(records, head + 14, 8).view("<u8")[:, 0],
        "start": head + _MESSAGE_HEAD,
        "size": length - _MESSAGE_HEAD,
    }


def read_at(file: BinaryIO | io.BufferedReader, offset: int, length: int) -> bytes:
    """``length`` bytes of ``file`` from ``offset``."""
    file.seek(offset)
    data = file.read(length)
    if len(data) != length:
        raise InputError(
            getattr(file, "name", "MCAP"),
            f"{length} bytes at offset {offset}",
            f"{len(data)}",
            "The file is truncated.",
        )
    return data


# --------------------------------------------------------------------------- the two MCAP outputs


def imu_schema(schema_id: int) -> Schema:
    """The standard ``sensor_msgs/msg/Imu`` schema record (``ros2msg``)."""
    return Schema(id=schema_id, name=IMU_SCHEMA_NAME, encoding="ros2msg", data=IMU_DEFINITION.encode())


class McapImuSamples:
    """Samples (t_s, acc, gyro) as an MCAP file holding one ``sensor_msgs/msg/Imu`` channel.

    Orientation is unknown (``orientation_covariance[0] = −1``); times are the samples' own.
    """

    def __init__(self, file: BinaryIO, topic: str, frame_id: str, metadata: Mapping[str, str]) -> None:
        self.out = McapOut(file)
        self.out.start()
        self.out.add_schema(imu_schema(1))
        self.out.add_channel(Channel(id=1, schema_id=1, topic=topic, message_encoding="cdr", metadata=dict(metadata)))
        self.frame_id = frame_id
        self.sequence = 0

    def write(self, t_s: FloatArray, acc: FloatArray, gyro: FloatArray | None) -> None:
        """Append one chunk of samples: ``t_s`` (m,) s, ``acc`` (m, 3) m/s², ``gyro`` (m, 3) rad/s."""
        t_ns = np.round(np.asarray(t_s) * 1e9).astype(np.int64)
        payload = encode_imu_messages(ImuMessages.unknown_orientation(t_ns, gyro, acc), self.frame_id)
        sequence = self.sequence + np.arange(t_ns.shape[0])
        self.out.add_messages(1, sequence, t_ns, t_ns, payload)
        self.sequence += int(t_ns.shape[0])

    def close(self) -> None:
        self.out.finish()


@dataclass(frozen=True)
class CopyStats:
    """What :func:`copy_mcap_with_imu` copied and added."""

    topic: str
    imu_messages: int
    nonfinite: int
    imu_chunks: int
    largest_chunk: int
    copied_messages: int
    copied_channels: int


def open_mcap_summary(file: BinaryIO, where: str) -> tuple[Header, Any]:
    """The header and summary of an indexed MCAP file whose messages all lie in chunks."""
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    try:
        reader = make_reader(file)
        header = reader.get_header()
        summary = reader.get_summary()
    except (McapError, OSError, ValueError, struct.error) as err:
        raise InputError(
            where, "a readable, indexed MCAP file", f"an error reading it ({err})", "Check the file."
        ) from err
    if summary is None or not summary.chunk_indexes:
        raise InputError(
            where,
            "an MCAP file with a summary and chunk indexes (to copy it through)",
            "none",
            "Index it first (`mcap recover` of the mcap CLI), or write Parquet/CSV (--format parquet).",
        )
    if _loose_messages(file):
        raise InputError(
            where,
            "an MCAP file whose messages are all in chunks (to copy it through)",
            "messages outside chunks",
            "Re-chunk it (`mcap convert`), or write Parquet/CSV (--format parquet).",
        )
    return header, summary


def _loose_messages(file: BinaryIO) -> bool:
    """Whether a message record sits outside the chunks: one pass over the top-level record heads."""
    size = file.seek(0, io.SEEK_END)
    pos = len(MAGIC)
    while pos + _RECORD_HEAD <= size:
        file.seek(pos)
        opcode, length = struct.unpack("<BQ", file.read(_RECORD_HEAD))
        if opcode == Opcode.MESSAGE:
            return True
        if opcode == Opcode.DATA_END:
            return False
        pos += _RECORD_HEAD + int(length)
    return False


def copy_mcap_with_imu(
    src: str | os.PathLike[str],
    out: BinaryIO,
    transform: Any,
    *,
    topic: str | None,
    suffix: str,
    frame_id: str,
    metadata: Mapping[str, str],
) -> CopyStats:
    """Copy an MCAP file through unchanged and add a transformed copy of its IMU channel.

    Parameters
    ----------
    src : path
        An indexed MCAP file (all messages in chunks).
    out : binary file
        Where to write the new MCAP file.
    transform : callable
        ``transform(messages: ImuMessages) -> (ImuMessages, int)``: the new messages of one chunk
        and how many of them hold non-finite values.
    topic : str, optional
        The ``sensor_msgs/msg/Imu`` topic; default: the only one.
    suffix : str
        The new topic is the IMU topic plus this suffix (e.g. ``/vehicle``).
    frame_id : str
        ``header.frame_id`` of the new messages.
    metadata : mapping
        The new channel's metadata.

    Returns
    -------
    CopyStats
    """
    where = str(src)
    with open(src, "rb") as f:
        header, summary = open_mcap_summary(f, where)
        imu_ids, imu_topic, schema_id = _imu_channels(summary, topic, where)
        new_id = max(summary.channels) + 1
        new_topic = f"{imu_topic.rstrip('/')}{suffix}"
        if any(ch.topic == new_topic for ch in summary.channels.values()):
            raise InputError(
                where, f"no topic named {new_topic!r} yet", "one", "This log was already rotated; use the original."
            )
        w = McapOut(out)
        w.start(profile=header.profile, library=f"{metadata.get('software', 'mountcal')} (from: {header.library})")
        for schema in summary.schemas.values():
            w.add_schema(schema)
        for channel in summary.channels.values():
            w.add_channel(channel)
        w.add_channel(
            Channel(
                id=new_id,
                schema_id=schema_id,
                topic=new_topic,
                message_encoding="cdr",
                metadata={**metadata, "source_topic": imu_topic},
            )
        )
        n_imu = nonfinite = chunks = largest = copied = 0
        for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            raw = read_at(f, index.chunk_start_offset, index.chunk_length + index.message_index_length)
            counts = chunk_counts(raw, index)
            records: U8Array | None = None
            imu_at = np.empty(0, np.int64)
            if counts is None:  # no message index: count, and find the IMU messages, by walking
                records = decompress_chunk(raw, where)
                at_all, channel_all = walk_messages(records)
                ids, n = np.unique(channel_all, return_counts=True)
                counts = dict(zip(ids.tolist(), n.tolist(), strict=True))
                imu_at = at_all[np.isin(channel_all, list(imu_ids))]
            elif imu_ids & set(counts):
                records = decompress_chunk(raw, where)
                imu_at = indexed_offsets(raw, index, imu_ids)
            w.copy_chunk(raw, index, counts)
            copied += sum(counts.values())
            if records is None or imu_at.size == 0:
                continue
            try:
                fields = message_fields(records, imu_at)
                msgs = decode_imu_messages(records, fields["start"], fields["size"])
            except cdr.CdrError as err:
                raise InputError(
                    where, f"sensor_msgs/msg/Imu messages in CDR on {imu_topic!r}", str(err), "The file is damaged."
                ) from err
            rotated, bad = transform(msgs)
            w.add_messages(
                new_id,
                fields["sequence"],
                fields["log_ns"],
                fields["publish_ns"],
                encode_imu_messages(rotated, frame_id),
            )
            n_imu, nonfinite = n_imu + len(msgs), nonfinite + bad
            chunks, largest = chunks + 1, max(largest, len(msgs))
        if n_imu == 0:
            raise InputError(where, f"messages on the IMU topic {imu_topic!r}", "none", "Check the topic.")
        for attachment in summary.attachment_indexes:
            w.copy_record(read_at(f, attachment.offset, attachment.length), attachment)
        for meta in summary.metadata_indexes:
            w.copy_record(read_at(f, meta.offset, meta.length), meta)
        w.finish()
    return CopyStats(new_topic, n_imu, nonfinite, chunks, largest, copied, len(summary.channels))


def _imu_channels(summary: Any, topic: str | None, where: str) -> tuple[frozenset[int], str, int]:
    """Channel ids, topic and schema id of the IMU topic: the one named, else the only one."""
    by_topic: dict[str, list[Channel]] = {}
    for ch in summary.channels.values():
        by_topic.setdefault(ch.topic, []).append(ch)

    def is_imu(ch: Channel) -> bool:
        schema = summary.schemas.get(ch.schema_id)
        return schema is not None and schema.name in (IMU_SCHEMA_NAME, "sensor_msgs/Imu")

    listing = ", ".join(sorted(by_topic)) or "none"
    if topic is None:
        candidates = sorted(t for t, chs in by_topic.items() if all(is_imu(c) for c in chs))
        if len(candidates) != 1:
            raise InputError(
                where,
                "exactly one sensor_msgs/msg/Imu topic",
                f"{len(candidates)}: {', '.join(candidates)}" if candidates else f"none; the topics are {listing}",
                "Name the topic to rotate with --topic.",
            )
        topic = candidates[0]
    if topic not in by_topic or not all(is_imu(c) for c in by_topic[topic]):
        raise InputError(
            where, f"a sensor_msgs/msg/Imu topic named {topic!r}", f"topics {listing}", "Pass one of them as --topic."
        )
    chans = by_topic[topic]
    if any(c.message_encoding != "cdr" for c in chans):
        raise InputError(
            where,
            f"topic {topic!r} encoded as CDR (ROS 2), to copy it in its own layout",
            f"message encoding {chans[0].message_encoding!r}",
            "Write Parquet or CSV instead (--format parquet), which reads JSON messages too.",
        )
    return frozenset(c.id for c in chans), topic, int(chans[0].schema_id)


def written_by_mountcal(path: Path) -> bool:
    """Whether mountcal wrote this file (recognised by its metadata, not its name).

    A fleet table or a rotated log in Parquet carries ``mountcal.*`` file metadata; a rotated MCAP
    has a channel whose metadata holds the frame and the calibration applied. Such a file is an
    output, never a log to calibrate (a rotated log would calibrate to the identity).
    """
    suffix = path.suffix.lower()
    try:
        if suffix in (".parquet", ".pq"):
            keys = (pq.read_schema(path).metadata or {}).keys()
            return any(k.startswith(b"mountcal.") for k in keys)
        if suffix == ".mcap":
            with path.open("rb") as f:
                summary = make_reader(f).get_summary()
            channels = summary.channels.values() if summary is not None else ()
            return any({"frame", "calibration"} <= c.metadata.keys() for c in channels)
    except Exception:  # unreadable: not recognisably ours; the log reader will say what is wrong with it
        return False
    return False
