"""Vectorised DBC decoding against cantools' frame-by-frame decoder, in every log format."""

from __future__ import annotations

import math
import random
from pathlib import Path
from typing import Any

import can
import cantools
import numpy as np
import pytest

from mountcal.core.errors import InputError
from mountcal.io.can.dbc import decode, load_dbc, payload_bytes
from mountcal.io.can.files import read_frames
from mountcal.io.can.frames import CanFrames

DATA = Path(__file__).resolve().parents[1] / "data"
OWN_DBC = DATA / "mm5_imu.dbc"
FORMATS = ["blf", "asc", "log", "trc", "csv", "mf4"]
T0 = 1_650_000_000.0

# real DBCs and the messages exercised: little/big-endian, signed/unsigned, 1..40-bit, multiplexed
REAL_SETS = {
    "bosch": ("dbc/bosch_abs_m5_mm5.10_abs.dbc", ["MM5_10_TX1", "MM5_10_TX2", "MM5_10_TX3", "BREMSE_33", "BREMSE_52"]),
    "canedge": ("canedge/dbc/gnss.dbc", ["0x9", "0x3", "0x5", "0x7", "0x2"]),
    "toyota": ("dbc/opendbc_toyota_2017_common.dbc", ["KINEMATICS", "STEER_ANGLE_SENSOR"]),
}
OWN_MESSAGES = ["MM5_10_TX1", "TEST_MIXED", "TEST_MUX", "TEST_BE64", "TEST_EXT64", "IMU_ACC_EXT"]


def _message(db: Any, ref: str) -> Any:
    if ref.startswith("0x"):
        return next(m for m in db.messages if m.frame_id == int(ref, 16))
    return db.get_message_by_name(ref)


def _random_values(message: Any, rng: random.Random) -> dict[str, float]:
    """Physical values from random raw values, one multiplexer branch chosen at random."""
    mux_choice: dict[str, int] = {}
    for signal in message.signals:
        if signal.is_multiplexer:
            ids = sorted({i for s in message.signals if s.multiplexer_signal == signal.name for i in s.multiplexer_ids})
            mux_choice[signal.name] = rng.choice(ids)
    values: dict[str, float] = {}
    for signal in message.signals:
        if signal.multiplexer_ids and mux_choice[signal.multiplexer_signal] not in signal.multiplexer_ids:
            continue
        if signal.name in mux_choice:
            values[signal.name] = mux_choice[signal.name]
        elif signal.is_float:
            values[signal.name] = rng.uniform(-1e6, 1e6)
        else:
            low, high = (
                (-(1 << (signal.length - 1)), (1 << (signal.length - 1)) - 1)
                if signal.is_signed
                else (0, (1 << signal.length) - 1)
            )
            values[signal.name] = rng.randint(low, high) * signal.scale + signal.offset
    return values


def _traffic(db: Any, refs: list[str], n_each: int) -> list[can.Message]:
    """Frames of the given messages, payloads encoded by cantools, interleaved with foreign ids."""
    rng = random.Random(3)
    messages = []
    for k in range(n_each):
        for j, ref in enumerate(refs):
            message = _message(db, ref)
            data = message.encode(_random_values(message, rng), scaling=True, strict=False)
            messages.append(
                can.Message(
                    timestamp=T0 + k * 0.01 + j * 1e-4,
                    arbitration_id=message.frame_id,
                    is_extended_id=message.is_extended_frame,
                    data=data,
                    channel=0,
                )
            )
        messages.append(
            can.Message(timestamp=T0 + k * 0.01 + 5e-3, arbitration_id=0x7DF, is_extended_id=False, data=b"\2\1\x0d")
        )
    return messages


def _write(path: Path, messages: list[can.Message]) -> Path:
    with can.Logger(path) as writer:
        for message in messages:
            writer.on_message_received(message)
    return path


def _check_against_cantools(path: Path, db: Any, refs: list[str]) -> int:
    """Decode every message of the log both ways; return the number of values compared."""
    frames = read_frames(path)
    with can.LogReader(path) as reader:
        reference = list(reader)
    compared = 0
    for ref in refs:
        message = _message(db, ref)
        rows = np.flatnonzero(
            (frames.arbitration_id == message.frame_id) & (frames.is_extended == message.is_extended_frame)
        )
        ours = decode(frames.take(rows), message)
        theirs = [
            db.decode_message(m.arbitration_id, m.data, decode_choices=False, force_extended_id=m.is_extended_id)
            for m in reference
            if m.arbitration_id == message.frame_id and m.is_extended_id == message.is_extended_frame
        ]
        assert len(theirs) == rows.shape[0] > 0
        for signal in message.signals:
            expected = np.array([float(d[signal.name]) if signal.name in d else np.nan for d in theirs])
            np.testing.assert_allclose(
                ours[signal.name], expected, rtol=1e-9, atol=0, equal_nan=True, err_msg=f"{ref}.{signal.name}"
            )
            compared += int(np.isfinite(expected).sum())
    return compared


@pytest.mark.parametrize("fmt", FORMATS)
def test_decode_equals_cantools_own_dbc(tmp_path: Path, fmt: str) -> None:
    """Runs without the real recordings: a DBC modelled on the MM5.10 plus layouts that stress the
    bit arithmetic (big-endian signed 12 and 64 bits, 13-bit signed at bit 17, float32, 64-bit
    unsigned on a 29-bit id, a multiplexer with little- and big-endian branches)."""
    db = cantools.database.load_file(OWN_DBC)
    path = _write(tmp_path / f"own.{fmt}", _traffic(db, OWN_MESSAGES, 40))
    assert _check_against_cantools(path, load_dbc(OWN_DBC), OWN_MESSAGES) > 500


@pytest.mark.real_data
@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("which", sorted(REAL_SETS))
def test_decode_equals_cantools_real_dbcs(real_data: Path, tmp_path: Path, fmt: str, which: str) -> None:
    dbc_path, refs = REAL_SETS[which]
    db = load_dbc(real_data / dbc_path)
    path = _write(tmp_path / f"{which}.{fmt}", _traffic(db, refs, 30))
    assert _check_against_cantools(path, db, refs) > 100


@pytest.mark.real_data
@pytest.mark.parametrize("name", ["opendbc_honda_common.dbc", "opendbc_hyundai_can.dbc"])
def test_opendbc_comment_lines_cantools_rejects_are_dropped(real_data: Path, name: str) -> None:
    path = real_data / "dbc" / name
    with pytest.raises(cantools.database.UnsupportedDatabaseFormatError):
        cantools.database.load_file(path, strict=False)
    db = load_dbc(path)
    message = db.get_message_by_name("KINEMATICS" if "honda" in name else "ESP12")
    rng = random.Random(5)
    payloads = [message.encode(_random_values(message, rng), strict=False) for _ in range(20)]
    frames = _frames(message.frame_id, payloads)
    ours = decode(frames, message)
    for k, payload in enumerate(payloads):
        for signal, value in message.decode(payload, decode_choices=False).items():
            assert ours[signal][k] == pytest.approx(float(value), rel=1e-9, abs=0)


@pytest.mark.real_data
def test_toyota_dbc_needs_non_strict_mode(real_data: Path) -> None:
    path = real_data / "dbc" / "opendbc_toyota_2017_common.dbc"
    with pytest.raises(cantools.database.UnsupportedDatabaseFormatError):
        cantools.database.load_file(path)
    assert load_dbc(path).get_message_by_name("KINEMATICS").frame_id == 0x24


def _frames(frame_id: int, payloads: list[bytes]) -> CanFrames:
    n = len(payloads)
    data = np.zeros((n, 64), np.uint8)
    for k, payload in enumerate(payloads):
        data[k, : len(payload)] = np.frombuffer(payload, np.uint8)
    return CanFrames(
        np.arange(n, dtype=np.float64),
        np.zeros(n, np.int64),
        np.full(n, frame_id, np.uint32),
        np.zeros(n, np.bool_),
        np.array([len(p) for p in payloads], np.uint8),
        data,
    )


def test_short_frames_and_other_multiplexer_values_decode_to_nan() -> None:
    db = load_dbc(OWN_DBC)
    mux = db.get_message_by_name("TEST_MUX")
    frames = _frames(mux.frame_id, [bytes([1, 10, 0, 0]), bytes([2, 1, 2, 0]), bytes([1])])
    values = decode(frames, mux, ["ValA", "ValB"])
    assert values["ValA"][0] == pytest.approx(1.0) and np.isnan(values["ValA"][1])
    assert np.isnan(values["ValB"][0]) and values["ValB"][1] == 0x0102
    assert np.isnan(values["ValA"][2])  # one byte: too short for ValA
    assert payload_bytes(mux, ["ValB"]) == 3


def test_unknown_signal_is_reported() -> None:
    message = load_dbc(OWN_DBC).get_message_by_name("MM5_10_TX1")
    with pytest.raises(InputError, match=r"MM5_10_TX1: expected signals AX1, found only AY1, Yaw_Rate"):
        decode(_frames(0x70, [bytes(8)]), message, ["AX1"])


NESTED_DBC = """VERSION ""
NS_ :
BS_:
BU_: N
BO_ 100 NESTED: 8 N
 SG_ Outer M : 0|8@1+ (1,0) [0|255] "" N
 SG_ Inner m1M : 8|8@1+ (1,0) [0|255] "" N
 SG_ Deep m2 : 16|8@1+ (1,0) [0|255] "" N
SG_MUL_VAL_ 100 Inner Outer 1-1;
SG_MUL_VAL_ 100 Deep Inner 2-2;
"""


def test_nested_multiplexing_is_refused_clearly(tmp_path: Path) -> None:
    path = tmp_path / "nested.dbc"
    path.write_text(NESTED_DBC)
    message = load_dbc(path).get_message_by_name("NESTED")
    with pytest.raises(InputError, match=r"at most one level of multiplexing"):
        decode(_frames(100, [bytes([1, 2, 3, 0, 0, 0, 0, 0])]), message, ["Deep"])


def test_unparsable_and_missing_dbc_are_reported(tmp_path: Path) -> None:
    bad = tmp_path / "bad.dbc"
    bad.write_text('VERSION ""\nBO_ 1 X: 8 N\n SG_ broken : nonsense\n')
    with pytest.raises(InputError, match=r"bad\.dbc: expected a DBC file cantools can parse"):
        load_dbc(bad)
    with pytest.raises(InputError, match=r"no such file"):
        load_dbc(tmp_path / "none.dbc")


@pytest.mark.parametrize(
    ("role", "unit", "scale"),
    [("ax", "m·s⁻²", 1.0), ("ax", "m/s²", 1.0), ("gx", "°·s⁻¹", math.pi / 180.0), ("gx", "° / s", math.pi / 180.0)],
)
def test_unit_spellings_with_typographic_characters(role: str, unit: str, scale: float) -> None:
    """SI's typographic spellings (a middle dot, superscript minus): "m·s⁻²" was no known unit, and an
    accelerometer so declared was refused."""
    from mountcal.io.can.signals import si_scale

    assert si_scale(role, unit) == pytest.approx((scale, 0.0))


def test_a_utf8_dbc_is_read_as_utf8_and_a_cp1252_one_as_cp1252(tmp_path: Path) -> None:
    """cantools reads a DBC as cp1252 by default: a UTF-8 file's "°/s" came out "Â°/s". A file that is valid
    UTF-8 beyond ASCII is read as UTF-8 (with or without a byte-order mark); Vector's cp1252 stays cp1252."""
    text = (
        'VERSION ""\n\n\nNS_ :\n\nBS_:\n\nBU_:\n\n\nBO_ 16 IMU: 8 Vector__XXX\n'
        ' SG_ GyroZ : 0|16@1- (0.01,0) [-300|300] "°/s" Vector__XXX\n'
    )
    for name, raw in (
        ("utf8.dbc", text.encode("utf-8")),
        ("bom.dbc", b"\xef\xbb\xbf" + text.encode("utf-8")),
        ("cp1252.dbc", text.encode("cp1252")),
    ):
        path = tmp_path / name
        path.write_bytes(raw)
        assert load_dbc(path).get_message_by_name("IMU").get_signal_by_name("GyroZ").unit == "°/s", name
