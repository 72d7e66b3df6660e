"""The fleet under faults: special files in a folder, a kill or an interrupt at any moment, an
address that names no scheduler — each ends cleanly, and what finished is kept."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from mountcal.cli import main
from mountcal.fleet import outputs_of
from mountcal.simulate.stops import simulate_stops
from mountcal.stops.table import write_stop_table

REPO = Path(__file__).resolve().parents[1]


def _command(*args: str) -> list[str]:
    return [sys.executable, "-m", "mountcal", "fleet", *args]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(REPO / "src")}


def _stop_tables(folder: Path, n: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    for i in range(n):
        table, _ = simulate_stops(5.0, 6.0, 7.0, noise_g=0.001, seed=i)
        write_stop_table(table, folder / f"log_{i:02d}.csv")


def test_a_fifo_or_a_symlink_loop_in_a_folder_fails_its_row_and_the_rest_run(tmp_path: Path) -> None:
    _stop_tables(tmp_path / "logs" / "van", 3)
    for suffix in ("csv", "mcap", "parquet", "mf4"):
        os.mkfifo(tmp_path / "logs" / "van" / f"pipe.{suffix}")
    (tmp_path / "logs" / "van" / "loop.blf").symlink_to("loop.blf")
    output = tmp_path / "fleet.parquet"
    done = subprocess.run(
        _command(str(tmp_path / "logs"), "-o", str(output), "--workers", "1"),
        env=_env(),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
    logs = pd.read_parquet(output).set_index("log")
    assert len(logs) == 8 and (logs["status"] == "ok").sum() == 3
    for suffix in ("csv", "mcap", "parquet", "mf4"):
        error = logs.loc[str(tmp_path / "logs" / "van" / f"pipe.{suffix}"), "error"]
        assert "FIFO" in error and f"pipe.{suffix}" in error
    assert "symbolic links" in logs.loc[str(tmp_path / "logs" / "van" / "loop.blf"), "error"]


@pytest.mark.parametrize("address", ["inproc://x", "ucx://host:1", "tcp://", "not an address"])
def test_a_scheduler_address_that_names_no_scheduler_is_refused_at_once(
    tmp_path: Path, address: str, capsys: pytest.CaptureFixture[str]
) -> None:
    _stop_tables(tmp_path / "v", 3)
    started = time.monotonic()
    assert main(["fleet", str(tmp_path / "v"), "-o", str(tmp_path / "o.parquet"), "--scheduler", address, "-q"]) == 2
    assert time.monotonic() - started < 5.0
    err = capsys.readouterr().err
    assert f"--scheduler {address}" in err and "tcp://HOST:PORT" in err and "Traceback" not in err
    assert not (tmp_path / "o.parquet").exists()


def test_a_scheduler_port_nothing_listens_on_is_refused_at_once(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Not after the Client's 20 s of retries, and saying what was found: nothing listening."""
    import socket

    with socket.socket() as probe:  # a port that was free a moment ago
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    _stop_tables(tmp_path / "v", 3)
    address = f"tcp://127.0.0.1:{port}"
    started = time.monotonic()
    assert main(["fleet", str(tmp_path / "v"), "-o", str(tmp_path / "o.parquet"), "--scheduler", address, "-q"]) == 2
    assert time.monotonic() - started < 5.0
    err = capsys.readouterr().err
    assert f"--scheduler {address}" in err and f"nothing listening on port {port}" in err and "Traceback" not in err
    assert not (tmp_path / "o.parquet").exists()


def _children(pid: int) -> list[int]:
    out = subprocess.run(["ps", "-o", "pid=", "--ppid", str(pid)], capture_output=True, text=True).stdout
    pids = [int(p) for p in out.split()]
    return pids + [c for p in pids for c in _children(p)]


def _alive(pids: list[int]) -> list[int]:
    out = subprocess.run(["ps", "-o", "pid=,stat=", "-p", ",".join(map(str, pids))], capture_output=True, text=True)
    return [int(line.split()[0]) for line in out.stdout.splitlines() if line.split()[1:] and "Z" not in line.split()[1]]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_the_workers_end_with_the_command_and_release_its_output_pipe(tmp_path: Path, sig: signal.Signals) -> None:
    _stop_tables(tmp_path / "logs" / "van", 40)
    output = tmp_path / "fleet.parquet"
    proc = subprocess.Popen(
        _command(str(tmp_path / "logs"), "-o", str(output), "--workers", "2"),
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    try:
        parts = outputs_of(output)[2]
        deadline = time.monotonic() + 120
        while not list(parts.glob("*.json")) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        workers = _children(proc.pid)
        assert workers
        proc.send_signal(sig)  # to the command alone, as `kill PID` does
        _, stderr = proc.communicate(timeout=30)  # EOF only once no worker holds the pipes
    finally:
        proc.kill()
        proc.wait()
    deadline = time.monotonic() + 10
    while _alive(workers) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not _alive(workers)
    if sig == signal.SIGTERM:
        assert proc.returncode == 128 + signal.SIGTERM and b"run the same command again to resume" in stderr
        assert b"terminated by SIGTERM" in stderr
        assert b"Traceback" not in stderr
    assert main(["fleet", str(tmp_path / "logs"), "-o", str(output), "-q", "--workers", "2"]) == 0
    assert len(pd.read_parquet(output)) == 40


@pytest.mark.parametrize("delay_s", [0.0, 0.2, 0.5, 1.0, 2.0, 4.0])
def test_ctrl_c_at_any_moment_ends_cleanly_and_the_run_resumes(tmp_path: Path, delay_s: float) -> None:
    """Ctrl-C at moments from the command's first act (starting its worker server: before that,
    Python itself is starting, and an interrupt is the interpreter's own) to the last log."""
    _stop_tables(tmp_path / "logs" / "van", 30)
    output = tmp_path / "fleet.parquet"
    proc = subprocess.Popen(
        _command(str(tmp_path / "logs"), "-o", str(output), "--workers", "2"),
        env=_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # as a foreground job: not ignored
    )
    deadline = time.monotonic() + 60
    while not _children(proc.pid) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.002)  # mountcal's code runs: the worker server is being started
    time.sleep(delay_s)
    os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C reaches the whole foreground process group
    try:
        _, stderr = proc.communicate(timeout=60)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert b"Traceback" not in stderr and b"KeyboardInterrupt" not in stderr, stderr.decode()
    # 130: interrupted; 0: it finished first; −SIGINT: it had finished and was exiting (Python's own
    # handler is gone by then), with its tables written
    assert proc.returncode in (0, 130) or (proc.returncode == -signal.SIGINT and output.exists()), proc.returncode
    assert main(["fleet", str(tmp_path / "logs"), "-o", str(output), "-q"]) == 0
    assert len(pd.read_parquet(output)) == 30


def test_errors_name_the_files_as_given_and_the_options_as_flags(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A log that cannot give yaw from driving: its row says why in the user's terms."""
    import numpy as np

    folder = tmp_path / "fleet" / "van"
    folder.mkdir(parents=True)
    t = np.arange(0.0, 120.0, 0.01)
    rng = np.random.default_rng(1)
    moving = pd.DataFrame({"t_s": t, "ax": rng.normal(0, 1, t.size), "ay": rng.normal(0, 1, t.size)})
    moving = moving.assign(az=9.8 + rng.normal(0, 1, t.size), speed_mps=np.where(t < 2.0, 5.0, 0.0))  # 2 s of driving
    moving.to_csv(folder / "drive.csv", index=False)
    monkeypatch.chdir(tmp_path)
    assert main(["fleet", "fleet", "-o", "out.parquet", "--use", "driving", "--workers", "1"]) == 0
    error = pd.read_parquet(tmp_path / "out.parquet")["error"].iloc[0]
    assert "fleet/van/drive.csv" in error and str(tmp_path) not in error, error
    assert "--protocol" in error and "protocol=" not in error, error
    assert "fleet/van/drive.csv" in capsys.readouterr().err


def test_with_a_dbc_a_stop_table_in_the_folder_is_still_a_stop_table(tmp_path: Path) -> None:
    """--dbc makes a CSV possibly a CAN log; a CSV with a stop table's columns stays a stop table."""
    import shutil

    van = tmp_path / "fleet" / "van"
    van.mkdir(parents=True)
    shutil.copy(REPO / "data" / "zhang2011_stops.csv", van / "stops.csv")
    shutil.copy(REPO / "data" / "parking.blf", van / "parking.blf")
    output = tmp_path / "out.parquet"
    args = ["fleet", str(tmp_path / "fleet"), "-o", str(output), "--dbc", str(REPO / "data" / "imu_mm5_10.dbc")]
    assert main([*args, "--uphill-azimuth-deg", "30", "--workers", "1", "-q"]) == 0
    logs = pd.read_parquet(output).set_index(pd.read_parquet(output)["log"].map(lambda p: Path(p).name))
    assert logs.loc["stops.csv", "status"] == "ok", logs.loc["stops.csv", "error"]
    assert logs.loc["stops.csv", "input_kind"] == "stop table" and logs.loc["stops.csv", "n_stops"] == 12
    assert logs.loc["parking.blf", "status"] == "ok" and logs.loc["parking.blf", "input_kind"] == "log"


def test_an_interrupted_engine_waits_for_its_workers_once_not_per_step(monkeypatch: pytest.MonkeyPatch) -> None:
    # kill() and close() share one clean-up budget: a start that hangs costs it once, not once per
    # step (three 5 s waits in a row once summed to the whole 15 s grace of an interrupted command)
    import threading

    from mountcal.fleet import engines

    monkeypatch.setattr(engines, "CLEANUP_WAIT_S", 0.6)
    engine = engines.LocalEngine(1)
    hung = threading.Event()
    engine._starting = threading.Thread(target=hung.wait, args=(30,), daemon=True)
    engine._starting.start()
    started = time.monotonic()
    engine.kill()
    engine.close()
    took = time.monotonic() - started
    hung.set()
    assert 0.5 < took < 1.0, f"kill + close waited {took:.2f} s for a budget of 0.6 s"
