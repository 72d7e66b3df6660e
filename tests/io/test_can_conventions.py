"""The conventions a CAN log's numbers cross into mountcal with, run through the command line: the unit a
DBC (or the mapping's ``[units]``) gives a signal, and the text encoding of the DBC that spells it. A unit
that gravity contradicts is refused naming what stated it and the fix, by every command, before anything
is written; a unit spelled right is read whatever the DBC's encoding."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from mountcal.cli import main

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "data"
MM5_FACTOR = "(0.000127465,-4.1768) [-4.1768|4.1765]"  # the MM5.10's accelerometer signals, in g


def _dbc(tmp_path: Path, name: str, factor: str, unit: str, encoding: str = "cp1252") -> Path:
    """data/imu_mm5_10.dbc with the accelerometer signals' factor and unit replaced (a real DBC's text)."""
    text = (DATA / "imu_mm5_10.dbc").read_text(encoding="cp1252")
    lines = []
    for line in text.splitlines(True):
        if re.match(r" SG_ (AX1|AY1|AZ) ", line):
            line = line.replace(MM5_FACTOR, factor).replace('"g"', f'"{unit}"')
        lines.append(line)
    path = tmp_path / name
    path.write_text("".join(lines), encoding=encoding)
    return path


def _log(tmp_path: Path) -> Path:
    """data/parking.blf (written by python-can's BLFWriter), copied: the frames stay as logged."""
    return Path(shutil.copy(DATA / "parking.blf", tmp_path / "parking.blf"))


def test_rotate_refuses_a_log_whose_dbc_says_g_for_signals_in_m_s2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The DBC gives the m/s² factor (×9.80665) but calls the unit g: every sample decodes 9.8 times too
    large. rotate wrote them (|a| ≈ 96 m/s² in the vehicle frame, exit 0): its own check only caught
    magnitudes below 0.3 g. The CAN reader now refuses, naming the DBC's unit and the one that fits."""
    g = 9.80665
    dbc = _dbc(tmp_path, "mps2_called_g.dbc", f"({0.000127465 * g:.9g},{-4.1768 * g:.9g}) [-40.96|40.96]", "g")
    log, cal, out = _log(tmp_path), tmp_path / "cal.json", tmp_path / "vehicle.csv"
    assert main(["calibrate", str(DATA / "zhang2011_stops.csv"), "-o", str(cal)]) == 0
    capsys.readouterr()
    assert main(["rotate", str(log), "--dbc", str(dbc), "--calibration", str(cal), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert not out.exists() and "Traceback" not in err
    assert "read in g (the DBC unit of MM5_10_TX2.AX1, MM5_10_TX1.AY1, MM5_10_TX3.AZ)" in err
    assert re.search(r"\(9\.8\d* g\)", err) and 'accel = "m/s^2"' in err


@pytest.mark.parametrize(
    ("factor", "unit", "fits"), [(MM5_FACTOR, "m/s^2", "g"), ("(0.127465,-4176.8) [-4176.8|4176.5]", "g", "mg")]
)
def test_stops_names_the_can_mapping_unit_that_fits_not_unit_g(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], factor: str, unit: str, fits: str
) -> None:
    """A DBC calling g signals m/s² (or the counts of mg signals g): `stops` and `calibrate` refused naming
    `--unit g`, which a CAN log refuses in turn ("Drop --unit"); a signal read 1000 times too large gave
    "no static reading in either unit". They name the mapping's [units] accel now, and with it the log
    calibrates to the simulated mounting (roll 5°, pitch 6°, yaw 7°)."""
    dbc = _dbc(tmp_path, "wrong_unit.dbc", factor, unit)
    log, stops = _log(tmp_path), tmp_path / "stops.csv"
    capsys.readouterr()
    assert main(["stops", str(log), "--dbc", str(dbc), "-o", str(stops)]) == 2
    err = capsys.readouterr().err
    assert not stops.exists() and "--unit" not in err and f'accel = "{fits}"' in err
    mapping = tmp_path / "mapping.toml"
    mapping.write_text((DATA / "imu_mm5_10.toml").read_text() + f'\n[units]\naccel = "{fits}"\n', encoding="utf-8")
    out = tmp_path / "result.json"
    protocol = ["--protocol", str(DATA / "parking_protocol.csv")]
    assert main(["calibrate", str(log), "--dbc", str(dbc), "--mapping", str(mapping), *protocol, "-o", str(out)]) == 0
    doc = json.loads(out.read_text(encoding="utf-8"))
    truth = {"roll_deg": 5.0, "pitch_deg": 6.0, "yaw_deg": 7.0}
    assert doc["confident"] and all(abs(doc["mounting"][k] - v) < 0.05 for k, v in truth.items())
    # the result says in which units the signals were read, and what stated them (it did not)
    units = next(c for c in doc["provenance"]["conventions"] if c["name"] == "can_units")
    assert units["value"].startswith(f"ax, ay, az: {fits}; gx, gy, gz: °/s;") and units["how"] == "stated"
    assert units["by"].startswith("the DBC's signal units, and the mapping's units.accel")


@pytest.mark.parametrize("bom", [False, True])
def test_a_utf8_dbc_with_degree_and_squared_units_reads_as_its_units_say(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], bom: bool
) -> None:
    """A DBC saved as UTF-8 (as tools of today write it; CSS Electronics' J1939 DBC is UTF-8) with the gyro
    in "°/s", the accelerometer in "m/s²" and the heading in "°": read as cp1252 (cantools' default), "°/s"
    became "Â°/s" and calibrate refused the gyro for a unit the DBC states plainly. The acceleration is
    re-encoded in m/s² by cantools (the same frames' values), so the answer must be the simulated one."""
    import can
    import cantools

    db = cantools.database.load_file(DATA / "imu_mm5_10.dbc")
    text = (DATA / "imu_mm5_10.dbc").read_text(encoding="cp1252")  # its gyro in "°/s"
    text = text.replace('"deg"', '"°"').replace(f'{MM5_FACTOR} "g"', '(0.00125,-40.96) [-40.96|40.95] "m/s²"')
    dbc = tmp_path / "utf8.dbc"
    dbc.write_bytes((b"\xef\xbb\xbf" if bom else b"") + text.encode("utf-8"))
    utf8 = cantools.database.load_string(text, database_format="dbc")
    log = tmp_path / "parking.blf"
    with can.BLFReader(str(DATA / "parking.blf")) as reader, can.BLFWriter(str(log)) as writer:
        for frame in reader:
            message = db.get_message_by_frame_id(frame.arbitration_id)
            values = message.decode(frame.data, decode_choices=False)
            if message.name.startswith("MM5_10"):
                values = {k: v * 9.80665 if k in ("AX1", "AY1", "AZ") else v for k, v in values.items()}
            frame.data = bytearray(utf8.get_message_by_name(message.name).encode(values, strict=False))
            writer.on_message_received(frame)
    out = tmp_path / "result.json"
    capsys.readouterr()
    argv = ["calibrate", str(log), "--dbc", str(dbc), "--mapping", str(DATA / "imu_mm5_10.toml")]
    assert main([*argv, "--protocol", str(DATA / "parking_protocol.csv"), "-o", str(out)]) == 0, capsys.readouterr().err
    doc = json.loads(out.read_text(encoding="utf-8"))
    truth = {"roll_deg": 5.0, "pitch_deg": 6.0, "yaw_deg": 7.0}
    assert doc["confident"] and all(abs(doc["mounting"][k] - v) < 0.05 for k, v in truth.items())


def test_an_auto_detected_heading_of_an_unknown_unit_is_said_to_be_left_out(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The heading found by its name, in a unit no table knows ("degrees true"), was left out without a
    word: the stops had no headings, --uphill-azimuth-deg went unused and yaw was undetermined. It is still
    left out (a unit is not guessed), but said, with the [units] entry that reads it; stated so, yaw is found."""
    text = (DATA / "imu_mm5_10.dbc").read_text(encoding="cp1252")
    text = re.sub(r'(SG_ Heading .*)"deg"', r'\1"degrees true"', text)
    dbc = tmp_path / "heading_degrees_true.dbc"
    dbc.write_text(text, encoding="cp1252")
    log, out = _log(tmp_path), tmp_path / "result.json"
    argv = ["calibrate", str(log), "--dbc", str(dbc), "--uphill-azimuth-deg", "30", "-o", str(out)]
    capsys.readouterr()
    assert main(argv) == 0
    err = capsys.readouterr().err
    assert "heading not read: SIM_GNSS_HEADING.Heading was found by its name, but its DBC unit 'degrees true'" in err
    assert json.loads(out.read_text(encoding="utf-8"))["mounting"]["yaw_deg"] is None
    mapping = tmp_path / "units.toml"
    mapping.write_text('[units]\nheading = "deg"\n', encoding="utf-8")
    assert main([*argv, "--mapping", str(mapping)]) == 0
    assert abs(json.loads(out.read_text(encoding="utf-8"))["mounting"]["yaw_deg"] - 7.0) < 0.05


def test_a_log_whose_clock_restarts_is_refused_where_it_steps_back(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """data/parking.blf rewritten by python-can with its second half restamped from the log's start (a logger
    whose clock restarted): its samples, put in time order, interleaved two stretches of the session, and
    calibrate answered "no parked period found … relax the stillness thresholds" (exit 3), an untrue reason.
    It is refused naming the step back. A step back of 1 s (a clock synchronised) is put in order, as before."""
    import can

    with can.BLFReader(str(DATA / "parking.blf")) as reader:
        frames = list(reader)
    half = len(frames) // 2
    t0, t_half = frames[0].timestamp, frames[half].timestamp
    argv = ["--dbc", str(DATA / "imu_mm5_10.dbc"), "--mapping", str(DATA / "imu_mm5_10.toml")]
    protocol = ["--protocol", str(DATA / "parking_protocol.csv")]
    for name, back in (("restart.blf", t_half - t0 - 0.001), ("synced.blf", 1.0)):
        log, out = tmp_path / name, tmp_path / f"{name}.json"
        with can.BLFWriter(str(log)) as writer:
            for k, frame in enumerate(frames):
                frame.timestamp -= back if k >= half else 0.0
                writer.on_message_received(frame)
                frame.timestamp += back if k >= half else 0.0
        capsys.readouterr()
        code = main(["calibrate", str(log), *argv, *protocol, "-o", str(out)])
        err = capsys.readouterr().err
        if name == "synced.blf":
            assert code == 0 and abs(json.loads(out.read_text(encoding="utf-8"))["mounting"]["roll_deg"] - 5.0) < 0.05
            continue
        assert code == 2 and not out.exists() and "Traceback" not in err
        assert f"{log}: expected sample times on one clock that runs forward" in err
        assert re.search(r"the clock stepping back by \d+\.\d s at sample \d+ \(t = 17145577\d\d\.\d+ s", err)
        assert "Split the log where its clock steps back" in err
