"""A speed channel on a clock seconds away from the IMU's (a GNSS receiver's GPS time, 18 leap seconds ahead
of UTC; a logger's clock off): the drive's lag is found beyond the ±2 s searched first, and the answer is right.

Before, the lag search looked within ±2 s only: an 18 s lag sat at its edge, the drive's tilt came out 14° and
17° off (roll 17.0°, pitch 12.9° for 4.1° and −4.5°), confident; a 5 s lag left yaw undetermined.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mountcal.cli import main
from mountcal.simulate.drive import DriveLog, simulate_drive


def _table(drive: DriveLog, path: Path) -> Path:
    """mountcal's own columns written by pandas, the speed interpolated onto the IMU's rows (its lag kept)."""
    samples = drive.to_samples()
    assert samples.gyro_s is not None
    frame = pd.DataFrame({"t_s": samples.t_s - samples.t_s[0]})
    for i, axis in enumerate("xyz"):
        frame[f"a{axis}"] = samples.acc_s[:, i]
    for i, axis in enumerate("xyz"):
        frame[f"g{axis}"] = samples.gyro_s[:, i]
    speed = samples.channels["speed_mps"]
    frame["speed_mps"] = np.interp(samples.t_s, speed.t_s, speed.value)
    frame.to_csv(path, index=False)
    return path


@pytest.mark.parametrize("lag_s", [18.0, 5.0])
def test_a_speed_clock_seconds_behind_the_imu_is_found_and_the_drive_answered_right(
    lag_s: float, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    truth = simulate_drive(3.0, -4.0, 30.0, duration_s=600.0, seed=21)
    lagged = simulate_drive(3.0, -4.0, 30.0, duration_s=600.0, seed=21, speed_delay_s=lag_s)
    results = []
    for name, drive in (("aligned", truth), ("lagged", lagged)):
        out = tmp_path / f"{name}.json"
        assert (
            main(["calibrate", str(_table(drive, tmp_path / f"{name}.csv")), "--use", "driving", "-o", str(out)]) == 0
        )
        results.append(json.loads(out.read_text()))
    err = capsys.readouterr().err
    aligned, found = results
    assert found["confident"] and found["yaw"]["determined"]
    for angle in ("roll_deg", "pitch_deg", "yaw_deg"):  # the lagged log answers as the aligned one does
        assert found["mounting"][angle] == pytest.approx(aligned["mounting"][angle], abs=0.3), angle
    assert abs(found["mounting"]["yaw_deg"] - 30.0) < 1.0
    assert f"{lag_s:.1f} s apart, beyond the ±2 s searched first" in err
