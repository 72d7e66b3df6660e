"""One test per physical fact of docs/conventions.md §1–2."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from mountcal.core.conventions import (
    G_N,
    angles_from_rot_vs,
    normal_gravity,
    rot_vs_from_angles,
    specific_force_v,
    tilt_from_normal,
)

S5, C5 = np.sin(np.radians(5)), np.cos(np.radians(5))


def sensor_reading_level(roll_deg: float, pitch_deg: float, yaw_deg: float = 0.0) -> np.ndarray:
    rot = rot_vs_from_angles(*np.radians([roll_deg, pitch_deg, yaw_deg]))
    return rot.inv().apply(specific_force_v(0.0, 0.0)[0])


def test_level_aligned_sensor_reads_plus_g_on_z() -> None:
    np.testing.assert_allclose(sensor_reading_level(0, 0), [0, 0, G_N], atol=1e-12)


def test_roll_plus_5_alone() -> None:
    np.testing.assert_allclose(sensor_reading_level(5, 0), [0, G_N * S5, G_N * C5], atol=1e-12)


def test_pitch_plus_5_alone() -> None:
    np.testing.assert_allclose(sensor_reading_level(0, 5), [-G_N * S5, 0, G_N * C5], atol=1e-12)


def test_yaw_alone_does_not_change_a_level_reading() -> None:
    np.testing.assert_allclose(sensor_reading_level(0, 0, 40), [0, 0, G_N], atol=1e-12)


def test_facing_uphill_reads_forward_specific_force() -> None:
    np.testing.assert_allclose(specific_force_v(np.radians(5), 0.0)[0], G_N * np.array([S5, 0, C5]), atol=1e-12)


def test_uphill_on_the_right_at_beta_90() -> None:
    # β = 90°: the uphill side is on the right (−y), so the reaction to gravity points right.
    np.testing.assert_allclose(specific_force_v(np.radians(5), np.pi / 2)[0], G_N * np.array([0, -S5, C5]), atol=1e-12)


def test_euler_sequence_is_intrinsic_zyx() -> None:
    r = rot_vs_from_angles(0.1, 0.2, 0.3)
    expected = Rotation.from_euler("z", 0.3) * Rotation.from_euler("y", 0.2) * Rotation.from_euler("x", 0.1)
    assert (r.inv() * expected).magnitude() < 1e-14
    assert (r.inv() * Rotation.from_euler("xyz", [0.1, 0.2, 0.3])).magnitude() < 1e-14


@given(
    st.floats(-179, 179),
    st.floats(-85, 85),
    st.floats(-179, 179),
)
def test_angles_round_trip(roll: float, pitch: float, yaw: float) -> None:
    got = np.degrees(angles_from_rot_vs(rot_vs_from_angles(*np.radians([roll, pitch, yaw]))))
    np.testing.assert_allclose(got, [roll, pitch, yaw], atol=1e-9)


@given(st.floats(-179, 179), st.floats(-89, 89))
def test_tilt_from_normal_inverts_the_vehicle_up_axis(roll: float, pitch: float) -> None:
    rot = rot_vs_from_angles(np.radians(roll), np.radians(pitch), 0.7)
    got = np.degrees(tilt_from_normal(rot.inv().apply([0.0, 0.0, 1.0])))
    np.testing.assert_allclose(got, [roll, pitch], atol=1e-7)


@pytest.mark.parametrize(("lat", "expected"), [(0.0, 9.7803253359), (90.0, 9.8321849378), (45.0, 9.8061978)])
def test_wgs84_normal_gravity_at_the_surface(lat: float, expected: float) -> None:
    assert normal_gravity(lat) == pytest.approx(expected, abs=2e-7)


def test_normal_gravity_falls_with_height_by_the_free_air_gradient() -> None:
    assert normal_gravity(45.0, 1000.0) - normal_gravity(45.0) == pytest.approx(-3.086e-3, rel=2e-3)
