"""The report's log over time: the accelerometer (and speed) decimated to a min/max envelope, the stops
shaded and numbered as in the stop table, the still periods detection dropped and the driving fit's
intervals marked; and a report made without the log says it cannot draw them."""

from __future__ import annotations

import re
import threading
import time
from dataclasses import replace
from pathlib import Path

import can
import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from mountcal.apply.rotate_log import to_frame
from mountcal.calibration.pipeline import LogResult, calibrate_log
from mountcal.cli import main
from mountcal.io.reader import LogOptions
from mountcal.io.samples import Channel, Samples
from mountcal.outputs.report import figures, render
from mountcal.outputs.report.embed import figure_html
from mountcal.outputs.report.timeline import COLUMNS, Timeline, envelope, timeline, timeline_of
from mountcal.simulate.drive import simulate_drive
from mountcal.stops.detect import StopDetection, find_stops
from mountcal.stops.table import StopTable

DATA = Path(__file__).resolve().parents[1] / "data"
DBC = str(DATA / "imu_mm5_10.dbc")
STOP_ID = re.compile(r'\bid="fig\d+-stop-(\d+)"')


def _spans(fig: Figure, kind: str) -> list[Patch]:
    """The shaded spans of one kind (``stop``, ``still``, ``driving``) drawn in the figure."""
    return [p for ax in fig.axes for p in ax.patches if (p.get_gid() or "").startswith(f"{kind}-")]


@pytest.fixture(scope="module")
def parking() -> LogResult:
    return calibrate_log(DATA / "parking.blf", log=LogOptions(dbc=DBC), protocol=DATA / "parking_protocol.csv")


@pytest.fixture(scope="module")
def drive_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A drive that waits at junctions (parked stops without headings) with a speed channel."""
    path = tmp_path_factory.mktemp("drive") / "drive.parquet"
    to_frame(simulate_drive(duration_s=600.0, seed=5).to_samples()).to_parquet(path, index=False)
    return path


# --- decimation -----------------------------------------------------------------------------------


def test_the_envelope_keeps_a_one_sample_spike_that_a_stride_hides() -> None:
    rng = np.random.default_rng(1)
    n = 1_000_003
    t = np.arange(n) / 200.0
    acc = rng.normal(0.0, 0.05, (n, 3)) + np.array([0.0, 0.0, 9.81])
    spike = 654_321
    acc[spike] = [31.0, -27.0, 40.0]  # a pothole: one sample
    stride = max(1, n // COLUMNS)
    assert spike % stride != 0  # a plain stride (every stride-th sample) misses it ...
    assert acc[::stride].max() < 1.0 + 9.81
    env = envelope(t, acc)
    assert env.decimated and env.t_s.shape == (COLUMNS,) and env.low.shape == env.high.shape == (COLUMNS, 3)
    assert env.high[:, 0].max() == 31.0 and env.low[:, 1].min() == -27.0 and env.high[:, 2].max() == 40.0
    column = int(np.argmax(env.high[:, 0]))  # ... the envelope holds it, in the column of its time
    assert env.high[column, 0] == 31.0 and env.low[column, 1] == -27.0
    assert abs(env.t_s[column] - t[spike]) <= (t[-1] - t[0]) / COLUMNS
    # every column is the exact min and max of the samples in it
    edges = np.linspace(t[0], t[-1], COLUMNS + 1)
    for k in (0, 17, 400, COLUMNS - 1):
        inside = (t >= edges[k]) & ((t < edges[k + 1]) if k < COLUMNS - 1 else (t <= edges[-1]))
        assert np.array_equal(env.low[k], acc[inside].min(axis=0))
        assert np.array_equal(env.high[k], acc[inside].max(axis=0))


def test_a_short_log_is_drawn_sample_by_sample_and_a_gap_stays_a_gap() -> None:
    t = np.linspace(0.0, 10.0, 1000)
    v = np.sin(t)[:, None]
    env = envelope(t, v)
    assert not env.decimated and np.array_equal(env.t_s, t) and np.array_equal(env.low, v)
    t_gap = np.concatenate([np.linspace(0.0, 100.0, 50_000), np.linspace(200.0, 300.0, 50_000)])
    env = envelope(t_gap, np.ones((t_gap.size, 1)))
    empty = ~np.isfinite(env.high[:, 0])
    assert empty.any() and np.all((env.t_s[empty] > 100.0) & (env.t_s[empty] < 200.0))
    assert np.all(env.high[~empty] == 1.0)


def test_unsorted_times_are_binned_by_time() -> None:
    rng = np.random.default_rng(3)
    t = rng.permutation(np.arange(100_000) / 100.0)
    env = envelope(t, t[:, None])  # the value is the time: each column's range lies inside it
    width = (t.max() - t.min()) / COLUMNS
    assert np.all(env.high[:, 0] - env.low[:, 0] < width)
    assert np.all(np.abs(0.5 * (env.high[:, 0] + env.low[:, 0]) - env.t_s) < width)


def test_the_drawing_of_a_long_log_is_as_small_as_that_of_a_short_one() -> None:
    def svg_bytes(n: int) -> int:
        t = np.arange(n) / 100.0
        acc = np.random.default_rng(0).normal(0.0, 0.5, (n, 3))
        speed = Channel(t[::10], np.abs(np.sin(t[::10] / 50.0)) * 20.0)
        tl = timeline(Samples(t, acc, None, {"speed_mps": speed}, source="long"))
        return len(figure_html(figures.log_over_time(tl), "log", "svg", 1))

    short, long = svg_bytes(20_000), svg_bytes(2_000_000)  # 3 min and 5.6 h at 100 Hz
    assert long < 400_000 and long < 1.5 * short


# --- the figure and the report ----------------------------------------------------------------------


def test_the_report_of_a_log_shades_and_numbers_every_stop_of_its_table(parking: LogResult) -> None:
    assert parking.table is not None and len(parking.table) == 12
    tl = timeline_of(parking)
    assert [s.number for s in tl.stops if s.status == "used"] == list(range(1, 13))
    assert tl.speed_mps is not None  # the parking log has a speed channel: drawn on its own axis
    fig = figures.log_over_time(tl)
    spans = _spans(fig, "stop")
    assert len(spans) == len(parking.table)
    assert len(fig.axes) == 2 and fig.axes[1].get_ylabel() == "speed (m/s)"
    labels = {t.get_text() for t in fig.axes[0].texts}
    assert {str(k) for k in range(1, 13)} <= labels
    # each span covers its stop's time in the table (times drawn from the log's start)
    assert parking.table.t_s is not None and parking.table.duration_s is not None
    x0 = parking.table.t_s - tl.t_start_s
    drawn = np.array([p.get_x() for p in spans])  # seconds: the log is 22 min long, under the minutes limit
    assert np.allclose(np.sort(drawn), np.sort(x0))

    html = render(parking.calibration, parking.table, timeline=tl)
    numbers = [int(n) for n in STOP_ID.findall(html)]
    assert sorted(numbers) == list(range(1, 13))
    assert "The log over time" in html and "not drawn" not in html
    ids = re.findall(r'\bid="([^"]+)"', html)
    assert len(ids) == len(set(ids))


def test_without_the_log_the_report_says_it_cannot_draw_it(parking: LogResult) -> None:
    html = render(parking.calibration, parking.table)
    assert STOP_ID.findall(html) == []
    line = [p for p in html.splitlines() if "log over time" in p]
    assert len(line) == 1 and "without the log's samples" in line[0] and "timeline=" in line[0]


def test_stops_left_out_not_used_and_dropped_are_marked_apart(parking: LogResult) -> None:
    assert parking.table is not None
    cal = parking.calibration
    left_out = replace(parking, calibration=replace(cal, fit=replace(cal.fit, excluded_stops=(3, 7))))
    tl = timeline_of(left_out)
    assert {s.number for s in tl.stops if s.status == "left out"} == {3, 7}
    fig = figures.log_over_time(tl)
    spans = {p.get_gid(): p for p in _spans(fig, "stop")}
    assert len(spans) == 12
    assert spans["stop-3"].get_hatch() == spans["stop-7"].get_hatch() != spans["stop-1"].get_hatch()
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any("left out" in t for t in legend) and any("used by the fit" in t for t in legend)

    # stops that the result was not fitted to (e.g. too few of them) are drawn as found, not used, with why
    unused = replace(parking, table=None, calibration=cal, skipped={"stops": "too few stops"})
    tl = timeline_of(unused)
    assert {s.status for s in tl.stops} == {"not used"} and len(tl.stops) == 12
    assert all(s.why == "too few stops" for s in tl.stops)


def test_still_periods_that_detection_dropped_are_drawn_hatched_and_unnumbered(parking: LogResult) -> None:
    # The parking log's 12 stops last 22 s: the default minimum (8 s once 2 s are trimmed at each end)
    # keeps them all, a minimum of 30 s none; those are then drawn as still periods not kept, with why.
    samples = parking.samples
    kept = find_stops(samples, StopDetection())
    none = find_stops(samples, StopDetection(min_duration_s=30.0))
    assert len(kept.stops) == 12 and none.stops == []
    long_dropped = [d for d in none.dropped if d.t_end_s - d.t_start_s > 15.0]
    assert len(long_dropped) == 12 and all("--min-stop-s" in d.why or "min_duration_s" in d.why for d in none.dropped)
    tl = timeline(samples, None, dropped=none.dropped)
    fig = figures.log_over_time(tl)
    assert _spans(fig, "stop") == [] and len(_spans(fig, "still")) >= 12
    assert {t.get_text() for t in fig.axes[0].texts} & {str(k) for k in range(1, 13)} == set()
    assert any("not kept as a stop" in t.get_text() for t in fig.legends[0].get_texts())


def test_the_driving_intervals_used_are_marked(drive_log: Path) -> None:
    done = calibrate_log(drive_log)
    assert done.driving is not None and "driving" in done.used
    spans = done.driving.segments_s
    assert spans.shape == (done.driving.n_segments, 2) and np.all(spans[:, 1] > spans[:, 0])
    assert np.sum(spans[:, 1] - spans[:, 0]) == pytest.approx(done.driving.usable_s, rel=0.05)
    tl = timeline_of(done)
    assert tl.driving_use == done.used
    fig = figures.log_over_time(tl)
    drawn = _spans(fig, "driving")
    assert 1 <= len(drawn) <= done.driving.n_segments  # touching segments are drawn as one
    assert sum(p.get_width() for p in drawn) == pytest.approx(done.driving.usable_s, rel=0.05)
    assert any("driving fit" in t.get_text() for t in fig.legends[0].get_texts())
    if done.table is not None:
        assert len(_spans(fig, "stop")) == len(done.table)


# --- the command line ------------------------------------------------------------------------------


def test_calibrate_a_log_with_a_report_draws_it_and_report_from_the_json_says_it_cannot(tmp_path: Path) -> None:
    html, result = tmp_path / "r.html", tmp_path / "r.json"
    argv = ["calibrate", str(DATA / "parking.blf"), "--dbc", DBC, "--protocol", str(DATA / "parking_protocol.csv")]
    assert main([*argv, "-o", str(result), "--report", str(html)]) == 0
    page = html.read_text(encoding="utf-8")
    assert sorted(int(n) for n in STOP_ID.findall(page)) == list(range(1, 13))
    again = tmp_path / "again.html"
    assert main(["report", str(result), "-o", str(again)]) == 0
    page = again.read_text(encoding="utf-8")
    assert STOP_ID.findall(page) == []
    note = [p for p in page.splitlines() if "log over time" in p]
    assert len(note) == 1 and "mountcal calibrate LOG" in note[0] and "--report" in note[0]


def test_live_with_a_report_draws_the_session_over_time(tmp_path: Path) -> None:
    from mountcal.io import writers as export
    from mountcal.simulate.stops import simulate_parking_log

    beta = (0.0, 60.0, 120.0, 180.0, 240.0, 300.0)
    blf = tmp_path / "sim.blf"
    export.write_log(blf, simulate_parking_log(beta_deg=beta, stop_s=20.0, drive_s=10.0, seed=11), dbc_path=DBC)
    channel = "timeline-report"

    def feed() -> None:  # once the session's bus listens on the channel, send the recording
        from can.interfaces.virtual import channels

        deadline = time.monotonic() + 60.0
        while not channels.get(channel) and time.monotonic() < deadline:
            time.sleep(0.02)
        with can.Bus(interface="virtual", channel=channel, preserve_timestamps=True) as tx:
            for msg in can.LogReader(str(blf)):
                tx.send(msg)

    feeder = threading.Thread(target=feed, daemon=True)
    feeder.start()
    report = tmp_path / "live.html"
    argv = ["live", "--interface", "virtual", "--channel", channel, "--dbc", DBC, "--timeout", "1.0"]
    plan = tmp_path / "plan.csv"
    plan.write_text("t_start_s,t_end_s,beta_deg\n" + "".join(f"0,1,{b}\n" for b in beta), encoding="utf-8")
    code = main([*argv, "--plan", str(plan), "-o", str(tmp_path / "session"), "--report", str(report)])
    feeder.join(timeout=5.0)
    assert code == 0
    page = report.read_text(encoding="utf-8")
    assert sorted(int(n) for n in STOP_ID.findall(page)) == list(range(1, 7))


def test_a_timeline_is_a_frozen_value() -> None:
    t = np.arange(100) / 10.0
    tl = timeline(Samples(t, np.zeros((100, 3)), None, {}, source="x"))
    assert isinstance(tl, Timeline) and tl.stops == () and tl.driving_s == () and tl.speed_mps is None
    with pytest.raises(AttributeError):
        tl.source = "y"  # type: ignore[misc]


def test_numbers_too_close_to_read_are_left_out_and_counted() -> None:
    t = np.arange(0.0, 3600.0, 0.1)
    samples = Samples(t, np.zeros((t.size, 3)), None, {}, source="dense")
    starts = np.array([100.0, 110.0, 120.0, 2000.0])  # three within 1 % of an hour of each other
    table = StopTable(acc_s=np.zeros((4, 3)), t_s=starts, duration_s=np.full(4, 8.0))
    fig = figures.log_over_time(timeline(samples, table))
    assert len(_spans(fig, "stop")) == 4
    assert sorted(t.get_text() for t in fig.axes[0].texts) == ["1", "4"]
    assert "2 too close to the one before left unnumbered" in fig.axes[0].get_title(loc="left")
