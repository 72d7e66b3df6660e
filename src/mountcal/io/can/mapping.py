"""The plan of a CAN read: which DBC signals hold which role (from a mapping file or detected by name),
in which units, in which messages at which ids and channels, validity flags and the axis mapping.
The mapping format is described in :mod:`mountcal.io.can.read`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mountcal.core import paths
from mountcal.core.errors import InputError
from mountcal.core.option_names import option
from mountcal.io.can.dbc import frame_id_text, id_match, load_dbcs
from mountcal.io.can.files import iter_frames, log_format
from mountcal.io.can.mismatch import SHOWN, Want, log_mismatch
from mountcal.io.can.signals import UNIT_HINT, UNIT_KIND, message_refs, si_scale
from mountcal.io.input_conventions import parse_axes
from mountcal.io.inputs import check_regular_file

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
class Source:
    """A message (and multiplexer value set) whose frames carry some of the mapped signals."""

    message: Any
    mux: tuple[int, ...] | None
    signals: list[str] = field(default_factory=list)
    valid: list[str] = field(default_factory=list)
    channels: set[int] = field(default_factory=set)
    ids: set[int] = field(default_factory=set)  # ids seen, for a message matched by J1939 PGN
    mux_found: set[int] = field(default_factory=set)  # multiplexer values of its message's frames, for a branch
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
class Plan:
    where: str  # the log and the DBC, for messages
    db: Any
    imu: list[Source]  # sources of the accel/gyro signals; imu[0] carries ax and sets the clock
    columns: list[tuple[int, str, float]]  # per output column: (source index, signal, scale to SI)
    has_gyro: bool
    aux: dict[str, tuple[Source, str, float, float]]  # channel key → source, signal, scale, offset
    aux_required: set[str]
    axes: NDArray[np.float64]  # (3, 3): sensor axis i = axes[i] · device axes
    axis_map: str
    channel: int | None
    # the accelerometer's signals as read: (label, unit, what states the unit, scale to m/s²), ax, ay, az
    acc_units: tuple[tuple[str, str, str, float], ...] = ()
    notes: tuple[str, ...] = ()  # what the plan left out and says (an auto-detected channel's unknown unit)
    units: tuple[str, str] = ("", "")  # the units the signals are read in, and what stated them

    def sources(self) -> list[Source]:
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


def database(dbc: str | Path | Sequence[str | Path] | Any) -> Any:
    """A cantools database from one DBC path, several, or the database itself."""
    return load_dbcs(dbc) if isinstance(dbc, str | Path | list | tuple) else dbc


def setup_plan(
    dbc: str | Path | Any, mapping: str | Path | Mapping[str, Any] | None, channel: int | None
) -> tuple[Any, dict[str, Any], int | None]:
    """The database, the mapping as a dict, and the IMU's channel (given, else the mapping's)."""
    db = database(dbc)
    spec = _mapping_dict(mapping)
    if channel is None and spec.get("channel") is not None:
        channel = _int_setting(spec["channel"], "channel")
    return db, spec, channel


def dbc_name(dbc: Any) -> str:
    if isinstance(dbc, str | Path):
        return str(dbc)
    if isinstance(dbc, list | tuple):
        return " + ".join(map(str, dbc))
    return "the DBC"


def make_plan(
    path: Path, dbc: str | Path | Any, mapping: str | Path | Mapping[str, Any] | None, channel: int | None
) -> Plan:
    log_format(path)
    check_regular_file(path, "CAN log")
    db, spec, channel = setup_plan(dbc, mapping, channel)
    where = f"{path} with {dbc_name(dbc)}"
    present = Presence(path, channel, db)
    signals = spec.get("signals") or detect(db, present, where)
    refs = {role: resolve(db, text, role, present, where) for role, text in signals.items()}
    units = spec.get("units", {})
    explicit = "signals" in spec and bool(spec["signals"])
    return build_plan(where, db, refs, units, spec, channel, explicit, present)


def _mapping_dict(mapping: str | Path | Mapping[str, Any] | None) -> dict[str, Any]:
    """The mapping as a dict, checked for unknown keys."""
    if mapping is None:
        return {}
    where = "the mapping"
    if isinstance(mapping, str | Path):
        where = str(mapping)
        # a regular file of bounded size (not a FIFO or a device: reading ends), parsed within the budget
        spec = dict(paths.read_document(mapping, "a mapping TOML file", toml=True))  # TOML: always a table
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


class Presence:
    """Which (id, extended) pairs of the DBC occur in the log on the channel; one pass, on first use."""

    def __init__(self, path: Path | None, channel: int | None, db: Any) -> None:
        self.path, self.channel, self.db = path, channel, db  # path None: the keys are set by the caller
        self.keys: set[tuple[int, bool]] | None = None

    def filter(self, messages: list[Any]) -> list[Any]:
        """The messages among ``messages`` that occur in the log."""
        if self.keys is None:
            assert self.path is not None  # a bus sets its keys itself
            wants = [Want.of(m, None) for m in self.db.messages]
            # a J1939 message matches a range of ids: then every id is read
            ids = sorted({w.value for w in wants}) if all(w.mask == 0x1FFFFFFF for w in wants) else None
            self.keys = set()
            for frames in iter_frames(self.path, ids=ids, channel=self.channel, max_frames=1 << 18):
                pairs = np.unique(frames.arbitration_id.astype(np.int64) * 2 + frames.is_extended)
                self.keys.update((int(p) // 2, bool(p % 2)) for p in pairs)
        keys = self.keys
        return [m for m in messages if Want.of(m, None).matches_any(keys)]


def _normalise(name: str) -> str:
    return re.sub(r"\d+$", "", re.sub(r"[^a-z0-9]", "", name.lower()))


def _matches(role: str, signal_name: str) -> bool:
    return re.fullmatch(_NAME_PATTERNS[role], _normalise(signal_name)) is not None


def detect(db: Any, present: Presence, where: str) -> dict[str, str]:
    """Signals for ax..az (required), gx..gz and the auxiliary channels, found by name."""
    accel = _detect_triple(db, ACCEL_ROLES, present, [])
    if accel is None:
        mismatch = log_mismatch(present.path, db, where, present.channel, [])
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
                ", ".join(names[:SHOWN]) + (f" and {len(names) - SHOWN} more" if len(names) > SHOWN else "")
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
    db: Any, roles: Sequence[str], present: Presence, prefer: list[Any]
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


def resolve(db: Any, text: Any, role: str, present: Presence, where: str) -> _Ref:
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
        wants = [Want.of(m, present.channel) for m in messages]
        mismatch = None if logged else log_mismatch(present.path, db, where, present.channel, wants)
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


def _unit_of(ref: _Ref, role: str, units: Mapping[str, Any]) -> tuple[str, str]:
    """The unit a signal is read in and what states it: the mapping's ``[units]``, else the DBC."""
    kind = UNIT_KIND[role]
    key = "accel" if kind == "accel" else "gyro" if kind == "gyro" else role
    given = units.get(key)
    if given is not None:
        return str(given), f"the mapping's units.{key}"
    return str(ref.message.get_signal_by_name(ref.signal).unit or ""), f"the DBC unit of {ref.label}"


def _unit_scale(ref: _Ref, role: str, units: Mapping[str, Any], where: str) -> tuple[float, float]:
    """Scale and offset from the signal's unit (the mapping's, else the DBC's) to SI."""
    kind = UNIT_KIND[role]
    key = "accel" if kind == "accel" else "gyro" if kind == "gyro" else role
    unit, source = _unit_of(ref, role, units)
    scale = si_scale(role, unit)
    if scale is not None:
        return scale
    raise InputError(
        where,
        f"{'an acceleration' if kind == 'accel' else 'a ' + kind} unit ({UNIT_HINT[kind]}) for {role}",
        f"{unit!r} ({source})",
        f"Check the mapping; if the DBC's unit is missing or wrong, set units.{key} in the mapping.",
    )


def build_plan(
    where: str,
    db: Any,
    refs: dict[str, _Ref],
    units: Mapping[str, Any],
    spec: Mapping[str, Any],
    channel: int | None,
    explicit: bool,
    present: Presence,
) -> Plan:
    has_gyro = all(r in refs for r in GYRO_ROLES)
    sources: list[Source] = []
    columns = []
    for role in ACCEL_ROLES + (GYRO_ROLES if has_gyro else ()):
        ref = refs[role]
        source = _source_for(sources, ref)
        source.signals.append(ref.signal)
        columns.append((sources.index(source), ref.signal, _unit_scale(ref, role, units, where)[0]))
    aux: dict[str, tuple[Source, str, float, float]] = {}
    notes: list[str] = []
    for role, key in AUX_KEYS.items():
        if role in refs:
            try:
                scale, offset = _unit_scale(refs[role], role, units, where)
            except InputError:
                if explicit:
                    raise
                # an auto-detected optional channel with an unknown unit is left out, and said
                unit, _ = _unit_of(refs[role], role, units)
                kind = UNIT_KIND[role]
                first = UNIT_HINT[kind].split(",")[0].split(" ")[0]
                notes.append(
                    f"{role} not read: {refs[role].label} was found by its name, but its DBC unit {unit!r} is no "
                    f"{kind} unit ({UNIT_HINT[kind]}); if that is the {role}, state its unit in the CAN mapping's "
                    f'[units] table: {role} = "{first}" (or {UNIT_HINT[kind]}; {option("mapping")})'
                )
                continue
            source = Source(refs[role].message, _mux_of(refs[role]), [refs[role].signal])
            aux[key] = (source, refs[role].signal, scale, offset)
    _assign_validity(sources + [a[0] for a in aux.values()], spec.get("valid"), db, where, present)
    axes, axis_map = _axes(spec.get("axes", "x,y,z"), spec.get("allow_left_handed", False))
    aux_required = {AUX_KEYS[r] for r in refs if r in AUX_KEYS} if explicit else set()
    placements = _placements(spec.get("messages", {}), db, where)
    for source in sources + [a[0] for a in aux.values()]:
        source.place(placements, channel)
    acc_units = tuple((refs[r].label, *_unit_of(refs[r], r, units), columns[i][2]) for i, r in enumerate(ACCEL_ROLES))
    plan = Plan(where, db, sources, columns, has_gyro, aux, aux_required, axes, axis_map, channel, acc_units)
    plan.notes = tuple(notes)
    read = [r for r in (*ACCEL_ROLES, *(GYRO_ROLES if has_gyro else ())) if r in refs]
    read += [r for r, k in AUX_KEYS.items() if k in aux]
    plan.units = _units_said(refs, read, units)
    return plan


def _units_said(refs: dict[str, _Ref], roles: Sequence[str], units: Mapping[str, Any]) -> tuple[str, str]:
    """The units the signals were read in, grouped (``ax, ay, az: g; gx, gy, gz: deg/s; …``), and what
    stated them (the DBC, or the mapping's [units] for some)."""
    grouped: dict[str, list[str]] = {}
    overridden: list[str] = []
    for role in roles:
        unit, by = _unit_of(refs[role], role, units)
        grouped.setdefault(unit, []).append(role)
        if by.startswith("the mapping") and by not in overridden:
            overridden.append(by)
    value = "; ".join(f"{', '.join(rs)}: {unit}" for unit, rs in grouped.items())
    by = "the DBC's signal units" + (", and " + ", ".join(overridden) if overridden else "")
    checked = "converted to SI; checked: the accelerometer's against gravity, the gyro's where stops or a drive show it"
    return value, f"{by} ({checked})"


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


def _source_for(sources: list[Source], ref: _Ref) -> Source:
    mux = _mux_of(ref)
    for source in sources:
        if source.message is ref.message and source.mux == mux:
            return source
    sources.append(Source(ref.message, mux))
    return sources[-1]


def _assign_validity(sources: list[Source], valid: Any, db: Any, where: str, present: Presence) -> None:
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
        ref = resolve(db, text, "valid", present, where)
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
    """The mapping's ``axes`` (a signed permutation, :func:`mountcal.io.input_conventions.parse_axes`) as a
    matrix (row i: device components of sensor axis i) and its description.

    A reflection states that the device's own triad is left-handed (the map makes it right-handed), as
    ``--axes`` does; ``allow_left_handed`` (older mappings needed it) may still give the reason. Whether
    the mapped axes are right-handed is checked where the data can tell (the stops' headings, turns).
    """
    axes = parse_axes(str(text), "the mapping's axes")
    if not axes.reflection:
        return axes.matrix, axes.text
    reason = allow if isinstance(allow, str) and allow else "the device's own triad is left-handed"
    return axes.matrix, f"{axes.text} (a reflection: {reason})"
