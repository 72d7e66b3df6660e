"""MF4 bus logs read by the file's own meaning, frame for frame as python-can's MF4Reader reads them.

CANedge firmware 01.07 and later writes one channel group per bus and id kind, with
``CAN_DataFrame.BusChannel`` and ``.IDE`` as 0-bit channels whose value is the constant of a linear
conversion (virtual data channels). :func:`_zero_bit_layout` turns a file written by python-can's MF4Writer (through the
simulator's writer, ``mountcal.io.writers.write_can_log``) into that layout: it points those two
channel blocks at new linear conversion blocks and makes them 0-bit virtual data channels (the bytes the records
still hold there are then meaningless, which is the point: a reader of raw values gets them wrong).
"""

from __future__ import annotations

import struct
from pathlib import Path

import can
import numpy as np
import pytest

from mountcal.io.can.files import read_frames
from mountcal.io.can.frames import CanFrames
from mountcal.io.writers import write_can_log
from mountcal.simulate.stops import simulate_parking_log

REPO = Path(__file__).resolve().parents[2]
DBC = REPO / "data" / "imu_mm5_10.dbc"
_CC_LINEAR = struct.Struct("<4s4xQQ4QBBHHH2d2d")  # ##CC, length, 4 links, type..val_count, range, P1, P2


def _zero_bit_layout(source: Path, target: Path, constants: list[tuple[int, int]]) -> Path:
    """Copy ``source`` with BusChannel and IDE of CAN group k as 0-bit channels of value constants[k]."""
    from asammdf import MDF

    mdf = MDF(source)
    try:
        groups = [g for g in mdf.groups if any(c.name == "CAN_DataFrame" for c in g.channels)]
        blocks = [
            {c.name.split(".")[-1]: int(c.address) for c in g.channels if c.name.startswith("CAN_DataFrame.")}
            for g in groups
        ]
    finally:
        mdf.close()
    assert len(blocks) == len(constants)
    data = bytearray(source.read_bytes())
    for fields, values in zip(blocks, constants, strict=True):
        for name, value in zip(("BusChannel", "IDE"), values, strict=True):
            data += b"\0" * (-len(data) % 8)
            cc = len(data)
            data += _CC_LINEAR.pack(b"##CC", _CC_LINEAR.size, 4, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0.0, 0.0, value, 0.0)
            cn = fields[name]
            (links,) = struct.unpack_from("<Q", data, cn + 16)
            struct.pack_into("<Q", data, cn + 24 + 4 * 8, cc)  # cn_cc_conversion
            body = cn + 24 + 8 * links
            data[body] = 6  # cn_type: virtual data channel, as CANedge writes them
            struct.pack_into("<II", data, body + 4, 0, 0)  # cn_byte_offset, cn_bit_count
    target.write_bytes(bytes(data))
    return target


def _python_can(path: Path) -> list[can.Message]:
    with can.LogReader(path) as reader:
        return [m for m in reader if not (m.is_error_frame or m.is_remote_frame)]


def _assert_same(frames: CanFrames, reference: list[can.Message]) -> None:
    """Time, channel, id, extended flag, DLC and data of every frame equal python-can's."""
    assert len(frames) == len(reference)
    np.testing.assert_array_equal(frames.t_s, [m.timestamp for m in reference])
    np.testing.assert_array_equal(frames.channel, [m.channel for m in reference])
    np.testing.assert_array_equal(frames.arbitration_id, [m.arbitration_id for m in reference])
    np.testing.assert_array_equal(frames.is_extended, [m.is_extended_id for m in reference])
    np.testing.assert_array_equal(frames.dlc, [m.dlc for m in reference])
    width = frames.data.shape[1]
    expected = np.zeros((len(reference), width), np.uint8)
    for k, message in enumerate(reference):
        expected[k, : len(message.data)] = np.frombuffer(bytes(message.data), np.uint8)
    np.testing.assert_array_equal(frames.data, expected)


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The simulator's MF4 (an IMU, 11-bit ids) and a J1939-like bus (29-bit ids) as two groups, in
    the classic layout and in the 0-bit layout (CAN 1 standard, CAN 2 extended)."""
    from asammdf import MDF

    folder = tmp_path_factory.mktemp("mf4")
    log = simulate_parking_log(beta_deg=(0.0, 120.0, 240.0), stop_s=6.0, drive_s=4.0, rate_hz=50.0, seed=3)
    imu = Path(write_can_log(folder / "imu.mf4", log, dbc_path=DBC, channel=0).path)
    start = float(MDF(imu).header.start_time.timestamp())
    rng = np.random.default_rng(5)
    messages = [
        can.Message(timestamp=start + 0.013 * i, arbitration_id=int(0x0CF00400 | rng.integers(0, 256)),
                    is_extended_id=True, data=bytes(rng.integers(0, 256, 8, dtype=np.uint8)), channel=0)
        for i in range(1500)
    ]  # fmt: skip
    bus = folder / "bus.mf4"
    with can.Logger(bus) as writer:
        for message in messages:
            writer.on_message_received(message)
    stacked = MDF.stack([imu, bus])
    classic = folder / "classic.mf4"
    stacked.save(classic, overwrite=True)
    stacked.close()
    return classic, _zero_bit_layout(classic, folder / "zero_bit.mf4", [(1, 0), (2, 1)])


def test_simulated_mf4_reads_as_python_can_in_both_layouts(simulated: tuple[Path, Path]) -> None:
    classic, zero_bit = simulated
    for path in simulated:
        _assert_same(read_frames(path), _python_can(path))
    old, new = read_frames(classic), read_frames(zero_bit)
    # the 0-bit layout carries its channel and id kind in the conversion, not in the record bytes
    assert set(old.channel.tolist()) == {0} and set(new.channel.tolist()) == {1, 2}
    np.testing.assert_array_equal(new.is_extended, new.channel == 2)
    np.testing.assert_array_equal(new.is_extended, old.is_extended)
    assert len(read_frames(zero_bit, channel=2)) == int(new.is_extended.sum()) == 1500


REAL_MF4 = [
    "canedge/truck_j1939_fw01.07_0bit-channels/00000001.MF4",
    "canedge/2F6913DB_desk_static_2022-01-06/00000001.MF4",
    "canedge/94C49784_boat_static_nmea2000_2021-05-10/00000017-6099D010.MF4",
    *[f"canedge/3BA199E2_car_DK_2021-07-26/00000164/{name}" for name in (
        "00000001-60FE3F04.MF4", "00000002-60FE415D.MF4", "00000003-60FE43B2.MF4", "00000004-60FEB585.MF4",
        "00000005-60FEB5A8.MF4")],
    *[f"canedge/3BA199E2_car_DK_2021-07-26/00000165/{name}" for name in (
        "00000001-60FEB68B.MF4", "00000002-60FEB8E3.MF4", "00000003-60FEBB3B.MF4", "00000004-60FEBD93.MF4",
        "00000005-60FEBFEB.MF4", "00000006-60FFE42F.MF4")],
]  # fmt: skip


@pytest.mark.real_data
@pytest.mark.parametrize("name", REAL_MF4)
def test_every_real_mf4_reads_as_python_can(real_data: Path, name: str) -> None:
    path = real_data / name
    frames = read_frames(path)
    _assert_same(frames, _python_can(path))
    if "truck" in name:  # firmware 01.07: J1939 on CAN 1, 29-bit; a few frames on the logger's CAN 9
        assert set(frames.channel.tolist()) == {1, 9}
        assert frames.is_extended[frames.channel == 1].all() and not frames.is_extended[frames.channel == 9].any()


@pytest.mark.real_data
def test_the_real_mf4_list_is_complete(real_data: Path) -> None:
    found = sorted(str(p.relative_to(real_data)) for p in real_data.rglob("*") if p.suffix.lower() in (".mf4", ".mdf"))
    assert found == sorted(REAL_MF4)
