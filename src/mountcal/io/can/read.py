"""Accelerometer (and gyro) samples from a CAN log and a DBC: the signal mapping and the readers.

A *mapping* says which DBC signals hold the accelerometer axes, the optional gyro axes and the
auxiliary channels, in which units, on which channel, and how the device's axes map to the
right-handed sensor frame. It is a small TOML file (or the equivalent dict)::

    channel = 2                    # optional: CAN channel, python-can numbering
    axes = "x,y,z"                 # optional: sensor axis i = signed device axis, e.g. "-y,x,z"
    allow_left_handed = false      # optional: true or a reason, to accept a reflection
    valid = ["gnss_imu.ImuValid"]  # optional: frames whose validity signal is 0 are dropped

    [signals]                      # message.signal; the message by name or by id ("0x9")
    ax = "gnss_imu.AccelerationX"
    ay = "gnss_imu.AccelerationY"
    az = "gnss_imu.AccelerationZ"
    gx = "gnss_imu.AngularRateX"   # optional gx, gy, gz
    gy = "gnss_imu.AngularRateY"
    gz = "gnss_imu.AngularRateZ"
    speed = "gnss_speed.Speed"     # optional: temperature, speed, heading, latitude, longitude, altitude
    heading = "gnss_attitude.Heading"

    [units]                        # optional: overrides the DBC's units
    accel = "m/s^2"                # m/s^2 or g
    gyro = "deg/s"                 # deg/s or rad/s

An optional ``[messages]`` table places a DBC message at another id and/or channel, e.g.
``MM5_10_TX1 = { id = 0x174, channel = 1 }`` (``extended = true`` for a 29-bit id <= 0x7FF).
The DBC may be several files (their messages together; a name or id defined twice is refused). A
message of a J1939 DBC (``VFrameFormat`` ``J1939PG``) is matched by its PGN, from any source
address; one PGN from several source addresses is refused until ``[messages]`` picks one id.

Without a mapping (or without its ``[signals]`` table) the signals are detected from their names
when the DBC and the log make the choice unambiguous: one message with AccelerationX/Y/Z, AccX..,
AX/AY/AZ or Accel_Longitudinal/Lateral/Vertical, or one such signal per axis across messages. A
message name the DBC defines twice (CANedge's gnss.dbc) resolves to the one present in the log.
Gyro axes and the auxiliary channels (Speed, Heading, Latitude, ...; a temperature only from the
accelerometer's own message) are added when they are as unambiguous; the log is read an extra time
only when the DBC alone leaves a choice. Without ``valid``, 1-bit signals whose name contains
"valid" in a used message are the validity flags.

Axes in different messages (Bosch MM5.10: AY1 in 0x70, AX1 in 0x80, AZ in 0x576) are aligned on
the clock of the message carrying ``ax``: each of its frames takes, from every other message, the
frame nearest in time (the earlier one on a tie) if it lies within one period of that message (the
median interval of its first 1000 frames); rows without such a partner are dropped and counted.

Output is float64 SI in the sensor frame, as :class:`~mountcal.samples.Samples` states; the
auxiliary channels are ``temperature_c``, ``speed_mps``, ``heading_deg`` (compass, as the DBC
gives it), ``lat_deg``, ``lon_deg``, ``alt_m``, each on its own message's clock. ``dropped`` counts
frames of the selected messages that were unusable: too short, flagged invalid, non-finite, or
without a partner in time. Frames of other messages or channels are simply not selected.
"""

from __future__ import annotations

import re
import tomllib
from collections import Counter
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mountcal.errors import InputError
from mountcal.io.can.dbc import decode, frame_id_text, id_match, load_dbcs, payload_bytes, raw_values
from mountcal.io.can.frames import CanFrames, iter_frames, log_format
from mountcal.io.can.signals import UNIT_HINT, UNIT_KIND, message_refs, si_scale
from mountcal.io.inputs import check_regular_file, hold
from mountcal.paths import input_file
from mountcal.samples import Channel, FloatArray, LogSummary, Samples, Stream

ACCEL_ROLES = ("ax", "ay", "az")
GYRO_ROLES = ("gx", "gy", "gz")
AUX_KEYS = {
    "temperature": "temperature_c",
    "speed": "speed_mps",
    "heading": "heading_deg",
    "latitude": "lat_deg",
    "longitude": "lon_deg",
    "altitude": "alt_m",
}
_PERIOD_FRAMES = 1000  # frames used to measure a message's period
_FRAMES_PER_CHUNK = 100_000  # frames decoded at a time by read_can (≈ 9 MB)


# signal-name patterns, matched against the lower-case name without separators and trailing digits
_ACC = "(?:a|acc|accel|acceleration|linacc|linearaccel|linearacceleration)"
_RATE = "(?:g|w|gyr|gyro|gyrorate|rate|angrate|angularrate|angularvelocity|omega)"
_NAME_PATTERNS = {
    "ax": rf"{_ACC}(?:x|long|longitudinal)|(?:long|longitudinal){_ACC}",
    "ay": rf"{_ACC}(?:y|lat|lateral)|(?:lat|lateral){_ACC}",
    "az": rf"{_ACC}(?:z|vert|vertical)|(?:vert|vertical){_ACC}",
    "gx": rf"{_RATE}(?:x|roll)|(?:x|roll){_RATE}",
    "gy": rf"{_RATE}(?:y|pitch)|(?:y|pitch){_RATE}",
    "gz": rf"{_RATE}(?:z|yaw)|(?:z|yaw){_RATE}",
    "temperature": "(?:imu|sensor|internal)?temp(?:erature)?",
    "speed": "(?:vehicle|veh|gnss|gps|ground)?speed|speedoverground|sog",
    "heading": "(?:gnss|gps)?heading|course|courseoverground|cog",
    "latitude": "(?:gnss|gps|pos)?lat(?:itude)?",
    "longitude": "(?:gnss|gps|pos)?lon(?:gitude)?",
    "altitude": "(?:gnss|gps|pos)?alt(?:itude)?",
}
_MAPPING_KEYS = {"channel", "axes", "allow_left_handed", "valid", "signals", "units", "messages"}
_UNIT_KEYS = {"accel", "gyro", *AUX_KEYS}


# ---------------------------------------------------------------------------------------------
# Public API


def read_can(
    path: str | Path,
    dbc: str | Path | Any,
    *,
    mapping: str | Path | Mapping[str, Any] | None = None,
    channel: int | None = None,
) -> Samples:
    """Read the accelerometer (and gyro) samples of a CAN log.

    Parameters
    ----------
    path : str or Path
        A BLF, ASC, candump ``.log``, TRC, CSV or MF4 log. It is only read.
    dbc : str, Path or cantools Database
        The DBC describing the bus.
    mapping : str, Path or dict, optional
        A mapping TOML file, or its content as a dict (see the module docstring). Signals are
        auto-detected when it is omitted or has no ``[signals]``.
    channel : int, optional
        The CAN channel (python-can numbering); overrides the mapping's.

    Returns
    -------
    Samples
        ``acc_s`` (n, 3) in m/s², ``gyro_s`` (n, 3) in rad/s when mapped, auxiliary channels,
        ``axis_map`` and ``dropped`` counts.

    Raises
    ------
    InputError
        Unreadable or empty log, wrong DBC, missing message or signal, bad mapping or unit.
    """
    path = Path(path)
    plan = _plan(path, dbc, mapping, channel)
    return _concat(hold(_pieces(path, plan, _FRAMES_PER_CHUNK), str(path), "samples"), plan, str(path))


def iter_can(
    path: str | Path,
    dbc: str | Path | Any,
    *,
    mapping: str | Path | Mapping[str, Any] | None = None,
    channel: int | None = None,
    max_samples: int = 100_000,
) -> Iterator[Samples]:
    """Stream the samples of a CAN log in chunks of at most ``max_samples`` rows.

    Memory is bounded by the chunk size. Concatenating the chunks (times, vectors, auxiliary
    channels, summed ``dropped``) gives exactly what :func:`read_can` returns. Parameters as there.

    Yields
    ------
    Samples
        Consecutive chunks; each carries the auxiliary samples and drop counts of its stretch.
    """
    if max_samples < 1:
        raise ValueError(f"max_samples must be >= 1; got {max_samples}")
    path = Path(path)
    plan = _plan(path, dbc, mapping, channel)
    held: list[Samples] = []  # pieces without rows but with auxiliary samples or drop counts
    for piece in _pieces(path, plan, max(2 * max_samples, 1000)):
        if not len(piece):
            if piece.channels or piece.dropped:
                held.append(piece)
            continue
        if held:
            piece, held = _concat([*held, piece], plan, str(path)), []
        # pieces go out as they come (views when split): joining them to exact sizes only copies
        while len(piece) > max_samples:
            head, piece = _split(piece, max_samples)
            yield head
        yield piece
    if held:
        yield _concat(held, plan, str(path))


def inspect_can(path: str | Path, dbc: str | Path | Any | None = None) -> LogSummary:
    """What a CAN log holds: one stream per (channel, message) with count, rate and signals.

    Parameters
    ----------
    path : str or Path
        A CAN log in any supported format.
    dbc : str, Path, sequence of them, or cantools Database, optional
        Names the messages and lists their signals; without it messages are named by hex id.

    Returns
    -------
    LogSummary
        Streams sorted by channel and id; ``kind`` is ``"can<channel>"`` (``"can"`` without one);
        ``dlcs`` the data lengths each id was seen with.
    """
    path = Path(path)
    fmt = log_format(path)
    db = _database(dbc) if dbc is not None else None
    stats = _id_stats(path)
    wants = [(_Want.of(m, None), m) for m in db.messages] if db is not None else []
    streams = []
    for (chan, ident, ext), entry in sorted(stats.items()):
        message = next((m for w, m in wants if w.matches(ident, ext)), None)
        name = message.name if message is not None else frame_id_text(ident, ext)
        fields = tuple(s.name for s in message.signals) if message is not None else ()
        span = entry.last - entry.first
        rate = (entry.count - 1) / span if span > 0 else 0.0
        kind = "can" if chan < 0 else f"can{chan}"
        streams.append(Stream(name, kind, entry.count, rate, fields, tuple(sorted(entry.dlcs))))
    if stats:
        duration = max(v.last for v in stats.values()) - min(v.first for v in stats.values())
    else:
        duration = 0.0
    return LogSummary(str(path), fmt, float(duration), tuple(streams))


# ---------------------------------------------------------------------------------------------
# The plan: what to read and how to convert it


@dataclass(frozen=True)
class _Ref:
    """One mapped signal of one DBC message."""

    message: Any
    signal: str

    @property
    def label(self) -> str:
        return f"{self.message.name}.{self.signal}"


@dataclass
class _Source:
    """A message (and multiplexer value set) whose frames carry some of the mapped signals."""

    message: Any
    mux: tuple[int, ...] | None
    signals: list[str] = field(default_factory=list)
    valid: list[str] = field(default_factory=list)
    channels: set[int] = field(default_factory=set)
    ids: set[int] = field(default_factory=set)  # ids seen, for a message matched by J1939 PGN
    # where its frames are: arbitration_id & mask == value, the id kind, the channel (None: any one)
    value: int = 0
    mask: int = 0x1FFFFFFF
    extended: bool = False
    channel: int | None = None

    def place(self, placements: Mapping[str, tuple[int | None, bool | None, int | None]], channel: int | None) -> None:
        """Where the frames are: the mapping's placement of the message, else the DBC's id (J1939
        messages by PGN) on ``channel``."""
        ident, extended, on = placements.get(self.message.name, (None, None, None))
        if ident is None:
            self.value, self.mask = id_match(self.message)
            self.extended = bool(self.message.is_extended_frame)
        else:
            self.value, self.mask = ident, 0x1FFFFFFF
            self.extended = ident > 0x7FF if extended is None else extended
        self.channel = channel if on is None else on

    @property
    def name(self) -> str:
        mux = "" if self.mux is None else f"[mux {'/'.join(map(str, self.mux))}]"
        return f"{self.message.name}{mux}"


@dataclass
class _Plan:
    where: str  # the log and the DBC, for messages
    db: Any
    imu: list[_Source]  # sources of the accel/gyro signals; imu[0] carries ax and sets the clock
    columns: list[tuple[int, str, float]]  # per output column: (source index, signal, scale to SI)
    has_gyro: bool
    aux: dict[str, tuple[_Source, str, float, float]]  # channel key → source, signal, scale, offset
    aux_required: set[str]
    axes: NDArray[np.float64]  # (3, 3): sensor axis i = axes[i] · device axes
    axis_map: str
    channel: int | None

    def sources(self) -> list[_Source]:
        return self.imu + [a[0] for a in self.aux.values()]

    def ids(self) -> list[int] | None:
        """The ids to read, or None when a source matches a range of them (J1939 PGN)."""
        if any(s.mask != 0x1FFFFFFF for s in self.sources()):
            return None
        return sorted({s.value for s in self.sources()})

    def read_channel(self) -> int | None:
        """The channel to read, when every source is on the same one."""
        channels = {s.channel for s in self.sources()}
        return channels.pop() if len(channels) == 1 else None


def _database(dbc: str | Path | Sequence[str | Path] | Any) -> Any:
    """A cantools database from one DBC path, several, or the database itself."""
    return load_dbcs(dbc) if isinstance(dbc, str | Path | list | tuple) else dbc


def _setup(
    dbc: str | Path | Any, mapping: str | Path | Mapping[str, Any] | None, channel: int | None
) -> tuple[Any, dict[str, Any], int | None]:
    """The database, the mapping as a dict, and the IMU's channel (given, else the mapping's)."""
    db = _database(dbc)
    spec = _mapping_dict(mapping)
    if channel is None and spec.get("channel") is not None:
        channel = _int_setting(spec["channel"], "channel")
    return db, spec, channel


def _dbc_name(dbc: Any) -> str:
    if isinstance(dbc, str | Path):
        return str(dbc)
    if isinstance(dbc, list | tuple):
        return " + ".join(map(str, dbc))
    return "the DBC"


def _plan(
    path: Path, dbc: str | Path | Any, mapping: str | Path | Mapping[str, Any] | None, channel: int | None
) -> _Plan:
    log_format(path)
    check_regular_file(path, "CAN log")
    db, spec, channel = _setup(dbc, mapping, channel)
    where = f"{path} with {_dbc_name(dbc)}"
    present = _Presence(path, channel, db)
    signals = spec.get("signals") or _detect(db, present, where)
    refs = {role: _resolve(db, text, role, present, where) for role, text in signals.items()}
    units = spec.get("units", {})
    explicit = "signals" in spec and bool(spec["signals"])
    return _build_plan(where, db, refs, units, spec, channel, explicit, present)


def _mapping_dict(mapping: str | Path | Mapping[str, Any] | None) -> dict[str, Any]:
    """The mapping as a dict, checked for unknown keys."""
    if mapping is None:
        return {}
    where = "the mapping"
    if isinstance(mapping, str | Path):
        where = str(mapping)
        input_file(mapping, "a mapping TOML file")  # not a FIFO or a device: reading ends
        try:
            with Path(mapping).open("rb") as f:
                spec = tomllib.load(f)
        except OSError as err:
            raise InputError(where, "a mapping TOML file", f"an unreadable path ({err})", "Check the path.") from err
        except tomllib.TOMLDecodeError as err:
            raise InputError(where, "valid TOML", f"a syntax error ({err})", "Fix the mapping file.") from err
    else:
        spec = dict(mapping)
    _check_keys(spec, _MAPPING_KEYS, where, "")
    signals = spec.get("signals", {})
    if not isinstance(signals, Mapping):
        raise InputError(where, "a [signals] table", f"{signals!r}", 'Write `[signals]` then `ax = "msg.sig"`.')
    _check_keys(signals, {*ACCEL_ROLES, *GYRO_ROLES, *AUX_KEYS}, where, "signals.")
    if signals and not set(ACCEL_ROLES) <= set(signals):
        missing = ", ".join(r for r in ACCEL_ROLES if r not in signals)
        raise InputError(where, "signals ax, ay and az", f"no {missing}", "Map all three accelerometer axes.")
    gyro = [r for r in GYRO_ROLES if r in signals]
    if gyro and len(gyro) < 3:
        raise InputError(where, "all of gx, gy, gz or none", "only " + ", ".join(gyro), "Map three or none.")
    _check_keys(spec.get("units", {}), _UNIT_KEYS, where, "units.")
    return spec


def _check_keys(table: Mapping[str, Any], allowed: set[str], where: str, prefix: str) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise InputError(
            where,
            "keys among " + ", ".join(prefix + k for k in sorted(allowed)),
            "unknown " + ", ".join(prefix + k for k in unknown),
            "Check the spelling against the mapping format in mountcal.io.can.read.",
        )


def _int_setting(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise InputError("the mapping", f"an integer {name}", repr(value), f"Write e.g. `{name} = 2`.")
    return value


class _Presence:
    """Which (id, extended) pairs of the DBC occur in the log on the channel; one pass, on first use."""

    def __init__(self, path: Path | None, channel: int | None, db: Any) -> None:
        self.path, self.channel, self.db = path, channel, db  # path None: the keys are set by the caller
        self.keys: set[tuple[int, bool]] | None = None

    def filter(self, messages: list[Any]) -> list[Any]:
        """The messages among ``messages`` that occur in the log."""
        if self.keys is None:
            assert self.path is not None  # a bus sets its keys itself
            wants = [_Want.of(m, None) for m in self.db.messages]
            # a J1939 message matches a range of ids: then every id is read
            ids = sorted({w.value for w in wants}) if all(w.mask == 0x1FFFFFFF for w in wants) else None
            self.keys = set()
            for frames in iter_frames(self.path, ids=ids, channel=self.channel, max_frames=1 << 18):
                pairs = np.unique(frames.arbitration_id.astype(np.int64) * 2 + frames.is_extended)
                self.keys.update((int(p) // 2, bool(p % 2)) for p in pairs)
        keys = self.keys
        return [m for m in messages if _Want.of(m, None).matches_any(keys)]


def _normalise(name: str) -> str:
    return re.sub(r"\d+$", "", re.sub(r"[^a-z0-9]", "", name.lower()))


def _matches(role: str, signal_name: str) -> bool:
    return re.fullmatch(_NAME_PATTERNS[role], _normalise(signal_name)) is not None


def _detect(db: Any, present: _Presence, where: str) -> dict[str, str]:
    """Signals for ax..az (required), gx..gz and the auxiliary channels, found by name."""
    accel = _detect_triple(db, ACCEL_ROLES, present, [])
    if accel is None:
        mismatch = _log_mismatch(present.path, db, where, present.channel, [])
        if mismatch is not None:
            raise mismatch
        hits = [(m, s.name) for m in db.messages for s in m.signals if _matches_any(s.name, ACCEL_ROLES)]
        logged = present.filter(list({id(m): m for m, _ in hits}.values())) if hits else []
        absent = " (not in the log)" if present.channel is None else f" (not on channel {present.channel})"
        names = [
            f"{m.name}.{sig} [{frame_id_text(m.frame_id, m.is_extended_frame)}]" + ("" if m in logged else absent)
            for m, sig in hits
        ]
        raise InputError(
            where,
            "one unambiguous set of accelerometer signals (AccelerationX/Y/Z, AccX.., AX/AY/AZ, "
            "Accel_Longitudinal/Lateral/Vertical) in messages present in the log",
            "candidates "
            + (
                ", ".join(names[:_SHOWN]) + (f" and {len(names) - _SHOWN} more" if len(names) > _SHOWN else "")
                if names
                else "none"
            ),
            "Write a mapping naming ax, ay, az as message.signal (see mountcal.io.can.read)"
            + ("." if present.channel is None else ", or check the channel."),
        )
    found = {role: f"0x{m.frame_id:X}.{sig}" for role, (m, sig) in accel.items()}
    accel_messages = [m for m, _ in accel.values()]
    gyro = _detect_triple(db, GYRO_ROLES, present, accel_messages)
    if gyro is not None:
        found.update({role: f"0x{m.frame_id:X}.{sig}" for role, (m, sig) in gyro.items()})
    for role in AUX_KEYS:
        # a temperature is the IMU's only when it sits in the IMU's own message (not a tyre or a battery)
        messages = accel_messages if role == "temperature" else db.messages
        hits = [(m, s.name) for m in messages for s in m.signals if _matches(role, s.name) and not s.multiplexer_ids]
        if len(hits) > 1:
            present_messages = present.filter([m for m, _ in hits])
            hits = [h for h in hits if h[0] in present_messages]
        if len(hits) == 1:
            found[role] = f"0x{hits[0][0].frame_id:X}.{hits[0][1]}"
    return found


def _matches_any(name: str, roles: Sequence[str]) -> bool:
    return any(_matches(role, name) for role in roles)


def _detect_triple(
    db: Any, roles: Sequence[str], present: _Presence, prefer: list[Any]
) -> dict[str, tuple[Any, str]] | None:
    """One message with all three roles, else one signal per role across messages; None if unclear.

    The log is consulted (one extra pass) only when the DBC alone leaves a choice.
    """
    per_message: dict[Any, dict[str, list[str]]] = {}
    for m in db.messages:
        hits = {role: [s.name for s in m.signals if _matches(role, s.name)] for role in roles}
        if any(hits.values()):
            per_message[m] = hits
    counts = [sum(len(hits[r]) for hits in per_message.values()) for r in roles]
    if min(counts, default=0) == 0:
        return None  # some axis has no candidate at all: the log cannot help
    candidates = list(per_message) if max(counts) == 1 else present.filter(list(per_message))
    return _choose_triple(per_message, candidates, roles, prefer)


def _choose_triple(
    per_message: dict[Any, dict[str, list[str]]], candidates: list[Any], roles: Sequence[str], prefer: list[Any]
) -> dict[str, tuple[Any, str]] | None:
    whole = [m for m in candidates if all(len(per_message[m][r]) == 1 for r in roles)]
    if len(whole) > 1 and prefer:
        whole = [m for m in whole if m in prefer] or whole
    if len(whole) == 1:
        return {r: (whole[0], per_message[whole[0]][r][0]) for r in roles}
    if whole:
        return None
    chosen: dict[str, tuple[Any, str]] = {}
    for role in roles:
        pairs = [(m, s) for m in candidates for s in per_message[m][role]]
        if len(pairs) != 1:
            return None
        chosen[role] = pairs[0]
    return chosen


def _resolve(db: Any, text: Any, role: str, present: _Presence, where: str) -> _Ref:
    """A ``message.signal`` string as a DBC message and signal name."""
    if not isinstance(text, str) or "." not in text:
        raise InputError(
            where, f'signals.{role} as "message.signal"', repr(text), 'E.g. ax = "gnss_imu.AccelerationX".'
        )
    message_text, signal = text.split(".", 1)
    messages = message_refs(db, message_text)
    if not messages:
        known = ", ".join(sorted({m.name for m in db.messages})[:40])
        raise InputError(
            where, f"a DBC message {message_text!r} for {role}", f"none; the DBC has {known}", "Fix the mapping."
        )
    messages = [m for m in messages if any(s.name == signal for s in m.signals)] or messages
    if not any(s.name == signal for s in messages[0].signals):
        names = ", ".join(s.name for s in messages[0].signals)
        raise InputError(
            where,
            f"signal {signal!r} in message {messages[0].name} for {role}",
            f"only {names}",
            "Fix the signal name in the mapping (names are case-sensitive).",
        )
    if len(messages) > 1:
        logged = present.filter(messages)
        wants = [_Want.of(m, present.channel) for m in messages]
        mismatch = None if logged else _log_mismatch(present.path, db, where, present.channel, wants)
        if mismatch is not None:
            raise mismatch
        messages = logged or messages
        if len(messages) > 1:
            ids = ", ".join(f"0x{m.frame_id:X}" for m in messages)
            raise InputError(
                where,
                f"one message named {message_text!r} in the log",
                f"several with that name ({ids})",
                'Name the message by its id in the mapping, e.g. "0x9.AccelerationX".',
            )
    return _Ref(messages[0], signal)


def _unit_scale(ref: _Ref, role: str, units: Mapping[str, Any], where: str) -> tuple[float, float]:
    """Scale and offset from the signal's unit (the mapping's, else the DBC's) to SI."""
    kind = UNIT_KIND[role]
    key = "accel" if kind == "accel" else "gyro" if kind == "gyro" else role
    given = units.get(key)
    unit = str(given) if given is not None else str(ref.message.get_signal_by_name(ref.signal).unit or "")
    scale = si_scale(role, unit)
    if scale is not None:
        return scale
    source = "the mapping's units." + key if given is not None else f"the DBC unit of {ref.label}"
    raise InputError(
        where,
        f"{'an acceleration' if kind == 'accel' else 'a ' + kind} unit ({UNIT_HINT[kind]}) for {role}",
        f"{unit!r} ({source})",
        f"Check the mapping; if the DBC's unit is missing or wrong, set units.{key} in the mapping.",
    )


def _build_plan(
    where: str,
    db: Any,
    refs: dict[str, _Ref],
    units: Mapping[str, Any],
    spec: Mapping[str, Any],
    channel: int | None,
    explicit: bool,
    present: _Presence,
) -> _Plan:
    has_gyro = all(r in refs for r in GYRO_ROLES)
    sources: list[_Source] = []
    columns = []
    for role in ACCEL_ROLES + (GYRO_ROLES if has_gyro else ()):
        ref = refs[role]
        source = _source_for(sources, ref)
        source.signals.append(ref.signal)
        columns.append((sources.index(source), ref.signal, _unit_scale(ref, role, units, where)[0]))
    aux: dict[str, tuple[_Source, str, float, float]] = {}
    for role, key in AUX_KEYS.items():
        if role in refs:
            try:
                scale, offset = _unit_scale(refs[role], role, units, where)
            except InputError:
                if explicit:
                    raise
                continue  # an auto-detected optional channel with an unknown unit is left out
            source = _Source(refs[role].message, _mux_of(refs[role]), [refs[role].signal])
            aux[key] = (source, refs[role].signal, scale, offset)
    _assign_validity(sources + [a[0] for a in aux.values()], spec.get("valid"), db, where, present)
    axes, axis_map = _axes(spec.get("axes", "x,y,z"), spec.get("allow_left_handed", False))
    aux_required = {AUX_KEYS[r] for r in refs if r in AUX_KEYS} if explicit else set()
    placements = _placements(spec.get("messages", {}), db, where)
    for source in sources + [a[0] for a in aux.values()]:
        source.place(placements, channel)
    return _Plan(where, db, sources, columns, has_gyro, aux, aux_required, axes, axis_map, channel)


def _placements(table: Any, db: Any, where: str) -> dict[str, tuple[int | None, bool | None, int | None]]:
    """The mapping's ``[messages]``: a DBC message placed at another id and/or channel, e.g.
    ``MM5_10_TX1 = { id = 0x174, channel = 1 }`` (``extended = true`` for a 29-bit id at or
    below 0x7FF)."""
    if not isinstance(table, Mapping):
        raise InputError(where, "a [messages] table", repr(table), "Write `[messages]` then `NAME = { id = 0x174 }`.")
    out: dict[str, tuple[int | None, bool | None, int | None]] = {}
    for name, place in table.items():
        messages = message_refs(db, str(name))
        if not messages:
            raise InputError(
                where, f"a DBC message {name!r} in [messages]", "no message of that name or id", "Fix the mapping."
            )
        if not isinstance(place, Mapping):
            raise InputError(where, f"messages.{name} as a table", repr(place), "Write `{ id = 0x174, channel = 1 }`.")
        _check_keys(place, {"id", "channel", "extended"}, where, f"messages.{name}.")
        ident = place.get("id")
        if ident is not None and (isinstance(ident, bool) or not isinstance(ident, int)):
            raise InputError(
                where, f"messages.{name}.id as a TOML integer", repr(ident), f"Write `{name} = {{ id = 0x174 }}`."
            )
        if ident is not None and not 0 <= ident <= 0x1FFFFFFF:
            raise InputError(where, "an id from 0 to 0x1FFFFFFF", f"{ident:#x}", f"Fix messages.{name}.id.")
        extended = place.get("extended")
        if extended is not None and not isinstance(extended, bool):
            raise InputError(where, f"messages.{name}.extended as true or false", repr(extended), "Fix the mapping.")
        channel = None if place.get("channel") is None else _int_setting(place["channel"], f"messages.{name}.channel")
        for message in messages:
            out[message.name] = (ident, extended, channel)
    return out


def _mux_of(ref: _Ref) -> tuple[int, ...] | None:
    ids = ref.message.get_signal_by_name(ref.signal).multiplexer_ids
    return tuple(sorted(ids)) if ids else None


def _source_for(sources: list[_Source], ref: _Ref) -> _Source:
    mux = _mux_of(ref)
    for source in sources:
        if source.message is ref.message and source.mux == mux:
            return source
    sources.append(_Source(ref.message, mux))
    return sources[-1]


def _assign_validity(sources: list[_Source], valid: Any, db: Any, where: str, present: _Presence) -> None:
    """Validity signals per source: the mapping's list, else 1-bit signals named like *valid*."""
    if valid is None:
        for source in sources:
            source.valid = [
                s.name
                for s in source.message.signals
                if "valid" in s.name.lower() and s.length == 1 and not s.multiplexer_ids
            ]
        return
    if isinstance(valid, str):
        valid = [valid]
    if not isinstance(valid, list):
        raise InputError(
            where, 'valid as a list of "message.signal"', repr(valid), 'E.g. valid = ["gnss_imu.ImuValid"].'
        )
    for text in valid:
        ref = _resolve(db, text, "valid", present, where)
        targets = [s for s in sources if s.message is ref.message]
        if not targets:
            raise InputError(
                where,
                f"validity signal {text!r} in a message the mapping uses",
                "a message that carries none of the mapped signals",
                "Remove it from `valid` or map a signal of that message.",
            )
        for source in targets:
            source.valid.append(ref.signal)


def _axes(text: Any, allow: Any) -> tuple[NDArray[np.float64], str]:
    """The signed permutation "-y,x,z" as a matrix (row i: device components of sensor axis i)."""
    tokens = [t.strip().lower() for t in str(text).split(",")]
    parsed = [re.fullmatch(r"([+-]?)([xyz])", t) for t in tokens]
    letters = [m.group(2) for m in parsed if m]
    if len(tokens) != 3 or not all(parsed) or sorted(letters) != ["x", "y", "z"]:
        raise InputError(
            "the mapping",
            'axes as a signed permutation of x, y, z such as "-y,x,z"',
            repr(text),
            "List, for sensor axes x, y, z in turn, the device axis (with its sign) that points along it.",
        )
    matrix = np.zeros((3, 3))
    for row, match in enumerate(parsed):
        assert match is not None
        matrix[row, "xyz".index(match.group(2))] = -1.0 if match.group(1) == "-" else 1.0
    canonical = ",".join(t.lstrip("+") for t in tokens)
    if np.linalg.det(matrix) > 0:
        return matrix, canonical
    if allow is False or allow is None or allow == "":
        raise InputError(
            "the mapping",
            "axes that keep the frame right-handed (an even number of swaps and sign flips)",
            f"{canonical!r}, a reflection that makes it left-handed",
            'Flip one more sign, or set allow_left_handed = "<reason>" if the device itself is left-handed.',
        )
    reason = allow if isinstance(allow, str) else "by the mapping"
    return matrix, f"{canonical} (reflection allowed: {reason})"


# ---------------------------------------------------------------------------------------------
# Streaming: frames → decoded, validated source samples → aligned rows


def _pieces(path: Path, plan: _Plan, frames_per_chunk: int) -> Iterator[Samples]:
    """Samples pieces, one per chunk of frames, then the final flush; raises on missing data."""
    decoder = _Decoder(plan, str(path))
    for frames in iter_frames(path, ids=plan.ids(), channel=plan.read_channel(), max_frames=frames_per_chunk):
        yield decoder.piece(frames)
    last = decoder.final()
    _check_found(path, plan, decoder.seen, decoder.rows_total, decoder.dropped_total)
    yield last


class _Decoder:
    """Chunks of frames → aligned Samples pieces, with the counts of what was seen and dropped."""

    def __init__(self, plan: _Plan, source: str) -> None:
        self.plan, self.source = plan, source
        self.aligner = _Aligner([len(s.signals) for s in plan.imu], [s.name for s in plan.imu])
        self.seen = Counter[str]()  # frames selected per source, before validation
        self.dropped_total = Counter[str]()
        self.rows_total = 0

    def piece(self, frames: CanFrames) -> Samples:
        dropped = Counter[str]()
        for k, source in enumerate(self.plan.imu):
            t_s, values = _take(frames, source, self.plan, dropped, self.seen)
            self.aligner.add(k, t_s, values)
        channels = _aux_piece(frames, self.plan, dropped, self.seen)
        t_s, rows = self.aligner.emit(final=False, dropped=dropped)
        self.rows_total += t_s.shape[0]
        self.dropped_total.update(dropped)
        return _to_samples(t_s, rows, channels, dropped, self.plan, self.source)

    def final(self) -> Samples:
        dropped = Counter[str]()
        t_s, rows = self.aligner.emit(final=True, dropped=dropped)
        self.rows_total += t_s.shape[0]
        self.dropped_total.update(dropped)
        return _to_samples(t_s, rows, {}, dropped, self.plan, self.source)


def samples_from_frames(
    frames: CanFrames,
    dbc: str | Path | Any,
    *,
    mapping: str | Path | Mapping[str, Any] | None = None,
    channel: int | None = None,
    source: str = "<bus>",
    complete: bool = False,
) -> Samples:
    """The samples of frames held in memory (a live bus), decoded exactly as :func:`read_can` decodes a log.

    Signals are resolved against the frames present, as against a log's. With ``complete`` (the
    whole session) a mapped message without frames is an error, as it is for a log; otherwise a bus
    still waiting for it gives what it has.
    """
    db, spec, channel = _setup(dbc, mapping, channel)
    where = f"{source} with {_dbc_name(dbc)}"
    present = _Presence(None, channel, db)
    on_channel = frames if channel is None else frames.take(frames.channel == channel)
    pairs = np.unique(on_channel.arbitration_id.astype(np.int64) * 2 + on_channel.is_extended)
    present.keys = {(int(p) // 2, bool(p % 2)) for p in pairs}
    signals = spec.get("signals") or _detect(db, present, where)
    refs = {role: _resolve(db, text, role, present, where) for role, text in signals.items()}
    explicit = "signals" in spec and bool(spec["signals"])
    plan = _build_plan(where, db, refs, spec.get("units", {}), spec, channel, explicit, present)
    ids, read_channel = plan.ids(), plan.read_channel()  # ids None: a J1939 PGN matches a range of ids
    keep = np.ones(len(frames), bool) if ids is None else np.isin(frames.arbitration_id, np.asarray(ids, np.uint32))
    if read_channel is not None:
        keep &= frames.channel == read_channel
    decoder = _Decoder(plan, source)
    samples = _concat([decoder.piece(frames.take(keep)), decoder.final()], plan, source)
    missing = [s.name for s in plan.imu if not decoder.seen[s.name]]
    missing += [plan.aux[k][0].name for k in sorted(plan.aux_required) if not decoder.seen[plan.aux[k][0].name]]
    if complete and missing:
        raise InputError(
            where,
            "frames of every mapped message (" + ", ".join(missing) + ")",
            "none of them on the bus",
            "Check the mapping, the channel and that the device sends these messages.",
        )
    return samples


def _select(frames: CanFrames, source: _Source, plan: _Plan) -> CanFrames:
    ids = frames.arbitration_id if source.mask == 0x1FFFFFFF else frames.arbitration_id & np.uint32(source.mask)
    wanted = (ids == source.value) & (frames.is_extended == source.extended)
    if source.channel is not None:
        wanted &= frames.channel == source.channel
    chosen = frames.take(wanted)
    if len(chosen):
        low, high = int(chosen.channel.min()), int(chosen.channel.max())
        source.channels.update((low, high) if low == high or high - low == 1 else np.unique(chosen.channel).tolist())
        if source.channel is None and len(source.channels) > 1:
            found = ", ".join(map(str, sorted(source.channels)))
            raise InputError(
                plan.where,
                f"message {source.message.name} on one CAN channel",
                f"it on channels {found}",
                "Choose one with `channel=` (or `channel = N` in the mapping).",
            )
        if source.mask != 0x1FFFFFFF:  # matched by J1939 PGN: one sender, or two streams would mix
            source.ids.update(np.unique(chosen.arbitration_id).tolist())
            if len(source.ids) > 1:
                found = ", ".join(frame_id_text(i, True) for i in sorted(source.ids)[:_SHOWN])
                raise InputError(
                    plan.where,
                    f"message {source.message.name} (J1939 PGN 0x{source.value >> 8:05X}) from one sender",
                    f"it from {len(source.ids)} ids: {found}",
                    f"Pick one in the mapping: [messages] {source.message.name} = {{ id = 0x... }}.",
                )
    return chosen


def _take(
    frames: CanFrames, source: _Source, plan: _Plan, dropped: Counter[str], seen: Counter[str]
) -> tuple[FloatArray, NDArray[np.float64]]:
    """Times (m,) and values (m, k) of one source's usable frames; the unusable ones counted."""
    chosen = _select(frames, source, plan)
    if source.mux is not None:
        signal = source.message.get_signal_by_name(source.signals[0])
        mux = source.message.get_signal_by_name(signal.multiplexer_signal)
        chosen = chosen.take(np.isin(raw_values(chosen.data, mux), np.asarray(source.mux, np.uint64)))
    seen[source.name] += len(chosen)
    name = source.message.name
    short = chosen.dlc < payload_bytes(source.message, source.signals + source.valid)
    _count(dropped, f"{name}: frame shorter than the DBC layout", short)
    if short.any():
        chosen = chosen.take(~short)
    decoded = decode(chosen, source.message, source.signals + source.valid)
    keep = np.ones(len(chosen), np.bool_)
    if source.valid:
        invalid = (np.stack([decoded[v] for v in source.valid]) == 0).any(axis=0)
        _count(dropped, f"{name}: {' or '.join(source.valid)} == 0", invalid)
        keep &= ~invalid
    values = np.stack([decoded[s] for s in source.signals], axis=1)
    finite = np.logical_and.reduce([np.isfinite(decoded[s]) for s in source.signals])
    _count(dropped, f"{name}: non-finite value", keep & ~finite)
    keep &= finite
    if keep.all():
        return chosen.t_s, values
    return chosen.t_s[keep], values[keep]


def _count(dropped: Counter[str], reason: str, rows: NDArray[np.bool_]) -> None:
    """Add the rows flagged in ``rows`` to the drop counts (no entry for none)."""
    n = int(rows.sum())
    if n:
        dropped[reason] += n


def _aux_piece(frames: CanFrames, plan: _Plan, dropped: Counter[str], seen: Counter[str]) -> dict[str, Channel]:
    channels = {}
    for key, (source, signal, scale, offset) in plan.aux.items():
        t_s, values = _take(frames, source, plan, dropped, seen)
        if t_s.shape[0]:
            channels[key] = Channel(t_s, values[:, source.signals.index(signal)] * scale + offset)
    return channels


class _Aligner:
    """Nearest-in-time alignment of several sources onto the clock of source 0, streamed.

    A row of source 0 at time t is emitted once every other source k holds a sample later than
    t + period_k (or the stream has ended), so the chunking never changes the result.
    """

    def __init__(self, widths: list[int], names: list[str]) -> None:
        self.names = names
        self.t: list[FloatArray] = [np.empty(0) for _ in widths]
        self.v: list[NDArray[np.float64]] = [np.empty((0, w)) for w in widths]
        self.period: list[float | None] = [None] * len(widths)

    def add(self, k: int, t_s: FloatArray, values: NDArray[np.float64]) -> None:
        if not t_s.shape[0]:
            return
        t, v = np.concatenate([self.t[k], t_s]), np.concatenate([self.v[k], values])
        if (np.diff(t) < 0).any():  # keep each source in time order
            order = np.argsort(t, kind="stable")
            t, v = t[order], v[order]
        self.t[k], self.v[k] = t, v

    def emit(self, *, final: bool, dropped: Counter[str]) -> tuple[FloatArray, list[NDArray[np.float64]]]:
        """Rows of source 0 whose partners are settled: times (n,) and per-source values (n, w_k)."""
        if len(self.t) == 1:
            n = self.t[0].shape[0]
        elif self._periods_known(final):
            n = self._settled(final)
        else:  # partners' periods not measured yet: hold everything
            return np.empty(0), [np.empty((0, v.shape[1])) for v in self.v]
        t_out, values, keep = self.t[0][:n], [self.v[0][:n]], np.ones(n, np.bool_)
        periods = [p or 0.0 for p in self.period]
        for k in range(1, len(self.t)):
            index, ok = _nearest(self.t[k], t_out, periods[k])
            keep &= ok
            values.append(self.v[k][index] if ok.any() else np.zeros((n, self.v[k].shape[1])))
        _count(dropped, f"{self.names[0]}: no frame of {', '.join(self.names[1:])} within one period", ~keep)
        self._trim(n, periods)
        if keep.all():
            return t_out, values
        return t_out[keep], [v[keep] for v in values]

    def _periods_known(self, final: bool) -> bool:
        """Measure each partner's period from its first frames, once there are enough of them."""
        for k in range(1, len(self.t)):
            if self.period[k] is None and (final or self.t[k].shape[0] >= _PERIOD_FRAMES):
                dt = np.diff(self.t[k][:_PERIOD_FRAMES])
                self.period[k] = float(np.median(dt)) if dt.shape[0] else 0.0
        return all(p is not None for p in self.period[1:])

    def _settled(self, final: bool) -> int:
        """How many rows of source 0 have all their candidate partners in hand."""
        if final:
            return int(self.t[0].shape[0])
        limits = [
            float(self.t[k][-1]) - (self.period[k] or 0.0) if self.t[k].shape[0] else -np.inf
            for k in range(1, len(self.t))
        ]
        return int(np.searchsorted(self.t[0], min(limits), side="left"))

    def _trim(self, n: int, periods: list[float]) -> None:
        """Forget emitted rows, and partner samples too early for any row still to come."""
        ref_t = self.t[0]
        lower = ref_t[n] if n < ref_t.shape[0] else (ref_t[n - 1] if n else -np.inf)
        self.t[0], self.v[0] = ref_t[n:], self.v[0][n:]
        for k in range(1, len(self.t)):
            first = int(np.searchsorted(self.t[k], lower - periods[k], side="left"))
            self.t[k], self.v[k] = self.t[k][first:], self.v[k][first:]


def _nearest(t_k: FloatArray, t_ref: FloatArray, tolerance: float) -> tuple[NDArray[np.int64], NDArray[np.bool_]]:
    """Index of the sample of ``t_k`` nearest each ``t_ref`` (earlier on ties) and whether it is
    within ``tolerance``."""
    if not t_k.shape[0]:
        return np.zeros(t_ref.shape[0], np.int64), np.zeros(t_ref.shape[0], np.bool_)
    after = np.clip(np.searchsorted(t_k, t_ref, side="left"), 0, t_k.shape[0] - 1)
    before = np.clip(after - 1, 0, None)
    use_before = np.abs(t_ref - t_k[before]) <= np.abs(t_k[after] - t_ref)
    index = np.where(use_before, before, after)
    return index, np.abs(t_k[index] - t_ref) <= tolerance


def _to_samples(
    t_s: FloatArray,
    rows: list[NDArray[np.float64]],
    channels: dict[str, Channel],
    dropped: Counter[str],
    plan: _Plan,
    source: str,
) -> Samples:
    """Scaled device-axis columns, permuted by the axis map, as one Samples piece."""
    n = t_s.shape[0]
    acc_s = np.empty((n, 3))
    gyro_s = np.empty((n, 3)) if plan.has_gyro else None
    # the axis map is a signed permutation: sensor axis i is ±(device axis j), a scaled column copy
    for i, j in enumerate(np.argmax(np.abs(plan.axes), axis=1)):
        sign = plan.axes[i, j]
        for out, column in ((acc_s, j), (gyro_s, 3 + j)):
            if out is not None:
                k, signal, scale = plan.columns[column]
                out[:, i] = rows[k][:, plan.imu[k].signals.index(signal)] * (sign * scale)
    return Samples(np.asarray(t_s, np.float64), acc_s, gyro_s, channels, source, plan.axis_map, dict(dropped))


def _concat(pieces: list[Samples], plan: _Plan, source: str) -> Samples:
    """One Samples from consecutive pieces: rows, auxiliary samples and drop counts joined."""
    t_s = np.concatenate([p.t_s for p in pieces]) if pieces else np.empty(0)
    acc_s = np.concatenate([p.acc_s for p in pieces]) if pieces else np.empty((0, 3))
    gyro_s = np.concatenate([p.gyro_s for p in pieces if p.gyro_s is not None]) if plan.has_gyro else None
    channels = {}
    for key in AUX_KEYS.values():
        parts = [p.channels[key] for p in pieces if key in p.channels]
        if parts:
            channels[key] = Channel(np.concatenate([c.t_s for c in parts]), np.concatenate([c.value for c in parts]))
    dropped = Counter[str]()
    for p in pieces:
        dropped.update(p.dropped)
    return Samples(t_s, acc_s, gyro_s, channels, source, plan.axis_map, dict(dropped))


def _split(samples: Samples, n: int) -> tuple[Samples, Samples]:
    """The first n rows (with every auxiliary sample and drop count so far) and the rest."""
    head = Samples(
        samples.t_s[:n],
        samples.acc_s[:n],
        None if samples.gyro_s is None else samples.gyro_s[:n],
        samples.channels,
        samples.source,
        samples.axis_map,
        samples.dropped,
    )
    rest = Samples(
        samples.t_s[n:],
        samples.acc_s[n:],
        None if samples.gyro_s is None else samples.gyro_s[n:],
        {},
        samples.source,
        samples.axis_map,
        {},
    )
    return head, rest


# ---------------------------------------------------------------------------------------------
# Errors that need a look at the whole log


def _check_found(path: Path, plan: _Plan, seen: Counter[str], total_rows: int, dropped: Counter[str]) -> None:
    """Raise when the log lacks the mapped messages, or none of their samples survived."""
    missing_aux = sorted(k for k in plan.aux_required if not seen[plan.aux[k][0].name])
    silent = [s for s in plan.imu if not seen[s.name]]
    if not silent and not missing_aux and total_rows:
        return
    sources = silent + [plan.aux[k][0] for k in missing_aux]
    wanted = [_Want(s.message.name, s.value, s.mask, s.extended, s.channel) for s in sources]
    mismatch = _log_mismatch(path, plan.db, plan.where, plan.channel, wanted)
    if mismatch is not None:
        raise mismatch
    raise InputError(
        plan.where,
        "usable accelerometer samples",
        "every row dropped (" + ", ".join(f"{k}: {v}" for k, v in dropped.items()) + ")",
        "Check the validity flags and the DBC layout against the log.",
    )


@dataclass(frozen=True)
class _Want:
    """A message looked for in the log: its name and where its frames would be."""

    name: str
    value: int
    mask: int
    extended: bool
    channel: int | None

    @classmethod
    def of(cls, message: Any, channel: int | None) -> _Want:
        value, mask = id_match(message)
        return cls(message.name, value, mask, bool(message.is_extended_frame), channel)

    def matches(self, ident: int, extended: bool) -> bool:
        return extended == self.extended and ident & self.mask == self.value

    def matches_any(self, keys: Iterable[tuple[int, bool]]) -> bool:
        return any(self.matches(i, e) for i, e in keys)

    @property
    def text(self) -> str:
        pgn = f", J1939 PGN 0x{self.value >> 8:05X}" if self.mask != 0x1FFFFFFF else ""
        return f"{self.name} ({frame_id_text(self.value, self.extended)}{pgn})"


_SHOWN = 10  # ids, channels and near matches an error lists: it has to fit on a screen


def _log_mismatch(
    path: Path | None, db: Any, where: str, channel: int | None, wanted: list[_Want]
) -> InputError | None:
    """The error for an empty log, a log the DBC does not describe, or one lacking ``wanted`` (None for a bus)."""
    if path is None:
        return None
    stats = _id_stats(path)
    if not stats:
        return InputError(str(path), "CAN frames", "an empty log (no data frames)", "Check the logger's output.")
    per_id = Counter[tuple[int, bool]]()
    for (_, ident, ext), entry in stats.items():
        per_id[(ident, ext)] += entry.count
    known = [_Want.of(m, None) for m in db.messages]
    if not any(w.matches_any(per_id) for w in known):
        examples = ", ".join(w.text for w in known[:_SHOWN]) + (", ..." if len(known) > _SHOWN else "")
        return InputError(
            where,
            f"frames of messages of the DBC ({len(known)} messages: {examples})",
            "no frame of any of them; the log has " + _seen(stats),
            "Use the DBC that describes this bus (29-bit ids print with 8 hex digits).",
        )
    if not wanted:
        return None
    names = ", ".join(w.text + ("" if w.channel is None else f" on channel {w.channel}") for w in wanted)
    return InputError(
        where,
        f"frames of {names}",
        "none; the log has " + _seen(stats) + "".join(_closest(w, stats) for w in wanted),
        "Check the mapping (its [messages] table places a message at another id or channel), the channel "
        "and that the logger recorded this message.",
    )


def _seen(stats: dict[tuple[int, int, bool], _IdStat]) -> str:
    """The channels and the most frequent ids of a log, with frame counts, in a few lines."""
    per_channel = Counter[int]()
    per_id = Counter[tuple[int, bool]]()
    for (chan, ident, ext), entry in stats.items():
        per_channel[chan] += entry.count
        per_id[(ident, ext)] += entry.count
    channels = ", ".join(f"{c} ({n} frames)" for c, n in per_channel.most_common(_SHOWN))
    more = f" and {len(per_channel) - _SHOWN} more" if len(per_channel) > _SHOWN else ""
    top = ", ".join(f"{frame_id_text(i, e)} ({n})" for (i, e), n in per_id.most_common(_SHOWN))
    return f"{len(per_id)} ids on channels {channels}{more}; the most frequent: {top}"


def _closest(want: _Want, stats: dict[tuple[int, int, bool], _IdStat]) -> str:
    """Where the log has the wanted id on other channels, else its ids nearest to it."""
    elsewhere = [(c, e.count) for (c, i, x), e in stats.items() if want.matches(i, x)]
    if elsewhere:
        where = ", ".join(f"channel {c} ({n} frames)" for c, n in sorted(elsewhere)[:_SHOWN])
        return f". {want.name} is on {where}"
    same_kind = sorted({(i, x) for (_, i, x) in stats if x == want.extended}, key=lambda k: abs(k[0] - want.value))
    if not same_kind:
        return f". No {'29' if want.extended else '11'}-bit id in the log for {want.name}"
    near = ", ".join(frame_id_text(i, x) for i, x in same_kind[:3])
    return f". Nearest ids to {want.name}'s: {near}"


@dataclass
class _IdStat:
    """One (channel, id, extended) of a log: frames, first and last time, the DLCs seen."""

    count: int
    first: float
    last: float
    dlcs: set[int]


def _id_stats(path: Path) -> dict[tuple[int, int, bool], _IdStat]:
    """Per (channel, id, extended): frame count, first and last time, DLCs, in one streamed pass."""
    stats: dict[tuple[int, int, bool], _IdStat] = {}
    for frames in iter_frames(path, max_frames=1 << 18):
        key = (frames.channel * (1 << 33)) + frames.arbitration_id.astype(np.int64) * 2 + frames.is_extended
        uniq, first, counts = np.unique(key, return_index=True, return_counts=True)
        last = len(key) - 1 - np.unique(key[::-1], return_index=True)[1]
        pairs = np.unique(key * 128 + frames.dlc)  # the DLCs of each id
        dlcs: dict[int, set[int]] = {}
        for pair in pairs.tolist():
            dlcs.setdefault(pair // 128, set()).add(pair % 128)
        for u, f, c, la in zip(uniq.tolist(), first, counts, last, strict=True):
            chan, rest = u // (1 << 33), u % (1 << 33)
            k = (chan, rest // 2, bool(rest % 2))
            entry = stats.setdefault(k, _IdStat(0, float(frames.t_s[f]), 0.0, set()))
            entry.count += int(c)
            entry.last = float(frames.t_s[la])
            entry.dlcs |= dlcs[u]
    return stats


__all__ = ["inspect_can", "iter_can", "read_can", "samples_from_frames"]
