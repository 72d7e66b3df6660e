"""The ROS 1 bag file (format 2.0), record by record, and its chunks as arrays of message records.

A bag is a header record, then chunks (compressed runs of connection and message records), each
followed by one index record per connection it holds (the time and in-chunk offset of each
message), and at the end the connection records and one chunk-info record per chunk. The reader
reads the header and the end section, then one chunk at a time: the chunk's index records give
every message's offset, so the message records are located and checked for all messages of a
chunk at once (:func:`blocks`), with no per-message Python unless a record's header is unusual.

Records are ``u32 header length, header, u32 data length, data``; a header is a list of
``u32 length, name=value`` fields; integers are little-endian; a time is ``u32 sec, u32 nsec``.
Damage is :class:`Corrupt` with the byte where it was found.
"""

from __future__ import annotations

import bz2
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import BinaryIO

import numpy as np
from numpy.typing import NDArray

from mountcal.core.errors import InputError
from mountcal.io.inputs import block_too_large, check_regular_file, max_block_bytes
from mountcal.io.mcap.chunks import unlz4
from mountcal.io.ros.types import normalize
from mountcal.io.ros2.cdr import Rows

I64Array = NDArray[np.int64]
U8Array = NDArray[np.uint8]

MAGIC = b"#ROSBAG V2.0\n"
OP_MESSAGE, OP_BAG_HEADER, OP_INDEX, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION = 0x02, 0x03, 0x04, 0x05, 0x06, 0x07
_U32 = struct.Struct("<I")
_INDEX_ENTRY = np.dtype([("sec", "<u4"), ("nsec", "<u4"), ("offset", "<u4")])
MAX_HEADER = 1 << 20  # a record header is a few fields; more is damage
COMPRESSIONS = ("none", "bz2", "lz4")


class Corrupt(Exception):
    """The bytes break the bag format; the text says where and how."""


@dataclass(frozen=True)
class Connection:
    """A topic's publisher as the bag records it: its message type and definition."""

    id: int
    topic: str
    type_name: str  # ROS 2 style: sensor_msgs/msg/Imu
    definition: str  # the message_definition text (ROS 1 .msg, dependencies after lines of '=')
    md5sum: str


@dataclass(frozen=True)
class ChunkInfo:
    """Where a chunk is, its time span (ns) and how many messages of each connection it holds."""

    pos: int
    start_ns: int
    end_ns: int
    counts: dict[int, int]


@dataclass
class Bag:
    """An opened bag: its connections and chunks."""

    file: BinaryIO
    where: str
    size: int
    connections: dict[int, Connection] = field(default_factory=dict)
    chunks: list[ChunkInfo] = field(default_factory=list)

    def topics(self) -> dict[str, list[Connection]]:
        out: dict[str, list[Connection]] = {}
        for c in self.connections.values():
            out.setdefault(c.topic, []).append(c)
        return out


@dataclass(frozen=True)
class Block:
    """One decompressed chunk and, per connection asked for, its messages: data start, size, record time (ns)."""

    data: U8Array
    messages: dict[int, tuple[I64Array, I64Array, I64Array]]
    what: str


def _time_ns(raw: bytes) -> int:
    sec, nsec = struct.unpack("<II", raw)
    return int(sec) * 1_000_000_000 + int(nsec)


def parse_header(raw: bytes | memoryview, where: str) -> dict[str, bytes]:
    """The ``name=value`` fields of a record header."""
    out, pos, n = {}, 0, len(raw)
    while pos < n:
        if pos + 4 > n:
            raise Corrupt(f"a record header cut inside a field length ({where})")
        (length,) = _U32.unpack_from(raw, pos)
        pos += 4
        if pos + length > n:
            raise Corrupt(f"a header field running past its header ({where})")
        name, eq, value = bytes(raw[pos : pos + length]).partition(b"=")
        if not eq:
            raise Corrupt(f"a header field without '=' ({where})")
        out[name.decode("ascii", "replace")] = value
        pos += length
    return out


def _get(fields: dict[str, bytes], name: str, fmt: str, where: str) -> int:
    raw = fields.get(name)
    if raw is None or len(raw) != struct.calcsize(fmt):
        raise Corrupt(f"a record without a valid '{name}' field ({where})")
    return int(struct.unpack(fmt, raw)[0])


class _Reader:
    """Reads records at byte positions, each checked to lie inside the file."""

    def __init__(self, file: BinaryIO, size: int) -> None:
        self.file, self.size = file, size

    def read(self, pos: int, n: int, what: str) -> bytes:
        if pos < 0 or pos + n > self.size:
            raise Corrupt(f"{what} at byte {pos} running past the end of the file ({self.size} bytes)")
        self.file.seek(pos)
        data = self.file.read(n)
        if len(data) != n:
            raise Corrupt(f"{what} at byte {pos} cut short")
        return data

    def record(self, pos: int, what: str) -> tuple[dict[str, bytes], int, int]:
        """(header fields, data position, data length) of the record at ``pos``."""
        (header_len,) = _U32.unpack(self.read(pos, 4, what))
        if header_len > MAX_HEADER:
            raise Corrupt(f"{what} at byte {pos} declaring a {header_len}-byte header")
        fields = parse_header(self.read(pos + 4, header_len, what), f"{what} at byte {pos}")
        (data_len,) = _U32.unpack(self.read(pos + 4 + header_len, 4, what))
        data_pos = pos + 8 + header_len
        if data_pos + data_len > self.size:
            raise Corrupt(f"{what} at byte {pos} whose {data_len} data bytes run past the end of the file")
        return fields, data_pos, data_len


def open_bag(path: str | os.PathLike[str]) -> Bag:
    """Open a bag and read its header, connections and chunk index.

    Raises
    ------
    InputError
        Not a bag of format 2.0, an unindexed (interrupted) or encrypted bag, or damage in the index.
    """
    p = check_regular_file(path, "ROS 1 bag")
    where = str(path)
    file = p.open("rb")
    try:
        bag = _open(file, where)
    except Corrupt as err:
        file.close()
        raise damaged(where, str(err)) from err
    except BaseException:
        file.close()
        raise
    return bag


def damaged(where: str, found: str) -> InputError:
    return InputError(
        where,
        "a complete, readable ROS 1 bag",
        found,
        "Copy the file again if it was transferred; `rosbag reindex` (ROS 1) rebuilds the index of an "
        "interrupted recording, `rosbag check` tells what else is wrong.",
    )


def _open(file: BinaryIO, where: str) -> Bag:
    size = os.fstat(file.fileno()).st_size
    head = file.read(len(MAGIC))
    if head != MAGIC:
        found = f"a file starting {head[:16]!r}" if head else "an empty file (0 bytes)"
        todo = "Pass a ROS 1 bag (.bag)."
        if head.startswith(b"#ROSBAG V"):
            found = f"a bag of format {head[9:].strip().decode('ascii', 'replace')}"
            todo = "Migrate it to format 2.0 with `rosbag fix` (ROS 1)."
        raise InputError(where, "a ROS 1 bag of format 2.0 (starting '#ROSBAG V2.0')", found, todo)
    reader = _Reader(file, size)
    fields, _, _ = reader.record(len(MAGIC), "the bag header record")
    if fields.get("op") != bytes([OP_BAG_HEADER]):
        raise Corrupt(f"no bag header record at byte {len(MAGIC)}")
    if fields.get("encryptor"):
        raise InputError(
            where,
            "an unencrypted ROS 1 bag",
            f"a bag encrypted with {fields['encryptor'].decode('ascii', 'replace')}",
            "Decrypt it with `rosbag decrypt` (ROS 1) first.",
        )
    index_pos = _get(fields, "index_pos", "<Q", "the bag header")
    conn_count = _get(fields, "conn_count", "<I", "the bag header")
    chunk_count = _get(fields, "chunk_count", "<I", "the bag header")
    if index_pos == 0:
        raise InputError(
            where,
            "an indexed ROS 1 bag",
            "a bag without an index (the recording was interrupted)",
            "Rebuild its index with `rosbag reindex` (ROS 1), then read it again.",
        )
    bag = Bag(file, where, size)
    pos = index_pos
    while pos < size:
        fields, data_pos, data_len = reader.record(pos, "an index-section record")
        op = fields.get("op", b"")
        if op == bytes([OP_CONNECTION]):
            conn = _connection(fields, reader.read(data_pos, data_len, "a connection record"), pos)
            bag.connections[conn.id] = conn
        elif op == bytes([OP_CHUNK_INFO]):
            bag.chunks.append(_chunk_info(fields, reader.read(data_pos, data_len, "a chunk-info record"), pos))
        pos = data_pos + data_len
    if len(bag.connections) != conn_count or len(bag.chunks) != chunk_count:
        raise Corrupt(
            f"an index section with {len(bag.connections)} connections and {len(bag.chunks)} chunks where the "
            f"header declares {conn_count} and {chunk_count}"
        )
    bag.chunks.sort(key=lambda c: c.pos)
    return bag


def _connection(fields: dict[str, bytes], data: bytes, pos: int) -> Connection:
    where = f"the connection record at byte {pos}"
    conn = _get(fields, "conn", "<I", where)
    inner = parse_header(data, where)
    if "type" not in inner:
        raise Corrupt(f"{where} without a message type")

    def text(raw: bytes | None) -> str:
        return (raw or b"").decode("utf-8", "replace")

    topic = text(fields.get("topic") or inner.get("topic"))
    return Connection(
        conn, topic, normalize(text(inner["type"])), text(inner.get("message_definition")), text(inner.get("md5sum"))
    )


def _chunk_info(fields: dict[str, bytes], data: bytes, pos: int) -> ChunkInfo:
    where = f"the chunk-info record at byte {pos}"
    if _get(fields, "ver", "<I", where) != 1:
        raise Corrupt(f"{where} of an unknown version")
    count = _get(fields, "count", "<I", where)
    if len(data) != 8 * count:
        raise Corrupt(f"{where} listing {count} connections in {len(data)} bytes")
    pairs = np.frombuffer(data, dtype="<u4").reshape(count, 2)
    start = fields.get("start_time", b"")
    end = fields.get("end_time", b"")
    if len(start) != 8 or len(end) != 8:
        raise Corrupt(f"{where} without its start and end times")
    return ChunkInfo(
        _get(fields, "chunk_pos", "<Q", where),
        _time_ns(start),
        _time_ns(end),
        {int(c): int(n) for c, n in pairs.tolist()},
    )


# --------------------------------------------------------------------------- chunks


def _decompress(raw: bytes, compression: str, size: int, what: str) -> U8Array:
    if compression == "none":
        out = np.frombuffer(raw, dtype=np.uint8)
    elif compression == "bz2":
        try:
            out = np.frombuffer(bz2.BZ2Decompressor().decompress(raw, max_length=size + 1), dtype=np.uint8)
        except (OSError, EOFError, ValueError) as err:
            raise Corrupt(f"{what} that does not decompress (bz2: {err})") from err
    else:
        try:
            out = unlz4(raw, size)
        except (RuntimeError, ValueError) as err:
            raise Corrupt(f"{what} that does not decompress (lz4: {err})") from err
    if out.size != size:
        raise Corrupt(f"{what} holding {out.size} bytes once decompressed where its header says {size}")
    return out


def _index(
    reader: _Reader, pos: int, entries: int, wanted: frozenset[int] | None, what: str
) -> tuple[dict[int, NDArray[np.void]], int]:
    """The ``entries`` index records from ``pos``: per connection, its (sec, nsec, offset) rows."""
    out: dict[int, NDArray[np.void]] = {}
    for _ in range(entries):
        fields, data_pos, data_len = reader.record(pos, f"an index record of {what}")
        where = f"the index record at byte {pos}"
        if fields.get("op") != bytes([OP_INDEX]) or _get(fields, "ver", "<I", where) != 1:
            raise Corrupt(f"no index record of version 1 at byte {pos} (after {what})")
        conn, count = _get(fields, "conn", "<I", where), _get(fields, "count", "<I", where)
        if data_len != count * _INDEX_ENTRY.itemsize:
            raise Corrupt(f"{where} listing {count} messages in {data_len} bytes")
        if wanted is None or conn in wanted:
            rows = np.frombuffer(reader.read(data_pos, data_len, where), dtype=_INDEX_ENTRY)
            out[conn] = np.concatenate([out[conn], rows]) if conn in out else rows
        pos = data_pos + data_len
    return out, pos


def blocks(bag: Bag, wanted: frozenset[int] | None) -> Iterator[Block]:
    """The chunks holding messages of the ``wanted`` connections (all when None), one at a time, in file order."""
    reader = _Reader(bag.file, bag.size)
    limit = max_block_bytes()
    for info in bag.chunks:
        if wanted is not None and not wanted & info.counts.keys():
            continue
        what = f"the chunk at byte {info.pos}"
        fields, data_pos, data_len = reader.record(info.pos, what)
        if fields.get("op") != bytes([OP_CHUNK]):
            raise Corrupt(f"no chunk record at byte {info.pos}, where the index places one")
        compression = fields.get("compression", b"").decode("ascii", "replace")
        size = _get(fields, "size", "<I", what)
        if compression not in COMPRESSIONS:
            raise InputError(
                bag.where,
                f"chunks compressed with {', '.join(COMPRESSIONS)}",
                f"{what} compressed with {compression!r}",
                "Recompress the bag with `rosbag compress --lz4` or `rosbag decompress` (ROS 1).",
            )
        if size > limit:
            raise block_too_large(bag.where, what, f"a chunk declaring {size} bytes")
        index, _ = _index(reader, data_pos + data_len, len(info.counts), wanted, what)
        data = _decompress(reader.read(data_pos, data_len, what), compression, size, what)
        yield Block(data, {conn: _messages(data, rows, conn, what) for conn, rows in index.items()}, what)


def record_spans(bag: Bag) -> dict[int, tuple[int, int, int]]:
    """Per connection: message count, first and last record time (ns), from the index records alone."""
    reader = _Reader(bag.file, bag.size)
    out: dict[int, tuple[int, int, int]] = {}
    for info in bag.chunks:
        what = f"the chunk at byte {info.pos}"
        _, data_pos, data_len = reader.record(info.pos, what)
        index, _ = _index(reader, data_pos + data_len, len(info.counts), None, what)
        for conn, rows in index.items():
            if rows.size:
                ns = rows["sec"].astype(np.int64) * 1_000_000_000 + rows["nsec"].astype(np.int64)
                n, first, last = out.get(conn, (0, int(ns.min()), int(ns.max())))
                out[conn] = (n + rows.size, min(first, int(ns.min())), max(last, int(ns.max())))
    return out


def _messages(data: U8Array, index: NDArray[np.void], conn: int, what: str) -> tuple[I64Array, I64Array, I64Array]:
    """The data start, size and record time of the message records the index places in ``data``."""
    at = index["offset"].astype(np.int64)
    time_ns = index["sec"].astype(np.int64) * 1_000_000_000 + index["nsec"].astype(np.int64)
    if at.size == 0:
        return at, at.copy(), time_ns
    n = data.size
    if int(at.max()) + 4 > n:
        raise Corrupt(f"an index entry pointing past the end of {what}")
    rows = Rows(data, at)
    header_len = rows.read(0, "<u4")[:, 0].astype(np.int64)
    if int((at + header_len).max()) + 8 > n:
        raise Corrupt(f"a record header running past the end of {what}")
    template = _template(data, int(at[0]), int(header_len[0]), what)
    same = header_len == header_len[0]
    if same.all() and template is not None:
        head = rows.read(4, "u1", int(header_len[0]))
        same &= np.all(head[:, template.mask] == template.names, axis=1)
        same &= head[:, template.op] == OP_MESSAGE
        same &= rows.read(4 + template.conn, "<u4")[:, 0] == conn
    else:
        same[:] = False
    data_at = at + 4 + header_len
    for i in np.flatnonzero(~same):  # an unusual header: read the record (skipping connection records) by hand
        data_at[i], header_len[i] = _slow_record(data, int(at[i]), conn, what)
    if int(data_at.max()) + 4 > n:
        raise Corrupt(f"a message record running past the end of {what}")
    size = Rows(data, data_at).read(0, "<u4")[:, 0].astype(np.int64)
    start = data_at + 4
    if int((start + size).max()) > n:
        raise Corrupt(f"a message running past the end of {what}")
    return start, size, time_ns


@dataclass(frozen=True)
class _Template:
    """The layout of a message record's header: name bytes (where ``mask``) and the op and conn values."""

    mask: NDArray[np.bool_]
    names: U8Array
    op: int  # offset of the op byte in the header
    conn: int  # offset of the conn value in the header


def _template(data: U8Array, at: int, header_len: int, what: str) -> _Template | None:
    """The header layout of the record at ``at``, when it is a message record with op, conn and time only."""
    if at + 4 + header_len > data.size:
        raise Corrupt(f"a record header running past the end of {what}")
    raw = data[at + 4 : at + 4 + header_len].tobytes()
    mask = np.ones(header_len, dtype=bool)
    values: dict[str, tuple[int, int]] = {}
    pos = 0
    while pos + 4 <= header_len:
        (length,) = _U32.unpack_from(raw, pos)
        name_end = raw.find(b"=", pos + 4, pos + 4 + length)
        if name_end < 0 or pos + 4 + length > header_len:
            return None
        values[raw[pos + 4 : name_end].decode("ascii", "replace")] = (name_end + 1, pos + 4 + length)
        mask[name_end + 1 : pos + 4 + length] = False
        pos += 4 + length
    expected = {"op": 1, "conn": 4, "time": 8}
    if pos != header_len or set(values) != set(expected) or any(e - s != expected[k] for k, (s, e) in values.items()):
        return None
    return _Template(mask, np.frombuffer(raw, np.uint8)[mask], values["op"][0], values["conn"][0])


def _slow_record(data: U8Array, at: int, conn: int, what: str) -> tuple[int, int]:
    """(data-length offset, header length) of the message record at ``at``; connection records before it skipped."""
    raw = memoryview(data.data)
    for _ in range(64):
        if at + 4 > data.size:
            break
        (header_len,) = _U32.unpack_from(raw, at)
        if at + 8 + header_len > data.size:
            break
        fields = parse_header(raw[at + 4 : at + 4 + header_len], what)
        op = fields.get("op", b"")
        if op == bytes([OP_MESSAGE]):
            if _get(fields, "conn", "<I", what) != conn:
                raise Corrupt(f"an index entry of connection {conn} pointing at another connection's message in {what}")
            return at + 4 + header_len, header_len
        if op != bytes([OP_CONNECTION]):
            break
        (data_len,) = _U32.unpack_from(raw, at + 4 + header_len)
        at += 8 + header_len + data_len
    raise Corrupt(f"an index entry pointing at no message record in {what}")


__all__ = [
    "Bag",
    "Block",
    "ChunkInfo",
    "Connection",
    "Corrupt",
    "blocks",
    "damaged",
    "open_bag",
    "parse_header",
    "record_spans",
]
