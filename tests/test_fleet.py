"""The fleet runner end to end: real logs, real worker processes, a real Dask cluster, real kills.

The logs are simulated but written by real writers: stop tables (``write_stop_table``), sample
tables (pandas CSV/Parquet), ROS 2 MCAP (``mcap_ros2.writer``) and a BLF (python-can).
"""

from __future__ import annotations

import contextlib
import io
import multiprocessing
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mountcal.cli import main
from mountcal.core.result import Calibration
from mountcal.fleet import FleetOptions, JobDefaults, LocalEngine, collect_jobs, outputs_of, run_fleet
from mountcal.fleet.engines import TRANSIENT
from mountcal.fleet.progress import Progress
from mountcal.fleet.store import HASH_BLOCK, PartStore, file_digest, job_hash
from mountcal.fleet.worker import run_job
from mountcal.io import writers as export
from mountcal.simulate.stops import ParkingLog, simulate_parking_log, simulate_stops
from mountcal.stops.table import write_stop_table

TRUTH = (5.0, 6.0, 7.0)
UPHILL_AZIMUTH_DEG = 30.0
T0_UNIX_S = 1_714_557_600  # 2024-05-01T10:00:00Z


# --- writing simulated logs with real writers ------------------------------------------------------


def parking(seed: int, rate_hz: float = 100.0) -> ParkingLog:
    """A parking session of a few minutes: 8 headings, 25 s stops."""
    return simulate_parking_log(
        *TRUTH, beta_deg=tuple(range(0, 360, 45)), stop_s=25.0, drive_s=12.0, rate_hz=rate_hz, seed=seed
    )


def sample_frame(log: ParkingLog) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "t_s": log.t_s,
            "ax": log.acc_s[:, 0],
            "ay": log.acc_s[:, 1],
            "az": log.acc_s[:, 2],
            "gx": log.gyro_s[:, 0],
            "gy": log.gyro_s[:, 1],
            "gz": log.gyro_s[:, 2],
            "speed_mps": log.speed_mps,
            "heading_deg": log.heading_deg,
            "temperature_c": log.temperature_c,
        }
    )


def write_mcap(path: Path, log: ParkingLog) -> None:
    """ROS 2 Imu messages stamped in Unix time, and the protocol sheet on that clock beside them."""
    export.write_mcap(path, log, with_temperature=False, with_odometry=False, start_time_s=T0_UNIX_S)
    export.write_protocol(path.with_name(path.stem + ".protocol.csv"), log, start_time_s=T0_UNIX_S)


def write_stop_tables(folder: Path, n: int, seed: int, change_at: int | None = None) -> None:
    """n stop tables of one vehicle; from log ``change_at`` on the unit is remounted by +2° of roll."""
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        roll = TRUTH[0] + (2.0 if change_at is not None and i >= change_at else 0.0)
        table, _ = simulate_stops(roll, TRUTH[1], TRUTH[2], noise_g=0.001, seed=seed + i)
        write_stop_table(table, folder / f"log_{i:02d}.csv")


def write_broken(folder: Path) -> dict[str, str]:
    """Corrupt and empty logs; returns each file's name and a phrase its error must contain."""
    import can

    folder.mkdir(parents=True, exist_ok=True)
    (folder / "empty.csv").write_bytes(b"")
    (folder / "empty.mcap").write_bytes(b"")
    (folder / "junk.mcap").write_bytes(np.random.default_rng(0).bytes(4096))
    good = folder / "whole.parquet"
    sample_frame(parking(99, rate_hz=20.0)).to_parquet(good)
    data = good.read_bytes()
    (folder / "truncated.parquet").write_bytes(data[: len(data) // 2])
    good.unlink()
    pd.DataFrame({"beta_deg": [0, 90], "ax": [0.0, 0.0], "ay": [0.0, 0.0], "az": [9.8, 9.8]}).to_csv(
        folder / "two_stops.csv", index=False
    )
    with can.BLFWriter(str(folder / "no_dbc.blf")) as writer:
        for i in range(10):
            writer.on_message_received(can.Message(timestamp=T0_UNIX_S + i * 0.01, arbitration_id=0x174, data=[0] * 8))
    return {
        "empty.csv": "empty file",
        "empty.mcap": "expected",
        "junk.mcap": "expected an MCAP file",
        "truncated.parquet": "does not parse",
        "two_stops.csv": "at least 3 stops",
        "no_dbc.blf": "a DBC to decode",
    }


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """A small fleet of every kind of input, calibrated once by the embedded engine through the CLI."""
    root = tmp_path_factory.mktemp("fleet")
    logs = root / "logs"
    write_stop_tables(logs / "moved", 10, seed=100, change_at=5)
    write_stop_tables(logs / "steady", 10, seed=200)
    car = logs / "car"
    car.mkdir()
    sample_frame(parking(1)).to_csv(car / "session_a.csv", index=False, float_format="%.7g")
    sample_frame(parking(2)).to_parquet(car / "session_b.parquet")
    write_mcap(car / "session_c.mcap", parking(3, rate_hz=50.0))
    broken = write_broken(logs / "broken")
    output = root / "out" / "fleet.parquet"
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(["fleet", str(logs), "-o", str(output), "--uphill-azimuth-deg", "30"])
    assert stdout.getvalue() == ""  # the summary is on stderr
    return {
        "logs_dir": logs,
        "output": output,
        "code": code,
        "stdout": stderr.getvalue(),  # the summary
        "logs": pd.read_parquet(output),
        "vehicles": pd.read_parquet(outputs_of(output)[1]),
        "broken": broken,
    }


# --- the acceptance items --------------------------------------------------------------------------


def test_every_log_gets_one_row_and_corrupt_or_empty_logs_fail_with_clear_errors(fleet: dict) -> None:
    logs: pd.DataFrame = fleet["logs"]
    assert fleet["code"] == 0
    assert len(logs) == 10 + 10 + 3 + len(fleet["broken"]) and logs["log"].is_unique
    failed = logs[logs["status"] == "failed"].copy()
    failed.index = failed["log"].map(lambda p: Path(p).name)
    assert set(failed.index) == set(fleet["broken"])
    for name, phrase in fleet["broken"].items():
        error = failed.loc[name, "error"]
        assert name in error and phrase in error and "Traceback" not in error, error
        assert failed.loc[name, "error_type"] in ("InputError", "NotEnoughInformation")
        assert np.isnan(failed.loc[name, "roll_deg"])
        assert f"failed  broken  {error}" in fleet["stdout"]
    ok = logs[logs["status"] == "ok"]
    assert ok["error"].isna().all() and len(ok) == 23
    for angle, truth in zip(("roll", "pitch"), TRUTH[:2], strict=True):
        off = (ok[f"{angle}_deg"] - truth).abs()
        steady = ok["vehicle_id"] != "moved"
        assert (off[steady] < 5 * ok.loc[steady, f"{angle}_sigma_deg"] + 0.01).all(), angle
    broken_vehicle = fleet["vehicles"].set_index("vehicle_id").loc["broken"]
    assert broken_vehicle["status"] == "no calibration" and "all 6 logs failed" in broken_vehicle["reason"]
    assert not broken_vehicle["latest_confident"] and broken_vehicle["n_failed"] == 6


def test_each_format_is_read_with_its_headings_and_start_time(fleet: dict) -> None:
    logs = fleet["logs"].set_index(fleet["logs"]["log"].map(lambda p: Path(p).name))
    assert (logs.loc["log_00.csv", "input_kind"] == "stop table").all()
    for name in ("session_a.csv", "session_b.parquet", "session_c.mcap"):
        row = logs.loc[name]
        assert row["status"] == "ok" and row["input_kind"] == "log" and row["n_stops"] == 8, name
        assert abs(row["yaw_deg"] - TRUTH[2]) < 5 * row["yaw_sigma_deg"] + 0.01, name
    assert logs.loc["session_c.mcap", "heading_source"] == "protocol sheet"
    assert logs.loc["session_c.mcap", "start_time"] == pd.Timestamp(T0_UNIX_S, unit="s", tz="UTC")
    assert logs.loc["session_c.mcap", "start_time_source"] == "log clock"
    assert "uphill azimuth 30" in logs.loc["session_a.csv", "heading_source"]
    assert pd.isna(logs.loc["session_a.csv", "start_time"])  # its clock starts at 0 s, not Unix time


def test_a_2deg_remount_half_way_is_flagged_at_the_right_log_and_a_steady_vehicle_is_not(fleet: dict) -> None:
    vehicles = fleet["vehicles"].set_index("vehicle_id")
    assert vehicles.index.is_unique  # one row per vehicle, its mountings over time nested
    assert vehicles.loc["steady", "n_remounts"] == 0 and vehicles.loc["steady", "n_mountings"] == 1
    moved = vehicles.loc["moved"]
    assert moved["n_remounts"] == 1 and len(moved["mountings"]) == 2 and moved["latest_confident"]
    (remount,) = moved["remounts"]
    assert Path(remount["log"]).name == "log_05.csv" and Path(moved["since_log"]).name == "log_05.csv"
    assert abs(remount["change_deg"] - 2.0) < 4 * remount["change_sigma_deg"] + 1e-3
    assert moved["roll_deg"] == pytest.approx(moved["mountings"][1]["roll_deg"])
    assert "remount moved at" in fleet["stdout"] and "log_05.csv" in fleet["stdout"]
    flagged = fleet["logs"][fleet["logs"]["flags"].map(lambda f: "remount" in list(f))]
    assert [Path(p).name for p in flagged["log"]] == ["log_05.csv"]


def test_a_dask_cluster_gives_the_same_tables_as_the_embedded_run(fleet: dict, tmp_path: Path) -> None:
    from distributed import LocalCluster

    output = tmp_path / "dask.parquet"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        address = cluster.scheduler_address
        code = main(
            [
                "fleet",
                str(fleet["logs_dir"]),
                "-o",
                str(output),
                "--uphill-azimuth-deg",
                "30",
                "-q",
                "--scheduler",
                address,
            ]
        )
    assert code == 0
    dask_logs = pd.read_parquet(output).drop(columns="elapsed_s")
    pd.testing.assert_frame_equal(dask_logs, fleet["logs"].drop(columns="elapsed_s"), check_exact=True)
    pd.testing.assert_frame_equal(pd.read_parquet(outputs_of(output)[1]), fleet["vehicles"], check_exact=True)


def test_a_killed_run_resumes_without_redoing_finished_logs_or_duplicating_rows(tmp_path: Path) -> None:
    logs = tmp_path / "logs"
    for v in range(2):
        (logs / f"van{v}").mkdir(parents=True)
        for i in range(6):
            sample_frame(parking(10 * v + i)).to_csv(logs / f"van{v}" / f"s{i}.csv", index=False, float_format="%.7g")
    output = tmp_path / "fleet.parquet"
    parts = outputs_of(output)[2]
    command = [sys.executable, "-m", "mountcal", "fleet", str(logs), "-o", str(output), "--workers", "1"]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while len(list(parts.glob("*.json"))) < 3 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.005)
        os.killpg(proc.pid, signal.SIGKILL)  # the CLI and its worker processes, mid-run
    finally:
        proc.wait()
    assert proc.returncode == -signal.SIGKILL
    assert not output.exists(), "the run finished before it could be killed: make the logs longer"
    before = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in parts.glob("*.json")}
    temporaries = len(list(parts.glob(".*.part")))  # a write the kill interrupted, if any
    stored, unreadable = PartStore(parts).load()
    assert 3 <= len(before) < 12 and unreadable == 0 and len(stored) == len(before)

    jobs = collect_jobs([logs], exclude=outputs_of(output))
    result = run_fleet(jobs, output, FleetOptions(workers=2, progress=False))
    assert result.computed == 12 - len(before) and result.reused == len(before)
    assert result.discarded["temporary files of a killed run"] == temporaries
    after = {p.name: (p.stat().st_ino, p.stat().st_mtime_ns) for p in parts.glob("*.json")}
    assert all(after[name] == stamp for name, stamp in before.items())  # finished logs were not redone
    assert len(after) == 12 and not list(parts.glob(".*.part"))
    table = pd.read_parquet(output)
    assert len(table) == 12 and table["log"].is_unique and table["content_hash"].is_unique
    assert (table["status"] == "ok").all()
    assert set(table["content_hash"]) == {job_hash(j) for j in jobs} == {n.removesuffix(".json") for n in after}


def test_a_rerun_reuses_every_stored_result(fleet: dict) -> None:
    output = fleet["output"]
    inputs = [fleet["logs_dir"], fleet["logs_dir"] / "steady"]  # the second names 10 logs again
    jobs = collect_jobs(inputs, JobDefaults(uphill_azimuth_deg=UPHILL_AZIMUTH_DEG), outputs_of(output))
    result = run_fleet(jobs, output, FleetOptions(progress=False))
    assert result.computed == 0 and result.reused == len(jobs) - 10 == 29
    assert result.discarded["inputs naming a log already listed"] == 10
    pd.testing.assert_frame_equal(pd.read_parquet(output), fleet["logs"], check_exact=True)


# --- inputs ------------------------------------------------------------------------------------------


def test_a_manifest_names_vehicles_joins_split_logs_and_orders_by_start_time(tmp_path: Path) -> None:
    data = tmp_path / "data"
    data.mkdir()
    frame = sample_frame(parking(5))
    half = len(frame) // 2
    frame.iloc[:half].to_csv(data / "big_part1.csv", index=False, float_format="%.7g")
    frame.iloc[half:].to_csv(data / "big_part2.csv", index=False, float_format="%.7g")
    write_stop_tables(data / "stops", 6, seed=300, change_at=2)
    rows = [
        {"vehicle_id": "truck7", "log": "data/big_part*.csv", "uphill_azimuth_deg": "30", "start_time": "2024-05-01"}
    ]
    for i in range(6):  # names run against time: log_05 … log_02 (remounted) come first, then log_01, log_00
        rows.append(
            {"vehicle_id": "truck8", "log": f"data/stops/log_{5 - i:02d}.csv", "start_time": f"2024-06-0{i + 1}"}
        )
    rows.append({"vehicle_id": "truck8", "log": "data/missing.csv", "start_time": "2024-07-01"})
    manifest = tmp_path / "manifest.csv"
    pd.DataFrame(rows).to_csv(manifest, index=False)
    output = tmp_path / "out.parquet"

    assert main(["fleet", str(manifest), "-o", str(output), "-q"]) == 0
    logs = pd.read_parquet(output).set_index("log")
    split = logs.loc[f"{data}/big_part1.csv + {data}/big_part2.csv"]
    assert split["vehicle_id"] == "truck7" and split["status"] == "ok" and split["n_samples"] == len(frame)
    assert split["yaw_deg"] == pytest.approx(TRUTH[2], abs=5 * split["yaw_sigma_deg"] + 0.01)
    assert split["start_time_source"] == "manifest"
    missing = logs.loc[f"{data}/missing.csv"]
    assert missing["status"] == "failed" and "missing.csv" in missing["error"] and "No such file" in missing["error"]
    vehicles = pd.read_parquet(outputs_of(output)[1]).set_index("vehicle_id")
    (remount,) = vehicles.loc["truck8", "remounts"]
    assert Path(remount["log"]).name == "log_01.csv"  # the change, in time order
    assert remount["time"] == pd.Timestamp("2024-06-05", tz="UTC")
    assert vehicles.loc["truck8", "order"] == "start_time"
    assert len(list(outputs_of(output)[2].glob("*.json"))) == 7  # the missing log is retried next time


def test_a_manifest_saved_by_a_spreadsheet_in_a_semicolon_locale_is_read(tmp_path: Path) -> None:
    """A German or French spreadsheet saves CSV with `;` between cells and a decimal comma: before, the fleet took
    such a manifest for a log (its one column `vehicle_id;log`) and refused it as a table without accelerations."""
    write_stop_tables(tmp_path / "stops", 2, seed=301)
    manifest = tmp_path / "manifest.csv"
    rows = ["vehicle_id;log;uphill_azimuth_deg"] + [f"van1;stops/log_{i:02d}.csv;30,5" for i in range(2)]
    manifest.write_text("\n".join(rows) + "\n", encoding="utf-8")
    jobs = collect_jobs([manifest], JobDefaults())
    assert [j.vehicle_id for j in jobs] == ["van1", "van1"] and all(j.layout == "manifest" for j in jobs)
    assert all(j.job.uphill_azimuth_deg == 30.5 for j in jobs)
    assert [Path(j.log).name for j in jobs] == ["log_00.csv", "log_01.csv"]


def test_bad_inputs_stop_with_a_clear_message_and_write_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    write_stop_tables(tmp_path / "v", 3, seed=1)
    bad_manifest = tmp_path / "manifest.csv"
    pd.DataFrame({"vehicle_id": ["a"], "log": ["v/log_00.csv"], "uphil_azimuth_deg": [3]}).to_csv(
        bad_manifest, index=False
    )
    log = tmp_path / "v" / "session.parquet"
    sample_frame(parking(4, rate_hz=20.0)).to_parquet(log)
    before = log.read_bytes()
    cases = [
        ([str(tmp_path / "nowhere")], str(tmp_path / "o.parquet"), "nothing at this path"),
        ([str(tmp_path / "v")], str(tmp_path / "o.csv"), "ending in .parquet"),
        ([str(bad_manifest)], str(tmp_path / "o.parquet"), "unknown column(s) uphil_azimuth_deg"),
        ([str(tmp_path / "v")], str(log), "never overwrites its input"),
        ([str(tmp_path / "v"), str(log)], str(log), "never overwrites its input"),
    ]
    for inputs, output, phrase in cases:
        assert main(["fleet", *inputs, "-o", output, "-q"]) == 2, phrase
        err = capsys.readouterr().err
        assert phrase in err and "Traceback" not in err, err
    with pytest.raises(SystemExit) as stop:  # the parser refuses it: the option's range (mountcal.core.ranges)
        main(["fleet", str(tmp_path / "v"), "--workers", "0", "-o", str(tmp_path / "o.parquet"), "-q"])
    assert stop.value.code == 2 and "worker processes: a whole number in [1, 1024]" in capsys.readouterr().err
    assert log.read_bytes() == before
    assert not (tmp_path / "o.parquet").exists() and not (tmp_path / "o.csv").exists()


# --- engine and progress ------------------------------------------------------------------------------


def test_a_worker_killed_mid_run_costs_no_log(fleet: dict) -> None:
    jobs = collect_jobs([fleet["logs_dir"] / "steady"])
    todo = {job_hash(j): j for j in jobs}
    seen: list[str] = []
    records = []
    with LocalEngine(workers=2) as engine:
        for key, record in engine.results(todo.items()):
            if not seen:  # after the first result: kill one of the pool's worker processes
                workers = [p for p in multiprocessing.active_children() if p.name.startswith(("ForkServer", "Spawn"))]
                assert workers
                os.kill(workers[0].pid, signal.SIGKILL)
            seen.append(key)
            records.append(record)
    assert sorted(seen) == sorted(todo)
    assert all(r["status"] == "ok" and TRANSIENT not in r for r in records)


def test_a_log_that_trips_a_bug_is_recorded_with_the_exception_type(fleet: dict) -> None:
    job = collect_jobs([fleet["logs_dir"] / "car" / "session_b.parquet"])[0]
    broken = replace(job, job=replace(job.job, uphill_azimuth_deg="north"))  # a job no caller should build
    record = run_job(broken)
    kind = record["error_type"]
    assert record["status"] == "failed" and not kind.startswith("mountcal.") and "." in kind
    assert record["error"].startswith(f"unexpected {kind}: ")


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_the_progress_bar_shows_done_failed_and_reused() -> None:
    stream = _Terminal()
    progress = Progress(total=6, stream=stream)
    progress.reuse()
    progress.reuse()
    progress.update(ok=True)
    progress.update(ok=False)
    progress.finish()
    text = stream.getvalue()
    last = text.rsplit("\r", 1)[1]
    assert "mountcal: fleet" in last and "4/6" in last and "1 failed, 2 reused" in last
    assert text.endswith("\n")


def test_a_disabled_progress_bar_writes_nothing() -> None:
    stream = _Terminal()
    progress = Progress(total=2, stream=stream, enabled=False)
    progress.update(ok=True)
    progress.finish()
    assert stream.getvalue() == "" and progress.done == 1


# --- real recordings -----------------------------------------------------------------------------------


@pytest.mark.real_data
def test_a_manifest_of_real_canedge_logs_runs_to_the_end(real_data: Path, tmp_path: Path) -> None:
    """Two real drives of one car (split MF4 files joined per drive) and a desk log, from a manifest."""
    canedge = real_data / "canedge"
    manifest = tmp_path / "manifest.csv"
    pd.DataFrame(
        {
            "vehicle_id": ["3BA199E2", "3BA199E2", "2F6913DB"],
            "log": [
                str(canedge / "3BA199E2_car_DK_2021-07-26" / "00000164" / "*.MF4"),
                str(canedge / "3BA199E2_car_DK_2021-07-26" / "00000165" / "*.MF4"),
                str(canedge / "2F6913DB_desk_static_2022-01-06" / "*.MF4"),
            ],
            "dbc": [str(canedge / "dbc" / "gnss.dbc")] * 3,
        }
    ).to_csv(manifest, index=False)
    output = tmp_path / "real.parquet"
    assert main(["fleet", str(manifest), "-o", str(output), "-q", "--workers", "2"]) == 0
    logs = pd.read_parquet(output)
    assert len(logs) == 3 and logs["log"].is_unique
    car = logs[logs["vehicle_id"] == "3BA199E2"]
    assert [len(log.split(" + ")) for log in car["log"]] == [5, 6]  # the splits of each drive joined
    assert (car["status"] == "ok").any()
    ok = car[car["status"] == "ok"]
    assert (ok["start_time_source"] == "log clock").all()  # the logger's clock is Unix time
    assert (ok["start_time"].dt.year == 2021).all()
    for row in logs.itertuples():
        if row.status == "ok":  # every answer carries its σ, and yaw is either determined or explained
            assert row.roll_sigma_deg > 0 and row.pitch_sigma_deg > 0
            assert (row.yaw_deg is None or np.isnan(row.yaw_deg)) == isinstance(row.yaw_reason, str)
        else:
            assert str(Path(row.log.split(" + ")[0])) in row.error and "Traceback" not in row.error
    vehicles = pd.read_parquet(outputs_of(output)[1])
    assert set(vehicles["vehicle_id"]) == {"3BA199E2", "2F6913DB"}
    assert vehicles["status"].isin(["ok", "no calibration"]).all()


@pytest.mark.real_data
def test_fleet_calibrates_a_real_drive_exactly_as_calibrate_does(real_data: Path, tmp_path: Path) -> None:
    """One pipeline: the CANedge car's drive (stops that do not determine yaw, and driving that does)
    gives the same roll, pitch, yaw and σ from `mountcal fleet` as from `mountcal calibrate`."""
    canedge = real_data / "canedge"
    drive = sorted((canedge / "3BA199E2_car_DK_2021-07-26" / "00000165").glob("*.MF4"))
    dbc = str(canedge / "dbc" / "gnss.dbc")
    result = tmp_path / "result.json"
    assert main(["calibrate", *map(str, drive), "--dbc", dbc, "--channel", "2", "-o", str(result)]) == 0
    single = Calibration.load(result)
    manifest = tmp_path / "manifest.csv"
    pd.DataFrame(
        {"vehicle_id": ["3BA199E2"], "log": [str(drive[0].parent / "*.MF4")], "dbc": [dbc], "channel": [2]}
    ).to_csv(manifest, index=False)
    output = tmp_path / "fleet.parquet"
    assert main(["fleet", str(manifest), "-o", str(output), "--workers", "1"]) == 0
    row = pd.read_parquet(output).iloc[0]
    assert row["status"] == "ok" and row["calibrated_from"] == single.fit.calibrated_from
    assert single.yaw_deg is not None  # the drive determines yaw: the fleet must not lose it
    for angle in ("roll", "pitch", "yaw"):
        assert row[f"{angle}_deg"] == pytest.approx(getattr(single, f"{angle}_deg"), abs=1e-9)
        assert row[f"{angle}_sigma_deg"] == pytest.approx(getattr(single, f"{angle}_sigma_deg"), abs=1e-9)


@pytest.mark.parametrize("size", [0, 1, HASH_BLOCK - 1, HASH_BLOCK, HASH_BLOCK + 1, 3 * HASH_BLOCK + 5])
def test_a_file_s_digest_is_the_xxh3_128_of_all_its_bytes_across_read_blocks(tmp_path: Path, size: int) -> None:
    """Read block by block, the digest is XXH3-128 of the whole file (xxhash's one-shot function on all
    the bytes at once) — no byte lost or repeated at a block's edge."""
    import xxhash

    data = np.random.default_rng(size).integers(0, 256, size, dtype=np.uint8).tobytes()
    path = tmp_path / "log.bin"
    path.write_bytes(data)
    assert file_digest(path) == f"xxh3-128:{xxhash.xxh3_128_hexdigest(data)}"
    if size:
        path.write_bytes(data[:-1] + bytes([data[-1] ^ 1]))  # the last byte of the last block counts
        assert file_digest(path) != f"xxh3-128:{xxhash.xxh3_128_hexdigest(data)}"
