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
from mountcal.io.writers import IMU_TOPIC, ODOMETRY_TOPIC, write_mcap, write_protocol
from mountcal.simulate.stops import simulate_parking_log

GPS_AHEAD_S = 18.0  # GPS time − UTC since 2017


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, Path, Path]:
    folder = tmp_path_factory.mktemp("gps")
    park = simulate_parking_log(5.0, 6.0, 7.0, seed=9)
    gps, utc, sheet, every = folder / "gps.mcap", folder / "utc.mcap", folder / "protocol.csv", folder / "all.mcap"
    write_mcap(gps, park, stamp_offsets_s={IMU_TOPIC: GPS_AHEAD_S})  # header.stamp = log_time + 18 s
    write_mcap(
        every, park, with_temperature=False, stamp_offsets_s={IMU_TOPIC: GPS_AHEAD_S, ODOMETRY_TOPIC: GPS_AHEAD_S}
    )
    write_mcap(utc, park)
    write_protocol(sheet, park)
    return gps, utc, sheet, every


@pytest.mark.parametrize("which", ["imu", "every topic"])
def test_topics_stamped_ahead_of_their_receipt_are_moved_onto_the_recorders_clock(
    which: str, logs: tuple[Path, Path, Path, Path]
) -> None:
    """The IMU alone ahead (beside the odometry on log_time), or every topic (no topic on the recorder's clock: no
    replay's stamps lie ahead of their receipt, so the recorder's clock is still the one to date them by)."""
    gps, utc, _, every = logs
    moved, stamped = read_log(gps if which == "imu" else every), read_log(utc)
    assert abs(float(moved.t_s[0] - stamped.t_s[0])) < 1e-6
    speed, right = moved.channels["speed_mps"], stamped.channels["speed_mps"]
    assert abs(float(speed.t_s[0] - right.t_s[0])) < 1e-6
    (clock,) = [c for c in moved.conventions if c.name == "stamp_clock"]
    assert "18.000 s ahead of the recorder's" in clock.value and clock.how == "inferred"


def test_a_parking_session_stamped_in_gps_time_calibrates_as_in_utc(
    logs: tuple[Path, Path, Path, Path], tmp_path: Path
) -> None:
    gps, utc, sheet, _ = logs
    docs = []
    for log in (gps, utc):
        out = tmp_path / f"{log.stem}.json"
        assert main(["calibrate", str(log), "--protocol", str(sheet), "-o", str(out)]) == 0
        docs.append(json.loads(out.read_text(encoding="utf-8")))
    ahead, right = docs
    assert ahead["confident"] and right["confident"]
    assert ahead["mounting"] == pytest.approx(right["mounting"], abs=1e-3)
