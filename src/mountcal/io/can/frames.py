"""Raw CAN frames in bulk: one array per field, read from any python-can log format.

Every reader returns :class:`CanFrames`, a frozen table of n frames (data frames only: remote and
error frames carry no signal values and are not part of it). Conventions:

- ``t_s`` is in seconds on the log's clock, exactly as python-can's reader of the same format
  reports ``Message.timestamp`` (absolute Unix time for BLF and MF4, whatever the text file says for
  the text formats).
- ``channel`` is the channel number as python-can reports it: Vector's 1-based ``CAN 1`` in BLF and
  ASC becomes 0, an MF4 ``BusChannel`` is kept as the file gives it (CANedge ``CAN 2`` is 2), ``can1`` in a
  candump log is 1. Formats without a channel (CSV) give -1.
- ``dlc`` is the number of data bytes (python-can's ``Message.dlc``; for CAN FD the length, not the
  4-bit code); ``data`` is zero-padded to 8 bytes, or to 64 when a frame is longer (CAN FD).

Speed: BLF is parsed here, not through python-can (whose ``BLFReader`` is kept only as the
cross-check of the tests): containers are inflated with ISA-L (``isal``, zlib-compatible and 1.7×
faster than zlib here) in a small thread pool, which releases the GIL;
a batch of them is first read as one strided record array while its objects repeat the first
one's size and kind (a classic CAN log is all 48-byte CAN_MESSAGEs); anything else goes through
a general scan that locates every ``LOBJ`` signature with numpy, verifies the object chain
vectorised and gathers the fields of the wanted frames with fancy indexing. MF4 bus logs are read
with asammdf's record arrays of raw values, each numeric field then through the file's conversion
for it (CANedge firmware 01.07+ stores ``BusChannel`` and ``IDE`` as 0-bit channels whose value is
the conversion's constant), as python-can's ``MF4Reader`` reads them. The text formats (ASC,
candump ``.log``, TRC, CSV) go through python-can's readers, batched into arrays; they are the slow
formats.
"""

from __future__ import annotations

import gc
import logging
import math
import struct
import sys
from collections import deque
from collections.abc import Callable, Collection, Iterable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from isal import isal_zlib  # zlib-compatible inflate, 1.7× faster than zlib's on BLF containers
from numpy.typing import NDArray

from mountcal.errors import InputError
from mountcal.io.inputs import block_too_large, check_regular_file, hold, max_block_bytes
from mountcal.threads import helpers_allowed

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

DATA_WIDTH = 64  # the longest CAN FD payload: the widest CanFrames.data
CLASSIC_WIDTH = 8  # the narrowest: a log of classic frames only keeps 8 bytes per row
FORMATS = {".blf": "blf", ".asc": "asc", ".log": "log", ".trc": "trc", ".csv": "csv", ".mf4": "mf4", ".mdf": "mf4"}


@dataclass(frozen=True)
class CanFrames:
    """A table of n CAN data frames, one array per field.

    Attributes
    ----------
    t_s : ndarray, shape (n,), float64
        Reception time in seconds on the log's clock.
    channel : ndarray, shape (n,), int64
        Bus channel as python-can numbers it; -1 where the format has none.
    arbitration_id : ndarray, shape (n,), uint32
        11- or 29-bit identifier (without flag bits).
    is_extended : ndarray, shape (n,), bool
        True for 29-bit identifiers.
    dlc : ndarray, shape (n,), uint8
        Number of data bytes.
    data : ndarray, shape (n, w), uint8
        Payload, zero beyond ``dlc``; w is 8 when no frame is longer (classic CAN), up to 64 for
        CAN FD. Bytes past w read as zero.
    """

    t_s: FloatArray
    channel: IntArray
    arbitration_id: NDArray[np.uint32]
    is_extended: NDArray[np.bool_]
    dlc: NDArray[np.uint8]
    data: NDArray[np.uint8]

    def __post_init__(self) -> None:
        n = self.t_s.shape[0]
        for name in ("t_s", "channel", "arbitration_id", "is_extended", "dlc"):
            if getattr(self, name).shape != (n,):
                raise ValueError(f"CanFrames.{name} must have shape ({n},); got {getattr(self, name).shape}")
        if self.data.ndim != 2 or self.data.shape[0] != n or not CLASSIC_WIDTH <= self.data.shape[1] <= DATA_WIDTH:
            raise ValueError(f"CanFrames.data must have shape ({n}, 8 to {DATA_WIDTH}); got {self.data.shape}")

    def __len__(self) -> int:
        return int(self.t_s.shape[0])

    @classmethod
    def empty(cls) -> CanFrames:
        """A table with no frames."""
        return cls(
            np.empty(0, np.float64),
            np.empty(0, np.int64),
            np.empty(0, np.uint32),
            np.empty(0, np.bool_),
            np.empty(0, np.uint8),
            np.empty((0, CLASSIC_WIDTH), np.uint8),
        )

    def take(self, index: NDArray[Any] | slice) -> CanFrames:
        """The frames selected by a boolean mask, an index array or a slice."""
        if isinstance(index, np.ndarray) and index.dtype == np.bool_:
            index = np.flatnonzero(index)  # once, not once per field
        data = self.data
        if not isinstance(index, slice) and data.flags.c_contiguous and data.shape[1] % 8 == 0:
            # rows as whole 8-byte words: a 1-D gather, several times faster than a row gather of bytes
            data = data.view(np.uint64)[index].view(np.uint8)
        else:
            data = data[index]
        return CanFrames(
            self.t_s[index],
            self.channel[index],
            self.arbitration_id[index],
            self.is_extended[index],
            self.dlc[index],
            data,
        )

    @classmethod
    def concat(cls, parts: Iterable[CanFrames]) -> CanFrames:
        """All frames of ``parts``, in order."""
        parts = [p for p in parts if len(p)]
        if not parts:
            return cls.empty()
        if len(parts) == 1:
            return parts[0]
        width = max(p.data.shape[1] for p in parts)
        return cls(
            np.concatenate([p.t_s for p in parts]),
            np.concatenate([p.channel for p in parts]),
            np.concatenate([p.arbitration_id for p in parts]),
            np.concatenate([p.is_extended for p in parts]),
            np.concatenate([p.dlc for p in parts]),
            np.concatenate([_widen(p.data, width) for p in parts]),
        )


def _widen(data: NDArray[np.uint8], width: int) -> NDArray[np.uint8]:
    """Payload rows zero-padded to ``width`` bytes."""
    if data.shape[1] == width:
        return data
    return np.pad(data, ((0, 0), (0, width - data.shape[1])))


# ---------------------------------------------------------------------------------------------
# Public readers


def log_format(path: str | Path) -> str:
    """The log format of ``path`` from its suffix: one of ``blf asc log trc csv mf4``.

    Raises
    ------
    InputError
        When the suffix is not a CAN log format.
    """
    fmt = FORMATS.get(Path(path).suffix.lower())
    if fmt is None:
        raise InputError(
            str(path),
            "a CAN log (" + ", ".join(sorted(FORMATS)) + ")",
            f"the suffix {Path(path).suffix!r}",
            "Rename the file to its format's suffix or convert it with python-can's `can.logconvert`.",
        )
    return fmt


def read_frames(path: str | Path, *, ids: Collection[int] | None = None, channel: int | None = None) -> CanFrames:
    """Read all data frames of a CAN log into one table.

    Parameters
    ----------
    path : str or Path
        A BLF, ASC, candump ``.log``, TRC, CSV or MF4 file.
    ids : collection of int, optional
        Keep only these arbitration ids (filtering happens before payloads are copied).
    channel : int, optional
        Keep only this channel (python-can numbering, see the module docstring).

    Returns
    -------
    CanFrames
        The frames in file order.
    """
    chunks = iter_frames(path, ids=ids, channel=channel, max_frames=1 << 20)
    return CanFrames.concat(hold(chunks, str(path), "CAN frames"))


def iter_frames(
    path: str | Path,
    *,
    max_frames: int = 100_000,
    ids: Collection[int] | None = None,
    channel: int | None = None,
) -> Iterator[CanFrames]:
    """Stream the data frames of a CAN log in chunks of at most ``max_frames`` frames.

    Memory stays bounded by the chunk size: BLF is read a batch of containers at a time, MF4 a
    record range at a time, the text formats a batch of lines at a time.

    Parameters
    ----------
    path : str or Path
        A BLF, ASC, candump ``.log``, TRC, CSV or MF4 file.
    max_frames : int
        Largest chunk, in frames (after filtering).
    ids, channel
        As for :func:`read_frames`.

    Yields
    ------
    CanFrames
        Consecutive, non-empty chunks in file order.
    """
    path = Path(path)
    fmt = log_format(path)
    check_regular_file(path, "CAN log")
    keep = _Filter(ids, channel)
    if fmt == "blf":
        chunks = _iter_blf(path, keep)
    elif fmt == "mf4":
        chunks = _iter_mf4(path, keep, max_frames)
    else:
        chunks = _iter_text(path, fmt, keep, max_frames)
    yield from _rechunk(chunks, max_frames)


# ---------------------------------------------------------------------------------------------
# Shared helpers


class _Filter:
    """The frame selection of a reader: arbitration ids and a channel, both optional."""

    def __init__(self, ids: Collection[int] | None, channel: int | None) -> None:
        self.ids = None if ids is None else np.unique(np.asarray(list(ids), dtype=np.uint32))
        self.channel = channel
        self._table: NDArray[np.bool_] | None = None
        if self.ids is not None and (self.ids.shape[0] == 0 or self.ids[-1] < 2048):
            self._table = np.zeros(2048 + 1, np.bool_)  # 11-bit ids: one lookup instead of isin
            self._table[self.ids] = True

    def id_mask(self, arbitration_id: NDArray[Any]) -> NDArray[np.bool_] | None:
        """Which frames have a wanted id, or None for all."""
        if self.ids is None:
            return None
        if self._table is not None:
            return self._table[np.minimum(arbitration_id, 2048)]
        return np.isin(arbitration_id, self.ids)

    def mask(self, arbitration_id: NDArray[Any], channel: IntArray) -> NDArray[np.bool_] | None:
        """Which frames to keep, or None for all."""
        mask = self.id_mask(arbitration_id)
        if self.channel is not None:
            on_channel = channel == self.channel
            mask = on_channel if mask is None else mask & on_channel
        return mask


def _rechunk(chunks: Iterable[CanFrames], max_frames: int) -> Iterator[CanFrames]:
    """Regroup a stream of tables into tables of at most ``max_frames`` rows (none empty).

    Small tables (a filter keeps few frames of a batch) are joined until they hold a quarter of
    ``max_frames``; larger ones go out as they are, split as views: joining them would only copy.
    """
    if max_frames < 1:
        raise ValueError(f"max_frames must be >= 1; got {max_frames}")
    pending: list[CanFrames] = []
    count = 0
    for chunk in chunks:
        if not len(chunk):
            continue
        pending.append(chunk)
        count += len(chunk)
        if count < max(max_frames // 4, 1):
            continue
        joined = CanFrames.concat(pending)
        for start in range(0, len(joined), max_frames):
            yield joined.take(slice(start, start + max_frames))
        pending, count = [], 0
    if count:
        yield CanFrames.concat(pending)


def _pad_payload(payload: NDArray[np.uint8], length: NDArray[Any]) -> NDArray[np.uint8]:
    """Payload bytes (m, w) as (m, 8) when no row is longer than 8 bytes, else (m, 64); zero from
    ``length`` on."""
    m, width = payload.shape
    width = min(width, DATA_WIDTH)
    out_width = CLASSIC_WIDTH if width <= CLASSIC_WIDTH or length.max(initial=0) <= CLASSIC_WIDTH else DATA_WIDTH
    width = min(width, out_width)
    out = np.zeros((m, out_width), np.uint8)
    np.multiply(payload[:, :width], np.arange(width)[None, :] < length[:, None], out=out[:, :width], casting="unsafe")
    return out


# ---------------------------------------------------------------------------------------------
# BLF (Vector binary logging format), parsed directly

_BLF_FILE_HEADER = struct.Struct("<4sLBBBBBBBBQQLL8H8H")
_BLF_OBJ_BASE = struct.Struct("<4sHHLL")  # signature, header size, header version, object size, type
_BLF_CONTAINER = struct.Struct("<H6xL4x")  # compression method, uncompressed size
_LOBJ = 0x4A424F4C  # b"LOBJ" read as a little-endian uint32
_LOG_CONTAINER, _CAN_MESSAGE, _CAN_MESSAGE2, _CAN_FD_MESSAGE, _CAN_FD_MESSAGE_64 = 10, 1, 86, 100, 101
_BLF_BATCH_BYTES = 4 << 20  # inflated bytes scanned at a time
_BLF_READ_BYTES = 4 << 20  # compressed bytes read at a time
_DLC2LEN = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64], np.uint8)


def _blf_error(path: Path, expected: str, found: str) -> InputError:
    return InputError(
        str(path),
        expected,
        found,
        "The file is truncated or corrupt; re-export it from the logger or the Vector tool "
        "(python-can's `can.logconvert` can rewrite what it can read).",
    )


def _blf_start_time(header: tuple[Any, ...]) -> float:
    """The file's start time (SYSTEMTIME, UTC) as Unix seconds; 0 when absent, as python-can does."""
    year, month, _, day, hour, minute, second, milli = header[14:22]
    try:
        return datetime(year, month, day, hour, minute, second, milli * 1000, tzinfo=UTC).timestamp()
    except ValueError:
        return 0.0


def _read_blf_header(f: BinaryIO, path: Path) -> float:
    """Check the file header, leave ``f`` after it and return the start time."""
    raw = f.read(_BLF_FILE_HEADER.size)
    if len(raw) < _BLF_FILE_HEADER.size or raw[:4] != b"LOGG":
        raise _blf_error(path, "a BLF file header starting with b'LOGG'", f"{raw[:8]!r} ({len(raw)} bytes)")
    header = _BLF_FILE_HEADER.unpack(raw)
    f.seek(header[1])
    file_size = header[10]
    actual = path.stat().st_size
    if file_size and actual < file_size:
        raise _blf_error(path, f"{file_size} bytes as the BLF header records", f"{actual} bytes")
    return _blf_start_time(header)


def _blf_compressed_containers(f: BinaryIO, path: Path) -> Iterator[tuple[int, int, bytes]]:
    """Top-level log containers as (method, uncompressed size, payload); other objects skipped.

    The file is read in large blocks (few system calls, and few GIL hand-overs with the inflating
    threads); objects are cut from the block.
    """
    offset = f.tell()
    block, pos = b"", 0
    while True:
        if len(block) - pos < _BLF_OBJ_BASE.size:
            block, pos = block[pos:] + f.read(_BLF_READ_BYTES), 0
        raw = block[pos : pos + _BLF_OBJ_BASE.size]
        if not raw.strip(b"\0"):  # end of file (or trailing padding)
            return
        if len(raw) < _BLF_OBJ_BASE.size:
            raise _blf_error(path, f"an object header at byte {offset}", f"{len(raw)} bytes before the end")
        signature, _, _, size, kind = _BLF_OBJ_BASE.unpack(raw)
        if signature != b"LOBJ" or size < _BLF_OBJ_BASE.size:
            raise _blf_error(path, f"an object signature b'LOBJ' at byte {offset}", f"{raw[:4]!r}")
        stride = size + size % 4  # objects are followed by size % 4 padding bytes
        if size > max_block_bytes():  # checked before it is read
            raise block_too_large(str(path), f"a BLF object (at byte {offset})", f"one of {size} bytes")
        if len(block) - pos < size:
            block, pos = block[pos:] + f.read(max(_BLF_READ_BYTES, stride)), 0
        if len(block) - pos < size:
            found = f"the file ends {len(block) - pos} bytes into it"
            raise _blf_error(path, f"a {size}-byte object at byte {offset}", found)
        if kind == _LOG_CONTAINER:
            if size < _BLF_OBJ_BASE.size + _BLF_CONTAINER.size:
                raise _blf_error(path, "a log container header", f"a {size}-byte container")
            method, usize = _BLF_CONTAINER.unpack_from(block, pos + _BLF_OBJ_BASE.size)
            if usize > max_block_bytes():
                found = f"one stating {usize} bytes"
                raise block_too_large(str(path), f"a BLF log container (at byte {offset})", found)
            yield method, usize, block[pos + _BLF_OBJ_BASE.size + _BLF_CONTAINER.size : pos + size]
        pos += stride
        offset += stride


def _inflate(method: int, usize: int, payload: bytes, path: Path) -> bytes:
    """A container's objects; the inflate stops one byte past the size the container states, so a
    container inflating to more (a decompression bomb) costs no more memory than it declares."""
    try:
        if method == 0:
            return payload
        if method == 2:
            inflater = isal_zlib.decompressobj()
            out = inflater.decompress(payload, max_length=usize + 1)
            if len(out) > usize:
                found = f"one stating {usize} bytes that inflates to more"
            elif not inflater.eof:
                found = "an incomplete zlib stream"
            else:
                return out
        else:
            found = f"unknown compression method {method}"
    except isal_zlib.error as err:  # type: ignore[misc]  # the stub types it as an instance, not a class
        found = f"an undecodable one ({err})"
    raise _blf_error(path, "a zlib-compressed log container", found)


def _blf_inflated(f: BinaryIO, path: Path) -> Iterator[bytes]:
    """Container payloads, inflated in two threads (ISA-L releases the GIL), or here where
    :func:`~mountcal.threads.helpers_allowed` says no.

    Up to a scan batch and a half of inflated bytes is kept in flight, so the threads inflate the
    next batch while the caller scans this one (a shallow queue left them idle during the scan).
    """
    containers = _blf_compressed_containers(f, path)
    if not helpers_allowed():
        yield from (_inflate(method, usize, payload, path) for method, usize, payload in containers)
        return
    pending: deque[tuple[Future[bytes], int]] = deque()
    in_flight = 0
    with ThreadPoolExecutor(max_workers=2) as pool:
        for method, usize, payload in containers:
            pending.append((pool.submit(_inflate, method, usize, payload, path), usize))
            in_flight += usize
            while in_flight > _BLF_BATCH_BYTES * 3 // 2:
                future, size = pending.popleft()
                in_flight -= size
                yield future.result()
        while pending:
            yield pending.popleft()[0].result()


def _iter_blf(path: Path, keep: _Filter) -> Iterator[CanFrames]:
    """Frames of a BLF file, a batch of containers at a time."""
    # One batch buffer, reused: the frames copy what they keep out of it, and fresh buffers of
    # megabytes would cost page faults each time.
    buf = bytearray(2 * _BLF_BATCH_BYTES)
    filled = 0
    with path.open("rb") as f:
        start = _read_blf_header(f, path)
        for block in _blf_inflated(f, path):
            if filled + len(block) > len(buf):  # a container larger than the usual: a larger buffer
                buf = buf[:filled] + bytearray(max(len(buf), filled + len(block)))
            buf[filled : filled + len(block)] = block
            filled += len(block)
            if filled >= _BLF_BATCH_BYTES:
                frames, used = _scan_blf(memoryview(buf)[:filled], start, keep, path)
                yield frames
                buf[: filled - used] = buf[used:filled]
                filled -= used
        frames, used = _scan_blf(memoryview(buf)[:filled], start, keep, path)
        yield frames
        if bytes(buf[used:filled]).strip(b"\0"):
            raise _blf_error(path, "complete objects up to the last container", "an object cut off at the end")


def _gather(arr: NDArray[np.uint8], pos: IntArray, width: int) -> NDArray[np.uint8]:
    """Bytes ``arr[pos + k]`` for k < width, shape (len(pos), width); reads past the end give 0."""
    index = pos[:, None] + np.arange(width)[None, :]
    if index.size and index[:, -1].max() < arr.shape[0]:
        return arr[index]
    inside = index < arr.shape[0]
    return np.where(inside, arr[np.minimum(index, arr.shape[0] - 1)], 0).astype(np.uint8)


def _field(arr: NDArray[np.uint8], pos: IntArray, dtype: str) -> NDArray[Any]:
    """A little-endian integer field at each of ``pos``, shape (len(pos),).

    Read as whole words from the four (or two, eight) aligned views of the buffer, which is much
    cheaper than gathering bytes; a position too close to the end reads as 0.
    """
    width = np.dtype(dtype).itemsize
    out = np.zeros(pos.shape[0], dtype)
    residue = pos % width
    for r in np.unique(residue) if width > 1 else (0,):
        count = (arr.shape[0] - int(r)) // width
        words = np.frombuffer(arr, dtype, count=max(count, 0), offset=int(r))
        sel = residue == r if width > 1 else slice(None)
        index = (pos[sel] - r) // width
        inside = index < count
        out[sel] = np.where(inside, words[np.minimum(index, max(count - 1, 0))] if count > 0 else 0, 0)
    return out


def _find_signatures(buf: memoryview) -> IntArray:
    """Sorted byte offsets of every b"LOBJ" in ``buf`` (four aligned uint32 scans)."""
    hits = [np.empty(0, np.int64)]
    for k in range(4):
        count = (len(buf) - k) // 4
        if count > 0:
            words = np.frombuffer(buf, dtype="<u4", count=count, offset=k)
            hits.append(np.flatnonzero(words == _LOBJ) * 4 + k)
    return np.sort(np.concatenate(hits))


def _object_chain(cand: IntArray, end: IntArray, n_bytes: int, path: Path) -> IntArray:
    """Indices into ``cand`` of the real objects, in order, the last one possibly incomplete.

    Objects follow each other: the next one starts within 8 bytes after ``start + size`` (python-can
    searches the same window). A b"LOBJ" inside a payload is a false hit, skipped because the chain
    jumps over it. A run where every hit is the next object costs no Python work.
    """
    n = cand.shape[0]
    if n == 0 or cand[0] >= 8:
        if n_bytes < 8:
            return np.empty(0, np.int64)
        raise _blf_error(path, "an object at the start of the log data", "no b'LOBJ' signature")
    succ = np.searchsorted(cand, end, side="left")
    follows = np.zeros(n, np.bool_)
    follows[:-1] = (succ[:-1] == np.arange(1, n)) & (cand[1:] < end[:-1] + 8)
    breaks = np.flatnonzero(~follows)
    runs: list[IntArray] = []
    i = 0
    while True:
        stop = int(breaks[np.searchsorted(breaks, i)])  # last index of this run
        runs.append(np.arange(i, stop + 1))
        nxt = int(succ[stop])
        if nxt < n and cand[nxt] < end[stop] + 8:
            i = nxt
            continue
        if end[stop] + 8 <= n_bytes:
            raise _blf_error(path, f"an object within 8 bytes after inflated byte {int(end[stop])}", "none")
        return np.concatenate(runs)


def _scan_blf(buf: memoryview, start: float, keep: _Filter, path: Path) -> tuple[CanFrames, int]:
    """Frames of the complete objects in ``buf``, and the number of bytes consumed.

    A leading run of equal-sized classic CAN objects (the usual case: every object of a CAN log is
    a 48-byte CAN_MESSAGE) is read as one strided record array; the rest goes through the general
    signature scan.
    """
    fast, used = _uniform_run(buf, start, keep)
    if used == len(buf):
        return fast, used
    rest, rest_used = _scan_general(buf[used:], start, keep, path)
    return CanFrames.concat([fast, rest]), used + rest_used


def _uniform_run(buf: memoryview, start: float, keep: _Filter) -> tuple[CanFrames, int]:
    """Frames of the leading run of CAN_MESSAGE(2) objects that all have the first one's header.

    The run is one strided record array over the buffer: validating it is two 8-byte compares per
    object (signature, header size and version; object size and type), the id filter one table
    lookup; everything else is computed for the selected frames only.
    """
    if len(buf) < _BLF_OBJ_BASE.size:
        return CanFrames.empty(), 0
    signature, header_size, version, size, kind = _BLF_OBJ_BASE.unpack_from(buf)
    if signature != b"LOBJ" or kind not in (_CAN_MESSAGE, _CAN_MESSAGE2) or size < header_size + 16:
        return CanFrames.empty(), 0
    if (version, header_size) not in ((1, 32), (2, 40)):
        return CanFrames.empty(), 0
    stride = size + size % 4  # objects are followed by size % 4 padding bytes
    hs = header_size
    layout = np.dtype(
        {
            "names": ["head", "size_kind", "flags", "ticks", "chan", "mflags", "dlc", "id", "data"],
            "formats": ["<u8", "<u8", "<u4", "<u8", "<u2", "u1", "u1", "<u4", "<u8"],
            "offsets": [0, 8, 16, 24, hs, hs + 2, hs + 3, hs + 4, hs + 8],
            "itemsize": stride,
        }
    )
    rec = np.frombuffer(buf, layout, count=len(buf) // stride)
    head, size_kind = np.frombuffer(buf[:16], "<u8")
    ok = (rec["head"] == head) & (rec["size_kind"] == size_kind)
    run = rec.shape[0] if ok.all() else int(np.argmin(ok))
    rec = rec[:run]
    # the selection as indices, then each field gathered once: no copy of whole records
    wanted = keep.id_mask(rec["id"] & 0x1FFFFFFF)
    data_frame = (rec["mflags"] & 0x80) == 0  # remote frames carry no data
    if keep.channel is not None:
        data_frame &= rec["chan"] == keep.channel + 1
    index = np.flatnonzero(data_frame if wanted is None else data_frame & wanted)
    chosen: IntArray | slice = slice(None) if index.shape[0] == run else index
    flags, ticks, raw_id = rec["flags"][chosen], rec["ticks"][chosen].astype(np.float64), rec["id"][chosen]
    channel, dlc = rec["chan"][chosen].astype(np.int64) - 1, rec["dlc"][chosen].copy()
    frames = CanFrames(
        # ticks / 1e9 is the correctly rounded quotient, the float python-can gets through Decimal
        np.where(flags == 1, ticks / 1e5, ticks / 1e9) + start,
        channel,
        (raw_id & 0x1FFFFFFF).astype(np.uint32),
        (raw_id & 0x80000000) != 0,
        dlc,
        _classic_payload(rec["data"][chosen], dlc),
    )
    return frames, run * stride


# the low k bytes of a little-endian 8-byte word, for k = 0..8
_LOW_BYTES = np.array([(1 << (8 * k)) - 1 for k in range(9)], np.uint64)


def _classic_payload(words: NDArray[np.uint64], dlc: NDArray[np.uint8]) -> NDArray[np.uint8]:
    """Classic CAN payloads, each read as one little-endian word, as (m, 8) bytes zero from the DLC
    on (a DLC above 8 means 8 bytes)."""
    return (words & _LOW_BYTES[np.minimum(dlc, 8)]).astype("<u8").view(np.uint8).reshape(-1, CLASSIC_WIDTH)


def _scan_general(buf: memoryview, start: float, keep: _Filter, path: Path) -> tuple[CanFrames, int]:
    """Frames of the complete objects in ``buf`` by locating every signature, and bytes consumed."""
    arr = np.frombuffer(buf, np.uint8)
    cand = _find_signatures(buf)
    size = _field(arr, cand + 8, "<u4").astype(np.int64)
    # a header cut by the batch end reads as incomplete; bogus sizes of false hits are clamped
    size = np.where(cand + _BLF_OBJ_BASE.size <= len(buf), np.maximum(size, 1), len(buf) + 8)
    chain = _object_chain(cand, cand + size, len(buf), path)
    if chain.shape[0] == 0:
        return CanFrames.empty(), 0
    complete = cand[chain] + size[chain] <= len(buf)
    used = int(cand[chain[-1]] + size[chain[-1]]) if complete[-1] else int(cand[chain[-1]])
    chain = chain[complete]
    pos, size = cand[chain], size[chain]
    if (size < 32).any():
        bad = int(pos[np.argmax(size < 32)])
        raise _blf_error(path, f"an object of at least 32 bytes at inflated byte {bad}", "a shorter one")
    kind = _field(arr, pos + 12, "<u4")
    pay = pos + _field(arr, pos + 4, "<u2").astype(np.int64)
    parts = []
    for types, parse in (
        ((_CAN_MESSAGE, _CAN_MESSAGE2), _blf_classic),
        ((_CAN_FD_MESSAGE,), _blf_fd),
        ((_CAN_FD_MESSAGE_64,), _blf_fd64),
    ):
        sel = np.flatnonzero(np.isin(kind, types))
        if sel.shape[0]:
            frames, order = parse(arr, pos[sel], pay[sel], size[sel], start, keep)
            parts.append((frames, sel[order]))
    if len(parts) <= 1:
        return (parts[0][0] if parts else CanFrames.empty()), used
    order = np.argsort(np.concatenate([o for _, o in parts]), kind="stable")  # back to file order
    return CanFrames.concat([p for p, _ in parts]).take(order), used


def _blf_time(arr: NDArray[np.uint8], pos: IntArray, start: float) -> FloatArray:
    """Object timestamps in seconds: flag 1 = 10 µs ticks, otherwise ns (python-can's rule)."""
    flags = _field(arr, pos + 16, "<u4")
    ticks = _field(arr, pos + 24, "<u8").astype(np.float64)
    # ticks / 1e9 is the correctly rounded quotient, the same float python-can gets through Decimal
    return np.where(flags == 1, ticks / 1e5, ticks / 1e9) + start


def _blf_select(
    raw_id: NDArray[np.uint32], channel: IntArray, not_remote: NDArray[np.bool_], keep: _Filter
) -> IntArray:
    """Indices of the data frames the filter keeps."""
    mask = keep.mask(raw_id & 0x1FFFFFFF, channel)
    return np.flatnonzero(not_remote if mask is None else not_remote & mask)


def _blf_frames(
    arr: NDArray[np.uint8],
    pos: IntArray,
    raw_id: NDArray[np.uint32],
    channel: IntArray,
    dlc: NDArray[np.uint8],
    data_pos: IntArray,
    length: NDArray[Any],
    start: float,
) -> CanFrames:
    return CanFrames(
        _blf_time(arr, pos, start),
        channel,
        (raw_id & 0x1FFFFFFF).astype(np.uint32),
        (raw_id & 0x80000000) != 0,
        dlc,
        _pad_payload(_gather(arr, data_pos, DATA_WIDTH if length.max(initial=0) > 8 else 8), length),
    )


def _blf_classic(
    arr: NDArray[np.uint8], pos: IntArray, pay: IntArray, size: IntArray, start: float, keep: _Filter
) -> tuple[CanFrames, IntArray]:
    """CAN_MESSAGE(2): channel u16, flags u8 (0x80 remote), dlc u8, id u32, 8 data bytes."""
    raw_id = _field(arr, pay + 4, "<u4")
    channel = _field(arr, pay, "<u2").astype(np.int64) - 1
    sel = _blf_select(raw_id, channel, (arr[pay + 2] & 0x80) == 0, keep)
    pay = pay[sel]
    dlc = arr[pay + 3]
    frames = _blf_frames(arr, pos[sel], raw_id[sel], channel[sel], dlc, pay + 8, np.minimum(dlc, 8), start)
    return frames, sel


def _blf_fd(
    arr: NDArray[np.uint8], pos: IntArray, pay: IntArray, size: IntArray, start: float, keep: _Filter
) -> tuple[CanFrames, IntArray]:
    """CAN_FD_MESSAGE: channel u16, flags u8, dlc code u8, id u32, ..., valid bytes u8 @14, data @20."""
    raw_id = _field(arr, pay + 4, "<u4")
    channel = _field(arr, pay, "<u2").astype(np.int64) - 1
    sel = _blf_select(raw_id, channel, (arr[pay + 2] & 0x80) == 0, keep)
    pay = pay[sel]
    dlc = _DLC2LEN[arr[pay + 3] & 0x0F]
    frames = _blf_frames(arr, pos[sel], raw_id[sel], channel[sel], dlc, pay + 20, arr[pay + 14], start)
    return frames, sel


def _blf_fd64(
    arr: NDArray[np.uint8], pos: IntArray, pay: IntArray, size: IntArray, start: float, keep: _Filter
) -> tuple[CanFrames, IntArray]:
    """CAN_FD_MESSAGE_64: channel u8, dlc code u8, valid bytes u8, ., id u32, ..., flags u32 @12,
    ext data offset u8 @35, data @40."""
    raw_id = _field(arr, pay + 4, "<u4")
    channel = arr[pay].astype(np.int64) - 1
    sel = _blf_select(raw_id, channel, (_field(arr, pay + 12, "<u4") & 0x10) == 0, keep)
    pos, pay, size = pos[sel], pay[sel], size[sel]
    ext_offset = arr[pay + 35].astype(np.int64)
    # python-can (issue 1905): the data field may be shorter than `valid`; the rest reads as zeros
    field = np.where(ext_offset > 0, ext_offset, size) - (pay - pos) - 40
    length = np.clip(arr[pay + 2].astype(np.int64), 0, np.maximum(field, 0))
    dlc = _DLC2LEN[arr[pay + 1] & 0x0F]
    return _blf_frames(arr, pos, raw_id[sel], channel[sel], dlc, pay + 40, length, start), sel


# ---------------------------------------------------------------------------------------------
# MF4 (ASAM MDF 4 bus logging), read with asammdf


def _mf4_error(path: Path, found: str) -> InputError:
    return InputError(
        str(path),
        "a readable MDF4 bus log with a CAN_DataFrame channel group",
        found,
        "Check that the file is a finalised MF4 (CANedge: run mdf2finalized) and was copied completely.",
    )


def _open_mdf(path: Path) -> Any:
    from asammdf import MDF

    with path.open("rb") as f:
        magic = f.read(8)
    if not magic.startswith((b"MDF", b"UnFinMF")):  # CANedge writes unfinalised files
        raise _mf4_error(path, f"no MDF file identification (the file starts {magic!r})")
    _check_mf4_channel_groups(path)
    try:
        with _asammdf_quiet():
            return MDF(path)
    except Exception as err:  # asammdf raises bare Exception, struct.error, ValueError, ... on bad files
        cause = err
    _release_quietly(cause)
    raise _mf4_error(path, f"a file asammdf cannot open ({type(cause).__name__}: {cause})") from cause


_CG_DATA_BYTES = 32  # an MDF 4.x channel group's data section: record id, cycles, flags, sizes
_MAX_MF4_BLOCKS = 1 << 16


def _check_mf4_channel_groups(path: Path) -> None:
    """Refuse channel-group blocks that asammdf would misread into a huge allocation while opening.

    asammdf sizes its buffers from each channel group's record size, read at offsets that depend on
    the block's stated length: a damaged length (or record size) makes it allocate gigabytes before
    any of our checks run. A 4.x channel group is 24 + 8·links + 32 bytes; its record must fit the
    block limit. Walked from the header through the data-group and channel-group chains (small reads).
    """
    if path.stat().st_size < 64 + 24:
        return  # asammdf says what is wrong with a file this short
    seen: set[int] = set()

    def block(offset: int, kind: bytes) -> tuple[list[int], bytes] | None:
        if offset in seen or len(seen) > _MAX_MF4_BLOCKS:
            raise _mf4_error(path, f"a block chain that loops or never ends (at byte {offset})")
        seen.add(offset)
        f.seek(offset)
        head = f.read(24)
        if len(head) < 24 or head[:4] != kind:
            return None  # not this file's layout: left to asammdf's own checks
        length, n_links = struct.unpack_from("<QQ", head, 8)
        if kind == b"##CG" and length != 24 + 8 * n_links + _CG_DATA_BYTES:
            raise _mf4_error(
                path,
                f"a channel group stating {length} bytes at byte {offset} (with {n_links} links a "
                f"channel group is {24 + 8 * n_links + _CG_DATA_BYTES})",
            )
        rest = f.read(min(length, 4096) - 24) if length >= 24 else b""
        if len(rest) < 8 * n_links:
            raise _mf4_error(path, f"a {kind.decode()} block at byte {offset} cut short")
        return list(struct.unpack_from(f"<{n_links}Q", rest)), rest[8 * n_links :]

    with path.open("rb") as f:
        header = block(64, b"##HD")
        dg = header[0][0] if header and header[0] else 0
        while dg:
            data_group = block(dg, b"##DG")
            if data_group is None or len(data_group[0]) < 2:
                return
            cg = data_group[0][1]
            while cg:
                group = block(cg, b"##CG")
                if group is None or len(group[1]) < _CG_DATA_BYTES:
                    return
                data_bytes, inval_bytes = struct.unpack_from("<II", group[1], 24)
                if data_bytes + inval_bytes > max_block_bytes():
                    raise block_too_large(
                        str(path),
                        f"an MF4 record (channel group at byte {cg})",
                        f"{data_bytes + inval_bytes} bytes per record",
                    )
                cg = group[0][0] if group[0] else 0
            dg = data_group[0][0]


@contextmanager
def _asammdf_quiet() -> Iterator[None]:
    """asammdf's logger silenced: on a damaged file it prints tracebacks of errors it recovers
    from (its own bus-logging decoding, which these raw frames do not use); what cannot be read
    raises, and becomes an InputError here."""
    logger = logging.getLogger("asammdf")
    level = logger.level
    logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        logger.setLevel(level)


def _release_quietly(err: BaseException) -> None:
    """Free the half-built MDF object a failed ``MDF()`` leaves in the traceback, now.

    Its ``__del__`` fails (no ``_file`` attribute yet) and Python would print that as an ignored
    exception at some later garbage collection; here it happens under a hook that drops just that.
    """
    previous = sys.unraisablehook

    def hook(unraisable: Any) -> None:
        if not (isinstance(unraisable.exc_value, AttributeError) and "MDF" in repr(unraisable.object)):
            previous(unraisable)

    sys.unraisablehook = hook
    try:
        err.__traceback__ = None
        gc.collect()
    finally:
        sys.unraisablehook = previous


def _mf4_can_groups(mdf: Any) -> list[int]:
    """Indices of the channel groups holding CAN data frames."""
    return [
        i
        for i, group in enumerate(mdf.groups)
        if group.channel_group.cycles_nr and any(ch.name == "CAN_DataFrame" for ch in group.channels)
    ]


def _mf4_records(path: Path, mdf: Any, group: int, start: float, keep: _Filter, max_frames: int) -> Iterator[CanFrames]:
    """One group's frames, a record range at a time."""
    total = int(mdf.groups[group].channel_group.cycles_nr)
    conversions = _mf4_conversions(mdf, group)
    for offset in range(0, total, max_frames):
        try:
            with _asammdf_quiet():
                sig = mdf.get("CAN_DataFrame", group=group, record_offset=offset, record_count=max_frames, raw=True)
            table = _mf4_table(sig.samples, np.asarray(sig.timestamps, np.float64) + start, keep, conversions, path)
        except Exception as err:  # asammdf reports damaged data blocks with assorted exceptions
            raise _mf4_error(path, f"unreadable records from {offset} ({type(err).__name__}: {err})") from err
        yield table


# the CAN_DataFrame fields whose value is a number we use (not DataBytes, read as bytes)
_MF4_NUMERIC = ("BusChannel", "ID", "IDE", "DLC", "DataLength")


def _mf4_conversions(mdf: Any, group: int) -> dict[str, Any]:
    """The conversions of a group's numeric CAN_DataFrame fields, by field name.

    A field's value is its raw value through its conversion. CANedge firmware 01.07 and later
    relies on it: one channel group per bus and id kind, with ``BusChannel`` and ``IDE`` stored as
    0-bit channels whose value is the constant of a linear conversion (the raw "value" of a 0-bit
    channel is only the record index). Raw values without a conversion are the values.
    """
    out = {}
    for channel in mdf.groups[group].channels:
        field = str(channel.name).removeprefix("CAN_DataFrame.")
        if field in _MF4_NUMERIC and channel.conversion is not None:
            out[field] = channel.conversion
    return out


def _mf4_converted(values: NDArray[Any], conversion: Any, field: str, path: Path) -> NDArray[Any]:
    """``values`` through an asammdf conversion; a conversion to text is refused."""
    if conversion is None:
        return values
    out = np.asarray(conversion.convert(values))
    if out.dtype.kind not in "biuf":
        raise _mf4_error(path, f"CAN_DataFrame.{field} converted to {out.dtype} values, not numbers")
    return out


def _mf4_table(rec: NDArray[Any], t_s: FloatArray, keep: _Filter, conversions: dict[str, Any], path: Path) -> CanFrames:
    """A CAN_DataFrame record array (raw values) as CanFrames: numeric fields through their
    conversions, as python-can's MF4Reader reads them; fields missing from the file take defaults."""
    names = set(rec.dtype.names or ())
    n = rec.shape[0]

    def column(name: str, default: int) -> NDArray[Any]:
        key = f"CAN_DataFrame.{name}"
        if key not in names:
            return np.full(n, default)
        return _mf4_converted(np.asarray(rec[key]), conversions.get(name), name, path)

    raw_id = column("ID", 0).astype(np.uint32)
    channel = column("BusChannel", -1).astype(np.int64)
    mask = keep.mask(raw_id & 0x1FFFFFFF, channel)
    index = np.arange(n) if mask is None else np.flatnonzero(mask)
    payload = _mf4_payload(rec["CAN_DataFrame.DataBytes"][index])
    length = column("DataLength", -1)[index].astype(np.int64)
    length = np.where(length < 0, _DLC2LEN[column("DLC", 8)[index].astype(np.int64) & 0x0F], length)
    ide = column("IDE", -1)[index]
    ident = raw_id[index] & 0x1FFFFFFF
    return CanFrames(
        t_s[index],
        channel[index],
        ident.astype(np.uint32),
        np.where(ide < 0, ident > 0x7FF, ide != 0),
        length.astype(np.uint8),
        _pad_payload(payload, length),
    )


def _mf4_payload(data: NDArray[Any]) -> NDArray[np.uint8]:
    """DataBytes as a 2-D uint8 array (variable-length records come as an object array)."""
    if data.dtype != object:
        return np.asarray(data, np.uint8).reshape(data.shape[0], math.prod(data.shape[1:]))
    out = np.zeros((data.shape[0], DATA_WIDTH), np.uint8)
    for row, value in enumerate(data):
        raw = np.frombuffer(bytes(value), np.uint8)[:DATA_WIDTH]
        out[row, : raw.shape[0]] = raw
    return out


def _iter_mf4(path: Path, keep: _Filter, max_frames: int) -> Iterator[CanFrames]:
    mdf = _open_mdf(path)
    try:
        groups = _mf4_can_groups(mdf)
        if not groups and not any(any(c.name == "CAN_DataFrame" for c in g.channels) for g in mdf.groups):
            raise _mf4_error(path, "no CAN_DataFrame channel group (not a bus log)")
        for g in groups:
            _check_mf4_blocks(path, mdf.groups[g])
            _check_mf4_vlsd(path, mdf, g)
        start = float(mdf.header.start_time.timestamp())
        sources = [_mf4_records(path, mdf, g, start, keep, max_frames) for g in groups]
        if len(sources) == 1:
            yield from sources[0]
        elif sources:  # CAN frames split over several channel groups: merge them in time
            yield from _merge_by_time([(c for c in s if len(c)) for s in sources])
    finally:
        mdf.close()


def _check_mf4_blocks(path: Path, group: Any) -> None:
    """Refuse a data block stating more than the block limit before asammdf inflates it, and a
    channel group stating more record bytes than its data blocks hold (a damaged record size or
    count: asammdf would allocate what it states)."""
    total = 0
    for block in group.get_data_blocks():
        if block.original_size > max_block_bytes():
            what = f"an MF4 data block (at byte {block.address})"
            raise block_too_large(str(path), what, f"one stating {block.original_size} bytes")
        total += int(block.original_size)
    cg = group.channel_group
    record = int(cg.samples_byte_nr) + int(cg.invalidation_bytes_nr)
    if int(cg.cycles_nr) * record > total:
        found = f"a channel group stating {cg.cycles_nr} records of {record} bytes, with {total} bytes of record data"
        raise _mf4_error(path, found)


_VLSD = 1  # cn_type of a variable-length signal data channel (CANedge: DataBytes)


def _check_mf4_vlsd(path: Path, mdf: Any, index: int) -> None:
    """Refuse variable-length data whose records point outside it, before asammdf reads it.

    asammdf's C ``extract`` copies each value at the offset its record states without a bounds
    check: a damaged offset or length would make it read past its buffer (a segfault). A sound
    file has each record's offset, ascending, at a 4-byte length and that many bytes inside the
    channel's signal data.
    """
    group = mdf.groups[index]
    for ch_nr, channel in enumerate(group.channels):
        if channel.channel_type != _VLSD:
            continue
        for block in group.get_signal_data_blocks(ch_nr):
            if block.original_size > max_block_bytes():
                what = f"an MF4 signal data block (at byte {block.address})"
                raise block_too_large(str(path), what, f"one stating {block.original_size} bytes")
        try:
            with _asammdf_quiet():
                data, offsets = _mf4_vlsd_arrays(mdf._mdf, group, ch_nr)  # the MDF4 object under MDF
        except Exception as err:  # asammdf reports damaged data blocks with assorted exceptions
            raise _mf4_error(path, f"unreadable {channel.name} ({type(err).__name__}: {err})") from err
        if not offsets.shape[0]:
            continue
        name = f"{channel.name} (channel group {index})"
        size = data.shape[0]
        outside = np.flatnonzero(offsets > size - 4) if size >= 4 else np.arange(offsets.shape[0])
        if outside.shape[0]:
            k = int(outside[0])
            raise _mf4_error(path, f"{name}: record {k} points to byte {offsets[k]} of {size} bytes of signal data")
        starts = offsets.astype(np.int64)
        ends = starts + 4 + _field(data, starts, "<u4").astype(np.int64)
        beyond = np.flatnonzero(ends > size)
        if beyond.shape[0]:
            k = int(beyond[0])
            raise _mf4_error(path, f"{name}: record {k}'s value ends at byte {ends[k]} of {size} bytes of signal data")
        # asammdf reads a record range's values from the data between its first and last offsets
        descending = np.flatnonzero(starts[1:] < starts[:-1])
        if descending.shape[0]:
            k = int(descending[0]) + 1
            raise _mf4_error(path, f"{name}: record {k} points back, to byte {starts[k]} after {starts[k - 1]}")


def _mf4_vlsd_arrays(mdf4: Any, group: Any, ch_nr: int) -> tuple[NDArray[np.uint8], NDArray[np.uint64]]:
    """A VLSD channel's signal data, and the offset into it stated by each record (read a data
    fragment at a time, 8 bytes per record kept)."""
    data = np.frombuffer(mdf4._load_signal_data(group, ch_nr), np.uint8)
    record = int(group.channel_group.samples_byte_nr) + int(group.channel_group.invalidation_bytes_nr)
    at = int(group.channels[ch_nr].byte_offset)
    parts = [np.empty(0, "<u8")]
    for fragment in mdf4._load_data(group):
        rows = np.frombuffer(fragment.data, np.uint8)
        rows = rows[: rows.shape[0] // record * record].reshape(-1, record)
        parts.append(np.ascontiguousarray(rows[:, at : at + 8]).view("<u8").ravel())
    return data, np.concatenate(parts)


def _merge_by_time(sources: list[Iterator[CanFrames]]) -> Iterator[CanFrames]:
    """Merge time-ordered chunk streams into one time-ordered stream, holding one chunk per source."""
    heads: list[CanFrames | None] = [next(s, None) for s in sources]
    while any(h is not None for h in heads):
        # everything up to the earliest last-time of the held chunks is complete
        held = [k for k, h in enumerate(heads) if h is not None]
        first = held[int(np.argmin([float(heads[k].t_s[-1]) for k in held]))]  # type: ignore[union-attr]
        horizon = float(heads[first].t_s[-1])  # type: ignore[union-attr]
        out = []
        for k, head in enumerate(heads):
            if head is None:
                continue
            # the chunk that sets the horizon goes whole: progress even where damaged times are unsorted
            cut = len(head) if k == first else int(np.searchsorted(head.t_s, horizon, side="right"))
            out.append(head.take(slice(0, cut)))
            rest = head.take(slice(cut, None))
            heads[k] = rest if len(rest) else next(sources[k], None)
        merged = CanFrames.concat(out)
        yield merged.take(np.argsort(merged.t_s, kind="stable"))


# ---------------------------------------------------------------------------------------------
# Text formats, through python-can's readers


def _text_reader(path: Path, fmt: str) -> Any:
    import can

    readers: dict[str, Callable[..., Any]] = {
        "asc": can.ASCReader,
        "log": can.CanutilsLogReader,
        "trc": can.TRCReader,
        "csv": can.CSVReader,
    }
    return readers[fmt](str(path))


def _iter_text(path: Path, fmt: str, keep: _Filter, max_frames: int) -> Iterator[CanFrames]:
    from can.util import channel2int

    rows: list[tuple[float, int, int, bool, int, bytes]] = []
    line_error = (ValueError, IndexError, KeyError, TypeError)
    try:
        reader = _text_reader(path, fmt)
        with reader:
            for msg in reader:
                if msg.is_error_frame or msg.is_remote_frame:
                    continue
                ch = channel2int(msg.channel)
                rows.append(
                    (msg.timestamp, -1 if ch is None else ch, msg.arbitration_id, msg.is_extended_id,
                     len(msg.data), bytes(msg.data))
                )  # fmt: skip
                if len(rows) >= max_frames:
                    yield _rows_table(rows, keep)
                    rows = []
    except line_error as err:
        raise InputError(
            str(path),
            f"a {fmt.upper()} log python-can can parse",
            f"a malformed line ({type(err).__name__}: {err})",
            "Repair or re-export the log.",
        ) from err
    yield _rows_table(rows, keep)


def _rows_table(rows: list[tuple[float, int, int, bool, int, bytes]], keep: _Filter) -> CanFrames:
    if not rows:
        return CanFrames.empty()
    t_s, channel, ident, ext, length, payload = zip(*rows, strict=True)
    raw_id = np.asarray(ident, np.uint32)
    chan = np.asarray(channel, np.int64)
    mask = keep.mask(raw_id, chan)
    index = np.arange(len(rows)) if mask is None else np.flatnonzero(mask)
    width = max((len(payload[k]) for k in index), default=0)
    data = np.zeros((index.shape[0], CLASSIC_WIDTH if width <= CLASSIC_WIDTH else DATA_WIDTH), np.uint8)
    for row, k in enumerate(index):
        raw = payload[k][:DATA_WIDTH]
        data[row, : len(raw)] = np.frombuffer(raw, np.uint8)
    return CanFrames(
        np.asarray(t_s, np.float64)[index],
        chan[index],
        raw_id[index],
        np.asarray(ext, np.bool_)[index],
        np.minimum(np.asarray(length, np.int64)[index], DATA_WIDTH).astype(np.uint8),
        data,
    )


__all__ = ["CLASSIC_WIDTH", "DATA_WIDTH", "CanFrames", "iter_frames", "log_format", "read_frames"]
