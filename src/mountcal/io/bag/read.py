"""ROS recordings to samples: ROS 1 bags, ROS 2 bag folders (SQLite ``.db3`` or ``.mcap`` storage), and
MCAP logs read with ``--field``, through one path: topics chosen (:mod:`.topics`), messages located a
block at a time by their container (a bag chunk, a batch of SQLite rows, an MCAP chunk), every
field decoded for the whole block from the message definitions (:mod:`mountcal.io.ros.kinds`).

Conventions as :mod:`mountcal.io.mcap.read` states them: a sample's time is its ``header.stamp``
(the record's time where the stamp is zero or the message has none); SI units; vectors in the
IMU message's frame; NaN or infinite values dropped and counted; a gyro marked unknown
(``angular_velocity_covariance[0] = −1``) is no gyro. Speed from a GNSS velocity is the horizontal
magnitude of its linear velocity (never negative); from odometry, ``twist.twist.linear.x``.
"""

from __future__ import annotations

import sqlite3
from collections import Counter
from collections.abc import Callable, Generator, Sequence
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from mountcal.core.errors import InputError
from mountcal.io.bag import ros1
from mountcal.io.bag.topics import Selection, Topic, choose_aux, choose_imu, mcap_topics
from mountcal.io.inputs import block_too_large, max_block_bytes, max_rows, too_many_rows
from mountcal.io.mcap.read import _concat, _gyro, _keep, _Piece, _pieces  # the MCAP reader's sample rules
from mountcal.io.mcap.records import Log
from mountcal.io.ros import kinds
from mountcal.io.ros.types import DefinitionError, Types, from_definition
from mountcal.io.ros2.cdr import CdrError, Decoded, Rows, cdr_rows
from mountcal.io.samples import Channel, FloatArray, Samples

I64Array = NDArray[np.int64]
SQLITE_BATCH = 65_536  # rows fetched at once from a .db3
MIN_COURSE_SPEED_MPS = 1.0  # a GNSS course over ground is a heading only while moving


@dataclass(frozen=True)
class Batch:
    """Messages of one selection from one block: their rows, record times (ns) and where they are."""

    selection: Selection
    rows: Rows
    record_ns: I64Array
    what: str


Batches = Callable[[Sequence[Selection]], Generator[Batch, None, None]]


def samples_of(
    where: str,
    topics: dict[str, Topic],
    batches: Batches,
    *,
    cdr: bool,
    topic: str | None = None,
    field: str | None = None,
    notes: Sequence[str] = (),
) -> Samples:
    """The samples of a recording whose topics are ``topics`` and whose messages ``batches`` yields."""
    imu = choose_imu(topics, where, topic, field)
    said = list(notes)
    aux = choose_aux(topics, where, said)
    selections = [imu, *(s for s in aux if s.topic.name != imu.topic.name)]
    collected: dict[str, list[_Piece]] = {}
    dropped: Counter[str] = Counter()
    held, limit = 0, max_rows()
    with closing(batches(selections)) as blocks:
        for batch in blocks:
            for key, piece in _decode(batch, where, cdr, dropped).items():
                collected.setdefault(key, []).append(piece)
                held += piece.t_s.size
            if held > limit:
                raise too_many_rows(where, "samples (all topics read)", held)
    if not sum(p.t_s.size for p in collected.get("imu", [])):
        found = f"no messages on {imu.topic.name!r}"
        if dropped["imu_nonfinite"]:
            found = f"{dropped['imu_nonfinite']} messages on {imu.topic.name!r}, all with NaN or infinite values"
        raise InputError(where, "IMU samples", found, "Check the recording, or read another topic.")
    samples = _concat(collected.pop("imu"))
    channels = {}
    for key, parts in collected.items():
        joined = _concat(parts)
        channels[key] = Channel(joined.t_s, joined.columns["value"])
    if imu.kind == "acc":
        gyro = None
        said.append(f"acceleration from {imu.topic.name} field {'.'.join(imu.target.prefix)}: no gyro")
    else:
        gyro = _gyro(samples, dropped)
    if imu.target.prefix and imu.kind == "imu":
        said.append(f"IMU from {imu.topic.name} field {'.'.join(imu.target.prefix)} ({imu.topic.type_name})")
    return Samples(
        t_s=samples.t_s,
        acc_s=samples.columns["acc"],
        gyro_s=gyro,
        channels=channels,
        source=where,
        dropped={k: v for k, v in dropped.items() if v},
        notes=tuple(said),
    )


def _decode(batch: Batch, where: str, cdr: bool, dropped: Counter[str]) -> dict[str, _Piece]:
    sel = batch.selection
    try:
        decoded = kinds.decode(batch.rows, sel.topic.definitions(where), sel.target, cdr=cdr)
    except CdrError as err:
        raise InputError(
            where,
            f"{sel.target.label} messages on {sel.topic.name!r} laid out as their definition says",
            f"{err}, in the {batch.what}",
            "The file is damaged, or its definition is not the one its messages were written with; "
            "export the topic to CSV instead.",
        ) from err
    t = _times(decoded, batch.record_ns)
    columns = {"t": t, **decoded.columns}
    if sel.kind == "acc":
        ok = np.isfinite(columns["acc"]).all(axis=1)
        dropped["imu_nonfinite"] += int((~ok).sum())
        return {"imu": _keep(t, {"acc": columns["acc"]}, ok)}
    if sel.kind == "velocity":
        v = columns["v"]
        speed = np.hypot(v[:, 0], v[:, 1])
        ok = np.isfinite(speed)
        dropped["speed_mps_nonfinite"] += int((~ok).sum())
        return {"speed_mps": _keep(t, {"value": speed}, ok)}
    if sel.kind == "nmea":
        return _nmea(t, columns, dropped)
    return _pieces(Decoded(decoded.sec, decoded.nanosec, columns), sel.kind, dropped)


def _nmea(t: FloatArray, columns: dict[str, FloatArray], dropped: Counter[str]) -> dict[str, _Piece]:
    """Speed from RMC/VTG sentences; their course as a heading while moving (at rest it is noise)."""
    bad = columns["bad_checksum"] > 0
    speed, course = columns["sog"], columns["cog"]
    has_speed = np.isfinite(speed)
    moving = has_speed & np.isfinite(course) & (speed >= MIN_COURSE_SPEED_MPS)
    dropped["nmea_bad_checksum"] += int(bad.sum())
    dropped["nmea_sentences_without_speed"] += int((~bad & ~has_speed).sum())
    dropped[f"heading_deg_below_{MIN_COURSE_SPEED_MPS:g}_mps"] += int((has_speed & np.isfinite(course) & ~moving).sum())
    return {
        "speed_mps": _keep(t, {"value": speed}, has_speed),
        "heading_deg": _keep(t, {"value": np.mod(course, 360.0)}, moving),
    }


def _times(decoded: Decoded, record_ns: I64Array) -> FloatArray:
    """Header stamp in seconds, or the record time where the stamp is zero (unset or absent)."""
    sec, nanosec = decoded.sec, decoded.nanosec
    unset = (sec == 0) & (nanosec == 0)
    if unset.any():
        sec = np.where(unset, record_ns // 1_000_000_000, sec)
        nanosec = np.where(unset, record_ns % 1_000_000_000, nanosec)
    return sec.astype(np.float64) + nanosec.astype(np.float64) * 1e-9


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
            str(file), f"CDR messages on {sel.topic.name!r}", str(err), "The file is damaged or not a ROS 2 bag."
        ) from err


# --------------------------------------------------------------------------- MCAP (ROS 2 storage, or --field)


def read_mcap_topics(path: str | Path, *, topic: str | None, field: str | None) -> Samples:
    """An MCAP log read through message definitions (for ``--field``)."""
    from mountcal.io.mcap.chunks import open_log
    from mountcal.io.mcap.records import Corrupt, damaged

    log = open_log(path)
    try:
        return samples_of(
            log.where, mcap_topics(log), lambda sels: mcap_batches(log, sels), cdr=True, topic=topic, field=field
        )
    except Corrupt as err:
        raise damaged(log.where, str(err)) from err
    finally:
        log.file.close()


def mcap_batches(
    log: Log, selections: Sequence[Selection], ids: dict[str, tuple[int, ...]] | None = None
) -> Generator[Batch, None, None]:
    """Blocks (MCAP chunks) of the selections' messages; ``ids`` gives each topic's channel ids in this
    file when they are not those of the selection (the files of a ROS 2 bag number channels apart)."""
    from mountcal.io.mcap.chunks import chunk_units
    from mountcal.io.mcap.records import MESSAGE_HEAD, RECORD_HEAD, record_field

    channel_ids = {s.topic.name: s.topic.ids if ids is None else ids.get(s.topic.name, ()) for s in selections}
    wanted = frozenset(i for v in channel_ids.values() for i in v)
    with closing(chunk_units(log, wanted)) as units:
        for unit in units:
            channel = record_field(unit.data, unit.messages, RECORD_HEAD.size, "<u2")
            for sel in selections:
                mine = np.isin(channel, channel_ids[sel.topic.name])
                if not mine.any():
                    continue
                at, size = unit.messages[mine], unit.lengths[mine] - MESSAGE_HEAD
                record = record_field(unit.data, at, RECORD_HEAD.size + 6, "<u8").astype(np.int64)
                try:
                    rows = cdr_rows(unit.data, at + RECORD_HEAD.size + MESSAGE_HEAD, size)
                except CdrError as err:
                    raise InputError(
                        log.where,
                        f"CDR messages on {sel.topic.name!r}",
                        f"{err}, in the {unit.what}",
                        "Check the file.",
                    ) from err
                yield Batch(sel, rows, record, unit.what)
            del unit


__all__ = ["read_mcap_topics", "read_ros1", "ros1_topics", "samples_of", "sqlite_batches"]
