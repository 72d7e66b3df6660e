"""CAN bytes to numbers, differentially: random DBCs built with cantools' own classes, random frames written
into real logs by python-can's writers (asammdf under python-can's MF4 writer), then what mountcal reads
for the mapped roles (accelerometer, gyro, speed, heading) against cantools' ``decode_message`` of each
frame python-can reads back from the same file.

The rule compared (docs: :func:`mountcal.io.can.dbc.decode`, :mod:`mountcal.io.can.read`): a frame gives a
value where cantools decodes the signal with ``allow_truncated=True`` (a frame too short for a signal has
none; a multiplexer value the DBC does not define, none), and a row only where every signal of the row's
message is there and finite; every other frame of the message is counted in ``dropped``. Remote and error
frames are not data: never decoded, never counted as dropped.
"""

from __future__ import annotations

import math
import tempfile
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
import cantools
import numpy as np
import pytest
from cantools.database.can import Database, Message, Signal
from cantools.database.can.formats.dbc import DbcAttributeDefinition, DbcSpecifics
from cantools.database.conversion import BaseConversion
from cantools.j1939 import frame_id_unpack, pgn_pack
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from mountcal.core.errors import InputError
from mountcal.io.can.dbc import decode, load_dbc, select_frames
from mountcal.io.can.files import iter_frames, read_frames
from mountcal.io.can.frames import CanFrames
from mountcal.io.can.read import read_can

PHASES = (Phase.explicit, Phase.reuse, Phase.generate)  # no shrinking: a failure prints its whole case
FORMATS = ("blf", "asc", "log", "trc", "csv", "mf4")
FD_LENGTHS = (12, 16, 20, 24, 32, 48, 64)
T0 = 1_700_000_000.0
G = 9.80665  # standard gravity: the reference's own number for a unit "g"

# each role's DBC units and their factor to mountcal's unit of the role (m/s², rad/s, m/s, deg)
UNITS = {
    "accel": {"m/s^2": 1.0, "g": G},
    "gyro": {"rad/s": 1.0, "deg/s": math.pi / 180.0},
    "speed": {"m/s": 1.0, "km/h": 1.0 / 3.6},
    "heading": {"deg": 1.0, "rad": 180.0 / math.pi},
}
GRAVITY = ("imu_ax", "imu_ay", "imu_az")
SCALES = (1, 2, -1, 0.5, 0.1, -0.25, 1 / 3, 0.0125, 1e-3, -7.5, 0.01)
OFFSETS = (0, 1, -40, 0.5, -273.15, 1000)

# the DBC's frame formats: what makes a message FD or J1939 (cantools writes VFrameFormat when defined)
V_FRAME_FORMAT = DbcAttributeDefinition(
    "VFrameFormat",
    default_value="StandardCAN",
    kind="BO_",
    type_name="ENUM",
    choices=[
        "StandardCAN",
        "ExtendedCAN",
        "reserved",
        "J1939PG",
        *["reserved"] * 10,
        "StandardCAN_FD",
        "ExtendedCAN_FD",
    ],
)


# ---------------------------------------------------------------------------------------------
# Random DBCs


@dataclass
class Msg:
    """One DBC message of the test: its cantools Message, the frame ids it is sent with, its mux."""

    message: Message
    send_ids: list[int]
    mux: str | None = None  # the multiplexer signal's name
    mux_ids: list[int] = field(default_factory=list)  # the values the mapped signals sit under
    other_mux: list[int] = field(default_factory=list)  # values of the decoy branch


@st.composite
def layouts(draw: st.DrawFn, first: int, size: int, *, float_ok: bool = True) -> dict[str, Any]:
    """A signal's layout within bytes ``first`` to ``first + size - 1``: byte order, start bit, length, sign,
    float."""
    bits = 8 * size
    kinds = (
        ["int"] + (["float32"] if bits >= 32 and float_ok else []) + (["float64"] if bits >= 64 and float_ok else [])
    )
    kind = draw(st.sampled_from(kinds))
    length = {"float32": 32, "float64": 64}.get(kind) or draw(st.integers(1, min(64, bits)))
    order = draw(st.sampled_from(["little_endian", "big_endian"]))
    at = 8 * first + draw(st.integers(0, bits - length))  # the first bit in the byte order's own sequence
    start = at if order == "little_endian" else 8 * (at // 8) + 7 - at % 8
    signed = kind != "int" or draw(st.booleans())
    return {"start": start, "length": length, "byte_order": order, "is_signed": signed, "is_float": kind != "int"}


def _signal(name: str, layout: dict[str, Any], scale: float, offset: float, unit: str, **kw: Any) -> Signal:
    conversion = BaseConversion.factory(scale, offset, None, layout["is_float"])
    return Signal(
        name,
        layout["start"],
        layout["length"],
        layout["byte_order"],
        layout["is_signed"],
        conversion=conversion,
        unit=unit,
        **kw,
    )


@st.composite
def messages(draw: st.DrawFn, name: str, frame_id: int, roles: dict[str, tuple[str, bool]]) -> Msg:
    """A message carrying ``roles`` (signal name → unit kind, on gravity), maybe multiplexed, J1939 or FD.

    Each signal (and the multiplexer) has bytes of its own, so that the frames cantools encodes carry every
    value; the accelerometer's signals (on gravity) get an offset that puts gravity (1 g split over three
    axes) on a raw value of their range, so that the log passes mountcal's gravity check."""
    kind = draw(st.sampled_from(["standard", "extended", "extended_low", "j1939"]))  # low: a 29-bit id <= 0x7FF
    fd = draw(st.booleans())
    # a multiplexer: the mapped signals under some of its values (a decoy under others), or static beside it
    muxing = draw(st.sampled_from(["none", "branch", "static"]))
    muxed = muxing != "none"
    count = len(roles) + muxed
    size = draw(st.sampled_from(FD_LENGTHS)) if fd else draw(st.integers(count, 8))
    cuts = (
        sorted(draw(st.lists(st.integers(1, size - 1), min_size=count - 1, max_size=count - 1, unique=True)))
        if count > 1
        else []
    )
    chunks = list(zip([0, *cuts], [*cuts, size], strict=True))
    signals = []
    mux_ids: list[int] = []
    other: list[int] = []
    mux = None
    if muxed:  # a multiplexer: mapped signals under some values, a decoy under others
        mux = f"{name}_mux"
        lo, hi = chunks.pop(0)
        mux_layout = draw(layouts(lo, hi - lo, float_ok=False).filter(lambda lay: lay["length"] <= 8))
        mux_layout["is_signed"] = False
        signals.append(_signal(mux, mux_layout, 1, 0, "", is_multiplexer=True))
        values = list(range(1 << mux_layout["length"]))
        mux_ids = sorted(draw(st.lists(st.sampled_from(values), min_size=1, max_size=2, unique=True)))
        left = [v for v in values if v not in mux_ids]
        other = sorted(draw(st.lists(st.sampled_from(left), max_size=2, unique=True))) if left else []
    for k, ((signal_name, (unit_kind, gravity)), (lo, hi)) in enumerate(zip(roles.items(), chunks, strict=True)):
        layout = draw(layouts(lo, hi - lo))
        scale = draw(st.sampled_from(SCALES))
        unit = draw(st.sampled_from(sorted(UNITS[unit_kind])))
        if gravity:
            raw = _raw_range(layout)
            at = draw(st.integers(raw[0], raw[1])) if not layout["is_float"] else draw(st.sampled_from([0, 1, -3]))
            offset: float = G / math.sqrt(3.0) / UNITS["accel"][unit] - at * scale
        else:
            offset = draw(st.sampled_from(OFFSETS))
        extra: dict[str, Any] = {"multiplexer_ids": mux_ids, "multiplexer_signal": mux} if muxing == "branch" else {}
        signals.append(_signal(signal_name, layout, scale, offset, unit, **extra))
        decoy = other if muxing == "branch" else mux_ids
        if k == 0 and mux and decoy:  # a decoy on another branch (over the same bits), or on the only one
            signals.append(_signal(f"{name}_decoy", layout, 1, 0, "", multiplexer_ids=decoy, multiplexer_signal=mux))
    if kind == "j1939":
        pdu_format = draw(st.sampled_from([0x10, 0x20, 0xF0, 0xF8])) + (frame_id & 7)  # a PGN of its own
        frame = (6 << 26) | (pdu_format << 16) | (frame_id & 0xFF) << 8 | 0x21
        da = draw(st.integers(0, 255)) if pdu_format < 240 else (frame >> 8) & 0xFF
        send = (draw(st.integers(0, 7)) << 26) | (pdu_format << 16) | (da << 8) | draw(st.integers(0, 255))
    else:
        frame = 0x1000000 | frame_id if kind == "extended" else frame_id
        send = frame
    message = Message(
        frame,
        name,
        size,
        signals,
        is_extended_frame=kind != "standard",
        is_fd=fd,
        protocol="j1939" if kind == "j1939" else None,
        strict=False,
    )
    return Msg(message, [send], mux, mux_ids, other)


def _raw_range(layout: dict[str, Any]) -> tuple[int, int]:
    n = layout["length"]
    return (-(1 << (n - 1)), (1 << (n - 1)) - 1) if layout["is_signed"] else (0, (1 << n) - 1)


def _dbc_text(msgs: list[Msg]) -> str:
    definitions = OrderedDict([("VFrameFormat", V_FRAME_FORMAT)])
    db = Database(
        [m.message for m in msgs], dbc_specifics=DbcSpecifics(attribute_definitions=definitions), strict=False
    )
    return str(db.as_dbc_string())


# ---------------------------------------------------------------------------------------------
# Random traffic


@st.composite
def payloads(draw: st.DrawFn, msg: Msg, gravity: bool) -> tuple[bytes, bool]:
    """A frame of ``msg``: encoded by cantools (gravity on the accelerometer), or random bytes of any length
    (shorter than the message, an FD length, an undefined multiplexer value)."""
    if gravity or draw(st.integers(0, 3)) == 0:
        values: dict[str, float] = {}
        for s in msg.message.signals:
            if s.is_multiplexer:
                values[s.name] = draw(st.sampled_from(msg.mux_ids))
            elif not s.multiplexer_ids or set(s.multiplexer_ids) <= set(msg.mux_ids):
                if gravity and s.name in GRAVITY:
                    low, high = _raw_range({"length": s.length, "is_signed": s.is_signed})
                    raw_g = (G / math.sqrt(3.0) / UNITS["accel"][str(s.unit)] - s.offset) / s.scale
                    values[s.name] = raw_g if s.is_float else min(max(round(raw_g), low), high)
                else:
                    raw = draw(st.integers(*_raw_range({"length": s.length, "is_signed": s.is_signed})))
                    values[s.name] = float(raw) if s.is_float else raw
        data = msg.message.encode(values, scaling=False, strict=False)  # raw values: no rounding at the range's ends
        return bytes(data), msg.message.is_fd
    fd = msg.message.is_fd and draw(st.booleans())
    length = draw(st.sampled_from((*range(9), *FD_LENGTHS))) if fd else draw(st.integers(0, 8))
    return draw(st.binary(min_size=length, max_size=length)), fd or length > 8


@st.composite
def traffic(draw: st.DrawFn, msgs: list[Msg], imu: Msg) -> list[can.Message]:
    """Frames of every message (the IMU's mostly gravity), foreign ids, remote and error frames, FD flags."""
    out: list[can.Message] = []
    n = draw(st.integers(8, 24))
    for _ in range(n):
        for msg in msgs:
            gravity = msg is imu and draw(st.integers(0, 4)) < 4
            data, fd = draw(payloads(msg, gravity))
            brs, esi = (draw(st.booleans()), draw(st.booleans())) if fd else (False, False)
            ident = msg.send_ids[0]
            # a DLC above the bytes: classic 9-15 (8 bytes on the wire), or an FD code beyond the bytes stored
            longer = [d for d in FD_LENGTHS if d > len(data)] if fd else list(range(9, 16)) if len(data) == 8 else []
            dlc = draw(st.sampled_from([len(data)] * 3 + longer[:1]))
            out.append(
                can.Message(
                    arbitration_id=ident,
                    is_extended_id=msg.message.is_extended_frame,
                    data=data,
                    dlc=dlc,
                    is_fd=fd,
                    bitrate_switch=brs,
                    error_state_indicator=esi,
                    channel=0,
                )
            )
            extra = draw(st.sampled_from(["none", "none", "remote", "error", "foreign"]))
            if extra == "remote":
                dlc = min(msg.message.length, 8)
                out.append(
                    can.Message(
                        arbitration_id=ident,
                        is_extended_id=msg.message.is_extended_frame,
                        is_remote_frame=True,
                        dlc=dlc,
                        channel=0,
                    )
                )
            elif extra == "error":
                out.append(can.Message(arbitration_id=0, is_error_frame=True, dlc=0, channel=0))
            elif extra == "foreign":
                out.append(can.Message(arbitration_id=0x7DF, data=b"\2\1\x0d", channel=0))
    for k, m in enumerate(out):
        m.timestamp = T0 + 0.001 * k
    return out


def _write(path: Path, frames: list[can.Message]) -> Path:
    with can.Logger(path) as writer:
        for frame in frames:
            writer.on_message_received(frame)
    return path


# ---------------------------------------------------------------------------------------------
# The reference: python-can reads the file back, cantools decodes each frame


def _pgn(frame_id: int) -> int:
    unpacked = frame_id_unpack(frame_id)
    ps = unpacked.pdu_specific if unpacked.pdu_format >= 240 else 0
    return int(pgn_pack(unpacked.reserved, unpacked.data_page, unpacked.pdu_format, ps))


def _is_frame_of(m: can.Message, message: Any) -> bool:
    if bool(m.is_extended_id) != bool(message.is_extended_frame):
        return False
    if message.protocol == "j1939":
        return _pgn(m.arbitration_id) == _pgn(message.frame_id)
    return int(m.arbitration_id) == int(message.frame_id)


def _reference(path: Path) -> list[can.Message]:
    with can.LogReader(path) as reader:
        return [m for m in reader if not (m.is_error_frame or m.is_remote_frame)]


def _cantools(message: Any, data: bytes) -> dict[str, float] | None:
    try:
        return {k: float(v) for k, v in message.decode(data, decode_choices=False, allow_truncated=True).items()}
    except cantools.database.DecodeError:
        return None  # cantools refuses the frame (a multiplexer value the DBC does not define)


def _expected_rows(
    reference: list[can.Message], message: Any, names: list[str], mux: str | None, mux_ids: list[int]
) -> tuple[list[float], list[list[float]], int]:
    """Times and values of the rows the frames of ``message`` give for ``names``, and how many were unusable."""
    t_s, rows, unusable = [], [], 0
    for m in reference:
        if not _is_frame_of(m, message):
            continue
        decoded = _cantools(message, bytes(m.data))
        if message.get_signal_by_name(names[0]).multiplexer_ids:
            # a source of multiplexer branches: frames of other values (defined or not) are not its frames;
            # one too short to carry the multiplexer may be, and is unusable
            if decoded is None or (mux in decoded and int(decoded[mux]) not in mux_ids):
                continue
        values = None if decoded is None else [decoded.get(n, math.nan) for n in names]
        if values is None or not all(math.isfinite(v) for v in values):
            unusable += 1
            continue
        t_s.append(m.timestamp)
        rows.append(values)
    return t_s, rows, unusable


def _close(ours: Any, theirs: Any, what: str) -> None:
    ours, theirs = np.asarray(ours, np.float64), np.asarray(theirs, np.float64)
    assert ours.shape == theirs.shape, f"{what}: {ours.shape} rows, cantools {theirs.shape}"
    with _errstate():
        scale = np.maximum(np.abs(theirs), 1.0)
        bad = ~((ours == theirs) | (np.abs(ours - theirs) <= 1e-9 * scale) | (np.isnan(ours) & np.isnan(theirs)))
    if bad.any():
        k = np.argwhere(bad)[0]
        raise AssertionError(f"{what}: row {k}: mountcal {ours[tuple(k)]!r}, cantools {theirs[tuple(k)]!r}")


# ---------------------------------------------------------------------------------------------
# The properties


@st.composite
def cases(draw: st.DrawFn) -> tuple[list[Msg], dict[str, str], list[can.Message], str]:
    roles = {name: ("accel", True) for name in GRAVITY}
    signals = {r: f"IMU.imu_{r}" for r in ("ax", "ay", "az")}
    if draw(st.booleans()):
        roles.update({f"imu_{r}": ("gyro", False) for r in ("gx", "gy", "gz")})
        signals.update({r: f"IMU.imu_{r}" for r in ("gx", "gy", "gz")})
    imu = draw(messages("IMU", 0x100, roles))
    msgs = [imu]
    for role, ident in (("speed", 0x102), ("heading", 0x103)):
        if draw(st.booleans()):
            msgs.append(draw(messages(role.upper(), ident, {f"{role}_sig": (role, False)})))
            signals[role] = f"{role.upper()}.{role}_sig"
    frames = draw(traffic(msgs, imu))
    fmt = draw(st.sampled_from(FORMATS))
    return msgs, signals, frames, fmt


def _mapping_text(signals: dict[str, str]) -> str:
    return "[signals]\n" + "".join(f'{role} = "{text}"\n' for role, text in signals.items())


@settings(max_examples=60, phases=PHASES, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(cases())
def test_mapped_roles_equal_cantools_on_every_frame(case: tuple[list[Msg], dict[str, str], list[Any], str]) -> None:
    msgs, signals, frames, fmt = case
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        dbc = folder / "random.dbc"
        dbc.write_text(_dbc_text(msgs), encoding="ascii")
        mapping = folder / "map.toml"
        mapping.write_text(_mapping_text(signals), encoding="utf-8")
        log = _write(folder / f"bus.{fmt}", frames)
        reference = _reference(log)
        db = cantools.database.load_file(dbc, strict=False)  # the reference's own reading of the DBC
        _check_decode(log, db, msgs)
        _check_roles(log, dbc, mapping, db, msgs, signals, reference)


def _errstate() -> Any:
    """The reference's own arithmetic on NaN and inf values, quietly (mountcal's must be quiet by itself)."""
    return np.errstate(over="ignore", invalid="ignore")


def _check_decode(log: Path, db: Any, msgs: list[Msg]) -> None:
    """Every signal of every message, frame by frame: mountcal's decode against cantools', on the whole table
    and on chunks of a few frames (a chunk of classic frames only is 8 bytes wide, one with CAN FD 64)."""
    ours_db = load_dbc(log.parent / "random.dbc")
    table = read_frames(log)
    chunks = list(iter_frames(log, max_frames=5))
    reference = _reference(log)
    for msg in msgs:
        message = db.get_message_by_name(msg.message.name)
        mine = ours_db.get_message_by_name(message.name)
        ours = decode(select_frames(table, mine), mine)
        parts = [decode(select_frames(chunk, mine), mine) for chunk in chunks]
        theirs = [_cantools(message, bytes(m.data)) for m in reference if _is_frame_of(m, message)]
        for signal in message.signals:
            expected = [math.nan if d is None else d.get(signal.name, math.nan) for d in theirs]
            _close(ours[signal.name], expected, f"{log.suffix} {message.name}.{signal.name}")
            chunked = np.concatenate([p[signal.name] for p in parts]) if parts else np.empty(0)
            _close(chunked, expected, f"{log.suffix} {message.name}.{signal.name}, in chunks of 5 frames")


def _check_roles(
    log: Path, dbc: Path, mapping: Path, db: Any, msgs: list[Msg], signals: dict[str, str], reference: list[can.Message]
) -> None:
    by_name = {m.message.name: m for m in msgs}
    imu_message = db.get_message_by_name("IMU")
    roles = [r for r in ("ax", "ay", "az", "gx", "gy", "gz") if r in signals]
    names = [f"imu_{r}" for r in roles]
    t_s, rows, unusable = _expected_rows(reference, imu_message, names, by_name["IMU"].mux, by_name["IMU"].mux_ids)
    aux = {}
    for role in ("speed", "heading"):
        if role in signals:
            message = db.get_message_by_name(role.upper())
            msg = by_name[role.upper()]
            aux[role] = (message, _expected_rows(reference, message, [f"{role}_sig"], msg.mux, msg.mux_ids))
    if not rows or any(not e[0] and not e[2] for _, e in aux.values()):
        # no usable IMU row, or a mapped message without a frame: refused, saying so
        with pytest.raises(InputError, match=r"expected (usable accelerometer samples|frames of|CAN frames)"):
            read_can(log, dbc, mapping=mapping)
        return
    kinds = ["accel"] * 3 + ["gyro"] * (len(roles) - 3)
    factors = [UNITS[k][str(imu_message.get_signal_by_name(n).unit)] for k, n in zip(kinds, names, strict=True)]
    with _errstate():
        expected = np.asarray(rows).reshape(-1, len(roles)) * factors
        magnitude = np.median(np.linalg.norm(expected[:, :3], axis=1))
    if not 0.5 * G <= magnitude <= 1.5 * G:  # random frames outvoted gravity
        with pytest.raises(InputError, match="expected accelerations of magnitude near 1 g"):
            read_can(log, dbc, mapping=mapping)
        return
    samples = read_can(log, dbc, mapping=mapping)
    _close(samples.t_s, t_s, "t_s")
    _close(samples.acc_s, expected[:, :3], "acc_s")
    if len(roles) == 6:
        _close(samples.gyro_s, expected[:, 3:], "gyro_s")
    assert sum(v for k, v in samples.dropped.items() if k.startswith("IMU")) == unusable, samples.dropped
    for role, (message, (t_aux, values, unusable)) in aux.items():
        factor = UNITS[role][str(message.get_signal_by_name(f"{role}_sig").unit)]
        key = {"speed": "speed_mps", "heading": "heading_deg"}[role]
        channel = samples.channels.get(key)
        _close(channel.t_s if channel is not None else [], t_aux, f"{key} t_s")
        with _errstate():
            scaled = np.asarray(values).ravel() * factor
        _close(channel.value if channel is not None else [], scaled, key)
        assert sum(v for k, v in samples.dropped.items() if k.startswith(role.upper())) == unusable, samples.dropped


# ---------------------------------------------------------------------------------------------
# The divergences the property found, one each


MUX_DBC = """VERSION ""
NS_ :
BS_:
BU_:
BO_ 256 IMU: 8 Vector__XXX
 SG_ Page M : 0|8@1+ (1,0) [0|0] "" Vector__XXX
 SG_ Temp m1 : 56|8@1+ (1,0) [0|0] "" Vector__XXX
 SG_ AccX : 8|16@1- (0.001,0) [0|0] "g" Vector__XXX
 SG_ AccY : 24|16@1- (0.001,0) [0|0] "g" Vector__XXX
 SG_ AccZ : 40|16@1- (0.001,0) [0|0] "g" Vector__XXX
"""


def _imu_frames(pages: list[int]) -> list[can.Message]:
    """Frames of the IMU above: gravity on z, the multiplexer page as given (only page 1 is defined)."""
    return [
        can.Message(
            timestamp=T0 + 0.01 * k,
            arbitration_id=256,
            is_extended_id=False,
            data=bytes([page, 0, 0, 0, 0, 0xE8, 0x03, 20]),
        )
        for k, page in enumerate(pages)
    ]


@pytest.mark.parametrize("fmt", ["blf", "asc"])
def test_a_frame_whose_multiplexer_value_the_dbc_does_not_define_is_not_read(tmp_path: Path, fmt: str) -> None:
    """cantools refuses such a frame whole (its static signals too): mountcal decoded them (page 7: AccZ = 1 g
    read as a sample); now every signal is NaN there and the frame is counted, not read."""
    dbc = tmp_path / "mux.dbc"
    dbc.write_text(MUX_DBC, encoding="ascii")
    log = _write(tmp_path / f"bus.{fmt}", _imu_frames([1, 7, 1, 1]))
    db = cantools.database.load_file(dbc)
    with pytest.raises(cantools.database.DecodeError):
        db.decode_message(256, bytes([7, 0, 0, 0, 0, 0xE8, 0x03, 20]))
    values = decode(read_frames(log), load_dbc(dbc).get_message_by_name("IMU"))
    assert np.isnan(values["AccZ"][1]) and np.isnan(values["Page"][1]) and values["AccZ"][0] == pytest.approx(1.0)
    mapping = {"signals": {"ax": "IMU.AccX", "ay": "IMU.AccY", "az": "IMU.AccZ"}}
    samples = read_can(log, dbc, mapping=mapping)
    np.testing.assert_allclose(samples.t_s - samples.t_s[0], [0.0, 0.02, 0.03], atol=1e-6)  # ASC: from its start
    assert samples.dropped == {"IMU: multiplexer value the DBC does not define": 1}


def _branch_dbc(folder: Path) -> Path:
    """The IMU above with its accelerometer on the multiplexer's page 1."""
    dbc = folder / "branch.dbc"
    text = MUX_DBC
    for axis in "XYZ":
        text = text.replace(f" SG_ Acc{axis} :", f" SG_ Acc{axis} m1 :")
    dbc.write_text(text, encoding="ascii")
    return dbc


def test_a_log_of_other_multiplexer_branches_only_is_refused_saying_so(tmp_path: Path) -> None:
    """The mapped branch (page 1) absent, the message present on page 2: refused as "found none ... IMU is on
    channel 0 (3 frames)", which sent the user to the channel; now it names the branch and the values found."""
    log = _write(tmp_path / "bus.blf", _imu_frames([2, 2, 2]))
    mapping = {"signals": {"ax": "IMU.AccX", "ay": "IMU.AccY", "az": "IMU.AccZ"}}
    with pytest.raises(
        InputError, match=r"expected frames of IMU with Page = 1 .*found frames of IMU with Page = 2 only"
    ):
        read_can(log, _branch_dbc(tmp_path), mapping=mapping)


def test_a_frame_too_short_for_its_multiplexer_is_counted_whatever_the_branch(tmp_path: Path) -> None:
    """A frame too short to carry the multiplexer may be of the mapped branch: it is counted as too short. It was
    counted only where the branch's value was 0 (the missing byte read as 0), else dropped without a word."""
    dbc = _branch_dbc(tmp_path)
    frames = _imu_frames([1, 1, 1])
    frames.insert(1, can.Message(timestamp=T0 + 0.005, arbitration_id=256, is_extended_id=False, data=b""))
    log = _write(tmp_path / "bus.blf", frames)
    mapping = {"signals": {"ax": "IMU.AccX", "ay": "IMU.AccY", "az": "IMU.AccZ"}}
    samples = read_can(log, dbc, mapping=mapping)
    assert len(samples) == 3
    assert samples.dropped == {"IMU: frame shorter than the DBC layout": 1}


def test_nan_and_huge_float_payloads_decode_quietly_to_what_cantools_gives() -> None:
    """A float64 signal holding a signalling NaN, or a float beyond the range once scaled, made numpy warn
    ("invalid value encountered in multiply", an error under pytest and a warning on the CLI's stderr)."""
    text = MUX_DBC.replace(
        "BO_ 256 IMU: 8 Vector__XXX",
        'BO_ 512 F: 8 Vector__XXX\n SG_ Big : 0|64@1- (1000,0) [0|0] "" Vector__XXX\n'
        "SIG_VALTYPE_ 512 Big : 2;\nBO_ 256 IMU: 8 Vector__XXX",
    )
    message = cantools.database.load_string(text, "dbc").get_message_by_name("F")
    payloads = [bytes.fromhex("010000000000f07f"), np.array([1e308], "<f8").tobytes()]  # a signalling NaN; 1e308
    table = CanFrames(
        np.arange(2, dtype=np.float64),
        np.zeros(2, np.int64),
        np.full(2, 512, np.uint32),
        np.zeros(2, np.bool_),
        np.full(2, 8, np.uint8),
        np.frombuffer(b"".join(payloads), np.uint8).reshape(2, 8).copy(),
    )
    ours = decode(table, message)["Big"]
    theirs = [float(message.decode(p)["Big"]) for p in payloads]
    assert np.isnan(ours[0]) and math.isnan(theirs[0])
    assert ours[1] == theirs[1] == math.inf
    single = message.signals[0]
    single.length, single.conversion = 32, BaseConversion.factory(1, 0, None, True)  # a float32, signalling NaN
    table.data[0, :4] = np.frombuffer(bytes.fromhex("0100a0ff"), np.uint8)
    assert np.isnan(decode(table, message)["Big"][0])


def test_a_blf_frame_carries_the_bytes_it_holds_not_its_dlc(tmp_path: Path) -> None:
    """A classic frame with DLC 15 carries 8 bytes, a CAN FD object whose DLC says 12 may store 8: python-can
    reads 8 bytes of each and cantools decodes no signal beyond them. mountcal's BLF reader took the DLC's length
    as the bytes, and decoded the zero padding beyond byte 8 as values (B and C read 0 for no byte in the log)."""
    db = cantools.database.load_string(
        'VERSION ""\nNS_ :\nBS_:\nBU_:\nBO_ 256 M: 64 Vector__XXX\n SG_ A : 0|8@1+ (1,0) [0|0] "" Vector__XXX\n'
        ' SG_ B : 64|8@1+ (1,0) [0|0] "" Vector__XXX\n SG_ C : 72|8@1+ (1,0) [0|0] "" Vector__XXX\n',
        "dbc",
        strict=False,
    )
    message = db.get_message_by_name("M")
    classic = [can.Message(timestamp=T0 + k, arbitration_id=256, is_extended_id=False, dlc=15, data=bytes(8))
               for k in range(3)]  # fmt: skip
    fd = can.Message(timestamp=T0 + 3, arbitration_id=256, is_extended_id=False, is_fd=True, dlc=12, data=bytes(8))
    for name, frames in (("uniform.blf", classic), ("mixed.blf", [*classic, fd])):  # BLF's fast path and its scan
        log = _write(tmp_path / name, frames)
        reference = _reference(log)
        ours = decode(read_frames(log), message)
        for k, m in enumerate(reference):
            assert len(m.data) == 8 and "B" not in message.decode(bytes(m.data), allow_truncated=True)
            assert np.isnan(ours["B"][k]) and np.isnan(ours["C"][k]) and ours["A"][k] == 0.0
        assert read_frames(log).dlc.tolist() == [8] * len(frames)


def test_a_decoded_acceleration_near_the_float_range_is_checked_by_gravity_quietly(tmp_path: Path) -> None:
    """A finite value whose square overflows (1e300: a float signal's bits, a huge factor) made the gravity check's
    norm warn "overflow encountered in multiply" (an error under pytest, stderr on the CLI); it is a row like
    any other, and gravity is judged on the median."""
    dbc = tmp_path / "huge.dbc"
    text = MUX_DBC.replace('"g"', '"m/s^2"').replace("AccZ : 40|16@1- (0.001,0)", "AccZ : 40|16@1- (1e+300,9.80665)")
    dbc.write_text(text, encoding="ascii")
    frames = _imu_frames([1, 1, 1, 1])
    for k, frame in enumerate(frames):
        frame.data[5:7] = b"\x01\x00" if k == 2 else b"\x00\x00"  # AccZ raw 0: 1 g, raw 1: 1e300 m/s²
    log = _write(tmp_path / "bus.blf", frames)
    samples = read_can(log, dbc, mapping={"signals": {"ax": "IMU.AccX", "ay": "IMU.AccY", "az": "IMU.AccZ"}})
    np.testing.assert_allclose(samples.acc_s[:, 2], [9.80665, 9.80665, 1e300, 9.80665])
