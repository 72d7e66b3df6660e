"""MCAP written record by record: vehicle-frame samples as one Imu channel, or (:mod:`.copy`) an input
copied through (tables: :mod:`mountcal.io.table.write`).

- :class:`McapOut`: an MCAP file written record by record. It either copies an input MCAP through
  — every chunk, message index, schema, channel, attachment and metadata record byte for byte,
  so every message keeps its channel, schema, sequence, log and publish time — and adds a
  vehicle-frame IMU channel beside the original one; or it holds that IMU channel alone. The new
  messages are ``sensor_msgs/msg/Imu`` in CDR, built for a whole chunk at once with numpy.

Every output is written through :func:`mountcal.core.atomic.atomic_output`: a process killed mid-write
leaves nothing behind.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, BinaryIO

import lz4.frame
import numpy as np
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.opcode import Opcode
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

from mountcal.io.mcap.records import MAGIC, MESSAGE_HEAD, RECORD_HEAD, U8Array
from mountcal.io.ros2.definitions import ros2_definition
from mountcal.io.ros2.imu import ImuMessages, encode_imu_messages

FloatArray = NDArray[np.float64]

IMU_SCHEMA_NAME = "sensor_msgs/msg/Imu"
IMU_DEFINITION = ros2_definition(IMU_SCHEMA_NAME)  # the one ROS 2 definition text mountcal writes


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
    rows["length"] = MESSAGE_HEAD + size
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
        offsets = np.arange(n, dtype=np.uint64) * np.uint64(RECORD_HEAD.size + MESSAGE_HEAD + payload.shape[1])
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
