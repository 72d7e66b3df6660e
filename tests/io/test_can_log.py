"""Samples from CAN logs: signal mapping, auto-detection, alignment, streaming, real CANedge logs."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path
from typing import Any

import can
import cantools
import numpy as np
import pytest

from mountcal.core.errors import InputError
from mountcal.io.can.read import inspect_can, iter_can, read_can
from mountcal.io.samples import Samples

DATA = Path(__file__).resolve().parents[1] / "data"
OWN_DBC = DATA / "mm5_imu.dbc"
G_N = 9.80665
T0 = 1_700_000_000.0
GRAVITY_G = np.array([0.05, -0.02, 0.998])  # device axes x, y, z, in g
CANEDGE = Path("canedge")


def _write(path: Path, messages: list[can.Message]) -> Path:
    messages = sorted(messages, key=lambda m: m.timestamp)
    with can.Logger(path) as writer:
        for message in messages:
            writer.on_message_received(message)
    return path


def _frame(db: Any, name: str, t: float, values: dict[str, float], channel: int = 0) -> can.Message:
    message = db.get_message_by_name(name)
    data = message.encode(values, strict=False)
    return can.Message(
        timestamp=t,
        arbitration_id=message.frame_id,
        is_extended_id=message.is_extended_frame,
        data=data,
        channel=channel,
    )


def _mm5_messages(n: int, *, skip_tx3: range = range(0), channel: int = 0) -> list[can.Message]:
    """An MM5.10 at 100 Hz: AY1 in TX1 (t), AX1 in TX2 (t + 0.1 ms), AZ in TX3 (t + 0.2 ms), with a
    slowly varying gravity vector, wheel speeds and an OBD request in between."""
    db = cantools.database.load_file(OWN_DBC)
    messages = []
    for k in range(n):
        t = T0 + 0.01 * k
        g = GRAVITY_G + 0.01 * math.sin(k / 50.0)
        messages.append(_frame(db, "MM5_10_TX1", t, {"Yaw_Rate": 1.0, "AY1": g[1]}, channel))
        messages.append(_frame(db, "MM5_10_TX2", t + 1e-4, {"Roll_Rate": -2.0, "AX1": g[0]}, channel))
        if k not in skip_tx3:
            messages.append(_frame(db, "MM5_10_TX3", t + 2e-4, {"AZ": g[2]}, channel))
        if k % 2 == 0:
            speeds = {"whlspeed_FL": 10.0, "whlspeed_FR": 10.0, "whlspeed_RL": 10.0, "whlspeed_RR": 10.0}
            messages.append(_frame(db, "BREMSE_33", t + 5e-3, speeds, channel))
        if k % 10 == 0:
            messages.append(
                can.Message(timestamp=t + 7e-3, arbitration_id=0x7DF, is_extended_id=False, data=b"\2\1\x0d")
            )
    return messages


def _expected_acc(t_s: np.ndarray) -> np.ndarray:
    k = np.round((t_s - t_s[0]) / 0.01)  # ASC times count from the first frame; the others are absolute
    return (GRAVITY_G[None, :] + 0.01 * np.sin(k / 50.0)[:, None]) * G_N


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _assert_same_samples(a: Samples, b: Samples) -> None:
    np.testing.assert_array_equal(a.t_s, b.t_s)
    np.testing.assert_array_equal(a.acc_s, b.acc_s)
    if a.gyro_s is None:
        assert b.gyro_s is None
    else:
        assert b.gyro_s is not None
        np.testing.assert_array_equal(a.gyro_s, b.gyro_s)
    assert a.channels.keys() == b.channels.keys()
    for key in a.channels:
        np.testing.assert_array_equal(a.channels[key].t_s, b.channels[key].t_s)
        np.testing.assert_array_equal(a.channels[key].value, b.channels[key].value)
    assert a.dropped == b.dropped and a.axis_map == b.axis_map


def _joined(chunks: list[Samples]) -> Samples:
    channels = {}
    for key in {k for c in chunks for k in c.channels}:
        parts = [c.channels[key] for c in chunks if key in c.channels]
        channels[key] = type(parts[0])(np.concatenate([p.t_s for p in parts]), np.concatenate([p.value for p in parts]))
    dropped: dict[str, int] = {}
    for chunk in chunks:
        for key, count in chunk.dropped.items():
            dropped[key] = dropped.get(key, 0) + count
    gyro = None if chunks[0].gyro_s is None else np.concatenate([c.gyro_s for c in chunks if c.gyro_s is not None])
    return Samples(
        np.concatenate([c.t_s for c in chunks]),
        np.concatenate([c.acc_s for c in chunks]),
        gyro,
        channels,
        chunks[0].source,
        chunks[0].axis_map,
        dropped,
    )


# --- the Bosch MM5.10 layout: three messages aligned in time ---------------------------------


@pytest.mark.parametrize("fmt", ["blf", "asc", "log", "trc", "csv", "mf4"])
def test_mm5_axes_from_three_messages_are_aligned(tmp_path: Path, fmt: str) -> None:
    path = _write(tmp_path / f"mm5.{fmt}", _mm5_messages(300))
    before = _digest(path)
    samples = read_can(path, OWN_DBC)  # auto-detected: AX1 in 0x80, AY1 in 0x70, AZ in 0x576
    assert len(samples) == 300 and samples.gyro_s is None and samples.axis_map == "x,y,z"
    # on the clock of TX2 (the message carrying ax); quantisation 0.000127465 g
    np.testing.assert_allclose(samples.acc_s, _expected_acc(samples.t_s), atol=0.7 * 0.000127465 * G_N)
    assert samples.t_s.dtype == np.float64 and np.all(np.diff(samples.t_s) > 0)
    assert samples.dropped == {} and samples.source == str(path)
    assert _digest(path) == before


def test_rows_without_a_partner_within_one_period_are_dropped_and_counted(tmp_path: Path) -> None:
    path = _write(tmp_path / "gap.blf", _mm5_messages(400, skip_tx3=range(100, 105)))
    samples = read_can(path, OWN_DBC)
    # TX2 rows 101..104 have no TX3 frame within 10 ms; row 100 takes TX3 #99 (9.9 ms away)
    assert samples.dropped == {"MM5_10_TX2: no frame of MM5_10_TX1, MM5_10_TX3 within one period": 4}
    assert len(samples) == 396


@pytest.mark.parametrize("max_samples", [1, 7, 128, 1000])
def test_iter_can_concatenates_to_read_can_across_messages(tmp_path: Path, max_samples: int) -> None:
    path = _write(tmp_path / "mm5.blf", _mm5_messages(2500, skip_tx3=range(700, 704)))
    whole = read_can(path, OWN_DBC)
    chunks = list(iter_can(path, OWN_DBC, max_samples=max_samples))
    assert all(len(c) <= max_samples for c in chunks)
    _assert_same_samples(_joined(chunks), whole)


# --- the mapping ------------------------------------------------------------------------------

MAPPING = """
channel = 0
axes = "-y,x,z"
valid = []

[signals]
ax = "MM5_10_TX2.AX1"
ay = "0x70.AY1"
az = "MM5_10_TX3.AZ"
speed = "BREMSE_33.whlspeed_FL"

[units]
accel = "g"
"""


def test_mapping_file_with_axis_permutation(tmp_path: Path) -> None:
    path = _write(tmp_path / "mm5.blf", _mm5_messages(200))
    mapping = tmp_path / "imu.toml"
    mapping.write_text(MAPPING)
    samples = read_can(path, OWN_DBC, mapping=mapping)
    device = _expected_acc(samples.t_s)
    np.testing.assert_allclose(samples.acc_s[:, 0], -device[:, 1], atol=2e-3)  # sensor x = -device y
    np.testing.assert_allclose(samples.acc_s[:, 1], device[:, 0], atol=2e-3)
    np.testing.assert_allclose(samples.acc_s[:, 2], device[:, 2], atol=2e-3)
    assert samples.axis_map == "-y,x,z"
    speed = samples.channels["speed_mps"]
    assert speed.value.shape == (100,) and np.allclose(speed.value, 10.0)


def _dbc_with_acc_unit(tmp_path: Path, unit: str) -> Path:
    """The test DBC with the MM5.10's accelerometer signals (in g) declared in ``unit``: a DBC that lies."""
    text = OWN_DBC.read_text(encoding="cp1252")
    lines = [line.replace('"g"', f'"{unit}"') if " SG_ A" in line else line for line in text.splitlines(True)]
    path = tmp_path / f"mm5_acc_{unit.replace('/', '_')}.dbc"
    path.write_text("".join(lines), encoding="cp1252")
    return path


def test_mapping_as_dict_overrides_units_and_channel_argument_wins(tmp_path: Path) -> None:
    path = _write(tmp_path / "mm5.blf", _mm5_messages(100, channel=1))
    spec = {"channel": 5, "signals": {"ax": "MM5_10_TX2.AX1", "ay": "MM5_10_TX1.AY1", "az": "MM5_10_TX3.AZ"}}
    in_g = read_can(path, OWN_DBC, mapping=spec, channel=1)
    wrong_dbc = _dbc_with_acc_unit(tmp_path, "m/s^2")  # the frames are in g, as the mapping says
    overridden = read_can(path, wrong_dbc, mapping={**spec, "units": {"accel": "g"}}, channel=1)
    np.testing.assert_array_equal(in_g.acc_s, overridden.acc_s)
    np.testing.assert_allclose(in_g.acc_s, _expected_acc(in_g.t_s), atol=1e-3)


@pytest.mark.parametrize(
    ("dbc_unit", "units", "fits", "said"),
    [
        ("m/s^2", {}, "g", "read in m/s^2 (the DBC unit of MM5_10_TX2.AX1, MM5_10_TX1.AY1, MM5_10_TX3.AZ)"),
        ("g", {"accel": "m/s^2"}, "g", "read in m/s^2 (the mapping's units.accel)"),
        ("mg", {}, "g", "read in mg (the DBC unit of"),
        ("g", {"accel": "mg"}, "g", "read in mg (the mapping's units.accel)"),
    ],
)
def test_an_acceleration_unit_gravity_contradicts_is_refused_naming_the_unit_that_fits(
    tmp_path: Path, dbc_unit: str, units: dict[str, str], fits: str, said: str
) -> None:
    """Frames in g read in another unit (the DBC's, or the mapping's [units]) have a median magnitude far
    from 1 g: refused, in the reader every command goes through (rotate wrote such samples, exit 0, and
    stops/calibrate named --unit g, which a CAN log refuses), naming what stated the unit and the one that fits."""
    path = _write(tmp_path / "mm5.blf", _mm5_messages(100))
    dbc = OWN_DBC if dbc_unit == "g" else _dbc_with_acc_unit(tmp_path, dbc_unit)
    mapping = {"units": units} if units else None
    for read in (
        lambda: read_can(path, dbc, mapping=mapping),
        lambda: next(iter_can(path, dbc, mapping=mapping, max_samples=10)),
    ):
        with pytest.raises(InputError) as err:
            read()
        text = str(err.value)
        assert said in text and "(0.5–1.5 g)" in text
        assert f'accel = "{fits}"' in text and "--unit" not in text


def test_acceleration_whose_unit_fits_none_names_the_dbc_factor(tmp_path: Path) -> None:
    """A factor off by 2048 (raw counts declared in g) fits no unit: the refusal says so and points at the
    factor; a median under 0.5 m/s² (a gravity-free signal) is marked, not refused, as for tables."""
    db = cantools.database.load_file(OWN_DBC)
    path = _write(tmp_path / "mm5.blf", _mm5_messages(50))
    text = OWN_DBC.read_text(encoding="cp1252").replace("(0.000127465,-4.1768)", "(0.261048,-8554.09)")
    counts = tmp_path / "counts.dbc"
    counts.write_text(text, encoding="cp1252")
    with pytest.raises(
        InputError, match=r"No unit fits: .* decode to a median magnitude of 20\d\d g, where 1 g is 1 g"
    ):
        read_can(path, counts)
    noise = np.random.default_rng(5).normal(0.0, 0.01, (50, 3))  # g: a gravity-free signal, mean ≈ 0
    still = [_frame(db, "MM5_10_TX1", T0 + 0.01 * k, {"Yaw_Rate": 0.0, "AY1": noise[k, 1]}) for k in range(50)]
    still += [_frame(db, "MM5_10_TX2", T0 + 0.01 * k + 1e-4, {"Roll_Rate": 0.0, "AX1": noise[k, 0]}) for k in range(50)]
    still += [_frame(db, "MM5_10_TX3", T0 + 0.01 * k + 2e-4, {"AZ": noise[k, 2]}) for k in range(50)]
    linear = read_can(_write(tmp_path / "linear.blf", still), OWN_DBC)
    assert linear.gravity_free.startswith("the acceleration's median magnitude is 0.1")


def test_a_left_handed_axis_map_is_a_statement_recorded_as_a_reflection(tmp_path: Path) -> None:
    """A reflection in the mapping states that the device's triad is left-handed (as --axes does): it is
    applied and recorded; whether the mapped axes are right-handed is checked where the data can tell."""
    path = _write(tmp_path / "mm5.blf", _mm5_messages(50))
    plain = read_can(path, OWN_DBC)
    mirrored = read_can(path, OWN_DBC, mapping={"axes": "y,x,z"})
    assert mirrored.axis_map == "y,x,z (a reflection: the device's own triad is left-handed)"
    np.testing.assert_array_equal(mirrored.acc_s, plain.acc_s[:, [1, 0, 2]])
    samples = read_can(path, OWN_DBC, mapping={"axes": "y,x,z", "allow_left_handed": "device triad is left-handed"})
    assert samples.axis_map == "y,x,z (a reflection: device triad is left-handed)"
    with pytest.raises(InputError, match=r"signed permutation"):
        read_can(path, OWN_DBC, mapping={"axes": "x,x,z"})


def test_extended_id_imu_with_validity_flag(tmp_path: Path) -> None:
    db = cantools.database.load_file(OWN_DBC)
    messages = []
    for k in range(100):
        values = {"ImuValid": 0 if k % 10 == 3 else 1, "AccX": 0.0, "AccY": 0.0, "AccZ": 1.0, "GyroX": 0.5}
        messages.append(_frame(db, "IMU_ACC_EXT", T0 + 0.01 * k, values))
    path = _write(tmp_path / "ext.blf", messages)
    spec = {"signals": {"ax": "IMU_ACC_EXT.AccX", "ay": "IMU_ACC_EXT.AccY", "az": "IMU_ACC_EXT.AccZ"}}
    samples = read_can(path, OWN_DBC, mapping=spec)  # validity auto-detected: ImuValid
    assert len(samples) == 90 and samples.dropped == {"IMU_ACC_EXT: ImuValid == 0": 10}
    np.testing.assert_allclose(samples.acc_s.mean(axis=0), [0.0, 0.0, G_N])
    kept = read_can(path, OWN_DBC, mapping={**spec, "valid": []})
    assert len(kept) == 100 and kept.dropped == {}


# --- bad input --------------------------------------------------------------------------------


@pytest.fixture
def mm5_blf(tmp_path: Path) -> Path:
    return _write(tmp_path / "mm5.blf", _mm5_messages(50))


def test_missing_signal_in_mapping(mm5_blf: Path) -> None:
    spec = {"signals": {"ax": "MM5_10_TX2.AXX", "ay": "MM5_10_TX1.AY1", "az": "MM5_10_TX3.AZ"}}
    with pytest.raises(InputError, match=r"signal 'AXX' in message MM5_10_TX2 for ax, found only Roll_Rate, AX1"):
        read_can(mm5_blf, OWN_DBC, mapping=spec)


def test_unit_that_is_not_acceleration(mm5_blf: Path) -> None:
    spec = {"signals": {"ax": "MM5_10_TX1.Yaw_Rate", "ay": "MM5_10_TX1.AY1", "az": "MM5_10_TX3.AZ"}}
    with pytest.raises(InputError, match=r"an acceleration unit \(m/s\^2 or g\) for ax, found 'deg/s'"):
        read_can(mm5_blf, OWN_DBC, mapping=spec)
    spec = {"units": {"accel": "km/h"}}
    with pytest.raises(InputError, match=r"found 'km/h' \(the mapping's units.accel\)"):
        read_can(mm5_blf, OWN_DBC, mapping=spec)


def test_mapping_errors(mm5_blf: Path, tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"unknown signals\.accel_x"):
        read_can(mm5_blf, OWN_DBC, mapping={"signals": {"accel_x": "a.b"}})
    with pytest.raises(InputError, match=r"signals ax, ay and az, found no az"):
        read_can(mm5_blf, OWN_DBC, mapping={"signals": {"ax": "MM5_10_TX2.AX1", "ay": "MM5_10_TX1.AY1"}})
    with pytest.raises(InputError, match=r"a DBC message 'NOPE' for az"):
        read_can(
            mm5_blf, OWN_DBC, mapping={"signals": {"ax": "MM5_10_TX2.AX1", "ay": "MM5_10_TX1.AY1", "az": "NOPE.AZ"}}
        )
    broken = tmp_path / "broken.toml"
    broken.write_text("[signals\nax = 1\n")
    with pytest.raises(InputError, match=r"broken\.toml: expected valid TOML"):
        read_can(mm5_blf, OWN_DBC, mapping=broken)
    with pytest.raises(InputError, match=r"axes as a signed permutation"):
        read_can(mm5_blf, OWN_DBC, mapping={"axes": "x,x,z"})


def test_missing_message_in_the_log(tmp_path: Path) -> None:
    messages = [m for m in _mm5_messages(50) if m.arbitration_id != 0x576]
    path = _write(tmp_path / "no_tx3.blf", messages)
    spec = {"signals": {"ax": "MM5_10_TX2.AX1", "ay": "MM5_10_TX1.AY1", "az": "MM5_10_TX3.AZ"}}
    with pytest.raises(
        InputError,
        match=r"expected frames of MM5_10_TX3 \(0x576\), found none; the log has 4 ids on channels 0 \(130 frames\); "
        r"the most frequent: 0x070 \(50\), 0x080 \(50\), 0x343 \(25\), 0x7DF \(5\)"
        r"\. Nearest ids to MM5_10_TX3's: 0x343",
    ):
        read_can(path, OWN_DBC, mapping=spec)


def test_a_message_sent_with_the_other_id_kind_is_named_with_the_placement_that_reads_it(tmp_path: Path) -> None:
    """The IMU's 0x576 sent as a 29-bit 0x00000576 (a gateway, a logger set to extended ids): the refusal
    listed the log's nearest 11-bit ids (0x343) and not the frames themselves; it names them and the
    mapping's [messages] placement, which then reads them."""
    messages = _mm5_messages(50)
    for m in messages:
        if m.arbitration_id == 0x576:
            m.is_extended_id = True
    path = _write(tmp_path / "tx3_extended.blf", messages)
    spec: dict[str, Any] = {"signals": {"ax": "MM5_10_TX2.AX1", "ay": "MM5_10_TX1.AY1", "az": "MM5_10_TX3.AZ"}}
    with pytest.raises(InputError) as err:
        read_can(path, OWN_DBC, mapping=spec)
    assert (
        "MM5_10_TX3's id is in the log as a 29-bit id, 0x00000576 (50 frames), where the DBC has an 11-bit 0x576"
        in str(err.value)
    )
    assert "[messages] MM5_10_TX3 = { id = 0x576, extended = true }" in str(err.value)
    placed = read_can(path, OWN_DBC, mapping={**spec, "messages": {"MM5_10_TX3": {"id": 0x576, "extended": True}}})
    np.testing.assert_allclose(placed.acc_s, _expected_acc(placed.t_s), atol=1e-3)


def test_wrong_dbc_lists_ids_seen_and_expected(tmp_path: Path) -> None:
    messages = [
        can.Message(timestamp=T0 + k * 0.01, arbitration_id=0x7E8 + k % 2, is_extended_id=False, data=b"\0" * 8)
        for k in range(20)
    ]
    path = _write(tmp_path / "obd.blf", messages)
    before = _digest(path)
    with pytest.raises(
        InputError,
        match=r"DBC \(\d+ messages: MM5_10_TX1 \(0x070\).*no frame of any of them; the log has 2 ids on channels 0 "
        r"\(20 frames\); the most frequent: 0x7E8 \(10\), 0x7E9 \(10\)",
    ):
        read_can(path, OWN_DBC)
    assert _digest(path) == before


def test_empty_log(tmp_path: Path) -> None:
    path = _write(tmp_path / "empty.blf", [])
    spec = {"signals": {"ax": "MM5_10_TX2.AX1", "ay": "MM5_10_TX1.AY1", "az": "MM5_10_TX3.AZ"}}
    with pytest.raises(InputError, match=r"empty\.blf: expected CAN frames, found an empty log"):
        read_can(path, OWN_DBC, mapping=spec)


def test_message_on_two_channels_needs_a_channel(tmp_path: Path) -> None:
    path = _write(tmp_path / "two.blf", _mm5_messages(30, channel=0) + _mm5_messages(30, channel=1))
    with pytest.raises(InputError, match=r"MM5_10_TX2 on one CAN channel, found it on channels 0, 1"):
        read_can(path, OWN_DBC)
    assert len(read_can(path, OWN_DBC, channel=1)) == 30


def test_inspect_names_messages_and_rates(mm5_blf: Path) -> None:
    summary = inspect_can(mm5_blf, OWN_DBC)
    assert summary.format == "blf" and summary.duration_s == pytest.approx(0.4902, abs=1e-5)
    streams = {s.name: s for s in summary.streams}
    assert streams["MM5_10_TX2"].count == 50 and streams["MM5_10_TX2"].rate_hz == pytest.approx(100.0)
    assert streams["MM5_10_TX2"].fields == ("Roll_Rate", "AX1") and streams["MM5_10_TX2"].kind == "can0"
    assert streams["MM5_10_TX2"].dlcs == (8,)
    assert streams["0x7DF"].count == 5 and streams["0x7DF"].fields == ()
    assert {s.name for s in inspect_can(mm5_blf).streams} == {"0x070", "0x080", "0x576", "0x343", "0x7DF"}


# --- CANedge: the real DBC and the real logs ---------------------------------------------------


def _canedge_messages(db: Any, n: int) -> list[can.Message]:
    """gnss_imu at 100 Hz on channel 2 (some frames invalid), GNSS at 1 Hz, OBD2 on channel 1."""
    imu = next(m for m in db.messages if m.frame_id == 9)
    messages = []
    for k in range(n):
        t = T0 + 0.01 * k
        values = {"ImuValid": 0 if k % 25 == 0 else 1, "AccelerationX": 9.75, "AccelerationY": -0.375,
                  "AccelerationZ": 0.875, "AngularRateX": 0.25, "AngularRateY": -0.5, "AngularRateZ": 1.0}  # fmt: skip
        data = imu.encode(values, strict=False)
        messages.append(can.Message(timestamp=t, arbitration_id=9, is_extended_id=False, data=data, channel=2))
        if k % 100 == 50:
            for msg_id, sig in ((7, {"SpeedValid": 1, "Speed": 12.5, "SpeedAccuracy": 0.1}),
                                (5, {"AttitudeValid": 1, "Roll": 0.0, "Pitch": 0.0, "Heading": 271.5,
                                     "RollAccuracy": 0.1, "PitchAccuracy": 0.1, "HeadingAccuracy": 0.1})):  # fmt: skip
                message = next(m for m in db.messages if m.frame_id == msg_id)
                data = message.encode(sig, strict=False)
                messages.append(
                    can.Message(timestamp=t + 1e-3, arbitration_id=msg_id, is_extended_id=False, data=data, channel=2)
                )
            messages.append(
                can.Message(timestamp=t + 2e-3, arbitration_id=0x7E8, is_extended_id=False, data=bytes(8), channel=1)
            )
    return messages


@pytest.mark.real_data
@pytest.mark.parametrize("fmt", ["blf", "mf4"])
def test_canedge_layout_with_the_real_dbc(real_data: Path, tmp_path: Path, fmt: str) -> None:
    dbc = real_data / CANEDGE / "dbc" / "gnss.dbc"  # defines gnss_imu twice (ids 9 and 25)
    path = _write(tmp_path / f"canedge.{fmt}", _canedge_messages(cantools.database.load_file(dbc), 1000))
    samples = read_can(path, dbc)
    assert len(samples) == 960 and samples.dropped == {"gnss_imu: ImuValid == 0": 40}
    np.testing.assert_allclose(samples.acc_s.mean(axis=0), [9.75, -0.375, 0.875])
    assert samples.gyro_s is not None
    np.testing.assert_allclose(np.degrees(samples.gyro_s.mean(axis=0)), [0.25, -0.5, 1.0])
    np.testing.assert_allclose(samples.channels["speed_mps"].value, 12.5)
    np.testing.assert_allclose(samples.channels["heading_deg"].value, 271.5)
    chunks = list(iter_can(path, dbc, max_samples=97))
    _assert_same_samples(_joined(chunks), samples)


@pytest.mark.real_data
def test_real_canedge_car_drive(real_data: Path) -> None:
    """The real drive: IMU on CAN 2, logger on its side (gravity on +X), ImuValid == 0 frames."""
    dbc = real_data / CANEDGE / "dbc" / "gnss.dbc"
    files = sorted((real_data / CANEDGE / "3BA199E2_car_DK_2021-07-26" / "00000165").glob("*.MF4"))
    assert len(files) == 6
    parts = [read_can(f, dbc) for f in files]
    acc = np.concatenate([p.acc_s for p in parts])
    assert acc.shape[0] > 250_000
    mean = acc.mean(axis=0)
    assert 9.4 < mean[0] < 10.0 and abs(mean[1]) < 1.0 and abs(mean[2]) < 1.5
    assert sum(p.dropped.get("gnss_imu: ImuValid == 0", 0) for p in parts) >= 1
    for part in parts:
        assert part.gyro_s is not None and {"speed_mps", "heading_deg"} <= part.channels.keys()
    speed = np.concatenate([p.channels["speed_mps"].value for p in parts])
    heading = np.concatenate([p.channels["heading_deg"].value for p in parts])
    assert 10.0 < speed.max() < 40.0 and speed.min() >= 0.0
    assert 0.0 <= heading.min() and heading.max() <= 360.0
    assert parts[1].t_s[0] > 1.6e9  # absolute time, as the logger recorded it


@pytest.mark.real_data
def test_real_canedge_streaming_equals_reading(real_data: Path) -> None:
    dbc = real_data / CANEDGE / "dbc" / "gnss.dbc"
    path = real_data / CANEDGE / "3BA199E2_car_DK_2021-07-26" / "00000165" / "00000002-60FEB8E3.MF4"
    _assert_same_samples(_joined(list(iter_can(path, dbc, max_samples=5000))), read_can(path, dbc))


@pytest.mark.real_data
@pytest.mark.parametrize("folder", ["2F6913DB_desk_static_2022-01-06", "94C49784_boat_static_nmea2000_2021-05-10"])
def test_real_canedge_desk_and_boat_open(real_data: Path, folder: str) -> None:
    dbc = real_data / CANEDGE / "dbc" / "gnss.dbc"
    path = next((real_data / CANEDGE / folder).glob("*.MF4"))
    summary = inspect_can(path, dbc)
    imu = next(s for s in summary.streams if s.name == "gnss_imu")
    assert summary.format == "mf4" and imu.kind == "can2" and 95.0 < imu.rate_hz < 110.0
    assert "AccelerationX" in imu.fields and any(s.kind == "can1" for s in summary.streams)
    samples = read_can(path, dbc)
    assert np.linalg.norm(samples.acc_s.mean(axis=0)) == pytest.approx(G_N, rel=0.1)


@pytest.mark.real_data
def test_the_documented_mapping_example_works(real_data: Path, tmp_path: Path) -> None:
    """The TOML example of the can_log module docstring, run against the real CANedge DBC."""
    import textwrap

    import mountcal.io.can.read as can_log

    lines = (can_log.__doc__ or "").split("::\n", 1)[1].splitlines()
    block = []
    for line in lines:  # the indented literal block after "::"
        if line and not line.startswith("    "):
            break
        block.append(line)
    mapping = tmp_path / "canedge.toml"
    mapping.write_text(textwrap.dedent("\n".join(block)))
    dbc = real_data / CANEDGE / "dbc" / "gnss.dbc"
    path = _write(tmp_path / "canedge.blf", _canedge_messages(cantools.database.load_file(dbc), 300))
    samples = read_can(path, dbc, mapping=mapping)
    assert samples.gyro_s is not None and set(samples.channels) == {"speed_mps", "heading_deg"}
    assert samples.dropped == {"gnss_imu: ImuValid == 0": 12}
