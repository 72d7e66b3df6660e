"""A fleet of CANedge loggers: devices × sessions × 10-minute MF4 splits, in folders and in a real
S3-compatible server (moto's standalone server on 127.0.0.1, as s3fs's own tests use).

The sessions are written by python-can's MF4Writer (asammdf) and split at 10 minutes of the logger's
session with asammdf's own ``cut``/``save``, named as CANedge names them
(``LOG/<device>/<session>/<split counter>-<hex Unix start>.MF4``). A stop and a drive span split
boundaries; device ``B0C1D2E3`` is remounted (+2° of roll) after its second session.
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pandas as pd
import pytest
from tests.s3_server import comparable, s3_server

from mountcal.cli import main
from mountcal.core.result import Calibration
from mountcal.fleet import outputs_of
from mountcal.fleet.storage import _orphaned  # what the sweep judges, for a failure's message
from mountcal.fleet.store import PartStore

REPO = Path(__file__).resolve().parents[1]
DBC = REPO / "data" / "imu_mm5_10.dbc"
AZIMUTH = ("--uphill-azimuth-deg", "30")  # the simulator's uphill direction: yaw is determined
T0_UNIX_S = 1_714_557_600  # 2024-05-01T10:00:00Z
SPLIT_S = 600.0  # CANedge's default split: 10 minutes
STEADY, MOVED = "A1B2C3D4", "B0C1D2E3"
# device → sessions: (session folder, roll offset (deg), seconds the logger ran before the first stop)
SESSIONS = {
    STEADY: [("00000011", 0.0, 0.0), ("00000012", 0.0, 40.0)],
    MOVED: [("0000002A", 0.0, 0.0), ("0000002B", 0.0, 40.0), ("0000002C", 2.0, 0.0), ("0000002D", 2.0, 40.0)],
}
MOUNTING = {STEADY: (5.0, -3.0, 7.0), MOVED: (-4.0, 6.0, 30.0)}
RATE_HZ = 20.0


def write_session(folder: Path, angles: tuple[float, float, float], seed: int, lead_s: float, start_s: float) -> None:
    """One parking session (10 headings, 40 s stops, 25 s drives ≈ 10.5 min) as CANedge splits.

    The logger started ``lead_s`` before the first sample, so its 10-minute boundaries fall at
    600 − lead_s s into the recording: inside a stop (lead 0: stop 9 spans 585–625 s) or a drive
    (lead 40: the boundary at 560 s is in the drive 560–585 s).
    """
    from mountcal.io.writers import write_can_log
    from mountcal.simulate.stops import simulate_parking_log

    log = simulate_parking_log(
        *angles, beta_deg=tuple(range(0, 360, 36)), stop_s=40.0, drive_s=25.0, rate_hz=RATE_HZ, seed=seed
    )
    whole = folder.parent / f".{folder.name}.whole.mf4"
    folder.mkdir(parents=True, exist_ok=True)
    write_can_log(whole, log, dbc_path=DBC, start_time_s=start_s)
    cut_session(whole, folder, lead_s)
    whole.unlink()


def cut_session(whole: Path, folder: Path, lead_s: float) -> list[Path]:
    """Split an MF4 at the logger's 10-minute boundaries with asammdf's cut and save, CANedge's names."""
    from asammdf import MDF

    mdf = MDF(whole)
    start_s = mdf.header.start_time.timestamp()
    last = max(float(mdf.get_master(i)[-1]) for i, g in enumerate(mdf.groups) if g.channel_group.cycles_nr)
    written = []
    k = 0
    edge = -lead_s
    while edge < last:
        lo, hi = max(edge, 0.0), edge + SPLIT_S
        part = mdf.cut(start=lo, stop=hi - 1e-6, whence=0, include_ends=False)
        path = folder / f"{k + 1:08d}-{int(start_s + lo):08X}.MF4"
        saved = part.save(path.with_suffix(".mf4"), overwrite=True)  # asammdf writes the suffix in lower case
        part.close()
        Path(saved).rename(path)
        written.append(path)
        k, edge = k + 1, hi
    mdf.close()
    return written


@pytest.fixture(scope="module")
def canedge(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The LOG folder of the fleet, written in parallel (set-up, not the test)."""
    root = tmp_path_factory.mktemp("canedge") / "LOG"
    tasks = []
    for d, (device, sessions) in enumerate(SESSIONS.items()):
        for s, (session, roll_offset, lead_s) in enumerate(sessions):
            roll, pitch, yaw = MOUNTING[device]
            start = T0_UNIX_S + 86_400 * s + 3600 * d
            tasks.append((root / device / session, (roll + roll_offset, pitch, yaw), 100 * d + s, lead_s, start))
    with ProcessPoolExecutor(2) as pool:
        for future in [pool.submit(write_session, *t) for t in tasks]:
            future.result()
    return root


def run_cli(*args: str) -> tuple[int, str]:
    """The exit code and the summary (stderr) of a fleet run; stdout stays empty."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(["fleet", *args])
    assert out.getvalue() == ""
    return code, err.getvalue()


@pytest.fixture(scope="module")
def local_run(canedge: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    output = tmp_path_factory.mktemp("local") / "fleet.parquet"
    code, stdout = run_cli(str(canedge), "-o", str(output), "--dbc", str(DBC), *AZIMUTH, "--workers", "2")
    return {
        "code": code,
        "stdout": stdout,
        "output": output,
        "logs": pd.read_parquet(output),
        "vehicles": pd.read_parquet(outputs_of(output)[1]),
    }


def test_the_canedge_layout_is_inferred_and_a_device_is_a_vehicle_and_a_session_one_log(
    canedge: Path, local_run: dict
) -> None:
    logs: pd.DataFrame = local_run["logs"]
    assert local_run["code"] == 0
    n_splits = sum(len(list((canedge / d / s).glob("*.MF4"))) for d, ss in SESSIONS.items() for s, _, _ in ss)
    assert n_splits == 2 * 6  # every session was cut into two splits
    assert sorted(logs["vehicle_id"].unique()) == sorted(SESSIONS)
    assert len(logs) == 6 and (logs["status"] == "ok").all(), logs[["log", "error"]]
    assert sorted(logs["session"]) == sorted(s for ss in SESSIONS.values() for s, _, _ in ss)
    assert (logs["n_splits"] == 2).all() and (logs["split_gaps"] == 0).all() and (logs["split_overlaps"] == 0).all()
    assert set(logs["log"]) == {str(canedge / d / s) for d, ss in SESSIONS.items() for s, _, _ in ss}
    assert f"layout: canedge (6 logs); 2 vehicles, 6 sessions, {n_splits} splits (0 gaps" in local_run["stdout"]
    vehicles: pd.DataFrame = local_run["vehicles"]
    assert sorted(vehicles["vehicle_id"]) == sorted(SESSIONS) and vehicles["vehicle_id"].is_unique  # one row each


def test_the_remount_is_found_at_the_right_session_and_the_steady_device_has_none(local_run: dict) -> None:
    vehicles = local_run["vehicles"].set_index("vehicle_id")
    assert vehicles.loc[STEADY, "n_remounts"] == 0 and vehicles.loc[STEADY, "latest_confident"]
    moved = vehicles.loc[MOVED]
    assert moved["n_remounts"] == 1
    (remount,) = moved["remounts"]
    assert remount["log"].endswith("/0000002C")
    assert remount["time"] == pd.Timestamp(T0_UNIX_S + 2 * 86_400 + 3600, unit="s", tz="UTC").floor("s")
    assert abs(remount["change_deg"] - 2.0) < 5 * remount["change_sigma_deg"] + 0.02
    assert moved["roll_deg"] == pytest.approx(MOUNTING[MOVED][0] + 2.0, abs=0.1)  # the latest mounting
    assert [m["roll_deg"] for m in moved["mountings"]] == pytest.approx([-4.0, -2.0], abs=0.1)
    assert f"remount {MOVED} at" in local_run["stdout"]


def test_the_overview_page_shows_each_vehicle_its_angles_over_time_and_its_remount(local_run: dict) -> None:
    page = local_run["output"].with_name("fleet_overview.html").read_text(encoding="utf-8")
    assert page.count("<svg") == 2  # a plot per vehicle
    rows = {row.split("</td>")[0]: row for row in page.split("<tr><td>")[1:]}
    assert set(rows) == {STEADY, MOVED}
    assert "2024-05-03 11:00 (2.0" in rows[MOVED] and "confident" in rows[MOVED]  # the remount: time and size
    assert "none" in rows[STEADY]
    assert page.index(MOVED) < page.index(STEADY)  # remounted vehicles come first


def test_a_session_calibrates_exactly_as_calibrate_does_on_its_joined_splits(
    canedge: Path, local_run: dict, tmp_path: Path
) -> None:
    session = canedge / MOVED / "0000002B"  # its 10-minute boundary falls in a drive
    splits = sorted(session.glob("*.MF4"))
    result = tmp_path / "session.json"
    assert main(["calibrate", *map(str, splits), "--dbc", str(DBC), *AZIMUTH, "-o", str(result), "-q"]) == 0
    single = Calibration.load(result)
    row = local_run["logs"].set_index("log").loc[str(session)]
    assert row["calibrated_from"] == (single.fit.calibrated_from or "stops")
    assert single.yaw_deg is not None
    for angle in ("roll", "pitch", "yaw"):
        assert row[f"{angle}_deg"] == pytest.approx(getattr(single, f"{angle}_deg"), abs=1e-9)
        assert row[f"{angle}_sigma_deg"] == pytest.approx(getattr(single, f"{angle}_sigma_deg"), abs=1e-9)


def test_splits_uploaded_twice_or_compressed_are_counted_and_a_mixed_folder_asks_for_a_layout(
    canedge: Path, tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    fleet = tmp_path / "LOG"
    shutil.copytree(canedge / STEADY, fleet / STEADY)
    session = fleet / STEADY / "00000011"
    first = sorted(session.glob("*.MF4"))[0]
    shutil.copy(first, session / (first.name[:8] + "-FFFFFFFF.MF4"))  # the same split counter, uploaded again
    (session / "00000003.MFC").write_bytes(b"compressed")
    output = tmp_path / "fleet.parquet"
    code, _ = run_cli(str(fleet), "-o", str(output), "--dbc", str(DBC), "--workers", "1")
    assert code == 0
    assert "set aside 1 CANedge splits uploaded twice" in caplog.text
    assert "set aside 1 compressed or encrypted CANedge splits" in caplog.text
    logs = pd.read_parquet(output)
    assert len(logs) == 2 and (logs["n_splits"] == 2).all()

    (fleet / "loose.mf4").write_bytes(first.read_bytes())  # a file outside the layout
    code, _ = run_cli(str(fleet), "-o", str(tmp_path / "mixed.parquet"), "--dbc", str(DBC))
    assert code == 2 and "--layout canedge" in caplog.text and "1 not" in caplog.text


# --- the same fleet in a real S3-compatible server --------------------------------------------------


@pytest.fixture(scope="module")
def s3(canedge: Path) -> Iterator[dict[str, str]]:
    """moto's standalone S3 server on 127.0.0.1 with the fleet uploaded to s3://fleet/LOG."""
    with s3_server(canedge, "fleet") as (env, _):
        yield env


def test_the_fleet_from_the_s3_server_gives_the_local_table(
    canedge: Path, local_run: dict, s3: dict[str, str], tmp_path: Path
) -> None:
    output = tmp_path / "s3.parquet"
    code, stdout = run_cli("s3://fleet/LOG", "-o", str(output), "--dbc", str(DBC), *AZIMUTH, "-q", "--workers", "2")
    assert code == 0, stdout
    logs = pd.read_parquet(output)
    assert set(logs["log"]) == {f"s3://fleet/LOG/{d}/{s}" for d, ss in SESSIONS.items() for s, _, _ in ss}
    assert logs["content_hash"].isin(local_run["logs"]["content_hash"]).sum() == 0  # keyed by ETag, not bytes
    pd.testing.assert_frame_equal(
        comparable(logs, "s3://fleet/LOG"), comparable(local_run["logs"], str(canedge)), check_exact=True
    )
    vehicles = pd.read_parquet(outputs_of(output)[1])
    assert (
        vehicles.drop(columns=["remounts", "mountings"])
        .pipe(comparable, "s3://fleet/LOG")
        .equals(local_run["vehicles"].drop(columns=["remounts", "mountings"]).pipe(comparable, str(canedge)))
    )

    # a killed worker's copies (its lock free) go at the end of a run even when it fetches nothing
    left = Path(tempfile.mkdtemp(prefix=f"mountcal-fetch-{os.getpid()}-"))
    (left / ".held").touch()
    code, stdout = run_cli("s3://fleet/LOG", "-o", str(output), "--dbc", str(DBC), *AZIMUTH, "-q", "--workers", "2")
    assert code == 0 and "0 calibrated now" in stdout and not left.exists()


def test_a_bad_endpoint_or_bucket_is_a_message_not_a_traceback(
    s3: dict[str, str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = str(tmp_path / "x.parquet")
    assert main(["fleet", "s3://no-such-bucket/LOG", "-o", out, "-q"]) == 2
    err = capsys.readouterr().err
    assert "s3://no-such-bucket/LOG" in err and "Traceback" not in err
    assert main(["fleet", "s3://fleet/LOG", "-o", out, "--storage-option", "endpoint_url", "-q"]) == 2
    assert "KEY=VALUE" in capsys.readouterr().err


def test_a_run_against_the_bucket_killed_mid_run_resumes_losing_and_repeating_nothing(
    canedge: Path, s3: dict[str, str], tmp_path: Path
) -> None:
    output = tmp_path / "fleet.parquet"
    parts = outputs_of(output)[2]
    env = {**os.environ, **s3, "PYTHONPATH": str(REPO / "src")}
    endpoint = s3["AWS_ENDPOINT_URL"]
    command = [sys.executable, "-m", "mountcal", "fleet", "s3://fleet/LOG", "-o", str(output), "--dbc", str(DBC)]
    command += [*AZIMUTH, "--workers", "2", "--storage-option", f"endpoint_url={endpoint}"]
    proc = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 300
        while len(list(parts.glob("*.json"))) < 2 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        workers = _children(proc.pid)
        proc.send_signal(signal.SIGKILL)  # the command alone: its workers must follow it
        stdout, _ = proc.communicate(timeout=30)  # returns once no process holds the pipe
        assert stdout == b""
    finally:
        proc.kill()
        proc.wait()
    assert not output.exists(), "the run finished before it could be killed"
    assert workers and _gone(workers, within_s=10.0), "workers outlived the killed command"
    before = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in parts.glob("*.json")}
    stored, unreadable = PartStore(parts).load()
    assert 2 <= len(before) < 6 and unreadable == 0 and len(stored) == len(before)

    code, stdout = run_cli("s3://fleet/LOG", "-o", str(output), "--dbc", str(DBC), *AZIMUTH, "-q", "--workers", "2")
    assert code == 0
    assert f"{6 - len(before)} calibrated now, {len(before)} from earlier runs" in stdout
    after = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in parts.glob("*.json")}
    assert all(after[name] == stamp for name, stamp in before.items())  # nothing finished was redone
    table = pd.read_parquet(output)
    assert len(table) == 6 and table["log"].is_unique and (table["status"] == "ok").all()
    scratch = Path(tempfile.gettempdir())
    left = [f for pid in workers for f in scratch.glob(f"mountcal-fetch-{pid}-*")]  # the killed ones' copies
    assert not left, [(str(f), sorted(p.name for p in f.rglob("*")), f"orphaned now: {_orphaned(f)}") for f in left]


def _children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` or one of its children (the worker server and its workers)."""
    found, frontier = [], [pid]
    while frontier:
        parent = frontier.pop()
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit():
                with contextlib.suppress(OSError):
                    fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
                    if int(fields[1]) == parent:
                        found.append(int(entry.name))
                        frontier.append(int(entry.name))
    return found


def _gone(pids: list[int], within_s: float) -> bool:
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        alive = [p for p in pids if Path(f"/proc/{p}").exists() and "Z" not in _state(p)]
        if not alive:
            return True
        time.sleep(0.05)
    return False


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return "Z"


# --- a real CANedge recording ---------------------------------------------------------------------


@pytest.mark.real_data
def test_a_real_canedge_drive_split_at_10_minutes_calibrates_as_the_unsplit_file(
    real_data: Path, tmp_path: Path
) -> None:
    """The CANedge car's second drive (5 logger splits, 46 min), joined into one MF4 by asammdf's
    ``concatenate``, then split again at 10 minutes with asammdf's ``cut``/``save`` into a session
    folder: the fleet's session gives the unsplit file's calibration, every frame kept."""
    from asammdf import MDF

    canedge = real_data / "canedge"
    drive = sorted((canedge / "3BA199E2_car_DK_2021-07-26" / "00000165").glob("*.MF4"))[:5]  # one power cycle
    joined = MDF.concatenate(drive)
    whole = Path(joined.save(tmp_path / "whole.mf4", overwrite=True))
    joined.close()
    session = tmp_path / "LOG" / "3BA199E2" / "00000165"
    splits = cut_session(whole, session, lead_s=0.0)
    assert len(splits) == 5

    def frames(path: Path) -> int:
        mdf = MDF(path)
        try:
            return sum(int(g.channel_group.cycles_nr) for g in mdf.groups)
        finally:
            mdf.close()

    assert sum(map(frames, splits)) == frames(whole)
    dbc = str(canedge / "dbc" / "gnss.dbc")
    result = tmp_path / "whole.json"
    assert main(["calibrate", str(whole), "--dbc", dbc, "--channel", "2", "-o", str(result), "-q"]) == 0
    single = Calibration.load(result)
    output = tmp_path / "fleet.parquet"
    code, stdout = run_cli(str(tmp_path / "LOG"), "-o", str(output), "--dbc", dbc, "--channel", "2", "--workers", "1")
    assert code == 0 and "layout: canedge (1 logs); 1 vehicles, 1 sessions, 5 splits (0 gaps" in stdout
    row = pd.read_parquet(output).iloc[0]
    assert row["status"] == "ok" and row["vehicle_id"] == "3BA199E2" and row["n_splits"] == 5
    assert single.yaw_deg is not None and row["calibrated_from"] == single.fit.calibrated_from
    for angle in ("roll", "pitch", "yaw"):
        assert row[f"{angle}_deg"] == pytest.approx(getattr(single, f"{angle}_deg"), abs=1e-9)
        assert row[f"{angle}_sigma_deg"] == pytest.approx(getattr(single, f"{angle}_sigma_deg"), abs=1e-9)


def test_a_fetch_folder_is_removed_once_its_owner_is_gone_even_if_its_pid_lives(tmp_path: Path) -> None:
    """A killed worker's scratch folder goes with the next fetch; a pid is no proof (pids are reused), its lock is."""
    import fcntl

    from mountcal.fleet.storage import SCRATCH_LOCK, SCRATCH_PREFIX, remove_orphans

    alive = os.getpid()  # a live pid: the folder's owner died and its pid went to another process
    left = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{alive}-"))
    (left / SCRATCH_LOCK).touch()
    held_by_us = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{alive}-"))
    (held_by_us / SCRATCH_LOCK).touch()
    starting = Path(tempfile.mkdtemp(prefix=f"{SCRATCH_PREFIX}{alive}-"))  # no lock yet: its pid decides
    with open(held_by_us / SCRATCH_LOCK) as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        assert remove_orphans() == 1
        assert not left.exists() and held_by_us.exists() and starting.exists()
    for folder in (held_by_us, starting):
        shutil.rmtree(folder)
