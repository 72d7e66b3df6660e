"""Hostile and unlucky inputs to the readers: decompression bombs and special files.

Each bomb starts from a file written by the real writer (mcap's Writer, python-can's BLFWriter)
and is then altered by byte surgery. Each is run through the CLI in a subprocess whose peak RSS is
measured: it must end in a clear message (exit 2, no traceback) within the memory bound stated
in docs/reliability.md.
"""

from __future__ import annotations

import ast
import os
import struct
import subprocess
import sys
import zlib
from collections.abc import Iterator
from pathlib import Path

import can
import lz4.frame
import numpy as np
import pytest
import zstandard
from mcap.writer import CompressionType, Writer

from mountcal.core.errors import InputError
from mountcal.io.can.files import read_frames
from mountcal.io.inputs import check_regular_file
from mountcal.io.mcap.inspect import inspect_mcap
from mountcal.io.mcap.read import read_mcap
from mountcal.io.table.read import read_table

REPO = Path(__file__).resolve().parents[2]
DBC = REPO / "data" / "imu_mm5_10.dbc"
MIB = 1 << 20
# The bound of docs/reliability.md for an input whose output is small: 1 GiB. These inputs are
# refused, so their peak must stay far below what the bomb declares or inflates to.
RSS_BOUND_MB = 1024

_MEASURE = """
import resource, subprocess, sys
run = subprocess.run(sys.argv[1:], capture_output=True, text=True, timeout=120)
peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
print(repr((run.returncode, run.stdout, run.stderr, peak_mb)))
"""


def run_cli(*args: str, env: dict[str, str] | None = None) -> tuple[int, str, float]:
    """Exit code, stderr and peak RSS (MB) of ``mountcal ARGS`` alone in a measuring process."""
    environ = {**os.environ, "PYTHONPATH": str(REPO / "src"), **(env or {})}
    cmd = [sys.executable, "-c", _MEASURE, sys.executable, "-m", "mountcal", *args]
    out = subprocess.run(cmd, capture_output=True, text=True, env=environ, timeout=180, check=True)
    code, _, stderr, peak = ast.literal_eval(out.stdout)
    return code, stderr, peak


def assert_refused(code: int, stderr: str, peak_mb: float, *words: str) -> None:
    assert code == 2, stderr
    assert "Traceback" not in stderr, stderr
    for word in words:
        assert word in stderr, stderr
    assert peak_mb < RSS_BOUND_MB, f"peak RSS {peak_mb:.0f} MB"
    print(f"peak RSS {peak_mb:.0f} MB")  # shown with -s: the figures of docs/reliability.md


# --------------------------------------------------------------------------- MCAP


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


def _zeros_compressed(size: int, compress: object, head: bytes = b"") -> bytes:
    """``size`` zero bytes through a streaming compressor (the test never holds them)."""
    piece = bytes(MIB)
    out = [head] + [compress.compress(piece) for _ in range(size // MIB)]  # type: ignore[attr-defined]
    return b"".join(out) + compress.flush()  # type: ignore[attr-defined]


def _bomb_mcap(path: Path, chunks: list[tuple[str, int, bytes]]) -> Path:
    """An MCAP log from mcap's Writer (header, schema, channel), then ``chunks`` of
    (compression, stated size, compressed records) spliced in, without indexes or summary."""
    real = path.with_suffix(".real.mcap")
    with real.open("wb") as f:
        writer = Writer(f, compression=CompressionType.NONE, use_chunking=False)
        writer.start(profile="ros2", library="test")
        writer.register_schema("sensor_msgs/msg/Imu", "ros2msg", b"")
        writer.finish()
    raw = real.read_bytes()
    magic = raw[:8]
    header_len = struct.unpack_from("<Q", raw, 9)[0]
    body_end = 8 + 9 + header_len
    out = bytearray(raw[:body_end])
    for compression, size, data in chunks:
        name = compression.encode()
        body = struct.pack("<QQQI", 0, 0, size, 0) + struct.pack("<I", len(name)) + name
        out += _record(0x06, body + struct.pack("<Q", len(data)) + data)
    out += _record(0x0F, struct.pack("<I", 0))  # data end
    out += _record(0x02, struct.pack("<QQI", 0, 0, 0))  # footer without a summary
    out += magic
    path.write_bytes(bytes(out))
    return path


@pytest.fixture(scope="module")
def zstd_gib_of_zeros() -> bytes:
    return _zeros_compressed(1 << 30, zstandard.ZstdCompressor(level=1).compressobj())


def test_mcap_chunk_stating_a_gibibyte_is_refused_before_inflating(tmp_path: Path, zstd_gib_of_zeros: bytes) -> None:
    bomb = _bomb_mcap(tmp_path / "bomb.mcap", [("zstd", 1 << 30, zstd_gib_of_zeros)])
    assert bomb.stat().st_size < 100_000
    assert_refused(*run_cli("inspect", str(bomb)), "MOUNTCAL_MAX_BLOCK_MB", str(bomb))
    assert_refused(*run_cli("stops", str(bomb), "-o", str(tmp_path / "s.csv")), "MOUNTCAL_MAX_BLOCK_MB")
    assert not (tmp_path / "s.csv").exists()


def test_mcap_six_chunks_of_zeros_under_the_limit_are_refused_in_bounded_memory(tmp_path: Path) -> None:
    """200 MiB of zero records per chunk: honest sizes, but 10⁸ empty records are no recording."""
    data = _zeros_compressed(200 * MIB, zstandard.ZstdCompressor(level=1).compressobj())
    bomb = _bomb_mcap(tmp_path / "bomb6.mcap", [("zstd", 200 * MIB, data)] * 6)
    assert bomb.stat().st_size < 200_000
    code, stderr, peak = run_cli("inspect", str(bomb))
    assert_refused(code, stderr, peak, "records other than messages")
    with pytest.raises(InputError, match="records other than messages"):
        read_mcap(bomb)


def test_mcap_lz4_chunk_inflating_past_its_stated_size_is_cut_off(tmp_path: Path) -> None:
    compressor = lz4.frame.LZ4FrameCompressor()
    data = _zeros_compressed(512 * MIB, compressor, compressor.begin())
    bomb = _bomb_mcap(tmp_path / "lz4.mcap", [("lz4", 4096, data)])
    assert_refused(*run_cli("inspect", str(bomb)), "does not decompress")


def test_mcap_raised_limit_is_used(tmp_path: Path, zstd_gib_of_zeros: bytes) -> None:
    """The limit is the variable's: at 2 MiB a 4 MiB chunk is refused, at the default it is read."""
    data = _zeros_compressed(4 * MIB, zstandard.ZstdCompressor(level=1).compressobj())
    bomb = _bomb_mcap(tmp_path / "small.mcap", [("zstd", 4 * MIB, data)])
    code, stderr, _ = run_cli("inspect", str(bomb), env={"MOUNTCAL_MAX_BLOCK_MB": "2"})
    assert code == 2 and "MOUNTCAL_MAX_BLOCK_MB=8" in stderr, stderr
    with pytest.raises(InputError, match="records other than messages"):  # read, then refused as filler
        inspect_mcap(bomb)


# --------------------------------------------------------------------------- BLF


def _blf_with_bomb(path: Path, inflated: int, stated: int) -> Path:
    """A BLF from python-can's BLFWriter whose first log container is replaced by one stating
    ``stated`` bytes whose zlib stream inflates to ``inflated`` zero bytes."""
    real = path.with_suffix(".real.blf")
    with can.BLFWriter(str(real)) as writer:
        for k in range(2000):
            writer.on_message_received(can.Message(timestamp=k * 0.01, arbitration_id=0x123, data=bytes(8)))
    raw = real.read_bytes()
    header_size = struct.unpack_from("<L", raw, 4)[0]
    signature, obj_header, _, obj_size, obj_type = struct.unpack_from("<4sHHLL", raw, header_size)
    assert signature == b"LOBJ" and obj_type == 10  # a log container
    payload = _zeros_compressed(inflated, zlib.compressobj(9))
    container = struct.pack("<H6xL4x", 2, stated) + payload
    size = 16 + len(container)
    obj = struct.pack("<4sHHLL", b"LOBJ", obj_header, 1, size, 10) + container + bytes(size % 4)
    rest = raw[header_size + obj_size + obj_size % 4 :]
    out = bytearray(raw[:header_size] + obj + rest)
    struct.pack_into("<Q", out, 16, len(out))  # the file size the header records
    path.write_bytes(bytes(out))
    return path


def test_blf_container_inflating_past_its_stated_size_is_refused(tmp_path: Path) -> None:
    bomb = _blf_with_bomb(tmp_path / "bomb.blf", 512 * MIB, 131_072)
    assert bomb.stat().st_size < 1_000_000
    code, stderr, peak = run_cli("inspect", str(bomb), "--dbc", str(DBC))
    assert_refused(code, stderr, peak, "stating 131072 bytes that inflates to more")
    assert peak < 400, f"peak RSS {peak:.0f} MB"  # the cap holds it to what the container states
    with pytest.raises(InputError, match="inflates to more"):
        read_frames(bomb)


def test_blf_container_stating_more_than_the_limit_is_refused(tmp_path: Path) -> None:
    bomb = _blf_with_bomb(tmp_path / "big.blf", MIB, 1 << 31)
    with pytest.raises(InputError, match="MOUNTCAL_MAX_BLOCK_MB"):
        read_frames(bomb)


# --------------------------------------------------------------------------- tables


def test_parquet_declaring_more_rows_than_the_limit_is_refused_from_its_footer(tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    n = 3_000_000  # zeros: a few kilobytes on disk
    table = pa.table({c: pa.array(np.zeros(n)) for c in ("t_s", "ax", "ay", "az")})
    path = tmp_path / "rows.parquet"
    pq.write_table(table, path)
    code, stderr, _ = run_cli("inspect", str(path), env={"MOUNTCAL_MAX_ROWS": "1000000"})
    assert code == 2 and "MOUNTCAL_MAX_ROWS" in stderr and "3000000" in stderr, stderr
    assert "Traceback" not in stderr


# --------------------------------------------------------------------------- special files


def _special_files(tmp_path: Path) -> Iterator[tuple[Path, str]]:
    fifo = tmp_path / "pipe.mcap"
    os.mkfifo(fifo)
    yield fifo, "FIFO"
    folder = tmp_path / "folder.blf"
    folder.mkdir()
    yield folder, "directory"
    yield Path("/dev/zero"), "character device"


@pytest.mark.parametrize("suffix", [".mcap", ".blf", ".csv", ".parquet"])
def test_special_files_are_refused_not_read(tmp_path: Path, suffix: str) -> None:
    for special, kind in _special_files(tmp_path):
        link = special.parent / f"link{suffix}"  # readers pick the format by suffix
        if link.is_symlink():
            link.unlink()
        link.symlink_to(special)
        args = ["inspect", str(link)] + (["--dbc", str(DBC)] if suffix == ".blf" else [])
        code, stderr, _ = run_cli(*args)  # a read of any of them would block or never end
        assert code == 2 and kind in stderr and "Traceback" not in stderr, stderr


def test_check_regular_file_names_the_role(tmp_path: Path) -> None:
    (tmp_path / "dir").mkdir()
    plain = tmp_path / "plain.csv"
    plain.write_text("t_s,ax,ay,az\n")
    assert check_regular_file(plain, "stop table") == plain
    with pytest.raises(InputError, match=r"a protocol sheet as a regular file.*a directory"):
        check_regular_file(tmp_path / "dir", "protocol sheet")
    with pytest.raises(InputError, match="no such file"):
        check_regular_file(tmp_path / "absent", "DBC")
    with pytest.raises(InputError, match="directory"):
        read_table(tmp_path / "dir")


def test_a_recording_still_reads_whole(tmp_path: Path) -> None:
    """The limits do not touch a real log: parking.mcap reads as before."""
    samples = read_mcap(REPO / "data" / "parking.mcap")
    assert len(samples) > 10_000 and np.isfinite(samples.acc_s).all()


def test_fleet_records_a_bomb_as_a_failed_log_once(tmp_path: Path, zstd_gib_of_zeros: bytes) -> None:
    """The bomb is an InputError for its log, recorded; the worker does not die and is not retried."""
    import pandas as pd

    vehicle = tmp_path / "logs" / "van"
    vehicle.mkdir(parents=True)
    _bomb_mcap(vehicle / "bomb.mcap", [("zstd", 1 << 30, zstd_gib_of_zeros)])
    (vehicle / "bomb.real.mcap").unlink()  # the writer's own file, not part of the fleet
    out = tmp_path / "fleet.parquet"
    _, stderr, _ = run_cli("fleet", str(tmp_path / "logs"), "-o", str(out), "--workers", "1", "-q")
    assert "Traceback" not in stderr, stderr
    logs = pd.read_parquet(out)
    assert len(logs) == 1 and logs["status"].iloc[0] == "failed", logs
    assert "MOUNTCAL_MAX_BLOCK_MB" in logs["error"].iloc[0] and logs["error_type"].iloc[0] == "InputError"
    assert "died" not in logs["error"].iloc[0]


def test_a_limit_that_is_not_a_positive_number_is_refused(monkeypatch: pytest.MonkeyPatch) -> None:
    from mountcal.io.inputs import max_block_bytes, max_rows

    monkeypatch.setenv("MOUNTCAL_MAX_BLOCK_MB", "lots")
    with pytest.raises(InputError, match="MOUNTCAL_MAX_BLOCK_MB"):
        max_block_bytes()
    monkeypatch.setenv("MOUNTCAL_MAX_BLOCK_MB", "3")
    assert max_block_bytes() == 3 * MIB
    monkeypatch.setenv("MOUNTCAL_MAX_ROWS", "0")
    with pytest.raises(InputError, match="MOUNTCAL_MAX_ROWS"):
        max_rows()


def test_merging_mf4_groups_with_damaged_unsorted_times_ends_with_every_frame() -> None:
    """Found by benchmarks/fuzz_mutations.py: a spliced MF4 whose times run backwards hung the merge."""
    from mountcal.io.can.frames import CanFrames
    from mountcal.io.can.mf4 import _merge_by_time

    def frames(t: list[float]) -> CanFrames:
        n = len(t)
        return CanFrames(
            np.array(t), np.zeros(n, np.int64), np.arange(n, dtype=np.uint32), np.zeros(n, bool),
            np.full(n, 8, np.uint8), np.zeros((n, 8), np.uint8),
        )  # fmt: skip

    a = iter([frames([10.0, 5.0, 0.0]), frames([1.0, 2.0])])
    b = iter([frames([3.0, 4.0]), frames([np.nan, 7.0])])
    merged = CanFrames.concat(list(_merge_by_time([a, b])))
    assert len(merged) == 9
    assert sorted(merged.t_s[np.isfinite(merged.t_s)].tolist()) == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 7.0, 10.0]


# --------------------------------------------------------------------------- MF4 variable-length data

DESK_MF4 = Path("canedge") / "2F6913DB_desk_static_2022-01-06" / "00000001.MF4"


@pytest.fixture(scope="module")
def _desk_plain(tmp_path_factory: pytest.TempPathFactory) -> tuple[bytes, int, int] | None:
    """The CANedge desk log saved uncompressed by asammdf (record bytes and DataBytes in the open),
    the address of its CAN record data and of its DataBytes signal data; None without the log."""
    from asammdf import MDF
    from tests.conftest import REAL_DATA

    if not (REAL_DATA / DESK_MF4).is_file():
        return None
    real_data = REAL_DATA
    plain = tmp_path_factory.mktemp("mf4") / "desk.mf4"
    mdf = MDF(real_data / DESK_MF4)
    mdf.save(plain, overwrite=True, compression=0)
    mdf.close()
    mdf = MDF(plain)
    try:
        group = mdf.groups[0]
        assert [c.name for c in group.channels][7] == "CAN_DataFrame.DataBytes"
        assert group.channel_group.samples_byte_nr == 22 and group.channels[7].byte_offset == 14
        (records,) = group.get_data_blocks()
        (values,) = group.get_signal_data_blocks(7)
        return plain.read_bytes(), int(records.address), int(values.address)
    finally:
        mdf.close()


@pytest.fixture
def desk_plain(real_data: Path, _desk_plain: tuple[bytes, int, int] | None) -> tuple[bytes, int, int]:
    if _desk_plain is None:
        pytest.skip(f"{DESK_MF4} not found in {real_data}")
    return _desk_plain


def _vlsd_offset(data: bytes | bytearray, records: int, k: int) -> int:
    return int(struct.unpack_from("<Q", data, records + 22 * k + 14)[0])


@pytest.mark.parametrize("damage", ["points back", "past the end", "value too long"])
def test_mf4_data_bytes_pointing_outside_their_data_are_refused(
    desk_plain: tuple[bytes, int, int], tmp_path: Path, damage: str
) -> None:
    """asammdf's C extract reads each DataBytes value where its record points, unchecked (a
    segfault on a damaged file); mountcal checks the offsets and lengths first."""
    plain, records, values = desk_plain
    data = bytearray(plain)
    k = 3000
    if damage == "points back":
        struct.pack_into("<Q", data, records + 22 * k + 14, _vlsd_offset(data, records, 10))
    elif damage == "past the end":
        struct.pack_into("<Q", data, records + 22 * k + 14, 1 << 40)
    else:  # the value's 4-byte length field, in the signal data
        struct.pack_into("<I", data, values + _vlsd_offset(data, records, k), 0xFFFFFF00)
    log = tmp_path / "damaged.mf4"
    log.write_bytes(bytes(data))
    assert_refused(*run_cli("inspect", str(log)), str(log), "DataBytes", f"record {k}")


def test_the_uncompressed_desk_log_reads_whole(desk_plain: tuple[bytes, int, int], tmp_path: Path) -> None:
    """The check refuses damage only: the same file undamaged reads every frame, its payloads intact."""
    plain, records, values = desk_plain
    log = tmp_path / "desk.mf4"
    log.write_bytes(plain)
    frames = read_frames(log)
    assert len(frames) == 5588
    # frame 3000's payload is the bytes its record points to (records are in time order in this log)
    offset = _vlsd_offset(plain, records, 3000)
    (length,) = struct.unpack_from("<I", plain, values + offset)
    k = int(np.argmin(np.abs(np.argsort(frames.t_s, kind="stable") - 3000)))
    assert bytes(frames.data[k, :length]) == plain[values + offset + 4 : values + offset + 4 + length]


@pytest.mark.parametrize("bits", [(822718, 1607624), (651235, 1072630)])
@pytest.mark.parametrize("command", ["inspect", "stops"])
def test_the_fuzzer_flips_that_crashed_asammdf_are_refused(
    real_data: Path, tmp_path: Path, bits: tuple[int, int], command: str
) -> None:
    """Found by benchmarks/fuzz_mutations.py --seed 2 (cases 104 and 152): two flipped bits in the
    desk log killed every command with SIGSEGV in asammdf's extract."""
    data = bytearray((real_data / DESK_MF4).read_bytes())
    for bit in bits:
        data[bit // 8] ^= 1 << (bit % 8)
    log = tmp_path / "flipped.MF4"
    log.write_bytes(bytes(data))
    args = ["--dbc", str(real_data / "canedge" / "dbc" / "gnss.dbc"), "-o", str(tmp_path / "out.csv")]
    assert_refused(*run_cli(command, str(log), *(args if command == "stops" else [])), str(log), "DataBytes")
    assert not (tmp_path / "out.csv").exists()


@pytest.mark.parametrize("command", ["inspect", "stops", "calibrate"])
def test_the_fuzzer_splice_that_made_a_data_bytes_offset_negative_is_refused(
    real_data: Path, tmp_path: Path, command: str
) -> None:
    """Found by benchmarks/fuzz.py --mutations 30 (case 25): 266 bytes spliced into the car's MF4 gave a value
    offset beyond 2⁶³, negative as a signed index, which the word reader took for a place inside the data."""
    data = (real_data / "canedge" / "3BA199E2_car_DK_2021-07-26" / "00000164" / "00000005-60FEB5A8.MF4").read_bytes()
    log = tmp_path / "spliced.MF4"
    log.write_bytes(data[:18468] + data[176452 : 176452 + 266] + data[18468 + 266 :])
    out = tmp_path / ("out.json" if command == "calibrate" else "out.csv")
    args = ["--dbc", str(real_data / "canedge" / "dbc" / "gnss.dbc"), "-o", str(out)]
    assert_refused(*run_cli(command, str(log), *(args if command != "inspect" else [])), str(log), "DataBytes")
    assert not out.exists()


@pytest.mark.parametrize("command", ["inspect", "calibrate"])
def test_asammdfs_printed_traceback_of_an_unfinalised_file_it_cannot_finalise_is_not_shown(
    real_data: Path, tmp_path: Path, command: str
) -> None:
    """Found by benchmarks/fuzz_mutations.py --count 300 --seed 7 (case 113): a block length of the desk log
    one byte short made asammdf print a traceback (to stdout) while finalising, before raising."""
    data = bytearray((real_data / DESK_MF4).read_bytes())
    struct.pack_into("<Q", data, 5296, 63)  # was 64
    log = tmp_path / "short.MF4"
    log.write_bytes(bytes(data))
    out = tmp_path / "out.json"
    assert_refused(*run_cli(command, str(log), *(["-o", str(out)] if command == "calibrate" else [])), "short.MF4")
    assert not out.exists()


@pytest.mark.parametrize("command", ["stops", "calibrate"])
def test_the_desk_log_with_times_far_apart_finds_no_stop_and_says_why(
    real_data: Path, tmp_path: Path, command: str
) -> None:
    """Found by benchmarks/fuzz_mutations.py --seed 2 (case 232): a size field of the desk log set
    to 1.66·10¹⁸ leaves it readable with samples 10⁷ s apart; stop detection failed with an
    IndexError (and, before that, took one-sample windows of zero spread for stops)."""
    data = bytearray((real_data / DESK_MF4).read_bytes())
    struct.pack_into("<Q", data, 5200, 1656215971714665311)
    log = tmp_path / "sizes.MF4"
    log.write_bytes(bytes(data))
    out = tmp_path / "out"
    code, stderr, peak = run_cli(
        command, str(log), "--dbc", str(real_data / "canedge" / "dbc" / "gnss.dbc"), "-o", str(out)
    )
    assert code == 3, stderr  # not enough information, as for any log without parked periods
    assert "Traceback" not in stderr, stderr
    for word in (str(log), "no parked period", "not judged still"):
        assert word in stderr, stderr
    assert peak < RSS_BOUND_MB
    assert not out.exists()


@pytest.mark.parametrize(
    ("field", "fmt", "value"),
    [(8, "<Q", 103), (8, "<Q", 208), (80, "<Q", 127908 * 1000), (96, "<I", 1 << 20)],
    # 104 -> 208: found by benchmarks/fuzz.py --mutations 150 --seed 6 on a real CANedge car MF4 (asammdf
    # read the record size from the wrong bytes while opening the file and peaked at 1.3 GB)
    ids=["block length 104 -> 103", "block length 104 -> 208", "record count x1000", "record of 1 MiB"],
)
def test_mf4_channel_group_stating_more_records_than_its_data_is_refused(
    tmp_path: Path, field: int, fmt: str, value: int
) -> None:
    """Found by benchmarks/fuzz_mutations.py --seed 3 (case 90): the CAN channel group block of
    data/parking.mf4 (python-can's MF4Writer) one byte shorter made asammdf read a record size
    of 1.3 GB and the count from the wrong bytes; it then allocated 1.4 GB over 24 s."""
    from asammdf import MDF

    source = REPO / "data" / "parking.mf4"
    mdf = MDF(source)
    cg = mdf.groups[0].channel_group
    address, cycles, record = int(cg.address), int(cg.cycles_nr), int(cg.samples_byte_nr)
    mdf.close()
    data = bytearray(source.read_bytes())
    assert data[address : address + 4] == b"##CG"
    assert struct.unpack_from("<QI", data, address + 80)[0] == cycles
    assert struct.unpack_from("<I", data, address + 96)[0] == record
    struct.pack_into(fmt, data, address + field, value)
    log = tmp_path / "cg.mf4"
    log.write_bytes(bytes(data))
    code, stderr, peak = run_cli("inspect", str(log))
    assert_refused(code, stderr, peak, str(log), "channel group stating")
