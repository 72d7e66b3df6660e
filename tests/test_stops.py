"""Stop detection on simulated parking logs: the stops, their headings, and the calibration they give."""

from __future__ import annotations

import numpy as np
import pytest

from mountcal.calibration.fit import calibrate
from mountcal.io.samples import Channel, Samples
from mountcal.simulate.stops import ParkingLog, simulate_parking_log
from mountcal.stops.detect import StopDetection, detect_stops, find_stops, still_mask
from mountcal.stops.headings import beta_from_heading, stop_table


@pytest.fixture(scope="module")
def log() -> ParkingLog:
    return simulate_parking_log(seed=3)


def samples_of(log: ParkingLog, speed: bool = True, gyro: bool = True) -> Samples:
    channels = {"heading_deg": Channel(log.t_s, log.heading_deg), "temperature_c": Channel(log.t_s, log.temperature_c)}
    if speed:
        channels["speed_mps"] = Channel(log.t_s, log.speed_mps)
    return Samples(log.t_s, log.acc_s, log.gyro_s if gyro else None, channels)


@pytest.mark.parametrize(("speed", "gyro"), [(True, True), (False, True), (False, False)])
def test_every_parked_period_is_found_inside_its_protocol_interval(log: ParkingLog, speed: bool, gyro: bool) -> None:
    stops = detect_stops(samples_of(log, speed, gyro))
    assert len(stops) == len(log.protocol)
    for stop, (lo, hi, _) in zip(stops, log.protocol, strict=True):
        assert lo <= stop.t_start_s < stop.t_end_s <= hi
        assert stop.duration_s > 0.8 * (hi - lo - 2 * StopDetection().trim_s)


def test_headings_from_the_log_and_the_uphill_azimuth_give_beta(log: ParkingLog) -> None:
    stops = detect_stops(samples_of(log))
    heading = np.array([s.channels["heading_deg"] for s in stops])
    beta = beta_from_heading(heading, log.uphill_azimuth_deg)
    diff = (beta - log.truth.beta_deg + 180.0) % 360.0 - 180.0
    np.testing.assert_allclose(diff, 0.0, atol=1e-9)


def test_detected_stops_calibrate_to_the_truth_within_sigma(log: ParkingLog) -> None:
    stops = detect_stops(samples_of(log))
    heading = np.array([s.channels["heading_deg"] for s in stops])
    table = stop_table(stops, beta_from_heading(heading, log.uphill_azimuth_deg))
    cal = calibrate(table)
    roll, pitch, yaw = log.truth.angles_deg
    assert abs(cal.roll_deg - roll) < 4 * cal.roll_sigma_deg
    assert abs(cal.pitch_deg - pitch) < 4 * cal.pitch_sigma_deg
    assert cal.yaw_deg is not None and abs(cal.yaw_deg - yaw) < 4 * cal.yaw_sigma_deg  # type: ignore[operator]


def test_stop_noise_is_the_noise_of_the_mean(log: ParkingLog) -> None:
    stops = detect_stops(samples_of(log))
    sigma_mean = np.sqrt(np.array([np.diag(s.acc_cov_mean_s) for s in stops]))
    expected = 0.05 / np.sqrt(np.array([s.n for s in stops]))[:, None]
    ratio = sigma_mean / expected
    assert 0.7 < np.median(ratio) < 1.3  # batch means: 10 batches, so ±25 % per stop


def test_a_quantised_signal_that_does_not_dither_keeps_its_quantisation_floor() -> None:
    t = np.arange(6000) / 100.0
    acc = np.tile([0.125 * 3, 0.0, 0.125 * 78], (t.size, 1))
    acc[::500, 2] += 0.125  # z toggles to the next level now and then; x and y never move
    stops = detect_stops(Samples(t, acc))
    assert len(stops) == 1
    np.testing.assert_allclose(np.sqrt(np.diag(stops[0].acc_cov_mean_s)), 0.125 / np.sqrt(12), rtol=1e-9)


def test_protocol_windows_select_the_stops(log: ParkingLog) -> None:
    windows = [(lo, hi) for lo, hi, _ in log.protocol[::2]]
    stops = detect_stops(samples_of(log), windows=windows)
    assert len(stops) == len(windows)
    assert all(lo <= s.t_start_s and s.t_end_s <= hi for s, (lo, hi) in zip(stops, windows, strict=True))


def test_driving_only_gives_no_stop(log: ParkingLog) -> None:
    moving = log.speed_mps > 0.5
    s = Samples(log.t_s[moving], log.acc_s[moving], log.gyro_s[moving])
    assert detect_stops(s) == []


def _quiet(t: np.ndarray, seed: int = 0) -> Samples:
    """A parked sensor: gravity on z and a little noise, at times ``t``."""
    rng = np.random.default_rng(seed)
    return Samples(t, np.array([0.0, 0.0, 9.81]) + rng.normal(0.0, 0.01, (t.size, 3)))


def test_a_gap_in_time_ends_a_stop(log: ParkingLog) -> None:
    """A dropout (here 10⁷ s: damaged times) inside a parked period: no stop spans it, and the
    samples whose window holds the gap are counted as not judged."""
    lo, hi, _ = log.protocol[0]
    mid = 0.5 * (lo + hi)
    shifted = np.where(log.t_s > mid, log.t_s + 1e7, log.t_s)
    samples = samples_of(log)
    channels = {k: Channel(np.where(c.t_s > mid, c.t_s + 1e7, c.t_s), c.value) for k, c in samples.channels.items()}
    search = find_stops(Samples(shifted, samples.acc_s, samples.gyro_s, channels))
    assert search.stops
    assert all(s.t_end_s <= mid or s.t_start_s > mid + 1e7 for s in search.stops)
    assert any("not judged still" in k and v > 0 for k, v in search.counts.items()), search.counts
    # the parked periods away from the gap are still found whole
    assert len(search.stops) >= len(log.protocol) - 1


def test_samples_far_apart_give_no_stop_and_say_why() -> None:
    """Samples 10⁷ s apart (found by the fuzzer: a damaged MF4 size field) measure no spread over a
    2 s window; before, every one-sample window had a spread of 0 and the whole log was a stop."""
    samples = _quiet(np.arange(4724) * 1e7)
    search = find_stops(samples)
    assert search.stops == []
    assert [v for k, v in search.counts.items() if "not judged still" in k] == [4724]


@pytest.mark.parametrize("n", [1, 4, 50])
def test_a_log_shorter_than_the_window_is_one_window(n: int) -> None:
    """0.01 s steps, a 2 s window: the log is one window (it crashed with a shape error)."""
    t = np.arange(n) * 0.01
    quiet = still_mask(_quiet(t), StopDetection())
    assert quiet.shape == (n,)
    assert quiet.all() == (n >= 5)  # fewer than 5 samples measure no spread: not still
    # one window is all the log has to set its rest noise from: a stated threshold judges motion
    moving = Samples(t, _quiet(t).acc_s + np.random.default_rng(1).normal(0.0, 2.0, (n, 3)))
    assert not still_mask(moving, StopDetection(max_acc_std_mps2=0.3)).any()
    assert still_mask(_quiet(t), StopDetection(max_acc_std_mps2=0.3)).all() == (n >= 5)
