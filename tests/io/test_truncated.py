"""Files that are shorter than they say: every reader knows whether it reached the end of a whole file.

A copy cut short is refused with the byte where it ends (:class:`TruncatedInput`); with
``--allow-truncated`` (``LogOptions.allow_truncated``) its whole part is read — exactly a prefix of
what the whole file gives — and the samples, listings and results name the cut (issue 23,
reproduction 5). Cut points are drawn by hypothesis over 30–99.9 % of each file's bytes; the files
are real recordings or written by the real writers (python-can, mcap, asammdf, pandas).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import can
import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mountcal.cli import main
from mountcal.core.errors import InputError
from mountcal.io.can.files import iter_frames
from mountcal.io.can.frames import CanFrames
from mountcal.io.logs import inspect_log, iter_log, read_log
from mountcal.io.reader import LogOptions
from mountcal.io.whole import TruncatedInput, reading
from mountcal.stops.table import read_stop_table

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "data"
DBC = DATA / "imu_mm5_10.dbc"
CUTS = st.floats(min_value=0.30, max_value=0.999)
UNFINALISED_MF4 = [
    "canedge/2F6913DB_desk_static_2022-01-06/00000001.MF4",
    "canedge/truck_j1939_fw01.07_0bit-channels/00000001.MF4",
    "canedge/94C49784_boat_static_nmea2000_2021-05-10/00000017-6099D010.MF4",
]
FINALISED_MF4 = ["canedge/3BA199E2_car_DK_2021-07-26/00000164/00000005-60FEB5A8.MF4"]
UNVERIFIED = "cannot be told from the whole file"


def cut_copy(source: Path, folder: Path, fraction: float) -> Path:
    """``source``'s first ``fraction`` of bytes, under the same name in ``folder``."""
    data = source.read_bytes()
    out = folder / source.name
    out.write_bytes(data[: int(len(data) * fraction)])
    return out


def frames_of(path: Path, allow: bool) -> tuple[CanFrames, list[str]]:
    with reading(allow) as cuts:
        frames = CanFrames.concat(list(iter_frames(path, max_frames=1 << 16)))
    return frames, [c.sentence for c in cuts]


def assert_prefix(part: CanFrames, whole: CanFrames) -> None:
    """The frames of a cut file are, for each id on each channel, the first frames of the whole file,
    unchanged (a log of several channel groups is cut at a different frame in each)."""
    assert 0 < len(part) < len(whole)
    key = lambda f: f.channel * (1 << 32) + f.arbitration_id  # noqa: E731
    for k in np.unique(key(part)):
        mine, all_of = part.take(key(part) == k), whole.take(key(whole) == k)
        n = len(mine)
        np.testing.assert_array_equal(mine.t_s, all_of.t_s[:n])
        np.testing.assert_array_equal(mine.data, all_of.data[:n, : mine.data.shape[1]])


def never_silent(path: Path, whole: CanFrames, whole_notes: list[str]) -> None:
    """A cut file is refused; allowed, it gives a prefix of the frames and names the cut. The one
    exception is stated, not silent: an unfinalised MF4 cut exactly between two records reads as
    one the logger closed there, and its samples say that its end cannot be verified."""
    size = path.stat().st_size
    try:
        part, notes = frames_of(path, allow=False)
    except TruncatedInput as err:
        assert err.cut.ends_at == size and f"ends at byte {size}" in str(err)
        assert "allow_truncated=True" in str(err)  # the library's spelling; the CLI's is --allow-truncated
    else:
        assert any(UNVERIFIED in n for n in notes) and any(UNVERIFIED in n for n in whole_notes), notes
        assert_prefix(part, whole)
        return
    try:
        part, notes = frames_of(path, allow=True)
    except TruncatedInput as err:  # allowed, but what is left cannot be opened (a finalised MF4's metadata)
        assert f"ends at byte {size}" in str(err) and "cannot be read" in str(err)
        return
    assert len(notes) == 1 and f"ends at byte {size}" in notes[0], notes
    assert_prefix(part, whole)


@pytest.mark.real_data
@pytest.mark.parametrize("name", UNFINALISED_MF4 + FINALISED_MF4)
def test_a_real_canedge_mf4_cut_anywhere_is_never_read_silently(
    real_data: Path, name: str, tmp_path_factory: pytest.TempPathFactory
) -> None:
    source = real_data / name
    whole, whole_notes = frames_of(source, allow=False)
    if name in UNFINALISED_MF4:  # the logger wrote no length: even the whole file says what it cannot check
        assert len(whole_notes) == 1 and UNVERIFIED in whole_notes[0]
    else:
        assert whole_notes == []
    folder = tmp_path_factory.mktemp("cut")

    @settings(max_examples=12)
    @given(fraction=CUTS)
    def check(fraction: float) -> None:
        never_silent(cut_copy(source, folder, fraction), whole, whole_notes)

    check()


@pytest.mark.real_data
def test_an_unfinalised_mf4_cut_between_records_is_read_saying_its_end_is_unverified(
    real_data: Path, tmp_path: Path
) -> None:
    """The truck file (firmware 01.07) holds fixed 16- and 19-byte records after a 1-byte id: the
    cut that lands on a record boundary is the case no check can see; it is said, not hidden."""
    source = real_data / UNFINALISED_MF4[1]
    whole, _ = frames_of(source, allow=False)
    data = source.read_bytes()
    for fraction in (0.5, 0.8):
        cut = int(len(data) * fraction)
        found = None
        for end in range(cut, cut + 64):  # the next record boundary: where a strict read succeeds
            (tmp_path / source.name).write_bytes(data[:end])
            try:
                found = frames_of(tmp_path / source.name, allow=False)
                break
            except TruncatedInput:
                continue
        assert found is not None
        part, notes = found
        assert_prefix(part, whole)
        assert len(notes) == 1 and UNVERIFIED in notes[0]


def test_the_simulators_mf4_missing_its_attachment_is_refused_or_read_saying_so(tmp_path: Path) -> None:
    whole, _ = frames_of(DATA / "parking.mf4", allow=False)
    path = tmp_path / "parking.mf4"
    path.write_bytes((DATA / "parking.mf4").read_bytes()[:-360])
    with pytest.raises(TruncatedInput, match=r"the rest of its AT block at byte 358424 .* ends at byte 359136"):
        frames_of(path, allow=False)
    frames, notes = frames_of(path, allow=True)  # the frames are all there: only the attachment is cut
    assert len(frames) == len(whole) and len(notes) == 1


@given(fraction=CUTS)
@settings(max_examples=25)
def test_a_blf_cut_anywhere_is_refused_or_read_to_its_last_whole_container(
    fraction: float, tmp_path_factory: pytest.TempPathFactory
) -> None:
    whole, _ = frames_of(DATA / "parking.blf", allow=False)
    never_silent(cut_copy(DATA / "parking.blf", tmp_path_factory.mktemp("blf"), fraction), whole, [])


def test_a_blf_its_writer_never_closed_is_incomplete(tmp_path: Path) -> None:
    """python-can's BLFWriter records the file's size when it stops; before, the header holds its own size."""
    path = tmp_path / "unclosed.blf"
    writer = can.BLFWriter(path)
    messages = [can.Message(timestamp=1e9 + k * 0.01, arbitration_id=0x70, data=bytes(8)) for k in range(20_000)]
    try:
        for message in messages:
            writer.on_message_received(message)
        writer.file.flush()  # what a crash leaves: the containers written so far, the header as it began
        with pytest.raises(TruncatedInput, match="never closed"):
            frames_of(path, allow=False)
        part, notes = frames_of(path, allow=True)
    finally:
        writer.stop()
    assert 0 < len(part) < len(messages) and len(notes) == 1
    # the start time is written with the size: without it, times count from the first frame
    expected = np.array([m.timestamp for m in messages[: len(part)]]) - messages[0].timestamp
    np.testing.assert_allclose(part.t_s - part.t_s[0], expected, rtol=0, atol=1e-6)
    assert len(frames_of(path, allow=False)[0]) == len(messages)


@pytest.mark.parametrize("suffix", [".asc", ".log", ".trc", ".csv"])
def test_a_text_log_cut_inside_a_line_is_refused_or_read_without_that_line(suffix: str, tmp_path: Path) -> None:
    path = tmp_path / f"bus{suffix}"
    messages = [
        can.Message(timestamp=1000 + k * 0.01, arbitration_id=0x123, data=bytes([k % 256, 1, 2, 3, 4, 5, 6, 7]))
        for k in range(500)
    ]
    with can.Logger(path) as writer:
        for message in messages:
            writer.on_message_received(message)
    whole, _ = frames_of(path, allow=False)
    assert len(whole) == len(messages)
    data = path.read_bytes()
    for fraction in (0.31, 0.5, 0.77, 0.999):
        cut = tmp_path / "cut" / path.name
        cut.parent.mkdir(exist_ok=True)
        end = int(len(data) * fraction)
        end -= data[end - 1 : end] == b"\n"  # inside a line
        cut.write_bytes(data[:end])
        never_silent(cut, whole, [])
    if suffix == ".asc":  # cut between two lines: the trigger block is never closed
        cut.write_bytes(data[: data.index(b"\n", len(data) // 2) + 1])
        with pytest.raises(TruncatedInput, match="End TriggerBlock"):
            frames_of(cut, allow=False)


def test_a_cut_sample_table_is_refused_or_read_without_its_last_row(tmp_path: Path) -> None:
    t = np.arange(3000) * 0.01
    frame = pd.DataFrame({"t_s": t, "ax": 0.1 + 0 * t, "ay": -0.2 + 0 * t, "az": 9.80665 + 0 * t})
    csv, parquet = tmp_path / "s.csv", tmp_path / "s.parquet"
    frame.to_csv(csv, index=False)
    frame.to_parquet(parquet)
    text = csv.read_bytes()
    csv.write_bytes(text[: len(text) - 5])  # the last row loses its end: "9.806" would read as a number
    for path in (csv, parquet):
        if path == parquet:
            path.write_bytes(path.read_bytes()[:-100])
        with pytest.raises(TruncatedInput, match=f"ends at byte {path.stat().st_size}"):
            read_log(path)
        with pytest.raises(TruncatedInput):
            list(iter_log(path))
    part = read_log(csv, LogOptions(allow_truncated=True))
    assert len(part) == len(t) - 1 and part.incomplete and "s.csv ends at byte" in part.incomplete[0]
    np.testing.assert_array_equal(part.acc_s[:, 2], 9.80665)
    chunks = list(iter_log(csv, LogOptions(allow_truncated=True), 1000))
    assert sum(len(c) for c in chunks) == len(t) - 1 and chunks[0].incomplete == part.incomplete
    with pytest.raises(TruncatedInput, match="cannot be read"):  # a Parquet file lists its rows in its footer
        read_log(parquet, LogOptions(allow_truncated=True))


def test_a_cut_mcap_is_refused_or_read_to_its_last_whole_chunk(tmp_path: Path) -> None:
    whole = read_log(DATA / "parking.mcap")
    for fraction in (0.35, 0.7, 0.999):
        path = cut_copy(DATA / "parking.mcap", tmp_path, fraction)
        size = path.stat().st_size
        for reader in (read_log, inspect_log, lambda p: list(iter_log(p))):
            with pytest.raises(TruncatedInput, match=f"ends at byte {size}"):
                reader(path)
        allowed = LogOptions(allow_truncated=True)
        part = read_log(path, allowed)  # cut inside the summary (0.999): every message is still there
        assert 0 < len(part) <= len(whole) and len(part.incomplete) == 1
        np.testing.assert_array_equal(part.t_s, whole.t_s[: len(part)])
        np.testing.assert_array_equal(part.acc_s, whole.acc_s[: len(part)])
        assert inspect_log(path, allowed).incomplete == part.incomplete
        chunks = list(iter_log(path, allowed, 5000))
        assert [c.incomplete for c in chunks if c.incomplete] == [part.incomplete]


def test_a_stop_table_cut_inside_its_last_row_is_refused_or_fitted_without_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    text = (DATA / "zhang2011_stops.csv").read_bytes()
    whole = read_stop_table(DATA / "zhang2011_stops.csv")
    cut = tmp_path / "stops.csv"
    cut.write_bytes(text.rstrip(b"\n")[:-3])  # the last value loses its last digits
    with pytest.raises(TruncatedInput, match="its last line"):
        read_stop_table(cut)
    with reading(allow_truncated=True):
        part = read_stop_table(cut)
    assert len(part) == len(whole) - 1 and part.incomplete
    assert main(["calibrate", str(cut), "-o", str(tmp_path / "r.json")]) == 2
    assert "ends at byte" in capsys.readouterr().err
    assert main(["calibrate", str(cut), "-o", str(tmp_path / "r.json"), "--allow-truncated"]) == 0
    out = capsys.readouterr().err
    result = json.loads((tmp_path / "r.json").read_text())
    assert result["provenance"]["incomplete_inputs"] == list(part.incomplete)
    assert "input file: " in out and "stops.csv ends at byte" in out and "read in part" in out


def test_rotate_of_a_cut_log_records_the_cut_in_the_output(tmp_path: Path) -> None:
    result = tmp_path / "r.json"
    assert main(["calibrate", str(DATA / "zhang2011_stops.csv"), "-o", str(result)]) == 0
    path = cut_copy(DATA / "parking.mcap", tmp_path, 0.6)
    out = tmp_path / "v.parquet"
    args = ["rotate", str(path), "--calibration", str(result), "-o", str(out)]
    assert main(args) == 2 and not out.exists()
    assert main([*args, "--allow-truncated"]) == 0
    meta = pq.read_schema(out).metadata
    recorded = json.loads(meta[b"mountcal.incomplete_inputs"])
    assert len(recorded) == 1 and f"ends at byte {path.stat().st_size}" in recorded[0]


def test_every_command_takes_allow_truncated_from_one_declaration() -> None:
    import argparse

    from mountcal.cli import COMMANDS, build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    for name in COMMANDS:
        flags = [f for a in sub.choices[name]._actions for f in a.option_strings]
        assert flags.count("--allow-truncated") == 1, name


READERS: list[tuple[str, Callable[[Path], object]]] = [
    ("read_log", lambda p: read_log(p, LogOptions(dbc=str(DBC)))),
    ("inspect_log", lambda p: inspect_log(p, LogOptions(dbc=str(DBC)))),
]


@pytest.mark.parametrize(("name", "reader"), READERS)
def test_can_log_readers_refuse_a_cut_blf_by_default(
    name: str, reader: Callable[[Path], object], tmp_path: Path
) -> None:
    path = cut_copy(DATA / "parking.blf", tmp_path, 0.5)
    with pytest.raises(InputError, match=f"ends at byte {path.stat().st_size}"):
        reader(path)


def test_a_cut_blf_streams_in_chunks_as_it_reads_whole(tmp_path: Path) -> None:
    """iter_log (rotate's reader) consumes a reader's generator one step at a time: the cut found
    at the header and the object cut at the end are one cut, in every step."""
    path = cut_copy(DATA / "parking.blf", tmp_path, 0.55)
    options = LogOptions(dbc=str(DBC), allow_truncated=True)
    whole = read_log(path, options)
    chunks = list(iter_log(path, options, 2000))
    assert sum(len(c) for c in chunks) == len(whole) > 0
    assert [c.incomplete for c in chunks if c.incomplete] == [whole.incomplete]


@pytest.mark.real_data
def test_a_comma2k19_array_cut_short_is_refused_with_the_byte_where_it_ends(real_data: Path, tmp_path: Path) -> None:
    import shutil

    folder = tmp_path / "seg"
    shutil.copytree(real_data / "comma2k19" / "rav4_2018-08-02--08-34-47_seg40", folder)
    values = folder / "processed_log" / "IMU" / "accelerometer" / "value"
    data = values.read_bytes()
    values.write_bytes(data[: len(data) * 2 // 3])
    for allow in (False, True):
        with pytest.raises(TruncatedInput, match=f"ends at byte {len(data) * 2 // 3}"):
            read_log(folder, LogOptions(allow_truncated=allow))


def test_a_cut_phone_export_is_refused_or_read_without_its_last_line(tmp_path: Path) -> None:
    """A known export is read through its column map (mountcal.io.table.mapped): the same rule."""
    t = np.arange(2000) * 0.01
    frame = pd.DataFrame(
        {
            "Time (s)": t,
            **{f"Acceleration {c} (m/s^2)": 0.0 * t + v for c, v in zip("xyz", (0.1, 0.2, 9.8), strict=True)},
        }
    )
    path = tmp_path / "phyphox.csv"
    frame.to_csv(path, index=False)
    path.write_bytes(path.read_bytes()[:-3])
    with pytest.raises(TruncatedInput, match=f"ends at byte {path.stat().st_size}"):
        read_log(path)
    part = read_log(path, LogOptions(allow_truncated=True))
    assert len(part) == len(t) - 1 and part.incomplete
    assert sum(len(c) for c in iter_log(path, LogOptions(allow_truncated=True), 500)) == len(t) - 1
