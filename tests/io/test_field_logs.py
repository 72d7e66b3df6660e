"""Field CAN logs: J1939 by PGN, several DBCs, a mapping that moves a message, inspect without a DBC,
errors that fit on a screen, overlapping files refused. References: cantools' own decoding and
python-can's readers; the J1939 DBC and the truck log are real (CSS Electronics, see
../shared/data/real/canedge/README.txt)."""

from __future__ import annotations

import shlex
import shutil
from pathlib import Path
from typing import Any

import can
import cantools
import numpy as np
import pandas as pd
import pytest
from cantools import j1939
from tests.test_doc_commands import collect, missing_lines

from mountcal.cli import main
from mountcal.core.errors import InputError
from mountcal.io.can.dbc import decode, load_dbcs, select_frames
from mountcal.io.can.files import read_frames
from mountcal.io.can.read import inspect_can, read_can
from mountcal.io.logs import iter_log, read_log
from mountcal.io.reader import LogOptions

REPO = Path(__file__).resolve().parents[2]
IMU_DBC = REPO / "tests" / "data" / "mm5_imu.dbc"
T0 = 1_650_000_000.0
G_N = 9.80665
TRUCK = Path("canedge/truck_j1939_fw01.07_0bit-channels/00000001.MF4")
J1939_DBC = Path("canedge/dbc/CSS-Electronics-SAE-J1939-DEMO.dbc")


def _write(path: Path, messages: list[can.Message]) -> Path:
    with can.Logger(path) as writer:
        for message in sorted(messages, key=lambda m: m.timestamp):
            writer.on_message_received(message)
    return path


def _vehicle_bus(j1939_dbc: Path, n: int, *, tx1_id: int = 0x70, t0: float = T0) -> list[can.Message]:
    """A Bosch MM5.10 at 100 Hz (its TX1 at ``tx1_id``) on a truck's J1939 bus, all on channel 1:
    CCVS1 (wheel speed) at 10 Hz sent from source address 00, not the DBC's FE."""
    imu, truck = cantools.database.load_file(IMU_DBC), cantools.database.load_file(j1939_dbc)
    ccvs1 = truck.get_message_by_name("CCVS1")
    messages = []
    for k in range(n):
        t = t0 + 0.01 * k
        for name, ident, dt, values in (
            ("MM5_10_TX1", tx1_id, 0.0, {"Yaw_Rate": 0.0, "AY1": 0.0}),
            ("MM5_10_TX2", 0x80, 1e-4, {"Roll_Rate": 0.0, "AX1": 0.1}),
            ("MM5_10_TX3", 0x576, 2e-4, {"AZ": 0.99}),
        ):
            data = imu.get_message_by_name(name).encode(values)
            messages.append(
                can.Message(timestamp=t + dt, arbitration_id=ident, is_extended_id=False, data=data, channel=1)
            )
        if k % 10 == 0:
            data = ccvs1.encode({"WheelBasedVehicleSpeed": 0.5 * k / 10})
            messages.append(
                can.Message(timestamp=t + 5e-3, arbitration_id=0x18FEF100, is_extended_id=True, data=data, channel=1)
            )
    return messages


@pytest.mark.real_data
def test_truck_eec1_engine_speed_decodes_as_cantools_with_pgn_matching(real_data: Path) -> None:
    db = load_dbcs(real_data / J1939_DBC)
    eec1 = db.get_message_by_name("EEC1")
    frames = read_frames(real_data / TRUCK)
    ours = decode(select_frames(frames, eec1), eec1, ["EngineSpeed"])["EngineSpeed"]
    # reference: python-can's reader, frames whose PGN is EEC1's, each decoded by cantools
    pgn = j1939.pgn_from_frame_id(eec1.frame_id)
    with can.LogReader(real_data / TRUCK) as reader:
        hits = [m for m in reader if m.is_extended_id and j1939.pgn_from_frame_id(m.arbitration_id) == pgn]
    expected = [db.decode_message(eec1.frame_id, bytes(m.data), decode_choices=False)["EngineSpeed"] for m in hits]
    assert len(hits) > 1000 and {m.arbitration_id for m in hits} == {0x0CF00400}  # source 00, not the DBC's FE
    np.testing.assert_array_equal(ours, expected)


@pytest.mark.real_data
def test_several_dbcs_and_a_message_moved_by_the_mapping(real_data: Path, tmp_path: Path) -> None:
    j1939_dbc = real_data / J1939_DBC
    path = _write(tmp_path / "truck.blf", _vehicle_bus(j1939_dbc, 300, tx1_id=0x174))
    mapping = {
        "signals": {
            "ax": "MM5_10_TX2.AX1",
            "ay": "MM5_10_TX1.AY1",
            "az": "MM5_10_TX3.AZ",
            "speed": "CCVS1.WheelBasedVehicleSpeed",
        },
        "messages": {"MM5_10_TX1": {"id": 0x174, "channel": 1}},
    }
    samples = read_can(path, [IMU_DBC, j1939_dbc], mapping=mapping)
    assert len(samples) == 300 and samples.dropped == {}
    np.testing.assert_allclose(samples.acc_s.mean(axis=0), [0.1 * G_N, 0.0, 0.99 * G_N], atol=2e-3)
    speed = samples.channels["speed_mps"]
    truck = cantools.database.load_file(j1939_dbc)
    with can.LogReader(path) as reader:
        expected = [
            truck.decode_message("CCVS1", bytes(m.data))["WheelBasedVehicleSpeed"] / 3.6
            for m in reader
            if m.arbitration_id == 0x18FEF100
        ]
    np.testing.assert_allclose(speed.value, expected, rtol=1e-12)
    # without the placement the message is not found, and the error points at the moved id's neighbours
    del mapping["messages"]
    with pytest.raises(InputError, match=r"frames of MM5_10_TX1 \(0x070\).*Nearest ids to MM5_10_TX1's: 0x080"):
        read_can(path, [IMU_DBC, j1939_dbc], mapping=mapping)


@pytest.mark.real_data
def test_a_pgn_from_two_senders_is_refused_until_one_is_placed(real_data: Path, tmp_path: Path) -> None:
    j1939_dbc = real_data / J1939_DBC
    messages = _vehicle_bus(j1939_dbc, 200)
    other = [m for m in messages if m.arbitration_id == 0x18FEF100]
    for m in other:  # a second sender (source address 0x17) of the same PGN, with other speeds
        data = bytes(m.data[:1]) + bytes([0xFF, 0x7F]) + bytes(m.data[3:])
        messages.append(can.Message(timestamp=m.timestamp + 1e-3, arbitration_id=0x18FEF117, data=data, channel=1))
    path = _write(tmp_path / "two_senders.blf", messages)
    signals = {"ax": "MM5_10_TX2.AX1", "ay": "MM5_10_TX1.AY1", "az": "MM5_10_TX3.AZ"}
    mapping: dict[str, Any] = {"signals": {**signals, "speed": "CCVS1.WheelBasedVehicleSpeed"}}
    with pytest.raises(
        InputError,
        match=r"CCVS1 \(J1939 PGN 0x0FEF1\) from one sender, found it from 2 ids: "
        r"0x18FEF100, 0x18FEF117",
    ):
        read_can(path, [IMU_DBC, j1939_dbc], mapping=mapping)
    mapping["messages"] = {"CCVS1": {"id": 0x18FEF100}}
    speed = read_can(path, [IMU_DBC, j1939_dbc], mapping=mapping).channels["speed_mps"]
    assert len(speed.value) == len(other) and speed.value.max() < 10.0  # only source 00's 0-4.5 km/h


def test_a_message_clash_between_dbcs_is_reported(tmp_path: Path) -> None:
    twin = shutil.copy(IMU_DBC, tmp_path / "twin.dbc")
    with pytest.raises(InputError, match=r"expected DBC files that define different messages, found message name"):
        load_dbcs([IMU_DBC, twin])
    path = _write(tmp_path / "x.blf", [can.Message(timestamp=T0, arbitration_id=0x70, data=bytes(8))])
    assert main(["stops", str(path), "--dbc", str(IMU_DBC), "--dbc", str(twin), "-o", str(tmp_path / "s.csv")]) == 2
    assert not (tmp_path / "s.csv").exists()


@pytest.mark.real_data
def test_a_pgn_clash_between_dbcs_is_reported(real_data: Path, tmp_path: Path) -> None:
    """The demo DBC's messages renamed and sent from source address 00: by PGN they are the same."""
    text = (real_data / J1939_DBC).read_text(encoding="cp1252")
    eec1_from_00 = 0x80000000 | 0x0CF00400  # the DBC's extended-id flag
    copy = text.replace("EEC1", "EEC1_ECU00").replace("CCVS1", "CCVS1_ECU00")
    copy = copy.replace(str(0x80000000 | 0x0CF004FE), str(eec1_from_00))
    (tmp_path / "ecu00.dbc").write_text(copy, encoding="cp1252")
    with pytest.raises(
        InputError, match=r"frame id 0x0CF00400 \(EEC1_ECU00 in .*ecu00\.dbc\) matches 0x0CF004FE \(EEC1 in"
    ):
        load_dbcs([real_data / J1939_DBC, tmp_path / "ecu00.dbc"])


@pytest.mark.real_data
def test_inspect_without_a_dbc_lists_ids_per_channel(real_data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    summary = inspect_can(real_data / TRUCK)
    streams = {(s.kind, s.name): s for s in summary.streams}
    eec1 = streams[("can1", "0x0CF00400")]
    with can.LogReader(real_data / TRUCK) as reader:
        times = [m.timestamp for m in reader if m.arbitration_id == 0x0CF00400 and m.channel == 1]
    assert eec1.count == len(times) and eec1.dlcs == (8,) and eec1.fields == ()
    assert eec1.rate_hz == pytest.approx((len(times) - 1) / (times[-1] - times[0]))
    assert {k for k, _ in streams} == {"can1", "can9"} and len(summary.streams) == 61 + 6
    assert main(["inspect", str(real_data / TRUCK)]) == 0
    out = capsys.readouterr().err  # the listing is the command's summary, on stderr
    assert "0x0CF00400" in out and "DLC 8" in out
    assert main(["inspect", str(real_data / TRUCK), "--dbc", str(real_data / J1939_DBC)]) == 0
    assert "EEC1" in capsys.readouterr().err


@pytest.mark.real_data
def test_errors_fit_on_a_screen(real_data: Path, capsys: pytest.CaptureFixture[str]) -> None:
    gnss = real_data / "canedge" / "dbc" / "canmod-gps.dbc"
    argv = ["stops", str(real_data / TRUCK), "--dbc", str(gnss), "-o", "/nonexistent/x.csv"]
    assert main([*argv, "--channel", "9"]) == 2
    err = capsys.readouterr().err
    assert len(err) < 2000 and "Traceback" not in err
    assert "channels 1 (139136 frames), 9 (11275 frames)" in err


def test_overlapping_files_are_refused(tmp_path: Path) -> None:
    first, second = _two_splits(tmp_path)
    options = LogOptions(dbc=str(IMU_DBC))
    assert len(read_log([first, second], options)) == 400  # consecutive splits join
    overlapping = _write(tmp_path / "other_logger.blf", _imu_only(200, T0 + 1.0))
    with pytest.raises(InputError, match=r"overlapping clocks: .*other_logger\.blf starts at"):
        read_log([first, overlapping], options)
    # rotate streams the files: refused too, and no output is left
    assert sum(len(c) for c in iter_log([second, first], options, 64)) == 400
    with pytest.raises(InputError, match=r"overlapping clocks: .*other_logger\.blf starts at t = "):
        list(iter_log([first, overlapping], options, 64))


def _imu_only(n: int, t0: float) -> list[can.Message]:
    imu = cantools.database.load_file(IMU_DBC)
    messages = []
    for k in range(n):
        t = t0 + 0.01 * k
        for name, values in (("MM5_10_TX1", {"AY1": 0.0}), ("MM5_10_TX2", {"AX1": 0.0}), ("MM5_10_TX3", {"AZ": 1.0})):
            message = imu.get_message_by_name(name)
            full = {s.name: values.get(s.name, 0.0) for s in message.signals}
            messages.append(
                can.Message(
                    timestamp=t, arbitration_id=message.frame_id, is_extended_id=False, data=message.encode(full)
                )
            )
    return messages


def _two_splits(tmp_path: Path) -> tuple[Path, Path]:
    """Two consecutive 2-s splits of one IMU log."""
    return (
        _write(tmp_path / "split1.blf", _imu_only(200, T0)),
        _write(tmp_path / "split2.blf", _imu_only(200, T0 + 2.0 + 0.005)),
    )


DOC = REPO / "docs" / "field-logs.md"


def _doc_commands() -> list[list[str]]:
    """The ``$ mountcal ...`` lines of docs/field-logs.md, as argument lists."""
    lines = DOC.read_text(encoding="utf-8").splitlines()
    return [shlex.split(line[len("$ mountcal ") :]) for line in lines if line.startswith("$ mountcal ")]


def _doc_mapping() -> str:
    text = DOC.read_text(encoding="utf-8")
    block = text.split("```toml\n", 1)[1].split("```", 1)[0]
    assert block.startswith("# mm5_on_truck.toml\n")
    return block


def _truck_with_mm5(path: Path, j1939_dbc: Path) -> Path:
    """An MM5.10 (data/imu_mm5_10.dbc, its TX1 at 0x174) on a truck's J1939 bus, channel 1: parked
    for 40 s (CCVS1 speed 0 from source address 00), then driving at 30 km/h for 20 s."""
    imu = cantools.database.load_file(REPO / "data" / "imu_mm5_10.dbc")
    ccvs1 = cantools.database.load_file(j1939_dbc).get_message_by_name("CCVS1")
    rng = np.random.default_rng(11)
    messages = []
    for k in range(6000):
        t = T0 + 0.01 * k
        g = np.array([0.05, -0.03, 0.998]) + rng.normal(0.0, 0.002, 3)
        for name, ident, dt, values in (
            ("MM5_10_TX1", 0x174, 0.0, {"AY1": g[1]}),
            ("MM5_10_TX2", 0x80, 1e-4, {"AX1": g[0]}),
            ("MM5_10_TX3", 0x576, 2e-4, {"AZ": g[2]}),
        ):
            message = imu.get_message_by_name(name)
            full = {s.name: values.get(s.name, 0.0) for s in message.signals}
            messages.append(
                can.Message(
                    timestamp=t + dt, arbitration_id=ident, is_extended_id=False, data=message.encode(full), channel=1
                )
            )
        if k % 10 == 0:
            data = ccvs1.encode({"WheelBasedVehicleSpeed": 0.0 if k < 4000 else 30.0})
            messages.append(
                can.Message(timestamp=t + 5e-3, arbitration_id=0x18FEF100, is_extended_id=True, data=data, channel=1)
            )
    return _write(path, messages)


@pytest.mark.real_data
def test_field_logs_doc_commands(
    real_data: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    (tmp_path / "canedge").symlink_to(real_data / "canedge")  # the doc's paths, without copying the logs
    (tmp_path / "data").symlink_to(REPO / "data")
    (tmp_path / "mm5_on_truck.toml").write_text(_doc_mapping(), encoding="utf-8")
    _truck_with_mm5(tmp_path / "truck_mm5.blf", real_data / J1939_DBC)
    monkeypatch.chdir(tmp_path)
    commands = _doc_commands()
    assert [c[0] for c in commands] == ["inspect", "inspect", "stops", "inspect", "inspect", "inspect", "stops"]
    outputs = []
    shown = [c.output for c in collect(DOC).commands]  # the lines the page shows under each command
    assert len(shown) == len(commands) and sum(map(len, shown)) >= 20
    for argv, lines in zip(commands, shown, strict=True):
        assert main(argv) == 0, argv
        printed = capsys.readouterr()
        gone = missing_lines(lines, printed.out + printed.err)
        assert not gone, (argv, gone)
        outputs.append(printed.err)  # each command's summary
    assert "0x0CF00400" in outputs[1] and "DLC 8" in outputs[1]
    assert "parked periods: 1 stops, 1 near misses" in outputs[3]  # the 11.6 s stop under a 15 s minimum
    assert "under the --min-stop-s of 15 s; --min-stop-s 11.6 would keep it" in outputs[3]
    assert "EEC1" in outputs[4] and "CCVS1" in outputs[4] and "WheelBasedVehicleSpeed" in outputs[4]
    assert "MM5_10_TX2" in outputs[5] and "CCVS1" in outputs[5] and "0x174" in outputs[5]
    assert len(pd.read_csv(tmp_path / "stops.csv")) >= 3  # the car parks several times
    truck_stops = pd.read_csv(tmp_path / "truck_stops.csv")
    assert len(truck_stops) == 1 and truck_stops["duration_s"].iloc[0] > 30.0
    # the IMU's mean specific force, read through the moved message, in m/s²
    np.testing.assert_allclose(
        truck_stops[["ax", "ay", "az"]].iloc[0], [0.05 * G_N, -0.03 * G_N, 0.998 * G_N], atol=0.01
    )
