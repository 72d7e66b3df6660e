"""Headings a half turn off (a course over ground of a vehicle that reversed into its spot, an uphill azimuth that
names the downhill direction): a single such stop is set aside naming the half turn; all of them turn the yaw by
180°, which stops alone cannot tell from a sensor facing backwards, and the answer says both."""

from __future__ import annotations

import dataclasses
import re

import numpy as np
import pytest

from mountcal.calibration.fit import calibrate
from mountcal.calibration.summary import summary
from mountcal.simulate.stops import simulate_stops

BETA = np.arange(0.0, 360.0, 45.0)


def _turned(table, stops):  # type: ignore[no-untyped-def]
    beta = table.beta_rad.copy()
    beta[stops] = (beta[stops] + np.pi) % (2.0 * np.pi)
    return dataclasses.replace(table, beta_rad=beta)


@pytest.mark.parametrize(("stop", "slope", "seed"), [(0, 5.0, 1), (3, 3.0, 2), (5, 8.0, 3), (7, 2.0, 4)])
def test_a_stop_entered_in_reverse_is_set_aside_naming_its_half_turn(stop: int, slope: float, seed: int) -> None:
    table, _ = simulate_stops(5.0, 6.0, 7.0, slope_deg=slope, beta_deg=BETA, seed=seed)
    cal = calibrate(_turned(table, [stop]))
    text = summary(cal)
    stated = (BETA[stop] + 180.0) % 360.0
    assert f"stop set aside: stop {stop + 1}, β = {stated:.0f}°" in text
    assert f"fits a heading a half turn away (β = {BETA[stop]:.0f}°" in text
    assert cal.confident
    for angle, truth in (("roll", 5.0), ("pitch", 6.0), ("yaw", 7.0)):
        sigma = getattr(cal, f"{angle}_sigma_deg")
        assert abs(getattr(cal, f"{angle}_deg") - truth) < 3.0 * sigma


def test_a_stop_off_for_another_reason_is_set_aside_without_a_half_turn() -> None:
    """A knock (a door closing, a passenger) moves one stop's reading; a half turn would not predict it."""
    kick = np.zeros((len(BETA), 3))
    kick[2] = [0.25, -0.15, 0.05]
    table, _ = simulate_stops(5.0, 6.0, 7.0, slope_deg=5.0, beta_deg=BETA, disturbance_mps2=kick, seed=5)
    text = summary(calibrate(table))
    assert "stop set aside: stop 3" in text
    assert "half turn" not in text


def test_headings_all_a_half_turn_off_turn_the_yaw_and_the_answer_names_the_other_reading() -> None:
    """Metamorphic: every β + 180° (downhill for uphill) gives yaw + 180°, roll and pitch unchanged; the
    note then names the yaw of the other reading, which is the true one here."""
    table, _ = simulate_stops(5.0, 6.0, 7.0, slope_deg=5.0, beta_deg=BETA, seed=6)
    right, turned = calibrate(table), calibrate(_turned(table, list(range(len(BETA)))))
    assert right.yaw_deg is not None and turned.yaw_deg is not None
    assert (turned.yaw_deg - right.yaw_deg) % 360.0 == pytest.approx(180.0, abs=1e-6)
    assert turned.roll_deg == pytest.approx(right.roll_deg, abs=1e-6)
    assert turned.pitch_deg == pytest.approx(right.pitch_deg, abs=1e-6)
    assert not any("backwards" in n for n in right.notes)
    (note,) = [n for n in turned.notes if "backwards" in n]
    other = float(re.search(r"the yaw is (-?[\d.]+)°", note)[1])  # type: ignore[index]
    assert other == pytest.approx(right.yaw_deg, abs=0.05)
    assert "downhill" in note and "course" in note and "drive" in note


@pytest.mark.parametrize("headings", ["relative", "none"])
def test_headings_that_fix_no_yaw_say_nothing_of_its_direction(headings: str) -> None:
    table, _ = simulate_stops(5.0, 6.0, 170.0, slope_deg=5.0, beta_deg=BETA, headings=headings, seed=7)  # type: ignore[arg-type]
    assert not any("backwards" in n for n in calibrate(table).notes)


@pytest.mark.parametrize(("stops", "seed"), [([1, 6], 2), ([0, 4, 9], 3), ([2, 11], 4)])
def test_several_stops_entered_in_reverse_are_named_and_the_answer_is_not_confident(
    stops: list[int], seed: int
) -> None:
    """More stops than the loop sets aside: the misfit is not explained, and the note names which headings, turned,
    make every stop fit (the answer itself is not changed: the user corrects the headings)."""
    beta = np.arange(0.0, 360.0, 30.0)
    table, _ = simulate_stops(5.0, 6.0, 7.0, slope_deg=5.0, beta_deg=beta, seed=seed)
    cal = calibrate(_turned(table, stops))
    assert not cal.confident
    (note,) = [n for n in cal.notes if "half a turn away" in n]
    named = [int(k) - 1 for k in re.findall(r"(\d+) \(β = ", note)]
    assert named == sorted(stops)


def test_stops_knocked_out_of_place_are_not_called_a_half_turn() -> None:
    beta = np.arange(0.0, 360.0, 30.0)
    kick = np.zeros((len(beta), 3))
    kick[[1, 6]] = [[0.3, -0.2, 0.05], [-0.25, 0.1, 0.1]]
    table, _ = simulate_stops(5.0, 6.0, 7.0, slope_deg=5.0, beta_deg=beta, disturbance_mps2=kick, seed=8)
    cal = calibrate(table)
    assert not cal.confident
    assert not any("half a turn" in n for n in cal.notes)


@pytest.mark.parametrize(("yaw", "noted"), [(100.0, False), (-110.0, False), (160.0, True), (-150.0, True)])
def test_only_an_x_axis_pointing_backwards_is_said_to_have_another_reading(yaw: float, noted: bool) -> None:
    """Any yaw from headings has the half-turn reading; the note is for the one that looks like it (x backwards),
    not for a sensor turned sideways."""
    table, _ = simulate_stops(5.0, 6.0, yaw, slope_deg=5.0, beta_deg=BETA, seed=9)
    assert any("backwards" in n for n in calibrate(table).notes) is noted
