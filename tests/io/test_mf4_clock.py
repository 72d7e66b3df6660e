"""An MF4's clock is the same on every machine, and a header that keeps local time says so.

MDF 4 stores the measurement's start as nanoseconds since 1970, UTC — or, with the header's
local-time flag, the recorder's wall clock of a time zone the file does not record. asammdf returns
the second as a naive datetime, and its ``timestamp()`` takes the zone of the machine that reads the
file: the same log started hours apart on two machines (a protocol sheet in Unix time matched on
one and not on the other; a fleet's dates moved). The logs here are written by python-can's
MF4Writer (through mountcal's simulator writer) and re-dated by asammdf, the real writers; each is
read in a fresh interpreter under three ``TZ`` settings.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import pytest

from mountcal.io.logs import read_log
from mountcal.io.reader import LogOptions
from mountcal.io.writers import write_log

REPO = Path(__file__).resolve().parents[2]
DBC = REPO / "data" / "imu_mm5_10.dbc"
MAPPING = REPO / "data" / "imu_mm5_10.toml"
WALL = datetime(2024, 5, 1, 18, 0, 0)  # a recorder's wall clock (Tokyo's, say); the file keeps no zone
ZONES = ("UTC", "Asia/Tokyo", "America/New_York")
READ = """
import json, sys
from mountcal.io.logs import read_log
from mountcal.io.reader import LogOptions
s = read_log(sys.argv[1], LogOptions(dbc=sys.argv[2], mapping=sys.argv[3]))
clock = [c.how + ": " + c.value for c in s.conventions if c.name == "clock"]
print(json.dumps({"t0": float(s.t_s[0]), "clock": clock}))
"""


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    from asammdf import MDF

    folder = tmp_path_factory.mktemp("clock")
    utc = folder / "utc.mf4"
    write_log(utc, read_log(REPO / "data" / "parking.mcap"), dbc_path=DBC)
    mdf = MDF(utc)
    try:
        mdf.header.start_time = WALL  # naive: asammdf writes the local-time flag
        local = Path(mdf.save(folder / "local.mf4", overwrite=True))
    finally:
        mdf.close()
    return utc, local


def _read_in(zone: str, path: Path) -> dict[str, object]:
    env = {**os.environ, "TZ": zone, "PYTHONPATH": str(REPO / "src")}
    out = subprocess.run(
        [sys.executable, "-c", READ, str(path), str(DBC), str(MAPPING)],
        env=env,
        capture_output=True,
        text=True,
        check=True,
        timeout=300,
    )
    return dict(json.loads(out.stdout.strip().splitlines()[-1]))


def _first_offset_s(path: Path) -> float:
    """The first IMU frame's time after the header's start, as asammdf reads the file (not mountcal)."""
    from asammdf import MDF

    mdf = MDF(path)
    try:
        start = mdf.header.abs_time / 1e9
    finally:
        mdf.close()
    return float(read_log(path, LogOptions(dbc=str(DBC), mapping=str(MAPPING))).t_s[0]) - start


def test_a_local_time_header_starts_at_the_same_instant_on_every_machine_and_says_its_clock(
    logs: tuple[Path, Path],
) -> None:
    _, local = logs
    read = {zone: _read_in(zone, local) for zone in ZONES}
    starts = {zone: r["t0"] for zone, r in read.items()}
    assert len(set(starts.values())) == 1, starts  # before: hours apart, by the reading machine's zone
    offset = _first_offset_s(local)
    assert starts["UTC"] == pytest.approx(WALL.replace(tzinfo=UTC).timestamp() + offset, abs=1e-6)
    for zone, r in read.items():
        (clock,) = r["clock"]  # type: ignore[misc]
        assert clock.startswith("stated: the recorder's local time"), (zone, clock)
        assert "read as UTC" in clock


def test_a_utc_header_is_read_as_asammdf_dates_it_and_says_nothing_of_its_clock(logs: tuple[Path, Path]) -> None:
    from asammdf import MDF

    utc, _ = logs
    read = {zone: _read_in(zone, utc) for zone in ZONES}
    mdf = MDF(utc)
    try:
        aware = mdf.header.start_time  # asammdf's own reading: a datetime with its zone
    finally:
        mdf.close()
    assert aware.tzinfo is not None
    for zone, r in read.items():
        assert r["t0"] == pytest.approx(aware.timestamp() + _first_offset_s(utc), abs=1e-5), zone
        assert r["clock"] == [], zone


def test_a_real_canedge_log_starts_where_asammdf_dates_it(real_data: Path) -> None:
    from asammdf import MDF

    from mountcal.io.can.mf4 import local_time_header, start_s

    path = real_data / "canedge" / "2F6913DB_desk_static_2022-01-06" / "00000001.MF4"
    mdf = MDF(path)
    try:
        aware, ours = mdf.header.start_time, start_s(mdf.header)
    finally:
        mdf.close()
    assert aware.tzinfo is not None and not local_time_header(path)  # CANedge dates its logs in UTC
    assert ours == pytest.approx(aware.timestamp(), abs=1e-6)
