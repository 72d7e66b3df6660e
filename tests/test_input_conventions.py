"""The conventions of the inputs (issue 23, reproductions 2–4): every convention a number crosses into
mountcal with is stated, checked or inferred — and the result says which — or refused with the option
that states it. The tests change the *convention* (heading reference, axis sign, unit, direction),
not values inside it, and check that no confident wrong answer comes out."""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mountcal.apply.rotate_log import to_frame
from mountcal.calibration.fit import Options, calibrate
from mountcal.cli import main
from mountcal.core.errors import InputError
from mountcal.core.result import Calibration
from mountcal.io.input_conventions import GRAVITY, NOISE, parse_axes, parse_quantity
from mountcal.io.logs import iter_log, read_log
from mountcal.io.reader import LogOptions
from mountcal.io.samples import Channel, Samples
from mountcal.simulate.drive import simulate_drive
from mountcal.simulate.stops import simulate_parking_log, simulate_stops
from mountcal.stops.table import read_stop_table, write_stop_table

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "data"
CAN = ["--dbc", str(DATA / "imu_mm5_10.dbc"), "--mapping", str(DATA / "imu_mm5_10.toml")]


def _result(path: Path) -> dict:  # type: ignore[type-arg]
    return json.loads(path.read_text(encoding="utf-8"))


def _check(doc: dict, name: str) -> dict:  # type: ignore[type-arg]
    return next(c for c in doc["checks"] if c["name"] == name)


def _convention(doc: dict, name: str) -> dict:  # type: ignore[type-arg]
    return next(c for c in doc["provenance"]["conventions"] if c["name"] == name)


# --------------------------------------------------------------------------- reproduction 2: heading reference


def test_stops_without_a_protocol_write_relative_headings_that_calibrate_reads_as_relative(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Repro 2: `stops` without a protocol wrote relative β unmarked; calibrate read them as from uphill
    (yaw 36.999° ± 0.581°, confident; the truth is 7°)."""
    stops = tmp_path / "s.csv"
    assert main(["stops", str(DATA / "parking.blf"), *CAN, "-o", str(stops)]) == 0
    assert set(pd.read_csv(stops)["heading_ref"]) == {"relative"}
    out = tmp_path / "r.json"
    assert main(["calibrate", str(stops), "-o", str(out)]) == 0
    doc = _result(out)
    assert doc["mounting"]["yaw_deg"] is None and "relative" in doc["yaw"]["reason"]
    assert _convention(doc, "heading_reference") == {
        "name": "heading_reference",
        "value": "relative",
        "how": "stated",
        "by": "the table's column heading_ref",
    }
    assert "input heading_reference: relative (stated by the table's column heading_ref)" in capsys.readouterr().err
    # the compass column and the slope's uphill azimuth make them uphill: the truth again
    assert main(["calibrate", str(stops), "--uphill-azimuth-deg", "30", "-o", str(out)]) == 0
    doc = _result(out)
    assert doc["mounting"]["yaw_deg"] == pytest.approx(7.0, abs=0.1) and doc["confident"]
    assert _convention(doc, "uphill_azimuth")["value"] == "30"


def test_a_relative_table_called_uphill_is_refused_naming_the_column(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    table, _ = simulate_stops(headings="relative", heading_offset_deg=30.0, seed=1)
    path = tmp_path / "s.csv"
    write_stop_table(table, path)
    assert main(["calibrate", str(path), "--headings", "uphill"]) == 2
    err = capsys.readouterr().err
    assert "heading_ref" in err and "--uphill-azimuth-deg" in err
    # saying less than the table is allowed: nothing is invented
    assert main(["calibrate", str(path), "--headings", "none", "-o", str(tmp_path / "r.json")]) == 0
    assert _result(tmp_path / "r.json")["mounting"]["yaw_deg"] is None


def test_a_table_edited_into_two_references_is_refused(tmp_path: Path) -> None:
    table, _ = simulate_stops(seed=2)
    df = table.to_frame()
    df.loc[3, "heading_ref"] = "relative"
    path = tmp_path / "s.csv"
    df.to_csv(path, index=False)
    with pytest.raises(InputError, match="one value in the column heading_ref"):
        read_stop_table(path)


def test_an_old_table_without_the_marker_is_read_as_uphill_and_says_it_was_assumed(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    table, _ = simulate_stops(seed=3)
    path = tmp_path / "old.csv"
    table.to_frame().drop(columns=["heading_ref"]).to_csv(path, index=False)
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "-o", str(out)]) == 0
    doc = _result(out)
    assert doc["mounting"]["yaw_deg"] == pytest.approx(7.0, abs=1.0)
    stated = _convention(doc, "heading_reference")
    assert stated["how"] == "default" and "heading_ref" in stated["by"]
    assert "input heading_reference: uphill (assumed:" in capsys.readouterr().err


def _same_answer(a: Calibration, b: Calibration) -> None:
    assert (a.yaw_deg is None) == (b.yaw_deg is None)
    for key in ("roll_deg", "pitch_deg", "yaw_deg", "slope_deg"):
        x, y = getattr(a, key), getattr(b, key)
        assert (x is None and y is None) or x == pytest.approx(y, abs=1e-7), key
    assert a.confident == b.confident


@settings(max_examples=12)
@given(
    headings=st.sampled_from(["uphill", "relative", "none"]),
    offset=st.floats(0.0, 359.0),
    seed=st.integers(0, 1000),
    suffix=st.sampled_from([".csv", ".parquet"]),
)
def test_every_stop_table_written_reads_back_to_the_same_answer(
    tmp_path_factory: pytest.TempPathFactory, headings: str, offset: float, seed: int, suffix: str
) -> None:
    """Round trip over the writer every command uses (simulate, stops, live): the same headings, the same answer."""
    table, _ = simulate_stops(headings=headings, heading_offset_deg=offset, seed=seed)  # type: ignore[arg-type]
    path = tmp_path_factory.mktemp("rt") / f"s{suffix}"
    write_stop_table(table, path)
    again = read_stop_table(path)
    assert again.headings == table.headings
    _same_answer(calibrate(table), calibrate(again))


@pytest.mark.parametrize(
    ("log_args", "headings"),
    [
        ([], "relative"),
        (["--protocol", str(DATA / "parking_protocol.csv")], "uphill"),
        (["--uphill-azimuth-deg", "30"], "uphill"),
    ],
)
def test_the_stop_table_of_a_log_reads_back_to_the_log_s_answer(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], log_args: list[str], headings: str
) -> None:
    """`calibrate LOG` and `calibrate $(stops LOG)` agree, whatever the headings' source and the table's format."""
    direct = tmp_path / "direct.json"
    assert main(["calibrate", str(DATA / "parking.mcap"), *log_args, "-o", str(direct)]) == 0
    for name in ("s.csv", "s.parquet"):
        table = tmp_path / name
        assert main(["stops", str(DATA / "parking.mcap"), *log_args, "-o", str(table)]) == 0
        via = tmp_path / f"{name}.json"
        assert main(["calibrate", str(table), "-o", str(via)]) == 0
        a, b = Calibration.load(direct), Calibration.load(via)
        assert b.fit.headings == headings
        _same_answer(a, b)
    capsys.readouterr()
    assert main(["stops", str(DATA / "parking.mcap"), *log_args, "-o", "-"]) == 0  # the CSV on stdout
    piped = tmp_path / "piped.csv"
    piped.write_text(capsys.readouterr().out, encoding="utf-8")
    _same_answer(Calibration.load(direct), calibrate(read_stop_table(piped)))


# --------------------------------------------------------------------------- reproduction 3: handedness


def _mirrored_table(seed: int = 4):  # type: ignore[no-untyped-def]
    table, truth = simulate_stops(12.0, -4.0, 33.0, slope_deg=7.0, noise_g=0.002, seed=seed)
    return dataclasses.replace(table, acc_s=table.acc_s * np.array([1.0, -1.0, 1.0])), truth


@pytest.mark.parametrize("headings", ["uphill", "relative"])
def test_a_mirrored_stop_table_is_refused_naming_the_axis_map(headings: str) -> None:
    """Repro 3: one axis negated makes a left-handed triad; with headings the stops go round the wrong way."""
    table, _ = _mirrored_table()
    table = dataclasses.replace(table, headings=headings)  # type: ignore[arg-type]
    with pytest.raises(InputError, match=r"--axes|axes=") as err:
        calibrate(table)
    assert "left-handed" in str(err.value)


def test_the_axis_map_makes_a_mirrored_table_right_handed(tmp_path: Path) -> None:
    table, truth = _mirrored_table()
    path = tmp_path / "mirrored.csv"
    write_stop_table(table, path)
    assert main(["calibrate", str(path)]) == 2
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "--axes", "x,-y,z", "-o", str(out)]) == 0
    doc = _result(out)
    roll, pitch, yaw = truth.angles_deg
    assert doc["confident"] and _check(doc, "handedness_stops")["passed"] is True
    for key, value in (("roll_deg", roll), ("pitch_deg", pitch), ("yaw_deg", yaw)):
        assert doc["mounting"][key] == pytest.approx(value, abs=1.0)
    axes = _convention(doc, "axes")
    assert axes["how"] == "stated" and axes["value"].startswith("x,-y,z (a reflection")


def test_a_mirrored_log_is_refused_and_the_axis_map_is_applied_to_every_reader(tmp_path: Path) -> None:
    """--axes is applied where logs are read (any format); a map that leaves the triad left-handed is refused."""
    protocol = ["--protocol", str(DATA / "parking_protocol.csv")]
    for log, extra in ((DATA / "parking.mcap", []), (DATA / "parking.blf", CAN)):
        assert main(["calibrate", str(log), *extra, *protocol, "--axes", "x,-y,z"]) == 2
    plain, turned = tmp_path / "plain.json", tmp_path / "turned.json"
    assert main(["calibrate", str(DATA / "parking.mcap"), *protocol, "-o", str(plain)]) == 0
    assert main(["calibrate", str(DATA / "parking.mcap"), *protocol, "--axes", "-y,x,z", "-o", str(turned)]) == 0
    a, b = Calibration.load(plain), Calibration.load(turned)  # a right-handed map (a turn): the same vehicle frame
    back = b.rot_vs * Rotation.from_matrix(parse_axes("-y,x,z").matrix)
    assert np.degrees((back * a.rot_vs.inv()).magnitude()) < 0.05 and b.confident
    assert next(c for c in b.provenance.conventions if c.name == "axes").value == "-y,x,z"


@settings(max_examples=10)
@given(perm=st.permutations([0, 1, 2]), signs=st.lists(st.sampled_from([1.0, -1.0]), min_size=3, max_size=3))
def test_any_signed_permutation_is_applied_alike_whole_and_streamed(perm: list[int], signs: list[float]) -> None:
    text = ",".join(("-" if s < 0 else "") + "xyz"[j] for j, s in zip(perm, signs, strict=True))
    plain = read_log(DATA / "parking.mcap")
    mapped = read_log(DATA / "parking.mcap", LogOptions(axes=text))
    expected = plain.acc_s[:, perm] * np.array(signs)
    np.testing.assert_array_equal(mapped.acc_s, expected)
    assert plain.gyro_s is not None and mapped.gyro_s is not None
    np.testing.assert_array_equal(mapped.gyro_s, plain.gyro_s[:, perm] * np.array(signs))
    streamed = np.concatenate([c.acc_s for c in iter_log(DATA / "parking.mcap", LogOptions(axes=text))])
    np.testing.assert_array_equal(streamed, expected)
    assert parse_axes(text).reflection == (np.prod(signs) * _parity(perm) < 0)


def _parity(perm: list[int]) -> float:
    return float(np.linalg.det(np.eye(3)[perm]))


@pytest.fixture(scope="module")
def drive():  # type: ignore[no-untyped-def]
    return simulate_drive(roll_deg=5.0, pitch_deg=6.0, yaw_deg=7.0, duration_s=600.0, seed=8)


def _write(samples: Samples, path: Path) -> Path:
    to_frame(samples).to_parquet(path, index=False)
    return path


def test_a_mirrored_drive_is_refused_naming_the_axis_map(tmp_path: Path, drive, capsys) -> None:  # type: ignore[no-untyped-def]
    """Repro 3: driving-only calibration of a mirrored sensor came back confident, a left/right mirror image."""
    s = drive.to_samples(heading=True)
    flip = np.array([1.0, -1.0, 1.0])  # a device that reports y negated (NovAtel RAWIMU): accel and gyro
    mirrored = _write(dataclasses.replace(s, acc_s=s.acc_s * flip, gyro_s=s.gyro_s * flip), tmp_path / "m.parquet")
    assert main(["calibrate", str(mirrored), "--use", "driving"]) == 2
    err = capsys.readouterr().err
    assert "--axes" in err and "r = -" in err
    out = tmp_path / "r.json"
    assert main(["calibrate", str(mirrored), "--use", "driving", "--axes", "x,-y,z", "-o", str(out)]) == 0
    doc = _result(out)
    assert doc["mounting"]["yaw_deg"] == pytest.approx(7.0, abs=0.5)
    assert _check(doc, "handedness_turns")["passed"] is True


def test_an_accelerometer_mirrored_against_its_gyro_is_refused(tmp_path: Path, drive, capsys) -> None:  # type: ignore[no-untyped-def]
    """A DBC sign on the accelerometer's vertical axis alone: the gyro's yaw rate about the fitted up axis
    turns against the heading (r ≈ +1 between heading rate and rotated yaw rate in the report's words)."""
    s = drive.to_samples(heading=True)
    bad = _write(dataclasses.replace(s, acc_s=s.acc_s * np.array([1.0, 1.0, -1.0])), tmp_path / "z.parquet")
    assert main(["calibrate", str(bad), "--use", "driving"]) == 2
    assert "heading" in capsys.readouterr().err


def test_a_right_handed_drive_passes_the_turn_check(tmp_path: Path, drive) -> None:  # type: ignore[no-untyped-def]
    out = tmp_path / "r.json"
    assert main(["calibrate", str(_write(drive.to_samples(heading=True), tmp_path / "d.parquet")), "-o", str(out)]) == 0
    check = _check(_result(out), "handedness_turns")
    assert check["passed"] is True and "r = +" in check["reason"]


@pytest.mark.real_data
def test_a_real_drive_mirrored_by_an_axis_map_is_refused(real_data: Path, tmp_path: Path, capsys) -> None:  # type: ignore[no-untyped-def]
    """The CANedge car (logger on its side, GNSS heading, OBD speed): its cues agree as logged; reversing one
    axis (any one) makes them disagree, and driving-only calibration is refused instead of a mirror image."""
    car = real_data / "canedge" / "3BA199E2_car_DK_2021-07-26" / "00000164"
    files = [str(p) for p in sorted(car.glob("*.MF4"))]
    log = [*files, "--dbc", str(real_data / "canedge" / "dbc" / "gnss.dbc"), "--channel", "2", "--use", "driving"]
    out = tmp_path / "r.json"
    assert main(["calibrate", *log, "-o", str(out)]) == 0
    check = _check(_result(out), "handedness_turns")
    assert check["passed"] is True and check["reason"].count("r = +0.9") == 3
    for axes in ("x,-y,z", "-x,y,z"):
        assert main(["calibrate", *log, "--axes", axes]) == 2
        assert "--axes" in capsys.readouterr().err


@pytest.mark.real_data
def test_a_straight_real_drive_is_not_tested_rather_than_guessed(real_data: Path, tmp_path: Path) -> None:
    """comma2k19's minute of highway barely turns (under 1°/s): the cues are not compared, not guessed."""
    segment = real_data / "comma2k19" / "rav4_2018-08-02--08-34-47_seg40"
    out = tmp_path / "r.json"
    assert main(["calibrate", str(segment), "--use", "driving", "-o", str(out)]) == 0
    assert _check(_result(out), "handedness_turns")["passed"] is None


# --------------------------------------------------------------------------- reproduction 4: directions and units


def _parking_and_drive(drive) -> Samples:  # type: ignore[no-untyped-def]
    """A parking session on a 5° slope (uphill azimuth 30°) and then a drive, one log, with heading and speed."""
    park = simulate_parking_log(5.0, 6.0, 7.0, seed=9)
    d = drive.to_samples(heading=True)
    t0 = park.t_s[-1] + 10.0
    cat = np.concatenate
    speed = Channel(
        cat([park.t_s, d.channels["speed_mps"].t_s + t0]), cat([park.speed_mps, d.channels["speed_mps"].value])
    )
    heading = Channel(cat([park.t_s, d.t_s + t0]), cat([park.heading_deg, d.channels["heading_deg"].value]))
    assert d.gyro_s is not None
    return Samples(
        cat([park.t_s, d.t_s + t0]),
        cat([park.acc_s, d.acc_s]),
        cat([park.gyro_s, d.gyro_s]),
        {"speed_mps": speed, "heading_deg": heading},
        source="<parking and drive>",
    )


def test_an_uphill_azimuth_given_downhill_is_a_finding_that_names_it(tmp_path: Path, drive) -> None:  # type: ignore[no-untyped-def]
    """Repro 4: an uphill azimuth given as the downhill direction was confident, yaw 180° off, although a
    drive with speed could tell."""
    log = _write(_parking_and_drive(drive), tmp_path / "log.parquet")
    detection = ["--min-stop-s", "25"]  # the parking stops (36 s), not the drive's waits at junctions
    out = tmp_path / "r.json"
    assert main(["calibrate", str(log), "--uphill-azimuth-deg", "210", *detection, "-o", str(out)]) == 0
    doc = _result(out)
    assert not doc["confident"]
    check = _check(doc, "stops_vs_driving_direction")
    assert check["passed"] is False and "--uphill-azimuth-deg 30" in check["reason"]
    assert any(u["test"] == "stops_vs_driving_direction" for u in doc["unexplained"])
    assert not any("backwards" in n for n in doc["notes"])  # the drive settled the direction: no doubt left open
    stops_only = ["--use", "stops", "-o", str(out)]
    assert main(["calibrate", str(log), "--uphill-azimuth-deg", "210", *detection, *stops_only]) == 0
    doc = _result(out)  # the stops alone: a sensor facing backwards, or the azimuth downhill
    assert any("backwards" in n and "downhill" in n for n in doc["notes"])
    # and the drive's turns, compared with that yaw, run backwards and mirrored: a half turn, not a mirror image
    # (this was refused as a left-handed sensor, naming --axes x,-y,z)
    assert not doc["confident"] and "half a turn off" in _check(doc, "handedness_turns")["reason"]
    assert main(["calibrate", str(log), "--uphill-azimuth-deg", "30", *detection, "-o", str(out)]) == 0
    doc = _result(out)
    assert _check(doc, "stops_vs_driving_direction")["passed"] is True
    assert doc["mounting"]["yaw_deg"] == pytest.approx(7.0, abs=0.5)


def test_headings_in_radians_are_refused_naming_the_option_or_converted_when_stated(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Repro 4: β in radians exited 0 (roll ± 17 300°, "slope 88.5° too small to determine yaw")."""
    df = pd.read_csv(DATA / "zhang2011_stops.csv")
    df["beta_deg"] = np.radians(df["beta_deg"])
    table = tmp_path / "rad.csv"
    df.to_csv(table, index=False)
    assert main(["calibrate", str(table)]) == 2
    assert "--heading-unit rad" in capsys.readouterr().err
    out = tmp_path / "r.json"
    assert main(["calibrate", str(table), "--heading-unit", "rad", "-o", str(out)]) == 0
    doc = _result(out)
    assert doc["mounting"]["yaw_deg"] == pytest.approx(7.0, abs=1.0) and doc["confident"]
    assert _convention(doc, "heading_unit") == {
        "name": "heading_unit",
        "value": "rad",
        "how": "stated",
        "by": "--heading-unit rad",
    }
    sheet = pd.read_csv(DATA / "parking_protocol.csv")
    sheet["beta_deg"] = np.radians(sheet["beta_deg"])
    protocol = tmp_path / "protocol_rad.csv"
    sheet.to_csv(protocol, index=False)
    assert main(["calibrate", str(DATA / "parking.mcap"), "--protocol", str(protocol)]) == 2
    assert "--heading-unit rad" in capsys.readouterr().err
    assert main(["calibrate", str(DATA / "parking.mcap"), "--protocol", str(protocol), "--heading-unit", "rad"]) == 0


def test_a_heading_channel_in_radians_is_refused(tmp_path: Path, drive, capsys) -> None:  # type: ignore[no-untyped-def]
    s = drive.to_samples(heading=True)
    h = s.channels["heading_deg"]
    rad = dataclasses.replace(s, channels={**s.channels, "heading_deg": Channel(h.t_s, np.radians(h.value))})
    log = _write(rad, tmp_path / "rad.parquet")
    assert main(["calibrate", str(log), "--use", "driving"]) == 2
    assert "--heading-unit rad" in capsys.readouterr().err
    assert main(["calibrate", str(log), "--use", "driving", "--heading-unit", "rad"]) == 0


def test_gravity_in_g_is_refused_or_taken_with_its_unit(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Repro 4: --gravity 1 (g for m/s²) was accepted."""
    stops = str(DATA / "zhang2011_stops.csv")
    assert main(["calibrate", stops, "--gravity", "1"]) == 2
    assert "--gravity 1g" in capsys.readouterr().err
    out = tmp_path / "r.json"
    assert main(["calibrate", stops, "--gravity", "1g", "-o", str(out)]) == 0
    assert _result(out)["gravity"]["value_mps2"] == pytest.approx(9.80665)
    assert main(["calibrate", stops, "--gravity", "9.81", "-o", str(out)]) == 0
    assert _result(out)["gravity"]["value_mps2"] == pytest.approx(9.81)
    assert parse_quantity("9.80665m/s2", GRAVITY)[0] == pytest.approx(9.80665)
    with pytest.raises(InputError):
        calibrate(read_stop_table(stops), Options(gravity_mps2=1.0))  # the library refuses it too


def test_plan_noise_in_g_is_refused_or_taken_with_its_unit(capsys: pytest.CaptureFixture[str]) -> None:
    """Repro 4: plan --noise 0.005 (g for mg) was accepted."""
    target = ["plan", "--target", "roll=0.5,pitch=0.5", "--slope-deg", "5"]
    assert main([*target, "--noise", "0.005"]) == 2
    assert "--noise 0.005g" in capsys.readouterr().err
    outputs = set()
    for noise in ("5", "5mg", "0.005g", f"{0.005 * 9.80665!r}m/s2"):
        main([*target, "--noise", noise])
        outputs.add(capsys.readouterr().out)
    assert len(outputs) == 1
    assert parse_quantity("5", NOISE)[0] == pytest.approx(5.0)


def test_a_slope_no_vehicle_parks_on_is_not_confident_with_the_reason() -> None:
    """Repro 4: a slope of 55° was marked confident."""
    cal = calibrate(simulate_stops(slope_deg=55.0, seed=5)[0])
    check = next(c for c in cal.checks if c.name == "slope_range")
    assert check.passed is False and "30°" in check.reason and not cal.confident
    assert any("slope_range" in n for n in cal.notes)
    assert all(c.passed for c in calibrate(simulate_stops(slope_deg=20.0, seed=5)[0]).checks if c.name == "slope_range")


def test_an_exact_fit_is_not_confident_with_the_reason(tmp_path: Path) -> None:
    """Repro 4: χ² exactly 0 (copied or noise-free data) was marked confident."""
    path = tmp_path / "exact.csv"
    assert main(["simulate", "--noise-g", "0", "-o", str(path)]) == 0
    out = tmp_path / "r.json"
    assert main(["calibrate", str(path), "-o", str(out)]) == 0
    doc = _result(out)
    assert not doc["confident"] and _check(doc, "exact_fit")["passed"] is False


def test_noise_columns_in_another_unit_are_not_confident(tmp_path: Path) -> None:
    """sx, sy, sz left in m/s² while ax, ay, az are in g: the stated noise is 9.8× the scatter."""
    table, _ = simulate_stops(seed=6)
    df = table.to_frame()
    for c in ("ax", "ay", "az"):
        df[c] = df[c] / 9.80665
    path = tmp_path / "g.csv"
    df.to_csv(path, index=False)
    cal = calibrate(read_stop_table(path, unit="g"))
    assert not cal.confident and next(c for c in cal.checks if c.name == "noise_scale").passed is False


# --------------------------------------------------------------------------- the result


def test_a_log_s_result_holds_its_files_hashes_and_conventions(tmp_path: Path) -> None:
    import hashlib

    out = tmp_path / "r.json"
    assert (
        main(
            ["calibrate", str(DATA / "parking.mcap"), "--protocol", str(DATA / "parking_protocol.csv"), "-o", str(out)]
        )
        == 0
    )
    doc = _result(out)
    assert doc["provenance"]["input_sha256"] == [hashlib.sha256((DATA / "parking.mcap").read_bytes()).hexdigest()]
    names = {c["name"] for c in doc["provenance"]["conventions"]}
    assert {"axes", "heading_reference", "heading_unit", "gravity"} <= names
    assert all(c["passed"] is not False for c in doc["checks"]) and doc["confident"]


def test_old_result_files_without_checks_or_conventions_still_load(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    assert main(["calibrate", str(DATA / "zhang2011_stops.csv"), "-o", str(out)]) == 0
    doc = _result(out)
    del doc["checks"]
    del doc["provenance"]["conventions"]
    old = Calibration.from_dict(doc)
    assert old.checks == () and old.provenance.conventions == () and math.isfinite(old.roll_deg)


def test_every_refusal_of_a_convention_names_its_option() -> None:
    """The library spells the Python parameter, the CLI the flag (one table, mountcal.core.option_names)."""
    for bad in ("1", "0.5", "12"):
        with pytest.raises(InputError, match=re.escape("Options.gravity_mps2=")):
            parse_quantity(bad, GRAVITY)
    with pytest.raises(InputError, match=r"signed permutation"):
        parse_axes("x,y,y")


@pytest.mark.parametrize("suffix", [".parquet", ".mcap"])
def test_rotate_takes_the_axes_the_calibration_was_made_with_and_gives_the_same_vehicle_frame(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], suffix: str
) -> None:
    """Metamorphic: a right-handed axis map changes the sensor frame, not the vehicle-frame data."""
    log, protocol = str(DATA / "parking.mcap"), ["--protocol", str(DATA / "parking_protocol.csv")]
    plain, turned = tmp_path / "plain.json", tmp_path / "turned.json"
    assert main(["calibrate", log, *protocol, "-o", str(plain)]) == 0
    assert main(["calibrate", log, *protocol, "--axes", "-y,x,z", "-o", str(turned)]) == 0
    assert main(["rotate", log, "--calibration", str(turned), "-o", str(tmp_path / f"x{suffix}")]) == 2
    assert "--axes -y,x,z" in capsys.readouterr().err
    a, b = tmp_path / f"a{suffix}", tmp_path / f"b{suffix}"
    assert main(["rotate", log, "--calibration", str(plain), "-o", str(a)]) == 0
    assert main(["rotate", log, "--calibration", str(turned), "--axes", "-y,x,z", "-o", str(b)]) == 0
    if suffix == ".parquet":
        da, db = pd.read_parquet(a), pd.read_parquet(b)
        for c in ("ax", "ay", "az", "gx", "gy", "gz"):
            np.testing.assert_allclose(db[c], da[c], atol=2e-3, err_msg=c)  # the two fits agree to their noise
    else:
        va = read_log(a, LogOptions(topic="/imu/data/vehicle"))
        vb = read_log(b, LogOptions(topic="/imu/data/vehicle"))
        np.testing.assert_allclose(vb.acc_s, va.acc_s, atol=2e-3)


def test_the_table_slips_of_the_benchmark_end_right_not_confident_or_refused_naming_the_fix(tmp_path: Path) -> None:
    """One draw of benchmarks/convention_slips.py's stop-table slips (the long run is the benchmark)."""
    import sys

    sys.path.insert(0, str(REPO / "benchmarks"))
    import convention_slips as slips

    good = {"answered, right", "answered, not confident", "refused, names the fix"}
    for name, case in slips.table_slips(np.random.default_rng(7), tmp_path).items():
        outcome, detail = slips.run_case(case, tmp_path)
        if case.cannot_tell:
            assert outcome != "traceback", name
        else:
            assert outcome in good, f"{name}: {outcome} ({detail})"


def test_the_seam_slips_of_the_benchmark_end_right_not_confident_or_refused_naming_the_fix(tmp_path: Path) -> None:
    """One draw of benchmarks/convention_slips.py's seam slips: a time unit, a gyro's and a speed's unit, a sheet's
    clock, and mountcal's own outputs taken back in (rotated again, their calibration applied or exported, a triad)."""
    import sys

    sys.path.insert(0, str(REPO / "benchmarks"))
    import convention_slips as slips

    good = {"answered, right", "answered, not confident", "refused, names the fix"}
    cases = slips.seam_slips(np.random.default_rng(8), tmp_path)
    assert sum(case.refuse for case in cases.values()) >= 4
    for name, case in cases.items():
        outcome, detail = slips.run_case(case, tmp_path)
        assert outcome in good, f"{name}: {outcome} ({detail})"
        assert not case.refuse or outcome == "refused, names the fix", name


def test_two_readings_of_a_heading_that_turn_opposite_ways_are_not_confident() -> None:
    """β (counter-clockwise from uphill) and a compass heading (clockwise from north) must add up to one
    azimuth; a heading column that turns the other way (an ENU yaw) contradicts the protocol's β."""
    table, _ = simulate_stops(seed=11)
    beta = np.degrees(table.beta_rad)  # type: ignore[arg-type]
    right = calibrate(dataclasses.replace(table, heading_deg=(30.0 - beta) % 360.0))
    check = next(c for c in right.checks if c.name == "heading_directions")
    assert check.passed is True and "30.0°" in check.reason and right.confident
    wrong = calibrate(dataclasses.replace(table, heading_deg=(30.0 + beta) % 360.0))
    check = next(c for c in wrong.checks if c.name == "heading_directions")
    assert check.passed is False and not wrong.confident


def test_a_stop_table_s_axis_map_turns_its_means_and_covariances() -> None:
    table, _ = simulate_stops(seed=12)
    df = table.to_frame()
    mapped = read_stop_table_frame(df, "-y,x,z")
    p = parse_axes("-y,x,z").matrix
    np.testing.assert_allclose(mapped.acc_s, table.acc_s @ p.T)
    assert table.cov_s is not None and mapped.cov_s is not None
    np.testing.assert_allclose(mapped.cov_s, p @ table.cov_s @ p.T, rtol=1e-12)
    vehicle = calibrate(mapped).rot_vs * Rotation.from_matrix(p)  # a turned sensor: the same vehicle frame
    assert np.degrees((vehicle * calibrate(table).rot_vs.inv()).magnitude()) < 1e-6


def read_stop_table_frame(df: pd.DataFrame, axes: str):  # type: ignore[no-untyped-def]
    from mountcal.stops.table import stop_table_from_frame

    return stop_table_from_frame(df, axes=parse_axes(axes))


def test_a_stop_table_written_with_an_axis_map_says_so_and_rotate_asks_for_the_same(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log, protocol = str(DATA / "parking.mcap"), ["--protocol", str(DATA / "parking_protocol.csv")]
    table = tmp_path / "s.csv"
    assert main(["stops", log, *protocol, "--axes", "-y,x,z", "-o", str(table)]) == 0
    assert set(pd.read_csv(table)["axes"]) == {"-y,x,z"}
    result = tmp_path / "r.json"
    assert main(["calibrate", str(table), "-o", str(result)]) == 0  # not mapped a second time
    direct = tmp_path / "d.json"
    assert main(["calibrate", log, *protocol, "--axes", "-y,x,z", "-o", str(direct)]) == 0
    _same_answer(Calibration.load(result), Calibration.load(direct))
    assert main(["rotate", log, "--calibration", str(result), "-o", str(tmp_path / "v.parquet")]) == 2
    assert "--axes -y,x,z" in capsys.readouterr().err
    assert (
        main(["rotate", log, "--calibration", str(result), "--axes", "-y,x,z", "-o", str(tmp_path / "v.parquet")]) == 0
    )


def test_samples_read_outside_read_log_get_the_log_conventions_in_the_pipeline(tmp_path: Path) -> None:
    """The fleet reads a log's splits itself: the pipeline applies --axes to them all the same (once)."""
    from mountcal.calibration.pipeline import LogJob, calibrate_job
    from mountcal.io.registry import reader_for

    path = DATA / "parking.mcap"
    job = LogJob(paths=(str(path),), log=LogOptions(axes="-y,x,z"), protocol=str(DATA / "parking_protocol.csv"))
    raw = reader_for(path, job.log).read(path, job.log)
    given, read = calibrate_job(job, raw), calibrate_job(job)
    assert next(c for c in given.calibration.provenance.conventions if c.name == "axes").value == "-y,x,z"
    _same_answer(given.calibration, read.calibration)


def test_a_fleet_calibration_skips_only_the_provenance_hashes(tmp_path: Path) -> None:
    """A fleet keys its results by its own digest: its workers leave out the files' SHA-256, and nothing else."""
    import hashlib

    from mountcal.calibration.pipeline import LogJob, calibrate_job

    path = DATA / "parking.mcap"
    job = LogJob(paths=(str(path),), protocol=str(DATA / "parking_protocol.csv"))
    hashed, unhashed = calibrate_job(job), calibrate_job(job, hash_files=False)
    assert hashed.calibration.provenance.input_sha256 == (hashlib.sha256(path.read_bytes()).hexdigest(),)
    assert unhashed.calibration.provenance.input_sha256 == ()
    _same_answer(hashed.calibration, unhashed.calibration)
    assert unhashed.calibration.provenance.conventions == hashed.calibration.provenance.conventions


def test_the_uphill_azimuth_says_it_must_share_the_heading_channels_north(tmp_path: Path) -> None:
    """True and magnetic north differ by the declination, which the data cannot tell: said, not assumed silently."""
    table = tmp_path / "compass.csv"
    df = pd.read_csv(REPO / "data" / "zhang2011_stops.csv")
    df["heading_deg"] = (30.0 - df["beta_deg"]) % 360.0
    df.drop(columns=["beta_deg"]).to_csv(table, index=False)
    out = tmp_path / "r.json"
    assert main(["calibrate", str(table), "--uphill-azimuth-deg", "30", "-o", str(out)]) == 0
    said = json.loads(out.read_text())["provenance"]["conventions"]
    by = next(c for c in said if c["name"] == "uphill_azimuth")["by"]
    assert "same north" in by and "declination" in by, by
