"""Sensor Logger recordings (folder or zip) of one simulated parking session, written as the app writes them
on Android (TotalAcceleration.csv) and on iOS (Accelerometer.csv + Gravity.csv, negated with the app's
default "Standardise Units & Frames" off; as Android with it on), read as one log: the same mounting back,
the sign stated, inferred or assumed and said, and never a confident answer on a sign nothing confirmed."""

from __future__ import annotations

import json
import shlex
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from tests.conftest import Refused

from mountcal.cli import main
from mountcal.io.logs import read_log
from mountcal.simulate.stops import ParkingLog, simulate_parking_log

REPO = Path(__file__).resolve().parents[1]
T0_NS = 1_716_979_893_874_983_200  # 2024-05-29 10:51:33 UTC
G_N = 9.80665
GRAVITY_LAG = 5  # Gravity.csv starts 5 samples (and 7 ms) after Accelerometer.csv: aligned by time
NEGATIVE_SPEED_EVERY = 37  # every 37th Location row has speed −1 (invalid)


@pytest.fixture(scope="module")
def session() -> ParkingLog:
    """Six stops on a 5° slope, driven between with turns: roll 5°, pitch 6°, yaw 7°."""
    return simulate_parking_log(5.0, 6.0, 7.0, beta_deg=(0, 60, 120, 180, 240, 300), stop_s=20.0, drive_s=15.0,
                                rate_hz=50.0, seed=4)  # fmt: skip


def _ns(t: np.ndarray) -> np.ndarray:
    return T0_NS + np.round(t * 1e9).astype(np.int64)


def _vectors(path: Path, t: np.ndarray, v: np.ndarray) -> None:
    frame = {"time": _ns(t), "seconds_elapsed": t, "z": v[:, 2], "y": v[:, 1], "x": v[:, 0]}  # the app's order
    pd.DataFrame(frame).to_csv(path, index=False)


def record(
    folder: Path,
    log: ParkingLog,
    platform: str,
    *,
    standardised: bool = False,
    uncalibrated: str | None = None,
    motion: bool = True,
    metadata: dict[str, str] | None = None,
) -> Path:
    """``log`` written as Sensor Logger writes it on ``platform`` (Android, or iOS with the setting
    ``standardised`` on or off); ``uncalibrated`` "g" or "m/s2" adds AccelerometerUncalibrated.csv;
    ``motion`` False leaves out the gyro and the location (nothing to test handedness by)."""
    folder.mkdir(parents=True)
    t, acc = log.t_s, log.acc_s
    meta = {"version": "3", "device name": "phone", "recording time": "2024-05-29_10-51-33", "platform": platform}
    pd.DataFrame([meta | {"appVersion": "1.31.3", "sampleRateMs": "20"} | (metadata or {})]).to_csv(
        folder / "Metadata.csv", index=False
    )
    smooth = pd.DataFrame(acc).rolling(50, center=True, min_periods=1).mean().to_numpy()
    gravity = smooth / np.linalg.norm(smooth, axis=1, keepdims=True) * G_N  # the phone's gravity estimate
    sign = 1.0 if platform == "Android" or standardised else -1.0  # iOS's default logs the inertial force
    if platform == "Android":
        _vectors(folder / "TotalAcceleration.csv", t, acc)
    t_g = t[GRAVITY_LAG:] + 0.007
    on_g = np.column_stack([np.interp(t_g, t, gravity[:, k]) for k in range(3)])
    _vectors(folder / "Accelerometer.csv", t, sign * (acc - gravity))
    _vectors(folder / "Gravity.csv", t_g, sign * on_g)
    if uncalibrated is not None:
        _vectors(folder / "AccelerometerUncalibrated.csv", t, sign * acc / (G_N if uncalibrated == "g" else 1.0))
    if motion:
        _vectors(folder / "Gyroscope.csv", t + 0.003, log.gyro_s)
        i = np.arange(0, t.size, 50)  # 1 Hz
        speed = log.speed_mps[i].copy()
        bearing = np.where(speed < 0.3, -1.0, log.heading_deg[i] % 360.0)  # no course while parked
        speed[::NEGATIVE_SPEED_EVERY] = -1.0
        location = {"time": _ns(t[i]), "seconds_elapsed": t[i], "bearingAccuracy": 5.0, "speedAccuracy": 0.5}
        location |= {"speed": speed, "bearing": bearing, "altitude": 100.0, "longitude": 8.5, "latitude": 47.4}
        pd.DataFrame(location | {"horizontalAccuracy": 3.0}).to_csv(folder / "Location.csv", index=False)
    return folder


def zipped(folder: Path, path: Path | None = None) -> Path:
    path = folder.with_suffix(".zip") if path is None else path
    with zipfile.ZipFile(path, "w") as z:
        for f in sorted(folder.iterdir()):
            z.write(f, f.name)
    return path


def _protocol(log: ParkingLog, path: Path) -> Path:
    """The stops' times in Unix seconds (the recording's clock) with their β."""
    rows = [(a + T0_NS * 1e-9, b + T0_NS * 1e-9, beta) for a, b, beta in log.protocol]
    pd.DataFrame(rows, columns=["t_start_s", "t_end_s", "beta_deg"]).to_csv(path, index=False)
    return path


def _calibrate(path: Path, tmp_path: Path, *args: str) -> dict:  # type: ignore[type-arg]
    out = tmp_path / f"{path.name}.json"
    assert main(["calibrate", str(path), "-o", str(out), *args]) == 0
    return dict(json.loads(out.read_text()))


def _sign(doc: dict) -> dict:  # type: ignore[type-arg]
    return next(c for c in doc["provenance"]["conventions"] if c["name"] == "acceleration_sign")


def _check(doc: dict, name: str) -> dict:  # type: ignore[type-arg]
    return next(c for c in doc["checks"] if c["name"] == name)


def _assert_truth(doc: dict, log: ParkingLog, yaw: bool = True) -> None:  # type: ignore[type-arg]
    truth = dict(zip(("roll_deg", "pitch_deg", "yaw_deg"), log.truth.angles_deg, strict=True))
    for name in ("roll_deg", "pitch_deg", *(("yaw_deg",) if yaw else ())):
        assert doc["mounting"][name] == pytest.approx(truth[name], abs=doc["uncertainty"][name]), name


# --------------------------------------------------------------------------- the same mounting on both platforms


@pytest.mark.parametrize("as_zip", [False, True])
def test_android_and_ios_recordings_give_the_simulated_mounting(
    session: ParkingLog, tmp_path: Path, as_zip: bool
) -> None:
    sheet = _protocol(session, tmp_path / "protocol.csv")
    docs = {}
    for platform in ("Android", "iOS"):
        folder = record(tmp_path / platform, session, platform)
        docs[platform] = _calibrate(zipped(folder) if as_zip else folder, tmp_path, "--protocol", str(sheet))
        _assert_truth(docs[platform], session)
        assert docs[platform]["confident"]
    for name in ("roll_deg", "pitch_deg", "yaw_deg"):  # one mounting, whichever phone logged it
        assert docs["iOS"]["mounting"][name] == pytest.approx(docs["Android"]["mounting"][name], abs=0.05)
    android, ios = _sign(docs["Android"]), _sign(docs["iOS"])
    assert (android["how"], android["value"].split()[0]) == ("stated", "as") and "platform Android" in android["by"]
    assert (ios["how"], ios["value"].split()[0]) == ("inferred", "negated")  # the default, confirmed by the stops
    assert "the app's default" in ios["by"] and "confirmed by handedness_stops" in ios["by"]


@pytest.mark.parametrize("platform", ["Android", "iOS"])
def test_the_bearing_invalid_while_parked_gives_the_stops_the_course_before_them(
    session: ParkingLog, tmp_path: Path, platform: str
) -> None:
    """Location.csv's bearing is a course over ground: −1 while parked. With the uphill azimuth, each stop takes
    the course it was driven in by (said in the result), and yaw comes out as with a protocol sheet."""
    doc = _calibrate(record(tmp_path / platform, session, platform), tmp_path, "--uphill-azimuth-deg", "30")
    read = next(c for c in doc["provenance"]["conventions"] if c["name"] == "heading_at_stops")
    assert read["how"] == "inferred" and "empty at" in read["by"]
    _assert_truth(doc, session)


def test_ios_samples_are_the_specific_force_only_with_the_negation(session: ParkingLog, tmp_path: Path) -> None:
    """The negation is what makes iOS read right: the samples are the simulator's specific force (+g up)."""
    samples = read_log(record(tmp_path / "ios", session, "iOS"))
    expected = np.column_stack([np.interp(samples.t_s - T0_NS * 1e-9, session.t_s, session.acc_s[:, k]) for k in
                                range(3)])  # fmt: skip
    np.testing.assert_allclose(samples.acc_s, expected, atol=0.05)  # gravity interpolated across 7 ms
    up = session.truth.rot_vs.inv().apply([0.0, 0.0, 1.0])
    assert float(np.median(samples.acc_s @ up)) == pytest.approx(G_N, abs=0.1)  # naive (−) would give −g


def test_rows_outside_gravity_and_invalid_speeds_are_counted(session: ParkingLog, tmp_path: Path) -> None:
    samples = read_log(record(tmp_path / "ios", session, "iOS"))
    t_g0 = session.t_s[GRAVITY_LAG] + 0.007
    assert samples.dropped["accelerometer rows outside Gravity.csv's span"] == int((session.t_s < t_g0).sum())
    rows = np.arange(0, session.t_s.size, 50).size
    negative = np.arange(0, rows, NEGATIVE_SPEED_EVERY).size
    assert any(f"{negative} of {rows} rows with a negative speed" in n for n in samples.notes)
    assert len(samples.channels["speed_mps"].t_s) == rows - negative
    assert (samples.channels["speed_mps"].value >= 0).all() and (samples.channels["heading_deg"].value >= 0).all()
    assert samples.t_s[0] == pytest.approx(T0_NS * 1e-9 + t_g0, abs=0.02)  # Unix time, UTC
    assert samples.gyro_s is not None and {"lat_deg", "lon_deg", "alt_m"} <= set(samples.channels)


# --------------------------------------------------------------------------- the sign: stated, inferred, assumed


@pytest.mark.parametrize(("standardised", "unit", "value"), [(False, "g", "negated"), (True, "m/s2", "as")])
def test_the_uncalibrated_files_unit_tells_the_ios_setting(
    session: ParkingLog, tmp_path: Path, standardised: bool, unit: str, value: str
) -> None:
    folder = record(tmp_path / "ios", session, "iOS", standardised=standardised, uncalibrated=unit)
    doc = _calibrate(folder, tmp_path, "--protocol", str(_protocol(session, tmp_path / "p.csv")))
    sign = _sign(doc)
    assert (sign["how"], sign["value"].split()[0]) == ("inferred", value)
    assert "AccelerometerUncalibrated.csv" in sign["by"] and unit in sign["by"]
    _assert_truth(doc, session)


def test_a_metadata_column_naming_the_setting_states_it(session: ParkingLog, tmp_path: Path) -> None:
    folder = record(tmp_path / "ios", session, "iOS", standardised=True, metadata={"standardisation": "true"})
    sign = next(c for c in read_log(folder).conventions if c.name == "acceleration_sign")
    assert (sign.how, sign.value.split()[0]) == ("stated", "as") and "standardisation" in sign.by


@pytest.mark.parametrize("protocol", [True, False])
def test_ios_with_the_setting_on_and_nothing_to_tell_ends_right_by_the_handedness_checks(
    session: ParkingLog, tmp_path: Path, protocol: bool
) -> None:
    """The setting on, no AccelerometerUncalibrated.csv: the default sign mirrors the data; the stops' headings
    (or, without a protocol, the turns) show it, and the other sign is taken, inferred and said."""
    folder = record(tmp_path / "ios", session, "iOS", standardised=True)
    args = ("--protocol", str(_protocol(session, tmp_path / "p.csv"))) if protocol else ()
    doc = _calibrate(folder, tmp_path, *args)
    sign = _sign(doc)
    assert (sign["how"], sign["value"].split()[0]) == ("inferred", "as")
    assert "Standardise Units & Frames' was on" in sign["by"]
    assert _check(doc, "handedness_stops" if protocol else "handedness_turns")["passed"] is True
    _assert_truth(doc, session, yaw=protocol)
    assert doc["confident"]


@pytest.mark.parametrize("standardised", [False, True])
def test_a_sign_nothing_confirms_is_not_confident(session: ParkingLog, tmp_path: Path, standardised: bool) -> None:
    """No gyro, no location, no headings: no handedness check can test the app's default, so the result is not
    confident — with the setting on it is upside down, which nothing here could show."""
    folder = record(tmp_path / "ios", session, "iOS", standardised=standardised, motion=False)
    doc = _calibrate(folder, tmp_path)
    assert _sign(doc)["how"] == "default"
    check = _check(doc, "acceleration_sign")
    assert check["passed"] is False and "AccelerometerUncalibrated" in check["reason"]
    assert not doc["confident"]


# --------------------------------------------------------------------------- refusals


def test_a_zip_that_is_no_recording_is_refused_naming_what_it_holds(tmp_path: Path, refused: Refused) -> None:
    path = tmp_path / "stops.zip"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("stops.csv", "t_s,ax,ay,az\n0,0,0,9.8\n")
    out = tmp_path / "r.json"
    err = refused(["calibrate", str(path), "-o", str(out)], out)
    assert str(path) in err and "stops.csv" in err and "Metadata.csv" in err


@pytest.mark.parametrize("name", ["Accelerometer.csv", "Gravity.csv", "Gyroscope.csv"])
def test_a_single_file_of_an_ios_recording_is_refused_naming_the_recording(
    session: ParkingLog, tmp_path: Path, refused: Refused, name: str
) -> None:
    folder = record(tmp_path / "ios", session, "iOS")
    out = tmp_path / "r.json"
    err = refused(["calibrate", str(folder / name), "-o", str(out)], out)
    assert f"its folder {folder.resolve()}" in err and "TotalAcceleration" not in err


def test_total_acceleration_alone_still_reads(session: ParkingLog, tmp_path: Path) -> None:
    folder = record(tmp_path / "android", session, "Android")
    samples = read_log(folder / "TotalAcceleration.csv")
    assert len(samples) == session.t_s.size and samples.gyro_s is None


# --------------------------------------------------------------------------- docs/inputs.md


def still_ios_zip(path: Path) -> Path:
    """A phone lying flat and still for 30 s, recorded by Sensor Logger on iOS (the default: negated), zipped."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 30.0, 0.01)
    gravity = np.tile([0.0, 0.0, G_N], (t.size, 1))
    folder = path.parent / f"{path.stem}_unzipped"
    folder.mkdir()
    pd.DataFrame([{"version": "3", "device name": "phone", "platform": "iOS"}]).to_csv(
        folder / "Metadata.csv", index=False
    )
    _vectors(folder / "Accelerometer.csv", t, -rng.normal(0, 0.02, (t.size, 3)))
    _vectors(folder / "Gravity.csv", t, -gravity)
    return zipped(folder, path)


def test_the_inputs_doc_command_reads_a_recording_zip(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    lines = (REPO / "docs" / "inputs.md").read_text(encoding="utf-8").splitlines()
    command = next(line[len("$ mountcal ") :] for line in lines if line.startswith("$ mountcal ") and ".zip" in line)
    still_ios_zip(tmp_path / "sensorlogger.zip")
    monkeypatch.chdir(tmp_path)
    assert main(shlex.split(command)) == 0
    samples = read_log(tmp_path / "sensorlogger.zip")
    np.testing.assert_allclose(np.median(samples.acc_s, axis=0), [0.0, 0.0, G_N], atol=0.01)  # +g up: negated


def test_rotate_reads_the_recording_with_the_sign_its_calibration_found(
    session: ParkingLog, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """iOS with the setting on: calibrate turns the app's default round (the handedness checks); rotate, which
    checks no handedness, must apply the calibration to the data as calibrated, not to their mirror image."""
    ios = record(tmp_path / "ios_on", session, "iOS", standardised=True)
    android = record(tmp_path / "android", session, "Android")
    frames = {}
    for name, rec in (("ios", ios), ("android", android)):
        cal = tmp_path / f"{name}.json"
        assert (
            main(["calibrate", str(rec), "--protocol", str(_protocol(session, tmp_path / "p.csv")), "-o", str(cal)])
            == 0
        )
        out = tmp_path / f"{name}.parquet"
        assert main(["rotate", str(rec), "--calibration", str(cal), "-o", str(out)]) == 0
        frames[name] = pd.read_parquet(out)
    ios_v, android_v = frames["ios"], frames["android"]
    n = min(len(ios_v), len(android_v))
    # the same vehicle-frame data (Accelerometer + Gravity rebuilt against TotalAcceleration: within 0.05 m/s²)
    for c in ("ax", "ay", "az"):
        assert np.median(np.abs(ios_v[c].to_numpy()[-n:] - android_v[c].to_numpy()[-n:])) < 0.05, c
    assert ios_v["az"].median() == pytest.approx(G_N, abs=0.2)  # +g up: not the mirror image (−g)


def test_rotate_says_a_sign_nothing_confirmed(
    session: ParkingLog, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ios = record(tmp_path / "ios", session, "iOS", motion=False)
    cal = tmp_path / "cal.json"
    assert main(["calibrate", str(ios), "-o", str(cal)]) == 0  # no headings, no drive: the sign is only assumed
    capsys.readouterr()
    assert main(["rotate", str(ios), "--calibration", str(cal), "--level-only", "-o", str(tmp_path / "v.parquet")]) == 0
    err = capsys.readouterr().err
    assert "Standardise Units & Frames" in err and "mirror image" in err, err
    meta = pq_metadata(tmp_path / "v.parquet")
    assert "Standardise Units & Frames" in meta["mountcal.warnings"]


def pq_metadata(path: Path) -> dict[str, str]:
    import pyarrow.parquet as pq

    return {k.decode(): v.decode() for k, v in (pq.read_schema(path).metadata or {}).items()}


def test_a_fleet_reads_each_recording_folder_and_zip_as_one_log_of_its_vehicle(
    session: ParkingLog, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A fleet folder of recordings: a recording's CSVs are its parts, not logs of their own (before, each file
    was a log, the recording's folder its vehicle, and every file but TotalAcceleration.csv failed)."""
    logs = tmp_path / "logs"
    record(logs / "v01" / "rec_a", session, "Android")
    zipped(record(tmp_path / "rec_b", session, "iOS"), logs / "v01" / "rec_b.zip")
    record(logs / "v02" / "rec_c", session, "iOS", uncalibrated="g")
    out = tmp_path / "fleet.parquet"
    assert main(["fleet", str(logs), "-o", str(out)]) == 0, capsys.readouterr().err
    table = pd.read_parquet(out).sort_values("log")
    assert [Path(p).name for p in table["log"]] == ["rec_a", "rec_b.zip", "rec_c"]
    assert list(table["vehicle_id"]) == ["v01", "v01", "v02"]
    alone = _calibrate(logs / "v02" / "rec_c", tmp_path)
    assert table["roll_deg"].iloc[2] == pytest.approx(alone["mounting"]["roll_deg"], abs=1e-6)
    assert (table["roll_deg"] - 5.0).abs().max() < 0.5 and (table["pitch_deg"] - 6.0).abs().max() < 0.5
    capsys.readouterr()
    assert main(["fleet", str(logs), "-o", str(out)]) == 0  # resumed: the folders' contents key their results
    assert "0 calibrated now, 3 from earlier runs" in capsys.readouterr().err


def test_a_recording_zip_cut_short_or_without_readable_rows_is_refused_saying_so(
    session: ParkingLog, tmp_path: Path, refused: Refused
) -> None:
    whole = zipped(record(tmp_path / "rec", session, "Android"))
    cut = tmp_path / "cut.zip"
    cut.write_bytes(whole.read_bytes()[: whole.stat().st_size // 2])  # an interrupted download
    err = refused(["calibrate", str(cut), "-o", str(tmp_path / "r.json")], tmp_path / "r.json")
    assert "cut.zip" in err and "does not open" in err and "cut short" in err, err
    for rows, name in (("foo,bar,1,2,3\n", "garbled.zip"), ("", "empty.zip")):
        with zipfile.ZipFile(tmp_path / name, "w") as z:
            z.writestr("Metadata.csv", "platform\nAndroid\n")
            z.writestr("TotalAcceleration.csv", "time,seconds_elapsed,z,y,x\n" + rows)
        err = refused(["calibrate", str(tmp_path / name), "-o", str(tmp_path / "r.json")], tmp_path / "r.json")
        assert f"{name}:TotalAcceleration.csv" in err and "none among its" in err, err  # not "no parked period"
