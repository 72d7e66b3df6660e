"""ROS 2 bags: a folder with ``metadata.yaml`` and its storage files (SQLite ``.db3`` or ``.mcap``), or a
lone ``.db3``. ``rosbags`` reads the metadata (every rosbag2 version), the topics and the message
definitions the storage holds (and decompresses a file-compressed bag into a temporary folder);
the messages are read a block at a time (:mod:`mountcal.io.ros.batches`).
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mountcal.core.errors import InputError
from mountcal.io.bag.read import sqlite_batches
from mountcal.io.folder import Folder, LocalFolder
from mountcal.io.mcap.topics import mcap_batches, mcap_topics
from mountcal.io.ros.batches import Batch, samples_of
from mountcal.io.ros.topics import Selection, Topic
from mountcal.io.ros.types import DefinitionError, Types, from_definition, standard
from mountcal.io.samples import LogSummary, Samples, Stream

STORAGES = {".db3": "sqlite3", ".mcap": "mcap"}
METADATA = "metadata.yaml"


@dataclass(frozen=True)
class Opened:
    """A ROS 2 bag opened by rosbags: where it is, its storage, files, topics and message compression."""

    where: str
    storage: str  # "sqlite3" or "mcap"
    files: tuple[Path, ...]  # the storage files to read (decompressed copies for a file-compressed bag)
    topics: dict[str, Topic]
    counts: dict[str, int]
    message_compression: bool
    duration_s: float


def bag_folder(path: Path) -> Path | None:
    """``path`` when it is a bag folder (it holds ``metadata.yaml``), else None.

    Its ``metadata.yaml`` alone is not claimed: a folder walk (``mountcal fleet``) would read the bag
    once for that file and once more for its storage files.
    """
    return path if path.is_dir() and holds_bag(LocalFolder(path)) else None


def holds_bag(folder: Folder) -> bool:
    """Whether a folder (on disk, or a prefix listed in object storage) is a ROS 2 bag: it holds ``metadata.yaml``."""
    return folder.has_file(METADATA)


@contextmanager
def open_bag(path: Path) -> Iterator[Opened]:
    """Open a ROS 2 bag folder (or a lone ``.db3``) with rosbags; closed (temporary copies removed) on exit.

    Raises
    ------
    InputError
        No metadata, a storage or compression rosbags cannot read, a damaged database.
    """
    from rosbags.rosbag2 import Reader, ReaderError

    folder = bag_folder(path)
    target = folder or path
    where = str(path)
    try:
        reader = Reader(target)
        reader.open()
    except FileNotFoundError as err:
        raise InputError(
            where, "a ROS 2 bag folder with its metadata.yaml and storage files", str(err), _REINDEX
        ) from err
    except (ReaderError, KeyError, ValueError, TypeError) as err:
        raise InputError(where, "a ROS 2 bag that rosbags can read", f"{type(err).__name__}: {err}", _REINDEX) from err
    try:
        yield _opened(reader, where, folder is None)
    finally:
        reader.close()


_REINDEX = (
    "Give the bag's folder (the one holding metadata.yaml); `ros2 bag reindex FOLDER` rewrites a lost "
    "metadata.yaml. A single storage file is read as it is: a .db3, or an .mcap as an MCAP log."
)


def _opened(reader: Any, where: str, lone: bool) -> Opened:
    storage_obj = reader.storage
    if lone:
        storages = [storage_obj]
        compression = None
    else:
        storages = list(storage_obj.storages)
        compression = reader.compression_mode
    files = tuple(Path(s.path) for s in storages)
    kinds = {STORAGES.get(f.suffix.lower(), f.suffix) for f in files}
    if len(kinds) != 1 or next(iter(kinds)) not in STORAGES.values():
        raise InputError(
            where,
            "a ROS 2 bag stored in SQLite (.db3) or MCAP",
            f"storage files {[f.name for f in files]}",
            "Convert it with `ros2 bag convert`.",
        )
    topics: dict[str, Topic] = {}
    counts: dict[str, int] = {}
    for conn in reader.connections:
        counts[conn.topic] = counts.get(conn.topic, 0) + int(conn.msgcount)
    for conn in reader.connections:
        if conn.topic not in topics:
            types, problem = _definitions(conn)
            topics[conn.topic] = Topic(conn.topic, conn.msgtype, (conn.id,), types, problem, counts[conn.topic])
    return Opened(
        where,
        next(iter(kinds)),
        files,
        topics,
        counts,
        compression == "message",
        float(reader.duration) * 1e-9 if reader.message_count else 0.0,
    )


def _definitions(conn: Any) -> tuple[Types | None, str]:
    """The definitions a connection carries (stored in the bag), else the standard ones of its type."""
    from rosbags.interfaces import MessageDefinitionFormat

    fmt, data = conn.msgdef.format, conn.msgdef.data
    try:
        if fmt == MessageDefinitionFormat.MSG and data:
            return from_definition(data, conn.msgtype, "msg"), ""
        if fmt == MessageDefinitionFormat.IDL and data:
            return from_definition(data, conn.msgtype, "idl"), ""
        return standard(conn.msgtype), ""
    except DefinitionError as err:
        return None, str(err)


def _unzstd(data: bytes) -> bytes:
    """One message of a bag compressed message by message, inflated to at most the block limit."""
    import zstandard

    from mountcal.io.inputs import max_block_bytes

    return zstandard.ZstdDecompressor().decompress(data, max_output_size=max_block_bytes())


def read_ros2(path: Path, *, topic: str | None = None, field: str | None = None) -> Samples:
    """The samples of a ROS 2 bag (see :mod:`mountcal.io.bag.read` for the conventions)."""
    with open_bag(path) as bag:
        notes = []
        if bag.message_compression:
            notes.append("messages zstd-compressed one by one in the bag: decompressed one by one (slower)")
        batches: Callable[[Sequence[Selection]], Generator[Batch, None, None]]
        if bag.storage == "sqlite3":
            decompress = _unzstd if bag.message_compression else None

            def batches(sels: Sequence[Selection]) -> Generator[Batch, None, None]:
                return sqlite_batches(bag.files, sels, decompress)

        else:
            if bag.message_compression:
                raise InputError(
                    bag.where,
                    "a ROS 2 MCAP bag without per-message compression",
                    "messages compressed one by one",
                    "Convert it with `ros2 bag convert` to chunk compression (the MCAP default).",
                )

            def batches(sels: Sequence[Selection]) -> Generator[Batch, None, None]:
                return _mcap_files(bag.files, sels)

        return samples_of(bag.where, bag.topics, batches, cdr=True, topic=topic, field=field, notes=notes)


def _mcap_files(files: Sequence[Path], selections: Sequence[Selection]) -> Generator[Batch, None, None]:
    from mountcal.io.mcap.chunks import open_log
    from mountcal.io.mcap.records import Corrupt, damaged

    for file in files:
        log = open_log(file)
        try:
            ids = {name: t.ids for name, t in mcap_topics(log).items()}
            yield from mcap_batches(log, selections, ids)
        except Corrupt as err:
            raise damaged(log.where, str(err)) from err
        finally:
            log.file.close()


def inspect_ros2(path: Path) -> LogSummary:
    """What a ROS 2 bag holds: topics, types, counts (from its metadata), rates and fields."""
    with open_bag(path) as bag:
        spans = _spans(bag)
        streams = []
        for name, t in bag.topics.items():
            count, first, last = spans.get(name, (bag.counts.get(name, 0), 0, 0))
            rate = (count - 1) / ((last - first) * 1e-9) if count > 1 and last > first else 0.0
            fields = tuple(f for f, _ in t.types[t.type_name][1]) if t.types is not None else ()
            streams.append(Stream(name, t.type_name, count, rate, fields))
        return LogSummary(bag.where, f"ros2 bag ({bag.storage})", bag.duration_s, tuple(streams))


def _spans(bag: Opened) -> dict[str, tuple[int, int, int]]:
    """Per topic: message count, first and last record time (ns), over every storage file."""
    import sqlite3

    from mountcal.io.mcap.inspect import topic_spans

    out: dict[str, tuple[int, int, int]] = {}
    for file in bag.files:
        if bag.storage == "sqlite3":
            db = sqlite3.connect(f"{file.resolve().as_uri()}?mode=ro&immutable=1", uri=True)
            try:
                rows = db.execute(
                    "SELECT topics.name, COUNT(*), MIN(timestamp), MAX(timestamp) FROM messages "
                    "JOIN topics ON messages.topic_id = topics.id GROUP BY topics.name"
                ).fetchall()
            except sqlite3.DatabaseError as err:
                raise InputError(str(file), "a readable ROS 2 SQLite bag file", str(err), "Check the file.") from err
            finally:
                db.close()
        else:
            rows = [(name, *span) for name, span in topic_spans(file).items()]
        for name, count, first, last in rows:
            n, a, b = out.get(name, (0, first, last))
            out[name] = (n + int(count), min(a, int(first)), max(b, int(last)))
    return out


__all__ = ["bag_folder", "holds_bag", "inspect_ros2", "open_bag", "read_ros2"]
