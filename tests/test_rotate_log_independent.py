"""The vehicle-frame MCAP channel of `mountcal rotate`, checked against an independent derivation.

A vehicle is placed in the world (tilted, turning at a known rate); a sensor is mounted in it with a known
rotation. What that sensor publishes as ``sensor_msgs/msg/Imu`` (its orientation in the world, the specific
force and rate in its own axes, covariances given about its own axes — an AHRS whose heading is far less certain
than its tilt) is written with the mcap-ros2 writer, rotated by mountcal, and read back with the mcap-ros2
decoder. The expected vehicle-frame message is built here from the same physics with scipy: the vehicle's own
orientation, specific force and rate, and every covariance turned to the vehicle's axes (``R C Rᵀ``), as the ROS
consumers of a turned ``sensor_msgs/Imu`` do (imu_transformer / tf2_sensor_msgs ``doTransform``: angular
velocity, linear acceleration *and* orientation covariances through ``transformCovariance``).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer
from scipy.spatial.transform import Rotation

from mountcal.apply.rotate_log import rotate_log
from mountcal.calibration.fit import calibrate
from mountcal.core.option_names import option
from mountcal.core.result import Calibration, Convention
from mountcal.io.mcap.write import IMU_DEFINITION
from mountcal.io.reader import LogOptions
from mountcal.simulate.stops import simulate_stops

T0_NS = 1_714_557_600_000_000_000
G = 9.80665
RATE_HZ, N = 100, 60
YAW_RATE = 0.1  # rad/s, about the world's vertical
VEHICLE_TILT = Rotation.from_euler("xyz", [3.0, -4.0, 0.0], degrees=True)  # rolled 3°, pitched −4° (fixed axes)
# about the sensor's own x, y, z (rad², row-major): tilt well known, heading poorly, with a correlation
ORIENTATION_COV_S = np.array([[1e-4, 2e-5, 0.0], [2e-5, 4e-4, 0.0], [0.0, 0.0, 1e-1]])
GYRO_COV_S = np.diag([1e-6, 4e-6, 9e-6])
ACC_COV_S = np.array([[1e-3, 1e-4, 0.0], [1e-4, 2e-3, 0.0], [0.0, 0.0, 5e-3]])


@pytest.fixture(scope="module")
def cal() -> Calibration:
    """A sensor on its side and turned: y up, x pointing back-left — no axis near the vehicle's."""
    truth = Rotation.from_euler("ZYX", [135.0, 10.0, -90.0], degrees=True)
    table, _ = simulate_stops(rot_vs=truth, seed=5)
    result = calibrate(table)
    assert result.yaw_determined and result.confident
    return result


def vehicle_in_world(t: float) -> Rotation:
    """The vehicle's orientation (vehicle → world), heading 30° + YAW_RATE·t."""
    return Rotation.from_rotvec([0.0, 0.0, np.radians(30.0) + YAW_RATE * t]) * VEHICLE_TILT


def write_sensor_log(path: Path, cal: Calibration, device_from_sensor: np.ndarray | None = None) -> None:
    """What the IMU publishes; with ``device_from_sensor`` (D: device = D · sensor), in the device's axes."""
    d = np.eye(3) if device_from_sensor is None else device_from_sensor
    r_vs = cal.rot_vs
    bias = np.zeros(3) if cal.bias_mps2 is None else np.asarray(cal.bias_mps2)
    with open(path, "wb") as f:
        w = Ros2Writer(f)
        imu = w.register_msgdef("sensor_msgs/msg/Imu", IMU_DEFINITION)
        for i in range(N):
            t = i / RATE_HZ
            r_wv = vehicle_in_world(t)
            r_ws = r_wv * r_vs  # sensor → world
            f_v = r_wv.inv().apply([0.0, 0.0, G])  # at rest: gravity's reaction, in vehicle axes
            w_v = VEHICLE_TILT.inv().apply([0.0, 0.0, YAW_RATE])  # body rate of Rz(ψ(t))·tilt
            a_s = r_vs.inv().apply(f_v) + bias
            g_s = r_vs.inv().apply(w_v)
            x, y, z, qw = (r_ws * Rotation.from_matrix(d).inv()).as_quat()  # device → world
            stamp = T0_NS + i * 10_000_000
            msg = {
                "header": {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9}, "frame_id": "imu_link"},
                "orientation": {"x": x, "y": y, "z": z, "w": qw},
                "orientation_covariance": (d @ ORIENTATION_COV_S @ d.T).ravel().tolist(),
                "angular_velocity": dict(zip("xyz", (d @ g_s).tolist(), strict=True)),
                "angular_velocity_covariance": (d @ GYRO_COV_S @ d.T).ravel().tolist(),
                "linear_acceleration": dict(zip("xyz", (d @ a_s).tolist(), strict=True)),
                "linear_acceleration_covariance": (d @ ACC_COV_S @ d.T).ravel().tolist(),
            }
            w.write_message("/imu/data", imu, msg, log_time=stamp, publish_time=stamp, sequence=i)
        w.finish()


def test_vehicle_channel_is_what_an_imu_along_the_vehicle_would_publish(cal: Calibration, tmp_path: Path) -> None:
    src, out = tmp_path / "sensor.mcap", tmp_path / "vehicle.mcap"
    write_sensor_log(src, cal)
    report = rotate_log(src, cal, out)
    assert report.topic == "/imu/data/vehicle" and report.samples_out == N
    with open(out, "rb") as f:
        msgs = [
            m
            for _, _, _, m in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages(
                topics=["/imu/data/vehicle"]
            )
        ]
    assert len(msgs) == N
    r = cal.rot_vs.as_matrix()  # the vehicle's axes from the sensor's: covariances turn as R C Rᵀ
    for i, m in enumerate(msgs):
        t = i / RATE_HZ
        r_wv = vehicle_in_world(t)
        assert m.header.frame_id == "base_link"
        assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == T0_NS + i * 10_000_000
        got_q = Rotation.from_quat([m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w])
        assert (got_q.inv() * r_wv).magnitude() < 1e-9  # the vehicle's orientation in the world
        acc = np.array([m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z])
        np.testing.assert_allclose(acc, r_wv.inv().apply([0.0, 0.0, G]), atol=1e-9)
        rate = np.array([m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z])
        np.testing.assert_allclose(rate, VEHICLE_TILT.inv().apply([0.0, 0.0, YAW_RATE]), atol=1e-12)
        for got, cov_s in (
            (m.linear_acceleration_covariance, ACC_COV_S),
            (m.angular_velocity_covariance, GYRO_COV_S),
            (m.orientation_covariance, ORIENTATION_COV_S),
        ):
            np.testing.assert_allclose(np.reshape(got, (3, 3)), r @ cov_s @ r.T, rtol=0, atol=1e-15)
    # the sensor's heading uncertainty (about its z, horizontal here: the sensor lies on its side) is now
    # about horizontal vehicle axes; the vehicle's heading is no less certain than its tilt
    cov_v = np.reshape(msgs[0].orientation_covariance, (3, 3))
    assert cov_v[0, 0] + cov_v[1, 1] > 0.09 and cov_v[2, 2] < 0.01


def test_vehicle_channel_of_a_log_read_with_an_axis_map_is_the_same(cal: Calibration, tmp_path: Path) -> None:
    """A device publishing other axes (``--axes y,-x,z``: sensor x = device y, sensor y = −device x, z = z): its
    orientation and every covariance are the device's; the vehicle channel must still be the vehicle's."""
    p = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # sensor = P · device
    stated = Convention("axes", "y,-x,z", "stated", option("axes"))  # as calibrate records it
    mapped_cal = replace(cal, provenance=replace(cal.provenance, conventions=(*cal.provenance.conventions, stated)))
    src, out = tmp_path / "device.mcap", tmp_path / "vehicle.mcap"
    write_sensor_log(src, cal, device_from_sensor=p.T)
    report = rotate_log(src, mapped_cal, out, options=LogOptions(axes="y,-x,z"))
    assert report.samples_out == N
    with open(out, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        msgs = [m for _, _, _, m in reader.iter_decoded_messages(topics=["/imu/data/vehicle"])]
    r = cal.rot_vs.as_matrix()
    for i, m in enumerate(msgs):
        r_wv = vehicle_in_world(i / RATE_HZ)
        got_q = Rotation.from_quat([m.orientation.x, m.orientation.y, m.orientation.z, m.orientation.w])
        assert (got_q.inv() * r_wv).magnitude() < 1e-9
        acc = np.array([m.linear_acceleration.x, m.linear_acceleration.y, m.linear_acceleration.z])
        np.testing.assert_allclose(acc, r_wv.inv().apply([0.0, 0.0, G]), atol=1e-9)
        for got, cov_s in (
            (m.linear_acceleration_covariance, ACC_COV_S),
            (m.angular_velocity_covariance, GYRO_COV_S),
            (m.orientation_covariance, ORIENTATION_COV_S),
        ):
            np.testing.assert_allclose(np.reshape(got, (3, 3)), r @ cov_s @ r.T, rtol=0, atol=1e-15)
