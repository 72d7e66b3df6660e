"""Hostile and unlucky paths (issue 12): inputs protected as a set, special files, system errors.

Each case ends in a clear message (exit code as documented in docs/reliability.md) or a correct
result, never a traceback; an input is never modified and no partial output is left.
"""

from __future__ import annotations

import contextlib
import os
import resource
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
import pytest

from mountcal.cli import main
from mountcal.core.paths import output_lock

REPO = Path(__file__).resolve().parents[1]
DBC = REPO / "data" / "imu_mm5_10.dbc"
ENV = {**os.environ, "PYTHONPATH": str(REPO / "src"), "PYTHONDONTWRITEBYTECODE": "1", "OMP_NUM_THREADS": "1"}


def run(args: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


def run_process(args: list[str], timeout: float = 120, **kw: object) -> subprocess.CompletedProcess[str]:
    """The CLI in its own process (for hangs, resource limits and other users)."""
    return subprocess.run(  # type: ignore[call-overload, no-any-return]
        [sys.executable, "-m", "mountcal", *args], capture_output=True, text=True, timeout=timeout, env=ENV, **kw
    )


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A stop table, its result, a simulated CAN log with its protocol sheet, a mapping, the DBC."""
    d = tmp_path_factory.mktemp("hostile")
    stops, log, sheet = d / "stops.csv", d / "session.blf", d / "session_protocol.csv"
    assert main(["simulate", "-o", str(stops), "--seed", "4"]) == 0
    assert main(["calibrate", str(stops), "-o", str(d / "result.json")]) == 0
    dbc = d / "imu.dbc"
    shutil.copy(DBC, dbc)
    assert main(["simulate", "--log", str(log), "--dbc", str(dbc), "--protocol", str(sheet), "--rate-hz", "50"]) == 0
    mapping = d / "mapping.toml"
    mapping.write_text('[signals]\nax = "IMU_Acc.AccX"\nay = "IMU_Acc.AccY"\naz = "IMU_Acc.AccZ"\n')
    return {
        "stops": stops,
        "result": d / "result.json",
        "log": log,
        "protocol": sheet,
        "dbc": dbc,
        "mapping": mapping,
        "dir": d,
    }


def snapshot(*paths: Path) -> list[tuple[int, bytes]]:
    return [(p.stat().st_ino, p.read_bytes()) for p in paths]


# ------------------------------------------------------------------ outputs over other inputs


def test_report_onto_the_stop_table_is_refused_and_the_table_kept(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    before = snapshot(files["stops"])
    code, _, err = run(["calibrate", str(files["stops"]), "--report", str(files["stops"])], capsys)
    assert code == 2
    assert "--report" in err and "never overwrites its input" in err
    assert snapshot(files["stops"]) == before


@pytest.mark.parametrize("option", ["--protocol", "--dbc", "--mapping"])
@pytest.mark.parametrize("command", ["calibrate", "stops"])
def test_an_output_onto_a_file_the_command_reads_is_refused(
    files: dict[str, Path], option: str, command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    target = files[option.lstrip("-")]
    before = snapshot(target)
    code, _, err = run(
        [command, str(files["log"]), "--dbc", str(files["dbc"]), option, str(target), "-o", str(target)], capsys
    )
    assert code == 2
    assert f"the {option} file" in err and "Traceback" not in err
    assert snapshot(target) == before


def test_rotate_onto_its_mapping_or_dbc_is_refused(files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    for target in (files["mapping"], files["dbc"], files["result"]):
        before = snapshot(target)
        args = ["rotate", str(files["log"]), "--calibration", str(files["result"]), "--dbc", str(files["dbc"])]
        code, _, err = run([*args, "--mapping", str(files["mapping"]), "-o", str(target)], capsys)
        assert code == 2 and "never overwrites its input" in err
        assert snapshot(target) == before


def test_two_outputs_on_one_path_are_refused(files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    out = files["dir"] / "both.json"
    code, _, err = run(["calibrate", str(files["stops"]), "-o", str(out), "--report", str(out)], capsys)
    assert code == 2 and "different paths" in err and not out.exists()
    code, _, err = run(["simulate", "-o", str(out), "--truth", str(out)], capsys)
    assert code == 2 and "different paths" in err and not out.exists()


def test_a_hard_link_or_symlink_to_an_input_is_the_input(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    hard, soft = files["dir"] / "hard.csv", files["dir"] / "soft.json"
    os.link(files["stops"], hard)
    soft.symlink_to(files["stops"])
    before = snapshot(files["stops"])
    try:
        for out in (hard, soft):
            code, _, err = run(["calibrate", str(files["stops"]), "-o", str(out)], capsys)
            assert code == 2 and "never overwrites its input" in err
        assert snapshot(files["stops"]) == before
    finally:
        hard.unlink()
        soft.unlink()


def test_distinct_outputs_are_still_written(files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    out, html = files["dir"] / "again.json", files["dir"] / "again.html"
    code, _, _ = run(["calibrate", str(files["stops"]), "-o", str(out), "--report", str(html)], capsys)
    assert code == 0 and out.stat().st_size > 0 and html.read_text().startswith("<!")


# ------------------------------------------------------------------ special files


def test_an_output_on_a_device_fifo_or_directory_is_refused_and_left_alone(
    files: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    fifo = files["dir"] / "out.fifo"
    os.mkfifo(fifo)
    folder = files["dir"] / "a_folder"
    folder.mkdir()
    try:
        for target, kind in (("/dev/null", "a character device"), (fifo, "a FIFO"), (folder, "a directory")):
            code, _, err = run(["calibrate", str(files["stops"]), "-o", str(target)], capsys)
            assert code == 2 and kind in err, err
        assert stat.S_ISCHR(os.stat("/dev/null").st_mode)
        assert stat.S_ISFIFO(os.stat(fifo).st_mode) and folder.is_dir() and not any(folder.iterdir())
    finally:
        fifo.unlink()
        folder.rmdir()


@pytest.mark.parametrize("command", ["stops", "rotate", "report", "simulate"])
def test_an_output_naming_a_directory_is_a_message_in_every_command(
    files: dict[str, Path], command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = files["dir"]
    args = {
        "stops": ["stops", str(files["log"]), "--dbc", str(files["dbc"]), "-o", str(folder)],
        "rotate": ["rotate", str(files["stops"]), "--calibration", str(files["result"]), "-o", str(folder)],
        "report": ["report", str(files["result"]), "-o", str(folder)],
        "simulate": ["simulate", "-o", str(folder)],
    }[command]
    code, _, err = run(args, capsys)
    assert code == 2 and "a directory" in err and "Name a file" in err


SPECIAL_INPUT = {
    "protocol": ["calibrate", "{log}", "--dbc", "{dbc}", "--protocol", "{special}"],
    "mapping": ["calibrate", "{log}", "--dbc", "{dbc}", "--mapping", "{special}"],
    "dbc": ["calibrate", "{log}", "--dbc", "{special}"],
    "stop-table": ["calibrate", "{special}"],
    "calibration": ["rotate", "{stops}", "--calibration", "{special}", "-o", "{dir}/r.parquet"],
    "result": ["report", "{special}", "-o", "{dir}/r.html"],
    "report-stops": ["report", "{result}", "--stops", "{special}", "-o", "{dir}/r.html"],
    "fleet-input": ["fleet", "{special}", "-o", "{dir}/f.parquet", "--workers", "1", "-q"],
}
# every input as a FIFO (would block); /dev/zero (would never end) where the reader differs
SPECIAL_CASES = [(k, "fifo") for k in SPECIAL_INPUT] + [(k, "zero") for k in ("protocol", "stop-table", "calibration")]


@pytest.mark.parametrize(("case", "kind"), SPECIAL_CASES, ids=[f"{k}-{c}" for c, k in SPECIAL_CASES])
def test_a_fifo_or_dev_zero_as_an_input_is_refused_quickly(files: dict[str, Path], case: str, kind: str) -> None:
    args = SPECIAL_INPUT[case]
    fifo = files["dir"] / f"special_{kind}.csv"
    if kind == "fifo":
        os.mkfifo(fifo)
    else:
        fifo.symlink_to("/dev/zero")  # a name with the suffix the command expects, pointing at the device
    try:
        filled = [
            a.format(special=fifo, dir=files["dir"], **{k: v for k, v in files.items() if k != "dir"}) for a in args
        ]
        started = time.monotonic()
        done = run_process(filled, timeout=60)
        assert time.monotonic() - started < 60
        assert "Traceback" not in done.stderr
        assert done.returncode == 2 and "regular file" in done.stderr, done.stderr
    finally:
        fifo.unlink()


def test_a_manifest_pointing_at_a_fifo_and_dev_zero_fails_those_rows_only(files: dict[str, Path]) -> None:
    d = files["dir"] / "fleet_special"
    d.mkdir()
    fifo = d / "pipe.csv"
    os.mkfifo(fifo)
    manifest = d / "manifest.csv"
    manifest.write_text(f"vehicle_id,log\nv1,{files['stops']}\nv1,{fifo}\nv2,/dev/zero\n")
    done = run_process(["fleet", str(manifest), "-o", str(d / "f.parquet"), "--workers", "1"], timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout == "" and "1 ok, 2 failed" in done.stderr.splitlines()[0]  # the answer, then the failures
    assert "found a FIFO" in done.stderr and "found a character device" in done.stderr


def test_an_input_over_the_size_limit_names_the_limit_and_how_to_raise_it(
    files: dict[str, Path], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.setenv("MOUNTCAL_MAX_INPUT_MB", str(100 / 2**20))  # 100 bytes
    code, _, err = run(["report", str(files["result"]), "-o", str(files["dir"] / "x.html")], capsys)
    assert code == 2 and "at most" in err and "MOUNTCAL_MAX_INPUT_MB" in err
    assert not (files["dir"] / "x.html").exists()


# ------------------------------------------------------------------ system errors


def test_rotate_chunk_zero_is_a_message(files: dict[str, Path], capsys: pytest.CaptureFixture[str]) -> None:
    out = files["dir"] / "chunk0.parquet"
    args = ["rotate", str(files["stops"]), "--calibration", str(files["result"]), "-o", str(out), "--chunk", "0"]
    with pytest.raises(SystemExit) as stop:  # refused by the parser: the option's range (mountcal.core.ranges)
        main(args)
    err = capsys.readouterr().err
    assert stop.value.code == 2 and "--chunk" in err and not out.exists()


def _write_commands(files: dict[str, Path], out_dir: Path) -> dict[str, list[str]]:
    """One writing invocation of each of the seven commands that write, into ``out_dir``."""
    log = ["--dbc", str(files["dbc"]), "--protocol", str(files["protocol"])]
    return {
        "calibrate": ["calibrate", str(files["stops"]), "--report", str(out_dir / "r.html")],
        "stops": ["stops", str(files["log"]), *log, "-o", str(out_dir / "s.csv")],
        "rotate": ["rotate", str(files["log"]), "--dbc", str(files["dbc"]), "--calibration", str(files["result"]),
                   "-o", str(out_dir / "rot.csv")],
        "report": ["report", str(files["result"]), "-o", str(out_dir / "r.html")],
        "simulate": ["simulate", "-o", str(out_dir / "sim.csv")],
        "simulate-log": ["simulate", "--log", str(out_dir / "sim.mcap"), "--rate-hz", "200"],
        "fleet": ["fleet", str(files["stops"]), "-o", str(out_dir / "f.parquet"), "--workers", "1", "-q"],
    }  # fmt: skip


@contextlib.contextmanager
def small_tmpfs(size: str, *, read_only: bool = False) -> Iterator[Path]:
    """A fresh tmpfs of ``size`` (needs the right to mount: skipped where it is missing)."""
    where = Path(tempfile.mkdtemp(prefix="mountcal-tmpfs-"))
    opts = f"size={size}" + (",ro" if read_only else "")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(where)], capture_output=True)
    if done.returncode != 0:
        where.rmdir()
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.decode().strip()})")
    try:
        yield where
    finally:
        subprocess.run(["umount", str(where)], check=True)
        where.rmdir()


@pytest.mark.parametrize("command", ["calibrate", "stops", "rotate", "report", "simulate", "simulate-log", "fleet"])
def test_a_read_only_folder_is_a_message_naming_the_path(files: dict[str, Path], command: str) -> None:
    with small_tmpfs("1m", read_only=True) as folder:
        done = run_process(_write_commands(files, folder)[command])
        assert done.returncode == 5, done.stderr
        assert "Traceback" not in done.stderr and str(folder) in done.stderr
        assert "read-only" in done.stderr and "write elsewhere" in done.stderr


@pytest.mark.parametrize("command", ["calibrate", "stops", "rotate", "report", "simulate", "simulate-log", "fleet"])
def test_a_folder_without_write_permission_is_a_message(files: dict[str, Path], command: str) -> None:
    locked = files["dir"] / f"locked_{command}"
    locked.mkdir()
    if os.geteuid() == 0:  # root ignores permission bits; an immutable folder refuses even root (EPERM)
        if subprocess.run(["chattr", "+i", str(locked)], capture_output=True).returncode != 0:
            pytest.skip("cannot make a folder immutable here (chattr)")
        undo = ["chattr", "-i", str(locked)]
    else:
        locked.chmod(0o555)
        undo = ["chmod", "755", str(locked)]
    try:
        done = run_process(_write_commands(files, locked)[command])
        assert done.returncode == 5, done.stderr
        assert "not permitted" in done.stderr or "Permission denied" in done.stderr
        assert str(locked) in done.stderr and "permissions" in done.stderr and "Traceback" not in done.stderr
        assert list(locked.iterdir()) == []
    finally:
        subprocess.run(undo, check=True)


@pytest.mark.parametrize("command", ["calibrate", "rotate", "simulate-log", "report", "fleet"])
def test_a_full_disk_is_a_message_and_leaves_nothing(files: dict[str, Path], command: str) -> None:
    with small_tmpfs("64k") as folder:
        before = set(folder.iterdir())
        done = run_process(_write_commands(files, folder)[command])
        assert done.returncode == 5, done.stdout + done.stderr
        assert "No space left on device" in done.stderr and "Traceback" not in done.stderr
        left = set(folder.iterdir()) - before
        assert not [p for p in left if p.name.endswith(".part")], left  # no temporary file
        if command == "fleet":  # the per-log results kept for resuming, and whole tables only
            for table in (p for p in left if p.suffix == ".parquet"):
                assert pq.read_metadata(table).num_rows >= 1
        else:
            assert left == set(), left


def _small_files() -> None:
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write beyond the limit fails with EFBIG instead
    resource.setrlimit(resource.RLIMIT_FSIZE, (48 * 1024, 48 * 1024))


@pytest.mark.parametrize("command", ["calibrate", "rotate", "simulate-log", "report"])
def test_a_file_size_limit_is_a_message_and_leaves_nothing(files: dict[str, Path], command: str) -> None:
    out = files["dir"] / f"efbig_{command}"
    out.mkdir()
    done = run_process(_write_commands(files, out)[command], preexec_fn=_small_files)
    assert done.returncode == 5, done.stderr
    assert "File too large" in done.stderr and "ulimit -f" in done.stderr and "Traceback" not in done.stderr
    assert list(out.iterdir()) == []


# ------------------------------------------------------------------ fleet: lock and scheduler


def test_a_second_fleet_on_one_output_is_refused_naming_the_holder(files: dict[str, Path]) -> None:
    out = files["dir"] / "locked_fleet.parquet"
    with output_lock(out):
        done = run_process(["fleet", str(files["stops"]), "-o", str(out), "--workers", "1", "-q"])
    assert done.returncode == 2, done.stderr
    assert f"locked by process {os.getpid()}" in done.stderr and not out.exists()
    done = run_process(["fleet", str(files["stops"]), "-o", str(out), "--workers", "1", "-q"])  # released
    assert done.returncode == 0 and out.exists(), done.stderr


def test_a_malformed_scheduler_address_is_one_message_at_once(files: dict[str, Path]) -> None:
    started = time.monotonic()
    done = run_process(
        ["fleet", str(files["stops"]), "-o", str(files["dir"] / "s.parquet"), "--scheduler", "not a url"]
    )
    assert time.monotonic() - started < 20
    assert done.returncode == 2 and "tcp://HOST:PORT" in done.stderr
    assert "Traceback" not in done.stderr and "Exception ignored" not in done.stderr


# ------------------------------------------------------------------ signals and closed standard streams


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGHUP], ids=lambda s: s.name)
def test_a_signal_during_a_write_leaves_no_temporary_file(files: dict[str, Path], sig: signal.Signals) -> None:
    folder = files["dir"] / f"signal_{sig.name}"
    folder.mkdir()
    args = ["simulate", "--log", str(folder / "s.blf"), "--dbc", str(files["dbc"]), "--rate-hz", "400"]
    with subprocess.Popen(
        [sys.executable, "-m", "mountcal", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=ENV,
        preexec_fn=_as_a_foreground_job,
    ) as proc:
        deadline = time.monotonic() + 300
        while not any(p.name.startswith(".") for p in folder.iterdir()):  # the hidden temporary exists: writing
            if proc.poll() is not None or time.monotonic() > deadline:
                proc.kill()
                pytest.fail(f"the write ended before it could be stopped: {proc.communicate()[1]}")
            time.sleep(0.05)
        time.sleep(0.5)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + sig, err
    assert "Traceback" not in err and ("interrupted" if sig == signal.SIGINT else sig.name) in err
    assert list(folder.iterdir()) == []


def _as_a_foreground_job() -> None:
    """Ctrl-C as a terminal's foreground job gets it: a test run started in the background of a
    non-interactive shell inherits SIGINT ignored, and an ignored signal is no test of its handling."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _close(fd: int) -> Any:
    return lambda: os.close(fd)


def test_a_closed_stdout_is_a_message_not_a_traceback(files: dict[str, Path]) -> None:
    out = files["dir"] / "closed.json"
    for args in (
        ["export", str(files["result"]), "--to", "json", "-o", "-"],
        ["calibrate", str(files["stops"]), "-o", str(out)],
    ):
        done = run_process(args, preexec_fn=_close(1))
        assert done.returncode == 2, done.stderr
        assert "stdout" in done.stderr and "closed" in done.stderr and "Traceback" not in done.stderr
    assert not out.exists()


def test_a_closed_stderr_leaves_stdout_to_the_result(files: dict[str, Path]) -> None:
    import json

    done = run_process(["calibrate", str(files["stops"]), "--json", "-v"], preexec_fn=_close(2))
    assert done.returncode == 0
    assert json.loads(done.stdout)["mounting"]  # no status line mixed in


def test_a_closed_stdin_is_an_empty_input(files: dict[str, Path]) -> None:
    done = run_process(["calibrate", "-"], preexec_fn=_close(0))
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
