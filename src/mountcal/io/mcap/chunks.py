"""Chunks → tables of message records, decompressed on one background thread a few chunks ahead.

For each chunk the message records are located from the chunk's message index (checked to tile
the chunk exactly), or from a fixed stride, or — only when neither holds — by a plain loop over
the records. Memory stays bounded by the read-ahead (see ``docs/performance-mcap.md``).
"""

from __future__ import annotations

import array
import os
import struct
import zlib
from collections import deque
from collections.abc import Generator, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import closing
from dataclasses import dataclass

import lz4.frame
import numpy as np
import zstandard
from numpy.typing import NDArray

from mountcal.core import budget
from mountcal.core.errors import InputError
from mountcal.core.threads import helpers_allowed
from mountcal.io.inputs import block_too_large, check_regular_file, max_block_bytes
from mountcal.io.mcap.records import (
    LOOSE_BATCH_BYTES,
    MAX_CHUNK_OTHERS,
    MESSAGE_HEAD,
    OP_CHANNEL,
    OP_CHUNK,
    OP_MESSAGE,
    OP_MESSAGE_INDEX,
    OP_SCHEMA,
    READ_AHEAD,
    READ_AHEAD_BYTES,
    RECORD_HEAD,
    Corrupt,
    I64Array,
    Log,
    McapChannel,
    Schema,
    U8Array,
    chunk_others,
    damaged,
    parse_channel,
    parse_schema,
    read_layout,
    record_field,
    walk_file,
    walk_records,
)

# --------------------------------------------------------------------------- chunks → record tables


@dataclass(frozen=True)
class Unit:
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
            records = unzstd(job.data, job.out)
        elif job.compression == "lz4":
            records = unlz4(job.data, job.size)
        else:
            records = np.frombuffer(job.data, dtype=np.uint8)
    except (zstandard.ZstdError, RuntimeError, ValueError) as err:
        raise Corrupt(f"a chunk at byte {job.at} that does not decompress ({job.compression}: {err})") from err
    if records.size != job.size or (job.crc and zlib.crc32(records.data) != job.crc):
        raise Corrupt(f"a chunk at byte {job.at} whose content fails its size or CRC check")
    return records


def unlz4(data: bytes | memoryview, size: int) -> U8Array:
    """Decompress an lz4 frame, stopping one byte past ``size``: a frame inflating to more than
    the chunk states is refused without inflating the rest."""
    out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1)
    if len(out) > size:
        raise ValueError("more data than the chunk's stated uncompressed size")
    return np.frombuffer(out, dtype=np.uint8)


def unzstd(data: bytes | memoryview, out: U8Array) -> U8Array:
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


def _messages_from_index(data: U8Array, at: I64Array, what: str) -> Unit | None:
    """The unit whose messages the chunk's index lists, checked to tile ``data`` exactly.

    Gaps between the indexed messages may hold only non-message records (the schema and channel
    records of the chunk). Returns None when the index does not describe this chunk.
    """
    n = data.size
    if at.size == 0 or at[0] < 0 or at[-1] + RECORD_HEAD.size > n:
        return None
    if np.any(record_field(data, at, 0, "u1") != OP_MESSAGE):
        return None
    length = record_field(data, at, 1, "<u8")
    if np.any(length > n) or np.any(length < MESSAGE_HEAD):
        return None
    end = at + RECORD_HEAD.size + length.astype(np.int64)
    gap_start = np.concatenate([[0], end])
    gap_end = np.concatenate([at, [n]])
    if np.any(gap_end < gap_start):
        return None  # overlapping or repeated entries
    others: list[tuple[int, int, int]] = []
    for i in np.flatnonzero(gap_end > gap_start):  # normally just the leading schema/channel records
        try:
            records = chunk_others(walk_records(data.data, int(gap_start[i]), int(gap_end[i]), what), what, len(others))
        except Corrupt:
            return None
        if any(op == OP_MESSAGE for op, _, _ in records):
            return None  # a message the index does not list
        others += records
    return Unit(data, at, length.astype(np.int64), others, what)


def _messages_by_stride(data: U8Array, what: str) -> Unit | None:
    """The unit when all records after the leading non-message ones are messages of one length."""
    n, pos = data.size, 0
    others: list[tuple[int, int, int]] = []
    while pos + RECORD_HEAD.size <= n and data[pos] != OP_MESSAGE and len(others) < 64:
        opcode, length = RECORD_HEAD.unpack_from(data.data, pos)
        others.append((int(opcode), pos + RECORD_HEAD.size, int(length)))
        pos += RECORD_HEAD.size + int(length)
    if pos + RECORD_HEAD.size > n or data[pos] != OP_MESSAGE:
        return None
    length = int(RECORD_HEAD.unpack_from(data.data, pos)[1])
    stride = RECORD_HEAD.size + length
    if length < MESSAGE_HEAD or (n - pos) % stride:
        return None
    at = pos + stride * np.arange((n - pos) // stride, dtype=np.int64)
    if np.any(record_field(data, at, 0, "u1") != OP_MESSAGE) or np.any(record_field(data, at, 1, "<u8") != length):
        return None
    return Unit(data, at, np.full(at.size, length, dtype=np.int64), others, what)


def messages_by_walk(data: U8Array, what: str) -> Unit:
    """The unit found by stepping through the records one by one (the slow, general way).

    Message offsets and lengths go to compact arrays (each message record is at least 31 bytes,
    so they take at most half the chunk's size); other records are capped in number.
    """
    at, lengths = array.array("q"), array.array("q")
    others: list[tuple[int, int, int]] = []
    for opcode, pos, length in walk_records(data.data, 0, data.size, what):
        if opcode != OP_MESSAGE:
            others.append((opcode, pos, length))
            if len(others) > MAX_CHUNK_OTHERS:
                raise Corrupt(f"more than {MAX_CHUNK_OTHERS} records other than messages in the {what}")
        elif length < MESSAGE_HEAD:
            raise Corrupt(f"a message record shorter than its 22-byte header in the {what}")
        else:
            at.append(pos - RECORD_HEAD.size)
            lengths.append(length)
    return Unit(data, np.array(at, dtype=np.int64), np.array(lengths, dtype=np.int64), others, what)


def _unit(data: U8Array, index: I64Array | None, what: str, where: str) -> Unit:
    """Locate the message records of ``data``: by its index, by stride, or by walking them (the
    records walked charged to the budget of the file ``where``)."""
    unit = _messages_from_index(data, np.sort(index), what) if index is not None else None
    unit = unit or _messages_by_stride(data, what)
    if unit is None:
        unit = messages_by_walk(data, what)
        budget.charge("records", unit.messages.size + len(unit.others), where, "MCAP records stepped through")
    return unit


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


def _jobs(log: Log, wanted: frozenset[int] | None) -> Iterator[_Job]:
    """Every chunk (and batch of loose records) of the data section, in file order.

    A chunk whose message index lists none of the ``wanted`` channel ids is skipped unread; with
    ``wanted=None`` nothing is skipped.
    """
    chunk: tuple[int, int] | None = None
    index: dict[int, I64Array] = {}
    loose, loose_at = bytearray(), 0
    for opcode, at, length in walk_file(log):
        if opcode == OP_MESSAGE_INDEX and chunk is not None:
            channel_id, pairs = read_message_index(log, at, length)
            index[channel_id] = pairs[:, 1].astype(np.int64)
            continue
        if chunk is not None:
            yield from _chunk_job(log, chunk, index, wanted)
            chunk, index = None, {}
        if opcode == OP_CHUNK:
            chunk = (at, length)
        elif opcode in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
            loose_at = loose_at if loose else at - RECORD_HEAD.size
            log.file.seek(at - RECORD_HEAD.size)
            loose += log.file.read(RECORD_HEAD.size + length)
        if loose and (opcode == OP_CHUNK or len(loose) > LOOSE_BATCH_BYTES):
            yield _loose_job(loose_at, loose)
            loose.clear()
    if chunk is not None:
        yield from _chunk_job(log, chunk, index, wanted)
    if loose:
        yield _loose_job(loose_at, loose)


def read_message_index(log: Log, at: int, length: int) -> tuple[int, NDArray[np.uint64]]:
    """A message index record: its channel id and its (log time, offset) pairs, shape (m, 2)."""
    log.file.seek(at)
    body = log.file.read(length)
    if length < 6 or len(body) != length:
        raise Corrupt(f"a damaged message index record at byte {at}")
    channel_id, records_len = struct.unpack_from("<HI", body, 0)
    if records_len != length - 6 or records_len % 16:
        raise Corrupt(f"a message index record at byte {at} with an inconsistent length")
    pairs = np.frombuffer(body, dtype="<u8", offset=6).reshape(-1, 2).astype(np.uint64)
    return int(channel_id), pairs


def _chunk_job(
    log: Log, chunk: tuple[int, int], index: dict[int, I64Array], wanted: frozenset[int] | None
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
        raise Corrupt(f"a damaged chunk header at byte {at}") from err
    data = memoryview(body)[40 + name_len : 40 + name_len + data_len]
    if len(data) != data_len or size > _MAX_CHUNK_BYTES:
        raise Corrupt(f"a chunk at byte {at} whose stated sizes do not fit the file")
    if size > max_block_bytes() or data_len > max_block_bytes():
        raise block_too_large(log.where, f"an MCAP chunk (at byte {at})", f"a chunk stating {size} bytes")
    if compression not in ("zstd", "lz4", ""):
        raise Corrupt(f"a chunk at byte {at} compressed with {compression!r} (readable: zstd, lz4, none)")
    budget.inflate(data_len, size, log.where, f"the MCAP chunks up to byte {at}")
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
    decoding done by the caller (inline where :func:`~mountcal.core.threads.helpers_allowed` says no).
    A job the worker has not started when its turn comes is done by the caller instead of waited
    for, which balances the two threads and keeps a descheduled worker (a busy machine) from
    stalling the read. The read-ahead is bounded (``READ_AHEAD`` chunks), so memory does not grow
    with the log.
    """
    if not helpers_allowed():
        yield from ((job, _payload(job)) for job in jobs)
        return
    with ThreadPoolExecutor(1, thread_name_prefix="mountcal-mcap") as pool:
        pending: deque[tuple[_Job, Future[U8Array]]] = deque()
        try:
            for job in jobs:
                if job.size > READ_AHEAD_BYTES:  # a big chunk: alone in memory, not read ahead
                    while pending:
                        yield _next_done(pending)
                    yield job, _payload(job)
                    continue
                pending.append((job, pool.submit(_payload, job)))
                if len(pending) > READ_AHEAD:
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


def chunk_units(log: Log, wanted: frozenset[int] | None) -> Generator[Unit, None, None]:
    """The units of :func:`_jobs`, decompressed and with their message records located."""
    with closing(_prefetch(_jobs(log, wanted))) as prefetched:  # stop the worker on any exit
        for job, data in prefetched:
            what = f"{'chunk' if job.chunk else 'records'} at byte {job.at}"
            unit = _unit(data, job.index if job.chunk else None, what, log.where)
            del job, data  # hold one chunk, not two, while the next one is read
            yield unit
            del unit


def discover_channels(log: Log) -> tuple[dict[int, Schema], dict[int, McapChannel]]:
    """Schemas and channels of a log without a usable summary, by reading its data section."""
    schemas, channels = {}, {}
    with closing(chunk_units(log, None)) as units:
        for unit in units:
            for opcode, at, length in unit.others:
                if opcode == OP_SCHEMA:
                    schema = parse_schema(unit.data.data[at : at + length])
                    schemas[schema.id] = schema
                elif opcode == OP_CHANNEL:
                    channel = parse_channel(unit.data.data[at : at + length])
                    channels[channel.id] = channel
            del unit  # not held while the next chunk is read
    return schemas, channels


def open_log(path: str | os.PathLike[str], *, discover: bool = True) -> Log:
    """Open ``path`` and read its layout and summary.

    Without a summary listing the channels, ``discover`` finds them by reading the data section.
    """
    where = str(path)
    check_regular_file(path, "MCAP log")
    try:
        file = open(path, "rb")  # closed by the caller, which owns the Log
    except OSError as err:
        raise InputError(
            where, "a readable MCAP file", f"{type(err).__name__}: {err.strerror}", "Check the path."
        ) from err
    try:
        log = read_layout(file, where)
        if discover and not log.channels:  # no summary, or one without channels
            log.schemas, log.channels = discover_channels(log)
        return log
    except Corrupt as err:
        file.close()
        raise damaged(where, str(err)) from err
    except BaseException:
        file.close()
        raise
