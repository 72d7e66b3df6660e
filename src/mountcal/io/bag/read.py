"""ROS 1 bags and the SQLite storage of ROS 2 bag folders, located a block at a time (a bag chunk, a batch
of SQLite rows) for the one path every ROS container is read through (:mod:`mountcal.io.ros.batches`; the
MCAP storage and ``--field`` on MCAP logs: :mod:`mountcal.io.mcap.topics`).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable, Generator, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mountcal.core.errors import InputError
from mountcal.io.bag import ros1
from mountcal.io.inputs import block_too_large, max_block_bytes
from mountcal.io.ros.batches import Batch, samples_of
from mountcal.io.ros.topics import Selection, Topic
from mountcal.io.ros.types import DefinitionError, Types, from_definition
from mountcal.io.ros2.cdr import CdrError, Rows, cdr_rows
from mountcal.io.samples import Samples

I64Array = NDArray[np.int64]
SQLITE_BATCH = 65_536  # rows fetched at once from a .db3


# --------------------------------------------------------------------------- ROS 1 bags


def ros1_topics(bag: ros1.Bag) -> dict[str, Topic]:
    """A bag's topics, each with the definitions its first connection records."""
    out = {}
    for name, conns in bag.topics().items():
        first = conns[0]
        types: Types | None
        try:
            types, problem = from_definition(first.definition, first.type_name), ""
        except DefinitionError as err:
            types, problem = None, str(err)
        ids = tuple(c.id for c in conns)
        count = sum(info.counts.get(i, 0) for info in bag.chunks for i in ids)
        out[name] = Topic(name, first.type_name, ids, types, problem, count)
    return out


def read_ros1(path: str | Path, *, topic: str | None = None, field: str | None = None) -> Samples:
    """The samples of a ROS 1 bag (see the module doc)."""
    bag = ros1.open_bag(path)
    try:
        return samples_of(
            bag.where, ros1_topics(bag), lambda sels: _ros1_batches(bag, sels), cdr=False, topic=topic, field=field
        )
    except ros1.Corrupt as err:
        raise ros1.damaged(bag.where, str(err)) from err
    finally:
        bag.file.close()


def _ros1_batches(bag: ros1.Bag, selections: Sequence[Selection]) -> Generator[Batch, None, None]:
    wanted = frozenset(i for s in selections for i in s.topic.ids)
    for block in ros1.blocks(bag, wanted):
        for sel in selections:
            parts = [block.messages[i] for i in sel.topic.ids if i in block.messages]
            if not parts or not sum(p[0].size for p in parts):
                continue
            start, size, record = (np.concatenate(c) for c in zip(*parts, strict=True))
            if len(parts) > 1:  # several publishers of one topic: back in file order
                order = np.argsort(start, kind="stable")
                start, size, record = start[order], size[order], record[order]
            yield Batch(sel, Rows(block.data, start, size), record, block.what)


# --------------------------------------------------------------------------- ROS 2 SQLite storage


def sqlite_batches(
    files: Sequence[Path], selections: Sequence[Selection], decompress: Callable[[bytes], bytes] | None
) -> Generator[Batch, None, None]:
    """Blocks of at most ``SQLITE_BATCH`` rows (one pass over each file, in insertion order), split by topic.

    The database is opened read-only and immutable: nothing is written beside it.
    """
    for file in files:
        db = sqlite3.connect(f"{file.resolve().as_uri()}?mode=ro&immutable=1", uri=True)
        try:
            ids = dict(db.execute("SELECT name, id FROM topics"))
            mine = {ids[s.topic.name]: s for s in selections if s.topic.name in ids}
            if not mine:
                continue
            marks = ",".join("?" * len(mine))
            cursor = db.execute(  # rowid order: the order of insertion, with no sort
                f"SELECT topic_id, timestamp, data FROM messages WHERE topic_id IN ({marks})", tuple(mine)
            )
            n = 0
            while rows := cursor.fetchmany(SQLITE_BATCH):
                topics, stamps, blobs = zip(*rows, strict=True)  # columns, transposed in C
                topic = np.array(topics, dtype=np.int64)
                record = np.array(stamps, dtype=np.int64)
                data = np.empty(len(blobs), dtype=object)
                data[:] = blobs
                what = f"rows {n}–{n + len(rows) - 1} of {file.name}"
                n += len(rows)
                del rows, blobs
                for topic_id, sel in mine.items():
                    take = topic == topic_id
                    if take.any():
                        yield _sqlite_batch(sel, data[take].tolist(), record[take], decompress, file, what)
        except sqlite3.DatabaseError as err:
            raise InputError(
                str(file), "a readable ROS 2 SQLite bag file", f"{type(err).__name__}: {err}", "Check the file."
            ) from err
        finally:
            db.close()


def _sqlite_batch(
    sel: Selection,
    data: list[bytes],
    record: I64Array,
    decompress: Callable[[bytes], bytes] | None,
    file: Path,
    what: str,
) -> Batch:
    if decompress is not None:
        data = [decompress(d) for d in data]
    size = np.fromiter(map(len, data), dtype=np.int64, count=len(data))
    if int(size.sum()) > max_block_bytes():  # one batch of rows is this reader's block
        raise block_too_large(str(file), f"a batch of {size.size} messages ({what})", f"{int(size.sum())} bytes")
    start = np.zeros(size.size, dtype=np.int64)
    np.cumsum(size[:-1], out=start[1:])
    buf = np.frombuffer(b"".join(data), dtype=np.uint8)
    try:
        return Batch(sel, cdr_rows(buf, start, size), record, what)
    except CdrError as err:
        raise InputError(
            str(file),
            f"CDR messages on {sel.topic.name!r}",
            str(err),
            err.fix or "The file is damaged or not a ROS 2 bag.",
        ) from err


__all__ = ["read_ros1", "ros1_topics", "sqlite_batches"]
