"""BLF (Vector binary logging format) parsed directly into :class:`~mountcal.io.can.frames.CanFrames`:
containers inflated on one background thread, object headers found and decoded on whole arrays.

Whole (:mod:`mountcal.io.whole`): the file is as long as its header records (the writer records
the size when it closes the file: python-can's BLFWriter leaves only the header's own size in a
file it never closed), and its last object is complete. A cut file read with ``--allow-truncated``
gives the frames of its complete containers.
"""

from __future__ import annotations

import struct
from collections import deque
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np
from isal import isal_zlib  # zlib-compatible inflate, 1.7× faster than zlib's on BLF containers
from numpy.typing import NDArray

from mountcal.core import budget
from mountcal.core.errors import InputError
from mountcal.core.threads import helpers_allowed
from mountcal.io.can.frames import CLASSIC_WIDTH, DATA_WIDTH, CanFrames, Filter, FloatArray, IntArray, pad_payload
from mountcal.io.inputs import block_too_large, max_block_bytes
from mountcal.io.whole import found_cut, was_cut

# ---------------------------------------------------------------------------------------------
# BLF (Vector binary logging format), parsed directly

_BLF_FILE_HEADER = struct.Struct("<4sLBBBBBBBBQQLL8H8H")
_BLF_OBJ_BASE = struct.Struct("<4sHHLL")  # signature, header size, header version, object size, type
_BLF_CONTAINER = struct.Struct("<H6xL4x")  # compression method, uncompressed size
_LOBJ = 0x4A424F4C  # b"LOBJ" read as a little-endian uint32
_LOG_CONTAINER, _CAN_MESSAGE, _CAN_MESSAGE2, _CAN_FD_MESSAGE, _CAN_FD_MESSAGE_64 = 10, 1, 86, 100, 101
_BLF_BATCH_BYTES = 4 << 20  # inflated bytes scanned at a time
_BLF_READ_BYTES = 4 << 20  # compressed bytes read at a time
_BLF_JOB_BYTES = 256 << 10  # containers handed to a thread together (inflated + compressed bytes)
_BLF_JOB_CONTAINERS = 1024  # ... or this many of them
_BLF_JOBS_IN_FLIGHT = 8
_BLF_RECORDS_CHARGED = 1 << 16  # objects walked between charges to the budget
DLC2LEN = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64], np.uint8)


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
        found_cut(path, actual, f"byte {file_size}, where its header says it ends")
    elif 0 < file_size <= header[1] < actual:  # the size of the header alone: never closed
        found_cut(path, actual, "the end its header records (the writer never closed the file: the header gives "
                  f"{file_size} bytes, its own size)")  # fmt: skip
    return _blf_start_time(header)


def _blf_compressed_containers(f: BinaryIO, path: Path) -> Iterator[tuple[int, int, bytes]]:
    """Top-level log containers as (method, uncompressed size, payload); other objects skipped.

    The file is read in large blocks (few system calls, and few GIL hand-overs with the inflating
    threads); objects are cut from the block.
    """
    offset = f.tell()
    block, pos = b"", 0
    walked = 0  # objects stepped through, charged to the budget in batches
    while True:
        if len(block) - pos < _BLF_OBJ_BASE.size:
            block, pos = block[pos:] + f.read(_BLF_READ_BYTES), 0
        raw = block[pos : pos + _BLF_OBJ_BASE.size]
        if not raw.strip(b"\0"):  # end of file (or trailing padding)
            budget.charge("records", walked, str(path), "BLF objects")
            return
        if len(raw) < _BLF_OBJ_BASE.size:
            found_cut(path, offset + len(raw), f"the rest of its object header at byte {offset}")
            return  # allowed: the complete objects before it are read
        signature, _, _, size, kind = _BLF_OBJ_BASE.unpack(raw)
        if signature != b"LOBJ" or size < _BLF_OBJ_BASE.size:
            raise _blf_error(path, f"an object signature b'LOBJ' at byte {offset}", f"{raw[:4]!r}")
        stride = size + size % 4  # objects are followed by size % 4 padding bytes
        if size > max_block_bytes():  # checked before it is read
            raise block_too_large(str(path), f"a BLF object (at byte {offset})", f"one of {size} bytes")
        if len(block) - pos < size:
            block, pos = block[pos:] + f.read(max(_BLF_READ_BYTES, stride)), 0
        if len(block) - pos < size:
            found_cut(path, offset + len(block) - pos, f"the rest of its {size}-byte object at byte {offset}")
            return  # allowed: the complete objects before it are read
        if kind == _LOG_CONTAINER:
            if size < _BLF_OBJ_BASE.size + _BLF_CONTAINER.size:
                raise _blf_error(path, "a log container header", f"a {size}-byte container")
            method, usize = _BLF_CONTAINER.unpack_from(block, pos + _BLF_OBJ_BASE.size)
            if usize > max_block_bytes():
                found = f"one stating {usize} bytes"
                raise block_too_large(str(path), f"a BLF log container (at byte {offset})", found)
            if usize:  # all containers together within the decompression ratio
                budget.inflate(size, usize, str(path), f"the BLF log containers up to byte {offset}")
            yield method, usize, block[pos + _BLF_OBJ_BASE.size + _BLF_CONTAINER.size : pos + size]
        pos += stride
        offset += stride
        walked += 1
        if walked == _BLF_RECORDS_CHARGED:
            budget.charge("records", walked, str(path), "BLF objects")
            walked = 0


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


def _inflate_all(containers: list[tuple[int, int, bytes]], path: Path) -> list[bytes]:
    return [_inflate(method, usize, payload, path) for method, usize, payload in containers]


def _jobs(containers: Iterator[tuple[int, int, bytes]]) -> Iterator[tuple[list[tuple[int, int, bytes]], int]]:
    """Containers grouped into jobs of about ``_BLF_JOB_BYTES`` (inflated and compressed), each with
    its size: a thread hand-over per job, not per container (a file of tiny or empty containers
    would otherwise cost a future each, and a queue of them)."""
    job: list[tuple[int, int, bytes]] = []
    size = 0
    for container in containers:
        job.append(container)
        size += container[1] + len(container[2])
        if size >= _BLF_JOB_BYTES or len(job) >= _BLF_JOB_CONTAINERS:
            yield job, size
            job, size = [], 0
    if job:
        yield job, size


def _blf_inflated(f: BinaryIO, path: Path) -> Iterator[bytes]:
    """Container payloads, inflated in two threads (ISA-L releases the GIL), or here where
    :func:`~mountcal.core.threads.helpers_allowed` says no.

    Up to a scan batch and a half of inflated bytes (and at most a few jobs) is kept in flight, so
    the threads inflate the next batch while the caller scans this one (a shallow queue left them
    idle during the scan).
    """
    containers = _blf_compressed_containers(f, path)
    if not helpers_allowed():
        yield from (_inflate(method, usize, payload, path) for method, usize, payload in containers)
        return
    pending: deque[tuple[Future[list[bytes]], int]] = deque()
    in_flight = 0
    with ThreadPoolExecutor(max_workers=2) as pool:
        for job, job_size in _jobs(containers):
            pending.append((pool.submit(_inflate_all, job, path), job_size))
            in_flight += job_size
            while in_flight > _BLF_BATCH_BYTES * 3 // 2 or len(pending) > _BLF_JOBS_IN_FLIGHT:
                future, size = pending.popleft()
                in_flight -= size
                yield from future.result()
        while pending:
            yield from pending.popleft()[0].result()


def iter_blf(path: Path, keep: Filter) -> Iterator[CanFrames]:
    """Frames of a BLF file, a batch of containers at a time."""
    # One batch buffer, reused: the frames copy what they keep out of it, and fresh buffers of
    # megabytes would cost page faults each time.
    buf = bytearray(2 * _BLF_BATCH_BYTES)
    filled = 0
    with path.open("rb") as f:
        start = _read_blf_header(f, path)
        for block in _blf_inflated(f, path):
            if not block:
                continue
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
        if bytes(buf[used:filled]).strip(b"\0") and not was_cut(path):  # a cut: the object ran on past it
            raise _blf_error(path, "complete objects up to the last container", "an object cut off at the end")


def _gather(arr: NDArray[np.uint8], pos: IntArray, width: int) -> NDArray[np.uint8]:
    """Bytes ``arr[pos + k]`` for k < width, shape (len(pos), width); reads past either end give 0."""
    index = pos[:, None] + np.arange(width)[None, :]
    if index.size and index[:, -1].max() < arr.shape[0] and pos.min() >= 0:
        return np.asarray(arr[index], dtype=np.uint8)
    inside = (index >= 0) & (index < arr.shape[0])
    return np.where(inside, arr[np.clip(index, 0, arr.shape[0] - 1)], 0).astype(np.uint8)


def le_field(arr: NDArray[np.uint8], pos: IntArray, dtype: str) -> NDArray[Any]:
    """A little-endian integer field at each of ``pos``, shape (len(pos),).

    Read as whole words from the four (or two, eight) aligned views of the buffer, which is much
    cheaper than gathering bytes; a position too close to the end, or before the start, reads as 0.
    """
    width = np.dtype(dtype).itemsize
    out = np.zeros(pos.shape[0], dtype)
    residue = pos % width
    for r in np.unique(residue) if width > 1 else (0,):
        count = (arr.shape[0] - int(r)) // width
        words = np.frombuffer(arr, dtype, count=max(count, 0), offset=int(r))
        sel = residue == r if width > 1 else slice(None)
        index = (pos[sel] - r) // width
        inside = (index >= 0) & (index < count)
        out[sel] = np.where(inside, words[np.clip(index, 0, max(count - 1, 0))] if count > 0 else 0, 0)
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


def _scan_blf(buf: memoryview, start: float, keep: Filter, path: Path) -> tuple[CanFrames, int]:
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


def _uniform_run(buf: memoryview, start: float, keep: Filter) -> tuple[CanFrames, int]:
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
    # the bytes the frame carries: a classic DLC of 9 to 15 means 8 (python-can's data holds 8)
    channel, dlc = rec["chan"][chosen].astype(np.int64) - 1, np.minimum(rec["dlc"][chosen], 8).astype(np.uint8)
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


def _scan_general(buf: memoryview, start: float, keep: Filter, path: Path) -> tuple[CanFrames, int]:
    """Frames of the complete objects in ``buf`` by locating every signature, and bytes consumed."""
    arr = np.frombuffer(buf, np.uint8)
    cand = _find_signatures(buf)
    size = le_field(arr, cand + 8, "<u4").astype(np.int64)
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
    kind = le_field(arr, pos + 12, "<u4")
    pay = pos + le_field(arr, pos + 4, "<u2").astype(np.int64)
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
    flags = le_field(arr, pos + 16, "<u4")
    ticks = le_field(arr, pos + 24, "<u8").astype(np.float64)
    # ticks / 1e9 is the correctly rounded quotient, the same float python-can gets through Decimal
    return np.where(flags == 1, ticks / 1e5, ticks / 1e9) + start


def _blf_select(raw_id: NDArray[np.uint32], channel: IntArray, not_remote: NDArray[np.bool_], keep: Filter) -> IntArray:
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
        # the bytes the frame carries: its DLC's length, or fewer where the object stores fewer (python-can's data)
        np.minimum(dlc, np.minimum(length, DATA_WIDTH)).astype(np.uint8),
        pad_payload(_gather(arr, data_pos, DATA_WIDTH if length.max(initial=0) > 8 else 8), length),
    )


def _blf_can_head(arr: NDArray[np.uint8], pay: IntArray, keep: Filter) -> tuple[NDArray[Any], IntArray, IntArray]:
    """Id, channel (0-based) and the kept rows of CAN_MESSAGE(2) and CAN_FD_MESSAGE objects: channel u16,
    flags u8 (0x80 remote), ., id u32."""
    raw_id = le_field(arr, pay + 4, "<u4")
    channel = le_field(arr, pay, "<u2").astype(np.int64) - 1
    return raw_id, channel, _blf_select(raw_id, channel, (arr[pay + 2] & 0x80) == 0, keep)


def _blf_classic(
    arr: NDArray[np.uint8], pos: IntArray, pay: IntArray, size: IntArray, start: float, keep: Filter
) -> tuple[CanFrames, IntArray]:
    """CAN_MESSAGE(2): channel u16, flags u8 (0x80 remote), dlc u8, id u32, 8 data bytes."""
    raw_id, channel, sel = _blf_can_head(arr, pay, keep)
    pay = pay[sel]
    dlc = arr[pay + 3]
    frames = _blf_frames(arr, pos[sel], raw_id[sel], channel[sel], dlc, pay + 8, np.minimum(dlc, 8), start)
    return frames, sel


def _blf_fd(
    arr: NDArray[np.uint8], pos: IntArray, pay: IntArray, size: IntArray, start: float, keep: Filter
) -> tuple[CanFrames, IntArray]:
    """CAN_FD_MESSAGE: channel u16, flags u8, dlc code u8, id u32, ..., valid bytes u8 @14, data @20."""
    raw_id, channel, sel = _blf_can_head(arr, pay, keep)
    pay = pay[sel]
    dlc = DLC2LEN[arr[pay + 3] & 0x0F]
    frames = _blf_frames(arr, pos[sel], raw_id[sel], channel[sel], dlc, pay + 20, arr[pay + 14], start)
    return frames, sel


def _blf_fd64(
    arr: NDArray[np.uint8], pos: IntArray, pay: IntArray, size: IntArray, start: float, keep: Filter
) -> tuple[CanFrames, IntArray]:
    """CAN_FD_MESSAGE_64: channel u8, dlc code u8, valid bytes u8, ., id u32, ..., flags u32 @12,
    ext data offset u8 @35, data @40."""
    raw_id = le_field(arr, pay + 4, "<u4")
    channel = arr[pay].astype(np.int64) - 1
    sel = _blf_select(raw_id, channel, (le_field(arr, pay + 12, "<u4") & 0x10) == 0, keep)
    pos, pay, size = pos[sel], pay[sel], size[sel]
    ext_offset = arr[pay + 35].astype(np.int64)
    # python-can (issue 1905): the data field may be shorter than `valid`; the rest reads as zeros
    field = np.where(ext_offset > 0, ext_offset, size) - (pay - pos) - 40
    length = np.clip(arr[pay + 2].astype(np.int64), 0, np.maximum(field, 0))
    dlc = DLC2LEN[arr[pay + 1] & 0x0F]
    return _blf_frames(arr, pos, raw_id[sel], channel[sel], dlc, pay + 40, length, start), sel
