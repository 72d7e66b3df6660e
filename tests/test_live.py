"""`mountcal live` on python-can's virtual bus: the session's answer is `calibrate` on its recording."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path
from typing import Any

import can
import numpy as np
import pandas as pd
import pytest

from mountcal.calibration.fit import Calibration, Options, calibrate
from mountcal.calibration.pipeline import LogJob, calibrate_job
from mountcal.cli import main
from mountcal.core.errors import InputError, NotEnoughInformation
from mountcal.core.option_names import as_flags
from mountcal.estimate.bound import crb_deg, true_state
from mountcal.io import writers as export
from mountcal.io.reader import LogOptions
from mountcal.io.sensor_spec import SensorSpec
from mountcal.sessions.live import CANDIDATES_DEG, Live, LiveOptions, Session, fail_if_empty, next_heading
from mountcal.simulate.stops import simulate_parking_log, simulate_stops
from mountcal.stops.detect import StopDetection
from mountcal.stops.table import StopTable

DATA = Path(__file__).resolve().parents[1] / "data"
DBC, MAPPING = str(DATA / "imu_mm5_10.dbc"), str(DATA / "imu_mm5_10.toml")
BETA = (0.0, 60.0, 120.0, 180.0, 240.0, 300.0)


@pytest.fixture(scope="module")
def sim_blf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short simulated parking session, written as BLF by the project's writer."""
    log = simulate_parking_log(beta_deg=BETA, stop_s=20.0, drive_s=10.0, seed=11)
    path = tmp_path_factory.mktemp("sim") / "parking.blf"
    export.write_log(path, log, dbc_path=DBC, with_fix=(56.15, 10.2, 40.0))
    return path


def replay(
    path: Path, channel: str, extra: list[can.Message] | None = None, first: list[can.Message] | None = None
) -> can.BusABC:
    """A receiving virtual bus with every frame of ``path`` queued (faster than real time), after ``first``
    and before ``extra``."""
    rx = can.Bus(interface="virtual", channel=channel)
    with can.Bus(interface="virtual", channel=channel, preserve_timestamps=True) as tx:
        for msg in first or []:
            tx.send(msg)
        with can.LogReader(str(path)) as reader:
            for msg in reader:
                tx.send(msg)
        for msg in extra or []:
            tx.send(msg)
    return rx


def run_session(bus: can.BusABC, opts: LiveOptions, recording: Path) -> tuple[Session, list[dict[str, Any]]]:
    events: list[dict[str, Any]] = []
    try:
        return Live(opts, recording, events.append).run(bus), events
    finally:
        bus.shutdown()


def offline(
    recording: Path, session: Session, log: LogOptions, uphill: float | None = None, options: Options | None = None
) -> Calibration:
    """`calibrate` on the recording, with the protocol sheet the session wrote on the log's clock."""
    sheet = None
    if session.protocol is not None:
        sheet = recording.with_suffix(".protocol.csv")
        session.protocol.to_csv(sheet, index=False, float_format="%.17g")
    job = LogJob(paths=(str(recording),), log=log, protocol=None if sheet is None else str(sheet),
                 uphill_azimuth_deg=uphill, options=options or Options())  # fmt: skip
    done = calibrate_job(job)
    assert session.table is not None
    assert len(done.table) == len(session.table)
    assert np.array_equal(done.table.acc_s, session.table.acc_s)  # the same stops, sample for sample
    return done.calibration


def assert_same(a: Calibration, b: Calibration) -> None:
    """The session's result ``a`` is calibrate's ``b``: the angles and σ, and what the pipeline adds to a fit —
    the verdict, the model, the checks, the conventions (their ``by`` aside: the session states its own sheet),
    the notes and the unexplained findings."""
    for name in ("roll_deg", "pitch_deg", "yaw_deg", "roll_sigma_deg", "pitch_sigma_deg", "yaw_sigma_deg"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert abs(x - y) < 1e-6, name
    assert (a.confident, a.model) == (b.confident, b.model)
    assert [(c.name, c.passed) for c in a.checks] == [(c.name, c.passed) for c in b.checks]
    conventions = [[(c.name, c.value, c.how) for c in x.provenance.conventions] for x in (a, b)]
    assert conventions[0] == conventions[1]
    assert a.notes == b.notes
    assert [u.test for u in a.unexplained] == [u.test for u in b.unexplained]


def test_a_replayed_simulated_session_gives_calibrate_on_its_recording(sim_blf: Path, tmp_path: Path) -> None:
    bus = replay(sim_blf, "sim")
    opts = LiveOptions(DBC, MAPPING, target_deg={"roll": 1e-4}, plan_beta_deg=BETA, silence_s=0.5)
    session, events = run_session(bus, opts, tmp_path / "rec.blf")
    assert session.reason == "bus silent"
    stops = [e for e in events if e["event"] == "stop"]
    assert [e["beta_deg"] for e in stops] == list(BETA)
    fits = [e for e in events if e["event"] == "fit"]
    assert len(fits) >= len(BETA) - 2  # a refit after each stop once three headings are in
    assert session.calibration is not None
    assert_same(session.calibration, offline(tmp_path / "rec.blf", session, LogOptions(dbc=DBC, mapping=MAPPING)))
    truth = simulate_parking_log(beta_deg=BETA, stop_s=20.0, drive_s=10.0, seed=11).truth.angles_deg
    assert abs(session.calibration.roll_deg - truth[0]) < 5 * session.calibration.roll_sigma_deg


def test_the_target_ends_the_session_early(sim_blf: Path, tmp_path: Path) -> None:
    bus = replay(sim_blf, "early")
    # a calibrated sensor's limits: with the default class's (±3 % scale) no number of stops gets the tilt to 0.5°
    tight = Options(spec=SensorSpec(scale=1e-3, cross_axis=1e-3, bias_mps2=0.01, source="test: a calibrated part"))
    opts = LiveOptions(
        DBC, MAPPING, target_deg={"roll": 0.5, "pitch": 0.5}, options=tight, plan_beta_deg=BETA, silence_s=0.5
    )
    session, events = run_session(bus, opts, tmp_path / "rec.blf")
    assert session.reason == "target met" and events[-2]["event"] == "target_met"
    assert session.table is not None and len(session.table) < len(BETA)
    log = LogOptions(dbc=DBC, mapping=MAPPING)
    assert_same(session.calibration, offline(tmp_path / "rec.blf", session, log, options=tight))  # type: ignore[arg-type]


def test_a_target_below_the_sensor_s_systematic_part_is_said_to_be_unreachable(sim_blf: Path, tmp_path: Path) -> None:
    bus = replay(sim_blf, "unreachable")
    opts = LiveOptions(DBC, MAPPING, target_deg={"roll": 0.1, "pitch": 0.1}, plan_beta_deg=BETA, silence_s=0.5)
    session, events = run_session(bus, opts, tmp_path / "rec.blf")  # the default class: ~0.6° of tilt
    told = [e for e in events if e["event"] == "target_unreachable"]
    assert len(told) == 1 and set(told[0]["systematic_deg"]) == {"roll", "pitch"}
    assert all(v > 0.1 for v in told[0]["systematic_deg"].values())
    assert session.reason == "bus silent" and not any(e["event"] == "target_met" for e in events)


def test_frames_with_a_wrong_dlc_are_counted_and_recorded(sim_blf: Path, tmp_path: Path) -> None:
    with can.LogReader(str(sim_blf)) as reader:
        first = next(m for m in reader if m.arbitration_id == 0x70)  # MM5_10_TX1: AY1 in 8 bytes
    short = [
        can.Message(timestamp=first.timestamp + 0.0005 + 0.01 * k, arbitration_id=first.arbitration_id,
                    is_extended_id=first.is_extended_id, data=bytes(first.data[:2]))
        for k in range(7)
    ]  # fmt: skip
    bus = replay(sim_blf, "dlc", extra=short)
    opts = LiveOptions(DBC, MAPPING, target_deg={"roll": 1e-4}, plan_beta_deg=BETA, silence_s=0.5)
    session, _ = run_session(bus, opts, tmp_path / "rec.blf")
    counted = {k: v for k, v in session.dropped.items() if "shorter than the DBC layout" in k}
    assert sum(counted.values()) == 7
    with can.BLFReader(str(tmp_path / "rec.blf")) as reader:
        recorded = [m for m in reader if m.arbitration_id == 0x70 and len(m.data) == 2]
    assert len(recorded) == 7


def test_a_silent_bus_ends_with_a_message_and_keeps_the_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    prefix = tmp_path / "quiet"
    code = main(["live", "--interface", "virtual", "--channel", "silent", "--dbc", DBC, "--timeout", "0.3",
                 "-o", str(prefix)])  # fmt: skip
    captured = capsys.readouterr()
    assert code == NotEnoughInformation.exit_code
    assert captured.out == ""  # the events are shown on stderr, as they come
    assert "bus silent for 0.3 s" in captured.err and "the recording is kept" in captured.err
    assert prefix.with_suffix(".blf").is_file()
    with can.BLFReader(str(prefix.with_suffix(".blf"))) as reader:
        assert list(reader) == []


def test_the_suggested_heading_is_the_best_of_a_brute_force_search() -> None:
    headings = (0.0, 30.0, 100.0, 200.0)  # four: with three, the bias term is refused as not separable from the tilt
    table, truth = simulate_stops(3.0, -2.0, 40.0, slope_deg=4.0, beta_deg=headings, noise_g=0.002, seed=3)
    fit = calibrate(table, Options(model="rotation,slope,bias"))
    assert fit.slope_deg is not None and fit.bias_mps2 is not None and table.cov_s is not None
    target = {"roll": 0.1, "pitch": 0.1, "yaw": 0.5}
    chosen = next_heading(table, fit, target)
    state = true_state(fit.rot_vs, fit.slope_deg, fit.gravity_mps2, bias_mps2=fit.bias_mps2)
    alpha = np.radians(fit.slope_deg)
    worst = {}
    for beta in CANDIDATES_DEG:  # brute force: every candidate's bound from scratch
        b = np.radians(beta)
        f_v = fit.gravity_mps2 * np.array([np.sin(alpha) * np.cos(b), -np.sin(alpha) * np.sin(b), np.cos(alpha)])
        grown = StopTable(
            acc_s=np.vstack([table.acc_s, fit.rot_vs.inv().apply(f_v) + fit.bias_mps2]),
            beta_rad=np.radians([*truth.beta_deg, beta]),
            cov_s=np.concatenate([table.cov_s, table.cov_s.mean(axis=0)[None]]),
        )
        crb = crb_deg(grown, state, ("rotation", "slope", "bias"), fit.gravity_mps2)
        assert crb is not None
        worst[beta] = max(float(crb[f"{a}_deg"]) / t for a, t in target.items())  # type: ignore[arg-type]
    assert chosen == min(worst, key=worst.__getitem__)
    assert min(worst.values()) < 0.9 * max(worst.values())  # and the choice matters


CTRL_C_SCRIPT = textwrap.dedent(
    """
    import sys, threading, time
    import can
    from mountcal.cli import main

    def feed():
        time.sleep(1.0)  # the session's bus is open by then
        with can.Bus(interface="virtual", channel="ctrlc", preserve_timestamps=True) as tx:
            for msg in can.LogReader(sys.argv[1]):
                tx.send(msg)
                time.sleep(0.0002)  # ≈ 50× real time
    threading.Thread(target=feed, daemon=True).start()
    argv = ["live", "--interface", "virtual", "--channel", "ctrlc", "--dbc", sys.argv[2], "--mapping", sys.argv[3]]
    sys.exit(main([*argv, "--plan", sys.argv[4], "--target", "roll=0.0001", "--timeout", "60", "-o", sys.argv[5],
                  "--json-events", sys.argv[5] + ".jsonl"]))
    """
)


def test_ctrl_c_keeps_the_recording_and_what_was_measured(sim_blf: Path, tmp_path: Path) -> None:
    plan = tmp_path / "plan.csv"
    pd.DataFrame({"t_start_s": np.zeros(6), "t_end_s": np.ones(6), "beta_deg": BETA}).to_csv(plan, index=False)
    prefix = tmp_path / "session"
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src")}
    proc = subprocess.Popen(
        [sys.executable, "-c", CTRL_C_SCRIPT, str(sim_blf), DBC, MAPPING, str(plan), str(prefix)],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip
    assert proc.stderr is not None
    deadline = time.monotonic() + 120
    for line in proc.stderr:  # wait until four stops are in, then Ctrl-C (the events are on stderr)
        if line.startswith("STOP 4 ended") or time.monotonic() > deadline:
            break
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert out == "" and "interrupted: keeping what was measured" in err
    events = [json.loads(line) for line in prefix.with_suffix(".jsonl").read_text(encoding="utf-8").splitlines()]
    kinds = [e["event"] for e in events]
    assert kinds[0] == "started" and kinds[-1] == "ended" and "interrupted" in kinds
    assert kinds.count("stop") >= 4 and events[-1]["reason"] == "interrupted"
    result = Calibration.load(prefix.with_suffix(".json"))
    job = LogJob(paths=(str(prefix.with_suffix(".blf")),), log=LogOptions(dbc=DBC, mapping=MAPPING),
                 protocol=str(prefix.with_name("session_protocol.csv")))  # fmt: skip
    with as_flags():  # what `mountcal calibrate` says: the session's notes name the options as flags too
        offline_result = calibrate_job(job).calibration
    assert_same(result, offline_result)


def test_a_replayed_real_canedge_log_gives_calibrate_on_its_recording(real_data: Path, tmp_path: Path) -> None:
    log = real_data / "canedge" / "3BA199E2_car_DK_2021-07-26" / "00000165" / "00000001-60FEB68B.MF4"
    dbc = str(real_data / "canedge" / "dbc" / "gnss.dbc")
    bus = replay(log, "real")
    opts = LiveOptions(dbc, target_deg={"roll": 1e-4}, uphill_azimuth_deg=0.0, silence_s=0.5,
                       detection=StopDetection())  # fmt: skip
    session, events = run_session(bus, opts, tmp_path / "rec.blf")
    assert session.calibration is not None and len([e for e in events if e["event"] == "stop"]) >= 3
    assert_same(session.calibration, offline(tmp_path / "rec.blf", session, LogOptions(dbc=dbc), uphill=0.0))


def test_a_mapped_message_missing_from_the_whole_session_gives_no_result_as_offline(tmp_path: Path) -> None:
    log = simulate_parking_log(beta_deg=BETA[:3], stop_s=20.0, drive_s=10.0, seed=12)
    path = tmp_path / "nofix.blf"
    export.write_log(path, log, dbc_path=DBC)  # no GNSS position, which the mapping names
    bus = replay(path, "nofix")
    opts = LiveOptions(DBC, MAPPING, target_deg={"roll": 1e-4}, plan_beta_deg=BETA, silence_s=0.5)
    session, events = run_session(bus, opts, tmp_path / "rec.blf")
    assert session.calibration is None
    assert "SIM_GNSS_POSITION" in events[-2]["why"]
    with pytest.raises(NotEnoughInformation, match="the recording is kept"):
        fail_if_empty(session)
    with pytest.raises(InputError, match="SIM_GNSS_POSITION"):
        calibrate_job(LogJob(paths=(str(tmp_path / "rec.blf"),), log=LogOptions(dbc=DBC, mapping=MAPPING)))


# ------------------------------------------------------------------ faults (issue 27): stamps, timeout, disk, crash


def test_frames_with_stamps_a_recording_cannot_hold_are_counted_and_the_session_kept(
    sim_blf: Path, tmp_path: Path
) -> None:
    with can.LogReader(str(sim_blf)) as reader:
        first = next(iter(reader))
    bad = [np.nan, np.inf, -np.inf, 1e12, first.timestamp + 1e12, -5.0, 3e11]
    frames = [can.Message(timestamp=t, arbitration_id=first.arbitration_id, is_extended_id=first.is_extended_id,
                          data=bytes(first.data)) for t in bad]  # fmt: skip
    bus = replay(sim_blf, "stamps", extra=frames, first=frames[:3])
    opts = LiveOptions(DBC, MAPPING, target_deg={"roll": 1e-4}, plan_beta_deg=BETA, silence_s=0.5)
    session, _ = run_session(bus, opts, tmp_path / "rec.blf")
    assert session.reason == "bus silent" and session.calibration is not None
    refused = {k: v for k, v in session.dropped.items() if "timestamp" in k}
    assert sum(refused.values()) == 3 + len(bad), session.dropped
    with can.BLFReader(str(tmp_path / "rec.blf")) as reader:
        recorded = list(reader)
    assert all(np.isfinite(m.timestamp) and m.timestamp < 1e11 for m in recorded)
    assert len(recorded) == session.frames
    assert_same(session.calibration, offline(tmp_path / "rec.blf", session, LogOptions(dbc=DBC, mapping=MAPPING)))


@pytest.mark.parametrize("timeout", ["-1", "0", "nan", "inf"])
def test_a_timeout_that_is_not_a_positive_number_is_a_message(
    timeout: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    try:
        code = main(["live", "--interface", "virtual", "--channel", "t", "--dbc", DBC, "--timeout", timeout,
                     "-o", str(tmp_path / "s")])  # fmt: skip
    except SystemExit as refused:  # by the parser: --timeout is a duration of mountcal.core.ranges
        code = refused.code
    err = capsys.readouterr().err
    assert code == 2 and "--timeout" in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


LIVE_SCRIPT = textwrap.dedent(
    """
    import sys, threading, time
    import can
    from mountcal.cli import main

    def feed():
        time.sleep(1.0)  # the session's bus is open by then
        with can.Bus(interface="virtual", channel=sys.argv[2], preserve_timestamps=True) as tx:
            for msg in can.LogReader(sys.argv[1]):
                tx.send(msg)
                time.sleep(0.0002)  # ≈ 50× real time
    threading.Thread(target=feed, daemon=True).start()
    sys.exit(main(["live", "--interface", "virtual", "--channel", sys.argv[2], *sys.argv[3:]]))
    """
)


def live_process(blf: Path, channel: str, *args: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1] / "src")}
    return subprocess.Popen(
        [sys.executable, "-c", LIVE_SCRIPT, str(blf), channel, *args],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
    )  # fmt: skip


def frames_read(recording: Path) -> int:
    """The frames mountcal's own reader gives (it refuses a file cut inside a block)."""
    from mountcal.io.can.files import read_frames

    return len(read_frames(recording).t_s)


def on_the_bus_clock(recording: Path, sent: Path) -> bool:
    """Whether the recording's first frame has the stamp of a frame sent (its header's start is the bus's)."""
    from mountcal.io.can.files import read_frames

    first = read_frames(recording).t_s[0]
    return bool(np.min(np.abs(read_frames(sent).t_s - first)) < 1e-4)


def test_a_full_disk_keeps_a_readable_recording_and_says_so(sim_blf: Path) -> None:
    from tests.test_hostile_paths import small_tmpfs

    with small_tmpfs("96k") as folder:
        proc = live_process(sim_blf, "full", "--dbc", DBC, "--mapping", MAPPING, "--timeout", "3",
                            "-o", str(folder / "session"))  # fmt: skip
        out, err = proc.communicate(timeout=300)
        assert proc.returncode == 5, out + err
        assert "No space left on device" in err and "Traceback" not in err
        assert "no partial file was left" not in err
        recording = folder / "session.blf"
        assert "session.blf" in err and "kept" in err
        n = frames_read(recording)
        assert 0 < n < 54910  # a prefix of the session, as far as the disk held
        assert on_the_bus_clock(recording, sim_blf)
        with can.BLFReader(str(recording)) as reader:
            assert sum(1 for _ in reader) == n
        assert [p.name for p in folder.iterdir()] == ["session.blf"]  # no partial result, table or sheet


def test_a_killed_session_leaves_a_readable_recording(sim_blf: Path, tmp_path: Path) -> None:
    prefix = tmp_path / "killed"
    proc = live_process(sim_blf, "killed", "--dbc", DBC, "--mapping", MAPPING, "--timeout", "60", "-o", str(prefix))
    assert proc.stderr is not None
    deadline = time.monotonic() + 120
    for line in proc.stderr:
        if line.startswith("STOP 2 ended") or time.monotonic() > deadline:
            break
    proc.kill()
    proc.communicate(timeout=60)
    n = frames_read(prefix.with_suffix(".blf"))
    assert n > 1000  # every whole block written before the kill
    assert on_the_bus_clock(prefix.with_suffix(".blf"), sim_blf)  # the header was kept current


def test_the_recording_reads_whole_at_every_moment_it_can_be_cut(tmp_path: Path) -> None:
    """Each state the file passes through on disk (after each container and header) is a BLF both readers
    read to the same frames, every frame whole: what a kill at that moment leaves."""
    from mountcal.io.can.bus import Recording
    from mountcal.io.can.files import read_frames

    rng = np.random.default_rng(4)
    path = tmp_path / "rec.blf"
    recording = Recording(path)
    states, t = [], 1714557600.0
    for k in range(40_000):
        t += float(rng.uniform(0, 2e-3))
        size = int(rng.choice([0, 3, 8]))
        recording.add(can.Message(timestamp=t, arbitration_id=int(rng.integers(0, 0x7FF)), data=bytes(size),
                                  is_error_frame=k % 997 == 0))  # fmt: skip
        if recording.file.size != (states[-1][0] if states else 0):
            states.append((recording.file.size, path.read_bytes()))
    recording.close()
    states.append((path.stat().st_size, path.read_bytes()))
    assert len(states) > 5
    counts = []
    for i, (_, data) in enumerate(states):
        cut = tmp_path / f"cut{i}.blf"
        cut.write_bytes(data)
        with can.BLFReader(str(cut)) as reader:
            theirs = [m for m in reader if not m.is_error_frame]
        ours = read_frames(cut)
        assert len(ours.t_s) == len(theirs)
        if theirs:
            assert abs(ours.t_s[0] - theirs[0].timestamp) < 1e-6 and abs(ours.t_s[0] - 1714557600.0) < 1
        counts.append(len(theirs))
    assert counts == sorted(counts) and counts[-1] == 40_000 - len(range(0, 40_000, 997))
