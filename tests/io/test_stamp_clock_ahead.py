"""A ROS topic stamped ahead of its receipt (mountcal/io/stamp_clock.py): an IMU driver stamping GPS time, 18 s
ahead of the recorder's UTC log_time. No latency is negative, so such stamps are on another clock: moved onto the
recorder's and said, as a boot clock's are.

Before, any stamp within 60 s of log_time was read as stamped: the IMU sat 18 s off its odometry. On a parking
session with drives between the stops, the drive's speed clock offset came out +4.97 s (a spurious peak), its yaw
20.7° against the stops' 7.0°, and the result was not confident (stops and drive disagreeing) where the same log
stamped in UTC answers confident.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mountcal.cli import main
from mountcal.io.logs import read_log
from mountcal.io.writers import IMU_TOPIC, write_mcap, write_protocol
from mountcal.simulate.stops import simulate_parking_log

GPS_AHEAD_S = 18.0  # GPS time − UTC since 2017


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path]:
    folder = tmp_path_factory.mktemp("gps")
    park = simulate_parking_log(5.0, 6.0, 7.0, seed=9)
    gps, utc, sheet = folder / "gps.mcap", folder / "utc.mcap", folder / "protocol.csv"
    write_mcap(gps, park, stamp_offsets_s={IMU_TOPIC: GPS_AHEAD_S})  # header.stamp = log_time + 18 s
    write_mcap(utc, park)
    write_protocol(sheet, park)
    return gps, utc, sheet


def test_an_imu_stamped_ahead_of_its_receipt_is_moved_onto_the_recorders_clock(logs: tuple[Path, Path, Path]) -> None:
    gps, utc, _ = logs
    moved, stamped = read_log(gps), read_log(utc)
    assert abs(float(moved.t_s[0] - stamped.t_s[0])) < 1e-6
    (clock,) = [c for c in moved.conventions if c.name == "stamp_clock"]
    assert "18.000 s ahead of the recorder's" in clock.value and clock.how == "inferred"


def test_a_parking_session_stamped_in_gps_time_calibrates_as_in_utc(
    logs: tuple[Path, Path, Path], tmp_path: Path
) -> None:
    gps, utc, sheet = logs
    docs = []
    for log in (gps, utc):
        out = tmp_path / f"{log.stem}.json"
        assert main(["calibrate", str(log), "--protocol", str(sheet), "-o", str(out)]) == 0
        docs.append(json.loads(out.read_text(encoding="utf-8")))
    ahead, right = docs
    assert ahead["confident"] and right["confident"]
    assert ahead["mounting"] == pytest.approx(right["mounting"], abs=1e-3)
