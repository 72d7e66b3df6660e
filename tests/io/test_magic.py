"""A file named for another format: its content is said, whatever command reads it (the reader
dispatch and the input-kind decision both look), and the file is not read as its name says."""

from __future__ import annotations

import gzip
import hashlib
import shutil
from pathlib import Path

import pandas as pd
import pytest
from tests.conftest import Refused

from mountcal.cli import main
from mountcal.core.errors import InputError
from mountcal.io.magic import DECOMPRESS, SIGNATURES, content_format

DATA = Path(__file__).resolve().parents[2] / "data"
DBC = ["--dbc", str(DATA / "imu_mm5_10.dbc"), "--mapping", str(DATA / "imu_mm5_10.toml")]


def _contents(tmp: Path) -> dict[str, Path]:
    """Real files of each signed format (the sample logs, a Parquet table, a gzip of a CSV)."""
    parquet = tmp / "real.parquet"
    pd.read_csv(DATA / "zhang2011_stops.csv").to_parquet(parquet)
    gz = tmp / "real.csv.gz"
    gz.write_bytes(gzip.compress((DATA / "zhang2011_stops.csv").read_bytes()))
    return {".blf": DATA / "parking.blf", ".mf4": DATA / "parking.mf4", ".mcap": DATA / "parking.mcap"} | {
        ".parquet": parquet,
        ".gz": gz,
    }


@pytest.mark.parametrize("named", [".blf", ".mf4", ".mcap", ".csv", ".parquet", ".asc", ".log", ".trc", ".bag"])
@pytest.mark.parametrize("command", ["calibrate", "inspect", "stops"])
def test_a_file_named_for_another_format_is_refused_naming_its_content(
    tmp_path: Path, named: str, command: str, capsys: pytest.CaptureFixture[str]
) -> None:
    for content, source in _contents(tmp_path).items():
        if content == named:
            continue
        path = tmp_path / f"log{named}"
        shutil.copyfile(source, path)
        before = hashlib.sha256(path.read_bytes()).hexdigest()
        args = [command, str(path), *DBC]
        if command == "stops":
            args += ["-o", str(tmp_path / "s.csv")]
        assert main(args) == 2, (named, content)
        err = capsys.readouterr().err
        what = content_format(path)
        assert what is not None and what[1] == content
        assert f"log{named}" in err and what[0] in err, err
        if content in DECOMPRESS:  # no suffix makes a compressed file readable: the fix decompresses it
            assert f"{DECOMPRESS[content]} log{named} > log_plain{named}" in err, err
        else:
            assert f"log{content}" in err, err
        assert "Traceback" not in err
        assert hashlib.sha256(path.read_bytes()).hexdigest() == before
        assert not (tmp_path / "s.csv").exists()


def test_a_file_named_for_its_own_format_reads(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    for name in ("parking.blf", "parking.mf4", "parking.mcap"):
        assert main(["inspect", str(DATA / name), *DBC]) == 0, capsys.readouterr().err
    path = tmp_path / "stops.pq"
    pd.read_csv(DATA / "zhang2011_stops.csv").to_parquet(path)  # .pq is a Parquet name too
    assert main(["calibrate", str(path), "-q"]) == 0, capsys.readouterr().err


def test_the_signatures_are_those_the_real_writers_write(tmp_path: Path) -> None:
    """Each signature is checked against a file of that format written by its real writer (not our own
    table of bytes read back): the sample logs, pandas' Parquet, gzip."""
    files = _contents(tmp_path)
    for suffix, path in files.items():
        found = content_format(path)
        assert found is not None and found[1] == suffix, (suffix, found)
    assert {suffix for _, _, suffix in SIGNATURES} >= set(files)


def test_a_fifo_is_not_opened_to_look(tmp_path: Path) -> None:
    import os

    fifo = tmp_path / "pipe.blf"
    os.mkfifo(fifo)
    assert content_format(fifo) is None  # returns at once: a FIFO would block a read


def test_a_suffix_mountcal_does_not_own_is_not_judged(tmp_path: Path) -> None:
    """A reader plugin's format may be a Parquet table or a ZIP inside: its name is not checked."""
    from mountcal.io.magic import check_named_for_content

    path = tmp_path / "drive.noisy"
    pd.read_csv(DATA / "zhang2011_stops.csv").to_parquet(path)
    check_named_for_content(path)  # no refusal
    with pytest.raises(InputError, match=r"drive\.parquet"):
        check_named_for_content(path.rename(tmp_path / "drive.csv"))


def test_a_compressed_log_is_refused_naming_the_command_that_gives_the_file_inside(
    tmp_path: Path, refused: Refused
) -> None:
    """``log.csv.gz``: no reader takes ``.gz``; the refusal names the decompression, and its output reads."""
    gz = _contents(tmp_path)[".gz"]
    err = refused(["calibrate", str(gz), "-o", str(tmp_path / "r.json")], tmp_path / "r.json")
    assert "real.csv.gz" in err and "gzip -dc real.csv.gz > real.csv" in err, err
    (tmp_path / "real.csv").write_bytes(gzip.decompress(gz.read_bytes()))  # what that command writes
    assert main(["calibrate", str(tmp_path / "real.csv"), "-o", str(tmp_path / "r.json")]) == 0


@pytest.mark.parametrize(
    ("suffix", "what"), [(".MFC", "compressed"), (".MFE", "encrypted"), (".mfm", "compressed and")]
)
def test_a_canedge_packed_log_is_refused_naming_what_unpacks_it(
    tmp_path: Path, refused: Refused, suffix: str, what: str
) -> None:
    """A CANedge log compressed or encrypted was refused as any unknown suffix: "Convert it, or name it by its
    format" — and named .MF4 it would still be packed. The refusal says what it is and what unpacks it."""
    log = tmp_path / f"00000001{suffix}"
    log.write_bytes(b"\x00" * 64)  # its content is not looked at: the suffix decides
    err = refused(["stops", str(log), "-o", str(tmp_path / "s.csv")], tmp_path / "s.csv")
    assert f"It is a CANedge log, {what}" in err and "mdf2finalized" in err and "name it by its format" not in err


def test_a_fleet_folder_counts_a_canedge_packed_log_whatever_its_name(tmp_path: Path) -> None:
    """fleet --layout folders found only files a reader takes, and CANedge splits by their split names: a
    packed log renamed (van1/b.MFC) was never seen, not counted, not reported. It is one failed log now."""
    import contextlib
    import io

    van = tmp_path / "fleet" / "van1"
    van.mkdir(parents=True)
    shutil.copy(DATA / "parking.blf", van / "a.blf")
    shutil.copy(DATA / "parking_protocol.csv", van / "a.blf.protocol.csv")
    (van / "b.MFC").write_bytes(b"\x00" * 64)
    (van / "c.MFE").write_bytes(b"\x00" * 64)
    out = tmp_path / "fleet.parquet"
    can = ["--dbc", str(DATA / "imu_mm5_10.dbc"), "--mapping", str(DATA / "imu_mm5_10.toml")]
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        code = main(["fleet", str(tmp_path / "fleet"), "--layout", "folders", *can, "--workers", "1", "-o", str(out)])
    logs = pd.read_parquet(out).set_index("log")
    assert code == 0 and len(logs) == 3, err.getvalue()
    assert logs.loc[str(van / "a.blf"), "status"] == "ok"
    for name in ("b.MFC", "c.MFE"):
        assert logs.loc[str(van / name), "status"] == "failed" and "CANedge log" in logs.loc[str(van / name), "error"]
