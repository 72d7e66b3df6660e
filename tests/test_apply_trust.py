"""Applying a calibration: correct, or a clear refusal (issue 11, items 3, 4, 5 and 7).

- An undetermined yaw is never stored nor applied: the result holds the levelling rotation
  (yaw the sensor's own), ``rotate`` refuses it or (``--level-only``) writes a frame that says so,
  on every path (stops, driving, fleet consensus, the Python API, old result files).
- A result that is not confident is applied with a warning recorded in the output, or refused.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from scipy.spatial.transform import Rotation

from mountcal import calibrate
from mountcal.apply.rotate import acc_to_vehicle, check_applicable, frame_to_vehicle
from mountcal.apply.rotate_log import rotate_log, to_frame
from mountcal.cli import main
from mountcal.core.conventions import angles_from_rot_vs
from mountcal.core.errors import InputError
from mountcal.core.result import Calibration
from mountcal.simulate.drive import simulate_drive
from mountcal.simulate.stops import simulate_stops
from mountcal.stops.table import write_stop_table as write_table

REPO = Path(__file__).resolve().parents[1]
PARKING = REPO / "data" / "parking.mcap"
E_Z = np.array([0.0, 0.0, 1.0])


def up_of(rot: Rotation) -> np.ndarray:
    """The vehicle's up axis in sensor coordinates."""
    return np.asarray(rot.inv().apply(E_Z), dtype=float)


@pytest.fixture(scope="module")
def noyaw() -> Calibration:
    """Stops with relative headings: tilt determined, yaw not (docs/conventions.md §4)."""
    table, _ = simulate_stops(roll_deg=5.0, pitch_deg=6.0, yaw_deg=37.0, slope_deg=5.0, headings="relative", seed=2)
    cal = calibrate(table)
    assert cal.yaw_deg is None and cal.yaw_reason
    return cal


@pytest.fixture(scope="module")
def drive_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("drive") / "drive.csv"
    to_frame(simulate_drive(duration_s=120.0, seed=4).to_samples()).to_csv(path, index=False)
    return path


# --------------------------------------------------------------------------- what is stored


def test_a_result_without_yaw_stores_the_levelling_rotation_not_an_invented_yaw(noyaw: Calibration) -> None:
    truth = Rotation.from_euler("ZYX", [37.0, 6.0, 5.0], degrees=True)
    yaw = np.degrees(angles_from_rot_vs(noyaw.rot_vs)[2])
    assert abs(yaw) < 1e-9  # the estimator's own yaw (≈ 37° + the unknown offset) is not kept
    assert np.degrees(np.arccos(up_of(noyaw.rot_vs) @ up_of(truth))) < 0.5  # it still levels
    # the levelled x axis is the sensor's x on the horizontal: sensor x has no levelled-y part
    assert abs(noyaw.rot_vs.apply([1.0, 0.0, 0.0])[1]) < 1e-12
    doc = noyaw.to_dict()
    assert doc["rotation"]["yaw"] == "sensor's own" and "levelled" in doc["rotation"]["frame"]
    assert doc["mounting"]["yaw_deg"] is None


def test_an_old_result_file_with_a_yaw_in_its_rotation_is_levelled_on_load(noyaw: Calibration, tmp_path: Path) -> None:
    doc = noyaw.to_dict()
    yawed = Rotation.from_euler("z", 37.0, degrees=True) * noyaw.rot_vs  # as the previous version stored it
    doc["rotation"] = {"quaternion_xyzw": yawed.as_quat().tolist(), "matrix_vs": yawed.as_matrix().tolist()}
    path = tmp_path / "old.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    loaded = Calibration.load(path)
    assert abs(np.degrees(angles_from_rot_vs(loaded.rot_vs)[2])) < 1e-9
    assert np.allclose(up_of(loaded.rot_vs), up_of(yawed), atol=1e-12)
    out = tmp_path / "out.parquet"
    assert main(["rotate", str(PARKING), "--calibration", str(path), "-o", str(out)]) == 2
    assert not out.exists()


# --------------------------------------------------------------------------- rotate refuses, or levels only


def test_issue_repro_rotate_refuses_a_calibration_whose_yaw_was_never_determined(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    result, out = tmp_path / "noyaw.json", tmp_path / "out.parquet"
    assert main(["calibrate", str(PARKING), "-o", str(result)]) == 0
    doc = json.loads(result.read_text(encoding="utf-8"))
    assert doc["mounting"]["yaw_deg"] is None
    stored_yaw = np.degrees(angles_from_rot_vs(Rotation.from_quat(doc["rotation"]["quaternion_xyzw"]))[2])
    assert abs(stored_yaw) < 1e-9  # was ~37°
    capsys.readouterr()
    assert main(["rotate", str(PARKING), "--calibration", str(result), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and str(result) in err and "yaw not determined" in err
    for remedy in ("--protocol", "--uphill-azimuth-deg", "speed", "--level-only"):
        assert remedy in err
    assert not out.exists()


def test_level_only_writes_a_frame_whose_metadata_and_columns_say_yaw_is_the_sensors_own(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    result, out = tmp_path / "noyaw.json", tmp_path / "out.parquet"
    assert main(["calibrate", str(PARKING), "-o", str(result)]) == 0
    capsys.readouterr()
    assert main(["rotate", str(PARKING), "--calibration", str(result), "-o", str(out), "--level-only"]) == 0
    captured = capsys.readouterr()
    assert "levelled" in captured.err and "levelled-frame samples" in captured.err
    schema = pq.read_schema(out)
    meta = {k.decode(): v.decode() for k, v in (schema.metadata or {}).items()}
    assert meta["mountcal.frame"].startswith("levelled") and "sensor's own" in meta["mountcal.frame"]
    assert "ISO 8855" not in meta["mountcal.frame"]
    assert meta["mountcal.yaw"].startswith("sensor's own")
    for name in ("ax", "ay", "az", "gx", "gy", "gz"):
        assert "sensor's own heading" in schema.field(name).metadata[b"description"].decode()
    # the data: the parked samples have gravity on +z (levelled) whatever the heading
    df = pd.read_parquet(out)
    assert float(df["az"].median()) > 9.7
    # a CSV says it in its column frame, and reads back as levelled samples (rotating them again is refused)
    csv = tmp_path / "o.csv"
    assert main(["rotate", str(PARKING), "--calibration", str(result), "-o", str(csv), "--level-only"]) == 0
    assert set(pd.read_csv(csv)["frame"]) == {"levelled"}
    again = ["rotate", str(csv), "--calibration", str(result), "-o", str(tmp_path / "o2.csv"), "--level-only"]
    assert main(again) == 2 and not (tmp_path / "o2.csv").exists()


def test_level_only_mcap_uses_a_levelled_topic_and_frame_id(noyaw: Calibration, tmp_path: Path) -> None:
    from mcap.reader import make_reader

    out = tmp_path / "out.mcap"
    report = rotate_log(PARKING, noyaw, out, level_only=True)
    assert report.topic is not None and report.topic.endswith("/levelled")
    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    channels = {c.topic: c for c in summary.channels.values()}
    assert not any(t.endswith("/vehicle") for t in channels)
    assert "sensor's own" in channels[report.topic].metadata["frame"]


def test_the_python_api_refuses_an_undetermined_yaw_unless_level_only(noyaw: Calibration) -> None:
    acc = np.tile([0.0, 0.0, 9.8], (20, 1))
    with pytest.raises(InputError, match="yaw not determined"):
        acc_to_vehicle(acc, noyaw)
    df = pd.DataFrame(acc, columns=["ax", "ay", "az"])
    with pytest.raises(InputError, match="level_only=True"):
        frame_to_vehicle(df, noyaw)
    with pytest.warns(UserWarning, match="levelled only"):
        levelled = frame_to_vehicle(df, noyaw, level_only=True)
    assert levelled.attrs["frame"] == "levelled"
    with pytest.raises(InputError):
        rotate_log(PARKING, noyaw, Path("never-written.parquet"))
    assert not Path("never-written.parquet").exists()


def test_a_drive_that_does_not_determine_yaw_stores_no_yaw_and_is_refused(drive_csv: Path, tmp_path: Path) -> None:
    from mountcal.calibration.pipeline import calibrate_log
    from mountcal.estimate.driving_options import DrivingOptions

    done = calibrate_log(drive_csv, use="driving", driving=DrivingOptions(max_yaw_sigma_deg=1e-6))
    cal = done.calibration
    assert cal.yaw_deg is None and "determines yaw only" in str(cal.yaw_reason)
    assert abs(np.degrees(angles_from_rot_vs(cal.rot_vs)[2])) < 1e-9
    with pytest.raises(InputError, match="speed"):
        rotate_log(drive_csv, cal, tmp_path / "o.parquet")
    assert not (tmp_path / "o.parquet").exists()


def test_a_fleet_consensus_without_yaw_stores_the_levelling_rotation(tmp_path: Path) -> None:
    for seed in range(3):
        table, _ = simulate_stops(
            roll_deg=4.0, pitch_deg=-3.0, yaw_deg=50.0, slope_deg=6.0, headings="relative", seed=seed
        )
        (tmp_path / "van").mkdir(exist_ok=True)
        write_table(table, tmp_path / "van" / f"stops_{seed}.csv")
    out = tmp_path / "fleet.parquet"
    assert main(["fleet", str(tmp_path / "van"), "-o", str(out), "--headings", "relative", "--workers", "1", "-q"]) == 0
    logs = pd.read_parquet(out)
    vehicles = pd.read_parquet(tmp_path / "fleet_vehicles.parquet")
    assert (logs["status"] == "ok").all() and logs["yaw_deg"].isna().all()
    for frame in (logs, vehicles):
        for _, row in frame.iterrows():
            rot = Rotation.from_quat(row[["quat_x", "quat_y", "quat_z", "quat_w"]].to_numpy(dtype=float))
            assert abs(np.degrees(angles_from_rot_vs(rot)[2])) < 1e-6
    assert vehicles["yaw_deg"].isna().all()


# --------------------------------------------------------------------------- not confident: visible, or refused


@pytest.fixture(scope="module")
def doubtful(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A result the residual loop marks not confident: stops disturbed by 30 mg the model lacks."""
    disturbance = np.random.default_rng(0).normal(0.0, 0.03, (12, 3))
    table, _ = simulate_stops(disturbance_mps2=disturbance, seed=1)
    cal = calibrate(table)
    assert not cal.confident and cal.yaw_deg is not None
    path = tmp_path_factory.mktemp("doubtful") / "doubtful.json"
    cal.save(path)
    return path


def test_issue_repro_rotate_warns_about_and_records_a_result_that_is_not_confident(
    doubtful: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out.parquet"
    assert main(["rotate", str(PARKING), "--calibration", str(doubtful), "-o", str(out)]) == 0
    err = capsys.readouterr().err
    assert "warning" in err and "not confident" in err
    meta = {k.decode(): v.decode() for k, v in (pq.read_schema(out).metadata or {}).items()}
    assert json.loads(meta["mountcal.confident"]) is False
    assert any("not confident" in w for w in json.loads(meta["mountcal.warnings"]))
    assert meta["mountcal.frame"].startswith("vehicle")
    mcap_out = tmp_path / "out.mcap"
    report = rotate_log(PARKING, Calibration.load(doubtful), mcap_out)
    assert any("not confident" in w for w in report.warnings)
    from mcap.reader import make_reader

    with open(mcap_out, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    assert [c.metadata["confident"] for c in summary.channels.values() if c.topic == report.topic] == ["false"]


def test_require_confident_refuses_a_result_that_is_not_confident(
    doubtful: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out.parquet"
    code = main(["rotate", str(PARKING), "--calibration", str(doubtful), "-o", str(out), "--require-confident"])
    err = capsys.readouterr().err
    assert code == 2 and "not confident" in err and str(doubtful) in err and "Traceback" not in err
    assert not out.exists()
    with pytest.raises(InputError, match="not confident"):
        frame_to_vehicle(
            pd.DataFrame(np.tile([0.0, 0.0, 9.8], (20, 1)), columns=["ax", "ay", "az"]),
            Calibration.load(doubtful),
            require_confident=True,
        )


def test_fleet_warns_about_logs_that_are_not_confident_and_records_them(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    van = tmp_path / "van"
    van.mkdir()
    write_table(simulate_stops(seed=3)[0], van / "good.csv")
    disturbance = np.random.default_rng(0).normal(0.0, 0.03, (12, 3))
    write_table(simulate_stops(disturbance_mps2=disturbance, seed=1)[0], van / "doubtful.csv")
    out = tmp_path / "fleet.parquet"
    assert main(["fleet", str(van), "-o", str(out), "--workers", "1", "-q"]) == 0
    err = capsys.readouterr().err
    assert "warning" in err and "1 log(s) not confident" in err and "doubtful.csv" in err
    for table in (out, tmp_path / "fleet_vehicles.parquet"):
        meta = pq.read_schema(table).metadata or {}
        assert json.loads(meta[b"mountcal.confident"]) is False
        assert [Path(p).name for p in json.loads(meta[b"mountcal.not_confident_logs"])] == ["doubtful.csv"]
    logs = pq.read_table(out).to_pandas()  # a bool column (the flag not_confident stays for those who filter on it)
    assert pq.read_schema(out).field("confident").type == "bool"
    by_name = {Path(str(log)).name: row for log, row in zip(logs["log"], logs.itertuples(), strict=True)}
    assert by_name["good.csv"].confident is True and by_name["doubtful.csv"].confident is False
    assert "not_confident" in list(by_name["doubtful.csv"].flags)
    refused = tmp_path / "refused.parquet"
    assert main(["fleet", str(van), "-o", str(refused), "--workers", "1", "-q", "--require-confident"]) == 2
    assert "not confident" in capsys.readouterr().err
    assert not refused.exists() and not (tmp_path / "refused_vehicles.parquet").exists()


def test_issue_repro_fleet_never_takes_its_own_outputs_as_logs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import shutil

    van = tmp_path / "fleet" / "van"
    van.mkdir(parents=True)
    shutil.copy(PARKING, van / "parking.mcap")
    shutil.copy(REPO / "data" / "parking_protocol.csv", van / "parking.protocol.csv")
    first = tmp_path / "fleet" / "fleet.parquet"
    assert main(["fleet", str(tmp_path / "fleet"), "-o", str(first), "--workers", "1", "-q"]) == 0
    assert len(pd.read_parquet(first)) == 1
    # Outputs lying among the logs under other names: recognised by their content, not their names.
    result = tmp_path / "result.json"
    args = ["--protocol", str(van / "parking.protocol.csv")]
    assert main(["calibrate", str(van / "parking.mcap"), *args, "-o", str(result)]) == 0
    assert (
        main(["rotate", str(van / "parking.mcap"), "--calibration", str(result), "-o", str(van / "day2.parquet")]) == 0
    )
    assert main(["rotate", str(van / "parking.mcap"), "--calibration", str(result), "-o", str(van / "day3.mcap")]) == 0
    first.rename(van / "day4.parquet")
    capsys.readouterr()
    second = tmp_path / "second.parquet"
    assert main(["fleet", str(tmp_path), "-o", str(second), "--workers", "1"]) == 0
    out = capsys.readouterr().err  # status lines go to stderr
    logs = pd.read_parquet(second)
    assert [Path(p).name for p in logs["log"]] == ["parking.mcap"] and (logs["status"] == "ok").all()
    assert "set aside 4 file(s) mountcal wrote" in out  # day2, day3, day4 and the first run's vehicles table
    with pytest.raises(InputError, match="a file mountcal wrote"):
        from mountcal.fleet.inputs import collect_jobs

        collect_jobs([van / "day2.parquet"])
    outputs = tmp_path / "outputs"  # a folder of outputs alone: nothing to calibrate, and said why
    outputs.mkdir()
    for name in ("day2.parquet", "day3.mcap"):
        shutil.copy(van / name, outputs / name)
    with pytest.raises(InputError, match=r"found no log; set aside 2 file\(s\) mountcal wrote, e\.g\. .*day"):
        collect_jobs([outputs])


# --------------------------------------------------------------------------- optional dependencies, checked first

BLOCKER = """
import importlib.abc, runpy, sys
HIDDEN = set(sys.argv[1].split(","))
class Hide(importlib.abc.MetaPathFinder):  # as if `pip install .` without the extra
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in HIDDEN:
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None
sys.meta_path.insert(0, Hide())
sys.argv = ["mountcal", *sys.argv[2:]]
runpy.run_module("mountcal", run_name="__main__")
"""


def run_without(hidden: str, *args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """The real CLI in a fresh interpreter where ``hidden`` (comma-separated top-level modules) cannot be imported."""
    env = {**os.environ, "PYTHONPATH": str(REPO / "src")}
    return subprocess.run(
        [sys.executable, "-c", BLOCKER, hidden, *args], capture_output=True, text=True, cwd=cwd, env=env, timeout=300
    )


def test_issue_repro_calibrate_report_without_matplotlib_refuses_before_writing_anything(tmp_path: Path) -> None:
    stops = REPO / "data" / "zhang2011_stops.csv"
    done = run_without("matplotlib", "calibrate", str(stops), "-o", "r.json", "--report", "r.html", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr and "ModuleNotFoundError" not in done.stderr
    assert "matplotlib" in done.stderr and "pip install 'mountcal[report]'" in done.stderr
    assert not (tmp_path / "r.json").exists() and not (tmp_path / "r.html").exists()
    assert list(tmp_path.iterdir()) == []  # no temporary file either
    # the blocker hides only what it names: without --report the same command works and writes
    done = run_without("matplotlib", "calibrate", str(stops), "-o", "r.json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "r.json").exists()


def test_report_and_fleet_scheduler_name_their_extra_when_it_is_missing(tmp_path: Path) -> None:
    result = tmp_path / "r.json"
    assert main(["calibrate", str(REPO / "data" / "zhang2011_stops.csv"), "-o", str(result)]) == 0
    done = run_without("matplotlib", "report", str(result), cwd=tmp_path)
    assert done.returncode == 2 and "pip install 'mountcal[report]'" in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "r.html").exists()
    (tmp_path / "van").mkdir()
    write_table(simulate_stops(seed=0)[0], tmp_path / "van" / "a.csv")
    args = ("fleet", str(tmp_path / "van"), "-o", "f.parquet", "--scheduler", "tcp://127.0.0.1:1", "-q")
    done = run_without("distributed,dask", *args, cwd=tmp_path)
    assert done.returncode == 2 and "pip install 'mountcal[fleet]'" in done.stderr and "Traceback" not in done.stderr
    assert not (tmp_path / "f.parquet").exists() and not (tmp_path / "f.parquet.parts").exists()


# --------------------------------------------------------------------------- stops against driving


@pytest.fixture(scope="module")
def drive_and_stops(tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    """One mounting seen by a drive (written as a log) and by stops on a 5° slope, headings relative."""
    truth = dict(roll_deg=-7.0, pitch_deg=-2.0, yaw_deg=25.0)
    path = tmp_path_factory.mktemp("drive") / "drive.csv"
    to_frame(simulate_drive(**truth, duration_s=300.0, seed=5).to_samples()).to_csv(path, index=False)
    table, _ = simulate_stops(**truth, slope_deg=5.0, headings="relative", seed=5)
    return path, table, calibrate(table)


def mirror_of(cal: Calibration) -> Calibration:
    """The stops' mirror solution (roll + 180°, slope 180° − α): it fits stops without headings as well."""
    flipped = cal.rot_vs * Rotation.from_euler("x", 180.0, degrees=True)
    roll = (cal.roll_deg + 360.0) % 360.0 - 180.0
    return replace(cal, rot_vs=flipped, roll_deg=roll, slope_deg=180.0 - (cal.slope_deg or 0.0))


def test_issue_repro_stops_and_driving_that_disagree_in_tilt_are_a_finding_not_combined(
    drive_and_stops, capsys: pytest.CaptureFixture[str]
) -> None:  # type: ignore[no-untyped-def]
    from mountcal.calibration.pipeline import LogJob, stops_with_drive
    from mountcal.calibration.summary import summary
    from mountcal.calibration.with_driving import combine
    from mountcal.estimate.driving import estimate_driving
    from mountcal.io.logs import read_log
    from mountcal.outputs.report import render

    path, table, static = drive_and_stops
    samples = read_log([path])
    agree = combine(static, estimate_driving(samples, tilt_from=static))  # the same mounting: combined
    assert agree.confident and agree.yaw_deg is not None and agree.fit.calibrated_from == "stops + driving"
    mirror = mirror_of(static)
    fit = estimate_driving(samples, tilt_from=mirror)
    assert fit.tilt_check is not None and fit.tilt_check.angle_deg > 170.0
    cal = stops_with_drive(mirror, table, fit, samples, LogJob(paths=(str(path),)))
    assert not cal.confident
    assert [u.test for u in cal.unexplained if u.test == "stops_vs_driving"] == ["stops_vs_driving"]
    assert cal.fit.calibrated_from is not None and "disagree" in cal.fit.calibrated_from
    assert cal.fit.driving is not None and cal.fit.driving_levelled_with_stops is not None
    assert not cal.fit.driving.tilt_source.startswith("static")  # levelled by the drive itself
    assert cal.fit.driving_levelled_with_stops.tilt_source.startswith("static")
    text = summary(cal)
    assert "DISAGREE" in text and "NOT CONFIDENT" in text and "tilt by 1" in text
    assert "stops_vs_driving" in render(cal, None)
    # the physical branch: the rotated drive has +g up (the mirror would give −g)
    acc_v = cal.rot_vs.apply(samples.acc_s)
    assert float(np.median(acc_v[:, 2])) > 9.0
    assert float(np.median(mirror.rot_vs.apply(samples.acc_s)[:, 2])) < -9.0
    # and the result is refused where confidence is required
    with pytest.raises(InputError, match="not confident"):
        check_applicable(cal, require_confident=True)


def test_stops_and_driving_that_disagree_in_yaw_are_not_combined(drive_and_stops) -> None:  # type: ignore[no-untyped-def]
    from mountcal.calibration.with_driving import combine
    from mountcal.estimate.driving import estimate_driving
    from mountcal.io.logs import read_log

    path, _, _ = drive_and_stops
    table, _ = simulate_stops(roll_deg=-7.0, pitch_deg=-2.0, yaw_deg=25.0, slope_deg=5.0, seed=5)
    static = calibrate(table)  # uphill headings: a yaw of its own
    assert static.yaw_deg is not None and static.confident
    wrong = replace(static, yaw_deg=static.yaw_deg + 20.0)  # as from a wrong uphill azimuth
    wrong = replace(wrong, rot_vs=Rotation.from_euler("z", 20.0, degrees=True) * static.rot_vs)
    cal = combine(wrong, estimate_driving(read_log([path]), tilt_from=wrong))
    assert not cal.confident and cal.yaw_deg == wrong.yaw_deg  # not averaged with the drive's
    finding = [u for u in cal.unexplained if u.test == "stops_vs_driving"]
    assert len(finding) == 1 and "yaw by -2" in finding[0].size


@pytest.mark.real_data
def test_a_real_drive_with_stops_is_combined_only_when_they_agree_and_rotates_to_plus_g_up(real_data: Path) -> None:
    from mountcal.calibration.pipeline import calibrate_log
    from mountcal.io.reader import LogOptions

    car = real_data / "canedge" / "3BA199E2_car_DK_2021-07-26" / "00000165"
    opts = LogOptions(dbc=str(real_data / "canedge" / "dbc" / "gnss.dbc"), channel=2)
    done = calibrate_log(sorted(car.glob("*.MF4")), log=opts)
    cal = done.calibration
    combination = cal.fit.combination
    assert combination is not None
    if combination.disagreement is not None:  # a finding: not combined, not confident, said everywhere
        assert not cal.confident and any(u.test == "stops_vs_driving" for u in cal.unexplained)
    else:
        tilt = combination.tilt_check  # combined: within 3σ about both horizontal axes (may be outside 2σ)
        assert tilt is not None and done.used == "stops + driving" and tilt.z_max <= 3
    acc_v = cal.rot_vs.apply(done.samples.acc_s)
    assert float(np.nanmedian(acc_v[:, 2])) > 9.0  # the physical branch: +g up


def test_a_document_that_says_yaw_is_not_determined_is_never_given_one(noyaw: Calibration) -> None:
    doc = noyaw.to_dict()
    doc["mounting"]["yaw_deg"], doc["uncertainty"]["yaw_deg"] = 37.0, 1.0  # hand-edited, or another writer
    with pytest.raises(InputError, match=r"yaw\.determined = false while mounting\.yaw_deg = 37"):
        Calibration.from_dict(doc)  # a contradiction is refused on load, never resolved by taking the number
    cal = Calibration.from_dict(noyaw.to_dict())
    assert cal.yaw_deg is None and not cal.yaw_determined
    with pytest.raises(InputError, match="yaw not determined"):
        check_applicable(cal)
