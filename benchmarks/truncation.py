"""How files cut short are read: refused, read in part and said, or (the one stated blind spot) read
whole with an end that cannot be verified — counted over many cut points of real and written logs.

For each file, ``--cuts`` cut points evenly spread over 30–99.9 % of its bytes (plus a random
jitter of up to one record's size, seeded) are copied to a temporary file and read twice through
:func:`mountcal.io.can.files.iter_frames` / :func:`mountcal.io.logs.read_log`: by default and with
``allow_truncated``. Outcomes:

- ``refused``: the default read raised ``TruncatedInput`` naming the byte where the file ends;
- ``read in part``: with ``allow_truncated`` the whole part was read and the cut named;
- ``unreadable``: with ``allow_truncated`` still refused (nothing readable: a finalised MF4's lost metadata);
- ``unverified``: read by default, with the sentence that the end cannot be verified (an
  unfinalised MF4 cut exactly between records);
- ``SILENT``: read by default with nothing said — the failure this measures; must be 0.

Usage::

    PYTHONPATH=src .venv/bin/python benchmarks/truncation.py --cuts 200
"""

from __future__ import annotations

import argparse
import contextlib
import io
import random
import tempfile
from collections import Counter
from pathlib import Path

from mountcal.core.errors import InputError
from mountcal.io.can.files import iter_frames
from mountcal.io.logs import read_log
from mountcal.io.reader import LogOptions
from mountcal.io.whole import TruncatedInput, reading

REPO = Path(__file__).resolve().parents[1]
REAL = REPO / ".." / "shared" / "data" / "real" / "canedge"
FILES = [
    REAL / "2F6913DB_desk_static_2022-01-06" / "00000001.MF4",
    REAL / "truck_j1939_fw01.07_0bit-channels" / "00000001.MF4",
    REAL / "94C49784_boat_static_nmea2000_2021-05-10" / "00000017-6099D010.MF4",
    REAL / "3BA199E2_car_DK_2021-07-26" / "00000164" / "00000005-60FEB5A8.MF4",
    REPO / "data" / "parking.mf4",
    REPO / "data" / "parking.blf",
    REPO / "data" / "parking.mcap",
]


def _read(path: Path, allow: bool) -> list[str]:
    """The notes of one read (the cuts and unverifiable ends), raising on a refusal."""
    with contextlib.redirect_stdout(io.StringIO()):  # asammdf prints the errors it recovers from
        if path.suffix.lower() == ".mcap":
            return list(read_log(path, LogOptions(allow_truncated=allow)).incomplete)
        with reading(allow) as cuts:
            for _ in iter_frames(path, max_frames=1 << 16):
                pass
    return [c.sentence for c in cuts]


def outcome(path: Path) -> str:
    try:
        notes = _read(path, allow=False)
    except TruncatedInput:
        try:
            _read(path, allow=True)
        except InputError:
            return "refused; allowed: unreadable"
        return "refused; allowed: read in part"
    except InputError as err:
        return f"other refusal: {str(err)[:80]}"
    return "unverified (said)" if notes else "SILENT"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cuts", type=int, default=200, help="cut points per file")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    total: Counter[str] = Counter()
    with tempfile.TemporaryDirectory() as tmp:
        for source in FILES:
            if not source.is_file():
                print(f"{source}: absent, skipped")
                continue
            data = source.read_bytes()
            counts: Counter[str] = Counter()
            for k in range(args.cuts):
                fraction = 0.30 + 0.699 * k / max(args.cuts - 1, 1)
                end = min(len(data) - 1, int(len(data) * fraction) + rng.randrange(0, 64))
                cut = Path(tmp) / source.name
                cut.write_bytes(data[:end])
                counts[outcome(cut)] += 1
            total.update(counts)
            print(f"{source.relative_to(source.parents[1])} ({len(data)} bytes): {dict(counts)}")
    print(f"all: {dict(total)}")


if __name__ == "__main__":
    main()
