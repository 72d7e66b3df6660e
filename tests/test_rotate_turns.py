"""``rotate`` with a calibration made elsewhere checks the log's turns against it (:class:`TurnWatch`).

A drive log rotated with the calibration of another session has had none of ``calibrate``'s checks: a gyro in
rad/s stated to be deg/s (converted to rates 57.3 times too small), a gyro axis reversed by a DBC sign, a
calibration half a turn off for this log would each be written as vehicle-frame data, a silent wrong file. The
turns at speed tell each apart: the gyro's yaw rate against ``a_y / v`` and the heading's rate.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from mountcal.cli import main
from mountcal.core.result import Calibration
from mountcal.io.writers import write_mcap
from mountcal.simulate.drive import DriveLog, simulate_drive

OWN = "time=t_s,ax=ax,ay=ay,az=az,gx=gx,gy=gy,gz=gz,speed=speed_mps"
STATED_DEG = "time=t_s,ax=ax,ay=ay,az=az,gx=gx:deg/s,gy=gy:deg/s,gz=gz:deg/s,speed=speed_mps"


@pytest.fixture(scope="module")
def drive() -> DriveLog:
    return simulate_drive(3.0, -4.0, 30.0, duration_s=600.0, seed=21)


def _table(
    drive: DriveLog, path: Path, gyro: tuple[float, float, float] = (1.0, 1.0, 1.0), acc_xy: float = 1.0
) -> Path:
    """mountcal's own columns written by pandas; ``gyro`` scales each rate axis, ``acc_xy`` the x and y
    accelerations (−1: the sensor turned half a turn about its z axis)."""
    samples = drive.to_samples()
    assert samples.gyro_s is not None
    frame = pd.DataFrame({"t_s": samples.t_s - samples.t_s[0]})
    for i, axis in enumerate("xyz"):
        frame[f"a{axis}"] = samples.acc_s[:, i] * (acc_xy if i < 2 else 1.0)
    for i, axis in enumerate("xyz"):
        frame[f"g{axis}"] = samples.gyro_s[:, i] * gyro[i] * (acc_xy if i < 2 else 1.0)
    speed = samples.channels["speed_mps"]
    frame["speed_mps"] = np.interp(samples.t_s, speed.t_s, speed.value)
    frame.to_csv(path, index=False)
    return path


def _calibrated(table: Path, out: Path) -> Path:
    assert main(["calibrate", str(table), "-o", str(out)]) == 0
    return out


def _refused(capsys: pytest.CaptureFixture[str], args: list[str], out: Path) -> str:
    capsys.readouterr()
    assert main([*args, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert not out.exists() and "Traceback" not in err
    return err


def test_a_gyro_in_rad_s_stated_deg_s_is_refused_by_rotate_on_the_stream_and_the_mcap_copy(
    drive: DriveLog, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    table = _table(drive, tmp_path / "drive.csv")
    cal = _calibrated(table, tmp_path / "cal.json")
    rotate = ["rotate", "--calibration", str(cal), str(table)]
    assert main([*rotate, "--columns", OWN, "-o", str(tmp_path / "ok.parquet")]) == 0
    said = "".join(capsys.readouterr())
    assert "gyro_scale: checked" in said and "handedness_turns: checked" in said, said
    for out in ("v.parquet", "v.csv"):
        err = _refused(capsys, [*rotate, "--columns", STATED_DEG], tmp_path / out)
        assert "drive.csv" in err and "57.3 times too small" in err and "drop the deg/s" in err, err
    small = drive.to_samples()
    assert small.gyro_s is not None
    mcap = tmp_path / "small.mcap"
    write_mcap(mcap, small.__class__(**{**small.__dict__, "gyro_s": small.gyro_s / np.degrees(1.0)}), start_time_s=0)
    for out in ("v.mcap", "w.parquet"):
        err = _refused(capsys, ["rotate", "--calibration", str(cal), str(mcap)], tmp_path / out)
        assert "small.mcap" in err and "57.3 times too small" in err, err


def test_a_gyro_axis_reversed_or_a_calibration_half_a_turn_off_is_refused_by_rotate(
    drive: DriveLog, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cal = _calibrated(_table(drive, tmp_path / "drive.csv"), tmp_path / "cal.json")
    reversed_z = _table(drive, tmp_path / "gz_reversed.csv", gyro=(1.0, 1.0, -1.0))
    err = _refused(capsys, ["rotate", "--calibration", str(cal), str(reversed_z)], tmp_path / "v.parquet")
    assert "gz_reversed.csv" in err and "opposite turns" in err and "wrong sign at its source" in err, err
    # a sensor turned half a turn about its z axis since: the calibration is not this log's mounting
    turned = _table(drive, tmp_path / "turned.csv", acc_xy=-1.0)
    err = _refused(capsys, ["rotate", "--calibration", str(cal), str(turned)], tmp_path / "v.parquet")
    assert "turned.csv" in err and "half a turn off" in err and "moved or remounted since" in err, err
    own = _calibrated(turned, tmp_path / "own.json")  # its own calibration rotates it
    assert main(["rotate", "--calibration", str(own), str(turned), "-o", str(tmp_path / "ok.parquet")]) == 0
    # a calibration half a turn off in yaw (stops' headings from downhill): x and y both point backwards
    right = Calibration.load(cal)
    assert right.yaw_deg is not None
    half = Rotation.from_euler("z", 180.0, degrees=True) * right.rot_vs
    wrong = replace(right, rot_vs=half, yaw_deg=(right.yaw_deg + 360.0) % 360.0 - 180.0)
    wrong.save(tmp_path / "half.json")
    log = tmp_path / "drive.csv"
    err = _refused(capsys, ["rotate", "--calibration", str(tmp_path / "half.json"), str(log)], tmp_path / "v.csv")
    assert "drive.csv" in err and "half a turn off" in err and "calibrate the vehicle again" in err, err


def test_a_log_without_turns_at_speed_is_rotated_and_the_report_says_nothing_was_checked(
    drive: DriveLog, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    table = _table(drive, tmp_path / "drive.csv")
    cal = _calibrated(table, tmp_path / "cal.json")
    parked = pd.read_csv(table)
    parked["speed_mps"] = 0.0
    parked.to_csv(tmp_path / "parked.csv", index=False)
    capsys.readouterr()
    assert main(["rotate", "--calibration", str(cal), str(tmp_path / "parked.csv"), "-o", str(tmp_path / "p.csv")]) == 0
    said = "".join(capsys.readouterr())
    assert "handedness_turns: not checked" in said and "gyro_scale: not checked, too little turning" in said
    imu_only = tmp_path / "imu_only.mcap"  # an MCAP copied through is not read twice for turns it cannot show
    write_mcap(imu_only, drive.to_samples(), with_odometry=False, start_time_s=0)
    assert main(["rotate", "--calibration", str(cal), str(imu_only), "-o", str(tmp_path / "v.mcap")]) == 0
    assert "not checked: the log holds no odometry topic" in "".join(capsys.readouterr())


def test_frame_to_vehicle_checks_the_turns_sense_but_takes_rates_in_any_unit(drive: DriveLog, tmp_path: Path) -> None:
    from mountcal import frame_to_vehicle
    from mountcal.apply.rotate_log import to_frame
    from mountcal.core.errors import InputError
    from mountcal.io.logs import read_log

    table = _table(drive, tmp_path / "drive.csv")
    right = Calibration.load(_calibrated(table, tmp_path / "cal.json"))
    df = to_frame(read_log(table))
    gyro = ("gx", "gy", "gz")
    assert frame_to_vehicle(df, right, gyro_columns=gyro)["az"].median() == pytest.approx(9.8, abs=0.1)
    in_degrees = df.assign(**{c: np.degrees(df[c]) for c in gyro})  # this API rotates rates in any unit
    turned = frame_to_vehicle(in_degrees, right, gyro_columns=gyro)
    np.testing.assert_allclose(turned["gz"], np.degrees(frame_to_vehicle(df, right, gyro_columns=gyro)["gz"]))
    assert right.yaw_deg is not None
    half = replace(
        right,
        rot_vs=Rotation.from_euler("z", 180.0, degrees=True) * right.rot_vs,
        yaw_deg=(right.yaw_deg + 360.0) % 360.0 - 180.0,
    )
    with pytest.raises(InputError, match="half a turn off"):
        frame_to_vehicle(df, half, gyro_columns=gyro)
