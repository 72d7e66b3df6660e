"""The gyro's unit from its size while the vehicle turns: its yaw rate against the heading's rate and a_y / v.

A gyro in deg/s read as rad/s turns 57.3 times too fast, one in rad/s stated to be deg/s 57.3 times too slowly,
whatever the speed and however gentle the turns (a highway drive shows no rate at rest or in a tight turn that
:mod:`mountcal.stops.gyro_unit` would see). The correlation that decides the handedness decides here too.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from mountcal.core.errors import InputError
from mountcal.core.result import Check
from mountcal.io.samples import Samples
from mountcal.loop.crosscheck import DEG_PER_RAD, gyro_scale, turn_cues
from mountcal.simulate.drive import simulate_drive


@pytest.fixture(scope="module")
def drive():  # type: ignore[no-untyped-def]
    return simulate_drive(3.0, -4.0, 30.0, duration_s=600.0, seed=21)


def _check(samples: Samples, rot_vs: Rotation, yaw_known: bool) -> Check:
    return gyro_scale(samples, turn_cues(samples, rot_vs, yaw_known))


def _scaled(samples: Samples, factor: float) -> Samples:
    assert samples.gyro_s is not None
    return dataclasses.replace(samples, gyro_s=samples.gyro_s * factor, source="drive.parquet")


@pytest.mark.parametrize(("heading", "yaw_known"), [(True, True), (False, True), (True, False)])
def test_a_gyro_in_rad_s_turns_as_the_heading_and_the_lateral_acceleration(drive, heading, yaw_known) -> None:  # type: ignore[no-untyped-def]
    check = _check(drive.to_samples(heading=heading), drive.truth.rot_vs, yaw_known)
    assert check.passed is True
    ratios = [float(x) for x in check.reason.split("is ")[1].replace(";", "").split() if x[0].isdigit()]
    assert ratios and all(0.8 < r < 1.25 for r in ratios), check.reason


@pytest.mark.parametrize(("heading", "yaw_known"), [(True, True), (False, True)])
def test_a_gyro_in_deg_s_read_as_rad_s_is_refused_with_what_states_its_unit(drive, heading, yaw_known) -> None:  # type: ignore[no-untyped-def]
    samples = _scaled(drive.to_samples(heading=heading), DEG_PER_RAD)
    with pytest.raises(InputError, match=r"57\.3 times too large") as err:
        _check(samples, drive.truth.rot_vs, yaw_known)
    assert str(err.value).startswith("drive.parquet: ") and "add :deg/s to its gx, gy, gz" in str(err.value)


def test_a_gyro_in_rad_s_stated_to_be_deg_s_is_refused(drive) -> None:  # type: ignore[no-untyped-def]
    samples = _scaled(drive.to_samples(heading=True), 1.0 / DEG_PER_RAD)
    with pytest.raises(InputError, match=r"57\.3 times too small"):
        _check(samples, drive.truth.rot_vs, True)


def test_the_heading_alone_says_the_mismatch_and_refuses_nothing(drive) -> None:  # type: ignore[no-untyped-def]
    """A heading channel's unit is a convention too (stated radians on a channel in degrees): without v·ω, a
    57.3 between gyro and heading cannot tell whose unit is wrong."""
    samples = _scaled(drive.to_samples(heading=True), DEG_PER_RAD)
    check = _check(samples, drive.truth.rot_vs, False)  # the lateral cue needs the yaw
    assert check.passed is None and "heading channel's unit" in check.reason
    heading = drive.to_samples(heading=True)
    h = heading.channels["heading_deg"]
    wrong = dataclasses.replace(
        heading, channels={**heading.channels, "heading_deg": dataclasses.replace(h, value=h.value * DEG_PER_RAD)}
    )
    check = _check(wrong, drive.truth.rot_vs, True)  # v·ω sides with the gyro
    assert check.passed is None and "the heading channel's rate does not" in check.reason


def test_no_turns_or_no_second_cue_is_not_judged(drive) -> None:  # type: ignore[no-untyped-def]
    samples = drive.to_samples()
    assert _check(dataclasses.replace(samples, channels={}), drive.truth.rot_vs, True).passed is None
    assert _check(samples, drive.truth.rot_vs, False).passed is None  # no heading, and a_y needs the yaw
    still = dataclasses.replace(samples, gyro_s=np.zeros_like(samples.gyro_s) + 1e-4)
    assert _check(still, drive.truth.rot_vs, True).passed is None


@pytest.mark.real_data
def test_the_real_canedge_car_s_gyro_turns_as_its_gnss_heading_and_its_v_omega(real_data: Path) -> None:
    """A real drive (CANedge GNSS/IMU logger, on its side in the car): the check passes, both ratios near 1."""
    from mountcal.calibration.pipeline import calibrate_log
    from mountcal.io.reader import LogOptions

    car = real_data / "canedge" / "3BA199E2_car_DK_2021-07-26" / "00000164"
    opts = LogOptions(dbc=str(real_data / "canedge" / "dbc" / "gnss.dbc"), channel=2)
    cal = calibrate_log(sorted(car.glob("*.MF4")), log=opts).calibration
    check = next(c for c in cal.checks if c.name == "gyro_scale")
    assert check.passed is True, check.reason
    ratios = [float(x) for x in re.findall(r"is ([\d.]+) times|; ([\d.]+) times", check.reason) for x in x if x]
    assert len(ratios) == 2 and all(0.85 < r < 1.15 for r in ratios), check.reason
