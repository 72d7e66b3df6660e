"""A Parquet time column of timestamps with and without a zone (mountcal/io/table/time_unit.py): a zoned one is an
instant; a naive one (pandas' datetime64 without tz, Arrow's timestamp with no zone) is a wall clock's in a zone
the file does not name, taken as UTC — and now said so, where before it read as plain UTC, stated by the type."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from mountcal.io.logs import read_log

T0 = 1714557600.0  # 2024-05-01 10:00:00 UTC


def _table(path: Path, zone: str | None) -> Path:
    """A still 100 Hz sample table written by pandas/pyarrow, its t_s a timestamp (in ``zone``, or naive UTC)."""
    n = 3000
    t = pd.to_datetime(T0 + np.arange(n) / 100.0, unit="s", utc=True)
    frame = pd.DataFrame(
        {
            "t_s": t.tz_convert(zone) if zone else t.tz_localize(None),
            "ax": np.full(n, 0.3),
            "ay": np.full(n, -0.5),
            "az": np.full(n, 9.78) + np.random.default_rng(1).normal(0.0, 0.02, n),
        }
    )
    frame.to_parquet(path, index=False)
    return path


@pytest.mark.parametrize("zone", [None, "Europe/Berlin", "UTC"])
def test_a_timestamp_column_reads_as_its_instant_and_a_naive_one_says_it_was_taken_as_utc(
    zone: str | None, tmp_path: Path
) -> None:
    samples = read_log(_table(tmp_path / "t.parquet", zone))
    assert samples.t_s[0] == pytest.approx(T0, abs=1e-6)
    (unit,) = [c for c in samples.conventions if c.name == "time_unit"]
    assert unit.value == "timestamp"
    assert ("the type names no time zone: taken as UTC" in unit.by) == (zone is None)
