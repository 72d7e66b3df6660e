"""An MCAP log copied through with a vehicle-frame IMU channel added (``mountcal rotate`` to MCAP).

Every chunk, message index, schema, channel, attachment and metadata record of the input is copied
byte for byte, so every message keeps its channel, schema, sequence, log and publish time; the IMU
messages of each chunk are decoded on whole arrays (:mod:`mountcal.io.ros2.imu`), turned, and
written as a new chunk on the new channel (:class:`~mountcal.io.mcap.write.McapOut`).
"""

from __future__ import annotations

import io
import os
import struct
import zlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, BinaryIO

import numpy as np
import zstandard
from mcap.opcode import Opcode
from mcap.reader import make_reader
from mcap.records import (
    Channel,
    ChunkIndex,
    Header,
)
from numpy.typing import NDArray

from mountcal.core import budget
from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.io.frame import topic_label
from mountcal.io.inputs import block_too_large, max_block_bytes
from mountcal.io.mcap.chunks import messages_by_walk, unlz4, unzstd
from mountcal.io.mcap.records import MAGIC, MESSAGE_HEAD, RECORD_HEAD, Corrupt, U8Array, damaged, record_field
from mountcal.io.mcap.write import IMU_SCHEMA_NAME, McapOut
from mountcal.io.ros2 import cdr
from mountcal.io.ros2.imu import decode_imu_messages, encode_imu_messages
from mountcal.io.sensor_frame import refuse_several


def chunk_counts(raw: bytes, index: ChunkIndex) -> dict[int, int] | None:
    """Messages per channel from a chunk's message index records (None when it has none)."""
    if index.message_index_length == 0:
        return None
    counts: dict[int, int] = {}
    pos = index.chunk_length
    while pos < len(raw):
        _, length = struct.unpack_from("<BQ", raw, pos)
        channel_id, records_len = struct.unpack_from("<HI", raw, pos + RECORD_HEAD.size)
        counts[channel_id] = counts.get(channel_id, 0) + records_len // 16
        pos += RECORD_HEAD.size + length
    return counts


def decompress_chunk(raw: bytes, where: str) -> U8Array:
    """The records of a chunk record (``raw`` starts with it), decompressed and CRC-checked."""
    try:
        _, _, size, crc, name_len = struct.unpack_from("<QQQII", raw, RECORD_HEAD.size)
        at = RECORD_HEAD.size + 32
        compression = raw[at : at + name_len].decode()
        (data_len,) = struct.unpack_from("<Q", raw, at + name_len)
        data = raw[at + name_len + 8 : at + name_len + 8 + data_len]
        if size > max_block_bytes():
            raise block_too_large(where, "an MCAP chunk", f"{size} bytes stated")
        budget.inflate(len(data), size, where, "the MCAP chunks copied")
        if compression == "zstd":
            out = unzstd(data, np.empty(size, dtype=np.uint8))
        elif compression == "lz4":
            out = unlz4(data, size)
        elif compression == "":
            out = np.frombuffer(data, dtype=np.uint8)
        else:
            raise ValueError(f"compression {compression!r}")
    except (struct.error, UnicodeDecodeError, ValueError, zstandard.ZstdError, RuntimeError) as err:
        raise InputError(
            where,
            "readable MCAP chunks (zstd, lz4 or none)",
            f"a chunk that does not decode ({err})",
            "Check the file.",
        ) from err
    if out.size != size or (crc and zlib.crc32(out.data) != crc):
        raise InputError(where, "chunks that pass their CRC", "a damaged chunk", "The file is corrupt; re-record it.")
    return out


def walk_messages(records: U8Array, where: str) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Offsets and channel ids of every message record in a chunk's records, by walking them.

    Used only for a chunk without message index records (a per-record loop: the rare slow path).
    """
    try:
        at = messages_by_walk(records, "chunk").messages
    except Corrupt as err:
        raise damaged(where, str(err)) from err
    budget.charge("records", at.size, where, "MCAP records stepped through")
    return at, record_field(records, at, RECORD_HEAD.size, "<u2").astype(np.int64)


def indexed_offsets(raw: bytes, index: ChunkIndex, channel_ids: frozenset[int]) -> NDArray[np.int64]:
    """Offsets (in the decompressed records) of the messages of ``channel_ids``, from the message
    index records that follow the chunk in ``raw``; sorted, i.e. in file order."""
    parts = []
    for channel_id, at in index.message_index_offsets.items():
        if channel_id not in channel_ids:
            continue
        pos = at - index.chunk_start_offset
        (records_len,) = struct.unpack_from("<I", raw, pos + RECORD_HEAD.size + 2)
        pairs = np.frombuffer(raw, dtype="<u8", count=records_len // 8, offset=pos + RECORD_HEAD.size + 6)
        parts.append(pairs.reshape(-1, 2)[:, 1].astype(np.int64))
    return np.sort(np.concatenate(parts)) if parts else np.empty(0, np.int64)


def message_fields(records: U8Array, at: NDArray[np.int64]) -> dict[str, NDArray[Any]]:
    """Header fields of the message records at offsets ``at``: sequence, log and publish time (ns),
    and each payload's start and size in ``records``."""
    length = cdr.gather(records, at + 1, 8).view("<u8")[:, 0].astype(np.int64)
    if np.any(length < MESSAGE_HEAD) or np.any(at + RECORD_HEAD.size + length > records.size):
        raise cdr.CdrError("a message record whose length does not fit its chunk")
    head = at + RECORD_HEAD.size
    return {
        "sequence": cdr.gather(records, head + 2, 4).view("<u4")[:, 0],
        "log_ns": cdr.gather(records, head + 6, 8).view("<u8")[:, 0],
        "publish_ns": cdr.gather(records, head + 14, 8).view("<u8")[:, 0],
        "start": head + MESSAGE_HEAD,
        "size": length - MESSAGE_HEAD,
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
            f"Index it first (`mcap recover` of the mcap CLI), or write Parquet/CSV ({option('format', 'parquet')}).",
        )
    if _loose_messages(file):
        raise InputError(
            where,
            "an MCAP file whose messages are all in chunks (to copy it through)",
            "messages outside chunks",
            f"Re-chunk it (`mcap convert`), or write Parquet/CSV ({option('format', 'parquet')}).",
        )
    return header, summary


def _loose_messages(file: BinaryIO) -> bool:
    """Whether a message record sits outside the chunks: one pass over the top-level record heads."""
    size = file.seek(0, io.SEEK_END)
    pos = len(MAGIC)
    while pos + RECORD_HEAD.size <= size:
        file.seek(pos)
        opcode, length = struct.unpack("<BQ", file.read(RECORD_HEAD.size))
        if opcode == Opcode.MESSAGE:
            return True
        if opcode == Opcode.DATA_END:
            return False
        pos += RECORD_HEAD.size + int(length)
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
        frames: dict[str, int] = {}  # the IMU messages' frame names so far
        for index in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            raw = read_at(f, index.chunk_start_offset, index.chunk_length + index.message_index_length)
            counts = chunk_counts(raw, index)
            records: U8Array | None = None
            imu_at = np.empty(0, np.int64)
            if counts is None:  # no message index: count, and find the IMU messages, by walking
                records = decompress_chunk(raw, where)
                at_all, channel_all = walk_messages(records, where)
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
                for name, times in cdr.decode_imu(records, fields["start"], fields["size"]).frames.items():
                    frames[name] = frames.get(name, 0) + times
            except cdr.CdrError as err:
                raise InputError(
                    where,
                    f"sensor_msgs/msg/Imu messages in CDR on {imu_topic!r}",
                    str(err),
                    err.fix or "The file is damaged.",
                ) from err
            refuse_several(frames, imu_topic, where)  # one calibration, one sensor frame
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
                f"{len(candidates)}: {', '.join(topic_label(t, by_topic[t][0].metadata) for t in candidates)}"
                if candidates
                else f"none; the topics are {listing}",
                f"Name the topic to rotate with {option('topic')}.",
            )
        topic = candidates[0]
    if topic not in by_topic or not all(is_imu(c) for c in by_topic[topic]):
        raise InputError(
            where,
            f"a sensor_msgs/msg/Imu topic named {topic!r}",
            f"topics {listing}",
            f"Pass one of them as {option('topic')}.",
        )
    chans = by_topic[topic]
    if any(c.message_encoding != "cdr" for c in chans):
        raise InputError(
            where,
            f"topic {topic!r} encoded as CDR (ROS 2), to copy it in its own layout",
            f"message encoding {chans[0].message_encoding!r}",
            f"Write Parquet or CSV instead ({option('format', 'parquet')}), which reads JSON messages too.",
        )
    return frozenset(c.id for c in chans), topic, int(chans[0].schema_id)
