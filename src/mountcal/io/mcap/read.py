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
  rule is applied per message and identically on every topic. A topic stamped on another clock
  than the recorder's (a driver's boot time, seconds since power-on, against ``log_time`` in Unix
  time: more than 60 s apart) is moved onto the recorder's by its median ``log_time − stamp``, one
  constant per topic, and said (convention ``stamp_clock``, :mod:`mountcal.io.stamp_clock`), so all
  channels share one clock; topics on the recorder's clock are left as stamped. Times are float64
  seconds (sub-microsecond resolution at Unix-epoch magnitudes). :func:`iter_mcap` streams the IMU
  alone, as stamped.
- **Units**: SI as in :class:`~mountcal.io.samples.Samples`; vectors in the IMU message's
  ``frame_id`` frame, taken as the sensor frame ``s`` (``axis_map`` ``"x,y,z"``); the ``frame_id``
  values are counted (``Samples.frame_ids``: :mod:`mountcal.io.sensor_frame`).
- **Drops**: samples with a NaN or infinite value are dropped and counted in ``Samples.dropped``;
  so are GNSS fixes with ``status < 0`` (no fix) and odometry orientations that are not a rotation.
- **Gyro**: ``angular_velocity_covariance[0] = −1`` (REP 145: not provided) in any message of a read
  or chunk means no gyro (``gyro_s`` None), counted as ``imu_gyro_marked_unknown``; its zeros
  would otherwise read as a vehicle that never turns.
- **Errors**: anything wrong with the file or the request raises
  :class:`~mountcal.core.errors.InputError` naming the file, what was expected, what was found and what to
  do. The input file is only read.
"""

from __future__ import annotations

import json
import os
from collections import Counter
from collections.abc import Generator, Iterator, Sequence
from contextlib import closing
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from mountcal.core import budget
from mountcal.core.errors import InputError
from mountcal.io.frame import Rotated, channel_rotated, topic_label
from mountcal.io.heading_frame import heading_frame_convention
from mountcal.io.mcap.chunks import Unit, chunk_units, open_log
from mountcal.io.mcap.records import (
    ARGUMENT,
    ENCODINGS,
    MESSAGE_HEAD,
    RECORD_HEAD,
    TYPE_NAME,
    Corrupt,
    I64Array,
    Log,
    McapChannel,
    U8Array,
    damaged,
    record_field,
)
from mountcal.io.reader import CHUNK_SAMPLES
from mountcal.io.ros.pieces import Piece, concat, gyro_of, join_unsorted, pieces_of
from mountcal.io.ros2 import cdr
from mountcal.io.samples import Channel, FloatArray, Samples
from mountcal.io.sensor_frame import frame_ids
from mountcal.io.stamp_clock import StampClocks

if TYPE_CHECKING:
    from mountcal.core.result import Convention

STREAM_CLOCK_BLOCKS = 8  # blocks per topic a stream judges its clock on: bounded memory, and a steady clock shows

# --------------------------------------------------------------------------- choosing topics


@dataclass(frozen=True)
class _Selection:
    kind: str  # "imu", "temperature", "fix", "odom"
    topic: str
    channel_ids: frozenset[int]
    encoding: str  # "cdr" or "json"
    rotated: Rotated | None = None  # what the chosen channel's own metadata say of its frame


def schema_fields(text: str) -> tuple[tuple[str, str], ...]:
    """Top-level (type base name, field name) of a ``ros2msg`` definition; constants skipped."""
    out = []
    for line in text.split("\n=====", 1)[0].splitlines():
        words = line.split("#", 1)[0].split()
        if len(words) < 2 or "=" in words[1] or (len(words) > 2 and words[2].startswith("=")):
            continue
        out.append((words[0].rsplit("/", 1)[-1], words[1]))
    return tuple(out)


def _select(log: Log, kind: str, topic: str | None) -> _Selection | None:
    """The topic to read for ``kind``: the one named, else the only one of that type."""
    topics = log.topics()
    argument, flag = ARGUMENT[kind], f"--{ARGUMENT[kind].replace('_', '-')}"
    candidates = [t for t, chs in topics.items() if log.kind(chs[0]) == kind]
    names = ", ".join(topic_label(t, topics[t][0].metadata) for t in candidates)
    if topic is not None:
        if topic not in topics:
            raise InputError(
                log.where,
                f"a topic named {topic!r}",
                f"topics {log.listing()}",
                f"Pass one of the {TYPE_NAME[kind]} topics ({names}) as {argument}= (CLI: {flag})."
                if candidates
                else f"The log has no {TYPE_NAME[kind]} topic to pass as {argument}= (CLI: {flag}).",
            )
        chosen = topics[topic]
        if any(log.kind(ch) != kind for ch in chosen):
            raise InputError(
                log.where,
                f"topic {topic!r} of type {TYPE_NAME[kind]}",
                f"type {log.type_name(chosen[0])}",
                f"Pass a {TYPE_NAME[kind]} topic as {argument}= (CLI: {flag})"
                + (f": {names}." if candidates else "; the log has none.")
                + _field_hint(log, kind),
            )
    else:
        if len(candidates) != 1:
            if kind != "imu" and not candidates:
                return None
            raise InputError(
                log.where,
                f"exactly one {TYPE_NAME[kind]} topic",
                f"{len(candidates)}: {names}" if candidates else f"none; the topics are {log.listing()}",
                f"Name the topic to read with {argument}= (CLI: {flag})."
                + ("" if candidates else _field_hint(log, kind)),
            )
        topic = candidates[0]
        chosen = topics[topic]
    encoding = _check_encoding(log, kind, topic, chosen)
    rotated = next((r for ch in chosen if (r := channel_rotated(ch.metadata, topic)) is not None), None)
    return _Selection(kind, topic, frozenset(ch.id for ch in chosen), encoding, rotated)


def _field_hint(log: Log, kind: str) -> str:
    """How to read an Imu or Vector3 that a topic's message carries (``--topic … --field …``), or ""."""
    if kind != "imu":
        return ""
    from mountcal.io.mcap.topics import mcap_topics
    from mountcal.io.ros.topics import carried_hint

    return carried_hint(mcap_topics(log))


def _check_encoding(log: Log, kind: str, topic: str, channels: Sequence[McapChannel]) -> str:
    encodings = {ch.message_encoding for ch in channels}
    encoding = encodings.pop()
    if encodings or encoding not in ENCODINGS:
        raise InputError(
            log.where,
            f"topic {topic!r} encoded as CDR (ROS 2) or JSON",
            f"message encoding {encoding!r}",
            "Convert the log to ROS 2 CDR (for example with rosbags-convert) or export it to CSV.",
        )
    schema = log.schemas.get(channels[0].schema_id)
    if encoding == "cdr" and schema is not None and schema.encoding == "ros2msg":
        declared = schema_fields(schema.data.decode(errors="replace"))
        if declared != cdr.FIELDS[kind]:
            raise InputError(
                log.where,
                f"topic {topic!r} with the standard {TYPE_NAME[kind]} fields "
                f"({', '.join(name for _, name in cdr.FIELDS[kind])})",
                f"a schema declaring {', '.join(f'{t} {n}' for t, n in declared) or 'no fields'}",
                "Export this topic to CSV, or convert it to the standard message.",
            )
    return encoding


# --------------------------------------------------------------------------- decoding


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
    frames: Counter[str] = Counter()
    raw = data.tobytes()
    for s, n in zip(start.tolist(), size.tolist(), strict=True):
        try:
            message = json.loads(raw[s : s + n])
        except (json.JSONDecodeError, UnicodeDecodeError) as err:
            raise cdr.CdrError(f"a message that is not JSON ({err})") from err
        stamps.append(_json_stamp(message))
        unknown.append(_json_gyro_unknown(message))
        frames[_json_frame_id(message)] += 1
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
    return cdr.Decoded(sec, nanosec, columns, dict(frames) if kind in ("imu", "odom") else {})


def _json_frame_id(message: object) -> str:
    """``header.frame_id``, or "" when absent (a message naming no frame)."""
    header = message.get("header") if isinstance(message, dict) else None
    frame = header.get("frame_id") if isinstance(header, dict) else None
    return frame if isinstance(frame, str) else ""


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


def _decode(unit: Unit, mine: NDArray[np.bool_], sel: _Selection) -> tuple[cdr.Decoded, NDArray[np.uint64]]:
    """Fields of the unit's messages selected by ``mine`` (``sel``'s topic), with ``t`` in seconds; their
    log times (ns)."""
    at, size = unit.messages, unit.lengths - MESSAGE_HEAD
    if not mine.all():
        at, size = at[mine], size[mine]
    start = at + RECORD_HEAD.size + MESSAGE_HEAD
    if sel.encoding == "cdr":
        decoded = cdr.DECODERS[sel.kind](unit.data, start, size)
    else:
        decoded = _decode_json(sel.kind, unit.data, start, size)
    log_ns = record_field(unit.data, at, RECORD_HEAD.size + 6, "<u8")
    columns = {"t": _times(decoded, log_ns), **decoded.columns}
    return cdr.Decoded(decoded.sec, decoded.nanosec, columns, decoded.frames), log_ns


# pieces, drops, the IMU's and the odometry's frame_ids
UnitDecoded = tuple[dict[str, Piece], Counter[str], Counter[str], Counter[str]]


def _decode_unit(
    unit: Unit, selections: Sequence[_Selection], where: str, clocks: StampClocks | None = None
) -> UnitDecoded:
    """One unit's finite, time-sorted pieces of every selection, what was dropped, and the IMU
    messages' and the odometry's ``header.frame_id`` values with their counts; each topic's stamps
    against its log times told to ``clocks``."""
    channel = record_field(unit.data, unit.messages, RECORD_HEAD.size, "<u2")
    pieces: dict[str, Piece] = {}
    dropped: Counter[str] = Counter()
    frames: Counter[str] = Counter()
    odom_frames: Counter[str] = Counter()
    for sel in selections:
        ids = list(sel.channel_ids)
        mine = channel == ids[0] if len(ids) == 1 else np.isin(channel, ids)
        if not mine.any():
            continue
        try:
            decoded, log_ns = _decode(unit, mine, sel)
        except cdr.CdrError as err:
            raise InputError(
                where,
                f"{TYPE_NAME[sel.kind]} messages on {sel.topic!r} laid out as the schema says",
                f"{err}, in the {unit.what}",
                err.fix or "The file is damaged or mislabelled; export the topic to CSV instead.",
            ) from err
        (frames if sel.kind == "imu" else odom_frames).update(decoded.frames)  # IMU's and odometry's only
        mine_pieces = pieces_of(decoded, sel.kind, dropped)
        if clocks is not None:
            clocks.add(sel.topic, decoded.sec, decoded.nanosec, log_ns.astype(np.int64), mine_pieces)
        pieces.update(mine_pieces)
    return pieces, dropped, frames, odom_frames


def _decoded_units(
    log: Log, selections: Sequence[_Selection], clocks: StampClocks | None = None
) -> Generator[UnitDecoded, None, None]:
    """Per unit, in file order: what :func:`_decode_unit` gives."""
    wanted = frozenset(i for s in selections for i in s.channel_ids)
    with closing(chunk_units(log, wanted)) as units:
        for unit in units:
            decoded = _decode_unit(unit, selections, log.where, clocks)
            del unit  # not held while the next chunk is read
            yield decoded


# --------------------------------------------------------------------------- public API


def _no_samples(log: Log, topic: str, dropped: Counter[str]) -> InputError:
    found = f"no messages on {topic!r}"
    if dropped["imu_nonfinite"]:
        found = f"{dropped['imu_nonfinite']} messages on {topic!r}, all with NaN or infinite values"
    return InputError(log.where, "IMU samples", found, "Check the recording, or pass another topic=.")


def _read(path: str | os.PathLike[str], fn_topics: dict[str, str | None]) -> Samples:
    log = open_log(path)
    try:
        return _read_open(log, fn_topics)
    except Corrupt as err:
        raise damaged(log.where, str(err)) from err
    finally:
        log.file.close()


def _read_open(log: Log, topics: dict[str, str | None]) -> Samples:
    imu = _select(log, "imu", topics["imu"])
    assert imu is not None  # the IMU topic is never optional
    aux = [_select(log, kind, topic) for kind, topic in topics.items() if kind != "imu" and topic != ""]
    selections = [imu, *(s for s in aux if s is not None)]
    collected: dict[str, list[Piece]] = {}
    dropped: Counter[str] = Counter()
    frames: Counter[str] = Counter()
    odom_frames: Counter[str] = Counter()
    clocks = StampClocks("log_time")
    with closing(_decoded_units(log, selections, clocks)) as units:
        for pieces, drops, named, odom_named in units:
            dropped.update(drops)
            frames.update(named)
            odom_frames.update(odom_named)
            for key, piece in pieces.items():
                collected.setdefault(key, []).append(piece)
            # counted a chunk at a time, before the whole log is held
            budget.charge("rows", sum(p.t_s.size for p in pieces.values()), log.where, "samples (all topics read)")
    if not collected.get("imu") or not sum(p.t_s.size for p in collected["imu"]):
        raise _no_samples(log, imu.topic, dropped)
    samples = concat(collected.pop("imu"))
    channels = {}
    for key, parts in collected.items():
        joined = concat(parts)
        channels[key] = Channel(joined.t_s, joined.columns["value"])
    read = Samples(
        t_s=samples.t_s,
        acc_s=samples.columns["acc"],
        gyro_s=gyro_of(samples, dropped),
        channels=channels,
        source=log.where,
        dropped={k: v for k, v in dropped.items() if v},
        rotated=imu.rotated,
        frame_ids=frame_ids(imu.topic, frames, log.where),
        conventions=_heading_frame(aux, channels, odom_frames, log.where),
    )
    return clocks.settle(read)  # topics stamped on another clock than the recorder's: onto it, said


def _heading_frame(
    aux: Sequence[_Selection | None], channels: dict[str, Channel], counts: Counter[str], where: str
) -> tuple[Convention, ...]:
    """The frame of the heading channel, where it came from odometry (:mod:`mountcal.io.heading_frame`)."""
    odom = next((s for s in aux if s is not None and s.kind == "odom"), None)
    if odom is None or "heading_deg" not in channels:
        return ()
    said = heading_frame_convention(odom.topic, counts, where)
    return () if said is None else (said,)


@budget.scoped
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
    path: str | os.PathLike[str], *, topic: str | None = None, max_samples: int = CHUNK_SAMPLES
) -> Iterator[Samples]:
    """Stream the IMU samples of an MCAP log in batches of at most ``max_samples``, bounded memory.

    The file is checked and the topic chosen (as in :func:`read_mcap`) before this returns; then
    one MCAP chunk at a time is decoded. Each batch is sorted by time; batches follow the file's
    chunk order, which is time order for recorders that write chunks as they go. Concatenated, the
    batches equal :func:`read_mcap`'s IMU samples and channels whenever chunks do not overlap in time
    (every topic's clock judged on its first :data:`STREAM_CLOCK_BLOCKS` blocks, not on the whole log).

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
        ``t_s`` (m,), ``acc_s`` and ``gyro_s`` (m, 3), m ≤ ``max_samples``, as in :func:`read_mcap`,
        with the auxiliary samples read since the batch before (the only temperature, fix and odometry
        topic of each type; none of a type with several); ``dropped`` counts the samples dropped from
        the chunks that fed this batch.

    Raises
    ------
    InputError
        As :func:`read_mcap`, the file-level problems immediately, damage found in a later chunk
        when the iteration reaches it.
    """
    if max_samples < 1:
        raise ValueError(f"max_samples must be at least 1, got {max_samples}")
    log = open_log(path)
    try:
        selection = _select(log, "imu", topic)
        aux = tuple(a for kind in ("temperature", "fix", "odom") if (a := _the_only(log, kind)) is not None)
    finally:
        log.file.close()
    assert selection is not None  # the IMU topic is never optional
    return _iter_batches(path, selection, aux, max_samples)


def has_odometry(path: str | os.PathLike[str]) -> bool:
    """Whether the log holds an odometry topic: an MCAP's only source of a speed and a heading."""
    log = open_log(path)
    try:
        return any(log.kind(channels[0]) == "odom" for channels in log.topics().values())
    finally:
        log.file.close()


def _the_only(log: Log, kind: str) -> _Selection | None:
    """The auxiliary topic of ``kind`` a stream carries: the only one of its type; none where there are several
    (:func:`read_mcap` asks which; a stream, which only rotates, goes on without)."""
    try:
        return _select(log, kind, None)
    except InputError:
        return None


@budget.scoped_iter
def _iter_batches(
    path: str | os.PathLike[str], selection: _Selection, aux: tuple[_Selection, ...], max_samples: int
) -> Iterator[Samples]:
    log = open_log(path, discover=False)  # the channels were chosen already
    try:
        yield from _batches(log, selection, aux, max_samples)
    except Corrupt as err:
        raise damaged(log.where, str(err)) from err
    finally:
        log.file.close()


def _batches(log: Log, selection: _Selection, aux: tuple[_Selection, ...], max_samples: int) -> Iterator[Samples]:
    """IMU batches, each with the auxiliary samples read since the batch before, every topic moved onto the
    recorder's clock as :func:`read_mcap` moves it (judged on the blocks read so far: a steady clock shows in its
    first)."""
    pending: list[Piece] = []
    count, total = 0, 0
    dropped: Counter[str] = Counter()
    frames: Counter[str] = Counter()
    odom_frames: Counter[str] = Counter()
    held: dict[str, list[Piece]] = {}
    clocks = StampClocks("log_time", max_blocks=STREAM_CLOCK_BLOCKS)

    def settled(batch: Samples) -> Samples:
        channels = {}
        for key, parts in held.items():
            joined = concat(parts)
            channels[key] = Channel(joined.t_s, joined.columns["value"])
        held.clear()
        conventions = _heading_frame(aux, channels, odom_frames, log.where)
        return clocks.settle(replace(batch, channels=channels, conventions=conventions))

    with closing(_decoded_units(log, [selection, *aux], clocks)) as units:
        for pieces, drops, named, odom_named in units:
            dropped.update(drops)
            frames.update(named)
            odom_frames.update(odom_named)
            for key, piece in pieces.items():
                if key != "imu" and piece.t_s.size:
                    held.setdefault(key, []).append(piece)
            if "imu" in pieces and pieces["imu"].t_s.size:
                pending.append(pieces["imu"])
                count += pieces["imu"].t_s.size
            while count >= max_samples:
                joined = join_unsorted(pending)
                yield settled(_batch(log, selection, joined, 0, max_samples, dropped, frames))
                pending = [_slice(joined, max_samples, count)]
                count, total, dropped, frames = count - max_samples, total + max_samples, Counter(), Counter()
    if count:
        yield settled(_batch(log, selection, join_unsorted(pending), 0, count, dropped, frames))
    elif not total:
        raise _no_samples(log, selection.topic, dropped)
    elif held:  # auxiliary samples after the last IMU batch: carried by an empty one
        yield settled(Samples(np.empty(0), np.empty((0, 3)), source=log.where, rotated=selection.rotated))


def _slice(piece: Piece, start: int, stop: int) -> Piece:
    return Piece(piece.t_s[start:stop], {k: v[start:stop] for k, v in piece.columns.items()})


def _batch(
    log: Log, selection: _Selection, piece: Piece, start: int, stop: int, dropped: Counter[str], frames: Counter[str]
) -> Samples:
    """Rows ``start:stop`` of ``piece`` as Samples of their own (copied, sorted by time); ``dropped`` and
    ``frames`` count the messages of the chunks that fed it."""
    part = concat([_slice(piece, start, stop)])
    gyro = gyro_of(part, dropped)
    return Samples(
        t_s=part.t_s.copy(),
        acc_s=part.columns["acc"].copy(),
        gyro_s=None if gyro is None else gyro.copy(),
        source=log.where,
        dropped={k: v for k, v in dropped.items() if v},
        rotated=selection.rotated,
        frame_ids=frame_ids(selection.topic, frames, log.where),
    )
