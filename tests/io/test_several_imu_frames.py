"""One IMU topic whose messages name two frames — two drivers publishing on one topic, two sensors mounted
differently — read as one sensor's samples mixes two mountings: calibrate is then not confident (checks:
sensor_frame), and rotate refuses before writing (one calibration applies to one frame), for every output.

Before: the parking demo's IMU interleaved with a second sensor turned 20° about z (frame imu_link_rear) gave
yaw −3.0° ± 0.6° *confident* (neither sensor's: 7° and −13°), with only a note; `rotate` with the first sensor's
calibration wrote all 79200 samples, half of them rotated with the wrong mounting, exit 0 (Parquet and MCAP).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from mcap_ros2.writer import Writer
from scipy.spatial.transform import Rotation

from mountcal.cli import main
from mountcal.io.logs import read_log
from mountcal.io.writers import ros2_definition

REPO = Path(__file__).resolve().parents[2]
PARKING, PROTOCOL = REPO / "data" / "parking.mcap", REPO / "data" / "parking_protocol.csv"


def _message(t_ns: int, acc: np.ndarray, gyro: np.ndarray, frame: str) -> dict[str, object]:
    def xyz(v: np.ndarray) -> dict[str, float]:
        return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}

    return {
        "header": {"stamp": {"sec": t_ns // 10**9, "nanosec": t_ns % 10**9}, "frame_id": frame},
        "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        "orientation_covariance": [-1.0] + [0.0] * 8,
        "angular_velocity": xyz(gyro),
        "angular_velocity_covariance": [0.0] * 9,
        "linear_acceleration": xyz(acc),
        "linear_acceleration_covariance": [0.0] * 9,
    }


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    folder = tmp_path_factory.mktemp("two_sensors")
    samples = read_log(PARKING)
    turn = Rotation.from_euler("z", 20.0, degrees=True)  # the second sensor's axes against the first's
    assert samples.gyro_s is not None
    rear_acc, rear_gyro = turn.apply(samples.acc_s), turn.apply(samples.gyro_s)
    log = folder / "two.mcap"
    with open(log, "wb") as f, Writer(f) as writer:
        schema = writer.register_msgdef("sensor_msgs/msg/Imu", ros2_definition("sensor_msgs/msg/Imu"))
        for i, t in enumerate(samples.t_s.tolist()):
            t_ns = round(t * 1e9)
            for frame, acc, gyro, lag in (
                ("imu_link", samples.acc_s, samples.gyro_s, 0),
                ("imu_link_rear", rear_acc, rear_gyro, 3_000_000),  # another driver, 3 ms later
            ):
                writer.write_message("/imu/data", schema, _message(t_ns + lag, acc[i], gyro[i], frame), t_ns + lag)
    result = folder / "r.json"
    assert main(["calibrate", str(PARKING), "--protocol", str(PROTOCOL), "-o", str(result), "-q"]) == 0
    return {"log": log, "calibration": result}


def test_two_frames_on_one_topic_calibrate_not_confident(files: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    assert main(["calibrate", str(files["log"]), "--protocol", str(PROTOCOL), "-o", str(out), "-q"]) == 0
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert not doc["confident"]
    (check,) = [c for c in doc["checks"] if c["name"] == "sensor_frame"]
    assert check["passed"] is False and "imu_link_rear" in check["reason"] and "--topic" in check["reason"]


@pytest.mark.parametrize("suffix", [".parquet", ".csv", ".mcap"])
def test_two_frames_on_one_topic_are_not_rotated_with_one_calibration(
    files: dict[str, Path], suffix: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / f"vehicle{suffix}"
    capsys.readouterr()
    assert main(["rotate", str(files["log"]), "--calibration", str(files["calibration"]), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "several frames" in err and "imu_link_rear" in err and str(files["log"]) in err
    assert not out.exists()


def test_one_frame_still_rotates(files: dict[str, Path], tmp_path: Path) -> None:
    out = tmp_path / "vehicle.mcap"
    assert main(["rotate", str(PARKING), "--calibration", str(files["calibration"]), "-o", str(out), "-q"]) == 0
    assert out.stat().st_size > 0


def test_a_stop_table_of_two_frames_keeps_them(files: dict[str, Path], tmp_path: Path) -> None:
    """`mountcal stops` writes the frames into its column sensor_frame: the table is not confident either
    (before, the table read back as one sensor's stops: confident, yaw −3.06°)."""
    table, out = tmp_path / "stops.csv", tmp_path / "r.json"
    assert main(["stops", str(files["log"]), "--protocol", str(PROTOCOL), "-o", str(table), "-q"]) == 0
    assert main(["calibrate", str(table), "-o", str(out), "-q"]) == 0
    doc = json.loads(out.read_text(encoding="utf-8"))
    assert not doc["confident"] and any(c["name"] == "sensor_frame" and c["passed"] is False for c in doc["checks"])
    (said,) = [c for c in doc["provenance"]["conventions"] if c["name"] == "sensor_frame"]
    assert said["value"].startswith("several frames") and said["by"].endswith("column sensor_frame)")
