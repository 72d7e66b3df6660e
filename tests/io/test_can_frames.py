"""Bulk CAN frame readers: every format against python-can's own reader of the same file."""

from __future__ import annotations

import hashlib
import random
import shutil
import struct
import zlib
from pathlib import Path

import can
import numpy as np
import pytest
from can.io import blf

from mountcal.core.errors import InputError
from mountcal.io.can.files import iter_frames, read_frames
from mountcal.io.can.frames import CanFrames

FORMATS = ["blf", "asc", "log", "trc", "csv", "mf4"]
T0 = 1_600_000_000.0


def _traffic(n: int, *, fd: bool = True, seed: int = 1) -> list[can.Message]:
    """A mixed bus: standard and extended ids, 0-8 byte frames, some CAN FD, three channels,
    and payloads that contain the BLF object signature b"LOBJ" to tempt a naive scanner."""
    rng = random.Random(seed)
    messages = []
    for i in range(n):
        extended = rng.random() < 0.2
        is_fd = fd and rng.random() < 0.1
        length = rng.choice([8, 12, 16, 64]) if is_fd else rng.randint(0, 8)
        data = bytes(rng.getrandbits(8) for _ in range(length))
        if rng.random() < 0.05:
            data = (b"LOBJ" * 16)[:length]
        messages.append(
            can.Message(
                timestamp=T0 + i * 0.001 + rng.random() * 1e-4,
                arbitration_id=rng.getrandbits(29 if extended else 11),
                is_extended_id=extended,
                is_fd=is_fd,
                data=data,
                channel=rng.randint(0, 2),
            )
        )
    return messages


def _write(path: Path, messages: list[can.Message], **kwargs: object) -> Path:
    with can.Logger(path, **kwargs) as writer:
        for message in messages:
            writer.on_message_received(message)
    return path


def _reference(path: Path) -> list[can.Message]:
    with can.LogReader(path) as reader:
        return [m for m in reader if not (m.is_error_frame or m.is_remote_frame)]


def _assert_same(frames: CanFrames, reference: list[can.Message], *, channels: bool = True) -> None:
    assert len(frames) == len(reference)
    np.testing.assert_array_equal(frames.t_s, [m.timestamp for m in reference])
    np.testing.assert_array_equal(frames.arbitration_id, [m.arbitration_id for m in reference])
    np.testing.assert_array_equal(frames.is_extended, [m.is_extended_id for m in reference])
    if channels:
        expected = [-1 if m.channel is None else can.util.channel2int(m.channel) for m in reference]
        np.testing.assert_array_equal(frames.channel, expected)
    for k, message in enumerate(reference):
        n = len(message.data)
        assert frames.data[k, :n].tobytes() == bytes(message.data)
        assert not frames.data[k, n:].any()
        assert frames.dlc[k] == message.dlc


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.mark.parametrize("fmt", FORMATS)
def test_every_format_matches_python_can(tmp_path: Path, fmt: str) -> None:
    fd = fmt in ("blf", "asc", "mf4", "log")  # python-can writes CAN FD in these
    path = _write(tmp_path / f"bus.{fmt}", _traffic(600, fd=fd))
    before = _digest(path)
    frames = read_frames(path)
    _assert_same(frames, _reference(path))
    widest = int(frames.dlc.max())
    assert frames.data.shape == (len(frames), 8 if widest <= 8 else 64) and frames.data.dtype == np.uint8
    assert frames.t_s.dtype == np.float64 and frames.arbitration_id.dtype == np.uint32
    assert _digest(path) == before


def test_blf_fast_path_equals_blfreader_on_multi_container_file(tmp_path: Path) -> None:
    # small containers: many of them, objects cut across container boundaries, FD frames mixed in
    path = _write(tmp_path / "bus.blf", _traffic(20_000), max_container_size=4096)
    _assert_same(read_frames(path), _reference(path))


def test_blf_single_thread_path_equals_threaded(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A process limited to one thread (OMP_NUM_THREADS=1, as fleet workers) inflates inline."""
    path = _write(tmp_path / "bus.blf", _traffic(20_000), max_container_size=4096)
    threaded = read_frames(path)
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    inline = read_frames(path)
    for name in ("t_s", "channel", "arbitration_id", "is_extended", "dlc", "data"):
        np.testing.assert_array_equal(getattr(inline, name), getattr(threaded, name))
    _assert_same(inline, _reference(path))


def test_blf_uniform_classic_log_equals_blfreader(tmp_path: Path) -> None:
    path = _write(tmp_path / "bus.blf", _traffic(30_000, fd=False), max_container_size=16384)
    _assert_same(read_frames(path), _reference(path))


def _blf_object(kind: int, payload: bytes, ticks: int, *, version: int = 1) -> bytes:
    header_size = 32 if version == 1 else 40
    size = header_size + len(payload)
    base = blf.OBJ_HEADER_BASE_STRUCT.pack(b"LOBJ", header_size, version, size, kind)
    if version == 1:
        header = blf.OBJ_HEADER_V1_STRUCT.pack(blf.TIME_ONE_NANS, 0, 0, ticks)
    else:
        header = blf.OBJ_HEADER_V2_STRUCT.pack(blf.TIME_ONE_NANS, 0, 0, ticks)
    return base + header + payload + b"\0" * (size % 4)


def _handmade_blf(path: Path) -> Path:
    """A BLF with object kinds python-can's writer never produces: CAN_FD_MESSAGE_64, CAN_MESSAGE2
    with a version-2 header, a remote frame, next to ordinary CAN_MESSAGEs; uncompressed and
    zlib containers."""
    classic = [
        _blf_object(blf.CAN_MESSAGE, blf.CAN_MSG_STRUCT.pack(2, 0, 8, 0x100 + i, bytes(range(i, i + 8))), 1000 * i)
        for i in range(5)
    ]
    remote = _blf_object(blf.CAN_MESSAGE, blf.CAN_MSG_STRUCT.pack(1, 0x80, 0, 0x7FF, bytes(8)), 6000)
    fd64_body = blf.CAN_FD_MSG_64_STRUCT.pack(
        3, 9, 12, 0, 0x1ABCDE | blf.CAN_MSG_EXT, 0, 0x1000, 0, 0, 0, 0, 0, 0, 0, 0
    )
    fd64 = _blf_object(blf.CAN_FD_MESSAGE_64, fd64_body + bytes(range(40, 52)), 7000)
    msg2 = _blf_object(
        blf.CAN_MESSAGE2, blf.CAN_MSG_STRUCT.pack(1, 0, 3, 0x321, b"abc" + bytes(5)) + bytes(8), 8000, version=2
    )
    plain = b"".join([*classic[:3], remote, fd64])
    packed = b"".join([msg2, *classic[3:]])
    containers = b""
    for method, raw in ((blf.NO_COMPRESSION, plain), (blf.ZLIB_DEFLATE, packed)):
        body = raw if method == blf.NO_COMPRESSION else zlib.compress(raw)
        size = blf.OBJ_HEADER_BASE_STRUCT.size + blf.LOG_CONTAINER_STRUCT.size + len(body)
        containers += blf.OBJ_HEADER_BASE_STRUCT.pack(b"LOBJ", 16, 1, size, blf.LOG_CONTAINER)
        containers += blf.LOG_CONTAINER_STRUCT.pack(method, len(raw)) + body + b"\0" * (size % 4)
    start = blf.timestamp_to_systemtime(T0)
    header = [b"LOGG", blf.FILE_HEADER_SIZE, 5, 0, 0, 0, 2, 6, 8, 1, 0, 0, 9, 0, *start, *start]
    head = blf.FILE_HEADER_STRUCT.pack(*header).ljust(blf.FILE_HEADER_SIZE, b"\0")
    path.write_bytes(head + containers)
    return path


def test_blf_rare_object_kinds_equal_blfreader(tmp_path: Path) -> None:
    path = _handmade_blf(tmp_path / "rare.blf")
    frames = read_frames(path)
    _assert_same(frames, _reference(path))
    assert frames.is_extended.sum() == 1 and frames.dlc.max() == 12  # the FD-64 frame is there


@pytest.mark.parametrize("fmt", ["blf", "mf4", "asc"])
def test_iter_frames_chunks_concatenate_to_read_frames(tmp_path: Path, fmt: str) -> None:
    path = _write(tmp_path / f"bus.{fmt}", _traffic(3000), **({"max_container_size": 2048} if fmt == "blf" else {}))
    whole = read_frames(path)
    chunks = list(iter_frames(path, max_frames=257))
    assert all(0 < len(c) <= 257 for c in chunks)
    joined = CanFrames.concat(chunks)
    for name in ("t_s", "channel", "arbitration_id", "is_extended", "dlc", "data"):
        np.testing.assert_array_equal(getattr(joined, name), getattr(whole, name))


@pytest.mark.parametrize("fmt", ["blf", "mf4", "log"])
def test_filters_select_ids_and_channel(tmp_path: Path, fmt: str) -> None:
    messages = _traffic(2000)
    path = _write(tmp_path / f"bus.{fmt}", messages)
    whole = read_frames(path)
    wanted = [int(whole.arbitration_id[3]), int(whole.arbitration_id[10])]
    chosen = read_frames(path, ids=wanted, channel=1)
    mask = np.isin(whole.arbitration_id, wanted) & (whole.channel == 1)
    np.testing.assert_array_equal(chosen.t_s, whole.t_s[mask])
    width = chosen.data.shape[1]  # the payload table is as wide as its longest frame needs
    np.testing.assert_array_equal(chosen.data, whole.data[mask][:, :width])
    assert not whole.data[mask][:, width:].any()


def test_blf_channel_numbering_follows_python_can(tmp_path: Path) -> None:
    """Vector's CAN 2 is stored as 2 in the file and reported 0-based, like python-can does."""
    path = _write(tmp_path / "bus.blf", [can.Message(timestamp=T0, arbitration_id=5, data=b"\1", channel=1)])
    assert read_frames(path).channel.tolist() == [1]


# --- bad input ------------------------------------------------------------------------------


@pytest.fixture
def good_blf(tmp_path: Path) -> Path:
    return _write(tmp_path / "good.blf", _traffic(5000, fd=False))


def _copy(src: Path, dst: Path, data: bytes) -> Path:
    dst.write_bytes(data)
    return dst


def test_truncated_blf_is_reported(tmp_path: Path, good_blf: Path) -> None:
    data = good_blf.read_bytes()
    cut = _copy(good_blf, tmp_path / "cut.blf", data[: len(data) // 2])
    before = _digest(cut)
    with pytest.raises(InputError, match=rf"cut\.blf: expected a complete file: byte {len(data)}, .* ends at byte"):
        read_frames(cut)
    assert _digest(cut) == before
    # an unfinalised header (file size 0) does not hide the cut: the last container is incomplete
    header = bytearray(data[:144])
    struct.pack_into("<Q", header, 16, 0)  # the file size field
    open_ended = _copy(good_blf, tmp_path / "open.blf", bytes(header) + data[144 : len(data) // 2])
    with pytest.raises(InputError, match=r"the rest of its \d+-byte object at byte \d+, found a file that ends"):
        read_frames(open_ended)


@pytest.mark.parametrize("threads", ["default", "one"])
def test_corrupt_blf_container_is_reported(
    tmp_path: Path, good_blf: Path, threads: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    if threads == "one":
        monkeypatch.setenv("OMP_NUM_THREADS", "1")
    data = bytearray(good_blf.read_bytes())
    data[144 + 32 + 100 : 144 + 32 + 140] = b"\xff" * 40  # inside the first zlib stream
    bad = _copy(good_blf, tmp_path / "bad.blf", bytes(data))
    with pytest.raises(InputError, match=r"bad\.blf.*zlib-compressed log container.*undecodable"):
        read_frames(bad)


def test_not_a_blf_is_reported(tmp_path: Path) -> None:
    path = tmp_path / "noise.blf"
    path.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(InputError, match=r"b'LOGG'"):
        read_frames(path)


def test_corrupt_and_truncated_mf4_are_reported(tmp_path: Path) -> None:
    good = _write(tmp_path / "good.mf4", _traffic(3000, fd=False))
    data = good.read_bytes()
    cut = _copy(good, tmp_path / "cut.mf4", data[: len(data) // 2])
    before = _digest(cut)
    with pytest.raises(InputError, match=rf"cut\.mf4: expected a complete file: .*ends at byte {len(data) // 2}\."):
        read_frames(cut)
    assert _digest(cut) == before
    noise = _copy(good, tmp_path / "noise.mf4", bytes(range(256)) * 64)
    with pytest.raises(InputError, match=r"noise\.mf4: expected a readable MDF4"):
        read_frames(noise)


def test_malformed_text_log_is_reported(tmp_path: Path) -> None:
    path = tmp_path / "bad.csv"
    path.write_text("timestamp,arbitration_id,extended,remote,error,dlc,data\n1.0,zz,0,0,0,1,AA==\n")
    with pytest.raises(InputError, match=r"bad\.csv: expected a CSV log python-can can parse"):
        read_frames(path)


def test_unknown_suffix_and_missing_file_are_reported(tmp_path: Path) -> None:
    with pytest.raises(InputError, match=r"suffix '\.bin'"):
        read_frames(tmp_path / "x.bin")
    with pytest.raises(InputError, match=r"no such file"):
        read_frames(tmp_path / "missing.blf")


def test_empty_logs_give_no_frames(tmp_path: Path) -> None:
    for fmt in ("blf", "asc", "csv"):
        path = _write(tmp_path / f"empty.{fmt}", [])
        assert len(read_frames(path)) == 0


@pytest.mark.real_data
def test_canedge_mf4_matches_python_can(real_data: Path, tmp_path: Path) -> None:
    src = real_data / "canedge" / "2F6913DB_desk_static_2022-01-06" / "00000001.MF4"
    path = shutil.copy(src, tmp_path / "desk.MF4")
    frames = read_frames(path)
    _assert_same(frames, _reference(Path(path)))
    assert set(np.unique(frames.channel)) == {1, 2}
    assert len(read_frames(path, channel=7)) == 0 and len(read_frames(path, ids=[0x7FF])) == 0


def test_mf4_with_several_can_groups_is_merged_in_time(tmp_path: Path) -> None:
    from asammdf import MDF

    parts = []
    for channel, offset in ((1, 0.0), (2, 0.005)):
        messages = [
            can.Message(timestamp=T0 + 0.01 * i + offset, arbitration_id=0x100 + channel, data=bytes([i % 256] * 8),
                        is_extended_id=False, channel=channel)
            for i in range(300)
        ]  # fmt: skip
        parts.append(_write(tmp_path / f"part{channel}.mf4", messages))
    stacked = MDF.stack(parts)
    path = tmp_path / "stacked.mf4"
    stacked.save(path, overwrite=True)
    stacked.close()
    frames = read_frames(path)
    _assert_same(frames, _reference(path))
    assert np.all(np.diff(frames.t_s) >= 0) and set(frames.channel.tolist()) == {1, 2}
    chunks = list(iter_frames(path, max_frames=37))
    np.testing.assert_array_equal(np.concatenate([c.t_s for c in chunks]), frames.t_s)
